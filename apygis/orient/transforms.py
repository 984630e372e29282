"""Map orientation: tablet-to-ground transforms (conformal, affine, bilinear).

The map lies on the digitiser tablet; the tablet gives positions ``(x, y)`` in
tablet millimetres (``tablet_mm``), the transforms turn them into ground
``(X, Y)`` in metres (the photogrammetric conventions of
:mod:`apygis.orient.rotation` do not enter here: both systems are planar,
right-handed, x/X east-ish and y/Y north-ish).

Models (the seed's ORIENTATION section):

conformal (Helmert, 4 parameters)
    ``X = a x - b y + c``, ``Y = b x + a y + d``; at least two points, each
    measured twice (the double measurement gives the pointing precision).
affine (6 parameters)
    ``X = a x + b y + c``, ``Y = d x + e y + f`` (the order of the
    ``affine`` library); at least three different, non-collinear points. It
    takes up most of the shrinkage of a paper map.
bilinear (8 parameters)
    ``X = a0 + a1 x + a2 y + a3 x y``, ``Y = b0 + b1 x + b2 y + b3 x y``;
    four different points (a quadrangle), more by least squares. The inverse
    is computed by Newton's method (vectorised).

Each transform is an immutable value (a frozen dataclass) with
:meth:`forward`, :meth:`inverse`, :meth:`jacobian`, :meth:`to_dict` and
``from_dict``. :func:`fit_map_transform` estimates one from measured control
points by least squares (on centred and scaled tablet coordinates, for
conditioning) and returns a :class:`MapOrientation` with the residuals
``transform(tablet) - control`` per point, the RMSE in position
``sqrt(mean(vX**2 + vY**2))``, the standard error of unit weight and the
pointing precision from the repeated measurements.

Examples
--------
>>> t = ConformalTransform.from_scale_rotation(5.0, 0.0, 2683000.0, 1248000.0)
>>> t.forward([100.0, 200.0]).tolist()
[2683500.0, 1249000.0]
>>> t.inverse([2683500.0, 1249000.0]).tolist()
[100.0, 200.0]
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import Field, dataclass, fields
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from apygis.errors import (
    ConvergenceError,
    DegenerateGeometryError,
    MeasurementError,
    OrientationError,
)
from apygis.orient._fields import finite_fields

__all__ = [
    "MODELS",
    "AffineTransform",
    "BilinearTransform",
    "ConformalTransform",
    "MapOrientation",
    "MirroredTransformWarning",
    "fit_map_transform",
    "transform_from_dict",
]

#: Minimum number of different points per model.
MODELS = {"conformal": 2, "affine": 3, "bilinear": 4}


class MirroredTransformWarning(UserWarning):
    """The fitted map transform mirrors the tablet (its Jacobian determinant is negative).

    A tablet and a map are both right-handed, so a mirror means that x and y
    were swapped (or one axis reversed) in the measurements, the control or
    the tablet set-up. The fit is returned (``MapOrientation.mirrored`` is
    true) because a deliberately mirrored set-up is possible.
    """


def _xy(a, what="points"):
    a = np.asarray(a, dtype=float)
    if a.shape[-1:] != (2,):
        raise OrientationError(f"{what} must have shape (..., 2), got {a.shape}")
    return a


class _Transform:
    """Shared behaviour of the transform value types."""

    model: str = ""

    if TYPE_CHECKING:  # every transform is a dataclass with these (see the subclasses)
        __dataclass_fields__: ClassVar[dict[str, Field[Any]]]

        def forward(self, points) -> np.ndarray: ...

        def jacobian(self, points) -> np.ndarray: ...

    def __post_init__(self):
        names = [f.name for f in fields(self)]
        finite_fields(self, names, prefix=f"{self.model} coefficient ")

    def __call__(self, points):
        return self.forward(points)

    def to_dict(self) -> dict:
        """``{"model": name, coefficient: value, ...}`` (JSON-ready)."""
        d = {"model": self.model}
        d.update({f.name: getattr(self, f.name) for f in fields(self)})
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> _Transform:
        """The inverse of :meth:`to_dict`."""
        if d.get("model", cls.model) != cls.model:
            raise OrientationError(f"not a {cls.model} transform: model {d.get('model')!r}")
        missing = [f.name for f in fields(cls) if f.name not in d]
        if missing:
            raise OrientationError(f"{cls.model} transform lacks {', '.join(missing)}")
        return cls(**{f.name: d[f.name] for f in fields(cls)})

    @property
    def n_parameters(self) -> int:
        return len(fields(self))

    def mean_scale(self, at=(0.0, 0.0)) -> float:
        """``sqrt(|det J|)`` at a tablet position: ground metres per tablet millimetre."""
        return float(math.sqrt(abs(np.linalg.det(self.jacobian(at)))))


@dataclass(frozen=True)
class ConformalTransform(_Transform):
    """``X = a x - b y + c``, ``Y = b x + a y + d`` (scale and rotation, no shear)."""

    a: float
    b: float
    c: float
    d: float
    model = "conformal"

    @classmethod
    def from_scale_rotation(cls, scale, rotation_rad, X0=0.0, Y0=0.0) -> ConformalTransform:
        """From scale (ground per tablet unit), rotation (rad, counter-clockwise) and shift."""
        return cls(
            scale * math.cos(rotation_rad), scale * math.sin(rotation_rad), float(X0), float(Y0)
        )

    @property
    def scale(self) -> float:
        """Ground metres per tablet millimetre."""
        return math.hypot(self.a, self.b)

    @property
    def rotation_rad(self) -> float:
        """Rotation of the tablet axes to the ground axes, counter-clockwise."""
        return math.atan2(self.b, self.a)

    def forward(self, points):
        """Tablet ``(..., 2)`` -> ground ``(..., 2)``."""
        p = _xy(points)
        out = np.empty(p.shape)
        out[..., 0] = self.a * p[..., 0] - self.b * p[..., 1] + self.c
        out[..., 1] = self.b * p[..., 0] + self.a * p[..., 1] + self.d
        return out

    def forward_xy(self, x: float, y: float) -> tuple[float, float]:
        """:meth:`forward` of one position, as floats (see :meth:`_Transform.forward_xy`)."""
        x, y = float(x), float(y)
        return self.a * x - self.b * y + self.c, self.b * x + self.a * y + self.d

    def inverse(self, points):
        """Ground ``(..., 2)`` -> tablet ``(..., 2)``."""
        p = _xy(points)
        k = self.a * self.a + self.b * self.b
        if k == 0:
            raise DegenerateGeometryError("the conformal transform has scale 0: no inverse")
        u, v = p[..., 0] - self.c, p[..., 1] - self.d
        out = np.empty(p.shape)
        out[..., 0] = (self.a * u + self.b * v) / k
        out[..., 1] = (-self.b * u + self.a * v) / k
        return out

    def jacobian(self, points):
        """``d(X, Y)/d(x, y)``, shape ``(..., 2, 2)``."""
        p = _xy(points)
        J = np.empty((*p.shape[:-1], 2, 2))
        J[..., 0, 0], J[..., 0, 1] = self.a, -self.b
        J[..., 1, 0], J[..., 1, 1] = self.b, self.a
        return J


@dataclass(frozen=True)
class AffineTransform(_Transform):
    """``X = a x + b y + c``, ``Y = d x + e y + f``."""

    a: float
    b: float
    c: float
    d: float
    e: float
    f: float
    model = "affine"

    def forward(self, points):
        """Tablet ``(..., 2)`` -> ground ``(..., 2)``."""
        p = _xy(points)
        out = np.empty(p.shape)
        out[..., 0] = self.a * p[..., 0] + self.b * p[..., 1] + self.c
        out[..., 1] = self.d * p[..., 0] + self.e * p[..., 1] + self.f
        return out

    def forward_xy(self, x: float, y: float) -> tuple[float, float]:
        """:meth:`forward` of one position, as floats (see :meth:`_Transform.forward_xy`)."""
        x, y = float(x), float(y)
        return self.a * x + self.b * y + self.c, self.d * x + self.e * y + self.f

    def inverse(self, points):
        """Ground ``(..., 2)`` -> tablet ``(..., 2)``."""
        p = _xy(points)
        det = self.a * self.e - self.b * self.d
        if det == 0:
            raise DegenerateGeometryError("the affine transform is singular: no inverse")
        u, v = p[..., 0] - self.c, p[..., 1] - self.f
        out = np.empty(p.shape)
        out[..., 0] = (self.e * u - self.b * v) / det
        out[..., 1] = (-self.d * u + self.a * v) / det
        return out

    def jacobian(self, points):
        """``d(X, Y)/d(x, y)``, shape ``(..., 2, 2)``."""
        p = _xy(points)
        J = np.empty((*p.shape[:-1], 2, 2))
        J[..., 0, 0], J[..., 0, 1] = self.a, self.b
        J[..., 1, 0], J[..., 1, 1] = self.d, self.e
        return J


@dataclass(frozen=True)
class BilinearTransform(_Transform):
    """``X = a0 + a1 x + a2 y + a3 x y``, ``Y = b0 + b1 x + b2 y + b3 x y``."""

    a0: float
    a1: float
    a2: float
    a3: float
    b0: float
    b1: float
    b2: float
    b3: float
    model = "bilinear"

    def forward(self, points):
        """Tablet ``(..., 2)`` -> ground ``(..., 2)``."""
        p = _xy(points)
        x, y = p[..., 0], p[..., 1]
        xy = x * y
        out = np.empty(p.shape)
        out[..., 0] = self.a0 + self.a1 * x + self.a2 * y + self.a3 * xy
        out[..., 1] = self.b0 + self.b1 * x + self.b2 * y + self.b3 * xy
        return out

    def forward_xy(self, x: float, y: float) -> tuple[float, float]:
        """:meth:`forward` of one position, as floats (see :meth:`_Transform.forward_xy`)."""
        x, y = float(x), float(y)
        xy = x * y
        return (
            self.a0 + self.a1 * x + self.a2 * y + self.a3 * xy,
            self.b0 + self.b1 * x + self.b2 * y + self.b3 * xy,
        )

    def jacobian(self, points):
        """``d(X, Y)/d(x, y)``, shape ``(..., 2, 2)``."""
        p = _xy(points)
        x, y = p[..., 0], p[..., 1]
        J = np.empty((*p.shape[:-1], 2, 2))
        J[..., 0, 0] = self.a1 + self.a3 * y
        J[..., 0, 1] = self.a2 + self.a3 * x
        J[..., 1, 0] = self.b1 + self.b3 * y
        J[..., 1, 1] = self.b2 + self.b3 * x
        return J

    def inverse(self, points, *, tol_mm: float = 1e-10, max_iter: int = 50):
        """Ground ``(..., 2)`` -> tablet ``(..., 2)`` by Newton's method.

        Starts from the inverse of the affine part ``(a0, a1, a2, b0, b1,
        b2)`` and iterates ``t -= J(t)^-1 (F(t) - P)`` for all points at once
        until every step is below ``tol_mm`` (relative to 1 + |t|).

        Raises
        ------
        ConvergenceError
            If a point's Jacobian is singular or Newton does not converge
            (the point lies beyond the fold of the bilinear surface).
        """
        P = _xy(points)
        det0 = self.a1 * self.b2 - self.a2 * self.b1
        if det0 == 0:
            raise DegenerateGeometryError("the bilinear transform's linear part is singular")
        u, v = P[..., 0] - self.a0, P[..., 1] - self.b0
        t = np.empty(P.shape)
        t[..., 0] = (self.b2 * u - self.a2 * v) / det0
        t[..., 1] = (-self.b1 * u + self.a1 * v) / det0
        for _ in range(max_iter):
            r = self.forward(t) - P
            J = self.jacobian(t)
            det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
            if np.any(det == 0) or not np.all(np.isfinite(det)):
                raise ConvergenceError("bilinear inverse: singular Jacobian at some points")
            dx = (J[..., 1, 1] * r[..., 0] - J[..., 0, 1] * r[..., 1]) / det
            dy = (-J[..., 1, 0] * r[..., 0] + J[..., 0, 0] * r[..., 1]) / det
            t[..., 0] -= dx
            t[..., 1] -= dy
            step = np.maximum(np.abs(dx), np.abs(dy)) / (1.0 + np.abs(t).max(axis=-1))
            if np.all(step < tol_mm):
                return t
        raise ConvergenceError(f"bilinear inverse did not converge in {max_iter} Newton iterations")


_TYPES: dict[str, type[_Transform]] = {
    "conformal": ConformalTransform,
    "affine": AffineTransform,
    "bilinear": BilinearTransform,
}


def transform_from_dict(d: Mapping):
    """Rebuild a transform from its :meth:`to_dict` form (dispatch on ``"model"``).

    Examples
    --------
    >>> t = AffineTransform(5.0, 0.01, 2683000.0, -0.02, 5.0, 1248000.0)
    >>> transform_from_dict(t.to_dict()) == t
    True
    """
    try:
        cls = _TYPES[d["model"]]
    except (KeyError, TypeError):
        model = d.get("model") if isinstance(d, Mapping) else None
        raise OrientationError(
            f"unknown map transform model {model!r}; expected one of {', '.join(_TYPES)}"
        ) from None
    return cls.from_dict(d)


@dataclass(frozen=True, eq=False)
class MapOrientation:
    """The result of :func:`fit_map_transform`.

    Attributes
    ----------
    transform : ConformalTransform or AffineTransform or BilinearTransform
    ids : tuple of str
        Point ids used, in the order of their first measurement.
    tablet_mm : numpy.ndarray, shape (n, 2)
        Mean measured tablet position per point.
    ground : numpy.ndarray, shape (n, 2)
        Control coordinates per point, metres.
    n_measurements : numpy.ndarray, shape (n,)
    residuals : numpy.ndarray, shape (n, 2)
        ``transform(tablet_mm) - ground`` per point, metres.
    rmse : float
        RMSE in position, ``sqrt(mean(vX**2 + vY**2))`` over the points,
        metres; nan when ``redundancy`` is 0 (an exact fit checks nothing).
    sigma0 : float
        Standard error of unit weight of one coordinate of one measurement,
        ``sqrt(sum(v**2) / (2 M - u))`` over all M measurements (ground
        metres); nan when ``redundancy`` is 0.
    pointing_sigma_mm : float
        Pointing precision of one tablet coordinate from the repeated
        measurements: ``sqrt(sum((t - mean)**2) / (2 (M - n)))``; nan if no
        point was measured twice.
    pointing_sigma : float
        The same in ground metres (times the transform's mean scale).
    rejected : tuple of str
        Ids rejected by the caller.
    redundancy : int
        ``2 n - u``: coordinates of the n different points beyond the ``u``
        unknowns of the model. With 0 (two conformal, three affine, four
        bilinear points) the transform fits the control exactly whatever the
        errors: nothing is checked, and ``rmse`` and ``sigma0`` are nan
        (repeated measurements still give ``pointing_sigma_mm``).
    mirrored : bool
        The transform's Jacobian determinant at the centroid of the points is
        negative (a :class:`MirroredTransformWarning` was issued). A
        conformal transform cannot mirror; with three or more points its
        flag tells whether the best affine fit would.
    """

    transform: _Transform
    ids: tuple
    tablet_mm: np.ndarray
    ground: np.ndarray
    n_measurements: np.ndarray
    residuals: np.ndarray
    rmse: float
    sigma0: float
    pointing_sigma_mm: float
    pointing_sigma: float
    rejected: tuple = ()
    redundancy: int = 0
    mirrored: bool = False

    @property
    def model(self) -> str:
        return self.transform.model

    @property
    def checked(self) -> bool:
        """Whether the control checks the transform (redundancy > 0)."""
        return self.redundancy > 0

    def summary(self) -> dict:
        """Figures of merit (JSON-ready; nan figures become null in the file)."""
        return {
            "model": self.model,
            "points": len(self.ids),
            "redundancy": self.redundancy,
            "checked": self.checked,
            "rmse_m": self.rmse,
            "sigma0_m": self.sigma0,
            "pointing_sigma_mm": self.pointing_sigma_mm,
            "mirrored": self.mirrored,
            "rejected": list(self.rejected),
        }


def _design(model: str, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, int]:
    """Design matrix for the unknowns in normalised coordinates; rows X then Y."""
    n = len(u)
    one, zero = np.ones(n), np.zeros(n)
    if model == "conformal":  # (a, b, c, d)
        AX = np.column_stack([u, -v, one, zero])
        AY = np.column_stack([v, u, zero, one])
    elif model == "affine":  # (a, b, c, d, e, f)
        AX = np.column_stack([u, v, one, zero, zero, zero])
        AY = np.column_stack([zero, zero, zero, u, v, one])
    else:  # (a0, a1, a2, a3, b0, b1, b2, b3)
        base = np.column_stack([one, u, v, u * v])
        AX = np.hstack([base, np.zeros((n, 4))])
        AY = np.hstack([np.zeros((n, 4)), base])
    return np.vstack([AX, AY]), AX.shape[1]


def _denormalise(model: str, p: np.ndarray, xm: float, ym: float, s: float, Gx: float, Gy: float):
    """Coefficients for raw tablet coordinates from those for ``u = (x-xm)/s``, ``v = (y-ym)/s``."""
    if model == "conformal":
        a, b, c, d = p
        a, b = a / s, b / s
        return ConformalTransform(a, b, Gx + c - a * xm + b * ym, Gy + d - b * xm - a * ym)
    if model == "affine":
        a, b, c, d, e, f = p
        a, b, d, e = a / s, b / s, d / s, e / s
        return AffineTransform(a, b, Gx + c - a * xm - b * ym, d, e, Gy + f - d * xm - e * ym)

    def bil(k0, k1, k2, k3, G):
        c3 = k3 / (s * s)
        c1 = k1 / s - c3 * ym
        c2 = k2 / s - c3 * xm
        c0 = G + k0 - k1 * xm / s - k2 * ym / s + c3 * xm * ym
        return c0, c1, c2, c3

    return BilinearTransform(*bil(p[0], p[1], p[2], p[3], Gx), *bil(p[4], p[5], p[6], p[7], Gy))


def fit_map_transform(
    ids: Iterable,
    tablet_mm,
    control: Mapping,
    model: str = "affine",
    *,
    reject: Iterable = (),
) -> MapOrientation:
    """Orient the map: fit a tablet-to-ground transform to measured control points.

    Least squares over all measurements (a point measured twice counts
    twice): minimise ``sum |T(t_k) - G_i|**2``. The unknowns are solved in
    tablet coordinates centred on their mean and scaled by their RMS distance
    from it, then converted back, so the normal equations stay well
    conditioned for any tablet origin.

    Parameters
    ----------
    ids : iterable of str
        Point id of each measurement (repeated for repeated measurements).
    tablet_mm : array_like, shape (M, 2)
        Measured tablet positions, millimetres.
    control : mapping of str to sequence
        Point id -> ``(X, Y[, Z])`` ground coordinates, metres.
    model : {"conformal", "affine", "bilinear"}
    reject : iterable of str
        Point ids to leave out (the seed: "points can now be rejected or
        added, followed by a recalculation"; re-run with another set).

    Returns
    -------
    MapOrientation

    Raises
    ------
    MeasurementError
        A measured point not in the control, a rejected id never measured, or
        (conformal) a point measured once.
    DegenerateGeometryError
        Too few different points for the model, or points that do not
        determine it (coincident, collinear, a degenerate quadrangle).

    Examples
    --------
    >>> control = {"1": (2683000.0, 1248000.0), "2": (2684000.0, 1248500.0)}
    >>> ids = ["1", "1", "2", "2"]
    >>> tab = [[100.0, 100.0], [100.02, 100.0], [300.0, 200.0], [300.0, 200.02]]
    >>> fit = fit_map_transform(ids, tab, control, "conformal")
    >>> round(fit.transform.scale, 3), fit.ids
    (5.0, ('1', '2'))
    """
    if model not in MODELS:
        raise OrientationError(f"unknown map model {model!r}; expected one of {', '.join(MODELS)}")
    ids = [str(i) for i in ids]
    t = np.asarray(tablet_mm, dtype=float)
    if t.ndim != 2 or t.shape != (len(ids), 2):
        raise OrientationError(
            f"tablet_mm must have shape ({len(ids)}, 2) to match the ids, got {t.shape}"
        )
    if not np.all(np.isfinite(t)):
        raise MeasurementError("tablet measurements must be finite numbers")
    reject = tuple(str(r) for r in reject)
    unknown = [r for r in reject if r not in ids]
    if unknown:
        raise MeasurementError(f"cannot reject point(s) {', '.join(unknown)}: never measured")
    keep = np.array([i not in reject for i in ids], dtype=bool)
    ids_k = [i for i, k in zip(ids, keep, strict=True) if k]
    t = t[keep]
    order = list(dict.fromkeys(ids_k))
    missing = [i for i in order if i not in control]
    if missing:
        raise MeasurementError(f"measured point(s) {', '.join(missing)} not in the control")
    index = {pid: k for k, pid in enumerate(order)}
    which = np.array([index[i] for i in ids_k], dtype=int)
    counts = np.bincount(which, minlength=len(order))
    if model == "conformal":
        once = [pid for pid, c in zip(order, counts, strict=True) if c < 2]
        if once:
            raise MeasurementError(
                f"point(s) {', '.join(once)} measured once; the conformal map orientation "
                "needs each point measured twice"
            )
    need = MODELS[model]
    if len(order) < need:
        raise DegenerateGeometryError(
            f"the {model} map orientation needs at least {need} different points, "
            f"got {len(order)}" + (f" ({', '.join(order)})" if order else "")
        )
    try:
        G = np.array([[float(control[p][0]), float(control[p][1])] for p in order])
    except (TypeError, ValueError, IndexError, OverflowError):
        raise MeasurementError("control coordinates must be pairs of finite numbers") from None
    if not np.all(np.isfinite(G)):
        raise MeasurementError("control coordinates must be finite")

    mean_t = np.zeros((len(order), 2))
    np.add.at(mean_t, which, t)
    mean_t /= counts[:, None]

    # Normalise: centre and RMS scale of the distinct points.
    xm, ym = mean_t.mean(axis=0)
    s = float(np.sqrt(((mean_t - (xm, ym)) ** 2).sum(axis=1).mean()))
    if not s > 1e-9 * (1.0 + abs(xm) + abs(ym)):
        raise DegenerateGeometryError(
            f"the points {', '.join(order)} all have the same tablet position"
        )
    Gm = G.mean(axis=0)
    u = (t[:, 0] - xm) / s
    v = (t[:, 1] - ym) / s
    A, _ = _design(model, u, v)
    Gk = G[which] - Gm
    obs = np.concatenate([Gk[:, 0], Gk[:, 1]])
    # Check the geometry on the distinct points.
    ud, vd = (mean_t[:, 0] - xm) / s, (mean_t[:, 1] - ym) / s
    Ad, _ = _design(model, ud, vd)
    sv = np.linalg.svd(Ad, compute_uv=False)
    if sv[-1] < 1e-8 * sv[0]:
        what = {
            "conformal": "two different positions",
            "affine": "three points that are not collinear",
            "bilinear": "four points forming a proper quadrangle (no three collinear)",
        }[model]
        raise DegenerateGeometryError(
            f"the {model} map orientation needs {what}; points {', '.join(order)} do not "
            "determine it"
        )
    # The ground side must span the plane too (else the transform is singular).
    gs = float(np.sqrt(((G - Gm) ** 2).sum(axis=1).mean()))
    if not gs > 1e-9 * (1.0 + float(np.abs(Gm).max())):
        raise DegenerateGeometryError(
            f"the control points {', '.join(order)} all have the same ground position: "
            "no map transform"
        )
    p, *_ = np.linalg.lstsq(A, obs, rcond=None)
    if not np.all(np.isfinite(p)):
        raise OrientationError(
            f"the {model} map orientation overflowed: the coordinates are too large"
        )
    transform = _denormalise(model, p, xm, ym, s, float(Gm[0]), float(Gm[1]))
    centre = np.array([xm, ym])
    det = float(np.linalg.det(transform.jacobian(centre)))
    if not abs(det) > 1e-10 * (gs / s) ** 2:
        raise DegenerateGeometryError(
            f"the {model} map transform is singular: the ground positions of points "
            f"{', '.join(order)} are collinear (or coincide) while their tablet positions are not"
        )
    mirrored = det < 0
    if model == "conformal" and len(order) >= 3:  # a conformal fit cannot show a mirror
        Aa, _ = _design("affine", ud, vd)
        Ga = G - Gm
        pa, *_ = np.linalg.lstsq(Aa, np.concatenate([Ga[:, 0], Ga[:, 1]]), rcond=None)
        mirrored = bool(pa[0] * pa[4] - pa[1] * pa[3] < 0)

    v_all = transform.forward(t) - G[which]
    res = transform.forward(mean_t) - G
    if not (np.all(np.isfinite(v_all)) and np.all(np.isfinite(res))):
        raise OrientationError(
            f"the {model} map orientation overflowed: the coordinates are too large"
        )
    redundancy = 2 * len(order) - transform.n_parameters
    if redundancy > 0:
        rmse = float(np.sqrt((res**2).sum(axis=1).mean()))
        dof = 2 * len(t) - transform.n_parameters
        sigma0 = float(np.sqrt((v_all**2).sum() / dof))
    else:  # an exact fit: residuals are 0 whatever the errors
        rmse = sigma0 = math.nan
    dev = t - mean_t[which]
    rep_dof = 2 * (len(t) - len(order))
    psig = float(np.sqrt((dev**2).sum() / rep_dof)) if rep_dof > 0 else math.nan
    if mirrored:
        warnings.warn(
            MirroredTransformWarning(
                f"the {model} map transform mirrors the tablet (x and y swapped, or an axis "
                f"reversed, in the measurements or the control?): points {', '.join(order)}"
            ),
            stacklevel=2,
        )
    return MapOrientation(
        transform=transform,
        ids=tuple(order),
        tablet_mm=mean_t,
        ground=G,
        n_measurements=counts,
        residuals=res,
        rmse=rmse,
        sigma0=sigma0,
        pointing_sigma_mm=psig,
        pointing_sigma=psig * transform.mean_scale((xm, ym)),
        rejected=reject,
        redundancy=redundancy,
        mirrored=bool(mirrored),
    )
