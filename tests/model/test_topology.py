"""Chains, branches, validation, closure, AREA, DHI and geometries."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

import apygis
from apygis.errors import TopologyError
from apygis.model import topology as topo
from apygis.model.records import LINE_DTYPE, NO_REF


def _table(rows):
    lp = np.zeros(len(rows), LINE_DTYPE)
    for i, (num, fwd, back, s1, s2) in enumerate(rows):
        lp[i] = (num, float(num), 0.0, 0.0, 1, fwd, back, s1, s2)
    return lp


@settings(max_examples=60, deadline=None)
@given(
    lines=st.lists(st.tuples(st.integers(1, 12), st.booleans()), min_size=0, max_size=25),
    seed=st.integers(0, 2**32 - 1),
)
def test_chains_recover_the_lines_that_were_added(lines, seed):
    lay = apygis.MapFile("T").layer("r")
    expected = []
    for k, (n, closed) in enumerate(lines):
        closed = closed and n >= 3
        pts = [(float(i), float(k), 0.0) for i in range(n)]
        expected.append((tuple(lay.add_line(pts, code=k % 100, closed=closed)), closed))
    # Row order must not matter: shuffle the table.
    lp = lay.line_points.copy()
    np.random.default_rng(seed).shuffle(lp)
    cs = topo.chains(lp)
    got = []
    for k, rows in enumerate(cs):
        nums = tuple(int(v) for v in lp["num"][rows])
        if cs.closed[k]:  # a ring starts anywhere: rotate to its lowest number
            i = nums.index(min(nums))
            nums = nums[i:] + nums[:i]
        got.append((nums, bool(cs.closed[k])))
    assert sorted(got) == sorted(expected)
    assert len(lp) == 0 or sorted(cs.order.tolist()) == list(range(len(lp)))


def test_chains_of_a_long_ring_and_a_long_line():
    lay = apygis.MapFile("T").layer("r")
    ang = np.linspace(0, 2 * math.pi, 5000, endpoint=False)
    ring = lay.add_line(np.column_stack([np.cos(ang), np.sin(ang), 0 * ang]), 1, closed=True)
    line = lay.add_line([(float(i), 5.0, 0.0) for i in range(3000)], 2)
    cs = lay.chains()
    assert len(cs) == 2
    assert cs.closed.tolist() == [True, False]
    assert lay.line_points["num"][cs.rows(0)].tolist() == ring
    assert lay.line_points["num"][cs.rows(1)].tolist() == line


def test_validation_finds_each_kind_of_error():
    lp = _table(
        [
            (1, 2, NO_REF, NO_REF, NO_REF),
            (2, NO_REF, 1, 9, NO_REF),  # side reference to a point that does not exist
            (3, 4, NO_REF, NO_REF, NO_REF),
            (4, NO_REF, NO_REF, NO_REF, NO_REF),  # 3 -> 4 but 4 does not point back
            (5, 5, NO_REF, NO_REF, NO_REF),  # itself
            (6, 7, NO_REF, NO_REF, NO_REF),
            (7, 6, NO_REF, NO_REF, NO_REF),  # a two-point forward cycle
            (8, NO_REF, NO_REF, 1, 1),  # same side twice (and 1 does not know 8)
            (8, NO_REF, NO_REF, NO_REF, NO_REF),  # duplicate number
        ]
    )
    kinds = {(i.kind, i.num) for i in topo.validate_line_points(lp)}
    assert ("dangling-reference", 2) in kinds
    assert ("asymmetric-reference", 3) in kinds
    assert ("self-reference", 5) in kinds
    assert ("short-cycle", 6) in kinds
    assert ("duplicate-side", 8) in kinds
    assert ("duplicate-number", 8) in kinds
    assert ("asymmetric-reference", 8) in kinds
    assert not any(num == 1 for kind, num in kinds if kind != "asymmetric-reference")


def test_validation_accepts_branches_and_rings(sample_map):
    for lay in sample_map:
        assert lay.validate() == [], lay.ext


def test_margin_points_are_free_line_ends_not_branch_ends():
    lay = apygis.MapFile("T").layer("h")
    main = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=31)
    trib = lay.add_line([(10, 10, 0), (10, 5, 0)], code=32)
    lay.join(trib[-1], main[1])
    lay.add_line([(0, 9, 0), (1, 9, 0), (1, 8, 0)], code=35, closed=True)
    assert sorted(lay.margin_points()["num"].tolist()) == sorted([main[0], main[2], trib[0]])


def test_closure_says_where_a_line_is_open():
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (30, 0, 0), (30, 40, 0)], code=21)
    c = lay.closure(n[1])
    assert not c.closed
    assert (c.start, c.end) == (n[0], n[2])
    assert c.gap_m == pytest.approx(50.0)
    assert "not closed between point 3 and point 1 (gap 50.00 m)" in str(c)


def test_area_clockwise_and_counterclockwise():
    lay = apygis.MapFile("T").layer("r")
    # clockwise seen from above: (0,0) -> (0,10) -> (20,10) -> (20,0)
    n = lay.add_line([(0, 0, 0), (0, 10, 0), (20, 10, 0), (20, 0, 0)], code=21, closed=True)
    r = lay.area(n[0], n[1])
    assert (r.area_m2, r.perimeter_m, r.clockwise) == (200.0, 60.0, True)
    assert r.points == tuple(n)
    r = lay.area(n[1], n[0])
    assert (r.area_m2, r.clockwise) == (200.0, False)
    assert r.points == (n[1], n[0], n[3], n[2])


def test_area_is_accurate_far_from_the_origin():
    lay = apygis.MapFile("T").layer("r")
    e, n = 2_684_000.0, 1_247_500.0
    nums = lay.add_line(
        [(e, n, 0), (e, n + 0.1, 0), (e + 0.1, n + 0.1, 0), (e + 0.1, n, 0)], code=21, closed=True
    )
    # The corners themselves are off by up to ulp(2.7e6) = 4.7e-10 m, i.e. 5e-9 of a side;
    # a shoelace sum about the origin would be off by about 1e-3 m2 (10 % of the area).
    assert lay.area(nums[0], nums[1]).area_m2 == pytest.approx(0.01, rel=1e-7)


def test_area_of_open_line_names_the_gap():
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (0, 10, 0), (20, 10, 0), (20, 0, 0)], code=21)
    with pytest.raises(TopologyError, match=r"ends at point 4 .* and at point 1 .*gap 20.00 m"):
        lay.area(n[1], n[2])
    with pytest.raises(TopologyError, match="not neighbours"):
        lay.area(n[0], n[2])


def test_area_of_sample_buildings(sample_map):
    lay = sample_map.layers["r"]
    cs = lay.chains()
    lp = lay.line_points
    polys = lay.geometries()
    for k in np.flatnonzero(cs.closed):
        rows = cs.rows(k)
        a, b = (int(v) for v in lp["num"][rows[:2]])
        r = lay.area(a, b)
        assert r.clockwise  # the sample script digitises buildings clockwise
        assert r.area_m2 == pytest.approx(polys[k].area, rel=1e-9)
        assert 40.0 < r.area_m2 < 260.0


def test_dhi():
    d = topo.dhi((2684000.0, 1247000.0, 420.0), (2684030.0, 1247040.0, 415.0))
    assert d.distance_m == pytest.approx(50.0)
    assert d.dz_m == pytest.approx(-5.0)
    assert d.slope_distance_m == pytest.approx(math.hypot(50, 5))
    assert d.inclination_pct == pytest.approx(-10.0)
    assert d.inclination_deg == pytest.approx(math.degrees(math.atan(-0.1)))
    assert topo.dhi((0, 0, 0), (0, 0, 3)).inclination_pct is None


def test_geometries_are_3d_lines_and_polygons():
    lay = apygis.MapFile("T").layer("r")
    lay.add_line([(0, 0, 1), (10, 0, 2)], code=11)
    lay.add_line([(0, 0, 5), (0, 10, 5), (10, 10, 5)], code=21, closed=True)
    lay.add_line([(7, 7, 7)], code=13)
    g = lay.geometries()
    assert g[0].geom_type == "LineString"
    assert g[0].has_z
    assert shapely.get_coordinates(g[0], include_z=True).tolist() == [[0, 0, 1], [10, 0, 2]]
    assert g[1].geom_type == "Polygon"
    assert g[1].has_z
    assert g[1].area == 50.0
    assert g[2].is_empty


def test_lookup_and_mutual_links_with_missing_numbers():
    lp = _table([(5, 6, NO_REF, NO_REF, NO_REF), (6, NO_REF, 5, NO_REF, NO_REF)])
    succ, pred = topo.mutual_links(lp)
    assert succ.tolist() == [1, -1]
    assert pred.tolist() == [-1, 0]
    assert topo.lookup(lp["num"], np.array([6, 7])).tolist() == [1, -1]


def test_area_refuses_a_loop_closed_by_a_branch_from_any_start():
    # 1 -> 2 -> 3 -> 4, and 4 hangs on 2 as a branch: the loop 2, 3, 4 is no closed line
    # (chains() says so). AREA walked 2, 3, 4 back to 2 and measured it when started at
    # 2, but refused when started at 3: it did not check that the last link back to the
    # first point was mutual (found by the stateful edit test).
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, -10, 0), (0, 0, 0), (0, 10, 0), (10, 10, 0)], code=21)
    assert lay.join(n[3], n[1]) == "branch"
    assert not lay.closure(n[1]).closed
    for a, b in [(n[1], n[2]), (n[2], n[3]), (n[2], n[1]), (n[3], n[2])]:
        with pytest.raises(TopologyError, match=r"not closed.*point 4 hangs on point 2 of the"):
            lay.area(a, b)
