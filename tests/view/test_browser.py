"""The page in a real browser (headless Chromium): the sample map, and the sample session live.

Run as a user runs them: ``apygis view`` and ``apygis session --view`` as
subprocesses, the page loaded by Chromium through WebDriver, what the page
holds read through its hook ``window.apygisView`` and compared with what
apygis wrote.
"""

from __future__ import annotations

import json
import re
import time
import urllib.request

import pytest

import apygis
from apygis.view.scene import layer_rows

pytestmark = pytest.mark.browser

SESSION = [
    "session",
    "samples/ZH1091",
    "--orientation",
    "samples/session/ZH1091.orientation.json",
    "--replay",
    "samples/session/ZH1091-revision.rec",
    "-o",
    "out",
    "--motors",
    "sim",
    "--overwrite",
    "--view",
    "--no-browser",
]

ENTRY_RE = re.compile(
    r"^entry (\d+): (?:(symbol|line point|text) (\d+) (added|deleted) in \w+\.(\w+)"
    r"|undo in \w+\.(\w+)"
    r"|line point (\d+) joined to (\d+) in \w+\.(\w+))"
)
TABLE = {"symbol": "symbols", "line point": "line_points", "text": "texts"}


def _until(chrome, script: str, timeout: float = 30.0):
    deadline = time.monotonic() + timeout
    while True:
        got = chrome.execute_script(script)
        if got:
            return got
        if time.monotonic() > deadline:
            raise AssertionError(f"not true within {timeout} s: {script}")
        time.sleep(0.05)


def _hook(chrome, expr: str):
    return chrome.execute_script(f"return window.apygisView.{expr};")


def _entries_of_monitor(text: str) -> list[list]:
    out = []
    for line in text.splitlines():
        m = ENTRY_RE.match(line)
        if not m:
            continue
        n = int(m.group(1))
        if m.group(2):
            verb = m.group(4)
            out.append([n, verb, m.group(5), TABLE[m.group(2)], int(m.group(3))])
        elif m.group(6):
            out.append([n, "undone", m.group(6), None, None])
        else:
            out.append([n, "linked", m.group(9), "line_points", int(m.group(7))])
    return out


def _rows_of_map(m) -> dict:
    return {lay.ext: layer_rows(lay) for lay in m}


def _centimetres(records: dict) -> dict:
    """Records with X, Y, Z rounded to the centimetre, as the APY layer files store them."""
    return {
        ext: {
            t: [[r[0], *(round(v, 2) for v in r[1:4]), *r[4:]] for r in rows]
            for t, rows in tables.items()
        }
        for ext, tables in records.items()
    }


def _replayed_map(sandbox, tmp_path):
    """The map of the sample session replayed here, through the same Session and parsers."""
    from apygis.compile.oriented import OrientedGeometry
    from apygis.instrument.pad import BUTTONS
    from apygis.instrument.replay import Replayer, check_recording
    from apygis.instrument.tablet import TabletConfig, make_parser
    from apygis.model.symbols import load_library
    from apygis.orient.io import load_orientation
    from apygis.session import ReportDecoder, Session, run_tablet_stream

    rec = sandbox / "samples" / "session" / "ZH1091-revision.rec"
    meta = check_recording(rec)
    cfg = TabletConfig(counts_per_mm=float(meta["counts_per_mm"]))
    here = tmp_path / "inprocess"
    here.mkdir()
    apygis.write(apygis.read(sandbox / "samples" / "ZH1091"), here / "ZH1091", driver="apy")
    geometry = OrientedGeometry(
        load_orientation(sandbox / "samples" / "session" / "ZH1091.orientation.json")
    )
    sess = Session(here / "ZH1091", geometry, layer="c", library=load_library(None))
    run_tablet_stream(
        sess, Replayer(rec), make_parser(meta["protocol"], cfg), ReportDecoder(cfg, BUTTONS)
    )
    assert sess.finished
    return sess.map


def test_view_shows_the_sample_map(chrome, sandbox, served, tmp_path):
    srv = served(["view", "samples/ZH1091", "--no-browser"], sandbox)
    chrome.get(srv.url)
    _until(chrome, "return window.apygisView && window.apygisView.seq() >= 0")
    sample = apygis.read(sandbox / "samples" / "ZH1091")
    page = _hook(chrome, "records()")
    assert page == _rows_of_map(sample)
    drawn = _hook(chrome, "drawNow()")
    counts = {t: sum(len(lay.table(t)) for lay in sample) for t in ("symbols", "texts")}
    assert drawn["symbols"] == counts["symbols"]  # everything is in view after "fit"
    assert drawn["texts"] == counts["texts"]
    spot = sum(int((lay.symbols["code"] == 0).sum()) for lay in sample)
    assert drawn["spot_heights"] == spot > 0
    assert drawn["segments"] > 0
    assert sorted(drawn["layers"]) == sorted(sample.layers)
    chrome.save_screenshot(str(tmp_path / "view.png"))

    # a layer switched off is not drawn; on again, it is
    chrome.find_element("css selector", "input[data-layer='e']").click()
    drawn = _hook(chrome, "drawNow()")
    assert "e" not in drawn["layers"]
    assert drawn["spot_heights"] == 0
    chrome.find_element("css selector", "input[data-layer='e']").click()
    assert "e" in _hook(chrome, "drawNow()")["layers"]

    # a click on a line point shows its record: number, code, references
    lay = sample.layers["h"]
    lp = lay.line_points[5]
    sx, sy = chrome.execute_script(
        "return window.apygisView.toScreen(arguments[0], arguments[1]);",
        float(lp["x"]),
        float(lp["y"]),
    )
    from selenium.webdriver.common.action_chains import ActionChains

    canvas = chrome.find_element("id", "map")
    w, h = canvas.size["width"], canvas.size["height"]
    ActionChains(chrome).move_to_element_with_offset(
        canvas, round(sx - w / 2), round(sy - h / 2)
    ).click().perform()
    sel = _until(chrome, "return window.apygisView.selected();", 5)
    assert sel == {"ext": "h", "table": "line_points", "num": int(lp["num"])}
    text = chrome.find_element("id", "recordtable").text
    assert f"line point {int(lp['num'])}" in text
    assert f"line code {int(lp['code']):02d}" in text
    fwd = int(lp["fwd"])
    assert f"forward {fwd if fwd >= 0 else '—'}" in text
    # the pointer's ground coordinates in the map's CRS
    readout = chrome.find_element("id", "readout").text
    assert "EPSG:2056" in readout
    x_shown = float(re.search(r"X (\S+)", readout).group(1))
    assert abs(x_shown - float(lp["x"])) < 2.0  # within a pixel or two at the fitted scale
    code, _out, err = srv.stop()
    assert code == 0, err
    assert "Traceback" not in err


def test_sample_session_live_in_the_browser(chrome, sandbox, served, tmp_path):
    srv = served([*SESSION, "--view-wait", "60"], sandbox)
    chrome.get(srv.url)  # the replay starts once the page is open
    srv.wait_for(r"session ended; the view stays", 120)
    _until(chrome, "return window.apygisView.ended();")
    with urllib.request.urlopen(srv.url + "state.json", timeout=10) as r:
        final = json.loads(r.read())
    _until(chrome, f"return window.apygisView.seq() >= {final['seq']};")
    chrome.save_screenshot(str(tmp_path / "session-end.png"))

    # every entry, in order, each arriving as it was made (no resynchronisation)
    monitor = _entries_of_monitor("".join(srv.lines))
    assert len(monitor) > 20
    page = [e[:5] for e in _hook(chrome, "entries()")]
    assert page == monitor
    received = _hook(chrome, "received()")
    assert received[0] == {"t": "state", "seq": 0, "entries": 0}
    assert [r["t"] for r in received[1:]] == ["delta"] * (len(received) - 1)
    arrived = [n for r in received[1:] for n in r["entries"]]
    assert arrived == list(range(1, len(monitor) + 1))

    # the page ends equal to the session's map: exactly (the same replay in this process),
    # and to the centimetre the layer files store
    records = _hook(chrome, "records()")
    assert records == _rows_of_map(_replayed_map(sandbox, tmp_path))
    result = apygis.read(sandbox / "out" / "ZH1091")
    assert _centimetres(records) == _rows_of_map(result)

    # AREA and DHI results are drawn; the status line and the mark are shown
    kinds = [o["kind"] for o in _hook(chrome, "overlays()")]
    assert "area" in kinds
    assert "dhi" in kinds
    drawn = _hook(chrome, "drawNow()")
    assert drawn["overlays"] >= 2
    assert drawn["mark"]
    _until(chrome, "return window.apygisView.status().mode === 'terminated';", 10)
    assert _hook(chrome, "messages()")[-1] == "compilation terminated"
    code, _out, err = srv.stop()
    assert code == 0, err
    assert "Traceback" not in err


def test_display_scale_crosshair_and_mark_act_on_the_page(chrome, tmp_path):
    """PROCEED items 1 and 3 zoom the page and size its crosshair; the mark moves; two pages."""
    from apygis.compile.events import Mark, Press
    from apygis.compile.oriented import OrientedGeometry
    from apygis.orient.io import load_orientation
    from apygis.session import Session
    from apygis.view import SessionFeed, ViewProcess, session_hub
    from tests.conftest import SAMPLES
    from tests.view.wsclient import WsClient

    apygis.write(apygis.read(SAMPLES / "ZH1091"), tmp_path / "ZH1091", driver="apy")
    geometry = OrientedGeometry(load_orientation(SAMPLES / "session" / "ZH1091.orientation.json"))
    sess = Session(tmp_path / "ZH1091", geometry, layer="r")
    server = ViewProcess(session_hub(sess))
    server.start()
    feed = SessionFeed(server, sess)
    other = WsClient(server.url)  # a second page at the same time
    try:
        chrome.get(server.url)
        _until(chrome, "return window.apygisView.seq() >= 0;")

        def press(*buttons):
            for b in buttons:
                sess.handle(Press(b))

        X, Y = 2684300.0, 1247900.0
        sess.handle(Mark(*geometry.tablet(X, Y)))
        _until(chrome, "const s = window.apygisView.status(); return s.mark && s.mark.length;")
        mk = _hook(chrome, "status()")["mark"]
        assert abs(mk[0] - X) < 0.01
        assert abs(mk[1] - Y) < 0.01
        press("PROCEED", "1", "ENTER", "4", "ENTER")  # display scale factor 4x
        _until(chrome, "return window.apygisView.display().scale === 4;")
        v = _hook(chrome, "view()")
        assert v["factor"] == 4
        assert abs(v["cx"] - mk[0]) < 1e-6
        assert abs(v["cy"] - mk[1]) < 1e-6
        # 4x at 1:5000: one ground metre is 4 * 0.2 mm on the screen
        assert v["pxPerM"] == pytest.approx(4 * 0.2 * 96 / 25.4)
        base = _hook(chrome, "drawNow()")["crosshair_px"]
        press("3", "ENTER", "2", "ENTER")  # crosshair scale 2x
        _until(chrome, "return window.apygisView.display().crosshair === 2;")
        assert _hook(chrome, "drawNow()")["crosshair_px"] == pytest.approx(2 * base)
        # back to compiling: a line of four points appears as it is entered
        press("5", "ENTER", "DESCR", "2", "ENTER", "ENTER", "1", "2", "ENTER")
        for k in range(4):
            sess.handle(Mark(*geometry.tablet(X + 25.0 * k, Y + 8.0 * k * k)))
            press("ENTER")
            n = sess.entries
            _until(chrome, f"return window.apygisView.entries().length === {n};", 10)
        press("PROCEED")
        mk2 = (X + 20.0, Y - 15.0)
        sess.handle(Mark(*geometry.tablet(*mk2)))
        _until(
            chrome,
            "const s = window.apygisView.status();"
            f" return s.mark && Math.abs(s.mark[0] - {mk2[0]}) < 0.01;",
        )
        drawn = _hook(chrome, "drawNow()")
        assert drawn["mark"]
        assert drawn["segments"] > 0
        chrome.save_screenshot(str(tmp_path / "session-4x.png"))
        want = {lay.ext: layer_rows(lay) for lay in sess.map}
        assert _hook(chrome, "records()") == want
        other.wait(lambda m: m.display.get("crosshair") == 2 and len(m.entries) == sess.entries)
        assert other.mirror.records() == {
            k: {t: sorted(r) for t, r in v.items()} for k, v in want.items()
        }
    finally:
        feed.close()
        other.close()
        server.stop()
        sess.close()
