"""The E00 parser: the sections of a plain E00 file to plain data (arrays, INFO tables)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NoReturn

import numpy as np

from apygis.errors import FormatError
from apygis.formats._readguard import MAX_COORD, ascii_int, bad_coord_rows
from apygis.formats._report import warn
from apygis.formats.e00._common import (
    _MAX_COUNT,
    _SECTION_RE,
    _SKIP_TO_TERM,
    _SKIP_UNTIL,
    _SUPER,
    _TERM,
    DOUBLE,
    SINGLE,
    _e00_width,
    log,
)
from apygis.formats.e00.compress import decompress


@dataclass
class _Table:
    name: str
    items: list[tuple[str, int, int, int]]  # name, type, size, e00 offset
    matrix: np.ndarray  # (nrec, nl * 80) bytes
    first_line: int
    lines_per_record: int

    def __len__(self) -> int:
        return len(self.matrix)

    def has(self, name: str) -> bool:
        return any(it[0] == name for it in self.items)

    def raw(self, name: str) -> tuple[np.ndarray, tuple]:
        for it in self.items:
            if it[0] == name:
                width = _e00_width(it[1], it[2])
                assert width is not None  # checked when the item definition was read
                cols = self.matrix[:, it[3] : it[3] + width]
                return np.ascontiguousarray(cols).view(f"S{width}").reshape(-1), it
        raise KeyError(name)


class _Cursor:
    def __init__(self, lines: list[bytes], path, word: str):
        self.lines = lines
        self.i = 0
        self.path = path
        self.word = word

    def fail(self, msg: str, line: int | None = None) -> NoReturn:
        raise FormatError(msg, path=self.path, record=f"{self.word} {line or self.i}")

    def next(self, what: str) -> bytes:
        if self.i >= len(self.lines):
            self.fail(f"the file ends inside the {what} (is it truncated?)", len(self.lines))
        line = self.lines[self.i]
        self.i += 1
        return line

    def need(self, count: int, what: str) -> None:
        if self.i + count > len(self.lines):
            self.fail(
                f"the file ends inside the {what}: {count} more lines expected, "
                f"{len(self.lines) - self.i} left (is it truncated?)",
                len(self.lines),
            )


def _ints(fields: list[bytes], cur: _Cursor, line: int, what: str) -> list[int]:
    out = []
    for f in fields:
        s = f.strip()
        v = ascii_int(s, signed=True) if s else 0  # no '1_0', at most 18 digits
        if v is None:
            cur.fail(f"{what}: expected an integer, found {f.decode('latin-1')!r}", line)
        out.append(v)
    return out


def _floats(fields: list[bytes], cur: _Cursor, lines: list[int], what: str) -> np.ndarray:
    try:
        arr = np.array(fields, dtype=np.bytes_).astype(np.float64) if fields else np.zeros(0)
        ok = bool(np.isfinite(arr).all())
    except ValueError:
        ok = False
    if ok:
        return arr
    for k, f in enumerate(fields):
        try:
            v = float(f)
        except ValueError:
            v = math.nan
        if not math.isfinite(v):
            cur.fail(f"{what}: expected a number, found {f.decode('latin-1')!r}", lines[k])
    return arr  # pragma: no cover


def _fixed_fields(rows: list[bytes], width: int, nvals: int) -> np.ndarray:
    """The first ``nvals`` fields of ``width`` columns of each row, as an (nrows, nvals) S array."""
    w = width * nvals
    raw = b"".join(r[:w].ljust(w) for r in rows)
    m = np.frombuffer(raw, np.uint8).reshape(len(rows), nvals, width)
    return np.ascontiguousarray(m).view(f"S{width}").reshape(len(rows), nvals)


def _fixed_reals(rows: list[bytes], lines: np.ndarray, width: int, nvals: int, cur, what):
    """``nvals`` reals of ``width`` columns from each row: an ``(nrows, nvals)`` array."""
    fields = _fixed_fields(rows, width, nvals)
    try:
        v = fields.astype(np.float64)
        if not len(bad_coord_rows(v)):
            return v
    except ValueError:
        pass
    for r in range(len(rows)):
        for c in range(nvals):
            try:
                ok = abs(float(fields[r, c])) <= MAX_COORD  # False for NaN
            except ValueError:
                ok = False
            if not ok:
                cur.fail(
                    f"{what}: expected a number in {width} columns, finite and at most "
                    f"{MAX_COORD:g} in magnitude, found {bytes(fields[r, c]).decode('latin-1')!r}",
                    int(lines[r]),
                )
    raise AssertionError  # pragma: no cover


def _parse_arcs(cur: _Cursor, prec: int, out: dict) -> None:
    """ARC section: records until the end-of-section line.

    The record structure is walked arc by arc; the vertices of all arcs are
    then converted at once (also when a damaged record stops the walk, so
    that ``recover`` keeps the arcs before it).
    """
    per = 1 if prec == DOUBLE else 2
    heads, starts, counts = [], [], []
    try:
        while True:
            line = cur.next("ARC section")
            ln = cur.i
            if line.startswith(_TERM):
                return
            if len(line) < 70:
                cur.fail(
                    "ARC record: expected 7 integers in 10 columns each (arc, user ID, from and "
                    f"to node, left and right polygon, vertex count), found {line[:80]!r}"
                )
            vals = _ints([line[k : k + 10] for k in range(0, 70, 10)], cur, ln, "ARC record")
            nv = vals[6]
            if not 0 <= nv <= _MAX_COUNT:
                cur.fail(f"ARC record: vertex count {nv} is out of range")
            nrows = (nv + per - 1) // per
            cur.need(nrows, f"arc {vals[0]} ({nv} vertices)")
            heads.append(vals)
            starts.append(cur.i)
            counts.append(nv)
            cur.i += nrows
    finally:
        _arc_vertices(cur, prec, out, heads, starts, counts)


def _arc_vertices(cur: _Cursor, prec: int, out: dict, heads, starts, counts) -> None:
    width = 21 if prec == DOUBLE else 14
    per = 1 if prec == DOUBLE else 2
    counts = np.asarray(counts, np.int64)
    nrows = (counts + per - 1) // per
    row_arc = np.repeat(np.arange(len(counts)), nrows)
    first_row = np.r_[0, np.cumsum(nrows)][:-1]
    line_idx = np.asarray(starts, np.int64)[row_arc] + (
        np.arange(len(row_arc)) - first_row[row_arc]
    )
    rows = [cur.lines[k] for k in line_idx.tolist()]
    # the vertices each line holds: 1 (double), 2, or 1 on the last line of an odd arc
    held = np.full(len(rows), per, np.int64)
    if per == 2:
        odd = np.flatnonzero(counts % 2 == 1)
        held[first_row[odd] + nrows[odd] - 1] = 1
    lens = np.fromiter((len(r) for r in rows), np.int64, len(rows))
    short = np.flatnonzero(lens < 2 * width * held)
    if len(short):
        k = int(short[0])
        cur.fail(
            f"arc {heads[row_arc[k]][0]}: expected {2 * held[k]} numbers in {width} columns "
            f"each, found {rows[k][:80]!r}",
            int(line_idx[k]) + 1,
        )
    for k in np.flatnonzero(held < per).tolist():  # fill the empty half of a line
        rows[k] = rows[k][: 2 * width] + b"0".rjust(width) * 2
    vals = _fixed_reals(rows, line_idx + 1, width, 2 * per, cur, "ARC vertex")
    vals = vals.reshape(-1, 2)
    keep = np.ones(len(vals), bool)
    if per == 2:
        keep[2 * np.flatnonzero(held == 1) + 1] = False
    xy = vals[keep]
    arcs = out["arcs"]
    arcs["heads"] += heads
    arcs["xy"].append(xy)
    arcs["lens"].append(counts)


def _parse_labels(cur: _Cursor, prec: int, out: dict) -> None:
    width = 21 if prec == DOUBLE else 14
    per = 2 if prec == DOUBLE else 1  # coordinate lines after each header line
    need = 20 + 2 * width
    heads: list[int] = []
    try:
        while True:
            line = cur.next("LAB section")
            if line.startswith(_TERM):
                return
            if len(line) < need:
                cur.fail(
                    "LAB record: expected label ID, polygon ID (10 columns each) and X, Y "
                    f"({width} columns each), found {line[:80]!r}"
                )
            heads.append(cur.i - 1)
            cur.need(per, "label record")
            cur.i += per
    finally:
        idx = np.asarray(heads, np.int64)
        rows = [cur.lines[k] for k in heads]
        ids = _fixed_ints(rows, idx + 1, 10, 2, cur, "LAB record")
        xy = _fixed_reals([r[20:] for r in rows], idx + 1, width, 2, cur, "LAB record")
        lab = out["labels"]
        lab["ids"].append(ids[:, 0])
        lab["poly"].append(ids[:, 1])
        lab["xy"].append(xy)


def _parse_pal(cur: _Cursor, prec: int, out: dict) -> None:
    """PAL section (polygon arc lists): per polygon, its arc entries until the end line.

    A polygon record is a header (arc count, then the polygon's box: one line
    in single precision, two in double) and its arcs, three integers each
    (arc number, negative when the arc is walked backwards; from node;
    polygon on the other side), two arcs a line; an arc number 0 separates
    the rings of islands. Polygon 1 is the outside ("universe") polygon.
    """
    width = 21 if prec == DOUBLE else 14
    pal = out["pal"]
    while True:
        line = cur.next("PAL section")
        ln = cur.i
        if line.startswith(_TERM):
            if prec == DOUBLE and cur.i < len(cur.lines) and cur.lines[cur.i].startswith(b" 0.0"):
                cur.i += 1
            return
        if len(line) < 10 + 2 * width:
            cur.fail(
                "PAL record: expected the arc count (10 columns) and the polygon's box "
                f"({width} columns per number), found {line[:80]!r}"
            )
        (narcs,) = _ints([line[:10]], cur, ln, "PAL record")
        if not 0 <= narcs <= _MAX_COUNT:
            cur.fail(f"PAL record: arc count {narcs} is out of range")
        if prec == DOUBLE:
            cur.next("PAL record (second line of its box)")
        nrows = (narcs + 1) // 2
        cur.need(nrows, f"polygon {len(pal) + 1} ({narcs} arcs)")
        rows = cur.lines[cur.i : cur.i + nrows]
        first = cur.i + 1
        cur.i += nrows
        need = [30 if k == nrows - 1 and narcs % 2 else 60 for k in range(nrows)]
        short = [k for k, r in enumerate(rows) if len(r.rstrip()) < need[k]]
        if short:
            k = short[0]
            cur.fail(
                "PAL arcs: expected arc, node and polygon numbers in 10 columns each, "
                f"found {rows[k][:80]!r}",
                first + k,
            )
        vals = _fixed_ints(rows, np.arange(first, first + nrows), 10, 6, cur, "PAL arcs")
        pal.append(vals.reshape(-1, 3)[:narcs])


def _fixed_ints(rows: list[bytes], lines: np.ndarray, width: int, nvals: int, cur, what):
    fields = _fixed_fields(rows, width, nvals)
    fields = np.where(np.char.strip(fields) == b"", b"0", fields)  # a blank field is 0
    try:
        return fields.astype(np.int64)
    except (ValueError, OverflowError):
        pass
    for r in range(len(rows)):
        _ints(list(fields[r]), cur, int(lines[r]), what)
    raise FormatError(f"{what}: integer out of range", path=cur.path)  # pragma: no cover


def _skip_to(cur: _Cursor, end: bytes, what: str) -> None:
    while True:
        line = cur.next(what)
        if line.rstrip().upper() == end:
            return


def _skip_to_term(cur: _Cursor, what: str, extra_line: bool) -> None:
    while True:
        line = cur.next(what)
        if line.startswith(_TERM):
            if extra_line and cur.i < len(cur.lines) and cur.lines[cur.i].startswith(b" 0.0"):
                cur.i += 1
            return


def _parse_prj(cur: _Cursor, out: dict) -> None:
    entries: list[str] = []
    while True:
        line = cur.next("PRJ section").decode("latin-1").rstrip()
        if line.upper().startswith("EOP"):
            break
        if line.startswith("~"):
            if len(line) > 1 and entries:
                entries[-1] += line[1:]
        else:
            entries.append(line)
    out["prj"] = entries


def _parse_ifo(cur: _Cursor, out: dict) -> None:
    while True:
        line = cur.next("INFO section (IFO ... EOI)")
        ln = cur.i
        if line.rstrip().upper() == b"EOI":
            return
        if len(line) < 56:
            cur.fail(
                "INFO table header: expected the table name (32 columns), the external flag, "
                f"item counts, record size and record count, found {line[:80]!r}"
            )
        name = line[0:32].rstrip().decode("latin-1")
        nfields, nitems, _, nrec = _ints(
            [line[34:38], line[38:42], line[42:46], line[46:56]], cur, ln, "INFO table header"
        )
        if not 0 <= nfields <= nitems <= 10240 or not 0 <= nrec <= _MAX_COUNT:
            cur.fail(f"INFO table {name}: item count {nfields} or record count {nrec} out of range")
        items: list[tuple[str, int, int, int]] = []
        offset = 0
        for _ in range(nitems):
            d = cur.next(f"item definitions of INFO table {name}")
            dl = cur.i
            if len(d) < 69:
                cur.fail(f"INFO table {name}: an item definition has 69 columns or more")
            size, type_, index = _ints([d[16:19], d[34:37], d[65:69]], cur, dl, "item definition")
            if index <= 0:
                continue  # a deleted item
            iname = d[0:16].split(b" ")[0].decode("latin-1").upper()
            t = (type_ // 10) * 10
            width = _e00_width(t, size)
            if width is None or size <= 0:
                cur.fail(f"INFO table {name}: item {iname} has type {type_} and size {size}")
            if len(items) >= nfields:
                cur.fail(f"INFO table {name}: more items than the {nfields} announced")
            items.append((iname, t, size, offset))
            offset += width
        if len(items) != nfields:
            cur.fail(f"INFO table {name}: {len(items)} items defined, {nfields} announced")
        reclen = offset
        nl = -(-reclen // 80) if nfields and nrec else 0
        cur.need(nrec * nl, f"records of INFO table {name}")
        block = cur.lines[cur.i : cur.i + nrec * nl]
        first = cur.i + 1
        cur.i += nrec * nl
        if nl:
            raw = b"".join(b[:80].ljust(80) for b in block)
            matrix = np.frombuffer(raw, np.uint8).reshape(nrec, nl * 80)
        else:
            matrix = np.zeros((0, 0), np.uint8)
        out["tables"].append(_Table(name, items, matrix, first, nl))


def _split_e00(data: bytes, path) -> tuple[list[bytes], str]:
    if not data[:4].upper() == b"EXP ":
        raise FormatError("not an E00 file: it must begin with an EXP line", path=path)
    if b"\0" in data:
        raise FormatError("binary data (NUL bytes): not an E00 text file", path=path)
    nl = data.find(b"\n")
    header = (data[:nl] if nl >= 0 else data).rstrip(b"\r")
    words = header.split()
    if len(words) < 2 or words[1] not in (b"0", b"1"):
        raise FormatError(
            "the EXP line must give the compression: 'EXP  0' (none) or 'EXP  1'",
            path=path,
            record="line 1",
        )
    word = "line"
    if words[1] == b"1":
        data = decompress(data, path)
        word = "uncompressed line"
    lines = data.replace(b"\r\n", b"\n").split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    return lines, word


def decode(data: bytes, path=None, recover: bool = False) -> dict:
    """Parse E00 bytes into sections: ``arcs``, ``labels``, ``pal``, ``prj``, ``tables``,
    ``precision``.

    With ``recover``, a file that ends early or breaks off in a section
    gives what was read before the damage (a warning names it) instead of
    raising.
    """
    lines, word = _split_e00(data, path)
    cur = _Cursor(lines, path, word)
    cur.i = 1
    out: dict = {
        "arcs": {"heads": [], "xy": [], "lens": []},
        "labels": {"ids": [], "poly": [], "xy": []},
        "prj": None,
        "pal": [],
        "tables": [],
        "precision": None,
    }
    try:
        _decode_sections(cur, out)
    except FormatError as exc:
        if not recover:
            raise
        warn(log, f"{exc}; kept what was read before (recover=True)", "damaged")
        out["damaged"] = str(exc)
    return out


def _decode_sections(cur: _Cursor, out: dict) -> None:
    while True:
        if cur.i >= len(cur.lines):
            cur.fail("the file ends without EOS (is it truncated?)", len(cur.lines))
        line = cur.lines[cur.i]
        cur.i += 1
        text = line.rstrip()
        if not text:
            continue
        upper = text.upper()
        if upper == b"EOS":
            return
        m = _SECTION_RE.match(text)
        if not m:
            cur.fail(f"expected a section header (ARC  2, LAB  3, ...) or EOS, found {text[:80]!r}")
        name, prec = m.group(1).upper(), int(m.group(2))
        if name == b"GRD":
            cur.fail(
                "this is a grid (raster) E00 file (GRD section): apygis reads vector coverages "
                "only (ARC and LAB sections)"
            )
        if prec not in (SINGLE, DOUBLE) and name not in _SKIP_UNTIL:
            cur.fail(f"section {name.decode()}: precision {prec}, expected 2 or 3")
        if name == b"ARC":
            _parse_arcs(cur, prec, out)
            out["precision"] = prec
        elif name == b"LAB":
            _parse_labels(cur, prec, out)
        elif name == b"PAL":
            _parse_pal(cur, prec, out)
        elif name == b"TOL":
            _skip_to_term(cur, "TOL section", False)
        elif name == b"PRJ":
            _parse_prj(cur, out)
        elif name == b"IFO":
            _parse_ifo(cur, out)
        elif name in _SKIP_UNTIL:
            _skip_to(cur, _SKIP_UNTIL[name], f"{name.decode()} section")
        elif name in _SKIP_TO_TERM:
            log.info("%s: section %s skipped", cur.path, name.decode())
            _skip_to_term(cur, f"{name.decode()} section", name == b"PAL" and prec == DOUBLE)
        elif name in _SUPER:
            log.info("%s: section %s skipped", cur.path, name.decode())
            _skip_to(cur, b"JABBERWOCKY", f"{name.decode()} section")
        else:
            cur.fail(f"unknown section {name.decode()!r}")
