"""The one topology rebuild from plain polylines (apygis.model.polylines.rebuild).

Its rules and refusals, and the bugs the four reader policies it replaced had.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import apygis
from apygis.errors import RecordError
from apygis.model.polylines import to_csr

SQUARE = [((0, 0), (1, 0)), ((1, 0), (1, 1)), ((1, 1), (0, 1)), ((0, 1), (0, 0))]


def _add(layer, lines, codes=11, closed=None, snap_m=0.005, **kw):
    coords, offsets = to_csr(lines)
    return layer.add_polylines(coords, offsets, codes, closed, snap_m=snap_m, **kw)


def _errors(layer):
    return [i for i in layer.validate() if i.severity == "error"]


@pytest.mark.parametrize("order", list(itertools.permutations(range(4))))
def test_four_segments_of_a_square_are_one_closed_line_in_any_order_and_direction(order):
    for flips in itertools.product((False, True), repeat=4):
        segs = [SQUARE[k][::-1] if f else SQUARE[k] for k, f in zip(order, flips, strict=True)]
        lay = apygis.Layer("r")
        rep = _add(lay, segs)
        assert lay.counts()["lines"] == 1, (order, flips)
        assert lay.counts()["closed_lines"] == 1, (order, flips)
        assert len(lay.line_points) == 4
        assert (rep.merged, rep.rings) == (4, 1)
        assert _errors(lay) == []
        lp = lay.line_points
        a, b = (int(v) for v in lp["num"][lay.chains().rows(0)][:2])
        assert abs(lay.area(a, b).area_m2) == pytest.approx(1.0)


def test_a_merged_chain_runs_the_way_its_first_line_does():
    lay = apygis.Layer("r")
    _add(lay, [[(0, 0), (1, 0)], [(2, 0), (1, 0)]])  # the second digitised against the first
    lp = lay.line_points
    assert lp["x"][lay.chains().rows(0)].tolist() == [0, 1, 2]


def test_ends_meeting_on_a_merged_line_point_are_one_vertex():
    """Bug: [(0,.03)->(0,-.01)], [(0,-.01)->(0,.01)], [(0,.03)->(0,0)] gave two points at
    (0, -0.01) linked forward (found by the export/rebuild property test)."""
    lay = apygis.Layer("r")
    rep = _add(
        lay, [[(0, 0.03), (0, -0.01)], [(0, -0.01), (0, 0.01)], [(0, 0.03), (0, 0)]], 1, snap_m=0.0
    )
    lp = lay.line_points
    assert int(((lp["x"] == 0) & (lp["y"] == -0.01)).sum()) == 1
    assert int(((lp["x"] == 0) & (lp["y"] == 0.03)).sum()) == 1
    assert len(lay.chains()) == 1
    assert len(lp) == 4
    assert rep.merged == 2
    assert _errors(lay) == []


def test_a_line_and_its_reverse_do_not_become_a_two_point_loop():
    """Bug: two lines A->B and B->A merged into a 2-point "ring" that validate() refused
    ("reference each other forward")."""
    lay = apygis.Layer("r")
    rep = _add(lay, [[(0, 0), (5, 0)], [(5, 0), (0, 0)]], 1, snap_m=0.0)
    assert _errors(lay) == []
    assert rep.refused == {"two-point-loop": 1}
    assert lay.counts()["closed_lines"] == 0
    assert len(lay.chains()) == 2
    assert len(lay.line_points) == 4
    assert "refused" in rep.message()


def test_a_line_whose_ends_meet_with_two_distinct_vertices_stays_open():
    lay = apygis.Layer("r")
    rep = _add(lay, [[(0, 0), (5, 0), (0, 0)]], 1, snap_m=0.0)
    assert lay.counts()["closed_lines"] == 0
    assert rep.refused == {"two-point-loop": 1}
    assert _errors(lay) == []


def test_consecutive_duplicates_are_removed_and_counted():
    lay = apygis.Layer("r")
    rep = _add(lay, [[(0, 0, 1), (0, 0, 2), (1, 0, 0), (1, 0.001, 0), (2, 0, 0)]])
    assert rep.duplicates_removed == 2
    assert lay.line_points["z"].tolist() == [1, 0, 0]  # the first of each stays
    assert rep.nums.tolist() == [1, 1, 2, 2, 3]


def test_a_closed_flag_or_a_repeated_first_vertex_closes_a_ring():
    lay = apygis.Layer("r")
    rep = _add(
        lay,
        [[(0, 0), (1, 0), (1, 1)], [(5, 5), (6, 5), (6, 6), (5, 5)], [(9, 9), (9, 8)]],
        closed=[True, False, True],
    )
    assert lay.counts()["closed_lines"] == 2
    assert rep.rings == 2
    assert rep.refused == {"ring-too-short": 1}  # two points cannot close
    assert len(lay.line_points) == 8


def test_lines_of_different_codes_meeting_end_to_end_join_as_a_branch():
    lay = apygis.Layer("r")
    rep = _add(lay, [[(0, 0), (1, 0)], [(1, 0), (2, 0)]], [11, 12])
    assert (rep.merged, rep.joined) == (0, 1)
    assert len(lay.chains()) == 2
    assert len(lay.branches()) == 1
    assert sorted(lay.line_points["code"].tolist()) == [11, 11, 12]
    assert _errors(lay) == []


def test_a_junction_takes_two_branches_and_refuses_a_third():
    lay = apygis.Layer("r")
    main = [(-1, 0), (0, 0), (1, 0)]
    spokes = [[(0, 5), (0, 0)], [(0, -5), (0, 0)], [(3, 3), (0, 0)]]
    rep = _add(lay, [main, *spokes])
    assert rep.joined == 2
    assert rep.refused == {"no-free-side": 1}
    assert len(lay.branches()) == 2
    assert _errors(lay) == []


def test_an_end_on_an_existing_line_point_is_a_branch_of_it():
    lay = apygis.Layer("r")
    main = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=31)
    rep = _add(lay, [[(10, 8), (10, 0.003)]], 32)
    assert rep.nums.tolist() == [4, main[1]]
    lp = lay.line_points
    assert lp["side1"][lp["num"] == main[1]][0] == 4
    assert _errors(lay) == []


def test_join_false_adds_each_line_as_it_is():
    lay = apygis.Layer("r")
    rep = _add(lay, [seg for seg in SQUARE], join=False)
    assert len(lay.chains()) == 4
    assert len(lay.line_points) == 8
    assert rep.merged == rep.joined == 0


def test_numbers_follow_the_model_rule():
    lay = apygis.Layer("r")
    lay.add_line([(0, 0, 0), (1, 1, 0)], code=1)
    lay.delete_line_point(1)
    rep = _add(lay, [[(5, 5), (6, 6)]])
    assert rep.nums.tolist() == [3, 4]


@pytest.mark.parametrize(
    ("coords", "offsets", "codes", "match"),
    [
        ([(0, 0), (np.nan, 1)], [0, 2], 1, "not finite"),
        ([(0, 0), (2e12, 1)], [0, 2], 1, "exceed"),
        ([(0, 0), (1, 1)], [0, 3], 1, "offsets"),
        ([(0, 0), (1, 1)], [0, 2], 100, "0-99"),
        ([(0, 0), (1, 1)], [0, 2], True, "integers"),
        ([(0, 0), (1, 1)], [0, 1, 2], [1, 2, 3], "one per line"),
    ],
)
def test_bad_input_is_refused_and_nothing_added(coords, offsets, codes, match):
    lay = apygis.Layer("r")
    with pytest.raises(RecordError, match=match):
        lay.add_polylines(np.array(coords, float), np.array(offsets), codes)
    assert len(lay.line_points) == 0


@pytest.mark.parametrize("name", ["r\n", "AB\n"])
def test_names_with_a_final_newline_are_refused(name):
    from apygis.model.map import check_ext, check_map_id

    with pytest.raises(RecordError):
        (check_ext if len(name) == 2 else check_map_id)(name)
