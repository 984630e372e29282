"""The three record tables of a layer: symbols, line points and texts.

Each table is a numpy structured array, one row per record, so that a driver
converts a million points with a handful of array operations.

Fields (coordinates in metres, float64):

========== =========================== =========================================
table      fields                      meaning
========== =========================== =========================================
symbols    num, x, y, z, code          point number, position, symbol code 0-99
line       num, x, y, z, code,         point number, position, line code 0-99,
points     fwd, back, side1, side2     references (point numbers) to the next and
                                       previous point of the line and to up to two
                                       branch points; ``NO_REF`` (-1) where none
texts      num, x, y, z, text          point number, position, text (a Python str
                                       of any length: the model has no limit;
                                       the APY native formats hold 24 characters)
========== =========================== =========================================

Point numbers are unique within a table (the symbols, the line points and the
texts of a layer are numbered independently, as in APY). The model itself has
no limit on their size or on the number of records; the APY native format's
limits are in :data:`APY_CAPACITY` and :data:`APY_MAX_NUM` and are enforced by
its driver.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "APY_CAPACITY",
    "APY_MAX_NUM",
    "LINE_DTYPE",
    "MAX_CODE",
    "MAX_COORD",
    "NO_REF",
    "REF_FIELDS",
    "SYMBOL_DTYPE",
    "TABLES",
    "TABLE_WORDS",
    "TEXT_DTYPE",
    "TEXT_LEN",
    "Table",
    "next_numbers",
]

NO_REF = -1
"""Reference value meaning "no neighbour"."""

MAX_CODE = 99
MAX_COORD = 1e12
"""Largest coordinate magnitude a record may have (metres, or the CRS's units).

The model and every reader refuse larger (and non-finite) coordinates: past
it, float64 no longer resolves a millimetre, and no map needs it."""
TEXT_LEN = 24
"""Characters of a text that APY (and its native formats) hold; the model has no limit."""
APY_MAX_NUM = 9999
"""Largest point number the APY native format stores (4 digits)."""

APY_CAPACITY = {"symbols": 1000, "line_points": 10000, "texts": 500}
"""Records per layer that APY (and its native format) holds."""

REF_FIELDS = ("fwd", "back", "side1", "side2")

SYMBOL_DTYPE = np.dtype([("num", "i8"), ("x", "f8"), ("y", "f8"), ("z", "f8"), ("code", "i2")])
LINE_DTYPE = np.dtype(
    [
        ("num", "i8"),
        ("x", "f8"),
        ("y", "f8"),
        ("z", "f8"),
        ("code", "i2"),
        ("fwd", "i8"),
        ("back", "i8"),
        ("side1", "i8"),
        ("side2", "i8"),
    ]
)
TEXT_DTYPE = np.dtype([("num", "i8"), ("x", "f8"), ("y", "f8"), ("z", "f8"), ("text", "O")])
"""The texts table; ``text`` holds Python ``str`` objects (no length limit, nothing cut)."""

TABLES = {"symbols": SYMBOL_DTYPE, "line_points": LINE_DTYPE, "texts": TEXT_DTYPE}
TABLE_WORDS = {"symbols": "symbol", "line_points": "line point", "texts": "text"}
"""A record of each table in words, for messages (``"line point 12"``)."""
"""Table name -> dtype, in the order the native formats store them."""


def next_numbers(used: np.ndarray, count: int) -> np.ndarray:
    """``count`` new point numbers for a table whose numbers in use are ``used``.

    The model's numbering rule: one more than the highest number in use (1
    for an empty table), consecutively. When the last of them would pass
    :data:`APY_MAX_NUM` (9999), the free numbers from 1 to 9999 are taken in
    increasing order, then 0, so that a layer can be filled to APY's
    capacity; past that, numbers go on above the highest one in use (the
    model has no limit; only the APY native format refuses them).

    >>> next_numbers(np.array([4, 2]), 3).tolist()
    [5, 6, 7]
    >>> next_numbers(np.array([9998, 3]), 3).tolist()  # 9998 + 3 would pass 9999
    [1, 2, 4]
    """
    used = np.asarray(used, dtype=np.int64)
    start = int(used.max()) + 1 if len(used) else 1
    if start + count - 1 <= APY_MAX_NUM:
        return np.arange(start, start + count, dtype=np.int64)
    free = np.setdiff1d(np.r_[np.arange(1, APY_MAX_NUM + 1), 0], used, assume_unique=False)
    free = np.r_[free[free != 0], free[free == 0]]
    # numbers above the APY range, continuing after the highest one in use
    beyond_start = max(start, APY_MAX_NUM + 1)
    need = max(0, count - len(free))
    return np.r_[free[:count], np.arange(beyond_start, beyond_start + need)].astype(np.int64)


class Table:
    """A growable structured array: amortised O(1) append, O(n) delete.

    ``data`` is a read-only view of the live rows; change records through the
    :class:`~apygis.model.map.Layer` methods, which keep the references right.
    """

    __slots__ = ("_buf", "_n")

    def __init__(self, dtype: np.dtype, data: np.ndarray | None = None):
        self._buf = np.zeros(16, dtype=dtype)
        self._n = 0
        if data is not None:
            self.replace(data)

    @property
    def dtype(self) -> np.dtype:
        return self._buf.dtype

    @property
    def data(self) -> np.ndarray:
        view = self._buf[: self._n]
        view.flags.writeable = False
        return view

    def __len__(self) -> int:
        return self._n

    def _reserve(self, n: int) -> None:
        if n > len(self._buf):
            cap = max(n, 2 * len(self._buf))
            buf = np.zeros(cap, dtype=self._buf.dtype)
            buf[: self._n] = self._buf[: self._n]
            self._buf = buf

    def append(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=self._buf.dtype)
        rows = rows.reshape(-1)
        self._reserve(self._n + len(rows))
        self._buf[self._n : self._n + len(rows)] = rows
        self._n += len(rows)

    def replace(self, data: np.ndarray) -> None:
        data = np.asarray(data)
        if data.dtype != self._buf.dtype:
            conv = np.zeros(len(data), dtype=self._buf.dtype)
            for name in self._buf.dtype.names:
                conv[name] = data[name]
            data = conv
        self._buf = np.array(data, dtype=self._buf.dtype, copy=True).reshape(-1)
        if len(self._buf) == 0:
            self._buf = np.zeros(16, dtype=self._buf.dtype)
            self._n = 0
        else:
            self._n = len(data)

    def keep(self, mask: np.ndarray) -> None:
        """Keep only the rows where ``mask`` is true."""
        rows = self._buf[: self._n][mask]
        self._buf[: len(rows)] = rows
        self._n = len(rows)

    def rows(self) -> np.ndarray:
        """The live rows, writable (for the Layer's own edits)."""
        return self._buf[: self._n]
