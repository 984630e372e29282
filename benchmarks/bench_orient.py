"""Throughput of the real-time loop and time of a photo orientation.

The set-up: a stereo pair at 1:15000 (c = 153 mm, H about 2300 m, base
1380 m, kappa about pi) in LV95, motor calibrations with 2 um steps.

* ``loop_points_per_s``: :meth:`RealtimeLoop.update_many` on 1 M mark
  positions (photo coordinates, parallaxes and the four motor positions for
  both photos); best of ``--repeat`` runs. Goal >= 1 M/s.
* ``single_update_us``: :meth:`RealtimeLoop.update` for one mark position,
  median over ``--single`` calls (each timed in a batch of 100 calls to beat
  the timer resolution). Goal <= 20 us.
* ``photo_orientation_ms``: :func:`orient_photo` from 8 control spots with
  4 um parallax noise (six unknowns), median of ``--repeat-orient`` runs.

Run: ``python benchmarks/bench_orient.py [--points N] [--repeat N]``
Last line: one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import time

import numpy as np

from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation
from apygis.orient.photo import PhotoOrientation, approximate_orientation, orient_photo
from apygis.orient.realtime import MotorCalibration, RealtimeLoop

XM, YM = 2_684_200.0, 1_247_800.0


def pair():
    io = InteriorOrientation(153.0)
    s = 153.0 / 2295.0
    left = PhotoOrientation(
        "4711", io, ExteriorOrientation(XM - 690, YM, 2815.0, 0.003, -0.005, math.pi + 0.01), s, s
    )
    right = PhotoOrientation(
        "4712", io, ExteriorOrientation(XM + 690, YM, 2810.0, -0.002, 0.004, math.pi - 0.01), s, s
    )
    return left, right


def terrain(X, Y):
    return 500.0 + 60.0 * np.sin((X - XM) / 500.0) * np.cos((Y - YM) / 700.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--single", type=int, default=2000)
    ap.add_argument("--repeat-orient", type=int, default=50)
    args = ap.parse_args()

    left, right = pair()
    loop = RealtimeLoop(
        left,
        right,
        MotorCalibration("4711", step_um=2.0, plate_rotation_rad=0.01),
        MotorCalibration("4712", step_um=2.0, plate_rotation_rad=-0.02),
    )
    rng = np.random.default_rng(1)
    X = XM + rng.uniform(-650, 650, args.points)
    Y = YM + rng.uniform(-800, 800, args.points)
    xyz = np.column_stack([X, Y, terrain(X, Y)])

    loop.update_many(xyz[:1000])  # warm up
    best = math.inf
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        loop.update_many(xyz)
        best = min(best, time.perf_counter() - t0)
    pps = args.points / best
    print(
        f"real-time loop, {args.points:,} mark positions: {best * 1e3:.1f} ms = {pps / 1e6:.2f} M/s"
    )

    update = loop.update
    pts = [tuple(map(float, p)) for p in xyz[: args.single]]
    per = []
    for i in range(0, len(pts), 100):
        chunk = pts[i : i + 100]
        t0 = time.perf_counter()
        for X_, Y_, Z_ in chunk:
            update(X_, Y_, Z_)
        per.append((time.perf_counter() - t0) / len(chunk))
    single_us = statistics.median(per) * 1e6
    print(f"one update (fast path), median: {single_us:.2f} us")

    spots = []
    for dx, dy in ((-700, 700), (-700, 0), (-700, -700), (700, 700), (700, 0), (700, -700),
                   (0, 650), (0, -650)):  # fmt: skip
        spots.append((XM + dx, YM + dy))
    spots = np.array(spots)
    G = np.column_stack([spots, terrain(spots[:, 0], spots[:, 1])])
    P = left.parallax(G) + rng.normal(0, 0.004, (8, 2))
    approx, _ = approximate_orientation(
        "4711",
        left.interior,
        centre_xy=(XM - 600, YM + 100),
        mean_height=float(G[:, 2].mean()),
        scale_number=15000.0,
        sx_mm_per_m=left.sx_mm_per_m,
        sy_mm_per_m=left.sy_mm_per_m,
    )
    times = []
    for _ in range(args.repeat_orient):
        t0 = time.perf_counter()
        r = orient_photo(G, P, approx, fixed={"sx", "sy"})
        times.append(time.perf_counter() - t0)
    orient_ms = statistics.median(times) * 1e3
    print(
        f"photo orientation, 8 control spots, 6 unknowns: {orient_ms:.2f} ms "
        f"({r.iterations} iterations, RMSE {r.rmse_mm * 1000:.1f} um)"
    )
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    print(
        json.dumps(
            {
                "loop_points_per_s": round(pps),
                "single_update_us": round(single_us, 3),
                "photo_orientation_ms": round(orient_ms, 3),
            }
        )
    )


if __name__ == "__main__":
    main()
