"""Pen plotter output of a :class:`~apygis.plot.drawing.Drawing`: HP-GL/1, or HP-GL/2 on request.

APY drove "drafting plotters", flat bed or drum, through its PLOTTER.DEF;
HP-GL is the language those plotters share. Coordinates are absolute
plotter units of 0.025 mm (40 per mm), (0, 0) at the paper's lower-left
corner.

**HP-GL/1** (the default; what an HP 7475A, 7550A or DraftPro understands)::

    IN;PA;DT\\x03;            initialise, absolute coordinates, labels end with ETX
    SP1;                      select pen 1 (its width is whatever sits in that slot)
    PU600,600;PD800,600,...;  pen up to a point, pen down along a polyline
    SI0.137,0.25;DI1,0;       character width and cap height in cm; direction
    PU900,700;LBKirchweg\\x03; a label, the start of its baseline at the pen
    PU;SP0;                   lift the pen and put it away

No ``PW``: HP-GL/1 has no pen widths; the plotter definition's widths
decide how densely symbols are hatched, and the pens in the carousel draw.

**HP-GL/2** (``version=2``) adds, after ``IN;PA;DT\\x03;``: ``WU0;`` (widths
in mm), ``NPn;`` and ``CR0,255,0,255,0,255;`` with ``PCpen,r,g,b;`` for the
pens' colours, ``PWwidth,pen;`` for their widths, and ``LA1,4,2,4;`` (round
caps and joins).

Items are drawn pen by pen (pen 1 first) to save pen changes, each pen's
items in drawing order. A closed line returns to its first point. Filled
rectangles (a symbol's painted cells, the scale bar) are hatched with
strokes along each rectangle's longer side, as many as the pen needs to
cover its shorter side (:func:`hatch_strokes`); filled polygons (the north
arrow) with horizontal strokes a pen width apart (:func:`hatch_polygon`).

**Labels**: a label in printable ASCII is written with ``LB`` in the
plotter's stick font, its character width set (``SI``) so that the label
is as long as the layout measured it in DejaVu Sans (a stick character
cell is 1.5 character widths), so that placed labels keep clear of what
they were placed to avoid; a turned label sets ``DI``. A label with any
other character (``Zürich``, ``Łódź``, ``Ελλάδα``) cannot be held by the
plotter's character set: it is drawn as the outlines of its DejaVu Sans
glyphs (pen strokes), nothing dropped or replaced; ``report["outlined"]``
counts them.

Examples
--------
>>> from apygis.plot.drawing import Drawing, PaperLine
>>> from apygis.plot.plotdef import PenDef
>>> d = Drawing(210, 297, "A4 portrait", 5000, (0.0, 0.0), (15, 15, 195, 282),
...             {1: PenDef(1, (0, 0, 0), 0.35)})
>>> d.items.append(PaperLine(1, np.array([(15.0, 15.0), (20.0, 15.0)]), False))
>>> print(drawing_hpgl(d).decode("ascii"))
IN;PA;DT\x03;
SP1;
PU600,600;PD800,600;
PU;SP0;
<BLANKLINE>
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from apygis.plot.fonts import text_outlines, text_size
from apygis.plot.primitives import FilledPolygon, FilledRects, PaperLine, PaperText

__all__ = [
    "CELL",
    "ETX",
    "UNITS_PER_MM",
    "drawing_hpgl",
    "hatch_polygon",
    "hatch_strokes",
    "is_plotter_text",
]

#: Plotter units per millimetre (1 unit = 0.025 mm).
UNITS_PER_MM = 40
#: Label terminator.
ETX = "\x03"
#: A stick-font character cell is this many character widths wide (the glyph and its space).
CELL = 1.5


def is_plotter_text(text: str) -> bool:
    """Whether the plotter's standard character set holds ``text`` (printable ASCII).

    >>> is_plotter_text("P 1091-01"), is_plotter_text("Zürich")
    (True, False)
    """
    return all(32 <= ord(ch) < 127 for ch in text)


def hatch_strokes(rects, pen_width_mm: float) -> np.ndarray:
    """Strokes (k, 2, 2) in mm that fill ``rects`` (``x0, y0, x1, y1``) with a round pen.

    >>> hatch_strokes([(0.0, 0.0, 1.0, 0.2)], 0.35).tolist()
    [[[0.175, 0.1], [0.825, 0.1]]]
    >>> len(hatch_strokes([(0.0, 0.0, 1.0, 0.6)], 0.25))
    3
    """
    rects = np.asarray(rects, dtype=float).reshape(-1, 4)
    pw = float(pen_width_mm)
    out = []
    for i, (x0, y0, x1, y1) in enumerate(rects):
        w, h = x1 - x0, y1 - y0
        horizontal = w >= h
        long0, long1, short0, short1 = (x0, x1, y0, y1) if horizontal else (y0, y1, x0, x1)
        short = short1 - short0
        n = max(1, math.ceil(short / pw - 1e-9))
        if n == 1:
            offs = [(short0 + short1) / 2.0]
        else:  # first and last stroke touch the edges, the others evenly between
            a, b = short0 + pw / 2.0, short1 - pw / 2.0
            offs = [a + (b - a) * j / (n - 1) for j in range(n)]
        s, e = long0 + pw / 2.0, long1 - pw / 2.0
        if s > e:
            s = e = (long0 + long1) / 2.0
        for j, o in enumerate(offs):
            p, q = (s, e) if (i + j) % 2 == 0 else (e, s)
            out.append([(p, o), (q, o)] if horizontal else [(o, p), (o, q)])
    return np.array(out, dtype=float).reshape(-1, 2, 2)


def hatch_polygon(points, pen_width_mm: float) -> list[np.ndarray]:
    """Strokes that fill a polygon: its outline, then horizontal strokes a pen width apart.

    >>> strokes = hatch_polygon([(0, 0), (2, 0), (1, 2)], 0.5)
    >>> len(strokes) > 3, bool(np.allclose(strokes[0][0], strokes[0][-1]))
    (True, True)
    """
    import shapely

    pts = np.asarray(points, dtype=float)
    poly = shapely.Polygon(pts)
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
    out = [np.vstack([pts, pts[:1]])]
    inner = poly.buffer(-pen_width_mm / 2.0)
    if inner.is_empty:
        return out
    x0, y0, x1, y1 = inner.bounds
    n = max(1, math.ceil((y1 - y0) / pen_width_mm))
    for k in range(n + 1):
        y = y0 + (y1 - y0) * k / max(n, 1)
        cut = inner.intersection(shapely.LineString([(x0 - 1, y), (x1 + 1, y)]))
        parts = getattr(cut, "geoms", [cut])
        for g in parts:
            if g.is_empty or g.geom_type != "LineString":
                continue
            seg = np.asarray(g.coords, dtype=float)
            out.append(seg if k % 2 == 0 else seg[::-1])
    return out


def _pu(xy: npt.ArrayLike) -> np.ndarray:
    return np.rint(np.asarray(xy, dtype=float) * UNITS_PER_MM).astype(np.int64)


def _coords(units: np.ndarray) -> str:
    return ",".join(str(v) for v in units.ravel().tolist())


def _polyline(pts: np.ndarray) -> str:
    u = _pu(pts)
    return f"PU{_coords(u[0])};PD{_coords(u[1:] if len(u) > 1 else u)};\n"


def _num(v: float) -> str:
    s = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def drawing_hpgl(d, version: int = 1, report: dict | None = None) -> bytes:
    """The drawing as HP-GL/1 (``version=1``) or HP-GL/2 (``version=2``) instructions.

    ``report``, when given, receives ``labels`` (labels written) and
    ``outlined`` (labels drawn as glyph outlines, their characters outside
    the plotter's character set).
    """
    if version not in (1, 2):
        raise ValueError(f"HP-GL version must be 1 or 2, not {version!r}")
    out = [f"IN;PA;DT{ETX};\n"]
    used = d.used_pens()
    if version == 2 and used:
        out.append(f"WU0;NP{max(max(used), 2)};CR0,255,0,255,0,255;LA1,4,2,4;\n")
        for p in used:
            pen = d.pens.get(p)
            if pen is not None:
                r, g, b = pen.colour
                out.append(f"PC{p},{r},{g},{b};PW{_num(pen.width_mm)},{p};")
        out.append("\n")
    size = direction = None
    labels = outlined = 0
    for pen in used:
        out.append(f"SP{pen};\n")
        pw = d.pens[pen].width_mm if pen in d.pens else 0.35
        for it in d.items:
            if it.pen != pen:
                continue
            if isinstance(it, PaperLine):
                pts = it.points
                if it.closed:
                    pts = np.vstack([pts, pts[:1]])
                out.append(_polyline(pts))
            elif isinstance(it, FilledRects):
                for st in hatch_strokes(it.rects, pw):
                    out.append(_polyline(st))
            elif isinstance(it, FilledPolygon):
                for st in hatch_polygon(it.points, pw):
                    out.append(_polyline(st))
            elif isinstance(it, PaperText):
                if not it.text.strip():
                    continue
                labels += 1
                if not is_plotter_text(it.text):
                    outlined += 1
                    for ring in text_outlines(it.text, it.x, it.y, it.height, it.angle):
                        out.append(_polyline(ring))
                    continue
                width = it.width or text_size(it.text, it.height)[0]
                n = len(it.text)
                w = width / (CELL * n - (CELL - 1.0))
                w = min(max(w, 0.25 * it.height), 1.5 * it.height)
                si = f"SI{_num(w / 10.0)},{_num(it.height / 10.0)};"
                if si != size:
                    out.append(si + "\n")
                    size = si
                a = math.radians(it.angle)
                di = f"DI{_num(math.cos(a))},{_num(math.sin(a))};"
                if di != direction and (direction is not None or it.angle):
                    out.append(di + "\n")
                    direction = di
                u = _pu((it.x, it.y))
                out.append(f"PU{_coords(u)};LB{it.text}{ETX};\n")
    out.append("PU;SP0;\n")
    if report is not None:
        report["labels"] = labels
        report["outlined"] = outlined
    return "".join(out).encode("ascii")
