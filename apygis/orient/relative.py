"""Relative orientation of a dependent photo pair (coplanarity, five parameters).

Conventions: :mod:`apygis.orient.rotation`. The left photo's orientation in
the model system is given (by default the centre at the origin and all angles
0). The right photo's centre is the left one plus the base
``b = (bx, by, bz)`` with ``bx`` fixed (it sets the model scale, default 1
model unit); the five unknowns are ``by, bz, omega, phi, kappa`` of the right
photo (model units and radians).

For each tie point with photo coordinates ``(x1, y1)`` left and ``(x2, y2)``
right (millimetres), the rays ``r1 = R1 (x1 - x0, y1 - y0, -c1)`` and
``r2 = R2 (x2 - x0, y2 - y0, -c2)`` and the base are coplanar::

    F = b . (r1 x r2) = det[b, r1, r2] = 0

The residual minimised is ``e = F / |grad F|``, ``grad F`` the gradient of F
by the four photo coordinates: ``e`` (millimetres) is, to first order, the
smallest root-sum-square correction of the photo coordinates that makes the
rays coplanar (in the normal case ``(y1 - y2) / sqrt 2``), so with photo
coordinates of standard deviation ``sigma`` each, ``e`` has standard
deviation ``sigma`` and the estimated ``sigma0`` estimates it. The gradient
is re-evaluated each iteration (iteratively reweighted, the usual
linearisation of the Gauss-Helmert model). At least five points; the model
points follow by space intersection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from apygis.errors import DegenerateGeometryError, MeasurementError, OrientationError
from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation
from apygis.orient.intersection import intersect
from apygis.orient.lsq import gauss_newton
from apygis.orient.rotation import rotation_derivatives, rotation_matrix

__all__ = ["RELATIVE_PARAMETERS", "RelativeOrientationResult", "relative_orientation"]

#: The five unknowns of the dependent relative orientation.
RELATIVE_PARAMETERS = ("by", "bz", "omega", "phi", "kappa")


@dataclass(frozen=True, eq=False)
class RelativeOrientationResult:
    """Result of :func:`relative_orientation`.

    Attributes
    ----------
    left, right : ExteriorOrientation
        In the model system (model units, radians).
    base : numpy.ndarray, shape (3,)
        ``(bx, by, bz)``.
    residuals_mm : numpy.ndarray, shape (n,)
        Normalised coplanarity residuals ``e`` per point.
    sigma0_mm : float
        ``sqrt(e^T e / (n - 5))``; nan for five points.
    covariance : numpy.ndarray, shape (5, 5)
        Of ``(by, bz, omega, phi, kappa)``.
    model_points : numpy.ndarray, shape (n, 3)
        The tie points intersected in the model system.
    redundancy, iterations : int
    """

    left: ExteriorOrientation
    right: ExteriorOrientation
    base: np.ndarray
    residuals_mm: np.ndarray
    sigma0_mm: float
    covariance: np.ndarray
    model_points: np.ndarray
    redundancy: int
    iterations: int

    @property
    def parameters(self) -> np.ndarray:
        """``(by, bz, omega, phi, kappa)`` of the right photo."""
        r = self.right
        return np.array([self.base[1], self.base[2], r.omega_rad, r.phi_rad, r.kappa_rad])

    @property
    def std(self) -> dict:
        d = np.sqrt(np.diag(self.covariance))
        return dict(zip(RELATIVE_PARAMETERS, (float(v) for v in d), strict=True))


def _vectors(p, io):
    v = np.empty((len(p), 3))
    v[:, 0] = p[:, 0] - io.x0_mm
    v[:, 1] = p[:, 1] - io.y0_mm
    v[:, 2] = -io.focal_mm
    return v


def _behind(r1: np.ndarray, r2: np.ndarray, b: np.ndarray) -> tuple[int, int]:
    """How many tie points lie behind the left and the right camera.

    The rays ``C1 + l1 r1`` and ``C2 + l2 r2`` (``C2 - C1 = b``, ``r = R (x -
    x0, y - y0, -c)``) come closest at the least-squares ``(l1, l2)`` of
    ``l1 r1 - l2 r2 = b``; the image point is at ``l = 1``, so a point in
    front of a camera has ``l > 0`` (depth ``q_z = -c l < 0``,
    :mod:`apygis.orient.rotation`). Parallel rays (a point at infinity) are
    not counted.
    """
    a = np.einsum("ij,ij->i", r1, r1)
    m = np.einsum("ij,ij->i", r1, r2)
    c = np.einsum("ij,ij->i", r2, r2)
    d = r1 @ b
    e = r2 @ b
    den = a * c - m * m
    ok = den > 1e-12 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = (d * c - m * e) / den
        l2 = (m * d - a * e) / den
    return int(np.count_nonzero(ok & ~(l1 > 0))), int(np.count_nonzero(ok & ~(l2 > 0)))


def relative_orientation(
    left_mm,
    right_mm,
    interior_left: InteriorOrientation,
    interior_right: InteriorOrientation | None = None,
    *,
    left: ExteriorOrientation | None = None,
    bx: float = 1.0,
    approx=None,
    sigma_mm: float | None = None,
    max_iter: int = 50,
) -> RelativeOrientationResult:
    """Dependent relative orientation from five or more tie points.

    Parameters
    ----------
    left_mm, right_mm : array_like, shape (n, 2)
        Photo coordinates of the tie points, millimetres.
    interior_left, interior_right : InteriorOrientation
        ``interior_right`` defaults to ``interior_left``. Frame imagery.
    left : ExteriorOrientation, optional
        The left photo in the model system (default: origin, angles 0).
    bx : float
        The fixed base component (model scale).
    approx : sequence of 5 floats, optional
        Start ``(by, bz, omega, phi, kappa)``; default ``by = bz = 0`` and the
        left photo's angles.
    sigma_mm : float, optional
        A priori standard deviation of a photo coordinate (scales the
        covariance if given; else ``sigma0``).

    Raises
    ------
    DegenerateGeometryError
        Fewer than five points or a critical configuration.
    OrientationError
        The solution puts tie points behind a camera (rays that meet behind
        the projection centre, depth ``q_z >= 0``): coplanarity holds for
        such a "twisted" or mirrored pair too, e.g. when x and y of the photo
        coordinates are swapped; the message says how many.

    Examples
    --------
    >>> from apygis.orient.collinearity import ground_to_photo
    >>> io = InteriorOrientation(153.0)
    >>> L = ExteriorOrientation(0.0, 0.0, 0.0)
    >>> R = ExteriorOrientation(1.0, 0.02, -0.01, 0.01, -0.02, 0.03)
    >>> rng = np.random.default_rng(0)
    >>> M = np.column_stack(
    ...     [rng.uniform(-0.3, 1.3, 9), rng.uniform(-1, 1, 9), rng.uniform(-1.8, -1.6, 9)])
    >>> ro = relative_orientation(ground_to_photo(M, L, io), ground_to_photo(M, R, io), io)
    >>> ro.parameters.round(9).tolist()
    [0.02, -0.01, 0.01, -0.02, 0.03]
    """
    io1 = interior_left
    io2 = interior_right or interior_left
    if io1.scanned or io2.scanned:
        raise OrientationError("relative orientation needs frame imagery, not scanned imagery")
    p1 = np.asarray(left_mm, dtype=float)
    p2 = np.asarray(right_mm, dtype=float)
    if p1.ndim != 2 or p1.shape[1] != 2 or p2.shape != p1.shape:
        raise MeasurementError(
            f"left_mm and right_mm must both be (n, 2), got {p1.shape} and {p2.shape}"
        )
    if not (np.all(np.isfinite(p1)) and np.all(np.isfinite(p2))):
        raise MeasurementError("tie point coordinates must be finite")
    n = len(p1)
    if n < 5:
        raise DegenerateGeometryError(f"relative orientation needs at least 5 tie points, got {n}")
    if not bx:
        raise OrientationError("bx must not be 0")
    left = left or ExteriorOrientation(0.0, 0.0, 0.0)
    R1 = left.rotation
    r1 = _vectors(p1, io1) @ R1.T
    v2 = _vectors(p2, io2)
    if approx is None:
        approx = (0.0, 0.0, left.omega_rad, left.phi_rad, left.kappa_rad)

    def fun(x):
        b = np.array([bx, x[0], x[1]])
        R2 = rotation_matrix(x[2], x[3], x[4])
        r2 = v2 @ R2.T
        cr = np.cross(r1, r2)
        F = cr @ b
        # gradient by the photo coordinates: dF/dv1 = R1^T (r2 x b), dF/dv2 = R2^T (b x r1)
        g1 = np.cross(r2, b) @ R1
        g2 = np.cross(b, r1) @ R2
        g = np.sqrt(g1[:, 0] ** 2 + g1[:, 1] ** 2 + g2[:, 0] ** 2 + g2[:, 1] ** 2)
        J = np.empty((n, 5))
        J[:, 0] = cr[:, 1]
        J[:, 1] = cr[:, 2]
        for j, dR in enumerate(rotation_derivatives(x[2], x[3], x[4])):
            J[:, 2 + j] = np.cross(r1, v2 @ dR.T) @ b
        return F / g, J / g[:, None]

    sol = gauss_newton(
        fun, approx, RELATIVE_PARAMETERS, what="relative orientation", max_iter=max_iter
    )
    x = sol.x.copy()
    for k in range(2, 5):
        x[k] = math.remainder(x[k], 2 * math.pi)
    base = np.array([bx, x[0], x[1]])
    r2 = v2 @ rotation_matrix(x[2], x[3], x[4]).T
    b1, b2 = _behind(r1, r2, base)
    if b1 or b2:
        raise OrientationError(
            f"relative orientation: the solution puts tie points behind the cameras "
            f"({b1} of {n} behind the left, {b2} of {n} behind the right; the cameras look "
            "down their -z axes, apygis.orient.rotation): are x and y of the photo "
            "coordinates swapped, a sign reversed, or the start values far off?"
        )
    c2 = left.centre + base
    right = ExteriorOrientation(c2[0], c2[1], c2[2], x[2], x[3], x[4])
    try:
        model = intersect([(left, io1), (right, io2)], np.stack([p1, p2])).points
    except DegenerateGeometryError:
        model = np.full((n, 3), math.nan)
    sigma = float(sigma_mm) if sigma_mm is not None else sol.sigma0
    return RelativeOrientationResult(
        left=left,
        right=right,
        base=base,
        residuals_mm=sol.f,
        sigma0_mm=sol.sigma0,
        covariance=sigma**2 * sol.cofactor,
        model_points=model,
        redundancy=sol.redundancy,
        iterations=sol.iterations,
    )
