"""The orientation file: what an orientation produces, as a JSON text file.

An :class:`Orientation` gathers the map transform, the photo orientations,
the height correction and the motor calibrations (each part optional) and is
saved and loaded as UTF-8 JSON, specified in ``docs/formats/orientation.md``.
Angles are radians and follow :mod:`apygis.orient.rotation`. Numbers are
written with Python's shortest round-trip representation, so save -> load
gives back the same floats.

Writes are atomic (:func:`apygis.fileio.atomic_write`): the text goes to a
temporary file beside the target, is flushed and synced, and then replaces
the target with :func:`os.replace`; a replaced file keeps its mode.

Examples
--------
>>> from apygis.orient.transforms import ConformalTransform
>>> t = ConformalTransform(5.0, 0.0, 2683000.0, 1248000.0)
>>> o = Orientation(map_id="ZH1091", map_transform=t)
>>> loads(dumps(o)).map_transform == o.map_transform
True
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

from apygis.errors import ApygisError, FormatError
from apygis.fileio import atomic_write
from apygis.orient import _files
from apygis.orient._files import MAX_JSON_BYTES, parse_json, range_error, read_input
from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation
from apygis.orient.height import HeightCorrection
from apygis.orient.photo import PhotoOrientation
from apygis.orient.realtime import MotorCalibration
from apygis.orient.transforms import _TYPES, _Transform, transform_from_dict

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "Orientation",
    "dumps",
    "load_orientation",
    "loads",
    "save_orientation",
]

FORMAT_NAME = "apygis-orientation"
FORMAT_VERSION = 1


@dataclass(frozen=True, eq=False)
class Orientation:
    """The content of an orientation file.

    Attributes
    ----------
    map_id : str or None
        The map identification.
    map_transform : ConformalTransform, AffineTransform, BilinearTransform or None
        Tablet millimetres -> ground metres.
    photos : tuple of PhotoOrientation
        In stage order (the first is the left photo of the stereo pair).
    height_correction : HeightCorrection or None
    motors : tuple of MotorCalibration
        One per photo that has motors (matched by ``photo_id``).
    quality : dict
        Free-form figures of merit (RMSE, sigma0, rejected points, ...);
        informational, JSON-ready values only.
    """

    map_id: str | None = None
    map_transform: _Transform | None = None
    photos: tuple = ()
    height_correction: HeightCorrection | None = None
    motors: tuple = ()
    quality: dict = field(default_factory=dict)

    def photo(self, photo_id: str) -> PhotoOrientation:
        """The photo orientation with this id (KeyError if absent)."""
        for p in self.photos:
            if p.photo_id == str(photo_id):
                return p
        raise KeyError(photo_id)

    def motor(self, photo_id: str) -> MotorCalibration:
        """The motor calibration of this photo (KeyError if absent)."""
        for m in self.motors:
            if m.photo_id == str(photo_id):
                return m
        raise KeyError(photo_id)

    def replace(self, **changes) -> Orientation:
        """A copy with fields replaced (``dataclasses.replace``)."""
        return replace(self, **changes)

    def to_dict(self) -> dict:
        """The JSON document (see ``docs/formats/orientation.md``)."""
        return {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "conventions": (
                "R = R_omega(X) R_phi(Y) R_kappa(Z), angles in radians, image at z = -c, "
                "photo mm, ground m (apygis.orient.rotation)"
            ),
            "map_id": self.map_id,
            "map": None if self.map_transform is None else self.map_transform.to_dict(),
            "photos": [p.to_dict() for p in self.photos],
            "height_correction": (
                None if self.height_correction is None else self.height_correction.to_dict()
            ),
            "motors": [m.to_dict() for m in self.motors],
            "quality": _json_safe(self.quality),
        }

    @classmethod
    def from_dict(cls, d, path=None) -> Orientation:
        """Rebuild from :meth:`to_dict` output; :class:`FormatError` names the faulty key."""
        return _parse(d, path)


def _json_safe(v):
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, Mapping):
        return {str(k): _json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_json_safe(x) for x in v]
    if hasattr(v, "item"):  # numpy scalar
        return _json_safe(v.item())
    if isinstance(v, str | int | bool) or v is None:
        return v
    raise FormatError(f"quality value {v!r} is not JSON-ready")


_NUM = "number"
_INT = "integer"
_STR = "string"
_BOOL = "boolean"

# key -> (type, range or None, unit, range applies to the magnitude); the
# ranges are those of docs/formats/orientation.md.
_PHOTO_KEYS = {
    "id": (_STR, None, "", False),
    "focal_mm": (_NUM, _files.FOCAL_MM, "mm", False),
    "x0_mm": (_NUM, _files.MM, "mm", False),
    "y0_mm": (_NUM, _files.MM, "mm", False),
    "scanned": (_BOOL, None, "", False),
    "Xo": (_NUM, _files.GROUND_M, "m", False),
    "Yo": (_NUM, _files.GROUND_M, "m", False),
    "Zo": (_NUM, _files.GROUND_M, "m", False),
    "omega_rad": (_NUM, _files.ANGLE_RAD, "rad", False),
    "phi_rad": (_NUM, _files.ANGLE_RAD, "rad", False),
    "kappa_rad": (_NUM, _files.ANGLE_RAD, "rad", False),
    "sx_mm_per_m": (_NUM, _files.SCALE_ABS, "mm per m", True),
    "sy_mm_per_m": (_NUM, _files.SCALE_ABS, "mm per m", True),
}
_HEIGHT_KEYS = {
    **dict.fromkeys(("A", "B", "C", "D", "Xc", "Yc"), (_NUM, _files.GROUND_M, "m", False)),
    "scale_m": (_NUM, _files.SCALE_M, "m", False),
}
_MOTOR_KEYS = {
    "photo_id": (_STR, None, "", False),
    "step_um": (_NUM, _files.STEP_UM, "um", False),
    "plate_rotation_rad": (_NUM, _files.ANGLE_RAD, "rad", False),
    "zero_x_steps": (_INT, _files.MOTOR_STEPS, "steps", False),
    "zero_y_steps": (_INT, _files.MOTOR_STEPS, "steps", False),
    "scale_ratio": (_NUM, _files.RATIO, "", False),
}
_COEFF = (_NUM, _files.COEFF, "", False)


def _check_type(value, kind) -> bool:
    if kind == _NUM:
        if isinstance(value, bool) or not isinstance(value, int | float):
            return False
        try:
            return math.isfinite(float(value))
        except OverflowError:  # an int beyond a double
            return False
    if kind == _INT:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == _STR:
        return isinstance(value, str)
    return isinstance(value, bool)


def _shown(value) -> str:
    r = repr(value) if not isinstance(value, int) or abs(value) < 10**30 else "a huge integer"
    return r if len(r) <= 60 else r[:57] + "..."


def _section(obj, keys: Mapping, where: str, path):
    if not isinstance(obj, Mapping):
        raise FormatError(f"expected a JSON object, got {type(obj).__name__}", path, where)
    for k, (kind, bounds, unit, magnitude) in keys.items():
        if k not in obj:
            raise FormatError(f"missing key {k!r}", path, where)
        v = obj[k]
        if not _check_type(v, kind):
            a = "an" if kind == _INT else "a"
            raise FormatError(f"{k!r} must be {a} {kind}, got {_shown(v)}", path, where)
        if bounds is not None:
            msg = range_error(v, bounds, repr(k), unit, magnitude=magnitude)
            if msg:
                raise FormatError(msg, path, where)
    return obj


def _parse(d, path) -> Orientation:
    if not isinstance(d, Mapping):
        raise FormatError("an orientation file is a JSON object", path)
    if d.get("format") != FORMAT_NAME:
        raise FormatError(f"not an orientation file: 'format' must be {FORMAT_NAME!r}", path)
    version = d.get("version")
    if (
        not isinstance(version, int)
        or isinstance(version, bool)
        or not 1 <= version <= FORMAT_VERSION
    ):
        raise FormatError(
            f"unsupported version {version!r} (this reader knows 1 to {FORMAT_VERSION})", path
        )
    try:
        map_id = d.get("map_id")
        if map_id is not None and not isinstance(map_id, str):
            raise FormatError("'map_id' must be a string or null", path, "map_id")
        transform = None
        m = d.get("map")
        if m is not None:
            if (
                not isinstance(m, Mapping)
                or not isinstance(m.get("model"), str)
                or (m["model"] not in _TYPES)
            ):
                raise FormatError(f"'model' must be one of {', '.join(_TYPES)}", path, "map")
            names = [f.name for f in fields(_TYPES[m["model"]])]
            _section(m, dict.fromkeys(names, _COEFF), "map", path)
            transform = transform_from_dict(m)
        photos = []
        plist = d.get("photos", [])
        if not isinstance(plist, list):
            raise FormatError("'photos' must be a list", path, "photos")
        for i, p in enumerate(plist):
            where = f"photos[{i}]"
            _section(p, _PHOTO_KEYS, where, path)
            try:
                photos.append(
                    PhotoOrientation(
                        p["id"],
                        InteriorOrientation(p["focal_mm"], p["x0_mm"], p["y0_mm"], p["scanned"]),
                        ExteriorOrientation(
                            p["Xo"], p["Yo"], p["Zo"], p["omega_rad"], p["phi_rad"], p["kappa_rad"]
                        ),
                        p["sx_mm_per_m"],
                        p["sy_mm_per_m"],
                    )
                )
            except ApygisError as exc:
                raise FormatError(str(exc), path, where) from exc
        ids = [p.photo_id for p in photos]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise FormatError(f"photo id(s) {', '.join(dup)} appear twice", path, "photos")
        hc = None
        h = d.get("height_correction")
        if h is not None:
            _section(h, _HEIGHT_KEYS, "height_correction", path)
            try:
                hc = HeightCorrection.from_dict(h)
            except ApygisError as exc:
                raise FormatError(str(exc), path, "height_correction") from exc
        motors = []
        mlist = d.get("motors", [])
        if not isinstance(mlist, list):
            raise FormatError("'motors' must be a list", path, "motors")
        for i, mc in enumerate(mlist):
            where = f"motors[{i}]"
            _section(mc, _MOTOR_KEYS, where, path)
            try:
                motors.append(MotorCalibration.from_dict(mc))
            except ApygisError as exc:
                raise FormatError(str(exc), path, where) from exc
        quality = d.get("quality")
        quality = {} if quality is None else quality
        if not isinstance(quality, Mapping):
            raise FormatError("'quality' must be an object", path, "quality")
    except FormatError:
        raise
    except ApygisError as exc:
        raise FormatError(str(exc), path) from exc
    return Orientation(map_id, transform, tuple(photos), hc, tuple(motors), dict(quality))


def dumps(orientation: Orientation) -> str:
    """The orientation as JSON text (2-space indent, trailing newline)."""
    return json.dumps(orientation.to_dict(), indent=2, allow_nan=False) + "\n"


def loads(text: str | bytes, path=None) -> Orientation:
    """Parse JSON text; :class:`~apygis.errors.FormatError` names the line or key.

    The JSON is read by the package's guarded parser
    (``apygis.orient._files.parse_json``): ``NaN``/``Infinity``, numbers beyond
    a double, integers of more than 18 digits, nesting deeper than 32
    levels and lone surrogates are refused with a :class:`FormatError`.
    """
    return _parse(parse_json(text, path), path)


def load_orientation(path) -> Orientation:
    """Read an orientation file.

    Raises
    ------
    FormatError
        The path is missing, a directory, a symbolic-link loop, unreadable,
        not a regular file or larger than 4 MiB; the content is not UTF-8, not
        JSON, not an orientation file, or has a missing, mistyped or
        out-of-range key (named in the message).
    """
    p = Path(path)
    return loads(read_input(p, "orientation file", MAX_JSON_BYTES), p)


def save_orientation(orientation: Orientation, path) -> Path:
    """Write an orientation file atomically (temporary file beside it, then ``os.replace``).

    Raises
    ------
    WriteError
        The file cannot be written (it names the path and the reason); the
        old file, if any, is left as it was.
    FileOverwriteError
        The path is a directory, a device or a pipe.
    """
    p = Path(path)
    atomic_write(p, dumps(orientation).encode("utf-8"))
    return p
