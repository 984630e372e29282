"""The APY native binary format: round trips, capacity, limits, corruption."""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

import apygis
from apygis.errors import CapacityError, DriverError, FormatError, ValueRangeError
from apygis.formats import apy
from tests.formats.strategies import maps


def test_sample_round_trip_is_exact(sample_dir, tmp_path):
    m = apygis.read(sample_dir / "ZH1091")
    assert sorted(m.layers) == ["c", "e", "h", "r"]
    written = apygis.write(m, tmp_path / "ZH1091")
    assert sorted(p.name for p in written) == ["ZH1091.c", "ZH1091.e", "ZH1091.h", "ZH1091.r"]
    for p in written:
        assert p.read_bytes() == (sample_dir / p.name).read_bytes()
    assert apygis.read(tmp_path / "ZH1091") == m


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(m=maps())
def test_property_round_trip(m, tmp_path_factory):
    if not m.layers:
        return
    d = tmp_path_factory.mktemp("rt")
    apygis.write(m, d / "MAP")
    assert apygis.read(d / "MAP") == m


def test_one_layer_file_and_the_rename_workflow(sample_dir, tmp_path):
    m = apygis.read(sample_dir / "ZH1091.h")
    assert sorted(m.layers) == ["h"]
    # APY moves a layer by renaming ID.c to ID.e: the file name's extension wins
    (tmp_path / "ZH1091.x").write_bytes((sample_dir / "ZH1091.c").read_bytes())
    m2 = apygis.read(tmp_path / "ZH1091.x")
    assert sorted(m2.layers) == ["x"]
    assert (
        m2.layers["x"].symbols.tolist()
        == apygis.read(sample_dir / "ZH1091").layers["c"].symbols.tolist()
    )


def test_write_to_directory_and_single_layer_path(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path)
    assert len(list(tmp_path.glob("ZH1091.*"))) == 4
    with pytest.raises(DriverError, match="has 4 layers"):
        apygis.write(sample_map, tmp_path / "out.r")
    one = apygis.MapFile("ONE")
    one.add_layer(sample_map.layers["e"].copy())
    apygis.write(one, tmp_path / "single.q")
    assert sorted(apygis.read(tmp_path / "single.q").layers) == ["q"]


def test_rewrite_removes_layer_files_of_dropped_layers(sample_map, tmp_path):
    apygis.write(sample_map, tmp_path / "ZH1091")
    (tmp_path / "ZH1091.notes").write_text("not an APY file, must survive")
    del sample_map.layers["e"]
    apygis.write(sample_map, tmp_path / "ZH1091")
    assert not (tmp_path / "ZH1091.e").exists()
    assert (tmp_path / "ZH1091.notes").exists()
    assert sorted(apygis.read(tmp_path / "ZH1091").layers) == ["c", "h", "r"]


@pytest.mark.parametrize(
    ("table", "cap"), [("symbols", 1000), ("line_points", 10000), ("texts", 500)]
)
def test_capacity_is_enforced_and_nothing_is_written(table, cap, tmp_path):
    m = apygis.MapFile("CAP")
    m.layer("a").add_symbol(0, 0, 0, 1)  # a valid layer before the full one
    lay = m.layer("r")
    for i in range(cap):
        if table == "symbols":
            lay.add_symbol(i, 0, 0, 1)
        elif table == "texts":
            lay.add_text(i, 0, 0, "t")
    if table == "line_points":
        lay.add_line([(float(i), 0.0, 0.0) for i in range(cap)], code=1)
    apygis.write(m, tmp_path / "ok" / "CAP")  # exactly the capacity fits
    assert len(apygis.read(tmp_path / "ok" / "CAP").layers["r"].table(table)) == cap
    if table == "symbols":
        lay.add_symbol(0, 0, 0, 1)
    elif table == "texts":
        lay.add_text(0, 0, 0, "t")
    else:
        lay.add_line([(0.0, 1.0, 0.0)], code=1)
    word = table.replace("_", " ")
    with pytest.raises(CapacityError, match=rf"layer r: {cap + 1} {word} exceed .* {cap}"):
        apygis.write(m, tmp_path / "over" / "CAP")
    assert not (tmp_path / "over").exists() or not any((tmp_path / "over").iterdir())


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda lay: lay.add_symbol(10_000_000.0, 0, 0, 1), r"symbol 1: X = .* 9 digits"),
        (lambda lay: lay.add_symbol(0, -10_000_000.0, 0, 1), r"Y = .* 9 digits"),
        (lambda lay: lay.add_symbol(0, 0, 10_000.0, 1), r"Z = .* 6 digits"),
        (lambda lay: lay.add_text(0, 0, 0, "Łódź"), "outside ISO 8859-1"),
    ],
)
def test_values_that_do_not_fit_the_digits(edit, match, tmp_path):
    m = apygis.MapFile("V")
    edit(m.layer("r"))
    with pytest.raises(ValueRangeError, match=match):
        apygis.write(m, tmp_path / "V")
    assert list(tmp_path.iterdir()) == []


def test_point_numbers_beyond_four_digits_are_refused(tmp_path):
    m = apygis.MapFile("N")
    lay = m.layer("r")
    lay.add_line([(float(i), 0.0, 0.0) for i in range(9999)], code=1)
    lay.delete_line_point(5)
    lay.add_line([(0.0, 1.0, 0.0)], code=1)  # takes 5 again
    lay.add_line([(0.0, 2.0, 0.0)], code=1)  # takes 0
    lay.add_line([(0.0, 3.0, 0.0)], code=1)  # 10000: over the capacity anyway
    with pytest.raises(CapacityError):
        apygis.write(m, tmp_path / "N")
    lay.delete_line_point(0)
    with pytest.raises(ValueRangeError, match="point number outside 0-9999"):
        apygis.write(m, tmp_path / "N")


def _valid_bytes(sample_dir):
    return (sample_dir / "ZH1091.r").read_bytes()


def _patch(data: bytes, offset: int, new: bytes, fix_crc: bool = True) -> bytes:
    b = bytearray(data)
    b[offset : offset + len(new)] = new
    if fix_crc:
        struct.pack_into("<I", b, 60, zlib.crc32(bytes(b[64:])))
    return bytes(b)


def _first_line_record(data: bytes) -> int:
    meta, ns = struct.unpack_from("<IH", data, 48)
    return 64 + meta + ns * 16


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d[:40], "truncated: 40 bytes"),
        (lambda d: b"XXXX" + d[4:], "not an APY layer file"),
        (lambda d: _patch(d, 4, struct.pack("<H", 9)), "version 9"),
        (lambda d: d[:-3], "truncated"),
        (lambda d: d + b"\0", "trailing bytes"),
        (lambda d: _patch(d, 200, b"\xff", fix_crc=False), "checksum mismatch"),
        (lambda d: _patch(d, 54, struct.pack("<H", 10001)), "more than the APY capacity"),
        (lambda d: _patch(d, 8, b"r1\0\0"), "layer extension"),
        (lambda d: _patch(d, 12, b"bad id" + b"\0" * 26), "map ID"),
        (
            lambda d: _patch(d, _first_line_record(d), struct.pack("<H", 10000)),
            "line point record 1",
        ),
        (lambda d: _patch(d, _first_line_record(d) + 14, b"\x64"), "code outside 0-99"),
        (
            lambda d: _patch(d, _first_line_record(d) + 18, struct.pack("<H", 12000)),
            "back reference",
        ),
        (
            lambda d: _patch(d, _first_line_record(d) + 2, struct.pack("<i", 10**9)),
            "X has more digits",
        ),
        (lambda d: _patch(d, 64, b"["), "metadata block is not UTF-8 JSON"),
    ],
)
def test_corrupt_files_raise_format_error_naming_the_problem(sample_dir, tmp_path, mutate, match):
    p = tmp_path / "ZH1091.r"
    p.write_bytes(mutate(_valid_bytes(sample_dir)))
    with pytest.raises(FormatError, match=match) as exc:
        apygis.read(p, driver="apy")
    assert str(p) in str(exc.value)


def test_text_with_control_bytes_is_refused(tmp_path):
    m = apygis.MapFile("T")
    m.layer("r").add_text(0, 0, 0, "abc")
    apygis.write(m, tmp_path / "T")
    data = (tmp_path / "T.r").read_bytes()
    off = len(data) - 40 + 16  # the text field of the only text record
    (tmp_path / "T.r").write_bytes(_patch(data, off, b"a\x07c"))
    with pytest.raises(FormatError, match="text record 1"):
        apygis.read(tmp_path / "T.r")
    (tmp_path / "T.r").write_bytes(_patch(data, off, b"a\0c"))
    with pytest.raises(FormatError, match="after its NUL padding"):
        apygis.read(tmp_path / "T.r")


def test_header_layout_is_as_documented(sample_dir):
    data = (sample_dir / "ZH1091.e").read_bytes()
    magic, version, hsize, ext, mid, scale, meta, ns, nl, nt, res, crc = apy.HEADER.unpack_from(
        data
    )
    assert (magic, version, hsize) == (b"APYL", 1, 64)
    assert ext.rstrip(b"\0") == b"e"
    assert mid.rstrip(b"\0") == b"ZH1091"
    assert (scale, ns, nl, nt, res) == (5000, 96, 0, 0, 0)
    assert data[64 : 64 + meta].decode().startswith('{"crs": "EPSG:2056"')
    assert crc == zlib.crc32(data[64:])
    rec = np.frombuffer(data, apy.SYMBOL_REC, ns, 64 + meta)
    m = apygis.read(sample_dir / "ZH1091.e")
    assert np.array_equal(rec["x"], np.rint(m.layers["e"].symbols["x"] * 100).astype(int))


def test_failed_write_leaves_no_file_and_no_temporary(sample_map, tmp_path, monkeypatch):
    apygis.write(sample_map, tmp_path / "ZH1091")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    sample_map.layers["r"].add_symbol(1, 1, 1, 3)

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        apygis.write(sample_map, tmp_path / "ZH1091")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_missing_map_is_a_clear_error(tmp_path):
    with pytest.raises(DriverError, match="no such file"):
        apygis.read(tmp_path / "NOPE")
    with pytest.raises(FormatError, match="no such file"):
        apygis.read(tmp_path / "NOPE", driver="apy")


# ------------------------------------------------------------------ hostile metadata (issue 9)


def _layer_with_metadata(meta: bytes) -> bytes:
    """An empty layer file ``r`` of map ``T`` whose metadata block is ``meta``, CRC valid."""
    header = apy.HEADER.pack(apy.MAGIC, 1, 64, b"r", b"T", 0, len(meta), 0, 0, 0, 0, 0)
    return _patch(header + meta, 0, b"")


@pytest.mark.parametrize(
    ("meta", "match"),
    [
        (b"[" * 10_000 + b"]" * 10_000, "JSON nested 10000 deep"),
        (b'{"notes": ' + b"[" * 5000 + b"]" * 5000 + b"}", "JSON nested 5001 deep"),
        (b'{"scale": ' + b"7" * 5000 + b"}", "an integer of 5000 digits"),
        (b'{"crs": "EPSG:2056", "x": NaN}', "NaN is not a number JSON allows"),
        (b'{"x": -Infinity}', "-Infinity is not a number JSON allows"),
        (b'{"x": 1e999}', "overflows"),
        (b'{"notes": "caf\\udcfc"}', "lone surrogate U\\+DCFC"),
        (b'{"\\ud800": 1}', "lone surrogate U\\+D800"),
        (b'{"notes": 5}', "'notes' must be a string"),
        (b'["notes"]', "not a JSON object"),
        (b"\xff{}", "not UTF-8"),
    ],
)
def test_hostile_metadata_is_a_format_error(tmp_path, meta, match):
    p = tmp_path / "T.r"
    p.write_bytes(_layer_with_metadata(meta))
    with pytest.raises(FormatError, match=match) as exc:
        apygis.read(p, driver="apy")
    assert exc.value.path == str(p)
    assert "metadata" in str(exc.value)


def test_metadata_with_valid_escapes_is_read(tmp_path):
    p = tmp_path / "T.r"
    p.write_bytes(_layer_with_metadata(b'{"notes": "caf\\u00e9 \\ud83d\\ude00", "crs": null}'))
    with pytest.raises(FormatError, match="'crs' must be a string"):
        apygis.read(p, driver="apy")
    p.write_bytes(_layer_with_metadata(b'{"notes": "caf\\u00e9 \\ud83d\\ude00"}'))
    assert apygis.read(p, driver="apy").notes == "caf\u00e9 \U0001f600"


@pytest.mark.parametrize(("offset", "value"), [(8, b"r\n\0\0"), (12, b"ZH\n" + b"\0" * 29)])
def test_header_names_with_a_line_break_are_refused(sample_dir, tmp_path, offset, value):
    """The reader's guard and the model's check_ext/check_map_id (fullmatch) both refuse."""
    p = tmp_path / "X"
    p.write_bytes(_patch(_valid_bytes(sample_dir), offset, value))
    with pytest.raises(FormatError, match=r"holds a line break|1 to 3 letters|map ID is") as exc:
        apygis.read(p, driver="apy")
    assert exc.value.path == str(p)
