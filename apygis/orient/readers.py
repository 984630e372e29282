"""Readers of the orientation input files (control, measurements, photo file).

The formats are specified in ``docs/formats/orient-control.md``,
``orient-map-measurements.md``, ``orient-photos.md`` and
``orient-photo-measurements.md``. Common rules: UTF-8 text, one record per
line; ``#`` starts a comment that runs to the end of the line; blank lines
are ignored; fields are separated by spaces or tabs; numbers use Python's
float syntax without ``nan`` / ``inf``; point and photo ids are any token
(compared as text, ``"012"`` is not ``"12"``).

Every reader raises :class:`~apygis.errors.FormatError` naming the file and
the line (``record="line 12"``) and saying what was expected; undecodable
bytes are reported the same way, never as ``UnicodeDecodeError``.

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> _ = (d / "c.txt").write_text("# id X Y Z\\n101 2683000.00 1248000.00 512.3\\n")
>>> read_control(d / "c.txt")["101"]
(2683000.0, 1248000.0, 512.3)
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from apygis.errors import FormatError, MeasurementError, OrientationError
from apygis.orient._files import (
    ANGLE_RAD,
    FOCAL_MM,
    GROUND_M,
    MAX_TEXT_BYTES,
    MM,
    SCALE_ABS,
    range_error,
    read_input,
)
from apygis.orient.collinearity import InteriorOrientation
from apygis.orient.photo import PhotoOrientation, approximate_orientation

__all__ = [
    "PhotoEntry",
    "control_for",
    "read_control",
    "read_map_measurements",
    "read_photo_file",
    "read_photo_measurements",
]


def _lines(path) -> Iterator[tuple[int, list[str]]]:
    p = Path(path)
    data = read_input(p, "file", MAX_TEXT_BYTES)
    start = 0
    n = 0
    size = len(data)
    while start <= size:  # line by line: no list of all lines (memory)
        end = data.find(b"\n", start)
        if end < 0:
            end = size
        raw = data[start:end]
        start = end + 1
        n += 1
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FormatError(
                f"not UTF-8 text (byte {exc.start} of the line)", p, f"line {n}"
            ) from None
        line = line.split("#", 1)[0].strip()
        if n == 1 and line.startswith("\ufeff"):
            line = line[1:].strip()
        if line:
            yield n, line.split()


# The number syntax of docs/formats/orient-control.md: decimal point, optional
# sign and exponent, ASCII digits only (no "1_000", no "inf", no "0x10").
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NON_FINITE = {"nan", "inf", "infinity"}


def _number(
    tok: str, what: str, path, n: int, bounds=None, unit: str = "", *, magnitude=False
) -> float:
    """``tok`` as a float; a FormatError naming the line if not a finite number in ``bounds``."""
    if _NUMBER.fullmatch(tok) is None:
        if tok.lower().lstrip("+-") in _NON_FINITE:
            raise FormatError(f"{what} must be a finite number, got {tok!r}", path, f"line {n}")
        shown = tok if len(tok) <= 40 else tok[:37] + "..."
        raise FormatError(f"{what} must be a number, got {shown!r}", path, f"line {n}")
    v = float(tok)
    if not math.isfinite(v):
        shown = tok if len(tok) <= 40 else tok[:37] + "..."
        raise FormatError(
            f"{what} must be a finite number, got {shown!r} (beyond a double's range)",
            path,
            f"line {n}",
        )
    if bounds is not None:
        msg = range_error(v, bounds, what, unit, magnitude=magnitude)
        if msg:
            raise FormatError(msg, path, f"line {n}")
    return v


def read_control(path) -> dict[str, tuple[float, float, float]]:
    """Read a control point file: ``ID X Y Z`` per line (metres; Z may be ``-``).

    Returns
    -------
    dict
        Point id -> ``(X, Y, Z)`` in file order; ``Z`` is nan where ``-``.
    """
    out: dict[str, tuple[float, float, float]] = {}
    where: dict[str, int] = {}
    for n, f in _lines(path):
        if len(f) != 4:
            raise FormatError(
                f"expected 4 fields 'ID X Y Z', got {len(f)}", Path(path), f"line {n}"
            )
        pid = f[0]
        X = _number(f[1], "X", path, n, GROUND_M, "m")
        Y = _number(f[2], "Y", path, n, GROUND_M, "m")
        Z = math.nan if f[3] == "-" else _number(f[3], "Z (or '-')", path, n, GROUND_M, "m")
        if pid in out:
            raise FormatError(
                f"point {pid} appears twice (first on line {where[pid]})", Path(path), f"line {n}"
            )
        out[pid] = (X, Y, Z)
        where[pid] = n
    return out


def read_map_measurements(path) -> tuple[list[str], np.ndarray]:
    """Read map (tablet) measurements: ``ID x_mm y_mm`` per line; repeat a line per measurement.

    Returns
    -------
    (list of str, numpy.ndarray of shape (M, 2))
    """
    ids: list[str] = []
    xy: list[tuple[float, float]] = []
    for n, f in _lines(path):
        if len(f) != 3:
            raise FormatError(
                f"expected 3 fields 'ID x_mm y_mm', got {len(f)}", Path(path), f"line {n}"
            )
        ids.append(f[0])
        xy.append(
            (_number(f[1], "x_mm", path, n, MM, "mm"), _number(f[2], "y_mm", path, n, MM, "mm"))
        )
    return ids, np.array(xy, dtype=float).reshape(-1, 2)


def read_photo_measurements(path) -> dict[str, tuple[list[str], np.ndarray]]:
    """Read photo measurements: ``POINT_ID PHOTO_ID px_mm py_mm`` per line.

    Returns
    -------
    dict
        Photo id -> (point ids, parallaxes of shape (n, 2)), in file order.
    """
    out: dict[str, tuple[list[str], list]] = {}
    seen: dict[tuple[str, str], int] = {}
    for n, f in _lines(path):
        if len(f) != 4:
            raise FormatError(
                f"expected 4 fields 'POINT_ID PHOTO_ID px_mm py_mm', got {len(f)}",
                Path(path),
                f"line {n}",
            )
        key = (f[0], f[1])
        if key in seen:
            raise FormatError(
                f"point {f[0]} in photo {f[1]} appears twice (first on line {seen[key]})",
                Path(path),
                f"line {n}",
            )
        seen[key] = n
        ids, vals = out.setdefault(f[1], ([], []))
        ids.append(f[0])
        vals.append(
            (_number(f[2], "px_mm", path, n, MM, "mm"), _number(f[3], "py_mm", path, n, MM, "mm"))
        )
    return {k: (ids, np.array(v, dtype=float)) for k, (ids, v) in out.items()}


_ANGLE_UNITS = {"rad": 1.0, "gon": math.pi / 200.0, "deg": math.pi / 180.0}
_LINEAR = {"Xo", "Yo", "Zo", "sx", "sy"}


@dataclass(frozen=True)
class PhotoEntry:
    """One line of the photo file.

    Attributes
    ----------
    photo_id : str
    interior : InteriorOrientation
    known : dict
        Entered (fixed) values by parameter name (``Xo``, ``Yo``, ``Zo``,
        ``omega``, ``phi``, ``kappa`` in radians, ``sx``, ``sy``).
    approx : dict
        Approximate (start) values, same names.
    line : int
        Line number in the file.
    """

    photo_id: str
    interior: InteriorOrientation
    known: dict = field(default_factory=dict)
    approx: dict = field(default_factory=dict)
    line: int = 0

    def approximation(self, ground) -> tuple[PhotoOrientation, frozenset]:
        """Start values and the fixed set for :func:`~apygis.orient.photo.orient_photo`.

        Known values are used and fixed; approximate ones are used as start
        values; the rest follow :func:`~apygis.orient.photo.approximate_orientation`
        with ``(Xo, Yo)`` defaulting to the centroid of the control spots
        and the mean height of the spots.

        Parameters
        ----------
        ground : array_like, shape (n, 3)
            The photo's control spots.
        """
        G = np.asarray(ground, dtype=float)
        v = {**self.approx, **self.known}
        mean_h = float(np.mean(G[:, 2]))
        cx = v.get("Xo", float(np.mean(G[:, 0])))
        cy = v.get("Yo", float(np.mean(G[:, 1])))
        if "Zo" not in v and "sx" not in v and "sy" not in v:
            raise OrientationError(
                f"photo {self.photo_id}: give Zo, an approximate Zo~ or the scale factors "
                "sx/sy in the photo file (Zo = focal / photo scale + mean height)"
            )
        po, fixed = approximate_orientation(
            self.photo_id,
            self.interior,
            centre_xy=(cx, cy),
            mean_height=mean_h,
            Zo=v.get("Zo"),
            sx_mm_per_m=v.get("sx"),
            sy_mm_per_m=v.get("sy"),
            kappa_rad=v.get("kappa"),
        )
        p = po.parameters
        names = ("Xo", "Yo", "Zo", "omega", "phi", "kappa", "sx", "sy")
        for i, name in enumerate(names):
            if name in v:
                p[i] = v[name]
        return po.with_parameters(p), frozenset(fixed | set(self.known))


def read_photo_file(path) -> list[PhotoEntry]:
    """Read a photo file: ``PHOTO_ID FOCAL_MM frame|scanned [KEY=VALUE|KEY~VALUE ...]``.

    ``KEY=VALUE`` enters a known value (kept fixed by the orientation),
    ``KEY~VALUE`` an approximate one. Keys: ``Xo``, ``Yo``, ``Zo`` (metres),
    ``omega``/``phi``/``kappa`` with a unit suffix ``_gon``, ``_deg`` or
    ``_rad``, ``sin_omega``, ``sin_phi``, ``sx``, ``sy`` (photo mm per ground
    metre), ``x0_mm``, ``y0_mm`` (principal point, ``=`` only).
    """
    p = Path(path)
    out: list[PhotoEntry] = []
    where: dict[str, int] = {}
    for n, f in _lines(p):
        rec = f"line {n}"
        if len(f) < 3:
            raise FormatError("expected 'PHOTO_ID FOCAL_MM frame|scanned [KEY=VALUE ...]'", p, rec)
        pid = f[0]
        if pid in where:
            raise FormatError(f"photo {pid} appears twice (first on line {where[pid]})", p, rec)
        focal = _number(f[1], "FOCAL_MM", p, n)
        if focal <= 0:
            raise FormatError(f"FOCAL_MM must be positive, got {f[1]!r}", p, rec)
        msg = range_error(focal, FOCAL_MM, "FOCAL_MM", "mm")
        if msg:
            raise FormatError(msg, p, rec)
        kind = f[2].lower()
        if kind not in ("frame", "scanned"):
            raise FormatError(f"the third field must be 'frame' or 'scanned', got {f[2]!r}", p, rec)
        known: dict[str, float] = {}
        approx: dict[str, float] = {}
        pp = {"x0_mm": 0.0, "y0_mm": 0.0}
        for tok in f[3:]:
            if "=" in tok:
                key, _, val = tok.partition("=")
                target = known
            elif "~" in tok:
                key, _, val = tok.partition("~")
                target = approx
            else:
                raise FormatError(f"expected KEY=VALUE or KEY~VALUE, got {tok!r}", p, rec)
            value = _number(val, key, p, n)
            if key in pp:
                if target is approx:
                    raise FormatError(f"{key} takes '=' only", p, rec)
                pp[key] = _number(val, key, p, n, MM, "mm")
                continue
            if key in ("sx", "sy"):
                name = key
                value = _number(val, key, p, n, SCALE_ABS, "mm per m", magnitude=True)
            elif key in _LINEAR:
                name = key
                value = _number(val, key, p, n, GROUND_M, "m")
            elif key in ("sin_omega", "sin_phi"):
                if target is approx:
                    raise FormatError(f"{key} takes '=' only", p, rec)
                if not -1.0 <= value <= 1.0:
                    raise FormatError(f"{key} must lie in [-1, 1], got {val!r}", p, rec)
                name = key[4:]
                value = math.asin(value)
            else:
                name, _, unit = key.rpartition("_")
                if name not in ("omega", "phi", "kappa") or unit not in _ANGLE_UNITS:
                    raise FormatError(
                        f"unknown key {key!r}; expected Xo, Yo, Zo, omega_gon, phi_gon, "
                        "kappa_gon (or _deg, _rad), sin_omega, sin_phi, sx, sy, x0_mm, y0_mm",
                        p,
                        rec,
                    )
                value *= _ANGLE_UNITS[unit]
                msg = range_error(value, ANGLE_RAD, f"{key} (in radians)", "rad")
                if msg:
                    raise FormatError(msg, p, rec)
            if name in known or name in approx:
                raise FormatError(f"{name} is given twice", p, rec)
            target[name] = value
        if kind == "scanned":
            for name in ("Yo", "sy"):
                known.pop(name, None)
                approx.pop(name, None)
        try:
            io = InteriorOrientation(focal, pp["x0_mm"], pp["y0_mm"], kind == "scanned")
        except OrientationError as exc:
            raise FormatError(str(exc), p, rec) from None
        out.append(PhotoEntry(pid, io, known, approx, n))
        where[pid] = n
    if not out:
        raise FormatError("no photo in the photo file", p)
    return out


def control_for(ids, control, photo_id: str | None = None, *, need_z: bool = True) -> np.ndarray:
    """Ground coordinates of ``ids`` from a control mapping (helper for the CLI).

    Raises
    ------
    MeasurementError
        A point not in the control, or without height where one is needed.
    """
    rows = []
    ctx = f" (photo {photo_id})" if photo_id is not None else ""
    for i in ids:
        if i not in control:
            raise MeasurementError(f"measured point {i}{ctx} is not in the control")
        try:
            X, Y, Z = (float(v) for v in control[i])
        except (TypeError, ValueError, OverflowError):
            raise MeasurementError(
                f"control point {i}{ctx} must be three numbers (X, Y, Z), got {control[i]!r:.80}"
            ) from None
        if not (math.isfinite(X) and math.isfinite(Y)):
            raise MeasurementError(f"control point {i}{ctx} needs finite X and Y")
        if need_z and not math.isfinite(Z):
            raise MeasurementError(f"control point {i}{ctx} has no height (Z '-')")
        rows.append((X, Y, Z))
    return np.array(rows, dtype=float).reshape(-1, 3)
