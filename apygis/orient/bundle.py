"""Bundle block adjustment: collinearity for many photos and points at once.

Conventions: :mod:`apygis.orient.rotation` (omega-phi-kappa, image at
``z = -c``, ground metres, photo millimetres, radians).

Observations and the model
--------------------------
An image observation ``o`` of point ``j`` in image ``i`` (camera ``k``) gives
measured photo coordinates ``(x, y)`` (millimetres, through the image's
interior orientation, already corrected for any distortion known from the
camera's calibration) with standard deviations ``(s_x, s_y)``. With
``q = R_i.T (X_j - C_i)``, the collinearity equations give the projection::

    x_p = x0_k - c_k q_x / q_z          y_p = y0_k - c_k q_y / q_z

Self-calibration (optional, per camera) adds the additional parameters of
the photo coordinates, evaluated at the **measured** point in coordinates
reduced to the principal point and normalised by the camera's radius
``r0`` (half the format diagonal): ``u = (x - x0) / r0``, ``v = (y - y0) / r0``,
``rho^2 = u^2 + v^2``, ``K = k1 rho^2 + k2 rho^4 + k3 rho^6``::

    dx = r0 (u K + p1 (rho^2 + 2 u^2) + 2 p2 u v + b1 u + b2 v)
    dy = r0 (v K + p2 (rho^2 + 2 v^2) + 2 p1 u v)

(Brown's radial ``k1..k3`` and decentring ``p1, p2`` distortion, and the
in-plane affinity ``b1`` (scale difference of x and y) and shear ``b2`` of a
film's image deformation; all dimensionless, so that ``r0 k1`` is the radial
displacement at ``r0`` in millimetres). The corrected measurement
``(x + dx, y + dy)`` obeys the collinearity equations, so the residual of one
observation is::

    f_o = ((x_p - x - dx) / s_x, (y_p - y - dy) / s_y)        (dimensionless)

Control points add ``(X_j - X_ctrl) / s_X`` (and Y, Z; a coordinate with an
infinite sigma is free: check points and planimetric or height control),
projection-centre observations (GPS) ``(C_i - C_gps) / s_C``. The adjustment
minimises ``sum f^2`` (Gauss-Newton with Levenberg-Marquardt damping), so
``sigma0 = sqrt(f.f / r)`` (``r`` the redundancy) is 1 when the a priori
standard deviations are right.

The normal equations and the Schur complement
---------------------------------------------
The unknowns are the six orientation elements of each image and the free
calibration parameters (together the "global" unknowns ``g``), and three
coordinates per point ``p``. The normal equations::

    [N_gg   W  ] [dg]   [b_g]
    [W.T    V  ] [dp] = [b_p]

have a block-diagonal ``V`` (one 3 x 3 block per point), so the points are
eliminated: ``S dg = b_g - W V^-1 b_p`` with the reduced matrix
``S = N_gg - W V^-1 W.T`` (sparse: images are coupled only through common
points), factorised by a sparse LU in symmetric mode (minimum-degree
ordering; a Cholesky factorisation without pivoting) after symmetric
Jacobi scaling; then ``dp = V^-1 (b_p - W.T dg)`` point by point.

Precision
---------
``Q_gg = S^-1`` (dense inverse up to :data:`DENSE_COVARIANCE_MAX` unknowns,
else by sparse solves in chunks keeping only the blocks needed); point
cofactors ``Q_pp,j = V_j^-1 + Y_j Q_gg Y_j.T`` with ``Y_j = V_j^-1 W_j.T``.
Covariances are ``sigma0^2 Q`` (the a posteriori variance factor). The
redundancy number of each image observation (the diagonal of
``I - A Q A.T`` for its two rows, exact, including the uncertainty of the
orientations) gives the standardised residual ``w = f / (sigma0 sqrt(r))``
of data snooping (Baarda's w-test with Pope's a posteriori ``sigma0``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from apygis.errors import ConvergenceError, DegenerateGeometryError, OrientationError
from apygis.orient.rotation import rotation_derivatives, rotation_matrix

__all__ = [
    "CALIBRATION_PARAMETERS",
    "DENSE_COVARIANCE_MAX",
    "SNOOPING_THRESHOLD",
    "BundleProblem",
    "BundleSolution",
    "Rejection",
    "adjust",
    "intersect_rays",
    "project",
    "robust_adjust",
]

#: The calibration parameters of a camera, in this order (see the module docstring).
CALIBRATION_PARAMETERS = ("c", "x0", "y0", "k1", "k2", "k3", "p1", "p2", "b1", "b2")
_NCAL = len(CALIBRATION_PARAMETERS)

#: Up to this many global unknowns the cofactor matrix ``S^-1`` is formed densely.
DENSE_COVARIANCE_MAX = 12000


@dataclass
class BundleProblem:
    """A bundle adjustment problem (arrays; see the module docstring).

    Cameras (``K``): ``calibration`` ``(K, 10)`` initial values in the order of
    :data:`CALIBRATION_PARAMETERS` (``c``, ``x0``, ``y0`` in mm, the rest
    dimensionless), ``radius_mm`` ``(K,)`` the normalising radius ``r0``,
    ``free`` ``(K, 10)`` bool: the parameters to estimate (self-calibration),
    ``calibration_sigma`` ``(K, 10)`` optional prior standard deviations of the
    free parameters (inf: no prior).

    Images (``M``): ``camera`` ``(M,)`` index into the cameras, ``eo`` ``(M, 6)``
    approximate ``(Xo, Yo, Zo, omega, phi, kappa)`` (m, rad).

    Points (``P``): ``xyz`` ``(P, 3)`` approximate coordinates (m).

    Image observations (``N``): ``obs_image``, ``obs_point`` ``(N,)``,
    ``obs_xy`` ``(N, 2)`` photo mm, ``obs_sigma`` ``(N, 2)`` mm.

    Control (``C``): ``ctrl_point`` ``(C,)``, ``ctrl_xyz`` ``(C, 3)``,
    ``ctrl_sigma`` ``(C, 3)`` m (inf: that coordinate is not observed).
    Centres (``G``): ``gps_image`` ``(G,)``, ``gps_xyz`` ``(G, 3)``,
    ``gps_sigma`` ``(G, 3)`` m.
    """

    calibration: np.ndarray
    radius_mm: np.ndarray
    camera: np.ndarray
    eo: np.ndarray
    xyz: np.ndarray
    obs_image: np.ndarray
    obs_point: np.ndarray
    obs_xy: np.ndarray
    obs_sigma: np.ndarray
    # (K, 10) after construction; None: all fixed, no priors
    free: Any = None
    calibration_sigma: Any = None
    ctrl_point: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    ctrl_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    ctrl_sigma: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    gps_image: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    gps_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    gps_sigma: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __post_init__(self):
        f = np.asarray
        self.calibration = f(self.calibration, float).reshape(-1, _NCAL).copy()
        K = len(self.calibration)
        self.radius_mm = f(self.radius_mm, float).reshape(K)
        self.free = (
            np.zeros((K, _NCAL), bool)
            if self.free is None
            else f(self.free, bool).reshape(K, _NCAL)
        )
        self.calibration_sigma = (
            np.full((K, _NCAL), np.inf)
            if self.calibration_sigma is None
            else f(self.calibration_sigma, float).reshape(K, _NCAL)
        )
        self.camera = f(self.camera, np.int64).ravel()
        self.eo = f(self.eo, float).reshape(-1, 6).copy()
        self.xyz = f(self.xyz, float).reshape(-1, 3).copy()
        self.obs_image = f(self.obs_image, np.int64).ravel()
        self.obs_point = f(self.obs_point, np.int64).ravel()
        N = len(self.obs_image)
        self.obs_xy = f(self.obs_xy, float).reshape(N, 2)
        sig = f(self.obs_sigma, float)
        sig = sig.reshape(N, -1) if sig.size in (N, 2 * N) else sig.reshape(-1)
        self.obs_sigma = np.broadcast_to(sig, (N, 2)).copy()
        self.ctrl_point = f(self.ctrl_point, np.int64).ravel()
        C = len(self.ctrl_point)
        self.ctrl_xyz = f(self.ctrl_xyz, float).reshape(C, 3)
        self.ctrl_sigma = f(self.ctrl_sigma, float).reshape(C, 3)
        self.gps_image = f(self.gps_image, np.int64).ravel()
        G = len(self.gps_image)
        self.gps_xyz = f(self.gps_xyz, float).reshape(G, 3)
        self.gps_sigma = f(self.gps_sigma, float).reshape(G, 3)
        self._check()

    @property
    def n_images(self) -> int:
        return len(self.eo)

    @property
    def n_points(self) -> int:
        return len(self.xyz)

    def _check(self) -> None:
        M, P, K = len(self.eo), len(self.xyz), len(self.calibration)
        if len(self.camera) != M:
            raise OrientationError(f"bundle: {len(self.camera)} camera indices for {M} images")
        for name, idx, n in (
            ("camera", self.camera, K),
            ("obs_image", self.obs_image, M),
            ("obs_point", self.obs_point, P),
            ("ctrl_point", self.ctrl_point, P),
            ("gps_image", self.gps_image, M),
        ):
            if len(idx) and (idx.min() < 0 or idx.max() >= n):
                raise OrientationError(f"bundle: {name} out of range 0..{n - 1}")
        for name in ("calibration", "eo", "xyz", "obs_xy", "ctrl_xyz", "gps_xyz"):
            if not np.isfinite(getattr(self, name)).all():
                raise OrientationError(f"bundle: {name} holds values that are not finite")
        for name in ("obs_sigma", "ctrl_sigma", "gps_sigma", "calibration_sigma"):
            s = getattr(self, name)
            if np.isnan(s).any() or (s <= 0).any():
                raise OrientationError(f"bundle: {name} must be positive (inf: not observed)")
        if not np.isfinite(self.obs_sigma).all():
            raise OrientationError("bundle: obs_sigma must be finite")
        if (self.calibration[:, 0] <= 0).any() or (self.radius_mm <= 0).any():
            raise OrientationError("bundle: principal distances and radii must be positive")
        key = self.obs_image * max(P, 1) + self.obs_point
        if len(np.unique(key)) != len(key):
            raise OrientationError("bundle: a point is observed twice in one image")


@dataclass(eq=False)
class BundleSolution:
    """The result of :func:`adjust` (arrays in the problem's order).

    ``eo`` ``(M, 6)``, ``xyz`` ``(P, 3)``, ``calibration`` ``(K, 10)``;
    ``residuals`` ``(N, 2)`` photo mm (``projection - corrected measurement``;
    for an observation with weight 0 its discrepancy); ``w`` ``(N, 2)``
    standardised residuals per coordinate, ``w_obs`` ``(N,)`` the test of each
    observation's two coordinates together as a normal deviate
    (``test_stat / sigma0^2`` with ``test_df`` degrees of freedom,
    :func:`normal_deviate`), ``redundancy`` ``(N, 2)`` redundancy numbers;
    ``sigma0`` the a posteriori standard deviation of unit weight (1 when the
    a priori sigmas are right);
    ``eo_std`` ``(M, 6)``, ``xyz_cov`` ``(P, 3, 3)``, ``calibration_std``
    ``(K, 10)`` (NaN where fixed), ``calibration_corr`` the correlation matrix
    of the free calibration parameters (rows ``calibration_names``) and
    ``calibration_eo_corr`` their largest absolute correlation with any
    orientation element. ``ctrl_residuals`` ``(C, 3)`` ``X - X_ctrl``.
    ``obs_sigma`` the a priori sigmas used (mm; scaled by variance components
    in :func:`robust_adjust`), ``variance_factors`` those components by group.
    """

    eo: np.ndarray
    xyz: np.ndarray
    calibration: np.ndarray
    residuals: np.ndarray
    w: np.ndarray
    w_obs: np.ndarray
    test_stat: np.ndarray
    test_df: np.ndarray
    redundancy: np.ndarray
    sigma0: float
    dof: int
    iterations: int
    eo_std: np.ndarray
    xyz_cov: np.ndarray
    calibration_std: np.ndarray
    calibration_names: list[tuple[int, str]]
    calibration_corr: np.ndarray
    calibration_eo_corr: np.ndarray
    ctrl_residuals: np.ndarray
    gps_residuals: np.ndarray
    obs_sigma: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    variance_factors: dict[int, float] = field(default_factory=dict)

    @functools.cached_property
    def xyz_std(self) -> np.ndarray:
        """Standard deviations of the point coordinates, ``(P, 3)`` metres."""
        return np.sqrt(np.maximum(np.einsum("nii->ni", self.xyz_cov), 0.0))


def project(problem: BundleProblem, eo=None, xyz=None, calibration=None):
    """Projections of every observation: ``(x_p, y_p)`` ``(N, 2)`` mm and ``q_z`` ``(N,)``."""
    eo = problem.eo if eo is None else eo
    xyz = problem.xyz if xyz is None else xyz
    cal = problem.calibration if calibration is None else calibration
    i, j = problem.obs_image, problem.obs_point
    R = rotation_matrix(eo[:, 3], eo[:, 4], eo[:, 5])
    d = xyz[j] - eo[i, :3]
    q = np.einsum("nk,nkl->nl", d, R[i])
    k = problem.camera[i]
    out = np.empty((len(i), 2))
    out[:, 0] = cal[k, 1] - cal[k, 0] * q[:, 0] / q[:, 2]
    out[:, 1] = cal[k, 2] - cal[k, 0] * q[:, 1] / q[:, 2]
    return out, q[:, 2]


def intersect_rays(centres, directions, point, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares intersection of rays, many points at once.

    Ray ``r`` starts at ``centres[r]`` with direction ``directions[r]`` and
    belongs to point ``point[r]``. Each point minimises the sum of squared
    perpendicular distances to its rays: ``sum_r (I - d_r d_r.T) (X - C_r) = 0``
    with unit ``d_r``. Returns ``(xyz (n_points, 3), ok (n_points,))``: ``ok``
    is False for points with fewer than two rays or rays too close to
    parallel (condition of the 3 x 3 system above 1e10).
    """
    C = np.asarray(centres, float)
    d = np.asarray(directions, float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    A = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    b = np.einsum("rij,rj->ri", A, C)
    AA = np.zeros((n_points, 3, 3))
    bb = np.zeros((n_points, 3))
    np.add.at(AA, point, A)
    np.add.at(bb, point, b)
    count = np.bincount(point, minlength=n_points)
    ok = count >= 2
    ev = np.linalg.eigvalsh(AA)
    ok &= ev[:, 0] > 1e-10 * np.maximum(ev[:, 2], 1e-300)
    xyz = np.zeros((n_points, 3))
    if ok.any():
        xyz[ok] = np.linalg.solve(AA[ok], bb[ok][:, :, None])[:, :, 0]
    return xyz, ok


# --- the linearised model --------------------------------------------------------------


def _additional(cal, radius, k, xy):
    """``(dx, dy)`` and their derivatives by ``(u, v)`` and the ten parameters."""
    r0 = radius[k]
    u = (xy[:, 0] - cal[k, 1]) / r0
    v = (xy[:, 1] - cal[k, 2]) / r0
    k1, k2, k3, p1, p2, b1, b2 = (cal[k, c] for c in range(3, 10))
    r2 = u * u + v * v
    K = k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    dK = k1 + 2 * k2 * r2 + 3 * k3 * r2 * r2  # dK/d(r2)
    dx = r0 * (u * K + p1 * (r2 + 2 * u * u) + 2 * p2 * u * v + b1 * u + b2 * v)
    dy = r0 * (v * K + p2 * (r2 + 2 * v * v) + 2 * p1 * u * v)
    # derivatives of (dx, dy) / r0 by u and v
    dxu = K + u * dK * 2 * u + 6 * p1 * u + 2 * p2 * v + b1
    dxv = u * dK * 2 * v + 2 * p1 * v + 2 * p2 * u + b2
    dyu = v * dK * 2 * u + 2 * p2 * u + 2 * p1 * v
    dyv = K + v * dK * 2 * v + 6 * p2 * v + 2 * p1 * u
    # derivatives by k1, k2, k3, p1, p2, b1, b2 (mm)
    n = len(u)
    P = np.empty((n, 2, 7))
    P[:, 0, 0], P[:, 1, 0] = u * r2, v * r2
    P[:, 0, 1], P[:, 1, 1] = u * r2 * r2, v * r2 * r2
    P[:, 0, 2], P[:, 1, 2] = u * r2**3, v * r2**3
    P[:, 0, 3], P[:, 1, 3] = r2 + 2 * u * u, 2 * u * v
    P[:, 0, 4], P[:, 1, 4] = 2 * u * v, r2 + 2 * v * v
    P[:, 0, 5], P[:, 1, 5] = u, 0.0
    P[:, 0, 6], P[:, 1, 6] = v, 0.0
    P *= r0[:, None, None]
    return dx, dy, (dxu, dxv, dyu, dyv), P


def _linearise(pb: BundleProblem, eo, xyz, cal, with_jacobian: bool = True):
    """Weighted residuals ``f (N, 2)`` and Jacobians by EO ``(N,2,6)``, point ``(N,2,3)``
    and calibration ``(N,2,10)``; ``qz (N,)``."""
    i, j = pb.obs_image, pb.obs_point
    k = pb.camera[i]
    R = rotation_matrix(eo[:, 3], eo[:, 4], eo[:, 5])
    Ri = R[i]
    d = xyz[j] - eo[i, :3]
    q = np.einsum("nk,nkl->nl", d, Ri)
    c = cal[k, 0]
    inv = 1.0 / q[:, 2]
    xy = pb.obs_xy
    dx, dy, dd, P = _additional(cal, pb.radius_mm, k, xy)
    s = pb.obs_sigma
    f = np.empty((len(i), 2))
    f[:, 0] = (cal[k, 1] - c * q[:, 0] * inv - xy[:, 0] - dx) / s[:, 0]
    f[:, 1] = (cal[k, 2] - c * q[:, 1] * inv - xy[:, 1] - dy) / s[:, 1]
    if not with_jacobian:
        return f, None, None, None, q[:, 2]
    Dq = np.zeros((len(i), 2, 3))
    Dq[:, 0, 0] = -c * inv
    Dq[:, 0, 2] = c * q[:, 0] * inv * inv
    Dq[:, 1, 1] = -c * inv
    Dq[:, 1, 2] = c * q[:, 1] * inv * inv
    Jp = np.einsum("nab,ncb->nac", Dq, Ri)  # Dq @ R.T
    Je = np.empty((len(i), 2, 6))
    Je[:, :, :3] = -Jp
    dRs = rotation_derivatives(eo[:, 3], eo[:, 4], eo[:, 5])
    for a, dR in enumerate(dRs):
        dq = np.einsum("nk,nkl->nl", d, dR[i])
        Je[:, :, 3 + a] = np.einsum("nij,nj->ni", Dq, dq)
    Jc = np.zeros((len(i), 2, _NCAL))
    Jc[:, 0, 0] = -q[:, 0] * inv
    Jc[:, 1, 0] = -q[:, 1] * inv
    # x0, y0: the projection moves with them, the reduced measurement against them
    Jc[:, 0, 1] = 1.0 + dd[0]
    Jc[:, 0, 2] = dd[1]
    Jc[:, 1, 1] = dd[2]
    Jc[:, 1, 2] = 1.0 + dd[3]
    Jc[:, :, 3:] = -P
    w = 1.0 / s
    Je *= w[:, :, None]
    Jp *= w[:, :, None]
    Jc *= w[:, :, None]
    return f, Je, Jp, Jc, q[:, 2]


# --- the normal equations, reduced --------------------------------------------------------


class _Layout:
    """Where the global unknowns are: 6 per image, then the free calibration parameters."""

    def __init__(self, pb: BundleProblem):
        M = pb.n_images
        self.M = M
        free = pb.free
        assert free is not None
        self.cal_index = np.full(free.shape, -1, np.int64)
        names = []
        n = 6 * M
        for kk, par in zip(*np.nonzero(free), strict=True):
            self.cal_index[kk, par] = n
            names.append((int(kk), CALIBRATION_PARAMETERS[par]))
            n += 1
        self.names = names
        self.G = n
        # per observation: its global columns (6 EO + the camera's free parameters, padded)
        self.ncal_max = int(free.sum(axis=1).max()) if len(free) else 0


def _obs_columns(pb: BundleProblem, lay: _Layout):
    """``cols (N, 6 + ncal_max)`` global columns of each observation (-1: padding) and
    ``sel (N, ncal_max)`` which calibration parameter each padded column is."""
    i = pb.obs_image
    k = pb.camera[i]
    N = len(i)
    nc = lay.ncal_max
    cols = np.full((N, 6 + nc), -1, np.int64)
    cols[:, :6] = 6 * i[:, None] + np.arange(6)
    sel = np.zeros((N, nc), np.int64)
    if nc:
        for kk in range(len(pb.calibration)):
            pars = np.nonzero(pb.free[kk])[0]
            rows = k == kk
            for slot, par in enumerate(pars):
                cols[rows, 6 + slot] = lay.cal_index[kk, par]
                sel[rows, slot] = par
    return cols, sel


@dataclass
class _Normals:
    S: object  # scipy sparse (G x G), reduced
    rhs: np.ndarray  # (G,)
    Vinv: np.ndarray  # (P, 3, 3)
    bp: np.ndarray  # (P, 3)
    W: object  # scipy sparse (G x 3P)
    Ngg_diag: np.ndarray
    V: np.ndarray


class _Structure:
    """Sparsity patterns of the normal equations, fixed for one adjustment.

    ``W`` (global x points) has, in each orientation row ``6 i + a``, three
    entries per observation of image ``i``; its CSR arrays are built once
    here and each iteration only gathers the data (``perm``). Rows of the
    calibration (few) are assembled per iteration.
    """

    def __init__(self, pb: BundleProblem, lay: _Layout):
        i, j = pb.obs_image, pb.obs_point
        N, M, P = len(i), lay.M, pb.n_points
        order = np.argsort(i, kind="stable")
        n_i = np.bincount(i, minlength=M)
        first = np.r_[0, np.cumsum(n_i)[:-1]]  # first sorted observation of each image
        rank = np.empty(N, np.int64)
        rank[order] = np.arange(N) - first[i[order]]
        row_len = np.repeat(3 * n_i, 6)
        self.indptr = np.r_[0, np.cumsum(row_len)].astype(np.int64)
        # position of entry (o, a, k): 18 * first[i] + a * 3 n_i + 3 rank + k
        a = np.arange(6)[None, :, None]
        k = np.arange(3)[None, None, :]
        pos = (18 * first[i])[:, None, None] + a * (3 * n_i[i])[:, None, None]
        pos = pos + (3 * rank)[:, None, None] + k
        self.perm = np.empty(18 * N, np.int64)
        flat = (np.arange(N)[:, None, None] * 18 + a * 3 + k).ravel()
        self.perm[pos.ravel()] = flat
        self.indices = np.empty(18 * N, np.int64)
        self.indices[pos.ravel()] = (3 * j[:, None, None] + k + 0 * a).ravel()
        self.shape_e = (6 * M, 3 * P)
        # block-diagonal patterns: 6 x 6 per image, 3 x 3 per point
        self.bd6 = _block_diagonal_pattern(M, 6)
        self.bd3 = _block_diagonal_pattern(P, 3)


def _block_diagonal_pattern(n: int, b: int):
    indptr = np.arange(0, n * b * b + 1, b, dtype=np.int64)
    indices = (b * np.arange(n)[:, None, None] + np.zeros((1, b, 1), np.int64)
               + np.arange(b)[None, None, :]).ravel()  # fmt: skip
    return indptr, indices


def _normals(pb, lay, st, cols, sel, f, Je, Jp, Jc, eo, xyz, cal, weight, damping: float):
    """Form and reduce the normal equations at the current values (module docstring)."""
    import scipy.sparse as sp

    P = pb.n_points
    M = lay.M
    G = lay.G
    i, j = pb.obs_image, pb.obs_point
    wgt = np.sqrt(weight)[:, None]
    fw = f * wgt
    Ae = Je * wgt[:, :, None]
    B = Jp * wgt[:, :, None]
    nc = cols.shape[1] - 6
    if nc:
        Ac = np.take_along_axis(Jc, sel[:, None, :].repeat(2, 1), 2) * wgt[:, :, None]
        padc = cols[:, 6:] < 0
        Ac[np.broadcast_to(padc[:, None, :], Ac.shape)] = 0.0
        # calibration index of each column (padding: 0, with zero data)
        colc = np.where(padc, 6 * M, cols[:, 6:]) - 6 * M
    # N_ee: block diagonal, one 6 x 6 block per image
    Nee = np.zeros((M, 6, 6))
    np.add.at(Nee, i, np.einsum("nai,naj->nij", Ae, Ae))
    be = np.zeros((M, 6))
    np.add.at(be, i, -np.einsum("nai,na->ni", Ae, fw))
    if len(pb.gps_image):
        wg = 1.0 / pb.gps_sigma**2
        rg = eo[pb.gps_image, :3] - pb.gps_xyz
        ax = np.arange(3)
        np.add.at(Nee, (pb.gps_image[:, None], ax, ax), wg)
        np.add.at(be, (pb.gps_image[:, None], ax), -(wg * rg))
    bg = np.zeros(G)
    bg[: 6 * M] = be.ravel()
    diag_cal = np.zeros(G - 6 * M)
    if nc:
        ncal = G - 6 * M
        Ncc = np.zeros((ncal, ncal))
        blk = np.einsum("nai,naj->nij", Ac, Ac)
        np.add.at(Ncc, (colc[:, :, None], colc[:, None, :]), blk)
        np.add.at(bg, 6 * M + colc[~padc], -np.einsum("nai,na->ni", Ac, fw)[~padc])
        # N_ce: calibration x orientation (per observation: nc x 6 into the image's columns)
        blk = np.einsum("nai,naj->nij", Ac, Ae)  # (N, nc, 6)
        rr = np.broadcast_to(colc[:, :, None], blk.shape)
        cc = np.broadcast_to((6 * i)[:, None, None] + np.arange(6), blk.shape)
        keep = np.broadcast_to(~padc[:, :, None], blk.shape)
        Nce = sp.coo_matrix((blk[keep], (rr[keep], cc[keep])), shape=(ncal, 6 * M)).tocsr()
        for kk, par in zip(*np.nonzero(pb.free), strict=True):
            sg = pb.calibration_sigma[kk, par]
            if np.isfinite(sg):
                g = lay.cal_index[kk, par]
                # prior: the parameter stays near its initial value
                diag_cal[g - 6 * M] += 1.0 / sg**2
                bg[g] -= (cal[kk, par] - pb.calibration[kk, par]) / sg**2
    # V (points)
    V = np.zeros((P, 3, 3))
    np.add.at(V, j, np.einsum("nai,naj->nij", B, B))
    bp = np.zeros((P, 3))
    np.add.at(bp, j, -np.einsum("nai,na->ni", B, fw))
    if len(pb.ctrl_point):
        wc = 1.0 / pb.ctrl_sigma**2  # inf sigma: weight 0
        rc = xyz[pb.ctrl_point] - pb.ctrl_xyz
        rc = np.where(wc > 0, rc, 0.0)
        ax = np.arange(3)
        np.add.at(V, (pb.ctrl_point[:, None], ax, ax), wc)
        np.add.at(bp, pb.ctrl_point, -wc * rc)
    if damping > 0:
        de = np.einsum("nii->ni", Nee)
        floor = 1e-12 * max(float(de.max()) if de.size else 1.0, 1.0)
        Nee = Nee + damping * np.eye(6)[None] * np.maximum(de, floor)[:, None, :]
        dv = np.einsum("nii->ni", V)
        V = V + damping * np.eye(3)[None] * dv[:, None, :]
    # points seen by no observation with weight: keep them where they are
    dv = np.einsum("nii->ni", V)
    dead = dv.max(axis=1) <= 0
    V[dead] = np.eye(3)
    bp[dead] = 0.0
    try:
        Vinv = np.linalg.inv(V)
    except np.linalg.LinAlgError:
        raise DegenerateGeometryError(
            "bundle: some points are not determined by their rays (singular 3 x 3 blocks)"
        ) from None
    # W and W V^-1 (same pattern), orientation rows
    Wblk = np.einsum("nai,naj->nij", Ae, B)  # (N, 6, 3)
    WVblk = np.einsum("nai,nij->naj", Wblk, Vinv[j])
    We = sp.csr_matrix((Wblk.ravel()[st.perm], st.indices, st.indptr), shape=st.shape_e)
    WVe = sp.csr_matrix((WVblk.ravel()[st.perm], st.indices, st.indptr), shape=st.shape_e)
    Ngg = sp.csr_matrix((Nee.ravel(), st.bd6[1], st.bd6[0]), shape=(6 * M, 6 * M))
    if nc:
        Wc_blk = np.einsum("nai,naj->nij", Ac, B)  # (N, nc, 3)
        WVc_blk = np.einsum("nai,nij->naj", Wc_blk, Vinv[j])
        rr = np.broadcast_to(colc[:, :, None], Wc_blk.shape)
        cc = np.broadcast_to((3 * j)[:, None, None] + np.arange(3), Wc_blk.shape)
        keep = np.broadcast_to(~padc[:, :, None], Wc_blk.shape)
        shape = (G - 6 * M, 3 * P)
        Wc = sp.coo_matrix((Wc_blk[keep], (rr[keep], cc[keep])), shape=shape).tocsr()
        WVc = sp.coo_matrix((WVc_blk[keep], (rr[keep], cc[keep])), shape=shape).tocsr()
        W = sp.vstack([We, Wc], format="csr")
        WV = sp.vstack([WVe, WVc], format="csr")
        Ncc = Ncc + np.diag(diag_cal)
        if damping > 0:
            Ncc = Ncc + damping * np.diag(np.maximum(np.diag(Ncc), 1e-300))
        Ngg = sp.bmat([[Ngg, Nce.T], [Nce, sp.csr_matrix(Ncc)]], format="csr")
    else:
        W, WV = We, WVe
    S = (Ngg - WV @ W.T).tocsr()
    rhs = bg - WV @ bp.ravel()
    Ngg_diag = Ngg.diagonal()
    return _Normals(S, rhs, Vinv, bp, W, Ngg_diag, V)


class _Factor:
    """A factorisation of the (scaled) reduced matrix ``S``."""

    def __init__(self, S):
        import scipy.sparse as sp
        import scipy.sparse.linalg as spl

        d = S.diagonal()
        if (d <= 0).any() or not np.isfinite(d).all():
            raise DegenerateGeometryError(
                f"bundle: {int((d <= 0).sum())} orientation or calibration unknowns have no "
                "observation (an image without tie points, a parameter nothing depends on)"
            )
        self.scale = 1.0 / np.sqrt(d)
        Dm = sp.diags(self.scale)
        Ss = (Dm @ S @ Dm).tocsr()
        # symmetric: the CSR arrays of S are the CSC arrays of S.T = S
        self.Ss = sp.csc_matrix((Ss.data, Ss.indices, Ss.indptr), shape=Ss.shape)
        self.n = S.shape[0]
        try:
            self.lu = spl.splu(
                self.Ss,
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        except RuntimeError as exc:  # exactly singular
            raise DegenerateGeometryError(
                "bundle: the block has no datum or a weak part (the reduced normal matrix is "
                f"singular: {exc}); give control points or projection centres, and check that "
                "every image is tied to the others"
            ) from None
        U = self.lu.U.diagonal()
        if (U <= 0).any() or U.min() < 1e-13 * U.max():
            raise DegenerateGeometryError(
                "bundle: the block has no datum or a weak part (the reduced normal matrix is "
                "not positive definite); give control points (at least three, not on a line) "
                "or projection centres, and check that every image is tied to the others"
            )

    def solve(self, b):
        return self.scale * self.lu.solve(self.scale * b)

    def inverse_lower(self) -> np.ndarray:
        """The lower triangle of the *scaled* ``S^-1`` (dense; the upper triangle holds
        rubbish): Cholesky factor and its inverse (LAPACK ``dpotrf``, ``dpotri``).
        ``S^-1[r, c] = L[max(r, c), min(r, c)] * scale[r] * scale[c]``."""
        import scipy.linalg as la

        A = self.Ss.toarray()
        c, info = la.lapack.dpotrf(A, lower=1, overwrite_a=1, clean=0)
        if info == 0:
            c, info = la.lapack.dpotri(c, lower=1, overwrite_c=1)
        if info != 0:
            raise DegenerateGeometryError("bundle: the reduced normal matrix is singular")
        return c

    def columns(self, cols: np.ndarray) -> np.ndarray:
        """Columns ``cols`` of ``S^-1``."""
        E = np.zeros((self.n, len(cols)))
        E[cols, np.arange(len(cols))] = 1.0
        return self.scale[:, None] * self.lu.solve(self.scale[:, None] * E)


# --- the adjustment ------------------------------------------------------------------------


def _cost(f, weight, pb, eo, xyz, cal) -> float:
    c = float(np.sum(weight[:, None] * f * f))
    if len(pb.ctrl_point):
        r = (xyz[pb.ctrl_point] - pb.ctrl_xyz) / pb.ctrl_sigma
        c += float(np.sum(np.where(np.isfinite(pb.ctrl_sigma), r, 0.0) ** 2))
    if len(pb.gps_image):
        c += float(np.sum(((eo[pb.gps_image, :3] - pb.gps_xyz) / pb.gps_sigma) ** 2))
    fin = np.isfinite(pb.calibration_sigma) & pb.free
    if fin.any():
        c += float(np.sum(((cal - pb.calibration)[fin] / pb.calibration_sigma[fin]) ** 2))
    return c


def _apply(pb, lay, eo, xyz, cal, dg, dp):
    M = lay.M
    eo2 = eo + dg[: 6 * M].reshape(M, 6)
    xyz2 = xyz + dp
    cal2 = cal.copy()
    if lay.names:
        kk, par = np.nonzero(pb.free)
        cal2[kk, par] += dg[lay.cal_index[kk, par]]
    return eo2, xyz2, cal2


def adjust(
    problem: BundleProblem,
    *,
    weight: np.ndarray | None = None,
    max_iter: int = 30,
    tol: float = 1.0,
    covariance: bool | str = True,
    progress=None,
) -> BundleSolution:
    """Adjust the bundle (module docstring): Gauss-Newton with Levenberg-Marquardt damping.

    ``weight`` ``(N,)`` multiplies each observation's weight (0 leaves it out:
    rejected observations; robust reweighting). Converged when the largest
    update is below ``tol`` times 0.01 mm (ground points, centres), 0.1 urad
    (angles) and 1e-7 (calibration), or the cost no longer falls and the
    update is below a thousand times that.
    ``covariance=False`` skips the precisions (and the redundancy numbers);
    ``covariance="approximate"`` computes the points' and the observations' as if
    the orientations were known (cheap; optimistic for the points, a little
    pessimistic for the redundancy numbers: what data snooping needs to find
    large errors), and no orientation precisions.
    ``progress(done, total)`` (:mod:`apygis.progress`) counts iterations
    (``total`` is ``max_iter``; the last call is ``(max_iter, max_iter)``).
    """
    pb = problem
    N = len(pb.obs_image)
    weight = np.ones(N) if weight is None else np.asarray(weight, float).copy()
    if weight.shape != (N,) or (weight < 0).any() or not np.isfinite(weight).all():
        raise OrientationError("bundle: weight must be N finite values >= 0")
    lay = _Layout(pb)
    st = _Structure(pb, lay)
    cols, sel = _obs_columns(pb, lay)
    eo, xyz, cal = pb.eo.copy(), pb.xyz.copy(), pb.calibration.copy()
    f, Je, Jp, Jc, qz = _linearise(pb, eo, xyz, cal)
    if (qz[weight > 0] >= 0).any():
        bad = int(np.sum(qz[weight > 0] >= 0))
        raise OrientationError(
            f"bundle: {bad} observations are of points behind their camera at the approximate "
            "values (check the approximate orientations)"
        )
    cost = _cost(f, weight, pb, eo, xyz, cal)
    lam = 1e-6
    it = 0
    converged = False
    for it in range(1, max_iter + 1):
        nm = _normals(pb, lay, st, cols, sel, f, Je, Jp, Jc, eo, xyz, cal, weight, lam)
        fac = _Factor(nm.S)
        dg = fac.solve(nm.rhs)
        dp = np.einsum("nij,nj->ni", nm.Vinv, nm.bp - (nm.W.T @ dg).reshape(-1, 3))
        eo2, xyz2, cal2 = _apply(pb, lay, eo, xyz, cal, dg, dp)
        f2, _, _, _, qz2 = _linearise(pb, eo2, xyz2, cal2, with_jacobian=False)
        cost2 = _cost(f2, weight, pb, eo2, xyz2, cal2) if np.isfinite(f2).all() else np.inf
        if progress is not None:
            progress(it, max_iter)
        step = _step_size(dg, dp, lay)
        if cost2 <= cost * (1 + 1e-12) and (qz2[weight > 0] < 0).all():
            eo, xyz, cal = eo2, xyz2, cal2
            small = step < tol
            relative_fall = (cost - cost2) / max(cost, 1e-300)
            cost = cost2
            f, Je, Jp, Jc, qz = _linearise(pb, eo, xyz, cal)
            lam = max(lam / 10.0, 1e-9)
            if small or (relative_fall < 1e-10 and step < 1e3 * tol):
                converged = True
                break
        else:
            lam *= 10.0
            if lam > 1e8:
                break
    if not converged:
        raise ConvergenceError(
            f"bundle: the adjustment did not converge in {it} iterations (cost {cost:.6g}); "
            "check the approximate values and look for gross errors"
        )
    if progress is not None:
        progress(max_iter, max_iter)
    return _solution(pb, lay, st, cols, sel, eo, xyz, cal, f, Je, Jp, Jc, weight, it, covariance)


def _step_size(dg, dp, lay) -> float:
    """The largest update in units of 0.01 mm (ground, centres), 0.1 urad (angles) and 1e-7
    (calibration): below 1, an update changes nothing that matters."""
    M = lay.M
    e = dg[: 6 * M].reshape(M, 6)
    s = 0.0
    if M:
        s = max(float(np.abs(e[:, :3]).max()) / 1e-5, float(np.abs(e[:, 3:]).max()) / 1e-7)
    if len(dp):
        s = max(s, float(np.abs(dp).max()) / 1e-5)
    if len(dg) > 6 * M:
        s = max(s, float(np.abs(dg[6 * M :]).max()) / 1e-7)
    return s


def _solution(pb, lay, st, cols, sel, eo, xyz, cal, f, Je, Jp, Jc, weight, it, covariance):
    N = len(f)
    K = len(cal)
    used = weight > 0
    n_obs = 2 * int(used.sum())
    n_obs += int(np.isfinite(pb.ctrl_sigma).sum()) + 3 * len(pb.gps_image)
    n_obs += int((np.isfinite(pb.calibration_sigma) & pb.free).sum())
    # unknowns: every image, every point observed with weight, the free calibration
    seen = np.zeros(pb.n_points, bool)
    seen[pb.obs_point[used]] = True
    ctrl_seen = np.zeros(pb.n_points, bool)
    ctrl_seen[pb.ctrl_point[np.isfinite(pb.ctrl_sigma).any(axis=1)]] = True
    n_unk = lay.G + 3 * int((seen | ctrl_seen).sum())
    dof = n_obs - n_unk
    cost = _cost(f, weight, pb, eo, xyz, cal)
    sigma0 = math.sqrt(cost / dof) if dof > 0 else float("nan")
    resid = f * pb.obs_sigma  # mm, projection - corrected measurement
    eo_std = np.full((lay.M, 6), np.nan)
    xyz_cov = np.full((pb.n_points, 3, 3), np.nan)
    cal_std = np.full((K, _NCAL), np.nan)
    names = lay.names
    ncal = len(names)
    corr = np.full((ncal, ncal), np.nan)
    eo_corr = np.full(ncal, np.nan)
    red = np.full((N, 2), np.nan)
    w = np.full((N, 2), np.nan)
    w_obs = np.full(N, np.nan)
    test_stat = np.full(N, np.nan)
    test_df = np.zeros(N, np.int64)
    if not covariance:
        # the damped iterations converge even without a datum: the undamped matrix must
        # be regular for the solution to mean anything
        nm = _normals(pb, lay, st, cols, sel, f, Je, Jp, Jc, eo, xyz, cal, weight, 0.0)
        _Factor(nm.S)
    elif covariance == "approximate":
        # the orientations taken as known: point cofactors V^-1, redundancy from the points
        nm = _normals(pb, lay, st, cols, sel, f, Je, Jp, Jc, eo, xyz, cal, weight, 0.0)
        _Factor(nm.S)  # as above: no solution without a datum
        s2 = sigma0**2 if dof > 0 else 1.0
        xyz_cov = nm.Vinv * s2
        B = Jp * np.sqrt(weight)[:, None, None]
        qvv = np.eye(2)[None] - np.einsum("nai,nij,nbj->nab", B, nm.Vinv[pb.obs_point], B)
        qvv[~used] = np.nan
        red = np.einsum("naa->na", qvv)
        test_stat, test_df = _observation_test(f * np.sqrt(weight)[:, None], qvv)
        w_obs = normal_deviate(test_stat / s2, test_df)
    elif covariance:
        nm = _normals(pb, lay, st, cols, sel, f, Je, Jp, Jc, eo, xyz, cal, weight, 0.0)
        fac = _Factor(nm.S)
        s2 = sigma0**2 if dof > 0 else 1.0
        look = _BlockLookup(fac)
        Qd = look.diag()
        eo_std = np.sqrt(np.maximum(Qd[: 6 * lay.M].reshape(lay.M, 6), 0.0) * s2)
        if ncal:
            cal_cols = np.arange(6 * lay.M, lay.G)
            Qc = look.gather(np.arange(lay.G)[:, None], cal_cols[None, :])  # (G, ncal)
            qcc = Qc[cal_cols]
            sd = np.sqrt(np.diag(qcc))
            corr = qcc / np.outer(sd, sd)
            if lay.M:
                eo_sd = np.sqrt(np.maximum(Qd[: 6 * lay.M], 1e-300))
                eo_corr = np.max(np.abs(Qc[: 6 * lay.M] / np.outer(eo_sd, sd)), axis=0)
            for (kk, par), sdv in zip(names, sd, strict=True):
                cal_std[kk, CALIBRATION_PARAMETERS.index(par)] = sdv * math.sqrt(s2)
        xyz_q, qvv = _point_cofactors(pb, nm, look, cols, sel, f, Je, Jp, Jc, weight)
        xyz_cov = xyz_q * s2
        red = np.einsum("naa->na", qvv)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(
                red > 1e-6,
                (f * np.sqrt(weight)[:, None]) / (sigma0 * np.sqrt(np.maximum(red, 1e-12))),
                0.0,
            )
        w[~used] = np.nan
        test_stat, test_df = _observation_test(f * np.sqrt(weight)[:, None], qvv)
        w_obs = normal_deviate(test_stat / (sigma0**2 if dof > 0 else 1.0), test_df)
    ctrl_res = xyz[pb.ctrl_point] - pb.ctrl_xyz
    gps_res = eo[pb.gps_image, :3] - pb.gps_xyz
    return BundleSolution(
        eo=eo,
        xyz=xyz,
        calibration=cal,
        residuals=resid,
        w=w,
        w_obs=w_obs,
        test_stat=test_stat,
        test_df=test_df,
        redundancy=red,
        sigma0=sigma0,
        dof=dof,
        iterations=it,
        eo_std=eo_std,
        xyz_cov=xyz_cov,
        calibration_std=cal_std,
        calibration_names=names,
        calibration_corr=corr,
        calibration_eo_corr=eo_corr,
        ctrl_residuals=ctrl_res,
        gps_residuals=gps_res,
        obs_sigma=pb.obs_sigma.copy(),
    )


def _pairs(obs_point: np.ndarray, used: np.ndarray):
    """All ordered pairs ``(o1, o2)`` of observations (with weight) of the same point."""
    idx = np.nonzero(used)[0]
    order = idx[np.argsort(obs_point[idx], kind="stable")]
    pts = obs_point[order]
    starts = np.r_[0, np.nonzero(np.diff(pts))[0] + 1]
    counts = np.diff(np.r_[starts, len(pts)])
    # for each observation in a group of size k: k partners
    rep = np.repeat(counts, counts)  # partners per observation
    grp_start = np.repeat(starts, counts)
    o1 = np.repeat(order, rep)
    # partner offsets 0..k-1 within the group
    offs = np.arange(int(rep.sum())) - np.repeat(np.cumsum(rep) - rep, rep)
    o2 = order[np.repeat(grp_start, rep) + offs]
    return o1, o2


class _BlockLookup:
    """Entries ``S^-1[r, c]`` for many ``(r, c)``: the dense inverse up to
    :data:`DENSE_COVARIANCE_MAX` unknowns, else columns solved in chunks on demand."""

    def __init__(self, fac: _Factor):
        self.fac = fac
        self.G = fac.n
        self.scale = fac.scale
        self.dense = fac.inverse_lower() if fac.n <= DENSE_COVARIANCE_MAX else None
        self.cols: dict[int, np.ndarray] = {}

    def _ensure(self, cols: np.ndarray) -> None:
        todo = [int(c) for c in np.unique(cols) if int(c) not in self.cols]
        for s in range(0, len(todo), 256):
            chunk = np.array(todo[s : s + 256])
            X = self.fac.columns(chunk)
            for k, cc in enumerate(chunk):
                self.cols[int(cc)] = X[:, k]

    def diag(self) -> np.ndarray:
        if self.dense is not None:
            return np.diag(self.dense) * self.scale**2
        self._ensure(np.arange(self.G))
        return np.array([self.cols[c][c] for c in range(self.G)])

    def gather(self, r: np.ndarray, c: np.ndarray) -> np.ndarray:
        r, c = np.broadcast_arrays(r, c)
        if self.dense is not None:
            return self.dense[np.maximum(r, c), np.minimum(r, c)] * self.scale[r] * self.scale[c]
        self._ensure(c)
        out = np.empty(r.shape)
        flat_r, flat_c, o = r.ravel(), c.ravel(), out.reshape(-1)
        for cc in np.unique(flat_c):
            m = flat_c == cc
            o[m] = self.cols[int(cc)][flat_r[m]]
        return out


def _point_cofactors(pb, nm, look: _BlockLookup, cols, sel, f, Je, Jp, Jc, weight):
    """Point cofactor matrices ``(P, 3, 3)`` and redundancy numbers ``(N, 2)``.

    For observation ``o`` of point ``j`` with rows ``a_g`` (global) and ``a_p``
    (point), weighted: ``h_o = a_p (V^-1 + M_j) a_p.T - 2 sym(a_g K_o a_p.T) +
    a_g Q_oo a_g.T`` with ``Y_o = V_j^-1 W_o.T``, ``M_j = sum_{o1,o2} Y_o1 Q_o1o2
    Y_o2.T`` and ``K_o = sum_o2 Q_oo2 Y_o2.T``; the redundancy numbers are the
    diagonal of ``I - h_o``.
    """
    N = len(f)
    used = weight > 0
    wgt = np.sqrt(weight)[:, None, None]
    Ag = np.concatenate([Je, np.take_along_axis(Jc, sel[:, None, :].repeat(2, 1), 2)], axis=2)
    pad = cols < 0
    Ag = np.where(pad[:, None, :], 0.0, Ag) * wgt
    B = Jp * wgt
    colsz = np.where(pad, 0, cols)
    j = pb.obs_point
    Vinv = nm.Vinv
    Wo = np.einsum("nai,naj->nij", Ag, B)  # (N, gdim, 3)
    Y = np.einsum("nij,nkj->nik", Vinv[j], Wo)  # (N, 3, gdim) = V^-1 W_o.T
    P = pb.n_points
    M = np.zeros((P, 3, 3))
    K = np.zeros((N, Ag.shape[2], 3))
    o1, o2 = _pairs(j, used)
    chunk = 200_000
    for s in range(0, len(o1), chunk):
        a, b = o1[s : s + chunk], o2[s : s + chunk]
        Q = look.gather(colsz[a][:, :, None], colsz[b][:, None, :])  # (n, g, g)
        Q = np.where(pad[a][:, :, None] | pad[b][:, None, :], 0.0, Q)
        QY = np.einsum("nij,nkj->nik", Q, Y[b])  # Q_ab Y_b.T: (n, g, 3)
        np.add.at(K, a, QY)
        np.add.at(M, j[a], np.einsum("nij,njk->nik", Y[a], QY))
    cov = Vinv + M
    # observations of unused points keep NaN covariance only if no weight at all
    seen = np.zeros(P, bool)
    seen[j[used]] = True
    if len(pb.ctrl_point):
        seen[pb.ctrl_point[np.isfinite(pb.ctrl_sigma).any(axis=1)]] = True
    cov[~seen] = np.nan
    # redundancy numbers
    Qoo = look.gather(colsz[:, :, None], colsz[:, None, :])
    Qoo = np.where(pad[:, :, None] | pad[:, None, :], 0.0, Qoo)
    h = np.einsum("nai,nij,nbj->nab", B, cov[j], B)
    cross = np.einsum("nai,nij,nbj->nab", Ag, K, B)
    h = h - cross - np.transpose(cross, (0, 2, 1)) + np.einsum("nai,nij,nbj->nab", Ag, Qoo, Ag)
    qvv = np.eye(2)[None] - h  # cofactor of the weighted residuals of each observation
    qvv[~used] = np.nan
    return cov, qvv


def _observation_test(f: np.ndarray, qvv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The test quantity of each observation (both coordinates together), unscaled.

    ``T = f.T Qvv^+ f`` (``sigma0 = 1``), with as many degrees of freedom as
    ``Qvv`` has rank: 2; 1 where only one direction is checked (the y-parallax
    of a two-ray point); 0 where nothing is. Returns ``(T, df)``; NaN and 0 for
    unused observations. :func:`normal_deviate` turns ``T / sigma^2`` into a
    normal deviate.
    """
    ok = np.isfinite(qvv).all(axis=(1, 2))
    ev, V = np.linalg.eigh(np.where(ok[:, None, None], qvv, np.eye(2)))
    keep = ev > 1e-4  # directions with redundancy
    z = np.einsum("nab,na->nb", V, f)  # residual in the eigenbasis
    T = np.sum(np.where(keep, z * z / np.where(keep, ev, 1.0), 0.0), axis=1)
    df = np.where(ok, keep.sum(axis=1), 0)
    return np.where(ok, T, np.nan), df


def normal_deviate(T: np.ndarray, df: np.ndarray) -> np.ndarray:
    """``w >= 0`` with ``P(|N(0, 1)| > w) = P(chi2_df > T)``: one threshold for every rank.

    0 where ``df`` is 0 (nothing checked), NaN where ``T`` is NaN.
    """
    from scipy.stats import chi2, norm

    T = np.asarray(T, float)
    w = np.where(np.isnan(T), np.nan, 0.0)
    for k in (1, 2, 3):
        m = (df == k) & np.isfinite(T)
        if m.any():
            with np.errstate(divide="ignore"):
                v = norm.isf(chi2.sf(T[m], k) / 2.0)
            # beyond the tail a double can hold: the deviate's asymptote
            w[m] = np.where(np.isfinite(v), v, np.sqrt(T[m]))
    return w


# --- robust estimation: data snooping ----------------------------------------------------------

#: Standardised residual above which an observation is a gross error (Baarda's w-test with
#: Pope's a posteriori sigma0; two-sided, about 6e-5 per coordinate of a good observation).
SNOOPING_THRESHOLD = 4.0

#: Reasons of a rejection (:class:`Rejection`).
REJECTED_LARGEST = "largest standardised residual of its point"
REJECTED_TWO_RAYS = "two-ray point: the gross error cannot be localised, both rays rejected"
REJECTED_NOT_LOCALISED = (
    "the largest standardised residuals of its point are alike (the error cannot be "
    "localised): all rays rejected"
)
#: A point's largest test is localised unless the second largest ``sqrt(T)`` reaches this share
#: of it: equal tests (a two-ray point's y-parallax; an error along the flight in a point seen
#: from three centres on one line) cannot tell which ray is wrong. Nearly equal ones can: the
#: largest is rejected, and should it have been the wrong one, the next round finds the other.
LOCALISE_RATIO = 0.97
REJECTED_CONTROL = (
    "control point whose coordinates disagree with its rays (the largest test of its point)"
)


@dataclass(frozen=True)
class Rejection:
    """One rejected observation: image observation ``obs`` (index into the problem's
    observations; -1 for a control coordinate), ``control`` (index into the problem's
    control, -1 for an image observation), its residual (photo mm ``(2,)``, or metres ``(3,)``
    for control), its standardised residual ``w`` (the largest of its coordinates; NaN where
    not computed), the round it was found in and the reason."""

    obs: int
    control: int
    residual: tuple[float, ...]
    w: float
    round: int
    reason: str


def robust_adjust(
    problem: BundleProblem,
    *,
    threshold: float = SNOOPING_THRESHOLD,
    max_rounds: int = 16,
    max_iter: int = 30,
    groups: np.ndarray | None = None,
    progress=None,
) -> tuple[BundleSolution, list[Rejection]]:
    """Adjust and reject gross errors by iterated data snooping, then a final least squares.

    Each round adjusts (warm-started from the round before) and tests every
    observation: ``w`` is its test quantity ``T`` (both coordinates together,
    exact redundancy) scaled by the variance factor, as a normal deviate
    (:func:`normal_deviate`). The variance factor is robust
    (:func:`robust_sigma0`) while the threshold is still above ``threshold``
    (gross errors inflate the least-squares ``sigma0``), then the adjustment's
    own ``sigma0`` (Pope's tau test): real measurement errors have heavier
    tails than a normal distribution, and the robust scale, which ignores the
    tails, would reject good measurements among them. In every point, the one observation with the
    largest ``w`` is rejected when ``w`` exceeds the round's threshold: a gross
    error spreads into the other rays of its point, so only the worst of a
    point goes per round. When the second largest test of the point is alike
    (:data:`LOCALISE_RATIO`: a two-ray point's y-parallax, an error along the
    flight in a point seen from three centres on a line), the error cannot be
    localised and all rays of the point are rejected. The threshold starts at four times
    ``threshold`` and halves each round down to ``threshold``: the first
    solutions are distorted by all gross errors at once, and only the largest
    are sure to be gross then. A control point's observed coordinates are
    tested together (:func:`_control_tests`) and compete with the image
    observations of their point: a wrong control point pulls its point away
    from its rays, and it is the control that must go, not the rays (it
    becomes a tie point). Rounds go on until nothing more
    is rejected; the last round is the final least-squares adjustment without
    the rejected observations; should a round's rejections leave part of the
    block undetermined (a weak block losing its only control rays), they are
    taken back, kept for good, and the rounds go on. Returns the solution and the
    rejections in the order found. ``progress(done, total)`` counts rounds.
    """
    pb = problem
    N = len(pb.obs_image)
    weight = np.ones(N)
    rejected: list[Rejection] = []
    work = pb
    sol = None
    sigma = pb.obs_sigma.copy()
    factors: dict[int, float] = {}
    if groups is not None:
        groups = np.asarray(groups, np.int64).ravel()
        factors = {int(g): 1.0 for g in np.unique(groups)}
    vce_done = 0
    prev: tuple | None = None
    protected = np.zeros(N, bool)
    protected_ctrl: set[int] = set()
    revert_left = 3
    exact = False
    final = False
    for rnd in range(1, max_rounds + 1):
        level = threshold * max(4.0 / 2 ** (rnd - 1), 1.0)
        try:
            # while errors are sought, the redundancy with the orientations known is enough
            # (and far cheaper) and the iterations may stop at 0.1 mm; once (almost) nothing
            # more is found, an exact round, and after its few rejections a final one
            sol = adjust(work, weight=weight, max_iter=max_iter,
                         covariance=True if exact else "approximate",
                         tol=1.0 if exact else 10.0)  # fmt: skip
            if final:
                break
        except DegenerateGeometryError:
            if prev is None or revert_left <= 0:
                raise
            # the last round's rejections left part of the block undetermined: they are
            # taken back and kept for good, and the rounds go on from before them
            revert_left -= 1
            _, rejected, sigma, factors, weight, work, last = prev
            for r in last:
                if r.obs >= 0:
                    protected[r.obs] = True
                else:
                    protected_ctrl.add(r.control)
            prev = None
            continue
        if progress is not None:
            progress(rnd, max_rounds)
        found = _snoop(work, sol, weight, level, rnd, robust_scale=level > threshold,
                       protected=protected, protected_ctrl=protected_ctrl)  # fmt: skip
        rescaled = False
        if groups is not None and level <= threshold and vce_done < VCE_ROUNDS:
            # from the first round at the threshold on, with the observations rejected now
            # already left out of the estimate
            wv = weight.copy()
            for r in found:
                if r.obs >= 0:
                    wv[r.obs] = 0.0
            k = _variance_components(sol, wv, groups)
            if any(abs(v - 1.0) > 0.05 for v in k.values()):
                for g, v in k.items():
                    sigma[groups == g] *= v
                    factors[g] *= v
                rescaled = True
                vce_done += 1
        # a trickle of marginal cases (a few tests just over the threshold, which each
        # re-adjustment shifts a little) no longer needs a round of its own
        quiet = len(found) <= max(2, N // 20000)
        if quiet and not rescaled and level <= threshold:
            if exact and not found:
                break
            if exact:
                final = True
            exact = True
        prev = (sol, list(rejected), sigma.copy(), dict(factors), weight.copy(), work, found)
        rejected += found
        cs = work.ctrl_sigma.copy()
        for r in found:
            if r.obs >= 0:
                weight[r.obs] = 0.0
            else:
                cs[r.control] = np.inf
        # warm start: the next round begins at this solution
        work = BundleProblem(
            calibration=pb.calibration,
            radius_mm=pb.radius_mm,
            camera=pb.camera,
            eo=sol.eo,
            xyz=sol.xyz,
            obs_image=pb.obs_image,
            obs_point=pb.obs_point,
            obs_xy=pb.obs_xy,
            obs_sigma=sigma,
            free=pb.free,
            calibration_sigma=pb.calibration_sigma,
            ctrl_point=pb.ctrl_point,
            ctrl_xyz=pb.ctrl_xyz,
            ctrl_sigma=cs,
            gps_image=pb.gps_image,
            gps_xyz=pb.gps_xyz,
            gps_sigma=pb.gps_sigma,
        )
        work.calibration = sol.calibration.copy()
        # the priors of the calibration refer to the problem's initial values
        work.calibration_sigma = pb.calibration_sigma
    else:
        raise ConvergenceError(
            f"bundle: gross errors were still found after {max_rounds} rounds of data "
            "snooping; the block has more gross errors than the tests can separate"
        )
    assert sol is not None
    sol.variance_factors = factors
    sol.obs_sigma = sigma
    if progress is not None:
        progress(max_rounds, max_rounds)
    return sol, rejected


#: At most this many variance component steps in :func:`robust_adjust`.
VCE_ROUNDS = 5


def _variance_components(sol: BundleSolution, weight, groups) -> dict[int, float]:
    """Per group ``k = sqrt(sum f^2 / sum r)`` over its observations with weight (groups with
    a redundancy below 10 keep 1: too few to estimate)."""
    used = weight > 0
    out = {}
    for g in np.unique(groups):
        m = used & (groups == g)
        r = float(np.nansum(sol.redundancy[m]))
        if r < 10:
            out[int(g)] = 1.0
            continue
        ff = sol.residuals[m] / sol.obs_sigma[m]
        out[int(g)] = float(np.sqrt(np.sum(ff * ff) / r))
    return out


def _snoop(
    pb: BundleProblem,
    sol: BundleSolution,
    weight,
    threshold,
    rnd,
    robust_scale: bool,
    protected=None,
    protected_ctrl=frozenset(),
) -> list[Rejection]:
    """One round of data snooping (see :func:`robust_adjust`): per point the largest test
    among its image observations and its control coordinates; ``protected`` observations
    (and control entries ``protected_ctrl``) are never rejected."""
    used = weight > 0
    j = pb.obs_point
    scale = robust_sigma0(sol, weight) if robust_scale else sol.sigma0
    w = normal_deviate(sol.test_stat / scale**2, sol.test_df)
    w = np.where(used, np.nan_to_num(w, nan=0.0), -1.0)
    if protected is not None:
        w = np.where(protected, np.minimum(w, 0.0), w)
    rt = np.sqrt(np.nan_to_num(sol.test_stat, nan=0.0))
    wc, tc = _control_tests(pb, sol, scale)
    for c in protected_ctrl:
        wc[c] = 0.0
    out: list[Rejection] = []
    # control coordinates beat their point's image observations when their test is larger
    by_point_ctrl: dict[int, int] = {}
    for ci in np.nonzero(wc > threshold)[0].tolist():
        pt = int(pb.ctrl_point[ci])
        if pt not in by_point_ctrl or wc[ci] > wc[by_point_ctrl[pt]]:
            by_point_ctrl[pt] = ci
    # observations grouped by point, the largest w first
    order = np.lexsort((-w, j))
    order = order[used[order]]
    pts = j[order]
    start = np.r_[0, np.nonzero(np.diff(pts))[0] + 1].astype(np.int64)
    count = np.diff(np.r_[start, len(pts)])
    if not len(order):
        start = count = np.zeros(0, np.int64)
    top = order[start]
    second = np.where(count > 1, rt[order[np.minimum(start + 1, len(order) - 1)]], 0.0)
    flagged = w[top] > threshold
    ctrl_wins = np.array([
        int(j[o]) in by_point_ctrl and wc[by_point_ctrl[int(j[o])]] >= w[o] for o in top
    ], bool)  # fmt: skip
    flagged &= ~ctrl_wins
    group_pts = pts[start] if len(pts) else np.zeros(0, np.int64)
    for c in by_point_ctrl.values():
        pt = int(pb.ctrl_point[c])
        gi = int(np.searchsorted(group_pts, pt))
        if gi < len(group_pts) and group_pts[gi] == pt and not ctrl_wins[gi]:
            continue  # an image observation of this point has the larger test
        res = tuple(float(v) for v in sol.ctrl_residuals[c])
        out.append(Rejection(-1, int(c), res, float(wc[c]), rnd, REJECTED_CONTROL))
    # localised: the largest clearly above the second (else all rays of the point go)
    local = flagged & (count >= 3) & (second < LOCALISE_RATIO * rt[top])
    whole = flagged & ~local
    for o in top[local]:
        out.append(_rej(sol, o, rnd, REJECTED_LARGEST, w[o]))
    for s0, n in zip(start[whole], count[whole], strict=True):
        reason = REJECTED_TWO_RAYS if n == 2 else REJECTED_NOT_LOCALISED
        for o in order[s0 : s0 + n]:
            out.append(_rej(sol, o, rnd, reason, w[o]))
    del tc
    return out


def _control_tests(pb: BundleProblem, sol: BundleSolution, scale: float):
    """The test of each control point's observed coordinates together, as a normal deviate.

    ``T = v.T (S - Q)^-1 v`` over the observed coordinates (``S`` their a priori
    variances, ``Q`` the cofactor of the adjusted point, ``v`` the residuals),
    chi-square with as many degrees of freedom as coordinates are observed.
    Returns ``(w (C,), T (C,))``; 0 for check points (nothing observed).
    """
    C = len(pb.ctrl_point)
    w = np.zeros(C)
    T = np.zeros(C)
    if not C or not np.isfinite(sol.sigma0):
        return w, T
    obs = np.isfinite(pb.ctrl_sigma)
    Q = sol.xyz_cov[pb.ctrl_point] / sol.sigma0**2
    df = obs.sum(axis=1)
    for c in np.nonzero(df)[0]:
        m = obs[c]
        Cv = np.diag(pb.ctrl_sigma[c, m] ** 2) - Q[c][np.ix_(m, m)]
        v = sol.ctrl_residuals[c, m]
        ev, V = np.linalg.eigh(Cv)
        keep = ev > 1e-6 * pb.ctrl_sigma[c, m].max() ** 2
        z = V.T @ v
        T[c] = float(np.sum(z[keep] ** 2 / ev[keep]))
        df[c] = int(keep.sum())
    w = normal_deviate(T / scale**2, df)
    return np.nan_to_num(w, nan=0.0), T


def robust_sigma0(sol: BundleSolution, weight) -> float:
    """A scale of the standardised residuals that gross errors do not inflate.

    ``1.4826 median |f / sqrt(r)|`` over the coordinates (with weight) whose
    redundancy number ``r`` exceeds 0.05: the normalised median absolute
    deviation, which equals ``sigma0`` without gross errors. Data snooping tests
    with it (Pope's tau test with a robust variance factor), since the least
    squares ``sigma0`` of a block with 5 % gross errors is several times too large
    and would hide them.
    """
    used = (weight > 0)[:, None] & (sol.redundancy > 0.05)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = sol.residuals / np.where(np.isfinite(sol.redundancy), 1.0, np.nan)
    # residuals in units of their a priori sigma: the weighted residual is
    # f / s; here recomputed from w (per coordinate, a posteriori) times sigma0
    u = sol.w * sol.sigma0
    del f
    u = np.abs(u[used & np.isfinite(u)])
    if not len(u):
        return sol.sigma0 if np.isfinite(sol.sigma0) else 1.0
    return max(float(1.4826 * np.median(u)), 1e-12)


def _rej(sol, o, rnd, reason, w) -> Rejection:
    return Rejection(int(o), -1, tuple(float(v) for v in sol.residuals[o]), float(w), rnd, reason)
