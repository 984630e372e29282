"""Space intersection: ground points from their images in two or more oriented photos.

Conventions: :mod:`apygis.orient.rotation`. For each point the unknowns are
``(X, Y, Z)`` (metres), the observations its photo coordinates ``(x, y)``
(millimetres) in ``k >= 2`` photos, and the equations the collinearity
conditions (a), ``2k`` per point. The solution is vectorised over many
points:

1. start: the point closest to all rays in the least-squares sense,
   ``sum_j (I - d_j d_j^T) (P - C_j) = 0`` with ``d_j`` the unit ray
   direction ``R_j (x - x0, y - y0, -c)`` and ``C_j`` the centre;
2. Gauss-Newton on the collinearity equations (3 x 3 normal equations per
   point, solved in one batch).

The covariance of each point is ``sigma**2 (J^T J)^-1`` with ``sigma`` the a
priori ``sigma_mm`` if given, else the point's own ``sigma0`` (which has only
``2k - 3`` degrees of freedom: one for a stereo pair).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from apygis.errors import (
    ConvergenceError,
    DegenerateGeometryError,
    MeasurementError,
    OrientationError,
)
from apygis.orient.collinearity import (
    ExteriorOrientation,
    InteriorOrientation,
    collinearity_jacobian,
)

__all__ = ["IntersectionResult", "intersect"]


@dataclass(frozen=True, eq=False)
class IntersectionResult:
    """Result of :func:`intersect`.

    Attributes
    ----------
    points : numpy.ndarray, shape (N, 3)
        Ground ``(X, Y, Z)``, metres.
    covariance : numpy.ndarray, shape (N, 3, 3)
        Per point, square metres.
    residuals_mm : numpy.ndarray, shape (k, N, 2)
        ``computed - observed`` photo coordinates per photo and point.
    sigma0_mm : numpy.ndarray, shape (N,)
        ``sqrt(v^T v / (2k - 3))`` per point.
    redundancy : int
        ``2k - 3``.
    """

    points: np.ndarray
    covariance: np.ndarray
    residuals_mm: np.ndarray
    sigma0_mm: np.ndarray
    redundancy: int

    @property
    def std(self) -> np.ndarray:
        """Standard deviations ``(sX, sY, sZ)`` per point, shape (N, 3)."""
        return np.sqrt(np.diagonal(self.covariance, axis1=1, axis2=2))


def _orientations(photos):
    out = []
    for ph in photos:
        if hasattr(ph, "exterior") and hasattr(ph, "interior"):
            eo, io = ph.exterior, ph.interior
        else:
            try:
                eo, io = ph
            except (TypeError, ValueError):
                eo = io = None
        if not isinstance(eo, ExteriorOrientation) or not isinstance(io, InteriorOrientation):
            raise OrientationError(
                "each photo must be a PhotoOrientation or an (ExteriorOrientation, "
                "InteriorOrientation) pair"
            )
        if io.scanned:
            raise OrientationError("space intersection needs frame imagery, not scanned imagery")
        out.append((eo, io))
    return out


def intersect(
    photos: Sequence,
    photo_mm,
    *,
    sigma_mm: float | None = None,
    max_iter: int = 30,
    tol_mm: float = 1e-10,
) -> IntersectionResult:
    """Intersect the rays of points seen in two or more photos.

    Parameters
    ----------
    photos : sequence
        ``k >= 2`` photos: :class:`~apygis.orient.photo.PhotoOrientation`
        objects or ``(ExteriorOrientation, InteriorOrientation)`` pairs.
    photo_mm : array_like, shape (k, N, 2) or (k, 2)
        Photo coordinates of the N points in each photo, millimetres.
    sigma_mm : float, optional
        A priori standard deviation of one photo coordinate.

    Returns
    -------
    IntersectionResult

    Raises
    ------
    DegenerateGeometryError
        Fewer than two photos, or rays that do not intersect (parallel).
    ConvergenceError
        No convergence (rays nearly parallel).

    Examples
    --------
    >>> from apygis.orient.collinearity import ground_to_photo
    >>> io = InteriorOrientation(153.0)
    >>> left = (ExteriorOrientation(0.0, 0.0, 2300.0), io)
    >>> right = (ExteriorOrientation(1380.0, 0.0, 2300.0), io)
    >>> P = np.array([[700.0, 300.0, 120.0]])
    >>> obs = [ground_to_photo(P, *left), ground_to_photo(P, *right)]
    >>> intersect([left, right], obs).points.round(6)
    array([[700., 300., 120.]])
    """
    ors = _orientations(photos)
    k = len(ors)
    if k < 2:
        raise DegenerateGeometryError(f"space intersection needs at least 2 photos, got {k}")
    obs = np.asarray(photo_mm, dtype=float)
    if obs.ndim == 2:
        obs = obs[:, None, :]
    if obs.ndim != 3 or obs.shape[0] != k or obs.shape[2] != 2:
        raise MeasurementError(f"photo_mm must have shape ({k}, N, 2), got {obs.shape}")
    if not np.all(np.isfinite(obs)):
        raise MeasurementError("photo coordinates must be finite")
    N = obs.shape[1]
    # 1. least-squares closest point to the rays
    A = np.zeros((N, 3, 3))
    b = np.zeros((N, 3))
    eye = np.eye(3)
    for (eo, io), o in zip(ors, obs, strict=True):
        v = np.empty((N, 3))
        v[:, 0] = o[:, 0] - io.x0_mm
        v[:, 1] = o[:, 1] - io.y0_mm
        v[:, 2] = -io.focal_mm
        d = v @ eo.rotation.T
        d /= np.linalg.norm(d, axis=1)[:, None]
        M = eye - d[:, :, None] * d[:, None, :]
        A += M
        b += M @ eo.centre
    det = np.linalg.det(A)
    if np.any(~(np.abs(det) > 1e-12 * k**3)):
        raise DegenerateGeometryError(
            "space intersection: the rays of some points are parallel (no intersection)"
        )
    P = np.linalg.solve(A, b[:, :, None])[:, :, 0]
    # 2. Gauss-Newton on the collinearity equations
    for _ in range(max_iter):
        f, J = _system(ors, P, obs)
        Nm = np.einsum("nki,nkj->nij", J, J)
        g = np.einsum("nki,nk->ni", J, f)
        try:
            dx = -np.linalg.solve(Nm, g[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            raise DegenerateGeometryError("space intersection: singular normal equations") from None
        P = P + dx
        if np.max(np.abs(np.einsum("nki,ni->nk", J, dx))) < tol_mm:
            break
    else:
        raise ConvergenceError(f"space intersection did not converge in {max_iter} iterations")
    f, J = _system(ors, P, obs)
    Q = np.linalg.inv(np.einsum("nki,nkj->nij", J, J))
    r = 2 * k - 3
    sigma0 = np.sqrt((f * f).sum(axis=1) / r)
    sig = float(sigma_mm) if sigma_mm is not None else sigma0[:, None, None]
    cov = sig**2 * Q
    res = f.reshape(N, k, 2).transpose(1, 0, 2)
    return IntersectionResult(P, cov, res, sigma0, r)


def _system(ors, P, obs):
    """Stacked residuals ``(N, 2k)`` and Jacobians ``(N, 2k, 3)``."""
    fs, Js = [], []
    for (eo, io), o in zip(ors, obs, strict=True):
        m, _, Jg = collinearity_jacobian(P, eo, io)
        fs.append(m - o)
        Js.append(Jg)
    f = np.stack(fs, axis=1).reshape(len(P), -1)
    J = np.stack(Js, axis=1).reshape(len(P), -1, 3)
    return f, J
