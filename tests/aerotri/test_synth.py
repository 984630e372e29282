"""Synthetic blocks with truth (apygis.aerotri.synth)."""

from __future__ import annotations

import csv
import dataclasses
import itertools
import warnings

import numpy as np
import pytest
import rasterio
from rasterio.errors import NotGeoreferencedWarning
from scipy.ndimage import map_coordinates

from apygis.aerotri.camera import read_camera
from apygis.aerotri.synth import (
    LAKE_DN,
    SynthSpec,
    dihedral,
    dihedral_matrix,
    load_truth,
    render_image,
    synth_block,
)

SPEC = SynthSpec(strips=2, images_per_strip=3, size_px=400, rotated_scans={203: 5}, seed=3)


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth")
    calls = []
    path = synth_block(out, SPEC, progress=lambda d, t: calls.append((d, t)))
    assert calls[0] == (0, 6)
    assert calls[-1] == (6, 6)
    return path, load_truth(path)


def _read(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path) as ds:
            assert ds.count == 1
            assert ds.dtypes[0] == "uint8"
            assert ds.profile.get("tiled")
            assert ds.block_shapes[0] == (256, 256)
            return ds.read(1)


def test_files_are_written_and_readable(block):
    path, truth = block
    d = path.parent
    cam = read_camera(d / "camera.toml")
    assert cam == truth.camera
    assert cam.kind == "film"
    assert len(cam.fiducials) == 8
    assert cam.orientation_mark_mm == (-12.0, 110.0)
    assert truth.images == [101, 102, 103, 201, 202, 203]
    for n in truth.images:
        a = _read(d / f"img_{n}.tif")
        assert a.shape == (400, 400)
        assert 40 < a.mean() < 200
    with open(d / "images.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["image", "strip", "file", "X", "Y", "Z", "heading_deg"]
    assert [int(r[0]) for r in rows[1:]] == truth.images
    heads = {int(r[0]): float(r[6]) for r in rows[1:]}
    assert heads[101] == 90.0
    assert heads[201] == 270.0
    # approximate centres: truth + noise of s.d. 0.5 % of H (~6 m): within 6 sigma
    for r in rows[1:]:
        c = truth.exterior[int(r[0])].centre
        err = np.array([float(v) for v in r[3:6]]) - c
        assert np.all(np.abs(err) < 6 * SPEC.approx_error)
    with open(d / "control.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["name", "X", "Y", "Z", "sigma_xy_m", "sigma_z_m", "kind"]
    kinds = [r[6] for r in rows[1:]]
    assert kinds.count("full") >= 4
    assert 2 <= kinds.count("check") <= 4


def test_control_points_are_true_road_crossings(block):
    _, truth = block
    e, n = truth.origin
    for c in truth.control:
        assert truth.height(c["X"], c["Y"]) == pytest.approx(c["Z"], abs=1e-3)
        assert truth.scene.road_distance(np.array(c["X"] - e), np.array(c["Y"] - n)) < 0
        seen = [m for m in truth.images if truth.visible(m, [[c["X"], c["Y"], c["Z"]]])[0]]
        assert len(seen) >= 2


def test_ground_and_project_are_inverse(block):
    _, truth = block
    rng = np.random.default_rng(1)
    for n in truth.images:
        w, h = truth.size[n]
        px = rng.uniform([0, 0], [w - 1, h - 1], (200, 2))
        g = truth.ground(n, px)
        # the point lies on the DEM (Newton to 1e-6 m) and on the pixel's ray
        assert np.abs(g[:, 2] - truth.height(g[:, 0], g[:, 1])).max() < 1e-6
        assert np.abs(truth.project(n, g) - px).max() < 1e-6


def test_truth_file_round_trip(block):
    path, truth = block
    again = load_truth(path)
    for n in truth.images:
        assert again.exterior[n] == truth.exterior[n]
        assert np.array_equal(again.scan[n].matrix, truth.scan[n].matrix)
    assert again.dihedral_code[203] == 5
    assert again.size[203] == (400, 400)


def _ncc(a, b):
    a = a - a.mean()
    b = b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def test_overlapping_images_agree(block):
    """Relief-consistent rendering: image 102 resampled at the projections of the ground
    points of image 101's pixels reproduces image 101.

    Noise: 2 DN grain per image on windows of texture s.d. >= 15 DN caps NCC near
    1 - 2 (2/15)^2 ~ 0.96; bilinear resampling (up to 1/2 px) and the slightly different
    pixel footprints cost more at this coarse GSD (4.8 m; 0.87 .. 0.98 seen), so a mean
    > 0.9 and a minimum > 0.8 are demanded; the same window shifted by 3 pixels (a wrong
    geometry) must fall below 0.6 on average (0.3 seen)."""
    path, truth = block
    a = _read(path.parent / "img_101.tif").astype(float)
    b = _read(path.parent / "img_102.tif").astype(float)
    rng = np.random.default_rng(5)
    good, bad = [], []
    r = 7
    while len(good) < 20:
        c0 = rng.integers(220, 370, 2)  # image 101's half nearest image 102
        win = a[c0[1] - r : c0[1] + r + 1, c0[0] - r : c0[0] + r + 1]
        if win.std() < 15:
            continue
        cc, rr = np.meshgrid(np.arange(-r, r + 1) + c0[0], np.arange(-r, r + 1) + c0[1])
        px = np.column_stack([cc.ravel(), rr.ravel()]).astype(float)
        q = truth.project(102, truth.ground(101, px))
        s = map_coordinates(b, [q[:, 1], q[:, 0]], order=1).reshape(win.shape)
        t = map_coordinates(b, [q[:, 1] + 3, q[:, 0] + 3], order=1).reshape(win.shape)
        good.append(_ncc(win, s))
        bad.append(_ncc(win, t))
    assert min(good) > 0.8
    assert np.mean(good) > 0.9, good
    assert np.mean(bad) < 0.6


def test_lake_is_textureless(block):
    """Inside the lake only the grain remains: s.d. = sqrt(noise^2 + 1/12) (8-bit rounding)
    = 2.02 DN; over 15 x 15 pixels the s.d. scatters by ~5 % (sigma / sqrt(2 * 224)),
    so +-0.35 DN is ~7 sigma; the mean scatters by 2/15 DN."""
    path, truth = block
    lx, ly, _, _ = truth.lake
    X, Y = truth.origin[0] + lx, truth.origin[1] + ly
    g = np.array([[X, Y, truth.height(X, Y)]])
    n = [m for m in (101, 102, 103) if truth.visible(m, g)[0]]
    assert len(n) >= 2  # at a von Gruber point of model 101-102 (and 102-103)
    for m in n:
        c, r = np.rint(truth.project(m, g)[0]).astype(int)
        win = _read(path.parent / f"img_{m}.tif")[r - 7 : r + 8, c - 7 : c + 8].astype(float)
        assert win.std() == pytest.approx(np.hypot(SPEC.noise_dn, 12**-0.5), abs=0.35)
        assert win.mean() == pytest.approx(LAKE_DN, abs=0.8)
    # and the texture elsewhere is not
    assert _read(path.parent / "img_101.tif")[150:250, 150:250].std() > 10


def test_overlaps_as_specified(block):
    """Forward and side overlap of the footprints along the photo x / y axes through the
    principal point, against the spec: relief (+-4 % of the footprint at the edges), the
    centre jitter (1 % of the footprint) and the attitudes (0.5 %) allow +-0.07."""
    _, truth = block
    half = 115.0

    def span(n, axis):
        mm = np.zeros((2, 2))
        mm[:, axis] = [-half, half]
        g = truth.ground(n, truth.scan[n].to_px(mm))
        return g[:, :2]

    for s in (1, 2):
        ns = [100 * s + i for i in (1, 2, 3)]
        for a, b in itertools.pairwise(ns):
            xa, xb = span(a, 0)[:, 0], span(b, 0)[:, 0]
            lo, hi = max(xa.min(), xb.min()), min(xa.max(), xb.max())
            assert (hi - lo) / np.ptp(xa) == pytest.approx(SPEC.forward_overlap, abs=0.07)
    ya, yb = span(102, 1)[:, 1], span(202, 1)[:, 1]
    lo, hi = max(ya.min(), yb.min()), min(ya.max(), yb.max())
    assert (hi - lo) / np.ptp(ya) == pytest.approx(SPEC.side_overlap, abs=0.07)


@pytest.mark.parametrize("code", range(8))
def test_dihedral_matrix_matches_numpy(code):
    h, w = 5, 7
    idx = np.arange(h * w).reshape(h, w)
    rot = dihedral(idx, code)
    M = dihedral_matrix(code, w, h)
    for r2 in range(rot.shape[0]):
        for c2 in range(rot.shape[1]):
            c, r, _ = M @ [c2, r2, 1.0]
            assert idx[round(r), round(c)] == rot[r2, c2]


def test_rotated_scan_is_the_turned_image(block):
    """Image 203 (code 5) is the normal scan turned and mirrored, and its truth transform
    says so: a ground point lands on corresponding pixels of both."""
    path, truth = block
    stored = _read(path.parent / "img_203.tif")
    plain = dataclasses.replace(truth, dihedral_code={**truth.dihedral_code, 203: 0})
    base = render_image(plain, 203)
    assert np.array_equal(stored, dihedral(base, 5))
    rng = np.random.default_rng(2)
    px = rng.uniform(30, 370, (50, 2))
    g = truth.ground(203, px)
    q = truth.project(203, g)
    p0 = plain.scan_base[203].to_px(_photo(truth, 203, g))
    M = dihedral_matrix(5, 400, 400)
    back = q @ M[:2, :2].T + M[:2, 2]
    assert np.abs(back - p0).max() < 1e-6


def _photo(truth, n, g):
    from apygis.orient.collinearity import ground_to_photo

    return ground_to_photo(g, truth.exterior[n], truth.interior)


def test_digital_block(tmp_path):
    spec = SynthSpec(strips=1, images_per_strip=2, size_px=240, camera="digital", lake=False)
    truth = load_truth(synth_block(tmp_path, spec))
    cam = read_camera(tmp_path / "camera.toml")
    assert cam.kind == "digital"
    assert cam.sensor_px == (240, 160)
    assert cam.pixel_um == pytest.approx(150.0)
    assert cam.focal_mm == 50.0
    assert _read(tmp_path / "img_101.tif").shape == (160, 240)
    px = np.array([[0.0, 0.0], [239.0, 159.0], [120.3, 80.7]])
    assert np.abs(truth.project(102, truth.ground(102, px)) - px).max() < 1e-6
    assert truth.lake is None


def test_layout_headings_and_cross_strips():
    from apygis.aerotri.synth import _build_truth

    spec = SynthSpec(strips=2, images_per_strip=3, cross_strips=1, size_px=200)
    truth = _build_truth(spec)
    cross = [n for n in truth.images if truth.strip[n] == 3]
    assert len(cross) >= 2
    assert cross[0] == 301
    # kappa = radians(90 - heading) within the +-1 deg of the attitude noise
    for n in truth.images:
        k = np.radians(90.0 - truth.heading[n]) - truth.exterior[n].kappa_rad
        assert abs(np.angle(np.exp(1j * k))) < np.radians(1.0) + 1e-12
        assert abs(truth.exterior[n].omega_rad) < np.radians(1.5)  # 5 sigma of 0.3 deg
    assert {truth.heading[n] for n in (101, 102, 103)} == {90.0}
    assert {truth.heading[n] for n in (201, 202, 203)} == {270.0}
    assert {truth.heading[n] for n in cross} == {0.0}
    # strip 1 flies east: its image numbers increase eastwards; strip 2 westwards
    assert truth.exterior[101].Xo < truth.exterior[103].Xo
    assert truth.exterior[201].Xo > truth.exterior[203].Xo
    assert truth.exterior[101].Yo > truth.exterior[201].Yo  # strip 1 in the north
    # the cross strip runs north across both strips
    assert truth.exterior[cross[0]].Yo < truth.exterior[cross[-1]].Yo


def test_truth_pickles_for_parallel_rendering(block):
    import pickle

    _, truth = block
    truth.texture([truth.origin[0]], [truth.origin[1]])  # builds the scene
    again = pickle.loads(pickle.dumps(truth))
    assert np.array_equal(
        render_image(again, 101, noise=False), render_image(truth, 101, noise=False)
    )


def test_texture_is_a_function_of_position(block):
    """The same ground point gets the same texture value whatever the array's shape."""
    _, truth = block
    rng = np.random.default_rng(4)
    e, n = truth.origin
    X = e + rng.uniform(-1500, 1500, 50000)
    Y = n + rng.uniform(-1200, 1200, 50000)
    flat = truth.texture(X, Y)
    assert flat.shape == (50000,)
    assert np.array_equal(truth.texture(X.reshape(100, 500), Y.reshape(100, 500)).ravel(), flat)
    assert np.array_equal(truth.texture(X[7:9], Y[7:9]), flat[7:9])
    assert flat.min() >= 30.0
    assert flat.max() <= 220.0
    assert flat.std() > 20.0


def test_bad_specs_are_refused():
    from apygis.aerotri.synth import _build_truth
    from apygis.errors import FormatError

    with pytest.raises(FormatError, match="camera"):
        SynthSpec(camera="lidar")
    with pytest.raises(FormatError, match=r"0\.\.7"):
        SynthSpec(rotated_scans={101: 8})
    with pytest.raises(FormatError, match="image 999"):
        _build_truth(SynthSpec(size_px=200, rotated_scans={999: 1}))


def test_single_strip_of_two_has_control():
    from apygis.aerotri.synth import _build_truth

    truth = _build_truth(SynthSpec(strips=1, images_per_strip=2, size_px=200))
    assert len(truth.control) >= 4
    for c in truth.control:
        g = [[c["X"], c["Y"], c["Z"]]]
        assert truth.visible(101, g)[0]
        assert truth.visible(102, g)[0]


@pytest.mark.parametrize("n", [101, 203])
def test_fiducial_marks_lie_where_the_scan_transform_says(block, n):
    """Each 8 x 8 mm mark is a dark square (DN 15) with a small bright disk and ring:
    its median over 9 x 9 pixels (5.4 mm at 0.6 mm per pixel) stays dark (< 60, well
    below any ground texture's 30..220 mean) and its maximum is bright (the disk and ring
    cover whole pixels' fractions of 235 DN)."""
    path, truth = block
    a = _read(path.parent / f"img_{n}.tif").astype(float)
    for xy in truth.camera.fiducials.values():
        c, r = np.rint(truth.scan[n].to_px([xy])[0]).astype(int)
        win = a[r - 4 : r + 5, c - 4 : c + 5]
        assert np.median(win) < 60
        assert win.max() > 120
