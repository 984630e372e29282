"""Records per second writing and reading 1 M line points in the APY native formats.

The map: 100 full layers of 10 000 line points each (chains of 100 points),
coordinates at centimetre resolution in the LV95 range. Binary: one file per
layer (``ID.<ext>``); ASCII: one file for the whole map. Each figure is the
best of ``--repeat`` runs, measured with ``time.perf_counter`` around
``apygis.write`` / ``apygis.read``, files on the temporary directory's disk.

Goal (issue 2): binary >= 2 M records/s each way; ASCII vectorised.

Run: ``python benchmarks/bench_native.py [--repeat N] [--layers N]``
Last line: one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import itertools
import json
import string
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import apygis

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from tests.formats.strategies import random_rows


def make_map(n_layers: int) -> apygis.MapFile:
    rng = np.random.default_rng(2)
    m = apygis.MapFile("BENCH", scale=5000, crs="EPSG:2056")
    exts = ("".join(p) for p in itertools.product(string.ascii_lowercase, repeat=2))
    for ext in itertools.islice(exts, n_layers):
        m.add_layer(apygis.Layer.from_arrays(ext, line_points=random_rows(rng, 10_000)))
    return m


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--layers", type=int, default=100)
    args = ap.parse_args()
    m = make_map(args.layers)
    n = sum(len(lay.line_points) for lay in m)
    figures = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for fmt, target in (("binary", tmp / "BENCH"), ("ascii", tmp / "BENCH.apa")):
            tw = best(lambda target=target: apygis.write(m, target), args.repeat)
            tr = best(lambda target=target: apygis.read(target), args.repeat)
            assert apygis.read(target) == m
            size = sum(p.stat().st_size for p in tmp.glob(target.name + "*"))
            figures[f"{fmt}_write_records_per_s"] = round(n / tw)
            figures[f"{fmt}_read_records_per_s"] = round(n / tr)
            print(
                f"{fmt:<7} {n} line points in {args.layers} layers, {size / 1e6:.1f} MB: "
                f"write {tw:.3f} s ({n / tw / 1e6:.2f} M/s), "
                f"read {tr:.3f} s ({n / tr / 1e6:.2f} M/s)"
            )
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
