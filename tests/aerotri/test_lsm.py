"""Least-squares matching against synthetic truth.

The images are samples of a *continuous* texture, a random field of K cosines
``T(x) = sum a cos(w_k . x + phi_k)`` with frequencies drawn from the spectrum
of Gaussian-filtered white noise (``w ~ N(0, 1/(2 s^2))`` per axis for a filter
of ``s`` px), evaluated exactly at every pixel of both images: the search image
is ``S(x) = T(M^-1 (x - d))`` (true affine ``M``, shift ``d``), never a
resampling of the reference with the matcher's own interpolator.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy import ndimage

from apygis.aerotri.imagery import ArraySource, full_to_level, level_to_full
from apygis.aerotri.lsm import LsmReason, SplineImage, lsm, track

STD = 30.0  # texture standard deviation, DN


def cosine_texture(rng, scales, k=150, std=STD):
    """Continuous texture: ``k`` cosines per scale ``s`` (px) of the list ``scales``."""
    om = np.concatenate([rng.normal(scale=1 / (np.sqrt(2) * s), size=(k, 2)) for s in scales])
    ph = rng.uniform(0, 2 * np.pi, len(om)).astype(np.float32)
    amp = np.full(len(om), std * np.sqrt(2 / len(om)), dtype=np.float32)
    om = om.astype(np.float32)

    def texture(xy):
        xy = np.asarray(xy, dtype=np.float32)
        shape = xy.shape[:-1]
        xy = xy.reshape(-1, 2)
        out = np.empty(len(xy))
        for s in range(0, len(xy), 32768):
            out[s : s + 32768] = np.cos(xy[s : s + 32768] @ om.T + ph) @ amp
        return out.reshape(shape)

    return texture


def pixel_grid(h, w):
    cc, rr = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return np.stack([cc, rr], -1)


ROT = np.radians(2.0)
M_TRUE = np.array([[np.cos(ROT), -np.sin(ROT)], [np.sin(ROT), np.cos(ROT)]]) @ np.array(
    [[1.03, 0.02], [0.0, 1.03]]
)  # rotation 2 deg, scale 1.03, shear 0.02
D_TRUE = np.array([12.3, -7.6])


@pytest.fixture(scope="module")
def pair():
    """Noise-free reference and search images (700 x 700) of one texture, s = 1.8 px."""
    rng = np.random.default_rng(42)
    tex = cosine_texture(rng, [1.8])
    pix = pixel_grid(700, 700)
    ref = tex(pix)
    search = tex((pix - D_TRUE) @ np.linalg.inv(M_TRUE).T)
    return ref, search


def grid_points(lo, hi, step):
    g = np.arange(lo, hi, step, dtype=float)
    x, y = np.meshgrid(g, g)
    return np.stack([x.ravel(), y.ravel()], 1)


def test_spline_image_equals_map_coordinates_and_derivatives():
    rng = np.random.default_rng(1)
    img = rng.normal(size=(40, 50)) * 10
    sp = SplineImage(img, col0=5, row0=3, dtype=np.float64)
    coef = ndimage.spline_filter(img, order=3, mode="mirror")
    pts = np.c_[rng.uniform(5, 54, 500), rng.uniform(3, 42, 500)]
    want = ndimage.map_coordinates(coef, [pts[:, 1] - 3, pts[:, 0] - 5], order=3, prefilter=False)
    v, gc, gr = sp.sample_grad(pts)
    np.testing.assert_allclose(v, want, atol=1e-10)
    np.testing.assert_allclose(sp.sample(pts), want, atol=1e-10)
    h = 1e-5  # central differences: truncation ~h^2 f''', rounding ~1e-16 * 30 / h
    dc, dr = np.array([h, 0.0]), np.array([0.0, h])
    num_c = (sp.sample(pts + dc) - sp.sample(pts - dc)) / (2 * h)
    num_r = (sp.sample(pts + dr) - sp.sample(pts - dr)) / (2 * h)
    np.testing.assert_allclose(gc, num_c, atol=1e-6)
    np.testing.assert_allclose(gr, num_r, atol=1e-6)
    # the spline interpolates: integer positions give the pixels
    np.testing.assert_allclose(sp.sample([[5.0 + 7, 3.0 + 4]]), [img[4, 7]], atol=1e-10)


def test_noise_free_subpixel_affine(pair):
    ref, search = pair
    rng = np.random.default_rng(2)
    p = rng.uniform(40, 600, size=(500, 2))
    true = p @ M_TRUE.T + D_TRUE
    r = lsm(SplineImage(ref), p, SplineImage(search), true + rng.uniform(-1, 1, (500, 2)))
    assert r.ok.all()
    # only the interpolation error of the (s = 1.8 px) texture is left: ~1e-3 px
    assert np.abs(r.xy - true).max() < 0.005
    assert np.abs(r.affine - M_TRUE).max() < 0.002
    np.testing.assert_allclose(r.gain, 1.0, atol=1e-3)
    assert (r.corr > 0.999).all()


def test_noisy_accuracy_matches_predicted_sigma(pair):
    ref, search = pair
    rng = np.random.default_rng(3)
    sn = 2.5  # DN, pixel-white noise in both images
    ref_n = ref + rng.normal(scale=sn, size=ref.shape)
    search_n = search + rng.normal(scale=sn, size=search.shape)
    # ~1900 points on a 15 px grid: templates (15 x 15) do not overlap -> independent errors
    p = grid_points(25, 680 - 25, 15) + rng.uniform(0, 1, (1, 2))
    p = p + rng.uniform(-0.5, 0.5, p.shape)
    true = p @ M_TRUE.T + D_TRUE
    keep = np.all((true > 20) & (true < 680), axis=1)
    p, true = p[keep], true[keep]
    n = len(p)
    r = lsm(SplineImage(ref_n), p, SplineImage(search_n), true + rng.uniform(-1, 1, (n, 2)))
    assert r.ok.mean() > 0.99
    e = (r.xy - true)[r.ok]
    rms = np.sqrt((e**2).mean())
    rms_pred = np.sqrt((r.sigma[r.ok] ** 2).mean())
    ratio = rms / rms_pred
    med = np.median(np.hypot(*e.T))
    print(
        f"\nLSM noise {sn} DN: RMS {rms:.4f} px/axis, median radial {med:.4f} px, "
        f"predicted RMS {rms_pred:.4f}, ratio {ratio:.3f}"
    )
    # with ~1900 independent points the ratio's own scatter is ~1/sqrt(2 * 2n) ~ 1.2 %
    assert 0.8 < ratio < 1.3
    # unbiased (pixel locking removed): the mean error is within 4 sigma of its scatter
    assert np.all(np.abs(e.mean(axis=0)) < 4 * rms / np.sqrt(len(e)))
    # normalised errors are standard normal in shape, too (no heavy tails among ok points)
    z = np.abs(e / r.sigma[r.ok, None])
    assert np.quantile(z, 0.99) < 3.5 * ratio


def test_no_pixel_locking():
    """Noise interpolated at a fraction f has variance q(f) sigma^2 (q(0.5) = 0.756): the
    plain LSM cost pulls the search point towards half pixels. A pure shift by
    (3.25, -2.25) puts every search sample at fractions (0.25, 0.75), where the pull is
    largest: without the correction the mean error is (+0.046, -0.038) px here (noise
    4 DN on a 30 DN texture); with it the mean is zero within 4 standard errors."""
    rng = np.random.default_rng(9)
    tex = cosine_texture(rng, [1.8])
    pix = pixel_grid(500, 500)
    d = np.array([3.25, -2.25])
    sn = 4.0
    ref = tex(pix) + rng.normal(scale=sn, size=(500, 500))
    search = tex(pix - d) + rng.normal(scale=sn, size=(500, 500))
    p = grid_points(25, 475, 15)  # non-overlapping templates: independent errors
    true = p + d
    r = lsm(SplineImage(ref), p, SplineImage(search), true + rng.uniform(-1, 1, p.shape))
    assert r.ok.mean() > 0.99
    e = (r.xy - true)[r.ok]
    se = np.sqrt((e**2).mean(axis=0) / len(e))
    assert np.all(np.abs(e.mean(axis=0)) < 4 * se)
    np.testing.assert_allclose(r.gain[r.ok].mean(), 1.0, atol=3e-3)  # no attenuation


def test_radiometric_gain_and_offset(pair):
    ref, search = pair
    rng = np.random.default_rng(4)
    p = rng.uniform(40, 600, size=(300, 2))
    true = p @ M_TRUE.T + D_TRUE
    # g_ref = r0 + r1 g_search  with  g_search = (g - 20) / 1.3  ->  r1 = 1.3, r0 = 20
    s = (search - 20.0) / 1.3
    r = lsm(SplineImage(ref), p, SplineImage(s), true + rng.uniform(-1, 1, (300, 2)))
    assert r.ok.all()
    np.testing.assert_allclose(r.gain, 1.3, atol=2e-3)
    np.testing.assert_allclose(r.offset, 20.0, atol=0.5)
    assert np.abs(r.xy - true).max() < 0.005


def test_convergence_radius(pair):
    ref, search = pair
    rng = np.random.default_rng(5)
    n = 3000
    p = rng.uniform(40, 600, size=(n, 2))
    true = p @ M_TRUE.T + D_TRUE
    ang = rng.uniform(0, 2 * np.pi, n)
    sr, ss = SplineImage(ref), SplineImage(search)
    off2 = 2.0 * np.c_[np.cos(ang), np.sin(ang)]
    r = lsm(sr, p, ss, true + off2, M_TRUE)
    assert r.ok.mean() > 0.97
    assert np.abs(r.xy - true)[r.ok].max() < 0.005
    off6 = 6.0 * np.c_[np.cos(ang), np.sin(ang)]
    r = lsm(sr, p, ss, true + off6, M_TRUE, half=7)
    err = np.hypot(*(r.xy - true).T)
    # never a wrong "ok": every accepted point is right (without the affine_max check ~0.6 %
    # of these points fit a wrong place at correlation 0.76 - 0.94 with a distorted A)
    assert (err[r.ok] < 0.01).all()
    assert (~r.ok).sum() > 0.2 * n  # 6 px is beyond the radius for most points
    assert (r.reason[~r.ok] != LsmReason.OK).all()
    assert (r.reason[r.ok] == LsmReason.OK).all()


def test_failures_flagged():
    flat = np.full((60, 60), 100.0)
    sp = SplineImage(flat)
    r = lsm(sp, [[30.0, 30.0]], sp, [[30.0, 30.0]])
    assert not r.ok[0]
    assert r.reason[0] == LsmReason.SINGULAR
    rng = np.random.default_rng(6)
    img = ndimage.gaussian_filter(rng.normal(size=(60, 60)), 1.5) * 100
    sp = SplineImage(img)
    # the template leaves the reference window
    r = lsm(sp, [[3.0, 30.0], [30.0, 30.0]], sp, [[3.0, 30.0], [30.0, 30.0]])
    assert r.reason[0] == LsmReason.OUTSIDE
    assert not r.ok[0]
    assert r.ok[1]
    assert np.abs(r.xy[1] - 30).max() < 1e-3
    # uncorrelated content: never ok
    other = SplineImage(ndimage.gaussian_filter(rng.normal(size=(60, 60)), 1.5) * 100)
    r = lsm(sp, [[30.0, 30.0]], other, [[30.0, 30.0]])
    assert not r.ok[0]


class RecordingSource:
    """An ArraySource that records the size of every window read."""

    def __init__(self, a, smallest):
        self.src = ArraySource(a, smallest=smallest)
        self.reads: list[tuple[int, int, int]] = []

    @property
    def levels(self):
        return self.src.levels

    def shape(self, level):
        return self.src.shape(level)

    def read(self, level, col0, row0, width, height):
        self.reads.append((level, width, height))
        return self.src.read(level, col0, row0, width, height)


def test_track_three_levels():
    rng = np.random.default_rng(7)
    size = 900
    # multi-scale texture: detail for level 0 and coarse structure for levels 1-2
    tex = cosine_texture(rng, [1.8, 5.0, 12.0], k=80)
    th = np.radians(-1.5)
    M = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]) * 0.98
    d = np.array([40.3, 25.7])
    pix = pixel_grid(size, size)
    sn = 2.0
    ref = tex(pix) + rng.normal(scale=sn, size=(size, size))
    search = tex((pix - d) @ np.linalg.inv(M).T) + rng.normal(scale=sn, size=(size, size))
    rs, ss = RecordingSource(ref, 200), RecordingSource(search, 200)
    assert rs.levels >= 3
    p0 = grid_points(60, 800, 20) + rng.uniform(-0.5, 0.5, (1, 2))
    true0 = p0 @ M.T + d
    n = len(p0)
    # approximate positions at level 2, within ~1 level-2 pixel of the truth
    approx2 = full_to_level(true0, 2) + rng.uniform(-1, 1, (n, 2))
    r = track(rs, ss, p0, approx2, np.tile(M, (n, 1, 1)) * 1.01, start=2, tile=256)
    assert r.ok.mean() > 0.95
    # a template reaching outside the reference image: never measured on edge padding
    edge = np.array([[3.0, 400.0], [400.0, size - 2.0]])
    re = track(rs, ss, edge, full_to_level(edge @ M.T + d, 2), M, start=2, tile=256)
    assert not re.ok.any()
    assert (re.reason == LsmReason.OUTSIDE).all()
    e = (r.xy - true0)[r.ok]
    rms = np.sqrt((e**2).mean())
    ratio = rms / np.sqrt((r.sigma[r.ok] ** 2).mean())
    print(f"\ntrack: {n} points, ok {r.ok.mean():.3f}, RMS {rms:.4f} px, ratio {ratio:.2f}")
    assert rms < 0.05  # noise 2 DN on a 30 DN texture: sigma ~0.02 px
    assert 0.8 < ratio < 1.3
    # A is determined like the shift over lever arms sqrt(mean u^2) = 4.3 px: ~sigma / 4.3
    sig = np.sqrt((r.sigma[r.ok] ** 2).mean())
    assert np.sqrt(((r.affine[r.ok] - M) ** 2).mean()) < 1.5 * sig / 4.3
    # windows are bounded by the tile size (plus template margins), never the whole image
    assert max(max(w, h) for _, w, h in rs.reads + ss.reads) < 256 + 80
    assert {lv for lv, _, _ in rs.reads} == {0, 1, 2}
    # the level mapping is the pyramid's: level_to_full inverts full_to_level
    np.testing.assert_allclose(level_to_full(full_to_level(p0, 2), 2), p0)


def test_speed_figure(pair):
    ref, search = pair
    rng = np.random.default_rng(8)
    n = 5000
    p = rng.uniform(30, 620, size=(n, 2))
    true = p @ M_TRUE.T + D_TRUE
    ref_n = SplineImage(ref + rng.normal(scale=2.5, size=ref.shape))
    search_n = SplineImage(search + rng.normal(scale=2.5, size=search.shape))
    t = time.process_time()
    r = lsm(ref_n, p, search_n, true + rng.uniform(-1, 1, (n, 2)))
    dt = time.process_time() - t
    print(f"\nLSM speed: {n / dt:.0f} measurements/s CPU time (n={n}, half=7)")
    assert r.ok.mean() > 0.99
