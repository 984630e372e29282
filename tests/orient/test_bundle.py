"""The bundle adjustment against a brute-force dense solution and against simulated truth.

Tolerances come from the noise: normalised errors (error / estimated standard
deviation) have RMS 1 when the precisions are right; with ``n`` independent
samples the RMS of ``n`` standard normal values lies within ``1 +- 3 / sqrt(2 n)``
(three standard deviations of a chi distribution's scale), and sigma0's relative
standard deviation is ``1 / sqrt(2 r)`` for redundancy ``r``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from apygis.aerotri.simulate import simulate_block
from apygis.errors import DegenerateGeometryError, OrientationError
from apygis.orient import bundle as bd
from apygis.orient.rotation import rotation_matrix


def _small_problem(free=(), seed=5):
    """Five photos over 40 points with control, GPS centres and optional self-calibration."""
    rng = np.random.default_rng(seed)
    c = 100.0
    eo = np.array(
        [
            [0, 0, 1000, 0.01, -0.01, 0.1],
            [400, 0, 1000, 0, 0.02, 0.0],
            [800, 10, 1010, -0.01, 0, 0.05],
            [0, 500, 1000, 0, 0, 0],
            [400, 500, 1000, 0, 0, 0.02],
        ],
        float,
    )
    P = 40
    xyz = np.c_[rng.uniform(-100, 900, P), rng.uniform(-100, 600, P), rng.normal(0, 20, P)]
    R = rotation_matrix(eo[:, 3], eo[:, 4], eo[:, 5])
    oi, op, xy = [], [], []
    for i in range(len(eo)):
        q = (xyz - eo[i, :3]) @ R[i]
        x, y = -c * q[:, 0] / q[:, 2], -c * q[:, 1] / q[:, 2]
        for p in np.nonzero((abs(x) < 60) & (abs(y) < 60))[0]:
            oi.append(i)
            op.append(p)
            xy.append([x[p], y[p]])
    oi, op = np.array(oi), np.array(op)
    xy = np.array(xy) + rng.normal(0, 0.002, (len(oi), 2))
    assert (np.bincount(op, minlength=P) >= 2).all()
    mask = np.zeros((1, 10), bool)
    for name in free:
        mask[0, bd.CALIBRATION_PARAMETERS.index(name)] = True
    pb = bd.BundleProblem(
        calibration=[[c] + [0] * 9],
        radius_mm=[80],
        camera=np.zeros(len(eo), int),
        eo=eo + 0.01,
        xyz=xyz + 0.1,
        obs_image=oi,
        obs_point=op,
        obs_xy=xy,
        obs_sigma=0.002,
        ctrl_point=[0, 1, 2, 3, 4],
        ctrl_xyz=xyz[:5],
        ctrl_sigma=np.full((5, 3), 0.01),
        gps_image=[0, 1],
        gps_xyz=eo[:2, :3],
        gps_sigma=np.full((2, 3), 0.5),
        free=mask,
    )
    return pb


def test_against_a_dense_brute_force_solution():
    """sigma0, degrees of freedom, precisions and redundancy numbers equal those of the
    dense Gauss-Markov model with a numerical Jacobian (calibration, GPS and control in)."""
    pb = _small_problem(free=("c", "k1"))
    sol = bd.adjust(pb)
    M, P = pb.n_images, pb.n_points
    free = [0, 3]

    def resid(x):
        e = x[: 6 * M].reshape(M, 6)
        cal = sol.calibration.copy()
        cal[0, free] = x[6 * M : 6 * M + 2]
        p = x[6 * M + 2 :].reshape(P, 3)
        f, *_ = bd._linearise(pb, e, p, cal, with_jacobian=False)
        rc = ((p[pb.ctrl_point] - pb.ctrl_xyz) / pb.ctrl_sigma).ravel()
        rg = ((e[pb.gps_image, :3] - pb.gps_xyz) / pb.gps_sigma).ravel()
        return np.r_[f.ravel(), rc, rg]

    x0 = np.r_[sol.eo.ravel(), sol.calibration[0, free], sol.xyz.ravel()]
    r0 = resid(x0)
    J = np.empty((len(r0), len(x0)))
    for k in range(len(x0)):
        h = 1e-7 if (6 * M <= k < 6 * M + 2 or (k < 6 * M and k % 6 >= 3)) else 1e-5
        xp, xm = x0.copy(), x0.copy()
        xp[k] += h
        xm[k] -= h
        J[:, k] = (resid(xp) - resid(xm)) / (2 * h)
    # the solution is a minimum: the gradient vanishes
    assert np.abs(J.T @ r0).max() < 1e-6 * np.abs(J).max()
    Q = np.linalg.inv(J.T @ J)
    dof = len(r0) - len(x0)
    s0 = math.sqrt(r0 @ r0 / dof)
    assert sol.dof == dof
    assert sol.sigma0 == pytest.approx(s0, rel=1e-9)
    sd = np.sqrt(np.diag(Q)) * s0
    np.testing.assert_allclose(sol.eo_std, sd[: 6 * M].reshape(M, 6), rtol=1e-5)
    np.testing.assert_allclose(sol.calibration_std[0, free], sd[6 * M : 6 * M + 2], rtol=1e-5)
    Qp = Q[6 * M + 2 :, 6 * M + 2 :]
    cov = np.array([Qp[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] for i in range(P)]) * s0**2
    np.testing.assert_allclose(sol.xyz_cov, cov, rtol=1e-3, atol=1e-12)
    H = J @ Q @ J.T
    N = len(pb.obs_image)
    red = 1.0 - np.diag(H)[: 2 * N].reshape(N, 2)
    np.testing.assert_allclose(sol.redundancy, red, atol=1e-6)
    # redundancy numbers sum to the degrees of freedom (control and GPS hold the rest)
    rc = 1.0 - np.diag(H)[2 * N :]
    assert sol.redundancy.sum() + rc.sum() == pytest.approx(dof, abs=1e-4)


@pytest.fixture(scope="module")
def block():
    return simulate_block(3, 8, points_per_image=200, seed=11)


def test_truth_is_recovered_within_the_estimated_precision(block):
    sb = block
    sol = bd.adjust(sb.problem)
    r = sol.dof
    assert abs(sol.sigma0 - 1.0) < 3 / math.sqrt(2 * r)  # the injected noise, recovered
    err = (sol.eo - sb.eo) / sol.eo_std
    assert np.abs(err).max() < 4.0, np.abs(err).max(axis=0)
    pts = (sol.xyz - sb.xyz) / sol.xyz_std
    # point errors share the errors of the orientations: about 6 M independent samples
    n = 6 * sb.problem.n_images
    assert abs(np.sqrt(np.mean(pts**2)) - 1.0) < 3 / math.sqrt(2 * n)
    # check points: the object rms within 1.2x of what the covariance predicts
    chk = sb.check
    rms = np.sqrt(np.mean((sol.xyz[chk] - sb.xyz[chk]) ** 2))
    pred = np.sqrt(np.mean(sol.xyz_std[chk] ** 2))
    assert rms < 1.2 * pred * (1 + 3 / math.sqrt(2 * 3 * len(chk)))


def test_noise_level_is_recovered():
    """sigma0 times the a priori sigma is the injected noise, within 10 %."""
    for sigma_px in (0.05, 0.3):
        sb = simulate_block(2, 6, points_per_image=150, sigma_px=sigma_px, seed=3)
        pb = sb.problem
        pb.obs_sigma[:] = 0.1 * sb.pixel_mm  # a priori 0.1 px, whatever the truth
        sol = bd.adjust(pb)
        assert sol.sigma0 * 0.1 == pytest.approx(sigma_px, rel=0.1)


def test_gross_errors_are_found():
    """5 % gross errors (2-20 px): >= 95 % of those on points with >= 3 rays rejected,
    < 1 % of the good observations of such points; sigma0 back to the noise."""
    sb = simulate_block(3, 8, points_per_image=200, gross_fraction=0.05, seed=7)
    pb = sb.problem
    sol, rej = bd.robust_adjust(pb)
    out = np.zeros(len(pb.obs_image), bool)
    out[[r.obs for r in rej if r.obs >= 0]] = True
    rays = np.bincount(pb.obs_point)[pb.obs_point]
    g = sb.gross
    assert out[g & (rays >= 3)].mean() >= 0.95
    assert out[~g & (rays >= 3)].mean() < 0.01
    assert abs(sol.sigma0 - 1.0) < 0.1
    # every rejection says why, with its residual and test value
    assert all(r.reason and r.round >= 1 and len(r.residual) == 2 for r in rej if r.obs >= 0)
    # the orientations are as good as without gross errors
    err = (sol.eo - sb.eo) / sol.eo_std
    assert np.abs(err).max() < 4.0


def test_a_wrong_control_point_is_rejected():
    sb = simulate_block(3, 6, points_per_image=150, seed=2)
    pb = sb.problem
    pb.ctrl_xyz[3, 2] += 1.0  # a height wrong by 1 m (sigma 3 cm)
    _, rej = bd.robust_adjust(pb)
    ctrl = [r for r in rej if r.control >= 0]
    assert [r.control for r in ctrl] == [3]
    assert ctrl[0].reason == bd.REJECTED_CONTROL
    assert abs(ctrl[0].residual[2]) > 0.5


def test_self_calibration_recovers_the_camera():
    """A camera with 15 um radial distortion at r0 and a principal distance off by 50 um,
    in a block with strong relief: k1 and c are found within 3 sigma."""
    sb = simulate_block(3, 8, points_per_image=300, relief_m=400.0, seed=4)
    pb = sb.problem
    k1_true, dc = 15e-3 / pb.radius_mm[0], 0.05
    cal_true = pb.calibration[0].copy()
    cal_true[0] += dc
    cal_true[3] = k1_true
    # measured = ideal - dx(measured): solve the fixed point
    ideal, _ = bd.project(pb, sb.eo, sb.xyz, cal_true[None, :])
    noise = pb.obs_xy - bd.project(pb, sb.eo, sb.xyz)[0]
    meas = ideal.copy()
    k = np.zeros(len(meas), int)
    for _ in range(20):
        dx, dy, _, _ = bd._additional(cal_true[None, :], pb.radius_mm, k, meas)
        meas = ideal - np.c_[dx, dy]
    pb.obs_xy = meas + noise
    pb.free = np.zeros((1, 10), bool)
    pb.free[0, [0, 3]] = True
    sol = bd.adjust(pb)
    est, sd = sol.calibration[0], sol.calibration_std[0]
    assert abs(est[0] - cal_true[0]) < 3 * sd[0]
    assert abs(est[3] - k1_true) < 3 * sd[3]
    assert sol.calibration_corr.shape == (2, 2)
    assert np.isfinite(sol.calibration_eo_corr).all()
    assert abs(sol.sigma0 - 1) < 0.1


def test_no_datum_is_refused():
    sb = simulate_block(2, 4, points_per_image=100, control=0, check=0, seed=1)
    with pytest.raises(DegenerateGeometryError, match="datum"):
        bd.adjust(sb.problem)


def test_points_behind_the_camera_are_refused():
    pb = _small_problem()
    pb.xyz[:, 2] = 5000.0  # above the cameras
    with pytest.raises(OrientationError, match="behind"):
        bd.adjust(pb)


def test_bad_problems_are_refused():
    pb = _small_problem()
    with pytest.raises(OrientationError, match="out of range"):
        bd.BundleProblem(
            calibration=pb.calibration, radius_mm=pb.radius_mm, camera=pb.camera, eo=pb.eo,
            xyz=pb.xyz, obs_image=pb.obs_image, obs_point=pb.obs_point + 1000,
            obs_xy=pb.obs_xy, obs_sigma=pb.obs_sigma,
        )  # fmt: skip
    bad = pb.obs_xy.copy()
    bad[0, 0] = np.nan
    with pytest.raises(OrientationError, match="not finite"):
        bd.BundleProblem(
            calibration=pb.calibration, radius_mm=pb.radius_mm, camera=pb.camera, eo=pb.eo,
            xyz=pb.xyz, obs_image=pb.obs_image, obs_point=pb.obs_point, obs_xy=bad,
            obs_sigma=pb.obs_sigma,
        )  # fmt: skip
    with pytest.raises(OrientationError, match="twice"):
        bd.BundleProblem(
            calibration=pb.calibration, radius_mm=pb.radius_mm, camera=pb.camera, eo=pb.eo,
            xyz=pb.xyz, obs_image=np.r_[pb.obs_image, pb.obs_image[:1]],
            obs_point=np.r_[pb.obs_point, pb.obs_point[:1]],
            obs_xy=np.r_[pb.obs_xy, pb.obs_xy[:1]], obs_sigma=0.002,
        )  # fmt: skip


def test_intersect_rays():
    C = np.array([[0.0, 0, 100], [10, 0, 100], [0, 0, 100]])
    target = np.array([[3.0, 4.0, 0.0], [1.0, 1.0, 0.0]])
    d = np.array([target[0] - C[0], target[0] - C[1], target[1] - C[2]])
    xyz, ok = bd.intersect_rays(C, d, np.array([0, 0, 1]), 2)
    np.testing.assert_allclose(xyz[0], target[0], atol=1e-9)
    assert ok.tolist() == [True, False]  # one ray only


def test_normal_deviate():
    from scipy.stats import norm

    T = np.array([norm.isf(0.025) ** 2, 1e6, np.nan, 3.0])
    w = bd.normal_deviate(T, np.array([1, 2, 2, 0]))
    assert w[0] == pytest.approx(norm.isf(0.025))
    assert w[1] == pytest.approx(1000.0, rel=0.01)
    assert np.isnan(w[2])
    assert w[3] == 0.0
