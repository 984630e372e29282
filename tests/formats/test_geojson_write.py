"""GeoJSON as GDAL and RFC 7946 want it: strict RFC 7946 in EPSG:4326, a CRS without an
EPSG code kept, a map without CRS not taken for WGS 84, every float64 back bit for bit."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import shapely
from pyproj import CRS

import apygis
from apygis.model.reproject import reproject

pyogrio = pytest.importorskip("pyogrio")

BC_ALBERS_LIKE = (  # an Albers of its own: no EPSG code
    "+proj=aea +lat_1=50 +lat_2=58.5 +lat_0=45 +lon_0=-126.5 +x_0=1000000 +y_0=0 "
    "+datum=NAD83 +units=m +no_defs"
)


def _rfc7946_problems(doc: dict) -> list[str]:
    """What in a parsed GeoJSON text breaks RFC 7946 (sections 3, 3.1.6, 4)."""
    bad = []
    if doc.get("type") != "FeatureCollection" or not isinstance(doc.get("features"), list):
        bad.append("not a FeatureCollection with a features array")
    if "crs" in doc:
        bad.append("a crs member (RFC 7946 section 4: WGS 84 only, no crs)")

    def position(p, where):
        if not (
            isinstance(p, list) and 2 <= len(p) <= 3 and all(isinstance(v, float | int) for v in p)
        ):
            bad.append(f"{where}: position {p!r}")
        elif not (-180 <= p[0] <= 180 and -90 <= p[1] <= 90):
            bad.append(f"{where}: {p[:2]} is not longitude, latitude")

    for k, f in enumerate(doc.get("features", [])):
        where = f"feature {k}"
        if f.get("type") != "Feature" or "properties" not in f or "geometry" not in f:
            bad.append(f"{where}: not a Feature with properties and geometry")
            continue
        g = f["geometry"]
        if g is None:
            continue
        t, c = g.get("type"), g.get("coordinates")
        if t == "Point":
            position(c, where)
        elif t == "LineString":
            if len(c) < 2:
                bad.append(f"{where}: a LineString of {len(c)} positions")
            for p in c:
                position(p, where)
        elif t == "Polygon":
            for i, ring in enumerate(c):
                for p in ring:
                    position(p, where)
                if len(ring) < 4 or ring[0] != ring[-1]:
                    bad.append(f"{where}: ring {i} not closed or shorter than 4")
                ccw = shapely.is_ccw(shapely.LinearRing([p[:2] for p in ring]))
                if ccw != (i == 0):  # section 3.1.6: exterior counter-clockwise, holes clockwise
                    bad.append(f"{where}: ring {i} turns the wrong way")
        else:
            bad.append(f"{where}: geometry type {t}")
    return bad


def _files(folder):
    return sorted(folder.glob("*.geojson"))


def _gdal_crs(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return pyogrio.read_info(path)["crs"]


def test_epsg_4326_is_written_as_rfc_7946(sample_map, tmp_path):
    wgs = reproject(sample_map, "EPSG:4326")
    out = tmp_path / "wgs"
    apygis.write(wgs, out, driver="geojson")
    files = _files(out)
    assert any(f.name.endswith("_areas.geojson") for f in files)  # closed lines: polygons
    for f in files:
        doc = json.loads(f.read_text(encoding="utf-8"))
        assert _rfc7946_problems(doc) == [], f.name
        if not f.name.endswith("apygis_map.geojson"):  # WGS 84 (with heights: 3-D)
            assert _gdal_crs(f) in ("EPSG:4326", "EPSG:4979")
    assert apygis.read(out) == wgs  # every coordinate back bit for bit


def test_rfc_7946_turns_clockwise_rings(tmp_path):
    m = apygis.MapFile("CW", crs="EPSG:4326")
    m.layer("h").add_line(
        [(8.0, 47.0, 0), (8.0, 47.1, 0), (8.1, 47.1, 0), (8.1, 47.0, 0)], 35, True
    )
    apygis.write(m, tmp_path / "cw", driver="geojson")
    (areas,) = (tmp_path / "cw").glob("*_areas.geojson")
    assert _rfc7946_problems(json.loads(areas.read_text())) == []
    assert apygis.read(tmp_path / "cw") == m  # the line points keep their own order


def test_a_crs_without_an_epsg_code_is_kept(tmp_path):
    m = apygis.MapFile("ALB", crs=BC_ALBERS_LIKE)
    assert m.crs.to_epsg() is None
    m.layer("r").add_line([(1000000.5, 500000.25, 12.0), (1000010.0, 500020.0, 13.5)], 3)
    apygis.write(m, tmp_path / "alb", driver="geojson")
    (lines,) = (tmp_path / "alb").glob("*_r_lines.geojson")
    assert CRS.from_user_input(_gdal_crs(lines)).equals(m.crs)  # GDAL (and QGIS) see it
    back = apygis.read(lines)  # one file alone: the CRS from the file, not the header
    assert back.crs.equals(m.crs)


def test_a_map_without_crs_is_not_read_as_wgs84(tmp_path):
    m = apygis.MapFile("LOCAL")
    m.layer("r").add_symbol(1000.0, 2000.0, 3.0, 5)
    apygis.write(m, tmp_path / "loc", driver="geojson")
    (sym,) = (tmp_path / "loc").glob("*_r_symbols.geojson")
    got = _gdal_crs(sym)
    assert got is not None
    assert "4326" not in got
    assert "WGS" not in got.upper()
    assert apygis.read(sym).crs is None
    assert apygis.read(tmp_path / "loc") == m


def test_every_float_comes_back_bit_for_bit(tmp_path):
    """GDAL's own writer gives 0.3 for 0.1 + 0.2, even with 17 significant figures."""
    x = 0.1 + 0.2
    m = apygis.MapFile("BITS", crs="EPSG:2056")
    pts = [(2683000.0 + x, 1247000.0 + 1 / 3, 431.2 + x), (2683000.1, 1247000.7, np.pi)]
    m.layer("r").add_line(pts, 12)
    m.layer("r").add_symbol(2683001.0 + 2 / 3, 1247001.0 + x, 1e-7 + x, 6)
    apygis.write(m, tmp_path / "bits", driver="geojson")
    assert apygis.read(tmp_path / "bits") == m
    (lp,) = (tmp_path / "bits").glob("*_r_line_points.geojson")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, _, wkb, _ = pyogrio.raw.read(lp)
    got = shapely.get_coordinates(shapely.from_wkb(wkb), include_z=True)
    assert got.tolist() == [list(p) for p in pts]  # GDAL reads them exactly too
