"""BLUH's input files, laid out in one place, and the map driver of the APY way.

BLUH (the bundle block adjustment of Karsten Jacobsen, Leibniz University Hannover)
has no public specification of its files that we could find; ``docs/formats/bluh.md``
says what is known (the program system: BLPRE prepares photo coordinates, BLIM
inputs control data, BLUH adjusts) and marks the layout below as apygis's
ASSUMPTION, so that it is one module to change once a BLUH manual is at hand. Points
and photos are numbers (Fortran ``INTEGER*4``: 1 to 2147483647):

photo coordinate file (``.pho``)::

           101                          <- photo number (I10)
          1001     -1.2346      8.9012  <- point number (I10), x, y in mm (2F12.4),
          1002     45.1000    -99.0000     photo system: x right, y up
             0                          <- point number 0 closes the photo

control file (``.ctl``)::

          1001    2600100.000    1200200.000     512.300  3
             0

``number X Y Z code`` (I10, 2F15.3, F12.3, I3; metres) with code 3 full control, 1
planimetric (Z not used, written 0.000), 2 height (X, Y approximate); a record ``0``
ends the list.

Reading splits records on blanks; every value is checked and a bad one is a
:class:`~apygis.errors.FormatError` naming the file and the line. Writing refuses a
point name that is not a whole number from 1 to 2147483647 written without leading
zeros (BLUH has numbers, not names: nothing is renumbered behind the user's back)
and a value that does not fit its field (:class:`~apygis.errors.ValueRangeError`).

The map driver ``bluh`` writes the photo coordinate file of a densification map
(:mod:`apygis.formats._bundlemap`): ``apygis convert MAP out/x.bluh --to bluh``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import NamedTuple

import numpy as np

from apygis.errors import FormatError, ValueRangeError
from apygis.fileio import atomic_write
from apygis.formats import Driver
from apygis.formats._bundlemap import photo_measurements
from apygis.formats._records import fixed, number, photo_blocks, text_lines, whole

__all__ = [
    "CODES",
    "DRIVER",
    "MAX_LINE",
    "MAX_NUMBER",
    "PhotoRecords",
    "decode_control",
    "decode_photo_coordinates",
    "encode_control",
    "encode_photo_coordinates",
    "point_number",
    "write",
]

MAX_NUMBER = 2**31 - 1
"""The largest photo or point number (Fortran INTEGER*4)."""
CODES = {3: "full", 1: "planimetric", 2: "height"}
"""Control codes of the control file and the kinds of control they stand for."""
MAX_LINE = 512
"""The longest line read (bytes)."""


class PhotoRecords(NamedTuple):
    """The points of one photo: numbers, photo coordinates ``(n, 2)`` in mm, lines."""

    photo: int
    numbers: list[int]
    xy_mm: np.ndarray
    lines: list[int]


def point_number(name, path, record: str, what: str = "point name") -> int:
    """The BLUH number of a point or photo name: a whole number from 1 to 2147483647
    written without leading zeros; :class:`ValueRangeError` otherwise.

    >>> point_number("1001", "f", "r")
    1001
    >>> point_number("GCP1", "f", "photo 3")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    apygis.errors.ValueRangeError: f: photo 3: point name 'GCP1' is not a BLUH point number ...
    """
    s = str(name)
    if s.isascii() and s.isdigit() and s == str(int(s)) and 1 <= int(s) <= MAX_NUMBER:
        return int(s)
    raise ValueRangeError(
        f"{what} {s[:40]!r} is not a BLUH point number (a whole number from 1 to "
        f"{MAX_NUMBER} without leading zeros)",
        path,
        record,
    )


def _int_field(v: int, width: int, path, record: str, what: str) -> str:
    if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 1 <= v <= MAX_NUMBER:
        raise ValueRangeError(
            f"{what} {v!r} is not a whole number from 1 to {MAX_NUMBER}", path, record
        )
    return f"{int(v):>{width}d}"


# ------------------------------------------------------------------ photo coordinates


def encode_photo_coordinates(
    photos: Iterable[tuple[int, Sequence[int], np.ndarray]], path="photo coordinate file"
) -> bytes:
    """The photo coordinate file: per photo its number, one record per point (number,
    x, y in mm with 4 decimals) and a record ``0``.

    >>> encode_photo_coordinates([(7, [1001], np.array([[1.5, -2.25]]))]).decode()
    '         7\\n      1001      1.5000     -2.2500\\n         0\\n'
    """
    out = []
    for photo, numbers, xy_mm in photos:
        rec = f"photo {photo}"
        out.append(_int_field(photo, 10, path, rec, "photo number"))
        xy = np.asarray(xy_mm, dtype=float).reshape(-1, 2)
        for num, (x, y) in zip(numbers, xy.tolist(), strict=True):
            r = f"{rec} point {num}"
            out.append(
                _int_field(num, 10, path, r, "point number")
                + fixed(x, 12, 4, path, r, "x (mm)")
                + fixed(y, 12, 4, path, r, "y (mm)")
            )
        out.append(f"{0:>10d}")
    return ("\n".join(out) + "\n").encode("ascii") if out else b""


def decode_photo_coordinates(data: bytes, path) -> list[PhotoRecords]:
    """The photos of a photo coordinate file (see :func:`encode_photo_coordinates`)."""
    blocks = photo_blocks(
        data, path, "a BLUH photo coordinate file", max_line=MAX_LINE, end="0",
        end_text="a record 0", photo_hi=MAX_NUMBER,
        point_key=lambda tok, rec: whole(tok, path, rec, "point number", hi=MAX_NUMBER),
        point_what="number", unit="mm", to_mm=1.0, limit=1e6,
    )  # fmt: skip
    return [PhotoRecords(*b) for b in blocks]


def encode_control(
    points: Iterable[tuple[int, float, float, float, int]], path="control file"
) -> bytes:
    """The control file: ``number X Y Z code`` per point (see the module docstring) and a
    record ``0``. A planimetric point's Z (NaN) is written 0.000.

    >>> encode_control([(1001, 2600100.0, 1200200.0, 512.3, 3)]).decode()
    '      1001    2600100.000    1200200.000     512.300  3\\n         0\\n'
    """
    out = []
    for num, X, Y, Z, code in points:
        r = f"point {num}"
        if code not in CODES:
            raise ValueRangeError(f"control code {code!r} is not one of {sorted(CODES)}", path, r)
        if code == 1:
            Z = 0.0
        out.append(
            _int_field(num, 10, path, r, "point number")
            + fixed(X, 15, 3, path, r, "X")
            + fixed(Y, 15, 3, path, r, "Y")
            + fixed(Z, 12, 3, path, r, "Z")
            + f"{code:>3d}"
        )
    out.append(f"{0:>10d}")
    return ("\n".join(out) + "\n").encode("ascii")


def decode_control(data: bytes, path) -> list[tuple[int, np.ndarray, int, int]]:
    """``(number, XYZ, code, line)`` of every control point; a planimetric point's Z is NaN.
    A number given twice, records after the closing ``0`` or a missing ``0`` are refused."""
    out: list[tuple[int, np.ndarray, int, int]] = []
    seen: dict[int, int] = {}
    ended = False
    for k, text in text_lines(data, path, "a BLUH control file", max_line=MAX_LINE):
        tok = text.split()
        rec = f"line {k}"
        if not tok:
            continue
        if ended:
            raise FormatError("a record after the closing record 0", path, rec)
        if len(tok) == 1 and tok[0] == "0":
            ended = True
            continue
        if len(tok) != 5:
            raise FormatError(
                f"expected a control record (number, X, Y, Z, code) or 0, found {len(tok)} fields",
                path,
                rec,
            )
        num = whole(tok[0], path, rec, "point number", hi=MAX_NUMBER)
        if num in seen:
            raise FormatError(
                f"control point {num} is given twice (also at line {seen[num]})", path, rec
            )
        seen[num] = k
        xyz = np.array([number(t, path, rec, c) for t, c in zip(tok[1:4], "XYZ", strict=True)])
        code = whole(tok[4], path, rec, "control code", lo=1, hi=3)
        if code == 1:
            xyz[2] = np.nan
        out.append((num, xyz, code, k))
    if not ended:
        raise FormatError("the control file is not closed by a record 0: it is truncated", path)
    return out


# ------------------------------------------------------------------ the map driver


def write(map_, path, progress=None) -> list:
    """Write the photo coordinate file of a densification map (the APY way, see
    :mod:`apygis.formats._bundlemap`): point names must be BLUH point numbers;
    ``progress(done, total)`` over the photos."""
    photos = photo_measurements(map_, max_photo=MAX_NUMBER)
    if progress:
        progress(0, len(photos))
    rows = []
    for p in photos:
        numbers = [
            point_number(nm, None, f"map {map_.id} {origin}")
            for nm, origin in zip(p.names, p.origins, strict=True)
        ]
        rows.append((p.photo, numbers, p.xy_mm))
    out = atomic_write(path, encode_photo_coordinates(rows, path), parents=True)
    if progress:
        progress(len(photos), len(photos))
    return [out]


DRIVER = Driver(
    name="bluh",
    description="BLUH photo coordinate file of a densification map, write only "
    "(docs/formats/bluh.md)",
    extensions=("bluh", "pho"),
    writer=write,
)
