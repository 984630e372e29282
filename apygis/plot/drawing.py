"""The plot of a map on paper: a list of drawing primitives in paper millimetres.

:func:`build_drawing` lays out a map once, by a :class:`~apygis.plot.plotdef.PlotterDef`;
the HP-GL, SVG and PDF back-ends (:mod:`~apygis.plot.hpgl`,
:mod:`~apygis.plot.svg`, :mod:`~apygis.plot.pdf`) only render the
primitives. Paper coordinates are millimetres from the paper's lower-left
corner, x to the right (ground X, east) and y up (ground Y, north)::

    x_mm = (X - X0) * 1000 / scale        y_mm = (Y - Y0) * 1000 / scale

with ``(X0, Y0)`` the plot origin (ground metres at the paper's lower-left
corner). At 1:5000, 1 m on the ground is 0.2 mm on paper.

Three primitives:

* :class:`PaperLine` — a polyline in one pen (map lines, the neat line, the
  title box);
* :class:`FilledRects` — filled rectangles in one pen: a symbol, its 15x15
  bitmap cut into strokes of painted cells (see :func:`symbol_runs`);
* :class:`PaperText` — a text in one pen, its lower-left corner (start of
  the baseline) at ``(x, y)``, ``height`` the cap height in mm.

What falls outside the neat line (the paper less its margins) is handled so:
lines are clipped at the neat line (a line leaving and re-entering becomes
several pieces); symbols and texts whose anchor point (the symbol centre, the
text's start) lies outside are dropped, and the painted cells of a kept
symbol are cut at the neat line. A text may run on past the neat line into
the margin, and so may a spot height's label (it is dropped only if it would
start off the paper). :attr:`Drawing.stats` counts what was drawn, clipped and dropped.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from apygis.errors import FormatError, RecordError
from apygis.model.map import MapFile, crs_string
from apygis.plot.plotdef import ISO_A_SIZES, TITLE_BLOCK_MM, PenDef, PlotterDef
from apygis.progress import Progress

__all__ = [
    "CAP_HEIGHT",
    "SPOT_HEIGHT_CODE",
    "TITLE_HEIGHTS_MM",
    "Drawing",
    "FilledRects",
    "PaperLine",
    "PaperText",
    "build_drawing",
    "clip_polyline",
    "symbol_runs",
]

log = logging.getLogger(__name__)

#: Cap height of the sans-serif font (Helvetica) as a fraction of its size.
CAP_HEIGHT = 0.718
#: The symbol code of the spot height.
SPOT_HEIGHT_CODE = 0
#: Cap heights of the two title lines, mm.
TITLE_HEIGHTS_MM = (4.0, 2.5)

_EPS = 1e-9  # mm: points this close outside the neat line count as on it


class PaperLine(NamedTuple):
    """A polyline: ``points`` (n, 2) mm; ``closed`` joins the last point to the first.

    ``role`` is ``"line"`` (a map line), ``"frame"`` (the neat line) or
    ``"title"`` (the title box).
    """

    pen: int
    points: np.ndarray
    closed: bool
    role: str = "line"


class FilledRects(NamedTuple):
    """Filled rectangles ``rects`` (k, 4) as ``x0, y0, x1, y1`` mm: one symbol."""

    pen: int
    rects: np.ndarray
    role: str = "symbol"


class PaperText(NamedTuple):
    """A text, lower-left at ``(x, y)`` mm, cap height ``height`` mm.

    ``role`` is ``"text"`` (a map text), ``"spot-height"`` (a spot height's
    label) or ``"title"``.
    """

    pen: int
    x: float
    y: float
    height: float
    text: str
    role: str = "text"


@dataclass
class Drawing:
    """A laid-out plot: paper, placement, pens and primitives.

    Attributes
    ----------
    width_mm, height_mm : float
        The paper.
    paper : str
        The paper in words (``"A2 landscape"``, ``"600 x 400 mm"``).
    scale : int
        Plot scale denominator.
    origin : (float, float)
        Ground X, Y (metres) at the paper's lower-left corner.
    frame : (float, float, float, float)
        The neat line ``x0, y0, x1, y1`` in mm (the paper less its margins).
    pens : dict of int to PenDef
        All pens of the plotter definition.
    items : list
        :class:`PaperLine`, :class:`FilledRects` and :class:`PaperText`, in
        drawing order.
    map_id : str
        The map's identification (for titles of the output files).
    stats : dict
        Counts: ``layers``, ``lines`` (map lines drawn, whole or in part),
        ``line_pieces``, ``lines_clipped``, ``lines_dropped``, ``symbols``,
        ``symbols_dropped``, ``spot_heights``, ``texts``, ``texts_dropped``,
        ``labels_dropped`` (spot-height labels that would start off the
        paper).
    """

    width_mm: float
    height_mm: float
    paper: str
    scale: int
    origin: tuple[float, float]
    frame: tuple[float, float, float, float]
    pens: dict[int, PenDef]
    items: list = field(default_factory=list)
    map_id: str = ""
    stats: dict = field(default_factory=dict)

    @property
    def mm_per_m(self) -> float:
        """Paper millimetres per ground metre (1000 / scale)."""
        return 1000.0 / self.scale

    def to_paper(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Ground X, Y (metres) to paper x, y (mm).

        >>> d = Drawing(100, 100, "", 5000, (1000.0, 2000.0), (0, 0, 100, 100), {})
        >>> [float(v) for v in d.to_paper(1100.0, 2050.0)]
        [20.0, 10.0]
        """
        f = self.mm_per_m
        return (
            (np.asarray(x, dtype=float) - self.origin[0]) * f,
            (np.asarray(y, dtype=float) - self.origin[1]) * f,
        )

    def used_pens(self) -> list[int]:
        """The pen numbers the items use, ascending."""
        return sorted({it.pen for it in self.items})

    def count(self, kind: type[Any], role: str | None = None) -> int:
        """Number of items of class ``kind`` (and ``role``)."""
        return sum(1 for it in self.items if isinstance(it, kind) and role in (None, it.role))

    def summary(self) -> str:
        """One line: paper, scale, counts.

        Example: ``A2 landscape (594 x 420 mm), 1:5000, layers c e h r:
        18 lines, 115 symbols (96 spot heights), 14 texts``.
        """
        s = self.stats
        out = (
            f"{self.paper} ({self.width_mm:g} x {self.height_mm:g} mm), 1:{self.scale}, "
            f"layers {' '.join(s.get('layers', [])) or 'none'}: {s.get('lines', 0)} lines, "
            f"{s.get('symbols', 0)} symbols ({s.get('spot_heights', 0)} spot heights), "
            f"{s.get('texts', 0)} texts"
        )

        def n(k: str) -> str:
            word = k.split("_")[0]
            return f"{s[k]} {word if s[k] != 1 else word[:-1]}"

        if s.get("lines_clipped"):
            out += f"; {n('lines_clipped')} clipped at the neat line"
        keys = ("lines_dropped", "symbols_dropped", "texts_dropped", "labels_dropped")
        dropped = [n(k) for k in keys if s.get(k)]
        if dropped:
            out += "; dropped: " + ", ".join(dropped)
        return out


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


def _fallback_bitmap() -> np.ndarray:
    """An open square of 5x5 cells: the mark of a code with no bitmap."""
    bm = np.zeros((15, 15), dtype=bool)
    bm[5, 5:10] = bm[9, 5:10] = True
    bm[5:10, 5] = bm[5:10, 9] = True
    return bm


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


def _inside(x, y, rect) -> np.ndarray:
    return (
        (x >= rect[0] - _EPS)
        & (x <= rect[2] + _EPS)
        & (y >= rect[1] - _EPS)
        & (y <= rect[3] + _EPS)
    )


# --------------------------------------------------------------------------- layout


def _choose_paper(pdef: PlotterDef, need_w: float, need_h: float) -> tuple[float, float, str]:
    """Paper width, height and label for a plot needing ``need_w`` x ``need_h`` mm."""
    spec = pdef.paper
    if spec.name == "custom":
        return spec.width_mm, spec.height_mm, spec.label()
    wide = need_w > need_h
    pref = ("landscape", "portrait") if wide else ("portrait", "landscape")
    orients = (spec.orientation,) if spec.orientation else pref
    names = list(ISO_A_SIZES)[::-1] if spec.name == "auto" else [spec.name]  # A4 first
    for name in names:
        for o in orients:
            w, h = ISO_A_SIZES[name] if o == "portrait" else ISO_A_SIZES[name][::-1]
            if need_w <= w + 1e-6 and need_h <= h + 1e-6:
                return w, h, f"{name} {o}"
    name, o = names[-1], orients[0]
    w, h = ISO_A_SIZES[name] if o == "portrait" else ISO_A_SIZES[name][::-1]
    log.warning(
        "the plot (%.0f x %.0f mm) does not fit on %s %s; what lies off the neat line is clipped",
        need_w,
        need_h,
        name,
        o,
    )
    return w, h, f"{name} {o}"


def _extent(layers) -> tuple[float, float, float, float] | None:
    boxes = [e for e in (lay.extent() for lay in layers) if e is not None]
    if not boxes:
        return None
    return (
        min(b[0] for b in boxes),
        min(b[1] for b in boxes),
        max(b[3] for b in boxes),
        max(b[4] for b in boxes),
    )


def build_drawing(
    m: MapFile,
    plotdef: PlotterDef | None = None,
    library=None,
    layers: Sequence[str] | None = None,
    progress: Progress | None = None,
) -> Drawing:
    """Lay out map ``m`` on paper.

    Parameters
    ----------
    m : MapFile
        The map.
    plotdef : PlotterDef, optional
        Plotter parameters; default :meth:`PlotterDef.default`.
    library : SymbolLibrary, optional
        Symbol bitmaps; default :func:`apygis.model.symbols.load_library`.
    layers : sequence of str, optional
        Layer extensions to plot (default: all, in alphabetical order).
    progress : Progress, optional
        ``progress(done, total)`` after each layer (:mod:`apygis.progress`).

    Returns
    -------
    Drawing

    Raises
    ------
    RecordError
        If ``layers`` names a layer the map lacks.
    FormatError
        If neither the plotter definition nor the map gives a scale, or the
        margins leave no room on the paper.

    Examples
    --------
    >>> m = MapFile("T1", scale=1000)
    >>> _ = m.layer("r").add_line([(0, 0, 0), (100, 0, 0), (100, 50, 0)], code=12)
    >>> d = build_drawing(m)
    >>> d.paper, d.scale, d.origin, d.stats["lines"]
    ('A4 landscape', 1000, (-15.0, -15.0), 1)
    >>> d.items[1].points.tolist()
    [[15.0, 15.0], [115.0, 15.0], [115.0, 65.0]]
    """
    from apygis.model.polylines import export_lines
    from apygis.model.symbols import load_library

    pdef = PlotterDef.default() if plotdef is None else plotdef
    problems = pdef.problems()
    if problems:
        raise FormatError("plotter definition: " + problems[0])
    lib = load_library() if library is None else library
    if layers is None:
        exts = sorted(m.layers)
    else:
        exts = [e.lower() for e in layers]
        missing = [e for e in exts if e not in m.layers]
        if missing:
            raise RecordError(
                f"map {m.id} has no layer {', '.join(missing)} "
                f"(its layers: {' '.join(sorted(m.layers)) or 'none'})"
            )
    scale = pdef.scale or m.scale
    if not scale:
        raise FormatError(
            f"map {m.id} has no compilation scale; give 'scale' in the plotter definition"
        )
    f = 1000.0 / scale
    ml, mb, mr, mt = pdef.margins_mm
    ext = _extent([m.layers[e] for e in exts])
    if pdef.origin is not None:
        origin = (float(pdef.origin[0]), float(pdef.origin[1]))
    elif ext is not None:
        origin = (ext[0] - ml / f, ext[1] - mb / f)
    else:
        origin = (0.0, 0.0)
    if ext is None:
        need_w, need_h = ml + mr + 1.0, mb + mt + 1.0
    else:
        need_w = (ext[2] - origin[0]) * f + mr
        need_h = (ext[3] - origin[1]) * f + mt
    W, H, label = _choose_paper(pdef, need_w, need_h)
    frame = (ml, mb, W - mr, H - mt)
    if frame[2] <= frame[0] or frame[3] <= frame[1]:
        raise FormatError(
            f"the margins ({ml:g}, {mb:g}, {mr:g}, {mt:g} mm) leave no room on {label} paper"
        )
    d = Drawing(
        width_mm=W,
        height_mm=H,
        paper=label,
        scale=int(scale),
        origin=origin,
        frame=frame,
        pens=dict(pdef.pens),
        map_id=m.id,
    )
    stats: dict[str, Any] = dict.fromkeys(
        (
            "lines",
            "line_pieces",
            "lines_clipped",
            "lines_dropped",
            "symbols",
            "symbols_dropped",
            "spot_heights",
            "texts",
            "texts_dropped",
            "labels_dropped",
        ),
        0,
    )
    stats["layers"] = exts
    items = d.items
    x0, y0, x1, y1 = frame
    if pdef.frame:
        corners = np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], dtype=float)
        items.append(PaperLine(pdef.frame_pen, corners, True, "frame"))

    size = pdef.symbol_size_mm
    cell = size / 15.0
    th = pdef.text_height_mm
    warned: set[int] = set()
    for k, e in enumerate(exts):
        if progress is not None and k:
            progress(k, len(exts))
        lay = m.layers[e]
        # -- lines
        ls = export_lines(lay)
        if len(ls):
            px, py = d.to_paper(ls.coords[:, 0], ls.coords[:, 1])
            xy = np.column_stack([px, py])
            inside = _inside(px, py, frame)
            outside_count = np.add.reduceat((~inside).astype(np.int64), ls.offsets[:-1])
            pens = {int(c): pdef.pen_for(e, "lines", int(c)) for c in np.unique(ls.codes)}
            for k in range(len(ls)):
                a, b = int(ls.offsets[k]), int(ls.offsets[k + 1])
                pts = xy[a:b]
                pen = pens[int(ls.codes[k])]
                closed = bool(ls.closed[k])
                if outside_count[k] == 0:
                    if len(pts) == 1:
                        pts = np.vstack([pts, pts])
                    items.append(PaperLine(pen, pts, closed))
                    stats["lines"] += 1
                    stats["line_pieces"] += 1
                    continue
                pieces = clip_polyline(pts, frame, closed)
                if not pieces:
                    stats["lines_dropped"] += 1
                    continue
                stats["lines"] += 1
                stats["lines_clipped"] += 1
                for p in pieces:
                    if len(p) == 1:
                        p = np.vstack([p, p])
                    items.append(PaperLine(pen, p, False))
                    stats["line_pieces"] += 1
        # -- symbols (spot heights with their labels)
        sym = lay.symbols
        if len(sym):
            sx, sy = d.to_paper(sym["x"], sym["y"])
            keep = _inside(sx, sy, frame)
            stats["symbols_dropped"] += int((~keep).sum())
            labels = []
            for i in np.flatnonzero(keep):
                code = int(sym["code"][i])
                bm = np.asarray(lib[code].bitmap, dtype=bool)
                if not bm.any():
                    if code not in warned:
                        log.warning("symbol code %02d has no bitmap; drawn as a square", code)
                        warned.add(code)
                    bm = _fallback_bitmap()
                unit = _unit_rects(bm.tobytes(), bm.shape)
                rects = unit * cell + np.array([sx[i], sy[i], sx[i], sy[i]])
                rects[:, 0] = np.maximum(rects[:, 0], x0)
                rects[:, 1] = np.maximum(rects[:, 1], y0)
                rects[:, 2] = np.minimum(rects[:, 2], x1)
                rects[:, 3] = np.minimum(rects[:, 3], y1)
                rects = rects[(rects[:, 2] > rects[:, 0]) & (rects[:, 3] > rects[:, 1])]
                items.append(FilledRects(pdef.pen_for(e, "symbols", code), rects))
                stats["symbols"] += 1
                if code == SPOT_HEIGHT_CODE:
                    stats["spot_heights"] += 1
                    text = f"{float(sym['z'][i]):.{pdef.height_decimals}f}"
                    tx = float(sx[i]) + size * 2.5 / 15.0 + 0.4 * th
                    ty = float(sy[i]) - th / 2.0
                    if not _inside(tx, ty, (0.0, 0.0, W, H)):
                        stats["labels_dropped"] += 1
                        continue
                    labels.append(
                        PaperText(pdef.pen_for(e, "symbols", code), tx, ty, th, text, "spot-height")
                    )
            items.extend(labels)
        # -- texts
        tx_ = lay.texts
        if len(tx_):
            px, py = d.to_paper(tx_["x"], tx_["y"])
            keep = _inside(px, py, frame)
            stats["texts_dropped"] += int((~keep).sum())
            pen = pdef.pen_for(e, "texts")
            for i in np.flatnonzero(keep):
                items.append(PaperText(pen, float(px[i]), float(py[i]), th, str(tx_["text"][i])))
                stats["texts"] += 1

    if pdef.title:
        _title_block(d, m, pdef, exts)
    d.stats = stats
    if progress is not None:
        progress(len(exts), len(exts))
    log.info("plot of %s: %s", m.id, d.summary() if d.stats else "")
    return d


def _title_block(d: Drawing, m: MapFile, pdef: PlotterDef, exts: list[str]) -> None:
    """The title box below the neat line, full width, and its two lines."""
    x0, y0, x1, _ = d.frame
    top = y0 - 2.0
    bottom = y0 - TITLE_BLOCK_MM
    box = np.array([(x0, bottom), (x1, bottom), (x1, top), (x0, top)], dtype=float)
    pen = pdef.frame_pen
    d.items.append(PaperLine(pen, box, True, "title"))
    h1, h2 = TITLE_HEIGHTS_MM
    line1 = f"{m.id}   1:{d.scale}"
    if m.scale and m.scale != d.scale:
        line1 += f"   (compiled at 1:{m.scale})"
    crs = crs_string(m.crs) if m.crs is not None else "none"
    f = d.mm_per_m
    e0, n0 = d.origin[0] + x0 / f, d.origin[1] + y0 / f
    e1, n1 = d.origin[0] + x1 / f, d.origin[1] + d.frame[3] / f
    line2 = (
        f"CRS {crs}   layers {' '.join(exts) or 'none'}   "
        f"neat line E {_fmt_m(e0)} - {_fmt_m(e1)}  N {_fmt_m(n0)} - {_fmt_m(n1)}"
    )
    d.items.append(PaperText(pen, x0 + 3.0, top - 1.5 - h1, h1, line1, "title"))
    d.items.append(PaperText(pen, x0 + 3.0, bottom + 2.0, h2, line2, "title"))


def _fmt_m(v: float) -> str:
    return f"{v:.0f}" if math.isclose(v, round(v), abs_tol=0.005) else f"{v:.2f}"
