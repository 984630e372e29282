"""The real-time loop and the motor calibration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from apygis.errors import DegenerateGeometryError, OrientationError
from apygis.orient.collinearity import ground_to_photo, parallax
from apygis.orient.realtime import (
    MotorCalibration,
    RealtimeLoop,
    calibrate_plates,
    calibrate_stage,
    map_to_photo_scale,
)
from apygis.orient.transforms import AffineTransform, ConformalTransform

from . import synth

MAP = ConformalTransform.from_scale_rotation(5.0, 0.02, 2682700.0, 1246750.0)


def _loop(scanned=False):
    left, right = synth.pair(scanned=scanned)
    ml = MotorCalibration(
        "L", step_um=2.0, plate_rotation_rad=0.03, zero_x_steps=100, zero_y_steps=-50
    )
    mr = MotorCalibration("R", step_um=2.5, plate_rotation_rad=-0.02)
    return RealtimeLoop(left, right, ml, mr), left, right, ml, mr


@pytest.mark.parametrize("scanned", [False, True])
def test_loop_matches_collinearity_and_parallax(scanned):
    loop, left, right, ml, _mr = _loop(scanned)
    G = synth.model_points(1000, np.random.default_rng(1))
    b = loop.update_many(G)
    for k, po in enumerate((left, right)):
        np.testing.assert_allclose(
            b.photo_mm[k], ground_to_photo(G, po.exterior, po.interior), atol=1e-12
        )
        np.testing.assert_allclose(
            b.parallax_mm[k],
            parallax(G, po.exterior, po.interior, po.sx_mm_per_m, po.sy_mm_per_m),
            atol=1e-12,
        )
    nlx, nly = ml.steps(b.parallax_mm[0, :, 0], b.parallax_mm[0, :, 1])
    np.testing.assert_array_equal(b.steps[:, 0], nlx)
    np.testing.assert_array_equal(b.steps[:, 1], nly)
    # the fast scalar path gives the same numbers
    for i in range(0, 1000, 97):
        u = loop.update(*G[i])
        np.testing.assert_allclose(
            [u.x_left, u.y_left, u.x_right, u.y_right],
            [*b.photo_mm[0, i], *b.photo_mm[1, i]],
            atol=1e-12,
        )
        np.testing.assert_allclose(
            [u.px_left, u.py_left, u.px_right, u.py_right],
            [*b.parallax_mm[0, i], *b.parallax_mm[1, i]],
            atol=1e-12,
        )
        assert (u.steps_left_x, u.steps_left_y, u.steps_right_x, u.steps_right_y) == tuple(
            b.steps[i]
        )
        assert all(type(v) is int for v in u[8:])


def test_steps_and_shift_are_inverse():
    m = MotorCalibration("L", step_um=2.0, plate_rotation_rad=0.4, zero_x_steps=7, zero_y_steps=-3)
    px, py = np.array([0.5, -1.2, 0.0]), np.array([0.3, 2.1, 0.0])
    nx, ny = m.steps(px, py)
    bx, by = m.shift(nx, ny)
    assert np.all(np.hypot(bx - px, by - py) <= 0.002 / math.sqrt(2) + 1e-12)
    assert m.steps(0.0, 0.0) == (7, -3)
    assert MotorCalibration.from_dict(m.to_dict()) == m
    with pytest.raises(OrientationError, match="step_um"):
        MotorCalibration("x", step_um=0.0)
    with pytest.raises(OrientationError, match="integer"):
        MotorCalibration("x", zero_x_steps=1.5)


def test_stage_calibration():
    """Crosses 100 mm apart appear 300 mm apart on the tablet, opposite: rho = +1/3."""
    cal = calibrate_stage([[-50.0, 10.0], [50.0, 10.0]], [[400.0, 300.0], [100.0, 300.0]])
    assert cal.scale_ratio == pytest.approx(1 / 3)
    assert cal.stage_rotation_rad == pytest.approx(0.0, abs=1e-12)
    turned = calibrate_stage(
        [[0, 0], [100, 0]], [[0, 0], [300 * math.cos(0.01), 300 * math.sin(0.01)]]
    )
    assert turned.scale_ratio < 0  # image not turned by the optics
    assert abs(turned.stage_rotation_rad) == pytest.approx(0.01)
    with pytest.raises(DegenerateGeometryError, match="coincide"):
        calibrate_stage([[0, 0], [0, 0]], [[0, 0], [1, 1]])
    sx, sy = map_to_photo_scale(1 / 3, MAP, (300.0, 200.0))
    assert sx == pytest.approx(1 / 15)
    assert sy == pytest.approx(1 / 15)
    aff = AffineTransform(5.0, 0.0, 0.0, 0.0, 5.01, 0.0)
    sx, sy = map_to_photo_scale(1 / 3, aff, (0.0, 0.0))
    assert sx == pytest.approx(1 / 15)
    assert sy == pytest.approx(1 / 15 / 1.002)


def test_plate_calibration_recovers_the_instrument():
    """Simulate the cross measured twice and recover step size and plate rotation."""
    left, _ = synth.pair()
    true = MotorCalibration("L", step_um=2.0, plate_rotation_rad=0.05)
    dn = (400, 300)
    dp = np.array(true.shift(*dn))  # photo shift caused by driving the motors
    # the mark follows the cross: ground displacement dG = dp / s, tablet = J^-1 dG
    dG = dp / np.array([left.sx_mm_per_m, left.sy_mm_per_m])
    t1 = np.array([250.0, 180.0])
    t2 = t1 + np.linalg.solve(MAP.jacobian(t1), dG)
    cal = calibrate_plates(
        "L",
        t1,
        t2,
        dn,
        sx_mm_per_m=left.sx_mm_per_m,
        sy_mm_per_m=left.sy_mm_per_m,
        map_transform=MAP,
    )
    assert cal.step_um == pytest.approx(2.0, rel=1e-9)
    assert cal.plate_rotation_rad == pytest.approx(0.05, abs=1e-9)
    with pytest.raises(DegenerateGeometryError, match="drive both motors"):
        calibrate_plates("L", t1, t2, (0, 5), sx_mm_per_m=0.07, sy_mm_per_m=0.07, map_transform=MAP)
    with pytest.raises(DegenerateGeometryError, match="did not move"):
        calibrate_plates("L", t1, t1, dn, sx_mm_per_m=0.07, sy_mm_per_m=0.07, map_transform=MAP)


def test_loop_rejects_bad_input():
    loop, left, right, ml, _mr = _loop()
    with pytest.raises(OrientationError, match="shape"):
        loop.update_many(np.zeros((3, 2)))
    with pytest.raises(OrientationError):
        RealtimeLoop(left, right, ml, None)
