"""The bilinear height correction dpZ = A x + B y + C x y + D."""

from __future__ import annotations

import numpy as np
import pytest

from apygis.errors import DegenerateGeometryError, OrientationError
from apygis.orient.height import HeightCorrection, fit_height_correction

from . import synth


def _truth():
    return HeightCorrection(0.31, -0.12, 0.05, 0.2, synth.XM, synth.YM, 700.0)


def test_exact_recovery():
    rng = np.random.default_rng(0)
    xy = synth.control_spots(8, rng)[:, :2]
    true = _truth()
    fit = fit_height_correction(xy, true.dpz(xy[:, 0], xy[:, 1]))
    grid = synth.model_points(100, rng)[:, :2]
    np.testing.assert_allclose(
        fit.correction.dpz(grid[:, 0], grid[:, 1]), true.dpz(grid[:, 0], grid[:, 1]), atol=1e-9
    )
    assert fit.rmse < 1e-9


def test_four_points_no_redundancy():
    xy = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 1000.0], [0.0, 1000.0]]) + np.array(
        [2.68e6, 1.25e6]
    )
    fit = fit_height_correction(xy, [0.1, 0.2, 0.4, 0.3])
    np.testing.assert_allclose(fit.residuals, 0.0, atol=1e-12)
    assert np.isnan(fit.sigma0)


def test_correct_uncorrect_inverse():
    h = _truth()
    X, Y, Z = synth.XM + 300.0, synth.YM - 200.0, 512.0
    assert h.uncorrect(X, Y, h.correct(X, Y, Z)) == pytest.approx(Z)
    assert HeightCorrection.from_dict(h.to_dict()) == h
    assert HeightCorrection.zero().dpz(X, Y) == 0.0


def test_degenerate():
    with pytest.raises(DegenerateGeometryError, match="at least 4 points"):
        fit_height_correction([[0, 0], [1, 0], [0, 1]], [0, 0, 0])
    line = [[0, 0], [100, 100], [200, 200], [300, 300], [400, 400]]
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        fit_height_correction(line, [0, 1, 2, 3, 4])
    with pytest.raises(OrientationError):
        fit_height_correction([[0, 0]] * 4, [0, 0, 0])
    with pytest.raises(OrientationError, match="scale_m"):
        HeightCorrection(0, 0, 0, 0, scale_m=0)


def test_sigmas_match_spread():
    """Seeded trials: truth within 3 sigma, estimated sigmas vs spread within 20 %."""
    rng = np.random.default_rng(5)
    xy = synth.control_spots(10, rng)[:, :2]
    true = _truth()
    dz0 = true.dpz(xy[:, 0], xy[:, 1])
    fit = fit_height_correction(xy, dz0 + rng.normal(0, 0.15, len(dz0)))
    # one trial: D (the correction at the fit centre) vs the truth there
    c = fit.correction
    assert abs(c.D - true.dpz(c.Xc, c.Yc)) < 3 * np.sqrt(fit.covariance[3, 3])
    fits = [fit_height_correction(xy, dz0 + rng.normal(0, 0.15, len(dz0))) for _ in range(300)]
    for k, name in enumerate("ABCD"):
        spread = np.std([getattr(f.correction, name) for f in fits])
        sig = np.sqrt(np.mean([f.covariance[k, k] for f in fits]))
        assert sig == pytest.approx(spread, rel=0.2), name
