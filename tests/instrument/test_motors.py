"""The plate motor client against the simulated grblHAL controller (pty, socket, direct)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from apygis.errors import ApygisError, InstrumentError, MotorError, ProtocolError
from apygis.instrument.motors import (
    MotorController,
    SimulatedGrbl,
    format_move,
    open_controller,
    parse_status,
)

from .conftest import DirectPort

# --------------------------------------------------------------------------- over pty and socket


def test_moves_and_status(served_sim):
    sim, url = served_sim
    with open_controller(url, timeout=2.0) as ctl:
        assert ctl.banner.startswith("GrblHAL")
        assert ctl.move_to(x=120, y=-35, z=98, a=-40) == "G0 X120 Y-35 Z98 A-40"
        ctl.move_to(x=121, feed=6000)
        st = ctl.status()
        assert st.state == "Idle"
        assert st.idle
        assert st.steps == (121, -35, 98, -40)
        assert ctl.position == {"X": 121, "Y": -35, "Z": 98, "A": -40}
        assert sim.received[-1] == "G1 X121 F6000"
        assert "G21 G90" in sim.received


def test_error_line_raises_motor_error(served_sim):
    _sim, url = served_sim
    with open_controller(url, timeout=2.0) as ctl:
        with pytest.raises(MotorError) as info:
            ctl.command("G1 X5")  # no feed rate yet
        err = info.value
        assert err.code == 22
        assert err.line == "G1 X5"
        assert err.port == url
        assert "error:22" in str(err)
        assert url in str(err)
        with pytest.raises(MotorError) as info:
            ctl.move_to(x=10**6)  # beyond the soft limits
        assert info.value.code == 15
        assert ctl.status().steps == (0, 0, 0, 0)  # position kept
        ctl.move_to(x=7)  # the session goes on
        assert ctl.status().steps[0] == 7
        assert isinstance(info.value, InstrumentError)
        assert isinstance(info.value, OSError)


def test_timeout_names_port_and_command(served_sim):
    sim, url = served_sim
    with open_controller(url, timeout=0.3) as ctl:
        sim.mute = True
        t0 = time.monotonic()
        with pytest.raises(MotorError) as info:
            ctl.move_to(x=1, y=2)
        elapsed = time.monotonic() - t0
        assert 0.25 < elapsed < 2.0
        msg = str(info.value)
        assert url in msg
        assert "G0 X1 Y2" in msg
        assert "no answer" in msg
        assert info.value.line == "G0 X1 Y2"
        with pytest.raises(MotorError, match="no status report"):
            ctl.status()


def test_no_banner(served_sim):
    sim, url = served_sim
    sim.mute = True
    sim.banner = ""  # a silent device
    with pytest.raises(MotorError, match="no Grbl banner") as info:
        open_controller(url, timeout=0.2)
    assert info.value.port == url


def test_pipelined_moves(served_sim):
    _sim, url = served_sim
    with open_controller(url, timeout=2.0) as ctl:
        for i in range(60):
            ctl.move_to(x=i, y=-i, z=2 * i, a=-2 * i, wait=False)
            assert sum(len(s) + 1 for s in ctl_sent(ctl)) <= ctl.rx_buffer
        ctl.drain()
        assert ctl.pending == 0
        assert ctl.wait_idle().steps == (59, -59, 118, -118)


def ctl_sent(ctl):
    return [e.line for e in ctl._sent]


def test_banner_on_connect_tcp():
    with SimulatedGrbl(banner_on_connect=True, banner="Grbl 1.1h ['$' for help]") as sim:
        url = sim.serve_tcp()
        with open_controller(url, timeout=2.0) as ctl:
            ctl.move_to(x=3)
            assert ctl.banner.startswith("Grbl 1.1h")
            assert ctl.status().steps[0] == 3


def test_open_bad_url():
    with pytest.raises(MotorError, match="cannot open"):
        open_controller("socket://127.0.0.1:1", timeout=0.2)


# --------------------------------------------------------------------------- in-process


def connected(sim: SimulatedGrbl, timeout: float = 0.5) -> MotorController:
    ctl = MotorController(DirectPort(sim), timeout=timeout)
    ctl.connect()
    return ctl


def test_alarm_reset_unlock():
    sim = SimulatedGrbl(soft_limit_alarm=True, limits=(-1000, 1000))
    ctl = connected(sim)
    ctl.move_to(x=10)
    with pytest.raises(MotorError) as info:
        ctl.move_to(x=5000)
    assert info.value.alarm == 2
    assert ctl.alarm == 2
    assert "ALARM:2" in str(info.value)
    assert info.value.line == "G0 X5000"
    # the controller answers nothing until a soft reset
    with pytest.raises(MotorError, match="no answer"):
        ctl.move_to(x=20)
    assert ctl.reset().startswith("GrblHAL")
    assert ctl.locked
    assert ctl.status().state == "Alarm"
    with pytest.raises(MotorError) as info:
        ctl.move_to(x=20)
    assert info.value.code == 9
    ctl.unlock()
    assert ctl.alarm is None
    assert not ctl.locked
    ctl.move_to(x=30)
    assert ctl.status().steps[0] == 30


def test_unexpected_reset_and_alarm_fail_pending():
    sim = SimulatedGrbl()
    ctl = connected(sim)
    sim.mute = True
    ctl.move_to(x=1, wait=False)
    sim.emit("\r\nGrblHAL 1.1f ['$' or '$HELP' for help]\r\n")
    with pytest.raises(MotorError, match="controller reset") as info:
        ctl.drain()
    assert info.value.line == "G0 X1"
    ctl.move_to(y=2, wait=False)
    sim.emit("ALARM:1\r\n")
    with pytest.raises(MotorError) as info:
        ctl.drain()
    assert info.value.alarm == 1
    assert "hard limit" in str(info.value)


def test_async_error_reported_later():
    sim = SimulatedGrbl(limits=(-100, 100))
    ctl = connected(sim)
    ctl.move_to(x=500, wait=False)
    ctl.move_to(x=50, wait=False)
    with pytest.raises(MotorError) as info:
        ctl.drain()
    assert info.value.code == 15
    assert info.value.line == "G0 X500"
    ctl.drain()
    assert ctl.status().steps[0] == 50


def test_poll_and_messages():
    sim = SimulatedGrbl()
    ctl = connected(sim)
    ctl.send("$G")
    time.sleep(0.01)
    ctl.poll()
    assert ctl.pending == 0
    assert any(m.startswith("[GC:") for m in ctl.messages)
    assert ctl.command("$$")[:1] == ["$100=1.000"]


def test_set_position_g92():
    sim = SimulatedGrbl()
    ctl = connected(sim)
    ctl.move_to(x=100, y=50)
    ctl.set_position(0, 0, 0, 0)
    st = ctl.status()
    assert st.steps == (100, 50, 0, 0)  # machine position
    assert st.wpos == (0.0, 0.0, 0.0, 0.0)
    ctl.move_to(x=10)
    assert ctl.status().steps[0] == 110


@pytest.mark.parametrize(
    ("line", "reply"),
    [
        ("G0 X1", b"ok\r\n"),
        ("", b"ok\r\n"),
        ("G0 X1 (comment) ; more", b"ok\r\n"),
        ("G1 X1", b"error:22\r\n"),
        ("X", b"error:2\r\n"),
        ("G0 X1.2.3", b"error:1\r\n"),
        ("#1", b"error:1\r\n"),
        ("M3", b"error:20\r\n"),
        ("G38 X1", b"error:20\r\n"),
        ("G0 G1 X1", b"error:21\r\n"),
        ("G0 X1 X2", b"error:25\r\n"),
        ("G92 G0 X1", b"error:24\r\n"),
        ("G92", b"error:26\r\n"),
        ("$Q", b"error:3\r\n"),
        ("$H", b"error:5\r\n"),
        ("G0 X" + "1" * 300, b"error:11\r\n"),
        ("G0 X200000", b"error:15\r\n"),
    ],
)
def test_simulator_answers(line, reply):
    assert SimulatedGrbl().handle(line.encode() + b"\n") == reply


def test_simulator_realtime_and_reset():
    sim = SimulatedGrbl()
    out = sim.handle(b"G0 X1?\n")  # '?' is served at once, even mid-line
    assert out.startswith(b"<Idle|MPos:0.000")
    assert out.endswith(b"ok\r\n")
    assert sim.handle(b"G0 X1\x18").startswith(b"\r\nGrblHAL")  # reset drops the partial line
    assert sim.mpos["X"] == 1.0


# --------------------------------------------------------------------------- formatting, parsing


def test_format_move():
    assert format_move(x=np.int64(5)) == "G0 X5"
    assert format_move(1, 2, 3, 4, feed=1500.0) == "G1 X1 Y2 Z3 A4 F1500"
    assert format_move(a=0, word="G92") == "G92 A0"
    for bad in (
        lambda: format_move(),
        lambda: format_move(x=1.5),
        lambda: format_move(x=1, feed=0),
    ):
        with pytest.raises(ProtocolError):
            bad()


def test_command_rejects_realtime_characters():
    ctl = connected(SimulatedGrbl())
    for line in ("G0 X1?", "G0\nX1", "", "G0 X1 ~"):
        with pytest.raises(ProtocolError):
            ctl.command(line)
    with pytest.raises(ProtocolError, match="buffer"):
        ctl.command("G0 X1 " + "(pad)" * 40)


def test_parse_status():
    st = parse_status("<Hold:1|WPos:1.000,2.000,3.000,4.000|WCO:1.000,1.000,1.000,1.000|FS:0,0>")
    assert st.state == "Hold"
    assert st.substate == 1
    assert st.mpos == (2.0, 3.0, 4.0, 5.0)
    assert st.steps == (2, 3, 4, 5)
    st = parse_status("<Idle|MPos:-1.500,0.000,0.000,7.000|Bf:15,128>")
    assert st.fields["Bf"] == "15,128"
    assert st.wpos is None
    for bad in ("Idle|MPos:0", "<>", "<Idle|MPos>", "<Idle|MPos:a,b>", "<1dle>"):
        with pytest.raises(ProtocolError):
            parse_status(bad)


def test_errors_are_apygis_errors():
    assert issubclass(MotorError, InstrumentError)
    assert issubclass(MotorError, ApygisError)
    assert issubclass(MotorError, OSError)
