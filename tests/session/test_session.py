"""Sessions as an operator meets them: replay, the whole chain, noise, crashes."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
import tty

import numpy as np
import pytest
import serial
from click.testing import CliRunner

import apygis
from apygis.cli import main
from apygis.compile.engine import Mark, Press
from apygis.compile.oriented import OrientedGeometry
from apygis.errors import FormatError
from apygis.formats import ascii as apa
from apygis.instrument.motors import SimulatedGrbl, open_controller
from apygis.instrument.replay import Chunk, Replayer
from apygis.instrument.simulator import BUTTONS, ScriptBuilder, VirtualInstrument
from apygis.instrument.tablet import TabletConfig, make_parser
from apygis.orient.io import load_orientation
from apygis.session import ReportDecoder, Session, run_live, run_tablet_stream
from apygis.session.journal import read_journal
from tests.conftest import ROOT, SAMPLES

SESSION = SAMPLES / "session"
ORIENTATION = SESSION / "ZH1091.orientation.json"
RECORDING = SESSION / "ZH1091-revision.rec"
CFG = TabletConfig(counts_per_mm=40.0)


@pytest.fixture(scope="module")
def geometry():
    return OrientedGeometry(load_orientation(ORIENTATION))


def _replay_cli(out_dir, *extra):
    res = CliRunner().invoke(
        main,
        ["session", str(SAMPLES / "ZH1091"), "--orientation", str(ORIENTATION),
         "--replay", str(RECORDING), "-o", str(out_dir), *extra],
        catch_exceptions=False,
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    return res.output


def test_sample_session_replays_to_the_expected_map_every_time(tmp_path):
    out1 = _replay_cli(tmp_path / "a")
    _replay_cli(tmp_path / "b", "--motors", "sim")
    expected = apygis.read(SESSION / "ZH1091-revision.expected.apa")
    for d in ("a", "b"):
        assert apygis.read(tmp_path / d / "ZH1091") == expected
        assert not (tmp_path / d / "ZH1091.journal").exists()  # terminated cleanly
    for ext in "cehr":
        a = (tmp_path / "a" / f"ZH1091.{ext}").read_bytes()
        assert a == (tmp_path / "b" / f"ZH1091.{ext}").read_bytes()
    assert "compilation terminated" in out1
    assert "tablet: " in out1
    assert " 0 bytes discarded" in out1


def test_sample_session_did_what_the_script_says(tmp_path):
    """Checks against the script's intent, independent of the expected file."""
    _replay_cli(tmp_path)
    before = apygis.read(SAMPLES / "ZH1091")
    after = apygis.read(tmp_path / "ZH1091")
    r0, r1, h0, h1 = before.layers["r"], after.layers["r"], before.layers["h"], after.layers["h"]
    # a new closed house of 14 m x 10 m (tablet resolution 0.025 mm = 0.125 m on the ground)
    assert r1.counts()["closed_lines"] == r0.counts()["closed_lines"] + 1
    cs = r1.chains()
    new_rings = [k for k in np.flatnonzero(cs.closed) if r1.line_points["num"][cs.rows(k)[0]] > 146]
    (k,) = new_rings
    a, b = (int(v) for v in r1.line_points["num"][cs.rows(k)[:2]])
    area = r1.area(a, b)
    assert area.clockwise
    assert area.area_m2 == pytest.approx(140.0, abs=0.125 * 48)
    # the Lindenweg branches off the Hauptstrasse, sampled: more than the entered points
    assert len(r1.branches()) == len(r0.branches()) + 1
    lind = max((cs.rows(k) for k in range(len(cs))), key=lambda rows: rows.min())
    assert len(lind) > 8
    # symbols: a fountain and a bus stop added, the well undone, one old bus stop deleted
    codes0, codes1 = r0.symbols["code"].tolist(), r1.symbols["code"].tolist()
    assert codes1.count(28) == codes0.count(28) + 1
    assert codes1.count(36) == codes0.count(36)
    assert 26 not in codes1
    assert len(r1.symbols) == len(r0.symbols) + 1
    assert {"Neubau", "Lindenweg"} <= set(r1.texts["text"].tolist())
    # the ditch ends on the Dorfbach: a branch in h
    assert len(h1.branches()) == len(h0.branches()) + 1
    assert h1.validate() == []
    assert r1.validate() == []
    margin = apygis.read(tmp_path / "ZH1091-margin.apa")
    n_margin = sum(len(lay.line_points) for lay in margin)
    assert n_margin == sum(len(lay.margin_points()) for lay in after)


def test_whole_chain_over_a_pty_to_a_simulated_controller(tmp_path, geometry):
    """simulator -> bytes -> pty -> parser -> engine -> orientation -> G-code -> controller."""
    b = ScriptBuilder(CFG, rate=200.0)
    pts = [(2684100.0 + 20 * k, 1247900.0 + 5 * k) for k in range(6)]
    b.move(*geometry.tablet(*pts[0]))
    for name in ("DESCR", "1", "ENTER", "2", "3", "ENTER"):
        b.button(name)
    for X, Y in pts[:3]:
        b.glide(*geometry.tablet(X, Y), 0.05).button("ENTER")
    for name in ("PROCEED", "DESCR", "2", "ENTER", "ENTER", "1", "2", "ENTER"):
        b.button(name)
    for X, Y in pts[3:]:
        b.glide(*geometry.tablet(X, Y), 0.05).button("UP").button("ENTER")
    for name in ("PROCEED", "PROCEED", "PROCEED", "4", "ENTER"):
        b.button(name)
    data = VirtualInstrument("calcomp", config=CFG).tablet_bytes(b.build())

    sim = SimulatedGrbl()
    ctl = open_controller(sim.serve_tcp())
    master, slave = os.openpty()
    port = serial.serial_for_url(os.ttyname(slave), timeout=0.002)
    sess = Session(tmp_path / "T1", geometry, layer="r", motors=ctl, scale=5000)
    parser = make_parser("calcomp", CFG)

    def feed():
        for i in range(0, len(data), 60):
            os.write(master, data[i : i + 60])
            time.sleep(0.001)

    writer = threading.Thread(target=feed, daemon=True)
    watchdog = threading.Timer(30.0, port.close)
    writer.start()
    watchdog.start()
    try:
        run_live(sess, port, parser, ReportDecoder(CFG, BUTTONS))
    finally:
        watchdog.cancel()
        port.close()
        os.close(master)
        os.close(slave)
    assert sess.finished
    lay = apygis.read(tmp_path / "T1").layers["r"]
    assert lay.symbols["code"].tolist() == [23, 23, 23]
    assert len(lay.line_points) == 3
    ctl.drain()
    moves = [line for line in sim.received if line.startswith(("G0", "G1"))]
    assert len(moves) > 20
    last = sess.geometry.plates(*sess.engine.mark())
    assert tuple(round(v) for v in (sim.mpos[a] for a in "XYZA")) == last
    ctl.close()
    sim.stop()


def test_noisy_serial_line_compiles_the_same_map(tmp_path, geometry):
    """Random bytes, dropped bytes and duplicates on the line: the same map comes out.

    A tablet in stream mode sends a report again and again; here a third of
    the reports are sent twice and the first copy is damaged: a burst of up
    to four random bytes after it (shorter than a packet, the parser's stated
    damage model), a byte dropped from it, or nothing (a plain duplicate).
    The parser must throw the damaged copies away and resynchronise, invent
    no point, and the session must compile exactly the expected map. UP and
    DOWN repeat while held, so their reports are not duplicated.
    """
    rng = np.random.default_rng(11)
    noisy = []
    for ch in Replayer(RECORDING).chunks():
        if ch.channel == "tablet" and rng.random() < 0.35:
            one = make_parser("calcomp", CFG)
            (report,) = one.feed(ch.data) + one.flush()
            if BUTTONS.get(report.button) not in ("UP", "DOWN"):
                kind = rng.integers(0, 3)
                if kind == 0:
                    junk = bytes(rng.integers(0, 256, rng.integers(1, 5)))
                    noisy.append(Chunk(ch.t, "tablet", ch.data + junk))
                elif kind == 1:
                    cut = int(rng.integers(1, len(ch.data)))
                    noisy.append(Chunk(ch.t, "tablet", ch.data[:cut] + ch.data[cut + 1 :]))
                else:
                    noisy.append(ch)
        noisy.append(ch)
    m = apygis.read(SAMPLES / "ZH1091")
    apygis.write(m, tmp_path / "ZH1091")
    parser = make_parser("calcomp", CFG)
    sess = Session(tmp_path / "ZH1091", geometry, layer="c")
    run_tablet_stream(sess, noisy, parser, ReportDecoder(CFG, BUTTONS))
    assert sess.finished
    assert parser.discarded_bytes > 200
    assert parser.resyncs > 50
    assert apygis.read(tmp_path / "ZH1091") == apygis.read(SESSION / "ZH1091-revision.expected.apa")


def crash_with_a_line_in_progress(base, geometry) -> None:
    """A session at ``base`` that entered 3 points of a line (layer r), then crashed.

    Its journal holds 13 events and a torn last line; its lock is gone.
    """
    s1 = Session(base, geometry, layer="r", scale=5000)
    s1.handle_all(Press(b) for b in ("DESCR", "2", "ENTER", "ENTER", "1", "1", "ENTER"))
    for k in range(3):
        s1.handle(Mark(*geometry.tablet(2684000.0 + 10 * k, 1247800.0)))
        s1.handle(Press("ENTER"))
    s1.journal._fh.flush()  # what a crash after the last fsync leaves behind
    with open(s1.journal_path, "ab") as fh:
        fh.write(b'{"press": "EN')  # a torn last line
    s1.lock.release()  # the crash: the kernel drops the dead process's lock


def test_recovery_restores_records_and_the_line_in_progress(tmp_path, geometry):
    base = tmp_path / "T2"
    crash_with_a_line_in_progress(base, geometry)
    lines = []
    s2 = Session(base, geometry, layer="c", monitor=lines.append)
    assert s2.recovered == 3 + 7 + 3
    assert s2.engine.mode == "line"
    assert s2.engine.state.end == 3
    s2.handle(Mark(*geometry.tablet(2684040.0, 1247800.0)))
    s2.handle(Press("ENTER"))
    assert s2.map.layers["r"].closure(1).points == (1, 2, 3, 4)
    assert any(line.startswith("recovered 13 journaled events") for line in lines)
    s2.close()
    j = read_journal(s2.journal_path)
    assert len(j.events) == 15
    assert not j.truncated


def test_damaged_journal_is_a_clear_error(tmp_path, geometry):
    s = Session(tmp_path / "T3", geometry, layer="r")
    s.handle(Press("DESCR"))
    s.close()
    with open(s.journal_path, "ab") as fh:
        fh.write(b"not json\n")
    with pytest.raises(FormatError, match=r"T3.journal: line 3: bad journal event"):
        Session(tmp_path / "T3", geometry)


def _crash_script(geometry):
    b = ScriptBuilder(CFG, rate=400.0)
    b.move(*geometry.tablet(2684000.0, 1247700.0))
    for name in ("DESCR", "1", "ENTER", "0", "0", "ENTER"):
        b.button(name)
    for k in range(70):
        X, Y = 2684000.0 + 7.0 * (k % 10), 1247700.0 + 9.0 * (k // 10)
        b.glide(*geometry.tablet(X, Y), 0.02).button("UP").button("ENTER")
    for name in ("PROCEED", "DESCR", "2", "ENTER", "ENTER", "3", "1", "ENTER"):
        b.button(name)
    for k in range(60):
        b.glide(*geometry.tablet(2684200.0 + 5.0 * k, 1247800.0 + 3.0 * np.sin(k)), 0.02)
        b.button("ENTER")
    return VirtualInstrument("calcomp", config=CFG).tablet_bytes(b.build())


def _reference_states(tmp_path, geometry, data):
    """The map after each entry, replaying the same bytes in this process."""
    sess = Session(tmp_path / "ref" / "T1", geometry, layer="r")
    states = {0: apa.encode(sess.map)}
    parser, dec = make_parser("calcomp", CFG), ReportDecoder(CFG, BUTTONS)
    for report in parser.feed(data) + parser.flush():
        for ev in dec.events(report):
            sess.handle(ev)
            states.setdefault(sess.entries, apa.encode(sess.map))
    return states


@pytest.mark.parametrize("trial", range(3))
def test_sigkill_loses_no_acknowledged_entry(tmp_path, geometry, trial):
    data = _crash_script(geometry)
    states = _reference_states(tmp_path, geometry, data)
    base = tmp_path / "run" / "T1"
    base.parent.mkdir()
    master, slave = os.openpty()
    tty.setraw(slave)  # no echo or line editing, even before the session opens the port
    cmd = [sys.executable, "-m", "apygis", "session", str(base), "--orientation", str(ORIENTATION),
           "--tablet", f"calcomp:{os.ttyname(slave)}", "--layer", "r"]  # fmt: skip
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, cwd=ROOT, env=env, text=True
    )
    out: list[str] = []
    ready = threading.Event()

    def read_out():
        for line in proc.stdout:
            out.append(line)
            if line.startswith("tablet calcomp on"):
                ready.set()

    threading.Thread(target=read_out, daemon=True).start()

    def feed():
        for i in range(0, len(data), 30):
            try:
                os.write(master, data[i : i + 30])
            except OSError:
                return
            time.sleep(0.0005)

    try:
        assert ready.wait(30), "the session did not start"
        rng = np.random.default_rng(trial)
        kill_at = int(rng.integers(1, 110))  # entries acknowledged before the kill
        threading.Thread(target=feed, daemon=True).start()
        deadline = time.monotonic() + 60
        while (
            time.monotonic() < deadline and sum(line.startswith("entry") for line in out) < kill_at
        ):
            time.sleep(0.002)
        time.sleep(float(rng.uniform(0, 0.02)))
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
        os.close(slave)
    time.sleep(0.1)
    acked = [int(m.group(1)) for line in out if (m := re.match(r"entry (\d+):", line))]
    # every layer file on disk is readable, whatever moment the kill hit
    for p in base.parent.glob("T1.[a-z]"):
        apygis.read(p)
    rec = subprocess.run(
        [*cmd[:7], "--recover-only"], capture_output=True, text=True, cwd=ROOT, check=True
    )
    m = re.search(r"recovered \d+ journaled events of map T1: (\d+) entries", rec.stdout)
    assert m, rec.stdout + rec.stderr
    recovered = int(m.group(1))
    assert len(acked) >= kill_at
    assert recovered >= max(acked)
    got = apa.encode(apygis.read(base)) if recovered else states[0]
    want = states[recovered]
    if recovered:
        # the saved map holds the layers with records
        assert apygis.read(base) == _nonempty(apa.decode(want))
    else:
        assert got == want


def _nonempty(m):
    for ext in [e for e, lay in m.layers.items() if not len(lay)]:
        del m.layers[ext]
    return m


def test_session_takes_a_pad_file(tmp_path):
    pad = tmp_path / "same.pad"
    pad.write_text("11 ENTER\n13 PROCEED\n")
    _replay_cli(tmp_path / "a", "--pad", str(pad))
    expected = apygis.read(SESSION / "ZH1091-revision.expected.apa")
    assert apygis.read(tmp_path / "a" / "ZH1091") == expected
    pad.write_text("11 JUMP\n")
    res = CliRunner().invoke(
        main,
        ["session", str(SAMPLES / "ZH1091"), "--orientation", str(ORIENTATION),
         "--replay", str(RECORDING), "-o", str(tmp_path / "b"), "--pad", str(pad)],
    )  # fmt: skip
    assert res.exit_code == 1
    assert "same.pad: line 1: unknown button 'JUMP'" in res.output
