"""Guarded file access for every orientation reader (private).

The guarded read and JSON are :mod:`apygis.fileio`'s (the one implementation
every layer shares), with the orientation readers' limits:

:func:`read_input`
    The bytes of a file (:func:`apygis.fileio.read_bytes`), with everything a
    user can get wrong about the path reported as a
    :class:`~apygis.errors.FormatError` naming it: a missing file, a
    directory, a symbolic-link loop, no permission, something that is not a
    regular file (a FIFO would block, ``/dev/zero`` would never end) and a
    file larger than the reader accepts (a memory bound).
:func:`parse_json`
    JSON text to Python values (:func:`apygis.fileio.loads_json`) without
    any of :mod:`json`'s escapes: ``NaN``/``Infinity``, numbers that
    overflow a double (``1e400``), integers of more than
    :data:`MAX_INT_DIGITS` digits, nesting deeper than
    :data:`MAX_JSON_DEPTH` and lone surrogates are refused, the refused value
    named by its key path (``photos[0].Xo``).

:func:`range_error` is the range check shared by both readers: every number
of an orientation file has a documented range (``docs/formats/``), so that
no zero or absurdly large scale factor reaches a division or an
``int64`` conversion.
"""

from __future__ import annotations

from apygis.fileio import MAX_INT_DIGITS, MAX_JSON_DEPTH, loads_json, read_bytes

__all__ = [
    "MAX_INT_DIGITS",
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_TEXT_BYTES",
    "parse_json",
    "range_error",
    "read_input",
]

#: Largest text input file (control, measurements, photo file) read, bytes.
MAX_TEXT_BYTES = 16 * 2**20
#: Largest orientation file read, bytes (a real one has a few kilobytes).
MAX_JSON_BYTES = 4 * 2**20


def read_input(path, what: str = "file", max_bytes: int = MAX_TEXT_BYTES) -> bytes:
    """The content of the regular file ``path`` (at most ``max_bytes``).

    Raises
    ------
    FormatError
        Naming the path: no such file, a directory, a symbolic-link loop, no
        permission, not a regular file, larger than ``max_bytes``.
    """
    return read_bytes(path, what, max_bytes)


def parse_json(data: bytes | str, path=None):
    """Parse JSON text (UTF-8 bytes or str) refusing what the module docstring lists.

    Raises
    ------
    FormatError
        Not UTF-8 (``byte N``), a JSON syntax error (``line L column C``),
        nesting deeper than :data:`MAX_JSON_DEPTH`, a refused number or a
        lone surrogate (named by its key path).
    """
    return loads_json(data, path=path)


#: Ranges of the numbers in the orientation files (``docs/formats/``); ``abs``
#: ranges bound the magnitude and so refuse 0.
GROUND_M = (-1e8, 1e8)  # ground coordinates, metres (LV95 is about 2.6e6)
MM = (-1e5, 1e5)  # tablet, photo and parallax coordinates, millimetres
FOCAL_MM = (1e-3, 1e5)  # principal distance
ANGLE_RAD = (-1e3, 1e3)
SCALE_ABS = (1e-6, 1e3)  # |sx|, |sy|: photo mm per ground metre, not 0
STEP_UM = (1e-6, 1e6)  # motor step; 1000 / step_um stays finite
MOTOR_STEPS = (-(2**31 - 1), 2**31 - 1)  # a motor controller's step counter
RATIO = (-1e3, 1e3)  # scale_ratio
SCALE_M = (1e-3, 1e8)  # height-correction normalisation length
COEFF = (-1e12, 1e12)  # map transform coefficients


def range_error(value, bounds: tuple[float, float], what: str, unit: str = "", *, magnitude=False):
    """The message for ``value`` outside ``bounds`` (``lo <= v <= hi``), else ``None``.

    With ``magnitude=True`` the bounds apply to ``|value|`` (so 0 fails).
    NaN always fails.
    """
    lo, hi = bounds
    v = abs(value) if magnitude else value
    if lo <= v <= hi:
        return None
    u = f" {unit}" if unit else ""
    if magnitude:
        return f"{what} must be non-zero with a magnitude in [{lo:g}, {hi:g}]{u}, got {value!r}"
    return f"{what} must lie in [{lo:g}, {hi:g}]{u}, got {value!r}"
