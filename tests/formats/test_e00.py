"""E00 driver: GDAL's sample files, round trips record for record, GDAL reading what we write."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pyogrio
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from pyogrio.raw import read as ogr_read

import apygis
from apygis.errors import DriverError, FormatError
from apygis.formats import driver_for, e00
from apygis.model.polylines import export_lines
from tests.conftest import EXTERNAL
from tests.formats import strategies

GDAL_DIR = EXTERNAL / "gdal"


def gdal_layer(path, layer):
    """``(meta, fids, geometries, {field: values})`` as GDAL's AVCE00 driver reads a layer."""
    meta, fids, geom, fields = ogr_read(path, layer=layer, return_fids=True)
    return meta, fids, shapely.from_wkb(geom), dict(zip(meta["fields"], fields, strict=True))


def segments(lines):
    """The undirected segments of polylines (coordinate lists), as a set."""
    out = set()
    for c in lines:
        c = [tuple(np.round(v[:2], 6)) for v in c]
        out |= {frozenset((a, b)) for a, b in itertools.pairwise(c) if a != b}
    return out


def drawn_lines(layer):
    """Every chain of a layer as drawn: branches touch their junctions, rings closed."""
    out = []
    for pl in export_lines(layer):
        c = pl.coords.tolist()
        out.append([*c, c[0]] if pl.closed else c)
    return out


# --------------------------------------------------------------------------- GDAL's samples


@pytest.mark.external
def test_reference_file_layers_as_gdal():
    path = GDAL_DIR / "test.e00"
    assert pyogrio.list_layers(path).tolist() == [["ARC", "LineString"], ["LAB", "Point"]]
    info = e00.decode(path.read_bytes(), path)
    assert info["precision"] == e00.SINGLE
    _, fids, geoms, fields = gdal_layer(path, "ARC")
    heads = info["arcs"]["heads"]
    assert [h[1] for h in heads] == fields["UserId"].tolist() == list(range(1, 8))
    ids, off, xy = e00._arc_arrays(info["arcs"])
    assert ids.tolist() == fids.tolist()
    for k, g in enumerate(geoms):
        np.testing.assert_array_equal(xy[off[k] : off[k + 1]], shapely.get_coordinates(g))
    # GDAL's autotest quotes the first arc as single precision floats
    first = [[340099.875, 4100200.0], [340400.0625, 4100399.5], [340900.125, 4100200.0],
             [340700.03125, 4100199.5]]  # fmt: skip
    np.testing.assert_array_equal(xy[: off[1]].astype(np.float32), first)


@pytest.mark.external
def test_reference_file_imports_with_gdal_geometry():
    path = GDAL_DIR / "test.e00"
    m = apygis.read(path)
    meta, _, arcs, _ = gdal_layer(path, "ARC")
    assert m.crs_string() == meta["crs"] == "EPSG:26713"
    assert sorted(m.layers) == ["arc", "lab"]  # as GDAL's layers ARC and LAB
    lay = m.layers["arc"]
    # the topology is rebuilt; the drawn network is GDAL's arcs, segment for segment
    gdal_lines = [shapely.get_coordinates(g) for g in arcs]
    assert segments(drawn_lines(lay)) == segments(gdal_lines)
    assert [i for i in lay.validate() if i.severity == "error"] == []
    _, _, labs, fields = gdal_layer(path, "LAB")
    sym = m.layers["lab"].symbols
    np.testing.assert_allclose(np.column_stack([sym["x"], sym["y"]]), shapely.get_coordinates(labs))
    assert sym["num"].tolist() == fields["ValueId"].tolist()
    assert set(sym["code"].tolist()) == {90}  # no code item: imported points


@pytest.mark.external
def test_grid_e00_is_refused():
    with pytest.raises(FormatError, match="grid") as exc:
        apygis.read(GDAL_DIR / "fake_e00grid.e00")
    assert exc.value.record == "line 2"


@pytest.mark.external
def test_compressed_file(tmp_path):
    path = GDAL_DIR / "compressed.e00"
    with pytest.raises(pyogrio.errors.DataSourceError, match="compressed"):
        ogr_read(path, layer="ARC")  # GDAL itself does not uncompress
    text = e00.decompress(path.read_bytes(), path)
    lines = text.split(b"\n")
    assert lines[0].startswith(b"EXP  0 /USR/USERS/HYDAO/RUSSIA.E00")
    assert lines[1:4] == [
        b"ARC  2",
        b"         1         9         1         2       437       175         3",
        b" 8.7311409E+01 7.4441254E+01 8.7306671E+01 7.4443100E+01",
    ]
    assert all(len(ln) <= 80 for ln in lines)
    # the sample is cut off inside its fourth arc
    with pytest.raises(FormatError, match="truncated") as exc:
        apygis.read(path)
    assert exc.value.record.startswith("uncompressed line")
    info = e00.decode(path.read_bytes(), path, recover=True)
    ids, off, xy = e00._arc_arrays(info["arcs"])
    assert ids.tolist() == [1, 2, 3]
    # GDAL reads the uncompressed text of the complete arcs the same way
    k = next(i for i, ln in enumerate(lines) if ln.startswith(b"         4"))
    plain = tmp_path / "russia.e00"
    plain.write_bytes(b"\n".join([*lines[:k], e00._TERM + b"         0" * 5, b"EOS", b""]))
    _, fids, geoms, fields = gdal_layer(plain, "ARC")
    assert fids.tolist() == [1, 2, 3]
    assert fields["UserId"].tolist() == [h[1] for h in info["arcs"]["heads"]] == [9, 9, 8]
    for j, g in enumerate(geoms):
        np.testing.assert_array_equal(xy[off[j] : off[j + 1]], shapely.get_coordinates(g))
    m = apygis.read(path, recover=True)
    assert segments(drawn_lines(m.layers["arc"])) == segments(
        [shapely.get_coordinates(g) for g in geoms]
    )


def _compress(text: bytes) -> bytes:
    """Level-1 E00 compression (runs of spaces, line ends, ``~``) in 80-column lines."""
    lines = text.split(b"\n")
    out = bytearray()
    for ln in lines[1:]:
        if not ln and ln is lines[-1]:
            break
        ln = ln.replace(b"~", b"~~")
        ln = re.sub(rb" {3,92}", lambda m: b"~ " + bytes([32 + len(m.group())]), ln)
        out += ln + b"~}"
    body = b"\n".join(bytes(out[k : k + 80]) for k in range(0, len(out), 80))
    return lines[0].replace(b"EXP  0", b"EXP  1") + b"\n" + body + b"\n"


def test_decompress_round_trip(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path / "ZH1091.e00")
    plain = (tmp_path / "ZH1091.e00").read_bytes()
    packed = _compress(plain)
    assert len(packed) < len(plain)
    assert e00.decompress(packed) == plain
    (tmp_path / "packed.e00").write_bytes(packed)
    assert apygis.read(tmp_path / "packed.e00") == sample_map


def test_decompress_numbers():
    # from compressed.e00: "~1" = point after 1 digit, exponent E+ before the last two
    # digits, even digit count; "x@/*" + '"' = digit pairs 87 31 14 09 01
    packed = b'EXP  1 /R.E00\n ~1x@/*" ~1kM-W"~}~ )1~}EOS~}'
    assert e00.decompress(packed) == (
        b"EXP  0 /R.E00\n 8.7311409E+01 7.4441254E+01\n         1\nEOS\n"
    )
    for bad in (b"EXP  1\n~", b"EXP  1\n~\x7f", b"EXP  1\n" + b"x" * 81):
        with pytest.raises(FormatError):
            e00.decompress(bad)


# --------------------------------------------------------------------------- round trips


def test_sample_map_round_trip(sample_map, tmp_path):
    target = tmp_path / "ZH1091.e00"
    assert e00.outputs(sample_map, target) == [target]
    assert apygis.write(sample_map, target) == [target]
    back = apygis.read(target)
    assert back == sample_map  # record for record: numbers, references, codes, heights, texts
    for ext, lay in sample_map.layers.items():
        np.testing.assert_array_equal(back.layers[ext].line_points, lay.line_points)
    text = target.read_text("ascii")
    for table in ("ZH1091.AAT", "ZH1091.PAT", "ZH1091.LINEPT", "ZH1091.APYMAP"):
        assert f"\n{table} " in text
    assert all(len(ln) <= 80 for ln in text.splitlines())


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(m=strategies.maps())
def test_round_trip_property(m, tmp_path_factory):
    target = tmp_path_factory.mktemp("e00") / "P.e00"
    apygis.write(m, target)
    assert apygis.read(target) == m


def _local(m):
    """The map moved to small local coordinates (thousands of metres): 8 digits hold cm."""
    out = apygis.MapFile(m.id, m.scale, None, m.notes)
    for lay in m:
        tables = {}
        for name in ("symbols", "line_points", "texts"):
            t = lay.table(name).copy()
            t["x"] -= 2680000.0
            t["y"] -= 1245000.0
            tables[name] = t
        out.add_layer(apygis.Layer.from_arrays(lay.ext, **tables))
    return out


def test_single_precision_refuses_what_it_cannot_hold(sample_map, tmp_path):
    # 8 significant digits at Swiss coordinates (2 684 000 m) are decimetres
    with pytest.raises(FormatError, match=r"single precision .* would be lost"):
        apygis.write(sample_map, tmp_path / "S.e00", precision=e00.SINGLE)
    assert not list(tmp_path.iterdir())


def test_single_precision(sample_map, tmp_path):
    sample_map = _local(sample_map)
    apygis.write(sample_map, tmp_path / "S.e00", precision=e00.SINGLE)
    text = (tmp_path / "S.e00").read_bytes()
    assert b"\nARC  2\n" in text
    assert b"\nLAB  2\n" in text
    back = apygis.read(tmp_path / "S.e00")
    for ext, lay in sample_map.layers.items():
        got = back.layers[ext]
        for table in ("line_points", "symbols"):
            a, b = lay.table(table), got.table(table)
            np.testing.assert_allclose(b["x"], a["x"], rtol=1e-7)
            np.testing.assert_array_equal(b["z"], a["z"])  # heights are doubles in INFO
            np.testing.assert_array_equal(b["num"], a["num"])
    _, _, arcs, _ = gdal_layer(tmp_path / "S.e00", "ARC")
    assert len(arcs) == sum(len(export_lines(lay)) for lay in sample_map)
    with pytest.raises(DriverError):
        apygis.write(sample_map, tmp_path / "X.e00", precision=4)


# --------------------------------------------------------------------------- what GDAL reads


def test_gdal_reads_what_we_write(sample_map, tmp_path):
    path = tmp_path / "ZH1091.e00"
    apygis.write(sample_map, path)
    assert pyogrio.list_layers(path).tolist() == [["ARC", "LineString"], ["LAB", "Point"]]
    meta, fids, arcs, f = gdal_layer(path, "ARC")
    assert meta["crs"] is not None
    from pyproj import CRS

    assert CRS.from_user_input(meta["crs"]).to_epsg() == 2056
    want_lines, want_layer, want_code = [], [], []
    for lay in sample_map:
        ls = export_lines(lay)
        want_lines += drawn_lines(lay)
        want_layer += [lay.ext] * len(ls)
        want_code += ls.codes.tolist()
    assert len(arcs) == len(want_lines) == 18
    assert fids.tolist() == list(range(1, len(arcs) + 1))
    for g, want in zip(arcs, want_lines, strict=True):
        np.testing.assert_array_equal(shapely.get_coordinates(g), np.array(want)[:, :2])
    assert f["LAYER"].tolist() == want_layer
    assert f["CODE"].tolist() == want_code
    np.testing.assert_allclose(f["LENGTH"], [g.length for g in arcs], rtol=1e-12)
    _, _, labs, f = gdal_layer(path, "LAB")
    sym = [(lay.ext, "S", r) for lay in sample_map for r in lay.symbols.tolist()]
    txt = [(lay.ext, "T", r) for lay in sample_map for r in lay.texts.tolist()]
    # symbols then texts, layer by layer
    want = [x for lay in sample_map for x in sym + txt if x[0] == lay.ext]
    assert len(labs) == len(want) == 129
    np.testing.assert_array_equal(shapely.get_coordinates(labs), [[r[1], r[2]] for _, _, r in want])
    assert f["NUM"].tolist() == [r[0] for _, _, r in want]
    assert f["KIND"].tolist() == [k for _, k, _ in want]
    np.testing.assert_array_equal(f["HEIGHT"], [r[3] for _, _, r in want])
    assert [t for t, (_, k, _) in zip(f["TEXT"], want, strict=True) if k == "T"] == [
        r[4] for _, k, r in want if k == "T"
    ]


def test_empty_map(tmp_path):
    m = apygis.MapFile("EMPTY", scale=1000, notes="nothing\nyet")
    m.layer("r")
    apygis.write(m, tmp_path / "E.e00")
    assert apygis.read(tmp_path / "E.e00") == m  # (GDAL opens no coverage without features)


@pytest.mark.external
def test_driver_choice(tmp_path):
    assert driver_for(tmp_path / "x.e00", "w").name == "e00"
    assert driver_for(GDAL_DIR / "test.e00", "r").name == "e00"
    assert e00.probe(GDAL_DIR / "compressed.e00")
    assert not e00.probe(GDAL_DIR / "lines.gen")


# --------------------------------------------------------------------------- bad input


@pytest.fixture(scope="module")
def small_e00(tmp_path_factory):
    path = tmp_path_factory.mktemp("small") / "FUZZ.e00"
    apygis.write(strategies.small_map(), path)
    return path.read_bytes()


def _edit(data: bytes, old: bytes, new: bytes) -> bytes:
    assert old in data
    return data.replace(old, new, 1)


def _line_of(data: bytes, needle: bytes) -> str:
    return f"line {_lines_before(data, data.index(needle)) + 1}"


def _lines_before(data: bytes, pos: int) -> int:
    return data[:pos].count(b"\n")


BAD = [
    ("truncated", lambda d: d[: len(d) // 2], "truncated", None),
    ("junk", lambda d: b"PK\x03\x04 not an e00", "must begin with an EXP line", None),
    ("compression", lambda d: _edit(d, b"EXP  0", b"EXP  7"), "compression", "line 1"),
    ("section", lambda d: _edit(d, b"TOL  3", b"XYZ  3"), "unknown section", b"XYZ  3"),
    ("precision", lambda d: _edit(d, b"LAB  3", b"LAB  5"), "precision 5", b"LAB  5"),
    (
        "arc header",
        lambda d: _edit(d, b"         1         1", b"         1"),
        "7 integers",
        "line 3",
    ),
    (
        "coordinate",
        lambda d: _edit(d, b" 2.68300000000000E+06", b" 2.683OOOOOOOOOOOE+06"),
        "expected a number",
        b" 2.683OOOO",
    ),
    ("no EOS", lambda d: d[: d.rindex(b"EOS")], "without EOS", None),
    (
        "records",
        lambda d: re.sub(rb"(FUZZ\.APYMAP +3   3  73) +\d+\n", rb"\1       999\n", d),
        "ends inside the records of INFO table FUZZ.APYMAP",
        None,
    ),
]


@pytest.mark.parametrize(("name", "edit", "what", "where"), BAD, ids=[b[0] for b in BAD])
def test_bad_input(tmp_path, small_e00, name, edit, what, where):
    data = edit(small_e00)
    assert data != small_e00
    p = tmp_path / "bad.e00"
    p.write_bytes(data)
    with pytest.raises(FormatError, match=re.escape(what)) as exc:
        apygis.read(p)
    assert exc.value.path == str(p)
    if isinstance(where, bytes):
        assert exc.value.record == _line_of(data, where)
    elif where:
        assert exc.value.record == where


def test_bad_info_values(tmp_path, small_e00):
    # a line point on an arc that does not exist
    data = small_e00
    k = data.index(b"FUZZ.LINEPT")
    rec = data.index(b"\n          1          1", k) + 1
    bad = data[:rec] + b"         99" + data[rec + 11 :]
    p = tmp_path / "bad.e00"
    p.write_bytes(bad)
    with pytest.raises(FormatError, match="item ARC#: expected the number of an arc") as exc:
        apygis.read(p)
    assert exc.value.record == f"line {_lines_before(bad, rec) + 1}"
    # a label kind that is neither S nor T
    pat = data.index(b"FUZZ.PAT")
    j = data.index(b"r  S", pat)
    p.write_bytes(data[:j] + b"r  Q" + data[j + 4 :])
    with pytest.raises(FormatError, match="S \\(symbol\\) or T \\(text\\)"):
        apygis.read(p)


def test_recover_keeps_what_was_read(tmp_path, small_e00):
    cut = small_e00[: small_e00.index(b"LAB  3")]
    p = tmp_path / "cut.e00"
    p.write_bytes(cut)
    with pytest.raises(FormatError):
        apygis.read(p)
    m = apygis.read(p, recover=True)
    lay = m.layers["arc"]
    assert len(lay.chains()) == len(export_lines(strategies.small_map().layers["r"]))


# ------------------------------------------------------------------------ hostile input (issue 9)


class _HangGuard:
    """Fail (not hang) if the block runs longer than ``seconds``: SIGALRM, main thread."""

    def __init__(self, seconds: int):
        self.seconds = seconds

    def __enter__(self):
        import signal

        def _timeout(signum, frame):
            raise TimeoutError(f"still running after {self.seconds} s")

        self.old = signal.signal(signal.SIGALRM, _timeout)
        signal.alarm(self.seconds)

    def __exit__(self, *exc):
        import signal

        signal.alarm(0)
        signal.signal(signal.SIGALRM, self.old)


def test_decompressing_a_400_kb_number_is_linear(tmp_path):
    """Each digit pair counted the digits so far: 400 KB took minutes (quadratic)."""
    p = tmp_path / "long.e00"
    p.write_bytes(b"EXP  1 /LONG.E00\nARC  2~}~!" + b"5" * 400_000 + b"~}EOS~}")
    with _HangGuard(20), pytest.raises(FormatError, match="longer than 80 characters") as exc:
        apygis.read(p)
    assert exc.value.record == "uncompressed line 2"


def test_a_400_kb_compressed_file_is_read(tmp_path):
    m = apygis.MapFile("BIG", crs="EPSG:2056")
    t = np.linspace(0, 2000, 9000)
    m.layer("r").add_line(np.column_stack([2.6e6 + t, 1.2e6 + np.sin(t) * 50, t / 10]), code=3)
    apygis.write(m, tmp_path / "BIG.e00")
    packed = _compress((tmp_path / "BIG.e00").read_bytes())
    assert len(packed) > 400_000
    (tmp_path / "packed.e00").write_bytes(packed)
    with _HangGuard(20):
        back = apygis.read(tmp_path / "packed.e00")
    assert len(back.layers["r"].line_points) == 9000


def _meta_line(key: bytes, value: bytes) -> bytes:
    """A record of the APYMAP table: KEY (8), VALUE (61), NBYTES (11 columns)."""
    return key.ljust(8) + value.ljust(61) + str(len(value)).encode().rjust(11)


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        (b"NOTES", b"caf\\udcfc", "lone surrogate U+DCFC"),
        (b"ID", b"\\ud800x", "lone surrogate U+D800"),
        (b"SCALE", "\u0665\u0660\u0660\u0660".encode(), "SCALE value '\u0665\u0660\u0660\u0660'"),
        (b"SCALE", b"5 000", "is not a whole number"),
        (b"NOTES", b"bad \\x escape", "NOTES value is not UTF-8 JSON"),
    ],
)
def test_hostile_metadata_values(tmp_path, small_e00, key, value, match):
    old = next(ln for ln in small_e00.split(b"\n") if ln.startswith(key.ljust(8)))
    data = _edit(small_e00, old, _meta_line(key, value))
    p = tmp_path / "bad.e00"
    p.write_bytes(data)
    with pytest.raises(FormatError, match=re.escape(match)) as exc:
        apygis.read(p)
    assert exc.value.path == str(p)
    assert "APYMAP" in exc.value.reason


@pytest.mark.parametrize(
    ("new", "what"),
    [
        (b" 1.0000000000000E+308", "ARC vertex"),
        (b"-2.0000000000000E+012", "ARC vertex"),
        (b"                  nan", "ARC vertex"),
    ],
)
def test_absurd_coordinates_are_refused(tmp_path, small_e00, new, what):
    """1e308 is finite but overflows the KD-tree that joins arc ends."""
    old = b" 2.68300000000000E+06"
    assert len(new) == len(old)
    data = _edit(small_e00, old, new)
    p = tmp_path / "big.e00"
    p.write_bytes(data)
    with pytest.raises(FormatError, match=f"{what}: expected a number") as exc:
        apygis.read(p)
    assert exc.value.record == _line_of(data, new)
    assert "1e+12 in magnitude" in exc.value.reason


def test_map_id_with_a_line_break_is_refused(tmp_path, small_e00):
    old = next(ln for ln in small_e00.split(b"\n") if ln.startswith(b"ID      "))
    p = tmp_path / "bad.e00"
    p.write_bytes(_edit(small_e00, old, _meta_line(b"ID", b"FUZZ\\n")))
    with pytest.raises(FormatError, match=r"holds a line break|map ID is"):
        apygis.read(p)


def test_foreign_arcs_go_through_the_one_rebuild(tmp_path, caplog):
    """A square of four arcs is one closed line even when other arcs cannot be joined
    (before, one arc pair that would make a two-point loop left every arc unjoined)."""
    arcs = [((0, 0), (10, 0)), ((10, 10), (10, 0)), ((10, 10), (0, 10)), ((0, 0), (0, 10))]
    arcs += [((20, 0), (25, 0)), ((25, 0), (20, 0))]  # a line and its reverse
    text = [b"EXP  0 /SQ.E00", b"ARC  2"]
    for k, (a, b) in enumerate(arcs, start=1):
        text.append("".join(f"{v:10d}" for v in (k, k, 0, 0, 0, 0, 2)).encode())
        text.append("".join(f"{v:14.7E}" for v in (*a, *b)).encode())
    text += ["".join(f"{v:10d}" for v in (-1, 0, 0, 0, 0, 0, 0)).encode(), b"EOS", b""]
    p = tmp_path / "sq.e00"
    p.write_bytes(b"\n".join(text))
    with caplog.at_level("INFO", logger="apygis.formats.e00"):
        lay = apygis.read(p).layers["arc"]
    assert lay.counts()["closed_lines"] == 1
    assert lay.counts()["lines"] == 3
    assert len(lay.line_points) == 8
    assert lay.validate() == []
    assert "two points into a loop" in caplog.text
