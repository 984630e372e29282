"""E00 coverages that ARC/INFO wrote: polygon coverages (PAT joined through the PAL, as
GDAL's AVCE00 driver does), point coverages, and the PRJ section's projections, each
compared with what GDAL reads from the same file."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest
from pyproj import CRS

import apygis
from apygis.errors import DriverError, FormatError
from tests.formats import e00_polygons as cov

pyogrio = pytest.importorskip("pyogrio")
shapely = pytest.importorskip("shapely")

LAMBERT = [
    "Projection    LAMBERT",
    "Datum         NAD83",
    "Units         METERS",
    "Spheroid      GRS1980",
    "Parameters",
    "  49  0  0.000",
    "  77  0  0.000",
    " -95  0  0.000",
    "  49  0  0.000",
    "0.0",
    "0.0",
]


def _gdal(path, layer):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta, _, geom, fields = pyogrio.raw.read(path, layer=layer)
    return meta, shapely.from_wkb(geom), dict(zip(meta["fields"], fields, strict=True))


def _write(tmp_path, prj=None, name="landuse.e00"):
    p = tmp_path / name
    p.write_bytes(cov.e00_text(prj))
    return p


def _closed_lines(lay):
    cs = lay.chains()
    lp = lay.line_points
    out = []
    for k in range(len(cs)):
        assert cs.closed[k]
        rows = cs.rows(k)
        out.append((shapely.Polygon(np.column_stack([lp["x"][rows], lp["y"][rows]])), lp[rows]))
    return out


def test_polygon_coverage_reads_as_gdal_reads_it(tmp_path):
    path = _write(tmp_path, LAMBERT)
    m = apygis.read(path)
    assert sorted(m.layers) == ["arc", "lab", "pal"]

    # polygons: one closed line per polygon but the outside one, on GDAL's outer ring,
    # with the code of its PAT record; AREA gives the area inside the outer ring
    _, polys, fields = _gdal(path, "PAL")
    assert len(polys) == 3  # polygon 1, the universe, is not a polygon of the map
    pal = m.layers["pal"]
    rings = _closed_lines(pal)
    assert len(rings) == len(polys)
    for g, code in zip(polys, fields["CODE"].tolist(), strict=True):
        outer = shapely.Polygon(g.exterior)
        match = [(r, lp) for r, lp in rings if r.equals(outer)]
        assert len(match) == 1, g.wkt
        _, lp = match[0]
        assert set(lp["code"].tolist()) == {code}
        area = pal.area(int(lp["num"][0]), int(lp["num"][1])).area_m2
        assert abs(area) == pytest.approx(outer.area)
    # the island of polygon 2 (GDAL's hole) is polygon 4, a closed line of its own
    assert sorted(round(r.area, 6) for r, _ in rings) == [4.0, 100.0, 100.0]

    # label points: joined to the PAT through their polygon IDs, as GDAL's LAB layer
    _, labs, lab_fields = _gdal(path, "LAB")
    sym = m.layers["lab"].symbols
    np.testing.assert_array_equal(
        np.column_stack([sym["x"], sym["y"]]), shapely.get_coordinates(labs)
    )
    assert sym["code"].tolist() == lab_fields["CODE"].tolist() == [23, 41, 35]
    assert sym["num"].tolist() == lab_fields["ValueId"].tolist()

    # arcs: GDAL's arcs, segment for segment
    _, arcs, _ = _gdal(path, "ARC")
    lay = m.layers["arc"]
    ours = set()
    for pl in apygis.model.polylines.export_lines(lay):
        xy = pl.coords[:, :2].tolist()
        ring = [*xy, xy[0]] if pl.closed else xy
        ours |= {tuple(sorted([tuple(a), tuple(b)])) for a, b in itertools.pairwise(ring)}
    for g in arcs:
        c = shapely.get_coordinates(g)
        for a, b in zip(c[:-1].tolist(), c[1:].tolist(), strict=True):
            assert tuple(sorted([tuple(a), tuple(b)])) in ours

    # the CRS: GDAL's translation of the PRJ section's LAMBERT
    meta, _, _ = _gdal(path, "ARC")
    assert m.crs.equals(CRS.from_user_input(meta["crs"]))
    assert "Lambert Conic Conformal" in m.crs.coordinate_operation.method_name


def test_source_layers_can_be_chosen_and_renamed(tmp_path):
    path = _write(tmp_path)
    m = apygis.read(path, layers=["pal"], layer_map="PAL=p")
    assert list(m.layers) == ["p"]
    assert m.layers["p"].counts()["closed_lines"] == 3
    with pytest.raises(DriverError, match=r"'CNT', which the file does not have .*ARC, LAB, PAL"):
        apygis.read(path, layer_map="CNT=c")
    with pytest.raises(DriverError, match="no layer 'TIC'"):
        apygis.read(path, layers=["TIC"])


def test_codes_outside_0_99_are_refused_or_take_the_default(tmp_path, monkeypatch):
    monkeypatch.setattr(cov, "CODES", [0, 2310, 41, 35])
    path = _write(tmp_path)
    with pytest.raises(FormatError, match=r"LANDUSE.PAT, record 2: CODE 2310 is not a code 0-99"):
        apygis.read(path)
    m = apygis.read(path, default_code=7)
    assert sorted(m.layers["lab"].symbols["code"].tolist()) == [7, 35, 41]
    assert any(w.kind == "recoded" and w.count == 1 for w in m.read_warnings)
    m = apygis.read(path, code_field="NOSUCH")
    assert set(m.layers["lab"].symbols["code"].tolist()) == {90}  # imported points
    assert set(m.layers["pal"].line_points["code"].tolist()) == {0}


def test_a_pat_that_fits_neither_polygons_nor_labels_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(cov, "PAL", cov.PAL[:3])  # a polygon less than the PAT has records
    path = _write(tmp_path)
    with pytest.raises(FormatError, match=r"LANDUSE\.PAT has 4 records for 3 polygons"):
        apygis.read(path)


@pytest.mark.parametrize(
    "prj",
    [
        LAMBERT,
        ["Projection    UTM", "Zone          13", "Datum         NAD27", "Units         METERS"],
        ["Projection    STATEPLANE", "Fipszone      406", "Datum         NAD83", "Units METERS"],
        ["Projection    STATEPLANE", "Zone          3301", "Datum         NAD83", "Units FEET"],
        ["Projection    ALBERS", "Datum         NAD83", "Units         METERS", "Parameters",
         "  29 30  0.000", "  45 30  0.000", " -96  0  0.000", "  23  0  0.000", "0.0", "0.0"],
        ["Projection    TRANSVERSE", "Datum NAD83", "Units METERS", "Parameters", "0.9996",
         "-123 0 0.0", "0 0 0.0", "500000", "0"],
        ["Projection    POLYCONIC", "Datum NAD27", "Units METERS", "Parameters", "-100 0 0.0",
         "40 0 0.0", "0", "0"],
        ["Projection    GEOGRAPHIC", "Datum WGS84", "Units DD"],
    ],
    ids=["lambert", "utm", "stateplane-fips", "stateplane-usgs", "albers", "tm", "polyconic",
         "geographic"],
)  # fmt: skip
def test_projections_are_translated_as_gdal_translates_them(tmp_path, prj):
    path = _write(tmp_path, prj)
    m = apygis.read(path)
    meta, _, _ = _gdal(path, "ARC")
    assert meta["crs"]
    assert m.crs is not None
    assert m.crs.equals(CRS.from_user_input(meta["crs"]))


def test_an_unknown_projection_is_said(tmp_path):
    path = _write(tmp_path, ["Projection    NONSENSE", "Units METERS"])
    m = apygis.read(path)
    assert m.crs is None
    (w,) = [w for w in m.read_warnings if w.kind == "crs"]
    assert "Projection NONSENSE" in w.message
    assert "not a projection GDAL knows" in w.message


def test_src_crs_replaces_the_prj(tmp_path):
    path = _write(tmp_path)
    assert apygis.read(path, crs="EPSG:2056").crs_string() == "EPSG:2056"
