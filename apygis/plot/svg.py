"""SVG output of a :class:`~apygis.plot.drawing.Drawing`.

One SVG document the size of the paper: ``width`` and ``height`` in mm
and a ``viewBox`` in mm, so one user unit is one paper millimetre. SVG's y
axis points down; paper y (north) points up, so every y is written as
``height - y``. Elements, each carrying its pen as ``class="pen-N"`` and its
role as ``data-role``:

* :class:`~apygis.plot.drawing.PaperLine` -> ``<polyline>`` (a closed
  line repeats its first point at the end), stroked in the pen's colour and
  width with round caps and joins, no fill;
* :class:`~apygis.plot.drawing.FilledRects` -> a ``<g>`` of ``<rect>``,
  filled in the pen's colour;
* :class:`~apygis.plot.drawing.PaperText` -> ``<text>`` at the start of
  its baseline, Helvetica (or Arial, or sans-serif), font size = cap height
  / 0.718, blanks kept (``xml:space="preserve"``).

Examples
--------
>>> import xml.etree.ElementTree as ET
>>> from apygis.plot.drawing import Drawing, PaperText
>>> from apygis.plot.plotdef import PenDef
>>> d = Drawing(210, 297, "A4 portrait", 5000, (0.0, 0.0), (15, 15, 195, 282),
...             {1: PenDef(1, (0, 0, 0), 0.35)})
>>> d.items.append(PaperText(1, 20.0, 20.0, 2.5, "A & B"))
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

from apygis.plot.drawing import CAP_HEIGHT, Drawing, FilledRects, PaperLine, PaperText

__all__ = ["SVG_NS", "drawing_svg"]

SVG_NS = "http://www.w3.org/2000/svg"


def _n(v: float) -> str:
    """A coordinate in mm with at most 3 decimals (micrometres), no trailing zeros."""
    s = f"{v:.3f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _xml_text(s: str) -> str:
    # characters XML 1.0 forbids cannot occur (the model refuses control characters)
    return escape(s)


def drawing_svg(d: Drawing) -> bytes:
    """The drawing as an SVG document (UTF-8 bytes)."""
    H = d.height_mm
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>\n',
        f'<svg xmlns="{SVG_NS}" width="{_n(d.width_mm)}mm" '
        f'height="{_n(H)}mm" viewBox="0 0 {_n(d.width_mm)} {_n(H)}">\n',
        f"<title>{_xml_text(f'{d.map_id} 1:{d.scale}')}</title>\n",
        "<style>\n",
    ]
    for p in d.used_pens():
        pen = d.pens.get(p)
        colour, width = (pen.hex, pen.width_mm) if pen else ("#000000", 0.35)
        out.append(f".pen-{p} {{ stroke: {colour}; stroke-width: {_n(width)}; fill: {colour}; }}\n")
    out += [
        "polyline { fill: none; stroke-linecap: round; stroke-linejoin: round; }\n",
        "rect, text { stroke: none; }\n",
        "text { font-family: Helvetica, Arial, sans-serif; }\n",
        "</style>\n",
    ]
    for it in d.items:
        pen = d.pens.get(it.pen)
        colour = pen.hex if pen else "#000000"
        cls = f'class="pen-{it.pen}" data-role={quoteattr(it.role)}'
        if isinstance(it, PaperLine):
            pts = np.vstack([it.points, it.points[:1]]) if it.closed else it.points
            coords = " ".join(f"{_n(x)},{_n(H - y)}" for x, y in pts.tolist())
            # presentation attributes too, for viewers that ignore <style>
            stroke = _n(pen.width_mm) if pen else "0.35"
            out.append(
                f'<polyline {cls} points="{coords}" fill="none" stroke="{colour}" '
                f'stroke-width="{stroke}" stroke-linecap="round" stroke-linejoin="round"/>\n'
            )
        elif isinstance(it, FilledRects):
            out.append(f'<g {cls} fill="{colour}">')
            for x0, y0, x1, y1 in it.rects.tolist():
                out.append(
                    f'<rect x="{_n(x0)}" y="{_n(H - y1)}" width="{_n(x1 - x0)}" '
                    f'height="{_n(y1 - y0)}"/>'
                )
            out.append("</g>\n")
        elif isinstance(it, PaperText):
            out.append(
                f'<text {cls} xml:space="preserve" x="{_n(it.x)}" y="{_n(H - it.y)}" '
                f'font-size="{_n(it.height / CAP_HEIGHT)}" fill="{colour}">'
                f"{_xml_text(it.text)}</text>\n"
            )
    out.append("</svg>\n")
    return "".join(out).encode("utf-8")
