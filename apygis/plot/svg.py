"""SVG output of a :class:`~apygis.plot.drawing.Drawing`.

One SVG document the size of the paper: ``width`` and ``height`` in mm and
a ``viewBox`` in mm, so one user unit is one paper millimetre. SVG's y axis
points down; paper y (north) points up, so every y is written as
``height - y``. Every element is styled by **presentation attributes**
only (no style sheet that could override them: a class rule ``fill`` would
beat ``fill="none"`` and turn every line into a black blob), and carries
its pen as ``class="pen-N"`` and its role as ``data-role``:

* :class:`~apygis.plot.primitives.PaperLine` -> ``<polyline>`` (a closed
  line repeats its first point at the end), ``fill="none"``, stroked in the
  pen's colour and width, round caps and joins;
* :class:`~apygis.plot.primitives.FilledRects` -> a ``<g>`` of ``<rect>``,
  filled in the pen's colour, not stroked;
* :class:`~apygis.plot.primitives.FilledPolygon` -> ``<polygon>``, filled;
* :class:`~apygis.plot.primitives.PaperText` -> ``<text>`` at the start of
  its baseline in DejaVu Sans (then Verdana, Arial, sans-serif), font size
  = cap height / :data:`~apygis.plot.fonts.CAP_HEIGHT`, blanks kept, turned
  with ``rotate(-angle)``, and ``textLength`` set to its advance width in
  DejaVu Sans, so a viewer that substitutes another font keeps the label
  where it was placed. Text is UTF-8: any script the viewer's fonts cover.
  A label that could not be placed free has a white halo (a white stroke
  painted under its fill: ``paint-order="stroke"``).

Examples
--------
>>> import xml.etree.ElementTree as ET
>>> from apygis.plot.drawing import Drawing
>>> from apygis.plot.primitives import make_text
>>> from apygis.plot.plotdef import PenDef
>>> d = Drawing(210, 297, "A4 portrait", 5000, (0.0, 0.0), (15, 15, 195, 282),
...             {1: PenDef(1, (0, 0, 0), 0.35)})
>>> d.items.append(make_text(1, 20.0, 20.0, 2.5, "A & B"))
>>> root = ET.fromstring(drawing_svg(d))
>>> root.get("width"), root.get("viewBox")
('210mm', '0 0 210 297')
>>> t = root.find("{http://www.w3.org/2000/svg}text")
>>> t.text, t.get("y")
('A & B', '277')
"""

from __future__ import annotations

from xml.sax.saxutils import escape, quoteattr

import numpy as np

from apygis.plot.fonts import CAP_HEIGHT, FONT_FAMILY, text_advance
from apygis.plot.primitives import HALO, FilledPolygon, FilledRects, PaperLine, PaperText

__all__ = ["SVG_NS", "drawing_svg"]

SVG_NS = "http://www.w3.org/2000/svg"
_FAMILY = f"'{FONT_FAMILY}', Verdana, Arial, sans-serif"


def _n(v: float) -> str:
    """A coordinate in mm with at most 3 decimals (micrometres), no trailing zeros."""
    s = f"{v:.3f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def drawing_svg(d) -> bytes:
    """The drawing as an SVG document (UTF-8 bytes)."""
    H = d.height_mm
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>\n',
        f'<svg xmlns="{SVG_NS}" version="1.1" width="{_n(d.width_mm)}mm" '
        f'height="{_n(H)}mm" viewBox="0 0 {_n(d.width_mm)} {_n(H)}">\n',
        f"<title>{escape(f'{d.map_id} 1:{d.scale}')}</title>\n",
        f'<rect data-role="paper" x="0" y="0" width="{_n(d.width_mm)}" height="{_n(H)}" '
        'fill="#ffffff" stroke="none"/>\n',
    ]
    for it in d.items:
        pen = d.pens.get(it.pen)
        colour = pen.hex if pen else "#000000"
        cls = f'class="pen-{it.pen}" data-role={quoteattr(it.role)}'
        if isinstance(it, PaperLine):
            pts = np.vstack([it.points, it.points[:1]]) if it.closed else it.points
            coords = " ".join(f"{_n(x)},{_n(H - y)}" for x, y in pts.tolist())
            width = _n(pen.width_mm) if pen else "0.35"
            out.append(
                f'<polyline {cls} points="{coords}" fill="none" stroke="{colour}" '
                f'stroke-width="{width}" stroke-linecap="round" stroke-linejoin="round"/>\n'
            )
        elif isinstance(it, FilledRects):
            out.append(f'<g {cls} fill="{colour}" stroke="none">')
            for x0, y0, x1, y1 in it.rects.tolist():
                out.append(
                    f'<rect x="{_n(x0)}" y="{_n(H - y1)}" width="{_n(x1 - x0)}" '
                    f'height="{_n(y1 - y0)}"/>'
                )
            out.append("</g>\n")
        elif isinstance(it, FilledPolygon):
            coords = " ".join(f"{_n(x)},{_n(H - y)}" for x, y in it.points.tolist())
            out.append(f'<polygon {cls} points="{coords}" fill="{colour}" stroke="none"/>\n')
        elif isinstance(it, PaperText):
            x, y = _n(it.x), _n(H - it.y)
            turn = f' transform="rotate({_n(-it.angle)} {x} {y})"' if it.angle else ""
            advance = text_advance(it.text, it.height)
            length = (
                f' textLength="{_n(advance)}" lengthAdjust="spacingAndGlyphs"'
                if advance > 0
                else ""
            )
            stroke = (
                f'stroke="#ffffff" stroke-width="{_n(HALO * it.height)}" '
                'stroke-linejoin="round" paint-order="stroke"'
                if it.halo
                else 'stroke="none"'
            )
            out.append(
                f'<text {cls} xml:space="preserve" x="{x}" y="{y}"{turn} '
                f'font-family="{_FAMILY}" font-size="{_n(it.height / CAP_HEIGHT)}" '
                f'fill="{colour}" {stroke}{length}>{escape(it.text)}</text>\n'
            )
    out.append("</svg>\n")
    return "".join(out).encode("utf-8")
