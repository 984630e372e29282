"""The editing API of Layer and MapFile: numbers, references, and their repair."""

from __future__ import annotations

import math

import numpy as np
import pytest

import apygis
from apygis.errors import ApygisError, RecordError, RecordNotFoundError, TopologyError
from apygis.model.records import NO_REF


def refs(layer, num):
    lp = layer.line_points
    r = lp[lp["num"] == num][0]
    return int(r["fwd"]), int(r["back"]), int(r["side1"]), int(r["side2"])


def test_add_records_number_from_one_per_table():
    lay = apygis.MapFile("T").layer("r")
    assert lay.add_symbol(1, 2, 3, 7) == 1
    assert lay.add_symbol(1, 2, 3, 0) == 2
    assert lay.add_text(1, 2, 3, "Kirchweg") == 1
    assert lay.add_line([(0, 0, 0), (1, 0, 0), (2, 0, 0)], code=12) == [1, 2, 3]
    assert refs(lay, 1) == (2, NO_REF, NO_REF, NO_REF)
    assert refs(lay, 2) == (3, 1, NO_REF, NO_REF)
    assert refs(lay, 3) == (NO_REF, 2, NO_REF, NO_REF)
    assert lay.validate() == []


def test_closed_line_links_last_to_first():
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (0, 5, 0), (5, 5, 0)], code=21, closed=True)
    assert refs(lay, n[0])[:2] == (n[1], n[2])
    assert refs(lay, n[2])[:2] == (n[0], n[1])
    assert lay.counts()["closed_lines"] == 1
    with pytest.raises(TopologyError, match="at least three points"):
        lay.add_line([(0, 0, 0), (1, 1, 1)], code=21, closed=True)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda lay: lay.add_symbol(0, 0, 0, 100), "0 to 99"),
        (lambda lay: lay.add_symbol(0, 0, 0, -1), "0 to 99"),
        (lambda lay: lay.add_symbol(0, 0, 0, 3.0), "integer"),
        (lambda lay: lay.add_symbol(math.nan, 0, 0, 3), "finite"),
        (lambda lay: lay.add_symbol("a", 0, 0, 3), "numbers"),
        (lambda lay: lay.add_text(0, 0, 0, "a\nb"), "control"),
        (lambda lay: lay.add_line([], 3), "one or more"),
        (lambda lay: lay.add_line([(0, 0)], 3), "one or more"),
    ],
)
def test_bad_arguments_raise_record_error(call, match):
    lay = apygis.MapFile("T").layer("r")
    with pytest.raises(RecordError, match=match):
        call(lay)
    assert len(lay) == 0


def test_map_header_validation():
    with pytest.raises(ApygisError, match="map ID"):
        apygis.MapFile("bad id")
    with pytest.raises(ApygisError, match="positive integer"):
        apygis.MapFile("T", scale=0)
    with pytest.raises(ApygisError, match="coordinate reference system"):
        apygis.MapFile("T", crs="EPSG:999999999")
    with pytest.raises(ApygisError, match="1 to 3 letters"):
        apygis.MapFile("T").layer("road")
    m = apygis.MapFile("T", scale=5000, crs=2056)
    assert m.crs.to_epsg() == 2056
    assert m.layer("R") is m.layer("r")


def test_numbers_fill_apy_range_then_continue():
    lay = apygis.MapFile("T").layer("r")
    nums = lay.add_line([(float(i), 0.0, 0.0) for i in range(9999)], code=1)
    assert nums[-1] == 9999
    assert lay.add_line([(0, 1, 0)], code=1) == [0]  # the 10000th point takes the free 0
    assert lay.add_line([(0, 2, 0)], code=1) == [10000]  # beyond: only the APY format refuses
    lay.delete_line_point(17)
    assert lay.add_symbol(0, 0, 0, 1) == 1
    assert lay.add_line([(0, 3, 0)], code=1) == [17]  # the lowest free number is reused


def test_extend_line_at_either_end():
    lay = apygis.MapFile("T").layer("h")
    a = lay.add_line([(0, 0, 0)], code=31)
    b = lay.extend_line(a[0], [(1, 0, 0), (2, 0, 0)])
    assert refs(lay, a[0])[:2] == (b[0], NO_REF)
    c = lay.extend_line(a[0], [(-1, 0, 0)])  # a[0] has a forward neighbour: grow at the start
    assert refs(lay, a[0])[:2] == (b[0], c[0])
    assert refs(lay, c[0])[:2] == (a[0], NO_REF)
    assert lay.closure(b[-1]).points == (c[0], a[0], *b)
    with pytest.raises(TopologyError, match="not the end"):
        lay.extend_line(a[0], [(5, 5, 5)])


def test_split_inserts_between_neighbours_in_either_order():
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=12)
    s = lay.split(n[1], n[0], (5.0, 0.0, 0.0))  # given backwards
    assert lay.closure(n[0]).points == (n[0], s, n[1], n[2])
    assert lay.line_points[lay.line_points["num"] == s]["code"][0] == 12
    with pytest.raises(TopologyError, match="not neighbours"):
        lay.split(n[0], n[2], (1, 1, 1))
    assert lay.validate() == []


def test_join_makes_branch_and_closes_ring():
    lay = apygis.MapFile("T").layer("r")
    main = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=11)
    br = lay.add_line([(10, 10, 0), (10, 20, 0)], code=12)
    assert lay.join(br[0], main[1]) == "branch"
    assert refs(lay, br[0])[1] == main[1]
    assert refs(lay, main[1])[2] == br[0]
    br2 = lay.add_line([(10, -10, 0)], code=12)
    assert lay.join(br2[0], main[1]) == "branch"
    assert refs(lay, main[1])[3] == br2[0]
    br3 = lay.add_line([(11, -10, 0)], code=12)
    with pytest.raises(TopologyError, match="two branches"):
        lay.join(br3[0], main[1])
    with pytest.raises(TopologyError, match="not the end"):
        lay.join(main[1], br3[0])
    ring = lay.add_line([(0, 50, 0), (0, 60, 0), (10, 60, 0)], code=21)
    assert lay.join(ring[-1], ring[0]) == "closed"
    assert lay.closure(ring[0]).closed
    assert lay.validate() == []
    assert {(b["point"], b["junction"]) for b in lay.branches()} == {
        (br[0], main[1]),
        (br2[0], main[1]),
    }


def test_delete_line_point_bridges_the_line():
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0), (30, 0, 0)], code=12)
    lay.delete_line_point(n[1])
    assert lay.closure(n[0]).points == (n[0], n[2], n[3])
    lay.delete_line_point(n[3])  # an end
    assert refs(lay, n[2])[:2] == (NO_REF, n[0])
    assert lay.validate() == []
    with pytest.raises(RecordNotFoundError, match="no line point number 99"):
        lay.delete_line_point(99)


def test_delete_from_ring_of_three_leaves_an_open_line():
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (0, 5, 0), (5, 5, 0)], code=21, closed=True)
    lay.delete_line_point(n[0])
    c = lay.closure(n[1])
    assert not c.closed
    assert c.points == (n[1], n[2])
    assert lay.validate() == []


def test_delete_junction_moves_branch_to_the_heir():
    lay = apygis.MapFile("T").layer("r")
    main = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=11)
    br = lay.add_line([(10, 10, 0), (10, 20, 0)], code=12)
    lay.join(br[0], main[1])
    lay.delete_line_point(main[1])
    assert refs(lay, br[0])[1] == main[0]
    assert refs(lay, main[0])[2] == br[0]
    assert lay.validate() == []
    lay.delete_line(main[0])
    assert refs(lay, br[0])[1] == NO_REF  # no heir left: the branch end is free
    assert lay.validate() == []
    assert lay.counts()["lines"] == 1


def test_delete_symbol_and_text():
    lay = apygis.MapFile("T").layer("c")
    s = lay.add_symbol(0, 0, 0, 1)
    t = lay.add_text(0, 0, 0, "P1")
    lay.delete_symbol(s)
    lay.delete_text(t)
    assert len(lay) == 0
    with pytest.raises(RecordNotFoundError, match="no symbol number 1"):
        lay.delete_symbol(s)
    with pytest.raises(RecordNotFoundError, match="no text number 1"):
        lay.delete_text(t)


def test_tables_are_read_only_views():
    lay = apygis.MapFile("T").layer("c")
    lay.add_symbol(0, 0, 0, 1)
    with pytest.raises(ValueError, match="read-only"):
        lay.symbols["code"][0] = 5


def test_growth_keeps_earlier_records():
    lay = apygis.MapFile("T").layer("e")
    for i in range(1000):
        lay.add_symbol(i, i, i, 0)
    assert lay.symbols["num"].tolist() == list(range(1, 1001))
    assert np.array_equal(lay.symbols["x"], np.arange(1000.0))


def test_map_equality_and_copy():
    m = apygis.MapFile("T", scale=5000, crs="EPSG:2056", notes="n")
    m.layer("r").add_line([(0, 0, 0), (1, 1, 1)], code=3)
    c = m.copy()
    assert c == m
    c.layer("r").add_symbol(0, 0, 0, 1)
    assert c != m


def _ref_table(layer):
    lp = layer.line_points
    return {
        int(r["num"]): (int(r["fwd"]), int(r["back"]), int(r["side1"]), int(r["side2"])) for r in lp
    }


def test_join_to_a_first_point_that_is_a_branch_end_makes_a_branch():
    # Issue 9: an operator starts a branch at junction a[0] (SEARCH), digitises two points
    # and SEARCHes the branch's first point: closing the ring there overwrote its backward
    # reference to the junction. The slot is taken, so the line hangs on its own first point.
    lay = apygis.MapFile("T").layer("r")
    a = lay.add_line([(0, 0, 0), (10, 0, 0)], code=1)
    (b,) = lay.add_line([(5, 5, 0)], code=1)
    assert lay.join(b, a[0]) == "branch"
    c = lay.extend_line(b, [(6, 9, 0), (2, 9, 0)])
    assert lay.join(c[-1], b) == "branch"
    assert lay.validate() == []
    assert refs(lay, b) == (c[0], a[0], c[-1], NO_REF)
    assert refs(lay, c[-1])[:2] == (b, c[0])
    assert {(d["point"], d["junction"]) for d in lay.branches()} == {(b, a[0]), (c[-1], b)}
    assert not lay.closure(b).closed


def test_join_to_a_last_point_that_is_a_branch_end_makes_a_branch():
    # The mirror case: the line's last point hangs on a junction by its forward reference.
    lay = apygis.MapFile("T").layer("r")
    a = lay.add_line([(0, 0, 0), (10, 0, 0)], code=1)
    n = lay.add_line([(0, 9, 0), (5, 9, 0), (5, 5, 0)], code=1)
    assert lay.join(n[-1], a[1]) == "branch"
    assert refs(lay, n[-1])[0] == a[1]
    assert lay.join(n[0], n[-1]) == "branch"
    assert refs(lay, n[0])[1] == n[-1]
    assert refs(lay, n[-1])[2] == n[0]
    assert lay.validate() == []


def test_join_refused_when_the_ring_cannot_close_and_no_side_is_free():
    lay = apygis.MapFile("T").layer("r")
    a = lay.add_line([(0, 0, 0), (10, 0, 0)], code=1)
    n = lay.add_line([(5, 5, 0), (6, 9, 0), (2, 9, 0)], code=1)
    lay.join(n[0], a[0])
    for k in range(2):
        (e,) = lay.add_line([(k, 20, 0)], code=1)
        lay.join(e, n[0])
    before = lay.copy()
    with pytest.raises(TopologyError, match=r"two branches.*cannot be closed"):
        lay.join(n[-1], n[0])
    assert lay == before


def test_join_refused_when_the_points_already_reference_each_other():
    # 4 hangs on 2 by its forward reference; joining 2 back to 4 made 2 and 4
    # reference each other forward (a two-point cycle).
    lay = apygis.MapFile("T").layer("r")
    a = lay.add_line([(0, 0, 0), (1, 0, 0)], code=1)
    b = lay.add_line([(0, 1, 0), (1, 1, 0)], code=1)
    assert lay.join(b[-1], a[-1]) == "branch"
    before = lay.copy()
    with pytest.raises(TopologyError, match="already joined"):
        lay.join(a[-1], b[-1])
    assert lay == before
    assert lay.validate() == []


def test_delete_line_point_does_not_hand_a_branch_to_its_own_neighbour():
    # Issue 9: 5 hangs on 2 (a loop); deleting 1, 2, 3 handed the branch on to 4,
    # which 5 already follows: 4 and 5 referenced each other forward.
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(float(k), 0.0, 0.0) for k in range(5)], code=1)
    assert lay.join(n[4], n[1]) == "branch"
    for k in n[:3]:
        lay.delete_line_point(k)
        assert lay.validate() == [], k
    assert _ref_table(lay) == {
        n[3]: (n[4], NO_REF, NO_REF, NO_REF),
        n[4]: (NO_REF, n[3], NO_REF, NO_REF),
    }


def test_delete_line_point_in_a_loop_of_three_keeps_the_branch():
    # 2 -> 3 -> 4, and 4 hangs on 2: deleting 3 bridged 2 -> 4, a two-point forward cycle.
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (1, 0, 0), (2, 0, 0), (2, 1, 0)], code=1)
    assert lay.join(n[3], n[1]) == "branch"
    lay.delete_line_point(n[2])
    assert lay.validate() == []
    assert _ref_table(lay) == {
        n[0]: (n[1], NO_REF, NO_REF, NO_REF),
        n[1]: (NO_REF, n[0], n[3], NO_REF),
        n[3]: (n[1], NO_REF, NO_REF, NO_REF),
    }
    assert lay.branches() == [{"chain": 1, "end": "end", "point": n[3], "junction": n[1]}]


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda m: setattr(m, "notes", "Z\udcfcrich"), "the notes"),
        (lambda m: apygis.MapFile("T", notes="\ud800"), "the notes"),
        (lambda m: m.layer("r").add_text(0, 0, 0, "Br\udcfccke"), "a text"),
        (lambda m: apygis.MapFile("Z\udcfcrich"), "map ID"),
        (lambda m: m.layer("\udcfc"), "layer extension"),
    ],
)
def test_lone_surrogates_are_refused_naming_the_field(call, field):
    # Issue 9: '\udcfc' (what surrogateescape makes of a Latin-1 byte) was accepted in
    # notes and texts, and the map then failed to write.
    m = apygis.MapFile("T", notes="n")
    with pytest.raises(RecordError, match=field) as exc:
        call(m)
    assert isinstance(exc.value, ValueError)
    assert m.notes == "n"
    assert len(m.layer("r")) == 0


def test_unencodable_texts_from_arrays_are_reported_by_validate():
    lay = apygis.MapFile("T").layer("r")
    lay.add_text(0, 0, 0, "Zürich")
    bad = lay.texts.copy()
    bad["text"][0] = "Z\udcfcrich"
    lay = type(lay).from_arrays("r", texts=bad)
    (issue,) = lay.validate()
    assert issue.kind == "unencodable-text"
    assert issue.severity == "error"
    assert "text 1" in issue.message
    assert "lone surrogate" in issue.message


def test_a_map_with_latin1_notes_and_texts_survives_the_apy_format(tmp_path):
    m = apygis.MapFile("T", notes="Flüsse, Brücken")
    m.layer("h").add_text(0.5, 1.25, 400.0, "Zürich")
    apygis.write(m, tmp_path / "T", driver="apy")
    assert apygis.read(tmp_path / "T", driver="apy") == m


@pytest.mark.parametrize(
    ("call", "match"),
    [
        # three (x, y) pairs were read as two (x, y, z) points
        (lambda lay, n: lay.extend_line(n[-1], [(1, 2), (3, 4), (5, 6)]), "points of"),
        (lambda lay, n: lay.extend_line(n[-1], [(1, 2)]), "points of"),
        (lambda lay, n: lay.extend_line(n[-1], [("a", 0, 0)]), "numbers"),
        (lambda lay, n: lay.extend_line(n[-1], None), "numbers"),
        (lambda lay, n: lay.extend_line(n[-1], [(0, 0, math.nan)]), "finite"),
        (lambda lay, n: lay.add_line([("a", 0, 0)], 3), "numbers"),
        (lambda lay, n: lay.add_line([(0, 0, 0), (1, 1)], 3), "numbers"),
        (lambda lay, n: lay.split(n[0], n[1], (0, 0)), "position"),
        (lambda lay, n: lay.split(n[0], n[1], None), "position"),
    ],
)
def test_bad_line_coordinates_raise_record_error(call, match):
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (1, 0, 0)], code=1)
    before = lay.copy()
    with pytest.raises(RecordError, match=match):
        call(lay, n)
    assert lay == before


def test_extend_line_with_no_points_still_needs_a_line_end():
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (1, 0, 0), (2, 0, 0)], code=1)
    assert lay.extend_line(n[-1], []) == []
    with pytest.raises(TopologyError, match="not the end"):
        lay.extend_line(n[1], [])


def test_delete_branch_end_keeps_the_branch_on_its_junction():
    # The branch's first point was deleted and the rest of the branch floated free,
    # a gap on the map; its neighbour now takes its place at the junction.
    lay = apygis.MapFile("T").layer("h")
    main = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=31)
    br = lay.add_line([(10, 5, 0), (10, 10, 0), (10, 15, 0)], code=32)
    lay.join(br[0], main[1])
    lay.delete_line_point(br[0])
    assert refs(lay, br[1]) == (br[2], main[1], NO_REF, NO_REF)
    assert refs(lay, main[1])[2:] == (br[1], NO_REF)
    # the same at the last point of a branch that hangs on by its forward reference
    tail = lay.add_line([(30, 5, 0), (25, 5, 0), (20, 1, 0)], code=32)
    lay.join(tail[-1], main[2])
    lay.delete_line_point(tail[-1])
    assert refs(lay, tail[1]) == (main[2], tail[0], NO_REF, NO_REF)
    assert refs(lay, main[2])[2:] == (tail[1], NO_REF)
    assert lay.validate() == []
    assert {(b["point"], b["junction"]) for b in lay.branches()} == {
        (br[1], main[1]),
        (tail[1], main[2]),
    }


def test_delete_branch_end_whose_neighbour_already_touches_the_junction():
    # 2 -> 3 -> 4 -> 5, 5 hangs on 3: deleting 5 cannot hand its place to 4, which
    # follows 3 already; 4 becomes a free end.
    lay = apygis.MapFile("T").layer("r")
    n = lay.add_line([(0, 0, 0), (1, 0, 0), (2, 0, 0), (2, 1, 0)], code=1)
    lay.join(n[3], n[1])
    lay.delete_line_point(n[3])
    assert refs(lay, n[2]) == (NO_REF, n[1], NO_REF, NO_REF)
    assert refs(lay, n[1]) == (n[2], n[0], NO_REF, NO_REF)
    assert lay.validate() == []
