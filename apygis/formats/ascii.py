"""APY ASCII: the "Make ASCII file" / "Read ASCII file" exchange format.

One UTF-8 text file holds a whole map in fixed columns, specified in
``docs/formats/apy-ascii.md``::

    APY ASCII 1
    MAP ZH1091
    SCALE 5000
    CRS EPSG:2056
    NOTE compiled 2026-11-22
    LAYER r
    SYMBOLS 1
    0001  2600001.00  1200002.00   403.50 07
    LINEPOINTS 2
    0001  2600000.01  1200000.02   400.03 12 0002 ---- ---- ----
    0002  2600010.00  1200000.00   401.00 12 ---- 0001 ---- ----
    TEXTS 1
    0001  2600001.00  1200002.00   403.50 Kirchweg
    END

Coordinates are metres with exactly two decimals (the centimetres of the
binary format, so binary -> ASCII -> binary is exact). The table rows are
written and parsed as byte matrices: a million line points take a few array
operations, not a Python loop per row.
"""

from __future__ import annotations

from typing import Any, NoReturn

import numpy as np

from apygis.errors import FormatError
from apygis.formats import Driver, Option
from apygis.formats._apycommon import check_layer_for_apy, cm_to_m, fit_texts, m_to_cm
from apygis.formats._io import atomic_write_many, check_resolution, read_bytes
from apygis.formats._readguard import ascii_int, check_coords
from apygis.formats._text import digit_columns, put_right
from apygis.model.map import Layer, MapFile, check_ext, check_map_id, check_text, crs_string
from apygis.model.records import (
    LINE_DTYPE,
    NO_REF,
    REF_FIELDS,
    SYMBOL_DTYPE,
    TEXT_DTYPE,
    TEXT_LEN,
)

__all__ = ["DRIVER", "read", "write"]

MAGIC = "APY ASCII 1"

# (field, first column, width) with 0-based columns; see docs/formats/apy-ascii.md
_COMMON = (("num", 0, 4), ("x", 5, 11), ("y", 17, 11), ("z", 29, 8))
SYMBOL_COLS = (*_COMMON, ("code", 38, 2))
LINE_COLS = (
    *_COMMON,
    ("code", 38, 2),
    ("fwd", 41, 4),
    ("back", 46, 4),
    ("side1", 51, 4),
    ("side2", 56, 4),
)
SYMBOL_WIDTH = 40
LINE_WIDTH = 60
TEXT_COL = 38  # 0-based column where the text starts; column 37 is blank
_SP, _DOT, _MINUS, _ZERO = 32, 46, 45, 48


# --------------------------------------------------------------------------- encode


def _put_int(out: np.ndarray, col: int, width: int, values: np.ndarray) -> None:
    """Zero-padded unsigned integers of ``width`` digits."""
    out[:, col : col + width] = digit_columns(values, width)


def _put_ref(out: np.ndarray, col: int, values: np.ndarray) -> None:
    _put_int(out, col, 4, np.where(values == NO_REF, 0, values))
    out[values == NO_REF, col : col + 4] = _MINUS


def _put_dec(out: np.ndarray, col: int, width: int, cm: np.ndarray) -> None:
    """Right-aligned metres with two decimals from integer centimetres."""
    a = np.abs(cm)
    nint = width - 3  # columns for the sign and the integer digits
    put_right(out, col, nint, a // 100, cm < 0)
    out[:, col + nint] = _DOT
    out[:, col + nint + 1 : col + width] = digit_columns(a % 100, 2)


def _encode_rows(table: np.ndarray, cols, width: int) -> bytes:
    n = len(table)
    out = np.full((n, width + 1), _SP, dtype=np.uint8)
    out[:, width] = 10
    for name, col, w in cols:
        if name in ("x", "y", "z"):
            _put_dec(out, col, w, m_to_cm(table[name]))
        elif name in REF_FIELDS:
            _put_ref(out, col, table[name].astype(np.int64))
        else:
            _put_int(out, col, w, table[name].astype(np.int64))
    return out.tobytes()


def encode(map_: MapFile, path=None) -> bytes:
    """The APY ASCII text of a map, as UTF-8 bytes."""
    for lay in map_:
        check_layer_for_apy(lay, path)
    head = [MAGIC, f"MAP {map_.id}"]
    if map_.scale:
        head.append(f"SCALE {map_.scale}")
    if map_.crs is not None:
        head.append(f"CRS {crs_string(map_.crs)}")
    if map_.notes:
        head += [f"NOTE {line}" if line else "NOTE" for line in map_.notes.split("\n")]
    parts = ["\n".join(head).encode("utf-8") + b"\n"]
    for lay in map_:
        parts.append(f"LAYER {lay.ext}\nSYMBOLS {len(lay.symbols)}\n".encode())
        parts.append(_encode_rows(lay.symbols, SYMBOL_COLS, SYMBOL_WIDTH))
        parts.append(f"LINEPOINTS {len(lay.line_points)}\n".encode())
        parts.append(_encode_rows(lay.line_points, LINE_COLS, LINE_WIDTH))
        tx = lay.texts
        parts.append(f"TEXTS {len(tx)}\n".encode())
        if len(tx):
            prefix = np.frombuffer(_encode_rows(tx, _COMMON, TEXT_COL - 1), dtype=np.uint8).reshape(
                len(tx), TEXT_COL
            )
            prefix = prefix[:, : TEXT_COL - 1]
            lines = [
                p.tobytes() + b" " + t.encode("utf-8") + b"\n"
                for p, t in zip(prefix, tx["text"].tolist(), strict=True)
            ]
            parts.append(b"".join(lines))
    parts.append(b"END\n")
    return b"".join(parts)


# --------------------------------------------------------------------------- decode


class _Reader:
    """Walks the file line by line for the headers and block by block for the tables."""

    def __init__(self, data: bytes, path):
        self.data = data
        self.path = path
        self.pos = 0
        self.line_no = 0
        first_nl = data.find(b"\n")
        self.eol = b"\r\n" if first_nl > 0 and data[first_nl - 1 : first_nl] == b"\r" else b"\n"

    def fail(self, msg: str, line: int | None = None) -> NoReturn:
        raise FormatError(msg, path=self.path, record=f"line {line or self.line_no}")

    def next_line(self) -> str | None:
        if self.pos >= len(self.data):
            return None
        end = self.data.find(b"\n", self.pos)
        if end < 0:
            self.line_no += 1
            self.fail("the last line has no line ending (is the file truncated?)")
        raw = self.data[self.pos : end]
        self.pos = end + 1
        self.line_no += 1
        if self.eol == b"\r\n":
            if not raw.endswith(b"\r"):
                self.fail("line ends with LF where the file uses CR LF")
            raw = raw[:-1]
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            self.fail(f"not UTF-8 ({exc.reason} at byte {exc.start})")

    def check_room(self, n: int, width: int, what: str) -> None:
        """Refuse a row count that the rest of the file cannot hold, before allocating.

        The first row that is missing or wrong is named when there is one
        (a walk over the lines that are there, so bounded by the file).
        """
        room = (len(self.data) - self.pos) // (width + len(self.eol))
        if n > room:
            save = self.pos, self.line_no
            self._explain_block(n, width, what)  # raises on a short or bad row
            self.pos, self.line_no = save  # pragma: no cover - the rows were all there
            self.fail(
                f"the {what} table announces {n} rows, but the rest of the file has room "
                f"for at most {room}"
            )  # pragma: no cover

    def block(self, n: int, width: int, what: str) -> np.ndarray:
        """``n`` fixed-width rows as an (n, width) uint8 matrix."""
        self.check_room(n, width, what)
        el = len(self.eol)
        size = n * (width + el)
        chunk = self.data[self.pos : self.pos + size]
        ok = len(chunk) == size
        if ok:
            m = np.frombuffer(chunk, dtype=np.uint8).reshape(n, width + el)
            ends = m[:, width:] == np.frombuffer(self.eol, dtype=np.uint8)
            ok = bool(ends.all())
        if not ok:
            self._explain_block(n, width, what)
        self.pos += size
        start = self.line_no + 1
        self.line_no += n
        self.block_start = start
        return m[:, :width]

    def _explain_block(self, n: int, width: int, what: str) -> NoReturn:
        """Find the first row that is not ``width`` columns and say so."""
        for _ in range(n):
            save = self.pos
            line = self.next_line()
            if line is None:
                self.fail(f"the file ends inside the {what} table (expected {n} rows)")
            if _is_header(line):
                self.fail(
                    f"found {line.split()[0]!r} where a {what} row was expected: "
                    f"the table header announced {n} rows"
                )
            nbytes = self.pos - save - len(self.eol)
            if nbytes != width:
                self.fail(f"a {what} row has {width} columns, this one has {nbytes}")
        self.fail(f"unreadable {what} table")  # pragma: no cover - rows were all fine


def _is_header(line: str) -> bool:
    word = line.split(" ", 1)[0]
    return word in {"LAYER", "SYMBOLS", "LINEPOINTS", "TEXTS", "END", "MAP", "SCALE", "CRS", "NOTE"}


def _digits(m: np.ndarray) -> np.ndarray:
    return (m >= _ZERO) & (m <= _ZERO + 9)


def _bad_row(
    rd: _Reader, bad: np.ndarray | np.bool_, col: int, width: int, name: str, expected: str, m
) -> NoReturn:
    i = int(np.flatnonzero(bad)[0])
    found = m[i, col : col + width].tobytes().decode("latin-1")
    rd.fail(
        f"{name} in columns {col + 1}-{col + width}: expected {expected}, found {found!r}",
        line=rd.block_start + i,
    )


def _get_int(rd, m, col, width, name):
    f = m[:, col : col + width]
    bad = ~_digits(f).all(axis=1)
    if bad.any():
        _bad_row(rd, bad, col, width, name, f"{width} digits", m)
    pw = 10 ** np.arange(width - 1, -1, -1, dtype=np.int64)
    return ((f.astype(np.int64) - _ZERO) * pw).sum(axis=1)


def _get_ref(rd, m, col, name):
    f = m[:, col : col + 4]
    none = (f == _MINUS).all(axis=1)
    bad = ~(_digits(f).all(axis=1) | none)
    if bad.any():
        _bad_row(rd, bad, col, 4, name, "4 digits or ----", m)
    pw = np.array([1000, 100, 10, 1], dtype=np.int64)
    return np.where(none, NO_REF, ((f.astype(np.int64) - _ZERO) * pw).sum(axis=1))


def _get_dec(rd, m, col, width, name):
    """Right-aligned ``[-]d+.dd`` in ``width`` columns -> integer centimetres."""
    f = m[:, col : col + width]
    n = len(f)
    nint = width - 3
    ip = f[:, :nint]
    isd = _digits(ip)
    nonsp = ip != _SP
    first = np.argmax(nonsp, axis=1)
    rows = np.arange(n)
    cols = np.arange(nint)
    after = cols[None, :] > first[:, None]
    lead_ok = isd[rows, first] | ((ip[rows, first] == _MINUS) & (first < nint - 1))
    ok = (
        nonsp.any(axis=1)
        & lead_ok
        & np.all(~after | isd, axis=1)
        & (f[:, nint] == _DOT)
        & _digits(f[:, nint + 1 :]).all(axis=1)
    )
    if not ok.all():
        _bad_row(rd, ~ok, col, width, name, "a right-aligned number with two decimals", m)
    pw = 10 ** np.arange(nint - 1, -1, -1, dtype=np.int64)
    digits = np.where(isd, ip.astype(np.int64) - _ZERO, 0)
    cm = (digits * pw).sum(axis=1) * 100
    cm += (f[:, nint + 1].astype(np.int64) - _ZERO) * 10 + (f[:, nint + 2].astype(np.int64) - _ZERO)
    neg = ip[rows, first] == _MINUS
    return np.where(neg, -cm, cm)


def _get_seps(rd, m, cols, width):
    """Every column that no field covers must be blank."""
    covered = np.zeros(width, dtype=bool)
    for _, c, w in cols:
        covered[c : c + w] = True
    gaps = np.flatnonzero(~covered)
    bad = (m[:, gaps] != _SP).any(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        c = int(gaps[np.flatnonzero(m[i, gaps] != _SP)[0]])
        rd.fail(
            f"column {c + 1} must be blank (fields are separated by one space)",
            line=rd.block_start + i,
        )


def _parse_table(rd, m, cols, width, dtype):
    _get_seps(rd, m, cols, width)
    out = np.zeros(len(m), dtype)
    for name, col, w in cols:
        if name in ("x", "y", "z"):
            out[name] = cm_to_m(_get_dec(rd, m, col, w, name.upper()))
        elif name in REF_FIELDS:
            out[name] = _get_ref(rd, m, col, name)
        else:
            v = _get_int(rd, m, col, w, name)
            out[name] = v
    check_coords(
        np.column_stack([out["x"], out["y"], out["z"]]),
        rd.path,
        lambda i: f"line {rd.block_start + i}",
    )
    return out


def decode(data: bytes, path=None) -> MapFile:
    """Parse APY ASCII bytes into a MapFile; raises FormatError naming the line."""
    rd = _Reader(data, path)
    if data.startswith(b"\xef\xbb\xbf"):
        rd.pos = 3
    first = rd.next_line()
    if first is None:
        raise FormatError(f"the file is empty: not an APY ASCII file (it begins {MAGIC!r})", path)
    if first != MAGIC:
        rd.fail(f"not an APY ASCII file: the first line must be {MAGIC!r}")
    header: dict[str, Any] = {"id": None, "scale": None, "crs": None, "notes": []}
    m = None
    layer_parts: dict | None = None
    layer_ext = None
    layers: list[tuple[str, dict]] = []
    while True:
        line = rd.next_line()
        if line is None:
            rd.fail("the file ends without END (is it truncated?)")
        word, _, rest = line.partition(" ")
        if word == "END" and not rest:
            break
        if m is None and word in ("MAP", "SCALE", "CRS", "NOTE"):
            if word == "MAP":
                header["id"] = rest
            elif word == "SCALE":
                scale = ascii_int(rest)
                if scale is None or scale < 1:
                    rd.fail(
                        "SCALE must be a positive integer denominator (digits 0-9), "
                        f"not {rest[:40]!r}"
                    )
                header["scale"] = scale
            elif word == "CRS":
                header["crs"] = rest
            else:
                header["notes"].append(rest)
            continue
        if word == "LAYER":
            if m is None:
                m = _make_map(rd, header)
            try:
                layer_ext = check_ext(rest)
            except ValueError as exc:
                rd.fail(str(exc))
            if any(e == layer_ext for e, _ in layers):
                rd.fail(f"layer {layer_ext} appears twice")
            layer_parts = {}
            layers.append((layer_ext, layer_parts))
            continue
        if word in ("SYMBOLS", "LINEPOINTS", "TEXTS"):
            if layer_parts is None:
                rd.fail(f"{word} before the first LAYER line")
            if word in layer_parts:
                rd.fail(f"a second {word} table in layer {layer_ext}")
            n = ascii_int(rest)
            if n is None:
                rd.fail(f"{word} must be followed by a row count (digits 0-9), not {rest[:40]!r}")
            if word == "SYMBOLS":
                mat = rd.block(n, SYMBOL_WIDTH, "symbol")
                layer_parts[word] = _parse_table(rd, mat, SYMBOL_COLS, SYMBOL_WIDTH, SYMBOL_DTYPE)
            elif word == "LINEPOINTS":
                mat = rd.block(n, LINE_WIDTH, "line point")
                layer_parts[word] = _parse_table(rd, mat, LINE_COLS, LINE_WIDTH, LINE_DTYPE)
            else:
                layer_parts[word] = _read_texts(rd, n)
            continue
        rd.fail(f"unexpected line {line[:40]!r}")
    trailing = rd.data[rd.pos :]
    if trailing.strip(b"\r\n\t "):
        rd.fail("data after END", line=rd.line_no + 1)
    if m is None:
        m = _make_map(rd, header)
    for ext, parts in layers:
        m.add_layer(
            Layer.from_arrays(
                ext, parts.get("SYMBOLS"), parts.get("LINEPOINTS"), parts.get("TEXTS")
            )
        )
    return m


def _make_map(rd: _Reader, header: dict) -> MapFile:
    if header["id"] is None:
        rd.fail("no MAP line before the first LAYER")
    try:
        check_map_id(header["id"])
        return MapFile(
            header["id"], scale=header["scale"], crs=header["crs"], notes="\n".join(header["notes"])
        )
    except ValueError as exc:
        rd.fail(f"header: {exc}")


def _read_texts(rd: _Reader, n: int) -> np.ndarray:
    # rows are collected, not preallocated: a count of 10**12 ends at the end of the file
    rows = []
    for _ in range(n):
        line = rd.next_line()
        if line is None:
            rd.fail(f"the file ends inside the text table (expected {n} rows)")
        if len(line) < TEXT_COL and _is_header(line):
            rd.fail(
                f"found {line.split()[0]!r} where a text row was expected: "
                f"the table header announced {n} rows"
            )
        if len(line) < TEXT_COL or line[TEXT_COL - 1] != " ":
            rd.fail(f"a text row has {TEXT_COL - 1} columns of fields, a blank and the text")
        raw = line[: TEXT_COL - 1].encode("latin-1", errors="replace")
        mat = np.frombuffer(raw, dtype=np.uint8).reshape(1, TEXT_COL - 1)
        rd.block_start = rd.line_no
        row = _parse_table(rd, mat, _COMMON, TEXT_COL - 1, TEXT_DTYPE)[0]
        try:
            text = check_text(line[TEXT_COL:])
        except ValueError as exc:
            rd.fail(str(exc))
        if len(text) > TEXT_LEN:
            rd.fail(
                f"a text has at most {TEXT_LEN} characters in APY ASCII, {text!r} has {len(text)}"
            )
        rows.append((row["num"], row["x"], row["y"], row["z"], text))
    out = np.zeros(len(rows), TEXT_DTYPE)
    for k, r in enumerate(rows):
        out[k] = r
    return out


# --------------------------------------------------------------------------- API


def probe(path) -> bool:
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(MAGIC) + 4)
    except OSError:
        return False
    return head.lstrip(b"\xef\xbb\xbf").startswith(MAGIC.encode())


def read(path, progress=None) -> MapFile:
    """Read an APY ASCII file."""
    m = decode(read_bytes(path), path)
    if progress:
        progress(1, 1)
    return m


def write(map_: MapFile, path, progress=None, cut_texts: bool = False) -> list:
    """Write a map as APY ASCII, atomically.

    A map whose CRS unit makes centimetres of a unit coarser than 1 cm (degrees)
    is refused: the format stores hundredths of a unit. Texts longer than 24
    characters are refused, or with ``cut_texts`` cut (with a warning).
    """
    map_ = fit_texts(map_, path, cut_texts)
    check_resolution(map_, path, 0.01, "APY ASCII stores coordinates in hundredths of a unit")
    from pathlib import Path

    out = atomic_write_many({Path(path): encode(map_, path)})
    if progress:
        progress(1, 1)
    return out


DRIVER = Driver(
    name="ascii",
    description="APY ASCII exchange file, fixed columns (docs/formats/apy-ascii.md)",
    extensions=("apa",),
    reader=read,
    writer=write,
    probe=probe,
    stream=True,
    options=(Option("cut_texts", "w", "bool", "cut texts to APY's 24 characters"),),
)
