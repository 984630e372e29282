"""ARC/INFO interchange (E00): a map as one line coverage with INFO tables.

The mapping is specified in ``docs/formats/e00.md``. In short, writing
``out/ZH1091.e00`` creates one uncompressed, double-precision E00 file
holding coverage ``ZH1091``:

* ``ARC``: one arc per line (chain) of every layer, as
  :func:`apygis.model.polylines.export_lines` gives them (a branch starts or ends
  at its junction's vertex; a closed line repeats its first vertex).
* ``LAB``: one label point per symbol and per text.
* ``TOL``: the ten tolerances, unverified. ``PRJ``: the map's CRS as ESRI WKT.
* INFO tables (``IFO``): ``ZH1091.AAT`` (per arc: the standard items, then
  ``LAYER``, ``CODE``, ``CLOSED``), ``ZH1091.PAT`` (per label: the standard
  items, then ``LAYER``, ``KIND``, ``NUM``, ``CODE``, ``HEIGHT``,
  ``TXTLEN``, ``TEXT``), ``ZH1091.LINEPT`` (per line point, in table
  order: ``ARC#``, ``VERTEX``, ``LAYER``, ``NUM``, ``HEIGHT``, ``CODE`` and
  the references ``FWD``, ``BACK``, ``SIDE1``, ``SIDE2``) and
  ``ZH1091.APYMAP`` (map ID, scale, CRS, notes, layer list).

Reading an E00 file written this way gives the map back record for record:
point numbers, references, heights, codes and texts come from the INFO
tables, X and Y from the arcs and labels. Any other vector E00 file
(compressed or not, single or double precision) is read as one layer: arcs
become lines whose topology is rebuilt by the model's one rebuild,
:meth:`apygis.model.Layer.add_polylines` (its report logged), label points
become symbols. Grid E00
files (a ``GRD`` section) are refused.

GDAL's AVCE00 driver reads the files written here as layers ``ARC`` (the AAT
items joined) and ``LAB`` (the PAT items joined).
"""

from __future__ import annotations

import json
import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from apygis.errors import DriverError, FormatError, RecordError, ValueRangeError
from apygis.formats import Driver
from apygis.formats._io import atomic_write_many, check_resolution, read_bytes, significant_step
from apygis.formats._readguard import MAX_COORD, ascii_int, bad_coord_rows, loads_json
from apygis.formats._text import digit_columns, esri_wkt, put_right
from apygis.model import topology
from apygis.model.map import Layer, MapFile, check_ext, check_map_id, check_text, crs_string
from apygis.model.polylines import export_lines
from apygis.model.records import LINE_DTYPE, MAX_CODE, NO_REF, TABLES

__all__ = [
    "DEFAULT_LAYER",
    "DRIVER",
    "decode",
    "decompress",
    "encode",
    "outputs",
    "probe",
    "read",
    "write",
]

log = logging.getLogger(__name__)

DEFAULT_LAYER = "a"
"""Layer extension of the records of an E00 file that apygis did not write."""

SINGLE, DOUBLE = 2, 3
"""E00 precision codes: single (7 decimals) and double (14) precision."""

T_DATE, T_CHAR, T_FIXINT, T_FIXNUM, T_BININT, T_BINFLOAT = 10, 20, 30, 40, 50, 60
"""INFO item types (the tens digit of the E00 type field)."""

_TERM = b"        -1         0"
_NL, _SP = 10, 32
_MAX_COUNT = 10 * 1024 * 1024
_COVER_RE = re.compile(r"[^A-Z0-9_]")
_SECTION_RE = re.compile(rb"^([A-Za-z0-9]{3})  ([0-9])\s*$")
# sections apygis does not use, and the line that ends each
_SKIP_UNTIL = {b"SIN": b"EOX", b"LOG": b"EOL", b"MTD": b"EOD"}
_SKIP_TO_TERM = {b"PAL", b"CNT", b"TXT"}
_SUPER = {b"TX6", b"TX7", b"RXP", b"RPL"}


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


@dataclass
class _Item:
    name: str
    type: int
    size: int
    width: int = 10
    prec: int = -1

    @property
    def e00_width(self) -> int:
        return _e00_width(self.type, self.size)


def _e00_width(type_: int, size: int) -> int | None:
    if type_ in (T_DATE, T_CHAR, T_FIXINT):
        return size
    if type_ == T_BININT:
        return {4: 11, 2: 6}.get(size)
    if type_ == T_BINFLOAT:
        return {4: 14, 8: 24}.get(size)
    if type_ == T_FIXNUM:
        return 14
    return None


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
    chunks, cur, n = [], [], 0
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
    if map_.crs is not None:
        entries.append(("CRS", crs_string(map_.crs)))
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
    labels = {"x": [], "y": [], "layer": [], "kind": [], "num": [], "code": [], "z": [], "text": []}
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
                labels["text"] += [s.encode("utf-8") for s in t["text"].tolist()]
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


# --------------------------------------------------------------------------- decompress


def decompress(data: bytes, path=None) -> bytes:
    """The uncompressed text of a compressed E00 file (``EXP  1``).

    The compressed stream (everything after the header line, its own line
    ends ignored) encodes: ``~}`` a line end, ``~ `` and one character a run
    of ``ord(c) - 32`` spaces, ``~~`` and ``~-`` a literal ``~`` and ``-``,
    and ``~`` with a format character from ``!`` to ``z`` a number, whose
    digits follow in pairs, one character each (``!`` is 00, 92-99 take two
    characters), until a space or a ``~``. The format character ``f`` gives,
    with ``n = ord(f) - 33``, the position of the decimal point ``n % 15``
    (0: none), the exponent ``n // 15 % 3`` (0: none, 1: ``E+``, 2: ``E-``,
    before the last two digits) and an odd digit count ``n // 45`` (the last
    digit dropped). After a number, ``~`` followed by anything but ``}`` or a
    space only ends the number.

    >>> decompress(b"EXP  1 /X.E00\\nARC  2~}~ )1~}EOS~}").decode()
    'EXP  0 /X.E00\\nARC  2\\n         1\\nEOS\\n'
    """
    nl = data.find(b"\n")
    header = data[:nl] if nl >= 0 else data
    header = header.rstrip(b"\r")
    k = header.find(b" 1")
    if k >= 0:
        header = header[:k] + b" 0" + header[k + 2 :]
    body = b"" if nl < 0 else data[nl + 1 :]
    stream = body.replace(b"\r", b"").replace(b"\n", b"")
    out = bytearray()
    col = 0
    line_no = 1
    i, n = 0, len(stream)
    after_number = False

    def fail(msg: str):
        raise FormatError(msg, path=path, record=f"uncompressed line {line_no}")

    while i < n:
        c = stream[i]
        i += 1
        if c != 0x7E:
            out.append(c)
            col += 1
            after_number = False
        else:
            if i >= n:
                fail("the compressed data end inside a ~ code (is the file truncated?)")
            c = stream[i]
            i += 1
            if c == 0x20:
                if i >= n:
                    fail("the compressed data end inside a run of spaces")
                run = stream[i] - 32
                i += 1
                if run < 0:
                    fail(f"bad run of spaces code {stream[i - 1]!r}")
                out += b" " * run
                col += run
                after_number = False
            elif c == 0x7D:
                out.append(_NL)
                col = 0
                line_no += 1
                after_number = False
            elif after_number:
                out.append(c)
                col += 1
                after_number = False
            elif c in (0x7E, 0x2D):
                out.append(c)
                col += 1
            elif 0x21 <= c <= 0x7A:
                code = c - 33
                point, odd, expo = code % 15, code // 45, (code // 15) % 3
                digits = bytearray()
                ndigits = 0  # digits so far, the decimal point not counted (linear time)
                while i < n and stream[i] not in (0x20, 0x7E):
                    v = stream[i] - 33
                    i += 1
                    if v == 92 and i < n:
                        v += stream[i] - 33
                        i += 1
                    if not 0 <= v <= 99:
                        fail(f"bad digit pair code in a compressed number ({v})")
                    for d in (v // 10, v % 10):
                        digits.append(48 + d)
                        ndigits += 1
                        if ndigits == point:
                            digits.append(46)
                    if col + len(digits) > 82:  # stop at once, not at the end of the number
                        fail(
                            "an uncompressed line is longer than 80 characters: "
                            "corrupt compressed data"
                        )
                if odd and digits:
                    del digits[-1]
                if expo and len(digits) >= 2:
                    digits[-2:-2] = b"E+" if expo == 1 else b"E-"
                out += digits
                col += len(digits)
                after_number = True
            else:
                fail(f"unknown compression code '~{chr(c)}'")
        if col > 80:
            fail("an uncompressed line is longer than 80 characters: corrupt compressed data")
    if out and out[-1] != _NL:
        out.append(_NL)
    return bytes(header) + b"\n" + bytes(out)


# --------------------------------------------------------------------------- decode


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
                cols = self.matrix[:, it[3] : it[3] + width]
                return np.ascontiguousarray(cols).view(f"S{width}").reshape(-1), it
        raise KeyError(name)


class _Cursor:
    def __init__(self, lines: list[bytes], path, word: str):
        self.lines = lines
        self.i = 0
        self.path = path
        self.word = word

    def fail(self, msg: str, line: int | None = None):
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


def _fixed_ints(rows: list[bytes], lines: np.ndarray, width: int, nvals: int, cur, what):
    fields = _fixed_fields(rows, width, nvals)
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
        items = []
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
    """Parse E00 bytes into sections: ``arcs``, ``labels``, ``prj``, ``tables``, ``precision``.

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
        "tables": [],
        "precision": None,
    }
    try:
        _decode_sections(cur, out)
    except FormatError as exc:
        if not recover:
            raise
        log.warning("%s; kept what was read before (recover=True)", exc)
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


# --------------------------------------------------------------------------- to the model


def _table(tables: list[_Table], suffix: str, path) -> _Table | None:
    found = [t for t in tables if t.name.upper().endswith(suffix)]
    if len(found) > 1:
        log.warning("%s: %d tables *%s; using %s", path, len(found), suffix, found[0].name)
    return found[0] if found else None


def _int_col(t: _Table, name: str, path) -> np.ndarray:
    raw, it = t.raw(name)
    raw = np.where(np.char.strip(raw) == b"", b"0", raw)
    try:
        return raw.astype(np.float64 if it[1] in (T_FIXNUM, T_BINFLOAT) else np.int64).astype(
            np.int64
        )
    except (ValueError, OverflowError):
        pass
    for k, v in enumerate(raw):
        try:
            int(v)
        except ValueError:
            _bad(t, k, it, path, "an integer", v)
    raise FormatError(f"INFO table {t.name}: item {name} out of range", path=path)


def _float_col(t: _Table, name: str, path) -> np.ndarray:
    raw, it = t.raw(name)
    raw = np.where(np.char.strip(raw) == b"", b"0", raw)
    try:
        v = raw.astype(np.float64)
        if not len(bad_coord_rows(v)):
            return v
    except ValueError:
        pass
    for k, s in enumerate(raw):
        try:
            ok = abs(float(s)) <= MAX_COORD  # False for NaN
        except ValueError:
            ok = False
        if not ok:
            _bad(t, k, it, path, f"a finite number of at most {MAX_COORD:g} in magnitude", s)
    raise AssertionError  # pragma: no cover


def _decode_text(b: bytes) -> str:
    try:
        return b.decode("utf-8")
    except UnicodeDecodeError:
        return b.decode("latin-1")


def _str_col(t: _Table, name: str, nbytes: np.ndarray | None = None) -> np.ndarray:
    """A character item as an object array of str (trailing blanks dropped, or cut to nbytes)."""
    raw, _ = t.raw(name)
    if nbytes is not None:
        return np.array(
            [_decode_text(b[: int(n)]) for b, n in zip(raw.tolist(), nbytes, strict=True)],
            dtype=object,
        )
    uniq, inv = np.unique(raw, return_inverse=True)
    words = np.array([_decode_text(b.rstrip(b" ")) for b in uniq.tolist()], dtype=object)
    return words[inv.reshape(-1)] if len(raw) else np.zeros(0, object)


def _bad(t: _Table, k: int, it, path, expected: str, found) -> None:
    line = t.first_line + k * t.lines_per_record + it[3] // 80
    raise FormatError(
        f"INFO table {t.name}, record {k + 1}, item {it[0]}: expected {expected}, "
        f"found {bytes(found).decode('latin-1')!r}",
        path=path,
        record=f"line {line}",
    )


def _need_items(t: _Table, names: tuple[str, ...]) -> bool:
    return all(t.has(n) for n in names)


_LPT_ITEMS = ("ARC#", "VERTEX", "LAYER", "NUM", "HEIGHT", "CODE", "FWD", "BACK", "SIDE1", "SIDE2")
_PAT_ITEMS = ("LAYER", "KIND", "NUM", "CODE", "HEIGHT", "TXTLEN", "TEXT")


def _meta(tables, path) -> dict:
    t = _table(tables, ".APYMAP", path)
    if t is None or not _need_items(t, ("KEY", "VALUE", "NBYTES")):
        return {}
    keys = _str_col(t, "KEY")
    nbytes = _int_col(t, "NBYTES", path)
    bad = (nbytes < 0) | (nbytes > 61)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(t, k, t.raw("NBYTES")[1], path, "a length 0-61", str(nbytes[k]).encode())
    raw, _ = t.raw("VALUE")
    joined: dict[str, bytes] = {}
    for k, key in enumerate(keys):
        joined[key] = joined.get(key, b"") + raw[k][: int(nbytes[k])]
    out = {}
    for key, b in joined.items():
        what = f"INFO table {t.name}: the {key} value"
        value = loads_json(b'"' + b + b'"', what, path=path)
        if not isinstance(value, str):  # pragma: no cover - quotes around it make a string
            raise FormatError(f"{what} is not an escaped string", path=path)
        out[key] = value
    if "SCALE" in out:
        scale = ascii_int(out["SCALE"].strip())
        if scale is None:
            raise FormatError(
                f"INFO table {t.name}: the SCALE value {out['SCALE'][:40]!r} is not a "
                "whole number (digits 0-9)",
                path=path,
            )
        out["SCALE"] = scale
    return out


def _crs_from_prj(entries: list[str] | None, path):
    if not entries:
        return None
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    first = entries[0].lstrip().upper()
    if first.startswith(("PROJCS", "GEOGCS", "GEOCCS", "COMPD_CS", "LOCAL_CS", "PROJCRS")):
        try:
            return CRS.from_wkt("".join(entries))
        except CRSError as exc:
            log.warning("%s: PRJ section is not a readable WKT (%s); no CRS", path, exc)
            return None
    keys = {}
    for e in entries:
        parts = e.split()
        if len(parts) >= 2:
            keys[parts[0].upper()] = parts[1].upper()
    proj, datum = keys.get("PROJECTION"), keys.get("DATUM")
    geo = {"NAD27": 4267, "NAD83": 4269, "WGS84": 4326}
    code = None
    if proj == "GEOGRAPHIC" and datum in geo:
        code = geo[datum]
    elif proj == "UTM" and datum in geo:
        try:
            zone = int(keys.get("ZONE", "0"))
        except ValueError:
            zone = 0
        base = {"NAD27": 26700, "NAD83": 26900, "WGS84": 32600}[datum]
        if 1 <= abs(zone) <= 60:
            code = base + abs(zone) + (100 if zone < 0 and datum == "WGS84" else 0)
    if code is None:
        log.info("%s: PRJ section %s not translated; no CRS", path, keys)
        return None
    return CRS.from_epsg(code)


def _map_from(info: dict, meta: dict, path, layer_opt: str | None, tol: float) -> MapFile:
    tables = info["tables"]
    stem = re.sub(r"[^A-Za-z0-9_-]", "_", Path(path).stem if path else "E00")[:32] or "E00"
    try:
        crs = meta.get("CRS") or _crs_from_prj(info["prj"], path)
        scale = meta.get("SCALE")
        mp = MapFile(check_map_id(meta.get("ID", stem)), scale=scale, crs=crs)
        mp.notes = meta.get("NOTES", "")
        layers = meta.get("LAYERS", "").split()
        for ext in layers:
            mp.layer(ext)
    except (RecordError, ValueError) as exc:
        raise FormatError(f"map metadata: {exc}", path=path) from None
    default = check_ext(layer_opt) if layer_opt else (layers[0] if layers else DEFAULT_LAYER)
    _lines_to_map(info, tables, mp, default, path, tol)
    _labels_to_map(info, tables, mp, default, path)
    return mp


def _arc_arrays(arcs: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arc numbers, vertex offsets and vertices (CSR) of the ARC sections read."""
    ids = np.array([h[0] for h in arcs["heads"]], np.int64)
    lens = np.concatenate(arcs["lens"]) if arcs["lens"] else np.zeros(0, np.int64)
    xy = np.concatenate(arcs["xy"]) if arcs["xy"] else np.zeros((0, 2))
    return ids, np.r_[0, np.cumsum(lens)].astype(np.int64), xy


def _check_ext_col(t: _Table, values: np.ndarray, path) -> None:
    for ext in set(values.tolist()):
        try:
            check_ext(ext)
        except RecordError:
            k = int(np.flatnonzero(values == ext)[0])
            _bad(t, k, t.raw("LAYER")[1], path, "a layer extension (1-3 letters)", ext.encode())


def _lines_to_map(info, tables, mp: MapFile, default: str, path, tol: float) -> None:
    ids, off, xy = _arc_arrays(info["arcs"])
    narc = len(ids)
    aat = _table(tables, ".AAT", path)
    if aat is not None and len(aat) != narc:
        raise FormatError(
            f"INFO table {aat.name} has {len(aat)} records for {narc} arcs", path=path
        )
    lpt = _table(tables, ".LINEPT", path)
    if lpt is not None and _need_items(lpt, _LPT_ITEMS):
        _lines_from_lpt(lpt, ids, off, xy, mp, path)
        return
    if narc == 0:
        return
    codes = np.zeros(narc, np.int64)
    if aat is not None and aat.has("CODE"):
        codes = _int_col(aat, "CODE", path)
        bad = (codes < 0) | (codes > MAX_CODE)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            _bad(aat, k, aat.raw("CODE")[1], path, "a code 0-99", str(codes[k]).encode())
    layer = mp.layer(default)
    rep = layer.add_polylines(xy, off, codes, snap_m=tol, crs=mp.crs)
    say = log.warning if rep.refused or rep.duplicates_removed or rep.empty else log.info
    say("%s: layer %s: arcs rebuilt: %s", path, layer.ext, rep.message())


def _lines_from_lpt(t: _Table, ids, off, xy, mp: MapFile, path) -> None:
    n = len(t)
    arc = _int_col(t, "ARC#", path)
    vertex = _int_col(t, "VERTEX", path)
    row = topology.lookup(ids, arc)
    if n and (row < 0).any():
        k = int(np.flatnonzero(row < 0)[0])
        _bad(t, k, t.raw("ARC#")[1], path, "the number of an arc", str(arc[k]).encode())
    nverts = off[1:] - off[:-1]
    bad = (vertex < 1) | (vertex > nverts[row]) if n else np.zeros(0, bool)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(t, k, t.raw("VERTEX")[1], path, "a vertex of the arc", str(vertex[k]).encode())
    layers = _str_col(t, "LAYER")
    _check_ext_col(t, layers, path)
    codes = _int_col(t, "CODE", path)
    bad = (codes < 0) | (codes > MAX_CODE)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(t, k, t.raw("CODE")[1], path, "a code 0-99", str(codes[k]).encode())
    rows = np.zeros(n, LINE_DTYPE)
    rows["num"] = _int_col(t, "NUM", path)
    pos = off[:-1][row] + vertex - 1 if n else np.zeros(0, np.int64)
    rows["x"], rows["y"] = xy[pos, 0], xy[pos, 1]
    rows["z"] = _float_col(t, "HEIGHT", path)
    rows["code"] = codes
    for f, item in (("fwd", "FWD"), ("back", "BACK"), ("side1", "SIDE1"), ("side2", "SIDE2")):
        v = _int_col(t, item, path)
        rows[f] = np.where(v < 0, NO_REF, v)
    _, first = np.unique(layers, return_index=True)
    for ext in layers[np.sort(first)].tolist():
        _add_records(mp.layer(ext).add_line_points, path, rows[layers == ext])


def _add_records(add, path, *args) -> None:
    """A layer's bulk ``add_*`` method called with ``args``; what it refuses is a FormatError."""
    try:
        add(*args)
    except RecordError as exc:
        raise FormatError(str(exc), path=path) from None


def _labels_to_map(info, tables, mp: MapFile, default: str, path) -> None:
    lab = info["labels"]
    value = np.concatenate(lab["ids"]) if lab["ids"] else np.zeros(0, np.int64)
    xy = np.concatenate(lab["xy"]) if lab["xy"] else np.zeros((0, 2))
    n = len(value)
    pat = _table(tables, ".PAT", path)
    if pat is not None and len(pat) != n:
        raise FormatError(
            f"INFO table {pat.name} has {len(pat)} records for {n} label points", path=path
        )
    if n == 0:
        return
    x, y = xy[:, 0], xy[:, 1]
    if pat is None or not _need_items(pat, _PAT_ITEMS):
        nums = value
        if nums.min() < 0 or len(np.unique(nums)) != n:
            log.warning("%s: label IDs negative or repeated; symbols numbered 1..%d", path, n)
            nums = np.arange(1, n + 1)
        z = np.zeros(n)
        if pat is not None and pat.has("HEIGHT"):
            z = _float_col(pat, "HEIGHT", path)
        codes = np.zeros(n, np.int64)
        if pat is not None and pat.has("CODE"):
            codes = _int_col(pat, "CODE", path)
            bad = (codes < 0) | (codes > MAX_CODE)
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                _bad(pat, k, pat.raw("CODE")[1], path, "a code 0-99", str(codes[k]).encode())
        _add_records(mp.layer(default).add_symbols, path, np.column_stack([x, y, z]), codes, nums)
        return
    layers = _str_col(pat, "LAYER")
    _check_ext_col(pat, layers, path)
    kinds = _str_col(pat, "KIND")
    nums = _int_col(pat, "NUM", path)
    codes = _int_col(pat, "CODE", path)
    z = _float_col(pat, "HEIGHT", path)
    tlen = _int_col(pat, "TXTLEN", path)
    width = pat.raw("TEXT")[1][2]
    bad = (tlen < 0) | (tlen > width)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(pat, k, pat.raw("TXTLEN")[1], path, f"a length 0-{width}", str(tlen[k]).encode())
    bad = ~np.isin(kinds, ["S", "T"])
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(pat, k, pat.raw("KIND")[1], path, "S (symbol) or T (text)", kinds[k].encode())
    is_text = kinds == "T"
    bad = ~is_text & ((codes < 0) | (codes > MAX_CODE))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(pat, k, pat.raw("CODE")[1], path, "a code 0-99", str(codes[k]).encode())
    raw_text = pat.raw("TEXT")[0]
    texts = {}
    for k in np.flatnonzero(is_text).tolist():
        texts[k] = _decode_text(raw_text[k][: int(tlen[k])].ljust(int(tlen[k])))
        try:
            check_text(texts[k])
        except RecordError as exc:
            _bad(pat, k, pat.raw("TEXT")[1], path, f"a text ({exc})", texts[k].encode())
    _, first = np.unique(layers, return_index=True)
    for ext in layers[np.sort(first)].tolist():
        lay = mp.layer(ext)
        here = layers == ext
        sel = np.flatnonzero(here & ~is_text)
        xyz = np.column_stack([x, y, z])
        if len(sel):
            _add_records(lay.add_symbols, path, xyz[sel], codes[sel], nums[sel])
        sel = np.flatnonzero(here & is_text)
        if len(sel):
            _add_records(lay.add_texts, path, xyz[sel], [texts[k] for k in sel.tolist()], nums[sel])


# --------------------------------------------------------------------------- API


def read(
    path,
    progress=None,
    recover: bool = False,
    tolerance_m: float = 0.005,
    layer: str | None = None,
) -> MapFile:
    """Read an E00 file (compressed or not) into a map.

    Parameters
    ----------
    path : str or os.PathLike
    progress : callable, optional
        ``progress(done, total)``.
    recover : bool
        Read a damaged or truncated file as far as it goes (a warning names
        the damage) instead of raising.
    tolerance_m : float
        For files apygis did not write: distance within which arc ends join
        other arcs when the line topology is rebuilt.
    layer : str, optional
        For files apygis did not write: the layer extension of their records
        (default ``"a"``).

    Returns
    -------
    MapFile

    Raises
    ------
    FormatError
        Not an E00 file, a grid E00 file, or bad content (the message names
        the line and what was expected).
    """
    try:
        tol = float(tolerance_m)
    except (TypeError, ValueError):
        tol = math.nan
    if not math.isfinite(tol) or tol < 0:
        raise DriverError(f"tolerance_m is a distance in metres >= 0, not {tolerance_m!r}")
    info = decode(read_bytes(path), path, recover=recover)
    if progress:
        progress(1, 2)
    meta = _meta(info["tables"], path)
    mp = _map_from(info, meta, path, layer, tol)
    if progress:
        progress(2, 2)
    return mp


def probe(path) -> bool:
    """True for a file that begins with an E00 ``EXP`` line."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return False
    return head[:4].upper() == b"EXP " and head[4:7].strip() in (b"0", b"1")


DRIVER = Driver(
    name="e00",
    description="ARC/INFO interchange file: one line coverage with INFO tables "
    "(docs/formats/e00.md)",
    extensions=("e00",),
    reader=read,
    writer=write,
    probe=probe,
    outputs=outputs,
)
