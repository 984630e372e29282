"""Simulated bundle problems: image observations of a block with known truth and noise.

Unlike :mod:`apygis.aerotri.synth`, which renders photos, this module makes the
observations directly: it is for testing and timing the bundle adjustment on
blocks of any size (the seed's Graz block has 659 images), with known noise and
known gross errors.

Geometry (conventions of :mod:`apygis.orient.rotation`): strips run east-west
(strip 1 in the north), flown alternately east and west (``kappa`` 0 and pi:
photo x along the flight), at the flying height ``H = c * scale`` over a
terrain of smooth relief; the attitude adds random omega, phi (s.d.
``attitude_sd_deg``) and kappa. Tie points are drawn uniformly over the block
at a density that gives each image about ``points_per_image`` observations,
kept where they fall in at least two images (inside the format, less a
margin). Image coordinates get Gaussian noise of ``sigma_px`` (pixel
``pixel_um``) per coordinate; a share ``gross_fraction`` of the observations
gets a gross error of ``gross_px`` (uniform between the two values) in a random
direction. Control points are tie points near the block's corners and edges
(``control``), with Gaussian errors of their sigmas; check points likewise
(``check``). The approximate values are the truth plus Gaussian errors
(``approx_centre_m``, ``approx_angle_deg``), the points intersected from them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from apygis.orient.bundle import BundleProblem, intersect_rays
from apygis.orient.rotation import rotation_matrix

__all__ = ["SimulatedBlock", "simulate_block"]


@dataclass
class SimulatedBlock:
    """A simulated problem with its truth.

    ``problem`` holds the approximate values; ``eo`` ``(M, 6)`` and ``xyz``
    ``(P, 3)`` the truth; ``gross`` ``(N,)`` marks the observations given a
    gross error; ``check`` ``(Ck,)`` the point indices of the check points
    (not in the problem's control) and ``check_xyz`` their true coordinates;
    ``strip`` ``(M,)`` the strip of each image; ``pixel_mm`` the pixel size.
    """

    problem: BundleProblem
    eo: np.ndarray
    xyz: np.ndarray
    gross: np.ndarray
    check: np.ndarray
    strip: np.ndarray
    pixel_mm: float
    sigma_px: float


def simulate_block(
    strips: int = 3,
    images_per_strip: int = 8,
    *,
    points_per_image: int = 300,
    forward_overlap: float = 0.6,
    side_overlap: float = 0.3,
    focal_mm: float = 153.0,
    format_mm: float = 230.0,
    scale: float = 10000.0,
    pixel_um: float = 10.0,
    sigma_px: float = 0.1,
    relief_m: float = 50.0,
    attitude_sd_deg: float = 0.3,
    gross_fraction: float = 0.0,
    gross_px: tuple[float, float] = (2.0, 20.0),
    control: int = 10,
    check: int = 10,
    control_sigma_m: tuple[float, float] = (0.02, 0.03),
    approx_centre_m: float = 5.0,
    approx_angle_deg: float = 0.5,
    seed: int = 0,
) -> SimulatedBlock:
    """Simulate a block (module docstring). Image ``i`` of strip ``s`` (0-based) has index
    ``s * images_per_strip + i``."""
    rng = np.random.default_rng(seed)
    c = focal_mm
    H = c * scale / 1000.0
    F = format_mm * scale / 1000.0  # footprint side, metres
    B = (1.0 - forward_overlap) * F
    D = (1.0 - side_overlap) * F
    M = strips * images_per_strip
    eo = np.zeros((M, 6))
    strip = np.repeat(np.arange(strips), images_per_strip)
    sd = math.radians(attitude_sd_deg)
    for s in range(strips):
        for i in range(images_per_strip):
            n = s * images_per_strip + i
            east = s % 2 == 0
            x = (i if east else images_per_strip - 1 - i) * B
            eo[n] = (
                x + rng.normal(0, 0.01 * B),
                -s * D + rng.normal(0, 0.01 * D),
                H + rng.normal(0, 0.005 * H),
                rng.normal(0, sd),
                rng.normal(0, sd),
                (0.0 if east else math.pi) + rng.normal(0, sd),
            )
    xmin, xmax = -0.5 * F, (images_per_strip - 1) * B + 0.5 * F
    ymin, ymax = -(strips - 1) * D - 0.5 * F, 0.5 * F
    area = (xmax - xmin) * (ymax - ymin)
    n_pts = int(points_per_image * area / (F * F))  # each image sees about points_per_image
    X = rng.uniform(xmin, xmax, n_pts)
    Y = rng.uniform(ymin, ymax, n_pts)

    def terrain(x, y):
        return relief_m * (
            0.5 * np.sin(x / (0.7 * F)) * np.cos(y / (0.9 * F)) + 0.3 * np.sin((x + y) / (0.33 * F))
        )

    xyz = np.c_[X, Y, terrain(X, Y)]
    R = rotation_matrix(eo[:, 3], eo[:, 4], eo[:, 5])
    half = 0.5 * format_mm * 0.95
    oi, op, oxy = [], [], []
    for n in range(M):
        q = (xyz - eo[n, :3]) @ R[n]
        x = -c * q[:, 0] / q[:, 2]
        y = -c * q[:, 1] / q[:, 2]
        vis = (np.abs(x) < half) & (np.abs(y) < half)
        idx = np.nonzero(vis)[0]
        oi.append(np.full(len(idx), n))
        op.append(idx)
        oxy.append(np.c_[x[idx], y[idx]])
    obs_i = np.concatenate(oi)
    obs_p = np.concatenate(op)
    xy_true = np.vstack(oxy)
    rays = np.bincount(obs_p, minlength=n_pts)
    keep_pt = rays >= 2
    keep = keep_pt[obs_p]
    new = np.cumsum(keep_pt) - 1
    obs_i, obs_p, xy_true = obs_i[keep], new[obs_p[keep]], xy_true[keep]
    xyz = xyz[keep_pt]
    P = len(xyz)
    pix = pixel_um / 1000.0
    sig = sigma_px * pix
    xy = xy_true + rng.normal(0.0, sig, xy_true.shape)
    gross = rng.random(len(obs_i)) < gross_fraction
    if gross.any():
        mag = rng.uniform(gross_px[0], gross_px[1], gross.sum()) * pix
        ang = rng.uniform(0, 2 * math.pi, gross.sum())
        xy[gross] += np.c_[mag * np.cos(ang), mag * np.sin(ang)]
    # control and check points: well-observed points spread along the block's edge
    rays = np.bincount(obs_p, minlength=P)
    cand = np.nonzero(rays >= 3)[0]
    sel = _spread(xyz[cand, :2], control + check, rng)
    chosen = cand[sel]
    ctrl = chosen[:control]
    chk = chosen[control:]
    sxy, sz = control_sigma_m
    ctrl_sigma = np.tile([sxy, sxy, sz], (len(ctrl), 1))
    ctrl_xyz = xyz[ctrl] + rng.normal(0.0, 1.0, (len(ctrl), 3)) * ctrl_sigma
    # approximate values
    eo0 = eo.copy()
    eo0[:, :3] += rng.normal(0.0, approx_centre_m, (M, 3))
    eo0[:, 3:] += rng.normal(0.0, math.radians(approx_angle_deg), (M, 3))
    R0 = rotation_matrix(eo0[:, 3], eo0[:, 4], eo0[:, 5])
    d = np.einsum("nij,nj->ni", R0[obs_i], np.c_[xy, np.full(len(xy), -c)])
    xyz0, ok = intersect_rays(eo0[obs_i, :3], d, obs_p, P)
    xyz0[~ok] = xyz[~ok] + rng.normal(0, 1.0, (int((~ok).sum()), 3))
    problem = BundleProblem(
        calibration=np.array([[c, 0.0, 0.0, 0, 0, 0, 0, 0, 0, 0]]),
        radius_mm=np.array([format_mm / math.sqrt(2.0)]),
        camera=np.zeros(M, np.int64),
        eo=eo0,
        xyz=xyz0,
        obs_image=obs_i,
        obs_point=obs_p,
        obs_xy=xy,
        obs_sigma=np.full((len(xy), 2), sig),
        ctrl_point=ctrl,
        ctrl_xyz=ctrl_xyz,
        ctrl_sigma=ctrl_sigma,
    )
    return SimulatedBlock(problem, eo, xyz, gross, chk, strip, pix, sigma_px)


def _spread(xy: np.ndarray, n: int, rng) -> np.ndarray:
    """Indices of ``n`` points spread over ``xy``: farthest-point sampling from the corner."""
    if n <= 0 or not len(xy):
        return np.zeros(0, np.int64)
    n = min(n, len(xy))
    first = int(np.argmin(xy[:, 0] + xy[:, 1]))
    chosen = [first]
    d = np.linalg.norm(xy - xy[first], axis=1)
    for _ in range(n - 1):
        k = int(np.argmax(d))
        chosen.append(k)
        d = np.minimum(d, np.linalg.norm(xy - xy[k], axis=1))
    del rng
    return np.array(chosen, np.int64)
