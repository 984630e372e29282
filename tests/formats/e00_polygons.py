"""A small ARC/INFO polygon coverage in E00, written here as ARC/INFO's EXPORT writes one.

Two squares side by side (polygons 2 and 3) and an island in the first
(polygon 4), polygon 1 the outside ("universe"); the PAT has one record per
polygon, universe included, with the items ``LANDUSE`` (C 10) and ``CODE``;
the labels carry their polygon's ID. GDAL's AVCE00 driver reads it as the
layers ARC, PAL (the polygons with the PAT joined) and LAB.
"""

from __future__ import annotations

import numpy as np

from apygis.formats.e00._common import T_BINFLOAT, T_BININT, T_CHAR
from apygis.formats.e00.write import _column, _Item, _table_bytes

# arc id, from node, to node, left polygon, right polygon, vertices
ARCS = [
    (1, 1, 2, 2, 3, [(10, 0), (10, 10)]),
    (2, 2, 1, 2, 1, [(10, 10), (0, 10), (0, 0), (10, 0)]),
    (3, 1, 2, 3, 1, [(10, 0), (20, 0), (20, 10), (10, 10)]),
    (4, 3, 3, 4, 2, [(2, 2), (4, 2), (4, 4), (2, 4), (2, 2)]),
]
# per polygon: (arc id (negative: reversed), from node, polygon on the other side); 0 0 0
# separates an island's ring
PAL = [
    [(-2, 1, 2), (-3, 2, 3)],  # the universe: the outer boundary, turned round
    [(2, 2, 1), (1, 1, 3), (0, 0, 0), (-4, 3, 4)],
    [(3, 1, 1), (-1, 2, 2)],
    [(4, 3, 2)],
]
LANDUSE = ["", "FOREST", "MEADOW", "POND"]
CODES = [0, 23, 41, 35]
AREAS = [-200.0, 96.0, 100.0, 4.0]
LABELS = [(2, 2, 6.0, 5.0), (3, 3, 15.0, 5.0), (4, 4, 3.0, 3.0)]  # id, polygon, x, y


def _real(v: float) -> str:
    return f"{v: .7E}"


def e00_text(prj: list[str] | None = None, cover: str = "LANDUSE") -> bytes:
    """The coverage as E00 bytes (single precision), with an optional PRJ section."""
    out = ["EXP  0 /WORK/" + cover + ".E00", "ARC  2"]
    for aid, fn, tn, lp, rp, pts in ARCS:
        out.append(f"{aid:10d}{aid:10d}{fn:10d}{tn:10d}{lp:10d}{rp:10d}{len(pts):10d}")
        for k in range(0, len(pts), 2):
            out.append("".join(_real(c) for p in pts[k : k + 2] for c in p))
    out.append(f"{-1:10d}" + f"{0:10d}" * 6)
    out.append("PAL  2")
    for k, arcs in enumerate(PAL):
        xs = [p[0] for a in arcs if a[0] for p in ARCS[abs(a[0]) - 1][5]]
        ys = [p[1] for a in arcs if a[0] for p in ARCS[abs(a[0]) - 1][5]]
        if k == 0:
            xs, ys = [0, 20], [0, 10]
        out.append(
            f"{len(arcs):10d}" + "".join(_real(v) for v in (min(xs), min(ys), max(xs), max(ys)))
        )
        for j in range(0, len(arcs), 2):
            out.append("".join(f"{v:10d}" for a in arcs[j : j + 2] for v in a))
    out.append(f"{-1:10d}" + f"{0:10d}" * 6)
    out.append("LAB  2")
    for lid, pid, x, y in LABELS:
        out.append(f"{lid:10d}{pid:10d}{_real(x)}{_real(y)}")
        out.append(_real(x) + _real(y) + _real(x) + _real(y))
    out.append(f"{-1:10d}{0:10d}{_real(0)}{_real(0)}")
    out.append("TOL  2")
    for k in range(1, 11):
        out.append(f"{k:10d}{2:10d}{_real(0)}")
    out.append(f"{-1:10d}" + f"{0:10d}" * 6)
    if prj:
        out.append("PRJ  2")
        for line in prj:
            out += [line, "~"]
        out.append("EOP")
    body = "\n".join(out).encode("ascii") + b"\n"
    ifo = b"IFO  2\n" + _pat(cover) + _aat(cover) + b"EOI\nEOS\n"
    return body + ifo


def _pat(cover: str) -> bytes:
    n = len(LANDUSE)
    items = [
        _Item("AREA", T_BINFLOAT, 4, 12, 3),
        _Item("PERIMETER", T_BINFLOAT, 4, 12, 3),
        _Item(f"{cover}#", T_BININT, 4, 5),
        _Item(f"{cover}-ID", T_BININT, 4, 5),
        _Item("LANDUSE", T_CHAR, 10, 10),
        _Item("CODE", T_BININT, 4, 5),
    ]
    ids = np.arange(1, n + 1)
    values = [AREAS, np.zeros(n), ids, ids - 1, [s.encode() for s in LANDUSE], CODES]
    cols = [_column(it, v, it.name) for it, v in zip(items, values, strict=True)]
    return _table_bytes(f"{cover}.PAT", items, cols, n, "XX")


def _aat(cover: str) -> bytes:
    n = len(ARCS)
    items = [
        _Item("FNODE#", T_BININT, 4, 5),
        _Item("TNODE#", T_BININT, 4, 5),
        _Item("LPOLY#", T_BININT, 4, 5),
        _Item("RPOLY#", T_BININT, 4, 5),
        _Item("LENGTH", T_BINFLOAT, 4, 12, 3),
        _Item(f"{cover}#", T_BININT, 4, 5),
        _Item(f"{cover}-ID", T_BININT, 4, 5),
    ]
    a = np.array([r[:5] for r in ARCS])
    length = [float(np.sum(np.hypot(*np.diff(np.array(r[5], float), axis=0).T))) for r in ARCS]
    values = [a[:, 1], a[:, 2], a[:, 3], a[:, 4], length, a[:, 0], a[:, 0]]
    cols = [_column(it, v, it.name) for it, v in zip(items, values, strict=True)]
    return _table_bytes(f"{cover}.AAT", items, cols, n, "XX")
