"""Exchange blocks made from simulated bundle problems (apygis.aerotri.simulate), for tests.

:func:`sim_block` turns a :class:`~apygis.aerotri.simulate.SimulatedBlock` into an
:class:`~apygis.aerotri.exchange.ExchangeBlock` with everything a format may carry:
a camera, images with a pixel transform, raster size, true exterior orientation and
standard deviations, tie points with their true coordinates, control points of every
kind and check points, and observations in photo mm and pixels with sigmas.
"""

from __future__ import annotations

import math

import numpy as np

from apygis.aerotri.camera import PixelTransform
from apygis.aerotri.exchange import ExCamera, ExchangeBlock, ExImage, ExObservation, ExPoint
from apygis.aerotri.simulate import simulate_block


def sim_block(
    strips: int = 2,
    images_per_strip: int = 4,
    points_per_image: int = 60,
    *,
    film: bool = False,
    seed: int = 1,
    crs: str = "EPSG:2056",
    origin=(2_600_000.0, 1_200_000.0, 400.0),
) -> ExchangeBlock:
    """A realistic small block: a 153 mm camera, 10 um pixels (a 23 000 px square digital
    frame, or for ``film`` a scanned film whose pixel transform is a rotated, slightly
    affine scan), control of every kind and check points, ground coordinates in LV95."""
    sim = simulate_block(
        strips, images_per_strip, points_per_image=points_per_image, control=8, check=3, seed=seed
    )
    pb = sim.problem
    rng = np.random.default_rng(seed)
    size = 23_000
    if film:
        cam = ExCamera(1, "RC30 film", 153.0, 0.004, -0.003, kind="film")
    else:
        cam = ExCamera(
            1,
            "DMC digital",
            153.0,
            0.004,
            -0.003,
            kind="digital",
            width_px=size,
            height_px=size,
            pixel_mm=0.01,
        )
    off = np.array(origin)
    images = []
    transforms = {}
    for i in range(len(sim.eo)):
        if film:
            a = math.radians(rng.normal(0, 0.3))
            s = 0.01 * (1 + rng.normal(0, 1e-4))
            t = PixelTransform.affine(
                s * math.cos(a), -s * math.sin(a) * 1.0002, -s * math.sin(a), -s * math.cos(a),
                -115.0 + rng.normal(0, 0.2), 115.0 + rng.normal(0, 0.2),
            )  # fmt: skip
        else:
            t = PixelTransform.digital(size, size, 10.0)
        n = 101 + i
        eo = sim.eo[i].copy()
        eo[:3] += off
        images.append(
            ExImage(
                image=n,
                name=f"img_{n}.tif",
                camera=1,
                pixel_to_mm=t.matrix.copy(),
                width_px=size,
                height_px=size,
                eo=eo,
                eo_std=np.array([0.05, 0.05, 0.04, 1e-5, 1e-5, 5e-6]),
            )
        )
        transforms[n] = t
    ctrl = set(pb.ctrl_point.tolist())
    chk = set(sim.check.tolist())
    kinds = {}
    for k, j in enumerate(sorted(ctrl)):
        kinds[j] = ("full", "full", "planimetric", "height")[k % 4]
    points = []
    for j, xyz in enumerate(sim.xyz):
        kind = kinds.get(j, "check" if j in chk else "tie")
        p = xyz + off
        if kind == "planimetric":
            p = np.array([p[0], p[1], np.nan])
        sigma = np.array([0.02, 0.02, 0.03]) if kind != "tie" else np.array([0.05, 0.05, 0.08])
        points.append(ExPoint(str(1000 + j), kind, p, sigma))
    obs = []
    for i, j, (x, y) in zip(
        pb.obs_image.tolist(), pb.obs_point.tolist(), pb.obs_xy.tolist(), strict=True
    ):
        n = 101 + i
        x, y = x + cam.x0_mm, y + cam.y0_mm  # the simulation's principal point is at 0, 0
        col, row = transforms[n].to_px([[x, y]])[0].tolist()
        obs.append(ExObservation(str(1000 + j), n, x, y, col, row, 0.1))
    return ExchangeBlock(crs=crs, cameras=[cam], images=images, points=points, observations=obs)
