"""APY ASCII: fixed columns, exact round trips with the binary format, precise errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

import apygis
from apygis.errors import FormatError
from apygis.formats import ascii as apa
from tests.formats.strategies import maps, random_rows


def test_binary_to_ascii_to_binary_is_identical(sample_dir, tmp_path):
    m = apygis.read(sample_dir / "ZH1091")
    apygis.write(m, tmp_path / "sheet.apa")
    back = apygis.read(tmp_path / "sheet.apa")
    assert back == m
    apygis.write(back, tmp_path / "bin" / "ZH1091")
    for ext in "cehr":
        a = (sample_dir / f"ZH1091.{ext}").read_bytes()
        assert (tmp_path / "bin" / f"ZH1091.{ext}").read_bytes() == a


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(m=maps())
def test_property_round_trip(m):
    assert apa.decode(apa.encode(m)) == m


def test_columns_are_as_documented():
    m = apygis.MapFile("COLS", scale=5000)
    lay = m.layer("r")
    lay.add_symbol(2683000.05, -1247000.5, -0.07, 7)
    lay.add_line([(1.0, 2.0, 3.0), (4.0, 5.0, 6.0)], code=12)
    lay.add_text(-9999999.99, 0.0, 9999.99, "  Zürich  ")
    lines = apa.encode(m).decode("utf-8").splitlines()
    assert lines[:4] == ["APY ASCII 1", "MAP COLS", "SCALE 5000", "LAYER r"]
    sym = lines[5]
    assert sym == "0001  2683000.05 -1247000.50    -0.07 07"
    assert len(sym) == 40
    assert lines[7] == "0001        1.00        2.00     3.00 12 0002 ---- ---- ----"
    assert lines[8] == "0002        4.00        5.00     6.00 12 ---- 0001 ---- ----"
    assert lines[10] == "0001 -9999999.99        0.00  9999.99   Zürich  "
    assert lines[-1] == "END"


def test_large_tables_parse_exactly():
    rng = np.random.default_rng(5)
    m = apygis.MapFile("BIG")
    m.add_layer(apygis.Layer.from_arrays("r", line_points=random_rows(rng, 10000)))
    assert apa.decode(apa.encode(m)) == m


def test_crlf_and_bom_are_accepted(sample_dir):
    text = (sample_dir / "ZH1091.apa").read_bytes()
    crlf = b"\xef\xbb\xbf" + text.replace(b"\n", b"\r\n")
    assert apa.decode(crlf) == apa.decode(text)


def _doc(rows: str, table="LINEPOINTS", n=1) -> bytes:
    return f"APY ASCII 1\nMAP T\nLAYER r\n{table} {n}\n{rows}END\n".encode()


GOOD = "0001        1.00        2.00     3.00 12 ---- ---- ---- ----\n"


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"hello\n", "line 1: not an APY ASCII file"),
        (_doc(GOOD)[:-4], "ends without END"),
        (_doc(GOOD).rstrip(b"\n"), "no line ending"),
        (
            _doc(GOOD.replace(" 1.00", " 1.0x")),
            r"line 5: X in columns 6-16: expected a right-aligned",
        ),
        (_doc(GOOD.replace("  2.00", "2.00  ")), r"line 5: Y in columns 18-28"),
        (_doc(GOOD.replace("0001", "00a1")), r"line 5: num in columns 1-4: expected 4 digits"),
        (_doc(GOOD.replace(" 12 ", " 1x ")), r"line 5: code in columns 39-40"),
        (
            _doc(GOOD.replace("---- ---- ---- ----", "---- 12-- ---- ----")),
            r"back in columns 47-50",
        ),
        (_doc(GOOD[:-2] + "\n"), r"line 5: a line point row has 60 columns, this one has 59"),
        (_doc(GOOD, n=2), "line 6: found 'END' where a line point row was expected"),
        (_doc(GOOD.replace("3.00 12", "3.00x12")), "column 38 must be blank"),
        (_doc(GOOD) + b"LAYER q\n", "data after END"),
        (b"APY ASCII 1\nMAP bad id\nLAYER r\nEND\n", "line 3: header: a map ID"),
        (b"APY ASCII 1\nMAP T\nSCALE x\nEND\n", "line 3: SCALE must be a positive integer"),
        (b"APY ASCII 1\nMAP T\nLAYER r1\nEND\n", "1 to 3 letters"),
        (b"APY ASCII 1\nMAP T\nLAYER r\nLAYER r\nEND\n", "line 4: layer r appears twice"),
        (b"APY ASCII 1\nMAP T\nSYMBOLS 0\nEND\n", "SYMBOLS before the first LAYER"),
        (b"APY ASCII 1\nMAP T\nCRS nonsense\nLAYER r\nEND\n", "not a coordinate reference system"),
        (
            b"APY ASCII 1\nMAP T\nLAYER r\nTEXTS 1\n0001        1.00        2.00     3.00\n",
            "text row",
        ),
        (
            b"APY ASCII 1\nMAP T\nLAYER r\nTEXTS 1\n"
            + b"0001        1.00        2.00     3.00 "
            + b"x" * 25
            + b"\nEND\n",
            "line 5: a text has at most 24 characters in APY ASCII",
        ),
        (b"APY ASCII 1\nMAP T\xff\nEND\n", "line 2: not UTF-8"),
    ],
)
def test_bad_input_names_the_line_and_what_was_expected(data, match, tmp_path):
    p = tmp_path / "bad.apa"
    p.write_bytes(data)
    with pytest.raises(FormatError, match=match) as exc:
        apygis.read(p, driver="ascii")
    assert str(p) in str(exc.value)


def test_map_without_layers_round_trips():
    m = apygis.MapFile("EMPTY", notes="\nblank first line")
    assert apa.decode(apa.encode(m)) == m


# ------------------------------------------------------ hostile counts and digits (issue 9)


@pytest.mark.parametrize("table", ["SYMBOLS", "LINEPOINTS", "TEXTS"])
@pytest.mark.parametrize("count", [10**7, 10**12, int("9" * 18)])
def test_huge_row_count_is_refused_without_allocating(table, count, tmp_path):
    """A count of 10**12 once allocated 116 TiB: counts are bounded by the file first."""
    import tracemalloc

    p = tmp_path / "big.apa"
    p.write_bytes(_doc(GOOD if table == "LINEPOINTS" else "", table=table, n=count))
    tracemalloc.start()
    try:
        with pytest.raises(FormatError) as exc:
            apygis.read(p, driver="ascii")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 10 * 2**20, f"{peak} bytes allocated for a file of {p.stat().st_size}"
    assert exc.value.path == str(p)
    assert exc.value.record in ("line 5", "line 6")
    assert (
        f"found 'END' where a {'line point' if table == 'LINEPOINTS' else table[:-1].lower()}"
        f" row was expected: the table header announced {count} rows" in exc.value.reason
    )


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("SCALE 5\u00b2", "line 3: SCALE must be a positive integer denominator"),
        ("SCALE \u0665000", "line 3: SCALE must be a positive integer denominator"),
        ("SCALE " + "9" * 5000, "line 3: SCALE must be"),
        ("SCALE " + "0" * 5000 + "1", None),
        ("LAYER r\nSYMBOLS \u00b2", "line 4: SYMBOLS must be followed by a row count"),
        ("LAYER r\nTEXTS 1\u00b2", "line 4: TEXTS must be followed by a row count"),
        ("LAYER r\nLINEPOINTS " + "7" * 5000, "line 4: LINEPOINTS must be followed"),
        ("LAYER r\nLINEPOINTS 1_0", "line 4: LINEPOINTS must be followed"),
    ],
)
def test_counts_and_scale_take_ascii_digits_only(line, match, tmp_path):
    """str.isdigit() accepts '²' and other scripts' digits; int() refuses or misreads them."""
    p = tmp_path / "d.apa"
    p.write_text(f"APY ASCII 1\nMAP T\n{line}\nEND\n", encoding="utf-8")
    if match is None:
        assert apygis.read(p, driver="ascii").scale == 1
        return
    with pytest.raises(FormatError, match=match):
        apygis.read(p, driver="ascii")
