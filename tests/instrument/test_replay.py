"""Record and replay: identical bytes, crash-safe files, clear errors for bad recordings."""

from __future__ import annotations

import json
import logging
import threading

import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from apygis.errors import FileOverwriteError, FormatError, InstrumentError
from apygis.instrument.replay import (
    Chunk,
    Recorder,
    Replayer,
    ReplayPort,
    read_recording,
)
from apygis.instrument.simulator import VirtualInstrument

from .conftest import DirectPort


def test_record_replay_identical(tmp_path):
    vi = VirtualInstrument("calcomp")
    script = vi.parse("move 10 10\nglide 20 30 0.3\nbutton ENTER\nbutton 7\n")
    path = tmp_path / "session.rec"
    port = serial.serial_for_url("loop://", timeout=0.05)
    live = vi.parser()
    live_reports = []
    reads = []
    with Recorder(path, meta={"protocol": "calcomp"}) as rec:
        tablet = rec.wrap(port, "tablet")
        vi.play(script, port, keyboard=lambda text: rec.record("keyboard", text.encode()))
        while True:
            data = tablet.read(tablet.in_waiting or 1)
            if not data:
                break
            reads.append(data)
            live_reports += live.feed(data)
        live_reports += live.flush()
        tablet.close()
    header, chunks = read_recording(path)
    assert header["format"] == "apygis-recording"
    assert header["protocol"] == "calcomp"
    assert [c.data for c in chunks if c.channel == "tablet"] == reads
    assert Replayer(path).data("tablet") == vi.tablet_bytes(script)
    # replaying through a fresh parser gives the same reports
    again = vi.parser()
    replayed = []
    for c in Replayer(path, channels=["tablet"]):
        replayed += again.feed(c.data)
    replayed += again.flush()
    assert replayed == live_reports == script.reports()
    times = [c.t for c in chunks]
    assert times == sorted(times)


def test_replay_port_serves_chunks(tmp_path):
    path = tmp_path / "r.rec"
    with Recorder(path) as rec:
        rec.record("tablet", b"abc")
        rec.record("motors", b"ok\r\n")
        rec.record("tablet", b"defg")
    p = Replayer(path).port("tablet")
    assert p.in_waiting == 3
    assert p.read(2) == b"ab"
    assert p.read(100) == b"c"
    assert p.read(100) == b"defg"
    assert p.exhausted
    assert p.read(1) == b""
    assert p.write(b"xx") == 2
    p.close()
    with ReplayPort([b"x"]) as q:
        assert q.read(5) == b"x"


def test_motor_traffic_both_directions(tmp_path, direct):
    _sim, port = direct
    path = tmp_path / "m.rec"
    with Recorder(path) as rec:
        rp = rec.wrap(port, "motors", record_writes=True)
        rp.write(b"G0 X5\n")
        assert rp.read(10) == b"ok\r\n"
    chunks = Replayer(path).chunks()
    assert [(c.channel, c.direction, c.data) for c in chunks] == [
        ("motors", "tx", b"G0 X5\n"),
        ("motors", "rx", b"ok\r\n"),
    ]
    assert [c.data for c in Replayer(path, directions=["tx"])] == [b"G0 X5\n"]
    assert '"dir": "tx"' in path.read_text()
    assert isinstance(port, DirectPort)


def test_realtime_replay_uses_recorded_times(tmp_path):
    path = tmp_path / "t.rec"
    with Recorder(path) as rec:
        rec.record("tablet", b"a", t=0.5)
        rec.record("tablet", b"b", t=0.75)
        rec.record("tablet", b"c", t=1.75)
    now = [10.0]
    sleeps = []

    def sleep(s):
        sleeps.append(round(s, 6))
        now[0] += s

    out = list(Replayer(path, realtime=True, speed=0.5, clock=lambda: now[0], sleep=sleep))
    assert [c.data for c in out] == [b"a", b"b", b"c"]
    assert sleeps == [0.5, 2.0]  # 0.25 s and 1 s, at half speed
    with pytest.raises(InstrumentError):
        Replayer(path, speed=0)


def test_recorder_is_crash_safe(tmp_path):
    path = tmp_path / "c.rec"
    rec = Recorder(path)
    rec.record("tablet", b"\x80\x01")
    # before close, the line is already in the file
    record = json.loads(path.read_text().splitlines()[1])
    assert record["ch"] == "tablet"
    assert record["hex"] == "8001"
    rec.close()
    with pytest.raises(InstrumentError, match="closed"):
        rec.record("tablet", b"x")
    assert rec.record("tablet", b"") is None  # empty chunks are not recorded


def test_truncated_last_line_tolerated(tmp_path, caplog):
    path = tmp_path / "cut.rec"
    with Recorder(path) as rec:
        rec.record("tablet", b"\x01\x02")
        rec.record("tablet", b"\x03")
    with open(path, "a", encoding="utf-8") as f:
        f.write('{"t": 0.5, "ch": "tab')  # the crash
    with caplog.at_level(logging.WARNING, logger="apygis.instrument.replay"):
        chunks = Replayer(path).chunks()
    assert [c.data for c in chunks] == [b"\x01\x02", b"\x03"]
    assert "line 4: cut off" in caplog.text
    # a complete last line without its newline is kept
    with open(path, "w", encoding="utf-8") as f:
        f.write(
            '{"format": "apygis-recording", "version": 1}\n{"t": 1, "ch": "tablet", "hex": "ff"}'
        )
    assert Replayer(path).chunks() == [Chunk(1.0, "tablet", b"\xff")]


HEADER = '{"format": "apygis-recording", "version": 1}\n'
GOOD = '{"t": 0.1, "ch": "tablet", "hex": "80"}\n'


@pytest.mark.parametrize(
    ("text", "record", "pattern"),
    [
        ("", None, "empty file"),
        ('{"format": "other", "version": 1}\n', "line 1", "not an apygis recording"),
        ('{"format": "apygis-recording", "version": 9}\n', "line 1", "version 9"),
        ("[1, 2]\n", "line 1", "not an apygis recording"),
        (HEADER + GOOD + "{bad json\n" + GOOD, "line 3", "bad JSON"),
        (HEADER + '{"t": -1, "ch": "tablet", "hex": "80"}\n', "line 2", "non-negative"),
        (HEADER + '{"t": "0", "ch": "tablet", "hex": "80"}\n', "line 2", "'t' must be"),
        (HEADER + GOOD + '{"t": 0.05, "ch": "tablet", "hex": "80"}\n', "line 3", "goes back"),
        (HEADER + '{"t": 0.1, "hex": "80"}\n', "line 2", "'ch' must be"),
        (HEADER + '{"t": 0.1, "ch": "9x", "hex": "80"}\n', "line 2", "'ch' must be"),
        (HEADER + '{"t": 0.1, "ch": "tablet", "hex": "8"}\n', "line 2", "hex digits"),
        (HEADER + '{"t": 0.1, "ch": "tablet", "hex": 80}\n', "line 2", "'hex' must be"),
        (HEADER + '{"t": 0.1, "ch": "tablet", "dir": "up", "hex": "80"}\n', "line 2", "'dir'"),
        (HEADER + "[]\n", "line 2", "JSON object"),
        # hostile input: wrong header types, deep nesting, huge or non-finite numbers
        ('{"format": "apygis-recording", "version": true}\n', "line 1", "version True"),
        ('{"format": "apygis-recording", "version": 1, "protocol": 5}\n', "line 1",
         "'protocol' must be a tablet protocol"),
        ('{"format": "apygis-recording", "version": 1, "protocol": "wacom"}\n', "line 1",
         "'protocol' must be a tablet protocol"),
        ('{"format": "apygis-recording", "version": 1, "counts_per_mm": "abc"}\n', "line 1",
         "'counts_per_mm' must be a number"),
        ('{"format": "apygis-recording", "version": 1, "counts_per_mm": 0}\n', "line 1",
         "'counts_per_mm' must be a number"),
        ('{"format": "apygis-recording", "version": 1, "counts_per_mm": 1e400}\n', "line 1",
         "'counts_per_mm' must be a number"),
        ('{"format": "apygis-recording", "version": 1, "counts_per_mm": NaN}\n', "line 1",
         "'counts_per_mm' must be a number"),
        ('{"format": "apygis-recording", "version": 1, "counts_per_mm": ' + "9" * 400 + "}\n",
         "line 1", "'counts_per_mm' must be a number"),
        ('{"format": "apygis-recording", "version": 1, "created": 5}\n', "line 1",
         "'created' must be"),
        ("[" * 100000 + "]" * 100000 + "\n", "line 1", "JSON nested too deeply"),
        (HEADER + '{"a": ' * 50000 + "1" + "}" * 50000 + "\n", "line 2", "nested too deeply"),
        (HEADER + '{"t": ' + "9" * 400 + ', "ch": "tablet", "hex": "80"}\n', "line 2",
         "'t' must be"),
        (HEADER + '{"t": ' + "9" * 5000 + ', "ch": "tablet", "hex": "80"}\n', "line 2",
         "bad JSON"),
        (HEADER + '{"t": 1e300, "ch": "tablet", "hex": "80"}\n', "line 2", "'t' must be"),
        (HEADER + '{"t": NaN, "ch": "tablet", "hex": "80"}\n', "line 2", "'t' must be"),
        (HEADER + '{"t": Infinity, "ch": "tablet", "hex": "80"}\n', "line 2", "'t' must be"),
    ],
)  # fmt: skip
def test_bad_recordings(tmp_path, text, record, pattern):
    path = tmp_path / "bad.rec"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(FormatError) as info:
        Replayer(path).chunks()
    msg = str(info.value)
    assert str(path) in msg
    if record:
        assert f"{path}: {record}: " in msg
    assert pattern in msg


def test_check_recording_reads_every_line_first(tmp_path):
    from apygis.instrument.replay import check_recording

    path = tmp_path / "late.rec"
    path.write_text(HEADER + GOOD * 3 + '{"t": 0.1, "ch": "tablet", "hex": "8"}\n')
    with pytest.raises(FormatError, match="line 5: 'hex'"):
        check_recording(path)
    path.write_text(HEADER.replace("}", ', "protocol": "mm", "counts_per_mm": 40}') + GOOD)
    assert check_recording(path)["protocol"] == "mm"
    with pytest.raises(InstrumentError, match="speed"):
        Replayer(path, speed=10**400)


def test_bad_recording_bytes(tmp_path):
    path = tmp_path / "bin.rec"
    path.write_bytes(HEADER.encode() + b"\xff\xfe\n")
    with pytest.raises(FormatError, match="line 2: not UTF-8"):
        Replayer(path).chunks()
    with pytest.raises(FormatError, match="cannot open"):
        Replayer(tmp_path / "missing.rec").chunks()


def test_overwrite_and_channel_checks(tmp_path):
    path = tmp_path / "o.rec"
    Recorder(path).close()
    with pytest.raises(FileOverwriteError):
        Recorder(path)
    with Recorder(path, overwrite=True, fsync=False) as rec:
        with pytest.raises(InstrumentError, match="channel"):
            rec.record("9bad", b"x")
        with pytest.raises(InstrumentError, match="direction"):
            rec.record("tablet", b"x", direction="up")
    with pytest.raises(InstrumentError, match="cannot create"):
        Recorder(tmp_path / "no" / "such" / "dir.rec")


def test_concurrent_recording(tmp_path):
    path = tmp_path / "threads.rec"
    with Recorder(path, fsync=False) as rec:

        def work(ch):
            for i in range(200):
                rec.record(ch, bytes([i]))

        threads = [threading.Thread(target=work, args=(ch,)) for ch in ("tablet", "motors")]
        for t in threads:
            t.start()
        for t in threads:
            t.join(10)
    chunks = Replayer(path).chunks()
    assert len(chunks) == 400
    for ch in ("tablet", "motors"):
        assert [c.data[0] for c in chunks if c.channel == ch] == list(range(200))


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    body=st.lists(
        st.sampled_from([GOOD, '{"t": 1, "ch": "x", "hex": ""}\n', "{}\n", "\n", "nul\n"])
        | st.text(max_size=30)
        | st.binary(max_size=30).map(lambda b: b.decode("latin-1")),
        max_size=6,
    )
)
def test_recording_fuzz_only_format_errors(tmp_path, body):
    path = tmp_path / "fuzz.rec"
    path.write_bytes((HEADER + "".join(body)).encode("utf-8", "surrogateescape"))
    try:
        chunks = Replayer(path).chunks()
    except FormatError as exc:
        message = str(exc)
        chunks = None
    if chunks is None:
        assert str(path) in message
    else:
        assert all(isinstance(c, Chunk) for c in chunks)
