"""Photo orientation by the APY parallax conditions.

Conventions: :mod:`apygis.orient.rotation` (axes, angles, sign of c) and
:mod:`apygis.orient.collinearity` (the conditions (a), (b), (c), the sign of
the map-to-photo scale factors, scanned imagery).

At each control spot ``i`` (ground ``X_i, Y_i, Z_i`` known) the operator
zeroes the parallax between photo and map; the plate shift reached,
``(px_i, py_i)`` in photo millimetres, is the observation. The parameters of
one photo are the eight of the parallax conditions (c)::

    Xo, Yo, Zo, omega, phi, kappa, sx, sy

and the equations solved, two per spot, are::

    px_i = sx (X_i - Xo) - c (a11 dX + a21 dY + a31 dZ) / (a13 dX + a23 dY + a33 dZ)
    py_i = sy (Y_i - Yo) - c (a12 dX + a22 dY + a32 dZ) / (a13 dX + a23 dY + a33 dZ)

Only the parameters not already known are solved for (the seed: "the
orientation procedure is automatically limited to determine the yet unknown
parameters"): values entered in the photo file are passed in ``fixed`` and
stay as they are. For scanned imagery ``Yo`` and ``sy`` do not occur and are
always fixed. The solution is Gauss-Newton least squares with equal weights;
residuals are ``computed - observed`` (millimetres) per spot, with the RMSE in
position ``sqrt(mean(vx**2 + vy**2))``, the standard error of unit weight
``sigma0 = sqrt(v^T v / (2 n - u))`` and the covariance
``sigma0**2 (J^T J)^-1`` of the free parameters.

What the data determine: when the superposition nearly matches the photo
(``s ~ c/H``, small parallaxes), ``px`` depends on ``Xo`` (and ``py`` on
``Yo``) only through relief displacement and the projective terms, so the
centre comes out with standard deviations of metres while the parallax
function, which the real-time loop uses, is determined to micrometres. The
optics carry the same ``Xo`` in the superposition, so the errors cancel in
compilation (see ``docs/orientation.md``); for a projection centre in the
collinearity sense use :func:`apygis.orient.resection.resect`.

Rejecting or adding points is a re-run with another set: :func:`orient_photo`
is a pure function (use ``reject=``).

Approximate values (the seed's OPERATION section): ``Zo = c / photo scale +
mean height`` with the photo scale from two map distances against the photo
distances (:func:`photo_scale_number`, :func:`approximate_orientation`); if
the control does not cover the four standard orientation areas, ``sin omega =
sin phi = 0.0001`` is entered, i.e. omega and phi are fixed at
``asin(0.0001)`` and the photo is compiled in an approximate central
projection.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from apygis.errors import DegenerateGeometryError, MeasurementError, OrientationError
from apygis.orient._fields import finite_fields
from apygis.orient.collinearity import (
    ExteriorOrientation,
    InteriorOrientation,
    depth,
    ground_to_photo,
    parallax,
    parallax_jacobian,
)
from apygis.orient.lsq import gauss_newton

__all__ = [
    "NO_CONTROL_SIN",
    "PHOTO_PARAMETERS",
    "PhotoOrientation",
    "PhotoOrientationResult",
    "approximate_orientation",
    "orient_photo",
    "photo_scale_number",
]

#: The eight parameters of the APY parallax conditions, in this order.
PHOTO_PARAMETERS = ("Xo", "Yo", "Zo", "omega", "phi", "kappa", "sx", "sy")

#: The seed's entry for omega and phi without control in the standard areas.
NO_CONTROL_SIN = 0.0001


def _wrap(a: float) -> float:
    """Angle into (-pi, pi]."""
    a = math.remainder(a, 2.0 * math.pi)
    return math.pi if a == -math.pi else a


@dataclass(frozen=True)
class PhotoOrientation:
    """Everything the real-time loop needs of one photo.

    Parameters
    ----------
    photo_id : str
    interior : InteriorOrientation
        Principal distance, principal point, scanned or not.
    exterior : ExteriorOrientation
        Projection centre and angles.
    sx_mm_per_m, sy_mm_per_m : float
        Map-to-photo scale factors of the superposition (b), photo millimetres
        per ground metre, signed (see :mod:`apygis.orient.collinearity`).
    """

    photo_id: str
    interior: InteriorOrientation
    exterior: ExteriorOrientation
    sx_mm_per_m: float
    sy_mm_per_m: float

    def __post_init__(self):
        object.__setattr__(self, "photo_id", str(self.photo_id))
        finite_fields(self, ("sx_mm_per_m", "sy_mm_per_m"), prefix=f"photo {self.photo_id}: ")

    @property
    def parameters(self) -> np.ndarray:
        """The eight parameters in the order of :data:`PHOTO_PARAMETERS`."""
        return np.concatenate([self.exterior.parameters, [self.sx_mm_per_m, self.sy_mm_per_m]])

    def with_parameters(self, p) -> PhotoOrientation:
        """A copy with the eight parameters replaced (angles wrapped into (-pi, pi])."""
        p = [float(v) for v in p]
        eo = ExteriorOrientation(p[0], p[1], p[2], _wrap(p[3]), _wrap(p[4]), _wrap(p[5]))
        return replace(self, exterior=eo, sx_mm_per_m=p[6], sy_mm_per_m=p[7])

    def photo(self, ground):
        """Photo coordinates (mm) of ground points, collinearity (a)."""
        return ground_to_photo(ground, self.exterior, self.interior)

    def parallax(self, ground):
        """Parallax corrections ``(px, py)`` (mm) at mark positions, condition (c)."""
        return parallax(ground, self.exterior, self.interior, self.sx_mm_per_m, self.sy_mm_per_m)

    def to_dict(self) -> dict:
        """JSON-ready dict: ``id``, the interior and exterior fields, ``sx/sy_mm_per_m``."""
        d: dict[str, Any] = {"id": self.photo_id}
        d.update(self.interior.to_dict())
        d.update(self.exterior.to_dict())
        d["sx_mm_per_m"] = self.sx_mm_per_m
        d["sy_mm_per_m"] = self.sy_mm_per_m
        return d

    @classmethod
    def from_dict(cls, d) -> PhotoOrientation:
        """The inverse of :meth:`to_dict`."""
        return cls(
            d["id"],
            InteriorOrientation.from_dict(d),
            ExteriorOrientation.from_dict(d),
            d["sx_mm_per_m"],
            d["sy_mm_per_m"],
        )


@dataclass(frozen=True, eq=False)
class PhotoOrientationResult:
    """Result of :func:`orient_photo`.

    Attributes
    ----------
    orientation : PhotoOrientation
    ids : tuple of str
        Control spots used.
    free : tuple of str
        Parameters solved for (the order of ``covariance``).
    residuals_mm : numpy.ndarray, shape (n, 2)
        ``computed - observed`` parallaxes per spot.
    rmse_mm : float
        RMSE in position, ``sqrt(mean(vx**2 + vy**2))``; nan when
        ``redundancy`` is 0 (as many observations as unknowns, e.g. four
        spots and all eight parameters: the fit is exact whatever the
        errors, nothing is checked).
    rmse_ground_m : float
        ``rmse_mm`` in ground metres at the mean photo scale (nan likewise).
    sigma0_mm : float
        Standard error of unit weight (one parallax component); nan without
        redundancy.
    covariance : numpy.ndarray, shape (u, u)
        Of the free parameters (metres, radians, mm per m); from ``sigma0``,
        or from the a priori ``sigma_mm`` without redundancy (else nan).
    redundancy : int
    iterations : int
    rejected : tuple of str
    """

    orientation: PhotoOrientation
    ids: tuple
    free: tuple
    residuals_mm: np.ndarray
    rmse_mm: float
    rmse_ground_m: float
    sigma0_mm: float
    covariance: np.ndarray
    redundancy: int
    iterations: int
    rejected: tuple = ()

    @property
    def std(self) -> dict:
        """Standard deviation of each free parameter, by name (nan when unknown)."""
        return {
            n: float(math.sqrt(v)) for n, v in zip(self.free, np.diag(self.covariance), strict=True)
        }

    @property
    def checked(self) -> bool:
        """Whether the spots check the orientation (redundancy > 0)."""
        return self.redundancy > 0

    def summary(self) -> dict:
        """Figures of merit (JSON-ready; nan figures become null in the file)."""
        return {
            "points": len(self.ids),
            "free": list(self.free),
            "redundancy": self.redundancy,
            "checked": self.checked,
            "rmse_mm": self.rmse_mm,
            "rmse_ground_m": self.rmse_ground_m,
            "sigma0_mm": self.sigma0_mm,
            "std": self.std,
            "rejected": list(self.rejected),
        }


def orient_photo(
    ground,
    parallax_mm,
    approx: PhotoOrientation,
    *,
    fixed: Iterable[str] = (),
    ids: Iterable | None = None,
    reject: Iterable = (),
    sigma_mm: float | None = None,
    min_points: int = 4,
    max_iter: int = 50,
) -> PhotoOrientationResult:
    """Orient one photo from the parallaxes zeroed at control spots.

    Parameters
    ----------
    ground : array_like, shape (n, 3)
        Control spots ``(X, Y, Z)``, metres.
    parallax_mm : array_like, shape (n, 2)
        Plate shifts ``(px, py)`` at which the parallax vanished, photo mm.
    approx : PhotoOrientation
        Approximate values of all eight parameters; those in ``fixed`` are
        the known ones and stay.
    fixed : iterable of str
        Names from :data:`PHOTO_PARAMETERS` that are known.
    ids : iterable of str, optional
        Spot ids (default ``"1"``, ``"2"``, ...).
    reject : iterable of str
        Spot ids to leave out.
    sigma_mm : float, optional
        A priori standard deviation of one parallax component, used for the
        covariance when there is no redundancy.
    min_points : int
        The APY needs at least four control spots.
    max_iter : int

    Returns
    -------
    PhotoOrientationResult

    Raises
    ------
    DegenerateGeometryError
        Fewer than ``min_points`` spots, fewer observations than unknowns, or
        a geometry that leaves some parameter undetermined (named).
    MeasurementError
        Unknown ids in ``reject``, non-finite data, mismatched shapes.
    ConvergenceError
        Gauss-Newton did not converge from ``approx``.
    OrientationError
        The solution puts control spots behind the camera (depth ``q_z >=
        0``, :func:`~apygis.orient.collinearity.depth`).
    """
    G = np.asarray(ground, dtype=float)
    P = np.asarray(parallax_mm, dtype=float)
    if G.ndim != 2 or G.shape[1] != 3 or P.shape != (len(G), 2):
        raise MeasurementError(
            f"ground must be (n, 3) and parallax_mm (n, 2), got {G.shape} and {P.shape}"
        )
    if not (np.all(np.isfinite(G)) and np.all(np.isfinite(P))):
        raise MeasurementError(
            f"photo {approx.photo_id}: control spots need finite X, Y, Z and parallaxes"
        )
    ids = (
        tuple(str(i) for i in ids) if ids is not None else tuple(str(k + 1) for k in range(len(G)))
    )
    if len(ids) != len(G):
        raise MeasurementError(f"{len(ids)} ids for {len(G)} control spots")
    reject = tuple(str(r) for r in reject)
    unknown = [r for r in reject if r not in ids]
    if unknown:
        raise MeasurementError(
            f"photo {approx.photo_id}: cannot reject {', '.join(unknown)}: not a control spot"
        )
    keep = np.array([i not in reject for i in ids], dtype=bool)
    G, P = G[keep], P[keep]
    ids = tuple(i for i, k in zip(ids, keep, strict=True) if k)

    fixed = set(fixed)
    bad = fixed - set(PHOTO_PARAMETERS)
    if bad:
        raise OrientationError(
            f"unknown parameter(s) {', '.join(sorted(bad))}; expected {', '.join(PHOTO_PARAMETERS)}"
        )
    if approx.interior.scanned:
        fixed |= {"Yo", "sy"}
    free = tuple(n for n in PHOTO_PARAMETERS if n not in fixed)
    idx = [PHOTO_PARAMETERS.index(n) for n in free]
    what = f"photo {approx.photo_id} orientation"
    if len(G) < min_points:
        raise DegenerateGeometryError(
            f"{what} needs at least {min_points} control spots, got {len(G)}"
        )
    p_all = approx.parameters.copy()
    if not free:
        res = approx.parallax(G) - P
        return _result(approx, ids, (), res, np.zeros((0, 0)), 2 * len(G), 0, reject, G)

    def fun(x):
        p = p_all.copy()
        p[idx] = x
        po = approx.with_parameters(p)
        m, J = parallax_jacobian(G, po.exterior, po.interior, po.sx_mm_per_m, po.sy_mm_per_m)
        return (m - P).reshape(-1), J[:, :, idx].reshape(-1, len(idx))

    sol = gauss_newton(fun, p_all[idx], free, what=what, max_iter=max_iter)
    sol_x = p_all.copy()
    sol_x[idx] = sol.x
    po = approx.with_parameters(sol_x)
    behind = int(np.count_nonzero(~(depth(G, po.exterior, po.interior) < 0.0)))
    if behind:
        raise OrientationError(
            f"{what}: {behind} of {len(G)} control spots lie behind the camera in the solution "
            "(the camera looks down its -z axis, apygis.orient.rotation): check the approximate "
            "values (kappa, the sign of sx/sy) and the measurements"
        )
    res = sol.f.reshape(-1, 2)
    r = sol.redundancy
    if r > 0:
        cov = sol.sigma0**2 * sol.cofactor
    elif sigma_mm is not None:
        cov = float(sigma_mm) ** 2 * sol.cofactor
    else:
        cov = np.full(sol.cofactor.shape, math.nan)
    return _result(po, ids, free, res, cov, r, sol.iterations, reject, G)


def _result(po, ids, free, res, cov, r, iterations, reject, G):
    rmse = float(np.sqrt((res**2).sum(axis=1).mean())) if r > 0 else math.nan
    sigma0 = float(np.sqrt((res**2).sum() / r)) if r > 0 else math.nan
    height = po.exterior.Zo - float(G[:, 2].mean())
    return PhotoOrientationResult(
        orientation=po,
        ids=ids,
        free=free,
        residuals_mm=res,
        rmse_mm=rmse,
        rmse_ground_m=rmse * abs(height) / po.interior.focal_mm,
        sigma0_mm=sigma0,
        covariance=cov,
        redundancy=r,
        iterations=iterations,
        rejected=tuple(reject),
    )


def photo_scale_number(ground_xy, photo_mm) -> float:
    """The photo scale number ``m`` (photo scale 1 : m) from two points.

    ``m = |G_b - G_a| / |p_b - p_a|`` with the ground distance in metres and
    the photo distance converted from millimetres to metres.

    Parameters
    ----------
    ground_xy : array_like, shape (2, 2)
        Two points' ground ``(X, Y)`` (from the map), metres.
    photo_mm : array_like, shape (2, 2)
        The same points' photo coordinates, millimetres.

    Examples
    --------
    >>> photo_scale_number([[0, 0], [1500, 0]], [[0, 0], [100, 0]])
    15000.0
    """
    G = np.asarray(ground_xy, dtype=float)
    p = np.asarray(photo_mm, dtype=float)
    if G.shape != (2, 2) or p.shape != (2, 2):
        raise OrientationError("photo_scale_number needs two ground and two photo points")
    dg = float(np.hypot(*(G[1] - G[0])))
    dp = float(np.hypot(*(p[1] - p[0]))) / 1000.0
    if dg == 0 or dp == 0:
        raise DegenerateGeometryError("the two points for the photo scale coincide")
    return dg / dp


def approximate_orientation(
    photo_id: str,
    interior: InteriorOrientation,
    *,
    centre_xy,
    mean_height: float,
    scale_number: float | None = None,
    Zo: float | None = None,
    sx_mm_per_m: float | None = None,
    sy_mm_per_m: float | None = None,
    kappa_rad: float | None = None,
    control_in_standard_areas: bool = True,
) -> tuple[PhotoOrientation, frozenset]:
    """Approximate orientation of a photo after the seed's recipe.

    ``Zo = c / photo scale + mean height`` (``c`` in metres, photo scale
    ``1/scale_number``), unless ``Zo`` is given. Without given scale
    factors, ``|s| = c / (Zo - mean height)``, with the sign for ``kappa``
    (``+`` for ``kappa ~ pi``, ``-`` for ``kappa ~ 0``, see
    :mod:`apygis.orient.collinearity`). Without ``kappa_rad``, kappa is pi when
    the scale factors are positive, else 0. Omega and phi start at 0; with
    ``control_in_standard_areas=False`` they are set to
    ``asin(NO_CONTROL_SIN)`` and returned as fixed.

    Parameters
    ----------
    photo_id : str
    interior : InteriorOrientation
    centre_xy : (float, float)
        Approximate ``(Xo, Yo)`` measured on the map, metres.
    mean_height : float
        Average height of the points, metres.
    scale_number : float, optional
        The photo scale number (see :func:`photo_scale_number`).
    Zo : float, optional
    sx_mm_per_m, sy_mm_per_m : float, optional
    kappa_rad : float, optional
    control_in_standard_areas : bool

    Returns
    -------
    (PhotoOrientation, frozenset)
        The approximate orientation and the names to keep fixed.

    Examples
    --------
    >>> po, fixed = approximate_orientation(
    ...     "1", InteriorOrientation(153.0), centre_xy=(2683000.0, 1248000.0),
    ...     mean_height=500.0, scale_number=15000.0, control_in_standard_areas=False)
    >>> round(po.exterior.Zo, 3), sorted(fixed)
    (2795.0, ['omega', 'phi'])
    """
    c_m = interior.focal_mm / 1000.0
    if Zo is None:
        if scale_number is not None:
            Zo = c_m * float(scale_number) + float(mean_height)
        elif given := sx_mm_per_m or sy_mm_per_m:
            s = abs(given)
            Zo = interior.focal_mm / s + float(mean_height)
        else:
            raise OrientationError(
                f"photo {photo_id}: an approximate Zo needs the photo scale, Zo or the "
                "map-to-photo scale factors"
            )
    H = float(Zo) - float(mean_height)
    if not H > 0:
        raise OrientationError(f"photo {photo_id}: Zo must lie above the mean height")
    if sx_mm_per_m is None:
        if sy_mm_per_m is None:
            sign = 1.0 if kappa_rad is None or math.cos(kappa_rad) < 0 else -1.0
            sx_mm_per_m = sy_mm_per_m = sign * interior.focal_mm / H
        else:
            sx_mm_per_m = sy_mm_per_m
    elif sy_mm_per_m is None:
        sy_mm_per_m = sx_mm_per_m
    if kappa_rad is None:
        kappa_rad = math.pi if sx_mm_per_m > 0 else 0.0
    fixed: set = set()
    ang = 0.0
    if not control_in_standard_areas:
        ang = math.asin(NO_CONTROL_SIN)
        fixed |= {"omega", "phi"}
    cx, cy = (float(v) for v in centre_xy)
    eo = ExteriorOrientation(cx, cy, float(Zo), ang, ang, _wrap(float(kappa_rad)))
    return PhotoOrientation(photo_id, interior, eo, sx_mm_per_m, sy_mm_per_m), frozenset(fixed)
