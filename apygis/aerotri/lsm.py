"""Least-squares matching (LSM): the precise measurement of tie points.

A template of the reference image, ``(2 h + 1)^2`` samples on the grid of
offsets ``u = (du_col, du_row)``, ``du in {-h .. h}`` (pixels of the reference
level) centred *exactly* at the reference point ``p`` (sub-pixel), is matched
into the search image by the affine geometric and linear radiometric model
(Ackermann 1983)::

    g_ref(p + u) = r0 + r1 * g_search(t + A u)            for every offset u

with the eight unknowns per point: the search position ``t = (col, row)`` (the
point homologous to ``p``), the 2 x 2 affine ``A`` (``A[a, b] = d s_a / d u_b``,
rows/columns in (col, row) order) and the offset ``r0`` and gain ``r1``.
Gauss-Newton on the linearised observation equations::

    l = g_ref - r0 - r1 g_s(s),    s = t + A u
    J = [r1 gc, r1 gr, r1 gc u_c, r1 gc u_r, r1 gr u_c, r1 gr u_r, 1, g_s(s)]
    (J^T J) dx = J^T l  (+ the noise term below)
    dx = (dt_c, dt_r, dA00, dA01, dA10, dA11, dr0, dr1)

with ``(gc, gr)`` the gradient of the search image at ``s``. All points are
solved at once (batched 8 x 8 normal equations); a point stops updating when the
largest move of its window's corners in one step is below ``tol_px``, or below
``10 tol_px`` with every geometric step below 5 % of that parameter's own
standard deviation (where noise rivals the texture, Gauss-Newton's ``N``
overestimates the cost's curvature and the iteration creeps; steps that small
no longer matter). The corners, not the position alone, must settle: a point
whose shape keeps creeping is weakly determined, and letting it stop once its
position settles accepted 17 % more measurements on a noisy digital block, with
a median error 14 % larger.

Images are sampled through their cubic B-spline interpolant
(:class:`SplineImage`), values and analytic derivatives from the same spline,
so the Jacobian is the exact derivative of the model being fitted. Windows
should reach >= 10 px beyond the patches: the spline prefilter's boundary
effect decays by 0.268 per pixel.

Interpolated noise. Interpolating white pixel noise (variance ``sigma^2``) at
a fractional position ``f`` averages neighbouring pixels: per axis its
variance becomes ``q(f) sigma^2`` with ``q(f) = sum_j w_j(f)^2`` (``w`` the
cardinal cubic spline kernel; ``q(0) = 1``, ``q(0.5) = 0.756``), its
derivative has variance ``D(f) sigma^2`` (``D = sum w_j'^2``: 1.39 .. 3.42)
and ``E[e e'] = q'(f) sigma^2 / 2``. Three consequences, all handled:

* Pixel locking. The expected cost ``E sum l^2`` contains
  ``E = sigma^2 r1^2 sum_i q(s_i)``, which depends on the search position's
  fractions and pulls ``t`` towards half pixels (a bias of up to
  ``sigma^2 max|q'| / (2 mean g'^2)``, 0.02 px at 3 DN noise on a 30 DN
  texture), and it attenuates the gain. LSM minimises ``sum l^2 - E`` instead:
  the normal equations become ``N dx = J^T l + grad(E) / 2``, with ``sigma^2``
  from the current residuals. This removes the bias (and the gain's
  errors-in-variables attenuation).
* Residual variance. ``E[v^T v] / (m - 8) = sigma^2 (q_ref + r1^2 q_s)``
  (``q_ref`` at the template's fraction, ``q_s`` the mean over the search
  samples, ``m = (2 h + 1)^2``): ``sigma^2`` is estimated from it, while the
  position error is driven by the noise at the texture's (low) frequencies,
  which interpolation passes unattenuated: white-equivalent variance
  ``sigma^2 (1 + r1^2)`` (equal pixel noise in both images assumed).
* Noisy Jacobian. ``N = J^T J`` is built from noisy gradients, inflated on
  average by ``dN = sum_i B_i^T C_i B_i`` (``C_i`` the covariance of the
  noise's derivatives and value at sample ``i``, ``B_i`` its place in the
  Jacobian row), and the noise of ``J`` times the residual noise adds
  ``s0^2 dN`` to the covariance of ``J^T l``. Hence::

    Nc = N - dN
    Cov(t) = [Nc^-1 (sigma^2 (1 + r1^2) Nc + s0^2 dN) Nc^-1]  (position block)

  (``N`` itself where ``Nc`` is not positive definite). In simulation the
  normalised errors ``e / sigma`` have RMS 0.96 .. 0.99 from 1 to 6 DN noise on
  a 30 DN texture (the plain ``s0^2 N^-1`` gives 1.0 .. 1.7 there); at very low
  SNR a few points get large sigmas, honestly: weight by them.

Failure codes (:class:`LsmReason`): see its members. A point is ``ok`` only when
converged, inside both windows, with a sane affine (singular values in
``[0.5, 2]``), a positive gain, a normalised cross-correlation of template
and resampled search patch of at least ``corr_min`` and ``sigma <= sigma_max``.

:func:`track` runs LSM coarse to fine through two image pyramids
(:class:`~apygis.aerotri.imagery.ImageSource`), reading windows tile by tile.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from scipy import ndimage

from apygis.aerotri.imagery import ImageSource, full_to_level, level_to_full

__all__ = ["LsmReason", "LsmResult", "SplineImage", "lsm", "track"]


class LsmReason(enum.IntEnum):
    """Why a point of :func:`lsm` / :func:`track` is not ok (``OK`` when it is)."""

    OK = 0
    NOT_CONVERGED = 1  #: ``max_iter`` iterations without convergence
    SHIFT = 2  #: the position moved more than ``max_shift`` (default ``half``) from its start
    SINGULAR = 3  #: singular normal equations (no texture) or non-finite values
    AFFINE = 4  #: a singular value of ``A`` left ``[0.5, 2]``, or ``A`` left ``affine_max``
    GAIN = 5  #: gain ``r1`` not positive (contrast reversal)
    LOW_CORR = 6  #: correlation after convergence below ``corr_min``
    OUTSIDE = 7  #: template or search patch outside its window or image
    IMPRECISE = 8  #: converged, but ``sigma`` above ``sigma_max`` (noise swamps texture)


@dataclass
class LsmResult:
    """Result of :func:`lsm` / :func:`track` for ``n`` points.

    ``xy`` (n, 2) search position (col, row) homologous to the reference point;
    ``affine`` (n, 2, 2) ``A``; ``gain`` ``r1`` and ``offset`` ``r0`` (n,);
    ``corr`` (n,) normalised cross-correlation of template and resampled search
    patch; ``cov`` (n, 2, 2) covariance of ``xy`` (px^2); ``sigma`` (n,)
    ``sqrt(trace(cov) / 2)`` (px); ``iterations`` (n,); ``ok`` (n,) bool;
    ``reason`` (n,) :class:`LsmReason` codes.
    """

    xy: np.ndarray
    affine: np.ndarray
    gain: np.ndarray
    offset: np.ndarray
    corr: np.ndarray
    cov: np.ndarray
    sigma: np.ndarray
    iterations: np.ndarray
    ok: np.ndarray
    reason: np.ndarray

    def __len__(self) -> int:
        return len(self.ok)

    @classmethod
    def empty(cls, n: int) -> LsmResult:
        """``n`` points, all not ok (``NOT_CONVERGED``), NaN estimates."""
        nan = np.full(n, np.nan)
        return cls(
            xy=np.full((n, 2), np.nan),
            affine=np.tile(np.eye(2), (n, 1, 1)),
            gain=nan.copy(),
            offset=nan.copy(),
            corr=nan.copy(),
            cov=np.full((n, 2, 2), np.nan),
            sigma=nan.copy(),
            iterations=np.zeros(n, dtype=int),
            ok=np.zeros(n, dtype=bool),
            reason=np.full(n, int(LsmReason.NOT_CONVERGED), dtype=np.int8),
        )

    def put(self, idx: np.ndarray, other: LsmResult) -> None:
        """Copy ``other``'s points into the positions ``idx`` of this result."""
        for name in self.__dataclass_fields__:
            getattr(self, name)[idx] = getattr(other, name)


def _bspline_weights(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic B-spline weights of the 4 nodes ``floor(x) - 1 .. floor(x) + 2`` and their
    derivatives, for fractions ``f = x - floor(x)`` (shape (..., 4) each)."""
    f2 = f * f
    f3 = f2 * f
    g = 1 - f
    w = np.stack(
        [g * g * g / 6, (3 * f3 - 6 * f2 + 4) / 6, (-3 * f3 + 3 * f2 + 3 * f + 1) / 6, f3 / 6], -1
    )
    d = np.stack([-g * g / 2, (3 * f2 - 4 * f) / 2, (-3 * f2 + 2 * f + 1) / 2, f2 / 2], -1)
    return w, d


def _weights4(f: np.ndarray, grad: bool):
    """:func:`_bspline_weights` as tuples of arrays (the fast path of the gather)."""
    f2 = f * f
    f3 = f2 * f
    g = 1 - f
    w = (g * g * g * (1 / 6), 0.5 * f3 - f2 + (2 / 3), 0.5 * (f2 + f - f3) + (1 / 6), f3 * (1 / 6))
    if not grad:
        return w, ()
    d = (-0.5 * g * g, 1.5 * f2 - 2 * f, f - 1.5 * f2 + 0.5, 0.5 * f2)
    return w, d


class SplineImage:
    """The cubic B-spline interpolant of an image window.

    ``array`` (H x W) holds the pixels of a level from ``(col0, row0)`` on (the
    window's origin in the level's pixel coordinates). The coefficients are
    computed once (:func:`scipy.ndimage.spline_filter`, ``mode='mirror'``) and
    stored in ``dtype`` (float32: half the memory traffic; values are good to
    ~1e-7 relative, far below any noise). :meth:`sample` and
    :meth:`sample_grad` evaluate the spline at arbitrary ``(col, row)``; both
    equal :func:`scipy.ndimage.map_coordinates` (``order=3, prefilter=False,
    mode='mirror'``) inside the window.

    Derivatives are the analytic derivatives of the same spline (the B-spline
    weights differentiated), not differences: they are exact for the fitted
    model, and values and both derivatives come from one gather of the 4 x 4
    coefficients (cheaper than 5 map_coordinates passes for central differences).
    """

    _PAD = 2

    def __init__(self, array, col0: float = 0, row0: float = 0, dtype=np.float32):
        a = np.asarray(array, dtype=np.float64)
        if a.ndim != 2 or min(a.shape) < 4:
            raise ValueError(f"SplineImage needs a 2-D array of at least 4 x 4, got {a.shape}")
        c = ndimage.spline_filter(a, order=3, mode="mirror", output=np.float64)
        # 'mirror' reflects about the edge pixel centres: c[-1] = c[1] = np.pad 'reflect'
        self.coef = np.pad(c, self._PAD, mode="reflect").astype(dtype)
        self.col0 = float(col0)
        self.row0 = float(row0)
        self.height, self.width = a.shape

    def inside(self, xy, margin: float = 0.0) -> np.ndarray:
        """Whether points ``xy`` (..., 2) lie within the window shrunk by ``margin`` px."""
        xy = np.asarray(xy, dtype=float)
        c = xy[..., 0] - self.col0
        r = xy[..., 1] - self.row0
        return (
            (c >= margin)
            & (r >= margin)
            & (c <= self.width - 1 - margin)
            & (r <= self.height - 1 - margin)
        )

    def _gather(self, c: np.ndarray, r: np.ndarray, grad: bool):
        """Values (and derivatives) at window coordinates ``c, r`` (flat float arrays)."""
        hh, ww = self.coef.shape
        p = self._PAD
        # clamp far-outside points to the padded range (values there are meaningless)
        c = np.clip(c, 1.0 - p, ww - p - 3.0)
        r = np.clip(r, 1.0 - p, hh - p - 3.0)
        dt = self.coef.dtype
        flat = self.coef.ravel()
        offs = (np.arange(4)[:, None] * ww + np.arange(4)[None, :]).ravel()[:, None]
        n = c.size
        val = np.empty(n, dtype=dt)
        gc = np.empty(n if grad else 0, dtype=dt)
        gr = np.empty(n if grad else 0, dtype=dt)
        step = 1 << 15  # chunks that stay in cache
        for s in range(0, n, step):
            cs, rs = c[s : s + step], r[s : s + step]
            ci, ri = np.floor(cs), np.floor(rs)
            fc, fr = (cs - ci).astype(dt), (rs - ri).astype(dt)
            base = (ri.astype(np.intp) + (p - 1)) * ww + (ci.astype(np.intp) + (p - 1))
            C = flat.take(offs + base[None, :])  # (16, k): node (i, j) at 4 i + j
            wc, dc = _weights4(fc, grad)
            wr, dr = _weights4(fr, grad)
            v = gcs = grs = 0.0
            for i in range(4):
                rv = C[4 * i] * wc[0] + C[4 * i + 1] * wc[1] + C[4 * i + 2] * wc[2]
                rv += C[4 * i + 3] * wc[3]
                v = v + rv * wr[i]
                if grad:
                    rd = C[4 * i] * dc[0] + C[4 * i + 1] * dc[1] + C[4 * i + 2] * dc[2]
                    rd += C[4 * i + 3] * dc[3]
                    grs = grs + rv * dr[i]
                    gcs = gcs + rd * wr[i]
            val[s : s + step] = v
            if grad:
                gc[s : s + step] = gcs
                gr[s : s + step] = grs
        return val, gc, gr

    def _split(self, xy) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        xy = np.asarray(xy, dtype=float)
        c = (xy[..., 0] - self.col0).ravel()
        r = (xy[..., 1] - self.row0).ravel()
        return c, r, xy.shape[:-1]

    def sample(self, xy) -> np.ndarray:
        """Interpolated values at ``xy`` (..., 2) (col, row in the level)."""
        c, r, shape = self._split(xy)
        return self._gather(c, r, grad=False)[0].reshape(shape)

    def sample_grad(self, xy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Values and derivatives ``d/dcol``, ``d/drow`` at ``xy`` (..., 2)."""
        c, r, shape = self._split(xy)
        v, gc, gr = self._gather(c, r, grad=True)
        return v.reshape(shape), gc.reshape(shape), gr.reshape(shape)

    def sample_grad_cr(self, c: np.ndarray, r: np.ndarray):
        """:meth:`sample_grad` at level coordinates given as two arrays of one shape."""
        shape = np.shape(c)
        v, gc, gr = self._gather(np.ravel(c) - self.col0, np.ravel(r) - self.row0, grad=True)
        return v.reshape(shape), gc.reshape(shape), gr.reshape(shape)


@cache
def _noise_tables(k: int = 512) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise factors of cubic spline interpolation of white noise, ``f = i / k``, i = 0..k.

    With the cardinal kernel ``w_j(f)`` (value at ``f`` of the interpolant of a
    unit impulse at node ``j``): ``q(f) = sum w_j^2`` (variance of the
    interpolated noise, per unit pixel variance), ``q'(f) = 2 sum w_j w_j'``
    (so ``E[e e'] = q'/2``) and ``D(f) = sum w_j'^2`` (variance of its derivative).
    """
    n = 64
    d = np.zeros(n)
    d[n // 2] = 1.0
    b = ndimage.spline_filter1d(d, 3, mode="mirror")
    f = np.arange(k + 1) / k
    w, dw = _bspline_weights(f)  # (k+1, 4): nodes -1..2 around floor(x)
    j = np.arange(-20, 21)  # w_j(f) = K(f - j) = sum_i W_i(f) b[c - j - 1 + i]
    idx = n // 2 - j[:, None] - 1 + np.arange(4)[None, :]  # (41, 4)
    bb = b[idx]
    kv = np.einsum("fi,ji->fj", w, bb)
    kd = np.einsum("fi,ji->fj", dw, bb)
    return (kv**2).sum(1), 2 * (kv * kd).sum(1), (kd**2).sum(1)


def _q(x: np.ndarray) -> np.ndarray:
    """Noise variance factor ``q`` of spline interpolation at coordinate(s) ``x`` (one axis)."""
    t = _noise_tables()[0]
    k = len(t) - 1
    f = np.asarray(x, dtype=float) % 1.0
    return np.interp(f * k, np.arange(k + 1), t)


@cache
def _lookup_tables() -> tuple[np.ndarray, ...]:
    return tuple(np.ascontiguousarray(t[:-1], dtype=np.float32) for t in _noise_tables())


def _q_dq(x: np.ndarray, with_d: bool = False) -> tuple[np.ndarray, ...]:
    """``q``, ``q'`` (and ``D`` when ``with_d``) at ``x`` (nearest of 512 fractions per
    pixel: fast and ample), each shaped like ``x``."""
    t = _lookup_tables()
    k = len(t[0])  # a power of 2
    # truncation is floor for x >= -0.5 / k; below, one table step off: negligible
    i = (x * k + 0.5).astype(np.intp) & (k - 1)
    # one take per table: indexing the stacked tables as t[:2, i] is 8 times slower
    return tuple(tab.take(i) for tab in t[: 3 if with_d else 2])


# Jacobian columns (dt_c, dt_r, dA00, dA01, dA10, dA11, dr0, dr1) = phi * lever with
# phi in (a = r1 gc, b = r1 gr, 1, g) and lever in (1, u_c, u_r); the window sums of the
# products phi_k phi_l (rows of P in lsm) times moments (1, uc, ur, uc^2, uc ur, ur^2).
_PHI = np.array([0, 1, 0, 0, 1, 1, 2, 3])
_LEV = np.array([0, 0, 1, 2, 1, 2, 0, 0])
_PROD = np.array([[0, 1, 3, 5], [1, 2, 4, 6], [3, 4, 18, 8], [5, 6, 8, 7]])
_MOM = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])
_N_PROD = _PROD[_PHI[:, None], _PHI[None, :]]
_N_MOM = _MOM[_LEV[:, None], _LEV[None, :]]
_B_PROD = np.array([9, 10, 11, 12])[_PHI]
_B_MOM = _LEV


def _offsets(half: int) -> np.ndarray:
    """Template offsets ``u`` (m, 2) (col, row), row-major."""
    g = np.arange(-half, half + 1, dtype=float)
    ur, uc = np.meshgrid(g, g, indexing="ij")
    return np.stack([uc.ravel(), ur.ravel()], axis=1)


def lsm(
    ref: SplineImage,
    ref_xy,
    search: SplineImage,
    search_xy0,
    affine0=None,
    *,
    half: int = 7,
    max_iter: int = 15,
    tol_px: float = 0.002,
    corr_min: float = 0.75,
    sigma_max: float = 0.5,
    affine_max: float = 0.25,
    noise_model: bool = True,
    max_shift: float | None = None,
) -> LsmResult:
    """Least-squares matching of templates of ``ref`` at ``ref_xy`` into ``search``.

    ``ref_xy`` (n, 2) reference points and ``search_xy0`` (n, 2) approximate
    search positions, pixel (col, row) of the level the images are at;
    ``affine0`` (n, 2, 2) approximate ``A`` (identity when None; it must hold
    the pair's rotation, e.g. ``-I`` between strips flown in opposite
    directions: ``A`` may move only ``affine_max`` from it). Convergence
    radius: all points from 2 px off, 99 % from 3, 79 % from 4, 15 % from 6
    (``half = 7``, texture of 1.8 px scale; never a wrong ok in these trials). The model and
    the covariance are in the module docstring; ``tol_px`` bounds the last
    step's move of the window corners; ``sigma_max`` (px) the accepted
    ``sigma``; ``affine_max`` the accepted departure of ``A`` from ``affine0``,
    ``||(A - A0) A0^-1||_2`` (with six affine parameters a 15 x 15 window of
    fine texture can fit a wrong place at correlation 0.8 - 0.9, but only with
    a grossly distorted ``A``: 0.34 .. 1.1 in simulation, against < 0.12 for
    right matches at low SNR). ``noise_model=False`` leaves out the corrections of
    interpolated noise (module docstring: no pixel-locking correction, covariance
    ``s0^2 N^-1``): cheaper, but the iteration may then swing between neighbouring
    half pixels. ``max_shift`` (px, ``half`` when None) bounds the move from
    ``search_xy0``. Returns an :class:`LsmResult`; ``xy`` is the search point homologous
    to ``ref_xy`` itself.
    """
    ref_xy = np.asarray(ref_xy, dtype=float).reshape(-1, 2)
    n = len(ref_xy)
    search_xy0 = np.asarray(search_xy0, dtype=float).reshape(n, 2)
    if affine0 is not None:
        affine0 = np.array(np.broadcast_to(np.asarray(affine0, dtype=float), (n, 2, 2)))
    kw: dict[str, Any] = dict(
        half=half,
        max_iter=max_iter,
        tol_px=tol_px,
        corr_min=corr_min,
        sigma_max=sigma_max,
        affine_max=affine_max,
        noise_model=noise_model,
        max_shift=float(half) if max_shift is None else float(max_shift),
    )
    if n <= _BATCH:
        return _lsm(ref, ref_xy, search, search_xy0, affine0, **kw)
    # batches bound the memory (~35 MB of window sums per 1024 points at half = 7)
    out = LsmResult.empty(n)
    for s in range(0, n, _BATCH):
        sl = np.arange(s, min(n, s + _BATCH))
        a0 = None if affine0 is None else affine0[sl]
        out.put(sl, _lsm(ref, ref_xy[sl], search, search_xy0[sl], a0, **kw))
    return out


_BATCH = 1024


def _lsm(
    ref: SplineImage,
    ref_xy: np.ndarray,
    search: SplineImage,
    search_xy0: np.ndarray,
    affine0,
    *,
    half: int,
    max_iter: int,
    tol_px: float,
    corr_min: float,
    sigma_max: float,
    affine_max: float,
    noise_model: bool = True,
    max_shift: float,
) -> LsmResult:
    """:func:`lsm` for one batch of points."""
    n = len(ref_xy)
    t = np.asarray(search_xy0, dtype=float).reshape(n, 2).copy()
    t0 = t.copy()
    if affine0 is None:
        A = np.tile(np.eye(2), (n, 1, 1))
    else:
        A = np.array(np.broadcast_to(np.asarray(affine0, dtype=float), (n, 2, 2)))
    A0 = A.copy()
    u = _offsets(half)
    m = len(u)
    corners = np.array([[-half, -half], [half, -half], [-half, half], [half, half]], float)
    r0 = np.zeros(n)
    r1 = np.ones(n)
    res = LsmResult.empty(n)
    reason = res.reason
    iters = res.iterations
    s0sq = np.full(n, np.nan)
    nmat = np.full((n, 8, 8), np.nan)
    corr = res.corr

    tpl_pos = ref_xy[:, None, :] + u[None, :, :]
    tpl = ref.sample(tpl_pos).astype(np.float64)
    q_ref = _q(ref_xy[:, 0]) * _q(ref_xy[:, 1])
    tpl_sum = tpl.sum(axis=1)
    tpl_sq = np.einsum("nm,nm->n", tpl, tpl)
    uc, ur = u[:, 0], u[:, 1]
    moments = np.stack([np.ones(m), uc, ur, uc * uc, uc * ur, ur * ur], axis=1)
    ref_in = ref.inside(ref_xy, half + 1.0)
    reason[~ref_in] = LsmReason.OUTSIDE
    active = np.flatnonzero(ref_in)
    converged = np.zeros(n, dtype=bool)
    P_buf = np.empty((min(n, _CHUNK), 18, m))

    for _ in range(max_iter):
        if active.size == 0:
            break
        ra1 = r1[active]
        # the window sums, point chunk by point chunk (P stays in the cache)
        R = np.empty((active.size, 19, 6))
        for c0 in range(0, active.size, _CHUNK):
            ch = active[c0 : c0 + _CHUNK]
            k = ch.size
            _window_sums(
                search, t[ch], A[ch], r0[ch], r1[ch], tpl[ch], u, moments, noise_model,
                P_buf[:k], R[c0 : c0 + k],
            )  # fmt: skip
        N = R[:, _N_PROD, _N_MOM]
        b = R[:, _B_PROD, _B_MOM]
        dg = np.sqrt(np.einsum("nkk->nk", N))
        good = np.all(np.isfinite(N), axis=(1, 2)) & np.all(dg > 0, axis=1)
        dg[~good] = 1.0
        Ns = N / (dg[:, :, None] * dg[:, None, :])
        Ns[~good] = np.eye(8)
        ev = np.linalg.eigvalsh(Ns)
        good &= ev[:, 0] > 1e-10 * ev[:, -1]
        Ns[~good] = np.eye(8)
        Nsi = np.linalg.inv(Ns)
        Ni = Nsi / (dg[:, :, None] * dg[:, None, :])
        dx = np.einsum("nij,nj->ni", Ni, b)
        # statistics of this linearisation (used if the point converges now)
        vtv = R[:, 13, 0] - np.einsum("nk,nk->n", dx, b)
        # noise-bias correction: minimise sum(l^2) - E, E = sigma^2 r1^2 sum q_s(s_i)
        sum_qs = R[:, 16, 0]
        sig2 = np.maximum(vtv, 0.0) / ((m - 8) * (q_ref[active] + ra1 * ra1 * sum_qs / m))
        gradE = np.zeros((active.size, 8))
        gradE[:, 0:6] = R[:, [14, 15, 14, 14, 15, 15], [0, 0, 1, 2, 1, 2]] * (ra1 * ra1)[:, None]
        gradE[:, 7] = 2.0 * ra1 * sum_qs
        if noise_model:
            dx = dx + np.einsum("nij,nj->ni", Ni, gradE * (0.5 * sig2[:, None]))
        sg, sgg, sgt = R[:, 8, 0], R[:, 7, 0], R[:, 17, 0]
        st, stt = tpl_sum[active], tpl_sq[active]
        cc = (sgt - sg * st / m) / np.sqrt(
            np.maximum((sgg - sg * sg / m) * (stt - st * st / m), 1e-300)
        )
        # update
        dt = dx[:, :2]
        dA = dx[:, 2:6].reshape(-1, 2, 2)
        t[active] += dt
        A[active] += dA
        r0[active] += dx[:, 6]
        r1[active] += dx[:, 7]
        iters[active] += 1
        move = np.abs(dt[:, None, :] + np.einsum("nab,cb->nca", dA, corners)).max(axis=(1, 2))
        # divergence checks
        bad = np.zeros(active.size, dtype=np.int8)
        sv = np.linalg.svd(A[active], compute_uv=False)
        fin = np.all(np.isfinite(dx), axis=1)
        bad[(sv[:, 0] > 2.0) | (sv[:, 1] < 0.5)] = LsmReason.AFFINE
        bad[r1[active] <= 0] = LsmReason.GAIN
        bad[np.hypot(*(t[active] - t0[active]).T) > max_shift] = LsmReason.SHIFT
        bad[~(good & fin)] = LsmReason.SINGULAR
        reason[active[bad > 0]] = bad[bad > 0]
        # converged: the window corners moved < tol_px, or < 10 tol_px with every geometric
        # step below 5 % of its own standard deviation (weak texture converges slowly in
        # Gauss-Newton, whose N overestimates the curvature; such steps change nothing)
        sd = np.sqrt(np.abs(np.einsum("nkk->nk", Ni)[:, :6]) * (sig2 * (1.0 + ra1 * ra1))[:, None])
        tiny = np.all(np.abs(dx[:, :6]) <= 0.05 * sd, axis=1) & (move < 10 * tol_px)
        done = (bad == 0) & ((move < tol_px) | tiny)
        idx = active[done]
        converged[idx] = True
        s0sq[idx] = vtv[done] / (m - 8)
        nmat[idx] = N[done]
        corr[idx] = cc[done]
        active = active[(bad == 0) & ~done]

    ok = converged.copy()
    reason[ok] = LsmReason.OK
    low = ok & ~(corr >= corr_min)
    reason[low] = LsmReason.LOW_CORR
    with np.errstate(invalid="ignore"):
        dev = np.linalg.norm(
            np.matmul(np.nan_to_num(A - A0, nan=1e9), np.linalg.inv(A0)), 2, axis=(1, 2)
        )
    distorted = ok & ~(dev <= affine_max)
    reason[distorted] = LsmReason.AFFINE
    ok &= ~distorted
    # final search patch inside the search window (spline support: one pixel)
    s_corners = t[:, None, :] + np.einsum("nab,cb->nca", A, corners)
    outside = ok & ~np.all(search.inside(s_corners, 1.0), axis=1)
    reason[outside] = LsmReason.OUTSIDE
    ok &= ~(low | outside)

    # covariance: s0^2 and N corrected for the interpolated noise (module docstring)
    cov = np.full((n, 2, 2), np.nan)
    ci = np.flatnonzero(converged)
    if ci.size and noise_model:
        cov[ci] = _covariance(t[ci], A[ci], r1[ci], q_ref[ci], s0sq[ci], nmat[ci], u)
    elif ci.size:
        cov[ci] = (s0sq[ci, None, None] * np.linalg.inv(nmat[ci]))[:, :2, :2]
    res.xy = t
    res.affine = A
    res.gain = r1
    res.offset = r0
    res.cov = cov
    res.sigma = np.sqrt(0.5 * (cov[:, 0, 0] + cov[:, 1, 1]))
    vague = ok & ~(res.sigma <= sigma_max)
    reason[vague] = LsmReason.IMPRECISE
    res.ok = ok & ~vague
    return res


_CHUNK = 24
"""Points per chunk of the window sums: P (19 x m doubles a point) stays in the cache."""


def _window_sums(search, t, A, r0, r1, tpl, u, moments, noise_model, P, out) -> None:
    """The window sums of one chunk of points into ``out`` (k, 19, 6): the products
    (rows of ``P``, a k x 18 x m buffer) of the Jacobian's factors, the residuals
    ``l``, the noise factors ``q`` and the template, times the moments
    ``(1, uc, ur, uc^2, uc ur, ur^2)`` of the offsets ``u``; row 18 (the constant 1)
    is the moments' own sum."""
    m = len(u)
    sc = t[:, 0:1] + A[:, 0, 0:1] * u[:, 0] + A[:, 0, 1:2] * u[:, 1]
    sr = t[:, 1:2] + A[:, 1, 0:1] * u[:, 0] + A[:, 1, 1:2] * u[:, 1]
    g32, gc, gr = search.sample_grad_cr(sc, sr)
    g = P[:, 8]
    g[...] = g32
    la = np.multiply(r1[:, None], g, out=P[:, 11])  # l = tpl - r0 - r1 g
    np.subtract(tpl, la, out=la)
    la -= r0[:, None]
    if noise_model:
        qc, dqc = _q_dq(sc)
        qr, dqr = _q_dq(sr)
    else:
        qc = qr = np.ones((1, m), np.float32)
        dqc = dqr = np.zeros((1, m), np.float32)
    ga = np.multiply(r1[:, None], gc, out=P[:, 3])
    gb = np.multiply(r1[:, None], gr, out=P[:, 4])
    np.multiply(ga, ga, out=P[:, 0])
    np.multiply(ga, gb, out=P[:, 1])
    np.multiply(gb, gb, out=P[:, 2])
    np.multiply(ga, g, out=P[:, 5])
    np.multiply(gb, g, out=P[:, 6])
    np.multiply(g, g, out=P[:, 7])
    np.multiply(ga, la, out=P[:, 9])
    np.multiply(gb, la, out=P[:, 10])
    np.multiply(g, la, out=P[:, 12])
    np.multiply(la, la, out=P[:, 13])
    np.multiply(dqc, qr, out=P[:, 14])
    np.multiply(qc, dqr, out=P[:, 15])
    np.multiply(qc, qr, out=P[:, 16])
    np.multiply(g, tpl, out=P[:, 17])
    out[:, :18] = (P.reshape(-1, m) @ moments).reshape(len(P), 18, 6)
    out[:, 18] = moments.sum(axis=0)


def _covariance(t, A, r1, q_ref, s0sq, N, u) -> np.ndarray:
    """Covariance of the positions ``t`` (n, 2, 2), see the module docstring.

    ``sigma^2 = s0^2 / (q_ref + r1^2 q_search)`` is the pixel noise; the normal
    matrix ``N`` was built from noisy gradients and is inflated on average by
    ``dN = sigma^2 sum_i B_i^T C_i B_i`` (``C_i`` the covariance of the
    interpolated noise's derivatives and value ``(e_c', e_r', e)`` at sample
    ``i``, from ``q``, ``q'`` and ``D``; ``B_i`` maps them to the Jacobian row);
    ``Cov(t) = Nc^-1 (sigma^2 (1 + r1^2) Nc + s0^2 dN) Nc^-1`` with
    ``Nc = N - dN`` (position block), or ``N`` itself where ``Nc`` is not
    positive definite (noise swamping texture).
    """
    m = len(u)
    uc, ur = u[:, 0], u[:, 1]
    sc = t[:, 0:1] + A[:, 0, 0:1] * uc + A[:, 0, 1:2] * ur
    sr = t[:, 1:2] + A[:, 1, 0:1] * uc + A[:, 1, 1:2] * ur
    qc, dqc, dc = _q_dq(sc, with_d=True)
    qr, dqr, dr = _q_dq(sr, with_d=True)
    q_s = (qc * qr).mean(axis=1)
    sig2 = s0sq / (q_ref + r1 * r1 * q_s)
    # covariances of the noise of phi = (a, b, 1, g) (Jacobian columns = phi * lever):
    # a = r1 e_c', b = r1 e_r', g = e; rows in the order of _PROD's products
    P = np.zeros((len(t), 9, m))
    P[:, 0] = dc * qr
    P[:, 1] = 0.25 * dqc * dqr
    P[:, 2] = qc * dr
    P[:, 5] = 0.5 * dqc * qr
    P[:, 6] = 0.5 * qc * dqr
    P[:, 7] = qc * qr
    moments = np.stack([np.ones(m), uc, ur, uc * uc, uc * ur, ur * ur], axis=1)
    R = (P.reshape(-1, m) @ moments).reshape(len(t), 9, 6)
    scale = np.ones((len(t), 9))
    scale[:, [0, 1, 2]] = (r1 * r1)[:, None]
    scale[:, [5, 6]] = r1[:, None]
    R *= (scale * sig2[:, None])[:, :, None]
    Rz = np.concatenate([R, np.zeros((len(t), 10, 6))], axis=1)  # row 18 ("1 * 1"): no noise
    dN = Rz[:, _N_PROD, _N_MOM]
    Nc = N - dN
    d = np.sqrt(np.abs(np.einsum("nkk->nk", N)))
    ev = np.linalg.eigvalsh(Nc / (d[:, :, None] * d[:, None, :]))
    Nc[ev[:, 0] <= 1e-6] = N[ev[:, 0] <= 1e-6]
    Ni = np.linalg.inv(Nc)
    # first order sigma^2 (1 + r1^2) Nc, plus the noisy Jacobian times the residual noise
    F = (sig2 * (1.0 + r1 * r1))[:, None, None] * Nc + s0sq[:, None, None] * dN
    return np.matmul(np.matmul(Ni, F), Ni)[:, :2, :2]


def track(
    ref: ImageSource,
    search: ImageSource,
    ref_xy0,
    search_xy_approx,
    affine0=None,
    *,
    start: int,
    stop: int = 0,
    half: int = 7,
    corr_min: float = 0.75,
    tile: int = 4096,
    max_iter: int = 15,
    tol_px: float = 0.002,
    sigma_max: float = 0.5,
    affine_max: float = 0.25,
    max_shift: float | None = None,
) -> LsmResult:
    """LSM coarse to fine from pyramid level ``start`` down to level ``stop`` (full
    resolution by default).

    ``ref_xy0`` (n, 2): reference points, level-0 pixels (fixed: at level ``k``
    the template is centred at ``full_to_level(ref_xy0, k)``);
    ``search_xy_approx`` (n, 2): approximate search positions in level-``start``
    pixels; ``affine0`` (n, 2, 2) approximate ``A`` (identity when None; ``A``
    is the same at every level, both images being reduced alike). At each level
    the previous level's search position is mapped down
    (``full_to_level(level_to_full(xy, k + 1), k)``) and LSM refines it. Points
    are processed in groups by ``tile x tile`` tile of the reference and of the
    search positions, reading only windows around each group (memory bounded by
    the tile size). A point that fails at any level stops there and is reported
    not ok with that level's reason (its ``xy`` mapped to level 0). The other
    keywords are :func:`lsm`'s, at every level (``sigma_max`` in that level's
    pixels; ``affine_max`` against the previous level's ``A``; ``tol_px`` at
    full resolution, :data:`COARSE_TOL_PX` above it; ``max_shift`` bounds the
    move at the start level, ``half`` when None, and is :data:`FINE_SHIFT_PX`
    below it). The noise model stays at every level: without its correction of
    pixel locking the iteration can swing between neighbouring half pixels and
    not converge. Returns the :class:`LsmResult` with positions in level-0 pixels
    (``iterations`` summed over levels; ``cov`` and ``sigma`` in level-``stop``
    pixels).
    """
    if not 0 <= stop <= start:
        raise ValueError(f"levels run from start down to stop: got start {start}, stop {stop}")
    start_shift = float(half) if max_shift is None else float(max_shift)
    ref_xy0 = np.asarray(ref_xy0, dtype=float).reshape(-1, 2)
    n = len(ref_xy0)
    xy = np.asarray(search_xy_approx, dtype=float).reshape(n, 2).copy()
    A = (
        np.tile(np.eye(2), (n, 1, 1))
        if affine0 is None
        else np.array(np.broadcast_to(np.asarray(affine0, dtype=float), (n, 2, 2)))
    )
    opts = dict(
        max_iter=max_iter,
        tol_px=tol_px,
        corr_min=corr_min,
        sigma_max=sigma_max,
        affine_max=affine_max,
    )
    out = LsmResult.empty(n)
    alive = np.ones(n, dtype=bool)
    total_iter = np.zeros(n, dtype=int)
    for level in range(start, stop - 1, -1):
        if level < start:
            xy = full_to_level(level_to_full(xy, level + 1), level)
        rxy = full_to_level(ref_xy0, level)
        res = LsmResult.empty(n)
        res.xy[:] = xy
        res.affine[:] = A
        idx_all = np.flatnonzero(alive)
        # group by (ref tile, search tile)
        key = np.concatenate(
            [np.floor(rxy[idx_all] / tile), np.floor(np.nan_to_num(xy[idx_all]) / tile)], axis=1
        ).astype(np.int64)
        if idx_all.size:
            _, inv = np.unique(key, axis=0, return_inverse=True)
            inv = inv.ravel()
            order = np.argsort(inv, kind="stable")
            splits = np.flatnonzero(np.diff(inv[order])) + 1
            for grp in np.split(idx_all[order], splits):
                coarse = max(tol_px, COARSE_TOL_PX)
                lv_opts = {
                    **opts,
                    "max_shift": start_shift if level == start else FINE_SHIFT_PX,
                    **({} if level == 0 else {"tol_px": coarse}),
                }
                r = _track_group(ref, search, level, rxy[grp], xy[grp], A[grp], half, lv_opts)
                res.put(grp, r)
        total_iter += res.iterations
        failed = alive & ~res.ok
        out.put(failed, _subset(res, failed))
        out.xy[failed] = level_to_full(res.xy[failed], level)
        alive &= res.ok
        xy = np.where(alive[:, None], res.xy, xy)
        A = np.where(alive[:, None, None], res.affine, A)
        if level == stop:
            out.put(alive, _subset(res, alive))
            out.xy[alive] = level_to_full(res.xy[alive], level)
    out.iterations = total_iter
    return out


def _subset(r: LsmResult, sel) -> LsmResult:
    """The points ``sel`` (mask or indices) of ``r``."""
    return LsmResult(**{k: getattr(r, k)[sel] for k in r.__dataclass_fields__})


#: Pixels between a patch's samples and its neighbours in the atlas (spline prefilter reach).
ATLAS_MARGIN = 8

#: Largest move (pixels of the level) below the start level: a finer level refines what the
#: coarser one found (within a pixel or so); a point that moves further has jumped to another
#: feature. It also bounds the search atlas's patches (less prefiltering).
FINE_SHIFT_PX = 3.0

#: Convergence tolerance (pixels of the level) above full resolution: a coarse level only
#: seeds the next, whose convergence radius (2 px) is far larger than twice this.
COARSE_TOL_PX = 0.05


def _atlas(window: np.ndarray, c0: int, r0: int, xy: np.ndarray, m: int):
    """The patches of ``window`` (origin ``c0, r0``) around the points ``xy``, side by side.

    Each point gets the ``(2 m + 1)^2`` patch centred on its pixel; the patches
    are laid out in a grid (an atlas) whose cubic-spline coefficients are
    computed at once, so the prefilter's cost grows with the number of points,
    not with the area the points are spread over. The prefilter runs across
    neighbouring patches, but its influence decays by 0.268 per pixel and every
    sample lies at least ``m - (reach + max_shift)`` >= :data:`ATLAS_MARGIN` pixels
    inside its own patch (relative error 0.268^8 < 3e-5: below 0.01 DN of an
    8-bit image). Returns the :class:`SplineImage` and, per point,
    the integer offset (n x 2) from window-level pixel coordinates to atlas
    coordinates (sub-pixel fractions are kept).
    """
    n = len(xy)
    S = 2 * m + 1
    fc = np.floor(xy[:, 0]).astype(np.int64) - m  # patch origins, level pixels
    fr = np.floor(xy[:, 1]).astype(np.int64) - m
    ar = np.arange(S)
    rows = (fr - r0)[:, None, None] + ar[None, :, None]
    cols = (fc - c0)[:, None, None] + ar[None, None, :]
    rows = np.clip(rows, 0, window.shape[0] - 1)
    cols = np.clip(cols, 0, window.shape[1] - 1)
    patches = window[rows, cols]  # (n, S, S)
    ncol = int(np.ceil(np.sqrt(n)))
    nrow = -(-n // ncol)
    grid = np.zeros((nrow * ncol, S, S), dtype=np.float32)
    grid[:n] = patches
    atlas = grid.reshape(nrow, ncol, S, S).transpose(0, 2, 1, 3).reshape(nrow * S, ncol * S)
    k = np.arange(n)
    off = np.column_stack([(k % ncol) * S - fc, (k // ncol) * S - fr]).astype(float)
    return SplineImage(atlas, 0, 0), off


def _track_group(ref, search, level, rxy, sxy, A, half, opts) -> LsmResult:
    """LSM of one group of points at one level, windows read around the group.

    Templates reaching outside the reference image, and final search patches
    reaching outside the search image, are ``OUTSIDE`` (never measured on the
    source's edge padding)."""
    h_r, w_r = ref.shape(level)
    h_s, w_s = search.shape(level)
    res = LsmResult.empty(len(rxy))
    res.xy[:] = sxy
    res.affine[:] = A
    in_ref = (
        (rxy[:, 0] >= half)
        & (rxy[:, 1] >= half)
        & (rxy[:, 0] <= w_r - 1 - half)
        & (rxy[:, 1] <= h_r - 1 - half)
        & np.all(np.isfinite(sxy), axis=1)
    )
    res.reason[~in_ref] = LsmReason.OUTSIDE
    if not in_ref.any():
        return res
    rxy, sxy, A = rxy[in_ref], sxy[in_ref], A[in_ref]
    mref = half + ATLAS_MARGIN
    c0 = int(np.floor(rxy[:, 0].min())) - mref
    r0 = int(np.floor(rxy[:, 1].min())) - mref
    c1 = int(np.ceil(rxy[:, 0].max())) + mref
    r1 = int(np.ceil(rxy[:, 1].max())) + mref
    win_r = ref.read(level, c0, r0, c1 - c0 + 1, r1 - r0 + 1)
    spline_r, off_r = _atlas(win_r, c0, r0, rxy, mref)
    reach = float(np.abs(A).sum(axis=2).max()) * half
    ms = int(np.ceil(reach + opts["max_shift"] + ATLAS_MARGIN))
    c0 = int(np.floor(sxy[:, 0].min())) - ms
    r0 = int(np.floor(sxy[:, 1].min())) - ms
    c1 = int(np.ceil(sxy[:, 0].max())) + ms
    r1 = int(np.ceil(sxy[:, 1].max())) + ms
    win_s = search.read(level, c0, r0, c1 - c0 + 1, r1 - r0 + 1)
    spline_s, off_s = _atlas(win_s, c0, r0, sxy, ms)
    sub = lsm(
        spline_r,
        rxy + off_r,
        spline_s,
        sxy + off_s,
        A,
        half=half,
        **opts,
    )
    sub.xy = sub.xy - off_s
    corners = np.array([[-half, -half], [half, -half], [-half, half], [half, half]], float)
    sc = sub.xy[:, None, :] + np.einsum("nab,cb->nca", sub.affine, corners)
    with np.errstate(invalid="ignore"):
        in_s = np.all(
            (sc[..., 0] >= 0)
            & (sc[..., 1] >= 0)
            & (sc[..., 0] <= w_s - 1)
            & (sc[..., 1] <= h_s - 1),
            axis=1,
        )
    bad = sub.ok & ~in_s
    sub.reason[bad] = LsmReason.OUTSIDE
    sub.ok &= ~bad
    res.put(np.flatnonzero(in_ref), sub)
    return res
