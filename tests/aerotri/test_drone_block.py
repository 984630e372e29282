"""A real drone block: 17 DJI images with GPS in EXIF and no control (../shared/external).

There is no truth here, so the tie points are judged by their consistency: every
image is tied, the measurements agree with the pairs' relative orientations to a
fraction of a pixel, and the camera's yaw against the flight is found the same for
all images (one camera mounting for the whole flight).
"""

from __future__ import annotations

import numpy as np
import pytest

from apygis.aerotri.block import Block
from apygis.aerotri.match import MatchOptions, match_block
from apygis.aerotri.project import block_plan, init_block
from tests.conftest import EXTERNAL

TOLEDO = EXTERNAL / "aerial" / "toledo-drone" / "images"


@pytest.mark.external
def test_drone_block_from_exif_alone(tmp_path):
    blk = tmp_path / "toledo.block"
    r = init_block(blk, camera="exif", images=TOLEDO)
    assert (r.images, r.strips, r.crs) == (17, 4, "EPSG:32617")
    with Block.open(blk) as b:
        cam = b.cameras()[1]
        # 3.61 mm at 2.6 um: f ~ 1390 px for the 2400 x 1800 rasters (the README's figure)
        assert abs(cam.focal_mm / (cam.pixel_um / 1000) - 1390) < 15
        report = match_block(b, MatchOptions(scheduler="sync", points_per_image=3000))
        per_image = dict(b.conn.execute("SELECT image, COUNT(*) FROM observations GROUP BY image"))
        azimuths = [im.x_azimuth_deg for im in b.images()]
        # the flight direction of each image: its strip's line of centres
        headings = [block_plan(b).headings[im.image] for im in b.images()]
    assert set(per_image) == set(range(1, 18))
    assert min(per_image.values()) >= 200
    assert report.epipolar_rms_px is not None
    # the lens's distortion is unknown (no calibration; principal point at the centre):
    # what the relative orientations cannot absorb of it stays in the residual, so the
    # bound is one pixel, not the ~0.1 px of the distortion-free synthetic blocks
    assert report.epipolar_rms_px < 1.0, report.epipolar_rms_px
    # the camera's yaw against the course is the same (within a few degrees) for every image
    off = (np.array(azimuths) - np.array(headings) + 180.0) % 360.0 - 180.0
    spread = np.degrees(np.abs(np.angle(np.exp(1j * np.radians(off - off[0])))))
    assert spread.max() < 20.0, off
    assert sum(v for k, v in report.multiplicity.items() if k >= 3) > report.points / 2
