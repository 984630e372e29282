"""Session throughput and the latency from tablet bytes to the motor command.

Set-up: the sample sheet ZH1091 and the sample session orientation (two
photos with plate motors), a CalComp tablet at 40 counts/mm.

* ``events_per_s``: engine events (mark moves with an ENTER every 50th
  event, compiling a sampled line) through :class:`Engine` alone.
* ``session_events_per_s``: the same through :class:`Session`, which also
  journals every event (entries fsynced) and sends each plate position to
  the motor controller.
* Latency: for each tablet report, the time from handing the parser the
  bytes that complete the report (with the parser's default ``confirm=True``
  these are the first bytes of the next packet) until the G-code line for
  the plates has been written to the motor port. The motor port is a
  simulated grblHAL controller answering in the same process (the protocol
  exchange, character counting and ``ok`` handling are real; no serial
  driver). Percentiles over ``--reports`` reports.

* ``view_overhead_pct``: the session of ``session_events_per_s`` with and
  without the graphic display (``--view``: the view's process following the
  session's journal, the feed thread sending the mark and status line, one
  page connected as a WebSocket client in another process), run alternately
  ``--view-rounds`` times each; the best time of each, in per cent of the run
  without. ``view_noise_pct``: how much the runs without the view differ
  among themselves (the best of the odd runs against the best of the even
  ones): an overhead below it is not measurable on this machine.
* What that time is made of: ``view_cpu_overhead_pct``, the session
  process's CPU time (every thread: the engine, the journal, the motors, the
  feed thread) with the view against without;
  ``view_overhead_excl_sync_pct``, its time outside the journal's fsyncs;
  ``sync_wait_s`` / ``sync_wait_view_s``, the time it waited for the fsyncs
  (1200 of them) without and with the view; ``view_processes_cpu_s``, the
  CPU the view's and the page's processes used meanwhile.
* The peer: the same run without the view, beside a process that keeps a
  core busy the same share of the time as the view's and the page's
  processes did, waking every 4 ms (``peer_load_duty``): ``peer_overhead_pct``,
  and ``view_to_peer_time_ratio`` the view's best time over the peer's (on
  a two-core virtual machine another busy process lengthens the fsyncs,
  whatever it does).
* ``view_latency_ms_p50`` / ``view_latency_ms_p99``: from the moment the
  session is handed an ENTER until the page (a WebSocket client in another
  process, timestamps on the same monotonic clock) has received the delta of
  that entry; ``--view-entries`` entries, each after ten marks at a tablet's
  200 reports/s.
* ``paced_view_motor_ms_p50`` / ``_p99`` against ``paced_motor_ms_p50`` /
  ``_p99``: in that run at a tablet's pace, and in the same run without the
  view, the time from a report handed to the session until its motor
  command was written: what the view costs an operator at the instrument.

Goal (issue 5): >= 50 k events/s; p99 <= 1 ms. Goal (issue 15): the viewer
costs nothing measurable; entry-to-page latency < 50 ms.

Run: ``python benchmarks/bench_session.py [--events N] [--reports N]``
Last line: one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import apygis  # noqa: E402
from apygis.compile.engine import Engine, Mark, Press  # noqa: E402
from apygis.compile.oriented import OrientedGeometry  # noqa: E402
from apygis.instrument.motors import MotorController, SimulatedGrbl  # noqa: E402
from apygis.instrument.pad import BUTTONS  # noqa: E402
from apygis.instrument.tablet import TabletConfig, encode_calcomp, make_parser  # noqa: E402
from apygis.orient.io import load_orientation  # noqa: E402
from apygis.session import ReportDecoder, Session  # noqa: E402


class SimPort:
    """A port whose other end is a SimulatedGrbl in this process; notes write times."""

    def __init__(self, sim: SimulatedGrbl):
        self.sim = sim
        self.buf = b""
        self.timeout = 0.05
        self.last_write = 0.0

    def write(self, data: bytes) -> int:
        self.last_write = time.perf_counter()
        self.buf += self.sim.handle(data)
        return len(data)

    @property
    def in_waiting(self) -> int:
        return len(self.buf)

    def read(self, n: int = 1) -> bytes:
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def reset_input_buffer(self) -> None:
        self.buf = b""

    def flush(self) -> None:
        pass

    def close(self) -> None:
        pass


def events(geometry, n: int):
    """Marks along a meandering line with an ENTER every 50th event."""
    out = [Press(b) for b in ("DESCR", "2", "ENTER", "ENTER", "1", "2", "ENTER")]
    for k in range(n):
        X = 2_683_200.0 + 2000.0 * k / n
        Y = 1_247_900.0 + 80.0 * math.sin(k / 500.0)
        out.append(Mark(*geometry.tablet(X, Y)))
        if k % 50 == 49:
            out.append(Press("ENTER"))
        if k % 5000 == 4999:
            out.append(Press("PROCEED"))  # a new line: keep within APY's capacity
    return out


CLIENT = r"""
import asyncio, json, sys, time
import aiohttp

async def main(url, want):
    async with aiohttp.ClientSession() as http:
        async with http.ws_connect(url, max_msg_size=0) as ws:
            print("open", flush=True)
            async for msg in ws:
                m = json.loads(msg.data)
                now = time.monotonic()
                if m["t"] == "delta":
                    for e in m.get("entries", []):
                        print("entry", e[0], repr(now), flush=True)
                    if m.get("ended"):
                        break

asyncio.run(main(sys.argv[1], int(sys.argv[2])))
"""


class Page:
    """A page in another process: a WebSocket client printing when each entry arrived."""

    def __init__(self, url: str):
        import subprocess

        self.proc = subprocess.Popen(
            [sys.executable, "-c", CLIENT, url.replace("http://", "ws://") + "ws", "0"],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "open"

    def arrivals(self) -> dict[int, float]:
        out, _ = self.proc.communicate(timeout=120)
        got = {}
        for line in out.splitlines():
            word, n, t = line.split()
            if word == "entry":
                got[int(n)] = float(t)
        return got


class SyncClock:
    """The time the session waits for the journal's fsyncs (wrapped around Journal.sync)."""

    def __init__(self):
        from apygis.session.journal import Journal

        self.seconds = 0.0
        inner = Journal.sync

        def sync(journal):
            t = time.perf_counter()
            try:
                inner(journal)
            finally:
                self.seconds += time.perf_counter() - t

        Journal.sync = sync  # type: ignore[method-assign]


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


LOAD = r"""
import sys, time
duty, tick = float(sys.argv[1]), 0.004
print("busy", flush=True)
while True:
    t = time.perf_counter()
    while time.perf_counter() - t < duty * tick:
        pass
    time.sleep(tick * (1.0 - duty))
"""


class Load:
    """A process that keeps a core busy ``duty`` of the time, waking every 4 ms."""

    def __init__(self, duty: float):
        import subprocess

        duty = min(max(duty, 0.0), 1.0)
        self.proc = subprocess.Popen(
            [sys.executable, "-c", LOAD, str(float(duty))], stdout=subprocess.PIPE, text=True
        )
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "busy"

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait()


def session_run(
    sample, geometry, evs, view: bool, clock: SyncClock, load: float | None = None
) -> dict[str, float]:
    """``evs`` through a Session (journal, motors), with or without the view.

    With ``load`` (and no view), a :class:`Load` of that duty runs meanwhile
    (the peer: what another process using as much CPU as the view's costs).

    Returns seconds: ``wall``, ``cpu`` (this process, every thread), ``sync``
    (waiting for the journal's fsyncs), ``view_cpu`` (the view's process and
    the page's, 0 without), and ``entries``.
    """
    from apygis.view import SessionFeed, ViewProcess, session_hub

    tmp = Path(tempfile.mkdtemp())
    server = page = feed = peer = None
    try:
        apygis.write(sample, tmp / "ZH1091")
        ctl = MotorController(SimPort(SimulatedGrbl()), name="sim")
        ctl.connect(reset=True)
        sess = Session(tmp / "ZH1091", geometry, layer="t", motors=ctl)
        if load is not None:
            peer = Load(load)
        if view:
            server = ViewProcess(session_hub(sess))
            server.start()
            feed = SessionFeed(server, sess)
            page = Page(server.url)
        others = [] if server is None or page is None else [server.pid, page.proc.pid]
        before = sum(_cpu_s(p) for p in others)
        clock.seconds = 0.0
        c0 = time.process_time()
        t0 = time.perf_counter()
        for ev in evs:
            sess.handle(ev)
        out = {
            "wall": time.perf_counter() - t0,
            "cpu": time.process_time() - c0,
            "sync": clock.seconds,
            "view_cpu": sum(_cpu_s(p) for p in others) - before,
            "entries": sess.entries,
        }
        sess.close()
        return out
    finally:
        if peer is not None:
            peer.stop()
        if feed is not None:
            feed.close()
        if page is not None:
            page.proc.kill()
            page.proc.wait()
        if server is not None:
            server.stop()
        shutil.rmtree(tmp, ignore_errors=True)


def paced_run(sample, geometry, n_entries: int, view: bool) -> tuple[np.ndarray, np.ndarray]:
    """A session at a tablet's pace, with or without a page watching.

    Marks at 200 reports/s and an ENTER after every ten; the session drives
    the (simulated) motors. Returns the milliseconds from a tablet report
    handed to the session until its motor command was written, for every
    report that moved the motors, and (with ``view``) the milliseconds from
    handing the session an ENTER until the page had the entry (else empty).
    """
    from apygis.view import SessionFeed, ViewProcess, session_hub

    tmp = Path(tempfile.mkdtemp())
    try:
        apygis.write(sample, tmp / "ZH1091")
        port = SimPort(SimulatedGrbl())
        ctl = MotorController(port, name="sim")
        ctl.connect(reset=True)
        sess = Session(tmp / "ZH1091", geometry, layer="t", motors=ctl)
        server = feed = page = None
        if view:
            server = ViewProcess(session_hub(sess))
            server.start()
            feed = SessionFeed(server, sess)
            page = Page(server.url)
        for b in ("DESCR", "2", "ENTER", "ENTER", "1", "2", "ENTER"):
            sess.handle(Press(b))
        sent: dict[int, float] = {}
        motor: list[float] = []
        period = 1.0 / 200.0
        nxt = time.monotonic()
        for k in range(n_entries * 10):
            X = 2_683_300.0 + 1500.0 * k / (n_entries * 10)
            Y = 1_247_850.0 + 50.0 * math.sin(k / 40.0)
            nxt += period
            while time.monotonic() < nxt:
                time.sleep(max(0.0, nxt - time.monotonic() - 0.0005))
            before = port.last_write
            t0 = time.perf_counter()
            sess.handle(Mark(*geometry.tablet(X, Y)))
            if port.last_write != before:
                motor.append((port.last_write - t0) * 1000.0)
            if k % 10 == 9:
                t = time.monotonic()
                sess.handle(Press("ENTER"))
                sent[sess.entries] = t
        lat = np.zeros(0)
        if feed is not None and page is not None and server is not None:
            feed.end(sess)
            got = page.arrivals()
            server.stop()
            missing = sorted(set(sent) - set(got))
            if missing:
                raise SystemExit(f"the page never got entries {missing[:10]}")
            lat = np.array([(got[n] - sent[n]) * 1000.0 for n in sorted(sent)])
        sess.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return np.array(motor), lat


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--events", type=int, default=200_000)
    ap.add_argument("--reports", type=int, default=50_000)
    ap.add_argument("--view-events", type=int, default=60_000)
    ap.add_argument("--view-entries", type=int, default=300)
    ap.add_argument("--view-rounds", type=int, default=7)
    args = ap.parse_args()
    orientation = load_orientation(ROOT / "samples" / "session" / "ZH1091.orientation.json")
    geometry = OrientedGeometry(orientation)
    sample = apygis.read(ROOT / "samples" / "ZH1091")
    evs = events(geometry, args.events)
    figures = {}

    m = sample.copy()
    eng = Engine(m, "t", geometry)
    t0 = time.perf_counter()
    for ev in evs:
        eng.handle(ev)
    dt = time.perf_counter() - t0
    figures["events_per_s"] = round(len(evs) / dt)
    print(f"engine:  {len(evs)} events in {dt:.2f} s: {len(evs) / dt / 1e3:.1f} k events/s")

    tmp = Path(tempfile.mkdtemp())
    try:
        apygis.write(sample, tmp / "ZH1091")
        sim = SimulatedGrbl()
        port = SimPort(sim)
        ctl = MotorController(port, name="sim")
        ctl.connect(reset=True)
        sess = Session(tmp / "ZH1091", geometry, layer="t", motors=ctl)
        t0 = time.perf_counter()
        for ev in evs:
            sess.handle(ev)
        dt = time.perf_counter() - t0
        figures["session_events_per_s"] = round(len(evs) / dt)
        print(
            f"session: {len(evs)} events in {dt:.2f} s: {len(evs) / dt / 1e3:.1f} k events/s "
            f"(journal, {sess.journal.syncs} fsyncs, motor commands)"
        )
        sess.close()

        # latency: tablet bytes -> parser -> decoder -> session -> G-code line written
        shutil.rmtree(tmp)
        tmp.mkdir()
        apygis.write(sample, tmp / "ZH1091")
        sess = Session(tmp / "ZH1091", geometry, layer="t", motors=ctl)
        cfg = TabletConfig(counts_per_mm=40.0)
        parser = make_parser("calcomp", cfg)
        decoder = ReportDecoder(cfg, BUTTONS)
        packets = []
        for k in range(args.reports + 1):
            X = 2_683_500.0 + 1500.0 * k / args.reports
            Y = 1_247_800.0 + 60.0 * math.sin(k / 300.0)
            x, y = geometry.tablet(X, Y)
            packets.append(encode_calcomp(round(x * 40), round(y * 40), 0, True))
        lat = []
        for pkt in packets:
            before = port.last_write
            t0 = time.perf_counter()
            for report in parser.feed(pkt):
                sess.handle_all(decoder.events(report))
            if port.last_write != before:
                lat.append(port.last_write - t0)
        sess.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    lat_ms = np.array(lat) * 1000.0
    figures["p50_latency_ms"] = round(float(np.percentile(lat_ms, 50)), 4)
    figures["p99_latency_ms"] = round(float(np.percentile(lat_ms, 99)), 4)
    print(
        f"latency tablet bytes -> motor command over {len(lat)} reports: "
        f"p50 {figures['p50_latency_ms']:.3f} ms, p99 {figures['p99_latency_ms']:.3f} ms, "
        f"max {lat_ms.max():.3f} ms"
    )

    # the graphic display: what it costs the session, and how soon a page has an entry
    vevs = events(geometry, args.view_events)
    clock = SyncClock()
    runs: dict[bool | str, list[dict[str, float]]] = {False: [], True: [], "peer": []}
    for _ in range(args.view_rounds):
        for view in (False, True):
            runs[view].append(session_run(sample, geometry, vevs, view, clock))
        duty = np.median([r["view_cpu"] / r["wall"] for r in runs[True]])
        runs["peer"].append(session_run(sample, geometry, vevs, False, clock, load=duty))

    def best(view: bool | str, key) -> float:
        return min(key(r) for r in runs[view])

    def pct(key, view: bool | str = True) -> float:
        return round(100.0 * (best(view, key) - best(False, key)) / best(False, key), 2)

    n = int(runs[True][0]["entries"])
    figures["view_overhead_pct"] = pct(lambda r: r["wall"])
    # what the same run without the view differs by from itself: the best of every other run
    plain = [r["wall"] for r in runs[False]]
    a, b = min(plain[0::2]), min(plain[1::2])
    figures["view_noise_pct"] = round(100.0 * abs(a - b) / min(a, b), 2)
    figures["view_cpu_overhead_pct"] = pct(lambda r: r["cpu"])
    figures["view_overhead_excl_sync_pct"] = pct(lambda r: r["wall"] - r["sync"])
    figures["sync_wait_s"] = round(best(False, lambda r: r["sync"]), 3)
    figures["sync_wait_view_s"] = round(best(True, lambda r: r["sync"]), 3)
    figures["view_processes_cpu_s"] = round(best(True, lambda r: r["view_cpu"]), 3)
    figures["peer_load_duty"] = round(float(duty), 3)
    figures["peer_overhead_pct"] = pct(lambda r: r["wall"], "peer")
    figures["view_to_peer_time_ratio"] = round(
        best(True, lambda r: r["wall"]) / best("peer", lambda r: r["wall"]), 4
    )
    print(
        f"session with and without the view ({len(vevs)} events, {n} entries, one page), "
        f"best of {args.view_rounds}: {best(True, lambda r: r['wall']):.3f} s vs "
        f"{best(False, lambda r: r['wall']):.3f} s: {figures['view_overhead_pct']:+.2f} % "
        f"(runs without the view differ by {figures['view_noise_pct']:.2f} % among themselves)"
    )
    print(
        f"  the session's CPU time {figures['view_cpu_overhead_pct']:+.2f} %; its time outside "
        f"the journal's fsyncs {figures['view_overhead_excl_sync_pct']:+.2f} %; waiting for the "
        f"fsyncs {figures['sync_wait_view_s']:.3f} s vs {figures['sync_wait_s']:.3f} s; the "
        f"view's and the page's processes {figures['view_processes_cpu_s']:.2f} s of CPU"
    )
    print(
        f"  the peer (a process busy {duty:.0%} of the time, as the view's and "
        f"the page's are, and no view): {figures['peer_overhead_pct']:+.2f} %; the view's time "
        f"/ the peer's {figures['view_to_peer_time_ratio']:.3f}"
    )
    plain_motor, _ = paced_run(sample, geometry, args.view_entries, False)
    view_motor, lat = paced_run(sample, geometry, args.view_entries, True)
    figures["view_latency_ms_p50"] = round(float(np.percentile(lat, 50)), 3)
    figures["view_latency_ms_p99"] = round(float(np.percentile(lat, 99)), 3)
    print(
        f"entry -> page over {len(lat)} entries: p50 {figures['view_latency_ms_p50']:.2f} ms, "
        f"p99 {figures['view_latency_ms_p99']:.2f} ms, max {lat.max():.2f} ms"
    )
    for key, ms in (("paced", plain_motor), ("paced_view", view_motor)):
        figures[f"{key}_motor_ms_p50"] = round(float(np.percentile(ms, 50)), 4)
        figures[f"{key}_motor_ms_p99"] = round(float(np.percentile(ms, 99)), 4)
    print(
        f"at a tablet's pace (200 reports/s), report -> motor command over {len(view_motor)} "
        f"reports: p50 {figures['paced_view_motor_ms_p50']:.3f} ms, "
        f"p99 {figures['paced_view_motor_ms_p99']:.3f} ms with a page watching; "
        f"{figures['paced_motor_ms_p50']:.3f} / {figures['paced_motor_ms_p99']:.3f} ms without"
    )
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
