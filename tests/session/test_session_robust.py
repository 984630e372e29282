"""Sessions against concurrent use, stale journals, failed starts, bad input and full disks."""

from __future__ import annotations

import errno
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import pytest
from click.testing import CliRunner

import apygis
from apygis.cli import main
from apygis.compile.engine import Keys, Mark, Press
from apygis.compile.oriented import OrientedGeometry
from apygis.errors import ApygisError, FormatError
from apygis.instrument.pad import BUTTONS
from apygis.instrument.replay import Chunk
from apygis.instrument.tablet import TabletConfig, make_parser
from apygis.orient.io import load_orientation
from apygis.session import (
    ReportDecoder,
    SaveError,
    Session,
    SessionLockedError,
    decode_typed,
    run_live,
    run_tablet_stream,
)
from apygis.session.journal import StaleJournalError, read_journal
from tests.conftest import ROOT, SAMPLES

SESSION = SAMPLES / "session"
ORIENTATION = SESSION / "ZH1091.orientation.json"
RECORDING = SESSION / "ZH1091-revision.rec"
CFG = TabletConfig(counts_per_mm=40.0)
SYMBOL = ("DESCR", "1", "ENTER", "2", "3", "ENTER")


@pytest.fixture(scope="module")
def geometry():
    return OrientedGeometry(load_orientation(ORIENTATION))


def _sheet(tmp_path) -> Path:
    """A copy of the sample sheet (APY binary) in tmp_path; returns dir/ID."""
    base = tmp_path / "ZH1091"
    apygis.write(apygis.read(SAMPLES / "ZH1091", driver="apy"), base, driver="apy")
    return base


def _symbols(sess, geometry, n, x0=2684000.0):
    sess.handle_all(Press(b) for b in SYMBOL)
    for k in range(n):
        sess.handle(Mark(*geometry.tablet(x0 + 10.0 * k, 1247800.0)))
        sess.handle(Press("ENTER"))


def _crash(sess):
    """What kill -9 leaves: the journal as synced, the lock dropped by the kernel."""
    sess.journal._fh.flush()
    sess.lock.release()


def _snapshot(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())} if d.exists() else {}


def _cli(*args):
    return CliRunner().invoke(main, ["session", *map(str, args)])


def _one_line_error(res, *needles):
    assert res.exit_code == 1, res.output
    assert "Traceback" not in res.output
    err = [line for line in res.output.splitlines() if line.startswith("Error:")]
    assert len(err) == 1, res.output
    for n in needles:
        assert n in err[0], err[0]
    return err[0]


# ----------------------------------------------------------------- 1. one session per map


def test_a_second_session_on_the_same_map_is_refused(tmp_path, geometry):
    base = _sheet(tmp_path)
    s1 = Session(base, geometry, layer="r")
    with pytest.raises(SessionLockedError, match=rf"pid {os.getpid()} .*started 20"):
        Session(base, geometry, layer="r")
    _symbols(s1, geometry, 2)
    s1.close()
    assert not base.with_name("ZH1091.lock").exists()
    s2 = Session(base, geometry, layer="r")  # free again: recovers s1's kept journal
    assert s2.recovered == len(SYMBOL) + 4
    s2.close()


def _start_live(base, pty_slave, *extra):
    cmd = [sys.executable, "-m", "apygis", "session", str(base), "--orientation",
           str(ORIENTATION), "--tablet", f"calcomp:{os.ttyname(pty_slave)}", "--layer", "r",
           *extra]  # fmt: skip
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        cwd=ROOT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        text=True,
    )
    ready = threading.Event()

    def read_out():
        for line in proc.stdout:
            if line.startswith("tablet calcomp on"):
                ready.set()

    threading.Thread(target=read_out, daemon=True).start()
    assert ready.wait(30), "the session did not start"
    return proc


def test_two_processes_one_map_then_sigkill_frees_the_lock(tmp_path):
    base = _sheet(tmp_path)
    journal = base.with_name("ZH1091.journal")
    master, slave = os.openpty()
    tty.setraw(slave)
    proc = _start_live(base, slave)
    try:
        head = journal.read_bytes()
        files = _snapshot(tmp_path)
        second = subprocess.run(
            [sys.executable, "-m", "apygis", "session", str(base), "--orientation",
             str(ORIENTATION), "--replay", str(RECORDING)],
            capture_output=True, text=True, cwd=ROOT, timeout=60,
        )  # fmt: skip
        assert second.returncode == 1, second.stdout + second.stderr
        assert "Traceback" not in second.stderr
        assert f"in use by another session (pid {proc.pid} on " in second.stderr
        assert "ZH1091.lock" in second.stderr
        assert len(second.stderr.strip().splitlines()) == 1
        assert "recovered" not in second.stdout
        assert journal.read_bytes() == head  # the second one did not touch the live journal
        assert _snapshot(tmp_path) == files
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
        os.close(slave)
    assert base.with_name("ZH1091.lock").exists()  # left behind by the killed holder...
    rec = subprocess.run(
        [sys.executable, "-m", "apygis", "session", str(base), "--orientation", str(ORIENTATION),
         "--recover-only"],
        capture_output=True, text=True, cwd=ROOT, timeout=60,
    )  # fmt: skip
    assert rec.returncode == 0, rec.stdout + rec.stderr  # ...and blocks nobody
    assert "recovered 0 journaled events" in rec.stdout
    assert not base.with_name("ZH1091.lock").exists()


# ----------------------------------------------------------------- 2. stale journals


def test_a_journal_is_not_replayed_over_files_changed_since(tmp_path, geometry):
    base = _sheet(tmp_path)
    s1 = Session(base, geometry, layer="r")
    _symbols(s1, geometry, 3)
    _crash(s1)
    # later, the layer file r is changed by other means (another program, a restore)
    m = apygis.read(base)
    m.layers["r"].add_symbol(2684500.0, 1247500.0, 440.0, 12)
    apygis.write(m, base, driver="apy")
    before = _snapshot(tmp_path)
    with pytest.raises(StaleJournalError) as exc:
        Session(base, geometry, layer="r")
    msg = str(exc.value)
    assert "ZH1091.journal" in msg
    assert "ZH1091.r changed" in msg
    assert "--discard-journal" in msg
    assert "--trust-journal" in msg
    assert _snapshot(tmp_path) == before  # nothing written, nothing replayed
    res = _cli(base, "--orientation", ORIENTATION, "--recover-only")
    _one_line_error(res, "ZH1091.r changed", "--discard-journal")
    assert _snapshot(tmp_path) == before
    # the operator's choices: trust the journal (its replay wins) ...
    s2 = Session(base, geometry, trust_journal=True)
    assert s2.recovered == len(SYMBOL) + 6
    s2.close()


def test_discard_journal_renames_it_aside_and_starts_from_the_files(tmp_path, geometry):
    base = _sheet(tmp_path)
    s1 = Session(base, geometry, layer="r")
    _symbols(s1, geometry, 2)
    _crash(s1)
    m = apygis.read(base)
    m.layers["e"].add_symbol(2684500.0, 1247500.0, 440.0, 0)
    apygis.write(m, base, driver="apy")
    old = base.with_name("ZH1091.journal").read_bytes()
    res = _cli(base, "--orientation", ORIENTATION, "--recover-only", "--discard-journal")
    assert res.exit_code == 0, res.output
    assert "renamed to ZH1091.journal.discarded" in res.output
    assert base.with_name("ZH1091.journal.discarded").read_bytes() == old
    assert apygis.read(base) == m  # the other program's edit is kept
    assert "--discard-journal" in _cli("--help").output


def test_recovery_accepts_files_the_session_saved_itself(tmp_path, geometry):
    base = _sheet(tmp_path)
    s1 = Session(base, geometry, layer="r", settings={"autosave_every": 2})
    _symbols(s1, geometry, 5)  # two autosaves: files changed by the session
    assert s1.saves == 2
    _crash(s1)
    s2 = Session(base, geometry)
    assert s2.engine.entries == 5
    s2.close()


def test_recovery_after_a_crash_in_the_middle_of_a_save(tmp_path, geometry, monkeypatch):
    """The save's file states are journaled, then the files written: a crash between is fine."""
    base = _sheet(tmp_path)
    s1 = Session(base, geometry, layer="r", settings={"autosave_every": 3})
    _symbols(s1, geometry, 2)

    def killed(*a, **k):  # the process dies after the journal line, before any rename
        raise KeyboardInterrupt

    monkeypatch.setattr(apygis, "write", killed)
    with pytest.raises(KeyboardInterrupt):
        _symbols(s1, geometry, 1, x0=2684300.0)
    monkeypatch.undo()
    _crash(s1)
    assert read_journal(s1.journal_path).file_states[-1]  # the save's line is there
    s2 = Session(base, geometry)
    assert s2.engine.entries == 3
    s2.close()


def test_an_old_journal_without_file_states_is_refused_unless_trusted(tmp_path, geometry):
    base = _sheet(tmp_path)
    s1 = Session(base, geometry, layer="r")
    _symbols(s1, geometry, 1)
    _crash(s1)
    lines = s1.journal_path.read_bytes().split(b"\n")
    head = json.loads(lines[0])
    head["journal"] = 1
    del head["files"]
    lines[0] = json.dumps(head).encode()
    s1.journal_path.write_bytes(b"\n".join(lines))
    with pytest.raises(StaleJournalError, match=r"version 1 journal.*--trust-journal"):
        Session(base, geometry)
    s2 = Session(base, geometry, trust_journal=True)
    assert s2.engine.entries == 1
    _symbols(s2, geometry, 1, x0=2684300.0)
    entries = s2.engine.entries
    _crash(s2)
    j = read_journal(s2.journal_path)  # rewritten as version 2, appended to since
    assert j.version == 2
    assert len(j.file_states) == 2  # the files trusted, the recovery's save
    s3 = Session(base, geometry)  # no option needed any more
    assert s3.engine.entries == entries > 1
    s3.close()


# ----------------------------------------------------------------- 3. failed starts write nothing


def _replay_args(out, *extra):
    return [SAMPLES / "ZH1091", "--orientation", ORIENTATION, "--replay", RECORDING,
            "-o", out, *extra]  # fmt: skip


def _bad_recording(tmp_path):
    p = tmp_path / "bad.rec"
    p.write_text('{"format": "apygis-recording", "version": 1, "counts_per_mm": "abc"}\n')
    return p


@pytest.mark.parametrize(
    "case",
    ["pad", "pad-superscript", "port", "tablet-nocolon", "tablet-protocol", "recording",
     "motors", "layer", "orientation", "record"],
)  # fmt: skip
@pytest.mark.parametrize("earlier", [False, True])
def test_a_failed_start_leaves_everything_as_it_was(tmp_path, case, earlier):
    out = tmp_path / "out"
    if earlier:  # an earlier run left its files there (terminated: no journal)
        assert _cli(*_replay_args(out)).exit_code == 0
    before = _snapshot(out)
    pad = tmp_path / "p.pad"
    pad.write_text("11 JUMP\n" if case == "pad" else "1² ENTER\n")
    src = SAMPLES / "ZH1091"
    args = {
        "pad": _replay_args(out, "--pad", pad, "--overwrite"),
        "pad-superscript": _replay_args(out, "--pad", pad, "--overwrite"),
        "port": [src, "--orientation", ORIENTATION, "--tablet", "calcomp:/nonexistent/tty",
                 "-o", out, "--overwrite"],
        "tablet-nocolon": [src, "--orientation", ORIENTATION, "--tablet", "nocolon", "-o", out],
        "tablet-protocol": [src, "--orientation", ORIENTATION, "--tablet", "wacom:/dev/x",
                            "-o", out],
        "recording": [src, "--orientation", ORIENTATION, "--replay", _bad_recording(tmp_path),
                      "-o", out, "--overwrite"],
        "motors": _replay_args(out, "--motors", "grbl:socket://127.0.0.1:1", "--overwrite"),
        "layer": _replay_args(out, "--layer", "road", "--overwrite"),
        "orientation": [src, "--orientation", pad, "--replay", RECORDING, "-o", out,
                        "--overwrite"],
        "record": [src, "--orientation", ORIENTATION, "--tablet", "calcomp:loop://",
                   "--record", tmp_path / "no" / "such" / "t.rec", "-o", out, "--overwrite"],
    }[case]  # fmt: skip
    needle = {
        "pad": "p.pad: line 1: unknown button 'JUMP'",
        "pad-superscript": "p.pad: line 1: expected 'CODE NAME'",
        "port": "cannot open the tablet port /nonexistent/tty",
        "tablet-nocolon": "expected PROTOCOL:URL",
        "tablet-protocol": "unknown tablet protocol 'wacom'",
        "recording": "bad.rec: line 1: 'counts_per_mm' must be a number",
        "motors": "127.0.0.1:1",
        "layer": "--layer",
        "orientation": "p.pad",
        "record": "cannot record there",
    }[case]
    _one_line_error(_cli(*args), needle)
    assert _snapshot(out) == before  # no copy, no journal, no lock file, no re-saved layer
    assert not list(tmp_path.glob("**/*.journal"))
    assert not list(tmp_path.glob("**/*.lock"))


def test_a_failed_start_on_the_map_itself_changes_no_file(tmp_path):
    base = _sheet(tmp_path)
    before = _snapshot(tmp_path)
    res = _cli(base, "--orientation", ORIENTATION, "--tablet", "calcomp:/nonexistent/tty")
    _one_line_error(res, "cannot open the tablet port")
    assert _snapshot(tmp_path) == before


# ----------------------------------------------------------------- 4. typed text


def test_typed_text_that_is_not_utf8_is_read_as_latin1_and_the_session_goes_on(tmp_path, geometry):
    lines = []
    s = Session(tmp_path / "T", geometry, layer="r", scale=5000, monitor=lines.append)
    s.handle_all(Press(b) for b in ("DESCR", "3", "ENTER"))
    s.handle(Keys("M\udcfcller"))  # what sys.stdin gives for b"M\xfcller" on a Latin-1 terminal
    s.handle(Mark(*geometry.tablet(2684000.0, 1247800.0)))
    s.handle(Press("ENTER"))
    s.handle(Keys(b"Br\xfccke"))  # raw bytes (the live keyboard, a recording)
    s.handle(Press("ENTER"))
    s.handle(Keys("\ud800"))  # a surrogate no decoder makes: replaced, not a crash
    assert any("not UTF-8 (byte 0xfc at 2); read as Latin-1: 'Müller'" in x for x in lines)
    assert s.map.layers["r"].texts["text"].tolist() == ["Müller", "Brücke"]
    s.close()
    events = read_journal(s.journal_path).events
    assert Keys("Müller") in events
    assert Keys("Brücke") in events
    s2 = Session(tmp_path / "T", geometry)
    assert s2.map.layers["r"].texts["text"].tolist() == ["Müller", "Brücke"]
    s2.close()


def test_run_live_and_replay_decode_keyboard_bytes(tmp_path, geometry):
    assert decode_typed(b"Kirchweg") == ("Kirchweg", None)
    s = Session(tmp_path / "T", geometry, layer="r", scale=5000)
    s.handle_all(Press(b) for b in ("DESCR", "3", "ENTER"))
    chunks = [Chunk(0.0, "keyboard", b"Gr\xfcn\n")]
    run_tablet_stream(s, chunks, make_parser("calcomp", CFG), ReportDecoder(CFG, BUTTONS))
    assert s.engine.state.text == "Grün"

    class Quiet:
        in_waiting = 0

        def __init__(self):
            self.reads = 0

        def read(self, n):
            self.reads += 1
            if self.reads > 3:
                raise OSError("gone")
            return b""

    typed = queue.Queue()
    typed.put("Z\udcfcrich")
    run_live(s, Quiet(), make_parser("calcomp", CFG), ReportDecoder(CFG, BUTTONS), typed)
    assert s.engine.state.text == "Zürich"
    s.close()


# ----------------------------------------------------------------- 6. hostile journals


def _head(tmp_path, geometry):
    s = Session(tmp_path / "H", geometry, layer="r", scale=5000)
    s.close()
    return s.journal_path, json.loads(s.journal_path.read_bytes().split(b"\n")[0])


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (b'{"mark": [NaN, 1.0]}', "finite"),
        (b'{"mark": [1e308, 1.0]}', "finite and within"),
        (b'{"mark": [Infinity, 1.0]}', "finite"),
        (b'{"mark": [' + b"9" * 400 + b", 1]}", "finite and within"),
        (b'{"mark": [' + b"9" * 5000 + b", 1]}", "bad JSON"),
        (b'{"mark": [1, 2, 3]}', "two numbers"),
        (b'{"mark": [true, 2]}', "two numbers"),
        (b'{"mark": "1,2"}', "two numbers"),
        (b"[" * 100000 + b"]" * 100000, "nested too deeply"),
        (b'{"a": ' * 50000 + b"1" + b"}" * 50000, "nested too deeply"),
        (b'{"press": 5}', "not a button name"),
        (b'{"press": "JUMP"}', "not a button name"),
        (b'{"keys": ["x"]}', "string"),
        (b'{"keys": "\\udcfc"}', "surrogate"),
        (b'{"keys": "' + b"x" * 20000 + b'"}', "at most"),
        (b'{"press": "ENTER", "keys": "x"}', "expected one of"),
        (b'{"files": {"r": {"size": "1", "sha256": "00"}}}', "layer r"),
        (b"\xff\xfe", "not UTF-8"),
        (b"5", "expected one of"),
    ],
)
def test_hostile_journal_events_are_one_clear_error(tmp_path, geometry, line, reason):
    path, _ = _head(tmp_path, geometry)
    with open(path, "ab") as fh:
        fh.write(line + b"\n")
    with pytest.raises(FormatError, match=r"H\.journal: line 2: bad journal event") as exc:
        Session(tmp_path / "H", geometry)
    assert reason in str(exc.value)
    assert len(str(exc.value)) < 400
    assert not (tmp_path / "H.lock").exists()


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"journal": True}, "version number"),
        ({"journal": "2"}, "version number"),
        ({"journal": 7}, "version 7 is not supported"),
        ({"layer": 5}, "layer extension"),
        ({"layer": "road"}, "1 to 3 letters"),
        ({"map": 5}, "APY ASCII text"),
        ({"settings": "abc"}, "must be an object"),
        ({"settings": {"snap_mm": "abc"}}, "snap_mm must be a number"),
        ({"settings": {"snap_mm": float("nan")}}, "snap_mm must be a number"),
        ({"settings": {"autosave_every": 1.5}}, "autosave_every must be a whole number"),
        ({"settings": {"autosave_every": 10**400}}, "autosave_every must be a whole number"),
        ({"settings": {"start_z_m": True}}, "start_z_m must be a number"),
        ({"settings": {"speed": 1}}, "unknown setting"),
        ({"files": {"r": None}}, "layer r"),
        ({"files": []}, "object of layer files"),
    ],
)
def test_hostile_journal_heads_are_one_clear_error(tmp_path, geometry, change, reason):
    path, head = _head(tmp_path, geometry)
    head.update(change)
    path.write_text(json.dumps(head) + "\n")
    with pytest.raises(FormatError, match=r"H\.journal: line 1: bad journal head") as exc:
        Session(tmp_path / "H", geometry)
    assert reason in str(exc.value)


def test_a_huge_integer_in_the_head_and_deep_nesting_are_errors_not_crashes(tmp_path, geometry):
    path, head = _head(tmp_path, geometry)
    text = json.dumps(head)
    path.write_text(text.replace('"layer": "r"', '"layer": ' + "1" * 5000) + "\n")
    with pytest.raises(FormatError, match="line 1: bad journal head: bad JSON"):
        read_journal(path)
    path.write_bytes(b"[" * 200000 + b"\n")
    with pytest.raises(FormatError, match="line 1: bad journal head: JSON nested too deeply"):
        read_journal(path)
    res = _cli(tmp_path / "H", "--orientation", ORIENTATION, "--recover-only")
    _one_line_error(res, "H.journal: line 1: bad journal head")


def test_session_settings_are_checked(tmp_path, geometry):
    with pytest.raises(ApygisError, match="snap_mm must be a number"):
        Session(tmp_path / "S", geometry, settings={"snap_mm": "abc"})
    assert not list(tmp_path.iterdir()) or not list(tmp_path.glob("S.*"))


def test_events_the_journal_would_refuse_are_never_journaled(tmp_path, geometry):
    """What a session writes, its recovery must read: absurd input is ignored, and told."""
    lines = []
    s = Session(tmp_path / "M", geometry, layer="r", scale=5000, monitor=lines.append)
    assert s.handle(Mark(float("nan"), 1.0)) == []
    assert s.handle(Mark(1e12, 1.0)) == []
    assert s.handle(Press("JUMP")) == []
    assert s.handle(Keys("x" * 20_000)) == []
    assert any("off any tablet: ignored" in x for x in lines)
    assert any("'JUMP' is not a button of the pad: ignored" in x for x in lines)
    assert any("typed text of 20000 characters" in x for x in lines)
    s.handle(Press("DESCR"))
    s.close()
    assert read_journal(s.journal_path).events == [Press("DESCR")]


# ----------------------------------------------------------------- 9. a full disk


def _enospc(monkeypatch, state):
    real = apygis.write

    def write(m, path, driver=None, **kw):
        if state["full"]:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(m, path, driver=driver, **kw)

    monkeypatch.setattr(apygis, "write", write)


def test_autosave_on_a_full_disk_loses_nothing(tmp_path, geometry, monkeypatch):
    base = _sheet(tmp_path)
    state = {"full": True}
    _enospc(monkeypatch, state)
    lines = []
    s = Session(base, geometry, layer="r", settings={"autosave_every": 2}, monitor=lines.append)
    before = _snapshot(tmp_path)
    _symbols(s, geometry, 5)  # two autosaves fail; compiling goes on
    assert s.engine.entries == 5
    assert s.save_failures == 2
    failed = [x for x in lines if x.startswith("SAVE FAILED (autosave)")]
    assert len(failed) == 2
    assert "No space left on device" in failed[0]
    assert "the journal ZH1091.journal still holds every entry" in failed[0]
    s.handle_all(Press(b) for b in ("PROCEED", "PROCEED", "4"))
    assert s.save_failures == 4  # and the two PROCEED saves
    with pytest.raises(SaveError, match=r"could not be saved at the end.*keeps every entry"):
        s.handle(Press("ENTER"))  # terminate
    assert not s.finished
    assert s.journal_path.exists()
    assert not base.with_name("ZH1091.lock").exists()
    for name, data in before.items():  # the layer files are as they were
        if name.startswith("ZH1091.") and name not in ("ZH1091.journal", "ZH1091.lock"):
            assert (tmp_path / name).read_bytes() == data
    state["full"] = False  # room again: the next session recovers and finishes it
    s2 = Session(base, geometry, monitor=lines.append)
    assert s2.finished
    assert not s2.journal_path.exists()
    assert len(apygis.read(base).layers["r"].symbols) == len(s.map.layers["r"].symbols)
    assert any(x.startswith("SAVE FAILED") for x in lines)


def test_a_full_disk_at_the_end_of_a_replay_is_exit_1_with_the_journal_kept(tmp_path, monkeypatch):
    state = {"full": False}
    _enospc(monkeypatch, state)
    out = tmp_path / "out"
    real_save = Session.save

    def save(self, reason):
        state["full"] = reason != "recovery" and self.entries > 0
        return real_save(self, reason)

    monkeypatch.setattr(Session, "save", save)
    res = CliRunner().invoke(main, ["session", *map(str, _replay_args(out))])
    err = _one_line_error(res, "could not be saved at the end", "ZH1091.journal")
    assert "No space left on device" in err
    assert "SAVE FAILED" in res.output
    assert (out / "ZH1091.journal").exists()
    assert not (out / "ZH1091.lock").exists()
    monkeypatch.undo()
    res = _cli(out / "ZH1091", "--orientation", ORIENTATION, "--recover-only")
    assert res.exit_code == 0, res.output
    assert "compilation terminated" in res.output
    assert apygis.read(out / "ZH1091") == apygis.read(SESSION / "ZH1091-revision.expected.apa")


def test_a_journal_that_cannot_be_written_stops_the_session_cleanly(tmp_path, geometry):
    s = Session(tmp_path / "J", geometry, layer="r", scale=5000)

    class Full:
        closed = False

        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

        def flush(self):
            raise OSError(errno.ENOSPC, "No space left on device")

        def fileno(self):
            return -1

        def close(self):
            self.closed = True

    s.journal._fh = Full()
    with pytest.raises(ApygisError, match=r"J\.journal: cannot write the journal"):
        s.handle(Press("DESCR"))
    with pytest.raises(ApygisError, match="the session stopped"):
        s.handle(Press("DESCR"))
    s.lock.release()


def test_lock_holder_note_and_release_are_robust(tmp_path):
    from apygis.session import SessionLock

    lock = SessionLock.acquire(tmp_path / "L")
    info = json.loads((tmp_path / "L.lock").read_text())
    assert info["pid"] == os.getpid()
    assert info["started"].endswith("Z")
    lock.release()
    lock.release()
    assert not (tmp_path / "L.lock").exists()
    time.sleep(0)  # a new lock after the old file is gone
    with SessionLock.acquire(tmp_path / "L"):
        assert (tmp_path / "L.lock").exists()
