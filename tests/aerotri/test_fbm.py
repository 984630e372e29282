"""Feature-based matching against a synthetic scene with known truth.

The scene: one continuous texture ``g(X, Y)`` on the ground (Gaussian-filtered
noise at three scales on a 3 m grid, sampled with cubic splines), a smooth
relief ``Z = h(X, Y)`` (+-60 m), vertical film photos (c = 153 mm, 1:10 000,
768 x 768 px of 0.3 mm = the "intermediate level": 3 m on the ground) with
attitudes of about 1 degree. A band of periodic texture (period 10 px, about
13 % of an image, inside the overlap) makes ambiguous matches; image noise
sigma 1 DN on a texture of standard deviation ~30 DN.

The truth of a match: the ray of a's point meets the relief (fixed-point
iteration), the ground point is projected into b with b's true orientation;
a correct match lies within 1.5 px of it. A Förstner point's position on the
texture is reproducible to a few tenths of a pixel between two views of
slightly different scale and rotation (the tolerance of 1.5 px is the brief's
level-pixel bound, about 5 times that), a wrong match is off by at least the
suppression radius (4 px) of the operator: the test separates the two.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy import ndimage

from apygis.aerotri import fbm
from apygis.aerotri.camera import PixelTransform
from apygis.aerotri.fbm import PairMatches, homography_from_orientations, match_pair
from apygis.aerotri.interest import foerstner
from apygis.aerotri.tracks import link
from apygis.orient.collinearity import (
    ExteriorOrientation,
    InteriorOrientation,
    ground_to_photo,
    photo_to_ground,
)

C_MM = 153.0
SIZE = 768
PIX_MM = 0.3
IO = InteriorOrientation(C_MM)
Z_MEAN = 400.0
ZO = Z_MEAN + 1530.0  # 1:10 000 -> 3 m per pixel
GRID_M = 3.0
X0, Y0 = -1400.0, -1400.0  # origin of the texture grid


def height(X, Y):
    return Z_MEAN + 45.0 * np.sin(X / 600.0) * np.cos(Y / 800.0) + 15.0 * np.sin(Y / 350.0 + 1.0)


def _texture(seed=7):
    rng = np.random.default_rng(seed)
    shape = (1550, 1350)  # rows = Y, cols = X, 3 m cells
    f = np.zeros(shape, dtype=np.float32)
    for sigma, amp in ((0.9, 1.0), (3.0, 0.8), (10.0, 0.6)):
        n = ndimage.gaussian_filter(rng.standard_normal(shape).astype(np.float32), sigma)
        f += amp * n / n.std()
    # ambiguous band: a periodic tile (10 cells = 10 px at the level) for X in [300, 600] m
    tile = ndimage.gaussian_filter(
        rng.standard_normal((10, 10)).astype(np.float32), 1.0, mode="wrap"
    )
    tile = tile / tile.std()
    c0, c1 = int((300 - X0) / GRID_M), int((600 - X0) / GRID_M)
    rows = np.arange(shape[0])[:, None] % 10
    cols = np.arange(c0, c1)[None, :] % 10
    f[:, c0:c1] = 1.6 * tile[rows, cols]
    return 128.0 + 30.0 * f / f.std()


TEXTURE = _texture()
SPLINE = ndimage.spline_filter(TEXTURE, order=3)  # cubic spline coefficients, once


def scan(rot_deg=0.3, dx=0.7, dy=-0.4) -> PixelTransform:
    """A scan's pixel -> photo similarity with a slight affinity (convention of the brief)."""
    a = math.radians(rot_deg)
    p, q = PIX_MM, PIX_MM * (1 + 1e-4)
    h = (SIZE - 1) / 2
    m = np.array([[p * math.cos(a), q * math.sin(a)], [p * math.sin(a), -q * math.cos(a)]])
    t = np.array([dx, dy]) - m @ [h, h]
    return PixelTransform(np.array([[*m[0], t[0]], [*m[1], t[1]], [0, 0, 1]]))


def ground_of(px, eo, T, iters=5):
    """Ray of pixels meets the relief (fixed-point iteration on Z).

    The iteration contracts by (relief slope <= 0.1) x (ray slope <= 0.75): 5 steps
    leave less than 60 m x 0.075**5 = 1e-4 m.
    """
    mm = T.to_mm(px)
    Z = np.full(len(mm), Z_MEAN)
    for _ in range(iters):
        G = photo_to_ground(mm, Z, eo, IO)
        Z = height(G[:, 0], G[:, 1])
    return photo_to_ground(mm, Z, eo, IO)


def render(eo, T, seed):
    """The image of the texture on the relief; ground coordinates exactly on a 4 px grid,
    cubic-spline interpolated in between (the map pixel -> ground is smooth: relief
    wavelengths >= 350 m = 120 px, so the interpolation error is far below 0.01 px)."""
    step = 4
    g = np.arange(0, SIZE + step, step, dtype=float)
    gc, gr = np.meshgrid(g, g)
    Gc = ground_of(np.column_stack([gc.ravel(), gr.ravel()]), eo, T).reshape(len(g), len(g), 3)
    r, c = np.mgrid[0:SIZE, 0:SIZE] / step
    X = ndimage.map_coordinates(Gc[..., 0], [r.ravel(), c.ravel()], order=3)
    Y = ndimage.map_coordinates(Gc[..., 1], [r.ravel(), c.ravel()], order=3)
    coords = np.stack([(Y - Y0) / GRID_M, (X - X0) / GRID_M])
    img = ndimage.map_coordinates(SPLINE, coords, order=3, mode="nearest", prefilter=False)
    img = img + np.random.default_rng(seed).normal(0.0, 1.0, img.shape)
    return img.reshape(SIZE, SIZE).astype(np.float32)


def kappa(heading_deg):
    return math.radians(90.0 - heading_deg)


# name: (true EO, scan transform)
VIEWS = {
    "A": (ExteriorOrientation(0.0, 0.0, ZO, 0.012, -0.008, kappa(90)), scan(0.3)),
    "B": (ExteriorOrientation(920.0, 15.0, ZO + 8, -0.01, 0.015, kappa(90) + 0.01), scan(-0.4)),
    "B180": (ExteriorOrientation(920.0, 15.0, ZO + 8, -0.01, 0.015, kappa(270)), scan(0.2)),
    "B90": (ExteriorOrientation(920.0, 15.0, ZO + 8, -0.01, 0.015, kappa(0)), scan(0.5)),
    "C": (ExteriorOrientation(460.0, 1725.0, ZO - 5, 0.008, 0.01, kappa(270)), scan(-0.2)),
}


def approx(eo: ExteriorOrientation, rng) -> ExteriorOrientation:
    """Approximate orientation: 15 m in position, angles 0 except kappa (0.5 deg off)."""
    return ExteriorOrientation(
        eo.Xo + rng.normal(0, 15), eo.Yo + rng.normal(0, 15), eo.Zo + rng.normal(0, 15),
        0.0, 0.0, eo.kappa_rad + math.radians(0.5),
    )  # fmt: skip


@pytest.fixture(scope="module")
def scene():
    images, points = {}, {}
    for k, (name, (eo, T)) in enumerate(VIEWS.items()):
        images[name] = render(eo, T, seed=k)
        points[name] = foerstner(images[name], max_points=3000, grid=8)
    return images, points


def true_b(name_a, name_b, xy_a):
    eo_a, Ta = VIEWS[name_a]
    eo_b, Tb = VIEWS[name_b]
    return Tb.to_px(ground_to_photo(ground_of(xy_a, eo_a, Ta), eo_b, IO))


def predict(name_a, name_b, seed=1):
    rng = np.random.default_rng(seed)
    (eo_a, Ta), (eo_b, Tb) = VIEWS[name_a], VIEWS[name_b]
    return homography_from_orientations(approx(eo_a, rng), approx(eo_b, rng), C_MM, Ta, Tb, Z_MEAN)


def run(scene, a, b, kind="strip", use_predict=True) -> PairMatches:
    images, points = scene
    return match_pair(
        images[a], images[b], points[a], points[b],
        predict=predict(a, b) if use_predict else None, kind=kind,
        photo_a=VIEWS[a][1].to_mm if kind == "strip" else None,
        photo_b=VIEWS[b][1].to_mm if kind == "strip" else None,
        focal_mm=C_MM if kind == "strip" else None,
    )  # fmt: skip


def check(m: PairMatches, a, b, least, sigma_max=0.8):
    assert m.reason == ""
    assert m.n_inliers == len(m.idx_a) > least
    err = np.linalg.norm(true_b(a, b, m.xy_a) - m.xy_b, axis=1)
    wrong = np.count_nonzero(err > 1.5)
    assert wrong <= 0.01 * len(err), (wrong, len(err))
    # the model's sigma: a few tenths of a pixel (Förstner repeatability) for the relative
    # orientation; a homography leaves the relief parallax too (sigma_max for it)
    assert 0.05 < m.sigma_px < sigma_max
    return err


@pytest.mark.parametrize("b", ["B", "B180", "B90"])
def test_strip_pairs(scene, b):
    m = run(scene, "A", b)
    assert m.predicted_by == "given"
    err = check(m, "A", b, 200)
    assert m.essential is not None
    assert np.median(err) < 0.5
    # the refined homography predicts b's points up to the relief parallax: +-60 m of
    # relief at a base of 920 m and 1530 m flying height is up to +-36 m = +-12 px
    pred = np.c_[m.xy_a, np.ones(len(m.xy_a))] @ np.asarray(m.homography).T
    res = np.linalg.norm(pred[:, :2] / pred[:, 2:] - m.xy_b, axis=1)
    assert np.max(res) < 15.0


def test_ambiguous_band_is_rejected(scene):
    """Points of a in the periodic band: only few of them survive, and those are right."""
    m = run(scene, "A", "B")
    eo_a, Ta = VIEWS["A"]
    X = ground_of(m.xy_a, eo_a, Ta)[:, 0]
    in_band = (X > 320) & (X < 580)
    _, points = scene
    Xall = ground_of(points["A"].xy, eo_a, Ta)[:, 0]
    band_all = (Xall > 320) & (Xall < 580)
    assert band_all.sum() > 150  # the band is there, inside the overlap (X > -230 m)
    # outside the band about 60 % of a's overlap points match; in it (ten candidates
    # within the search radius correlate alike) the distinctness test leaves few or none
    rate_band = in_band.sum() / band_all.sum()
    rate_rest = (~in_band).sum() / np.sum(~band_all & (Xall > -230))
    assert rate_band < 0.2 * rate_rest
    err = np.linalg.norm(true_b("A", "B", m.xy_a) - m.xy_b, axis=1)
    assert np.all(err[in_band] < 1.5)


@pytest.mark.parametrize("model", ["strip", "cross"])
def test_robust_models_reject_random_outliers(scene, model):
    """10 % random pairs added to the matches: the robust models remove them.

    A random pair passes the relative orientation only when b's point falls within
    3 sigma (~0.7 px) of the epipolar line of a's point: probability ~ 1.4 / 768 per
    pair, so among ~120 outliers at most a few pass (the bound 3 allows for that).
    A homography passes a random pair only within 3 sigma of H p_a: ~0 of them.
    """
    b = "B" if model == "strip" else "C"
    m = run(scene, "A", b, kind=model)
    rng = np.random.default_rng(11)
    n_out = len(m.xy_a) // 10
    xa = np.vstack([m.xy_a, rng.uniform(0, SIZE - 1, (n_out, 2))])
    xb = np.vstack([m.xy_b, rng.uniform(0, SIZE - 1, (n_out, 2))])
    if model == "strip":
        out = fbm._strip_model(xa, xb, VIEWS["A"][1].to_mm, VIEWS[b][1].to_mm, C_MM, 1.5)
    else:
        out = fbm._homography_model(xa, xb, 1.5, (SIZE, SIZE))
    assert out is not None
    inl = out[0]
    assert np.count_nonzero(inl[-n_out:]) <= 3
    assert np.count_nonzero(inl[:-n_out]) >= 0.95 * len(m.xy_a)


def test_cross_strip_pair(scene):
    m = run(scene, "A", "C", kind="cross")
    assert m.essential is None
    # across the 25 % side overlap the relief (+-60 m) departs from a plane by ~1 px rms
    check(m, "A", "C", 100, sigma_max=2.0)


def test_unknown_prediction_uses_sift(scene):
    m = run(scene, "A", "B180", use_predict=False)
    assert m.predicted_by == "sift"
    check(m, "A", "B180", 200)


def test_poor_prediction_falls_back(scene):
    """A prediction off by 200 px (a wrong approximate position) is replaced by SIFT's."""
    images, points = scene
    H = predict("A", "B")
    H = np.array([[1, 0, 200.0], [0, 1, 0], [0, 0, 1]]) @ H
    m = match_pair(
        images["A"], images["B"], points["A"], points["B"], predict=H,
        photo_a=VIEWS["A"][1].to_mm, photo_b=VIEWS["B"][1].to_mm, focal_mm=C_MM,
    )  # fmt: skip
    assert m.predicted_by == "sift"
    check(m, "A", "B", 200)


def test_unrelated_images_fail_with_reason():
    rng = np.random.default_rng(3)
    a = ndimage.gaussian_filter(rng.standard_normal((300, 300)), 1.5) * 100
    b = ndimage.gaussian_filter(rng.standard_normal((300, 300)), 1.5) * 100
    m = match_pair(a, b, foerstner(a, max_points=800), foerstner(b, max_points=800), kind="cross")
    assert m.n_inliers == 0 or m.n_inliers < 12
    if m.n_inliers == 0:
        assert m.reason


def test_homography_from_orientations_agrees_with_collinearity():
    rng = np.random.default_rng(5)
    eo_a, Ta = VIEWS["A"]
    eo_b, Tb = VIEWS["B180"]
    level = 2
    H = homography_from_orientations(eo_a, eo_b, C_MM, Ta, Tb, 350.0, level=level)
    # level-2 pixels of a -> level-0 px -> mm -> ground plane Z = 350 -> b mm -> level-2 px
    p2 = rng.uniform(0, SIZE / 4 - 1, (50, 2))
    f = 4.0
    p0 = p2 * f + (f - 1) / 2
    G = photo_to_ground(Ta.to_mm(p0), 350.0, eo_a, IO)
    q0 = Tb.to_px(ground_to_photo(G, eo_b, IO))
    q2 = (q0 - (f - 1) / 2) / f
    Hp = np.c_[p2, np.ones(50)] @ H.T
    np.testing.assert_allclose(Hp[:, :2] / Hp[:, 2:], q2, atol=1e-8)


def test_matches_link_into_tracks(scene):
    """A-B (strip), A-C and B-C (cross strip): 3-fold tracks in the triple overlap, right."""
    mab = run(scene, "A", "B")
    mac = run(scene, "A", "C", kind="cross")
    mbc = run(scene, "B", "C", kind="cross")
    t = link(
        [
            (n, k, m.idx_a, m.idx_b, m.ncc)
            for n, k, m in (("A", "B", mab), ("A", "C", mac), ("B", "C", mbc))
        ]
    )
    # the triple overlap is ~ half the cross-strip overlap, about 150 matches in A-C
    assert t.multiplicity_table().get(3, 0) > 50
    assert t.n_inconsistent <= 0.01 * len(t)
    _, points = scene
    three = [dict(t[k]) for k in np.flatnonzero(t.multiplicity == 3)]
    xa = np.array([points["A"].xy[d["A"]] for d in three])
    xc = np.array([points["C"].xy[d["C"]] for d in three])
    err = np.linalg.norm(true_b("A", "C", xa) - xc, axis=1)
    assert np.count_nonzero(err > 1.5) <= 0.01 * len(err)


def test_speed_and_counts(scene):
    """Not a benchmark, a guard: one pair with ~3000 points per image takes well under 5 s."""
    t0 = time.perf_counter()
    m = run(scene, "A", "B")
    assert time.perf_counter() - t0 < 5.0
    assert m.n_inliers > 200
