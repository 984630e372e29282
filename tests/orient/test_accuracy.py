"""The APY accuracy claims, in a simulation with APY-like pointing noise.

The seed claims "about 0.1 mm rmse at compilation scale" and "a height
accuracy of 0.02 % of the flying height". Simulated set-up (five seeded
repetitions, each must meet both claims):

* map: compilation scale 1:5000 on the tablet, affine map transform (0.4 gon
  turn, 0.15 % paper shrinkage); 8 map control points drawn with 0.05 mm
  error and digitised twice with 0.04 mm tablet noise; 200 details as drawn
  on the map digitised once (compared with their drawn position: the
  instrument's error, not the map's);
* photos: a stereo pair at 1:15000, c = 153 mm, flying height H = 2295 m,
  base 1380 m, over a hilly terrain of about 430-620 m (tests/orient/synth.py);
  the map-to-photo scale factors known from the stage calibration;
* photo orientation: 8 control spots in the standard orientation areas, the
  parallax zeroed with 5 um noise per component (plates stepped at 2 um);
* residual height correction dpZ = Ax + By + Cxy + D fitted on the model
  heights of the control spots;
* compilation: 300 check points on the terrain, each pointed in stereo with
  5 um noise per photo coordinate: the operator sets the mark where the
  superposed photo points (the optical superposition (b) plus the plate
  shifts of the estimated parallax conditions (c)) show the detail in both
  photos; heights corrected by dpZ.

Claims checked: planimetric RMSE in position <= 0.1 mm at 1:5000 (0.5 m),
both for map digitising and for stereo compilation; height RMSE <= 0.02 % of
H (0.459 m).
"""

from __future__ import annotations

import numpy as np
import pytest

from apygis.orient.height import fit_height_correction
from apygis.orient.intersection import intersect
from apygis.orient.photo import approximate_orientation, orient_photo
from apygis.orient.transforms import AffineTransform, fit_map_transform

from . import synth

MAP_SCALE = 5000
PHOTO_SIGMA_MM = 0.005
TABLET_SIGMA_MM = 0.04
DRAWING_SIGMA_MM = 0.05


def _map_transform():
    rot, k, shrink = 0.4 * np.pi / 200, 5.0, 1.0015
    c, s = np.cos(rot), np.sin(rot)
    return AffineTransform(k * c, -k * s * shrink, 2682700.0, k * s, k * c * shrink, 1246750.0)


def _simulate(seed: int):
    rng = np.random.default_rng(seed)
    # --- map orientation
    T = _map_transform()
    corners = np.array(
        [[60, 50], [540, 47], [542, 367], [62, 369], [155, 341], [160, 70], [450, 340], [445, 75.0]]
    )
    ctrl = {str(k): tuple(T.forward(t)) for k, t in enumerate(corners)}
    drawn = corners + rng.normal(0, DRAWING_SIGMA_MM, corners.shape)
    meas = np.repeat(drawn, 2, axis=0) + rng.normal(0, TABLET_SIGMA_MM, (16, 2))
    fit = fit_map_transform([str(k) for k in range(8) for _ in range(2)], meas, ctrl, "affine")
    # check details as drawn on the map, digitised once (the instrument's error, not the map's)
    check_t = rng.uniform([70, 60], [530, 360], (200, 2))
    digitised = check_t + rng.normal(0, TABLET_SIGMA_MM, check_t.shape)
    dmap = fit.transform.forward(digitised) - T.forward(check_t)
    map_rmse_mm = np.sqrt((dmap**2).sum(axis=1).mean()) / MAP_SCALE * 1000

    # --- photo orientation
    left, right = synth.pair()
    spots = synth.control_spots(8, rng)
    oriented = []
    for true in (left, right):
        P = true.parallax(spots) + rng.normal(0, PHOTO_SIGMA_MM, (8, 2))
        e = true.exterior
        approx, _ = approximate_orientation(
            true.photo_id,
            true.interior,
            centre_xy=(round(e.Xo, -2), round(e.Yo, -2)),
            mean_height=float(spots[:, 2].mean()),
            scale_number=15000.0,
            sx_mm_per_m=true.sx_mm_per_m,
            sy_mm_per_m=true.sy_mm_per_m,
        )
        oriented.append(orient_photo(spots, P, approx, fixed={"sx", "sy"}).orientation)

    # The operator moves the mark until the floating mark sits on the detail in
    # both photos. At mark G the optics show the photo point of the physical
    # superposition (b), placed with the true stage offset, plus the plate shift
    # of the estimated parallax function: x0 - s (X - Xo_true) + p_est(G), which
    # is the estimated collinearity x_est(G) + s (Xo_true - Xo_est). The compiled
    # point is therefore the intersection of the estimated rays with the images
    # of the detail (plus stereo pointing noise) offset by -s (Xo_true - Xo_est).
    offsets = np.stack(
        [
            [
                t.sx_mm_per_m * (t.exterior.Xo - o.exterior.Xo),
                t.sy_mm_per_m * (t.exterior.Yo - o.exterior.Yo),
            ]
            for t, o in zip((left, right), oriented, strict=True)
        ]
    )[:, None, :]

    def stereo(G):
        obs = np.stack([left.photo(G), right.photo(G)]) + rng.normal(
            0, PHOTO_SIGMA_MM, (2, len(G), 2)
        )
        return intersect(oriented, obs - offsets).points

    # --- residual height correction on the control spots
    model = stereo(spots)
    hc = fit_height_correction(spots[:, :2], spots[:, 2] - model[:, 2]).correction

    # --- compilation of check points
    G = synth.model_points(300, rng)
    M = stereo(G)
    Z = hc.correct(M[:, 0], M[:, 1], M[:, 2])
    xy_rmse_mm = np.sqrt(((M[:, :2] - G[:, :2]) ** 2).sum(axis=1).mean()) / MAP_SCALE * 1000
    z_rmse = np.sqrt(np.mean((Z - G[:, 2]) ** 2))
    return map_rmse_mm, xy_rmse_mm, z_rmse


@pytest.mark.parametrize("seed", range(5))
def test_apy_accuracy_claims(seed):
    map_rmse_mm, xy_rmse_mm, z_rmse = _simulate(seed)
    assert map_rmse_mm <= 0.1, f"map digitising: {map_rmse_mm:.3f} mm at 1:5000"
    assert xy_rmse_mm <= 0.1, f"stereo planimetry: {xy_rmse_mm:.3f} mm at 1:5000"
    assert z_rmse <= 0.0002 * synth.H, f"heights: {z_rmse:.3f} m = {z_rmse / synth.H:.4%} of H"
