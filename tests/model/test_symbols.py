"""Tests of the symbol library (apygis.model.symbols) and the .apysym format."""

from __future__ import annotations

import contextlib
import os
import random
import stat
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from apygis.errors import ApygisError, FormatError, SymbolLibraryError
from apygis.model import symbols as symmod
from apygis.model.symbols import (
    FREE_NAME,
    HEADER,
    SPOT_HEIGHT_SYMBOL,
    Symbol,
    SymbolLibrary,
    default_library,
    load_library,
    user_library_path,
)

EMPTY = "." * 15
FULL = "#" * 15


@pytest.fixture(autouse=True)
def _no_real_home(tmp_path, monkeypatch):
    """Never let a test touch the real user library."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("APYGIS_SYMBOLS", str(tmp_path / "home" / "user.apysym"))


def block(code: int, name: str, rows=None) -> str:
    rows = rows if rows is not None else [EMPTY] * 15
    return f"[{code:02d}] {name}\n" + "".join(r + "\n" for r in rows)


def doc(*blocks: str) -> str:
    return HEADER + "\n" + "".join(blocks)


# -- the default library ------------------------------------------------------------


def test_default_library_has_100_codes_and_35_designed_symbols():
    lib = default_library()
    assert len(lib) == 100
    assert list(lib) == list(range(100))
    designed = [lib[c] for c in range(1, 100) if not lib[c].is_free]
    assert len(designed) >= 35
    names = [s.name for s in designed]
    assert len(set(names)) == len(names)
    assert all(s.painted > 0 for s in designed)
    assert FREE_NAME not in names
    for name in ("trig point", "church", "chapel", "conifer", "deciduous tree", "spring"):
        assert name in names


def test_default_library_spot_height():
    lib = default_library()
    assert lib[0] == SPOT_HEIGHT_SYMBOL
    assert lib[0].name == "spot height"
    assert lib[0].is_reserved
    assert not lib[0].is_free
    # a tiny cross: the centre cell and its four arms
    bm = lib[0].bitmap
    for r, c in ((7, 7), (5, 7), (9, 7), (7, 5), (7, 9)):
        assert bm[r, c]
    assert bm.sum() == 9


def test_default_library_is_a_fresh_copy():
    a = default_library()
    a.set_name(1, "changed")
    a.paint(99, 0, 0)
    b = default_library()
    assert b.name(1) == "trig point"
    assert b[99].is_free


def test_default_file_round_trips():
    lib = default_library()
    text = lib.to_text()
    assert SymbolLibrary.from_text(text) == lib
    assert SymbolLibrary.from_text(text).to_text() == text


# -- Symbol -------------------------------------------------------------------------


def test_symbol_bitmap_is_readonly_copy():
    arr = np.zeros((15, 15), dtype=bool)
    s = Symbol(3, "x", arr)
    arr[0, 0] = True
    assert not s.bitmap[0, 0]
    with pytest.raises(ValueError, match="read-only"):
        s.bitmap[0, 0] = True
    assert s.bitmap.dtype == bool
    assert s.bitmap.shape == (15, 15)


def test_symbol_is_frozen():
    s = Symbol(3, "x", np.zeros((15, 15)))
    with pytest.raises(AttributeError):
        s.name = "y"


def test_symbol_accepts_ints_and_text_rows():
    s = Symbol(3, "x", np.eye(15, dtype=int))
    assert s.painted == 15
    rows = ["".join("#" if i == j else "." for j in range(15)) for i in range(15)]
    assert Symbol(3, "x", rows) == s
    assert s.rows == tuple(rows)


def test_symbol_equality_and_hash():
    a = Symbol(3, "x", np.eye(15))
    b = Symbol(3, "x", np.eye(15, dtype=bool))
    c = Symbol(3, "y", np.eye(15))
    assert a == b
    assert hash(a) == hash(b)
    assert a != c
    assert a != "x"
    assert repr(a) == "Symbol(code=3, name='x', painted=15)"


def test_symbol_is_free():
    zeros = np.zeros((15, 15), dtype=bool)
    assert Symbol(5, "free", zeros).is_free
    assert not Symbol(5, "well", zeros).is_free
    one = zeros.copy()
    one[3, 3] = True
    assert not Symbol(5, "free", one).is_free


@pytest.mark.parametrize(
    ("code", "name", "bitmap", "match"),
    [
        (100, "x", np.zeros((15, 15)), "out of range"),
        (-1, "x", np.zeros((15, 15)), "out of range"),
        ("7", "x", np.zeros((15, 15)), "integer"),
        (1.5, "x", np.zeros((15, 15)), "integer"),
        (1, "", np.zeros((15, 15)), "1 to 24"),
        (1, "x" * 25, np.zeros((15, 15)), "1 to 24"),
        (1, "a\tb", np.zeros((15, 15)), "printable"),
        (1, "a\nb", np.zeros((15, 15)), "printable"),
        (1, " a", np.zeros((15, 15)), "begin or end"),
        (1, "a ", np.zeros((15, 15)), "begin or end"),
        (1, 7, np.zeros((15, 15)), "string"),
        (1, "x", np.zeros((15, 14)), "shape"),
        (1, "x", np.zeros((15, 15, 1)), "shape"),
        (1, "x", np.full((15, 15), 2), "0 and 1"),
        (1, "x", np.full((15, 15), "#"), "0 and 1"),
        (1, "x", "#" * 225, "15x15"),
        (1, "x", [EMPTY] * 14, "15 rows"),
        (1, "x", [EMPTY] * 14 + ["." * 14], "15 rows"),
        (1, "x", [EMPTY] * 14 + ["." * 14 + "x"], "only '#'"),
        (1, "x", [[0, 1], [1]], "bitmap"),
    ],
)
def test_symbol_rejects(code, name, bitmap, match):
    with pytest.raises(SymbolLibraryError, match=match):
        Symbol(code, name, bitmap)


def test_symbol_name_limits():
    assert Symbol(1, "x" * 24, np.zeros((15, 15))).name == "x" * 24
    assert Symbol(1, "Brücke [alt] #3; ok", np.zeros((15, 15))).name == "Brücke [alt] #3; ok"


# -- SymbolLibrary ------------------------------------------------------------------


def test_empty_library():
    lib = SymbolLibrary()
    assert len(lib) == 100
    assert lib[0] == SPOT_HEIGHT_SYMBOL
    assert all(lib[c].is_free for c in range(1, 100))
    assert lib.free_codes == list(range(1, 100))
    assert repr(lib) == "<SymbolLibrary: 0 designed, 99 free>"


def test_library_is_a_mapping():
    lib = default_library()
    assert 0 in lib
    assert 99 in lib
    assert 100 not in lib
    assert "a" not in lib
    assert np.int64(6) in lib
    assert lib.get(100) is None
    assert lib.get(6).name == "church"
    assert lib[np.int16(6)].name == "church"
    assert dict(lib.items())[6] == lib[6]
    with pytest.raises(KeyError) as info:
        lib[100]
    assert str(info.value).startswith("symbol code 100 is out of range")
    with pytest.raises(SymbolLibraryError, match="out of range"):
        lib[-1]
    with pytest.raises(SymbolLibraryError, match="integer"):
        lib["06"]


def test_library_edit_and_equality():
    lib = SymbolLibrary()
    other = lib.copy()
    assert lib == other
    lib.set_name(12, "shrine")
    lib.paint(12, 0, 0)
    lib.paint(12, 14, 14)
    lib.paint(12, 14, 14)
    assert lib[12].painted == 2
    assert lib[12].bitmap[0, 0]
    assert lib[12].bitmap[14, 14]
    assert lib != other
    assert other[12].is_free
    lib.clear(12, 0, 0)
    lib.clear(12, 0, 0)
    assert lib[12].painted == 1
    lib.set_bitmap(12, np.ones((15, 15)))
    assert lib[12].painted == 225
    lib.set_bitmap(12, [EMPTY] * 15)
    assert lib[12].painted == 0
    assert not lib[12].is_free  # named, though empty
    lib.set_name(12, "free")
    assert lib[12].is_free
    assert lib == other
    assert lib != "library"


def test_library_returned_symbols_do_not_alias():
    lib = SymbolLibrary()
    s = lib[5]
    lib.paint(5, 1, 1)
    assert s.painted == 0
    assert lib[5].painted == 1


@pytest.mark.parametrize(
    "call",
    [
        lambda lib: lib.set_name(0, "height"),
        lambda lib: lib.set_name(0, "spot height"),
        lambda lib: lib.paint(0, 0, 0),
        lambda lib: lib.paint(0, 7, 7),
        lambda lib: lib.clear(0, 7, 7),
        lambda lib: lib.clear(0, 0, 0),
        lambda lib: lib.set_bitmap(0, np.zeros((15, 15))),
        lambda lib: lib.set_bitmap(0, SPOT_HEIGHT_SYMBOL.bitmap),
    ],
)
def test_spot_height_is_immutable(call):
    lib = default_library()
    with pytest.raises(SymbolLibraryError, match="reserved for the spot height"):
        call(lib)
    assert lib[0] == SPOT_HEIGHT_SYMBOL


def test_constructor():
    lib = SymbolLibrary([Symbol(3, "a", np.eye(15)), SPOT_HEIGHT_SYMBOL])
    assert lib.name(3) == "a"
    assert lib[3].painted == 15
    with pytest.raises(SymbolLibraryError, match="reserved"):
        SymbolLibrary([Symbol(0, "spot height", np.eye(15))])
    with pytest.raises(SymbolLibraryError, match="reserved"):
        SymbolLibrary([Symbol(0, "height", SPOT_HEIGHT_SYMBOL.bitmap)])
    with pytest.raises(SymbolLibraryError, match="twice"):
        SymbolLibrary([Symbol(3, "a", np.eye(15)), Symbol(3, "b", np.eye(15))])
    with pytest.raises(SymbolLibraryError, match="Symbol"):
        SymbolLibrary(["a"])


@pytest.mark.parametrize(
    ("row", "col", "match"),
    [
        (15, 0, "off the 15x15 grid"),
        (0, 15, "off the 15x15 grid"),
        (-1, 0, "off the 15x15 grid"),
        (0, -1, "off the 15x15 grid"),
        (1.0, 2, "integer"),
        ("1", 2, "integer"),
    ],
)
def test_cells_off_the_grid(row, col, match):
    lib = SymbolLibrary()
    with pytest.raises(SymbolLibraryError, match=match):
        lib.paint(5, row, col)
    with pytest.raises(SymbolLibraryError, match=match):
        lib.clear(5, row, col)
    assert lib[5].is_free


@pytest.mark.parametrize("code", [100, -1, 1000, "5", None])
def test_bad_codes_on_every_method(code):
    lib = SymbolLibrary()
    for call in (
        lambda: lib.name(code),
        lambda: lib.set_name(code, "x"),
        lambda: lib.paint(code, 0, 0),
        lambda: lib.clear(code, 0, 0),
        lambda: lib.set_bitmap(code, np.zeros((15, 15))),
        lambda: lib.render(code),
    ):
        with pytest.raises(SymbolLibraryError):
            call()


def test_bad_names_and_bitmaps_leave_the_library_unchanged():
    lib = default_library()
    before = lib.copy()
    with pytest.raises(SymbolLibraryError):
        lib.set_name(6, "x" * 25)
    with pytest.raises(SymbolLibraryError):
        lib.set_bitmap(6, np.zeros((14, 15)))
    assert lib == before


def test_render():
    lib = SymbolLibrary()
    lib.set_name(9, "corner")
    lib.paint(9, 0, 0)
    text = lib.render(9)
    lines = text.splitlines()
    assert lines[0] == "[09] corner  (1 cell painted)"
    assert len(lines) == 1 + 1 + 1 + 15 + 1
    assert lines[1].split() == [str(i) for i in range(1, 16)]
    assert lines[3].startswith("  1 | #  . ")
    assert lines[-2].startswith(" 15 | .  .")
    # the columns line up with their numbers
    assert lines[1].index(" 1 ") + 1 == lines[3].index("#")
    zero = lib.render(9, base=0).splitlines()
    assert zero[1].split() == [str(i) for i in range(15)]
    assert zero[3].startswith("  0 | #")
    assert lib.render(10).splitlines()[0] == "[10] free  (free)"
    assert "reserved" in lib.render(0).splitlines()[0]


# -- the text format ----------------------------------------------------------------


def test_to_text_layout():
    lib = SymbolLibrary()
    lib.set_name(7, "church")
    lib.paint(7, 1, 7)
    text = lib.to_text()
    lines = text.split("\n")
    assert lines[0] == HEADER
    assert text.endswith("\n")
    assert not text.endswith("\n\n")
    assert "[00] spot height" in lines
    assert "[99] free" in lines
    i = lines.index("[07] church")
    assert lines[i - 1] == ""
    assert lines[i + 2] == ".......#......."
    assert all(ln == ln.rstrip() for ln in lines)
    assert sum(ln.startswith("[") for ln in lines) == 100


def test_from_text_minimal_and_flexible():
    rows = [EMPTY] * 15
    rows[7] = ".......#......."
    text = (
        "\ufeff" + HEADER + "  \r\n"
        "\r\n"
        "   ; an indented comment\r\n"
        "[42] a;b # [c]\t \r\n" + "".join(r + " \r\n" for r in rows) + "\t\n"
        "; trailing comment"
    )
    lib = SymbolLibrary.from_text(text)
    assert lib.name(42) == "a;b # [c]"
    assert lib[42].painted == 1
    assert lib[42].bitmap[7, 7]
    assert lib[1].is_free
    assert lib[0] == SPOT_HEIGHT_SYMBOL
    # bytes work too
    assert SymbolLibrary.from_text(text.encode()) == lib
    assert SymbolLibrary.from_text(bytearray(text.encode())) == lib


def test_from_text_blocks_in_any_order_and_explicit_spot_height():
    a = block(9, "nine", [FULL] * 15)
    b = block(3, "three")
    spot = block(0, "spot height", list(SPOT_HEIGHT_SYMBOL.rows))
    lib = SymbolLibrary.from_text(doc(a, b, spot))
    assert lib.name(9) == "nine"
    assert lib[9].painted == 225
    assert lib.name(3) == "three"
    assert not lib[3].is_free
    assert SymbolLibrary.from_text(doc(b, a)) == lib


def test_header_only_is_an_empty_library():
    assert SymbolLibrary.from_text(HEADER) == SymbolLibrary()
    assert SymbolLibrary.from_text(HEADER + "\n") == SymbolLibrary()


def test_from_text_type_error():
    with pytest.raises(TypeError):
        SymbolLibrary.from_text(42)


SPOT = list(SPOT_HEIGHT_SYMBOL.rows)
ROWS = [EMPTY] * 15


def _rows_with(i, row):
    r = list(ROWS)
    r[i] = row
    return r


BAD_TEXTS = [
    # (text, line number, words in the message)
    ("", 1, "empty"),
    ("\n", 1, "expected the header"),
    ("APYSYM 2\n", 1, "unsupported version"),
    ("APYSYM\n", 1, "expected the header"),
    ("APYSYM 1 extra\n", 1, "expected the header"),
    ("apysym 1\n", 1, "expected the header"),
    ("[01] x\n", 1, "expected the header"),
    (" APYSYM 1\n", 1, "expected the header"),
    (doc("[1] x\n"), 2, "two digits"),
    (doc("[007] x\n"), 2, "two digits"),
    (doc("[100] x\n"), 2, "out of range"),
    (doc("[-1] x\n"), 2, "out of range"),
    (doc("[" + "9" * 6000 + "] x\n"), 2, "out of range"),
    (doc("[" + "0" * 6000 + "] x\n"), 2, "two digits"),
    (doc("[01]x\n"), 2, "symbol header"),
    (doc("[01]\n"), 2, "symbol header"),
    (doc("[01] \n"), 2, "symbol header"),
    (doc("[ab] x\n"), 2, "symbol header"),
    (doc("[٠١] x\n"), 2, "symbol header"),  # Arabic-Indic digits are not digits here
    (doc(" [01] x\n"), 2, "expected a symbol header"),
    (doc("[01]  x\n" + "".join(r + "\n" for r in ROWS)), 2, "begin or end with a space"),
    (doc(block(1, "y" * 25)), 2, "1 to 24"),
    (doc(block(1, "a\x0bb")), 2, "printable"),
    (doc(block(1, "a\u2028b")), 2, "printable"),
    (doc(block(1, "a\x00b")), 2, "printable"),
    (doc(block(1, "a"), block(2, "b"), block(1, "c")), 34, "duplicate symbol 01"),
    (doc(block(1, "a", _rows_with(3, "." * 14))), 6, "expected 15 characters"),
    (doc(block(1, "a", _rows_with(3, "." * 16))), 6, "found 16"),
    (doc(block(1, "a", _rows_with(3, ""))), 6, "empty line"),
    (doc(block(1, "a", _rows_with(3, "; a comment !!!"))), 6, "bad character ';'"),
    (doc(block(1, "a", _rows_with(3, " .............."))), 6, "bad character ' '"),
    (doc(block(1, "a", _rows_with(14, "......X........"))), 17, "column 7"),
    (doc(block(1, "a", _rows_with(0, "...\x00..........."))), 3, "bad character"),
    (doc(block(1, "a", _rows_with(0, "...\u2028..........."))), 3, "bad character"),
    (doc("[01] a\n" + EMPTY + "\n"), 4, "found 1 before the end of file"),
    (doc("[01] a\n"), 3, "found 0 before the end of file"),
    (doc(block(1, "a") + EMPTY + "\n"), 18, "more than 15 bitmap rows"),
    (doc(block(1, "a") + "\n" + EMPTY + "\n"), 19, "expected a symbol header"),
    (doc("# not a comment\n"), 2, "expected a symbol header"),
    (doc("x\n"), 2, "expected a symbol header"),
    (doc(block(0, "spot height", ROWS)), 2, "reserved for the spot height"),
    (doc(block(0, "height", SPOT)), 2, "reserved for the spot height"),
    (doc(block(0, "free", ROWS)), 2, "reserved for the spot height"),
    ("APYSYM 1\r[01] a\r", 1, "must end with LF"),
]


@pytest.mark.parametrize(("text", "line", "words"), BAD_TEXTS)
def test_reader_errors(text, line, words):
    with pytest.raises(FormatError) as info:
        SymbolLibrary.from_text(text, path="lib.apysym")
    err = info.value
    assert err.path == "lib.apysym"
    assert err.record == f"line {line}"
    assert words in err.reason
    assert str(err).startswith(f"lib.apysym: line {line}: ")
    assert isinstance(err, ValueError)


def test_reader_error_without_path():
    with pytest.raises(FormatError) as info:
        SymbolLibrary.from_text("nope")
    assert str(info.value).startswith("line 1: expected the header")


@pytest.mark.parametrize(
    ("data", "line"),
    [
        (b"\xff\xfe" + HEADER.encode(), 1),
        (HEADER.encode() + b"\n[01] caf\xe9\n", 2),
        (doc(block(1, "a")).encode() + b"\n\n\x80", 20),
        (HEADER.encode() + b"\n[01] \xed\xa0\x80\n", 2),  # an encoded surrogate
    ],
)
def test_reader_non_utf8(tmp_path, data, line):
    path = tmp_path / "bad.apysym"
    path.write_bytes(data)
    with pytest.raises(FormatError, match="UTF-8") as info:
        SymbolLibrary.read(path)
    assert info.value.record == f"line {line}"
    assert info.value.path == str(path)
    with pytest.raises(FormatError, match="UTF-8"):
        SymbolLibrary.from_text(data)


def test_reader_lone_surrogate_in_str():
    with pytest.raises(FormatError, match="printable"):
        SymbolLibrary.from_text(doc(block(1, "a\ud800")))


# -- round trips --------------------------------------------------------------------

_name_chars = st.characters(
    blacklist_categories=("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp", "Zs"),
) | st.just(" ")
names = st.text(_name_chars, min_size=1, max_size=24).filter(
    lambda s: s.isprintable() and not s.startswith(" ") and not s.endswith(" ")
)
bitmaps = hnp.arrays(np.bool_, (15, 15))
symbol_lists = st.dictionaries(st.integers(1, 99), st.tuples(names, bitmaps), max_size=12).map(
    lambda d: [Symbol(c, n, b) for c, (n, b) in d.items()]
)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(symbol_lists)
@example([Symbol(1, "free", np.ones((15, 15), dtype=bool))])
@example([Symbol(99, "#" * 24, np.zeros((15, 15), dtype=bool))])
@example([Symbol(5, "[05] x", np.eye(15, dtype=bool)), Symbol(6, ";", np.eye(15))])
def test_round_trip_library_text_library(syms):
    lib = SymbolLibrary(syms)
    text = lib.to_text()
    again = SymbolLibrary.from_text(text)
    assert again == lib
    assert again.to_text() == text
    for s in syms:
        assert again[s.code] == s


@settings(max_examples=100, deadline=None)
@given(symbol_lists, st.randoms(use_true_random=False))
def test_round_trip_text_library_text(syms, rnd):
    """A hand-written file (blocks shuffled, comments, free slots left out) normalises."""
    blocks = [block(s.code, s.name, list(s.rows)) for s in syms]
    rnd.shuffle(blocks)
    text = HEADER + "\n; comment\n" + "\n".join(blocks)
    lib = SymbolLibrary.from_text(text)
    canonical = lib.to_text()
    assert SymbolLibrary.from_text(canonical).to_text() == canonical
    assert lib == SymbolLibrary(syms)


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=400))
def test_reader_arbitrary_text_after_header(tail):
    with contextlib.suppress(FormatError):
        SymbolLibrary.from_text(HEADER + "\n" + tail)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400))
def test_reader_arbitrary_bytes(data):
    with contextlib.suppress(FormatError):
        SymbolLibrary.from_text(data)


# -- fuzz ---------------------------------------------------------------------------


def _mutations(seed: int, n: int):
    rnd = random.Random(seed)
    base = default_library()
    base.set_name(50, "Brücke")
    base.paint(50, 3, 4)
    sources = [base.to_text().encode(), doc(block(3, "x"), block(4, "y", [FULL] * 15)).encode()]
    for _ in range(n):
        data = bytearray(rnd.choice(sources))
        kind = rnd.randrange(9)
        if kind == 0:  # truncation
            data = data[: rnd.randrange(len(data) + 1)]
        elif kind == 1:  # byte flips
            for _ in range(rnd.randint(1, 8)):
                i = rnd.randrange(len(data))
                data[i] ^= 1 << rnd.randrange(8)
        elif kind == 2:  # random bytes overwritten
            for _ in range(rnd.randint(1, 8)):
                data[rnd.randrange(len(data))] = rnd.randrange(256)
        elif kind == 3:  # insert a line
            lines = data.split(b"\n")
            pick = rnd.choice(
                [b"", b"; c", b"#" * 15, b"." * 15, b"[07] x", b"[100] y", rnd.randbytes(15)]
            )
            lines.insert(rnd.randrange(len(lines) + 1), pick)
            data = bytearray(b"\n".join(lines))
        elif kind == 4:  # delete lines
            lines = data.split(b"\n")
            for _ in range(rnd.randint(1, 3)):
                if lines:
                    del lines[rnd.randrange(len(lines))]
            data = bytearray(b"\n".join(lines))
        elif kind == 5:  # duplicate or swap lines
            lines = data.split(b"\n")
            i, j = rnd.randrange(len(lines)), rnd.randrange(len(lines))
            if rnd.random() < 0.5:
                lines.insert(j, lines[i])
            else:
                lines[i], lines[j] = lines[j], lines[i]
            data = bytearray(b"\n".join(lines))
        elif kind == 6:  # purely random bytes, sometimes after a header
            junk = rnd.randbytes(rnd.randrange(300))
            data = bytearray((HEADER.encode() + b"\n" if rnd.random() < 0.5 else b"") + junk)
        elif kind == 7:  # a character changed inside a row or a header
            lines = data.split(b"\n")
            i = rnd.randrange(len(lines))
            if lines[i]:
                k = rnd.randrange(len(lines[i]))
                ch = rnd.choice([b"#", b".", b" ", b"[", b"]", b";", b"\t", b"\r", b"\xc3"])
                lines[i] = lines[i][:k] + ch + lines[i][k + 1 :]
            data = bytearray(b"\n".join(lines))
        else:  # a block header's code or name changed
            lines = data.split(b"\n")
            heads = [i for i, ln in enumerate(lines) if ln.startswith(b"[")]
            if heads:
                i = rnd.choice(heads)
                code = rnd.choice([b"00", b"01", b"99", b"7", b"100", b"-1", b"aa", b""])
                lines[i] = b"[" + code + b"] " + rnd.choice([b"x", b"", b" y", b"z" * 30])
            data = bytearray(b"\n".join(lines))
        yield bytes(data)


def test_fuzz_reader_only_raises_format_errors(tmp_path):
    outcomes = {"ok": 0, "error": 0}
    path = tmp_path / "fuzz.apysym"
    for i, data in enumerate(_mutations(seed=20240501, n=1500)):
        lib, err = None, None
        try:
            if i % 10 == 0:  # the file path as well as the in-memory one
                path.write_bytes(data)
                lib = SymbolLibrary.read(path)
            else:
                lib = SymbolLibrary.from_text(data, path="fuzz.apysym")
        except ApygisError as exc:  # anything else escapes and fails the test
            err = exc
        if err is not None:
            assert isinstance(err, FormatError), repr(err)
            assert (err.record or "").startswith("line "), repr(err)
            outcomes["error"] += 1
        else:
            outcomes["ok"] += 1
            # whatever was accepted writes back and reads the same
            assert SymbolLibrary.from_text(lib.to_text()) == lib
            assert lib[0] == SPOT_HEIGHT_SYMBOL
    assert sum(outcomes.values()) == 1500
    assert outcomes["error"] > 500  # the mutations do break files
    assert outcomes["ok"] > 50  # and some survive (comments, blank lines, names)


# -- files --------------------------------------------------------------------------


def test_write_and_read(tmp_path):
    lib = default_library()
    lib.set_name(60, "Kapelle")
    lib.paint(60, 7, 7)
    path = tmp_path / "lib.apysym"
    lib.write(path)
    assert SymbolLibrary.read(path) == lib
    assert SymbolLibrary.read(str(path)) == lib
    assert path.read_bytes() == lib.to_text().encode("utf-8")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib.apysym"]


def test_write_replaces_and_keeps_mode(tmp_path):
    path = tmp_path / "lib.apysym"
    path.write_text("old")
    if sys.platform != "win32":
        os.chmod(path, 0o640)
    SymbolLibrary().write(path)
    assert SymbolLibrary.read(path) == SymbolLibrary()
    if sys.platform != "win32":
        assert stat.S_IMODE(os.stat(path).st_mode) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib.apysym"]


def test_write_failure_leaves_target_and_no_temp(tmp_path, monkeypatch):
    path = tmp_path / "lib.apysym"
    path.write_text("old content")

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(symmod.os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        default_library().write(path)
    assert path.read_text() == "old content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib.apysym"]


def test_write_into_missing_directory(tmp_path):
    with pytest.raises(FileNotFoundError):
        SymbolLibrary().write(tmp_path / "no" / "such" / "lib.apysym")


def test_read_missing_file(tmp_path):
    path = tmp_path / "missing.apysym"
    with pytest.raises(FormatError, match="no such symbol library file") as exc:
        SymbolLibrary.read(path)
    assert exc.value.path == str(path)


def _symlink_loop(tmp_path):
    a, b = tmp_path / "a.apysym", tmp_path / "b.apysym"
    try:
        os.symlink(b, a)
        os.symlink(a, b)
    except (OSError, NotImplementedError):  # pragma: no cover - no symlinks here
        pytest.skip("symbolic links are not available")
    return a


@pytest.mark.parametrize("kind", ["directory", "missing", "loop", "notdir"])
def test_unreadable_library_path_is_a_format_error_naming_it(tmp_path, kind):
    """Issue 9: a directory, a missing file or a symlink loop escaped as a bare OSError."""
    if kind == "directory":
        path, match = tmp_path, "is a directory"
    elif kind == "missing":
        path, match = tmp_path / "gone.apysym", "no such symbol library file"
    elif kind == "loop":
        path, match = _symlink_loop(tmp_path), "loop of symbolic links"
    else:
        (tmp_path / "plain").write_text("x")
        path, match = tmp_path / "plain" / "lib.apysym", "not a directory"
    with pytest.raises(FormatError, match=match) as exc:
        SymbolLibrary.read(path)
    assert exc.value.path == str(path)
    assert not isinstance(exc.value, OSError)
    if kind == "missing":
        assert load_library(path) == default_library()  # documented: the default set
    else:
        with pytest.raises(FormatError, match=match) as exc:
            load_library(path)
        assert exc.value.path == str(path)


def test_library_from_env_that_is_a_loop(tmp_path, monkeypatch):
    monkeypatch.setenv("APYGIS_SYMBOLS", str(_symlink_loop(tmp_path)))
    with pytest.raises(FormatError, match="loop of symbolic links"):
        load_library()


def test_user_library_path(tmp_path, monkeypatch):
    monkeypatch.setenv("APYGIS_SYMBOLS", str(tmp_path / "mine.apysym"))
    assert user_library_path() == tmp_path / "mine.apysym"
    monkeypatch.setenv("APYGIS_SYMBOLS", "~/x.apysym")
    assert user_library_path() == tmp_path / "home" / "x.apysym"
    monkeypatch.setenv("APYGIS_SYMBOLS", "")
    assert user_library_path() == tmp_path / "home" / ".config" / "apygis" / "symbols.apysym"
    monkeypatch.delenv("APYGIS_SYMBOLS")
    assert user_library_path() == tmp_path / "home" / ".config" / "apygis" / "symbols.apysym"


def test_load_library(tmp_path, monkeypatch):
    assert load_library() == default_library()
    assert load_library(tmp_path / "nothing.apysym") == default_library()
    mine = SymbolLibrary()
    mine.set_name(8, "mine")
    path = tmp_path / "mine.apysym"
    mine.write(path)
    assert load_library(path) == mine
    monkeypatch.setenv("APYGIS_SYMBOLS", str(path))
    assert load_library() == mine
    path.write_text("garbage")
    with pytest.raises(FormatError, match="header"):
        load_library()
