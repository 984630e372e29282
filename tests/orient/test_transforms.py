"""Map orientation: conformal, affine, bilinear transforms and their fit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from apygis.errors import (
    ApygisError,
    ConvergenceError,
    DegenerateGeometryError,
    MeasurementError,
)
from apygis.orient.transforms import (
    AffineTransform,
    BilinearTransform,
    ConformalTransform,
    fit_map_transform,
    transform_from_dict,
)

TRUE = {
    "conformal": ConformalTransform.from_scale_rotation(5.0, 0.0063, 2682700.0, 1246750.0),
    "affine": AffineTransform(4.9995, -0.0307, 2682701.3, 0.0320, 5.0075, 1246747.6),
    "bilinear": BilinearTransform(
        2682701.3, 4.9995, -0.0307, 2.0e-6, 1246747.6, 0.0320, 5.0075, -1.5e-6
    ),
}
TABLET = np.array(
    [
        [60, 50],
        [540, 47],
        [542, 367],
        [62, 369],
        [155, 341],
        [160, 70],
        [450, 340],
        [445, 75],
        [300, 200],
    ],
    dtype=float,
)


def _control(T, pts=TABLET):
    G = T.forward(pts)
    return {str(k + 1): (G[k, 0], G[k, 1], 500.0) for k in range(len(pts))}


def _twice(pts=TABLET):
    ids = [str(k + 1) for k in range(len(pts)) for _ in range(2)]
    return ids, np.repeat(pts, 2, axis=0)


@pytest.mark.parametrize("model", ["conformal", "affine", "bilinear"])
def test_exact_recovery(model):
    T = TRUE[model]
    ids, t = _twice()
    fit = fit_map_transform(ids, t, _control(T), model)
    assert type(fit.transform) is type(T)
    for name, v in T.to_dict().items():
        if name != "model":
            assert fit.transform.to_dict()[name] == pytest.approx(v, rel=1e-9, abs=1e-12)
    assert fit.rmse < 1e-6
    assert fit.ids == tuple(str(k + 1) for k in range(len(TABLET)))
    assert list(fit.n_measurements) == [2] * len(TABLET)


@pytest.mark.parametrize("model", ["conformal", "affine", "bilinear"])
def test_minimum_points_exact(model):
    n = {"conformal": 2, "affine": 3, "bilinear": 4}[model]
    T = TRUE[model]
    pts = TABLET[:n]
    ids, t = _twice(pts)
    fit = fit_map_transform(ids, t, _control(T, pts), model)
    np.testing.assert_allclose(fit.transform.forward(TABLET), T.forward(TABLET), atol=1e-6)
    assert math.isnan(fit.sigma0) or fit.sigma0 < 1e-6


@pytest.mark.parametrize("model", ["conformal", "affine", "bilinear"])
def test_inverse_round_trip(model):
    T = TRUE[model]
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 600, (1000, 2))
    np.testing.assert_allclose(T.inverse(T.forward(t)), t, atol=1e-8)
    # shapes: one point and a grid
    assert T.forward([1.0, 2.0]).shape == (2,)
    assert T.inverse(np.zeros((3, 4, 2)) + T.forward([1.0, 2.0])).shape == (3, 4, 2)


@pytest.mark.parametrize("model", ["conformal", "affine", "bilinear"])
def test_jacobian_matches_numeric(model):
    T = TRUE[model]
    p = np.array([210.0, 130.0])
    h = 0.5  # the models are at most bilinear: central differences are exact
    num = np.column_stack([(T.forward(p + d) - T.forward(p - d)) / (2 * h) for d in np.eye(2) * h])
    np.testing.assert_allclose(T.jacobian(p), num, rtol=1e-9, atol=1e-9)


def test_bilinear_inverse_beyond_fold_raises():
    T = BilinearTransform(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0)  # X = x + xy: folds at y = -1
    with pytest.raises(ConvergenceError):
        T.inverse([[0.0, -1.0]])


@settings(max_examples=50, deadline=None)
@given(st.sampled_from(["conformal", "affine", "bilinear"]))
def test_dict_round_trip(model):
    T = TRUE[model]
    assert transform_from_dict(T.to_dict()) == T
    assert type(T).from_dict(T.to_dict()) == T


def test_from_dict_errors():
    with pytest.raises(ApygisError, match="unknown map transform model"):
        transform_from_dict({"model": "projective"})
    with pytest.raises(ApygisError, match="lacks"):
        transform_from_dict({"model": "affine", "a": 1.0})


def test_conformal_needs_each_point_twice():
    T = TRUE["conformal"]
    ids = ["1", "1", "2", "3", "3"]
    t = TABLET[[0, 0, 1, 2, 2]]
    with pytest.raises(MeasurementError, match=r"point\(s\) 2 measured once"):
        fit_map_transform(ids, t, _control(T), "conformal")
    # the affine orientation accepts single measurements
    fit_map_transform(ids, t, _control(T), "affine")


def test_too_few_and_degenerate_points():
    T = TRUE["affine"]
    ctrl = _control(T)
    with pytest.raises(DegenerateGeometryError, match="at least 3 different points"):
        fit_map_transform(["1", "2"], TABLET[:2], ctrl, "affine")
    with pytest.raises(DegenerateGeometryError, match="at least 4"):
        fit_map_transform(["1", "2", "3"], TABLET[:3], ctrl, "bilinear")
    line = np.array([[0.0, 0.0], [100.0, 100.0], [200.0, 200.0], [300.0, 300.0]])
    c2 = {str(k + 1): tuple(T.forward(p)) for k, p in enumerate(line)}
    with pytest.raises(DegenerateGeometryError, match="not collinear"):
        fit_map_transform(["1", "2", "3"], line[:3], c2, "affine")
    with pytest.raises(DegenerateGeometryError, match="quadrangle"):
        fit_map_transform(["1", "2", "3", "4"], line, c2, "bilinear")
    same = np.array([[5.0, 5.0]] * 4)
    with pytest.raises(DegenerateGeometryError, match="same tablet position"):
        fit_map_transform(["1", "1", "2", "2"], same, ctrl, "conformal")


def test_unknown_points_and_reject():
    T = TRUE["affine"]
    ctrl = _control(T)
    with pytest.raises(MeasurementError, match="99 not in the control"):
        fit_map_transform(["1", "2", "99"], TABLET[:3], ctrl, "affine")
    with pytest.raises(MeasurementError, match=r"cannot reject point\(s\) 42: never measured"):
        fit_map_transform(["1", "2", "3"], TABLET[:3], ctrl, "affine", reject=["42"])
    ids, t = _twice()
    bad = dict(ctrl)
    bad["5"] = (bad["5"][0] + 20.0, bad["5"][1], 500.0)  # a blunder
    fit = fit_map_transform(ids, t, bad, "affine")
    assert np.argmax(np.hypot(*fit.residuals.T)) == fit.ids.index("5")
    refit = fit_map_transform(ids, t, bad, "affine", reject=["5"])
    assert "5" not in refit.ids
    assert refit.rejected == ("5",)
    assert refit.rmse < 1e-6


def test_noise_statistics_and_pointing_precision():
    """Over seeded trials: sigma0 and the pointing precision estimate the simulated noise."""
    rng = np.random.default_rng(11)
    T = TRUE["affine"]
    ctrl = _control(T)
    ids, t = _twice()
    sig_mm = 0.04
    s0, ps, coef = [], [], []
    for _ in range(300):
        noisy = t + rng.normal(0, sig_mm, t.shape)
        fit = fit_map_transform(ids, noisy, ctrl, "affine")
        s0.append(fit.sigma0)
        ps.append(fit.pointing_sigma_mm)
        coef.append(fit.transform.c)
    scale = T.mean_scale()
    # sigma0 (ground) ~ tablet noise times the scale; pointing precision ~ tablet noise
    assert np.sqrt(np.mean(np.square(s0))) == pytest.approx(sig_mm * scale, rel=0.05)
    assert np.sqrt(np.mean(np.square(ps))) == pytest.approx(sig_mm, rel=0.05)
    assert np.mean(coef) == pytest.approx(T.c, abs=3 * np.std(coef) / np.sqrt(300))
