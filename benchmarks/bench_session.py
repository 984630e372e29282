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

Goal (issue 5): >= 50 k events/s; p99 <= 1 ms.

Run: ``python benchmarks/bench_session.py [--events N] [--reports N]``
Last line: one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import json
import math
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--events", type=int, default=200_000)
    ap.add_argument("--reports", type=int, default=50_000)
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
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
