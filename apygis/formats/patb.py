"""PAT-B's files, laid out in one place, and the map driver of the APY way.

PAT-B (the bundle block adjustment of the University of Stuttgart, later Inpho) has no
public specification; ``docs/formats/patb.md`` gathers what is publicly known, with
its sources, and marks what apygis assumes. This module is the only place that knows
the record layouts; the block exchange (:mod:`apygis.aerotri.exchange.patb`) and the
map driver below use its functions, which take and return plain numbers and strings
(no model):

image-coordinate file (``.im``; PAT-B input)::

                 101                                   <- photo number (I16)
                1001       -1234.567       8901.234    <- point name (A16, at most 15
                1002         765.432     -10987.654       characters, right-aligned),
                 -99                                      x, y in micrometres (2F16.3)
                 102                                   <- ... -99 closes each photo

control file (``.con``; PAT-B input): ``name X Y Z`` (A16, 3F16.3, metres), one record
per full control point, ``-99`` after the last.

exterior orientation file (``.ori``; PAT-B output), three records per photo::

    I16,16X,3F16.5   photo number, X0, Y0, Z0 (metres)
    5F16.12          a11 a12 a13 a21 a22
    4F16.12          a23 a31 a32 a33

with ``a_ij`` the rotation matrix of :mod:`apygis.orient.rotation` (image vector ->
ground direction; ASSUMED to be PAT-B's, see the doc).

Reading splits records on blanks (a file aligned differently still reads; numbers
that touch are refused, never split); every value is checked (finite, within its
field's range) and a bad one is a :class:`~apygis.errors.FormatError` naming the file
and the line. Writing refuses a name longer than 15 characters or holding a blank,
and a value that does not fit its field (:class:`~apygis.errors.ValueRangeError`
naming the file and the record); nothing is truncated.

The map driver ``patb`` writes the image-coordinate file of a densification map
(:mod:`apygis.formats._bundlemap`): ``apygis convert MAP out/x.patb --to patb``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import NamedTuple

import numpy as np

from apygis.errors import FormatError
from apygis.fileio import atomic_write
from apygis.formats import Driver
from apygis.formats._bundlemap import photo_measurements
from apygis.formats._records import check_name, fixed, name, number, photo_blocks, text_lines, whole

__all__ = [
    "DRIVER",
    "END",
    "MAX_LINE",
    "MAX_PHOTO",
    "NAME_LEN",
    "Orientation",
    "PhotoRecords",
    "decode_control",
    "decode_image_coordinates",
    "decode_orientations",
    "encode_control",
    "encode_image_coordinates",
    "encode_orientations",
    "write",
]

NAME_LEN = 15
"""The longest point name PAT-B takes."""
MAX_PHOTO = 10**15 - 1
"""The largest photo number written (I16 with a blank before it)."""
END = -99
"""The record that closes a photo (image coordinates) or the list (control)."""
MAX_LINE = 512
"""The longest line read (bytes); PAT-B's records are 16-column fields."""
_W = 16
_ROT_TOL = 1e-6  # largest |R^T R - I| accepted from a file (12 decimals give 1e-12)


class PhotoRecords(NamedTuple):
    """The points of one photo: names, photo coordinates ``(n, 2)`` in mm, and the file's
    line of each point (for messages)."""

    photo: int
    names: list[str]
    xy_mm: np.ndarray
    lines: list[int]


class Orientation(NamedTuple):
    """One photo's exterior orientation: projection centre (m) and rotation matrix."""

    photo: int
    centre: np.ndarray
    rotation: np.ndarray
    line: int


def _photo_field(photo: int, path, record: str) -> str:
    if isinstance(photo, bool) or not isinstance(photo, int | np.integer):
        raise FormatError(f"photo number {photo!r} is not a whole number", path, record)
    if not 1 <= photo <= MAX_PHOTO:
        raise FormatError(f"photo number {photo} is not from 1 to {MAX_PHOTO} (I16)", path, record)
    return f"{int(photo):>{_W}d}"


def _end() -> str:
    return f"{END:>{_W}d}"


# ------------------------------------------------------------------ image coordinates


def encode_image_coordinates(
    photos: Iterable[tuple[int, Sequence[str], np.ndarray]], path="image-coordinate file"
) -> bytes:
    """The image-coordinate file: per photo its number, one record per point (name, x, y
    in micrometres from ``xy_mm``) and ``-99``.

    ``path`` names the target in errors (a name too long, a coordinate that does not fit).

    >>> encode_image_coordinates([(7, ["A1"], np.array([[1.5, -2.25]]))]).decode()
    '               7\\n              A1        1500.000       -2250.000\\n             -99\\n'
    """
    out = []
    for photo, names, xy_mm in photos:
        rec = f"photo {photo}"
        out.append(_photo_field(photo, path, rec))
        xy = np.asarray(xy_mm, dtype=float).reshape(-1, 2) * 1000.0
        for nm, (x, y) in zip(names, xy.tolist(), strict=True):
            r = f"{rec} point {nm!r}"
            check_name(nm, path, r, "point name", max_len=NAME_LEN)
            if nm == str(END):
                raise FormatError(f"point name {nm!r} is PAT-B's end record", path, r)
            xs, ys = fixed(x, _W, 3, path, r, "x (um)"), fixed(y, _W, 3, path, r, "y (um)")
            out.append(f"{nm:>{_W}}{xs}{ys}")
        out.append(_end())
    return ("\n".join(out) + "\n").encode("ascii") if out else b""


def decode_image_coordinates(data: bytes, path) -> list[PhotoRecords]:
    """The photos of an image-coordinate file (see :func:`encode_image_coordinates`), in
    file order; coordinates in mm. A photo that appears twice, a point measured twice in
    one photo, a photo not closed by ``-99`` are refused, naming the lines."""
    blocks = photo_blocks(
        data, path, "a PAT-B image-coordinate file", max_line=MAX_LINE, end=str(END),
        end_text=str(END), photo_hi=MAX_PHOTO,
        point_key=lambda tok, rec: name(tok, path, rec, "point name", max_len=NAME_LEN),
        point_what="name", unit="um", to_mm=1000.0, limit=1e9,
    )  # fmt: skip
    return [PhotoRecords(*b) for b in blocks]


# ------------------------------------------------------------------ control


def encode_control(points: Iterable[tuple[str, float, float, float]], path="control file") -> bytes:
    """The control file: ``name X Y Z`` (metres, 3 decimals) per point, ``-99`` after the
    last.

    >>> encode_control([("GCP1", 2600100.0, 1200200.0, 512.3)]).decode()
    '            GCP1     2600100.000     1200200.000         512.300\\n             -99\\n'
    """
    out = []
    for nm, X, Y, Z in points:
        r = f"point {nm!r}"
        check_name(nm, path, r, "point name", max_len=NAME_LEN)
        if nm == str(END):
            raise FormatError(f"point name {nm!r} is PAT-B's end record", path, r)
        out.append(
            f"{nm:>{_W}}"
            + "".join(fixed(v, _W, 3, path, r, c) for v, c in ((X, "X"), (Y, "Y"), (Z, "Z")))
        )
    out.append(_end())
    return ("\n".join(out) + "\n").encode("ascii")


def decode_control(data: bytes, path) -> list[tuple[str, np.ndarray, int]]:
    """``(name, XYZ, line)`` of every control point; a name given twice, records after
    ``-99`` or a missing ``-99`` are refused."""
    out: list[tuple[str, np.ndarray, int]] = []
    seen: dict[str, int] = {}
    ended = False
    for k, text in text_lines(data, path, "a PAT-B control file", max_line=MAX_LINE):
        tok = text.split()
        rec = f"line {k}"
        if not tok:
            continue
        if ended:
            raise FormatError(f"a record after the closing {END}", path, rec)
        if len(tok) == 1 and tok[0] == str(END):
            ended = True
            continue
        if len(tok) != 4:
            raise FormatError(
                f"expected a control record (name, X, Y, Z) or {END}, found {len(tok)} fields",
                path,
                rec,
            )
        nm = name(tok[0], path, rec, "point name", max_len=NAME_LEN)
        if nm in seen:
            raise FormatError(
                f"control point {nm!r} is given twice (also at line {seen[nm]})", path, rec
            )
        seen[nm] = k
        xyz = np.array([number(t, path, rec, c) for t, c in zip(tok[1:], "XYZ", strict=True)])
        out.append((nm, xyz, k))
    if not ended:
        raise FormatError(f"the control file is not closed by {END}: it is truncated", path)
    return out


# ------------------------------------------------------------------ exterior orientation


def encode_orientations(
    rows: Iterable[tuple[int, Sequence[float], np.ndarray]], path="orientation file"
) -> bytes:
    """The exterior orientation file: per photo ``I16,16X,3F16.5`` (number, X0, Y0, Z0)
    then the rotation matrix row by row in ``5F16.12`` and ``4F16.12``."""
    out = []
    for photo, centre, R in rows:
        rec = f"photo {photo}"
        head = _photo_field(photo, path, rec) + " " * _W
        head += "".join(
            fixed(v, _W, 5, path, rec, c) for v, c in zip(centre, ("X0", "Y0", "Z0"), strict=True)
        )
        a = np.asarray(R, dtype=float).reshape(9).tolist()
        names = [f"a{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
        cells = [fixed(v, _W, 12, path, rec, n) for v, n in zip(a, names, strict=True)]
        out += [head, "".join(cells[:5]), "".join(cells[5:])]
    return ("\n".join(out) + "\n").encode("ascii") if out else b""


def decode_orientations(data: bytes, path) -> list[Orientation]:
    """The orientations of an exterior orientation file; a matrix that is not a rotation
    (``|R^T R - I| > 1e-6`` or a reflection) is refused, naming its line; the matrix is
    returned as read (the exchange takes the nearest rotation)."""
    lines = [
        (k, t.split())
        for k, t in text_lines(data, path, "a PAT-B orientation file", max_line=MAX_LINE)
    ]
    lines = [(k, t) for k, t in lines if t]
    out: list[Orientation] = []
    seen: dict[int, int] = {}
    for i in range(0, len(lines), 3):
        group = lines[i : i + 3]
        k0 = group[0][0]
        if len(group) < 3:
            raise FormatError(
                "an orientation needs three records (photo and centre, then the rotation matrix "
                "in 5 and 4 values): the file is truncated",
                path,
                f"line {k0}",
            )
        for (k, tok), n, what in zip(
            group,
            (4, 5, 4),
            ("photo number, X0, Y0, Z0", "a11 a12 a13 a21 a22", "a23 a31 a32 a33"),
            strict=True,
        ):
            if len(tok) != n:
                raise FormatError(
                    f"expected {n} values ({what}), found {len(tok)}", path, f"line {k}"
                )
        rec = f"line {k0}"
        photo = whole(group[0][1][0], path, rec, "photo number", hi=MAX_PHOTO)
        if photo in seen:
            raise FormatError(
                f"photo {photo} appears again (first at line {seen[photo]})", path, rec
            )
        seen[photo] = k0
        centre = np.array(
            [
                number(t, path, rec, c)
                for t, c in zip(group[0][1][1:], ("X0", "Y0", "Z0"), strict=True)
            ]
        )
        a = [
            number(t, path, f"line {k}", "a rotation matrix element", limit=1.5)
            for k, tok in group[1:]
            for t in tok
        ]
        R = np.array(a).reshape(3, 3)
        dev = float(np.abs(R.T @ R - np.eye(3)).max())
        if dev > _ROT_TOL or np.linalg.det(R) < 0:
            raise FormatError(
                f"the matrix of photo {photo} is not a rotation (|R^T R - I| = {dev:.2g}, "
                f"det {np.linalg.det(R):.6g})",
                path,
                f"line {group[1][0]}",
            )
        out.append(Orientation(photo, centre, R, k0))
    return out


# ------------------------------------------------------------------ the map driver


def write(map_, path, progress=None) -> list:
    """Write the image-coordinate file of a densification map (the APY way, see
    :mod:`apygis.formats._bundlemap`); ``progress(done, total)`` over the photos."""
    photos = photo_measurements(map_, max_photo=MAX_PHOTO)
    if progress:
        progress(0, len(photos))
    data = encode_image_coordinates(((p.photo, p.names, p.xy_mm) for p in photos), path)
    out = atomic_write(path, data, parents=True)
    if progress:
        progress(len(photos), len(photos))
    return [out]


DRIVER = Driver(
    name="patb",
    description="PAT-B image-coordinate file of a densification map, write only "
    "(docs/formats/patb.md)",
    extensions=("patb", "im"),
    writer=write,
)
