"""Polylines out and back in: export_lines and the topology rebuild (Layer.add_polylines)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings

import apygis
from apygis.errors import RecordError
from apygis.model.polylines import export_lines, to_csr
from tests.formats.strategies import layers


def add_lines(layer, lines, codes, closed=None, tolerance_m=0.005, crs=None):
    """A list of vertex arrays through the one rebuild; the report."""
    coords, offsets = to_csr(lines)
    return layer.add_polylines(
        coords,
        offsets,
        codes,
        None if closed is None else list(closed),
        snap_m=tolerance_m,
        crs=crs,
    )


def _shape(layer):
    """What the topology rebuild must preserve: chains' coordinates, rings, branches."""
    lp = layer.line_points
    cs = layer.chains()
    chains = []
    for k, rows in enumerate(cs):
        pts = [
            tuple(np.round(p, 6))
            for p in zip(lp["x"][rows], lp["y"][rows], lp["z"][rows], strict=True)
        ]
        if cs.closed[k]:
            i = pts.index(min(pts))
            pts = pts[i:] + pts[:i]
        chains.append((bool(cs.closed[k]), tuple(pts)))
    num_xy = {
        int(n): (round(x, 6), round(y, 6))
        for n, x, y in zip(lp["num"], lp["x"], lp["y"], strict=True)
    }
    br = sorted((num_xy[b["point"]], num_xy[b["junction"]], b["end"]) for b in layer.branches())
    return sorted(chains), br


def test_sample_layers_survive_export_and_rebuild(sample_map):
    for lay in sample_map:
        if not len(lay.line_points):
            continue
        ls = export_lines(lay)
        fresh = apygis.Layer(lay.ext)
        add_lines(fresh, [p.coords for p in ls], [p.code for p in ls], [p.closed for p in ls])
        assert _shape(fresh) == _shape(lay), lay.ext
        assert fresh.validate() == []
        keys = ("line_points", "lines", "closed_lines")
        assert [fresh.counts()[k] for k in keys] == [lay.counts()[k] for k in keys]


def test_export_appends_junctions_and_keeps_rings_unrepeated():
    lay = apygis.Layer("h")
    main = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=31)
    trib = lay.add_line([(10, 9, 1), (10, 4, 1)], code=32)
    lay.join(trib[-1], main[1])
    lay.add_line([(0, 50, 2), (0, 60, 2), (9, 60, 2)], code=35, closed=True)
    ls = export_lines(lay)
    assert [p.closed for p in ls] == [False, False, True]
    assert ls[1].nums == (*trib, main[1])
    assert ls[1].coords[-1].tolist() == [10.0, 0.0, 0.0]
    assert len(ls[2].coords) == 3
    assert ls.line_index().tolist() == [0, 0, 0, 1, 1, 1, 2, 2, 2]


def test_gis_lines_meeting_end_to_start_merge_and_closed_rings_close():
    lay = apygis.Layer("r")
    # two features that together form one road, then a ring digitised with a repeated vertex
    a = [(0, 0, 0), (10, 0, 0)]
    b = [(10, 0, 0), (20, 0, 0), (30, 5, 0)]
    ring = [(0, 10, 0), (0, 20, 0), (10, 20, 0), (10, 10, 0), (0, 10.001, 0)]
    add_lines(lay, [a, b, ring], [11, 11, 21])
    c = lay.counts()
    assert (c["lines"], c["closed_lines"], c["line_points"]) == (2, 1, 8)
    cs = lay.chains()
    lp = lay.line_points
    assert lp["x"][cs.rows(0)].tolist() == [0, 10, 20, 30]
    assert lay.area(*[int(v) for v in lp["num"][cs.rows(1)][:2]]).area_m2 == pytest.approx(100.0)
    assert lay.validate() == []


def test_three_lines_at_a_point_give_a_chain_and_a_branch():
    lay = apygis.Layer("r")
    add_lines(lay, [[(0, 0), (5, 5)], [(10, 0), (5, 5)], [(5, 5), (5, 10)]], 12)
    assert lay.counts()["lines"] == 2
    assert len(lay.branches()) == 1
    assert len(lay.line_points) == 4  # the meeting point once, plus the three far ends
    assert lay.validate() == []


def test_lines_join_existing_layer_points():
    lay = apygis.Layer("h")
    main = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=31)
    rep = add_lines(lay, [[(10, 8, 0), (10, 0.003, 0)]], 32)
    assert rep.nums.tolist() == [4, main[1]]  # the end went into the junction
    assert rep.joined == 1
    lp = lay.line_points
    assert lp["fwd"][lp["num"] == 4][0] == main[1]
    assert lp["side1"][lp["num"] == main[1]][0] == 4
    assert lay.validate() == []


def test_tolerance_and_bad_input():
    lay = apygis.Layer("r")
    add_lines(lay, [[(0, 0), (10, 0)], [(10.2, 0), (20, 0)]], 1, tolerance_m=0.1)
    assert lay.counts()["lines"] == 2
    lay2 = apygis.Layer("r")
    add_lines(lay2, [[(0, 0), (10, 0)], [(10.2, 0), (20, 0)]], 1, tolerance_m=0.5)
    assert lay2.counts()["lines"] == 1
    with pytest.raises(RecordError, match="0-99"):
        add_lines(lay, [[(0, 0), (1, 1)]], 100)
    with pytest.raises(RecordError, match=r"array of vertices|vertex"):
        add_lines(lay, [[0, 1, 2]], 1)


@settings(max_examples=200, deadline=None)
@given(lay=layers("r"))
def test_property_export_rebuild_keeps_geometry(lay):
    # line points at the same position are joined by design (an end on another line's
    # vertex becomes a junction): the property is about layers without such chance meetings
    xy = np.round(fresh_xyz(lay)[:, :2], 6)
    assume(len({tuple(p) for p in xy}) == len(xy))
    ls = export_lines(lay)
    fresh = apygis.Layer("r")
    rep = add_lines(
        fresh, [p.coords for p in ls], [p.code for p in ls], [p.closed for p in ls], 0.0
    )
    # the rebuilt topology is sound, every vertex is there once (a branch's copy of its
    # junction goes back into the junction), and the closed lines are the same
    assert [i for i in fresh.validate() if i.severity == "error"] == []
    assert sorted(map(tuple, np.round(fresh_xyz(fresh), 6))) == sorted(
        map(tuple, np.round(fresh_xyz(lay), 6))
    )
    assert fresh.counts()["closed_lines"] == lay.counts()["closed_lines"]
    assert rep.duplicates_removed == 0


def fresh_xyz(lay):
    lp = lay.line_points
    return np.column_stack([lp["x"], lp["y"], lp["z"]])


@pytest.mark.parametrize(
    "connector",
    [[(10, 0), (10, 10)], [(10, 0), (10, 5), (10, 10)], [(10, 0), (10, 4), (10, 6), (10, 10)]],
)
def test_a_line_touching_two_lines_is_joined_at_both_ends(connector):
    lay = apygis.Layer("r")
    add_lines(lay, [[(0, 0), (10, 0), (20, 0)], [(0, 10), (10, 10), (20, 10)], connector], 1)
    junctions = sorted(b["junction"] for b in lay.branches())
    assert junctions == [2, 5]
    assert lay.validate() == []


# ------------------------------------------------------------------ tolerances in CRS units


def test_tolerance_in_crs_units():
    from apygis.model.polylines import metres_per_unit_at, tolerance_in_crs

    assert tolerance_in_crs(0.005, None) == 0.005
    assert tolerance_in_crs(0.005, "EPSG:2056") == 0.005
    assert tolerance_in_crs(0.3048, "EPSG:2229") == pytest.approx(0.3048 / (1200 / 3937))  # US ft
    east, north = metres_per_unit_at("EPSG:4326", 0.0)
    assert east == pytest.approx(111_319.49, abs=0.01)  # a degree of the equator
    assert north == pytest.approx(110_574.3, abs=0.1)  # of the meridian at the equator
    # the shorter of the two: latitude at the equator, longitude in the north
    assert tolerance_in_crs(1.0, "EPSG:4326", 0.0) == pytest.approx(1 / north)
    east60, _ = metres_per_unit_at("EPSG:4326", 60.0)
    assert east60 == pytest.approx(55_799.98, abs=0.5)
    assert tolerance_in_crs(1.0, "EPSG:4326", 60.0) == pytest.approx(1 / east60)


@pytest.mark.parametrize(("gap_m", "joined"), [(300.0, False), (0.004, True), (0.006, False)])
def test_add_lines_tolerance_is_metres_in_a_geographic_crs(gap_m, joined):
    """At 60° N a degree of longitude is 55.8 km: 0.005 is 5 mm, never 0.005 degrees."""
    from apygis.model.polylines import metres_per_unit_at

    east, _ = metres_per_unit_at("EPSG:4326", 60.0)
    d = gap_m / east
    lay = apygis.MapFile("G", crs="EPSG:4326").layer("r")
    add_lines(
        lay,
        [[(10.0, 60.0), (10.001, 60.0)], [(10.001 + d, 60.0), (10.002, 60.0)]],
        11,
        tolerance_m=0.005,
        crs="EPSG:4326",
    )
    assert len(lay.chains()) == (1 if joined else 2)
    assert len(lay.line_points) == (3 if joined else 4)


def test_add_lines_refuses_a_negative_tolerance():
    lay = apygis.MapFile("G").layer("r")
    with pytest.raises(RecordError, match="distance in metres"):
        add_lines(lay, [[(0, 0), (1, 0)]], 11, tolerance_m=-1.0)


def test_an_open_line_of_coincident_vertices_is_one_point():
    lay = apygis.Layer("r")
    rep = add_lines(lay, [[(0, 0, 0), (0, 0, 0), (0, 0, 0)]], 11, tolerance_m=0.0)
    assert rep.nums.tolist() == [1, 1, 1]
    assert rep.duplicates_removed == 2
    assert lay.validate() == []
    assert len(lay.chains()) == 1
    assert lay.counts()["closed_lines"] == 0
