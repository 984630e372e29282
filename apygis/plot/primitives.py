"""The drawing primitives of a plot, in paper millimetres, and the geometry helpers they need.

Paper coordinates are millimetres from the paper's lower-left corner, x to
the right (east) and y up (north). Four primitives, each with a pen number
and a ``role`` saying what it draws (``line``, ``symbol``, ``text``,
``spot-height``, ``label``, ``frame``, ``grid``, ``grid-label``,
``heading``, ``legend``, ``scalebar``, ``north``, ``title``, ``control``):

* :class:`PaperLine` — a polyline stroked in the pen;
* :class:`FilledRects` — rectangles filled in the pen: a symbol, its 15x15
  bitmap cut into strokes of painted cells (:func:`symbol_runs`), or the
  scale bar's filled segments;
* :class:`FilledPolygon` — a polygon filled in the pen (the north arrow);
* :class:`PaperText` — a text in the pen: the start of its baseline at
  ``(x, y)``, its cap height ``height``, turned ``angle`` degrees
  counter-clockwise, its ink ``width`` as :mod:`apygis.plot.fonts` measures
  it (:func:`make_text` fills it in).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from apygis.plot.fonts import text_size

__all__ = [
    "HALO",
    "FilledPolygon",
    "FilledRects",
    "PaperLine",
    "PaperText",
    "clip_polyline",
    "make_text",
    "symbol_rects",
    "symbol_runs",
    "text_box",
]


class PaperLine(NamedTuple):
    """A polyline: ``points`` (n, 2) mm; ``closed`` joins the last point to the first."""

    pen: int
    points: np.ndarray
    closed: bool
    role: str = "line"


class FilledRects(NamedTuple):
    """Filled rectangles ``rects`` (k, 4) as ``x0, y0, x1, y1`` mm."""

    pen: int
    rects: np.ndarray
    role: str = "symbol"


class FilledPolygon(NamedTuple):
    """A filled polygon ``points`` (n, 2) mm (closed implicitly)."""

    pen: int
    points: np.ndarray
    role: str = "fill"


class PaperText(NamedTuple):
    """A text: baseline start ``(x, y)`` mm, cap height ``height`` mm, ``angle`` degrees.

    ``width`` is the ink width in mm (0 when unknown; :func:`make_text`
    measures it). ``halo``: drawn over a white outline (:data:`HALO`), for a
    label that could not be placed free, so that it stays legible over what
    it crosses (the SVG, PDF and pin plot; a pen plotter cannot erase).
    """

    pen: int
    x: float
    y: float
    height: float
    text: str
    role: str = "text"
    angle: float = 0.0
    width: float = 0.0
    halo: bool = False


#: Width of a label's white halo as a fraction of its cap height (each side half of it).
HALO = 0.35


def make_text(
    pen: int,
    x: float,
    y: float,
    height: float,
    text: str,
    role: str = "text",
    angle: float = 0.0,
    halo: bool = False,
) -> PaperText:
    """A :class:`PaperText` with its width measured.

    >>> t = make_text(1, 0.0, 0.0, 2.5, "Zürich")
    >>> round(t.width, 2)
    10.94
    """
    return PaperText(
        pen,
        float(x),
        float(y),
        float(height),
        text,
        role,
        float(angle),
        text_size(text, height)[0],
        halo,
    )


def text_box(t: PaperText) -> tuple[float, float, float, float]:
    """The axis-aligned box ``x0, y0, x1, y1`` (mm) a text covers, descenders included."""
    w, d = text_size(t.text, t.height)
    corners = np.array([(0.0, -d), (w, -d), (w, t.height), (0.0, t.height)])
    a = np.radians(t.angle)
    c, s = np.cos(a), np.sin(a)
    xs = t.x + corners[:, 0] * c - corners[:, 1] * s
    ys = t.y + corners[:, 0] * s + corners[:, 1] * c
    return (float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max()))


# --------------------------------------------------------------------------- symbols


def symbol_runs(bitmap) -> np.ndarray:
    """The painted cells of a 15x15 bitmap as strokes: (k, 4) ``row0, col0, row1, col1``.

    Rows and columns are inclusive; row 0 is the top. The rule, which draws
    well with a pen: first every horizontal run of two or more painted cells
    in a row; then the cells left over, joined into vertical runs (one cell
    or more) down each column.

    >>> from apygis.model.symbols import SPOT_HEIGHT_SYMBOL
    >>> symbol_runs(SPOT_HEIGHT_SYMBOL.bitmap).tolist()
    [[7, 5, 7, 9], [5, 7, 6, 7], [8, 7, 9, 7]]
    """
    bm = np.asarray(bitmap, dtype=bool)
    rows, cols = bm.shape
    covered = np.zeros_like(bm)
    out = []
    for r in range(rows):
        c = 0
        while c < cols:
            if bm[r, c]:
                e = c
                while e + 1 < cols and bm[r, e + 1]:
                    e += 1
                if e > c:
                    out.append((r, c, r, e))
                    covered[r, c : e + 1] = True
                c = e + 1
            else:
                c += 1
    rest = bm & ~covered
    for c in range(cols):
        r = 0
        while r < rows:
            if rest[r, c]:
                e = r
                while e + 1 < rows and rest[e + 1, c]:
                    e += 1
                out.append((r, c, e, c))
                r = e + 1
            else:
                r += 1
    return np.array(out, dtype=np.int64).reshape(-1, 4)


@functools.lru_cache(maxsize=256)
def _unit_rects(bits: bytes, shape: tuple[int, int]) -> np.ndarray:
    """Rects of a bitmap in cell units, centred on the bitmap's centre, y up."""
    bm = np.frombuffer(bits, dtype=bool).reshape(shape)
    runs = symbol_runs(bm).astype(float)
    half_r, half_c = shape[0] / 2.0, shape[1] / 2.0
    x0 = runs[:, 1] - half_c
    x1 = runs[:, 3] + 1.0 - half_c
    y0 = half_r - runs[:, 2] - 1.0
    y1 = half_r - runs[:, 0]
    return np.column_stack([x0, y0, x1, y1])


def symbol_rects(bitmap, x: float, y: float, size_mm: float) -> np.ndarray:
    """The strokes of ``bitmap`` as rects (k, 4) mm: ``size_mm`` wide, centred on (x, y).

    >>> symbol_rects(np.eye(15, dtype=bool)[:, ::-1] | np.eye(15, dtype=bool), 0, 0, 3.0).shape
    (29, 4)
    """
    bm = np.ascontiguousarray(np.asarray(bitmap, dtype=bool))
    unit = _unit_rects(bm.tobytes(), bm.shape)
    return unit * (size_mm / bm.shape[1]) + np.array([x, y, x, y], dtype=float)


# --------------------------------------------------------------------------- clipping


def clip_polyline(points, rect, closed: bool = False) -> list[np.ndarray]:
    """The parts of a polyline inside ``rect`` (``x0, y0, x1, y1``), as open polylines.

    Liang-Barsky on every segment; consecutive visible segments that are not
    cut between them stay one piece. A closed line is clipped as a ring: its
    last piece and its first are joined where the ring's first vertex is
    inside. A single point is kept if it is inside.

    >>> pieces = clip_polyline([(-5, 5), (5, 5), (5, 15), (5, 5.5)], (0, 0, 10, 10))
    >>> [p.tolist() for p in pieces]
    [[[0.0, 5.0], [5.0, 5.0], [5.0, 10.0]], [[5.0, 10.0], [5.0, 5.5]]]
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    xmin, ymin, xmax, ymax = (float(v) for v in rect)
    if len(pts) == 0:
        return []
    if len(pts) == 1:
        x, y = pts[0]
        return [pts.copy()] if xmin <= x <= xmax and ymin <= y <= ymax else []
    if closed:
        pts = np.vstack([pts, pts[:1]])
    p0 = pts[:-1]
    d = pts[1:] - p0
    n = len(p0)
    t0 = np.zeros(n)
    t1 = np.ones(n)
    ok = np.ones(n, dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for p, q in (
            (-d[:, 0], p0[:, 0] - xmin),
            (d[:, 0], xmax - p0[:, 0]),
            (-d[:, 1], p0[:, 1] - ymin),
            (d[:, 1], ymax - p0[:, 1]),
        ):
            r = q / p
            ok &= ~((p == 0) & (q < 0))
            neg, pos = p < 0, p > 0
            t0 = np.where(neg, np.maximum(t0, r), t0)
            t1 = np.where(pos, np.minimum(t1, r), t1)
    ok &= t0 <= t1
    a = p0 + t0[:, None] * d
    b = p0 + t1[:, None] * d
    pieces: list[list[np.ndarray]] = []
    cont = False  # does the current piece end at the segment's end, uncut?
    for i in range(n):
        if not ok[i]:
            cont = False
            continue
        if cont and t0[i] == 0.0:
            pieces[-1].append(b[i])
        else:
            pieces.append([a[i], b[i]])
        cont = t1[i] == 1.0
    if closed and len(pieces) > 1 and ok[0] and t0[0] == 0.0 and ok[-1] and t1[-1] == 1.0:
        first = pieces.pop(0)
        pieces[-1].extend(first[1:])
    return [np.array(p) for p in pieces]
