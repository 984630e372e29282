"""Guarded text records: what the readers and writers of the bundle exchange formats share.

The bundle formats (PAT-B, BLUH, COLMAP, OpenDroneMap; see ``docs/formats/``) are
text files of blank-separated records. Reading goes through :func:`text_lines`,
:func:`number`, :func:`whole` and :func:`name`, so that a hostile or damaged file
ends in one :class:`~apygis.errors.FormatError` naming the file and the line (text
that is not UTF-8, a line longer than the format allows, ``NaN``, ``1e999``,
superscript digits, a name holding a control character), never in a traceback or
an unbounded allocation. Writing goes through :func:`fixed` and :func:`check_name`,
which refuse a value that does not fit its field (:class:`~apygis.errors.ValueRangeError`
naming the file and the record) instead of widening or truncating it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator

import numpy as np

from apygis.errors import FormatError, ValueRangeError
from apygis.fileio import read_bytes
from apygis.formats._readguard import MAX_COORD, ascii_int

__all__ = [
    "MAX_BYTES",
    "MAX_COORD",
    "MAX_LINES",
    "check_name",
    "fixed",
    "name",
    "number",
    "numbers",
    "read_lines",
    "text_lines",
    "whole",
]

MAX_BYTES = 128 << 20
"""The largest bundle exchange file read (128 MiB: a block of a million observations
takes about 60 MB in any of these formats)."""
MAX_LINES = 2_000_000
"""The most lines read from one file (readers keep an object per record: bounded memory)."""

_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]{1,4})?", re.ASCII)


def read_lines(path, what: str, *, max_line: int) -> Iterator[tuple[int, str]]:
    """The lines of the text file ``path`` (see :func:`text_lines`), read through the guard
    of :func:`apygis.fileio.read_bytes` (a regular file of at most :data:`MAX_BYTES`)."""
    return text_lines(read_bytes(path, what, max_bytes=MAX_BYTES), path, what, max_line=max_line)


def text_lines(data: bytes, path, what: str, *, max_line: int) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of every line of UTF-8 ``data`` (``\\n`` or ``\\r\\n``; a
    leading byte-order mark is dropped), one at a time.

    Raises :class:`FormatError` naming ``path`` and the line for bytes that are not UTF-8,
    a line of more than ``max_line`` bytes and more than :data:`MAX_LINES` lines (what a
    reader keeps per line is bounded so).

    >>> list(text_lines(b"a b\\r\\n\\n c", "f", "test", max_line=80))
    [(1, 'a b'), (2, ''), (3, ' c')]
    """
    start, k, n = 0, 0, len(data)
    while start < n:
        end = data.find(b"\n", start)
        if end < 0:
            end = n
        k += 1
        if k > MAX_LINES:
            raise FormatError(
                f"more than {MAX_LINES} lines, more than {what} may have", path, f"line {k}"
            )
        if end - start > max_line:
            raise FormatError(
                f"a line of {end - start} bytes is longer than the {max_line} bytes "
                f"a line of {what} may have",
                path,
                f"line {k}",
            )
        line = data[start:end]
        start = end + 1
        if line.endswith(b"\r"):
            line = line[:-1]
        try:
            text = line.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FormatError(
                f"not UTF-8 text ({exc.reason} at byte {exc.start + 1} of the line)",
                path,
                f"line {k}",
            ) from None
        if k == 1 and text.startswith("\ufeff"):
            text = text[1:]
        yield k, text


def number(
    token: str,
    path,
    record: str,
    what: str,
    *,
    limit: float = MAX_COORD,
    nan_ok: bool = False,
) -> float:
    """``token`` as a finite float of magnitude at most ``limit`` (or NaN, if ``nan_ok``
    and the token is ``NaN`` in any case).

    Plain decimal numbers only (``-12.5``, ``1e3``): no ``inf``, no ``1_000``, no
    digits of other scripts.

    >>> number("-12.50", "f", "line 3", "X")
    -12.5
    >>> number("nan", "f", "line 3", "Z", nan_ok=True)
    nan
    >>> number("1e999", "f", "line 3", "X")
    Traceback (most recent call last):
    ...
    apygis.errors.FormatError: f: line 3: X '1e999' is not a finite number of at most 1e+12
    """
    if nan_ok and token.lower() == "nan":
        return math.nan
    v = float(token) if _NUMBER.fullmatch(token) else math.nan
    if not abs(v) <= limit:
        shown = token if len(token) <= 24 else token[:20] + "..."
        raise FormatError(
            f"{what} {shown!r} is not a finite number of at most {limit:g}", path, record
        )
    return v


_NUMERIC_TEXT = re.compile(r"[0-9eE+\-. \t]*", re.ASCII)


def numbers(
    tokens: list[str], path, record: str, what: str, *, limit: float = MAX_COORD
) -> np.ndarray:
    """Many tokens as finite floats of magnitude at most ``limit`` (a float64 array), fast;
    a bad token is reported as :func:`number` reports it.

    >>> numbers(["1", "-2.5e1"], "f", "line 2", "x").tolist()
    [1.0, -25.0]
    """
    if _NUMERIC_TEXT.fullmatch(" ".join(tokens)):
        try:
            a = np.array(tokens, dtype=np.float64)
        except ValueError:
            a = None
        if a is not None and (a.size == 0 or float(np.abs(a).max()) <= limit):
            return a
    for t in tokens:  # find the culprit, for the message
        number(t, path, record, what, limit=limit)
    return np.array(
        [number(t, path, record, what, limit=limit) for t in tokens]
    )  # pragma: no cover


def whole(token: str, path, record: str, what: str, *, lo: int = 1, hi: int = 2**63 - 1) -> int:
    """``token`` as a whole number from ``lo`` to ``hi`` (ASCII digits, an optional sign).

    >>> whole("42", "f", "line 1", "photo number")
    42
    >>> whole("4²", "f", "line 1", "photo number", hi=999)
    Traceback (most recent call last):
    ...
    apygis.errors.FormatError: f: line 1: photo number '4²' is not a whole number from 1 to 999
    """
    v = ascii_int(token, max_digits=19, signed=True)
    if v is None or not lo <= v <= hi:
        shown = token if len(token) <= 24 else token[:20] + "..."
        raise FormatError(f"{what} {shown!r} is not a whole number from {lo} to {hi}", path, record)
    return v


def _name_problem(s: str, max_len: int | None) -> str | None:
    if not s:
        return "is empty"
    if max_len is not None and len(s) > max_len:
        return f"has {len(s)} characters, more than the {max_len} the format allows"
    if s.split() != [s]:
        return "holds a blank (the format separates fields by blanks)"
    if not s.isprintable():
        return "holds a control character"
    if any(0xD800 <= ord(c) <= 0xDFFF for c in s):
        return "holds a lone surrogate (not valid Unicode text)"
    return None


def name(token: str, path, record: str, what: str, *, max_len: int | None = None) -> str:
    """A name read from a file: printable, without blanks, at most ``max_len`` characters
    (:class:`FormatError` naming the file and record otherwise)."""
    why = _name_problem(token, max_len)
    if why:
        shown = token if len(token) <= 40 else token[:36] + "..."
        raise FormatError(f"{what} {shown!r} {why}", path, record)
    return token


def check_name(s, path, record: str, what: str, *, max_len: int | None = None) -> str:
    """A name to write: a non-empty string, printable, without blanks, at most ``max_len``
    characters; :class:`ValueRangeError` naming the file and record otherwise (never
    truncated)."""
    if not isinstance(s, str):
        raise ValueRangeError(f"{what} {s!r} is not text", path, record)
    why = _name_problem(s, max_len)
    if why:
        shown = s if len(s) <= 40 else s[:36] + "..."
        raise ValueRangeError(f"{what} {shown!r} {why}", path, record)
    return s


def fixed(v, width: int, decimals: int, path, record: str, what: str) -> str:
    """``v`` right-aligned in ``width`` columns with ``decimals`` decimals (Fortran
    ``F<width>.<decimals>``), at least one blank before it; :class:`ValueRangeError`
    naming the file and record if it is not finite or does not fit.

    >>> fixed(-0.0001, 10, 3, "f", "r", "x")
    '     0.000'
    >>> fixed(123456.0, 8, 3, "f", "photo 3", "x")
    Traceback (most recent call last):
    ...
    apygis.errors.ValueRangeError: f: photo 3: x 123456.0 does not fit the field F8.3 of the format
    """
    v = float(v)
    if not math.isfinite(v):
        raise ValueRangeError(f"{what} {v} is not a finite number", path, record)
    s = f"{v:.{decimals}f}"
    if s.startswith("-") and not s.strip("-0."):
        s = s[1:]  # -0.000
    if len(s) >= width:
        raise ValueRangeError(
            f"{what} {v!r} does not fit the field F{width}.{decimals} of the format", path, record
        )
    return s.rjust(width)


def photo_blocks(
    data: bytes,
    path,
    what: str,
    *,
    max_line: int,
    end: str,
    end_text: str,
    photo_hi: int,
    point_key,
    point_what: str,
    unit: str,
    to_mm: float,
    limit: float,
) -> list[tuple[int, list, np.ndarray, list[int]]]:
    """The photo blocks of a bundle program's photo coordinate file (PAT-B's image
    coordinates, BLUH's photo coordinates): a record with the photo number alone, then
    one record ``key x y`` per point, closed by the record ``end``.

    ``point_key(token, record)`` reads a point's key (a name or a number); coordinates are
    in ``unit`` (``to_mm`` times millimetres; at most ``limit`` in size). Returns
    ``(photo, keys, xy_mm (n, 2), lines)`` per photo in file order. A photo that appears
    twice, a point measured twice in one photo, a photo left open at the end of the file,
    a record of another shape are refused, naming the lines.
    """
    photos: list[tuple[int, list, np.ndarray, list[int]]] = []
    first_line: dict[int, int] = {}
    photo: int | None = None
    keys: list = []
    lines: list[int] = []
    seen: dict = {}
    xy: list[tuple[float, float]] = []
    for k, text in text_lines(data, path, what, max_line=max_line):
        tok = text.split()
        rec = f"line {k}"
        if not tok:
            continue
        if photo is None:
            if len(tok) != 1:
                raise FormatError(
                    f"expected a photo record (the photo number alone), found {len(tok)} fields",
                    path,
                    rec,
                )
            photo = whole(tok[0], path, rec, "photo number", hi=photo_hi)
            if photo in first_line:
                raise FormatError(
                    f"photo {photo} appears again (first at line {first_line[photo]})", path, rec
                )
            first_line[photo] = k
            keys, lines, seen, xy = [], [], {}, []
        elif len(tok) == 1 and tok[0] == end:
            photos.append((photo, keys, np.array(xy, dtype=float).reshape(-1, 2), lines))
            photo = None
        elif len(tok) == 3:
            key = point_key(tok[0], rec)
            if key in seen:
                shown = repr(key) if isinstance(key, str) else key
                raise FormatError(
                    f"point {shown} is measured twice in photo {photo} (also at line {seen[key]})",
                    path,
                    rec,
                )
            seen[key] = k
            x = number(tok[1], path, rec, f"x ({unit})", limit=limit)
            y = number(tok[2], path, rec, f"y ({unit})", limit=limit)
            keys.append(key)
            lines.append(k)
            xy.append((x / to_mm, y / to_mm))
        else:
            raise FormatError(
                f"expected a point record ({point_what}, x, y in {unit}) or {end} closing "
                f"photo {photo}, found {len(tok)} fields",
                path,
                rec,
            )
    if photo is not None:
        raise FormatError(
            f"photo {photo} (line {first_line[photo]}) is not closed by {end_text}: "
            "the file is truncated",
            path,
        )
    return photos
