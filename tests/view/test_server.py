"""The view server and hub without a browser: token, view only, pages in order, nobody waits."""

from __future__ import annotations

import asyncio
import os
import signal
import threading
import time
import urllib.error
import urllib.request

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import apygis
from apygis.compile.events import Keys, Mark, Press
from apygis.compile.oriented import OrientedGeometry
from apygis.errors import ViewError
from apygis.instrument.pad import BUTTONS
from apygis.instrument.replay import Replayer, check_recording
from apygis.instrument.tablet import TabletConfig, make_parser
from apygis.orient.io import load_orientation
from apygis.session import ReportDecoder, Session
from apygis.view import SessionFeed, Viewer, ViewHub, ViewProcess, ViewServer, map_hub, session_hub
from apygis.view.scene import Pens, layer_rows
from tests.conftest import SAMPLES
from tests.view.wsclient import WsClient


def _get(url: str, method: str = "GET"):
    req = urllib.request.Request(url, method=method)
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers), exc.read()


@pytest.fixture
def map_server():
    m = apygis.read(SAMPLES / "ZH1091")
    server = ViewServer(map_hub(m))
    server.start()
    yield server, m
    server.stop()


def _rows(m) -> dict:
    return {lay.ext: layer_rows(lay) for lay in m}


def test_every_address_needs_the_token(map_server):
    server, _ = map_server
    base = server.url.rsplit("/", 2)[0]  # http://127.0.0.1:PORT
    assert server.url.startswith("http://127.0.0.1:")
    assert len(server.token) >= 20
    for path in (
        "/",
        "/app.js",
        "/ws",
        "/state.json",
        "/x" + server.token + "/",
        "/" + server.token[:-1] + "/",
    ):
        status, _, body = _get(base + path)
        assert status == 403, path
        assert b"state" not in body
    status, headers, body = _get(server.url)
    assert status == 200
    assert b"app.js" in body
    assert "default-src 'none'" in headers["Content-Security-Policy"]
    assert headers["Cache-Control"] == "no-store"
    status, _, body = _get(server.url + "app.js")
    assert status == 200
    assert b"apygisView" in body
    # nothing in the page is loaded from elsewhere
    for name in ("", "app.js", "style.css"):
        _, _, body = _get(server.url + name)
        assert b"http://" not in body.replace(b"http://www.w3.org", b"")
        assert b"https://" not in body


def test_the_page_can_only_view(map_server):
    server, m = map_server
    for method in ("POST", "PUT", "DELETE", "PATCH"):
        status, _, _ = _get(server.url + "state.json", method)
        assert status == 405, method
    c = WsClient(server.url)
    try:
        c.wait(lambda mr: mr.seq == 0)
        assert c.mirror.records() == _rows(m)
    finally:
        c.close()
    bad = WsClient(server.url, origin="http://evil.example")
    assert bad.status_code == 403


def test_a_bound_address_is_refused_with_one_line():
    first = ViewServer(None, port=0)
    first.bind()
    try:
        second = ViewServer(None, port=first.port)
        with pytest.raises(ViewError, match=rf"cannot serve on 127.0.0.1:{first.port}"):
            second.bind()
        with pytest.raises(ViewError, match="cannot serve on host"):
            ViewServer(None, host="no-such-host.invalid").bind()
    finally:
        first.stop()


# --------------------------------------------------------------------------- the hub


def _hub(limit: int) -> ViewHub:
    hub = ViewHub("session", Pens(), {}, {"id": "T"}, queue_limit=limit)
    hub.load_layers({"r": {"symbols": [], "line_points": [], "texts": []}})
    return hub


def _entry(hub: ViewHub, n: int) -> None:
    hub.apply(
        {
            "entries": [[n, "added", "r", "symbols", n, None]],
            "upsert": {"r": {"symbols": [[n, 1.0 * n, 2.0, 3.0, 5]]}},
        }
    )


def test_a_page_that_falls_behind_gets_the_whole_state_and_loses_nothing():
    async def main():
        hub = _hub(limit=3)
        sent: list[str] = []
        gate = asyncio.Event()

        async def send(text):
            await gate.wait()  # a page that does not read
            sent.append(text)

        v = Viewer(send, hub.queue_limit)
        hub.add(v)
        task = asyncio.ensure_future(v.run(hub))
        await asyncio.sleep(0)
        t0 = time.perf_counter()
        for n in range(1, 201):
            _entry(hub, n)  # never waits for the page
        assert time.perf_counter() - t0 < 1.0
        assert len(v.pending) <= 3
        gate.set()
        for _ in range(100):
            await asyncio.sleep(0.01)
            if not v.pending and not v.resync:
                break
        task.cancel()
        return hub, v, sent

    import json

    _, v, sent = asyncio.run(main())
    msgs = [json.loads(s) for s in sent]
    assert msgs[0]["t"] == "state"
    assert msgs[0]["seq"] == 0
    assert v.resyncs >= 1
    states = [m for m in msgs[1:] if m["t"] == "state"]
    assert states, "the page that fell behind was sent the whole state"
    last = msgs[-1]
    if last["t"] == "state":
        final_entries = last["entries"]
    else:
        final_entries = states[-1]["entries"] + [
            e for m in msgs[msgs.index(states[-1]) + 1 :] for e in m.get("entries", [])
        ]
    assert [e[0] for e in final_entries] == list(range(1, 201))
    seqs = [m["seq"] for m in msgs if m["t"] == "delta"]
    assert seqs == sorted(set(seqs))


def test_pages_that_keep_up_get_every_delta_in_order():
    async def main():
        hub = _hub(limit=1000)
        got: list[list[str]] = [[], []]
        viewers = [Viewer(lambda t, k=k: _append(got[k], t), hub.queue_limit) for k in range(2)]
        tasks = []
        for v in viewers:
            hub.add(v)
            tasks.append(asyncio.ensure_future(v.run(hub)))
        await asyncio.sleep(0.01)
        for n in range(1, 51):
            _entry(hub, n)
            await asyncio.sleep(0)
        await asyncio.sleep(0.05)
        for t in tasks:
            t.cancel()
        return got

    async def _append(lst, text):
        lst.append(text)

    import json

    for texts in asyncio.run(main()):
        msgs = [json.loads(t) for t in texts]
        assert msgs[0]["t"] == "state"
        assert [m["t"] for m in msgs[1:]] == ["delta"] * 50
        assert [m["entries"][0][0] for m in msgs[1:]] == list(range(1, 51))


# --------------------------------------------------------------------------- a session


def _session(tmp_path):
    apygis.write(apygis.read(SAMPLES / "ZH1091"), tmp_path / "ZH1091", driver="apy")
    geometry = OrientedGeometry(load_orientation(SAMPLES / "session" / "ZH1091.orientation.json"))
    return Session(tmp_path / "ZH1091", geometry, layer="c")


def _viewed(tmp_path):
    """A session, its view's process started, and the feed: ``(session, server, feed)``."""
    sess = _session(tmp_path)
    server = ViewProcess(session_hub(sess))
    server.start()
    return sess, server, SessionFeed(server, sess)


def _replay_events(sess):
    rec = SAMPLES / "session" / "ZH1091-revision.rec"
    meta = check_recording(rec)
    cfg = TabletConfig(counts_per_mm=float(meta["counts_per_mm"]))
    parser, decoder = make_parser(meta["protocol"], cfg), ReportDecoder(cfg, BUTTONS)
    out = []
    for ch in Replayer(rec):
        if ch.direction != "rx":
            continue
        if ch.channel == "tablet":
            for report in parser.feed(ch.data):
                out.extend(decoder.events(report))
        elif ch.channel == "keyboard":
            out.extend(Keys(line) for line in ch.data.splitlines())
    for report in parser.flush():
        out.extend(decoder.events(report))
    return out


def _want(m) -> dict:
    return {k: {t: sorted(r) for t, r in v.items()} for k, v in _rows(m).items()}


def test_pages_opened_before_and_during_a_session_end_equal_to_its_map(tmp_path):
    sess, server, feed = _viewed(tmp_path)
    events = _replay_events(sess)
    early = WsClient(server.url)
    slow = WsClient(server.url, read=False)  # reads nothing until the end
    late = None
    try:
        early.wait(lambda m: m.seq == 0)
        half = 0
        while sess.entries < 12:
            sess.handle(events[half])
            half += 1
        late = WsClient(server.url)  # opened in the middle: gets the whole current state
        late.wait(lambda m: m.seq >= 0)
        first = late.mirror.kinds[0]
        assert first == "state"
        for ev in events[half:-1]:
            sess.handle(ev)
        # replayed from the journal in the view's process: the same records, before any check
        early.wait(lambda m: len(m.entries) == sess.entries and m.records() == _want(sess.map))
        sess.handle(events[-1])
        assert sess.finished
        feed.end(sess)
        slow.start_reading()
        want = _rows(sess.map)
        for c in (early, late, slow):
            c.wait(
                lambda m: (
                    m.ended
                    and m.records()
                    == {k: {t: sorted(r) for t, r in v.items()} for k, v in want.items()}
                )
            )
        # the early page saw every entry arrive, one delta at a time, in order
        nums = [e[0] for e in early.mirror.entries]
        assert nums == list(range(1, sess.entries + 1))
        assert early.mirror.kinds.count("state") == 1
        # the late page got the entries made before it opened within its first state
        assert [e[0] for e in late.mirror.entries] == nums
        late.wait(lambda m: m.status.get("mode") == "terminated")  # the last status arrives
        kinds = {o["kind"] for o in early.mirror.overlays}
        assert {"area", "dhi"} <= kinds
    finally:
        for c in (early, slow, late):
            if c is not None:
                c.close()
        server.stop()


def test_the_session_never_waits_for_the_view(tmp_path):
    """A view's process that is stuck (stopped for 2 s) costs the session nothing."""
    sess, server, feed = _viewed(tmp_path)
    client = WsClient(server.url)
    try:
        client.wait(lambda m: m.seq == 0)
        os.kill(server.pid, signal.SIGSTOP)
        threading.Timer(2.0, os.kill, (server.pid, signal.SIGCONT)).start()
        geometry = sess.geometry
        t0 = time.perf_counter()
        sess.handle(Press("DESCR"))
        for b in ("2", "ENTER", "ENTER", "1", "2", "ENTER"):
            sess.handle(Press(b))
        for k in range(40):
            sess.handle(Mark(*geometry.tablet(2683500.0 + 10 * k, 1247900.0)))
            sess.handle(Press("ENTER"))
        took = time.perf_counter() - t0
        assert took < 1.5, took  # had it waited for the view, it would take 2 s or more
        assert sess.entries == 40
        client.wait(lambda m: len(m.entries) == 40, timeout=15)
        rows = _rows(sess.map)["t"]["line_points"] if "t" in sess.map.layers else None
        got = client.mirror.records()
        assert got[sess.engine.layer_ext]["line_points"] == sorted(
            _rows(sess.map)[sess.engine.layer_ext]["line_points"]
        )
        del rows
    finally:
        feed.close()
        client.close()
        server.stop()
        sess.close()


def test_a_closed_page_and_a_failing_observer_do_not_stop_the_session(tmp_path):
    sess, server, feed = _viewed(tmp_path)
    calls = []

    def broken(session, event, effects):
        calls.append(event)
        raise RuntimeError("a display bug")

    sess.subscribe(broken)
    c = WsClient(server.url)
    c.wait(lambda m: m.seq == 0)
    c.close()  # the page goes away
    try:
        for b in ("DESCR", "1", "ENTER", "0", "6", "ENTER"):
            sess.handle(Press(b))
        sess.handle(Mark(*sess.geometry.tablet(2683600.0, 1247950.0)))
        sess.handle(Press("ENTER"))
        assert sess.entries == 1
        assert len(calls) == 1  # dropped after its first failure
        server.stop()  # the server is gone: the session goes on
        sess.handle(Mark(*sess.geometry.tablet(2683700.0, 1247950.0)))
        sess.handle(Press("ENTER"))
        assert sess.entries == 2
        feed._thread.join(2.0)  # the feed's thread saw the server go, and ended
        assert not feed._thread.is_alive()
    finally:
        server.stop()
        sess.close()


def test_a_killed_view_process_does_not_stop_the_session(tmp_path):
    sess, server, feed = _viewed(tmp_path)
    try:
        for b in ("DESCR", "1", "ENTER", "0", "6", "ENTER"):
            sess.handle(Press(b))
        os.kill(server.pid, signal.SIGKILL)
        for k in range(30):
            sess.handle(Mark(*sess.geometry.tablet(2683600.0 + 5 * k, 1247950.0)))
            sess.handle(Press("ENTER"))
        assert sess.entries == 30
        feed.end(sess)  # told nobody: no error
        feed._thread.join(2.0)
        assert not feed._thread.is_alive()
        assert server.closed
    finally:
        server.stop()
        sess.close()


# the changes of a session, delivered in batches of any size: the page ends where the hub is

_NUMS = st.integers(1, 6)
_ROW = st.builds(lambda n, x: [n, float(x), 0.0, 0.0, 1], _NUMS, st.integers(0, 3))
_CHANGE = st.one_of(
    st.builds(lambda rows: {"upsert": {"r": {"symbols": rows}}}, st.lists(_ROW, max_size=3)),
    st.builds(lambda nums: {"remove": {"r": {"symbols": nums}}}, st.lists(_NUMS, max_size=3)),
    st.builds(
        lambda rows: {"full": {"r": {"symbols": list({r[0]: r for r in rows}.values())}}},
        st.lists(_ROW, max_size=4),
    ),
)


def _page_applies(page: dict[int, list], delta: dict) -> None:
    """What the page's applyDelta does to a table: upserts, then removes."""
    for r in delta.get("upsert", {}).get("r", {}).get("symbols", []):
        page[r[0]] = r
    for n in delta.get("remove", {}).get("r", {}).get("symbols", []):
        page.pop(n, None)


@settings(max_examples=300, deadline=None)
@given(st.lists(_CHANGE, max_size=12), st.lists(st.integers(1, 5), min_size=1, max_size=12))
def test_changes_in_batches_leave_the_page_equal_to_the_hub(changes, sizes):
    import json

    one, batched = _hub(limit=1000), _hub(limit=1000)
    pages: list[dict[int, list]] = [{}, {}]
    sent: list[list[dict]] = [[], []]

    async def nowhere(text: str) -> None:
        raise AssertionError("the deltas are read from the queue")

    for hub in (one, batched):
        v = Viewer(nowhere, 1000)
        v.resync = False  # a page that has the (empty) state already
        hub.add(v)
    for c in changes:
        one.apply(json.loads(json.dumps(c)))
    pos, k = 0, 0
    while pos < len(changes):
        size = sizes[k % len(sizes)]
        batched.apply_all([json.loads(json.dumps(c)) for c in changes[pos : pos + size]])
        pos, k = pos + size, k + 1
    for k, hub in enumerate((one, batched)):
        (v,) = hub.viewers
        for _, text in v.pending:
            delta = json.loads(text)
            sent[k].append(delta)
            _page_applies(pages[k], delta)
        assert pages[k] == hub.layers["r"]["symbols"]
    assert one.layers == batched.layers
    assert len(sent[1]) <= len(sent[0])
    for delta in sent[1]:  # a record is upserted or removed, never both in one delta
        up = {r[0] for r in delta.get("upsert", {}).get("r", {}).get("symbols", [])}
        assert not up & set(delta.get("remove", {}).get("r", {}).get("symbols", []))
