"""Relative (coplanarity) and absolute (3-D similarity) orientation.

Set-up: the stereo pair of tests/orient/synth.py; the model system is the
left photo's system with base bx = 1; tie points on the terrain, photo
coordinates with Gaussian noise of known sigma.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from apygis.errors import DegenerateGeometryError, MeasurementError
from apygis.orient.absolute import (
    Similarity3D,
    absolute_orientation,
    similarity_closed_form,
)
from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation, ground_to_photo
from apygis.orient.relative import relative_orientation
from apygis.orient.rotation import rotation_matrix

from . import synth

IO = InteriorOrientation(153.0, 0.01, -0.01)
LEFT = ExteriorOrientation(0.0, 0.0, 0.0)
RIGHT = ExteriorOrientation(1.0, 0.015, -0.02, 0.004, -0.006, 0.012)
TRUE5 = np.array([0.015, -0.02, 0.004, -0.006, 0.012])


def _model_points(n, rng):
    # model units: base 1; flying height ~1.66 base
    return np.column_stack(
        [
            rng.uniform(-0.1, 1.1, n),
            rng.uniform(-0.55, 0.55, n),
            -1.66 + rng.uniform(-0.05, 0.05, n),
        ]
    )


def test_relative_noise_free():
    rng = np.random.default_rng(1)
    M = _model_points(12, rng)
    r = relative_orientation(ground_to_photo(M, LEFT, IO), ground_to_photo(M, RIGHT, IO), IO)
    np.testing.assert_allclose(r.parameters, TRUE5, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(r.model_points, M, atol=1e-9)
    assert r.redundancy == 7


def test_relative_minimum_five_points():
    rng = np.random.default_rng(2)
    M = _model_points(5, rng)
    r = relative_orientation(ground_to_photo(M, LEFT, IO), ground_to_photo(M, RIGHT, IO), IO)
    np.testing.assert_allclose(r.parameters, TRUE5, atol=1e-9)
    with pytest.raises(DegenerateGeometryError, match="at least 5 tie points, got 4"):
        relative_orientation(
            ground_to_photo(M[:4], LEFT, IO), ground_to_photo(M[:4], RIGHT, IO), IO
        )


def test_relative_statistics():
    rng = np.random.default_rng(3)
    M = _model_points(15, rng)
    p1, p2 = ground_to_photo(M, LEFT, IO), ground_to_photo(M, RIGHT, IO)
    r = relative_orientation(
        p1 + rng.normal(0, 0.005, p1.shape), p2 + rng.normal(0, 0.005, p2.shape), IO
    )
    for k, name in enumerate(("by", "bz", "omega", "phi", "kappa")):
        assert abs(r.parameters[k] - TRUE5[k]) < 3 * r.std[name], name
    est, var = [], []
    for _ in range(250):
        r = relative_orientation(
            p1 + rng.normal(0, 0.005, p1.shape), p2 + rng.normal(0, 0.005, p2.shape), IO
        )
        est.append(r.parameters)
        var.append(np.diag(r.covariance))
    np.testing.assert_allclose(np.sqrt(np.mean(var, axis=0)), np.std(est, axis=0), rtol=0.2)
    assert np.sqrt(np.mean(np.square([0.005]))) == pytest.approx(0.005)


def test_relative_then_absolute_recovers_the_ground():
    """Relative orientation + absolute orientation = the true ground coordinates."""
    left, right = synth.pair()
    rng = np.random.default_rng(4)
    G = synth.model_points(30, rng)
    pl, pr = left.photo(G), right.photo(G)
    ro = relative_orientation(
        pl, pr, left.interior, left=ExteriorOrientation(0, 0, 0, *left.exterior.parameters[3:])
    )
    ao = absolute_orientation(ro.model_points[:8], G[:8])
    np.testing.assert_allclose(ao.transform.forward(ro.model_points), G, rtol=0, atol=1e-5)
    base = np.hypot(*(right.exterior.centre - left.exterior.centre)[:2])
    assert ao.transform.scale == pytest.approx(base, rel=1e-3)


def test_absolute_noise_free_and_closed_form():
    rng = np.random.default_rng(5)
    m = rng.uniform(-1, 1, (6, 3))
    S = Similarity3D(2683000.0, 1248000.0, 500.0, 1380.0, 0.01, -0.02, 2.9)
    G = S.forward(m)
    np.testing.assert_allclose(similarity_closed_form(m, G).parameters, S.parameters, rtol=1e-9)
    r = absolute_orientation(m, G)
    np.testing.assert_allclose(r.transform.parameters, S.parameters, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(r.transform.inverse(G), m, atol=1e-9)
    assert Similarity3D.from_dict(S.to_dict()) == S


def test_absolute_partial_control_and_statistics():
    """Height-only and planimetric points; 3-sigma truth; sigmas vs spread within 20 %."""
    rng = np.random.default_rng(6)
    m = rng.uniform(-0.6, 0.6, (10, 3)) * (1, 1, 0.1)
    S = Similarity3D(2683000.0, 1248000.0, 500.0, 1380.0, 0.01, -0.02, 2.9)
    G0 = S.forward(m)
    mask = np.ones_like(G0, dtype=bool)
    mask[7, :2] = False  # height point
    mask[8, 2] = False  # planimetric point
    est, var = [], []
    for t in range(250):
        G = np.where(mask, G0 + rng.normal(0, 0.1, G0.shape), np.nan)
        r = absolute_orientation(m, G)
        d = r.transform.parameters - S.parameters
        if t == 0:
            for k, name in enumerate(("tx", "ty", "tz", "scale", "omega", "phi", "kappa")):
                assert abs(d[k]) < 3 * r.std[name], name
            assert np.isnan(r.residuals[7, 0])
            assert np.isfinite(r.residuals[7, 2])
        est.append(d)
        var.append(np.diag(r.covariance))
    np.testing.assert_allclose(np.sqrt(np.mean(var, axis=0)), np.std(est, axis=0), rtol=0.2)


def test_absolute_degenerate():
    m = np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3.0]])
    with pytest.raises(DegenerateGeometryError, match="not collinear"):
        absolute_orientation(m, m * 2)
    with pytest.raises(DegenerateGeometryError, match="at least 3"):
        similarity_closed_form(m[:2], m[:2])
    with pytest.raises(MeasurementError, match="cannot reject"):
        absolute_orientation(m, m, reject=["x"])
    R = rotation_matrix(0.1, 0.2, 0.3)
    assert math.isclose(np.linalg.det(R), 1.0)
