"""Absolute orientation: the seven-parameter 3-D similarity from model to ground.

Conventions: the rotation is an omega-phi-kappa matrix of
:mod:`apygis.orient.rotation` (here rotating model axes into ground axes).
The transformation is::

    G = t + scale * R(omega, phi, kappa) @ m

with ``m`` model coordinates (model units), ``G`` ground coordinates
(metres), ``t = (tx, ty, tz)`` metres and ``scale`` metres per model unit.

Estimation:

1. closed form (Horn 1987 / Umeyama 1991) from the points with all three
   ground coordinates: centroids, the SVD of the cross-covariance
   ``H = sum (G - Gm)(m - mm)^T = U S V^T``, ``R = U diag(1, 1, det(U V^T)) V^T``,
   ``scale = trace(S D) / sum |m - mm|**2``, ``t = Gm - scale R mm``;
2. Gauss-Newton least squares over every known ground coordinate: a control
   point may give ``X, Y`` only (planimetric) or ``Z`` only (height point) by
   putting nan for the unknown ones. Model coordinates are treated as exact.
   The unknowns are solved about the centroids, for conditioning; the
   covariance is reported for ``(tx, ty, tz, scale, omega, phi, kappa)``.

Residuals are ``computed - control`` per point and coordinate (nan where the
coordinate is not control).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from apygis.errors import DegenerateGeometryError, MeasurementError, OrientationError
from apygis.orient._fields import finite_fields
from apygis.orient.lsq import gauss_newton
from apygis.orient.rotation import angles_from_matrix, rotation_derivatives, rotation_matrix

__all__ = [
    "SIMILARITY_PARAMETERS",
    "AbsoluteOrientationResult",
    "Similarity3D",
    "absolute_orientation",
    "similarity_closed_form",
]

#: The seven parameters, in the order of the covariance.
SIMILARITY_PARAMETERS = ("tx", "ty", "tz", "scale", "omega", "phi", "kappa")


@dataclass(frozen=True)
class Similarity3D:
    """``G = t + scale * R(omega, phi, kappa) @ m`` (immutable)."""

    tx: float
    ty: float
    tz: float
    scale: float
    omega_rad: float
    phi_rad: float
    kappa_rad: float

    def __post_init__(self):
        keys = [
            n if n in ("tx", "ty", "tz", "scale") else n + "_rad" for n in SIMILARITY_PARAMETERS
        ]
        finite_fields(self, keys, prefix="similarity ")
        if self.scale <= 0:
            raise OrientationError("similarity scale must be positive")

    @property
    def rotation(self) -> np.ndarray:
        return rotation_matrix(self.omega_rad, self.phi_rad, self.kappa_rad)

    @property
    def translation(self) -> np.ndarray:
        return np.array([self.tx, self.ty, self.tz])

    @property
    def parameters(self) -> np.ndarray:
        """``(tx, ty, tz, scale, omega_rad, phi_rad, kappa_rad)``."""
        return np.array(
            [self.tx, self.ty, self.tz, self.scale, self.omega_rad, self.phi_rad, self.kappa_rad]
        )

    def forward(self, model):
        """Model ``(..., 3)`` -> ground ``(..., 3)``."""
        m = np.asarray(model, dtype=float)
        return self.translation + self.scale * m @ self.rotation.T

    def inverse(self, ground):
        """Ground ``(..., 3)`` -> model ``(..., 3)``."""
        g = np.asarray(ground, dtype=float)
        return (g - self.translation) @ self.rotation / self.scale

    def to_dict(self) -> dict:
        return {
            "tx": self.tx,
            "ty": self.ty,
            "tz": self.tz,
            "scale": self.scale,
            "omega_rad": self.omega_rad,
            "phi_rad": self.phi_rad,
            "kappa_rad": self.kappa_rad,
        }

    @classmethod
    def from_dict(cls, d) -> Similarity3D:
        return cls(
            d["tx"], d["ty"], d["tz"], d["scale"], d["omega_rad"], d["phi_rad"], d["kappa_rad"]
        )


@dataclass(frozen=True, eq=False)
class AbsoluteOrientationResult:
    """Result of :func:`absolute_orientation`.

    Attributes
    ----------
    transform : Similarity3D
    ids : tuple of str
    residuals : numpy.ndarray, shape (n, 3)
        ``computed - control`` (metres; nan where not control).
    rmse_xy : float
        RMSE in position over the planimetric control, metres.
    rmse_z : float
        RMSE of the heights over the height control, metres.
    sigma0 : float
        ``sqrt(v^T v / (n_obs - 7))``.
    covariance : numpy.ndarray, shape (7, 7)
        Of ``(tx, ty, tz, scale, omega, phi, kappa)``.
    redundancy, iterations : int
    """

    transform: Similarity3D
    ids: tuple
    residuals: np.ndarray
    rmse_xy: float
    rmse_z: float
    sigma0: float
    covariance: np.ndarray
    redundancy: int
    iterations: int

    @property
    def std(self) -> dict:
        d = np.sqrt(np.diag(self.covariance))
        return dict(zip(SIMILARITY_PARAMETERS, (float(v) for v in d), strict=True))


def similarity_closed_form(model, ground) -> Similarity3D:
    """Closed-form 3-D similarity (Horn / Umeyama) from three or more full points.

    Raises
    ------
    DegenerateGeometryError
        Fewer than three points or collinear ones.

    Examples
    --------
    >>> m = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    >>> S = Similarity3D(100.0, 200.0, 300.0, 2.0, 0.1, -0.2, 0.3)
    >>> bool(np.allclose(similarity_closed_form(m, S.forward(m)).parameters, S.parameters))
    True
    """
    m = np.asarray(model, dtype=float)
    g = np.asarray(ground, dtype=float)
    if m.ndim != 2 or m.shape[1] != 3 or g.shape != m.shape:
        raise MeasurementError(f"model and ground must be (n, 3), got {m.shape} and {g.shape}")
    if len(m) < 3:
        raise DegenerateGeometryError(
            f"a 3-D similarity needs at least 3 full control points, got {len(m)}"
        )
    mm, gm = m.mean(axis=0), g.mean(axis=0)
    mc, gc = m - mm, g - gm
    sm = np.linalg.svd(mc, compute_uv=False)
    sg = np.linalg.svd(gc, compute_uv=False)
    if sm[1] < 1e-9 * max(sm[0], 1e-300) or sg[1] < 1e-9 * max(sg[0], 1e-300):
        raise DegenerateGeometryError(
            "a 3-D similarity needs control points that are not collinear"
        )
    H = gc.T @ mc
    U, S, Vt = np.linalg.svd(H)
    d = 1.0 if np.linalg.det(U @ Vt) >= 0 else -1.0
    D = np.diag([1.0, 1.0, d])
    R = U @ D @ Vt
    scale = float(np.trace(np.diag(S) @ D) / (mc * mc).sum())
    t = gm - scale * R @ mm
    w, p, k = angles_from_matrix(R)
    return Similarity3D(t[0], t[1], t[2], scale, w, p, k)


def absolute_orientation(
    model,
    ground,
    *,
    ids: Iterable | None = None,
    reject: Iterable = (),
    max_iter: int = 50,
) -> AbsoluteOrientationResult:
    """Absolute orientation: closed form, then least squares with partial control.

    Parameters
    ----------
    model : array_like, shape (n, 3)
        Model coordinates of the control points.
    ground : array_like, shape (n, 3)
        Ground coordinates, metres; nan for a coordinate that is not control.
    ids : iterable of str, optional
    reject : iterable of str
        Ids to leave out.

    Raises
    ------
    DegenerateGeometryError
        Fewer than three full (X, Y, Z) points, collinear points, or fewer
        than seven known coordinates.
    """
    m = np.asarray(model, dtype=float)
    g = np.asarray(ground, dtype=float)
    if m.ndim != 2 or m.shape[1] != 3 or g.shape != m.shape:
        raise MeasurementError(f"model and ground must be (n, 3), got {m.shape} and {g.shape}")
    ids = (
        tuple(str(i) for i in ids) if ids is not None else tuple(str(k + 1) for k in range(len(m)))
    )
    if len(ids) != len(m):
        raise MeasurementError(f"{len(ids)} ids for {len(m)} points")
    reject = tuple(str(r) for r in reject)
    unknown = [r for r in reject if r not in ids]
    if unknown:
        raise MeasurementError(f"cannot reject {', '.join(unknown)}: not a control point")
    keep = np.array([i not in reject for i in ids], dtype=bool)
    m, g = m[keep], g[keep]
    ids = tuple(i for i, k in zip(ids, keep, strict=True) if k)
    if not np.all(np.isfinite(m)):
        raise MeasurementError("model coordinates must be finite")
    known = np.isfinite(g)
    full = known.all(axis=1)
    start = similarity_closed_form(m[full], g[full])
    if known.sum() < 7:
        raise DegenerateGeometryError(
            f"absolute orientation needs at least 7 control coordinates, got {int(known.sum())}"
        )
    mm = m[full].mean(axis=0)
    gm = g[full].mean(axis=0)
    mc = m - mm
    gc = np.where(known, g - gm, 0.0)
    R0 = start.rotation
    tprime0 = start.translation + start.scale * R0 @ mm - gm

    def fun(x):
        R = rotation_matrix(x[4], x[5], x[6])
        dRs = rotation_derivatives(x[4], x[5], x[6])
        Rm = mc @ R.T
        pred = x[:3] + x[3] * Rm
        f = (pred - gc)[known]
        J = np.zeros((len(m), 3, 7))
        J[:, :, 0:3] = np.eye(3)
        J[:, :, 3] = Rm
        for j, dR in enumerate(dRs):
            J[:, :, 4 + j] = x[3] * mc @ dR.T
        return f, J[known]

    x0 = np.concatenate([tprime0, [start.scale, start.omega_rad, start.phi_rad, start.kappa_rad]])
    sol = gauss_newton(
        fun, x0, SIMILARITY_PARAMETERS, what="absolute orientation", max_iter=max_iter
    )
    x = sol.x
    R = rotation_matrix(x[4], x[5], x[6])
    t = x[:3] + gm - x[3] * R @ mm
    w, p, k = angles_from_matrix(R)
    S = Similarity3D(t[0], t[1], t[2], x[3], w, p, k)
    # covariance of (t, scale, angles) from that of (t', scale, angles)
    T = np.eye(7)
    T[:3, 3] = -R @ mm
    for j, dR in enumerate(rotation_derivatives(x[4], x[5], x[6])):
        T[:3, 4 + j] = -x[3] * dR @ mm
    sigma0 = sol.sigma0
    cov = sigma0**2 * T @ sol.cofactor @ T.T if sol.redundancy > 0 else np.full((7, 7), math.nan)
    res = np.where(known, S.forward(m) - g, np.nan)
    kxy = known[:, 0] & known[:, 1]
    rmse_xy = float(np.sqrt((res[kxy, :2] ** 2).sum(axis=1).mean())) if kxy.any() else math.nan
    rmse_z = float(np.sqrt(np.mean(res[known[:, 2], 2] ** 2))) if known[:, 2].any() else math.nan
    return AbsoluteOrientationResult(
        S, ids, res, rmse_xy, rmse_z, sigma0, cov, sol.redundancy, sol.iterations
    )
