"""Checks the readers share on untrusted input: JSON, digits, strings, coordinates.

Every reader turns what a file holds into model values through these, so that a
hostile or damaged file ends in a :class:`~apygis.errors.FormatError` naming the
file and the record, never in a ``RecursionError`` (JSON nested thousands
deep), a ``ValueError`` from :func:`int` (superscript digits that
:meth:`str.isdigit` accepts, integers of more than 4300 digits), a string
that cannot be written back (a lone surrogate), or an overflow further on
(a coordinate of 1e308 in a KD-tree).

The guarded JSON (:func:`loads_json`) and string check (:func:`check_str`)
are those of :mod:`apygis.fileio`, shared with every layer; they are
re-exported here for the readers.
"""

from __future__ import annotations

from typing import cast

import numpy as np

from apygis.errors import FormatError
from apygis.fileio import MAX_INT_DIGITS, MAX_JSON_DEPTH, check_str, loads_json
from apygis.model.records import MAX_COORD  # the model's bound: readers refuse what it would

__all__ = [
    "MAX_COORD",
    "MAX_INT_DIGITS",
    "MAX_JSON_DEPTH",
    "ascii_int",
    "bad_coord_rows",
    "check_coords",
    "check_str",
    "is_ascii_digits",
    "loads_json",
]


def is_ascii_digits(s: str | bytes) -> bool:
    """True if ``s`` is one or more of the ASCII digits 0-9 and nothing else.

    Unlike :meth:`str.isdigit`, which also accepts superscripts (``'²'``) and
    other scripts' digits that :func:`int` refuses or reads differently.

    >>> is_ascii_digits("42"), is_ascii_digits("4²"), is_ascii_digits(""), is_ascii_digits(b"7")
    (True, False, False, True)
    """
    if isinstance(s, bytes | bytearray):
        return bool(s) and all(48 <= c <= 57 for c in s)
    return bool(s) and s.isascii() and s.isdigit()


def ascii_int(s: str | bytes, max_digits: int = MAX_INT_DIGITS, signed: bool = False) -> int | None:
    """``s`` as an int if it is (an optional sign and) 1 to ``max_digits`` ASCII digits, else None.

    >>> ascii_int("0042"), ascii_int("-3", signed=True), ascii_int("1_0"), ascii_int("9" * 40)
    (42, -3, None, None)
    """
    if isinstance(s, bytes | bytearray):
        s = bytes(s).decode("latin-1")
    body = s[1:] if signed and s[:1] in ("-", "+") else s
    if not is_ascii_digits(body):
        return None
    body = body.lstrip("0") or "0"  # int() refuses more than 4300 digits, zeros included
    if len(body) > max_digits:
        return None
    return -int(body) if s[:1] == "-" and signed else int(body)


def bad_coord_rows(xyz) -> np.ndarray:
    """Indices of the rows of ``xyz`` (or of the values of a 1-D array) that are not
    finite or exceed :data:`MAX_COORD` in magnitude."""
    a = np.asarray(xyz, dtype=np.float64)
    # fast path: the extremes within bounds (a NaN makes them NaN, failing both tests)
    if a.size == 0 or (a.min() >= -MAX_COORD and a.max() <= MAX_COORD):
        return np.zeros(0, dtype=np.intp)
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(a) <= MAX_COORD)  # NaN compares False
    if bad.ndim > 1:
        # with an axis, any() gives an array (the stubs also allow a scalar)
        bad = cast(np.ndarray, bad.any(axis=tuple(range(1, bad.ndim))))
    return np.flatnonzero(bad)


def check_coords(xyz, path=None, record=None, what: str = "coordinates") -> None:
    """Refuse coordinates that are not finite or exceed :data:`MAX_COORD` in magnitude.

    ``record`` names where the first bad row is: a string, or a callable
    ``record(row_index) -> str`` (``"line 12"``) so that the message names
    the line or record of the file.

    >>> check_coords([[1.0, 2.0], [1e308, 0.0]], "F", lambda i: f"row {i}")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    apygis.errors.FormatError: F: row 1: coordinates (1e+308, 0.0) are not finite ...
    """
    rows = bad_coord_rows(xyz)
    if not len(rows):
        return
    i = int(rows[0])
    a = np.asarray(xyz, dtype=np.float64)
    shown = tuple(float(v) for v in np.atleast_1d(a[i]))
    shown_s = f"({', '.join(repr(v) for v in shown)})" if len(shown) > 1 else repr(shown[0])
    more = f" (and {len(rows) - 1} more)" if len(rows) > 1 else ""
    where = record(i) if callable(record) else record
    raise FormatError(
        f"{what} {shown_s} are not finite or exceed {MAX_COORD:g} in magnitude{more}",
        path=path,
        record=where,
    )
