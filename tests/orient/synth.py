"""Synthetic truth for the orientation tests: a stereo pair over a terrain, control spots.

Set-up (like the samples): photos about 1:15000, c = 153 mm, flying height
about 2295 m above a hilly terrain of about 430-620 m, base 1380 m (60 %
overlap), the optics turning the photo image by half a turn (kappa ~ pi,
positive map-to-photo scale factors), Swiss LV95 coordinates around
E 2'684'200, N 1'247'800.
"""

from __future__ import annotations

import math

import numpy as np

from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation
from apygis.orient.photo import PhotoOrientation

C_MM = 153.0
XM, YM = 2_684_200.0, 1_247_800.0
H = 2295.0
BASE = 1380.0
Z_MEAN = 520.0
GON = math.pi / 200.0


def terrain(X, Y):
    """Hilly synthetic terrain, metres."""
    x = (np.asarray(X, dtype=float) - XM) / 1200.0
    y = (np.asarray(Y, dtype=float) - YM) / 800.0
    return 500.0 + 50.0 * y**2 + 45.0 * np.sin(2.5 * x + 0.5) * np.cos(1.7 * y) - 20.0 * x * y


def pair(scanned: bool = False, kappa_left: float = math.pi, kappa_right: float = math.pi):
    """True left and right PhotoOrientation."""
    io = InteriorOrientation(C_MM, 0.012, -0.008, scanned)
    zo = Z_MEAN + H
    s = C_MM / H * 1.004
    left = PhotoOrientation(
        "L",
        io,
        ExteriorOrientation(
            XM - BASE / 2 + 12.0, YM - 20.0, zo + 9.0, 0.0035, -0.0052, kappa_left + 0.011
        ),
        s,
        s * 0.9985,
    )
    right = PhotoOrientation(
        "R",
        io,
        ExteriorOrientation(
            XM + BASE / 2 - 8.0, YM + 15.0, zo - 6.0, -0.0028, 0.0041, kappa_right - 0.009
        ),
        s * 1.001,
        s * 0.999,
    )
    return left, right


def control_spots(n: int = 8, rng=None, jitter: float = 60.0) -> np.ndarray:
    """``n`` control spots (X, Y, Z) in the standard orientation areas of the model."""
    base = [(-700, 700), (-700, 0), (-700, -700), (700, 700), (700, 0), (700, -700),
            (0, 650), (0, -650), (-350, 350), (350, -350), (350, 350), (-350, -350)]  # fmt: skip
    if n > len(base):
        raise ValueError("too many spots")
    xy = np.array(base[:n], dtype=float) + np.array([XM, YM])
    if rng is not None and jitter:
        xy = xy + rng.uniform(-jitter, jitter, xy.shape)
    return np.column_stack([xy, terrain(xy[:, 0], xy[:, 1])])


def model_points(n: int, rng) -> np.ndarray:
    """``n`` random ground points on the terrain inside the stereo model."""
    X = XM + rng.uniform(-650, 650, n)
    Y = YM + rng.uniform(-750, 750, n)
    return np.column_stack([X, Y, terrain(X, Y)])


def wrap(a):
    """Angle difference into (-pi, pi]."""
    return np.remainder(np.asarray(a) + np.pi, 2 * np.pi) - np.pi


def param_error(est, true) -> np.ndarray:
    """est - true for 8 photo parameters with the angles wrapped."""
    d = np.asarray(est, dtype=float) - np.asarray(true, dtype=float)
    d[3:6] = wrap(d[3:6])
    return d
