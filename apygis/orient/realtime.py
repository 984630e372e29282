"""The real-time loop: mark position -> photo coordinates, parallaxes, motor steps.

Conventions: :mod:`apygis.orient.rotation` and the parallax conditions of
:mod:`apygis.orient.collinearity`.

For each mark position ``(X, Y, Z)`` (the tablet position through the map
transform, and the height set with the push buttons) and each of the two
photos the loop computes

* the photo coordinates ``(x, y)`` by the collinearity condition (a), and
* the parallax corrections ``(px, py)`` by the APY parallax conditions (c),
  ``px = sx (X - Xo) + (x - x0)``, ``py = sy (Y - Yo) + (y - y0)``
  (``Y - Yo = 0`` for scanned imagery),

and turns ``(px, py)`` into positions of the two stepper motors of that photo
(four motors in all) through its :class:`MotorCalibration`::

    [nx, ny] = [zero_x, zero_y] + round(Rot(-theta) @ [px, py] / step)

``Rot(a) = [[cos a, -sin a], [sin a, cos a]]``, ``theta`` the plate rotation,
``step`` the photo shift of one motor step (millimetres) and ``round(v) =
floor(v + 0.5)``. :meth:`MotorCalibration.shift` is the inverse (without the
rounding).

Calibration (the seed: "two stage grid crosses have to be visited in each
photo for the stage/tablet scale ratio, and one cross in each photo twice to
calibrate the optical plate rotations"):

:func:`calibrate_stage`
    Two grid crosses of the stage with known photo coordinates ``g1, g2``
    (millimetres; the grid) are superposed with the mark at tablet positions
    ``t1, t2`` (millimetres), the plates at rest. The superposition turns a
    tablet displacement into the opposite photo displacement scaled by the
    ratio, ``g2 - g1 = -rho (t2 - t1)``, so::

        rho = -((g2 - g1) . (t2 - t1)) / |t2 - t1|**2

    (photo mm per tablet mm; positive when the optics turn the photo image by
    half a turn, the sign convention of (b)). Also reported: the angle from
    ``-rho (t2 - t1)`` to ``g2 - g1`` (stage rotation against the tablet; 0
    for an aligned instrument) and the length misclosure.
:func:`map_to_photo_scale`
    The scale factors of (b): ``sx = rho * |J^-1 e_X|``,
    ``sy = rho * |J^-1 e_Y|`` with ``J`` the map transform's Jacobian (ground
    metres per tablet millimetre) at a tablet position: exact for a
    conformal map transform, a first-order value for an affine or bilinear
    one (the photo orientation may then solve for sx, sy).
:func:`calibrate_plates`
    One cross is superposed twice: with the motors at ``n1`` (tablet ``t1``)
    and, after the motors were driven by ``dn = (dnx, dny)`` steps (both
    non-zero), again (tablet ``t2``). From (b) at a fixed photo point the
    plate shift equals ``s`` times the ground displacement of the mark::

        dG = J (t2 - t1)                  (ground metres)
        dp = (sx dG_X, sy dG_Y)           (photo millimetres)
        theta = atan2(dp_y, dp_x) - atan2(dny, dnx)
        step  = |dp| / |dn|

    assuming the two plates of a photo have the same gain and orthogonal
    axes. ``theta`` is the rotation of the plate axes against the photo axes.

Examples
--------
>>> from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation
>>> from apygis.orient.photo import PhotoOrientation
>>> io = InteriorOrientation(153.0)
>>> s = 153.0 / 2300.0
>>> L = PhotoOrientation("1", io, ExteriorOrientation(-690.0, 0.0, 2300.0, 0, 0, np.pi), s, s)
>>> R = PhotoOrientation("2", io, ExteriorOrientation(690.0, 0.0, 2300.0, 0, 0, np.pi), s, s)
>>> m = MotorCalibration("1", step_um=2.0)
>>> loop = RealtimeLoop(L, R, m, m)
>>> u = loop.update(0.0, 0.0, 0.0)
>>> round(u.x_left, 3), round(u.px_left, 6), u.steps_left_x
(-45.9, 0.0, 0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from apygis.errors import DegenerateGeometryError, OrientationError
from apygis.orient._fields import finite_fields
from apygis.orient.photo import PhotoOrientation

__all__ = [
    "MAX_MOTOR_STEPS",
    "LoopBatch",
    "LoopUpdate",
    "MarkPositionError",
    "MotorCalibration",
    "RealtimeLoop",
    "StageCalibration",
    "calibrate_plates",
    "calibrate_stage",
    "map_to_photo_scale",
]


#: Largest motor position (steps) the loop ever returns: a signed 32-bit step
#: counter, as motor controllers keep it. Positions beyond are refused.
MAX_MOTOR_STEPS = 2**31 - 1
#: Range of a motor step, micrometres (``1000 / step_um`` stays finite).
MIN_STEP_UM, MAX_STEP_UM = 1e-6, 1e6


class MarkPositionError(OrientationError):
    """A mark position the real-time loop refuses: not finite, on or behind a
    photo's projection centre, or one that would drive a motor beyond
    :data:`MAX_MOTOR_STEPS`. No motor position is returned for it."""


@dataclass(frozen=True)
class StageCalibration:
    """Result of :func:`calibrate_stage`.

    Attributes
    ----------
    scale_ratio : float
        ``rho``, signed photo millimetres per tablet millimetre.
    stage_rotation_rad : float
        Angle from ``-rho (t2 - t1)`` to ``g2 - g1`` (diagnostic).
    misclosure_mm : float
        ``| |g2 - g1| - |rho| |t2 - t1| |`` in photo millimetres (0 with two
        crosses unless the rotation is not small; diagnostic).
    """

    scale_ratio: float
    stage_rotation_rad: float
    misclosure_mm: float


def calibrate_stage(grid_mm, tablet_mm) -> StageCalibration:
    """Stage/tablet scale ratio from two stage grid crosses (see the module docstring).

    Parameters
    ----------
    grid_mm : array_like, shape (2, 2)
        Photo (stage grid) coordinates of the two crosses, millimetres.
    tablet_mm : array_like, shape (2, 2)
        Tablet positions where the crosses were superposed, millimetres.

    Examples
    --------
    >>> cal = calibrate_stage([[-50, 0], [50, 0]], [[400, 300], [100, 300]])
    >>> round(cal.scale_ratio, 6), round(cal.stage_rotation_rad, 6)
    (0.333333, 0.0)
    """
    g = np.asarray(grid_mm, dtype=float)
    t = np.asarray(tablet_mm, dtype=float)
    if g.shape != (2, 2) or t.shape != (2, 2):
        raise OrientationError("calibrate_stage needs two grid crosses and two tablet positions")
    dg, dt = g[1] - g[0], t[1] - t[0]
    nt = float(dt @ dt)
    if not (nt > 0 and float(dg @ dg) > 0):
        raise DegenerateGeometryError(
            "stage calibration: the two grid crosses (or their tablet positions) coincide"
        )
    rho = -float(dg @ dt) / nt
    if rho == 0:
        raise DegenerateGeometryError(
            "stage calibration: the tablet displacement is perpendicular to the grid displacement"
        )
    a = -rho * dt
    rot = math.atan2(a[0] * dg[1] - a[1] * dg[0], a @ dg)
    mis = abs(math.hypot(*dg) - abs(rho) * math.sqrt(nt))
    return StageCalibration(rho, rot, mis)


def map_to_photo_scale(scale_ratio: float, map_transform, at_tablet_mm) -> tuple[float, float]:
    """The scale factors ``(sx, sy)`` of (b) from the stage ratio and the map transform.

    ``sx = rho |J^-1 e_X|``, ``sy = rho |J^-1 e_Y|`` with ``J`` the Jacobian of
    ``map_transform`` (anything with a ``jacobian(points)`` method) at
    ``at_tablet_mm``; photo millimetres per ground metre.
    """
    J = np.asarray(map_transform.jacobian(np.asarray(at_tablet_mm, dtype=float)), dtype=float)
    try:
        Ji = np.linalg.inv(J)
    except np.linalg.LinAlgError:
        raise DegenerateGeometryError("the map transform is singular at that position") from None
    return float(scale_ratio * np.hypot(*Ji[:, 0])), float(scale_ratio * np.hypot(*Ji[:, 1]))


@dataclass(frozen=True)
class MotorCalibration:
    """The two plate motors of one photo.

    Parameters
    ----------
    photo_id : str
    step_um : float
        Photo shift per motor step, micrometres (positive).
    plate_rotation_rad : float
        Rotation of the plate axes against the photo axes (``theta``).
    zero_x_steps, zero_y_steps : int
        Motor positions at zero parallax correction (the seed's "eliminate
        parallax" function changes these).
    scale_ratio : float
        Stage/tablet ratio ``rho`` the calibration was made with (kept for
        the record; 0 if unknown).
    """

    photo_id: str
    step_um: float = 1.0
    plate_rotation_rad: float = 0.0
    zero_x_steps: int = 0
    zero_y_steps: int = 0
    scale_ratio: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "photo_id", str(self.photo_id))
        names = ("step_um", "plate_rotation_rad", "scale_ratio")
        finite_fields(self, names, prefix="motor calibration ")
        for name in ("zero_x_steps", "zero_y_steps"):
            v = getattr(self, name)
            if isinstance(v, float) and not v.is_integer():
                raise OrientationError(f"motor calibration {name} must be an integer")
            try:
                n = int(v)
            except (TypeError, ValueError, OverflowError):
                raise OrientationError(f"motor calibration {name} must be an integer") from None
            if not -MAX_MOTOR_STEPS <= n <= MAX_MOTOR_STEPS:
                raise OrientationError(
                    f"motor calibration {name} must lie within +-{MAX_MOTOR_STEPS} steps "
                    "(a motor controller's step counter)"
                )
            object.__setattr__(self, name, n)
        if self.step_um <= 0:
            raise OrientationError("motor calibration step_um must be positive")
        if not MIN_STEP_UM <= self.step_um <= MAX_STEP_UM:
            raise OrientationError(
                f"motor calibration step_um must lie in [{MIN_STEP_UM:g}, {MAX_STEP_UM:g}] um, "
                f"got {self.step_um!r}"
            )

    def steps(self, px_mm, py_mm):
        """Motor positions ``(nx, ny)`` (int64 arrays, or ints for scalars) for plate shifts."""
        c, s = math.cos(self.plate_rotation_rad), math.sin(self.plate_rotation_rad)
        k = 1000.0 / self.step_um
        px = np.asarray(px_mm, dtype=float)
        py = np.asarray(py_mm, dtype=float)
        nx = np.floor((c * px + s * py) * k + 0.5).astype(np.int64) + self.zero_x_steps
        ny = np.floor((-s * px + c * py) * k + 0.5).astype(np.int64) + self.zero_y_steps
        if nx.ndim == 0:
            return int(nx), int(ny)
        return nx, ny

    def shift(self, nx, ny):
        """Plate shift ``(px, py)`` (photo mm) at motor positions: the inverse of :meth:`steps`."""
        c, s = math.cos(self.plate_rotation_rad), math.sin(self.plate_rotation_rad)
        k = self.step_um / 1000.0
        ux = (np.asarray(nx, dtype=float) - self.zero_x_steps) * k
        uy = (np.asarray(ny, dtype=float) - self.zero_y_steps) * k
        return c * ux - s * uy, s * ux + c * uy

    def to_dict(self) -> dict:
        return {
            "photo_id": self.photo_id,
            "step_um": self.step_um,
            "plate_rotation_rad": self.plate_rotation_rad,
            "zero_x_steps": self.zero_x_steps,
            "zero_y_steps": self.zero_y_steps,
            "scale_ratio": self.scale_ratio,
        }

    @classmethod
    def from_dict(cls, d) -> MotorCalibration:
        return cls(
            d["photo_id"],
            d["step_um"],
            d["plate_rotation_rad"],
            d.get("zero_x_steps", 0),
            d.get("zero_y_steps", 0),
            d.get("scale_ratio", 0.0),
        )


def calibrate_plates(
    photo_id: str,
    first_tablet_mm,
    second_tablet_mm,
    steps_driven,
    *,
    sx_mm_per_m: float,
    sy_mm_per_m: float,
    map_transform,
    zero_steps=(0, 0),
    scale_ratio: float = 0.0,
) -> MotorCalibration:
    """Plate rotation and step size from one cross measured twice (see the module docstring).

    Parameters
    ----------
    photo_id : str
    first_tablet_mm, second_tablet_mm : (float, float)
        Tablet positions of the mark on the cross before and after driving
        the motors.
    steps_driven : (int, int)
        ``(dnx, dny)``, both non-zero.
    sx_mm_per_m, sy_mm_per_m : float
        The photo's map-to-photo scale factors.
    map_transform :
        The map transform (with a ``jacobian`` method).
    zero_steps : (int, int)
        Motor positions of zero correction to record.
    scale_ratio : float
        The stage ratio, recorded.
    """
    t1 = np.asarray(first_tablet_mm, dtype=float)
    t2 = np.asarray(second_tablet_mm, dtype=float)
    dnx, dny = (int(v) for v in steps_driven)
    if dnx == 0 or dny == 0:
        raise DegenerateGeometryError(
            "plate calibration: drive both motors (non-zero steps) between the two measurements"
        )
    J = np.asarray(map_transform.jacobian((t1 + t2) / 2.0), dtype=float)
    dG = J @ (t2 - t1)
    dp = np.array([sx_mm_per_m * dG[0], sy_mm_per_m * dG[1]])
    length = float(np.hypot(*dp))
    if not length > 0:
        raise DegenerateGeometryError(
            "plate calibration: the cross did not move between the two measurements"
        )
    theta = math.atan2(dp[1], dp[0]) - math.atan2(dny, dnx)
    theta = math.remainder(theta, 2 * math.pi)
    step_um = 1000.0 * length / math.hypot(dnx, dny)
    return MotorCalibration(photo_id, step_um, theta, zero_steps[0], zero_steps[1], scale_ratio)


class LoopUpdate(NamedTuple):
    """One real-time update: photo coordinates and parallaxes (mm), motor positions (steps)."""

    x_left: float
    y_left: float
    x_right: float
    y_right: float
    px_left: float
    py_left: float
    px_right: float
    py_right: float
    steps_left_x: int
    steps_left_y: int
    steps_right_x: int
    steps_right_y: int


class LoopBatch(NamedTuple):
    """Vectorised updates for N mark positions.

    Attributes
    ----------
    photo_mm : numpy.ndarray, shape (2, N, 2)
        ``(x, y)`` in the left (index 0) and right (1) photo.
    parallax_mm : numpy.ndarray, shape (2, N, 2)
        ``(px, py)`` per photo.
    steps : numpy.ndarray, shape (N, 4), int64
        Motor positions: left x, left y, right x, right y.
    """

    photo_mm: np.ndarray
    parallax_mm: np.ndarray
    steps: np.ndarray


def _constants(po: PhotoOrientation, mc: MotorCalibration):
    R = po.exterior.rotation
    io = po.interior
    k = 1000.0 / mc.step_um
    th = mc.plate_rotation_rad
    return (
        po.exterior.Xo,
        po.exterior.Yo,
        po.exterior.Zo,
        *(float(v) for v in R[:, 0]),
        *(float(v) for v in R[:, 1]),
        *(float(v) for v in R[:, 2]),
        io.focal_mm,
        io.x0_mm,
        io.y0_mm,
        po.sx_mm_per_m,
        po.sy_mm_per_m,
        0.0 if io.scanned else 1.0,
        math.cos(th) * k,
        math.sin(th) * k,
        mc.zero_x_steps,
        mc.zero_y_steps,
    )


def _step_bounds(zero: int) -> tuple[float, float]:
    """Bounds on ``t`` so that ``zero + floor(t)`` lies within +-MAX_MOTOR_STEPS."""
    return float(-MAX_MOTOR_STEPS - zero), float(MAX_MOTOR_STEPS - zero + 1)


def _make_update(cl, cr, refuse):
    """A specialised scalar update with the constants bound as closure cells.

    The guards: the depth ``den`` of the point in each camera frame must be
    negative (``q_z < 0``: in front, see :mod:`apygis.orient.rotation`; false
    for NaN), and the four motor offsets ``t`` (before ``floor``) must lie
    within the motor range. The fast test of the latter is one comparison,
    ``sum(t**2) < T**2`` with ``T = MAX_MOTOR_STEPS - max|zero| - 1`` (false
    for NaN and infinities; it implies every ``|t| < T``); only when it fails
    are the four ranges checked exactly. ``refuse`` raises
    :class:`MarkPositionError` with the reason.
    """
    (lXo, lYo, lZo, l11, l21, l31, l12, l22, l32, l13, l23, l33,
     lc, lx0, ly0, lsx, lsy, lyf, lck, lsk, lzx, lzy) = cl  # fmt: skip
    (rXo, rYo, rZo, r11, r21, r31, r12, r22, r32, r13, r23, r33,
     rc, rx0, ry0, rsx, rsy, ryf, rck, rsk, rzx, rzy) = cr  # fmt: skip
    floor = math.floor
    T = float(max(MAX_MOTOR_STEPS - max(abs(lzx), abs(lzy), abs(rzx), abs(rzy)) - 1, 0))
    T2 = T * T
    a0, a1 = _step_bounds(lzx)
    b0, b1 = _step_bounds(lzy)
    c0, c1 = _step_bounds(rzx)
    d0, d1 = _step_bounds(rzy)

    def update(X, Y, Z):
        try:
            dX = X - lXo
            dY = (Y - lYo) * lyf
            dZ = Z - lZo
            den = l13 * dX + l23 * dY + l33 * dZ
            if not den < 0.0:
                refuse(X, Y, Z)
            f = -lc / den
            u = f * (l11 * dX + l21 * dY + l31 * dZ)
            v = f * (l12 * dX + l22 * dY + l32 * dZ)
            pxl = lsx * dX + u
            pyl = lsy * dY + v
            xl = lx0 + u
            yl = ly0 + v
            dX = X - rXo
            dY = (Y - rYo) * ryf
            dZ = Z - rZo
            den = r13 * dX + r23 * dY + r33 * dZ
            if not den < 0.0:
                refuse(X, Y, Z)
            f = -rc / den
            u = f * (r11 * dX + r21 * dY + r31 * dZ)
            v = f * (r12 * dX + r22 * dY + r32 * dZ)
            pxr = rsx * dX + u
            pyr = rsy * dY + v
            tlx = lck * pxl + lsk * pyl + 0.5
            tly = lck * pyl - lsk * pxl + 0.5
            trx = rck * pxr + rsk * pyr + 0.5
            try_ = rck * pyr - rsk * pxr + 0.5
            if not tlx * tlx + tly * tly + trx * trx + try_ * try_ < T2 and not (
                a0 <= tlx < a1 and b0 <= tly < b1 and c0 <= trx < c1 and d0 <= try_ < d1
            ):
                refuse(X, Y, Z)
            return LoopUpdate(
                xl,
                yl,
                rx0 + u,
                ry0 + v,
                pxl,
                pyl,
                pxr,
                pyr,
                lzx + floor(tlx),
                lzy + floor(tly),
                rzx + floor(trx),
                rzy + floor(try_),
            )
        except (TypeError, ValueError, OverflowError):  # not float numbers (no cost when fine)
            refuse(X, Y, Z)

    return update


class RealtimeLoop:
    """The real-time loop for a stereo pair (see the module docstring).

    Parameters
    ----------
    left, right : PhotoOrientation
    left_motors, right_motors : MotorCalibration

    Notes
    -----
    :meth:`update` is the fast path for one mark position: plain float
    arithmetic on constants bound when the loop is built (no array is
    allocated). :meth:`update_many` is vectorised over N positions.
    """

    def __init__(
        self,
        left: PhotoOrientation,
        right: PhotoOrientation,
        left_motors: MotorCalibration,
        right_motors: MotorCalibration,
    ):
        if not (isinstance(left, PhotoOrientation) and isinstance(right, PhotoOrientation)):
            raise OrientationError("the real-time loop needs two PhotoOrientation objects")
        if not (
            isinstance(left_motors, MotorCalibration) and isinstance(right_motors, MotorCalibration)
        ):
            raise OrientationError("the real-time loop needs a MotorCalibration per photo")
        self.left, self.right = left, right
        self.left_motors, self.right_motors = left_motors, right_motors
        self._cl = _constants(left, left_motors)
        self._cr = _constants(right, right_motors)
        self.update = _make_update(self._cl, self._cr, self._refuse)
        self.update.__doc__ = (
            "update(X, Y, Z) -> LoopUpdate: photo coordinates, parallaxes and motor "
            "positions for one mark position (floats, metres)."
        )

    def __reduce__(self):
        # the fast path is a closure (not picklable): a copy is built again from the same
        # orientations and calibrations (the view's process replays a session with one)
        return (RealtimeLoop, (self.left, self.right, self.left_motors, self.right_motors))

    def _refuse(self, X, Y, Z):
        """Raise :class:`MarkPositionError` saying why ``(X, Y, Z)`` was refused."""
        where = f"mark position ({X!r}, {Y!r}, {Z!r})"
        try:
            P = np.array([[X, Y, Z]], dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise MarkPositionError(f"{where}: X, Y and Z must be numbers (metres)") from None
        raise MarkPositionError(f"{where}: {self._diagnose(P)[1]}")

    def _diagnose(self, P: np.ndarray) -> tuple[int, str]:
        """The first refused row of ``P`` (N, 3) and why (slow path, errors only)."""
        with np.errstate(all="ignore"):
            bad = ~np.isfinite(P).all(axis=1)
            if bad.any():
                return int(np.argmax(bad)), "X, Y and Z must be finite numbers (metres)"
            for po in (self.left, self.right):
                d = P - po.exterior.centre
                if po.interior.scanned:
                    d[:, 1] = 0.0
                depth = (d @ po.exterior.rotation)[:, 2]
                bad = ~(depth < 0.0)
                if bad.any():
                    return int(np.argmax(bad)), (
                        f"not in front of photo {po.photo_id} (on or behind the plane through "
                        "its projection centre): no photo position, no motor is driven"
                    )
        return 0, (
            f"a plate motor would have to go beyond +-{MAX_MOTOR_STEPS} steps "
            "(out of range for these orientations): no motor is driven"
        )

    def update_many(self, xyz) -> LoopBatch:
        """Vectorised updates for mark positions ``xyz`` of shape (N, 3) (metres).

        Raises
        ------
        MarkPositionError
            If any position is not finite, lies on or behind the plane of a
            projection centre, or needs a motor position beyond
            :data:`MAX_MOTOR_STEPS`; the message names the first such row. No
            partial result is returned.
        """
        try:
            P = np.asarray(xyz, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise MarkPositionError("mark positions must be numbers (metres)") from None
        if P.ndim != 2 or P.shape[1] != 3:
            raise OrientationError(f"mark positions must have shape (N, 3), got {P.shape}")
        N = len(P)
        photo = np.empty((2, N, 2))
        par = np.empty((2, N, 2))
        steps = np.empty((N, 4), dtype=np.int64)
        ok = True
        with np.errstate(all="ignore"):  # NaN/inf are caught by the range checks below
            for k, (po, c) in enumerate(((self.left, self._cl), (self.right, self._cr))):
                Xo, Yo, Zo = c[0], c[1], c[2]
                d = P - (Xo, Yo, Zo)
                if po.interior.scanned:
                    d[:, 1] = 0.0
                q = d @ po.exterior.rotation
                f = np.divide(-c[12], q[:, 2])  # contiguous, > 0 in front of the camera
                # min is NaN if any is NaN; -inf for a point in the plane of the centre
                if N and not f.min() > 0.0:
                    ok = False
                    break
                u = np.multiply(q[:, 0], f, out=q[:, 0])
                v = np.multiply(q[:, 1], f, out=q[:, 1])
                np.add(u, c[13], out=photo[k, :, 0])
                np.add(v, c[14], out=photo[k, :, 1])
                px = par[k, :, 0]
                py = par[k, :, 1]
                np.multiply(d[:, 0], c[15], out=px)
                px += u
                np.multiply(d[:, 1], c[16], out=py)
                py += v
                ck, sk = c[18], c[19]
                tx = np.multiply(px, ck, out=f)
                tx += sk * py
                tx += 0.5
                ty = np.multiply(py, ck, out=u)
                ty -= sk * px
                ty += 0.5
                for j, t in ((0, tx), (1, ty)):
                    lo, hi = _step_bounds(c[20 + j])
                    if N and not (t.min() >= lo and t.max() < hi):
                        ok = False
                        break
                    np.floor(t, out=t)
                    col = steps[:, 2 * k + j]
                    col[:] = t
                    col += c[20 + j]
                if not ok:
                    break
        if not ok:
            row, why = self._diagnose(P)
            X, Y, Z = (float(v) for v in P[row])
            raise MarkPositionError(f"mark position {row} ({X!r}, {Y!r}, {Z!r}): {why}")
        return LoopBatch(photo, par, steps)
