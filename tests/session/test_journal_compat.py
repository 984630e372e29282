"""Version 2 journals written before the engine became an enum state machine (issue 10)
replay to the same map.

The journals in ``data/`` hold the events of two sessions, and the
``.expected.apa`` files the maps the engine of that time made of them:

* ``T10-v2``: 600 random events (marks, every button, typed text) with 47
  entries over a map with a closed line, an open line, a branch, symbols
  and texts;
* ``T10-v2-undo-sample``: a sampled line, a PROCEED to the menu, an UNDO
  there, then a new line: the UNDO brings SAMPLE back on, and the new line
  is sampled (docs/compilation.md, "UNDO and the line in progress").

The journal records events, not effects, so a change to what the engine does
with a version 2 journal's events would silently give another map on
recovery; this test fails first.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from apygis.compile.engine import Engine, Mode
from apygis.compile.geometry import PlaneGeometry
from apygis.formats import ascii as apa
from apygis.session.journal import read_journal

DATA = Path(__file__).parent / "data"
GEO = PlaneGeometry(2683000.0, 1247000.0, scale=5000, height_step_m=0.05)


@pytest.mark.parametrize(
    ("name", "mode", "entries"),
    [("T10-v2", Mode.PROCEED, 47), ("T10-v2-undo-sample", Mode.LINE, 15)],
)
def test_v2_journal_replays_to_the_map_it_gave(name, mode, entries):
    j = read_journal(DATA / f"{name}.journal")
    assert j.version == 2
    e = Engine(j.map, j.layer, GEO, **j.settings)
    for ev in j.events:
        e.handle(ev)
    assert apa.encode(j.map) == (DATA / f"{name}.expected.apa").read_bytes()
    assert e.mode is mode
    assert e.entries == entries
    if name == "T10-v2-undo-sample":
        assert e.state.sampling
