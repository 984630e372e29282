"""The OGR drivers (GeoPackage, Shapefile, GeoJSON, FlatGeobuf): GDAL reads what they
write, maps round-trip record for record, foreign files import with rebuilt topology."""

from __future__ import annotations

import json
import os
import zipfile

import numpy as np
import pyogrio
import pyogrio.raw
import pytest
import shapely
from hypothesis import HealthCheck, given, settings

import apygis
from apygis.errors import ApygisError, DriverError, FormatError
from apygis.formats import driver_for, get_driver, ogr
from apygis.model.polylines import export_lines
from tests.formats.strategies import maps, small_map

FORMATS = ("gpkg", "shp", "geojson", "fgb")

# the foreign files written here leave out the CRS on purpose
pytestmark = pytest.mark.filterwarnings("ignore:'crs' was not provided")


def _target(tmp_path, name):
    """Where a whole map goes: a GeoPackage file, or a directory for the others."""
    return tmp_path / "out.gpkg" if name == "gpkg" else tmp_path / "out"


def _gdal_layers(written, name):
    """{OGR layer name: (dataset path, layer)} of what a writer produced, as GDAL lists it."""
    out = {}
    if name == "gpkg":
        (path,) = written
        for layer, _ in pyogrio.list_layers(path):
            out[str(layer)] = (path, str(layer))
        return out
    for p in written:
        if p.suffix in (".shp", ".geojson", ".fgb") or p.name.endswith("apygis_map.dbf"):
            out[p.stem.split("_", 1)[1]] = (p, None)
    return out


# --------------------------------------------------------------------------- GDAL reads it


@pytest.mark.parametrize("name", FORMATS)
def test_gdal_reads_every_writer(sample_map, tmp_path, name):
    written = apygis.write(sample_map, _target(tmp_path, name), driver=name)
    layers = _gdal_layers(written, name)
    expected = {"apygis_map"}
    for lay in sample_map:
        c = lay.counts()
        expected |= {f"{lay.ext}_symbols"} if c["symbols"] else set()
        expected |= {f"{lay.ext}_texts"} if c["texts"] else set()
        expected |= {f"{lay.ext}_line_points"} if c["line_points"] else set()
        expected |= {f"{lay.ext}_areas"} if c["closed_lines"] else set()
        expected |= {f"{lay.ext}_lines"} if c["lines"] > c["closed_lines"] else set()
    if name == "gpkg":
        expected.add("layer_styles")  # QGIS's styles (test_gpkg_styles.py)
    assert set(layers) == expected

    for lay in sample_map:
        for kind, table in (
            ("symbols", lay.symbols),
            ("texts", lay.texts),
            ("line_points", lay.line_points),
        ):
            if not len(table):
                continue
            path, layer = layers[f"{lay.ext}_{kind}"]
            info = pyogrio.read_info(path, layer=layer)
            assert info["features"] == len(table)
            assert info["geometry_type"] == "Point Z"
            assert info["crs"] == "EPSG:2056"
            meta, _, wkb, data = pyogrio.raw.read(path, layer=layer)
            cols = dict(zip(meta["fields"], data, strict=True))
            xyz = shapely.get_coordinates(shapely.from_wkb(wkb), include_z=True)
            np.testing.assert_array_equal(xyz[:, 0], table["x"])
            np.testing.assert_array_equal(xyz[:, 1], table["y"])
            np.testing.assert_array_equal(xyz[:, 2], table["z"])
            np.testing.assert_array_equal(cols["num"], table["num"])
            if kind == "symbols":
                assert cols["name"][0] == "trig point" if lay.ext == "c" else True
            if kind == "line_points":
                for ref in ("fwd", "back", "side1", "side2"):
                    np.testing.assert_array_equal(cols[ref], table[ref])
            if kind == "texts":
                assert list(cols["text"]) == list(table["text"])

    # the GIS lines: one feature per chain, branches reaching their junction
    lay = sample_map.layers["h"]
    ls = export_lines(lay)
    path, layer = layers["h_lines"]
    meta, _, wkb, data = pyogrio.raw.read(path, layer=layer)
    assert meta["geometry_type"] == "LineString Z"
    cols = dict(zip(meta["fields"], data, strict=True))
    opened = np.flatnonzero(~ls.closed)
    assert len(wkb) == len(opened)
    for k, g, pts, npts in zip(opened, wkb, cols["points"], cols["npoints"], strict=True):
        line = ls[int(k)]
        np.testing.assert_array_equal(
            shapely.get_coordinates(shapely.from_wkb(g), include_z=True), line.coords
        )
        if name != "shp":
            assert pts == ",".join(map(str, line.nums))
        assert npts == len(line.nums)
    path, layer = layers["r_areas"]
    meta, _, wkb, data = pyogrio.raw.read(path, layer=layer)
    assert meta["geometry_type"] in ("Polygon Z", "MultiPolygon Z")  # Shapefile: no Polygon
    areas = shapely.from_wkb(wkb)
    assert len(areas) == sample_map.layers["r"].counts()["closed_lines"]
    assert shapely.is_valid(areas).all()

    path, layer = layers["apygis_map"]
    meta, _, wkb, data = pyogrio.raw.read(path, layer=layer)
    cols = dict(zip(meta["fields"], data, strict=True))
    assert cols["id"][0] == "ZH1091"
    assert cols["scale"][0] == 5000
    assert cols["crs"][0] == "EPSG:2056"
    assert cols["layers"][0] == "c,e,h,r"


def test_geojson_names_its_crs(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path / "gj", driver="geojson")
    doc = json.loads((tmp_path / "gj" / "ZH1091_r_line_points.geojson").read_text())
    # RFC 7946 says WGS 84; GDAL writes the old-style crs member for any other CRS
    assert doc["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::2056"
    assert pyogrio.read_info(tmp_path / "gj" / "ZH1091_r_line_points.geojson")["crs"] == "EPSG:2056"


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("name", FORMATS)
def test_sample_round_trip_is_exact(sample_map, tmp_path, name):
    target = _target(tmp_path, name)
    written = apygis.write(sample_map, target, driver=name)
    assert sorted(written) == sorted(get_driver(name).targets(sample_map, target))
    assert not [p for p in tmp_path.rglob("*") if ".apygis-" in p.name]  # no temp left
    back = apygis.read(target, driver=name)
    assert back == sample_map
    assert back.crs_string() == "EPSG:2056"
    assert back.notes == sample_map.notes
    for ext, lay in sample_map.layers.items():
        assert back.layers[ext].line_points.tolist() == lay.line_points.tolist()


@pytest.mark.parametrize("name", FORMATS)
def test_every_float64_comes_back_bit_for_bit(tmp_path, name):
    rng = np.random.default_rng(1)
    m = apygis.MapFile("P", crs="EPSG:4326")
    lay = m.layer("r")
    for k in range(20):
        lay.add_symbol(*rng.uniform(-180, 180, 2), rng.normal() * 1e-7, k)
    lay.add_symbol(1e-300, -987654321098.7654, 5e-324, 1)  # readers refuse |x| > 1e12
    lay.add_line(rng.uniform(0, 1, (10, 3)), code=5)
    lay.add_text(1 / 3, 2 / 3, 123456.789012345678, "  blanks around ")
    target = _target(tmp_path, name)
    apygis.write(m, target, driver=name)
    back = apygis.read(target, driver=name)
    for table in ("symbols", "line_points"):
        assert back.layers["r"].table(table).tobytes() == lay.table(table).tobytes()
    # a DBF keeps no leading or trailing blanks
    want = "blanks around" if name == "shp" else "  blanks around "
    assert back.layers["r"].texts["text"].tolist() == [want]


@pytest.mark.parametrize("name", ["shp", "geojson", "fgb"])
def test_named_set_and_stale_files(sample_map, tmp_path, name):
    ext = "geojson" if name == "geojson" else name
    target = tmp_path / f"SHEET.{ext}"
    written = apygis.write(sample_map, target, driver=name)
    assert all(p.name.startswith("SHEET_") for p in written)
    assert driver_for(target, "r").name == name  # no such file: the set SHEET_*.ext
    assert apygis.read(target) == sample_map
    assert driver_for(tmp_path, "r").name == name  # the directory
    assert apygis.read(tmp_path, driver=name) == sample_map
    # one existing file: that OGR layer alone
    one = apygis.read(tmp_path / f"SHEET_r_line_points.{ext}")
    assert one.id == "SHEET"
    assert list(one.layers) == ["r"]
    assert one.layers["r"].line_points.tolist() == sample_map.layers["r"].line_points.tolist()
    # a smaller map replaces the set: files of layers it no longer has are removed
    smaller = sample_map.copy()
    del smaller.layers["h"], smaller.layers["c"]
    smaller.crs = None
    written = apygis.write(smaller, target, driver=name)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted([".SHEET.apyset", *(p.name for p in written)])  # + the set stamp
    assert not any(n.endswith(".prj") for n in left)
    assert apygis.read(target) == smaller


def test_gpkg_layers_header_and_empty_layers(tmp_path):
    m = apygis.MapFile("EMPTY-1", scale=None, crs=None, notes="")
    m.layer("q")
    m.layer("r").add_symbol(1.0, 2.0, 3.0, 5)
    apygis.write(m, tmp_path / "e.gpkg")
    assert sorted(str(n) for n, _ in pyogrio.list_layers(tmp_path / "e.gpkg")) == [
        "apygis_map",
        "layer_styles",
        "r_symbols",
    ]
    back = apygis.read(tmp_path / "e.gpkg")
    assert back == m
    assert back.scale is None
    assert back.crs is None
    assert list(back.layers) == ["q", "r"]


def test_shapefile_long_header_fields(tmp_path):
    m = small_map()
    m.notes = ("line one   \n" + "word " * 100 + "é" * 70 + "  end").strip()
    m.crs = "+proj=tmerc +lat_0=0 +lon_0=9 +k=1 +x_0=500000 +y_0=0 +ellps=GRS80 +units=m"
    assert len(m.crs_string()) > 254  # WKT: continued over several rows of the DBF
    apygis.write(m, tmp_path, driver="shp")
    back = apygis.read(tmp_path, driver="shp")
    assert back == m


def test_write_atomic_and_targets(sample_map, tmp_path):
    target = tmp_path / "a.gpkg"
    target.write_bytes(b"old")
    apygis.write(sample_map, target)
    assert apygis.read(target) == sample_map
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.gpkg"]
    with pytest.raises(DriverError, match="is a directory"):
        apygis.write(sample_map, tmp_path, driver="gpkg")
    (tmp_path / "file").write_text("x")
    with pytest.raises(DriverError, match="is a file"):
        apygis.write(sample_map, tmp_path / "file", driver="shp")
    assert ogr.outputs(sample_map, tmp_path / "o", "shp")[0].name == "ZH1091_apygis_map.dbf"
    assert driver_for(tmp_path / "x.gpkg", "w").name == "gpkg"
    assert driver_for(tmp_path / "x.fgb", "w").name == "fgb"
    assert driver_for(tmp_path / "x.json", "w").name == "geojson"


def test_gpkg_without_spatial_index(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path / "i.gpkg", spatial_index=False)
    assert apygis.read(tmp_path / "i.gpkg") == sample_map
    meta = pyogrio.read_info(tmp_path / "i.gpkg", layer="r_line_points")
    assert not meta["capabilities"]["fast_spatial_filter"]
    apygis.write(sample_map, tmp_path / "j.gpkg")
    meta = pyogrio.read_info(tmp_path / "j.gpkg", layer="r_line_points")
    assert meta["capabilities"]["fast_spatial_filter"]


def test_progress_is_reported(sample_map, tmp_path):
    calls = []
    apygis.write(sample_map, tmp_path / "p.gpkg", progress=lambda d, t: calls.append((d, t)))
    assert calls[-1][0] == calls[-1][1] == len(calls)
    calls.clear()
    apygis.read(tmp_path / "p.gpkg", progress=lambda d, t: calls.append((d, t)))
    layers = [str(n) for n, _ in pyogrio.list_layers(tmp_path / "p.gpkg")]
    layers.remove("layer_styles")  # no geometry, no map layer: not read
    # every layer is read: L_lines and L_areas are checked against L_line_points for edits
    assert calls[-1][0] == calls[-1][1] == len(layers) == len(calls)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(m=maps())
def test_property_round_trip_gpkg(m, tmp_path_factory):
    d = tmp_path_factory.mktemp("rt")
    apygis.write(m, d / "m.gpkg")
    assert apygis.read(d / "m.gpkg") == m


# --------------------------------------------------------------------------- foreign files


def _foreign_gpkg(path):
    """A GeoPackage written by pyogrio alone: roads as loose pieces, a pond, trees, names."""
    square = [  # four pieces of one closed road, end to start
        [(0, 0), (10, 0)],
        [(10, 0), (10, 10)],
        [(10, 10), (5, 10), (0, 10)],
        [(0, 10), (0, 0)],
    ]
    spur = [(5, 20), (5, 10.001)]  # ends 1 mm from a vertex: a branch of the square
    lines = np.array([shapely.LineString(c) for c in [*square, spur]], dtype=object)
    pyogrio.raw.write(
        path,
        shapely.to_wkb(lines),
        [np.array([12, 12, 12, 12, 13], np.int32)],
        ["code"],
        layer="roads",
        driver="GPKG",
        geometry_type="LineString",
        crs="EPSG:2056",
    )
    pond = shapely.polygons(
        [(100, 100, 5), (130, 100, 5), (130, 120, 5), (100, 120, 5)],
        holes=[[(110, 105, 5), (115, 105, 5), (115, 110, 5)]],
    )
    pyogrio.raw.write(
        path,
        shapely.to_wkb(np.array([pond])),
        [],
        [],
        layer="water",
        driver="GPKG",
        geometry_type="Polygon Z",
        crs="EPSG:2056",
    )
    trees = shapely.points([(1, 1, 400), (2, 2, 401)])
    pyogrio.raw.write(
        path,
        shapely.to_wkb(trees),
        [np.array([23, None], dtype=object)],
        ["code"],
        layer="trees",
        driver="GPKG",
        geometry_type="Point Z",
        crs="EPSG:2056",
    )
    pyogrio.raw.write(
        path,
        shapely.to_wkb(shapely.points([(3, 3)])),
        [np.array(["Dorfplatz"], dtype=object)],
        ["text"],
        layer="names",
        driver="GPKG",
        geometry_type="Point",
        crs="EPSG:2056",
    )


def test_foreign_gpkg_imports_with_rebuilt_topology(tmp_path):
    path = tmp_path / "foreign.gpkg"
    _foreign_gpkg(path)
    m = apygis.read(path, layer_map="roads=r, water=h", default_code=7)
    assert m.id == "foreign"
    assert m.crs_string() == "EPSG:2056"
    assert m.scale is None
    # one map layer per OGR layer, named from it: trees -> tre, names -> nam
    assert sorted(m.layers) == ["h", "nam", "r", "tre"]
    roads = m.layers["r"]
    assert roads.counts()["closed_lines"] == 1
    assert roads.counts()["lines"] == 2
    assert not roads.validate()
    ring = next(iter(roads.chains()))
    nums = roads.line_points["num"][ring]
    area = roads.area(int(nums[0]), int(nums[1]))
    assert area.area_m2 == pytest.approx(100.0)
    assert area.perimeter_m == pytest.approx(40.0)
    (branch,) = roads.branches()
    junction = roads.line_points[roads.line_points["num"] == branch["junction"]][0]
    assert (junction["x"], junction["y"]) == (5.0, 10.0)
    codes = sorted(set(roads.line_points["code"].tolist()))
    assert codes == [12, 13]
    assert (roads.line_points["z"] == 0).all()  # no Z in the file: 0
    pond = m.layers["h"]
    assert pond.counts()["closed_lines"] == 2  # the shore and the island
    assert (pond.line_points["code"] == 7).all()  # no code field: the default
    trees = m.layers["tre"].symbols
    assert trees["code"].tolist() == [23, 7]
    assert trees["z"].tolist() == [400, 401]
    names = m.layers["nam"].texts
    assert names["text"].tolist() == ["Dorfplatz"]
    assert names["num"].tolist() == [1]


def test_foreign_lines_of_our_own_are_rebuilt_without_line_points(sample_map, tmp_path):
    """A GeoPackage without its L_line_points layers: lines come from L_lines and L_areas."""
    full = tmp_path / "full.gpkg"
    apygis.write(sample_map, full)
    cut = tmp_path / "cut.gpkg"
    for name, _ in pyogrio.list_layers(full):
        if str(name).endswith("_line_points"):
            continue
        meta, _, wkb, data = pyogrio.raw.read(full, layer=str(name))
        pyogrio.raw.write(
            cut,
            wkb,
            data,
            list(meta["fields"]),
            layer=str(name),
            driver="GPKG",
            geometry_type=meta["geometry_type"],
            crs=meta["crs"],
        )
    back = apygis.read(cut)
    for ext, lay in sample_map.layers.items():
        got = back.layers[ext]
        assert got.symbols.tolist() == lay.symbols.tolist()
        want = lay.counts()
        assert got.counts() == want
        assert len(got.branches()) == len(lay.branches())
        assert sorted(got.line_points["x"].tolist()) == sorted(lay.line_points["x"].tolist())


def test_foreign_shapefile_zip_and_geojson(tmp_path):
    pts = shapely.to_wkb(shapely.points([(2600000.0, 1200000.0), (2600001.0, 1200001.0)]))
    d = tmp_path / "in"
    d.mkdir()
    pyogrio.raw.write(
        d / "wells.shp",
        pts,
        [np.array([26, 27], np.int32)],
        ["code"],
        driver="ESRI Shapefile",
        geometry_type="Point",
        crs="EPSG:2056",
    )
    m = apygis.read(d / "wells.shp")
    assert m.id == "wells"
    assert m.layers["wel"].symbols["code"].tolist() == [26, 27]  # layer wells: map layer wel
    with zipfile.ZipFile(tmp_path / "wells.shz", "w") as z:
        for p in d.iterdir():
            z.write(p, p.name)
    assert driver_for(tmp_path / "wells.shz", "r").name == "shp"
    assert apygis.read(tmp_path / "wells.shz") == m
    gj = tmp_path / "w.json"
    pyogrio.raw.write(gj, pts, [], [], driver="GeoJSON", geometry_type="Point")
    m = apygis.read(gj)  # no crs member: RFC 7946's WGS 84
    assert m.crs_string() == "EPSG:4326"
    (lay,) = m.layers.values()  # the layer w: map layer w
    assert lay.ext == "w"
    # 2-D points without a code field: imported points (90), not spot heights
    assert lay.symbols["code"].tolist() == [90, 90]


# --------------------------------------------------------------------------- errors


def test_bad_input_raises_format_errors(tmp_path, sample_map):
    with pytest.raises(FormatError, match=r"missing\.gpkg: no such file"):
        apygis.read(tmp_path / "missing.gpkg", driver="gpkg")
    junk = tmp_path / "junk.gpkg"
    junk.write_bytes(b"not a database at all" * 10)
    with pytest.raises(FormatError, match=r"junk\.gpkg: not a readable GIS file"):
        apygis.read(junk, driver="gpkg")
    with pytest.raises(FormatError, match=r"nothing.shp: no such file, nor files nothing_\*.shp"):
        apygis.read(tmp_path / "nothing.shp", driver="shp")
    shx = tmp_path / "lone"
    shx.mkdir()
    apygis.write(small_map(), shx, driver="shp")
    (shx / "FUZZ_r_line_points.shx").unlink()
    (shx / ".FUZZ.apyset").unlink()  # no set stamp: the reader's own error
    with pytest.raises(FormatError, match=r"FUZZ_r_line_points.shp: not a readable GIS file"):
        apygis.read(shx, driver="shp")

    # a layer named like ours but without our fields
    bad = tmp_path / "bad.gpkg"
    pyogrio.raw.write(
        bad,
        shapely.to_wkb(shapely.points([(0, 0, 0)])),
        [np.array([1]), np.array([3])],
        ["num", "code"],
        layer="r_line_points",
        driver="GPKG",
        geometry_type="Point Z",
    )
    with pytest.raises(FormatError, match=r"bad.gpkg: layer r_line_points: field fwd is missing"):
        apygis.read(bad)
    bad = tmp_path / "bad2.gpkg"
    pyogrio.raw.write(
        bad,
        shapely.to_wkb(shapely.points([(0, 0, 0)])),
        [np.array([1]), np.array([300])],
        ["num", "code"],
        layer="r_symbols",
        driver="GPKG",
        geometry_type="Point Z",
    )
    with pytest.raises(FormatError, match=r"layer r_symbols: feature 1: code 300 is outside 0-99"):
        apygis.read(bad)

    two = tmp_path / "two"
    apygis.write(sample_map, two / "A.fgb")
    apygis.write(sample_map, two / "B.fgb")
    with pytest.raises(FormatError, match=r"several maps \(A, B\)"):
        apygis.read(two, driver="fgb")
    assert apygis.read(two / "B.fgb") == sample_map

    with pytest.raises(DriverError, match="layer map"):
        apygis.read(junk, driver="gpkg", layer_map="roads")
    with pytest.raises(DriverError, match="default_code"):
        apygis.read(junk, driver="gpkg", default_code=100)


def test_header_errors(tmp_path):
    path = tmp_path / "h.gpkg"
    pyogrio.raw.write(
        path,
        None,
        [np.array([2]), np.array(["ok"], dtype=object)],
        ["apygis", "id"],
        layer="apygis_map",
        driver="GPKG",
    )
    with pytest.raises(FormatError, match="schema version 2"):
        apygis.read(path)
    pyogrio.raw.write(
        path,
        None,
        [np.array([1]), np.array(["not valid!"], dtype=object)],
        ["apygis", "id"],
        layer="apygis_map",
        driver="GPKG",
    )
    with pytest.raises(FormatError, match="map header: a map ID"):
        apygis.read(path)
    pyogrio.raw.write(
        path,
        None,
        [np.array([1]), np.array(["ok"], dtype=object), np.array(["EPSG:nope"], dtype=object)],
        ["apygis", "id", "crs"],
        layer="apygis_map",
        driver="GPKG",
    )
    with pytest.raises(FormatError, match="not a coordinate reference system"):
        apygis.read(path)


def test_errors_are_apygis_errors_for_truncated_files(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path / "t.gpkg")
    data = (tmp_path / "t.gpkg").read_bytes()
    for cut in (0, 50, 100, 4096, len(data) // 2):
        p = tmp_path / f"cut{cut}.gpkg"
        p.write_bytes(data[:cut])
        with pytest.raises(ApygisError):
            apygis.read(p, driver="gpkg")
    assert os.path.exists(tmp_path / "t.gpkg")


def test_a_flatgeobuf_claiming_more_features_than_bytes_is_refused():
    """Its header said two billion features in 2 KB: GDAL allocated 23 GB for it."""
    from tests.conftest import ROOT

    path = ROOT / "tests" / "fuzz_corpus" / "fgb" / "hostile-count-2e9-features.fgb"
    with pytest.raises(FormatError, match="claims 1946157058 features, but the file has only"):
        apygis.read(path)


def test_foreign_coordinates_beyond_any_ground_are_refused(tmp_path):
    path = tmp_path / "far.geojson"
    path.write_text(
        '{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {}, '
        '"geometry": {"type": "LineString", "coordinates": [[0, 0], [1e300, 5]]}}]}'
    )
    with pytest.raises(FormatError, match="feature 1: coordinates are not finite or exceed"):
        apygis.read(path)


@pytest.mark.parametrize(("driver", "ext"), [("GPKG", "gpkg"), ("FlatGeobuf", "fgb")])
def test_surfaces_are_refused_as_such(tmp_path, driver, ext):
    """A TIN (what GDAL gives for a multipatch) is refused saying what it is, not with
    shapely's "ParseException: Unknown WKB type 16"."""
    import struct

    ring = struct.pack("<I", 4) + b"".join(
        struct.pack("<3d", *p) for p in [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 0)]
    )
    tri = struct.pack("<BII", 1, 1017, 1) + ring
    tin = struct.pack("<BII", 1, 1016, 1) + tri
    line = shapely.to_wkb(shapely.LineString([(0, 0, 0), (1, 1, 0)]), flavor="iso")
    path = tmp_path / f"tin.{ext}"
    pyogrio.raw.write(
        path,
        np.array([line, tin], dtype=object),
        [np.array([1, 2])],
        ["id"],
        driver=driver,
        geometry_type="Unknown",
        crs="EPSG:2056",
    )
    with pytest.raises(FormatError, match=r"feature 2: a TIN .*surfaces are not supported") as exc:
        apygis.read(path)
    assert "ParseException" not in str(exc.value)
    assert "WKB type" not in str(exc.value)
