"""Every button and mode of the compilation engine, with no I/O at all."""

from __future__ import annotations

import math

import pytest

import apygis
from apygis.compile.engine import (
    Added,
    CrosshairScale,
    Deleted,
    DisplayScale,
    Engine,
    Ignored,
    Keys,
    Mark,
    Message,
    Plates,
    Press,
    Save,
    Terminate,
    Undone,
    ZeroPlates,
    event_from_dict,
    event_to_dict,
)
from apygis.compile.geometry import PlaneGeometry
from apygis.model.symbols import default_library

E0, N0 = 2683000.0, 1247000.0


class PlatesGeometry(PlaneGeometry):
    """A plane map plus fake plates: steps proportional to the mark position."""

    def plates(self, X, Y, Z):
        return (round(X - E0), round(Y - N0), round(Z * 10), 0)


class Op:
    """An operator at the engine: ground positions in, effects collected."""

    def __init__(self, geometry=None, **kw):
        self.map = apygis.MapFile("T", scale=5000)
        self.geo = geometry or PlaneGeometry(E0, N0, scale=5000, height_step_m=0.05)
        self.eng = Engine(self.map, "r", self.geo, library=default_library(), **kw)
        self.effects = []

    def at(self, X, Y):
        x, y = self.geo.tablet(E0 + X, N0 + Y)
        return self.send(Mark(x, y))

    def press(self, *buttons):
        out = []
        for b in buttons:
            for part in list(b) if b.isdigit() else [b]:
                out += self.send(Press(part))
        return out

    def number(self, digits, then="ENTER"):
        return self.press(*digits, then)

    def send(self, ev):
        out = self.eng.handle(ev)
        self.effects += out
        return out

    def messages(self):
        return [e.text for e in self.effects if isinstance(e, Message)]

    @property
    def layer(self):
        return self.map.layers[self.eng.layer_ext]


def start_line(op, code="12", decimals=""):
    op.press("DESCR")
    op.number("2")
    op.number(decimals)
    op.number(code)


def test_symbol_mode_enter_rechoose_and_proceed():
    op = Op()
    op.press("DESCR")
    op.number("1")
    op.number("06")
    assert "symbol 06 church" in op.messages()
    op.at(10, 20)
    out = op.press("ENTER")
    assert Added("r", "symbols", 1) in out
    op.press("DELETE")  # rechoose
    op.number("23")
    op.at(30, 40)
    op.press("ENTER")
    s = op.layer.symbols
    assert s["code"].tolist() == [6, 23]
    assert (s["x"][1], s["y"][1]) == pytest.approx((E0 + 30, N0 + 40))
    out = op.press("PROCEED")
    assert op.eng.mode == "menu"
    assert Save("proceed") in out


def test_symbol_list_and_bad_numbers():
    op = Op()
    op.press("DESCR")
    op.number("1")
    op.press("PROCEED")
    assert any(m.startswith("symbols: 00 spot height, 01 trig point") for m in op.messages())
    op.number("123")
    assert "symbol: a number from 0 to 99, please" in op.messages()
    op.press("ENTER")  # the mark was never placed
    op.number("5")
    op.press("ENTER")
    assert "place the mark first" in op.messages()


def test_line_mode_points_rounding_and_proceed_twice():
    op = Op()
    start_line(op, "31", decimals="1")
    op.eng.z_model = 431.27
    for x in (0, 10, 20):
        op.at(x, 0)
        op.press("ENTER")
    lp = op.layer.line_points
    assert lp["code"].tolist() == [31, 31, 31]
    assert lp["z"].tolist() == [431.2] * 3  # rounded down to one decimal
    assert op.layer.closure(1).points == (1, 2, 3)
    op.press("PROCEED")  # leaves the line open
    assert op.eng.mode == "line"
    op.at(0, 50)
    op.press("ENTER")
    op.at(0, 60)
    op.press("ENTER")
    assert op.layer.counts()["lines"] == 2
    op.press("PROCEED", "PROCEED")
    assert op.eng.mode == "menu"


def test_search_closes_a_ring_and_makes_branches():
    op = Op()
    start_line(op, "21")
    for x, y in ((0, 0), (0, 10), (20, 10), (20, 0)):
        op.at(x, y)
        op.press("ENTER")
    op.at(0.5, 0.5)  # near the first point (snap: 1 mm at 1:5000 = 5 m)
    op.press("SEARCH")
    assert op.layer.closure(1).closed
    assert op.layer.area(1, 2).area_m2 == pytest.approx(200.0)
    # a branch starting at a junction: SEARCH first, then its points
    op.press("PROCEED")
    start_line(op, "12")
    for x in (100, 110, 120):
        op.at(x, 100)
        op.press("ENTER")
    op.press("PROCEED")
    op.at(110.4, 100.3)
    op.press("SEARCH")
    op.at(110, 130)
    op.press("ENTER")
    op.at(110, 140)
    op.press("ENTER")
    br = op.layer.branches()
    assert len(br) == 1
    assert br[0]["junction"] == 6
    # a line that ends on another line: SEARCH after its points
    op.press("PROCEED")
    op.at(130, 150)
    op.press("ENTER")
    op.at(120.2, 100.1)
    op.press("SEARCH")
    assert len(op.layer.branches()) == 2
    assert op.layer.validate() == []


def test_search_continues_a_line_end():
    op = Op()
    start_line(op)
    op.at(0, 0)
    op.press("ENTER")
    op.at(10, 0)
    op.press("ENTER", "PROCEED")
    op.at(10.3, 0.2)
    op.press("SEARCH")
    op.at(20, 0)
    op.press("ENTER")
    assert op.layer.counts()["lines"] == 1
    assert op.layer.closure(1).points == (1, 2, 3)
    op.at(500, 500)
    op.press("SEARCH")
    assert any("SEARCH: no line point within 5.00 m" in m for m in op.messages())


def test_sample_enters_points_by_the_across_track_rule():
    op = Op(sample_tolerance_mm=0.2)  # 1 m at 1:5000
    start_line(op)
    op.press("SAMPLE")
    op.at(0, 0)
    op.press("ENTER")
    op.at(10, 0)
    op.press("ENTER")
    # along the track: nothing is entered
    for x in range(11, 30):
        op.at(x, 0.5)
    assert len(op.layer.line_points) == 2
    op.at(30, 0.9)  # still inside the 1 m corridor
    out = op.at(35, 3.0)  # out: (30, 0.9) is entered
    added = [e for e in out if isinstance(e, Added)]
    assert len(added) >= 1
    lp = op.layer.line_points
    assert (lp["x"][2] - E0, lp["y"][2] - N0) == pytest.approx((30, 0.9))
    op.press("SAMPLE")  # off
    n = len(op.layer.line_points)
    op.at(80, 40)
    assert len(op.layer.line_points) == n


def test_text_mode():
    op = Op()
    op.press("DESCR")
    op.number("3")
    op.press("ENTER")
    assert "type the text first" in op.messages()
    op.send(Keys("Oberdorf"))
    op.at(5, 5)
    op.press("ENTER")
    assert op.layer.texts["text"].tolist() == ["Oberdorf"]
    op.send(Keys("x" * 30))
    op.press("ENTER")  # too long: the model refuses, the engine says so
    assert any("at most 24" in m for m in op.messages())
    assert len(op.layer.texts) == 1


def test_ls_splits_the_nearest_line_side():
    op = Op()
    start_line(op)
    for x in (0, 20):
        op.at(x, 0)
        op.press("ENTER")
    op.press("PROCEED", "PROCEED", "LS")
    op.at(8, 1)
    op.press("ENTER")
    assert op.layer.closure(1).points == (1, 3, 2)
    op.at(200, 200)
    op.press("ENTER")
    assert any("LS: no line side" in m for m in op.messages())


def test_area_reports_area_or_the_gap():
    op = Op()
    start_line(op)
    for x, y in ((0, 0), (0, 10), (20, 10), (20, 0)):
        op.at(x, y)
        op.press("ENTER")
    op.press("PROCEED", "PROCEED", "AREA")
    op.at(0, 0)
    op.press("ENTER")
    op.at(0, 10)
    op.press("ENTER")
    assert any(
        m.startswith("AREA: the line is not closed") and "gap 20.00 m" in m for m in op.messages()
    )
    op.layer.join(4, 1)
    op.at(0, 0)
    op.press("ENTER")
    op.at(0, 10)
    op.press("ENTER")
    assert any(m.startswith("AREA 200.00 m2") and "clockwise" in m for m in op.messages())


def test_dhi():
    op = Op()
    op.press("DHI")
    op.eng.z_model = 400.0
    op.at(0, 0)
    op.press("ENTER")
    op.eng.z_model = 405.0
    op.at(30, 40)
    op.press("ENTER")
    assert any(
        m.startswith("DHI distance 50.00 m, height difference +5.00 m") and "(10.00 %)" in m
        for m in op.messages()
    )


def test_delete_each_kind_repairs_lines():
    op = Op()
    start_line(op)
    for x in (0, 10, 20):
        op.at(x, 0)
        op.press("ENTER")
    op.press("PROCEED", "PROCEED", "DESCR")
    op.number("3")
    op.send(Keys("Weg"))
    op.at(50, 50)
    op.press("ENTER", "PROCEED", "DELETE")
    op.number("2")
    op.at(10.5, 0.5)
    out = op.press("ENTER")
    assert Deleted("r", "line_points", 2) in out
    assert op.layer.closure(1).points == (1, 3)
    op.press("PROCEED", "DELETE")
    op.number("3")
    op.at(50, 50)
    op.press("ENTER")
    assert len(op.layer.texts) == 0
    op.at(300, 300)
    op.press("ENTER")
    assert any("DELETE: nothing within" in m for m in op.messages())


def test_undo_takes_back_entries():
    op = Op()
    start_line(op)
    for x in (0, 10, 20):
        op.at(x, 0)
        op.press("ENTER")
    out = op.press("UNDO")
    assert Undone("r") in out
    assert len(op.layer.line_points) == 2
    op.at(30, 0)
    op.press("ENTER")  # the line goes on from the point before the undone one
    assert op.layer.closure(1).points == (1, 2, 3)
    op.press("UNDO", "UNDO", "UNDO", "UNDO")
    assert len(op.layer.line_points) == 0
    assert "nothing to undo" in op.messages()


def test_heights_step_and_correction_and_plates():
    class Corrected(PlatesGeometry):
        def correct_z(self, X, Y, z):
            return z + 0.001 * (X - E0)  # dpZ = A x

    op = Op(geometry=Corrected(E0, N0, scale=5000, height_step_m=0.05))
    op.eng.z_model = 400.0
    out = op.at(100, 0)
    assert Plates((100, 0, 4001, 0)) in out
    out = op.press("UP", "UP", "DOWN")
    assert [e for e in out if isinstance(e, Plates)][-1] == Plates((100, 0, 4002, 0))
    z = op.eng.mark()[2]
    assert z == pytest.approx(400.05 + 0.1)


def test_proceed_menu_items_and_terminate():
    op = Op()
    op.press("PROCEED")
    assert any(m.startswith("T.r: 0 symbols (0.0 %)") for m in op.messages())
    op.number("1")
    out = op.press("2", "POINT", "5", "ENTER")
    assert DisplayScale(2.5) in out
    assert op.eng.display_scale == 2.5
    op.number("1")
    op.number("30")
    assert "a value from 0.25 to 25.0, please" in op.messages()
    assert op.eng.mode == "proceed_value"  # until a value in range
    out = op.number("4")
    assert DisplayScale(4.0) in out
    assert op.eng.display_scale == 4.0
    out = op.number("2")
    assert ZeroPlates() in out
    op.number("3")
    op.send(Keys("0.5"))
    out = op.press("ENTER")
    assert CrosshairScale(0.5) in out
    assert op.eng.crosshair_scale == 0.5
    op.number("6")
    op.send(Keys("h"))
    op.press("ENTER")
    assert op.eng.layer_ext == "h"
    assert "h" in op.map.layers
    op.press("PROCEED")
    out = op.number("4")
    assert Save("terminate") in out
    assert Terminate() in out
    assert op.eng.terminated
    ignored = Ignored("ENTER", "terminated", "compilation terminated")
    assert op.eng.handle(Press("ENTER")) == [ignored]
    assert op.eng.handle(Mark(0.0, 0.0)) == [Message("compilation terminated")]


def test_autosave_every_fifty_entries():
    op = Op(autosave_every=50)
    op.press("DESCR")
    op.number("1")
    op.number("00")
    saves = 0
    for i in range(120):
        op.at(i, 0)
        saves += sum(isinstance(e, Save) for e in op.press("ENTER"))
    assert saves == 2
    assert op.eng.entries == 120


def test_capacity_is_reported_not_exceeded():
    op = Op()
    for i in range(1000):
        op.layer.add_symbol(E0 + i, N0, 0, 1)
    op.press("DESCR")
    op.number("1")
    op.number("01")
    op.at(5, 5)
    op.press("ENTER")
    assert "layer r: symbols full (1000)" in op.messages()
    assert len(op.layer.symbols) == 1000


def test_same_events_same_map():
    def run():
        op = Op()
        start_line(op)
        for k in range(30):
            op.at(3 * k, 10 * math.sin(k / 3))
            op.press("ENTER")
        return op

    a, b = run(), run()
    assert a.map == b.map


def test_event_dicts_round_trip():
    for ev in (Mark(1.5, -2.25), Press("ENTER"), Keys("Dorfbach")):
        assert event_from_dict(event_to_dict(ev)) == ev
    with pytest.raises(ValueError, match="not an event"):
        event_from_dict({"x": 1})


def test_step_shutter_and_status_counts():
    op = Op()
    op.eng.z_model = 100.0
    op.at(0, 0)
    op.press("STEP", "UP")
    assert op.eng.mark()[2] == pytest.approx(100.5)
    op.press("STEP", "UP")
    assert op.eng.mark()[2] == pytest.approx(100.55)
    out = op.press("SHUTTER")
    assert Message("floating mark seen in the model") in out
    status = out[-1]
    assert status.counts == {"symbols": 0, "line_points": 0, "texts": 0}


def test_a_mark_the_real_time_loop_refuses_moves_no_plate():
    """A mark behind a projection centre is told once; the plates wait, then follow again."""
    from apygis.compile.oriented import OrientedGeometry
    from apygis.orient.io import load_orientation
    from tests.conftest import SAMPLES

    orientation = load_orientation(SAMPLES / "session" / "ZH1091.orientation.json")
    eng = Engine(apygis.read(SAMPLES / "ZH1091"), "r", OrientedGeometry(orientation))
    assert any(isinstance(e, Plates) for e in eng.handle(Mark(100.0, 100.0)))
    far = eng.handle(Mark(1e7, 1e7))
    assert not any(isinstance(e, Plates) for e in far)
    (msg,) = [e for e in far if isinstance(e, Message)]
    assert msg.text.startswith("the plates stay where they are: ")
    assert "not in front of photo" in msg.text
    again = eng.handle(Mark(2e7, 1e7))  # still refused: no plates, told only once
    assert not any(isinstance(e, (Plates, Message)) for e in again)
    back = eng.handle(Mark(100.0, 101.0))
    assert any(isinstance(e, Plates) for e in back)
