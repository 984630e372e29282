"""Every button in every mode, against the table of docs/compilation.md.

The table says, for each mode and each mode-dependent button, whether the
engine acts or ignores it ("-"); a second table lists the buttons that act
the same in every mode but ``terminated``. The engine is driven into each
mode (on a map with a line, a symbol and a text near the mark) and every
one of the 27 buttons is pressed there. An ignored press must answer
:class:`Ignored` and change nothing (mode, mode state, digits, records);
an action must not answer :class:`Ignored`.
"""

from __future__ import annotations

import copy
import re

import pytest

import apygis
from apygis.compile.engine import (
    GLOBAL_BUTTONS,
    HINTS,
    MODE_BUTTONS,
    MODE_STATE,
    Engine,
    Ignored,
    Keys,
    Mark,
    Mode,
    Press,
)
from apygis.compile.geometry import PlaneGeometry
from apygis.instrument.pad import BUTTONS
from tests.conftest import ROOT

E0, N0 = 2683000.0, 1247000.0
GEO = PlaneGeometry(E0, N0, scale=5000, height_step_m=0.05)
DOC = ROOT / "docs" / "compilation.md"

#: How to reach each mode from the menu.
PATHS: dict[Mode, list] = {
    Mode.MENU: [],
    Mode.DESCR: ["DESCR"],
    Mode.SYMBOL_CHOOSE: ["DESCR", "1", "ENTER"],
    Mode.SYMBOL_PLACE: ["DESCR", "1", "ENTER", "0", "6", "ENTER"],
    Mode.LINE_ROUND: ["DESCR", "2", "ENTER"],
    Mode.LINE_CODE: ["DESCR", "2", "ENTER", "ENTER"],
    Mode.LINE: ["DESCR", "2", "ENTER", "ENTER", "1", "2", "ENTER"],
    Mode.TEXT: ["DESCR", "3", "ENTER", Keys("Dorf")],
    Mode.SPLIT: ["LS"],
    Mode.AREA: ["AREA"],
    Mode.DHI: ["DHI"],
    Mode.DELETE_CHOOSE: ["DELETE"],
    Mode.DELETE_PLACE: ["DELETE", "1", "ENTER"],
    Mode.PROCEED: ["PROCEED"],
    Mode.PROCEED_VALUE: ["PROCEED", "1", "ENTER"],
    Mode.LAYER_CHOOSE: ["PROCEED", "6", "ENTER"],
    Mode.TERMINATED: ["PROCEED", "4", "ENTER"],
}


def _tables() -> tuple[dict[str, dict[str, str]], set[str]]:
    """(mode -> button -> "action"/"ignored", the every-mode buttons) from the docs."""
    lines = DOC.read_text(encoding="utf-8").splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("| mode | ENTER |"))
    header = [c.strip() for c in lines[start].strip("|").split("|")][1:]
    table: dict[str, dict[str, str]] = {}
    for ln in lines[start + 2 :]:
        if not ln.startswith("|"):
            break
        cells = [c.strip() for c in ln.strip().strip("|").split("|")]
        mode = cells[0].strip("`")
        assert len(cells) == len(header) + 1, f"docs table row {mode}: {len(cells)} cells"
        table[mode] = {
            b: "ignored" if c == "-" else "action" for b, c in zip(header, cells[1:], strict=True)
        }
    start = next(i for i, ln in enumerate(lines) if ln.startswith("| button | in every mode"))
    every: set[str] = set()
    for ln in lines[start + 2 :]:
        if not ln.startswith("|"):
            break
        first = ln.strip("|").split("|")[0]
        for lo, hi in re.findall(r"`(\d)`-`(\d)`", first):  # a range of digits
            every.update(str(d) for d in range(int(lo), int(hi) + 1))
        every.update(re.findall(r"`([^`]+)`", re.sub(r"`\d`-`\d`", "", first)))
    return table, every


TABLE, EVERY = _tables()


def _engine_in(mode: Mode) -> Engine:
    m = apygis.MapFile("T", scale=5000)
    r = m.layer("r")
    r.add_line([(E0, N0, 400.0), (E0 + 20, N0, 400.0), (E0 + 20, N0 + 20, 400.0)], 11)
    r.add_symbol(E0 + 1, N0 + 1, 400.0, 6)
    r.add_text(E0 + 1, N0 - 1, 400.0, "Weg")
    e = Engine(m, "r", GEO, start_z_m=400.0)
    e.handle(Mark(*GEO.tablet(E0 + 0.5, N0 + 0.5)))
    for step in PATHS[mode]:
        e.handle(step if isinstance(step, Keys) else Press(step))
    assert e.mode is mode, f"the path to {mode} ends in {e.mode}"
    return e


def _snapshot(e: Engine) -> tuple:
    lay = e.layer
    recs = (lay.symbols.tobytes(), lay.line_points.tobytes(), lay.texts.tobytes())
    return (e.mode, copy.deepcopy(e.state), e.buf, e.layer_ext, recs, e.entries, e.z_model)


def test_the_docs_table_covers_every_mode_and_button():
    assert set(TABLE) == {m.value for m in Mode}
    assert set(next(iter(TABLE.values()))) == set(MODE_BUTTONS)
    assert {*GLOBAL_BUTTONS, "DELETE"} == EVERY
    assert set(MODE_BUTTONS) | set(GLOBAL_BUTTONS) == set(BUTTONS.values())
    assert set(PATHS) == set(Mode) == set(Engine.HANDLERS) == set(MODE_STATE) == set(HINTS)


@pytest.mark.parametrize("mode", list(Mode), ids=lambda m: m.value)
def test_each_mode_answers_every_button_as_documented(mode):
    for button in sorted(set(BUTTONS.values())):
        e = _engine_in(mode)
        before = _snapshot(e)
        out = e.handle(Press(button))
        ignored = [x for x in out if isinstance(x, Ignored)]
        if mode is Mode.TERMINATED:
            want = "ignored"
        elif button in MODE_BUTTONS:
            want = TABLE[mode.value][button]
        else:
            want = "action"
        got = "ignored" if ignored else "action"
        assert got == want, f"{button} in {mode}: the engine's answer is {got}, docs say {want}"
        if ignored:
            assert ignored == [Ignored(button, mode.value, HINTS[mode])]
            assert _snapshot(e) == before, f"ignored {button} in {mode} changed the engine"
            assert ignored[0].text.startswith(f"{button}: ignored in {mode.value} mode; ")


@pytest.mark.parametrize("mode", [m for m in Mode if m is not Mode.TERMINATED], ids=str)
def test_delete_with_digits_typed_clears_them_in_every_mode(mode):
    e = _engine_in(mode)
    e.handle(Press("7"))
    assert e.buf.endswith("7")
    before_mode = e.mode
    out = e.handle(Press("DELETE"))
    assert not any(isinstance(x, Ignored) for x in out)
    assert e.buf == ""
    assert e.mode is before_mode


def test_a_mode_change_installs_the_new_modes_own_state():
    e = _engine_in(Mode.AREA)
    e.handle(Press("ENTER"))  # the first AREA point: a line point number
    assert e.state.first == 1
    e.handle(Press("PROCEED"))
    e.handle(Press("DHI"))
    assert type(e.state) is MODE_STATE[Mode.DHI]
    assert e.state.first is None  # nothing of AREA's pick leaks into DHI
    for mode in Mode:
        assert type(_engine_in(mode).state) is MODE_STATE[mode]
