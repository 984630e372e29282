"""Make the recorded sample revision session of sheet ZH1091 (deterministic).

An operator revises the sample sheet ``samples/ZH1091`` on the instrument:

* switches to layer ``r`` (PROCEED menu, item 6);
* digitises a new house as a closed line (SEARCH on its first corner closes
  the ring) and measures its AREA;
* digitises a new road, the Lindenweg, branching off the Hauptstrasse
  (SEARCH on the junction first), with SAMPLE on along a curve, then splits
  one of its sides (LS);
* places a fountain, re-chooses (DELETE) and places a bus stop; UNDO takes
  back a well placed by mistake;
* types and places two texts;
* deletes an old bus stop (DELETE, item 1);
* measures DHI between two points after raising the mark (UP, STEP);
* switches to layer ``h`` and digitises a ditch that ends on the Dorfbach
  (SEARCH at its end: a branch);
* terminates (PROCEED menu, item 4): layer files and margin file written.

The tablet is a CalComp binary tablet (27-button cursor, 40 counts/mm) at
50 reports/s; the mark glides between positions as a hand would move it.
Ground positions go to tablet millimetres through the inverse of the map
orientation in ``ZH1091.orientation.json`` (the truth orientation of the
orientation samples, with plate motor calibrations added).

Writes, next to this script:

* ``ZH1091.orientation.json``: the orientation the session uses;
* ``ZH1091-revision.rec``: the recording (``docs/protocols.md``);
* ``ZH1091-revision.expected.apa``: the map the replay must produce, for
  the tests.

Run: ``python samples/session/make_session_sample.py``
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
sys.path.insert(0, str(ROOT))

import apygis  # noqa: E402
from apygis.compile.oriented import OrientedGeometry  # noqa: E402
from apygis.instrument.replay import Recorder  # noqa: E402
from apygis.instrument.simulator import ScriptBuilder, VirtualInstrument  # noqa: E402
from apygis.instrument.tablet import TabletConfig  # noqa: E402
from apygis.orient.io import load_orientation, save_orientation  # noqa: E402
from apygis.orient.realtime import MotorCalibration  # noqa: E402

RATE = 50.0
PROTOCOL = "calcomp"
COUNTS_PER_MM = 40.0


def orientation():
    o = load_orientation(ROOT / "samples" / "orient" / "ZH1091-truth.orientation.json")
    motors = tuple(
        MotorCalibration(p.photo_id, step_um=2.5, plate_rotation_rad=0.004 * (k + 1))
        for k, p in enumerate(o.photos)
    )
    return o.replace(map_id="ZH1091", motors=motors)


class Operator:
    """Builds the tablet script from ground positions and button presses."""

    def __init__(self, geometry):
        self.g = geometry
        self.b = ScriptBuilder(TabletConfig(counts_per_mm=COUNTS_PER_MM), rate=RATE)
        self.at = None

    def go(self, X, Y, seconds=0.4):
        x, y = self.g.tablet(X, Y)
        if self.at is None:
            self.b.move(x, y)
        else:
            self.b.glide(x, y, seconds)
        self.at = (X, Y)
        return self

    def press(self, *names):
        for name in names:
            for part in list(name) if name.isdigit() else [name]:
                self.b.button(part)
                self.b.wait(0.15)
        return self

    def type(self, text):
        self.b.wait(0.5)
        self.b.type(text)
        self.b.wait(0.2)
        return self


def script(m, g):
    """The operator's actions over the sample map ``m``."""
    lay_r, lay_h = m.layers["r"], m.layers["h"]
    road = lay_r.line_points[lay_r.chains().rows(0)]  # the Hauptstrasse
    bus = lay_r.symbols[lay_r.symbols["code"] == 36]
    stream = lay_h.line_points[lay_h.chains().rows(0)]  # the Dorfbach
    op = Operator(g)
    E, N = 2_684_500.0, 1_247_950.0
    op.go(E, N)
    op.press("PROCEED", "6", "ENTER").type("r").press("ENTER")
    # a new house, corners clockwise (seen from above), closed by SEARCH
    op.press("DESCR", "2", "ENTER", "ENTER", "21", "ENTER")
    house = [(E, N), (E, N + 10.0), (E + 14.0, N + 10.0), (E + 14.0, N)]
    for X, Y in house:
        op.go(X, Y).press("ENTER")
    op.go(E + 0.8, N + 0.6).press("SEARCH", "PROCEED")
    op.press("AREA").go(*house[0]).press("ENTER").go(*house[1]).press("ENTER", "PROCEED")
    # the Lindenweg: branch off the Hauptstrasse, sampled along a curve
    junction = road[27]
    op.press("DESCR", "2", "ENTER", "1", "ENTER", "12", "ENTER")
    op.go(junction["x"] + 1.5, junction["y"] - 1.0).press("SEARCH")
    op.press("SAMPLE")
    start = (junction["x"] + 6.0, junction["y"] + 25.0)
    op.go(*start).press("ENTER").go(start[0] + 4.0, start[1] + 30.0).press("ENTER")
    for k in range(1, 25):
        t = k / 24
        X = start[0] + 8.0 + 90.0 * t
        Y = start[1] + 30.0 + 160.0 * t + 25.0 * math.sin(math.pi * t)
        op.go(X, Y, seconds=0.25)
    op.press("ENTER", "SAMPLE", "PROCEED", "PROCEED")
    lind_end = op.at
    op.press("LS").go(start[0] + 2.0, start[1] + 15.0).press("ENTER", "PROCEED")
    # symbols: a fountain, then re-choose and a bus stop; a well placed by mistake is undone
    op.press("DESCR", "1", "ENTER", "28", "ENTER").go(E - 20.0, N + 5.0).press("ENTER")
    op.press("DELETE", "36", "ENTER").go(lind_end[0] + 8.0, lind_end[1]).press("ENTER")
    op.press("DELETE", "26", "ENTER").go(E - 40.0, N).press("ENTER", "UNDO", "PROCEED")
    # texts
    op.press("DESCR", "3", "ENTER").type("Neubau").go(E + 16.0, N + 12.0).press("ENTER")
    op.type("Lindenweg").go(start[0] + 30.0, start[1] + 90.0).press("ENTER", "PROCEED")
    # an old bus stop is gone
    op.press("DELETE", "1", "ENTER").go(bus["x"][0] + 0.5, bus["y"][0] - 0.5).press("ENTER")
    op.press("PROCEED")
    # DHI from the house to the end of the Lindenweg, the mark raised first
    op.press("DHI").go(*house[2]).press("ENTER", "STEP", "UP", "UP", "STEP", "UP")
    op.go(*lind_end).press("ENTER", "PROCEED")
    # layer h: a ditch that ends on the Dorfbach
    op.press("PROCEED", "6", "ENTER").type("h").press("ENTER")
    op.press("DESCR", "2", "ENTER", "1", "ENTER", "34", "ENTER")
    s = stream[33]
    for dx, dy in ((-60.0, 140.0), (-35.0, 90.0), (-15.0, 40.0)):
        op.go(s["x"] + dx, s["y"] + dy).press("DOWN", "ENTER")
    op.go(s["x"] + 0.7, s["y"] - 0.4).press("SEARCH", "PROCEED")
    op.press("PROCEED", "4", "ENTER")
    return op.b.build()


def make(outdir: Path = HERE) -> None:
    from apygis.instrument.replay import Replayer
    from apygis.instrument.simulator import BUTTONS
    from apygis.instrument.tablet import make_parser
    from apygis.session import ReportDecoder, Session, run_tablet_stream

    o = orientation()
    save_orientation(o, outdir / "ZH1091.orientation.json")
    g = OrientedGeometry(o)
    m = apygis.read(ROOT / "samples" / "ZH1091")
    sc = script(m, g)
    rec_path = outdir / "ZH1091-revision.rec"
    meta = {
        "protocol": PROTOCOL,
        "counts_per_mm": COUNTS_PER_MM,
        "created": "2026-11-22T10:00:00Z",
        "note": "sample revision session of ZH1091, made by make_session_sample.py",
    }
    rec_tmp = rec_path.with_name(rec_path.name + ".tmp")
    with Recorder(rec_tmp, overwrite=True, fsync=False, meta=meta) as rec:
        for ch in VirtualInstrument(PROTOCOL, rate=RATE).chunks(sc):
            rec.record(ch.channel, ch.data, t=round(ch.t, 6))
    rec_tmp.replace(rec_path)
    with tempfile.TemporaryDirectory() as tmp:
        apygis.write(m, Path(tmp) / "ZH1091")
        cfg = TabletConfig(counts_per_mm=COUNTS_PER_MM)
        sess = Session(Path(tmp) / "ZH1091", g, layer="c")
        parser, decoder = make_parser(PROTOCOL, cfg), ReportDecoder(cfg, BUTTONS)
        run_tablet_stream(sess, Replayer(rec_path).chunks(), parser, decoder)
        if not sess.finished:
            raise SystemExit("the sample session did not terminate")
        result = apygis.read(Path(tmp) / "ZH1091")
    apygis.write(result, outdir / "ZH1091-revision.expected.apa")


if __name__ == "__main__":
    make()
