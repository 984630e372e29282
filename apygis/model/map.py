"""The compiled map: a :class:`MapFile` of :class:`Layer` s of symbols, line points and texts.

>>> m = MapFile("ZH1091", scale=5000)
>>> roads = m.layer("r")
>>> roads.add_line([(0, 0, 400), (50, 0, 401), (50, 30, 402)], code=12)
[1, 2, 3]
>>> roads.add_symbol(10.0, 5.0, 400.5, code=7)
1
>>> roads.add_text(12.0, 5.0, 400.5, "Kirchweg")
1
>>> roads.counts()
{'symbols': 1, 'line_points': 3, 'lines': 1, 'closed_lines': 0, 'texts': 1}

Point numbers
-------------
The symbols, line points and texts of a layer are numbered independently. A
new record gets one more than the highest number in use (1 for the first).
Once 9999 (the largest number the APY native format stores) is in use, the
lowest free number from 0 to 9999 is taken instead, so that a layer can be
filled to APY's capacity of 10000 line points; past that, numbers go on
above 9999 (the model has no limit; only the native format refuses them).
The rule is :func:`apygis.model.records.next_numbers`; every add, single or
bulk, and every reader that numbers records uses it.

Bulk adds
---------
Drivers never touch the tables: they add many records at once with
:meth:`Layer.add_symbols`, :meth:`Layer.add_texts`,
:meth:`Layer.add_line_points` (records with their references, for formats
that store them) and :meth:`Layer.add_polylines` (plain geometry, through
the one topology rebuild of :mod:`apygis.model.polylines`), or build a layer
from whole tables with :meth:`Layer.from_arrays`. All check what they take
(coordinates finite and at most ``MAX_COORD``, codes 0-99, texts) and add
nothing when any record is bad.
"""

from __future__ import annotations

import math
import re
import reprlib
from collections.abc import Iterable, Sequence

import numpy as np

from apygis.errors import CRSError, RecordError, RecordNotFoundError, TopologyError
from apygis.model import topology
from apygis.model.records import (
    APY_CAPACITY,
    LINE_DTYPE,
    MAX_CODE,
    MAX_COORD,
    NO_REF,
    REF_FIELDS,
    SYMBOL_DTYPE,
    TABLES,
    TEXT_DTYPE,
    Table,
    next_numbers,
)

__all__ = [
    "Layer",
    "MapFile",
    "check_encodable",
    "check_ext",
    "check_map_id",
    "check_text",
    "crs_string",
]

_EXT_RE = re.compile(r"[a-z]{1,3}")  # fullmatch: "$" would let a final newline through
_ID_RE = re.compile(r"[A-Za-z0-9_-]{1,32}")


def check_ext(ext: str) -> str:
    """A layer extension: 1-3 letters, returned in lower case.

    >>> check_ext("R")
    'r'
    """
    if not isinstance(ext, str) or not _EXT_RE.fullmatch(ext.lower()):
        raise RecordError(f"a layer extension is 1 to 3 letters (a-z), not {ext!r}")
    return ext.lower()


def check_map_id(map_id: str) -> str:
    """A map identification: 1-32 characters of A-Z, a-z, 0-9, '_' and '-'."""
    if not isinstance(map_id, str) or not _ID_RE.fullmatch(map_id):
        raise RecordError(
            f"a map ID is 1 to 32 characters of letters, digits, '_' and '-', not {map_id!r}"
        )
    return map_id


def _check_code(code) -> int:
    if isinstance(code, bool) or not isinstance(code, (int, np.integer)):
        raise RecordError(f"a code is an integer from 0 to {MAX_CODE}, not {code!r}")
    if not 0 <= int(code) <= MAX_CODE:
        raise RecordError(f"a code is from 0 to {MAX_CODE}, not {code}")
    return int(code)


def _check_xyz(x, y, z) -> tuple[float, float, float]:
    try:
        v = (float(x), float(y), float(z))
    except (TypeError, ValueError):
        raise RecordError(f"coordinates must be numbers, not {(x, y, z)!r}") from None
    if not all(math.isfinite(c) for c in v):
        raise RecordError(f"coordinates must be finite, not {v!r}")
    return v


def _check_point(xyz) -> tuple[float, float, float]:
    """One position ``(x, y, z)``: three finite numbers."""
    try:
        x, y, z = xyz
    except (TypeError, ValueError):
        raise RecordError(f"a position is (x, y, z), not {reprlib.repr(xyz)}") from None
    return _check_xyz(x, y, z)


def _check_points(points, min_count: int) -> np.ndarray:
    """Positions ``[(x, y, z), ...]`` as an ``(n, 3)`` float array, ``n >= min_count``."""
    try:
        pts = np.asarray(list(points), dtype=float)
    except (TypeError, ValueError):
        raise RecordError(
            f"line points are (x, y, z) numbers each, not {reprlib.repr(points)}"
        ) from None
    if len(pts) == 0 and min_count == 0:
        return pts.reshape(0, 3)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < max(min_count, 1):
        what = "one or more points" if min_count else "points"
        raise RecordError(f"a line needs {what} of (x, y, z), not {reprlib.repr(points)}")
    if not np.isfinite(pts).all():
        raise RecordError("line coordinates must be finite")
    return pts


def check_encodable(value: str, what: str) -> str:
    """``value`` if it can be encoded (as UTF-8), else a RecordError naming ``what``.

    Only a lone surrogate (U+D800-U+DFFF, as ``surrogateescape`` decoding
    leaves for undecodable bytes) cannot: no file format could store it.

    >>> check_encodable("Kirchweg", "a text")
    'Kirchweg'
    >>> try:
    ...     check_encodable("Z\\udcfcrich", "the notes")
    ... except RecordError as exc:
    ...     print(exc)
    the notes cannot be encoded: character 2 of 'Z\\udcfcrich' is a lone surrogate (U+DCFC)
    """
    try:
        value.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise RecordError(
            f"{what} cannot be encoded: character {exc.start + 1} of {value!r} is a lone "
            f"surrogate (U+{ord(value[exc.start]):04X})"
        ) from None
    return value


def check_text(text) -> str:
    """A text: a string without control characters that can be encoded.

    The model keeps texts of any length; only the APY native formats hold
    at most :data:`~apygis.model.records.TEXT_LEN` (24) characters, and
    their writers refuse (or, asked to, cut) longer ones.
    """
    if not isinstance(text, str):
        raise RecordError(f"a text is a string, not {text!r}")
    if any(ord(c) < 32 or 127 <= ord(c) < 160 for c in text):
        raise RecordError(f"a text may not contain control characters: {text!r}")
    return check_encodable(text, "a text")


_SURROGATE = re.compile("[\ud800-\udfff]")


def _has_surrogate(text: str) -> bool:
    return _SURROGATE.search(text) is not None


def _linked(lp: np.ndarray, i: int, j: int) -> bool:
    """Whether line-point rows ``i`` and ``j`` reference each other by any reference."""
    ni, nj = lp["num"][i], lp["num"][j]
    return any(lp[f][i] == nj or lp[f][j] == ni for f in REF_FIELDS)


def _allocate(used: np.ndarray, count: int) -> np.ndarray:
    """``count`` new point numbers by the rule in this module's docstring."""
    return next_numbers(used, count)


def _check_bulk_xyz(xyz, what: str) -> np.ndarray:
    """Positions as an ``(n, 3)`` float array: finite, at most MAX_COORD in magnitude."""
    try:
        pts = np.asarray(xyz, dtype=float)
    except (TypeError, ValueError):
        raise RecordError(f"{what} positions are (n, 3) numbers") from None
    if pts.size == 0:
        return pts.reshape(0, 3)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise RecordError(f"{what} positions are an (n, 3) array, not {pts.shape}")
    bad = ~(np.abs(pts) <= MAX_COORD).all(axis=1)  # NaN compares False
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise RecordError(
            f"{what} {k + 1}: coordinates {pts[k].tolist()} are not finite or exceed "
            f"{MAX_COORD:g} in magnitude"
        )
    return pts


def _check_bulk_codes(codes, n: int, what: str) -> np.ndarray:
    """One code 0-99 or ``n`` of them, as an int array of ``n``."""
    c = np.asarray(codes)
    if c.dtype == bool or not (np.issubdtype(c.dtype, np.integer) or c.size == 0):
        raise RecordError(f"{what} codes are integers 0-{MAX_CODE}")
    try:
        c = np.broadcast_to(c.astype(np.int64), (n,))
    except ValueError:
        raise RecordError(f"one {what} code or one per {what} ({n}), not {c.shape}") from None
    bad = (c < 0) | (c > MAX_CODE)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise RecordError(f"{what} {k + 1}: a code is from 0 to {MAX_CODE}, not {int(c[k])}")
    return c


def _bulk_nums(used: np.ndarray, nums, n: int, what: str) -> np.ndarray:
    """New point numbers: by the numbering rule, or ``nums`` checked (>= 0, distinct, free)."""
    if nums is None:
        return next_numbers(used, n)
    v = np.asarray(nums)
    if v.shape != (n,) or not (np.issubdtype(v.dtype, np.integer) or n == 0):
        raise RecordError(f"{what} numbers: {n} integers, not {reprlib.repr(nums)}")
    v = v.astype(np.int64)
    if (v < 0).any():
        raise RecordError(f"{what} number {int(v[v < 0][0])}: point numbers are >= 0")
    both = np.r_[used, v]
    uniq, counts = np.unique(both, return_counts=True)
    if (counts > 1).any():
        raise RecordError(f"{what} number {int(uniq[counts > 1][0])} is used twice")
    return v


def _check_table(name: str, t: np.ndarray) -> None:
    """The values of a whole table: coordinates and codes (vectorised)."""
    what = {"symbols": "symbol", "line_points": "line point", "texts": "text"}[name]
    names = t.dtype.names
    assert names is not None  # a table is a structured array
    for axis in ("x", "y", "z"):
        v = t[axis]
        if not len(v) or (v.min() >= -MAX_COORD and v.max() <= MAX_COORD):  # NaN fails
            continue
        bad = ~(np.abs(v) <= MAX_COORD)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise RecordError(
                f"{what} {t['num'][k]}: {axis.upper()} {float(t[axis][k])!r} is not finite or "
                f"exceeds {MAX_COORD:g} in magnitude"
            )
    if "code" in names and len(t) and not 0 <= t["code"].min() <= t["code"].max() <= MAX_CODE:
        bad = (t["code"] < 0) | (t["code"] > MAX_CODE)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise RecordError(f"{what} {t['num'][k]}: code {t['code'][k]} is outside 0-{MAX_CODE}")
    if "text" in names:
        for k, tx in enumerate(t["text"].tolist()):
            if not isinstance(tx, str):
                raise RecordError(f"{what} {t['num'][k]}: a text is a string, not {tx!r}")


def _as_records(records, dtype: np.dtype, what: str) -> np.ndarray:
    """``records`` as a fresh array of ``dtype`` (fields converted by name)."""
    names = dtype.names
    assert names is not None  # a record dtype (SYMBOL_DTYPE, ...) is structured
    arr = np.asarray(records)
    if arr.dtype == dtype:
        return np.array(arr, copy=True).reshape(-1)
    if arr.dtype.names is None or not set(names) <= set(arr.dtype.names):
        raise RecordError(f"{what} records need the fields {', '.join(names)}")
    out = np.zeros(len(arr), dtype)
    for name in names:
        out[name] = arr[name]
    return out


class Layer:
    """One map layer: its symbols, line points and texts.

    The tables are read-only numpy structured arrays (:attr:`symbols`,
    :attr:`line_points`, :attr:`texts`; fields in
    :mod:`apygis.model.records`). Change them with the methods below, which
    keep point numbers unique and line references consistent, add many at once
    with the bulk adds (:meth:`add_symbols`, :meth:`add_texts`,
    :meth:`add_line_points`, :meth:`add_polylines`), or build a layer from
    whole tables with :meth:`from_arrays`. Only :mod:`apygis.model` touches
    the tables themselves (``tests/test_model_privacy.py`` holds it).
    """

    def __init__(self, ext: str):
        self.ext = check_ext(ext)
        self._tables = {name: Table(dtype) for name, dtype in TABLES.items()}

    # ------------------------------------------------------------------ tables

    @classmethod
    def from_arrays(cls, ext: str, symbols=None, line_points=None, texts=None) -> Layer:
        """A layer from whole tables (copied; missing fields of other dtypes converted).

        Coordinates (finite, at most :data:`~apygis.model.records.MAX_COORD`)
        and codes (0-99) are checked as by the bulk adds: a RecordError
        names the first bad record. Numbers, references and texts are taken
        as they are; :meth:`validate` says whether they are sound (readers
        of exact topology report it).
        """
        lay = cls(ext)
        for name, arr in (("symbols", symbols), ("line_points", line_points), ("texts", texts)):
            if arr is not None:
                lay._tables[name].replace(arr)
                _check_table(name, lay._tables[name].data)
        return lay

    @property
    def symbols(self) -> np.ndarray:
        return self._tables["symbols"].data

    @property
    def line_points(self) -> np.ndarray:
        return self._tables["line_points"].data

    @property
    def texts(self) -> np.ndarray:
        return self._tables["texts"].data

    def table(self, name: str) -> np.ndarray:
        """A table by name: ``"symbols"``, ``"line_points"`` or ``"texts"``."""
        return self._tables[name].data

    def __len__(self) -> int:
        return sum(len(t) for t in self._tables.values())

    def __repr__(self) -> str:
        return (
            f"<Layer {self.ext!r}: {len(self.symbols)} symbols, "
            f"{len(self.line_points)} line points, {len(self.texts)} texts>"
        )

    def __eq__(self, other) -> bool:
        if not isinstance(other, Layer):
            return NotImplemented
        return self.ext == other.ext and all(
            np.array_equal(self.table(n), other.table(n)) for n in TABLES
        )

    __hash__ = None  # type: ignore[assignment]  # mutable, so unhashable

    def copy(self) -> Layer:
        return Layer.from_arrays(self.ext, self.symbols, self.line_points, self.texts)

    # ------------------------------------------------------------------ add

    def add_symbol(self, x: float, y: float, z: float, code: int) -> int:
        """Add a symbol (code 0-99; 0 is the spot height) and return its point number."""
        x, y, z = _check_xyz(x, y, z)
        code = _check_code(code)
        t = self._tables["symbols"]
        num = int(_allocate(t.data["num"], 1)[0])
        t.append(np.array([(num, x, y, z, code)], dtype=SYMBOL_DTYPE))
        return num

    def add_text(self, x: float, y: float, z: float, text: str) -> int:
        """Add a text (any length, no control characters) and return its point number."""
        x, y, z = _check_xyz(x, y, z)
        text = check_text(text)
        t = self._tables["texts"]
        num = int(_allocate(t.data["num"], 1)[0])
        t.append(np.array([(num, x, y, z, text)], dtype=TEXT_DTYPE))
        return num

    def add_line(
        self, points: Iterable[Sequence[float]], code: int, closed: bool = False
    ) -> list[int]:
        """Add a line through ``points`` ((x, y, z) each) and return its point numbers.

        Consecutive points reference each other forward and backward; a closed
        line (3 points at least) also links its last point to its first. A
        single point starts a line that :meth:`extend_line` continues.
        """
        code = _check_code(code)
        pts = _check_points(points, 1)
        if closed and len(pts) < 3:
            raise TopologyError(f"a closed line needs at least three points, not {len(pts)}")
        t = self._tables["line_points"]
        nums = _allocate(t.data["num"], len(pts))
        rows = np.zeros(len(pts), dtype=LINE_DTYPE)
        rows["num"] = nums
        rows["x"], rows["y"], rows["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
        rows["code"] = code
        rows["fwd"] = np.r_[nums[1:], nums[0] if closed else NO_REF]
        rows["back"] = np.r_[nums[-1] if closed else NO_REF, nums[:-1]]
        rows["side1"] = rows["side2"] = NO_REF
        t.append(rows)
        return [int(n) for n in nums]

    def extend_line(self, end: int, points: Iterable[Sequence[float]]) -> list[int]:
        """Continue a line from its end point ``end`` and return the new point numbers.

        ``end`` must lack a forward reference (the new points follow it) or,
        failing that, a backward reference (the line grows at its start).
        """
        lp = self._tables["line_points"].rows()
        i = self._line_row(end)
        pts = _check_points(points, 0)
        if lp["fwd"][i] == NO_REF:
            ahead, behind = "fwd", "back"
        elif lp["back"][i] == NO_REF:
            ahead, behind = "back", "fwd"
        else:
            raise TopologyError(f"layer {self.ext}: line point {end} is not the end of a line")
        if len(pts) == 0:
            return []
        code = int(lp["code"][i])
        nums = _allocate(lp["num"], len(pts))
        rows = np.zeros(len(pts), dtype=LINE_DTYPE)
        rows["num"] = nums
        rows["x"], rows["y"], rows["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
        rows["code"] = code
        rows[ahead] = np.r_[nums[1:], NO_REF]
        rows[behind] = np.r_[end, nums[:-1]]
        rows["side1"] = rows["side2"] = NO_REF
        lp[ahead][i] = nums[0]
        self._tables["line_points"].append(rows)
        return [int(n) for n in nums]

    # ------------------------------------------------------------------ bulk

    def add_symbols(self, xyz, codes, nums=None) -> np.ndarray:
        """Add many symbols at once and return their point numbers.

        ``xyz`` is ``(n, 3)`` (finite, at most
        :data:`~apygis.model.records.MAX_COORD` in magnitude), ``codes`` one
        code 0-99 or one per symbol, ``nums`` None (numbered by the rule in
        this module's docstring) or ``n`` distinct numbers >= 0 not in use.
        Nothing is added unless all are valid.
        """
        pts = _check_bulk_xyz(xyz, "symbol")
        c = _check_bulk_codes(codes, len(pts), "symbol")
        t = self._tables["symbols"]
        nums = _bulk_nums(t.data["num"], nums, len(pts), f"layer {self.ext}: symbol")
        rows = np.zeros(len(pts), SYMBOL_DTYPE)
        rows["num"], rows["code"] = nums, c
        rows["x"], rows["y"], rows["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
        t.append(rows)
        return nums

    def add_texts(self, xyz, texts, nums=None) -> np.ndarray:
        """Add many texts at once and return their point numbers.

        ``texts`` are one string each (:func:`check_text`: no control
        characters, encodable; any length); ``xyz`` and ``nums``
        as for :meth:`add_symbols`. Nothing is added unless all are valid.
        """
        pts = _check_bulk_xyz(xyz, "text")
        texts = list(texts)
        if len(texts) != len(pts):
            raise RecordError(f"{len(texts)} texts for {len(pts)} positions")
        for k, tx in enumerate(texts):
            try:
                check_text(tx)
            except RecordError as exc:
                raise RecordError(f"text {k + 1}: {exc}") from None
        t = self._tables["texts"]
        nums = _bulk_nums(t.data["num"], nums, len(pts), f"layer {self.ext}: text")
        rows = np.zeros(len(pts), TEXT_DTYPE)
        rows["num"], rows["text"] = nums, texts
        rows["x"], rows["y"], rows["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
        t.append(rows)
        return nums

    def add_line_points(self, records) -> np.ndarray:
        """Add line-point records as they are, references included (exact topology).

        For readers of files that store APY's references (APY native, the
        ASCII exchange, apygis's own GeoPackage, DXF and E00 tables):
        ``records`` is a structured array with the fields of
        :data:`~apygis.model.records.LINE_DTYPE` (others converted). Values
        are checked as everywhere (coordinates finite and at most
        :data:`~apygis.model.records.MAX_COORD`, codes 0-99, point numbers
        >= 0 and distinct, also from the layer's, references -1 or >= 0);
        whether the references make sound lines is :meth:`validate`'s to
        say (a reader reports it). Returns the numbers added.
        """
        rows = _as_records(records, LINE_DTYPE, "line point")
        _check_bulk_xyz(np.column_stack([rows["x"], rows["y"], rows["z"]]), "line point")
        _check_bulk_codes(rows["code"], len(rows), "line point")
        for f in REF_FIELDS:
            if (rows[f] < NO_REF).any():
                raise RecordError(f"a {f} reference is a point number or -1 (none)")
        t = self._tables["line_points"]
        nums = _bulk_nums(t.data["num"], rows["num"], len(rows), f"layer {self.ext}: line point")
        t.append(rows)
        return nums

    def add_polylines(
        self,
        coords,
        offsets,
        codes,
        closed=None,
        *,
        snap_m: float | None = None,
        crs=None,
        join: bool = True,
    ):
        """Add plain polylines, rebuilding their topology; returns the rebuild's report.

        The one way plain geometry becomes line points: see
        :func:`apygis.model.polylines.rebuild` for the rules (snapping
        ``snap_m`` metres, default 5 mm, whatever ``crs``; duplicate
        vertices; rings; merging; junctions; refusals). ``coords`` ``(N, 2|3)``
        and ``offsets`` (``m + 1``) as shapely's ``linestrings(coords,
        indices=...)``; ``codes`` and ``closed`` one or one per line.
        ``join=False`` adds every line as its own chain (rings still close).
        The layer's line points can be junctions; they are not otherwise
        changed. Nothing is added unless all input is valid.
        """
        from apygis.model import polylines

        t = self._tables["line_points"]
        plan = polylines.rebuild(
            t.data,
            coords,
            offsets,
            codes,
            closed,
            snap_m=polylines.DEFAULT_SNAP_M if snap_m is None else snap_m,
            crs=crs,
            join=join,
            numbers=lambda count: next_numbers(t.data["num"], count),
        )
        if plan.sides:
            lp = t.rows()
            for r, f, num in plan.sides:
                lp[f][r] = num
        t.append(plan.rows)
        return plan.report

    # ------------------------------------------------------------------ edit lines

    def _line_row(self, num: int) -> int:
        rows = np.flatnonzero(self._tables["line_points"].data["num"] == num)
        if len(rows) == 0:
            raise RecordNotFoundError(f"layer {self.ext}: no line point number {num}")
        return int(rows[0])

    def split(self, a: int, b: int, xyz: Sequence[float]) -> int:
        """LS (line split): insert a new point between neighbours ``a`` and ``b``.

        The new point takes the line code of ``a``; returns its number.
        """
        x, y, z = _check_point(xyz)
        t = self._tables["line_points"]
        lp = t.rows()
        i, j = self._line_row(a), self._line_row(b)
        if lp["fwd"][j] == a and lp["back"][i] == b:  # given against the line's direction
            i, j, a, b = j, i, b, a
        elif not (lp["fwd"][i] == b and lp["back"][j] == a):
            raise TopologyError(f"layer {self.ext}: line points {a} and {b} are not neighbours")
        num = int(_allocate(lp["num"], 1)[0])
        lp["fwd"][i] = num
        lp["back"][j] = num
        t.append(np.array([(num, x, y, z, lp["code"][i], b, a, NO_REF, NO_REF)], dtype=LINE_DTYPE))
        return num

    def join(self, num: int, target: int) -> str:
        """Join the line end ``num`` to the existing line point ``target``.

        * If ``target`` is the other end of the same open line (3 points at
          least), the line is closed by forward/backward references: returns
          ``"closed"``.
        * Otherwise ``num`` becomes a branch of ``target``: its free backward
          (else forward) reference points to ``target``, and ``target`` takes
          ``num`` on a free side reference: returns ``"branch"``.

        A line whose first point is itself a branch (its backward reference
        goes to a junction; likewise a last point whose forward reference
        does) cannot be closed there: that reference slot is taken, and a
        point has only one. Joining the other end to it then makes a branch
        as above (a loop hanging on its own first point, drawn the same but
        not a closed line for AREA), and returns ``"branch"``.

        Raises
        ------
        TopologyError
            ``num`` is not a line end (it has a forward and a backward
            reference), the two points already reference each other, they
            are the same point, or ``target`` has no free side reference.
            The layer is unchanged.
        """
        lp = self._tables["line_points"].rows()
        i, j = self._line_row(num), self._line_row(target)
        if i == j:
            raise TopologyError(f"layer {self.ext}: cannot join line point {num} to itself")
        if _linked(lp, i, j):
            raise TopologyError(
                f"layer {self.ext}: line points {num} and {target} are already joined"
            )
        free = [f for f in ("fwd", "back") if lp[f][i] == NO_REF]
        if not free:
            raise TopologyError(
                f"layer {self.ext}: line point {num} is not the end of a line (it has both a "
                "forward and a backward reference)"
            )
        clo = topology.closure(lp, num)
        closing = not clo.closed and len(clo.points) >= 3 and {num, target} == {clo.start, clo.end}
        if closing:
            ahead, behind = ("fwd", "back") if num == clo.end else ("back", "fwd")
            if lp[ahead][i] == NO_REF and lp[behind][j] == NO_REF:
                lp[ahead][i], lp[behind][j] = target, num
                return "closed"
            # target's slot holds its own branch reference: join as a branch instead
        side = next((s for s in ("side1", "side2") if lp[s][j] == NO_REF), None)
        if side is None:
            why = (
                f" (the line cannot be closed there: point {target} is itself a branch end)"
                if closing
                else ""
            )
            raise TopologyError(
                f"layer {self.ext}: line point {target} already has two branches "
                f"(both side references are used){why}"
            )
        ref = "back" if "back" in free else "fwd"
        lp[ref][i] = target
        lp[side][j] = num
        return "branch"

    # ------------------------------------------------------------------ delete

    def delete_symbol(self, num: int) -> None:
        """Delete the symbol with point number ``num``."""
        self._delete_plain("symbols", num)

    def delete_text(self, num: int) -> None:
        """Delete the text with point number ``num``."""
        self._delete_plain("texts", num)

    def _delete_plain(self, table: str, num: int) -> None:
        t = self._tables[table]
        mask = t.data["num"] != num
        if mask.all():
            word = "symbol" if table == "symbols" else "text"
            raise RecordNotFoundError(f"layer {self.ext}: no {word} number {num}")
        t.keep(mask)

    def delete_line_point(self, num: int) -> None:
        """Delete a line point and repair the references to it.

        Its backward and forward neighbours are linked to each other (a line
        loses the point, not its continuity), unless they already reference
        each other otherwise: a ring of three becomes an open line of two, and
        a loop hanging on its own point (a branch end joined to a point of its
        own line) keeps the link it has. If the point is a branch end, its
        neighbour along the branch takes its place at the junction (the branch
        stays joined) unless it already references the junction. Branches
        hanging on the point move to the neighbour that took its place
        (backward first) if that has a free side reference and does not
        already reference the branch end; otherwise their end becomes a free
        line end.
        """
        t = self._tables["line_points"]
        lp = t.rows()
        i = self._line_row(num)
        nums = lp["num"]
        b, f = int(lp["back"][i]), int(lp["fwd"][i])
        bi = topology.row_of(nums, b)
        fi = topology.row_of(nums, f)
        mutual_b = bi is not None and lp["fwd"][bi] == num
        mutual_f = fi is not None and lp["back"][fi] == num
        if mutual_b:
            lp["fwd"][bi] = NO_REF
        if mutual_f:
            lp["back"][fi] = NO_REF
        if bi is not None and bi == fi:  # two-point ring
            lp["fwd"][bi] = lp["back"][bi] = NO_REF
        elif (
            mutual_b and mutual_f and bi is not None and fi is not None and not _linked(lp, bi, fi)
        ):
            lp["fwd"][bi] = f
            lp["back"][fi] = b
        # A branch end: its neighbour along the branch takes its place at the junction.
        for ref, nb, mutual, ji in (("back", fi, mutual_f, bi), ("fwd", bi, mutual_b, fi)):
            # (mutual implies nb is not None; the check is for the type checker)
            if (
                not mutual
                or nb is None
                or ji is None
                or mutual_b == mutual_f
                or _linked(lp, nb, ji)
            ):
                continue
            side = next((s for s in ("side1", "side2") if lp[s][ji] == num), None)
            if side is not None and lp[ref][nb] == NO_REF:
                lp[ref][nb] = nums[ji]
                lp[side][ji] = nums[nb]
        heir = bi if mutual_b else (fi if mutual_f else None)
        # Every other reference to the deleted point: branches and side links.
        for ref in REF_FIELDS:
            hit = np.flatnonzero((lp[ref] == num) & (np.arange(len(lp)) != i))
            for k in hit:
                lp[ref][k] = NO_REF
                if ref in ("fwd", "back") and heir is not None and heir != k:
                    if _linked(lp, heir, int(k)):
                        continue
                    side = next((s for s in ("side1", "side2") if lp[s][heir] == NO_REF), None)
                    if side is not None:
                        lp[ref][k] = nums[heir]
                        lp[side][heir] = nums[k]
        mask = np.ones(len(lp), dtype=bool)
        mask[i] = False
        t.keep(mask)

    def delete_line(self, num: int) -> list[int]:
        """Delete the whole line (chain) through line point ``num``; returns the numbers deleted."""
        clo = topology.closure(self.line_points, num)
        for n in clo.points:
            self.delete_line_point(n)
        return list(clo.points)

    # ------------------------------------------------------------------ topology

    def chains(self) -> topology.ChainSet:
        """The lines of this layer as chains of line-point rows (see ``topology``)."""
        return topology.chains(self.line_points)

    def branches(self) -> list[dict]:
        return topology.branches(self.line_points)

    def margin_points(self) -> np.ndarray:
        """Line points lacking a forward or backward reference (APY's margin file)."""
        lp = self.line_points
        return lp[topology.margin_mask(lp)]

    def closure(self, num: int) -> topology.Closure:
        return topology.closure(self.line_points, num)

    def area(self, first: int, second: int) -> topology.AreaResult:
        return topology.area(self.line_points, first, second)

    def dhi(self, a: Sequence[float], b: Sequence[float]) -> topology.DHI:
        return topology.dhi(a, b)

    def geometries(self) -> np.ndarray:
        """Shapely LineString Z / Polygon Z of every line, in :meth:`chains` order."""
        return topology.line_geometries(self.line_points)

    def validate(self) -> list[topology.Issue]:
        """Errors and warnings about this layer's records (see :mod:`~apygis.model.topology`)."""
        issues = topology.validate_numbers("symbols", self.symbols["num"])
        issues += topology.validate_numbers("texts", self.texts["num"])
        issues += topology.validate_line_points(self.line_points)
        tx = self.texts
        bad = np.array([_has_surrogate(t) for t in tx["text"].tolist()], dtype=bool).reshape(-1)
        issues += [
            topology.Issue(
                "error",
                "texts",
                int(n),
                "unencodable-text",
                f"text {n}: {t!r} holds a lone surrogate, which no file format can encode",
            )
            for n, t in zip(tx["num"][bad], tx["text"][bad].tolist(), strict=True)
        ]
        bad = (self.symbols["code"] < 0) | (self.symbols["code"] > MAX_CODE)
        issues += [
            topology.Issue("error", "symbols", int(n), "bad-code", f"symbol {n}: code outside 0-99")
            for n in self.symbols["num"][bad]
        ]
        bad = (self.line_points["code"] < 0) | (self.line_points["code"] > MAX_CODE)
        issues += [
            topology.Issue(
                "error", "line_points", int(n), "bad-code", f"line point {n}: code outside 0-99"
            )
            for n in self.line_points["num"][bad]
        ]
        for name, cap in APY_CAPACITY.items():
            n = len(self.table(name))
            if n > cap:
                issues.append(
                    topology.Issue(
                        "warning",
                        name,
                        -1,
                        "over-capacity",
                        f"{n} {name.replace('_', ' ')} exceed APY's capacity of {cap}: "
                        "the APY native format cannot hold this layer",
                    )
                )
        return issues

    def counts(self) -> dict[str, int]:
        cs = self.chains()
        return {
            "symbols": len(self.symbols),
            "line_points": len(self.line_points),
            "lines": len(cs),
            "closed_lines": int(cs.closed.sum()),
            "texts": len(self.texts),
        }

    def extent(self) -> tuple[float, float, float, float, float, float] | None:
        """``(xmin, ymin, zmin, xmax, ymax, zmax)`` over all records, or None if empty."""
        parts = [t for t in (self.symbols, self.line_points, self.texts) if len(t)]
        if not parts:
            return None
        x = np.concatenate([p["x"] for p in parts])
        y = np.concatenate([p["y"] for p in parts])
        z = np.concatenate([p["z"] for p in parts])
        return (
            float(x.min()),
            float(y.min()),
            float(z.min()),
            float(x.max()),
            float(y.max()),
            float(z.max()),
        )


class MapFile:
    """A compiled map: identification, header and layers keyed by extension.

    Parameters
    ----------
    id : str
        Map identification (1-32 characters of letters, digits, '_', '-').
    scale : int, optional
        Compilation scale denominator (5000 for 1:5000).
    crs : pyproj.CRS or anything ``pyproj.CRS.from_user_input`` takes, optional
        The ground coordinate reference system.
    notes : str
        Free notes.

    Attributes
    ----------
    read_warnings : list
        What the reader that made this map reported about its file (skipped
        entities, records numbered anew, ...): ``apygis.formats`` fills it
        with its ``ReadWarning`` records. Not part of the map's equality.
    """

    def __init__(self, id: str, scale: int | None = None, crs=None, notes: str = ""):
        self.id = check_map_id(id)
        self.scale = scale
        self.crs = crs
        self.notes = notes
        self.layers: dict[str, Layer] = {}
        self.read_warnings: list = []

    @property
    def scale(self) -> int | None:
        return self._scale

    @scale.setter
    def scale(self, value) -> None:
        if value is not None:
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise RecordError(f"the scale is a positive integer denominator, not {value!r}")
            value = int(value)
        self._scale = value

    @property
    def crs(self):
        return self._crs

    @crs.setter
    def crs(self, value) -> None:
        if value is not None:
            from pyproj import CRS
            from pyproj.exceptions import CRSError as ProjCRSError

            try:
                value = CRS.from_user_input(value)
            except (ProjCRSError, TypeError) as exc:
                raise CRSError(f"not a coordinate reference system: {value!r} ({exc})") from None
        self._crs = value

    @property
    def notes(self) -> str:
        return self._notes

    @notes.setter
    def notes(self, value: str) -> None:
        if not isinstance(value, str):
            raise RecordError(f"notes are a string, not {value!r}")
        self._notes = check_encodable(value, "the notes")

    def layer(self, ext: str) -> Layer:
        """The layer with extension ``ext``, created empty if absent."""
        ext = check_ext(ext)
        if ext not in self.layers:
            self.layers[ext] = Layer(ext)
        return self.layers[ext]

    def add_layer(self, layer: Layer) -> Layer:
        """Add (or replace) a whole layer."""
        self.layers[layer.ext] = layer
        return layer

    def __iter__(self):
        return iter(self.layers.values())

    def __len__(self) -> int:
        return len(self.layers)

    def __repr__(self) -> str:
        scale = f" 1:{self.scale}" if self.scale else ""
        return f"<MapFile {self.id!r}{scale} layers={sorted(self.layers)}>"

    def __eq__(self, other) -> bool:
        if not isinstance(other, MapFile):
            return NotImplemented
        return (
            self.id == other.id
            and self.scale == other.scale
            and crs_string(self.crs) == crs_string(other.crs)
            and self.notes == other.notes
            and sorted(self.layers) == sorted(other.layers)
            and all(self.layers[k] == other.layers[k] for k in self.layers)
        )

    __hash__ = None  # type: ignore[assignment]  # mutable, so unhashable

    def copy(self) -> MapFile:
        m = MapFile(self.id, self.scale, self.crs, self.notes)
        for lay in self:
            m.add_layer(lay.copy())
        return m

    def crs_string(self) -> str | None:
        return crs_string(self.crs)


def crs_string(crs) -> str | None:
    """A CRS as ``"AUTH:CODE"`` when it has an exact one, else as WKT2 on one line."""
    if crs is None:
        return None
    auth = crs.to_authority(min_confidence=100)
    if auth is not None:
        return f"{auth[0]}:{auth[1]}"
    return crs.to_wkt()
