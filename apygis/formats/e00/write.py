"""The E00 writer: a map to one line coverage with INFO tables (see ``docs/formats/e00.md``)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from apygis.errors import DriverError, FormatError, ValueRangeError
from apygis.formats._io import atomic_write_many, check_resolution, significant_step
from apygis.formats._text import digit_columns, esri_wkt, put_right
from apygis.formats.e00._common import (
    _COVER_RE,
    _NL,
    _SP,
    _TERM,
    DOUBLE,
    SINGLE,
    T_BINFLOAT,
    T_BININT,
    T_CHAR,
    _e00_width,
)
from apygis.model.map import Layer, MapFile, crs_string
from apygis.model.polylines import export_lines
from apygis.model.records import TABLES

# --------------------------------------------------------------------------- number fields


def _int_field(values, width: int, what: str) -> np.ndarray:
    """Integers right-aligned in ``width`` columns: an ``(n, width)`` byte matrix.

    >>> _int_field([12, -1, 0], 5, "a number").tobytes()
    b'   12   -1    0'
    """
    v = np.asarray(values, dtype=np.int64).reshape(-1)
    n = len(v)
    out = np.full((n, width), _SP, np.uint8)
    if n == 0:
        return out
    a = np.abs(v)
    top = int(a.max())
    if top >= 10 ** (width - 1):
        raise ValueRangeError(f"{what} {int(v[np.argmax(a)])} does not fit {width} columns")
    put_right(out, 0, width, a, v < 0)
    return out


def _real_field(values, decimals: int, what: str = "coordinate") -> np.ndarray:
    """Reals as E00 writes them: sign, ``d.dddE+dd`` with ``decimals`` decimals.

    ``decimals`` is 7 (single precision, 14 columns), 14 (double, 21 columns)
    or 17 (double in INFO tables, 24 columns). At most 15 significant digits
    are computed; further decimals are zeros. 15 digits hold any value of up
    to 15 significant decimal digits exactly (centimetres below 10^13 m).

    >>> _real_field([340099.875, -0.5, 0.0], 7).tobytes()
    b' 3.4009988E+05-5.0000000E-01 0.0000000E+00'
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    n = len(v)
    width = decimals + 7
    out = np.full((n, width), 48, np.uint8)
    if n == 0:
        return out
    if not np.isfinite(v).all():
        raise ValueRangeError(f"a {what} is not finite: E00 holds finite numbers only")
    sig = min(decimals, 14) + 1
    a = np.abs(v)
    zero = a < 1e-99
    safe = np.where(zero, 1.0, a)
    e = np.floor(np.log10(safe)).astype(np.int64)
    for _ in range(2):  # log10 may be off by one next to powers of ten
        m = np.rint(safe * 10.0 ** (sig - 1 - e))
        e = e + (m >= 10.0**sig) - (m < 10.0 ** (sig - 1))
    m = np.rint(safe * 10.0 ** (sig - 1 - e)).astype(np.int64)
    m[zero] = 0
    e[zero] = 0
    if (e > 99).any():
        raise ValueRangeError(f"a {what} of {a.max():.6g} exceeds the E00 range (1E+99)")
    digits = digit_columns(m, sig)
    out[:, 0] = np.where((v < 0) & ~zero, 45, _SP)
    out[:, 1] = digits[:, 0]
    out[:, 2] = 46
    out[:, 3 : 2 + sig] = digits[:, 1:]
    out[:, width - 4] = 69
    out[:, width - 3] = np.where(e < 0, 45, 43)
    ae = np.abs(e)
    out[:, width - 2] = 48 + ae // 10
    out[:, width - 1] = 48 + ae % 10
    return out


def _hstack(*cols: np.ndarray) -> np.ndarray:
    return np.concatenate(cols, axis=1) if cols else np.zeros((0, 0), np.uint8)


def _assemble(parts: list[tuple[np.ndarray, np.ndarray]], total: int) -> bytes:
    """Rows placed at their positions (row ``k`` of the output), each ended by a newline.

    ``parts`` holds ``(positions, row matrix)``; the rows of one matrix have
    its width.
    """
    if total == 0:
        return b""
    width = max(m.shape[1] for _, m in parts) + 1
    out = np.zeros((total, width), np.uint8)  # NUL marks the unused cells
    for pos, m in parts:
        if len(pos):
            out[pos, : m.shape[1]] = m
            out[pos, m.shape[1]] = _NL
    flat = out.reshape(-1)
    return flat[flat != 0].tobytes()


def _text_lines(lines: list[str]) -> bytes:
    return "".join(ln + "\n" for ln in lines).encode("ascii")


# --------------------------------------------------------------------------- INFO tables


MAX_TEXT_BYTES = 320
"""The widest INFO character item (bytes of UTF-8): the longest text E00 holds."""


@dataclass
class _Item:
    name: str
    type: int
    size: int
    width: int = 10
    prec: int = -1

    @property
    def e00_width(self) -> int:
        width = _e00_width(self.type, self.size)
        assert width is not None, (self.type, self.size)  # the writer's items have known types
        return width


def _table_bytes(name: str, items: list[_Item], columns: list[np.ndarray], nrec: int, ext: str):
    """An INFO table in E00: header line, item definitions, records in 80-column lines."""
    recsize = sum(it.size for it in items)
    head = [f"{name:<32.32}{ext:2.2}{len(items):4d}{len(items):4d}{recsize:4d}{nrec:10d}"]
    offset = 1
    for k, it in enumerate(items):
        head.append(
            f"{it.name:<16.16}{it.size:3d}{-1:2d}{offset:4d}{4:1d}{-1:2d}{it.width:4d}"
            f"{it.prec:2d}{it.type:3d}{-1:2d}{-1:4d}{-1:4d}{-1:2d}{'':<16}{k + 1:4d}-"
        )
        offset += it.size
    out = _text_lines(head)
    if nrec == 0:
        return out
    rec = _hstack(*columns)
    reclen = rec.shape[1]
    pieces = []
    for k in range(0, reclen, 80):  # 80-column lines, the last one of a record shorter
        pieces += [rec[:, k : k + 80], np.full((nrec, 1), _NL, np.uint8)]
    return out + _hstack(*pieces).tobytes()


def _char_column(values, size: int) -> np.ndarray:
    """Byte strings left-aligned in ``size`` columns, space-padded."""
    a = np.asarray(values, dtype=f"S{size}") if len(values) else np.zeros(0, f"S{size}")
    m = a.view(np.uint8).reshape(len(a), size)
    return np.where(m == 0, _SP, m).astype(np.uint8)


def _column(item: _Item, values, what: str) -> np.ndarray:
    if item.type == T_BININT:
        v = np.asarray(values, dtype=np.int64)
        if len(v) and (v.min() < -(2**31) or v.max() >= 2**31):
            bad = int(v[(v < -(2**31)) | (v >= 2**31)][0])
            raise ValueRangeError(f"{what} {bad} does not fit a 4-byte INFO integer")
        return _int_field(v, 11, what)
    if item.type == T_BINFLOAT:
        return _real_field(values, 17 if item.size == 8 else 7, what)
    if item.type == T_CHAR:
        return _char_column(values, item.size)
    raise AssertionError(item)  # pragma: no cover - the writer uses these three types


# --------------------------------------------------------------------------- encode


def _cover_name(path) -> str:
    stem = Path(path).name.split(".")[0].upper()
    name = _COVER_RE.sub("_", stem)[:13]
    return name or "APY"


def _json_chunks(text: str, size: int) -> list[bytes]:
    """``text`` escaped as a JSON string body, in UTF-8 chunks of at most ``size`` bytes."""
    esc = json.dumps(text, ensure_ascii=False)[1:-1]
    chunks: list[bytes] = []
    cur: list[bytes] = []
    n = 0
    for ch in esc:
        b = ch.encode("utf-8")
        if n + len(b) > size:
            chunks.append(b"".join(cur))
            cur, n = [], 0
        cur.append(b)
        n += len(b)
    chunks.append(b"".join(cur))
    return chunks


def _meta_table(map_: MapFile, cover: str) -> bytes:
    entries = [("ID", map_.id)]
    if map_.scale:
        entries.append(("SCALE", str(map_.scale)))
    crs = crs_string(map_.crs)
    if crs is not None:
        entries.append(("CRS", crs))
    if map_.notes:
        entries.append(("NOTES", map_.notes))
    entries.append(("LAYERS", " ".join(lay.ext for lay in map_)))
    keys, values, lens = [], [], []
    for key, text in entries:
        for chunk in _json_chunks(text, 61):
            keys.append(key.encode())
            values.append(chunk)
            lens.append(len(chunk))
    items = [
        _Item("KEY", T_CHAR, 8, 8),
        _Item("VALUE", T_CHAR, 61, 61),
        _Item("NBYTES", T_BININT, 4, 5),
    ]
    cols = [
        _char_column(keys, 8),
        _char_column(values, 61),
        _int_field(lens, 11, "a length"),
    ]
    return _table_bytes(f"{cover}.APYMAP", items, cols, len(keys), "  ")


def _prj_lines(crs) -> list[str]:
    wkt = "".join(esri_wkt(crs).split("\n"))
    try:
        wkt.encode("ascii")
    except UnicodeEncodeError:
        wkt = wkt.encode("ascii", "replace").decode("ascii")
    chunks = [wkt[k : k + 79] for k in range(0, len(wkt), 79)]
    return [chunks[0]] + ["~" + c for c in chunks[1:]]


@dataclass
class _Arcs:
    """The arcs of all layers, CSR, with what the AAT and LINEPT tables need."""

    coords: list = field(default_factory=list)  # (n, 2) per layer
    lens: list = field(default_factory=list)
    layer: list = field(default_factory=list)
    code: list = field(default_factory=list)
    closed: list = field(default_factory=list)
    lpt: list = field(default_factory=list)  # per layer: dict of LINEPT columns
    count: int = 0


def _layer_arcs(layer: Layer, arcs: _Arcs) -> None:
    lp = layer.line_points
    if len(lp) == 0:
        return
    ls = export_lines(layer)
    k = len(ls)
    pl_start = ls.offsets[:-1]
    pl_len = np.diff(ls.offsets)
    # arc vertices: the polyline, a ring closed explicitly, a lone vertex doubled
    extra = (ls.closed | (pl_len == 1)).astype(np.int64)
    arc_len = pl_len + extra
    arc_off = np.r_[0, np.cumsum(arc_len)].astype(np.int64)
    arc_of = np.repeat(np.arange(k), arc_len)
    pos = np.arange(arc_off[-1]) - arc_off[:-1][arc_of]
    src = pl_start[arc_of] + np.where(pos >= pl_len[arc_of], 0, pos)
    arcs.coords.append(ls.coords[src, :2])
    arcs.lens.append(arc_len)
    arcs.layer += [layer.ext] * k
    arcs.code.append(ls.codes.astype(np.int64))
    arcs.closed.append(ls.closed.astype(np.int64))
    # every line point: its arc and vertex (0-based here), from its own polyline vertex
    line = ls.line_index()
    chain = np.empty(len(lp), np.int64)
    vertex = np.empty(len(lp), np.int64)
    chain[ls.rows[ls.own]] = line[ls.own]
    vertex[ls.rows[ls.own]] = (np.arange(len(ls.rows)) - pl_start[line])[ls.own]
    if not np.array_equal(ls.nums[pl_start[chain] + vertex], lp["num"]):
        raise RuntimeError("E00 writer: line points do not match their arcs")  # pragma: no cover
    arcs.lpt.append(
        {
            "arc": arcs.count + chain + 1,
            "vertex": vertex + 1,
            "layer": layer.ext,
            "lp": lp,
        }
    )
    arcs.count += k


def _arc_section(arcs: _Arcs, precision: int) -> tuple[bytes, np.ndarray, np.ndarray]:
    """The ARC section; returns it, the arc lengths (metres) and the node numbers."""
    head = f"ARC  {precision}\n".encode()
    term = _TERM + b"         0         0         0         0         0\n"
    if arcs.count == 0:
        return head + term, np.zeros(0), np.zeros((0, 2), np.int64)
    xy = np.concatenate(arcs.coords)
    lens = np.concatenate(arcs.lens)
    off = np.r_[0, np.cumsum(lens)].astype(np.int64)
    narc = len(lens)
    # nodes: arc end points with the same coordinates share a number
    ends = np.concatenate([xy[off[:-1]], xy[off[1:] - 1]])
    _, inv = np.unique(ends, axis=0, return_inverse=True)
    nodes = (inv.reshape(-1) + 1).reshape(2, narc).T
    arc_of = np.repeat(np.arange(narc), lens)
    seg = np.hypot(*np.diff(xy, axis=0).T)
    same = arc_of[1:] == arc_of[:-1]
    length = np.bincount(arc_of[1:][same], weights=seg[same], minlength=narc)
    ids = np.arange(1, narc + 1)
    header = _hstack(
        _int_field(ids, 10, "arc number"),
        _int_field(ids, 10, "arc number"),
        _int_field(nodes[:, 0], 10, "node number"),
        _int_field(nodes[:, 1], 10, "node number"),
        _int_field(np.zeros(narc, np.int64), 10, "polygon"),
        _int_field(np.zeros(narc, np.int64), 10, "polygon"),
        _int_field(lens, 10, "vertex count"),
    )
    dec = 14 if precision == DOUBLE else 7
    pair = _hstack(_real_field(xy[:, 0], dec), _real_field(xy[:, 1], dec))
    j = np.arange(len(xy)) - off[:-1][arc_of]
    per_row = 1 if precision == DOUBLE else 2  # vertices per line
    rows_per_arc = (lens + per_row - 1) // per_row
    block = np.r_[0, np.cumsum(rows_per_arc + 1)].astype(np.int64)
    head_pos = block[:-1]
    vpos = head_pos[arc_of] + 1 + j // per_row
    if precision == DOUBLE:
        parts = [(head_pos, header), (vpos, pair)]
    else:  # two vertices a line; an odd last vertex alone on its line
        first = j % 2 == 0
        second = np.flatnonzero(~first)
        alone = first.copy()
        alone[second - 1] = False
        full = first & ~alone
        rows = _hstack(pair[full], pair[second])
        parts = [(head_pos, header), (vpos[full], rows), (vpos[alone], pair[alone])]
    body = _assemble(parts, int(block[-1]))
    return head + body + term, length, nodes


def _lab_section(labels: dict, precision: int) -> bytes:
    head = f"LAB  {precision}\n".encode()
    dec = 14 if precision == DOUBLE else 7
    term = _TERM + _real_field([0.0], dec).tobytes() * 2 + b"\n"
    n = len(labels["x"])
    if n == 0:
        return head + term
    x, y = _real_field(labels["x"], dec), _real_field(labels["y"], dec)
    ids = np.arange(1, n + 1)
    header = _hstack(_int_field(ids, 10, "label number"), _int_field(np.zeros(n), 10, "poly"), x, y)
    per = 2 if precision == DOUBLE else 1
    box = _hstack(x, y) if precision == DOUBLE else _hstack(x, y, x, y)
    pos = np.arange(n) * (1 + per)
    parts = [(pos, header)] + [(pos + 1 + k, box) for k in range(per)]
    return head + _assemble(parts, n * (1 + per)) + term


def _tol_section(precision: int) -> bytes:
    dec = 14 if precision == DOUBLE else 7
    rows = _hstack(
        _int_field(np.arange(1, 11), 10, "index"),
        _int_field(np.full(10, 2), 10, "flag"),
        _real_field(np.zeros(10), dec),
    )
    term = _TERM + b"         0         0         0         0         0\n"
    return f"TOL  {precision}\n".encode() + _assemble([(np.arange(10), rows)], 10) + term


def encode(map_: MapFile, path=None, precision: int = DOUBLE) -> bytes:
    """The E00 text of a map (one coverage named after ``path``), as bytes.

    Parameters
    ----------
    map_ : MapFile
    path : str or os.PathLike, optional
        The target; its name gives the coverage name (upper case, 13
        characters at most).
    precision : {3, 2}
        Double (default) or single precision coordinates.
    """
    if precision not in (SINGLE, DOUBLE):
        raise DriverError(f"E00 precision is 2 (single) or 3 (double), not {precision!r}")
    cover = _cover_name(path or map_.id)
    arcs = _Arcs()
    keys = ("x", "y", "layer", "kind", "num", "code", "z", "text")
    labels: dict[str, list[Any]] = {key: [] for key in keys}
    for lay in map_:
        _layer_arcs(lay, arcs)
        for kind, t in (("S", lay.symbols), ("T", lay.texts)):
            labels["x"] += t["x"].tolist()
            labels["y"] += t["y"].tolist()
            labels["z"] += t["z"].tolist()
            labels["num"] += t["num"].tolist()
            labels["layer"] += [lay.ext.encode()] * len(t)
            labels["kind"] += [kind.encode()] * len(t)
            if kind == "S":
                labels["code"] += t["code"].tolist()
                labels["text"] += [b""] * len(t)
            else:
                labels["code"] += [0] * len(t)
                texts = [s.encode("utf-8") for s in t["text"].tolist()]
                long = [k for k, b in enumerate(texts) if len(b) > MAX_TEXT_BYTES]
                if long:
                    k = long[0]
                    raise ValueRangeError(
                        f"layer {lay.ext}: text {t['num'][k]} has {len(texts[k])} bytes; an INFO "
                        f"character item holds at most {MAX_TEXT_BYTES}",
                        path=path,
                    )
                labels["text"] += texts
    parts = [f"EXP  0 /{cover}.E00\n".encode()]
    arc_bytes, length, nodes = _arc_section(arcs, precision)
    parts += [arc_bytes, _lab_section(labels, precision), _tol_section(precision)]
    parts.append(f"SIN  {precision}\nEOX\n".encode())
    if map_.crs is not None:
        parts.append(_text_lines([f"PRJ  {precision}", *_prj_lines(map_.crs), "EOP"]))
    parts.append(f"IFO  {precision}\n".encode())
    parts.append(_aat(cover, arcs, length, nodes, precision))
    parts.append(_pat(cover, labels, precision))
    parts.append(_lpt(cover, arcs))
    parts.append(_meta_table(map_, cover))
    parts.append(b"EOI\nEOS\n")
    return b"".join(parts)


def _real_item(name: str, precision: int, prec: int) -> _Item:
    if precision == DOUBLE:
        return _Item(name, T_BINFLOAT, 8, 18, prec)
    return _Item(name, T_BINFLOAT, 4, 12, min(prec, 3))


def _aat(cover: str, arcs: _Arcs, length, nodes, precision: int) -> bytes:
    n = arcs.count
    items = [
        _Item("FNODE#", T_BININT, 4, 5),
        _Item("TNODE#", T_BININT, 4, 5),
        _Item("LPOLY#", T_BININT, 4, 5),
        _Item("RPOLY#", T_BININT, 4, 5),
        _real_item("LENGTH", precision, 5),
        _Item(f"{cover}#", T_BININT, 4, 5),
        _Item(f"{cover}-ID", T_BININT, 4, 5),
        _Item("LAYER", T_CHAR, 3, 3),
        _Item("CODE", T_BININT, 4, 5),
        _Item("CLOSED", T_BININT, 4, 5),
    ]
    ids = np.arange(1, n + 1)
    zeros = np.zeros(n, np.int64)
    values = [
        nodes[:, 0],
        nodes[:, 1],
        zeros,
        zeros,
        length,
        ids,
        ids,
        [e.encode() for e in arcs.layer],
        np.concatenate(arcs.code) if n else zeros,
        np.concatenate(arcs.closed) if n else zeros,
    ]
    cols = [_column(it, v, it.name) for it, v in zip(items, values, strict=True)]
    return _table_bytes(f"{cover}.AAT", items, cols, n, "XX")


def _pat(cover: str, labels: dict, precision: int) -> bytes:
    n = len(labels["x"])
    width = max([1, *(len(t) for t in labels["text"])])
    items = [
        _real_item("AREA", precision, 5),
        _real_item("PERIMETER", precision, 5),
        _Item(f"{cover}#", T_BININT, 4, 5),
        _Item(f"{cover}-ID", T_BININT, 4, 5),
        _Item("LAYER", T_CHAR, 3, 3),
        _Item("KIND", T_CHAR, 1, 1),
        _Item("NUM", T_BININT, 4, 10),
        _Item("CODE", T_BININT, 4, 5),
        _Item("HEIGHT", T_BINFLOAT, 8, 18, 3),
        _Item("TXTLEN", T_BININT, 4, 5),
        _Item("TEXT", T_CHAR, width, width),
    ]
    ids = np.arange(1, n + 1)
    zeros = np.zeros(n)
    values = [
        zeros,
        zeros,
        ids,
        ids,
        labels["layer"],
        labels["kind"],
        labels["num"],
        labels["code"],
        labels["z"],
        [len(t) for t in labels["text"]],
        labels["text"],
    ]
    cols = [_column(it, v, it.name) for it, v in zip(items, values, strict=True)]
    return _table_bytes(f"{cover}.PAT", items, cols, n, "XX")


def _lpt(cover: str, arcs: _Arcs) -> bytes:
    items = [
        _Item("ARC#", T_BININT, 4, 10),
        _Item("VERTEX", T_BININT, 4, 10),
        _Item("LAYER", T_CHAR, 3, 3),
        _Item("NUM", T_BININT, 4, 10),
        _Item("HEIGHT", T_BINFLOAT, 8, 18, 3),
        _Item("CODE", T_BININT, 4, 5),
        _Item("FWD", T_BININT, 4, 10),
        _Item("BACK", T_BININT, 4, 10),
        _Item("SIDE1", T_BININT, 4, 10),
        _Item("SIDE2", T_BININT, 4, 10),
    ]
    values: list[Any]  # arrays, and a list of bytes for the empty LAYER column
    if arcs.lpt:
        lp = np.concatenate([d["lp"] for d in arcs.lpt])
        values = [
            np.concatenate([d["arc"] for d in arcs.lpt]),
            np.concatenate([d["vertex"] for d in arcs.lpt]),
            np.repeat(
                np.array([d["layer"].encode() for d in arcs.lpt], dtype="S3"),
                [len(d["lp"]) for d in arcs.lpt],
            ),
            lp["num"],
            lp["z"],
            lp["code"],
            lp["fwd"],
            lp["back"],
            lp["side1"],
            lp["side2"],
        ]
        n = len(lp)
    else:
        n = 0
        values = [np.zeros(0, np.int64)] * 2 + [[]] + [np.zeros(0)] * 7
    what = ["arc number", "vertex", "", "point number", "height", "code"] + ["reference"] * 4
    cols = [_column(it, v, w) for it, v, w in zip(items, values, what, strict=True)]
    return _table_bytes(f"{cover}.LINEPT", items, cols, n, "  ")


def _target(map_: MapFile, path) -> Path:
    p = Path(path)
    return p / f"{map_.id}.e00" if p.is_dir() else p


def outputs(map_: MapFile, path) -> list[Path]:
    """The one file :func:`write` creates."""
    return [_target(map_, path)]


def _check_precision(map_: MapFile, target: Path, precision: int) -> None:
    """Refuse coordinates that the precision's significant digits cannot hold to 1 cm."""
    if precision not in (SINGLE, DOUBLE):
        return  # encode() names the valid codes
    digits = 8 if precision == SINGLE else 15
    xy = [lay.table(t)[k] for lay in map_ for t in TABLES for k in ("x", "y")]
    if not xy:
        return
    step = significant_step(np.concatenate(xy), digits)
    if step == 0.0:
        return
    word = "single" if precision == SINGLE else "double"
    what = (
        f"E00 {word} precision holds {digits} significant digits, a step of {step:g} "
        "units at these coordinates"
    )
    if map_.crs is None:
        if step > 0.01 * (1 + 1e-9):
            raise FormatError(
                f"{what}, so {step:g} m would be lost: write double precision",
                path=target,
            )
        return
    hint = "write double precision" if precision == SINGLE else None
    check_resolution(map_, target, step, what, hint=hint)


def write(map_: MapFile, path, progress=None, precision: int = DOUBLE) -> list[Path]:
    """Write a map as an uncompressed E00 file (one line coverage), atomically.

    Parameters
    ----------
    map_ : MapFile
    path : str or os.PathLike
        The ``.e00`` file (an existing directory means ``dir/<map id>.e00``);
        its name gives the coverage name.
    progress : callable, optional
        ``progress(done, total)``.
    precision : {3, 2}
        Double (default: 15 significant digits) or single precision (8
        digits; the INFO heights stay exact). Coordinates that the digits do
        not hold to a centimetre are refused (single precision at Swiss
        coordinates: decimetres; degrees: 1.1 cm).

    Returns
    -------
    list of Path
    """
    target = _target(map_, path)
    _check_precision(map_, target, precision)
    data = encode(map_, target, precision)
    if progress:
        progress(1, 2)
    out = atomic_write_many({target: data})
    if progress:
        progress(2, 2)
    return out
