"""Photo orientation by the APY parallax conditions.

Synthetic truth (tests/orient/synth.py): a 1:15000 stereo pair, c = 153 mm,
flying height 2295 m over a hilly terrain, 8 control spots in the standard
orientation areas; parallaxes computed from the true orientation plus
Gaussian noise of known sigma.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from apygis.errors import DegenerateGeometryError, MeasurementError, OrientationError
from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation
from apygis.orient.photo import (
    NO_CONTROL_SIN,
    PHOTO_PARAMETERS,
    PhotoOrientation,
    approximate_orientation,
    orient_photo,
    photo_scale_number,
)

from . import synth

SIX = ("Xo", "Yo", "Zo", "omega", "phi", "kappa")


def _approx(true: PhotoOrientation, G, *, known_s=True):
    """The seed's approximate orientation: centre off by ~100 m, Zo from the photo scale."""
    e = true.exterior
    po, fixed = approximate_orientation(
        true.photo_id,
        true.interior,
        centre_xy=(e.Xo + 80.0, e.Yo - 60.0),
        mean_height=float(G[:, 2].mean()),
        scale_number=15000.0,
        sx_mm_per_m=true.sx_mm_per_m if known_s else None,
        sy_mm_per_m=true.sy_mm_per_m if known_s else None,
    )
    return po, fixed


def _check_exact(r, true, free):
    d = synth.param_error(r.orientation.parameters, true.parameters)
    scale = np.maximum(1.0, np.abs(true.parameters))
    assert np.all(np.abs(d) <= 1e-9 * scale), dict(zip(PHOTO_PARAMETERS, d, strict=True))
    assert r.free == free
    assert r.rmse_mm < 1e-9


@pytest.mark.parametrize("side", [0, 1])
def test_noise_free_truth_comes_back(side):
    true = synth.pair()[side]
    G = synth.control_spots(8, np.random.default_rng(1))
    P = true.parallax(G)
    approx, _fixed = _approx(true, G)
    r = orient_photo(G, P, approx, fixed={"sx", "sy"})
    _check_exact(r, true, SIX)
    assert r.redundancy == 16 - 6


def test_noise_free_with_scale_factors_free():
    true = synth.pair()[0]
    G = synth.control_spots(10, np.random.default_rng(2))
    approx, _ = _approx(true, G, known_s=False)
    r = orient_photo(G, true.parallax(G), approx)
    _check_exact(r, true, PHOTO_PARAMETERS)


def test_known_parameters_stay_fixed():
    true = synth.pair()[1]
    G = synth.control_spots(6, np.random.default_rng(3))
    approx, _ = _approx(true, G)
    # Zo and omega are "entered in the photo file": the approximation carries the true values
    p = approx.parameters
    p[2] = true.exterior.Zo
    p[3] = true.exterior.omega_rad
    approx = approx.with_parameters(p)
    r = orient_photo(G, true.parallax(G), approx, fixed={"Zo", "omega", "sx", "sy"})
    assert r.free == ("Xo", "Yo", "phi", "kappa")
    assert r.orientation.exterior.Zo == true.exterior.Zo
    assert r.orientation.exterior.omega_rad == true.exterior.omega_rad
    _check_exact(r, true, ("Xo", "Yo", "phi", "kappa"))
    # a wrong entered value stays as entered and shows in the residuals
    p[2] += 30.0
    r = orient_photo(
        G, true.parallax(G), approx.with_parameters(p), fixed={"Zo", "omega", "sx", "sy"}
    )
    assert r.orientation.exterior.Zo == true.exterior.Zo + 30.0
    assert r.rmse_mm > 1e-3


def test_scanned_imagery():
    true = synth.pair(scanned=True)[0]
    G = synth.control_spots(8, np.random.default_rng(4))
    approx, _ = _approx(true, G)
    r = orient_photo(G, true.parallax(G), approx, fixed={"sx"})
    assert "Yo" not in r.free
    assert "sy" not in r.free
    d = synth.param_error(r.orientation.parameters, true.parameters)
    keep = [0, 2, 3, 4, 5]
    assert np.all(np.abs(d[keep]) <= 1e-9 * np.maximum(1, np.abs(true.parameters[keep])))


def test_noisy_truth_within_three_sigma():
    true = synth.pair()[0]
    rng = np.random.default_rng(17)
    G = synth.control_spots(8, rng)
    P = true.parallax(G) + rng.normal(0, 0.004, (8, 2))
    approx, _ = _approx(true, G)
    r = orient_photo(G, P, approx, fixed={"sx", "sy"})
    d = synth.param_error(r.orientation.parameters, true.parameters)
    for k, name in enumerate(SIX):
        assert abs(d[k]) < 3 * r.std[name], name
    assert r.sigma0_mm == pytest.approx(0.004, rel=0.6)
    assert r.rmse_ground_m == pytest.approx(r.rmse_mm * 2295 / 153, rel=0.02)


def test_sigmas_agree_with_spread():
    """Seeded Monte Carlo: estimated sigmas (RMS over trials) vs empirical spread within 20 %."""
    true = synth.pair()[1]
    rng = np.random.default_rng(8)
    G = synth.control_spots(8, rng)
    P0 = true.parallax(G)
    approx, _ = _approx(true, G)
    errs, var = [], []
    for _ in range(250):
        r = orient_photo(G, P0 + rng.normal(0, 0.005, P0.shape), approx, fixed={"sx", "sy"})
        errs.append(synth.param_error(r.orientation.parameters, true.parameters)[:6])
        var.append(np.diag(r.covariance))
    spread = np.std(errs, axis=0)
    est = np.sqrt(np.mean(var, axis=0))
    np.testing.assert_allclose(est, spread, rtol=0.2)
    # and unbiased: the mean error is within 3 standard errors of the mean
    assert np.all(np.abs(np.mean(errs, axis=0)) < 3 * spread / np.sqrt(250) + 1e-12)


def test_reject_and_recompute():
    true = synth.pair()[0]
    G = synth.control_spots(9, np.random.default_rng(9))
    P = true.parallax(G)
    P[4] += (0.05, -0.03)  # a blunder at spot 5
    ids = [f"2{k:02d}" for k in range(9)]
    approx, _ = _approx(true, G)
    r = orient_photo(G, P, approx, fixed={"sx", "sy"}, ids=ids)
    assert r.rmse_mm > 0.005
    r2 = orient_photo(G, P, approx, fixed={"sx", "sy"}, ids=ids, reject=["204"])
    assert r2.ids == tuple(i for i in ids if i != "204")
    assert r2.rejected == ("204",)
    assert r2.rmse_mm < 1e-9
    with pytest.raises(MeasurementError, match="cannot reject 999"):
        orient_photo(G, P, approx, ids=ids, reject=["999"])


def test_degenerate_input():
    true = synth.pair()[0]
    G = synth.control_spots(8, np.random.default_rng(10))
    P = true.parallax(G)
    approx, _ = _approx(true, G)
    with pytest.raises(DegenerateGeometryError, match="at least 4 control spots, got 3"):
        orient_photo(G[:3], P[:3], approx, fixed={"sx", "sy"})
    # four spots on one straight line: omega (rotation about it) and the centre are not separable
    t = np.linspace(-700, 700, 4)
    line = np.column_stack([synth.XM + t, synth.YM + 0.0 * t, 500.0 + 0.0 * t])
    with pytest.raises(DegenerateGeometryError, match="does not determine"):
        orient_photo(line, true.parallax(line), approx, fixed={"sx", "sy"})
    with pytest.raises(OrientationError, match="unknown parameter"):
        orient_photo(G, P, approx, fixed={"zeta"})
    with pytest.raises(MeasurementError, match="finite"):
        orient_photo(np.where(G[0, 0] == G, np.nan, G), P, approx)
    with pytest.raises(MeasurementError, match=r"shape|must be"):
        orient_photo(G, P[:5], approx)


def test_approximate_orientation_rules():
    io = InteriorOrientation(153.0)
    assert photo_scale_number([[0, 0], [3000, 4000]], [[0, 0], [200, 0]]) == pytest.approx(25000)
    po, fixed = approximate_orientation(
        "7", io, centre_xy=(1.0, 2.0), mean_height=500.0, scale_number=15000.0
    )
    assert po.exterior.Zo == pytest.approx(0.153 * 15000 + 500)
    assert po.sx_mm_per_m == pytest.approx(153.0 / 2295.0)
    assert po.exterior.kappa_rad == pytest.approx(math.pi)
    assert fixed == frozenset()
    po, fixed = approximate_orientation(
        "7",
        io,
        centre_xy=(1.0, 2.0),
        mean_height=500.0,
        scale_number=15000.0,
        control_in_standard_areas=False,
    )
    assert fixed == {"omega", "phi"}
    assert math.sin(po.exterior.omega_rad) == pytest.approx(NO_CONTROL_SIN)
    assert math.sin(po.exterior.phi_rad) == pytest.approx(NO_CONTROL_SIN)
    with pytest.raises(DegenerateGeometryError):
        photo_scale_number([[0, 0], [0, 0]], [[0, 0], [1, 0]])
    with pytest.raises(OrientationError, match="approximate Zo"):
        approximate_orientation("7", io, centre_xy=(0, 0), mean_height=0.0)


def test_no_control_areas_gives_approximate_central_projection():
    """sin(omega) = sin(phi) = 0.0001: omega, phi stay; the rest comes from the spots."""
    true = synth.pair()[0]
    G = synth.control_spots(8, np.random.default_rng(12))[[0, 1, 6, 7]]
    approx, fixed = approximate_orientation(
        "L",
        true.interior,
        centre_xy=(true.exterior.Xo + 50, true.exterior.Yo),
        mean_height=float(G[:, 2].mean()),
        scale_number=15000.0,
        sx_mm_per_m=true.sx_mm_per_m,
        sy_mm_per_m=true.sy_mm_per_m,
        control_in_standard_areas=False,
    )
    r = orient_photo(G, true.parallax(G), approx, fixed=fixed | {"sx", "sy"})
    assert r.free == ("Xo", "Yo", "Zo", "kappa")
    assert r.orientation.exterior.omega_rad == approx.exterior.omega_rad


def test_value_type_round_trip():
    true = synth.pair()[0]
    assert PhotoOrientation.from_dict(true.to_dict()) == true
    assert true.with_parameters(true.parameters).exterior.Xo == true.exterior.Xo
    with pytest.raises(OrientationError):
        PhotoOrientation("x", true.interior, ExteriorOrientation(0, 0, 0), math.inf, 1.0)
