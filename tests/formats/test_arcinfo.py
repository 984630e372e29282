"""ARC/INFO GENERATE driver: GDAL's sample files, round trips, what GDAL reads back, bad input.

GDAL's ARCGEN driver was deprecated in GDAL 3.5 and is not built into the
GDAL that pyogrio bundles. The comparisons with GDAL therefore run in two ways:

* against the geometries that GDAL's ARCGEN driver returns for the six sample
  files (``autotest/ogr/ogr_arcgen.py`` checks the first feature of each; the
  full lists below were read with GDAL 3.4.1's ARCGEN driver), and against
  pyogrio itself when its GDAL has the driver;
* for files apygis writes, through :func:`gdal_arcgen_read`, a transcription
  of the ARCGEN driver's open test and reader (``ograrcgendatasource.cpp``,
  ``ograrcgenlayer.cpp``): the first line must have 1, 3 or 4 numeric
  fields, the last 10 bytes hold one ``END`` (points) or two (lines), the
  layer is a polygon layer when the first feature's first and last vertex
  are the same text, and a vertex line with 3 fields makes it 2.5-D.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import apygis
from apygis.errors import DriverError, FormatError
from apygis.formats import arcinfo, driver_for
from apygis.model.polylines import export_lines
from tests.conftest import EXTERNAL

GDAL_DIR = EXTERNAL / "gdal"

# What GDAL's ARCGEN driver reads from the six sample files: (ID, coordinates) per feature.
GDAL_GEN = {
    "points.gen": ("Point", [(1, [(2, 49)]), (2, [(3, 50)])]),
    "points25d.gen": ("Point25D", [(1, [(2, 49, 10)]), (2, [(3, 50, 20)])]),
    "lines.gen": ("LineString", [(1, [(2, 49), (3, 50)]), (2, [(3, 50), (2, 49)])]),
    "lines25d.gen": (
        "LineString25D",
        [(1, [(2, 49, 10), (3, 50, 10)]), (2, [(3, 50, 20), (2, 49, 20)])],
    ),
    "polygons.gen": (
        "Polygon",
        [(k, [(2, 49), (2, 50), (3, 50), (3, 49), (2, 49)]) for k in (1, 2)],
    ),
    "polygons25d.gen": (
        "Polygon25D",
        [
            (k, [(2, 49, z), (2, 50, z), (3, 50, z), (3, 49, z), (2, 49, z)])
            for k, z in ((1, 10), (2, 20))
        ],
    ),
}


# --------------------------------------------------------------------------- GDAL's reader


def gdal_arcgen_read(path):
    """Read a GENERATE file the way GDAL's ARCGEN driver does: ``(geometry type, features)``.

    Returns None where the driver would not open the file. Features are
    ``(ID, [coordinate tuples])``; a polygon's ring repeats its first vertex.
    """
    with open(path, "rb") as fh:
        data = fh.read()
    first = data[:256]
    eol = [k for k in (first.find(b"\n"), first.find(b"\r")) if k >= 0]
    if not eol or any(c < 32 for c in first[: min(eol)]):
        return None
    toks = first[: min(eol)].replace(b",", b" ").split()
    if len(toks) not in (1, 3, 4):
        return None
    try:
        [float(t) for t in toks]
    except ValueError:
        return None
    if len(data) < 10:
        return None
    tail = data[-10:]
    lines = [ln.strip(b"\r") for ln in data.split(b"\n")]
    k = tail.upper().find(b"END")
    if k < 0:
        return None
    if tail.upper().find(b"END", k + 3) < 0:  # one END: points
        n = len(lines[0].replace(b",", b" ").split())
        gtype = {3: "Point", 4: "Point25D"}.get(n)
        if gtype is None:
            return None
        feats = []
        for ln in lines:
            if ln.upper() == b"END":
                break
            t = ln.replace(b",", b" ").split()
            if len(t) in (3, 4):
                feats.append((int(t[0]), [tuple(float(v) for v in t[1:])]))
        return gtype, feats
    # two ENDs: lines or polygons, decided by the first feature
    first_xy = last_xy = None
    is3d = False
    for n, ln in enumerate(lines[1:], start=2):
        t = ln.replace(b",", b" ").split()
        if n == 2:
            if len(t) not in (2, 3):
                return None
            is3d = len(t) == 3
            first_xy = t[:2]
        elif ln.upper() == b"END":
            break
        elif len(t) in (2, 3):
            last_xy = t[:2]
        else:
            return None
    base = "Polygon" if first_xy == last_xy else "LineString"
    gtype = base + ("25D" if is3d else "")
    feats, fid, pts = [], None, []
    for ln in lines:
        if ln.upper() == b"END":
            if fid is None:
                break
            feats.append((int(fid), pts))
            fid, pts = None, []
            continue
        t = ln.replace(b",", b" ").split()
        if fid is None:
            if not t:
                break
            fid = t[0]
        elif len(t) in (2, 3):
            pts.append(tuple(float(v) for v in t))
        else:
            break
    return gtype, feats


def _pyogrio_has_arcgen() -> bool:
    import pyogrio

    return "ARCGEN" in pyogrio.list_drivers()


def _pyogrio_features(path):
    """(geometry type, [(ID, coordinates)]) through pyogrio, rings as closed coordinate lists."""
    import shapely
    from pyogrio.raw import read

    meta, _, geom, fields = read(path)
    out = []
    for fid, g in zip(fields[0], shapely.from_wkb(geom), strict=True):
        ring = g.exterior if g.geom_type == "Polygon" else g
        out.append((int(fid), [tuple(c) for c in shapely.get_coordinates(ring, include_z=g.has_z)]))
    return meta["geometry_type"], out


# --------------------------------------------------------------------------- helpers


def polylines(layer):
    """Each chain of a layer as ``(closed, vertices)``, in a canonical order."""
    ls = export_lines(layer)
    return sorted((bool(pl.closed), tuple(map(tuple, pl.coords.tolist()))) for pl in ls)


def feature_coords(layer):
    """The drawn lines of a layer as GDAL features list them (rings closed explicitly)."""
    out = []
    for pl in export_lines(layer):
        c = [tuple(v) for v in pl.coords.tolist()]
        out.append([*c, c[0]] if pl.closed else c)
    return out


# --------------------------------------------------------------------------- GDAL's sample files


@pytest.mark.external
@pytest.mark.parametrize("name", sorted(GDAL_GEN))
def test_gdal_sample_files_read_as_gdal_reads_them(name):
    gtype, expected = GDAL_GEN[name]
    path = GDAL_DIR / name
    assert gdal_arcgen_read(path) == (
        gtype,
        [(i, [tuple(float(v) for v in c) for c in cs]) for i, cs in expected],
    )
    if _pyogrio_has_arcgen():  # the real driver, where pyogrio's GDAL has it
        assert _pyogrio_features(path)[1] == [
            (i, [tuple(float(v) for v in c) for c in cs]) for i, cs in expected
        ]
    m = apygis.read(path)
    assert list(m.layers) == [arcinfo.DEFAULT_LAYER]
    lay = m.layers[arcinfo.DEFAULT_LAYER]
    dims = len(expected[0][1][0])
    if gtype.startswith("Point"):
        assert lay.counts()["line_points"] == 0
        assert lay.symbols["num"].tolist() == [i for i, _ in expected]
        got = np.column_stack([lay.symbols["x"], lay.symbols["y"], lay.symbols["z"]])
        want = np.array([cs[0] + (0,) * (3 - dims) for _, cs in expected], float)
        np.testing.assert_array_equal(got, want)
        return
    assert lay.counts()["symbols"] == 0
    cs = lay.chains()
    assert len(cs) == len(expected)
    assert cs.closed.tolist() == [gtype.startswith("Polygon")] * len(expected)
    want = sorted([tuple(c + (0,) * (3 - dims)) for c in coords] for _, coords in expected)
    got = sorted(feature_coords(lay))
    assert got == [[tuple(float(v) for v in c) for c in w] for w in want]


@pytest.mark.external
def test_gdal_sample_files_rebuild_topology():
    m = apygis.read(GDAL_DIR / "polygons.gen")
    lay = m.layers["a"]
    nums = lay.chains().rows(0)
    first, second = lay.line_points["num"][nums[:2]]
    assert lay.area(int(first), int(second)).area_m2 == pytest.approx(1.0)
    assert lay.validate() == []
    # lines.gen holds one line twice, once reversed: kept as two lines, not a 2-point "ring"
    lines = apygis.read(GDAL_DIR / "lines.gen").layers["a"]
    assert [i for i in lines.validate() if i.severity == "error"] == []
    assert len(lines.chains()) == 2


# --------------------------------------------------------------------------- round trips


def test_sample_map_round_trip(sample_map, tmp_path):
    target = tmp_path / "out" / "ZH1091.gen"
    written = apygis.write(sample_map, target)
    assert sorted(written) == sorted(arcinfo.outputs(sample_map, target))
    assert (tmp_path / "out" / "ZH1091_r_lines.gen").is_file()
    assert (tmp_path / "out" / "ZH1091_r_lines.csv").read_text().startswith("ID,CODE\n")
    back = apygis.read(target)
    assert back.id == "ZH1091"
    assert back.crs_string() == "EPSG:2056"
    assert sorted(back.layers) == sorted(sample_map.layers)
    for ext, lay in sample_map.layers.items():
        got = back.layers[ext]
        assert polylines(got) == polylines(lay), ext
        assert got.counts() == lay.counts(), ext
        assert len(got.branches()) == len(lay.branches()), ext
        np.testing.assert_array_equal(got.symbols, lay.symbols)
        np.testing.assert_array_equal(got.texts, lay.texts)
        assert [i for i in got.validate() if i.severity == "error"] == []
    # the branches of the sample hang off the same junction points as before
    for ext in ("h", "r"):
        lp_a, lp_b = sample_map.layers[ext].line_points, back.layers[ext].line_points
        xy = {}
        for lp, key in ((lp_a, "a"), (lp_b, "b")):
            nums = {int(n): (x, y) for n, x, y in zip(lp["num"], lp["x"], lp["y"], strict=True)}
            xy[key] = sorted(nums[b["junction"]] for b in topology_branches(lp))
        assert xy["a"] == xy["b"]


def topology_branches(lp):
    from apygis.model import topology

    return topology.branches(lp)


def test_closed_lines_keep_area(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path / "ZH1091.gen")
    back = apygis.read(tmp_path / "ZH1091.gen")
    for ext in ("h", "r"):
        for lay in (sample_map.layers[ext], back.layers[ext]):
            cs = lay.chains()
            areas = sorted(
                round(
                    lay.area(*(int(n) for n in lay.line_points["num"][cs.rows(k)[:2]])).area_m2, 4
                )
                for k in range(len(cs))
                if cs.closed[k]
            )
            if lay is sample_map.layers[ext]:
                want = areas
        assert areas == want


coord = st.integers(-(10**8), 10**8).map(lambda v: v / 100.0)


@st.composite
def topo_layers(draw):
    """A layer of lines with distinct vertices: branches join interior points only."""
    lay = apygis.Layer("r")
    count = draw(st.integers(1, 5))
    sizes = [draw(st.integers(1, 6)) for _ in range(count)]
    xy = draw(
        st.lists(st.tuples(coord, coord), min_size=sum(sizes), max_size=sum(sizes), unique=True)
    )
    k = 0
    for n in sizes:
        pts = [(x, y, draw(coord)) for x, y in xy[k : k + n]]
        k += n
        closed = n >= 3 and draw(st.booleans())
        nums = lay.add_line(pts, code=draw(st.integers(0, 99)), closed=closed)
        if closed or not draw(st.booleans()):
            continue
        lp = lay.line_points
        inner = (lp["fwd"] != -1) & (lp["back"] != -1) & ~np.isin(lp["num"], nums)
        free = (lp["side1"] == -1) | (lp["side2"] == -1)
        targets = lp["num"][inner & free].tolist()
        if targets:
            lay.join(nums[0], draw(st.sampled_from(targets)))
    for _ in range(draw(st.integers(0, 3))):
        lay.add_symbol(draw(coord), draw(coord), draw(coord), draw(st.integers(0, 99)))
    return lay


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(lay=topo_layers())
def test_round_trip_property(lay, tmp_path_factory):
    out = tmp_path_factory.mktemp("gen") / "P.gen"
    m = apygis.MapFile("P")
    m.add_layer(lay)
    apygis.write(m, out)
    got = apygis.read(out).layers["r"]
    assert polylines(got) == polylines(lay)
    assert len(got.chains()) == len(lay.chains())
    assert len(got.branches()) == len(lay.branches())
    np.testing.assert_array_equal(got.symbols, lay.symbols)


def test_two_dimensional_files(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path / "Z.gen", dims=2)
    gen = (tmp_path / "Z_e_points.gen").read_text()
    assert gen.splitlines()[0].count(",") == 2
    back = apygis.read(tmp_path / "Z.gen")
    # heights of points and texts come back from the attribute tables
    np.testing.assert_array_equal(back.layers["e"].symbols, sample_map.layers["e"].symbols)
    np.testing.assert_array_equal(back.layers["c"].texts, sample_map.layers["c"].texts)
    assert (back.layers["r"].line_points["z"] == 0).all()


# --------------------------------------------------------------------------- what GDAL reads


@pytest.mark.parametrize("dims", [3, 2])
def test_gdal_reads_what_we_write(sample_map, tmp_path, dims):
    apygis.write(sample_map, tmp_path / "ZH1091.gen", dims=dims)
    suffix = "25D" if dims == 3 else ""
    n_checked = 0
    for (ext, kind), path in arcinfo.set_files(tmp_path / "ZH1091.gen").items():
        lay = sample_map.layers[ext]
        got = gdal_arcgen_read(path)
        assert got is not None, path
        gtype, feats = got
        if kind in ("points", "texts"):
            table = lay.symbols if kind == "points" else lay.texts
            assert gtype == "Point" + suffix
            assert [f[0] for f in feats] == table["num"].tolist()
            want = np.column_stack([table["x"], table["y"], table["z"]])[:, :dims]
            np.testing.assert_array_equal(np.array([f[1][0] for f in feats]), want)
        else:
            assert gtype == ("Polygon" if kind == "polygons" else "LineString") + suffix
            closed = kind == "polygons"
            want = [
                [c[:dims] for c in pl]
                for pl, is_closed in zip(
                    feature_coords(lay), export_lines(lay).closed.tolist(), strict=True
                )
                if is_closed == closed
            ]
            assert [f[1] for f in feats] == want
        if _pyogrio_has_arcgen():
            assert _pyogrio_features(path)[1] == feats
        n_checked += 1
    assert n_checked == 11


# --------------------------------------------------------------------------- names and probing


def test_outputs_and_stale_files(sample_map, tmp_path):
    target = tmp_path / "ZH1091.gen"
    names = [p.name for p in arcinfo.outputs(sample_map, target)]
    assert "ZH1091_c_texts.gen" in names
    assert "ZH1091_c_texts.csv" in names
    assert "ZH1091.prj" in names
    assert not any(p.exists() for p in arcinfo.outputs(sample_map, target))
    apygis.write(sample_map, target)
    smaller = sample_map.copy()
    smaller.layers["c"] = apygis.Layer.from_arrays("c", symbols=sample_map.layers["c"].symbols)
    apygis.write(smaller, target)
    assert not (tmp_path / "ZH1091_c_texts.gen").exists()
    assert not (tmp_path / "ZH1091_c_texts.csv").exists()
    assert apygis.read(target).layers["c"].counts()["texts"] == 0


@pytest.mark.external
def test_driver_choice(sample_map, tmp_path):
    target = tmp_path / "ZH1091.gen"
    assert driver_for(target, "w").name == "generate"
    apygis.write(sample_map, target)
    assert driver_for(target, "r").name == "generate"  # the set's name
    assert driver_for(tmp_path / "ZH1091_r_lines.gen", "r").name == "generate"
    assert arcinfo.probe(GDAL_DIR / "points.gen")
    assert not arcinfo.probe(GDAL_DIR / "test.e00")


def test_single_member_file_uses_its_attributes(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path / "ZH1091.gen")
    m = apygis.read(tmp_path / "ZH1091_r_points.gen")
    assert list(m.layers) == ["r"]
    np.testing.assert_array_equal(m.layers["r"].symbols, sample_map.layers["r"].symbols)
    t = apygis.read(tmp_path / "ZH1091_c_texts.gen")
    np.testing.assert_array_equal(t.layers["c"].texts, sample_map.layers["c"].texts)
    other = tmp_path / "plain.gen"
    other.write_bytes((tmp_path / "ZH1091_h_lines.gen").read_bytes())
    m = apygis.read(other, layer="h", default_code=31)
    assert list(m.layers) == ["h"]
    assert set(m.layers["h"].line_points["code"].tolist()) == {31}


def test_nothing_to_write(tmp_path):
    with pytest.raises(DriverError, match="nothing to write"):
        apygis.write(apygis.MapFile("E"), tmp_path / "E.gen")
    with pytest.raises(DriverError, match="dims"):
        apygis.write(apygis.MapFile("E"), tmp_path / "E.gen", dims=4)


# --------------------------------------------------------------------------- bad input


BAD = [
    (b"1\n2,49\n3,50\nEND\n", "line 4", "without the final END"),
    (b"1\n2,49\nx,50\nEND\nEND\n", "line 3", "expected numbers (X, Y)"),
    (b"1\n2,49,1,5\nEND\nEND\n", "line 2", "2 or 3 fields"),
    (b"1\n2,49\n3,50,7\nEND\nEND\n", "line 3", "vertex of 2 fields"),
    (b"1.5\n2,49\nEND\nEND\n", "line 1", "integer feature ID"),
    (b"1\nEND\nEND\n", "line 1", "has no vertices"),
    (b"1,2,49\n2,3\nEND\n", "line 2", "ID, X, Y[, Z]"),
    (b"1,2,49\n2,3,50,1\nEND\n", "line 2", "expected 3 fields like the first point"),
    (b"1,2,49\n2,3,50\n", "line 2", "without END"),
    (b"1,2,49\nEND\n3,4,5\n", "line 3", "data after the final END"),
    (b"1,nan,49\nEND\n", "line 1", "finite"),
    (b"99999999999,2,49\nEND\n", "line 1", "integer point ID"),
    (b"1,2\nEND\n", "line 1", "found 2 fields"),
]


@pytest.mark.parametrize(("data", "where", "what"), BAD)
def test_bad_input(tmp_path, data, where, what):
    p = tmp_path / "bad.gen"
    p.write_bytes(data)
    with pytest.raises(FormatError, match=re.escape(what)) as exc:
        apygis.read(p, driver="generate")
    assert exc.value.record == where
    assert exc.value.path == str(p)


@pytest.mark.parametrize("data", [b"", b"\x00\x01\x02", b"\xff\xfe\xfa junk\n", b"END\nx\n"])
def test_junk(tmp_path, data):
    p = tmp_path / "junk.gen"
    p.write_bytes(data)
    with pytest.raises(FormatError):
        apygis.read(p, driver="generate")


@pytest.mark.parametrize(
    ("table", "what"),
    [
        ("ID,CODE\n1,120\n", "CODE must be an integer from 0 to 99"),
        ("ID,CODE\n1\n", "expected 2 fields"),
        ("ID,CODE\nx,1\n", "ID must be an integer"),
        ("ID,CODE\n1,1\n1,2\n", "appears twice"),
        ("CODE\n1\n", "must name an ID column"),
    ],
)
def test_bad_attribute_table(tmp_path, table, what):
    (tmp_path / "L.gen").write_bytes(b"1\n2,49\n3,50\nEND\nEND\n")
    (tmp_path / "L.csv").write_text(table)
    with pytest.raises(FormatError, match=what) as exc:
        apygis.read(tmp_path / "L.gen")
    assert exc.value.path == str(tmp_path / "L.csv")


def test_missing_file(tmp_path):
    with pytest.raises(FormatError, match="no such file"):
        arcinfo.read(tmp_path / "none.gen")


def test_columnar_scale(tmp_path):
    """200 000 line points and 50 000 symbols go through in array operations."""
    from tests.formats.strategies import random_rows

    rng = np.random.default_rng(7)
    lp = random_rows(rng, 200_000)
    sym = np.zeros(50_000, apygis.Layer("r").symbols.dtype)
    sym["num"] = np.arange(50_000)
    sym["x"] = np.round(rng.uniform(2.6e6, 2.7e6, 50_000), 2)
    sym["code"] = 7
    m = apygis.MapFile("BIG")
    m.add_layer(apygis.Layer.from_arrays("r", symbols=sym, line_points=lp))
    apygis.write(m, tmp_path / "BIG.gen")
    back = apygis.read(tmp_path / "BIG.gen").layers["r"]
    assert back.counts() == m.layers["r"].counts()
    np.testing.assert_array_equal(back.symbols, m.layers["r"].symbols)


# ------------------------------------------------------------------------ hostile input (issue 9)


@pytest.mark.parametrize(
    ("data", "where"),
    [
        (b"1\n1e308,0\n2,2\nEND\nEND\n", "line 2"),  # finite: overflowed the KD-tree
        (b"1\n0,0\n2,-1.5e12\nEND\nEND\n", "line 3"),
        (b"1\n0,0,0\n2,2,1e300\nEND\nEND\n", "line 3"),
        (b"1,1e308,49\n2,3,50\nEND\n", "line 1"),
        (b"1,2,49,inf\nEND\n", "line 1"),
    ],
)
def test_absurd_coordinates_are_refused(tmp_path, data, where):
    p = tmp_path / "big.gen"
    p.write_bytes(data)
    with pytest.raises(FormatError, match=r"at most 1e\+12 in magnitude") as exc:
        apygis.read(p, driver="generate")
    assert exc.value.record == where
    assert exc.value.path == str(p)


def test_lines_just_inside_the_bound_are_read(tmp_path):
    p = tmp_path / "ok.gen"
    p.write_bytes(b"1\n-999999999999,0\n999999999999,1\nEND\nEND\n")
    lp = apygis.read(p, driver="generate").layers["a"].line_points
    assert sorted(lp["x"].tolist()) == [-999999999999.0, 999999999999.0]


@pytest.mark.parametrize(
    ("table", "what"),
    [
        ("ID,CODE\n1,\u0663\n", "CODE must be an integer from 0 to 99, not '\u0663'"),
        ("ID,CODE\n1,1_0\n", "CODE must be an integer from 0 to 99, not '1_0'"),
        ("ID,CODE\n\u00b9,1\n", "ID must be an integer"),
        ("ID,CODE\n" + "1" * 5000 + ",1\n", "ID must be an integer"),
    ],
)
def test_attribute_integers_take_ascii_digits_only(tmp_path, table, what):
    """int() reads Arabic-Indic digits and '1_0'; 5000 digits raised a bare ValueError."""
    (tmp_path / "L.gen").write_bytes(b"1\n2,49\n3,50\nEND\nEND\n")
    (tmp_path / "L.csv").write_text(table, encoding="utf-8")
    with pytest.raises(FormatError, match=re.escape(what)) as exc:
        apygis.read(tmp_path / "L.gen")
    assert exc.value.path == str(tmp_path / "L.csv")
    assert exc.value.record == "line 2"


def test_attribute_height_beyond_the_bound_is_refused(tmp_path):
    (tmp_path / "P.gen").write_bytes(b"1,2,49\nEND\n")
    (tmp_path / "P.csv").write_text("ID,CODE,HEIGHT\n1,3,1e300\n")
    with pytest.raises(FormatError, match=r"HEIGHT must be a finite number of at most 1e\+12"):
        apygis.read(tmp_path / "P.gen")
