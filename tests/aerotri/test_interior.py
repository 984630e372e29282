"""Interior orientation: transform fits and the automatic procedure on synthetic scans.

Synthetic scans: a mildly textured image area (|x|, |y| <= 115 mm; Gaussian-filtered
noise, 120 +- 40 DN), a dark surround (10 DN), the marks drawn by
:func:`draw_marks` (area coverage), and Gaussian noise of 3 DN. The scan transform is
a similarity with a 0.4 deg rotation, an offset of a few mm and an affinity of
1e-4, composed with one of the 8 dihedral maps of the pixel grid.

Tolerance of the recovered transform: a mark's centre from the level-0 least-squares
fit has sigma ~ noise / (contrast * sqrt(sum of squared edge slopes)), which the fit
itself estimates at ~0.004 px for 3 DN noise, 220 DN contrast and the disk + ring at
80 um (the measured error is ~0.002 px). An affine fit from 8 marks at the format's
edge propagates that to <= ~1.2 sigma anywhere in the 230 mm format, so the transform
rms over a grid covering the format is expected at ~0.003 px; 0.02 px (5x the
mark sigma; the brief's goal is 0.05 px) cannot be reached by noise.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from scipy import ndimage

from apygis.aerotri.camera import Camera, PixelTransform
from apygis.aerotri.fiducials import draw_marks
from apygis.aerotri.imagery import ArraySource
from apygis.aerotri.interior import (
    InteriorResult,
    digital_interior,
    dihedral_code,
    dihedral_matrix,
    fit_transform,
    interior_orientation,
)
from apygis.errors import OrientationError

FIDUCIALS = {
    "1": (-106.0, 106.0), "2": (106.0, 106.0), "3": (106.0, -106.0), "4": (-106.0, -106.0),
    "5": (0.0, 110.0), "6": (110.0, 0.0), "7": (0.0, -110.0), "8": (-110.0, 0.0),
}  # fmt: skip
CAMERA = Camera(
    name="synthetic", kind="film", focal_mm=153.0, fiducials=FIDUCIALS,
    orientation_mark_mm=(-12.0, 110.0),
)  # fmt: skip
GRID = np.stack(np.meshgrid(np.linspace(-115, 115, 24), np.linspace(-115, 115, 24)), -1)
GRID = GRID.reshape(-1, 2)
TOL_PX = 0.02  # see the module docstring


def scan_transform(n: int, pixel_mm: float, code: int = 0) -> PixelTransform:
    """The simulated scan: rotation 0.4 deg, offset (1.3, -2.1) mm, affinity 1e-4."""
    t = math.radians(0.4)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    a = pixel_mm * rot @ np.diag([1 + 5e-5, 1 - 5e-5]) @ dihedral_matrix(code)
    tv = np.array([1.3, -2.1]) - a @ np.full(2, (n - 1) / 2)
    return PixelTransform(np.vstack([np.column_stack([a, tv]), [0.0, 0.0, 1.0]]))


def transform_rms_px(found: PixelTransform, truth: PixelTransform) -> float:
    """Rms distance (px) of the two transforms' pixels over a grid covering the format."""
    d = found.to_px(GRID) - truth.to_px(GRID)
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


N = 3000
PIX = 240.0 / N  # 80 um


@pytest.fixture(scope="module")
def base():
    """The background (texture + surround), the noise and the transform of the 3000 px scan."""
    rng = np.random.default_rng(2024)
    t = scan_transform(N, PIX)
    tex = ndimage.gaussian_filter(rng.normal(0.0, 1.0, (N, N)).astype(np.float32), 4.0)
    tex = 120.0 + 40.0 * tex / tex.std()
    cols, rows = np.meshgrid(np.arange(N, dtype=np.float32), np.arange(N, dtype=np.float32))
    a, tv = t.matrix[:2, :2].astype(np.float32), t.matrix[:2, 2].astype(np.float32)
    x = a[0, 0] * cols + a[0, 1] * rows + tv[0]
    y = a[1, 0] * cols + a[1, 1] * rows + tv[1]
    bg = np.where((np.abs(x) <= 115) & (np.abs(y) <= 115), tex, np.float32(10.0))
    noise = rng.normal(0.0, 3.0, (N, N)).astype(np.float32)
    return bg, noise, t


def make_scan(base, camera: Camera = CAMERA) -> ArraySource:
    bg, noise, t = base
    return ArraySource(draw_marks(bg, t, camera) + noise)


@pytest.fixture(scope="module")
def scan(base):
    return make_scan(base)


# ------------------------------------------------------------------ fit_transform


@pytest.mark.parametrize("model", ["similarity", "affine", "projective"])
def test_fit_transform_recovers_each_model(model):
    rng = np.random.default_rng(1)
    px = rng.uniform(0, 3000, (8, 2))
    if model == "similarity":
        truth = scan_transform(3000, 0.08, 0)
        truth = PixelTransform(  # remove the affinity
            np.array([[0.08 * 0.99, -0.0008, 1.0], [-0.0008, -0.08 * 0.99, 2.0], [0, 0, 1]])
        )
    elif model == "affine":
        truth = scan_transform(3000, 0.08, 5)
    else:
        truth = PixelTransform(
            np.array([[0.08, 0.001, -120.0], [0.0005, -0.079, 118.0], [2e-7, -1e-7, 1.0]])
        )
    mm = truth.to_mm(px)
    found, res = fit_transform(px, mm, model)
    assert np.abs(res).max() < 1e-9
    assert transform_rms_px(found, truth) < 1e-6
    # noise of 2 um: residuals sum to zero (translation estimated) and their rms is
    # the noise times sqrt(redundancy / n) (chi-square: within a factor 0.3..1.8)
    noisy = mm + rng.normal(0.0, 0.002, mm.shape)
    _, res = fit_transform(px, noisy, model)
    if model != "projective":
        assert np.abs(res.sum(axis=0)).max() < 1e-12
    u = {"similarity": 4, "affine": 6, "projective": 8}[model]
    expected = 0.002 * math.sqrt((16 - u) / 8)
    assert 0.3 * expected < float(np.sqrt(np.mean(np.sum(res**2, axis=1)) / 2)) < 1.8 * expected


def test_similarity_takes_the_handedness_of_the_data():
    px = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    for sign in (1.0, -1.0):
        mm = np.column_stack([px[:, 0] * 0.1, sign * px[:, 1] * 0.1])
        t, res = fit_transform(px, mm, "similarity")
        assert np.abs(res).max() < 1e-12
        assert np.sign(np.linalg.det(t.matrix[:2, :2])) == sign


@pytest.mark.parametrize(("model", "need"), [("similarity", 2), ("affine", 3), ("projective", 4)])
def test_fit_transform_refuses_too_few_points(model, need):
    px = np.array([[0.0, 0.0], [100.0, 3.0], [7.0, 100.0], [90.0, 80.0]])[: need - 1]
    with pytest.raises(OrientationError, match=f"{model} transform needs at least {need} marks, "
                       f"got {need - 1}"):  # fmt: skip
        fit_transform(px, px * 0.1, model)
    px = np.array([[0.0, 0.0], [100.0, 3.0], [7.0, 100.0], [90.0, 80.0]])[:need]
    fit_transform(px, px * 0.1, model)  # exactly the minimum is a transform ...
    with pytest.raises(OrientationError, match="no redundancy"):  # ... but not checked
        fit_transform(px, px * 0.1, model, require_redundancy=True)


def test_dihedral_codes_are_the_eight_distinct_maps():
    mats = [dihedral_matrix(d) for d in range(8)]
    assert len({tuple(m.ravel()) for m in mats}) == 8
    for d in range(8):
        assert dihedral_code(scan_transform(1000, 0.1, d)) == d
    assert np.linalg.det(mats[0]) < 0  # the usual scan: rows down, no mirror


# ------------------------------------------------------------------ the automatic procedure


def test_interior_orientation_recovers_the_scan(scan, base):
    t0 = time.perf_counter()
    r = interior_orientation(scan, CAMERA, name="photo 17")
    elapsed = time.perf_counter() - t0
    assert transform_rms_px(r.transform, base[2]) < TOL_PX
    assert r.dihedral == 0
    assert r.missing == []
    assert r.notes == []
    assert set(r.fiducials_px) == set(FIDUCIALS)
    truth_px = base[2].to_px(np.array(list(FIDUCIALS.values())))
    found_px = np.array([r.fiducials_px[k] for k in FIDUCIALS])
    assert np.abs(found_px - truth_px).max() < TOL_PX
    # residual rms ~ 0.003 px * 80 um = 0.25 um; not flagged
    assert r.rms_um < 1.0
    assert not r.flagged
    assert r.max_um >= r.rms_um
    assert elapsed < 5.0  # ~0.1 s measured; generous for a busy machine
    back = InteriorResult.from_dict(json.loads(json.dumps(r.to_dict())))
    assert back == InteriorResult(**{**r.__dict__, "transform": back.transform})
    assert np.array_equal(back.transform.matrix, r.transform.matrix)


def test_other_models_on_the_scan(scan, base):
    for model in ("similarity", "projective"):
        r = interior_orientation(scan, CAMERA, model=model, approx_pixel_um=80.0)
        # the similarity cannot take the 1e-4 affinity: 1e-4 * 115 mm / 2 = ~6 um = 0.07 px
        tol = 0.15 if model == "similarity" else TOL_PX
        assert transform_rms_px(r.transform, base[2]) < tol
        assert r.model == model


def _dihedral_views(img: np.ndarray):
    """(code, view, new pixel -> old pixel map) for the 8 dihedral codes (module docstring
    of :mod:`apygis.aerotri.interior`: ``np.rot90(img, code % 4)``, then ``np.fliplr``
    for ``code >= 4``)."""
    n = img.shape[0]
    for code in range(8):

        def op(a, code=code):
            b = np.rot90(a, code % 4)
            return np.fliplr(b) if code >= 4 else b

        cols = op(np.tile(np.arange(n), (n, 1)))
        rows = op(np.tile(np.arange(n)[:, None], (1, n)))
        new = np.array([[0.0, 0.0], [n - 1.0, 0.0], [0.0, n - 1.0]])
        old = np.array([[cols[int(r), int(c)], rows[int(r), int(c)]] for c, r in new])
        ones = np.ones(3)
        m = np.linalg.solve(np.column_stack([new, ones]), np.column_stack([old, ones]))
        yield code, op(img), m.T  # homogeneous: old = m.T @ new


def test_all_eight_dihedral_codes(scan, base):
    img = scan.array(0)
    for code, view, new_to_old in _dihedral_views(img):
        truth = PixelTransform(base[2].matrix @ new_to_old)
        assert dihedral_code(truth) == code
        r = interior_orientation(ArraySource(np.ascontiguousarray(view)), CAMERA)
        assert r.dihedral == code
        assert transform_rms_px(r.transform, truth) < TOL_PX


def test_rotation_is_ambiguous_without_an_orientation_mark(scan, base):
    plain = Camera(name="plain", kind="film", focal_mm=153.0, fiducials=FIDUCIALS)
    view = np.ascontiguousarray(np.rot90(scan.array(0), 2))  # a scan turned by 180 deg
    r = interior_orientation(ArraySource(view), plain)
    assert r.dihedral == 0  # the one nearest the identity
    assert any("rotation ambiguous" in n for n in r.notes)
    assert r.rms_um < 1.0


def test_a_blotted_mark_is_missing(base):
    seven = Camera(
        name="seven", kind="film", focal_mm=153.0,
        fiducials={k: v for k, v in FIDUCIALS.items() if k != "3"},
        orientation_mark_mm=(-12.0, 110.0),
    )  # fmt: skip
    r = interior_orientation(make_scan(base, seven), CAMERA)
    assert r.missing == ["3"]
    assert "3" not in r.fiducials_px
    assert len(r.residuals_um) == 7
    assert any("3" in n and "not found" in n for n in r.notes)
    assert transform_rms_px(r.transform, base[2]) < TOL_PX


def test_a_displaced_mark_is_flagged(base):
    moved = dict(FIDUCIALS)
    moved["6"] = (110.0 + 0.030, 0.0)  # the mark is 30 um off its calibrated place
    drawn = Camera(
        name="moved", kind="film", focal_mm=153.0, fiducials=moved,
        orientation_mark_mm=(-12.0, 110.0),
    )  # fmt: skip
    r = interior_orientation(make_scan(base, drawn), CAMERA, max_residual_um=10.0)
    # affine from 8 marks: the residual of the moved mark is 30 um * (1 - leverage),
    # leverage of a side mark ~0.4 -> ~18 um, far above 10 um (noise 0.25 um)
    assert r.flagged
    worst = max(r.residuals_um, key=lambda k: math.hypot(*r.residuals_um[k]))
    assert worst == "6"
    assert r.max_um > 10.0
    assert r.residuals_um["6"][0] > 10.0  # the mark appears outwards (+x)
    assert any("fiducial 6" in n for n in r.notes)


def test_a_blank_image_raises_naming_it():
    rng = np.random.default_rng(0)
    blank = ArraySource((100.0 + rng.normal(0.0, 3.0, (1500, 1500))).astype(np.float32))
    with pytest.raises(OrientationError, match=r"scan_0042\.tif: found 0 fiducial mark"):
        interior_orientation(blank, CAMERA, name="scan_0042.tif")


def test_too_few_marks_raise(base):
    three = Camera(
        name="three", kind="film", focal_mm=153.0,
        fiducials={k: FIDUCIALS[k] for k in ("1", "2", "3")},
    )  # fmt: skip
    with pytest.raises(OrientationError, match=r"photo 3: found 3 of 8 fiducial marks"):
        interior_orientation(make_scan(base, three), CAMERA, name="photo 3")


# ------------------------------------------------------------------ a finer scan, by windows


class WindowedScan:
    """A 20 um scan (12000 px) drawn on demand, window by window (never whole at level 0).

    Level ``k`` is drawn at its own pixel size (area coverage of a 2^k block is the mean
    of its pixels' coverage); the texture is a smooth function of photo position; each
    read gets fresh noise of 3 DN / 2^k.
    """

    def __init__(self, n: int, pixel_mm: float, camera: Camera, code: int = 0):
        self.n, self.transform, self.camera = n, scan_transform(n, pixel_mm, code), camera
        self._levels = 6
        self.largest_level0_read = 0
        self._rng = np.random.default_rng(5)
        r = np.random.default_rng(9)
        self._k = r.uniform(0.5, 3.0, (6, 2)) * r.choice([-1, 1], (6, 2))  # rad / mm
        self._ph = r.uniform(0, 2 * math.pi, 6)

    @property
    def levels(self) -> int:
        return self._levels

    def shape(self, level: int) -> tuple[int, int]:
        s = self.n >> level
        return s, s

    def read(self, level, col0, row0, width, height):
        if level == 0:
            self.largest_level0_read = max(self.largest_level0_read, width * height)
        f = 2.0**level
        # level pixel -> level-0 pixel -> mm; then shifted to the window's origin
        shift = np.array([[f, 0, col0 * f + (f - 1) / 2], [0, f, row0 * f + (f - 1) / 2],
                          [0, 0, 1.0]])  # fmt: skip
        t = PixelTransform(self.transform.matrix @ shift)
        cols, rows = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
        mm = t.to_mm(np.column_stack([cols.ravel(), rows.ravel()]))
        tex = 120.0 + 15.0 * np.sin(mm @ self._k.T + self._ph).sum(axis=1)
        inside = (np.abs(mm) <= 115.0).all(axis=1)
        bg = np.where(inside, tex, 10.0).reshape(height, width)
        img = draw_marks(bg, t, self.camera)
        img += self._rng.normal(0.0, 3.0 / f, img.shape)
        return img.astype(np.float32)


def test_a_finer_scan_by_windows():
    src = WindowedScan(12000, 0.02, CAMERA, code=6)
    r = interior_orientation(src, CAMERA, approx_pixel_um=20.0)
    assert r.dihedral == 6
    # at 20 um the marks have 4x the pixels across: sigma in px about the same per
    # edge pixel with 4x as many edge pixels -> ~0.002 px; the same 0.02 px tolerance
    assert transform_rms_px(r.transform, src.transform) < TOL_PX
    assert r.missing == []
    # level 0 read by windows around the marks only (2.6 mm + slack at 20 um: ~300 px)
    assert src.largest_level0_read <= 400 * 400


def test_digital_interior():
    cam = Camera(name="dmc", kind="digital", focal_mm=120.0, pixel_um=12.0, sensor_px=(7680, 13824))
    r = digital_interior(cam, 7680, 13824)
    assert np.array_equal(r.transform.matrix, PixelTransform.digital(7680, 13824, 12.0).matrix)
    assert r.model == "digital"
    assert r.residuals_um == {}
    assert r.missing == []
    with pytest.raises(OrientationError, match="7680 x 13824"):
        digital_interior(cam, 7000, 13824)
    with pytest.raises(OrientationError, match="not a digital camera"):
        digital_interior(CAMERA, 100, 100)


def test_an_unknown_pixel_size_is_found():
    # 3000 px over 300 mm (100 um) with no pixel size given: the nominal guess is
    # 240 mm / 3000 px = 80 um, 25 % off; the templates at 1, 1.15 and 1.3 x cover it
    src = WindowedScan(3000, 0.1, CAMERA, code=1)
    r = interior_orientation(src, CAMERA)
    assert r.dihedral == 1
    assert transform_rms_px(r.transform, src.transform) < TOL_PX
    assert abs(r.transform.pixel_mm / 0.1 - 1.0) < 1e-4


def test_a_mark_cut_by_the_scan_edge_is_missing(scan, base):
    # crop the scan just outside mark 6's ring (17 px = 1.36 mm from its centre; the
    # ring ends at 1.3 mm): the fit alone would accept it (r2 ~0.89) with a 0.05 px
    # bias from the edge padding; it must be reported missing, the other 7 orient
    col6 = int(base[2].to_px([FIDUCIALS["6"]])[0, 0])
    crop = np.ascontiguousarray(scan.array(0)[:, : col6 + 17])
    r = interior_orientation(ArraySource(crop), CAMERA, approx_pixel_um=80.0)
    assert r.missing == ["6"]
    assert transform_rms_px(r.transform, base[2]) < TOL_PX
