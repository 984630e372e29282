"""Rotation matrices: the convention, the inverse, the derivatives."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from apygis.errors import ApygisError, DegenerateGeometryError
from apygis.orient.rotation import (
    angles_from_matrix,
    nearest_rotation,
    rotation_derivatives,
    rotation_matrix,
)

angle = st.floats(-math.pi + 1e-6, math.pi, allow_nan=False)
phi_angle = st.floats(-math.pi / 2 + 1e-3, math.pi / 2 - 1e-3, allow_nan=False)


def test_elementary_rotations_are_right_handed():
    # kappa = +90 deg turns the image x axis into the ground Y axis
    R = rotation_matrix(0.0, 0.0, math.pi / 2)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    # omega = +90 deg turns Y into Z; phi = +90 deg turns Z into X
    np.testing.assert_allclose(
        rotation_matrix(math.pi / 2, 0, 0) @ [0, 1, 0], [0, 0, 1], atol=1e-15
    )
    np.testing.assert_allclose(
        rotation_matrix(0, math.pi / 2, 0) @ [0, 0, 1], [1, 0, 0], atol=1e-15
    )


def test_order_is_omega_phi_kappa():
    w, p, k = 0.3, -0.2, 1.1
    Rw = rotation_matrix(w, 0, 0)
    Rp = rotation_matrix(0, p, 0)
    Rk = rotation_matrix(0, 0, k)
    np.testing.assert_allclose(rotation_matrix(w, p, k), Rw @ Rp @ Rk, atol=1e-15)


def test_written_out_elements():
    w, p, k = 0.1, 0.2, 0.3
    R = rotation_matrix(w, p, k)
    cw, sw, _cp, sp, ck, sk = (
        math.cos(w),
        math.sin(w),
        math.cos(p),
        math.sin(p),
        math.cos(k),
        math.sin(k),
    )
    assert R[0, 2] == pytest.approx(sp)
    assert R[1, 0] == pytest.approx(cw * sk + sw * sp * ck)
    assert R[2, 1] == pytest.approx(sw * ck + cw * sp * sk)


@given(angle, phi_angle, angle)
@example(0.0, 0.0, 0.0)
@example(0.0, 0.0, math.pi)
@example(-0.5, 1.5, 3.0)
def test_round_trip(w, p, k):
    R = rotation_matrix(w, p, k)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(R) == pytest.approx(1.0)
    w2, p2, k2 = angles_from_matrix(R)
    np.testing.assert_allclose(rotation_matrix(w2, p2, k2), R, atol=1e-12)
    assert p2 == pytest.approx(p, abs=1e-9)


def test_vectorised():
    w = np.linspace(-1, 1, 5)
    R = rotation_matrix(w, 0.1, [[0.2], [0.3]])
    assert R.shape == (2, 5, 3, 3)
    ws, _ps, ks = angles_from_matrix(R)
    np.testing.assert_allclose(ws, np.broadcast_to(w, (2, 5)), atol=1e-12)
    np.testing.assert_allclose(ks[:, 0], [0.2, 0.3])


@pytest.mark.parametrize("which", [0, 1, 2])
def test_derivatives_match_numeric(which):
    a = np.array([0.2, -0.4, 2.5])
    h = 1e-6
    up, dn = a.copy(), a.copy()
    up[which] += h
    dn[which] -= h
    num = (rotation_matrix(*up) - rotation_matrix(*dn)) / (2 * h)
    np.testing.assert_allclose(rotation_derivatives(*a)[which], num, atol=1e-9)


def test_derivatives_vectorised_shape():
    d = rotation_derivatives([0.1, 0.2], 0.0, 0.0)
    assert all(x.shape == (2, 3, 3) for x in d)


def test_gimbal_lock_and_reflection_raise():
    with pytest.raises(DegenerateGeometryError, match="gimbal"):
        angles_from_matrix(rotation_matrix(0.1, math.pi / 2, 0.2))
    with pytest.raises(DegenerateGeometryError, match=r"reflection|not a rotation"):
        angles_from_matrix(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ApygisError):
        angles_from_matrix(np.eye(2))


def test_nearest_rotation():
    R = rotation_matrix(0.1, 0.2, 0.3)
    noisy = R + 1e-3 * np.arange(9).reshape(3, 3)
    Q = nearest_rotation(noisy)
    np.testing.assert_allclose(Q @ Q.T, np.eye(3), atol=1e-14)
    assert np.abs(Q - R).max() < 1e-2
    with pytest.raises(DegenerateGeometryError):
        nearest_rotation(np.full((3, 3), np.nan))
