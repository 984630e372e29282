"""The bilinear residual height correction ``dpZ = A x + B y + C x y + D``.

After the photo orientation, the heights read at control points where the
parallaxes vanish (``Z_model``) still differ a little from the control heights
(the optical plates are stepped finer than the digitised planimetry, so these
residual height parallaxes are worth adjusting). The seed adjusts them with a
bilinear surface: A tilts the model in x, B in y, C takes up a differential
omega warp and D the bias in height.

Conventions
-----------
* ``dpZ = Z_control - Z_model`` in metres: a corrected height is
  ``Z_model + dpZ(X, Y)`` (:meth:`HeightCorrection.correct`), and the height to
  drive the plates to for a wanted (corrected) height is ``Z - dpZ(X, Y)``
  (:meth:`HeightCorrection.uncorrect`).
* ``x`` and ``y`` are **centred and normalised** ground coordinates,
  ``x = (X - Xc) / scale_m``, ``y = (Y - Yc) / scale_m``, where ``(Xc, Yc)``
  is the centroid of the fitting points and ``scale_m`` their RMS distance
  from it. This keeps the normal equations well conditioned with LV95
  coordinates (millions of metres) and makes A, B, C, D all metres of height
  (A = height change over one ``scale_m`` eastwards).

The fit is ordinary least squares over at least four points that are not
collinear (and do not lie on two lines through the centroid parallel to the
axes, which would leave C undetermined).

Examples
--------
>>> xy = [[0, 0], [1000, 0], [0, 1000], [1000, 1000], [500, 500]]
>>> dz = [0.1, 0.3, 0.2, 0.4, 0.25]
>>> fit = fit_height_correction(xy, dz)
>>> round(float(fit.correction.dpz(500.0, 500.0)), 6)
0.25
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from apygis.errors import DegenerateGeometryError, OrientationError
from apygis.orient._fields import finite_fields

__all__ = ["HeightCorrection", "HeightCorrectionFit", "fit_height_correction"]


@dataclass(frozen=True)
class HeightCorrection:
    """``dpZ = A x + B y + C x y + D`` with ``x = (X - Xc)/scale_m``, ``y = (Y - Yc)/scale_m``.

    All coefficients are metres of height; ``Xc``, ``Yc``, ``scale_m`` in
    ground metres.
    """

    A: float
    B: float
    C: float
    D: float
    Xc: float = 0.0
    Yc: float = 0.0
    scale_m: float = 1.0

    def __post_init__(self):
        names = ("A", "B", "C", "D", "Xc", "Yc", "scale_m")
        finite_fields(self, names, prefix="height correction ")
        if self.scale_m <= 0:
            raise OrientationError("height correction scale_m must be positive")

    @classmethod
    def zero(cls) -> HeightCorrection:
        """No correction."""
        return cls(0.0, 0.0, 0.0, 0.0)

    def dpz(self, X, Y):
        """The correction ``dpZ`` at ground positions (arrays broadcast), metres."""
        x = (np.asarray(X, dtype=float) - self.Xc) / self.scale_m
        y = (np.asarray(Y, dtype=float) - self.Yc) / self.scale_m
        return self.A * x + self.B * y + self.C * x * y + self.D

    def correct(self, X, Y, Z_model):
        """``Z_model + dpZ(X, Y)``: the corrected height of a model reading."""
        return np.asarray(Z_model, dtype=float) + self.dpz(X, Y)

    def uncorrect(self, X, Y, Z):
        """``Z - dpZ(X, Y)``: the model height that reads as ``Z`` once corrected."""
        return np.asarray(Z, dtype=float) - self.dpz(X, Y)

    def to_dict(self) -> dict:
        """JSON-ready dict, keys as the field names."""
        return {k: getattr(self, k) for k in ("A", "B", "C", "D", "Xc", "Yc", "scale_m")}

    @classmethod
    def from_dict(cls, d) -> HeightCorrection:
        """The inverse of :meth:`to_dict`."""
        return cls(d["A"], d["B"], d["C"], d["D"], d["Xc"], d["Yc"], d["scale_m"])


@dataclass(frozen=True, eq=False)
class HeightCorrectionFit:
    """Result of :func:`fit_height_correction`.

    Attributes
    ----------
    correction : HeightCorrection
    residuals : numpy.ndarray, shape (n,)
        ``dpZ(X, Y) - dz`` per point, metres.
    rmse : float
        ``sqrt(mean(residuals**2))``, metres.
    sigma0 : float
        ``sqrt(sum(v**2) / (n - 4))``; nan for four points.
    covariance : numpy.ndarray, shape (4, 4)
        Of ``(A, B, C, D)``, ``sigma0**2 (A^T A)^-1``; nan for four points.
    """

    correction: HeightCorrection
    residuals: np.ndarray
    rmse: float
    sigma0: float
    covariance: np.ndarray


def fit_height_correction(xy, dz) -> HeightCorrectionFit:
    """Fit ``dpZ = A x + B y + C x y + D`` to height differences by least squares.

    Parameters
    ----------
    xy : array_like, shape (n, 2)
        Ground ``(X, Y)`` of the points, metres.
    dz : array_like, shape (n,)
        ``Z_control - Z_model`` at the points, metres.

    Returns
    -------
    HeightCorrectionFit

    Raises
    ------
    DegenerateGeometryError
        Fewer than four points, or a geometry that does not determine the
        four coefficients (collinear points, ...).
    """
    P = np.asarray(xy, dtype=float)
    z = np.asarray(dz, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or z.shape != (len(P),):
        raise OrientationError(f"xy must be (n, 2) and dz (n,), got {P.shape} and {z.shape}")
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(z))):
        raise OrientationError("height correction points must be finite")
    if len(P) < 4:
        raise DegenerateGeometryError(
            f"the height correction dpZ = Ax + By + Cxy + D needs at least 4 points, got {len(P)}"
        )
    Xc, Yc = P.mean(axis=0)
    scale = float(np.sqrt(((P - (Xc, Yc)) ** 2).sum(axis=1).mean()))
    if not scale > 0:
        raise DegenerateGeometryError("the height correction points all coincide")
    x = (P[:, 0] - Xc) / scale
    y = (P[:, 1] - Yc) / scale
    A = np.column_stack([x, y, x * y, np.ones_like(x)])
    sv = np.linalg.svd(A, compute_uv=False)
    if sv[-1] < 1e-8 * sv[0]:
        raise DegenerateGeometryError(
            "the height correction points do not determine A, B, C, D "
            "(collinear, or on two axis-parallel lines); spread them over the model"
        )
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    corr = HeightCorrection(coef[0], coef[1], coef[2], coef[3], Xc=Xc, Yc=Yc, scale_m=scale)
    res = A @ coef - z
    dof = len(z) - 4
    sigma0 = float(np.sqrt(res @ res / dof)) if dof > 0 else math.nan
    cov = sigma0**2 * np.linalg.inv(A.T @ A)
    return HeightCorrectionFit(corr, res, float(np.sqrt(np.mean(res**2))), sigma0, cov)
