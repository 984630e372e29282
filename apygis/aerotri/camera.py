"""Cameras (the calibration protocol) and the pixel -> photo transform.

A camera file is TOML (documented in ``docs/aerotri.md``)::

    name = "RC30 15/4 UAGA-F 13245"
    kind = "film"                 # or "digital"
    focal_mm = 153.124            # calibrated principal distance c
    principal_point_mm = [0.002, -0.004]   # (x0, y0), photo system

    [fiducials]                   # film: calibrated coordinates, mm
    1 = [-106.002, -105.996]
    2 = [ 105.998, -106.001]

    orientation_mark_mm = [0.0, -112.5]     # optional: a mark that breaks the
                                            # symmetry of the fiducial pattern

    [distortion]                  # optional radial distortion table
    radius_mm = [0, 20, 40, 60, 80, 100, 120, 140, 150]
    dr_um = [0, 0.8, 1.2, 0.9, 0.1, -0.6, -1.1, -0.4, 0.3]

A digital camera has ``pixel_um`` and ``sensor_px = [W, H]`` instead of
fiducials. The distortion ``dr`` is the radial displacement of the imaged
point away from the principal point (positive outwards), so the corrected
photo coordinates are ``x_c = x0 + (x - x0) (1 - dr(r) / r)`` with
``r = |(x - x0, y - y0)|``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path

import numpy as np

from apygis.errors import FormatError
from apygis.fileio import read_bytes

__all__ = ["Camera", "PixelTransform", "read_camera"]


@dataclass(frozen=True)
class PixelTransform:
    """Photo millimetres from pixels: ``[x, y] = A @ [col, row] + t``.

    ``matrix`` is the 3 x 3 homogeneous matrix; for an affine transform its
    last row is ``(0, 0, 1)``; a projective one (scanners that need it) has a
    general last row and is applied with the division by the third component.
    """

    matrix: np.ndarray

    def __post_init__(self):
        m = np.asarray(self.matrix, dtype=float).reshape(3, 3)
        if not np.isfinite(m).all() or abs(np.linalg.det(m)) < 1e-300:
            raise FormatError(f"pixel transform is singular or not finite: {m.tolist()}")
        m = m / m[2, 2]
        m.setflags(write=False)
        object.__setattr__(self, "matrix", m)

    @classmethod
    def affine(cls, a, b, c, d, tx, ty) -> PixelTransform:
        """``x = a col + b row + tx``, ``y = c col + d row + ty``."""
        return cls(np.array([[a, b, tx], [c, d, ty], [0.0, 0.0, 1.0]]))

    @classmethod
    def digital(cls, width_px: int, height_px: int, pixel_um: float) -> PixelTransform:
        """The fixed transform of a digital frame camera (origin at the sensor centre)."""
        p = pixel_um / 1000.0
        return cls.affine(p, 0.0, 0.0, -p, -(width_px - 1) / 2 * p, (height_px - 1) / 2 * p)

    def to_mm(self, px) -> np.ndarray:
        """Photo coordinates (n x 2, mm) of pixel coordinates (n x 2)."""
        return _apply(self.matrix, px)

    def to_px(self, mm) -> np.ndarray:
        """Pixel coordinates (n x 2) of photo coordinates (n x 2, mm)."""
        return _apply(np.linalg.inv(self.matrix), mm)

    @property
    def pixel_mm(self) -> float:
        """The mean pixel size in millimetres (square root of the area scale)."""
        return math.sqrt(abs(np.linalg.det(self.matrix[:2, :2])))

    def to_list(self) -> list[float]:
        """The nine matrix elements, row by row (for JSON and the block database)."""
        return [float(v) for v in self.matrix.ravel()]

    @classmethod
    def from_list(cls, values) -> PixelTransform:
        """The inverse of :meth:`to_list`."""
        return cls(np.asarray(values, dtype=float).reshape(3, 3))


def _apply(m: np.ndarray, pts) -> np.ndarray:
    p = np.asarray(pts, dtype=float).reshape(-1, 2)
    h = p @ m[:2, :2].T + m[:2, 2]
    w = p @ m[2, :2] + m[2, 2]
    return h / w[:, None]


@dataclass(frozen=True)
class Camera:
    """A camera's calibration protocol (see the module docstring for the file)."""

    name: str
    kind: str  # "film" or "digital"
    focal_mm: float
    x0_mm: float = 0.0
    y0_mm: float = 0.0
    fiducials: dict[str, tuple[float, float]] = field(default_factory=dict)
    orientation_mark_mm: tuple[float, float] | None = None
    pixel_um: float | None = None
    sensor_px: tuple[int, int] | None = None
    distortion_radius_mm: tuple[float, ...] = ()
    distortion_dr_um: tuple[float, ...] = ()

    def __post_init__(self):
        if self.kind not in ("film", "digital"):
            raise FormatError(
                f"camera {self.name!r}: kind must be 'film' or 'digital', got {self.kind!r}"
            )
        if not (math.isfinite(self.focal_mm) and 1.0 <= self.focal_mm <= 2000.0):
            raise FormatError(
                f"camera {self.name!r}: focal_mm {self.focal_mm} is not in 1..2000 mm"
            )
        if self.kind == "film" and len(self.fiducials) < 3:
            raise FormatError(f"camera {self.name!r}: a film camera needs at least 3 fiducials")
        if self.kind == "digital" and (self.pixel_um is None or self.sensor_px is None):
            raise FormatError(
                f"camera {self.name!r}: a digital camera needs pixel_um and sensor_px"
            )
        r, d = self.distortion_radius_mm, self.distortion_dr_um
        if len(r) != len(d) or (r and any(b <= a for a, b in pairwise(r))):
            raise FormatError(
                f"camera {self.name!r}: distortion needs radius_mm increasing "
                "and as many dr_um values"
            )

    @property
    def fiducial_array(self) -> np.ndarray:
        """Calibrated fiducial coordinates (n x 2, mm), in the order of :attr:`fiducials`."""
        return np.array(list(self.fiducials.values()), dtype=float).reshape(-1, 2)

    def pixel_transform(self) -> PixelTransform:
        """The fixed pixel -> photo transform of a digital camera."""
        if self.kind != "digital" or self.pixel_um is None or self.sensor_px is None:
            raise FormatError(
                f"camera {self.name!r}: only a digital camera has a fixed pixel transform"
            )
        return PixelTransform.digital(self.sensor_px[0], self.sensor_px[1], self.pixel_um)

    def undistort(self, xy_mm) -> np.ndarray:
        """Photo coordinates corrected for radial distortion (n x 2, mm)."""
        p = np.asarray(xy_mm, dtype=float).reshape(-1, 2)
        if not self.distortion_radius_mm:
            return p.copy()
        c = np.array([self.x0_mm, self.y0_mm])
        v = p - c
        r = np.hypot(v[:, 0], v[:, 1])
        dr = np.interp(r, self.distortion_radius_mm, self.distortion_dr_um) / 1000.0
        f = np.where(r > 0, 1.0 - dr / np.where(r > 0, r, 1.0), 1.0)
        return c + v * f[:, None]

    def to_dict(self) -> dict:
        """A JSON-ready dict (the block database stores cameras this way)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "focal_mm": self.focal_mm,
            "principal_point_mm": [self.x0_mm, self.y0_mm],
            "fiducials": {k: list(v) for k, v in self.fiducials.items()},
            "orientation_mark_mm": (
                list(self.orientation_mark_mm) if self.orientation_mark_mm else None
            ),
            "pixel_um": self.pixel_um,
            "sensor_px": list(self.sensor_px) if self.sensor_px else None,
            "distortion": {
                "radius_mm": list(self.distortion_radius_mm),
                "dr_um": list(self.distortion_dr_um),
            },
        }

    @classmethod
    def from_dict(cls, d: dict, where: str = "camera") -> Camera:
        """A camera from a parsed TOML file or :meth:`to_dict` (errors name ``where``)."""
        return _camera(d, where)

    def to_toml(self) -> str:
        """The camera file text (read back by :func:`read_camera`)."""
        lines = [
            f"name = {_q(self.name)}",
            f"kind = {_q(self.kind)}",
            f"focal_mm = {self.focal_mm!r}",
            f"principal_point_mm = [{self.x0_mm!r}, {self.y0_mm!r}]",
        ]
        if self.pixel_um is not None:
            lines.append(f"pixel_um = {self.pixel_um!r}")
        if self.sensor_px is not None:
            lines.append(f"sensor_px = [{self.sensor_px[0]}, {self.sensor_px[1]}]")
        if self.orientation_mark_mm is not None:
            x, y = self.orientation_mark_mm
            lines.append(f"orientation_mark_mm = [{x!r}, {y!r}]")
        if self.fiducials:
            lines += ["", "[fiducials]"]
            lines += [f"{_q(k)} = [{x!r}, {y!r}]" for k, (x, y) in self.fiducials.items()]
        if self.distortion_radius_mm:
            lines += [
                "",
                "[distortion]",
                "radius_mm = [" + ", ".join(repr(v) for v in self.distortion_radius_mm) + "]",
                "dr_um = [" + ", ".join(repr(v) for v in self.distortion_dr_um) + "]",
            ]
        return "\n".join(lines) + "\n"


def _finite(a) -> bool:
    return isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a)


def _whole(a) -> bool:
    return isinstance(a, int) and not isinstance(a, bool)


def _q(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _num(d: dict, key: str, where: str, default=None) -> float:
    v = d.get(key, default)
    if v is None:
        raise FormatError(f"{where}: missing {key} (a number)")
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise FormatError(f"{where}: {key} must be a finite number, got {v!r}")
    return float(v)


def _pair(v, key: str, where: str) -> tuple[float, float]:
    if not isinstance(v, list) or len(v) != 2 or not all(_finite(a) for a in v):
        raise FormatError(f"{where}: {key} must be two finite numbers [x, y], got {v!r}")
    return float(v[0]), float(v[1])


def _camera(d: dict, where: str) -> Camera:
    known = {
        "name", "kind", "focal_mm", "principal_point_mm", "fiducials", "orientation_mark_mm",
        "pixel_um", "sensor_px", "distortion",
    }  # fmt: skip
    unknown = sorted(set(d) - known)
    if unknown:
        expected = ", ".join(sorted(known))
        raise FormatError(f"{where}: unknown key {unknown[0]!r} (expected one of {expected})")
    kind = d.get("kind", "film" if d.get("fiducials") else "digital")
    pp = _pair(d.get("principal_point_mm", [0.0, 0.0]), "principal_point_mm", where)
    fid_in = d.get("fiducials") or {}
    if not isinstance(fid_in, dict):
        raise FormatError(f"{where}: [fiducials] must be a table of name = [x, y]")
    fiducials = {str(k): _pair(v, f"fiducial {k}", where) for k, v in fid_in.items()}
    mark = d.get("orientation_mark_mm")
    sensor = d.get("sensor_px")
    if sensor is not None and (
        not isinstance(sensor, list)
        or len(sensor) != 2
        or not all(_whole(a) and 1 <= a <= 1_000_000 for a in sensor)
    ):
        raise FormatError(
            f"{where}: sensor_px must be two whole numbers [width, height], got {sensor!r}"
        )
    pixel = d.get("pixel_um")
    if pixel is not None:
        pixel = _num(d, "pixel_um", where)
        if not 0.1 <= pixel <= 1000:
            raise FormatError(f"{where}: pixel_um {pixel} is not in 0.1..1000 um")
    dist = d.get("distortion") or {}
    if not isinstance(dist, dict):
        raise FormatError(f"{where}: [distortion] must be a table with radius_mm and dr_um")
    radius = dist.get("radius_mm", [])
    dr = dist.get("dr_um", [])
    for key, arr in (("radius_mm", radius), ("dr_um", dr)):
        if not isinstance(arr, list) or not all(_finite(a) for a in arr):
            raise FormatError(f"{where}: distortion {key} must be a list of finite numbers")
    return Camera(
        name=str(d.get("name", "camera")),
        kind=str(kind),
        focal_mm=_num(d, "focal_mm", where),
        x0_mm=pp[0],
        y0_mm=pp[1],
        fiducials=fiducials,
        orientation_mark_mm=_pair(mark, "orientation_mark_mm", where) if mark is not None else None,
        pixel_um=pixel,
        sensor_px=(sensor[0], sensor[1]) if sensor is not None else None,
        distortion_radius_mm=tuple(float(a) for a in radius),
        distortion_dr_um=tuple(float(a) for a in dr),
    )


def read_camera(path) -> Camera:
    """Read a camera file (TOML, see the module docstring); errors name the file and line."""
    path = Path(path)
    data = read_bytes(path, "camera file", max_bytes=1 << 20)
    try:
        d = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise FormatError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise FormatError(f"{path}: not a camera file (TOML): {exc}") from None
    return _camera(d, str(path))
