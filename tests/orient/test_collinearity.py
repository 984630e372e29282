"""Collinearity (a), superposition (b) and the APY parallax conditions (c)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from apygis.errors import ApygisError, DegenerateGeometryError, OrientationError
from apygis.orient.collinearity import (
    ExteriorOrientation,
    InteriorOrientation,
    collinearity_jacobian,
    ground_to_photo,
    parallax,
    parallax_jacobian,
    photo_to_ground,
    superposition,
)

from . import synth

IO = InteriorOrientation(153.0, 0.01, -0.02)
EO = ExteriorOrientation(2684200.0, 1247800.0, 2815.0, 0.004, -0.006, 3.15)


def test_vertical_photo_is_a_positive():
    eo = ExteriorOrientation(0.0, 0.0, 2300.0)
    x, y = ground_to_photo([100.0, 200.0, 0.0], eo, InteriorOrientation(153.0))[0]
    assert x == pytest.approx(153.0 * 100 / 2300)
    assert y == pytest.approx(153.0 * 200 / 2300)


def test_seed_formula_written_out():
    G = np.array([2684500.0, 1247300.0, 480.0])
    R = EO.rotation
    dX, dY, dZ = G - EO.centre
    den = R[0, 2] * dX + R[1, 2] * dY + R[2, 2] * dZ
    x = IO.x0_mm - IO.focal_mm * (R[0, 0] * dX + R[1, 0] * dY + R[2, 0] * dZ) / den
    y = IO.y0_mm - IO.focal_mm * (R[0, 1] * dX + R[1, 1] * dY + R[2, 1] * dZ) / den
    np.testing.assert_allclose(ground_to_photo(G, EO, IO)[0], [x, y], rtol=1e-14)
    sx, sy = 0.0667, 0.0666
    px, py = parallax(G, EO, IO, sx, sy)[0]
    assert px == pytest.approx(sx * dX + x - IO.x0_mm, abs=1e-12)
    assert py == pytest.approx(sy * dY + y - IO.y0_mm, abs=1e-12)
    # (b) with the parallax added gives the photo point of (a)
    sup = superposition(G, EO, IO, sx, sy)[0]
    np.testing.assert_allclose(sup + np.array([px, py]), [x, y], atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(
    st.floats(-1000, 1000),
    st.floats(-1000, 1000),
    st.floats(300, 800),
)
def test_photo_ground_round_trip(dx, dy, Z):
    G = np.array([[EO.Xo + dx, EO.Yo + dy, Z]])
    back = photo_to_ground(ground_to_photo(G, EO, IO), Z, EO, IO)
    np.testing.assert_allclose(back, G, rtol=0, atol=1e-6)


def test_vectorised_many_points():
    rng = np.random.default_rng(0)
    G = synth.model_points(10_000, rng)
    p = ground_to_photo(G, EO, IO)
    assert p.shape == (10_000, 2)
    np.testing.assert_allclose(photo_to_ground(p, G[:, 2], EO, IO), G, atol=1e-6)


def test_photo_to_ground_rejects_rays_behind():
    with pytest.raises(DegenerateGeometryError, match="behind"):
        photo_to_ground([[0.0, 0.0]], 5000.0, EO, IO)


def test_scanned_imagery_has_no_y_superposition_term():
    io = InteriorOrientation(153.0, scanned=True)
    G = np.array([[EO.Xo + 300.0, EO.Yo + 900.0, 500.0]])
    eo2 = ExteriorOrientation(EO.Xo, EO.Yo + 12345.0, EO.Zo, EO.omega_rad, EO.phi_rad, EO.kappa_rad)
    # Yo does not matter: Y - Yo = 0
    np.testing.assert_allclose(parallax(G, EO, io, 0.07, 0.07), parallax(G, eo2, io, 0.07, 0.07))
    np.testing.assert_allclose(parallax(G, EO, io, 0.07, 0.07), parallax(G, EO, io, 0.07, 99.0))
    flat = G.copy()
    flat[0, 1] = EO.Yo
    np.testing.assert_allclose(
        ground_to_photo(G, EO, io), ground_to_photo(flat, EO, InteriorOrientation(153.0))
    )
    with pytest.raises(OrientationError, match="scanned"):
        photo_to_ground([[0.0, 0.0]], 500.0, EO, io)


def _numeric(fun, x, h):
    cols = []
    for j in range(len(x)):
        up, dn = x.copy(), x.copy()
        up[j] += h[j]
        dn[j] -= h[j]
        cols.append((fun(up) - fun(dn)) / (2 * h[j]))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("scanned", [False, True])
def test_jacobians_match_numeric(scanned):
    io = InteriorOrientation(153.0, 0.01, -0.02, scanned)
    rng = np.random.default_rng(1)
    G = synth.model_points(5, rng)
    photo, J_eo, J_g = collinearity_jacobian(G, EO, io)
    np.testing.assert_allclose(photo, ground_to_photo(G, EO, io))
    x = EO.parameters
    num = _numeric(
        lambda p: ground_to_photo(G, ExteriorOrientation.from_parameters(p), io),
        x,
        [1e-3] * 3 + [1e-7] * 3,
    )
    np.testing.assert_allclose(J_eo, num, rtol=1e-5, atol=1e-8)
    for k in range(len(G)):
        numg = _numeric(lambda g: ground_to_photo(g, EO, io)[0], G[k].copy(), [1e-3] * 3)
        np.testing.assert_allclose(J_g[k], numg, rtol=1e-5, atol=1e-8)
    sx, sy = 0.0668, 0.0667
    _p, J = parallax_jacobian(G, EO, io, sx, sy)
    x8 = np.concatenate([x, [sx, sy]])

    def par(q):
        return parallax(G, ExteriorOrientation.from_parameters(q[:6]), io, q[6], q[7])

    num8 = _numeric(par, x8, [1e-3] * 3 + [1e-7] * 3 + [1e-7] * 2)
    np.testing.assert_allclose(J, num8, rtol=1e-5, atol=1e-8)


def test_value_types_validate():
    with pytest.raises(OrientationError, match="focal_mm"):
        InteriorOrientation(-1.0)
    with pytest.raises(ApygisError, match="Xo"):
        ExteriorOrientation(math.nan, 0, 0)
    with pytest.raises(OrientationError, match="shape"):
        ground_to_photo([[1.0, 2.0]], EO, IO)
    assert ExteriorOrientation.from_dict(EO.to_dict()) == EO
    assert InteriorOrientation.from_dict(IO.to_dict()) == IO
