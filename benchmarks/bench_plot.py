"""Time of a big map sheet: layout with label placement, and every output.

The map: a synthetic 1:10000 sheet of 6 x 4 km in LV95 with ``--lines``
meandering lines of 100 points, 4 m apart (paths and outlines some 40 m
across: 200 000 line points by default), ``--spots`` spot heights and
``--texts`` names in several scripts (Latin with accents, Polish, Czech,
Greek, Cyrillic), laid out on its own (A1 at 1:10000).

Figures (seconds, best of ``--repeat``):

* ``layout_s``: :func:`build_drawing` (lines, symbols, the placement of every
  label, grid, legend, title block); ``labels_per_s`` and
  ``labels_overlapping`` (labels that could not be placed free);
* ``hpgl_s``, ``svg_s``, ``pdf_s``: the outputs; ``png_150dpi_s``: the pin plot;
* ``pdf_reportlab_s`` and ``pdf_ratio`` (apygis / reportlab): the same drawing
  written by reportlab (``pip install -e ".[bench]"``), a dedicated PDF
  library that embeds the same TrueType font as a subset; null when it is
  not installed. apygis writes its PDF with matplotlib's backend, which is
  already a dependency and renders the pin plot from the very same figure.

Run: ``python benchmarks/bench_plot.py [--lines N] [--spots N] [--texts N]``
Last line: one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

import apygis
from apygis.plot.drawing import build_drawing
from apygis.plot.fonts import CAP_HEIGHT, font_path
from apygis.plot.hpgl import drawing_hpgl
from apygis.plot.pdf import drawing_pdf
from apygis.plot.primitives import FilledPolygon, FilledRects, PaperLine, PaperText
from apygis.plot.raster import drawing_png
from apygis.plot.svg import drawing_svg

E0, N0 = 2_600_000.0, 1_200_000.0
NAMES = ["Zürich", "Łódź", "Plzeň", "Ελλάδα", "Москва", "Dorfbach", "Hauptstrasse", "Oberdorf"]


def make_map(lines: int, spots: int, texts: int, seed: int = 1) -> apygis.MapFile:
    rng = np.random.default_rng(seed)
    m = apygis.MapFile("BENCH", scale=10000, crs="EPSG:2056")
    lay = {ext: m.layer(ext) for ext in "hr"}
    for k in range(lines):
        start = rng.uniform((E0, N0), (E0 + 6000, N0 + 4000))
        steps = np.cumsum(rng.normal(0, 4, (100, 2)), axis=0)
        pts = np.clip(start + steps, (E0, N0), (E0 + 6000, N0 + 4000))
        lay["hr"[k % 2]].add_line([(float(x), float(y), 400.0) for x, y in pts], code=11 + k % 3)
    e = m.layer("e")
    for x, y in rng.uniform((E0, N0), (E0 + 6000, N0 + 4000), (spots, 2)):
        e.add_symbol(float(x), float(y), float(rng.uniform(400, 500)), code=0)
    t = m.layer("t")
    for i, (x, y) in enumerate(rng.uniform((E0, N0), (E0 + 6000, N0 + 4000), (texts, 2))):
        t.add_text(float(x), float(y), 0.0, f"{NAMES[i % len(NAMES)]} {i}")
    return m


def reportlab_pdf(d) -> bytes:
    """The same drawing written by reportlab (the peer), item for item, DejaVu Sans embedded."""
    import io

    from reportlab.pdfbase import pdfmetrics
    from reportlab.pdfbase.ttfonts import TTFont
    from reportlab.pdfgen import canvas

    pdfmetrics.registerFont(TTFont("DejaVuSans", font_path()))
    pt = 72 / 25.4
    buf = io.BytesIO()
    c = canvas.Canvas(buf, pagesize=(d.width_mm * pt, d.height_mm * pt), invariant=1)
    c.scale(pt, pt)
    c.setLineCap(1)
    c.setLineJoin(1)
    for it in d.items:
        pen = d.pens.get(it.pen)
        rgb = [v / 255 for v in (pen.colour if pen else (0, 0, 0))]
        if isinstance(it, PaperLine):
            c.setStrokeColorRGB(*rgb)
            c.setLineWidth(pen.width_mm if pen else 0.35)
            p = c.beginPath()
            p.moveTo(*it.points[0])
            for x, y in it.points[1:]:
                p.lineTo(x, y)
            if it.closed:
                p.close()
            c.drawPath(p, stroke=1, fill=0)
        elif isinstance(it, FilledRects):
            c.setFillColorRGB(*rgb)
            for x0, y0, x1, y1 in it.rects.tolist():
                c.rect(x0, y0, x1 - x0, y1 - y0, stroke=0, fill=1)
        elif isinstance(it, FilledPolygon):
            c.setFillColorRGB(*rgb)
            p = c.beginPath()
            p.moveTo(*it.points[0])
            for x, y in it.points[1:]:
                p.lineTo(x, y)
            p.close()
            c.drawPath(p, stroke=0, fill=1)
        elif isinstance(it, PaperText):
            c.setFillColorRGB(*rgb)
            c.saveState()
            c.translate(it.x, it.y)
            c.rotate(it.angle)
            c.setFont("DejaVuSans", it.height / CAP_HEIGHT)
            c.drawString(0, 0, it.text)
            c.restoreState()
    c.save()
    return buf.getvalue()


def best(f, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=2000)
    ap.add_argument("--spots", type=int, default=1500)
    ap.add_argument("--texts", type=int, default=500)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()

    m = make_map(args.lines, args.spots, args.texts)
    npts = sum(len(lay.line_points) for lay in m)
    layout_s, d = best(lambda: build_drawing(m, date="2024-01-01"), args.repeat)
    labels = d.stats["labels"]
    print(f"map: {npts} line points, {args.spots} spot heights, {args.texts} texts")
    print(f"sheet: {d.summary()}")
    print(f"layout (with {labels} labels placed): {layout_s:.2f} s")
    hpgl_s, _ = best(lambda: drawing_hpgl(d), args.repeat)
    svg_s, _ = best(lambda: drawing_svg(d), args.repeat)
    pdf_s, pdf = best(lambda: drawing_pdf(d), args.repeat)
    png_s, _ = best(lambda: drawing_png(d, dpi=150), 1)
    print(
        f"HP-GL {hpgl_s:.2f} s, SVG {svg_s:.2f} s, PDF {pdf_s:.2f} s ({len(pdf) / 1e6:.1f} MB), "
        f"PNG at 150 dpi {png_s:.2f} s"
    )
    try:
        import reportlab  # noqa: F401
    except ImportError:
        peer_s = None
        print("reportlab is not installed (pip install -e '.[bench]'): no peer for the PDF")
    else:
        peer_s, peer = best(lambda: reportlab_pdf(d), args.repeat)
        print(
            f"PDF by reportlab (the peer): {peer_s:.2f} s ({len(peer) / 1e6:.1f} MB); "
            f"apygis/reportlab = {pdf_s / peer_s:.2f}"
        )
    print(
        json.dumps(
            {
                "machine": platform.machine(),
                "line_points": npts,
                "labels": labels,
                "labels_overlapping": d.stats["labels_overlapping"],
                "layout_s": round(layout_s, 3),
                "labels_per_s": round(labels / layout_s, 1),
                "hpgl_s": round(hpgl_s, 3),
                "svg_s": round(svg_s, 3),
                "pdf_s": round(pdf_s, 3),
                "pdf_mb": round(len(pdf) / 1e6, 2),
                "png_150dpi_s": round(png_s, 3),
                "pdf_reportlab_s": None if peer_s is None else round(peer_s, 3),
                "pdf_ratio": None if peer_s is None else round(pdf_s / peer_s, 2),
            }
        )
    )


if __name__ == "__main__":
    main()
