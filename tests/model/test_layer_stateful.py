"""Any sequence of edits keeps a layer valid (issue 9).

A hypothesis state machine edits one :class:`~apygis.model.map.Layer` with
every edit the model has, on purpose also with arguments it must refuse. After
each step:

* :meth:`Layer.validate` reports no error;
* the record counts agree with a shadow count kept from what each edit is
  documented to do (``add_line`` adds its points, ``delete_line`` removes the
  chain's points, ...);
* an edit that fails raises an :class:`~apygis.errors.ApygisError` and leaves
  the layer exactly as it was.

Now and then the map goes through the APY native format and must come back
equal (coordinates lie on a centimetre grid, the format's resolution).

Bugs this machine found are pinned as plain regression tests in
``test_map.py``.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import event, settings
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    rule,
)

import apygis
from apygis.errors import ApygisError
from apygis.model.map import Layer
from apygis.model.records import APY_MAX_NUM, NO_REF, REF_FIELDS

MISSING = 99_999  # a point number no table of this machine reaches

cm = st.integers(-50_000, 50_000).map(lambda c: c / 100)  # +-500 m on a centimetre grid
z_cm = st.integers(-10_000, 400_000).map(lambda c: c / 100)
xyz = st.tuples(cm, cm, z_cm)
codes = st.integers(0, 99)
# printable ISO 8859-1, the APY native format's character set
texts = st.text(
    st.characters(min_codepoint=32, max_codepoint=126)
    | st.characters(min_codepoint=160, max_codepoint=255),
    max_size=24,
)


class LayerMachine(RuleBasedStateMachine):
    """One layer, edited at random; a shadow count of its records."""

    @initialize(
        lines=st.lists(st.tuples(st.lists(xyz, min_size=1, max_size=6), codes), max_size=4),
        high_numbers=st.booleans(),
    )
    def start(self, lines, high_numbers):
        """A few open lines to start from; numbered up to 9999 when ``high_numbers``.

        Then new points take the lowest free numbers: numbers no longer follow
        the rows, and lookups by number are put to the test.
        """
        self.map = apygis.MapFile("T9", scale=5000, notes="issue 9")
        self.lay = self.map.layer("r")
        self.n = {"symbols": 0, "line_points": 0, "lines": 0, "closed_lines": 0, "texts": 0}
        for points, code in lines:
            self.lay.add_line(points, code)
            self.n["line_points"] += len(points)
            self.n["lines"] += 1
        lp = self.lay.line_points.copy()
        if high_numbers and len(lp):
            shift = APY_MAX_NUM - int(lp["num"].max())
            for f in ("num", *REF_FIELDS):
                lp[f] = np.where(lp[f] == NO_REF, NO_REF, lp[f] + shift)
            self.lay = self.map.add_layer(Layer.from_arrays("r", line_points=lp))

    # ------------------------------------------------------------------ helpers

    def nums(self, table: str) -> list[int]:
        return [int(v) for v in self.lay.table(table)["num"]]

    def pick(self, data, table: str) -> int:
        """An existing point number of ``table``, or one that does not exist."""
        return data.draw(st.sampled_from([*self.nums(table), MISSING]), label=table)

    def pick_point(self, data) -> int:
        """A line point, drawn from the kinds where edits have most to repair.

        Any point, a line end (margin point), a junction, a branch end, or a
        number that does not exist.
        """
        lp = self.lay.line_points
        kinds = {
            "any": lp["num"].tolist(),
            "end": self.lay.margin_points()["num"].tolist(),
            "junction": lp["num"][(lp["side1"] != NO_REF) | (lp["side2"] != NO_REF)].tolist(),
            "branch end": [b["point"] for b in self.lay.branches()],
            "missing": [MISSING],
        }
        kind = data.draw(st.sampled_from([k for k, v in kinds.items() if v]), label="kind")
        return data.draw(st.sampled_from(kinds[kind]), label=kind)

    def attempt(self, edit, *args):
        """Run an edit; on an ApygisError check that the layer is unchanged, return None."""
        before = self.lay.copy()
        try:
            return (edit(*args),)
        except ApygisError:
            assert self.lay == before, f"{edit.__name__}{args} failed and changed the layer"
            return None

    # ------------------------------------------------------------------ add

    @rule(points=st.lists(xyz, min_size=1, max_size=6), code=codes, closed=st.booleans())
    def add_line(self, points, code, closed):
        got = self.attempt(self.lay.add_line, points, code, closed)
        if closed and len(points) < 3:
            assert got is None
            return
        (nums,) = got
        assert len(nums) == len(points)
        self.n["line_points"] += len(points)
        self.n["lines"] += 1
        self.n["closed_lines"] += closed
        c = self.lay.closure(nums[0])
        assert c.closed == closed
        assert sorted(c.points) == sorted(nums)

    @rule(p=xyz, code=codes)
    def add_symbol(self, p, code):
        self.lay.add_symbol(*p, code)
        self.n["symbols"] += 1

    @rule(p=xyz, text=texts)
    def add_text(self, p, text):
        num = self.lay.add_text(*p, text)
        assert self.lay.texts["text"][self.lay.texts["num"] == num][0] == text
        self.n["texts"] += 1

    # ------------------------------------------------------------------ lines

    @rule(data=st.data(), points=st.lists(xyz, min_size=1, max_size=4), any_point=st.booleans())
    def extend_line(self, data, points, any_point):
        """From a margin point (must work) or from any point (may be refused)."""
        if any_point:
            end = self.pick_point(data)
        else:
            ends = self.lay.margin_points()["num"].tolist()
            if not ends:  # only closed lines
                return
            end = data.draw(st.sampled_from(ends), label="end")
        got = self.attempt(self.lay.extend_line, end, points)
        if got is None:
            assert any_point
            return
        (nums,) = got
        assert len(nums) == len(points)
        self.n["line_points"] += len(points)
        assert end in self.lay.closure(nums[-1]).points

    @rule(data=st.data())
    def join(self, data):
        """Any point (or none) to any point: joined, or refused cleanly."""
        self._join(self.pick_point(data), self.pick_point(data))

    @rule(data=st.data(), other_end=st.booleans())
    def join_line_end(self, data, other_end):
        """A line end to any point, or to the other end of its line: mostly joined."""
        ends = self.lay.margin_points()["num"].tolist()
        if not ends:
            return
        num = data.draw(st.sampled_from(ends), label="end")
        clo = self.lay.closure(num)
        if other_end and num in (clo.start, clo.end):
            target = clo.start if num == clo.end else clo.end
        else:
            target = self.pick_point(data)
        self._join(num, target)

    @rule(data=st.data(), points=st.lists(xyz, min_size=1, max_size=4), code=codes)
    def add_branch(self, data, points, code):
        """APY's SEARCH on a line point, then ENTER: a new line starting at a junction."""
        (first, *_) = self.lay.add_line(points, code)
        self.n["line_points"] += len(points)
        self.n["lines"] += 1
        self._join(first, self.pick_point(data))

    def _join(self, num: int, target: int) -> None:
        got = self.attempt(self.lay.join, num, target)
        event(f"join: {'refused' if got is None else got[0]}")
        if got is None:
            return
        (how,) = got
        if how == "closed":  # the same line, now a ring
            self.n["closed_lines"] += 1
            clo = self.lay.closure(num)
            assert clo.closed
            assert target in clo.points
        else:
            assert how == "branch"
            hits = [(b["point"], b["junction"]) for b in self.lay.branches()]
            assert (num, target) in hits

    @rule(data=st.data(), p=xyz, neighbours=st.booleans(), backwards=st.booleans())
    def split(self, data, p, neighbours, backwards):
        """Between two neighbours (must work) or between any two points (may be refused)."""
        lp = self.lay.line_points
        if neighbours:
            links = [
                (int(a), int(f))
                for a, f in zip(lp["num"], lp["fwd"], strict=True)
                if f != NO_REF and lp["back"][lp["num"] == f][0] == a
            ]
            if not links:
                return
            a, b = data.draw(st.sampled_from(links), label="link")
        else:
            a, b = self.pick_point(data), self.pick_point(data)
        if backwards:
            a, b = b, a
        got = self.attempt(self.lay.split, a, b, p)
        if got is None:
            assert not neighbours
            return
        (new,) = got
        self.n["line_points"] += 1
        pts = self.lay.closure(new).points
        assert a in pts
        assert b in pts

    @rule(
        data=st.data(),
        points=st.one_of(
            st.none(),
            st.just("abc"),
            st.lists(st.tuples(cm, cm), min_size=1, max_size=3),
            st.lists(st.tuples(cm, cm, st.sampled_from([math.nan, math.inf])), min_size=1),
            st.lists(st.tuples(cm, st.sampled_from(["a", None]), cm), min_size=1, max_size=2),
        ),
        bad=st.sampled_from([math.nan, -math.inf, None, "a", (1.0,)]),
        code=st.one_of(
            st.integers(100, 1000), st.integers(-5, -1), st.floats(0, 99), st.booleans()
        ),
        text=st.one_of(  # any length is a text; control characters and surrogates are not
            st.sampled_from(["a\nb", "\x00", "Z\udcfcrich", "\x85"]),
            st.none(),
        ),
    )
    def refused_arguments(self, data, points, bad, code, text):
        """Malformed positions, codes and texts: each edit refuses with an ApygisError."""
        edits = [
            (self.lay.add_line, points, 1),
            (self.lay.add_line, [(0.0, 0.0, 0.0)], code),
            (self.lay.extend_line, self.pick_point(data), points),
            (self.lay.split, self.pick_point(data), self.pick_point(data), (0.0, bad, 0.0)),
            (self.lay.split, self.pick_point(data), self.pick_point(data), points),
            (self.lay.add_symbol, bad, 0.0, 0.0, 1),
            (self.lay.add_symbol, 0.0, 0.0, 0.0, code),
            (self.lay.add_text, 0.0, 0.0, bad, "T"),
            (self.lay.add_text, 0.0, 0.0, 0.0, text),
        ]
        for edit, *args in edits:
            assert self.attempt(edit, *args) is None, (edit.__name__, args)

    @rule(data=st.data())
    def area(self, data):
        """AREA from any point to any point: a ring's area, or refused."""
        a, b = self.pick_point(data), self.pick_point(data)
        try:
            res = self.lay.area(a, b)
        except ApygisError:
            return
        clo = self.lay.closure(a)
        assert clo.closed
        assert sorted(res.points) == sorted(clo.points)
        assert res.area_m2 >= 0

    # ------------------------------------------------------------------ delete

    @rule(data=st.data())
    def delete_line_point(self, data):
        num = self.pick_point(data)
        for b in self.lay.branches():
            if num == b["junction"]:
                event("delete_line_point: a junction")
            if num == b["point"]:
                event("delete_line_point: a branch end")
        if self.attempt(self.lay.delete_line_point, num) is not None:
            self.n["line_points"] -= 1
            assert num not in self.nums("line_points")
            # a ring may open, a loop come apart: take the line counts as they are
            counts = self.lay.counts()
            self.n["lines"], self.n["closed_lines"] = counts["lines"], counts["closed_lines"]
        else:
            assert num == MISSING

    @rule(data=st.data())
    def delete_line(self, data):
        num = self.pick_point(data)
        clo = self.lay.closure(num) if num != MISSING else None
        got = self.attempt(self.lay.delete_line, num)
        if got is None:
            assert num == MISSING
            return
        (deleted,) = got
        assert tuple(deleted) == clo.points
        self.n["line_points"] -= len(deleted)
        self.n["lines"] -= 1
        self.n["closed_lines"] -= clo.closed
        assert not set(deleted) & set(self.nums("line_points"))

    @rule(data=st.data())
    def delete_symbol(self, data):
        num = self.pick(data, "symbols")
        if self.attempt(self.lay.delete_symbol, num) is not None:
            self.n["symbols"] -= 1
        else:
            assert num == MISSING

    @rule(data=st.data())
    def delete_text(self, data):
        num = self.pick(data, "texts")
        if self.attempt(self.lay.delete_text, num) is not None:
            self.n["texts"] -= 1
        else:
            assert num == MISSING

    # ------------------------------------------------------------------ round trip

    @rule()
    def apy_round_trip(self):
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / self.map.id
            apygis.write(self.map, path, driver="apy")
            back = apygis.read(path, driver="apy")
        assert back == self.map

    # ------------------------------------------------------------------ invariants

    @invariant()
    def valid(self):
        errors = [str(i) for i in self.lay.validate() if i.severity == "error"]
        assert errors == []

    @invariant()
    def side_references_are_branches(self):
        """Edits make side references only for branches: each is a branch end's junction."""
        lp = self.lay.line_points
        sides = {
            (int(k), int(j))
            for j, s1, s2 in zip(lp["num"], lp["side1"], lp["side2"], strict=True)
            for k in (s1, s2)
            if k != NO_REF
        }
        assert sides == {(b["point"], b["junction"]) for b in self.lay.branches()}

    @invariant()
    def chains_follow_the_references(self):
        """Every row in one chain; consecutive points linked both ways; rings close."""
        lp = self.lay.line_points
        cs = self.lay.chains()
        assert sorted(cs.order.tolist()) == list(range(len(lp)))
        geoms = self.lay.geometries()
        assert len(geoms) == len(cs)
        for k, rows in enumerate(cs):
            nums = lp["num"][rows].tolist()
            pairs = list(zip(rows[:-1], nums[1:], strict=True))
            if cs.closed[k]:
                pairs.append((rows[-1], nums[0]))
                assert geoms[k].geom_type == "Polygon"
                ring = self.lay.area(nums[0], nums[1])
                assert sorted(ring.points) == sorted(nums)
            for row, nxt in pairs:
                assert lp["fwd"][row] == nxt
                assert lp["back"][lp["num"] == nxt][0] == lp["num"][row]

    @invariant()
    def counts_agree(self):
        """Records, lines and closed lines as each edit says it adds or removes them."""
        assert self.lay.counts() == self.n


TestLayerEdits = LayerMachine.TestCase
TestLayerEdits.settings = settings(
    max_examples=150, stateful_step_count=30, deadline=None, parent=settings.default
)
