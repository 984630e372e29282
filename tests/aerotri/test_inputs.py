"""Block inputs: image lists, control points, cameras, EXIF; errors name file and line."""

from __future__ import annotations

import math

import pytest

from apygis.aerotri.camera import Camera, read_camera
from apygis.aerotri.inputs import read_control, read_exif, read_image_list, utm_crs
from apygis.aerotri.project import camera_from_exif
from apygis.errors import FormatError
from tests.conftest import EXTERNAL

TOLEDO = EXTERNAL / "aerial" / "toledo-drone"


def test_image_list(tmp_path):
    p = tmp_path / "images.csv"
    p.write_text(
        "# a comment\n"
        "image,strip,file,X,Y,Z,heading_deg\n"
        "101,1,a.tif,10.5,20,1500,90\n"
        "102,1,sub/b.tif,,,,\n"
        "103,2,c.tif,exif,exif,exif,\n"
    )
    a, b, c = read_image_list(p)
    assert (a.image, a.strip, a.X, a.Y, a.Z, a.heading_deg) == (101, 1, 10.5, 20.0, 1500.0, 90.0)
    assert a.path == tmp_path / "a.tif"
    assert b.X is None
    assert b.heading_deg is None
    assert b.path == tmp_path / "sub" / "b.tif"
    assert c.from_exif
    assert c.X is None


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("image,strip,file\n0,1,a.tif\n", "line 2: image 0 must be at least 1"),
        ("image,strip,file\n1,1,a.tif\n1,1,b.tif\n", "line 3: image 1 is listed twice"),
        ("image,strip,file,X,Y,Z\n1,1,a.tif,nan,2,3\n", "line 2: X 'nan' is not a finite"),
        ("image,strip,file,X,Y,Z\n1,1,a.tif,x1,2,3\n", "line 2: X 'x1' is not a number"),
        ("image,strip,file,X,Y,Z\n1,1,a.tif,1,,3\n", "line 2: X and Y must both"),
        ("image,strip,file,X,Y,Z\n1,1,a.tif,exif,1,2\n", "line 2: X, Y and Z must all be 'exif'"),
        ("img,strip,file\n", "line 1: header"),
        ("image,strip,file\n", "no images"),
        ("", "empty"),
        ("image,strip,file\n1,1,\n", "line 2: file is empty"),
        ("image,strip,file\n1,1,a.tif,extra\n", "line 2: 4 fields"),
    ],
)
def test_image_list_errors(tmp_path, body, message):
    p = tmp_path / "images.csv"
    p.write_text(body)
    with pytest.raises(FormatError, match=message) as e:
        read_image_list(p)
    assert str(p) in str(e.value)


def test_control(tmp_path):
    p = tmp_path / "control.csv"
    p.write_text(
        "name,X,Y,Z,sigma_xy_m,sigma_z_m,kind\n"
        "G1,100,200,300,0.02,0.03,full\n"
        "G2,100,200,,0.02,,planimetric\n"
        "K1,1,2,3,,,check\n"
    )
    g1, g2, k1 = read_control(p)
    assert (g1.name, g1.Z, g1.sigma_xy_m, g1.kind) == ("G1", 300.0, 0.02, "full")
    assert g2.Z is None
    assert k1.kind == "check"
    p.write_text("name,X,Y,Z,sigma_xy_m,sigma_z_m,kind\nG1,1,2,3,,,gcp\n")
    with pytest.raises(FormatError, match="line 2: kind 'gcp'"):
        read_control(p)
    p.write_text("name,X,Y,Z\nG1,1,2,\n")
    with pytest.raises(FormatError, match="line 2: Z is empty"):
        read_control(p)
    p.write_text("name,X,Y,Z,sigma_xy_m\nG1,1,2,3,-1\n")
    with pytest.raises(FormatError, match="line 2: sigma_xy_m"):
        read_control(p)


def test_camera_file_roundtrip_and_errors(tmp_path):
    cam = Camera(
        "RC30", "film", 153.124, 0.002, -0.004,
        fiducials={"1": (-106.0, 106.0), "2": (106.0, 106.0), "3": (106.0, -106.0)},
        orientation_mark_mm=(-12.0, 110.0),
        distortion_radius_mm=(0.0, 50.0, 100.0), distortion_dr_um=(0.0, 2.0, -1.0),
    )  # fmt: skip
    p = tmp_path / "cam.toml"
    p.write_text(cam.to_toml())
    assert read_camera(p) == cam
    p.write_text('name = "x"\nfocal_mm = "long"\n')
    with pytest.raises(FormatError, match="focal_mm must be a finite number"):
        read_camera(p)
    p.write_text('name = "x"\nfocal_mm = 153\nfocl = 1\n')
    with pytest.raises(FormatError, match="unknown key 'focl'"):
        read_camera(p)
    p.write_text("name = \n")
    with pytest.raises(FormatError, match="not a camera file"):
        read_camera(p)
    p.write_text('kind = "digital"\nfocal_mm = 50\n')
    with pytest.raises(FormatError, match="needs pixel_um and sensor_px"):
        read_camera(p)


def test_camera_from_exif_pixel_pitch():
    # DJI FC350 resampled to 2400 x 1800: f = 3.61 mm, 35 mm equivalent 20 mm -> ~1390 px
    cam = camera_from_exif(3.61, 20.0, 2400, 1800, "DJI FC350")
    f_px = cam.focal_mm / (cam.pixel_um / 1000)
    assert math.isclose(f_px, 1388.0, rel_tol=0.01)


def test_utm_zone():
    assert utm_crs(-83.7, 41.5) == "EPSG:32617"
    assert utm_crs(7.4, 46.9) == "EPSG:32632"
    assert utm_crs(151.2, -33.9) == "EPSG:32756"


@pytest.mark.external
def test_exif_of_a_real_drone_image():
    e = read_exif(TOLEDO / "images" / "DJI_0061.JPG")
    assert math.isclose(e.lat, 41.54859617, abs_tol=1e-7)
    assert math.isclose(e.lon, -83.69864878, abs_tol=1e-7)  # W is negative
    assert math.isclose(e.alt_m, 119.7)
    assert (e.focal_mm, e.focal_35mm, e.model) == (3.61, 20.0, "FC350")
