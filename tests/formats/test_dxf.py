"""DXF: exact round trips through apygis's own DXF, real foreign files, GDAL, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

import apygis
from apygis.errors import DriverError, FormatError, RecordError, ValueRangeError
from apygis.formats import dxf, get_driver
from apygis.model.polylines import export_lines
from apygis.model.records import LINE_DTYPE, TEXT_DTYPE
from apygis.model.symbols import default_library
from tests.conftest import EXTERNAL
from tests.formats.strategies import maps, random_rows, small_map

# The real DXF files of ../shared/external (named, so that a missing folder skips or,
# under CI, fails these tests instead of collecting none of them).
FOREIGN = [
    EXTERNAL / "ezdxf" / name
    for name in ("ASCII_R12.dxf", "Leica_Disto_S910.dxf", "cc_dxflib.dxf",
                 "multi_insert_with_attribs.dxf", "text_alignments.dxf")
] + [
    EXTERNAL / "gdal" / name
    for name in ("LWPOLYLINE-OCS.dxf", "assorted.dxf", "entities_only.dxf")
]  # fmt: skip


# --------------------------------------------------------------------------- helpers


def _raw_entities(path: Path) -> list[tuple[str, dict[int, list[str]], list[dict]]]:
    """Model-space entities of an ASCII DXF file by a plain scan of its tags.

    Independent of ezdxf: returns ``(type, tags, subentities)`` for each
    top-level entity of the ENTITIES section (VERTEX, ATTRIB and SEQEND are
    subentities of the one before), paper-space entities (67 = 1) left out.
    """
    lines = path.read_bytes().decode("latin-1").splitlines()
    pairs = [(lines[i].strip(), lines[i + 1].rstrip()) for i in range(0, len(lines) - 1, 2)]
    out = []
    in_entities = False
    cur = None
    for k, (code, value) in enumerate(pairs):
        if code == "0" and value == "SECTION" and pairs[k + 1] == ("2", "ENTITIES"):
            in_entities = True
            continue
        if not in_entities:
            continue
        value = value.strip()
        if code == "0":
            if value == "ENDSEC":
                break
            if value in ("VERTEX", "ATTRIB", "SEQEND"):
                cur[2].append({"type": value})
                continue
            cur = (value, {}, [])
            out.append(cur)
            continue
        if cur is None:  # the section's name
            continue
        target = cur[2][-1] if cur[2] else cur[1]
        target.setdefault(int(code), []).append(value)
    return [e for e in out if e[1].get(67, ["0"])[0] != "1"]


def _expected_counts(path: Path) -> dict[str, int]:
    ents = _raw_entities(path)
    symbols = lines = texts = vertices = 0
    curves = False
    for kind, tags, subs in ents:
        if kind == "POINT":
            symbols += 1
        elif kind == "INSERT":
            cols = int(tags.get(70, ["1"])[0]) if float(tags.get(44, ["0"])[0]) else 1
            rows = int(tags.get(71, ["1"])[0]) if float(tags.get(45, ["0"])[0]) else 1
            symbols += cols * rows
            # each visible attribute of a foreign block is a text, in every copy
            shown = [s for s in subs if s["type"] == "ATTRIB" and not int(s.get(70, ["0"])[0]) & 1]
            texts += len(shown) * cols * rows
        elif kind in ("TEXT", "MTEXT"):
            texts += 1
        elif kind == "LINE":
            lines += 1
            vertices += 2
        elif kind == "LWPOLYLINE":
            lines += 1
            vertices += int(tags[90][0])
        elif kind == "POLYLINE":
            if int(tags.get(70, ["0"])[0]) & (16 | 64) == 0:
                lines += 1
                vertices += sum(1 for s in subs if s["type"] == "VERTEX")
        elif kind in ("ARC", "CIRCLE", "ELLIPSE", "SPLINE"):
            lines += 1
            curves = True
    return {
        "symbols": symbols,
        "lines": lines,
        "texts": texts,
        "vertices": vertices,
        "curves": curves,
    }


def _totals(m: apygis.MapFile) -> dict[str, int]:
    out = {"symbols": 0, "line_points": 0, "lines": 0, "texts": 0}
    for lay in m:
        c = lay.counts()
        for k in out:
            out[k] += c[k]
    return out


def _ocs_to_wcs(x: float, y: float, elevation: float, extrusion) -> np.ndarray:
    """DXF's arbitrary axis algorithm, written out."""
    n = np.asarray(extrusion, dtype=float)
    n = n / np.linalg.norm(n)
    if abs(n[0]) < 1 / 64 and abs(n[1]) < 1 / 64:
        ax = np.cross([0.0, 1.0, 0.0], n)
    else:
        ax = np.cross([0.0, 0.0, 1.0], n)
    ax /= np.linalg.norm(ax)
    ay = np.cross(n, ax)
    ay /= np.linalg.norm(ay)
    return x * ax + y * ay + elevation * n


def _all_line_xyz(m: apygis.MapFile) -> np.ndarray:
    parts = [np.column_stack([lay.line_points[a] for a in "xyz"]) for lay in m]
    return np.concatenate(parts) if parts else np.zeros((0, 3))


# --------------------------------------------------------------------------- round trips


def test_sample_sheet_round_trip_is_exact(sample_map, tmp_path):
    path = tmp_path / "ZH1091.dxf"
    assert apygis.write(sample_map, path) == [path]
    back = apygis.read(path)
    assert back == sample_map
    for ext, lay in sample_map.layers.items():  # record for record, references included
        for table in ("symbols", "line_points", "texts"):
            assert np.array_equal(back.layers[ext].table(table), lay.table(table))
    assert back.crs_string() == "EPSG:2056"
    assert back.notes == sample_map.notes


def test_written_file_passes_the_ezdxf_audit(sample_map, tmp_path):
    import ezdxf
    from ezdxf import recover

    path = tmp_path / "ZH1091.dxf"
    apygis.write(sample_map, path)
    doc = ezdxf.readfile(path)
    assert doc.dxfversion == "AC1024"  # R2010
    auditor = doc.audit()
    assert not auditor.has_errors, [e.message for e in auditor.errors]
    assert not auditor.fixes, [f.message for f in auditor.fixes]
    _, rec_auditor = recover.readfile(path)
    assert not rec_auditor.has_errors
    assert not rec_auditor.fixes


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(m=maps())
def test_property_round_trip(m, tmp_path_factory):
    path = tmp_path_factory.mktemp("dxf") / "m.dxf"
    apygis.write(m, path)
    assert apygis.read(path) == m  # apygis's own parser
    assert apygis.read(path, fast=False) == m  # through ezdxf


def test_fast_path_only_for_untouched_files(sample_map, tmp_path, caplog):
    import logging

    import ezdxf

    path = tmp_path / "s.dxf"
    apygis.write(sample_map, path)
    with caplog.at_level(logging.DEBUG, logger="apygis.formats.dxf"):
        assert apygis.read(path) == sample_map
    assert "own parser" in caplog.text
    caplog.clear()

    # re-saved by a CAD program (here ezdxf): other layout, same records
    ezdxf.readfile(path).saveas(tmp_path / "resaved.dxf")
    with caplog.at_level(logging.DEBUG, logger="apygis.formats.dxf"):
        assert apygis.read(tmp_path / "resaved.dxf") == sample_map
    assert "own parser" not in caplog.text

    # a coordinate edited by hand: the checksum no longer fits, ezdxf reads the change
    m = small_map()
    apygis.write(m, path)
    data = path.read_bytes()
    head, ents = data.split(b"\nENTITIES\n", 1)  # ($EXTMIN in the header holds it too)
    assert ents.count(b" 10\n2683000.0\n") == 1
    ents = ents.replace(b" 10\n2683000.0\n", b" 10\n2683000.5\n")
    path.write_bytes(head + b"\nENTITIES\n" + ents)
    with caplog.at_level(logging.DEBUG, logger="apygis.formats.dxf"):
        back = apygis.read(path)
    assert "own parser" not in caplog.text
    assert back.layers["r"].line_points["x"][0] == 2683000.5
    assert back != m


def test_any_table_order_numbers_and_references_survive(tmp_path):
    rng = np.random.default_rng(7)
    lp = random_rows(rng, 1000)
    lp["num"] += 20000  # beyond APY's four digits
    lp["fwd"] = np.where(lp["fwd"] >= 0, lp["fwd"] + 20000, -1)
    lp["back"] = np.where(lp["back"] >= 0, lp["back"] + 20000, -1)
    lp["side1"][::97] = 123456789  # dangling, as the model allows
    lp["side2"][5] = lp["num"][500]
    lp = lp[rng.permutation(len(lp))]  # table order is not chain order
    m = apygis.MapFile("ORDER", scale=25000)
    m.add_layer(apygis.Layer.from_arrays("abc", line_points=lp))
    m.layer("e")  # an empty layer is kept
    apygis.write(m, tmp_path / "o.dxf")
    assert apygis.read(tmp_path / "o.dxf") == m


def test_texts_round_trip_exactly_whatever_they_hold(tmp_path):
    m = apygis.MapFile("TXT", crs="+proj=tmerc +lon_0=9 +k=1 +x_0=0 +y_0=0 +ellps=GRS80")
    m.notes = "line one\n\\U+0041 stays\ttabbed\r\nZürich – Nord 日本"
    lay = m.layer("t")
    for t in ["日本語のテキスト", "\\U+0041x", "%%d 12", "  lead", "trail  ", "a^Jb", "", "\\P"]:
        lay.add_text(1.5, 2.5, 3.5, t)
    apygis.write(m, tmp_path / "t.dxf")
    back = apygis.read(tmp_path / "t.dxf")
    assert back == m
    assert back.layers["t"].texts["text"].tolist() == lay.texts["text"].tolist()


def test_empty_map_and_map_without_scale(tmp_path):
    m = apygis.MapFile("EMPTY")
    apygis.write(m, tmp_path / "e.dxf")
    assert apygis.read(tmp_path / "e.dxf") == m
    m.layer("r").add_symbol(1, 2, 3, 6)
    apygis.write(m, tmp_path / "e.dxf")
    assert apygis.read(tmp_path / "e.dxf") == m


def test_r2013_is_written_on_request(tmp_path):
    import ezdxf

    apygis.write(small_map(), tmp_path / "s.dxf", version="R2013")
    assert ezdxf.readfile(tmp_path / "s.dxf").dxfversion == "AC1027"
    assert apygis.read(tmp_path / "s.dxf") == small_map()
    with pytest.raises(DriverError, match="R12"):
        apygis.write(small_map(), tmp_path / "s.dxf", version="R12")


# --------------------------------------------------------------------------- the layout


def test_layout_layers_blocks_attributes_xdata_header(sample_map, tmp_path):
    import ezdxf

    path = tmp_path / "ZH1091.dxf"
    apygis.write(sample_map, path)
    doc = ezdxf.readfile(path)
    assert doc.header["$INSUNITS"] == 6
    assert {"c", "e", "h", "r"} <= {ly.dxf.name for ly in doc.layers}
    assert dxf.APPID in doc.appids

    rec = doc.rootdict[dxf.APPID]["HEADER"]
    tags = [(t[0], t[1]) for t in rec.tags]
    keys = [v for c, v in tags if c == 1]
    assert keys == ["format", "version", "id", "scale", "crs", "notes", "layers", "entities"]
    assert tags[:4] == [(1, "format"), (3, '"apygis-dxf"'), (1, "version"), (3, "1")]
    assert (3, '"EPSG:2056"') in tags

    msp = doc.modelspace()
    r = sample_map.layers["r"]
    polys = [p for p in msp.query("POLYLINE") if p.dxf.layer == "r"]
    assert len(polys) == len(r.chains())
    assert all(p.is_3d_polyline for p in polys)
    assert sum(p.is_closed for p in polys) == r.counts()["closed_lines"]
    lp = r.line_points
    v = polys[0].vertices[0]
    vals = [int(s) for s in v.get_xdata(dxf.APPID)[0][1].split()]
    num, code, fwd, back, s1, s2, row = vals
    assert tuple(lp[row][["num", "code", "fwd", "back", "side1", "side2"]].tolist()) == (
        num,
        code,
        fwd,
        back,
        s1,
        s2,
    )
    assert tuple(v.dxf.location) == tuple(lp[row][["x", "y", "z"]].tolist())

    inserts = [i for i in msp.query("INSERT") if i.dxf.layer == "r"]
    assert len(inserts) == len(r.symbols)
    first = inserts[0]
    s = r.symbols[0]
    assert first.dxf.name == f"APY_SYM_{s['code']:02d}"
    assert {a.dxf.tag: a.dxf.text for a in first.attribs} == {
        "NUM": str(s["num"]),
        "CODE": f"{s['code']:02d}",
        "Z": f"{s['z']:.2f}",
    }
    assert tuple(first.dxf.insert) == (s["x"], s["y"], s["z"])

    # spot heights: an INSERT of APY_SYM_00 and a TEXT label with the height
    e = sample_map.layers["e"]
    labels = [t for t in msp.query("TEXT") if t.dxf.layer == "e"]
    assert len(labels) == len(e.symbols)
    assert labels[0].dxf.text == f"{e.symbols['z'][0]:.2f}"
    assert labels[0].get_xdata(dxf.APPID)[0][1] == "H"


def test_symbol_blocks_are_drawn_from_the_bitmaps_at_map_scale(sample_map, tmp_path):
    import ezdxf
    from ezdxf import bbox

    apygis.write(sample_map, tmp_path / "s.dxf")
    doc = ezdxf.readfile(tmp_path / "s.dxf")
    lib = default_library()
    cell = 3.0 / 15 * 5000 / 1000  # 3 mm on paper at 1:5000 = 15 m for 15 cells
    used = {int(c) for lay in sample_map for c in lay.symbols["code"]}
    assert {b.name for b in doc.blocks if b.name.startswith("APY_SYM_")} == {
        f"APY_SYM_{c:02d}" for c in used
    }
    for code in used:
        blk = doc.blocks[f"APY_SYM_{code:02d}"]
        solids = blk.query("SOLID")
        assert len(solids) == len(dxf.block_rects(lib[code].bitmap))
        assert sorted(a.dxf.tag for a in blk.query("ATTDEF")) == ["CODE", "NUM", "Z"]
        box = bbox.extents(solids)
        rows, cols = np.nonzero(lib[code].bitmap)
        assert box.extmin.x == pytest.approx((cols.min() - 7.5) * cell)
        assert box.extmax.x == pytest.approx((cols.max() + 1 - 7.5) * cell)
        assert box.extmax.y == pytest.approx((7.5 - rows.min()) * cell)
        assert box.extmin.y == pytest.approx((7.5 - rows.max() - 1) * cell)
    # painted area equals the painted cells
    rects = dxf.block_rects(lib[6].bitmap)
    area = ((rects[:, 2] - rects[:, 0]) * (rects[:, 3] - rects[:, 1])).sum()
    assert area == lib[6].painted


def test_free_code_gets_an_outline_square(tmp_path):
    import ezdxf

    lib = default_library()
    free = lib.free_codes[0]
    m = apygis.MapFile("FREE", scale=1000)
    m.layer("r").add_symbol(0, 0, 0, free)
    apygis.write(m, tmp_path / "f.dxf")
    doc = ezdxf.readfile(tmp_path / "f.dxf")
    assert len(doc.blocks[f"APY_SYM_{free:02d}"].query("SOLID")) == 4
    assert apygis.read(tmp_path / "f.dxf") == m


# --------------------------------------------------------------------------- GDAL


def test_gdal_reads_what_we_write(sample_map, tmp_path):
    import shapely
    from pyogrio import list_layers, raw

    path = tmp_path / "ZH1091.dxf"
    apygis.write(sample_map, path)
    assert list_layers(path)[:, 0].tolist() == ["entities"]
    meta, _, wkb, fields = raw.read(path)
    names = meta["fields"].tolist()
    layer = fields[names.index("Layer")]
    sub = fields[names.index("SubClasses")]
    text = fields[names.index("Text")]
    geoms = shapely.from_wkb(wkb)

    # GDAL (DXF_INLINE_BLOCKS and DXF_MERGE_BLOCK_GEOMETRIES at their defaults)
    # gives one feature per POLYLINE, one per TEXT, and per INSERT one feature
    # of the block's merged geometry plus one point feature per ATTRIB.
    expected = 0
    for ext, lay in sample_map.layers.items():
        n_sym = len(lay.symbols)
        n_spot = int((lay.symbols["code"] == 0).sum())
        n_lines = len(lay.chains())
        n_text = len(lay.texts)
        here = layer == ext
        assert (here & (sub == "AcDbEntity:AcDb3dPolyline")).sum() == n_lines
        assert (here & (sub == "AcDbEntity:AcDbBlockReference")).sum() == n_sym
        assert (here & (sub == "AcDbEntity:AcDbText:AcDbAttribute")).sum() == 3 * n_sym
        assert (here & (sub == "AcDbEntity:AcDbText:AcDbText")).sum() == n_text + n_spot
        expected += n_lines + 4 * n_sym + n_text + n_spot
    # the sample: 115 symbols (96 spot heights), 18 lines, 14 texts
    assert len(wkb) == expected == 4 * 115 + 96 + 18 + 14

    # coordinates: polylines vertex for vertex, branch ends touching their junctions
    for ext, lay in sample_map.layers.items():
        got = geoms[(layer == ext) & (sub == "AcDbEntity:AcDb3dPolyline")]
        lines = export_lines(lay)
        assert len(got) == len(lines)
        for g, pl in zip(got, lines, strict=True):
            want = np.r_[pl.coords, pl.coords[:1]] if pl.closed else pl.coords
            assert np.array_equal(shapely.get_coordinates(g, include_z=True), want)
        # texts at their 3-D positions (after the spot-height labels of the layer)
        tx = lay.texts
        sel = np.flatnonzero((layer == ext) & (sub == "AcDbEntity:AcDbText:AcDbText"))
        sel = sel[len(sel) - len(tx) :]
        assert text[sel].tolist() == tx["text"].tolist()
        xyz = shapely.get_coordinates(geoms[sel], include_z=True)
        assert np.array_equal(xyz, np.column_stack([tx["x"], tx["y"], tx["z"]]).reshape(-1, 3))
        # symbols: the block geometry sits on the symbol, 15 m wide at most at 1:5000
        ins = geoms[(layer == ext) & (sub == "AcDbEntity:AcDbBlockReference")]
        for g, s in zip(ins, lay.symbols, strict=True):
            x0, y0, x1, y1 = shapely.bounds(g)
            assert s["x"] - 7.5 <= x0 < x1 <= s["x"] + 7.5
            assert s["y"] - 7.5 <= y0 < y1 <= s["y"] + 7.5


# --------------------------------------------------------------------------- foreign files


@pytest.mark.external
@pytest.mark.parametrize("path", FOREIGN, ids=lambda p: p.name)
def test_foreign_files_read_with_their_entity_counts(path):
    want = _expected_counts(path)
    plain = apygis.read(path, topology=False)
    got = _totals(plain)
    assert got["symbols"] == want["symbols"]
    assert got["texts"] == want["texts"]
    assert got["lines"] == want["lines"]
    if not want["curves"]:
        # the one rebuild closes a polyline whose last vertex repeats its first and drops
        # repeated consecutive vertices, with or without topology
        assert want["vertices"] - 2 * want["lines"] <= got["line_points"] <= want["vertices"]
    joined = _totals(apygis.read(path))  # topology rebuilt: lines may merge
    assert joined["symbols"] == want["symbols"]
    assert joined["texts"] == want["texts"]
    assert joined["lines"] <= want["lines"]
    assert joined["line_points"] <= got["line_points"]


@pytest.mark.external
def test_ocs_polylines_are_read_in_world_coordinates():
    path = EXTERNAL / "gdal" / "LWPOLYLINE-OCS.dxf"
    m = apygis.read(path, topology=False)
    xyz = _all_line_xyz(m)
    checked = 0
    for kind, tags, _ in _raw_entities(path):
        if kind != "LWPOLYLINE" or 210 not in tags:
            continue
        extrusion = [float(tags[c][0]) for c in (210, 220, 230)]
        elevation = float(tags.get(38, ["0"])[0])
        for x, y in zip(tags[10], tags[20], strict=True):
            w = _ocs_to_wcs(float(x), float(y), elevation, extrusion)
            assert np.min(np.abs(xyz - w).max(axis=1)) < 1e-6
            checked += 1
    assert checked >= 10
    # one value worked out by hand from the file's first OCS polyline
    assert np.min(np.abs(xyz - [600325.568, 3153021.253, 562.760]).max(axis=1)) < 1e-3


@pytest.mark.external
def test_foreign_details_points_texts_inserts():
    leica = apygis.read(EXTERNAL / "ezdxf" / "Leica_Disto_S910.dxf")
    # one map layer per DXF layer, named from it
    assert sorted(leica.layers) == ["ldd", "ldp", "lei"]
    pts = leica.layers["ldp"].symbols
    assert len(pts) == 11
    assert pts["num"].tolist() == list(range(1, 12))
    # a POINT with a height is a spot height (00), one at Z 0 an imported point (90)
    assert np.array_equal(pts["code"] == 0, pts["z"] != 0)
    assert set(pts["code"][pts["z"] == 0].tolist()) <= {90}
    assert np.count_nonzero(pts["z"]) > 0
    assert len(leica.layers["lei"].texts) == 11
    assert len(leica.layers["ldd"].line_points) > 0

    flags = apygis.read(EXTERNAL / "ezdxf" / "multi_insert_with_attribs.dxf", point_code=42)
    sym = flags.layers["fla"].symbols  # DXF layer FLAGS
    assert len(sym) == 25
    assert set(sym["code"].tolist()) == {42}
    assert len(np.unique(sym["num"])) == 25
    # the blocks' attributes: texts on their own layer (0), one per copy, as GDAL reads them
    tx = flags.layers["x"].texts["text"].tolist()
    assert len(tx) == 75
    assert tx.count("Flag") == 25
    assert tx.count("x = 0.000") == 25

    texts = apygis.read(EXTERNAL / "ezdxf" / "text_alignments.dxf").layers["x"].texts
    assert "BASELINE ADJUSTMENTS" in texts["text"].tolist()

    assorted = apygis.read(EXTERNAL / "gdal" / "assorted.dxf")  # ezdxf cannot audit it
    assert _totals(assorted)["texts"] == 1


@pytest.mark.external
def test_circles_are_flattened_to_closed_lines_on_the_circle():
    path = EXTERNAL / "ezdxf" / "text_alignments.dxf"
    circles = [t for kind, t, _ in _raw_entities(path) if kind == "CIRCLE"]
    m = apygis.read(path, topology=False, chord_m=0.001)
    assert sorted(m.layers) == ["ins", "x"]  # DXF layers 0 and INSERT_POINTS
    lay = m.layers["ins"]
    lp = lay.line_points
    cs = lay.chains()
    assert int(cs.closed.sum()) == len(circles) == 32
    for tags in circles[:4]:
        cx, cy, r = (float(tags[c][0]) for c in (10, 20, 40))
        ring = [k for k in range(len(cs)) if cs.closed[k]]
        dists = [np.hypot(lp["x"][cs.rows(k)] - cx, lp["y"][cs.rows(k)] - cy) for k in ring]
        on = [d for d in dists if np.allclose(d, r, atol=1e-9)]
        assert on, f"no ring on the circle at {cx}, {cy} r {r}"
        assert len(on[0]) >= 8


def test_binary_dxf_is_read(sample_map, tmp_path):
    import ezdxf

    from tests.test_fuzz import mutate

    apygis.write(sample_map, tmp_path / "a.dxf")
    ezdxf.readfile(tmp_path / "a.dxf").saveas(tmp_path / "b.dxf", fmt="bin")
    assert (tmp_path / "b.dxf").read_bytes().startswith(b"AutoCAD Binary DXF")
    assert dxf.probe(tmp_path / "b.dxf")
    assert apygis.read(tmp_path / "b.dxf") == sample_map
    seed = (tmp_path / "b.dxf").read_bytes()
    rng = np.random.default_rng(3)
    for _ in range(40):
        (tmp_path / "m.dxf").write_bytes(mutate(seed, rng))
        try:
            got = apygis.read(tmp_path / "m.dxf")
        except FormatError as exc:
            got = exc
        assert isinstance(got, apygis.MapFile) or "m.dxf" in str(got)


@pytest.mark.external
def test_layer_map_skipping_and_unknown_names():
    path = EXTERNAL / "ezdxf" / "Leica_Disto_S910.dxf"
    m = apygis.read(path, layer_map="LEICA_DISTO_POINT_ENTITY=p, leica_disto_3d=l,LEICA_DISTO_ID=-")
    counts = {k: (len(v.symbols), len(v.texts), len(v.line_points)) for k, v in m.layers.items()}
    assert counts == {"p": (11, 0, 0), "l": (0, 0, counts["l"][2])}
    assert counts["l"][2] > 0
    m2 = apygis.read(path, layer_map={"leica_disto_point_entity": "P"})
    assert sorted(m2.layers) == ["ldd", "lei", "p"]
    assert len(m2.layers["p"].symbols) == 11
    with pytest.raises(DriverError, match=r"'NOSUCH', which the file does not have .*LEICA"):
        apygis.read(path, layer_map="NOSUCH=r")
    only = apygis.read(path, layers=["leica_disto_id"])
    assert list(only.layers) == ["lei"]
    with pytest.raises(DriverError, match=r"no layer 'nope' in the file \(its layers: 0, "):
        apygis.read(path, layers=["nope"])


def test_layer_map_parsing():
    assert dxf.parse_layer_map("ROADS=r,WATER=h") == {"ROADS": "r", "WATER": "h"}
    assert dxf.parse_layer_map({"0": "-", "A": None}) == {"0": None, "A": None}
    with pytest.raises(DriverError, match="ROADS"):
        dxf.parse_layer_map("ROADS")
    with pytest.raises(DriverError, match="1 to 3 letters"):
        dxf.parse_layer_map({"ROADS": "road"})
    with pytest.raises(DriverError, match="point_code"):
        dxf.read("nowhere.dxf", point_code=100)


def test_dxf_edited_in_cad_keeps_records_and_adds_new_geometry(sample_map, tmp_path):
    import ezdxf

    path = tmp_path / "edited.dxf"
    apygis.write(sample_map, path)
    doc = ezdxf.readfile(path)
    msp = doc.modelspace()
    msp.add_line((2683900.0, 1247900.0, 500.0), (2683910.0, 1247900.0, 501.0), {"layer": "r"})
    msp.add_lwpolyline([(0, 0), (10, 0), (10, 10)], close=True, dxfattribs={"layer": "ROADS"})
    msp.add_text("new name", dxfattribs={"layer": "r", "insert": (2683901.0, 1247901.0, 9.0)})
    msp.add_point((2683950.0, 1247950.0, 512.5), dxfattribs={"layer": "e"})
    doc.saveas(path)
    back = apygis.read(path, layer_map="ROADS=r")
    r0, r1 = sample_map.layers["r"], back.layers["r"]
    n0 = len(r0.line_points)
    assert np.array_equal(r1.line_points[:n0], r0.line_points)
    assert len(r1.line_points) == n0 + 2 + 3
    assert r1.counts()["lines"] == r0.counts()["lines"] + 2
    assert r1.texts["text"][-1] == "new name"
    assert r1.texts["num"][-1] == r0.texts["num"].max() + 1
    e1 = back.layers["e"].symbols
    assert e1[-1]["code"] == 0
    assert e1[-1]["num"] == sample_map.layers["e"].symbols["num"].max() + 1


# --------------------------------------------------------------------------- registry


def test_registry_extension_and_probe(tmp_path):
    m = small_map()
    assert get_driver("dxf").extensions == ("dxf",)
    apygis.write(m, tmp_path / "sheet.DXF")
    assert apygis.read(tmp_path / "sheet.DXF") == m
    apygis.write(m, tmp_path / "sheet.cad", driver="dxf")
    assert dxf.probe(tmp_path / "sheet.cad")
    assert apygis.read(tmp_path / "sheet.cad") == m  # recognised by content
    assert not dxf.probe(tmp_path / "nothing.dxf")
    (tmp_path / "a.txt").write_text("hello\n")
    assert not dxf.probe(tmp_path / "a.txt")


# --------------------------------------------------------------------------- bad input


def _seed(tmp_path) -> bytes:
    apygis.write(small_map(), tmp_path / "seed.dxf")
    return (tmp_path / "seed.dxf").read_bytes()


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda d: b"", "empty"),
        (lambda d: b"   \n\n", "empty"),
        (lambda d: bytes(range(256)) * 8, "not a DXF"),
        (lambda d: b"\x89PNG\r\n\x1a\n" + d[:500], "not a DXF"),
        (lambda d: d[: len(d) // 2], "truncated"),
        (lambda d: d[:-20], "truncated"),
        (lambda d: b"  0\nSECTION\n  2\nENTITIES\n  0\nLINE\n 10\n1e999\n 20\n0\n 30\n0\n"
         b" 11\n1\n 21\n0\n 31\n0\n  0\nENDSEC\n  0\nEOF\n", "not finite"),
        (lambda d: d.replace(b"1000\n1 11 2 -1 -1 -1 0\n", b"1000\n1 11 2 -1 -1 x 0\n"), "XDATA"),
        (lambda d: d.replace(b'"apygis-dxf"', b'"other"'), "format"),
        (lambda d: d.replace(b"1000\nT 1\n", b"1000\nT one\n"), "XDATA"),
    ],
)  # fmt: skip
def test_bad_input_is_a_format_error(make, match, tmp_path):
    data = make(_seed(tmp_path))
    (tmp_path / "bad.dxf").write_bytes(data)
    with pytest.raises(FormatError, match=match) as exc:
        apygis.read(tmp_path / "bad.dxf")
    assert "bad.dxf" in str(exc.value)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(FormatError, match="no such file"):
        dxf.read(tmp_path / "none.dxf")
    (tmp_path / "d.dxf").mkdir()
    with pytest.raises(FormatError, match="directory"):
        dxf.read(tmp_path / "d.dxf")


def test_unwritable_records_are_refused_and_nothing_is_written(tmp_path):
    lp = np.zeros(2, LINE_DTYPE)
    lp["num"] = [1, 2]
    lp["x"] = [0.0, np.nan]
    lp["fwd"], lp["back"], lp["side1"], lp["side2"] = [2, -1], [-1, 1], -1, -1
    # the model refuses a non-finite coordinate before any writer could see it
    with pytest.raises(RecordError, match="not finite"):
        apygis.Layer.from_arrays("r", line_points=lp)
    tx = np.zeros(1, TEXT_DTYPE)
    tx["text"] = "two\nlines"
    m = apygis.MapFile("BAD")
    m.add_layer(apygis.Layer.from_arrays("r", texts=tx))
    with pytest.raises(ValueRangeError, match="control"):
        apygis.write(m, tmp_path / "bad.dxf")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "word", [b"EOF", b"ENDSEC", b"VERTEX", b"INSERT", b"SEQEND", b"AcDbEntity", b"APYGIS"]
)
def test_a_removed_structure_word_gives_a_map_or_a_format_error(word, tmp_path):
    data = _seed(tmp_path)
    k = data.find(word)
    (tmp_path / "m.dxf").write_bytes(data[:k] + data[k + len(word) :])
    try:
        got = apygis.read(tmp_path / "m.dxf")
    except FormatError as exc:
        got = exc
    assert isinstance(got, apygis.MapFile) or "m.dxf" in str(got)


# ------------------------------------------------------------------------ hostile input (issue 9)


def _header_entry(data: bytes, key: bytes) -> bytes:
    """The tags of one entry of the APYGIS header record: ``1 key`` and its ``3`` chunks."""
    start = data.index(b"  1\n" + key + b"\n  3\n")
    end = data.index(b"\n  1\n", start + 4) + 1
    if data.find(b"\n  0\n", start) < end:  # the last entry ends the record
        end = data.index(b"\n  0\n", start) + 1
    return data[start:end]


@pytest.mark.parametrize(
    "key", [b"format", b"version", b"id", b"scale", b"crs", b"notes", b"layers"]
)
def test_header_record_lacking_an_entry_is_a_format_error(key, tmp_path):
    """A header record without ``scale`` or ``crs`` once ended in a KeyError."""
    data = _seed(tmp_path)
    entry = _header_entry(data, key)
    assert data.count(entry) == 1
    (tmp_path / "bad.dxf").write_bytes(data.replace(entry, b""))
    for fast in (True, False):
        with pytest.raises(FormatError, match="APYGIS header record") as exc:
            dxf.read(tmp_path / "bad.dxf", fast=fast)
        assert exc.value.path == str(tmp_path / "bad.dxf")
        if key not in (b"format", b"version"):
            assert f"no '{key.decode()}' entry" in str(exc.value)


def test_header_record_without_entities_entry_is_read_through_ezdxf(tmp_path):
    data = _seed(tmp_path)
    (tmp_path / "a.dxf").write_bytes(data.replace(_header_entry(data, b"entities"), b""))
    assert dxf.read(tmp_path / "a.dxf") == small_map()


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        (b"notes", b"[" * 3000 + b"]" * 3000, "JSON nested 3000 deep"),
        (b"scale", b"9" * 5000, "an integer of 5000 digits"),
        (b"scale", b"NaN", "NaN is not a number JSON allows"),
        (b"scale", b"1e999", "overflows"),
        (b"notes", b'"caf\\udcfc"', "lone surrogate U\\+DCFC"),
        (b"crs", b'{"a": 1}', "bad crs"),
    ],
)
def test_hostile_header_json_is_a_format_error(key, value, match, tmp_path):
    data = _seed(tmp_path)
    entry = _header_entry(data, key)
    new = (
        b"  1\n"
        + key
        + b"\n"
        + b"".join(b"  3\n" + value[k : k + 250] + b"\n" for k in range(0, len(value), 250))
    )
    (tmp_path / "bad.dxf").write_bytes(data.replace(entry, new))
    for fast in (True, False):
        with pytest.raises(FormatError, match=match) as exc:
            dxf.read(tmp_path / "bad.dxf", fast=fast)
        assert exc.value.path == str(tmp_path / "bad.dxf")


def _foreign_text_dxf(tmp_path, fmt: str) -> Path:
    import ezdxf

    doc = ezdxf.new("R2010")
    doc.modelspace().add_text("cafXY", dxfattribs={"insert": (1, 2, 3), "layer": "r"})
    doc.saveas(tmp_path / "t.dxf", fmt=fmt)
    data = (tmp_path / "t.dxf").read_bytes()
    assert data.count(b"cafXY") == 1
    (tmp_path / "t.dxf").write_bytes(data.replace(b"cafXY", b"caf\xfc\xfc"))
    return tmp_path / "t.dxf"


@pytest.mark.parametrize("fmt", ["asc", "bin"])
def test_undecodable_text_is_refused_not_carried_as_a_lone_surrogate(fmt, tmp_path):
    """ezdxf decodes bad UTF-8 with surrogateescape: such a text could never be written."""
    path = _foreign_text_dxf(tmp_path, fmt)
    with pytest.raises(FormatError, match="lone surrogate U\\+DCFC") as exc:
        apygis.read(path)
    assert exc.value.path == str(path)
    assert exc.value.reason.startswith("TEXT #")


@pytest.mark.parametrize("value", [b"1e308", b"-2e12", b"inf"])
def test_absurd_coordinates_are_refused(value, tmp_path):
    """1e308 is finite but overflows the KD-tree that joins line ends."""
    (tmp_path / "big.dxf").write_bytes(
        b"  0\nSECTION\n  2\nENTITIES\n  0\nLINE\n  8\nr\n 10\n" + value + b"\n 20\n0\n 30\n0\n"
        b" 11\n1\n 21\n0\n 31\n0\n  0\nENDSEC\n  0\nEOF\n"
    )
    with pytest.raises(FormatError, match="not finite or exceed 1e\\+12") as exc:
        apygis.read(tmp_path / "big.dxf")
    assert exc.value.reason.startswith("LINE #")


def test_symbol_codes_and_numbers_take_ascii_digits_only():
    assert dxf._symbol_code(None, "APY_SYM_07", 0) == 7
    assert dxf._symbol_code(None, "APY_SYM_\u0660\u0667", 3) == 3  # Arabic-Indic 07
    assert dxf._symbol_code("\u00b2", "x", 4) == 4
    assert dxf._int_or_none(" -12 ") == -12
    assert dxf._int_or_none("1_0") is None
    assert dxf._int_or_none("9" * 5000) is None


@pytest.mark.parametrize(("key", "value"), [(b"id", b'"FUZZ\\n"'), (b"layers", b'["r\\n", "e"]')])
def test_header_names_with_a_line_break_are_refused(key, value, tmp_path):
    data = _seed(tmp_path)
    new = b"  1\n" + key + b"\n  3\n" + value + b"\n"
    (tmp_path / "bad.dxf").write_bytes(data.replace(_header_entry(data, key), new))
    with pytest.raises(FormatError, match=r"holds a line break|1 to 3 letters|map ID is"):
        apygis.read(tmp_path / "bad.dxf")


def test_dxf_layer_name_with_a_line_break_is_not_a_layer_extension():
    from apygis.formats._layers import LayerNames

    names = LayerNames(None, ["r", "r\n"])
    assert names("r") == "r"
    assert names("r\n") == "x"


def test_fast_header_takes_ascii_group_codes_only(tmp_path):
    data = _seed(tmp_path)
    assert dxf._fast_header(data, "seed.dxf")["id"] == "FUZZ"
    k = data.index(b"  1\nversion\n")
    odd = data[:k] + "  \u0661\nversion\n".encode() + data[k + len(b"  1\nversion\n") :]
    assert dxf._fast_header(odd, "odd.dxf") is None  # int() would read '\u0661' as 1
    (tmp_path / "odd.dxf").write_bytes(odd)
    with pytest.raises(FormatError):
        apygis.read(tmp_path / "odd.dxf")


# --------------------------------------------------------------------------- the one rebuild

_SQUARE = [((0, 0), (10, 0)), ((10, 0), (10, 10)), ((10, 10), (0, 10)), ((0, 10), (0, 0))]


@pytest.mark.parametrize(
    ("order", "flips"),
    [
        ((0, 1, 2, 3), (0, 0, 0, 0)),
        ((0, 2, 1, 3), (0, 1, 0, 1)),
        ((3, 1, 0, 2), (1, 1, 1, 1)),
        ((2, 0, 3, 1), (1, 0, 0, 1)),
    ],
)
def test_four_cad_lines_of_a_square_convert_to_one_closed_line(tmp_path, order, flips):
    """Four DXF LINEs gave two lines with duplicate points and no closed line (AREA failed)."""
    import ezdxf
    from click.testing import CliRunner

    from apygis.cli import main

    doc = ezdxf.new()
    msp = doc.modelspace()
    for k, f in zip(order, flips, strict=True):
        a, b = _SQUARE[k][::-1] if f else _SQUARE[k]
        msp.add_line((*a, 400.0), (*b, 400.0))
    src, out = tmp_path / "square.dxf", tmp_path / "square.apa"
    doc.saveas(src)
    res = CliRunner().invoke(main, ["convert", str(src), str(out)], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    (lay,) = apygis.read(out).layers.values()
    assert lay.counts()["lines"] == 1
    assert lay.counts()["closed_lines"] == 1
    assert len(lay.line_points) == 4
    assert lay.validate() == []
    a, b = (int(v) for v in lay.line_points["num"][lay.chains().rows(0)][:2])
    assert abs(lay.area(a, b).area_m2) == pytest.approx(100.0)


def test_a_symbol_copied_in_cad_with_its_number_is_numbered_anew(tmp_path, caplog):
    import ezdxf

    m = apygis.MapFile("CP")
    lay = m.layer("s")
    lay.add_symbol(1.0, 2.0, 3.0, 7)
    lay.add_symbol(5.0, 6.0, 7.0, 8)
    src = tmp_path / "cp.dxf"
    apygis.write(m, src)
    doc = ezdxf.readfile(src)
    msp = doc.modelspace()
    first = next(e for e in msp if e.dxftype() == "INSERT")
    dup = first.copy()
    msp.add_entity(dup)
    dup.dxf.insert = (9.0, 9.0, 3.0)
    doc.saveas(src)
    with caplog.at_level("WARNING", logger="apygis.formats.dxf"):
        got = apygis.read(src).layers["s"]
    assert len(got.symbols) == 3
    assert sorted(got.symbols["num"].tolist()) == [1, 2, 3]
    assert got.validate() == []
    assert "numbered anew" in caplog.text


def test_an_apygis_line_copied_in_cad_is_read_as_a_new_line(tmp_path, caplog):
    """The copy repeats the original's point numbers in its XDATA: it is new geometry."""
    import ezdxf

    m = apygis.MapFile("CP")
    m.layer("s").add_line([(0, 0, 0), (5, 0, 0), (5, 5, 0)], code=3)
    src = tmp_path / "cp.dxf"
    apygis.write(m, src)
    doc = ezdxf.readfile(src)
    msp = doc.modelspace()
    pl = next(e for e in msp if e.dxftype() == "POLYLINE")
    dup = pl.copy()
    msp.add_entity(dup)
    dup.translate(20, 0, 0)
    doc.saveas(src)
    with caplog.at_level("WARNING", logger="apygis.formats.dxf"):
        got = apygis.read(src).layers["s"]
    assert got.counts()["lines"] == 2
    assert len(got.line_points) == 6
    assert got.validate() == []
    assert "copied in CAD" in caplog.text
