"""HP-GL/2-compatible plotter output of a :class:`~apygis.plot.drawing.Drawing`.

APY drove "drafting plotters", flat bed or drum, through its PLOTTER.DEF;
HP-GL is the language those plotters share. The output uses a small,
widely understood subset, in absolute plotter units of 0.025 mm (40 per mm)
with (0, 0) at the paper's lower-left corner::

    IN;                       initialise
    PA;                       absolute coordinates
    DT\\x03;                   labels end with ETX (character 3)
    PW0.35,1;                 pen widths in mm, one per pen used (HP-GL/2)
    SP1;                      select pen 1
    PU600,600;PD800,600,...;  pen up to a point, pen down along a polyline
    SI0.125,0.25;             character width and cap height in cm
    PU900,700;LBKirchweg\\x03; a label, its lower-left corner at the pen
    PU;SP0;                   lift the pen and put it away

Each instruction group ends with a newline (plotters ignore it). Items are
drawn pen by pen (pen 1 first) to save pen changes, each pen's items in
drawing order. A closed line returns to its first point. A symbol's painted
cells (:class:`~apygis.plot.drawing.FilledRects`) are hatched with
strokes along each rectangle's longer side, as many as the pen needs to
cover its shorter side (one stroke for a one-cell-wide run when the pen is
at least a cell wide), the strokes inset by half the pen width so that the
ink covers the cells and no more, alternating in direction. Labels are
ASCII: German umlauts become ``ae oe ue`` (``ss`` for ``ß``), other accents
are dropped and what is left outside ASCII becomes ``?``.

Examples
--------
>>> from apygis.plot.drawing import Drawing, PaperLine
>>> from apygis.plot.plotdef import PenDef
>>> d = Drawing(210, 297, "A4 portrait", 5000, (0.0, 0.0), (15, 15, 195, 282),
...             {1: PenDef(1, (0, 0, 0), 0.35)})
>>> d.items.append(PaperLine(1, np.array([(15.0, 15.0), (20.0, 15.0)]), False))
>>> print(drawing_hpgl(d).decode("ascii"))
IN;PA;DT\x03;
PW0.35,1;
SP1;
PU600,600;PD800,600;
PU;SP0;
<BLANKLINE>
"""

from __future__ import annotations

import math
import unicodedata

import numpy as np
import numpy.typing as npt

from apygis.plot.drawing import Drawing, FilledRects, PaperLine, PaperText

__all__ = ["CHAR_WIDTH", "ETX", "UNITS_PER_MM", "ascii_label", "drawing_hpgl", "hatch_strokes"]

#: Plotter units per millimetre (1 unit = 0.025 mm).
UNITS_PER_MM = 40
#: Label terminator.
ETX = "\x03"
#: Character width (``SI``) as a fraction of the cap height.
CHAR_WIDTH = 0.5

_UMLAUTS = str.maketrans(
    {"ä": "ae", "ö": "oe", "ü": "ue", "Ä": "Ae", "Ö": "Oe", "Ü": "Ue", "ß": "ss"}
)


def ascii_label(text: str) -> str:
    """A label in plain ASCII for the plotter's standard character set.

    >>> ascii_label("Zürichstraße Côte 5°")
    'Zuerichstrasse Cote 5?'
    """
    t = unicodedata.normalize("NFKD", text.translate(_UMLAUTS))
    t = "".join(ch for ch in t if not unicodedata.combining(ch))
    return "".join(ch if 32 <= ord(ch) < 127 else "?" for ch in t)


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


def _pu(xy: npt.ArrayLike) -> np.ndarray:
    return np.rint(np.asarray(xy, dtype=float) * UNITS_PER_MM).astype(np.int64)


def _coords(units: np.ndarray) -> str:
    return ",".join(str(v) for v in units.ravel().tolist())


def drawing_hpgl(d: Drawing) -> bytes:
    """The drawing as HP-GL/2-compatible plotter instructions (ASCII bytes)."""
    out = [f"IN;PA;DT{ETX};\n"]
    used = d.used_pens()
    out.append("".join(f"PW{d.pens[p].width_mm:g},{p};" for p in used if p in d.pens) + "\n")
    size = None
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
                u = _pu(pts)
                out.append(f"PU{_coords(u[0])};PD{_coords(u[1:] if len(u) > 1 else u)};\n")
            elif isinstance(it, FilledRects):
                for st in hatch_strokes(it.rects, pw):
                    u = _pu(st)
                    out.append(f"PU{_coords(u[0])};PD{_coords(u[1])};\n")
            elif isinstance(it, PaperText):
                cm = it.height / 10.0
                si = f"SI{CHAR_WIDTH * cm:.4g},{cm:.4g};"
                if si != size:
                    out.append(si + "\n")
                    size = si
                u = _pu((it.x, it.y))
                out.append(f"PU{_coords(u)};LB{ascii_label(it.text)}{ETX};\n")
    out.append("PU;SP0;\n")
    return "".join(out).encode("ascii")
