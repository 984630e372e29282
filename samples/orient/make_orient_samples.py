"""Make the orientation samples (deterministic: same bytes every run).

A simulated APY set-up in Swiss LV95 (EPSG:2056):

* map sheet ZH1091 at 1:5000 on the digitiser tablet (5 m per tablet mm,
  turned by 0.4 gon, 0.15 % paper shrinkage in y: an affine map transform);
* a stereo pair of photos 4711 (left stage) and 4712 (right stage) at about
  1:15000, principal distance c = 153 mm, flying height about 2300 m over a
  hilly synthetic terrain of about 430-620 m, base 1380 m (60 % overlap);
  the optics turn the photo image by half a turn, so kappa is about pi
  (200 gon) and the map-to-photo scale factors sx, sy are positive;
* 8 control spots 201-208 in the standard orientation areas (X, Y, Z) and
  the 4 corner crosses 9001-9004 of the sheet (planimetric only);
* map measurements: each point digitised twice (tablet noise 0.04 mm, map
  drawing error 0.05 mm);
* photo measurements: the plate shifts px, py at which the parallax vanished
  at each control spot, with 4 um pointing noise;
* the photo file gives the scale factors from the stage calibration as known
  values (sx=, sy=) and rough approximations of the projection centres
  (Xo~, Yo~, Zo~).

Files written (OUTDIR defaults to this script's folder):

===================================== ==================================================
``ZH1091-control.txt``                control points (docs/formats/orient-control.md)
``ZH1091-map.txt``                    map measurements (orient-map-measurements.md)
``ZH1091-photos.txt``                 photo file (orient-photos.md)
``ZH1091-photo-measurements.txt``     parallaxes (orient-photo-measurements.md)
``ZH1091-truth.orientation.json``     the true orientation (orientation.md)
===================================== ==================================================

Run: ``python samples/orient/make_orient_samples.py [OUTDIR]``
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation
from apygis.orient.io import Orientation, save_orientation
from apygis.orient.photo import PhotoOrientation
from apygis.orient.transforms import AffineTransform

SEED = 4711
E0, N0 = 2_683_000.0, 1_247_000.0  # lower-left corner of the sheet
WIDTH, HEIGHT = 2400.0, 1600.0
FOCAL_MM = 153.0
TABLET_SIGMA_MM = 0.04
DRAWING_SIGMA_MM = 0.05
PARALLAX_SIGMA_MM = 0.004
GON = math.pi / 200.0


def terrain(e, n):
    """Synthetic terrain height in metres (a valley to the south, a ridge to the north-west)."""
    x = (np.asarray(e, dtype=float) - E0) / WIDTH
    y = (np.asarray(n, dtype=float) - N0) / HEIGHT
    return 430.0 + 120.0 * y**2 + 40.0 * np.sin(2.5 * x + 0.5) * np.cos(1.7 * y) - 25.0 * x * y


def map_transform() -> AffineTransform:
    """The true tablet -> ground transform: sheet corner at tablet (60, 50) mm."""
    scale = 5.0
    rot = 0.4 * GON
    shrink_y = 1.0015  # the paper shrank: more ground per tablet mm in y
    c, s = math.cos(rot), math.sin(rot)
    a, b = scale * c, -scale * s * shrink_y
    d, e = scale * s, scale * c * shrink_y
    t0 = np.array([60.0, 50.0])
    return AffineTransform(a, b, E0 - (a * t0[0] + b * t0[1]), d, e, N0 - (d * t0[0] + e * t0[1]))


def truth():
    """The true photo orientations (left, right) and the ground points."""
    io = InteriorOrientation(FOCAL_MM)
    xm, ym = E0 + WIDTH / 2, N0 + HEIGHT / 2
    zo = 2750.0
    # stage calibration result: rho = 1/3 (1:5000 map, 1:15000 photo) times 1.003 (zoom)
    s = round(1.003 / 3.0 / 5.0, 7)
    left = PhotoOrientation(
        "4711",
        io,
        ExteriorOrientation(
            xm - 690.0 + 14.2,
            ym - 22.7,
            zo + 8.4,
            0.21 * GON,
            -0.33 * GON,
            200.65 * GON - 2 * math.pi,
        ),
        s,
        round(s / 1.0015, 7),
    )
    right = PhotoOrientation(
        "4712",
        io,
        ExteriorOrientation(
            xm + 690.0 - 9.8, ym + 17.5, zo - 5.1, -0.18 * GON, 0.27 * GON, 199.48 * GON
        ),
        s,
        round(s / 1.0015, 7),
    )
    spots = []
    for dx, dy in ((-700, 700), (-700, 0), (-700, -700), (700, 700), (700, 0), (700, -700),
                   (0, 650), (0, -650)):  # fmt: skip
        spots.append((xm + dx, ym + dy))
    rng = np.random.default_rng(SEED)
    spots = np.round(np.array(spots) + rng.uniform(-60, 60, (len(spots), 2)), 2)
    Z = np.round(terrain(spots[:, 0], spots[:, 1]), 2)
    ground = np.column_stack([spots, Z])
    corners = np.array([[E0, N0], [E0 + WIDTH, N0], [E0 + WIDTH, N0 + HEIGHT], [E0, N0 + HEIGHT]])
    return left, right, ground, corners, rng


def make(outdir: Path) -> None:
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    left, right, ground, corners, rng = truth()
    T = map_transform()
    spot_ids = [str(201 + k) for k in range(len(ground))]
    corner_ids = [str(9001 + k) for k in range(4)]

    lines = [
        "# apygis control points, map sheet ZH1091 (1:5000), LV95 / LN02, metres",
        "# made by samples/orient/make_orient_samples.py; format: docs/formats/orient-control.md",
        "# ID  X(east)  Y(north)  Z  ('-': no height)",
    ]
    for pid, (X, Y) in zip(corner_ids, corners, strict=True):
        lines.append(f"{pid:>5} {X:12.3f} {Y:12.3f}        -")
    for pid, (X, Y, Z) in zip(spot_ids, ground, strict=True):
        lines.append(f"{pid:>5} {X:12.3f} {Y:12.3f} {Z:8.3f}")
    (outdir / "ZH1091-control.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")

    # map measurements: corners and four spots, each twice
    lines = [
        "# apygis map measurements, sheet ZH1091 on the tablet, tablet millimetres",
        "# made by samples/orient/make_orient_samples.py",
        "# format: docs/formats/orient-map-measurements.md",
        "# ID  x_mm  y_mm   (each point measured twice)",
    ]
    pts = [(pid, xy) for pid, xy in zip(corner_ids, corners, strict=True)]
    pts += [(spot_ids[k], ground[k, :2]) for k in (0, 2, 3, 5)]
    for pid, XY in pts:
        drawn = T.inverse(XY) + rng.normal(0.0, DRAWING_SIGMA_MM, 2)
        for _ in range(2):
            t = drawn + rng.normal(0.0, TABLET_SIGMA_MM, 2)
            lines.append(f"{pid:>5} {t[0]:9.3f} {t[1]:9.3f}")
    (outdir / "ZH1091-map.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")

    # photo file: known scale factors, approximate centres
    lines = [
        "# apygis photo file: PHOTO_ID FOCAL_MM frame|scanned [KEY=VALUE | KEY~VALUE ...]",
        "# KEY=VALUE: known (kept fixed), KEY~VALUE: approximate (solved for)",
        "# made by samples/orient/make_orient_samples.py; format: docs/formats/orient-photos.md",
        "# sx, sy from the stage calibration (photo mm per ground m); centres marked on the map",
    ]
    for po in (left, right):
        e = po.exterior
        lines.append(
            f"{po.photo_id} {FOCAL_MM:.3f} frame "
            f"Xo~{round(e.Xo, -1):.0f} Yo~{round(e.Yo, -1):.0f} Zo~{round(e.Zo, -2):.0f} "
            f"kappa_gon~200 sx={po.sx_mm_per_m:.7f} sy={po.sy_mm_per_m:.7f}"
        )
    (outdir / "ZH1091-photos.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")

    lines = [
        "# apygis photo measurements: plate shifts at zero parallax, photo millimetres",
        "# made by samples/orient/make_orient_samples.py",
        "# format: docs/formats/orient-photo-measurements.md",
        "# POINT_ID  PHOTO_ID  px_mm  py_mm",
    ]
    for po in (left, right):
        p = po.parallax(ground) + rng.normal(0.0, PARALLAX_SIGMA_MM, (len(ground), 2))
        for pid, (px, py) in zip(spot_ids, p, strict=True):
            lines.append(f"{pid:>5} {po.photo_id} {px:9.4f} {py:9.4f}")
    (outdir / "ZH1091-photo-measurements.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")

    save_orientation(
        Orientation(
            map_id="ZH1091",
            map_transform=T,
            photos=(left, right),
            quality={"note": "the truth the samples were simulated from"},
        ),
        outdir / "ZH1091-truth.orientation.json",
    )


if __name__ == "__main__":
    make(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent)
