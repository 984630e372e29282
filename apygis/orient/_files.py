"""Guarded file access for every orientation reader (private).

Two helpers, used by :mod:`apygis.orient.readers` (text input files) and
:mod:`apygis.orient.io` (the orientation file):

:func:`read_input`
    The bytes of a file, with everything a user can get wrong about the path
    reported as a :class:`~apygis.errors.FormatError` naming it: a missing
    file, a directory, a symbolic-link loop, no permission, something that is
    not a regular file (a FIFO would block, ``/dev/zero`` would never end)
    and a file larger than the reader accepts (a memory bound).
:func:`parse_json`
    JSON text to Python values without any of :mod:`json`'s escapes: the
    number hooks refuse ``NaN``/``Infinity``, numbers that overflow a double
    (``1e400``) and integers of more than :data:`MAX_INT_DIGITS` digits (no
    ``ValueError`` from Python's int-string limit, no ``OverflowError`` later
    in ``math.isfinite``), and nesting deeper than :data:`MAX_JSON_DEPTH`
    (no ``RecursionError``). The refused value is named by its key path
    (``photos[0].Xo``).

:func:`range_error` is the range check shared by both readers: every number
of an orientation file has a documented range (``docs/formats/``), so that
no zero or absurdly large scale factor reaches a division or an
``int64`` conversion.
"""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path

from apygis.errors import FormatError

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
#: Deepest nesting of JSON arrays and objects accepted (a real file has 5).
MAX_JSON_DEPTH = 32
#: Most digits of a JSON integer accepted (an int64 has 19).
MAX_INT_DIGITS = 19


def read_input(path, what: str = "file", max_bytes: int = MAX_TEXT_BYTES) -> bytes:
    """The content of the regular file ``path`` (at most ``max_bytes``).

    Raises
    ------
    FormatError
        Naming the path: no such file, a directory, a symbolic-link loop, no
        permission, not a regular file, larger than ``max_bytes``.
    """
    a = "an" if what[:1] in "aeiou" else "a"
    try:
        p = Path(path)
        flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
        fd = os.open(p, flags)  # non-blocking: a FIFO must not hang the reader
    except FileNotFoundError:
        raise FormatError(f"no such {what}", path) from None
    except IsADirectoryError:
        raise FormatError(f"is a directory, not {a} {what}", path) from None
    except PermissionError:
        raise FormatError(f"cannot read the {what}: permission denied", path) from None
    except (OSError, ValueError, TypeError) as exc:
        raise FormatError(f"cannot open the {what}: {_reason(exc)}", path) from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise FormatError(f"is a directory, not {a} {what}", path)
        if not stat.S_ISREG(st.st_mode):
            raise FormatError(
                f"is not a regular file (a device, FIFO or socket), not {a} {what}", path
            )
        if st.st_size > max_bytes:
            raise FormatError(
                f"{st.st_size} bytes is larger than the {max_bytes} bytes {a} {what} may have", path
            )
        chunks = []
        size = 0
        while True:
            b = os.read(fd, min(1 << 20, max_bytes + 1 - size))
            if not b:
                break
            chunks.append(b)
            size += len(b)
            if size > max_bytes:
                raise FormatError(
                    f"larger than the {max_bytes} bytes {a} {what} may have (it grew while read)",
                    path,
                )
        return b"".join(chunks)
    except OSError as exc:
        raise FormatError(f"cannot read the {what}: {_reason(exc)}", path) from None
    finally:
        os.close(fd)


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror.lower() if exc.errno is not None else exc.strerror
    return str(exc)


class _Refused:
    """A JSON number the hooks refused; reported with its key path after parsing."""

    __slots__ = ("reason",)

    def __init__(self, reason: str):
        self.reason = reason


def _parse_int(s: str):
    digits = len(s.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        return _Refused(
            f"an integer of {digits} digits is out of range (at most {MAX_INT_DIGITS} digits)"
        )
    return int(s)


def _parse_float(s: str):
    v = float(s)
    if not math.isfinite(v):
        shown = s if len(s) <= 24 else s[:20] + "..."
        return _Refused(f"the number {shown} is out of range (beyond a double's ±1.8e308)")
    return v


def _parse_constant(s: str):
    return _Refused(f"{s} is not allowed (numbers must be finite)")


def parse_json(data: bytes | str, path=None):
    """Parse JSON text (UTF-8 bytes or str) refusing what the module docstring lists.

    Raises
    ------
    FormatError
        Not UTF-8 (``byte N``), a JSON syntax error (``line L column C``),
        nesting deeper than :data:`MAX_JSON_DEPTH`, or a refused number
        (named by its key path).
    """
    if isinstance(data, bytes | bytearray):
        try:
            text = bytes(data).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FormatError(f"not UTF-8 text (byte {exc.start})", path) from None
    else:
        text = data
    try:
        value = json.loads(
            text,
            parse_int=_parse_int,
            parse_float=_parse_float,
            parse_constant=_parse_constant,
        )
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"invalid JSON: {exc.msg}", path, f"line {exc.lineno} column {exc.colno}"
        ) from None
    except RecursionError:
        raise FormatError(
            f"JSON nested too deeply (at most {MAX_JSON_DEPTH} levels of arrays and objects)",
            path,
        ) from None
    _check_tree(value, path)
    return value


def _check_tree(value, path) -> None:
    """Depth and refused numbers, iteratively (no recursion on hostile input)."""
    stack = [(value, "", 0)]
    while stack:
        v, where, depth = stack.pop()
        if isinstance(v, _Refused):
            raise FormatError(v.reason, path, where or None)
        if isinstance(v, dict | list):
            if depth >= MAX_JSON_DEPTH:
                raise FormatError(
                    f"JSON nested too deeply (at most {MAX_JSON_DEPTH} levels of arrays "
                    "and objects)",
                    path,
                    where or None,
                )
            if isinstance(v, dict):
                items = [(f"{where}.{k}" if where else str(k), x) for k, x in v.items()]
            else:
                items = [(f"{where}[{i}]", x) for i, x in enumerate(v)]
            stack.extend((x, w, depth + 1) for w, x in reversed(items))


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
