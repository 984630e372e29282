"""Least squares for photogrammetry: the one core every adjustment in apygis uses.

Problem: ``min |f(x)|**2`` where ``f(x) = W^(1/2) (model(x) - observations)``
(the caller weights its residuals, so ``f`` is dimensionless and sigma0 = 1 a
priori). Gauss-Newton: each step solves the linearised problem ``J dx = -f``.

Where the least-squares core lives (a decision of issue 10): here, in
``apygis.orient.lsq``, public. ``orient`` is the lowest layer that adjusts
anything, and the aerotriangulation (which imports ``orient``) builds its
bundle adjustment on it:

- :func:`gauss_newton` is the dense solver for small problems (an orientation
  has at most a few dozen unknowns): each step goes through the singular value
  decomposition of the Jacobian with its columns scaled to unit length (so
  metres, radians and scale factors mix safely); a relative singular value
  below ``rank_tol`` means that the data do not determine the parameters, and
  the error names those in the weakest direction. The cofactor matrix
  ``(J^T J)^-1`` of the solution gives the precisions.
- The bundle adjustment (thousands of photos, hundreds of thousands of points)
  cannot form a dense Jacobian: :mod:`apygis.orient.bundle` accumulates the
  sparse normal equations block by block (6 x 6 orientation blocks, 3 x 3 point
  blocks), reduces them to the orientations by the Schur complement and solves
  them by a sparse factorisation; its :class:`~apygis.orient.bundle.BundleSolution`
  carries the same figures (parameters, residuals, ``sigma0``, redundancy,
  precisions), so that reports and tests treat both alike.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from apygis.errors import ConvergenceError, DegenerateGeometryError

__all__ = ["LsqSolution", "gauss_newton"]


@dataclass(frozen=True, eq=False)
class LsqSolution:
    """A converged least-squares solution.

    ``x`` the parameters, ``f`` the weighted residuals ``model - observations``
    at ``x``, ``J`` the Jacobian of ``f`` there, ``cofactor`` ``(J^T J)^-1``
    (multiply by ``sigma0**2`` for the covariance), ``iterations`` the steps
    taken. ``redundancy`` is observations minus unknowns; with none, nothing
    is checked and ``sigma0`` is NaN.
    """

    x: np.ndarray
    f: np.ndarray  # model - observations at x (weighted)
    J: np.ndarray
    cofactor: np.ndarray  # (J^T J)^-1
    iterations: int

    @property
    def redundancy(self) -> int:
        return self.J.shape[0] - self.J.shape[1]

    @property
    def sigma0(self) -> float:
        r = self.redundancy
        return float(np.sqrt(self.f @ self.f / r)) if r > 0 else float("nan")


def _svd_checked(J: np.ndarray, names: Sequence[str], what: str, rank_tol: float):
    norms = np.sqrt((J * J).sum(axis=0))
    zero = [n for n, v in zip(names, norms, strict=True) if not v > 0]
    if zero:
        raise DegenerateGeometryError(
            f"{what}: the data do not determine {', '.join(zero)} (no observation depends on it)"
        )
    Js = J / norms
    U, s, Vt = np.linalg.svd(Js, full_matrices=False)
    if not np.all(np.isfinite(s)) or s[-1] < rank_tol * s[0]:
        weak = np.abs(Vt[-1])
        names_w = [n for n, w in zip(names, weak, strict=True) if w > 0.25 * weak.max()]
        raise DegenerateGeometryError(
            f"{what}: the geometry of the points does not determine "
            f"{', '.join(names_w)} (they are not separable); add or spread points, "
            "or fix a parameter"
        )
    return norms, U, s, Vt


def gauss_newton(
    fun: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    x0,
    names: Sequence[str],
    *,
    what: str = "orientation",
    tol: float = 1e-11,
    max_iter: int = 50,
    rank_tol: float = 1e-10,
) -> LsqSolution:
    """Iterate ``x += dx`` with ``J dx = -f`` until ``max |J dx|`` is negligible.

    Negligible: below ``tol`` (observation units) plus the round-off floor
    ``1e-13 max(|J| |x|)``, or below ``1e-9`` of the RMS residual.
    """
    x = np.array(x0, dtype=float)
    m = None
    for it in range(1, max_iter + 1):
        f, J = fun(x)
        if m is None:
            m = len(f)
            if m < J.shape[1]:
                raise DegenerateGeometryError(
                    f"{what}: {m} observations cannot determine {J.shape[1]} parameters "
                    f"({', '.join(names)})"
                )
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(J))):
            raise ConvergenceError(f"{what}: the iteration diverged (non-finite values)")
        norms, U, s, Vt = _svd_checked(J, names, what, rank_tol)
        dz = -(Vt.T @ ((U.T @ f) / s))
        dx = dz / norms
        x = x + dx
        change = float(np.max(np.abs(J @ dx)))
        rms = float(np.sqrt(np.mean(f * f)))
        # round-off floor: the model changes by about eps * |J| |x| when x is stored
        floor = 1e-13 * float(np.max(np.abs(J) @ np.abs(x)))
        if change < tol + floor or (it > 2 and change < 1e-9 * rms):
            f, J = fun(x)
            norms, U, s, Vt = _svd_checked(J, names, what, rank_tol)
            Q = (Vt.T / s**2) @ Vt / np.outer(norms, norms)
            return LsqSolution(x, f, J, Q, it)
    raise ConvergenceError(
        f"{what}: Gauss-Newton did not converge in {max_iter} iterations; "
        "check the approximate values and the measurements"
    )
