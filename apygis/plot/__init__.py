"""Print and plot: a map sheet as HP-GL, SVG, PDF or a raster pin plot, and the APY print-out.

These are not format drivers (a plot cannot be read back into a map): they
draw a :class:`~apygis.model.map.MapFile` for people and pen plotters. The
flow is one way::

    PLOTTER.DEF ──► PlotterDef ─┐                       ┌─► HP-GL/1 or /2 (hpgl.drawing_hpgl)
                                ├─► Drawing (paper mm) ─┼─► SVG     (svg.drawing_svg)
    MapFile + symbol library ───┘   build_drawing       ├─► PDF     (pdf.drawing_pdf)     ┐ one
                                                        └─► PNG/TIF (raster.drawing_png) ┘ figure

    MapFile ──► printout_text (text) ──► text_pages_pdf (A4 pages in DejaVu Sans Mono)

Modules:

* :mod:`~apygis.plot.plotdef` — PLOTTER.DEF (``docs/plotter-def.md``):
  paper, scale, window or origin, margins, grid, pens and pen rules, as a
  :class:`PlotterDef`;
* :mod:`~apygis.plot.drawing` — :func:`build_drawing` lays a map out once,
  as a :class:`Drawing` of primitives in paper millimetres, with
  :mod:`~apygis.plot.layout` (scale, window, paper, where the map and its
  panel go), :mod:`~apygis.plot.labels` (texts and spot heights placed off
  lines, symbols and each other), :mod:`~apygis.plot.margin` (grid, legend,
  scale bar, north arrow, title block), :mod:`~apygis.plot.primitives` and
  :mod:`~apygis.plot.fonts` (DejaVu Sans, measured);
* :mod:`~apygis.plot.hpgl`, :mod:`~apygis.plot.svg`, :mod:`~apygis.plot.pdf`,
  :mod:`~apygis.plot.raster` — the back-ends: each renders a
  :class:`Drawing` to ``bytes`` and decides nothing about the layout (PDF
  and the pin plot through one matplotlib figure, ``_mpl``; ``pdf`` also
  pages plain text);
* :mod:`~apygis.plot.printout` — the APY print-out (legend, symbols by code,
  line points with references, texts) as text.

The renderers return bytes; writing them is the caller's, through the one
atomic write of :func:`apygis.formats._io.atomic_write_many` (as ``apygis
plot`` and ``apygis printout`` do).

Layering: this package imports :mod:`apygis.model`, :mod:`apygis.errors`,
:mod:`apygis.progress` and the file helpers of :mod:`apygis.formats._io`,
nothing else of apygis; :mod:`apygis.model` and :mod:`apygis.orient` do not
import it (``tests/plot/test_layering.py``).

Examples
--------
>>> from apygis.model.map import MapFile
>>> from apygis.plot.drawing import build_drawing
>>> from apygis.plot.svg import drawing_svg
>>> m = MapFile("T1", scale=1000)
>>> _ = m.layer("r").add_line([(0, 0, 0), (100, 0, 0)], code=12)
>>> d = build_drawing(m, date="2024-01-01")
>>> d.paper, d.stats["lines"]
('A4 landscape', 1)
>>> drawing_svg(d)[:5]
b'<?xml'
"""

__all__: list[str] = []
