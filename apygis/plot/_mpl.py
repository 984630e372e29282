"""A :class:`~apygis.plot.drawing.Drawing` as a matplotlib figure: the PDF and the pin plot.

One figure the size of the paper, one axes filling it with limits in paper
millimetres, so a primitive's coordinates are used as they are:

* consecutive :class:`PaperLine` of one pen become one compound path
  stroked in the pen's colour and width (round caps and joins);
* :class:`FilledRects` and :class:`FilledPolygon` one filled path per run
  of one pen;
* consecutive :class:`PaperText` one artist that hands each text straight
  to the renderer (``draw_text``: what a matplotlib ``Text`` with left and
  baseline alignment does, pixel for pixel, without its layout machinery,
  several times faster): DejaVu Sans, the baseline start at the text's
  point, font size = cap height / :data:`~apygis.plot.fonts.CAP_HEIGHT`,
  turned by its angle; never parsed as mathtext (a ``$`` is a dollar); a
  text with a halo over a white stroke of its glyphs' outlines.

Items keep their drawing order (z-order = position). Small marker artists
between chunks of items report ``progress(done, total)`` while matplotlib
renders, so a long plot shows progress during the save itself.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np

from apygis.plot.fonts import CAP_HEIGHT, FONT_FAMILY, PT_PER_MM, text_outlines
from apygis.plot.primitives import HALO, FilledPolygon, FilledRects, PaperLine, PaperText
from apygis.progress import Progress

__all__ = ["RC", "drawing_figure"]

#: matplotlib settings of every rendering: TrueType (Type 42) fonts embedded
#: as subsets in PDF, no path simplification (the plot is drawn as it is).
RC: Any = {
    "pdf.fonttype": 42,
    "path.simplify": False,
    "svg.fonttype": "none",
    "text.usetex": False,
    "text.antialiased": True,
    "lines.antialiased": True,
    "patch.antialiased": True,
}

_CHUNKS = 20  # progress steps while rendering


def _colour(d, pen: int) -> tuple[float, float, float]:
    p = d.pens.get(pen)
    c = p.colour if p is not None else (0, 0, 0)
    return (c[0] / 255.0, c[1] / 255.0, c[2] / 255.0)


def _width_pt(d, pen: int) -> float:
    p = d.pens.get(pen)
    return (p.width_mm if p is not None else 0.35) * PT_PER_MM


def _line_path(lines: list[PaperLine]):
    from matplotlib.path import Path

    verts, codes = [], []
    for it in lines:
        pts = np.asarray(it.points, dtype=float)
        c = np.full(len(pts), Path.LINETO, dtype=np.uint8)
        c[0] = Path.MOVETO
        verts.append(pts)
        codes.append(c)
        if it.closed:
            verts.append(pts[:1])
            codes.append(np.array([Path.CLOSEPOLY], dtype=np.uint8))
    return Path(np.vstack(verts), np.concatenate(codes))


def _fill_path(items: list):
    from matplotlib.path import Path

    verts, codes = [], []
    for it in items:
        if isinstance(it, FilledRects):
            r = np.asarray(it.rects, dtype=float).reshape(-1, 4)
            if not len(r):
                continue
            v = np.stack(
                [r[:, [0, 1]], r[:, [2, 1]], r[:, [2, 3]], r[:, [0, 3]], r[:, [0, 1]]], axis=1
            ).reshape(-1, 2)
            c = np.tile(
                np.array([Path.MOVETO, Path.LINETO, Path.LINETO, Path.LINETO, Path.CLOSEPOLY]),
                len(r),
            ).astype(np.uint8)
            verts.append(v)
            codes.append(c)
        else:
            pts = np.asarray(it.points, dtype=float)
            c = np.full(len(pts) + 1, Path.LINETO, dtype=np.uint8)
            c[0], c[-1] = Path.MOVETO, Path.CLOSEPOLY
            verts.append(np.vstack([pts, pts[:1]]))
            codes.append(c)
    if not verts:
        return None
    return Path(np.vstack(verts), np.concatenate(codes))


def _runs(items: list) -> list[tuple[str, int, list]]:
    """Consecutive items of one kind and pen: ``(kind, pen, items)``."""
    out: list[tuple[str, int, list]] = []
    for it in items:
        if isinstance(it, PaperLine):
            kind = "line"
        elif isinstance(it, FilledRects | FilledPolygon):
            kind = "fill"
        elif isinstance(it, PaperText):
            kind = "text"
        else:
            continue
        if out and out[-1][0] == kind and (out[-1][1] == it.pen or kind == "text"):
            out[-1][2].append(it)
        else:
            out.append((kind, it.pen, [it]))
    return out


@functools.lru_cache(maxsize=1)
def _texts_class():
    from matplotlib.artist import Artist
    from matplotlib.font_manager import FontProperties
    from matplotlib.path import Path

    class Texts(Artist):
        """Texts drawn straight by the renderer, in order (see the module's notes)."""

        def __init__(self, texts: list[tuple[PaperText, tuple[float, float, float]]]):
            super().__init__()
            self._texts = texts
            self._props: dict[float, Any] = {}

        def _prop(self, height: float):
            prop = self._props.get(height)
            if prop is None:
                prop = FontProperties(family=FONT_FAMILY, size=height / CAP_HEIGHT * PT_PER_MM)
                self._props[height] = prop
            return prop

        def _halo(self, renderer, t: PaperText) -> None:
            """A white outline of the glyphs under the text (the text stays text)."""
            rings = text_outlines(t.text, t.x, t.y, t.height, t.angle)
            if not rings or self.axes is None:
                return
            verts = np.vstack([np.vstack([r, r[:1]]) for r in rings])
            codes = np.concatenate(
                [[Path.MOVETO, *([Path.LINETO] * (len(r) - 1)), Path.CLOSEPOLY] for r in rings]
            ).astype(np.uint8)
            hgc = renderer.new_gc()
            try:
                hgc.set_foreground((1.0, 1.0, 1.0, 1.0), isRGBA=True)
                hgc.set_linewidth(HALO * t.height * PT_PER_MM)
                hgc.set_joinstyle("round")
                hgc.set_capstyle("round")
                renderer.draw_path(hgc, Path(verts, codes), self.axes.transData, None)
            finally:
                hgc.restore()

        def draw(self, renderer) -> None:
            if not self.get_visible() or self.axes is None:
                return
            to_display = self.axes.transData.transform
            flip = renderer.flipy()
            canvas_h = renderer.get_canvas_width_height()[1]
            gc = renderer.new_gc()
            try:
                for t, colour in self._texts:
                    if not t.text:
                        continue
                    if t.halo:
                        self._halo(renderer, t)
                    gc.set_foreground((*colour, 1.0), isRGBA=True)
                    x, y = to_display((t.x, t.y))
                    if flip:
                        y = canvas_h - y
                    renderer.draw_text(
                        gc, x, y, t.text, self._prop(t.height), t.angle, ismath=False, mtext=None
                    )
            finally:
                gc.restore()

    return Texts


def _texts_artist(texts):
    return _texts_class()(texts)


def drawing_figure(d, progress: Progress | None = None):
    """The figure of drawing ``d`` (a :class:`matplotlib.figure.Figure`, 72 dpi).

    ``progress(done, total)`` is called while the figure is rendered (a save
    or a draw), after each of about 20 chunks of items.
    """
    from matplotlib.artist import Artist
    from matplotlib.figure import Figure
    from matplotlib.patches import PathPatch

    W, H = d.width_mm, d.height_mm
    fig = Figure(figsize=(W / 25.4, H / 25.4), dpi=72, facecolor="white")
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, W)
    ax.set_ylim(0.0, H)
    ax.set_axis_off()
    ax.set_autoscale_on(False)

    class _Marker(Artist):
        def __init__(self, done: int, total: int, report: Callable[[int, int], None]):
            super().__init__()
            self._done, self._total, self._report = done, total, report

        def draw(self, renderer) -> None:
            self._report(self._done, self._total)

    runs = _runs(d.items)
    total_items = max(1, sum(len(r[2]) for r in runs))
    step = max(1, total_items // _CHUNKS)
    done_items = 0
    next_mark = step
    z = 0.0
    marks = 0
    if progress is not None:
        ax.add_artist(_Marker(0, _CHUNKS + 1, progress)).set_zorder(-1.0)
    for kind, pen, group in runs:
        colour = _colour(d, pen)
        z += 1.0
        if kind == "line":
            patch = PathPatch(
                _line_path(group),
                fill=False,
                edgecolor=colour,
                linewidth=_width_pt(d, pen),
                capstyle="round",
                joinstyle="round",
            )
            patch.set_zorder(z)
            ax.add_artist(patch)
        elif kind == "fill":
            path = _fill_path(group)
            if path is not None:
                patch = PathPatch(path, facecolor=colour, edgecolor="none", linewidth=0.0)
                patch.set_zorder(z)
                ax.add_artist(patch)
        else:
            batch = _texts_artist([(t, _colour(d, t.pen)) for t in group])
            batch.set_zorder(z)
            ax.add_artist(batch)
        done_items += len(group)
        if progress is not None and done_items >= next_mark and marks < _CHUNKS - 1:
            marks += 1
            z += 1.0
            ax.add_artist(_Marker(marks, _CHUNKS + 1, progress)).set_zorder(z)
            next_mark += step
    if progress is not None:
        ax.add_artist(_Marker(_CHUNKS + 1, _CHUNKS + 1, progress)).set_zorder(z + 1.0)
    return fig
