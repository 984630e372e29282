"""Space resection: the six exterior orientation parameters of one photo.

Conventions: :mod:`apygis.orient.rotation`. Observations are the photo
coordinates ``(x, y)`` (millimetres) of at least three control points with
known ``(X, Y, Z)`` (metres); the equations solved are the collinearity
conditions (a)::

    x - x0 = -c (a11 dX + a21 dY + a31 dZ) / (a13 dX + a23 dY + a33 dZ)
    y - y0 = -c (a12 dX + a22 dY + a32 dZ) / (a13 dX + a23 dY + a33 dZ)

by Gauss-Newton least squares with equal weights, for ``Xo, Yo, Zo, omega,
phi, kappa``. Residuals are ``computed - observed`` (mm).

Approximate values, unless given:

* six or more points that are not (nearly) coplanar: the direct linear
  transformation (DLT) ``x ~ P X`` solved by SVD on normalised coordinates;
  the centre is the null vector of ``P``, and the rotation is the nearest
  rotation to ``K^-1 P[:, :3]`` with the known interior orientation
  ``K = [[-c, 0, x0], [0, -c, y0], [0, 0, 1]]``;
* otherwise a 2-D similarity from the photo to the ground plan, which fits a
  near-vertical photo: kappa = its rotation, ``Zo = mean Z + c * scale``,
  ``(Xo, Yo)`` = the ground position of the principal point, omega = phi = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from apygis.errors import DegenerateGeometryError, MeasurementError, OrientationError
from apygis.orient.collinearity import (
    EO_PARAMETERS,
    ExteriorOrientation,
    InteriorOrientation,
    collinearity_jacobian,
    depth,
)
from apygis.orient.lsq import gauss_newton
from apygis.orient.rotation import angles_from_matrix, nearest_rotation

__all__ = ["ResectionResult", "dlt_approximation", "resect", "similarity_approximation"]


@dataclass(frozen=True, eq=False)
class ResectionResult:
    """Result of :func:`resect`.

    Attributes
    ----------
    exterior : ExteriorOrientation
    residuals_mm : numpy.ndarray, shape (n, 2)
        ``computed - observed`` photo coordinates.
    rmse_mm : float
        ``sqrt(mean(vx**2 + vy**2))``; nan for three points (no redundancy:
        the fit is exact whatever the errors, nothing is checked).
    sigma0_mm : float
        ``sqrt(v^T v / (2 n - 6))``; nan for three points.
    covariance : numpy.ndarray, shape (6, 6)
        Of ``(Xo, Yo, Zo, omega, phi, kappa)`` (m, rad): ``sigma**2 (J^T J)^-1``
        with ``sigma = sigma_mm`` if given, else ``sigma0``.
    redundancy, iterations : int
    """

    exterior: ExteriorOrientation
    residuals_mm: np.ndarray
    rmse_mm: float
    sigma0_mm: float
    covariance: np.ndarray
    redundancy: int
    iterations: int

    @property
    def std(self) -> dict:
        """Standard deviations by parameter name."""
        d = np.sqrt(np.diag(self.covariance))
        return dict(zip(EO_PARAMETERS, (float(v) for v in d), strict=True))


def _check(ground, photo_mm):
    G = np.asarray(ground, dtype=float)
    p = np.asarray(photo_mm, dtype=float)
    if G.ndim != 2 or G.shape[1] != 3 or p.shape != (len(G), 2):
        raise MeasurementError(
            f"ground must be (n, 3) and photo_mm (n, 2), got {G.shape} and {p.shape}"
        )
    if not (np.all(np.isfinite(G)) and np.all(np.isfinite(p))):
        raise MeasurementError("resection needs finite ground and photo coordinates")
    return G, p


def similarity_approximation(
    ground, photo_mm, interior: InteriorOrientation
) -> ExteriorOrientation:
    """Approximate exterior orientation of a near-vertical photo from a 2-D similarity.

    Fits ``X + iY = a (x - x0 + i (y - y0)) + b`` (complex numbers) by least
    squares; ``kappa = arg a``, ``Zo = mean Z + |a| c``, ``(Xo, Yo) = b``,
    omega = phi = 0.
    """
    G, p = _check(ground, photo_mm)
    if len(G) < 2:
        raise DegenerateGeometryError("a similarity start needs at least 2 points")
    zg = G[:, 0] + 1j * G[:, 1]
    zp = (p[:, 0] - interior.x0_mm) + 1j * (p[:, 1] - interior.y0_mm)
    zgm, zpm = zg.mean(), zp.mean()
    den = np.sum(np.abs(zp - zpm) ** 2)
    if not den > 0:
        raise DegenerateGeometryError("the photo points coincide")
    a = np.sum((zg - zgm) * np.conj(zp - zpm)) / den
    b = zgm - a * zpm
    Zo = float(G[:, 2].mean() + abs(a) * interior.focal_mm)
    return ExteriorOrientation(b.real, b.imag, Zo, 0.0, 0.0, float(np.angle(a)))


def dlt_approximation(ground, photo_mm, interior: InteriorOrientation) -> ExteriorOrientation:
    """Approximate exterior orientation by the DLT (six or more non-coplanar points).

    Raises
    ------
    DegenerateGeometryError
        Fewer than six points, or (nearly) coplanar ones.
    """
    G, p = _check(ground, photo_mm)
    n = len(G)
    if n < 6:
        raise DegenerateGeometryError(f"the DLT needs at least 6 points, got {n}")
    gm = G.mean(axis=0)
    gs = float(np.sqrt(((G - gm) ** 2).sum(axis=1).mean()))
    pm = p.mean(axis=0)
    ps = float(np.sqrt(((p - pm) ** 2).sum(axis=1).mean()))
    if not (gs > 0 and ps > 0):
        raise DegenerateGeometryError("the DLT points coincide")
    sv = np.linalg.svd((G - gm) / gs, compute_uv=False)
    if sv[-1] < 0.02 * sv[0]:
        raise DegenerateGeometryError("the DLT needs control points that are not coplanar")
    Gn = np.hstack([(G - gm) / gs, np.ones((n, 1))])
    pn = (p - pm) / ps
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = Gn
    A[0::2, 8:12] = -pn[:, :1] * Gn
    A[1::2, 4:8] = Gn
    A[1::2, 8:12] = -pn[:, 1:] * Gn
    _, s, Vt = np.linalg.svd(A)
    if s[-2] < 1e-10 * s[0]:
        raise DegenerateGeometryError("the DLT is not determined by these points")
    Pn = Vt[-1].reshape(3, 4)
    Tg = np.eye(4)
    Tg[:3, :3] /= gs
    Tg[:3, 3] = -gm / gs
    Ti = np.array([[ps, 0, pm[0]], [0, ps, pm[1]], [0, 0, 1.0]])
    P = Ti @ Pn @ Tg
    _, _, Vp = np.linalg.svd(P)
    C = Vp[-1]
    if abs(C[3]) < 1e-12 * np.abs(C[:3]).max():
        raise DegenerateGeometryError("the DLT puts the projection centre at infinity")
    C = C[:3] / C[3]
    c = interior.focal_mm
    K = np.array([[-c, 0, interior.x0_mm], [0, -c, interior.y0_mm], [0, 0, 1.0]])
    Am = np.linalg.solve(K, P[:, :3])
    mu = np.cbrt(np.linalg.det(Am))
    if not mu != 0:
        raise DegenerateGeometryError("the DLT matrix is singular")
    R = nearest_rotation((Am / mu).T)
    w, ph, k = angles_from_matrix(R)
    return ExteriorOrientation(C[0], C[1], C[2], w, ph, k)


def resect(
    ground,
    photo_mm,
    interior: InteriorOrientation,
    *,
    approx: ExteriorOrientation | None = None,
    sigma_mm: float | None = None,
    max_iter: int = 50,
) -> ResectionResult:
    """Space resection from at least three control points.

    Parameters
    ----------
    ground : array_like, shape (n, 3)
        Control points, metres.
    photo_mm : array_like, shape (n, 2)
        Their measured photo coordinates, millimetres.
    interior : InteriorOrientation
        Frame imagery only.
    approx : ExteriorOrientation, optional
        Start values; default DLT or similarity (see the module docstring).
    sigma_mm : float, optional
        A priori standard deviation of a photo coordinate; if given it scales
        the covariance, else ``sigma0`` does.

    Raises
    ------
    DegenerateGeometryError
        Fewer than three points, collinear control, or an undetermined
        parameter.
    ConvergenceError
        No convergence from the start values.
    OrientationError
        The solution puts control points behind the camera (depth ``q_z >=
        0``, see :func:`~apygis.orient.collinearity.depth`): the collinearity
        equations are satisfied by a camera looking away from the points,
        e.g. when x and y of the photo coordinates are swapped (a mirrored
        photo); the message says how many.

    Examples
    --------
    >>> from apygis.orient.collinearity import ground_to_photo
    >>> io = InteriorOrientation(153.0)
    >>> eo = ExteriorOrientation(1000.0, 2000.0, 2800.0, 0.01, -0.02, 0.3)
    >>> G = np.array([[0, 1000, 400], [2000, 1100, 450], [1100, 3000, 500], [900, 2100, 420.0]])
    >>> r = resect(G, ground_to_photo(G, eo, io), io)
    >>> bool(np.allclose(r.exterior.parameters, eo.parameters))
    True
    """
    G, p = _check(ground, photo_mm)
    if interior.scanned:
        raise OrientationError("space resection needs frame imagery, not scanned imagery")
    n = len(G)
    if n < 3:
        raise DegenerateGeometryError(f"space resection needs at least 3 control points, got {n}")
    Gc = G - G.mean(axis=0)
    sv = np.linalg.svd(Gc, compute_uv=False)
    if sv[1] < 1e-9 * max(sv[0], 1e-300):
        raise DegenerateGeometryError("space resection needs control points that are not collinear")
    if approx is None:
        approx = None
        if n >= 6:
            try:
                approx = dlt_approximation(G, p, interior)
            except DegenerateGeometryError:
                approx = None
        if approx is None:
            approx = similarity_approximation(G, p, interior)

    def fun(x):
        eo = ExteriorOrientation.from_parameters(x)
        m, J, _ = collinearity_jacobian(G, eo, interior)
        return (m - p).reshape(-1), J.reshape(-1, 6)

    sol = gauss_newton(
        fun, approx.parameters, EO_PARAMETERS, what="space resection", max_iter=max_iter
    )
    x = sol.x.copy()
    for k in range(3, 6):
        x[k] = math.remainder(x[k], 2 * math.pi)
    eo = ExteriorOrientation.from_parameters(x)
    behind = int(np.count_nonzero(~(depth(G, eo, interior) < 0.0)))
    if behind:
        raise OrientationError(
            f"space resection: {behind} of {n} control points lie behind the camera in the "
            "solution (the camera looks down its -z axis, apygis.orient.rotation); a photo "
            "cannot show them: are x and y of the photo coordinates swapped, or a sign reversed?"
        )
    res = sol.f.reshape(-1, 2)
    sigma = float(sigma_mm) if sigma_mm is not None else sol.sigma0
    r = sol.redundancy
    return ResectionResult(
        exterior=eo,
        residuals_mm=res,
        rmse_mm=float(np.sqrt((res**2).sum(axis=1).mean())) if r > 0 else math.nan,
        sigma0_mm=sol.sigma0,
        covariance=sigma**2 * sol.cofactor,
        redundancy=sol.redundancy,
        iterations=sol.iterations,
    )
