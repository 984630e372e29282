"""Tests of apygis.aerotri.plan against synthetic blocks of known geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from apygis.aerotri.plan import (
    Frame,
    PlanImage,
    derive_headings,
    footprint,
    gap_report,
    gruber_regions,
    plan_block,
    plan_text,
    strips_from_track,
)
from apygis.errors import OrientationError
from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation, ground_to_photo

FRAME = Frame(153.0)  # film, 230 x 230 mm
TERRAIN = 500.0
Z = TERRAIN + 1530.0  # image scale 1:10000 -> footprint side L = 2300 m
L = 2300.0


def regular_block(
    n_strips=3, n_images=6, p=0.6, q=0.3, sigma=0.0, seed=0, alternate=True, headings=False
):
    """Strips along east, numbered south to north; alternate=True: even strips fly west.

    Image numbers follow the flight (so derived headings are the flight's).
    """
    rng = np.random.default_rng(seed)
    B, A = (1 - p) * L, (1 - q) * L
    out, n = [], 1
    for s in range(n_strips):
        west = alternate and s % 2 == 1
        for k in range(n_images):
            x = (n_images - 1 - k) * B if west else k * B
            dx, dy = rng.normal(0.0, sigma, 2)
            h = (270.0 if west else 90.0) if headings else None
            out.append(PlanImage(n, s + 1, 10_000 + x + dx, 50_000 + s * A + dy, Z, h))
            n += 1
    return out


# --- footprints ---------------------------------------------------------------------------


@pytest.mark.parametrize("heading", [0.0, 37.0, 90.0, 200.0, 270.0, 333.3])
def test_footprint_corners_project_back_to_the_frame_corners(heading):
    frame = Frame(35.0, 36.0, 24.0)  # non-square: x (36 mm) along the flight
    img = PlanImage(1, 1, 1000.0, 2000.0, 900.0, heading)
    fp = footprint(img, frame, 100.0)
    eo = ExteriorOrientation(1000.0, 2000.0, 900.0, 0.0, 0.0, math.radians(90.0 - heading))
    g = np.asarray(fp.exterior.coords)[:4]
    photo = ground_to_photo(np.column_stack([g, np.full(4, 100.0)]), eo, InteriorOrientation(35.0))
    np.testing.assert_allclose(
        photo, [(-18, -12), (18, -12), (18, 12), (-18, 12)], atol=1e-9
    )  # exact inverse up to rounding
    # the long side (36 mm * m, m = 800 / 35) lies along the flight azimuth
    m = 800.0 / 35.0
    side = g[1] - g[0]
    assert np.hypot(*side) == pytest.approx(36.0 * m)
    az = math.degrees(math.atan2(side[0], side[1])) % 360
    assert min(abs(az - heading) % 360, 360 - abs(az - heading) % 360) < 1e-9
    assert fp.area == pytest.approx(36.0 * 24.0 * m * m)


def test_footprint_needs_heading_and_height():
    with pytest.raises(OrientationError, match="no heading"):
        footprint(PlanImage(1, 1, 0.0, 0.0, 1000.0), FRAME, 0.0)
    with pytest.raises(OrientationError, match="not above"):
        footprint(PlanImage(1, 1, 0.0, 0.0, 100.0, 90.0), FRAME, 200.0)


# --- the regular block ------------------------------------------------------------------


def test_regular_block_overlaps_pairs_and_directions():
    # Centres with sigma = 5 m noise: a pair's overlap changes by about
    # sigma * sqrt(2) / L = 0.3 %, a strip mean of 5 pairs by less; 2 % is over 6 sigma.
    imgs = regular_block(sigma=5.0, seed=3)
    plan = plan_block(imgs, FRAME, TERRAIN)
    assert set(plan.strips) == {1, 2, 3}
    for s, st in plan.strips.items():
        assert st.kind == "normal"
        assert plan.overlaps.forward[s] == pytest.approx(0.60, abs=0.02)
        # alternating flight directions; images ordered along the flight
        assert st.direction_deg == pytest.approx(270.0 if s == 2 else 90.0, abs=1.0)
        assert st.images == list(range(6 * s - 5, 6 * s + 1))
    assert set(plan.overlaps.side) == {(1, 2), (2, 3)}
    for q in plan.overlaps.side.values():
        assert q == pytest.approx(0.30, abs=0.02)
    strip_of = {im.image: im.strip for im in imgs}
    in_strip = [p for p in plan.pairs if p.kind == "strip"]
    cross = [p for p in plan.pairs if p.kind == "cross"]
    for s in (1, 2, 3):
        mine = [p for p in in_strip if strip_of[p.a] == s]
        steps = sorted(abs(p.b - p.a) for p in mine)
        assert steps == [1] * 5 + [2] * 4  # neighbours + second neighbours (20 % >= 10 %)
        for p in mine:
            assert p.overlap == pytest.approx(0.6 if p.b - p.a == 1 else 0.2, abs=0.02)
    assert all(p.a < p.b for p in plan.pairs)
    # across strips: only neighbouring strips, same position (30 %) and diagonal (18 %)
    assert {abs(strip_of[p.a] - strip_of[p.b]) for p in cross} == {1}
    assert len(cross) == 2 * (6 + 2 * 5)
    assert all(p.overlap >= 0.1 for p in cross)
    assert plan.connected == [list(range(1, 19))]
    assert plan.main_direction_deg == pytest.approx(90.0, abs=1.0)


def test_given_headings_match_derived():
    a = plan_block(regular_block(headings=True), FRAME, TERRAIN)
    b = plan_block(regular_block(headings=False), FRAME, TERRAIN)
    assert a.headings == pytest.approx(b.headings)
    assert [(p.a, p.b, p.kind) for p in a.pairs] == [(p.a, p.b, p.kind) for p in b.pairs]


def test_cross_strip_is_classified_and_paired():
    imgs = regular_block()
    B, A = 0.4 * L, 0.7 * L
    imgs += [PlanImage(100 + k, 9, 10_000 + 2.5 * B, 50_000 - 0.5 * A + k * B, Z) for k in range(5)]
    plan = plan_block(imgs, FRAME, TERRAIN)
    assert plan.strips[9].kind == "cross"
    assert plan.strips[9].direction_deg == pytest.approx(0.0, abs=1e-6)
    assert all(plan.strips[s].kind == "normal" for s in (1, 2, 3))
    assert any(p.kind == "cross" and 100 in (p.a, p.b) for p in plan.pairs)
    # a cross strip does not take part in side overlaps
    assert set(plan.overlaps.side) == {(1, 2), (2, 3)}


def test_subblocks_share_one_strip():
    plan = plan_block(regular_block(n_strips=4, n_images=3), FRAME, TERRAIN, subblock_strips=2)
    assert plan.subblocks == [[1, 2], [2, 3], [3, 4]]
    plan = plan_block(regular_block(n_strips=6, n_images=3), FRAME, TERRAIN, subblock_strips=3)
    assert plan.subblocks == [[1, 2, 3], [3, 4, 5], [4, 5, 6]]
    for a, b in zip(plan.subblocks[:-1], plan.subblocks[1:], strict=True):
        assert set(a) & set(b)
    assert plan_block(regular_block(), FRAME, TERRAIN).subblocks == [[1, 2, 3]]
    with pytest.raises(OrientationError, match="subblock_strips"):
        plan_block(regular_block(), FRAME, TERRAIN, subblock_strips=1)


def test_disconnected_block_is_reported():
    imgs = regular_block(n_strips=1, n_images=3)
    imgs += [PlanImage(10 + k, 5, 90_000 + 900 * k, 50_000, Z) for k in range(3)]
    plan = plan_block(imgs, FRAME, TERRAIN)
    assert plan.connected == [[1, 2, 3], [10, 11, 12]]
    assert "NOT CONNECTED: 2 parts" in plan_text(plan)


def test_thinning_keeps_the_block_connected():
    # drone-like: 80 % forward, 60 % side overlap -> many pairs per image
    imgs = regular_block(n_strips=5, n_images=10, p=0.8, q=0.6)
    full = plan_block(imgs, FRAME, TERRAIN)
    thin = plan_block(imgs, FRAME, TERRAIN, max_pairs_per_image=3)
    deg_full = np.bincount([i for p in full.pairs for i in (p.a, p.b)])
    deg = np.bincount([i for p in thin.pairs for i in (p.a, p.b)])
    assert deg_full.max() > 3
    assert len(thin.connected) == 1 == len(full.connected)
    # at most 3 per image, except where the spanning forest needs one more
    assert deg.max() <= 4
    assert np.mean(deg[1:] <= 3) > 0.9
    kept = {(p.a, p.b) for p in thin.pairs}
    assert kept <= {(p.a, p.b) for p in full.pairs}


# --- headings and tracks ------------------------------------------------------------------


def test_derive_headings():
    imgs = [
        PlanImage(1, 1, 0.0, 0.0, Z),
        PlanImage(2, 1, 100.0, 100.0, Z),
        PlanImage(3, 1, 200.0, 200.0, Z),
        PlanImage(4, 2, 200.0, 0.0, Z, 123.0),  # given: kept
        PlanImage(5, 2, 100.0, -100.0, Z),  # strip 2 flies south-west (numbers in order)
        PlanImage(6, 2, 0.0, -200.0, Z),
        PlanImage(7, 3, 500.0, 500.0, Z),  # single image: the main direction
        PlanImage(8, 1, 300.0, 300.0, Z),
    ]
    h = derive_headings(imgs)
    assert h[1] == pytest.approx(45.0)
    assert h[8] == pytest.approx(45.0)
    assert h[4] == 123.0
    assert h[5] == pytest.approx(225.0)
    assert h[7] == pytest.approx(45.0)  # strip 1 has more images than strip 2


def zigzag(n_lines=3, n_per=5, step=100.0, spacing=300.0):
    pts = []
    for s in range(n_lines):
        xs = [k * step for k in range(n_per)]
        if s % 2:
            xs = xs[::-1]
        pts += [(x, s * spacing) for x in xs]
    return [PlanImage(i + 1, 0, x, y, Z) for i, (x, y) in enumerate(pts)]


def test_strips_from_track_zigzag():
    lines = strips_from_track(zigzag())
    assert lines == {i: (i - 1) // 5 + 1 for i in range(1, 16)}


def test_strips_from_track_gradual_and_turn_image():
    # a V-turn without connecting leg: the corner image joins the line its heading is closer to
    pts = [(k * 100.0, 0.0) for k in range(5)] + [(400.0 - k * 70.7, k * 70.7) for k in range(1, 5)]
    imgs = [PlanImage(i + 1, 0, x, y, Z) for i, (x, y) in enumerate(pts)]
    assert strips_from_track(imgs) == {i: 1 if i <= 5 else 2 for i in range(1, 10)}
    h2 = (math.degrees(math.atan2(-1.0, 1.0)) + 360) % 360  # second line's azimuth: 315
    imgs[4] = PlanImage(5, 0, 400.0, 0.0, Z, h2)
    assert strips_from_track(imgs) == {i: 1 if i <= 4 else 2 for i in range(1, 10)}
    # small wiggles (< 30 degrees) do not split a line
    wig = [PlanImage(i + 1, 0, i * 100.0, 20.0 * (i % 2), Z) for i in range(8)]
    assert set(strips_from_track(wig).values()) == {1}


# --- von Gruber regions and gaps -------------------------------------------------------------


def test_gruber_regions_in_model_at_nadirs():
    plan = plan_block(regular_block(), FRAME, TERRAIN)
    pair = plan.pair(2, 3)
    regions = gruber_regions(plan, pair)
    model = plan.footprints[2].intersection(plan.footprints[3])
    assert len(regions) == 6
    grown = model.buffer(1e-6)
    for r in regions:
        assert r.area > 0.03 * model.area
        assert grown.contains(r)
    na = np.array([plan.images[2].X, plan.images[2].Y])
    nb = np.array([plan.images[3].X, plan.images[3].Y])
    from shapely.geometry import Point

    assert regions[1].contains(Point(*na))
    assert regions[4].contains(Point(*nb))
    # columns: a's regions are at a's nadir along the base (x), b's at b's
    for k in range(3):
        assert abs(regions[k].centroid.x - na[0]) < abs(regions[k].centroid.x - nb[0])
        assert abs(regions[3 + k].centroid.x - nb[0]) < abs(regions[3 + k].centroid.x - na[0])
    # rows: top and bottom touch the model's edges across the base, centre in the middle
    _x0, y0, _x1, y1 = model.bounds
    assert regions[0].bounds[3] == pytest.approx(y1)
    assert regions[2].bounds[1] == pytest.approx(y0)
    assert regions[1].centroid.y == pytest.approx((y0 + y1) / 2)
    # a pair across strips (nadirs outside the model): regions still inside the model
    cross = plan.pair(2, 11)
    model = plan.footprints[2].intersection(plan.footprints[11])
    rc = gruber_regions(plan, cross)
    assert all(model.buffer(1e-6).contains(r) and r.area > 0 for r in rc)
    with pytest.raises(OrientationError, match="do not overlap"):
        gruber_regions(plan, (1, 18))


def test_gap_report_counts():
    plan = plan_block(regular_block(), FRAME, TERRAIN)
    regions = gruber_regions(plan, (2, 3))
    rng = np.random.default_rng(7)
    counts = [5, 0, 3, 2, 9, 1]
    pts = []
    for r, n in zip(regions, counts, strict=True):
        x0, y0, x1, y1 = r.bounds
        # inside the region: uniform within its bounds shrunk by 1 m (regions are rectangles)
        pts.append(
            np.column_stack([rng.uniform(x0 + 1, x1 - 1, n), rng.uniform(y0 + 1, y1 - 1, n)])
        )
    model = plan.footprints[2].intersection(plan.footprints[3])
    # plus points in the model outside all regions (between the rows): counted nowhere
    cx = model.centroid.x
    y_between = (regions[0].bounds[1] + regions[1].bounds[3]) / 2
    pts.append(np.array([[cx, y_between]] * 4))
    rep = gap_report(plan, (3, 2), np.vstack(pts), min_points=3)
    assert rep.counts == counts
    assert rep.gaps == [1, 3, 5]
    assert gap_report(plan, (2, 3), np.empty((0, 2))).gaps == list(range(6))


def test_plan_text_lists_the_block():
    plan = plan_block(regular_block(), FRAME, TERRAIN, subblock_strips=2)
    ppp = {(p.a, p.b): 40 for p in plan.pairs}
    txt = plan_text(plan, points_per_pair=ppp, gaps={(1, 2): [1, 4]})
    assert "strip 2: normal, heading 270.0 deg, 6 images (7-12), forward overlap 60%" in txt
    assert "strips 1-2: 30%" in txt
    assert "subblock 2: strips 2, 3 (12 images)" in txt
    assert "1-2 (strip, overlap 60%): 40 points; gaps a-centre, b-centre" in txt
    assert "connected: yes" in txt
