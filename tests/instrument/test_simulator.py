"""The virtual instrument: scripts, the button pad, bytes over loop:// and a pty."""

from __future__ import annotations

import os
import re
import threading
from pathlib import Path

import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from apygis.errors import FormatError, ProtocolError
from apygis.instrument.simulator import (
    BUTTON_CODES,
    BUTTONS,
    KeyEvent,
    ScriptBuilder,
    TabletEvent,
    VirtualInstrument,
    button_code,
    parse_script,
    read_script,
)
from apygis.instrument.tablet import Report, TabletConfig, read_reports

from .test_tablet import split

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = """\
# digitise a road and its name
units mm
rate 100
move 120.5 80.25
button DESCR
button 1
button 2
button ENTER
glide 130 80.25 0.05   # five reports
button ENTER
hold UP 0.03
proximity out
wait 0.2
proximity in
type Kirchweg
type "  spaced # not a comment\\n"
key ENTER
units counts
move 4000 20
button .
"""


def test_button_pad():
    assert sorted(BUTTONS) == list(range(1, 28))
    names = list(BUTTONS.values())
    assert len(set(names)) == 27
    required = [str(d) for d in range(10)] + [
        "ENTER",
        "DELETE",
        "PROCEED",
        "DESCR",
        "SEARCH",
        "SAMPLE",
        "LS",
        "AREA",
        "DHI",
        "UP",
        "DOWN",
        "UNDO",
    ]
    assert set(required) <= set(names)
    for code, name in BUTTONS.items():
        assert BUTTON_CODES[name] == code
        assert button_code(name.lower()) == code
    assert button_code("+") == BUTTON_CODES["PLUS"]
    with pytest.raises(ProtocolError, match="unknown button"):
        button_code("FOO")
    with pytest.raises(ProtocolError):
        button_code(28)


def test_button_pad_doc_matches_code():
    text = (ROOT / "docs" / "button-pad.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\|\s*(\d+)\s*\|\s*`([^`]+)`\s*\|", text, flags=re.M)
    assert {int(code): name for code, name in rows} == BUTTONS


def test_parse_script():
    s = parse_script(SCRIPT, config=TabletConfig(counts_per_mm=40))
    tab = s.tablet_events
    assert (tab[0].x_counts, tab[0].y_counts, tab[0].button) == (4820, 3210, 0)
    assert [e.button for e in tab[1:9]] == [14, 0, 1, 0, 2, 0, 11, 0]
    glide = tab[9:14]
    assert [e.x_counts for e in glide] == [4896, 4972, 5048, 5124, 5200]
    assert all(e.y_counts == 3210 for e in glide)
    assert [e.button for e in tab[14:20]] == [11, 0, 20, 20, 20, 0]
    assert [e.proximity for e in tab[20:22]] == [False, True]
    assert tab[21].t == pytest.approx(tab[20].t + 0.01 + 0.2)
    assert (tab[-3].x_counts, tab[-3].y_counts, tab[-3].button) == (4000, 20, 0)
    assert tab[-2].button == 23
    assert tab[-2].line == 20
    assert tab[-1].button == 0
    # times never decrease, reports at the rate
    times = [e.t for e in s.events]
    assert times == sorted(times)
    assert tab[1].t - tab[0].t == pytest.approx(0.01)
    keys = s.key_events
    assert [k.text for k in keys] == ["Kirchweg", "  spaced # not a comment\n", "\r"]
    assert s.keyboard_text == "Kirchweg  spaced # not a comment\n\r"
    assert s.duration == tab[-1].t


@pytest.mark.parametrize(
    ("text", "lineno", "pattern"),
    [
        ("move 1 2\nfly 3 4\n", 2, "unknown command 'fly'"),
        ("move 1\n", 1, "move needs 2 numbers"),
        ("move 1 x\n", 1, "'x' is not a number"),
        ("move 1 nan\n", 1, "not a finite number"),
        ("button ENTER\n", 1, "move first"),
        ("move 1 2\n\n# c\nbutton FOO\n", 4, "unknown button 'FOO'"),
        ("move 1 2\nbutton\n", 2, "one button name"),
        ("units inch\n", 1, "units must be"),
        ("rate 0\n", 1, "rate must be"),
        ("wait -1\n", 1, "non-negative"),
        ("glide 1 2 3\n", 1, "move first"),
        ("move 0 0\nglide 1 2 -3\n", 2, "must not be negative"),
        ("type\n", 1, "type needs a text"),
        ('type "unterminated\n', 1, "bad JSON string"),
        ("type 5\n", None, None),
        ("key F13\n", 1, "unknown key"),
        ("proximity up\n", 1, "'in' or 'out'"),
        ("units counts\nmove 1.5 2\n", 2, "whole number of counts"),
        ("move 1 2\nhold UP\n", 2, "hold needs"),
    ],
)
def test_script_errors_name_file_and_line(text, lineno, pattern):
    if pattern is None:
        assert parse_script(text).keyboard_text == "5"
        return
    with pytest.raises(FormatError) as info:
        parse_script(text, path="session.apyscript")
    msg = str(info.value)
    assert msg.startswith(f"session.apyscript: line {lineno}: ")
    assert re.search(re.escape(pattern), msg), msg


def test_read_script(tmp_path):
    p = tmp_path / "s.txt"
    p.write_text("move 1 1\nbutton ENTER\n", encoding="utf-8")
    assert len(read_script(p).tablet_events) == 3
    p.write_bytes(b"move 1 1\ntype \xff\n")
    with pytest.raises(FormatError, match="not UTF-8"):
        read_script(p)
    with pytest.raises(FormatError, match="cannot read"):
        read_script(tmp_path / "missing.txt")
    p.write_text("move 1 1\nbutton NOPE\n", encoding="utf-8")
    with pytest.raises(FormatError, match=re.escape(f"{p}: line 2:")):
        read_script(p)


def script_for_all_buttons() -> str:
    lines = ["move 10 20"]
    for code, name in BUTTONS.items():
        lines.append(f"move {code} {code * 2}")
        lines.append(f"button {name}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("protocol", "options"),
    [("calcomp", {}), ("ascii", {}), ("ascii", {"width": None, "signed": True})],
)
def test_bytes_to_parser_reproduce_script(protocol, options):
    vi = VirtualInstrument(protocol, **options)
    script = vi.parse(script_for_all_buttons() + "proximity out\n")
    data = vi.tablet_bytes(script)
    parser = vi.parser()
    got = []
    for chunk in split(data, [7, 100, 101, 333]):
        got += parser.feed(chunk)
    got += parser.flush()
    assert got == script.reports()
    pressed = [BUTTONS[r.button] for r in got if r.button]
    assert pressed == list(BUTTONS.values())
    cfg = vi.config
    positions = {(cfg.counts_to_mm(r.x_counts), cfg.counts_to_mm(r.y_counts)) for r in got}
    assert (27.0, 54.0) in positions


def test_mm_protocol_limits_buttons():
    vi = VirtualInstrument("mm")
    ok = vi.parse("move -10 -20\nbutton 7\n")
    parser = vi.parser()
    assert parser.feed(vi.tablet_bytes(ok)) + parser.flush() == ok.reports()
    bad = vi.parse("move 1 1\nbutton ENTER\n", path="enter.txt")
    with pytest.raises(ProtocolError, match=r"enter\.txt: line 2: .*0\.\.7"):
        vi.tablet_bytes(bad)


def test_calcomp_rejects_negative_with_line():
    vi = VirtualInstrument("calcomp")
    with pytest.raises(ProtocolError, match="line 1"):
        vi.tablet_bytes(vi.parse("move -1 0\n"))


def test_play_over_loop_url():
    vi = VirtualInstrument("calcomp", rate=200)
    script = vi.parse(SCRIPT)
    port = serial.serial_for_url("loop://", timeout=0.2)
    typed = []
    try:
        n = vi.play(script, port, keyboard=typed.append)
        assert n == 6 * len(script.tablet_events)
        parser = vi.parser()
        got = []
        while True:
            data = port.read(port.in_waiting or 1)
            if not data:
                break
            got += parser.feed(data)
        got += parser.flush()
    finally:
        port.close()
    assert got == script.reports()
    assert "".join(typed) == script.keyboard_text


def test_play_over_pty(pty_pair):
    vi = VirtualInstrument("ascii")
    script = vi.parse(script_for_all_buttons())
    expected = vi.tablet_bytes(script)
    # the simulator writes to the slave side, as a tablet would; we read the master
    n = vi.play_url(script, pty_pair.path)
    assert n == len(expected)
    data = pty_pair.read_master(len(expected))
    assert data == expected
    parser = vi.parser()
    assert parser.feed(data) + parser.flush() == script.reports()


def test_pty_reader_side(pty_pair):
    """The other direction: a parser reading the pty slave through pyserial."""
    vi = VirtualInstrument("mm")
    script = vi.parse("move 1 2\nglide 50 60 0.2\nbutton 3\n")
    data = vi.tablet_bytes(script)
    port = serial.serial_for_url(pty_pair.path, timeout=0.05)
    try:
        # two bursts, cut at a packet boundary: a quiet line never splits a packet
        bursts = [data[:25], data[25:]]
        writer = threading.Thread(
            target=lambda: [os.write(pty_pair.master, c) for c in bursts], daemon=True
        )
        writer.start()
        parser = vi.parser()
        got = []
        quiet = 0
        while len(got) < len(script.tablet_events) and quiet < 20:
            new = read_reports(port, parser)  # flushes the parser when the line is quiet
            quiet = 0 if new or writer.is_alive() else quiet + 1
            got += new
        writer.join(2)
    finally:
        port.close()
    assert got == script.reports()


def test_realtime_pacing_and_keyboard_port():
    vi = VirtualInstrument("calcomp", rate=50)
    script = vi.parse("move 0 0\nmove 1 1\nwait 0.5\ntype ab\nmove 2 2\n")
    now = [0.0]
    sleeps = []

    def sleep(s):
        sleeps.append(round(s, 6))
        now[0] += s

    kb = serial.serial_for_url("loop://", timeout=0.1)
    out = serial.serial_for_url("loop://", timeout=0.1)
    try:
        vi.play(
            script, out, keyboard=kb, realtime=True, speed=2.0, clock=lambda: now[0], sleep=sleep
        )
        assert kb.read(10) == b"ab"
    finally:
        kb.close()
        out.close()
    assert sleeps == [0.01, 0.26]  # 20 ms between reports at 50/s, 500 ms wait, at 2x speed


def test_builder_and_events():
    b = ScriptBuilder(TabletConfig(counts_per_mm=10), rate=10)
    s = b.move(1, 2).button(5).wait(1).type("x").build("mem")
    assert s.path == "mem"
    assert s.events[0] == TabletEvent(0.0, 10, 20, 0, True)
    assert s.events[1].report() == Report(10, 20, 5, True)
    assert isinstance(s.events[-1], KeyEvent)
    assert s.events[-1].t == pytest.approx(1.3)
    with pytest.raises(ProtocolError):
        VirtualInstrument("wacom")
    with pytest.raises(ProtocolError):
        VirtualInstrument("mm", width=5)


KEYWORDS = ["move", "glide", "button", "hold", "wait", "type", "key", "units", "rate", "proximity"]


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from([*KEYWORDS, "x", ""]),
            st.lists(
                st.sampled_from(["1", "-2.5", "ENTER", "mm", "counts", "in", "1e400", '"', "#"])
                | st.text(max_size=4),
                max_size=4,
            ),
        ),
        max_size=12,
    )
)
def test_script_fuzz_only_format_errors(lines):
    text = "\n".join(" ".join([kw, *args]) for kw, args in lines)
    try:
        script = parse_script(text, path="fuzz.txt")
    except FormatError as exc:
        message = str(exc)
        script = None
    if script is None:
        assert message.startswith("fuzz.txt: line ")
    else:
        times = [e.t for e in script.events]
        assert times == sorted(times)


def test_huge_durations_refused():
    for text in ("move 0 0\nhold UP 1e9\n", "move 0 0\nglide 1 1 1e12\n"):
        with pytest.raises(FormatError, match=r"line 2: .*more than"):
            parse_script(text)


def test_a_script_has_a_total_size_cap():
    """Each line under the per-command cap, together far over it: refused at the line."""
    from apygis.instrument.simulator import MAX_REPORTS

    text = "rate 100000\nmove 0 0\n" + "hold UP 1.5\n" * 10
    with pytest.raises(FormatError, match=rf"line 4: hold: .*more than {MAX_REPORTS} tablet"):
        parse_script(text)
    many_moves = "move 0 0\n" * (MAX_REPORTS + 1)
    with pytest.raises(FormatError, match=rf"line {MAX_REPORTS + 1}: a report: .*in all"):
        parse_script(many_moves)


def test_a_script_has_a_time_and_typing_cap(tmp_path):
    from apygis.instrument.simulator import MAX_DURATION_S, MAX_SCRIPT_BYTES, MAX_TYPED

    with pytest.raises(FormatError, match=r"line 2: wait: .*more than 86400 s"):
        parse_script(f"wait {MAX_DURATION_S}\nwait 1\n")
    with pytest.raises(FormatError, match=r"line 3: glide: .*more than 86400 s"):
        parse_script(f"move 0 0\nwait {MAX_DURATION_S - 0.5}\nglide 1 1 1\n")
    chunk = "x" * 100_000
    text = f"type {chunk}\n" * (MAX_TYPED // len(chunk) + 1)
    with pytest.raises(FormatError, match=rf"line {MAX_TYPED // len(chunk) + 1}: type: .*"):
        parse_script(text)
    big = tmp_path / "big.txt"
    with open(big, "wb") as fh:
        fh.truncate(MAX_SCRIPT_BYTES + 1)
    with pytest.raises(FormatError, match=r"big\.txt: .*at most"):
        read_script(big)
