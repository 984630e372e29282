"""A session's journal, replayed in the view's process, gives the session's map and entries.

The view of a session (``session --view``) never reads the session's memory:
its process replays the journal (:class:`SessionReplica`) and turns the
effects into the hub's changes (:class:`ChangeFeed`). These tests hold that
the replica, read while the session writes, is the session at every step,
and that the hub fed from it holds the session's records, without the check
the end of a session sends.
"""

from __future__ import annotations

import contextlib
import pickle

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import apygis
from apygis.compile.events import Keys, Mark, Press
from apygis.compile.oriented import OrientedGeometry
from apygis.errors import FormatError
from apygis.orient.io import load_orientation
from apygis.session import Session
from apygis.session.journal import JournalTail
from apygis.view import SessionReplica, deliver, map_hub
from apygis.view.scene import layer_rows
from tests.conftest import SAMPLES
from tests.session.test_session import crash_with_a_line_in_progress
from tests.view.test_server import _replay_events


def _geometry():
    return OrientedGeometry(load_orientation(SAMPLES / "session" / "ZH1091.orientation.json"))


def _session(tmp_path, layer="c"):
    apygis.write(apygis.read(SAMPLES / "ZH1091"), tmp_path / "ZH1091", driver="apy")
    return Session(tmp_path / "ZH1091", _geometry(), layer=layer)


@pytest.fixture
def opened():
    """``opened(path)``: the file opened for reading (binary), closed after the test."""
    with contextlib.ExitStack() as stack:
        yield lambda path: stack.enter_context(open(path, "rb"))


def _spec(sess, offset=0, entries=0):
    return {
        "path": str(sess.journal_path),
        "offset": offset,
        "entries": entries,
        "display": {"scale": 1.0, "crosshair": 1.0},
        "geometry": pickle.loads(pickle.dumps(sess.geometry)),  # as the child gets it
        "library": sess.library,
    }


def _rows(m) -> dict:
    return {lay.ext: {t: sorted(r) for t, r in layer_rows(lay).items()} for lay in m}


def _hub_rows(hub) -> dict:
    return {
        ext: {t: sorted(rows.values()) for t, rows in tables.items()}
        for ext, tables in hub.layers.items()
    }


def test_the_replica_is_the_session_at_every_step(tmp_path, opened):
    sess = _session(tmp_path)
    head = apygis.read(tmp_path / "ZH1091", driver="apy")
    hub = map_hub(head, kind="session")
    replica = SessionReplica(opened(sess.journal_path), _spec(sess))
    events = _replay_events(sess)
    assert len(events) > 300
    checked = 0
    for k, ev in enumerate(events):
        sess.handle(ev)
        if k % 37 == 0 or sess.finished:
            if not sess.journal.closed:
                sess.journal.flush()
            deliver(hub, replica.catch_up(), None, None)
            assert replica.entries == sess.entries
            assert replica.engine.mode == sess.engine.mode
            assert replica.display.scale == sess.display.scale
            assert _rows(replica.map) == _rows(sess.map)
            assert _hub_rows(hub) == _rows(sess.map)  # no full check needed to get there
            checked += 1
        if sess.finished:
            break
    assert sess.finished
    assert replica.finished
    assert checked > 10
    assert [e[0] for e in hub.entries] == list(range(1, sess.entries + 1))
    assert hub.corrections == 0  # the saves' full comparisons found nothing to correct


def test_a_replica_started_late_starts_from_the_offset(tmp_path, opened):
    sess = _session(tmp_path, layer="t")
    g = sess.geometry
    for b in ("DESCR", "2", "ENTER", "ENTER", "1", "2", "ENTER"):
        sess.handle(Press(b))
    for k in range(5):
        sess.handle(Mark(*g.tablet(2683500.0 + 20 * k, 1247900.0 + 3 * k)))
        sess.handle(Press("ENTER"))
    offset = sess.journal.flush()
    hub = map_hub(sess.map, kind="session")
    replica = SessionReplica(opened(sess.journal_path), _spec(sess, offset, sess.entries))
    assert replica.entries == 5
    assert replica.catch_up() == []  # what came before it started is in the hub already
    for k in range(5, 8):
        sess.handle(Mark(*g.tablet(2683500.0 + 20 * k, 1247900.0 + 3 * k)))
        sess.handle(Press("ENTER"))
    changes = replica.catch_up()
    deliver(hub, changes, None, None)
    assert [e[0] for c in changes for e in c.get("entries", [])] == [6, 7, 8]
    assert _hub_rows(hub) == _rows(sess.map)
    sess.close()


def test_a_removed_journal_is_read_to_its_end(tmp_path, opened):
    """A terminated session removes its journal: the replica holding it open reads it all."""
    sess = _session(tmp_path)
    replica = SessionReplica(opened(sess.journal_path), _spec(sess))
    for ev in _replay_events(sess):
        sess.handle(ev)
        if sess.finished:
            break
    assert sess.finished
    assert not sess.journal_path.exists()
    replica.catch_up()
    assert replica.finished
    assert _rows(replica.map) == _rows(sess.map)


def test_the_tail_waits_for_a_line_to_be_complete(tmp_path, opened):
    sess = _session(tmp_path)
    sess.journal.flush()
    path = sess.journal_path
    tail = JournalTail(opened(path), path)
    assert tail.read() == []
    with open(path, "ab") as fh:
        fh.write(b'{"press": "DE')
        fh.flush()
        assert tail.read() == []
        fh.write(b'SCR"}\n{"mark": [1.5, 2.5]}\n{"files": {}}\n{"keys": "12"')
        fh.flush()
        got = tail.read()
        assert got == [Press("DESCR"), Mark(1.5, 2.5)]  # the save record is no event
        fh.write(b"}\n")
        fh.flush()
        (keys,) = tail.read()
        assert keys.text == "12"
    with open(path, "ab") as fh:
        fh.write(b'{"press": "NO-SUCH-BUTTON"}\n')
    with pytest.raises(FormatError, match=r"line 6.*NO-SUCH-BUTTON"):
        tail.read()
    sess.journal.close()
    sess.lock.release()


def test_the_tail_reads_up_to_a_given_byte(tmp_path, opened):
    sess = _session(tmp_path)
    sess.handle(Press("DESCR"))
    sess.handle(Press("2"))
    upto = sess.journal.flush()
    sess.handle(Press("ENTER"))
    sess.journal.flush()
    tail = JournalTail(opened(sess.journal_path), sess.journal_path)
    assert tail.read(upto=upto) == [Press("DESCR"), Press("2")]
    assert tail.position == upto
    assert tail.read(upto=upto) == []
    assert tail.read() == [Press("ENTER")]
    sess.close()


def test_the_geometry_travels_to_the_views_process():
    g = _geometry()
    copy = pickle.loads(pickle.dumps(g))
    X, Y, Z = 2683500.0, 1247900.0, 480.0
    assert copy.loop.update(X, Y, Z) == g.loop.update(X, Y, Z)
    assert copy.height_step_m == g.height_step_m
    assert copy.tablet(X, Y) == g.tablet(X, Y)


_EVENTS = st.lists(
    st.one_of(
        st.builds(
            Mark,
            st.floats(-100_000.0, 100_000.0, allow_nan=False),
            st.floats(-100_000.0, 100_000.0, allow_nan=False),
        ),
        st.sampled_from(["ENTER", "DESCR", "1", "UNDO", "PROCEED"]).map(Press),
        st.text(max_size=20).map(Keys),
    ),
    max_size=40,
)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(events=_EVENTS, cuts=st.lists(st.integers(1, 200), min_size=1, max_size=20))
def test_the_tail_reads_what_the_journal_reader_reads(tmp_path_factory, events, cuts):
    """Written in pieces of any size, the tail gives the events written, as read_journal does."""
    from apygis.model.map import MapFile
    from apygis.session.journal import Journal, read_journal

    d = tmp_path_factory.mktemp("j")
    j = Journal.create(d / "m.journal", MapFile("M"), "c", {}, {})
    written = []
    for ev in events:
        try:
            j.append(ev, sync=False)
        except Exception:  # text the journal cannot hold (surrogates) is refused there
            continue
        written.append(ev)
    j.close()
    data = (d / "m.journal").read_bytes()
    want = read_journal(d / "m.journal").events
    head_end = data.index(b"\n") + 1
    live = d / "live.journal"
    live.write_bytes(data[:head_end])
    got = []
    with open(live, "rb") as fh, open(live, "ab") as w:
        tail = JournalTail(fh, live)
        pos, k = head_end, 0
        while pos < len(data):
            step = cuts[k % len(cuts)]
            w.write(data[pos : pos + step])
            w.flush()
            got.extend(tail.read())
            pos, k = pos + step, k + 1
    assert got == want
    assert got == written


def test_a_recovered_session_is_followed_from_where_it_stands(tmp_path, opened):
    """After a crash and a recovery (the journal replayed, a torn line cut), the view follows."""
    g = _geometry()
    base = tmp_path / "T"
    crash_with_a_line_in_progress(base, g)
    s2 = Session(base, g, layer="c")
    assert s2.recovered == 13
    hub = map_hub(s2.map, kind="session")
    replica = SessionReplica(opened(s2.journal_path), _spec(s2, s2.journal.flush(), s2.entries))
    assert replica.engine.mode == s2.engine.mode == "line"
    for k in range(3, 6):
        s2.handle(Mark(*g.tablet(2684000.0 + 10 * k, 1247800.0)))
        s2.handle(Press("ENTER"))
    s2.journal.flush()
    changes = replica.catch_up()
    deliver(hub, changes, None, None)
    assert [e[0] for c in changes for e in c.get("entries", [])] == [4, 5, 6]
    assert _hub_rows(hub) == _rows(s2.map)
    assert replica.map.layers["r"].closure(1).points == (1, 2, 3, 4, 5, 6)
    s2.close()
