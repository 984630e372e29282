"""Block exchange: PAT-B, BLUH, COLMAP, OpenDroneMap and MicMac files written and read.

Round trips run on simulated blocks (apygis.aerotri.simulate) turned into exchange
blocks with everything a format may carry (tests/aerotri/exchange_blocks.py); each
compares what the format holds, to the format's stated resolution, and the report of
what it cannot hold. COLMAP is checked against pycolmap both ways.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from apygis.aerotri.exchange import ExchangeBlock, complete_observations
from apygis.aerotri.exchange.bluh import read_bluh, write_bluh
from apygis.aerotri.exchange.colmap import read_colmap, write_colmap
from apygis.aerotri.exchange.micmac import read_micmac, write_micmac
from apygis.aerotri.exchange.odm import read_odm, write_odm
from apygis.aerotri.exchange.patb import read_patb, write_patb
from apygis.errors import CRSError, FormatError, ValueRangeError
from apygis.orient.rotation import rotation_matrix
from tests.aerotri.exchange_blocks import sim_block

EPS = 1e-9  # float rounding on top of a format's resolution (values up to 3e6)


@pytest.fixture(scope="module")
def block():
    return sim_block(2, 4, points_per_image=60, seed=1)


@pytest.fixture(scope="module")
def film_block():
    return sim_block(2, 3, points_per_image=40, film=True, seed=2)


def _obs(b: ExchangeBlock) -> dict:
    return {(o.point, o.image): o for o in b.observations}


def _by_kind(b: ExchangeBlock, *kinds) -> dict:
    return {p.name: p for p in b.points if p.kind in kinds}


def _R(eo) -> np.ndarray:
    return rotation_matrix(*np.asarray(eo)[3:])


# ------------------------------------------------------------------ PAT-B


def test_patb_round_trip(block, tmp_path):
    rep = write_patb(block, tmp_path / "blk")
    assert [f.name for f in rep.files] == ["blk.im", "blk.con", "blk.ori"]
    back = read_patb(tmp_path / "blk")
    # observations: micrometres with 3 decimals -> 0.5e-6 mm
    want, got = _obs(block), _obs(back)
    assert set(got) == set(want)
    for k, o in got.items():
        assert o.x_px is None
        assert abs(o.x_mm - want[k].x_mm) <= 0.5e-6 + EPS
        assert abs(o.y_mm - want[k].y_mm) <= 0.5e-6 + EPS
    # full control: 3 decimals of a metre
    full = _by_kind(block, "full")
    back_full = _by_kind(back, "full")
    assert set(back_full) == set(full)
    for n, p in back_full.items():
        assert np.abs(p.xyz - full[n].xyz).max() <= 0.0005 + EPS
    # orientations: centre 5 decimals, matrix 12 decimals
    eo = {im.image: im.eo for im in block.images}
    assert [im.image for im in back.images] == sorted(eo)
    for im in back.images:
        assert np.abs(im.eo[:3] - eo[im.image][:3]).max() <= 0.5e-5 + EPS
        assert np.abs(_R(im.eo) - _R(eo[im.image])).max() <= 2e-12
    # what PAT-B cannot hold, counted
    kinds = [p.kind for p in block.points]
    assert rep.written == {
        "photos": 8, "observations": len(block.observations),
        "control points": kinds.count("full"), "orientations": 8,
    }  # fmt: skip
    assert rep.skipped[
        "planimetric points (PAT-B's control file has full control only)"
    ] == kinds.count("planimetric")
    assert rep.skipped["height points (PAT-B's control file has full control only)"] == kinds.count(
        "height"
    )
    assert rep.skipped["check points (PAT-B's control file has full control only)"] == kinds.count(
        "check"
    )
    assert rep.skipped["observation sigmas (PAT-B's image file has none)"] == len(
        block.observations
    )
    assert rep.skipped["orientation standard deviations (PAT-B's file has none)"] == 8
    assert rep.skipped["cameras (PAT-B keeps them in its camera file)"] == 1


def test_patb_reads_one_file_of_a_set_or_another_name(block, tmp_path):
    write_patb(block, tmp_path / "blk.im")
    only_ori = tmp_path / "o.ori"
    only_ori.write_bytes((tmp_path / "blk.ori").read_bytes())
    b = read_patb(only_ori)
    assert len(b.images) == 8
    assert not b.observations
    assert all(im.eo is not None for im in b.images)
    other = tmp_path / "dens.patb"
    other.write_bytes((tmp_path / "blk.im").read_bytes())
    assert len(read_patb(other).observations) == len(block.observations)
    with pytest.raises(FormatError, match=r"no such file \(looked for .*nothing\.im"):
        read_patb(tmp_path / "nothing")


def test_patb_photo_coordinates_from_pixels(block, tmp_path):
    """An observation without photo mm is converted through its image's pixel transform."""
    b = sim_block(1, 2, points_per_image=20, seed=3)
    for o in b.observations:
        o.x_mm = o.y_mm = None
    write_patb(b, tmp_path / "px")
    back = _obs(read_patb(tmp_path / "px"))
    ref = _obs(sim_block(1, 2, points_per_image=20, seed=3))
    assert max(abs(o.x_mm - ref[k].x_mm) for k, o in back.items()) <= 0.5e-6 + EPS


def test_patb_refuses_what_does_not_fit(block, tmp_path):
    b = sim_block(2, 3, points_per_image=20, seed=5)
    long = "P" * 16
    b.points[0].name = long
    for o in b.observations:
        if o.point == b.points[0].name or o.point == str(1000):
            o.point = long
    with pytest.raises(
        ValueRangeError,
        match=r"blk\.im: photo \d+ point 'P{16}': point name .* 16 characters, more than the 15",
    ):
        write_patb(b, tmp_path / "blk")
    assert not list(tmp_path.iterdir())  # nothing half-written
    b = sim_block(2, 3, points_per_image=20, seed=5)
    b.images[0].eo[0] = 2e9  # F16.5 holds at most 10 digits before the point
    with pytest.raises(
        ValueRangeError,
        match=r"blk\.ori: photo 101: X0 2000000000\.0 does not fit the field F16\.5",
    ):
        write_patb(b, tmp_path / "blk")
    b = sim_block(2, 3, points_per_image=20, seed=5)
    b.observations[0].point = "nobody"
    with pytest.raises(
        ValueRangeError, match=r"observation 1 .*'nobody'.*: the block has no such point"
    ):
        write_patb(b, tmp_path / "blk")


# ------------------------------------------------------------------ BLUH


def test_bluh_round_trip(block, tmp_path):
    rep = write_bluh(block, tmp_path / "blk")
    assert [f.name for f in rep.files] == ["blk.pho", "blk.ctl"]
    back = read_bluh(tmp_path / "blk.pho")
    want, got = _obs(block), _obs(back)
    assert set(got) == set(want)
    for k, o in got.items():  # mm with 4 decimals
        assert abs(o.x_mm - want[k].x_mm) <= 0.5e-4 + EPS
        assert abs(o.y_mm - want[k].y_mm) <= 0.5e-4 + EPS
    control = _by_kind(block, "full", "planimetric", "height")
    back_control = _by_kind(back, "full", "planimetric", "height")
    assert {n: p.kind for n, p in back_control.items()} == {n: p.kind for n, p in control.items()}
    for n, p in back_control.items():
        ref = control[n].xyz
        if p.kind == "planimetric":
            assert math.isnan(p.xyz[2])
            assert np.abs(p.xyz[:2] - ref[:2]).max() <= 0.0005 + EPS
        else:
            assert np.abs(p.xyz - ref).max() <= 0.0005 + EPS
    assert rep.skipped["check points (BLUH's control file has control only)"] == 3
    assert rep.skipped["exterior orientations (not part of BLUH's input files)"] == 8


def test_bluh_refuses_names_that_are_not_numbers(tmp_path):
    for bad in ("GCP1", "0042", "2147483648", "0"):
        b = sim_block(2, 3, points_per_image=20, seed=5)
        name = b.observations[0].point
        for o in b.observations:
            if o.point == name:
                o.point = bad
        next(p for p in b.points if p.name == name).name = bad
        with pytest.raises(
            ValueRangeError,
            match=rf"blk\.pho: photo \d+: point name '{bad}' is not a BLUH point number",
        ):
            write_bluh(b, tmp_path / "blk")
    assert not list(tmp_path.iterdir())


# ------------------------------------------------------------------ COLMAP


def _cam_from_world(eo) -> np.ndarray:
    D = np.diag([1.0, -1.0, -1.0])
    R_cw = D @ _R(eo).T
    return np.c_[R_cw, -R_cw @ np.asarray(eo)[:3]]


def test_colmap_round_trip_digital(block, tmp_path):
    rep = write_colmap(block, tmp_path / "model")
    assert [f.name for f in rep.files] == ["cameras.txt", "images.txt", "points3D.txt"]
    assert not rep.notes
    back = read_colmap(tmp_path / "model", pixel_um=10.0)
    written = {p.name: p for p in block.points if p.xyz is not None and np.isfinite(p.xyz).all()}
    assert {p.name for p in back.points} == set(written)
    for p in back.points:
        assert p.kind == "tie"
        np.testing.assert_array_equal(p.xyz, written[p.name].xyz)
    want = _obs(block)
    got = _obs(back)
    assert set(got) == {k for k in want if k[0] in written}
    for k, o in got.items():
        assert abs(o.x_px - want[k].x_px) <= 1e-9
        assert abs(o.y_px - want[k].y_px) <= 1e-9
        assert abs(o.x_mm - want[k].x_mm) <= 1e-12
        assert abs(o.y_mm - want[k].y_mm) <= 1e-12
    ref = {im.image: im for im in block.images}
    for im in back.images:
        assert im.name == ref[im.image].name
        np.testing.assert_allclose(im.pixel_to_mm, ref[im.image].pixel_to_mm, rtol=0, atol=1e-12)
        assert np.abs(im.eo[:3] - ref[im.image].eo[:3]).max() <= 1e-9 * 3e6
        assert np.abs(_R(im.eo) - _R(ref[im.image].eo)).max() <= 1e-13
    cam = back.cameras[0]
    assert (cam.focal_mm, cam.width_px, cam.pixel_mm) == pytest.approx(
        (153.0, 23000, 0.01), abs=1e-12
    )
    assert (cam.x0_mm, cam.y0_mm) == pytest.approx((0.004, -0.003), abs=1e-12)
    assert rep.skipped["points without X, Y and Z, and their observations"] == 2  # planimetric
    assert rep.skipped["point kinds of control and check points (COLMAP has none)"] == 9
    assert rep.skipped["the CRS (COLMAP has none)"] == 1


def test_pycolmap_reads_what_apygis_writes(block, film_block, tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    for b, name in ((block, "digital"), (film_block, "film")):
        write_colmap(b, tmp_path / name)
        rec = pycolmap.Reconstruction(str(tmp_path / name))
        n_points = sum(1 for p in b.points if p.xyz is not None and np.isfinite(p.xyz).all())
        n_obs = sum(
            1
            for o in b.observations
            if o.point
            in {p.name for p in b.points if p.xyz is not None and np.isfinite(p.xyz).all()}
        )
        assert (rec.num_reg_images(), rec.num_points3D(), rec.compute_num_observations()) == (
            len(b.images),
            n_points,
            n_obs,
        )
        eo = {im.image: im.eo for im in b.images}
        for iid, im in rec.images.items():
            want = _cam_from_world(eo[iid])
            got = im.cam_from_world().matrix()
            assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()
        xyz = {
            int(p.name): p.xyz for p in b.points if p.xyz is not None and np.isfinite(p.xyz).all()
        }
        for pid, p in rec.points3D.items():
            np.testing.assert_array_equal(p.xyz, xyz[pid])
        # COLMAP's own projection of the points agrees with the observations (corner origin)
        obs = _obs(b)
        res = []
        for pid, p in rec.points3D.items():
            for el in p.track.elements:
                im = rec.images[el.image_id]
                uv = im.camera.img_from_cam(im.cam_from_world() * p.xyz)
                meas = im.points2D[el.point2D_idx].xy
                res.append(uv - meas)
                if name == "digital":
                    o = obs[(str(pid), el.image_id)]
                    assert np.abs(meas - [o.x_px + 0.5, o.y_px + 0.5]).max() <= 1e-9
        res = np.array(res)
        # the simulated noise is 0.1 px (10 um pixels, 1 um); half a pixel of convention
        # or a principal point off by its offset (0.4, 0.3 px) would show in the mean
        assert np.abs(res.mean(axis=0)).max() < 0.03
        assert 0.07 < res.std() < 0.13


def test_colmap_film_scan_is_a_virtual_pixel_grid(film_block, tmp_path):
    rep = write_colmap(film_block, tmp_path / "film")
    assert len(rep.notes) == 1
    assert "virtual pixel grid of 10.00 um" in rep.notes[0]
    back = read_colmap(tmp_path / "film", pixel_um=10.0)
    want = _obs(film_block)
    for k, o in _obs(back).items():  # photo coordinates come back, the scan pixels do not
        assert abs(o.x_mm - want[k].x_mm) <= 1e-12
        assert abs(o.y_mm - want[k].y_mm) <= 1e-12
    ref = {im.image: im for im in film_block.images}
    for im in back.images:
        assert np.abs(_R(im.eo) - _R(ref[im.image].eo)).max() <= 1e-13
        w, h = im.width_px, im.height_px
        corners = np.array([[-115.0, -115.0], [115.0, 115.0]])  # the film format fits the grid
        assert (np.abs(corners) < [w * 0.005, h * 0.005]).all()


def _pycolmap_model(pycolmap, folder, model: str, params, seed: int = 0):
    """A model made by pycolmap alone (no apygis): one camera, three posed images, 20
    points seen in all three plus one keypoint per image that is no 3-D point."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera(model=model, width=2000, height=1500, params=params, camera_id=3)
    rec.add_camera_with_trivial_rig(cam)
    X = rng.uniform([-5, -5, 18], [5, 5, 22], (20, 3))
    for iid in (4, 7, 9):
        pose = pycolmap.Rigid3d(
            np.c_[
                Rotation.from_euler("xyz", rng.normal(0, 0.05, 3)).as_matrix(), rng.normal(0, 1, 3)
            ]
        )
        im = pycolmap.Image(name=f"im{iid}.jpg", camera_id=3, image_id=iid)
        pts = [pycolmap.Point2D(cam.img_from_cam(pose * x)) for x in X]
        im.points2D = pycolmap.Point2DList([*pts, pycolmap.Point2D(np.array([5.0, 6.0]))])
        rec.add_image_with_trivial_frame(im, pose)
    for j, x in enumerate(X):
        track = pycolmap.Track()
        for iid in (4, 7, 9):
            track.add_element(iid, j)
        rec.add_point3D(x, track)
    folder.mkdir()
    rec.write_text(str(folder))
    return rec


def test_colmap_model_written_by_pycolmap_imports(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    rec = _pycolmap_model(pycolmap, tmp_path / "m", "PINHOLE", [2000.0, 2010.0, 1000.3, 750.7])
    back = read_colmap(tmp_path / "m", pixel_um={3: 4.5})
    assert back.skipped == {
        "points2D that no 3-D point's track names": 3,
        "rigs.txt (not read: each image's pose is in images.txt)": 1,
        "frames.txt (not read: each image's pose is in images.txt)": 1,
    }
    assert (len(back.images), len(back.points), len(back.observations)) == (3, 20, 60)
    cam = back.cameras[0]
    assert cam.focal_mm == pytest.approx(2000.0 * 0.0045, abs=1e-12)
    assert cam.pixel_mm is None  # fx != fy: the pitch of y is c / fy
    assert cam.x0_mm == pytest.approx((1000.3 - 1000.0) * 0.0045, abs=1e-12)
    assert cam.y0_mm == pytest.approx(-(750.7 - 750.0) * cam.focal_mm / 2010.0, abs=1e-12)
    for im in back.images:
        assert im.name == f"im{im.image}.jpg"
        got = _cam_from_world(im.eo)
        want = rec.images[im.image].cam_from_world().matrix()
        assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()
    for p in back.points:
        np.testing.assert_array_equal(p.xyz, rec.points3D[int(p.name)].xyz)
    for o in back.observations:
        k = int(o.point) - 1  # pycolmap numbered the points 1.. in order of X
        np.testing.assert_allclose(
            [o.x_px + 0.5, o.y_px + 0.5], rec.images[o.image].points2D[k].xy, rtol=0, atol=1e-9
        )
        # the photo coordinates obey apygis's collinearity with the imported camera
        im = next(i for i in back.images if i.image == o.image)
        R = _R(im.eo)
        q = R.T @ (rec.points3D[int(o.point)].xyz - im.eo[:3])
        assert abs(o.x_mm - (cam.x0_mm - cam.focal_mm * q[0] / q[2])) <= 1e-9
        assert abs(o.y_mm - (cam.y0_mm - cam.focal_mm * q[1] / q[2])) <= 1e-9


def test_colmap_opencv_camera_is_refused_or_undistorted(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    params = [2000.0, 2000.4, 1000.3, 750.7, -0.05, 0.01, 2e-4, -1e-4]
    rec = _pycolmap_model(pycolmap, tmp_path / "m", "OPENCV", params)
    with pytest.raises(
        FormatError, match=r"cameras\.txt: line 4: camera 3 is an OPENCV camera with distortion"
    ):
        read_colmap(tmp_path / "m", pixel_um=4.5)
    back = read_colmap(tmp_path / "m", pixel_um=4.5, distortion="undistort")
    pinhole = pycolmap.Camera(model="PINHOLE", width=2000, height=1500, params=params[:4])
    for o in back.observations:
        im = rec.images[o.image]
        want = pinhole.img_from_cam(im.cam_from_world() * rec.points3D[int(o.point)].xyz)
        assert np.abs(np.array([o.x_px + 0.5, o.y_px + 0.5]) - want).max() <= 1e-6


def test_colmap_refusals(block, tmp_path):
    b = sim_block(2, 3, points_per_image=20, seed=5)
    b.cameras[0].radial_mm, b.cameras[0].radial_um = (0.0, 100.0), (0.0, 5.0)
    with pytest.raises(
        ValueRangeError, match=r"cameras\.txt: camera 1: camera 1 .* radial distortion table"
    ):
        write_colmap(b, tmp_path / "d")
    rep = write_colmap(b, tmp_path / "d", distortion="undistort")
    assert any("corrected for its radial distortion table" in n for n in rep.notes)
    b = sim_block(2, 3, points_per_image=20, seed=5)
    b.images[0].name = "my photo.tif"
    with pytest.raises(
        ValueRangeError, match=r"images\.txt: image 101: image name 'my photo\.tif'"
    ):
        write_colmap(b, tmp_path / "e")
    stale = tmp_path / "f"
    stale.mkdir()
    (stale / "frames.txt").write_text("1 1 1 0 0 0 0 0 0 0\n")
    with pytest.raises(
        ValueRangeError, match=r"frames\.txt: the folder holds a frames\.txt of another model"
    ):
        write_colmap(block, stale)


# ------------------------------------------------------------------ OpenDroneMap


def test_odm_round_trip(block, tmp_path):
    rep = write_odm(block, tmp_path / "gcp_list.txt")
    assert (tmp_path / "gcp_list.txt").read_text().splitlines()[0] == "EPSG:2056"
    back = read_odm(tmp_path / "gcp_list.txt")
    assert back.crs == "EPSG:2056"
    ctl = _by_kind(block, "full", "planimetric")
    assert {p.name: p.kind for p in back.points} == {n: p.kind for n, p in ctl.items()}
    for p in back.points:
        np.testing.assert_array_equal(p.xyz, ctl[p.name].xyz)
    images = {im.image: im.name for im in block.images}
    want = {(o.point, images[o.image]): o for o in block.observations if o.point in ctl}
    got = {
        (o.point, {im.image: im.name for im in back.images}[o.image]): o for o in back.observations
    }
    assert set(got) == set(want)
    for k, o in got.items():  # full precision, no pixel shift
        assert (o.x_px, o.y_px) == (want[k].x_px, want[k].y_px)
        assert o.x_mm is None
    assert rep.written["measurements"] == len(want)
    assert rep.skipped["observations of check points (ODM's file holds control with X, Y)"] > 0
    assert rep.skipped["observations of height control (ODM's file holds control with X, Y)"] > 0
    # the pixel transforms of the block give back the photo coordinates
    names = {im.name: im for im in block.images}
    for im in back.images:
        im.pixel_to_mm = names[im.name].pixel_to_mm
    assert complete_observations(back) == len(got)
    for k, o in got.items():
        assert abs(o.x_mm - want[k].x_mm) <= 1e-9
        assert abs(o.y_mm - want[k].y_mm) <= 1e-9


def test_odm_reads_what_opensfm_reads(tmp_path):
    """Comments, blank lines, a UTM header, points without names grouped by coordinates,
    NaN heights, extra fields."""
    f = tmp_path / "gcp_list.txt"
    f.write_text(
        "# made by hand\n"
        "WGS84 UTM 32N\n"
        "\n"
        "544256.7 5320919.9 5 3044 2622 IMG_0525.jpg\n"
        "544157.7 5320899.2 NaN 4193 1552 IMG_0585.jpg\n"
        "544256.7 5320919.9 5 1606 2763 IMG_0690.jpg\n"
        "544033.4 5320876.0 7 10 20 IMG_0690.jpg target9 extra1 extra2\n"
    )
    b = read_odm(f)
    assert b.crs == "EPSG:32632"
    assert [(p.name, p.kind) for p in b.points] == [
        ("gcp-1", "full"),
        ("gcp-2", "planimetric"),
        ("target9", "full"),
    ]
    assert [im.name for im in b.images] == ["IMG_0525.jpg", "IMG_0585.jpg", "IMG_0690.jpg"]
    assert [(o.point, o.image) for o in b.observations] == [
        ("gcp-1", 1),
        ("gcp-2", 2),
        ("gcp-1", 3),
        ("target9", 3),
    ]
    assert b.skipped == {"extra fields after gcp_name (not read)": 1}


def test_odm_refusals(block, tmp_path):
    b = sim_block(2, 3, points_per_image=20, seed=5)
    b.crs = ""
    with pytest.raises(CRSError, match="the block has no CRS"):
        write_odm(b, tmp_path / "g.txt")
    f = tmp_path / "g.txt"
    f.write_text("EPSG:2056\n1 2 3 4 5 a.jpg P\n1 2 3 6 7 a.jpg P\n")
    with pytest.raises(
        FormatError,
        match=r"g\.txt: line 3: point 'P' is measured twice in image 'a\.jpg' \(also at line 2\)",
    ):
        read_odm(f)


# ------------------------------------------------------------------ MicMac


def test_micmac_round_trip(block, tmp_path):
    rep = write_micmac(block, tmp_path / "blk")
    assert [p.name for p in rep.files] == ["blk_3d_gcp.xml", "blk_2d_gcp.xml"]
    back = read_micmac(tmp_path / "blk")
    ctl = _by_kind(block, "full", "planimetric", "height", "check")
    assert {p.name: p.kind for p in back.points} == {n: p.kind for n, p in ctl.items()}
    for p in back.points:
        ref = ctl[p.name]
        np.testing.assert_array_equal(p.xyz, ref.xyz)
        if p.kind == "full":
            np.testing.assert_array_equal(p.sigma, ref.sigma)
        elif p.kind == "planimetric":
            assert p.sigma[:2].tolist() == ref.sigma[:2].tolist()
            assert math.isnan(p.sigma[2])
        elif p.kind == "height":
            assert p.sigma[2] == ref.sigma[2]
            assert np.isnan(p.sigma[:2]).all()
        else:
            assert p.sigma is None
    names = {im.image: im.name for im in block.images}
    back_names = {im.image: im.name for im in back.images}
    want = {(o.point, names[o.image]): o for o in block.observations if o.point in ctl}
    got = {(o.point, back_names[o.image]): o for o in back.observations}
    assert set(got) == set(want)
    for k, o in got.items():
        assert (o.x_px, o.y_px) == (want[k].x_px, want[k].y_px)
    assert rep.written == {"points": len(ctl), "measurements": len(want)}


def test_micmac_without_global_and_files_in_any_order(tmp_path):
    d3 = tmp_path / "gcp.xml"
    d3.write_text(
        "<DicoAppuisFlottant><OneAppuisDAF><Pt>1 2 3</Pt><NamePt>A&amp;B</NamePt>"
        "<Incertitude>0.1 0.1 0.2</Incertitude></OneAppuisDAF></DicoAppuisFlottant>"
    )
    d2 = tmp_path / "mes.xml"
    d2.write_text(
        "<?xml version='1.0'?><Global><SetOfMesureAppuisFlottants><MesureAppuiFlottant1Im>"
        "<NameIm>a.jpg</NameIm><OneMesureAF1I><NamePt>A&amp;B</NamePt><PtIm>10.5 20.25</PtIm>"
        "</OneMesureAF1I></MesureAppuiFlottant1Im></SetOfMesureAppuisFlottants></Global>"
    )
    for order in ((d3, d2), (d2, d3)):
        b = read_micmac(*order)
        assert [(p.name, p.kind, p.xyz.tolist()) for p in b.points] == [
            ("A&B", "full", [1.0, 2.0, 3.0])
        ]
        assert [(o.point, o.x_px, o.y_px) for o in b.observations] == [("A&B", 10.5, 20.25)]


def test_micmac_refusals(block, tmp_path):
    b = sim_block(2, 3, points_per_image=20, seed=5)
    for p in b.points:
        p.sigma = None
    with pytest.raises(
        ValueRangeError, match=r"_3d_gcp\.xml: point '\d+': the control point has no sigma"
    ):
        write_micmac(b, tmp_path / "x")
    rep = write_micmac(b, tmp_path / "x", default_sigma_m=0.05)
    assert rep.notes
    assert "Incertitude 0.05 m" in rep.notes[0]
    f = tmp_path / "lol.xml"
    f.write_text(
        '<?xml version="1.0"?>\n<!DOCTYPE l [<!ENTITY a "aaaa">]>\n<DicoAppuisFlottant/>\n'
    )
    with pytest.raises(FormatError, match=r"lol\.xml: line 2: holds <!DOCTYPE: document type"):
        read_micmac(f)


# ------------------------------------------------------------------ hostile input

HOSTILE = {
    # name: (file name, content, reader, message)
    "patb truncated": (
        "t.im",
        b"  7\n  P1  1.0  2.0\n",
        read_patb,
        r"t\.im: photo 7 \(line 1\) is not closed by -99",
    ),
    "patb huge photo number": (
        "t.im",
        b"  99999999999999999999\n  -99\n",
        read_patb,
        r"t\.im: line 1: photo number '9+' is not a whole number",
    ),
    "patb NaN": (
        "t.im",
        b"  7\n  P1  NaN  2.0\n  -99\n",
        read_patb,
        r"t\.im: line 2: x \(um\) 'NaN' is not a finite number",
    ),
    "patb inf": (
        "t.con",
        b"  G  inf  1  2\n  -99\n",
        read_patb,
        r"t\.con: line 1: X 'inf' is not a finite number",
    ),
    "patb not utf-8": (
        "t.im",
        b"  7\n  P\xe91  1.0  2.0\n  -99\n",
        read_patb,
        r"t\.im: line 2: not UTF-8 text",
    ),
    "patb line too long": (
        "t.im",
        b"  7\n" + b" " * 600 + b"P1 1 2\n  -99\n",
        read_patb,
        r"t\.im: line 2: a line of 606 bytes is longer than the 512",
    ),
    "patb not a rotation": (
        "t.ori",
        b"7 1 2 3\n1 0 0 0 1\n0 0 0.5 1\n",
        read_patb,
        r"t\.ori: line 2: the matrix of photo 7 is not a rotation",
    ),
    "bluh truncated": (
        "t.pho",
        b"  7\n  12  1.0  2.0\n",
        read_bluh,
        r"t\.pho: photo 7 \(line 1\) is not closed by a record 0",
    ),
    "bluh number too large": (
        "t.ctl",
        b"  99999999999  1 2 3 3\n  0\n",
        read_bluh,
        r"t\.ctl: line 1: point number '99999999999' is not a whole number from 1 to 2147483647",
    ),
    "colmap huge width": (
        "cameras.txt",
        b"1 PINHOLE 1000000000000 10 5 5 5 5\n",
        None,
        r"cameras\.txt: line 1: width '1000000000000' is not a whole number from 1 to 1000000",
    ),
    "colmap truncated images": (
        "images.txt",
        b"1 1 0 0 0 0 0 5 1 a.jpg\n",
        None,
        r"images\.txt: line 1: image 1 has no POINTS2D line",
    ),
    "colmap NaN point": (
        "points3D.txt",
        b"1 nan 2 3 0 0 0 -1\n",
        None,
        r"points3D\.txt: line 1: coordinate 'nan' is not a finite number",
    ),
    "colmap not utf-8": (
        "images.txt",
        b"1 1 0 0 0 0 0 5 1 \xff.jpg\n\n",
        None,
        r"images\.txt: line 1: not UTF-8 text",
    ),
    "odm 1e999": (
        "gcp_list.txt",
        b"EPSG:2056\n1e999 2 3 4 5 a.jpg\n",
        read_odm,
        r"gcp_list\.txt: line 2: geo coordinate '1e999' is not a finite number",
    ),
    "odm line too long": (
        "gcp_list.txt",
        b"EPSG:2056\n" + b"9" * 5000 + b" 2 3 4 5 a.jpg\n",
        read_odm,
        r"gcp_list\.txt: line 2: a line of 5014 bytes is longer than the 4096",
    ),
    "micmac entities": (
        "m.xml",
        b'<?xml version="1.0"?>\n<!DOCTYPE a [<!ENTITY x "y">]>\n<DicoAppuisFlottant/>\n',
        read_micmac,
        r"m\.xml: line 2: holds <!DOCTYPE",
    ),
    "micmac truncated": (
        "m.xml",
        b"<DicoAppuisFlottant><OneAppuisDAF><Pt>1 2",
        read_micmac,
        r"m\.xml: line 1 column \d+: not well-formed XML",
    ),
    "micmac not utf-8": (
        "m.xml",
        b"<DicoAppuisFlottant><OneAppuisDAF><NamePt>\xff</NamePt>",
        read_micmac,
        r"m\.xml: line 1 column \d+: not well-formed XML",
    ),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_input_is_one_clear_error(case, tmp_path):
    name, data, reader, message = HOSTILE[case]
    if reader is None:  # a COLMAP file: the other two valid
        from apygis.aerotri.exchange.colmap import write_colmap

        write_colmap(sim_block(2, 3, points_per_image=20, seed=5), tmp_path)
        reader = lambda p: read_colmap(p.parent, pixel_um=10.0)  # noqa: E731
    path = tmp_path / name
    path.write_bytes(data)
    with pytest.raises(FormatError, match=message) as err:
        reader(path)
    assert "\n" not in str(err.value)


def test_a_billion_laughs_expands_nothing(tmp_path):
    f = tmp_path / "lol.xml"
    f.write_text(
        '<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol">'
        + "".join(
            f'<!ENTITY lol{k} "{("&lol" + str(k - 1) + ";") * 10 if k > 1 else "&lol;" * 10}">'
            for k in range(1, 10)
        )
        + "]>\n<DicoAppuisFlottant><OneAppuisDAF><NamePt>&lol9;</NamePt></OneAppuisDAF>"
        + "</DicoAppuisFlottant>\n"
    )
    with pytest.raises(FormatError, match="document type declarations and entities are refused"):
        read_micmac(f)


def _same(a, b) -> bool:
    """Deep equality of exchange blocks (arrays compared with NaN equal to NaN)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is not None and b is not None and np.array_equal(a, b, equal_nan=True)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(
            _same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__
        )
    return a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b))


def test_writers_leave_the_block_as_it_was(tmp_path):
    import copy

    b = sim_block(2, 3, points_per_image=20, seed=5)
    b.cameras[0].radial_mm, b.cameras[0].radial_um = (0.0, 100.0, 160.0), (0.0, 3.0, -2.0)
    ref = copy.deepcopy(b)
    write_patb(b, tmp_path / "p")
    write_bluh(b, tmp_path / "b")
    write_colmap(b, tmp_path / "c", distortion="undistort")
    write_odm(b, tmp_path / "gcp_list.txt")
    write_micmac(b, tmp_path / "m")
    assert _same(b, ref)
    changed = copy.deepcopy(ref)
    changed.points[3].sigma[2] = -1.0
    assert not _same(changed, ref)  # the comparison does see a change


def test_a_file_of_millions_of_lines_is_refused_not_swallowed(tmp_path):
    """What a reader keeps per line is bounded by MAX_LINES (2 000 000 lines), and a
    file of newlines is refused at the line past it, not read into a list first."""
    from apygis.formats._records import MAX_LINES

    f = tmp_path / "many.im"
    f.write_bytes(b"7\n" + b"\n" * MAX_LINES)
    with pytest.raises(
        FormatError, match=rf"many\.im: line {MAX_LINES + 1}: more than {MAX_LINES} lines"
    ):
        read_patb(f)
