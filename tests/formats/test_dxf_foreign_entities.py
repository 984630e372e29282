"""Reading the entities CAD programs write that are not plain lines and points, compared
with what GDAL's DXF driver reads from the same file: hatches, dimensions, leaders,
multileaders, multilines, solids, 3-D faces, block attributes, curves; and what is
skipped is said (a warning per kind, in ``MapFile.read_warnings`` and ``info --json``)."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

import apygis
from apygis.cli import main

ezdxf = pytest.importorskip("ezdxf")
shapely = pytest.importorskip("shapely")
pyogrio = pytest.importorskip("pyogrio")

HATCH_AREA = 100 + math.pi * 25 / 2  # a 10 x 10 square with a half circle of r 5 on one side


def _drawing(path, surfaces: bool = True):
    """A drawing as AutoCAD users make them (through ezdxf, not through apygis)."""
    from ezdxf.math import Vec2
    from ezdxf.render import mleader

    doc = ezdxf.new("R2010", setup=True)
    msp = doc.modelspace()
    for name in ("HATCHES", "DIMS", "MISC"):
        doc.layers.add(name)
    h = msp.add_hatch(dxfattribs={"layer": "HATCHES"})
    h.paths.add_polyline_path([(0, 0, 0), (10, 0, 1), (10, 10, 0), (0, 10, 0)], is_closed=True)
    ep = h.paths.add_edge_path()
    ep.add_line((20, 0), (30, 0))
    ep.add_arc((30, 5), 5, -90, 90)
    ep.add_line((30, 10), (20, 10))
    ep.add_line((20, 10), (20, 0))
    dim = msp.add_linear_dim(
        base=(3, 22), p1=(0, 20), p2=(10, 20), dimstyle="EZDXF", dxfattribs={"layer": "DIMS"}
    )
    dim.render()
    msp.add_leader([(40, 0), (45, 5), (50, 5)], dxfattribs={"layer": "DIMS"})
    mb = msp.add_multileader_mtext("Standard", dxfattribs={"layer": "DIMS"})
    mb.set_content("Hello leader")
    mb.add_leader_line(mleader.ConnectionSide.left, [Vec2(55, 0)])
    mb.build(insert=Vec2(60, 5))
    msp.add_mline([(0, 40), (10, 40), (10, 50)], dxfattribs={"layer": "MISC"})
    msp.add_solid([(20, 40), (30, 40), (20, 50), (30, 50)], dxfattribs={"layer": "MISC"})
    msp.add_3dface(
        [(40, 40, 1), (50, 40, 2), (50, 50, 3), (40, 50, 4)], dxfattribs={"layer": "MISC"}
    )
    if surfaces:
        mesh = msp.add_mesh(dxfattribs={"layer": "MISC"})
        with mesh.edit_data() as md:
            md.vertices = [(0, 0, 0), (1, 0, 0), (1, 1, 0)]
            md.faces = [(0, 1, 2)]
        pf = msp.add_polyface(dxfattribs={"layer": "MISC"})
        pf.append_face([(0, 0, 0), (1, 0, 0), (1, 1, 0)])
        msp.add_xline((0, 0), (1, 1))
    blk = doc.blocks.new("TREE")
    blk.add_circle((0, 0), 1)
    blk.add_attdef("SPECIES", (1, 1), dxfattribs={"height": 0.5})
    blk.add_attdef("SECRET", (1, 0), dxfattribs={"height": 0.5, "flags": 1})
    ins = msp.add_blockref("TREE", (70, 70), dxfattribs={"layer": "MISC"})
    ins.add_auto_attribs({"SPECIES": "Oak", "SECRET": "x"})
    msp.add_arc((80, 0), 5, 0, 90, dxfattribs={"layer": "MISC"})
    msp.add_ellipse((80, 20), major_axis=(6, 0, 0), ratio=0.5, dxfattribs={"layer": "MISC"})
    msp.add_open_spline([(90, 0), (95, 5), (100, 0), (105, 5)], dxfattribs={"layer": "MISC"})
    msp.add_mtext("  padded text  ", dxfattribs={"layer": "MISC", "insert": (0, 60, 0)})
    msp.add_text("Chilliwack General Hospital", dxfattribs={"layer": "MISC", "insert": (0, 70, 0)})
    msp.add_point((5, 80, 0), dxfattribs={"layer": "MISC"})
    msp.add_point((6, 80, 432.5), dxfattribs={"layer": "MISC"})
    doc.paperspace().add_line((0, 0), (1, 1))
    doc.saveas(path)
    return path


def _gdal(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta, _, geom, fields = pyogrio.raw.read(path)
    cols = dict(zip(meta["fields"], fields, strict=True))
    return cols, geom


def _rings(lay):
    cs = lay.chains()
    lp = lay.line_points
    return [
        shapely.Polygon(np.column_stack([lp["x"][cs.rows(k)], lp["y"][cs.rows(k)]]))
        for k in range(len(cs))
        if cs.closed[k]
    ]


def test_foreign_entities_are_imported_as_gdal_reads_them(tmp_path):
    path = _drawing(tmp_path / "cad.dxf", surfaces=False)  # GDAL cannot parse meshes itself
    m = apygis.read(path)
    assert sorted(m.layers) == ["dim", "hat", "mis", "x"]
    cols, geom = _gdal(path)
    gd = shapely.from_wkb(geom)
    layer = np.asarray(cols["Layer"])
    sub = np.asarray(cols["SubClasses"])

    # HATCH: its boundaries are closed lines; the area GDAL's polygons have
    hat = _rings(m.layers["hat"])
    assert len(hat) == 2
    gdal_hatch = gd[(layer == "HATCHES") & (sub == "AcDbEntity:AcDbHatch")][0]
    assert sum(r.area for r in hat) == pytest.approx(gdal_hatch.area, rel=2e-3)
    for r in hat:  # chords within 0.025 of the half circle (r 5, length 5 pi): inside it
        assert 0 < HATCH_AREA - r.area < 0.025 * 5 * math.pi

    # texts: those GDAL has (dimension, multileader, MTEXT kept whole with its blanks,
    # a 27-character TEXT, the attributes, the invisible one too: it is data)
    ours = sorted(t for lay in m for t in lay.texts["text"].tolist())
    theirs = sorted(t for t in cols["Text"] if t and t != "SOLID")
    assert ours == theirs
    assert "  padded text  " in ours
    assert "Chilliwack General Hospital" in ours
    assert "x" in ours

    # SOLID and 3DFACE outlines: closed lines of GDAL's polygon areas
    mis = _rings(m.layers["mis"])
    faces = gd[(layer == "MISC") & np.isin(sub, ["AcDbEntity:AcDbTrace", "AcDbEntity:AcDbFace"])]
    assert sorted(round(r.area, 6) for r in mis if r.area > 99) == sorted(
        round(g.area, 6) for g in faces
    )
    # the 3DFACE keeps its heights
    lp = m.layers["mis"].line_points
    assert {1.0, 2.0, 3.0, 4.0} <= set(lp["z"].tolist())

    # points: a height makes a spot height (00); without one an imported point (90)
    sym = m.layers["mis"].symbols
    assert sorted(zip(sym["z"].tolist(), sym["code"].tolist(), strict=True)) == [
        (0.0, 90),
        (0.0, 90),  # the INSERT of the foreign block TREE
        (432.5, 0),
    ]

    # dimension and leader lines: lines on the DIMS layer, within the lines GDAL has
    dims = m.layers["dim"]
    gdal_dims = shapely.union_all(gd[(layer == "DIMS") & (shapely.get_type_id(gd) != 0)])
    ext = np.column_stack([dims.line_points["x"], dims.line_points["y"]])
    assert len(ext) >= 10
    assert all(gdal_dims.distance(shapely.Point(p)) < 1e-6 for p in ext)


def test_curves_follow_gdal_within_the_chord_tolerance(tmp_path):
    path = _drawing(tmp_path / "cad.dxf", surfaces=False)
    tol = 0.025
    m = apygis.read(path, topology=False)
    cols, geom = _gdal(path)
    gd = shapely.from_wkb(geom)
    sub = np.asarray(cols["SubClasses"])
    for kind in (
        "AcDbEntity:AcDbCircle:AcDbArc",
        "AcDbEntity:AcDbEllipse",
        "AcDbEntity:AcDbSpline",
    ):
        (theirs,) = gd[sub == kind]
        lp = m.layers["mis"].line_points
        pts = shapely.points(np.column_stack([lp["x"], lp["y"]]))
        near = pts[shapely.distance(pts, theirs.buffer(0.5)) == 0]
        assert len(near) >= 8, kind
        # every vertex of ours lies on GDAL's curve within the tolerances of both flattenings
        assert shapely.distance(near, theirs).max() < 2 * tol, kind


def test_what_is_skipped_is_said_per_kind(tmp_path, caplog):
    path = _drawing(tmp_path / "cad.dxf")
    m = apygis.read(path)
    got = {w.what: w for w in m.read_warnings if w.kind == "skipped"}
    assert {"MESH", "POLYFACE", "XLINE", "paper space"} <= set(got)
    assert got["MESH"].count == 1
    assert "surfaces are not supported" in got["MESH"].message
    assert str(path) in got["XLINE"].message


def test_info_json_counts_what_was_skipped(tmp_path):
    path = _drawing(tmp_path / "cad.dxf")
    r = CliRunner().invoke(main, ["info", "--json", str(path)])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    skipped = {w["what"]: w["count"] for w in d["read_warnings"] if w["kind"] == "skipped"}
    assert skipped["MESH"] == 1
    assert skipped["POLYFACE"] == 1
    assert d["warnings"] >= len(d["read_warnings"]) >= 4
    text = CliRunner().invoke(main, ["info", str(path)])
    assert "1 MESH skipped (surfaces are not supported)" in text.output
