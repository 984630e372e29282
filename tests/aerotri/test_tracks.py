"""Linking pairwise matches into tracks, and automatic point names."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from apygis.aerotri.tracks import PointNames, link


def a(*v):
    return np.array(v, dtype=np.int64)


def as_sets(tracks):
    return {frozenset(tracks[t]) for t in range(len(tracks))}


def test_chain_of_three_images_gives_threefold_tracks():
    # points 0..4 of image 1 match 10..14 of image 2, which match 20..24 of image 3;
    # 5 of image 1 matches 15 of image 2 only (a 2-fold track)
    t = link(
        [
            (1, 2, a(0, 1, 2, 3, 4, 5), a(10, 11, 12, 13, 14, 15)),
            (2, 3, a(10, 11, 12, 13, 14), a(20, 21, 22, 23, 24)),
        ]
    )
    assert len(t) == 6
    assert t.multiplicity_table() == {2: 1, 3: 5}
    assert frozenset({(1, 0), (2, 10), (3, 20)}) in as_sets(t)
    assert frozenset({(1, 5), (2, 15)}) in as_sets(t)
    assert t.n_inconsistent == 0


def test_closing_a_loop_adds_no_multiplicity_but_stays_consistent():
    t = link([(1, 2, a(0), a(0)), (2, 3, a(0), a(0)), (3, 1, a(0), a(0))])
    assert as_sets(t) == {frozenset({(1, 0), (2, 0), (3, 0)})}


def test_inconsistent_loop_is_split_at_its_weakest_link():
    # 1:0 - 2:0 - 3:0 - 1:7: image 1 twice; the 3-1 link is the weakest (ncc 0.71)
    m = [
        (1, 2, a(0), a(0), [0.95]),
        (2, 3, a(0), a(0), [0.90]),
        (3, 1, a(0), a(7), [0.71]),
        (1, 2, a(3), a(3), [0.9]),  # an unrelated consistent track
    ]
    t = link(m)
    assert t.n_inconsistent == 1
    assert t.n_links_dropped == 1
    assert as_sets(t) == {frozenset({(1, 0), (2, 0), (3, 0)}), frozenset({(1, 3), (2, 3)})}
    # with the weak link elsewhere the split is elsewhere: 1:0 - 2:0 dropped
    m[0] = (1, 2, a(0), a(0), [0.70])
    t = link(m)
    assert frozenset({(2, 0), (3, 0), (1, 7)}) in as_sets(t)
    assert t.n_links_dropped == 1


def test_inconsistent_loop_is_dropped_when_asked():
    m = [(1, 2, a(0, 3), a(0, 3)), (2, 3, a(0), a(0)), (3, 1, a(0), a(7))]
    t = link(m, inconsistent="drop")
    assert t.n_inconsistent == 1
    assert t.n_tracks_dropped == 1
    assert as_sets(t) == {frozenset({(1, 3), (2, 3)})}


def test_empty_and_bad_input():
    t = link([])
    assert len(t) == 0
    assert t.multiplicity_table() == {}
    with pytest.raises(ValueError, match="equal"):
        link([(1, 2, a(0, 1), a(0))])
    with pytest.raises(ValueError, match="itself"):
        link([(1, 1, a(0), a(1))])
    with pytest.raises(ValueError, match="inconsistent"):
        link([], inconsistent="keep")


def _components(edges):
    parent: dict = {}

    def find(x):
        parent.setdefault(x, x)
        while parent[x] != x:
            x = parent[x]
        return x

    for u, v in edges:
        parent[find(u)] = find(v)
    groups: dict = {}
    for x in list(parent):
        groups.setdefault(find(x), set()).add(x)
    return {frozenset(g) for g in groups.values()}


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 3), st.integers(0, 3), st.integers(0, 5), st.integers(0, 5)),
        max_size=30,
    )
)
def test_tracks_are_consistent_components(raw):
    edges = [((ia, pa), (ib, pb)) for ia, ib, pa, pb in raw if ia != ib]
    matches = [(u[0], v[0], a(u[1]), a(v[1])) for u, v in edges]
    t = link(matches)
    seen = set()
    for k in range(len(t)):
        members = t[k]
        images = [m[0] for m in members]
        assert len(set(images)) == len(images) >= 2  # one point per image
        assert not seen & set(members)  # a node is in one track at most
        seen |= set(members)
    comps = _components(edges)
    consistent = {c for c in comps if len({n[0] for n in c}) == len(c)}
    assert t.n_inconsistent == len(comps) - len(consistent)
    # consistent components are exactly the tracks; the others are split into parts
    assert consistent <= as_sets(t)
    for s in as_sets(t) - consistent:
        assert any(s < c for c in comps - consistent)


def test_numeric_names_never_repeat():
    n = PointNames(100000, 1)
    assert n.next(3) == ["100000", "100001", "100002"]
    n.taken(["100004", 100005, "0100006", "P100007"])  # only the numeric names count
    assert n.next(4) == ["100003", "100006", "100007", "100008"]
    n.taken(["100003"])  # already issued: nothing to do
    assert n.next(1) == ["100009"]


def test_alphanumeric_names_with_interval():
    n = PointNames("T0001", 5)
    assert n.next(3) == ["T0001", "T0006", "T0011"]
    n.taken(["T0016", "T16", "U0021", "T0021x"])  # T16 is not T0016's spelling
    assert n.next(2) == ["T0021", "T0026"]


def test_tail_widens_on_overflow_and_state_round_trips():
    n = PointNames("T9998", 1)
    assert n.next(3) == ["T9998", "T9999", "T10000"]
    n.taken(["T10002"])
    m = PointNames.from_dict(n.to_dict())
    assert m.next(2) == ["T10001", "T10003"]
    assert n.next(2) == ["T10001", "T10003"]  # the original goes on the same way


@settings(max_examples=40, deadline=None)
@given(
    st.integers(0, 10**6),
    st.integers(1, 7),
    st.lists(st.integers(0, 40), max_size=10),
    st.lists(st.integers(0, 40), max_size=10),
)
def test_names_unique_and_avoid_taken(start, step, before, ks):
    n = PointNames(start, step)
    taken = {str(start + step * i) for i in before}
    n.taken(taken)
    out = []
    for k in ks:
        out += n.next(k)
    assert len(out) == len(set(out)) == sum(ks)
    assert not set(out) & taken
    assert all((int(s) - start) % step == 0 and int(s) >= start for s in out)


def test_bad_names():
    with pytest.raises(ValueError, match="digits"):
        PointNames("TP", 1)
    with pytest.raises(ValueError, match="interval"):
        PointNames(1, 0)
