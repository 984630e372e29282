"""Fiducial marks: drawing by area coverage, coarse candidates, level-0 refinement."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from apygis.aerotri.camera import Camera, PixelTransform
from apygis.aerotri.fiducials import (
    BRIGHT_DN,
    DARK_DN,
    draw_marks,
    find_candidates,
    refine_mark,
)
from apygis.aerotri.imagery import ArraySource, level_to_full

FIDUCIALS = {
    "1": (-106.0, 106.0), "2": (106.0, 106.0), "3": (106.0, -106.0), "4": (-106.0, -106.0),
    "5": (0.0, 110.0), "6": (110.0, 0.0), "7": (0.0, -110.0), "8": (-110.0, 0.0),
}  # fmt: skip
CAMERA = Camera(
    name="synthetic", kind="film", focal_mm=153.0, fiducials=FIDUCIALS,
    orientation_mark_mm=(-12.0, 110.0),
)  # fmt: skip
# bright area of a fiducial mark: disk r 0.3 plus ring 1.0..1.3 (mm^2)
BRIGHT_AREA = math.pi * (0.3**2 + 1.3**2 - 1.0**2)


def local_transform(pixel_mm: float, angle_deg: float, centre_px, centre_mm, mirror=False):
    """Pixel -> mm with the given pixel size and rotation, ``centre_px`` on ``centre_mm``."""
    t = math.radians(angle_deg)
    f = np.diag([1.0, 1.0 if mirror else -1.0])  # rows down (or a mirrored scan)
    a = pixel_mm * np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]) @ f
    tv = np.asarray(centre_mm, float) - a @ np.asarray(centre_px, float)
    return PixelTransform(np.vstack([np.column_stack([a, tv]), [0.0, 0.0, 1.0]]))


def _reference(t: PixelTransform, n: int, k: int = 32) -> np.ndarray:
    """Brute-force area coverage of the disk and ring (k x k samples in every pixel)."""
    offs = (np.arange(k) + 0.5) / k - 0.5
    rows, cols = np.mgrid[0:n, 0:n]
    shape = (n, n, k, k)
    sc = np.broadcast_to(cols[..., None, None] + offs[None, None, None, :], shape).ravel()
    sr = np.broadcast_to(rows[..., None, None] + offs[None, None, :, None], shape).ravel()
    mm = t.to_mm(np.column_stack([sc, sr])) - np.array(FIDUCIALS["6"])
    r = np.hypot(mm[:, 0], mm[:, 1])
    bright = (r <= 0.3) | ((r >= 1.0) & (r <= 1.3))
    g = np.where(bright, BRIGHT_DN, DARK_DN).reshape(n, n, k * k)
    return g.mean(axis=2)


@settings(max_examples=8, deadline=None)
@given(
    dx=st.floats(-0.5, 0.5),
    dy=st.floats(-0.5, 0.5),
    angle=st.floats(-180.0, 180.0),
    pixel_um=st.floats(60.0, 120.0),
    mirror=st.booleans(),
)
def test_drawn_mark_is_area_coverage(dx, dy, angle, pixel_um, mirror):
    # area coverage: the sum of (g - dark) * pixel area is the bright area times the
    # contrast. 16 x 16 point samples on boundary pixels: a pixel's coverage error is
    # below one sample row (1/16 of the contrast, reached where an edge runs along a
    # row), ~1/200 of the contrast rms with random sign, so the area is good to
    # ~1e-3 relative and a 32 x 32 brute-force reference agrees to 1/16 (max) and
    # 1/100 (rms over the boundary pixels) of the contrast.
    # The pixel-sampled centroid differs from the true centre by the sampling of the
    # first moment (not a drawing error), a few 1e-3 px: checked to 0.01 px.
    p = pixel_um / 1000.0
    n = int(3.0 / p) | 1  # the disk and ring (r <= 1.3 mm) and a margin, all dark
    c = np.array([(n - 1) / 2 + dx, (n - 1) / 2 + dy])
    t = local_transform(p, angle, c, FIDUCIALS["6"], mirror)
    img = draw_marks(np.full((n, n), DARK_DN), t, CAMERA)
    w = img - DARK_DN
    assert abs(w.sum() * p * p / (BRIGHT_DN - DARK_DN) / BRIGHT_AREA - 1.0) < 2e-3
    ref = _reference(t, n)
    diff = (img - ref)[(ref > DARK_DN) & (ref < BRIGHT_DN)]
    assert np.abs(img - ref).max() < (BRIGHT_DN - DARK_DN) / 16.0
    assert np.sqrt(np.mean(diff**2)) < (BRIGHT_DN - DARK_DN) / 100.0
    rows, cols = np.mgrid[0:n, 0:n]
    centroid = np.array([(w * cols).sum(), (w * rows).sum()]) / w.sum()
    assert np.hypot(*(centroid - c)) < 0.01


def test_draw_marks_keeps_input_and_draws_orientation_mark():
    p = 0.1
    n = 2600  # covers +-130 mm
    t = PixelTransform.affine(p, 0, 0, -p, -(n - 1) / 2 * p, (n - 1) / 2 * p)
    bg = np.full((n, n), 120.0, dtype=np.float32)
    out = draw_marks(bg, t, CAMERA)
    assert out.dtype == np.float32
    assert (bg == 120.0).all()
    col, row = np.rint(t.to_px([(-12.0, 110.0)])[0]).astype(int)
    assert out[row, col] == BRIGHT_DN  # the orientation mark's disk
    assert out[row, col + 12] == DARK_DN  # its square (1.2 mm from the centre)
    assert out[row, col + 25] == 120.0  # outside (2.5 mm)
    col, row = np.rint(t.to_px([(110.0, 0.0)])[0]).astype(int)
    assert out[row, col] == BRIGHT_DN
    assert out[row, col + 6] == DARK_DN
    assert out[row, col + 11] == BRIGHT_DN  # the ring at 1.1 mm
    # no other change than within the marks' squares
    changed = np.argwhere(out != 120.0)
    mm = t.to_mm(changed[:, ::-1].astype(float))
    centres = np.array([*FIDUCIALS.values(), (-12.0, 110.0)])
    cheb = np.abs(mm[:, None, :] - centres[None, :, :]).max(axis=2).min(axis=1)
    assert cheb.max() <= 4.0 + 0.75 * p


def _noisy_scan(rng, pixel_mm=0.08, n=400, centre_mm=(110.0, 0.0), angle=0.3, sigma=3.0):
    c = np.array([(n - 1) / 2 + rng.uniform(-0.5, 0.5), (n - 1) / 2 + rng.uniform(-0.5, 0.5)])
    t = local_transform(pixel_mm, angle, c, centre_mm)
    img = draw_marks(np.full((n, n), 120.0), t, CAMERA) + rng.normal(0.0, sigma, (n, n))
    return img, t, c


def test_refine_mark_precision_matches_the_noise():
    # Least-squares precision of the centre: sigma_c ~ sigma_n / (contrast *
    # sqrt(sum of squared model slopes)); with sigma_n = 3 DN, contrast 220 DN and
    # ~4 x 2 pi (0.3 + 1.0 + 1.3) mm / 0.08 mm = ~800 edge pixels of slope ~1/px
    # (split over two axes) that is ~3 / (220 * 20) = ~0.0007 px; the fit's own
    # estimate (edges are ramps, not steps) is ~0.004 px. 12 marks: the rms error
    # must lie below 3x the mean estimate (chi-square with 24 dof: P(>1.5x) < 1e-3;
    # the remaining factor covers the edge model), and the estimate be of that order.
    rng = np.random.default_rng(7)
    errors, sigmas = [], []
    for _ in range(12):
        img, t, c = _noisy_scan(rng)
        start = c + rng.uniform(-6.0, 6.0, 2)  # 0.5 mm off
        fit = refine_mark(ArraySource(img), start, t.matrix[:2, :2])
        assert fit.ok
        assert fit.r2 > 0.95
        assert abs(fit.contrast - (BRIGHT_DN - DARK_DN)) < 5.0
        errors.append(np.array(fit.xy) - c)
        sigmas.append(fit.sigma_px)
    rms = float(np.sqrt(np.mean(np.square(errors))))
    s = float(np.mean(sigmas))
    assert 0.001 < s < 0.01
    assert rms < 3.0 * s


def test_refine_mark_rejects_no_mark():
    rng = np.random.default_rng(3)
    img = 120.0 + rng.normal(0.0, 3.0, (200, 200))
    fit = refine_mark(ArraySource(img), (100.0, 100.0), np.diag([0.08, -0.08]))
    assert not fit.ok


def test_find_candidates_at_a_coarse_level():
    rng = np.random.default_rng(11)
    p = 0.08
    n = 3000
    t = PixelTransform.affine(p, 0, 0, -p, -(n - 1) / 2 * p, (n - 1) / 2 * p)
    img = draw_marks(np.full((n, n), 120.0, np.float32), t, CAMERA)
    img += rng.normal(0.0, 3.0, img.shape).astype(np.float32)
    src = ArraySource(img)
    xy, score = find_candidates(src.array(2), 4 * p)
    assert len(xy) == 8
    assert (score > 0.7).all()
    truth = t.to_px(np.array(list(FIDUCIALS.values())))
    d = np.abs(level_to_full(xy, 2)[:, None, :] - truth[None, :, :]).max(axis=2).min(axis=1)
    assert d.max() < 2.0  # half a coarse pixel
    oxy, _ = find_candidates(src.array(2), 4 * p, orientation=True, threshold=0.6)
    o = t.to_px([(-12.0, 110.0)])[0]
    assert np.hypot(*(level_to_full(oxy, 2) - o).T).min() < 2.0
    blank = np.full((700, 700), 100.0)
    assert len(find_candidates(blank, 0.32)[0]) == 0


@pytest.mark.parametrize("pixel_um", [20.0, 80.0])
def test_refine_mark_in_a_rotated_scan(pixel_um):
    rng = np.random.default_rng(5)
    p = pixel_um / 1000.0
    n = int(6.0 / p)
    c = np.array([n / 2 + 0.37, n / 2 - 0.21])
    t = local_transform(p, 90.4, c, FIDUCIALS["2"], mirror=True)
    img = draw_marks(np.full((n, n), 120.0), t, CAMERA) + rng.normal(0.0, 3.0, (n, n))
    fit = refine_mark(ArraySource(img), c + 0.3 / p, t.matrix[:2, :2])
    assert fit.ok
    assert np.hypot(*(np.array(fit.xy) - c)) < 5.0 * max(fit.sigma_px)
