"""Space resection and space intersection against synthetic truth.

Set-up: the stereo pair of tests/orient/synth.py (1:15000, c = 153 mm,
H = 2295 m), photo coordinates from the true orientation plus Gaussian noise
of known sigma (4-5 um).
"""

from __future__ import annotations

import numpy as np
import pytest

from apygis.errors import DegenerateGeometryError, MeasurementError, OrientationError
from apygis.orient.collinearity import EO_PARAMETERS, ExteriorOrientation, InteriorOrientation
from apygis.orient.intersection import intersect
from apygis.orient.resection import dlt_approximation, resect, similarity_approximation

from . import synth


def _err(eo, true):
    d = eo.parameters - true.parameters
    d[3:] = synth.wrap(d[3:])
    return d


@pytest.mark.parametrize("n", [3, 4, 8])
def test_resection_noise_free(n):
    true = synth.pair()[0]
    G = synth.control_spots(n, np.random.default_rng(n))
    p = true.photo(G)
    r = resect(G, p, true.interior)
    d = _err(r.exterior, true.exterior)
    assert np.all(np.abs(d) <= 1e-9 * np.maximum(1.0, np.abs(true.exterior.parameters)))
    assert r.redundancy == 2 * n - 6


def test_dlt_and_similarity_starts():
    true = synth.pair()[1]
    G = synth.control_spots(12, np.random.default_rng(1))
    p = true.photo(G)
    start = dlt_approximation(G, p, true.interior)
    assert np.abs(_err(start, true.exterior)[:3]).max() < 0.05
    sim = similarity_approximation(G, p, true.interior)
    assert np.abs(_err(sim, true.exterior)[:3]).max() < 100.0
    flat = G.copy()
    flat[:, 2] = 500.0
    with pytest.raises(DegenerateGeometryError, match="coplanar"):
        dlt_approximation(flat, true.photo(flat), true.interior)
    r = resect(flat, true.photo(flat), true.interior)  # falls back to the similarity start
    assert np.abs(_err(r.exterior, true.exterior)).max() < 1e-6


def test_resection_statistics():
    """Truth within 3 sigma; estimated sigmas vs spread within 20 % over seeded trials."""
    true = synth.pair()[0]
    rng = np.random.default_rng(21)
    G = synth.control_spots(8, rng)
    p0 = true.photo(G)
    r = resect(G, p0 + rng.normal(0, 0.005, p0.shape), true.interior)
    d = _err(r.exterior, true.exterior)
    for k, name in enumerate(EO_PARAMETERS):
        assert abs(d[k]) < 3 * r.std[name], name
    errs, var = [], []
    for _ in range(250):
        r = resect(G, p0 + rng.normal(0, 0.005, p0.shape), true.interior, approx=true.exterior)
        errs.append(_err(r.exterior, true.exterior))
        var.append(np.diag(r.covariance))
    np.testing.assert_allclose(np.sqrt(np.mean(var, axis=0)), np.std(errs, axis=0), rtol=0.2)


def test_resection_degenerate():
    true = synth.pair()[0]
    G = synth.control_spots(8, np.random.default_rng(2))
    with pytest.raises(DegenerateGeometryError, match="at least 3 control points, got 2"):
        resect(G[:2], true.photo(G[:2]), true.interior)
    t = np.linspace(0, 1000, 5)
    line = np.column_stack([synth.XM + t, synth.YM + t, 500 + 0.1 * t])
    with pytest.raises(DegenerateGeometryError, match="not collinear"):
        resect(line, true.photo(line), true.interior)
    with pytest.raises(MeasurementError):
        resect(G, true.photo(G)[:4], true.interior)
    with pytest.raises(OrientationError, match="frame"):
        resect(G, true.photo(G), InteriorOrientation(153.0, scanned=True))


def test_intersection_noise_free_vectorised():
    left, right = synth.pair()
    G = synth.model_points(5000, np.random.default_rng(3))
    r = intersect([left, right], [left.photo(G), right.photo(G)])
    assert r.points.shape == (5000, 3)
    np.testing.assert_allclose(r.points, G, rtol=1e-12, atol=1e-7)
    assert r.redundancy == 1


def test_intersection_statistics():
    """Many points in one call are many trials: sigmas vs spread within 20 %, 3-sigma truth."""
    left, right = synth.pair()
    rng = np.random.default_rng(4)
    P = np.repeat(synth.model_points(1, rng), 2000, axis=0)
    obs = np.stack([left.photo(P), right.photo(P)])
    r = intersect([left, right], obs + rng.normal(0, 0.005, obs.shape), sigma_mm=0.005)
    err = r.points - P
    np.testing.assert_allclose(np.sqrt(np.mean(r.std**2, axis=0)), err.std(axis=0), rtol=0.2)
    assert np.all(np.abs(err[0]) < 3 * r.std[0])
    # a posteriori sigma0 per point (1 degree of freedom) is right on average
    assert np.sqrt(np.mean(r.sigma0_mm**2)) == pytest.approx(0.005, rel=0.2)
    # three photos: more redundancy
    third = (ExteriorOrientation(synth.XM, synth.YM + 600, 2815.0, 0.0, 0.0, np.pi), left.interior)
    r3 = intersect([left, right, third], np.concatenate([obs, ground_photo(third, P)[None]]))
    np.testing.assert_allclose(r3.points, P, atol=1e-7)
    assert r3.redundancy == 3


def ground_photo(ph, P):
    from apygis.orient.collinearity import ground_to_photo

    return ground_to_photo(P, *ph)


def test_intersection_degenerate():
    left, _ = synth.pair()
    G = synth.model_points(3, np.random.default_rng(5))
    with pytest.raises(DegenerateGeometryError, match="at least 2 photos"):
        intersect([left], [left.photo(G)])
    with pytest.raises(DegenerateGeometryError, match="parallel"):
        intersect([left, left], [left.photo(G), left.photo(G)])
    with pytest.raises(MeasurementError, match="shape"):
        intersect([left, left], [left.photo(G)])
    with pytest.raises(OrientationError):
        intersect(["a", "b"], np.zeros((2, 1, 2)))
