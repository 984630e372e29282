"""ARC/INFO GENERATE: the plain-text points and lines files of ARC's GENERATE command.

APY's DATA EXCHANGE made "ARC/INFO files" from which the ARC/INFO user
generates line and point coverages, and read them back "with line points in
string format only". This driver writes and reads the same files, specified
in ``docs/formats/arcinfo-generate.md``.

File formats (as ARC/INFO writes them and GDAL's ARCGEN driver reads them)::

    points file          lines file
    1,2683005.000,...    1                  <- feature ID
    2,2683050.000,...    2683000.000,1247000.000,420.000
    END                  2683010.500,1247001.250,421.000
                         END                <- end of the feature
                         END                <- end of the file

Fields are separated by a comma (a space is accepted on reading); a
vertex has 2 fields (X, Y) or 3 (X, Y, Z), a point 3 or 4 (ID, X, Y[, Z]).

A map is written as a *file set*, one file per layer and kind of record,
named after the path given (``out/ZH1091.gen``)::

    out/ZH1091_<ext>_lines.gen     open lines          + _lines.csv    ID,CODE
    out/ZH1091_<ext>_polygons.gen  closed lines        + _polygons.csv ID,CODE
    out/ZH1091_<ext>_points.gen    symbols (ID = num)  + _points.csv   ID,CODE,HEIGHT
    out/ZH1091_<ext>_texts.gen     texts (ID = num)    + _texts.csv    ID,HEIGHT,TEXT
    out/ZH1091.prj                 the CRS as ESRI WKT (when the map has one)

GENERATE has no attributes, so each ``.gen`` file has a companion CSV
attribute table keyed by ID. Only non-empty tables get files.

Reading takes either one ``.gen`` file (points or lines, detected from the
content; a companion ``.csv`` beside it is used when present) or the name of
a set (``out/ZH1091.gen`` when ``out/ZH1091_*_lines.gen`` and the others
exist). Lines come back "in string format": the references are rebuilt with
the model's one topology rebuild, :meth:`apygis.model.Layer.add_polylines`
(:func:`apygis.model.polylines.rebuild`: consecutive vertices become forward
and backward references, ends that meet within ``tolerance_m`` metres merge
or become branches, rings close), so that AREA and closure checks work on
imported data; its report is logged (a warning when it refused a join or
removed duplicate vertices). Point numbers of line points are allocated
afresh.

Writing is columnar: the text of a million vertices is built as one byte
matrix with numpy, not formatted point by point.
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
import re
from pathlib import Path
from typing import NoReturn

import numpy as np

from apygis.errors import DriverError, FormatError, RecordError, ValueRangeError
from apygis.formats import READ_OPTIONS, Driver, Option
from apygis.formats._io import (
    atomic_write_many,
    check_resolution,
    metres_per_unit,
    read_bytes,
    stamp_path,
)
from apygis.formats._readguard import MAX_COORD, ascii_int, bad_coord_rows
from apygis.formats._report import warn
from apygis.formats._text import digit_columns, esri_wkt, put_right
from apygis.model import topology
from apygis.model.map import Layer, MapFile, check_ext, check_map_id, check_text
from apygis.model.polylines import export_lines, to_csr
from apygis.model.records import MAX_CODE
from apygis.model.symbols import IMPORTED_POINT, SPOT_HEIGHT

__all__ = [
    "DEFAULT_LAYER",
    "DRIVER",
    "KINDS",
    "decode_file",
    "encode_lines",
    "encode_points",
    "outputs",
    "probe",
    "read",
    "set_files",
    "write",
]

log = logging.getLogger(__name__)

KINDS = ("lines", "polygons", "points", "texts")
"""The kinds of file in a set, in the order they are written and read."""

DEFAULT_LAYER = "a"
"""Layer extension of a file that is not part of a set and names none."""

_SP, _COMMA, _NL, _DOT, _MINUS, _ZERO = 32, 44, 10, 46, 45, 48
_MEMBER_RE = re.compile(r"^(?P<ext>[a-z]{1,3})_(?P<kind>lines|polygons|points|texts)\.gen$")
_SET_NAME_RE = re.compile(
    r"^(?P<stem>.+)_(?P<ext>[a-z]{1,3})_(?P<kind>lines|polygons|points|texts)\.gen$"
)
_CSV_FIELDS = {
    "lines": ("ID", "CODE"),
    "polygons": ("ID", "CODE"),
    "points": ("ID", "CODE", "HEIGHT"),
    "texts": ("ID", "HEIGHT", "TEXT"),
}


# --------------------------------------------------------------------------- number columns


def _int_column(values: np.ndarray) -> np.ndarray:
    """Integers as a right-aligned ``(n, width)`` byte matrix (spaces on the left)."""
    v = np.asarray(values, dtype=np.int64)
    n = len(v)
    if n == 0:
        return np.zeros((0, 1), np.uint8)
    a = np.abs(v)
    nd = max(1, len(str(int(a.max()))))
    width = nd + 1  # room for a sign
    out = np.full((n, width), _SP, np.uint8)
    put_right(out, 0, width, a, v < 0)
    return out


def _fixed_column(values: np.ndarray, decimals: int, what: str = "coordinate") -> np.ndarray:
    """Reals with ``decimals`` decimals as a right-aligned ``(n, width)`` byte matrix.

    The value is rounded half to even at the last decimal; ``-0.000`` is
    written ``0.000``.
    """
    v = np.asarray(values, dtype=np.float64)
    n = len(v)
    if n == 0:
        return np.zeros((0, 1), np.uint8)
    if not np.isfinite(v).all():
        raise ValueRangeError(f"a {what} is not finite: GENERATE holds finite numbers only")
    scale = 10**decimals
    limit = 2.0**62 / scale
    if np.abs(v).max() >= limit:
        raise ValueRangeError(
            f"a {what} of {np.abs(v).max():.6g} is too large to write with {decimals} decimals"
        )
    a = np.rint(np.abs(v) * scale).astype(np.int64)
    ip, fp = a // scale, a % scale
    nint = max(1, len(str(int(ip.max()))))
    width = 1 + nint + (1 + decimals if decimals else 0)
    out = np.full((n, width), _SP, np.uint8)
    put_right(out, 0, 1 + nint, ip, (v < 0) & (a != 0))
    if decimals:
        out[:, 1 + nint] = _DOT
        out[:, 2 + nint :] = digit_columns(fp, decimals)
    return out


def _join_columns(columns: list[np.ndarray], sep: int = _COMMA) -> np.ndarray:
    """Columns side by side, ``sep`` between them and a newline after the last."""
    n = len(columns[0])
    width = sum(c.shape[1] for c in columns) + len(columns)
    out = np.full((n, width), _SP, np.uint8)
    col = 0
    for k, c in enumerate(columns):
        out[:, col : col + c.shape[1]] = c
        col += c.shape[1]
        out[:, col] = sep if k < len(columns) - 1 else _NL
        col += 1
    return out


def _squeeze(rows: np.ndarray) -> bytes:
    """The rows of a byte matrix with every space removed (the padding of the columns)."""
    return rows[rows != _SP].tobytes()


def _literal_rows(n: int, text: bytes) -> np.ndarray:
    out = np.empty((n, len(text)), np.uint8)
    out[:] = np.frombuffer(text, np.uint8)
    return out


def _stack_rows(parts: list[tuple[np.ndarray, np.ndarray]], total: int) -> np.ndarray:
    """Place row matrices at the given row positions of one matrix (space-padded)."""
    width = max(m.shape[1] for _, m in parts)
    out = np.full((total, width), _SP, np.uint8)
    for pos, m in parts:
        out[pos, : m.shape[1]] = m
    return out


# --------------------------------------------------------------------------- encode


def encode_points(ids, xyz: np.ndarray, dims: int = 3, decimals: int = 3) -> bytes:
    """A points file: ``ID,X,Y[,Z]`` lines and ``END``.

    Parameters
    ----------
    ids : array-like of int
        Point IDs.
    xyz : ndarray (n, 3)
        Coordinates in metres.
    dims : {2, 3}
        Write X, Y or X, Y, Z.
    decimals : int
        Decimals of the coordinates.

    >>> encode_points([1, 2], np.array([[2.0, 49.0, 10.0], [3.0, 50.0, 20.5]]))
    b'1,2.000,49.000,10.000\\n2,3.000,50.000,20.500\\nEND\\n'
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    cols = [_int_column(_check_ids(ids, "point number"))] + [
        _fixed_column(xyz[:, k], decimals) for k in range(dims)
    ]
    body = _squeeze(_join_columns(cols)) if len(xyz) else b""
    return body + b"END\n"


def encode_lines(
    ids, coords: np.ndarray, offsets: np.ndarray, dims: int = 3, decimals: int = 3
) -> bytes:
    """A lines file: per feature an ID line, its vertices and ``END``; a final ``END``.

    ``coords[offsets[k]:offsets[k + 1]]`` are the vertices of feature ``k``
    (a polygon repeats its first vertex at the end, as ARC/INFO writes it).

    >>> encode_lines([7], np.array([[2.0, 49.0, 0.0], [3.0, 50.0, 0.0]]), np.array([0, 2]), dims=2)
    b'7\\n2.000,49.000\\n3.000,50.000\\nEND\\nEND\\n'
    """
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    offsets = np.asarray(offsets, dtype=np.int64)
    ids = _check_ids(ids, "feature ID")
    m = len(offsets) - 1
    if m == 0:
        return b"END\n"
    lens = np.diff(offsets)
    total = len(coords) + 2 * m + 1
    before = offsets[:-1]
    k = np.arange(m)
    id_pos = before + 2 * k
    end_pos = offsets[1:] + 2 * k + 1
    line_of = np.repeat(k, lens)
    vert_pos = np.arange(len(coords)) + 2 * line_of + 1
    parts = [
        (id_pos, _join_columns([_int_column(ids)])),
        (end_pos, _literal_rows(m, b"END\n")),
        (np.array([total - 1]), _literal_rows(1, b"END\n")),
    ]
    if len(coords):
        cols = [_fixed_column(coords[:, c], decimals) for c in range(dims)]
        parts.append((vert_pos, _join_columns(cols)))
    return _squeeze(_stack_rows(parts, total))


def _check_ids(ids, what: str) -> np.ndarray:
    ids = np.asarray(ids, dtype=np.int64)
    if len(ids) and (ids.min() < -(2**31) or ids.max() >= 2**31):
        bad = int(ids[(ids < -(2**31)) | (ids >= 2**31)][0])
        raise ValueRangeError(f"{what} {bad} does not fit a GENERATE ID (32-bit integer)")
    return ids


def _csv_numeric(columns: list[np.ndarray], header: tuple[str, ...]) -> bytes:
    head = (",".join(header) + "\n").encode()
    if len(columns[0]) == 0:
        return head
    return head + _squeeze(_join_columns(columns))


def _polyline_subset(ls, sel: np.ndarray, close: bool) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and offsets of the lines ``sel`` of a LineSet (rings closed explicitly)."""
    starts = ls.offsets[:-1][sel]
    lens = ls.offsets[1:][sel] - starts
    extra = int(close)
    out_lens = lens + extra * (lens > 0)
    offsets = np.r_[0, np.cumsum(out_lens)].astype(np.int64)
    line_of = np.repeat(np.arange(len(sel)), out_lens)
    pos = np.arange(offsets[-1]) - offsets[:-1][line_of]
    src = starts[line_of] + np.where(pos >= lens[line_of], 0, pos)
    return ls.coords[src], offsets


def _target_base(map_: MapFile, path) -> Path:
    p = Path(path)
    if p.is_dir():
        return p / map_.id
    if p.suffix.lower() == ".gen":
        return p.with_suffix("")
    return p


def _member(base: Path, ext: str, kind: str, suffix: str = ".gen") -> Path:
    return base.with_name(f"{base.name}_{ext}_{kind}{suffix}")


def _layer_contents(layer: Layer, base: Path, dims: int, decimals: int) -> dict[Path, bytes]:
    out: dict[Path, bytes] = {}
    ext = layer.ext
    ls = export_lines(layer)
    ids_all = np.arange(1, len(ls) + 1, dtype=np.int64)
    for kind, mask in (("lines", ~ls.closed), ("polygons", ls.closed)):
        sel = np.flatnonzero(mask)
        if len(sel) == 0:
            continue
        coords, offsets = _polyline_subset(ls, sel, close=(kind == "polygons"))
        ids = ids_all[sel]
        out[_member(base, ext, kind)] = encode_lines(ids, coords, offsets, dims, decimals)
        out[_member(base, ext, kind, ".csv")] = _csv_numeric(
            [_int_column(ids), _int_column(ls.codes[sel])], _CSV_FIELDS[kind]
        )
    sym = layer.symbols
    if len(sym):
        xyz = np.column_stack([sym["x"], sym["y"], sym["z"]])
        out[_member(base, ext, "points")] = encode_points(sym["num"], xyz, dims, decimals)
        out[_member(base, ext, "points", ".csv")] = _csv_numeric(
            [
                _int_column(sym["num"]),
                _int_column(sym["code"]),
                _fixed_column(sym["z"], decimals, "height"),
            ],
            _CSV_FIELDS["points"],
        )
    tx = layer.texts
    if len(tx):
        xyz = np.column_stack([tx["x"], tx["y"], tx["z"]])
        out[_member(base, ext, "texts")] = encode_points(tx["num"], xyz, dims, decimals)
        heights = _fixed_column(tx["z"], decimals, "height")
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(_CSV_FIELDS["texts"])
        for num, h, text in zip(tx["num"].tolist(), heights, tx["text"].tolist(), strict=True):
            w.writerow([num, h[h != _SP].tobytes().decode("ascii"), text])
        out[_member(base, ext, "texts", ".csv")] = buf.getvalue().encode("utf-8")
    return out


def _prj_text(crs) -> bytes:
    return esri_wkt(crs).encode("utf-8")


def _check_options(dims: int, decimals: int) -> None:
    if dims not in (2, 3):
        raise DriverError(f"GENERATE writes 2 or 3 dimensions, not dims={dims!r}")
    if not isinstance(decimals, int) or not 0 <= decimals <= 9:
        raise DriverError(f"decimals is an integer from 0 to 9, not {decimals!r}")


def _contents(map_: MapFile, path, dims: int, decimals: int) -> dict[Path, bytes]:
    base = _target_base(map_, path)
    contents: dict[Path, bytes] = {}
    for layer in map_:
        contents.update(_layer_contents(layer, base, dims, decimals))
    if not contents:
        raise DriverError(f"{path}: map {map_.id} has no records: nothing to write")
    if map_.crs is not None:
        contents[base.with_name(base.name + ".prj")] = _prj_text(map_.crs)
    return contents


def _planned(map_: MapFile, path) -> list[Path]:
    """The file names a write would create, without formatting any number."""
    base = _target_base(map_, path)
    out = []
    for layer in map_:
        cs = layer.chains()
        for kind, n in (
            ("lines", int((~cs.closed).sum())),
            ("polygons", int(cs.closed.sum())),
            ("points", len(layer.symbols)),
            ("texts", len(layer.texts)),
        ):
            if n:
                out += [_member(base, layer.ext, kind), _member(base, layer.ext, kind, ".csv")]
    if out and map_.crs is not None:
        out.append(base.with_name(base.name + ".prj"))
    return out


def outputs(map_: MapFile, path) -> list[Path]:
    """Every file :func:`write` would create for ``map_`` at ``path``.

    >>> m = MapFile("ZH1091")
    >>> _ = m.layer("r").add_line([(0, 0, 0), (1, 0, 0)], code=11)
    >>> _ = m.layer("r").add_symbol(0, 0, 0, code=6)
    >>> [p.name for p in outputs(m, "out/ZH1091.gen")]
    ['ZH1091_r_lines.gen', 'ZH1091_r_lines.csv', 'ZH1091_r_points.gen', 'ZH1091_r_points.csv']
    """
    return _planned(map_, path)


def set_files(path) -> dict[tuple[str, str], Path]:
    """The members of the set named by ``path``: ``{(ext, kind): file}``.

    ``path`` is ``dir/NAME.gen`` (or ``dir/NAME``); members are
    ``dir/NAME_<ext>_<kind>.gen``.
    """
    p = Path(path)
    base = p.with_suffix("") if p.suffix.lower() == ".gen" else p
    folder = base.parent
    if not folder.is_dir():
        return {}
    prefix = base.name + "_"
    found = {}
    try:
        names = sorted(os.listdir(folder))
    except OSError:
        return {}
    for name in names:
        if not name.startswith(prefix):
            continue
        m = _MEMBER_RE.match(name[len(prefix) :])
        if m and (folder / name).is_file():
            found[(m["ext"], m["kind"])] = folder / name
    return found


def _auto_decimals(map_: MapFile) -> int:
    """Decimals for millimetres (3 in metres or feet; 9 in degrees: 0.1 mm)."""
    if map_.crs is None:
        return 3
    m = metres_per_unit(map_.crs)
    return max(3, min(9, math.ceil(-math.log10(0.001 / m) - 1e-9)))


def members(path) -> tuple[Path, list[Path], bool] | None:
    """The set stamp and the files of the set a read of ``path`` takes."""
    p = Path(path)
    base = p.with_suffix("") if p.suffix.lower() == ".gen" else p
    stamp = stamp_path(base)
    if p.is_file():
        return stamp, [p, *[c for c in [p.with_suffix(".csv")] if c.is_file()]], False
    files = []
    for gen in set_files(base).values():
        files += [gen, *[c for c in [gen.with_suffix(".csv")] if c.is_file()]]
    prj = base.with_name(base.name + ".prj")
    if prj.is_file():
        files.append(prj)
    return stamp, files, True


def write(
    map_: MapFile, path, progress=None, dims: int = 3, decimals: int | None = None
) -> list[Path]:
    """Write a map as a set of GENERATE files with CSV attribute tables, atomically.

    Parameters
    ----------
    map_ : MapFile
    path : str or os.PathLike
        ``dir/NAME.gen`` (or ``dir/NAME``; an existing directory means
        ``dir/<map id>``): the set's files are ``dir/NAME_<ext>_<kind>.gen``.
    progress : callable, optional
        ``progress(done, total)``.
    dims : {3, 2}
        Write X, Y, Z (default) or X, Y (heights are then only in the CSV
        tables of points and texts).
    decimals : int, optional
        Decimals of coordinates and heights (default: millimetres, 3 in
        metres or feet, 9 in degrees). Decimals coarser than a centimetre in
        the map's CRS unit are refused.

    Returns
    -------
    list of Path
        The files written. Files of this set's naming that the map no longer
        fills (a layer or table that is now empty) are removed, so that
        reading the set gives this map back.
    """
    if decimals is None:
        decimals = _auto_decimals(map_)
    _check_options(dims, decimals)
    check_resolution(map_, path, 10.0**-decimals, f"GENERATE is written with {decimals} decimals")
    contents = _contents(map_, path, dims, decimals)
    if progress:
        progress(1, 2)
    base = _target_base(map_, path)
    stale = [f for old in set_files(base).values() for f in (old, old.with_suffix(".csv"))]
    stale.append(base.with_name(base.name + ".prj"))
    stale = [f for f in stale if f not in contents and f.is_file()]
    for f in stale:
        log.info("removing %s: the map no longer has these records", f)
    written = atomic_write_many(contents, stamp_path(base), complete=True, remove=stale)
    if progress:
        progress(2, 2)
    return written


# --------------------------------------------------------------------------- decode

_WS = np.zeros(256, bool)
_WS[[9, 10, 11, 12, 13, 32, 44]] = True  # whitespace and the comma separate fields
_MAX_TOKEN = 64


def _fields(line: bytes) -> list[bytes]:
    return line.replace(b",", b" ").split()


def _is_end(fields: list[bytes]) -> bool:
    return len(fields) == 1 and fields[0].upper() == b"END"


class _Tokens:
    """The fields of a text, found with array operations.

    ``mat`` holds each field left-aligned in a row (NUL-padded), ``lens`` their
    lengths, ``line`` the 0-based line of each, ``counts`` the fields per line.
    """

    def __init__(self, data: bytes, path):
        self.path = path
        if b"\0" in data:
            raise FormatError("binary data (NUL bytes): not a GENERATE text file", path=path)
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
        buf = np.frombuffer(data, np.uint8)
        ws = _WS[buf]
        starts = np.flatnonzero(~ws & np.r_[True, ws[:-1]]) if len(buf) else np.zeros(0, int)
        ends = np.flatnonzero(~ws & np.r_[ws[1:], True]) + 1 if len(buf) else starts
        nl = np.flatnonzero(buf == _NL)
        self.nlines = len(nl) + 1
        self.text_lines = len(nl) + (0 if data.endswith(b"\n") else 1)  # for messages
        self.line = np.searchsorted(nl, starts)
        self.lens = ends - starts
        self.counts = np.bincount(self.line, minlength=self.nlines)
        self.first = np.r_[0, np.cumsum(self.counts)][:-1]  # first field of each line
        if len(self.lens) and self.lens.max() > _MAX_TOKEN:
            k = int(np.argmax(self.lens))
            self.fail(f"a field of {self.lens[k]} characters; GENERATE fields are numbers", k)
        width = max(3, int(self.lens.max()) if len(self.lens) else 0)  # 3: room for END
        self.mat = np.zeros((len(starts), width), np.uint8)
        last = max(len(buf) - 1, 0)
        for c in range(width):  # column by column: no (fields x width) index array
            inside = self.lens > c
            self.mat[inside, c] = buf[np.minimum(starts[inside] + c, last)]
        low = self.mat[:, :3] | 0x20
        self.is_end = (self.lens == 3) & (low == np.frombuffer(b"end", np.uint8)).all(axis=1)

    def text(self, k: int) -> str:
        return self.mat[k, : self.lens[k]].tobytes().decode("latin-1")

    def fail(self, msg: str, token: int | None = None, line: int | None = None) -> NoReturn:
        if line is None:
            line = int(self.line[token]) if token is not None else max(self.text_lines - 1, 0)
        raise FormatError(msg, path=self.path, record=f"line {line + 1}")

    def ints(self, toks: np.ndarray, what: str) -> np.ndarray:
        """Fields as 32-bit integers (optional sign, digits)."""
        return _chunked(self._ints, toks, what)

    def reals(self, toks: np.ndarray, names: str) -> np.ndarray:
        """Fields as finite floats: plain decimals exactly, anything else via numpy."""
        return _chunked(self._reals, toks, names)

    def _ints(self, toks: np.ndarray, what: str) -> np.ndarray:
        m = self.mat[toks]
        lens = self.lens[toks]
        sign = (m[:, 0] == _MINUS) | (m[:, 0] == 43)
        col = np.arange(m.shape[1])[None, :]
        isd = (m >= _ZERO) & (m <= _ZERO + 9)
        body = (col >= sign[:, None]) & (col < lens[:, None])
        ok = (isd | ~body).all(axis=1) & (lens - sign >= 1) & (lens - sign <= 10)
        d = np.where(isd & body, m.astype(np.int64) - _ZERO, 0)
        right = np.cumsum(body[:, ::-1], axis=1)[:, ::-1] - body
        v = (d * 10 ** np.minimum(right, 18)).sum(axis=1)
        v = np.where(m[:, 0] == _MINUS, -v, v)
        ok &= (v >= -(2**31)) & (v < 2**31)
        if not ok.all():
            k = int(toks[np.flatnonzero(~ok)[0]])
            self.fail(f"expected an integer {what} (32 bits), found {self.text(k)!r}", k)
        return v

    def _reals(self, toks: np.ndarray, names: str) -> np.ndarray:
        m = self.mat[toks]
        lens = self.lens[toks]
        w = m.shape[1]
        col = np.arange(w)[None, :]
        sign = (m[:, 0] == _MINUS) | (m[:, 0] == 43)
        body = (col >= sign[:, None]) & (col < lens[:, None])
        isd = (m >= _ZERO) & (m <= _ZERO + 9) & body
        dot = (m == _DOT) & body
        ndig = isd.sum(axis=1)
        simple = ((isd | dot | ~body).all(axis=1)) & (dot.sum(axis=1) <= 1) & (ndig >= 1)
        simple &= ndig <= 15
        right = np.cumsum(isd[:, ::-1], axis=1)[:, ::-1] - isd
        mant = (np.where(isd, m.astype(np.int64) - _ZERO, 0) * 10 ** np.minimum(right, 18)).sum(
            axis=1
        )
        dotpos = np.where(dot.any(axis=1), np.argmax(dot, axis=1), w)
        nfrac = (isd & (col > dotpos[:, None])).sum(axis=1)
        v = mant / 10.0**nfrac
        v = np.where(m[:, 0] == _MINUS, -v, v)
        other = np.flatnonzero(~simple)
        if len(other):
            raw = np.ascontiguousarray(m[other]).view(f"S{w}").reshape(-1)
            try:
                v[other] = raw.astype(np.float64)
            except ValueError:
                for j, k in enumerate(other):
                    try:
                        float(raw[j])
                    except ValueError:
                        self.fail(
                            f"expected numbers ({names}), found {self.text(int(toks[k]))!r}",
                            int(toks[k]),
                        )
        bad = bad_coord_rows(v)
        if len(bad):
            tok = int(toks[bad[0]])
            self.fail(
                f"expected finite numbers ({names}) of at most {MAX_COORD:g} in magnitude, "
                f"found {self.text(tok)!r}",
                tok,
            )
        return v


def _chunked(fn, toks: np.ndarray, what: str, size: int = 1 << 19) -> np.ndarray:
    """``fn`` over slices of ``toks``: bounded temporary arrays for big files."""
    if len(toks) <= size:
        return fn(toks, what)
    return np.concatenate([fn(toks[k : k + size], what) for k in range(0, len(toks), size)])


def _decode_points(tk: _Tokens, first_line: int) -> dict:
    line_end = np.zeros(tk.nlines, bool)
    single = np.flatnonzero(tk.counts == 1)
    line_end[single] = tk.is_end[tk.first[single]]
    ends = np.flatnonzero(line_end)
    if len(ends) == 0:
        tk.fail("the file ends without END (is it truncated?)")
    e = int(ends[0])
    after = np.flatnonzero(tk.counts[e + 1 :] > 0)
    if len(after):
        tk.fail("data after the final END", line=e + 1 + int(after[0]))
    ncols = int(tk.counts[first_line])
    lines = np.flatnonzero(tk.counts[:e] > 0)
    bad = np.flatnonzero(tk.counts[lines] != ncols)
    if len(bad):
        ln = int(lines[bad[0]])
        c = int(tk.counts[ln])
        if c in (3, 4):
            tk.fail(f"expected {ncols} fields like the first point, found {c}", line=ln)
        tk.fail(f"expected ID, X, Y[, Z] (3 or 4 fields), found {c} fields", line=ln)
    toks = tk.first[lines][:, None] + np.arange(ncols)[None, :]
    dims = ncols - 1
    ids = tk.ints(toks[:, 0], "point ID")
    xyz = np.zeros((len(lines), 3))
    if len(lines):
        names = "X, Y" + (", Z" if dims == 3 else "")
        xyz[:, :dims] = tk.reals(toks[:, 1:].reshape(-1), names).reshape(-1, dims)
    return {"kind": "points", "ids": ids, "xyz": xyz, "dims": dims}


def _decode_lines(tk: _Tokens) -> dict:
    nb = np.flatnonzero(tk.counts > 0)
    end_nb = (tk.counts[nb] == 1) & tk.is_end[tk.first[nb]]
    prev_end = np.r_[True, end_nb[:-1]]
    final = np.flatnonzero(end_nb & prev_end)
    if len(final) == 0:
        tk.fail("the file ends without the final END (is it truncated?)")
    f = int(final[0])
    if f + 1 < len(nb):
        tk.fail("data after the final END", line=int(nb[f + 1]))
    nb, end_nb, prev_end = nb[:f], end_nb[:f], prev_end[:f]
    id_mask = prev_end & ~end_nb
    vx_mask = ~prev_end & ~end_nb
    id_lines, vx_lines = nb[id_mask], nb[vx_mask]
    bad = np.flatnonzero(~np.isin(tk.counts[id_lines], (1, 3)))
    if len(bad):
        ln = int(id_lines[bad[0]])
        tk.fail(
            "expected a feature ID line (ID, or ID and a label point), "
            f"found {tk.counts[ln]} fields",
            line=ln,
        )
    dims = int(tk.counts[vx_lines[0]]) if len(vx_lines) else 3
    bad = np.flatnonzero(tk.counts[vx_lines] != dims)
    if len(vx_lines) and dims not in (2, 3):
        bad = np.r_[0, bad]
    if len(bad):
        ln = int(vx_lines[bad[0]])
        c = int(tk.counts[ln])
        if dims in (2, 3) and c in (2, 3):
            tk.fail(f"expected a vertex of {dims} fields like the first one, found {c}", line=ln)
        tk.fail(f"expected a vertex X, Y[, Z] (2 or 3 fields), found {c} fields", line=ln)
    feature = np.cumsum(id_mask) - 1
    counts = np.bincount(feature[vx_mask], minlength=len(id_lines))
    empty = np.flatnonzero(counts == 0)
    if len(empty):
        ln = int(id_lines[empty[0]])
        tk.fail(f"feature {tk.text(int(tk.first[ln]))} has no vertices", line=ln)
    ids = tk.ints(tk.first[id_lines], "feature ID")
    coords = np.zeros((len(vx_lines), 3))
    if len(vx_lines):
        toks = (tk.first[vx_lines][:, None] + np.arange(dims)[None, :]).reshape(-1)
        names = "X, Y" + (", Z" if dims == 3 else "")
        coords[:, :dims] = tk.reals(toks, names).reshape(-1, dims)
    offsets = np.r_[0, np.cumsum(counts)].astype(np.int64)
    return {"kind": "lines", "ids": ids, "coords": coords, "offsets": offsets, "dims": dims}


def decode_file(data: bytes, path=None) -> dict:
    """Parse one GENERATE file; the kind (points or lines) is read from its first line.

    Returns a dict: ``kind`` (``"points"``, ``"lines"`` or ``"empty"``),
    ``ids``, ``dims`` and ``xyz`` (points) or ``coords`` and ``offsets``
    (lines).

    >>> d = decode_file(b"1\\n2,49\\n3,50\\nEND\\nEND\\n")
    >>> d["kind"], d["ids"].tolist(), d["coords"][:, :2].tolist()
    ('lines', [1], [[2.0, 49.0], [3.0, 50.0]])
    """
    tk = _Tokens(data, path)
    nonblank = np.flatnonzero(tk.counts > 0)
    if len(nonblank) == 0:
        raise FormatError("the file is empty: expected GENERATE points or lines", path=path)
    first = int(nonblank[0])
    c = int(tk.counts[first])
    if c == 1 and tk.is_end[tk.first[first]]:  # no feature at all: only the final END
        if len(nonblank) > 1:
            tk.fail("data after the final END", line=int(nonblank[1]))
        return {"kind": "empty", "ids": np.zeros(0, np.int64), "dims": 3}
    if c in (3, 4):
        return _decode_points(tk, first)
    if c == 1:
        return _decode_lines(tk)
    tk.fail(
        f"expected a feature ID (lines file) or ID, X, Y[, Z] (points file), found {c} fields",
        line=first,
    )
    raise AssertionError  # pragma: no cover


class _Attributes:
    """A companion CSV attribute table, by column, keyed by ID."""

    def __init__(self, path: Path):
        self.path = path
        data = read_bytes(path)
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise FormatError(f"not UTF-8 ({exc.reason} at byte {exc.start})", path=path) from None
        if "\0" in text:
            raise FormatError("binary data (NUL bytes): not a CSV table", path=path)
        reader = csv.reader(io.StringIO(text, newline=""))
        rows, lines = [], []
        try:
            header = next(reader, None)
            if header is None:
                raise FormatError("empty attribute table: expected a header line", path=path)
            for row in reader:
                if row and any(c.strip() for c in row):
                    rows.append(row)
                    lines.append(reader.line_num)
        except csv.Error as exc:
            raise FormatError(
                f"bad CSV: {exc}", path=path, record=f"line {reader.line_num}"
            ) from None
        self.header = [h.strip().upper() for h in header]
        if "ID" not in self.header:
            raise FormatError(
                f"the header must name an ID column, found {','.join(self.header)!r}",
                path=path,
                record="line 1",
            )
        self.lines = np.asarray(lines, np.int64)
        widths = np.fromiter((len(r) for r in rows), np.int64, len(rows))
        bad = np.flatnonzero(widths != len(self.header))
        if len(bad):
            k = int(bad[0])
            self.fail(
                f"expected {len(self.header)} fields ({','.join(self.header)}), found {widths[k]}",
                k,
            )
        cols = list(zip(*rows, strict=True)) if rows else [()] * len(self.header)
        self.cols = {h: np.array(c, dtype=object) for h, c in zip(self.header, cols, strict=True)}
        self.ids = self.ints("ID", -(2**31), 2**31 - 1)
        order = np.argsort(self.ids, kind="stable")
        dup = np.flatnonzero(np.diff(self.ids[order]) == 0)
        if len(dup):
            k = int(order[dup[0] + 1])
            self.fail(f"ID {self.ids[k]} appears twice", k)

    def __len__(self) -> int:
        return len(self.ids)

    def fail(self, msg: str, row: int) -> NoReturn:
        raise FormatError(msg, path=self.path, record=f"line {self.lines[row]}")

    def has(self, name: str) -> bool:
        return name in self.cols

    def need(self, name: str) -> None:
        if name not in self.cols:
            raise FormatError(f"the header lacks a {name} column", path=self.path, record="line 1")

    def ints(self, name: str, lo: int, hi: int, rows=None) -> np.ndarray:
        self.need(name)
        col = self.cols[name] if rows is None else self.cols[name][rows]
        rows = np.arange(len(col)) if rows is None else rows
        ints = [ascii_int(str(s).strip(), signed=True) for s in col]  # no '²', no '1_0'
        v = None if None in ints else np.array(ints, dtype=np.int64)
        if v is None or (len(v) and ((v < lo) | (v > hi)).any()):
            for j, s in enumerate(col):
                x = ints[j]
                ok = x is not None and lo <= x <= hi
                if not ok:
                    self.fail(f"{name} must be an integer from {lo} to {hi}, not {s!r}", rows[j])
        assert v is not None  # a value that is None (not an integer) failed above
        return v

    def reals(self, name: str, rows) -> np.ndarray:
        self.need(name)
        col = self.cols[name][rows]
        try:
            v = np.array([float(s) for s in col], dtype=np.float64)
        except ValueError:
            v = None
        if v is None or len(bad_coord_rows(v)):
            for j, s in enumerate(col):
                try:
                    ok = abs(float(s)) <= MAX_COORD  # False for NaN
                except ValueError:
                    ok = False
                if not ok:
                    self.fail(
                        f"{name} must be a finite number of at most {MAX_COORD:g} in "
                        f"magnitude, not {s[:40]!r}",
                        rows[j],
                    )
        assert v is not None  # a value float() refuses failed above
        return v

    def rows_for(self, ids: np.ndarray) -> np.ndarray:
        """Row of each ID (-1 where the table has none; logged)."""
        rows = topology.lookup(self.ids, ids)
        if (rows < 0).any():
            warn(
                log,
                f"{self.path}: no attributes for ID {ids[rows < 0][:5].tolist()}; defaults used",
                "skipped",
                int((rows < 0).sum()),
                "attributes",
            )
        return rows


def _unique_nums(ids: np.ndarray, path, what: str) -> np.ndarray:
    if len(ids) and (ids.min() < 0 or len(np.unique(ids)) != len(ids)):
        warn(
            log,
            f"{path}: {what} IDs are negative or repeated; numbered 1..{len(ids)}",
            "renumbered",
            len(ids),
            what,
        )
        return np.arange(1, len(ids) + 1, dtype=np.int64)
    return ids


def _points_to_layer(
    layer, d: dict, kind: str, table, gen_path, code: int | None, point_code: int
) -> None:
    ids, xyz = d["ids"], d["xyz"]
    rows = table.rows_for(ids) if table is not None else np.full(len(ids), -1)
    have = np.flatnonzero(rows >= 0)
    nums = _unique_nums(ids, gen_path, "text" if kind == "texts" else "symbol")
    xyz = np.array(xyz, dtype=float)
    if table is not None and d["dims"] == 2 and (kind == "texts" or table.has("HEIGHT")):
        xyz[have, 2] = table.reals("HEIGHT", rows[have])
    if kind == "symbols":
        if code is not None:
            codes = np.full(len(ids), code, np.int64)
        else:  # a height makes a spot height (00), else an imported point
            codes = np.where(xyz[:, 2] != 0, SPOT_HEIGHT, point_code).astype(np.int64)
        if table is not None:
            codes[have] = table.ints("CODE", 0, MAX_CODE, rows[have])
        layer.add_symbols(xyz, codes, nums)
        return
    out = [""] * len(ids)
    if table is not None:
        table.need("TEXT")
        texts = table.cols["TEXT"]
        for k in have:
            try:
                out[k] = check_text(texts[rows[k]])
            except RecordError as exc:
                table.fail(str(exc), rows[k])
    layer.add_texts(xyz, out, nums)


def _line_codes(d: dict, table, code: int | None) -> list[int]:
    codes = np.full(len(d["ids"]), 0 if code is None else code, np.int64)
    if table is not None:
        rows = table.rows_for(d["ids"])
        have = np.flatnonzero(rows >= 0)
        codes[have] = table.ints("CODE", 0, MAX_CODE, rows[have])
    return codes.tolist()


def _add_lines(layer: Layer, lines: list[np.ndarray], codes, closed, tol: float, crs, path) -> None:
    """The lines through the model's one topology rebuild; its report logged."""
    if not lines:
        return
    coords, offsets = to_csr(lines)
    rep = layer.add_polylines(coords, offsets, codes, closed, snap_m=tol, crs=crs)
    text = f"{path}: layer {layer.ext}: lines rebuilt: {rep.message()}"
    if rep.refused or rep.duplicates_removed or rep.empty:
        warn(log, text, "rebuilt", None, "lines")
    else:
        log.info("%s", text)


def _lines_of(d: dict) -> list[np.ndarray]:
    c, off = d["coords"], d["offsets"]
    return [c[off[k] : off[k + 1]] for k in range(len(off) - 1)]


def _map_name(name: str) -> str:
    cleaned = re.sub(r"[^A-Za-z0-9_-]", "_", name)[:32] or "GENERATE"
    return check_map_id(cleaned)


def _read_prj(path: Path):
    if not path.is_file():
        return None
    text = read_bytes(path).decode("utf-8", errors="replace").strip()
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        return CRS.from_user_input(text)
    except CRSError as exc:
        warn(log, f"{path}: not a readable CRS ({exc}); the map has none", "crs")
        return None


def _check_tol(tolerance_m) -> float:
    try:
        tol = float(tolerance_m)
    except (TypeError, ValueError):
        tol = math.nan
    if not math.isfinite(tol) or tol < 0:
        raise DriverError(f"tolerance_m is a distance in metres >= 0, not {tolerance_m!r}")
    return tol


def _check_kind(d: dict, kind: str, path: Path) -> None:
    want = "lines" if kind in ("lines", "polygons") else "points"
    if d["kind"] not in (want, "empty"):
        raise FormatError(
            f"a {kind} file of a set must be a GENERATE {want} file, this is a {d['kind']} file",
            path=path,
        )


def _read_single(
    p: Path, layer: str | None, tol: float, code: int | None, point_code: int, crs
) -> MapFile:
    d = decode_file(read_bytes(p), p)
    member = _SET_NAME_RE.match(p.name)
    map_name, ext, kind = p.stem, None, None
    if member:
        map_name, ext, kind = member["stem"], member["ext"], member["kind"]
    ext = check_ext(layer) if layer else (ext or DEFAULT_LAYER)
    if kind is None:
        kind = "lines" if d["kind"] == "lines" else "symbols"
    kind = "symbols" if kind == "points" else kind
    csv_path = p.with_suffix(".csv")
    table = _Attributes(csv_path) if csv_path.is_file() else None
    if member is None and kind == "symbols" and table is not None and table.has("TEXT"):
        kind = "texts"
    _check_kind(d, kind, p)
    mp = MapFile(
        _map_name(map_name), crs=crs if crs is not None else _read_prj(p.with_suffix(".prj"))
    )
    lay = mp.layer(ext)
    if d["kind"] == "empty":
        return mp
    if kind in ("lines", "polygons"):
        lines = _lines_of(d)
        codes = _line_codes(d, table, code)
        _add_lines(lay, lines, codes, [kind == "polygons"] * len(lines), tol, mp.crs, p)
    else:
        _points_to_layer(lay, d, kind, table, p, code, point_code)
    return mp


def _read_set(
    p: Path, members: dict, tol: float, code: int | None, point_code: int, crs, progress
) -> MapFile:
    base = p.with_suffix("") if p.suffix.lower() == ".gen" else p
    if crs is None:
        crs = _read_prj(base.with_name(base.name + ".prj"))
    mp = MapFile(_map_name(base.name), crs=crs)
    exts = sorted({ext for ext, _ in members})
    done = 0
    for ext in exts:
        lay = mp.layer(ext)
        all_lines, all_codes, all_closed = [], [], []
        for kind in KINDS:
            f = members.get((ext, kind))
            if f is None:
                continue
            d = decode_file(read_bytes(f), f)
            _check_kind(d, kind, f)
            csv_path = f.with_suffix(".csv")
            table = _Attributes(csv_path) if csv_path.is_file() else None
            if table is None:
                warn(log, f"{f}: no attribute table {csv_path.name}; default codes", "skipped")
            if d["kind"] == "empty":
                pass
            elif kind in ("lines", "polygons"):
                lines = _lines_of(d)
                all_lines += lines
                all_codes += _line_codes(d, table, code)
                all_closed += [kind == "polygons"] * len(lines)
            else:
                kind_ = "symbols" if kind == "points" else kind
                _points_to_layer(lay, d, kind_, table, f, code, point_code)
            done += 1
            if progress:
                progress(done, len(members))
        # rings first, so that branches of open lines find their junctions on them
        order = sorted(range(len(all_lines)), key=lambda k: not all_closed[k])
        _add_lines(
            lay,
            [all_lines[k] for k in order],
            [all_codes[k] for k in order],
            [all_closed[k] for k in order],
            tol,
            mp.crs,
            base,
        )
    return mp


def read(
    path,
    progress=None,
    tolerance_m: float = 0.005,
    layer: str | None = None,
    default_code: int | None = None,
    point_code: int = IMPORTED_POINT,
    crs=None,
) -> MapFile:
    """Read a GENERATE file, or a whole set written by :func:`write`.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.gen`` file (points or lines), or a set's name ``dir/NAME.gen``
        when ``dir/NAME_<ext>_<kind>.gen`` files exist.
    progress : callable, optional
        ``progress(done, total)``.
    tolerance_m : float
        Planimetric distance within which line ends join other lines.
    layer : str, optional
        Layer extension for a single file (default: from a set member's
        name, else ``"a"``).
    default_code : int or None
        Code (0-99) of records that no attribute table describes. None:
        lines 00; points 00 (spot height) where they have a height (a 3-D
        file, Z not 0), else ``point_code``.
    point_code : int
        Code of points without a code or a height (default 90, imported point).
    crs : optional
        The CRS (GENERATE has none; a ``.prj`` beside the file is read otherwise).

    Returns
    -------
    MapFile
    """
    tol = _check_tol(tolerance_m)
    for name, value in (("default_code", default_code), ("point_code", point_code)):
        if value is None and name == "default_code":
            continue
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_CODE:
            raise DriverError(f"{name} is an integer from 0 to {MAX_CODE}, not {value!r}")
    p = Path(path)
    if p.is_file():
        mp = _read_single(p, layer, tol, default_code, point_code, crs)
        if progress:
            progress(1, 1)
        return mp
    members = set_files(p)
    if not members:
        raise FormatError("no such file, nor a GENERATE file set NAME_<ext>_<kind>.gen", path=p)
    if layer:
        raise DriverError(f"{p}: names a file set; layer= applies to a single file")
    return _read_set(p, members, tol, default_code, point_code, crs, progress)


def probe(path) -> bool:
    """True for a GENERATE file (by content), or a set's name (``dir/NAME.gen``)."""
    p = Path(path)
    if not p.exists():
        return bool(set_files(p))
    if not p.is_file():
        return False
    try:
        with open(p, "rb") as fh:
            head = fh.read(256)
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(0, size - 32))
            tail = fh.read()
    except OSError:
        return False
    eol = min((k for k in (head.find(b"\n"), head.find(b"\r")) if k >= 0), default=-1)
    if eol <= 0 or any(c < 32 for c in head[:eol]):
        return False
    first = _fields(head[:eol])
    if len(first) not in (1, 3, 4) or _is_end(first):
        return False
    try:
        [float(t) for t in first]
    except ValueError:
        return False
    return tail.rstrip().upper().endswith(b"END")


DRIVER = Driver(
    name="generate",
    description="ARC/INFO GENERATE points/lines files with CSV attributes "
    "(docs/formats/arcinfo-generate.md)",
    extensions=("gen",),
    reader=read,
    writer=write,
    probe=probe,
    outputs=outputs,
    members=members,
    options=(
        *(READ_OPTIONS[k] for k in ("tolerance_m", "crs", "default_code", "point_code")),
        Option("layer", "r", "str", "map layer of a single GENERATE file (default a)"),
        Option("dims", "w", "int", "coordinates written: 3 (X, Y, Z) or 2 (X, Y)", low=2, high=3),
        Option("decimals", "w", "int", "decimals of coordinates", low=0, high=15),
    ),
)
