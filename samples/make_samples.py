"""Make the bundled sample map sheet ZH1091 (deterministic: same bytes every run).

A 1:5000 sheet in Swiss LV95 (EPSG:2056), 2.4 km x 1.6 km around
E 2'683'000-2'685'400, N 1'247'000-1'248'600, over a smooth synthetic
terrain of 405-480 m. Layers, as APY names them:

========= =================================================================
``c``     control: 6 trig points and 4 boundary stones, trig point names
``e``     elevations: 96 spot heights (symbol 00) on a jittered 200 m grid
``h``     hydrography: the Dorfbach crossing the sheet, two tributaries
          joining it (branches), a brook joining a tributary (a branch of a
          branch), a closed pond, springs and a well, names
``r``     roads: the Hauptstrasse crossing the sheet, the Kirchweg branching
          off it and ending at a second junction, a loop road leaving and
          rejoining it, a path, 8 closed building outlines, church, chapel,
          bus stops, place and street names
========= =================================================================

Line codes used here: 11 main road, 12 side road, 13 path, 21 building,
31 stream, 32 tributary, 33 brook, 35 pond shore. Symbol codes are those of
the default symbol library (``apygis symbols list``).

Writes ``samples/ZH1091.<ext>`` (APY binary), ``samples/ZH1091.apa`` (APY
ASCII) and ``samples/ZH1091.expected.json``: the counts this script means to
create, tallied here by construction (not by apygis), which the tests compare
with ``apygis info --json``.

Run: ``python samples/make_samples.py [OUTDIR]``
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

import apygis

E0, N0 = 2_683_000.0, 1_247_000.0
WIDTH, HEIGHT = 2400.0, 1600.0

TRIG, BENCH, STONE, CHURCH, CHAPEL, CROSS = 1, 4, 5, 6, 7, 8
MAST, TREE, CONIFER, WELL, SPRING, FOUNTAIN, BUS = 20, 23, 24, 26, 27, 28, 36
SPOT = 0
MAIN_ROAD, SIDE_ROAD, PATH, BUILDING = 11, 12, 13, 21
STREAM, TRIBUTARY, BROOK, POND = 31, 32, 33, 35


def terrain(e, n):
    """Height in metres: a valley along the stream, hills to the north."""
    x = (np.asarray(e) - E0) / WIDTH
    y = (np.asarray(n) - N0) / HEIGHT
    return 420.0 + 45.0 * y**1.5 + 12.0 * np.sin(3.1 * x) * np.cos(2.3 * y) + 6.0 * x


def cm(v):
    return np.round(np.asarray(v, dtype=float), 2)


def xyz(e, n):
    e, n = cm(e), cm(n)
    return np.column_stack([e, n, cm(terrain(e, n))])


def curve(e0, n0, e1, n1, count, bend, waves=1.0):
    """A gently meandering line from (e0, n0) to (e1, n1) of ``count`` points."""
    t = np.linspace(0.0, 1.0, count)
    de, dn = e1 - e0, n1 - n0
    length = math.hypot(de, dn)
    ne, nn = -dn / length, de / length
    off = bend * np.sin(math.pi * waves * t) * np.sin(math.pi * t)
    return xyz(e0 + de * t + ne * off, n0 + dn * t + nn * off)


class Tally:
    """Counts by construction, per layer."""

    def __init__(self):
        self.layers = {}

    def of(self, ext):
        return self.layers.setdefault(
            ext,
            {
                "symbols": 0,
                "line_points": 0,
                "lines": 0,
                "closed_lines": 0,
                "texts": 0,
                "branches": 0,
                "margin_points": 0,
            },
        )

    def line(self, ext, n, closed=False, joined_ends=0):
        t = self.of(ext)
        t["line_points"] += n
        t["lines"] += 1
        t["closed_lines"] += int(closed)
        t["branches"] += joined_ends
        if not closed:
            t["margin_points"] += 2 - joined_ends if n > 1 else 1


def make(outdir: Path) -> apygis.MapFile:
    rng = np.random.default_rng(1091)
    tally = Tally()
    m = apygis.MapFile(
        "ZH1091",
        scale=5000,
        crs="EPSG:2056",
        notes=(
            "apygis sample sheet ZH1091, 1:5000, synthetic terrain\nmade by samples/make_samples.py"
        ),
    )

    # ---- c: control
    c = m.layer("c")
    trig = [
        (2683150.0, 1247180.0),
        (2684120.0, 1247090.0),
        (2685230.0, 1247260.0),
        (2683280.0, 1248420.0),
        (2684300.0, 1248510.0),
        (2685310.0, 1248380.0),
    ]
    for k, (e, n) in enumerate(trig, start=1):
        p = xyz(e, n)[0]
        c.add_symbol(*p, TRIG)
        c.add_text(p[0] + 8.0, p[1] + 4.0, p[2], f"P 1091-{k:02d}")
        tally.of("c")["symbols"] += 1
        tally.of("c")["texts"] += 1
    for e, n in [
        (2683600.0, 1247400.0),
        (2683900.0, 1247420.0),
        (2684700.0, 1248000.0),
        (2685000.0, 1247700.0),
    ]:
        c.add_symbol(*xyz(e, n)[0], STONE)
        tally.of("c")["symbols"] += 1

    # ---- e: spot heights on a jittered 200 m grid
    el = m.layer("e")
    for i in range(12):
        for j in range(8):
            e = E0 + 100.0 + 200.0 * i + rng.uniform(-40, 40)
            n = N0 + 100.0 + 200.0 * j + rng.uniform(-40, 40)
            el.add_symbol(*xyz(e, n)[0], SPOT)
            tally.of("e")["symbols"] += 1

    # ---- h: hydrography
    h = m.layer("h")
    main = curve(E0 + WIDTH, N0 + 1150.0, E0, N0 + 380.0, 60, bend=70.0, waves=3.0)
    main[:, 2] = cm(np.linspace(452.0, 418.0, len(main)))  # water flows downhill
    stream = h.add_line(main, STREAM)
    tally.line("h", len(main))
    trib_a = curve(E0 + 1650.0, N0 + HEIGHT - 60.0, *main[20, :2], 18, bend=40.0)
    trib_a = trib_a[:-1]  # ends at the junction, which is a point of the stream
    a = h.add_line(trib_a, TRIBUTARY)
    h.join(a[-1], stream[20])
    tally.line("h", len(trib_a), joined_ends=1)
    trib_b = curve(E0 + 700.0, N0 + 60.0, *main[42, :2], 15, bend=-30.0)[:-1]
    b = h.add_line(trib_b, TRIBUTARY)
    h.join(b[-1], stream[42])
    tally.line("h", len(trib_b), joined_ends=1)
    brook = curve(E0 + 1300.0, N0 + HEIGHT - 250.0, *trib_a[9, :2], 10, bend=15.0)[:-1]
    bk = h.add_line(brook, BROOK)
    h.join(bk[-1], a[9])
    tally.line("h", len(brook), joined_ends=1)
    ang = np.linspace(0.0, 2 * math.pi, 12, endpoint=False)
    pond = xyz(E0 + 500.0 + 45.0 * np.cos(ang), N0 + 1050.0 + 28.0 * np.sin(ang))
    pond[:, 2] = pond[:, 2].min()
    h.add_line(pond, POND, closed=True)
    tally.line("h", len(pond), closed=True)
    for p, code in (
        (trib_a[0], SPRING),
        (trib_b[0], SPRING),
        (brook[0], SPRING),
        (xyz(E0 + 1210.0, N0 + 700.0)[0], WELL),
    ):
        h.add_symbol(*p, code)
        tally.of("h")["symbols"] += 1
    for p, text in ((main[30], "Dorfbach"), (pond[0], "Weiher"), (trib_a[5], "Rietbach")):
        h.add_text(p[0] + 10.0, p[1] + 10.0, p[2], text)
        tally.of("h")["texts"] += 1

    # ---- r: roads, buildings
    r = m.layer("r")
    hs = curve(E0, N0 + 820.0, E0 + WIDTH, N0 + 760.0, 40, bend=35.0, waves=2.0)
    road = r.add_line(hs, MAIN_ROAD)
    tally.line("r", len(hs))
    kw = curve(*hs[14, :2], E0 + 1050.0, N0 + 1450.0, 25, bend=25.0)[1:]
    kirchweg = r.add_line(kw, SIDE_ROAD)
    r.join(kirchweg[0], road[14])
    tally.line("r", len(kw), joined_ends=1)
    # the Kirchweg ends on a cross road that also meets the Hauptstrasse
    cross = curve(E0 + 600.0, N0 + 1450.0, *hs[5, :2], 20, bend=-30.0)[:-1]
    xr = r.add_line(cross, SIDE_ROAD)
    r.join(xr[-1], road[5])
    r.join(kirchweg[-1], xr[6])
    tally.line("r", len(cross), joined_ends=1)
    tally.of("r")["branches"] += 1
    tally.of("r")["margin_points"] -= 1  # the Kirchweg's far end is joined too
    loop = np.vstack(
        [
            curve(*hs[24, :2], E0 + 1700.0, N0 + 450.0, 10, bend=20.0)[1:],
            curve(E0 + 1700.0, N0 + 450.0, *hs[32, :2], 10, bend=20.0)[1:-1],
        ]
    )
    lp_nums = r.add_line(loop, SIDE_ROAD)
    r.join(lp_nums[0], road[24])
    r.join(lp_nums[-1], road[32])
    tally.line("r", len(loop), joined_ends=2)
    path = curve(E0 + 1900.0, N0 + 1300.0, E0 + 2300.0, N0 + 1560.0, 12, bend=20.0)
    r.add_line(path, PATH)
    tally.line("r", len(path))
    for k in range(8):
        ce = E0 + 700.0 + 60.0 * k + rng.uniform(-8, 8)
        cn = N0 + 860.0 + (30.0 if k % 2 else -95.0) + rng.uniform(-5, 5)
        w, d = rng.uniform(9, 16), rng.uniform(8, 13)
        if k == 3:  # an L-shaped house, six corners
            corners = [(0, 0), (w, 0), (w, d), (w / 2, d), (w / 2, d / 2), (0, d / 2)]
        else:
            corners = [(0, 0), (w, 0), (w, d), (0, d)]
        pts = xyz([ce + u for u, _ in corners], [cn + v for _, v in corners])
        pts[:, 2] = pts[:, 2].min()
        r.add_line(pts[::-1], BUILDING, closed=True)  # clockwise, as APY's AREA wants
        tally.line("r", len(pts), closed=True)
    church = xyz(E0 + 1040.0, N0 + 1400.0)[0]
    r.add_symbol(*church, CHURCH)
    r.add_symbol(*xyz(E0 + 1950.0, N0 + 1310.0)[0], CHAPEL)
    r.add_symbol(*xyz(E0 + 1310.0, N0 + 800.0)[0], FOUNTAIN)
    for k in (8, 30):
        r.add_symbol(hs[k, 0] + 6.0, hs[k, 1] + 6.0, hs[k, 2], BUS)
    tally.of("r")["symbols"] += 5
    for p, text in (
        (hs[20], "Hauptstrasse"),
        (kw[12], "Kirchweg"),
        (church, "Oberdorf"),
        (loop[8], "Riedring"),
        (hs[2], "Unterdorf"),
    ):
        r.add_text(p[0] + 12.0, p[1] + 12.0, p[2], text)
        tally.of("r")["texts"] += 1

    outdir.mkdir(parents=True, exist_ok=True)
    apygis.write(m, outdir / "ZH1091")
    apygis.write(m, outdir / "ZH1091.apa")
    expected = {"id": m.id, "scale": 5000, "crs": "EPSG:2056", "layers": tally.layers}
    (outdir / "ZH1091.expected.json").write_text(
        json.dumps(expected, indent=2, sort_keys=True) + "\n"
    )
    return m


if __name__ == "__main__":
    make(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent)
