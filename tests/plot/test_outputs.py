"""The outputs: HP-GL (both dialects), SVG, PDF, the raster pin plot, the text print-out.

Geometry is compared with the model's coordinates at scale; pictures are compared with
the pin plot of the same drawing, as rendered by other programs (rsvg-convert, poppler's
pdftoppm) and by the small HP-GL interpreter of ``tests/plot/hpgl_view.py``.
"""

from __future__ import annotations

import io
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import apygis
from apygis.errors import FormatError
from apygis.model.polylines import export_lines
from apygis.model.symbols import default_library
from apygis.plot.drawing import build_drawing
from apygis.plot.hpgl import drawing_hpgl, hatch_polygon, hatch_strokes, is_plotter_text
from apygis.plot.pdf import A4_PT, drawing_pdf, text_page_capacity, text_pages, text_pages_pdf
from apygis.plot.plotdef import PlotterDef, read_plotdef
from apygis.plot.primitives import FilledRects, PaperText
from apygis.plot.printout import printout_text
from apygis.plot.raster import MAX_PIXELS, drawing_png, drawing_rgba, drawing_tiff, raster_size
from apygis.plot.svg import SVG_NS, drawing_svg
from tests.plot import hpgl_view
from tests.plot.helpers import (
    PLOTTER_DEF,
    UNITS,
    expected_counts,
    ink,
    read_png,
    run_tool,
    similar,
)

LIB = default_library()
SCRIPTS = ("Zürich", "Łódź", "Ελλάδα", "Plzeň")


@pytest.fixture(scope="module", params=["plotter-def", "default"])
def sheet(request, tmp_path_factory):
    """The sample sheet laid out with samples/PLOTTER.DEF and without: map, drawing, definition."""
    from tests.conftest import _load_make_samples

    out = tmp_path_factory.mktemp("sheet")
    _load_make_samples().make(out)
    m = apygis.read(out / "ZH1091")
    pdef = read_plotdef(PLOTTER_DEF) if request.param == "plotter-def" else PlotterDef.default()
    d = build_drawing(m, pdef, LIB, date="2024-01-01")
    return m, d, pdef


@pytest.fixture(scope="module")
def scripts_map():
    m = apygis.MapFile("EU", scale=25000, crs="EPSG:3035")
    r = m.layer("r")
    r.add_line([(4200000, 3000000, 0), (4210000, 3004000, 0)], code=11)
    for i, t in enumerate(SCRIPTS):
        r.add_text(4201000 + 2000 * i, 3001500 + 500 * i, 0, t)
    return m


def paper_mm(d, x, y):
    """Where the model's ground point (x, y) belongs: 1:5000 from the window's corner.

    The window's lower-left is the neat line's (with samples/PLOTTER.DEF the sheet corner
    2683000, 1247000: tests/plot/test_sheet.py).
    """
    f = 1000.0 / 5000
    return (
        d.frame[0] + (np.asarray(x) - d.window[0]) * f,
        d.frame[1] + (np.asarray(y) - d.window[1]) * f,
    )


# --------------------------------------------------------------------------- HP-GL


def test_hpgl1_is_plain_hpgl(sheet):
    _, d, _ = sheet
    data = drawing_hpgl(d)
    plot = hpgl_view.interpret(data, version=1)  # refuses PW, PC, WU ... of HP-GL/2
    ops = [op for op, _ in plot.instructions]
    assert ops[:3] == ["IN", "PA", "DT"]
    assert ops[-2:] == ["PU", "SP"]
    assert "PW" not in ops
    sp = [int(a) for op, a in plot.instructions if op == "SP"]
    assert sp == [*sorted(set(sp) - {0}), 0]  # each pen once, ascending, then put away
    W, H = 594 * UNITS, 420 * UNITS
    for _, pts in plot.strokes:
        assert (pts[:, 0] >= 0).all()
        assert (pts[:, 0] <= W).all()
        assert (pts[:, 1] >= 0).all()
        assert (pts[:, 1] <= H).all()


def test_hpgl2_sets_widths_and_colours(sheet):
    _, d, _ = sheet
    plot = hpgl_view.interpret(drawing_hpgl(d, version=2), version=2)
    used = d.used_pens()
    assert plot.widths_mm == {p: d.pens[p].width_mm for p in used}
    assert plot.colours == {p: d.pens[p].colour for p in used}
    with pytest.raises(AssertionError, match="is not HP-GL/1"):
        hpgl_view.interpret(drawing_hpgl(d, version=2), version=1)
    with pytest.raises(ValueError, match="version must be 1 or 2"):
        drawing_hpgl(d, version=3)


def test_hpgl_lines_are_the_model_at_scale(sheet):
    m, d, pdef = sheet
    plot = hpgl_view.interpret(drawing_hpgl(d))
    strokes = {tuple(map(tuple, pts.tolist())): pen for pen, pts in plot.strokes}
    n = 0
    for ext in "hr":
        for pl in export_lines(m.layers[ext]):
            x, y = paper_mm(d, pl.coords[:, 0], pl.coords[:, 1])
            pts = [(round(a * UNITS), round(b * UNITS)) for a, b in zip(x, y, strict=True)]
            if pl.closed:
                pts.append(pts[0])
            got = strokes.get(tuple(pts))
            if got is None:  # rounding of the sheet's corner: allow one plotter unit
                near = [
                    (k, p)
                    for k, p in strokes.items()
                    if len(k) == len(pts) and np.abs(np.array(k) - np.array(pts)).max() <= 1
                ]
                assert near, (ext, pl.code)
                got = near[0][1]
            assert got == pdef.pen_for(ext, "lines", int(pl.code))
            n += 1
    assert n == 18


def test_hpgl_labels_and_symbols(sheet):
    m, d, _ = sheet
    report = {}
    plot = hpgl_view.interpret(drawing_hpgl(d, report=report))
    text_items = [t for t in d.items if isinstance(t, PaperText) and t.text.strip()]
    assert report["labels"] == len(text_items)
    assert len(plot.labels) + report["outlined"] == len(text_items)
    by_text = {lab.text: lab for lab in plot.labels}
    for t in text_items:
        if not is_plotter_text(t.text):
            continue
        lab = by_text[t.text]
        if lab.x == round(t.x * UNITS) and lab.y == round(t.y * UNITS):
            # the stick font set to the measured length: (1.5 n - 0.5) character widths
            n = len(t.text)
            length = (1.5 * n - 0.5) * lab.width_cm * 10
            if 0.25 * t.height < t.width / (1.5 * n - 0.5) < 1.5 * t.height:
                assert length == pytest.approx(t.width, rel=0.002)
            assert lab.height_cm * 10 == pytest.approx(t.height)
    placed = next(t for t in text_items if t.text == "Kirchweg")
    assert (by_text["Kirchweg"].x, by_text["Kirchweg"].y) == (
        round(placed.x * UNITS),
        round(placed.y * UNITS),
    )
    # grid labels on the left and right are turned to read upward
    turned = [lab for lab in plot.labels if lab.direction != (1.0, 0.0)]
    assert turned
    assert all(lab.direction == pytest.approx((0.0, 1.0)) for lab in turned)
    # symbols: one hatch stroke per run of cells (every pen is at least a cell wide)
    exp = expected_counts(m)
    symbol_strokes = sum(
        len(hatch_strokes(it.rects, d.pens[it.pen].width_mm))
        for it in d.items
        if isinstance(it, FilledRects) and it.role == "symbol"
    )
    assert symbol_strokes == exp["strokes"]


def test_hpgl_labels_outside_ascii_are_outlined(scripts_map):
    d = build_drawing(scripts_map, library=LIB)
    report = {}
    data = drawing_hpgl(d, report=report)
    assert report["outlined"] == len(SCRIPTS)
    for word in SCRIPTS:
        assert word.encode("utf-8") not in data
    plot = hpgl_view.interpret(data)
    assert not any(lab.text in SCRIPTS for lab in plot.labels)
    # the outlines lie where the layout put the text
    for t in (it for it in d.items if isinstance(it, PaperText) and it.text in SCRIPTS):
        x0, y0 = round(t.x * UNITS), round((t.y - 1.0) * UNITS)
        x1, y1 = round((t.x + t.width) * UNITS), round((t.y + t.height * 1.4) * UNITS)
        inside = [
            pts
            for _, pts in plot.strokes
            if (pts[:, 0] >= x0 - 4).all()
            and (pts[:, 0] <= x1 + 4).all()
            and (pts[:, 1] >= y0).all()
            and (pts[:, 1] <= y1).all()
        ]
        assert len(inside) >= len(t.text.replace(" ", "")), t.text


def test_hatching():
    assert len(hatch_strokes([(0, 0, 1, 0.2)], 0.35)) == 1
    st = hatch_strokes([(0, 0, 0.2, 2.0)], 0.25)  # vertical run
    assert st.tolist() == [[[0.1, 0.125], [0.1, 1.875]]]
    st = hatch_strokes([(0, 0, 4, 1)], 0.25)
    assert st[:, 0, 1].tolist() == pytest.approx([0.125, 0.375, 0.625, 0.875])
    strokes = hatch_polygon([(0, 0), (4, 0), (2, 4)], 0.25)
    ys = sorted({round(float(s[0][1]), 6) for s in strokes[1:]})
    assert len(ys) >= 14
    assert max(np.diff(ys)) <= 0.25 + 1e-9


def test_hpgl_renders_as_the_pin_plot(sheet, tmp_path):
    """The HP-GL, drawn by the test interpreter, shows the same sheet as the pin plot."""
    _, d, _ = sheet
    plot = hpgl_view.interpret(drawing_hpgl(d))
    widths = {p: pen.width_mm for p, pen in d.pens.items()}
    picture = hpgl_view.render(plot, d.width_mm, d.height_mm, dpi=100, pen_widths=widths)
    pin = drawing_rgba(d, dpi=100)
    import cv2

    cv2.imwrite(str(tmp_path / "hpgl.png"), picture)
    a, b = ink(picture), ink(pin)
    assert a.shape == b.shape[:2]
    assert similar(a, b, tolerance_px=3) > 0.85


# --------------------------------------------------------------------------- SVG


def _svg(d):
    return ET.fromstring(drawing_svg(d))


def test_svg_lines_are_the_model_at_scale(sheet):
    m, d, _ = sheet
    root = _svg(d)
    ns = {"s": SVG_NS}
    assert (root.get("width"), root.get("height"), root.get("viewBox")) == (
        "594mm",
        "420mm",
        "0 0 594 420",
    )
    polys = root.findall("s:polyline[@data-role='line']", ns)
    got = {p.get("points") for p in polys}
    n = 0
    for ext in "hr":
        for pl in export_lines(m.layers[ext]):
            x, y = paper_mm(d, pl.coords[:, 0], pl.coords[:, 1])
            pts = np.column_stack([x, 420.0 - y])
            if pl.closed:
                pts = np.vstack([pts, pts[:1]])
            match = [
                p
                for p in got
                if len(p.split()) == len(pts)
                and np.abs(
                    np.array([list(map(float, q.split(","))) for q in p.split()]) - pts
                ).max()
                < 1e-3
            ]
            assert len(match) == 1, (ext, pl.code)
            n += 1
    assert n == 18 == len(polys)


def test_svg_is_styled_so_that_lines_are_not_filled(sheet):
    _, d, _ = sheet
    data = drawing_svg(d)
    root = ET.fromstring(data)
    ns = {"s": SVG_NS}
    assert root.find("s:style", ns) is None
    assert b"<style" not in data
    for p in root.iter(f"{{{SVG_NS}}}polyline"):
        assert p.get("fill") == "none"
        assert p.get("style") is None
    for g in root.findall("s:g", ns):
        assert g.get("stroke") == "none"
        assert g.get("fill", "").startswith("#")
    exp = expected_counts(sheet[0])
    assert len(root.findall("s:g[@data-role='symbol']", ns)) == exp["symbols"]
    assert len(root.findall("s:g[@data-role='symbol']/s:rect", ns)) == exp["strokes"]
    texts = root.findall("s:text", ns)
    items = [t for t in d.items if isinstance(t, PaperText)]
    assert [t.text for t in texts] == [t.text for t in items]
    for el, t in zip(texts, items, strict=True):
        assert float(el.get("x")) == pytest.approx(t.x, abs=1e-3)
        assert float(el.get("y")) == pytest.approx(420 - t.y, abs=1e-3)
        assert ("rotate(-90" in (el.get("transform") or "")) == (t.angle == 90)


def test_svg_keeps_every_script(scripts_map):
    d = build_drawing(scripts_map, library=LIB)
    root = _svg(d)
    got = {t.text for t in root.iter(f"{{{SVG_NS}}}text")}
    assert set(SCRIPTS) <= got
    m = apygis.MapFile("X", scale=1000)
    m.layer("r").add_text(10, 10, 0, 'A<B & "C" $x$')
    got = {t.text for t in _svg(build_drawing(m, library=LIB)).iter(f"{{{SVG_NS}}}text")}
    assert 'A<B & "C" $x$' in got


@pytest.mark.rsvg
def test_rsvg_renders_the_svg_as_drawn(sheet, tmp_path):
    _, d, _ = sheet
    svg = tmp_path / "sheet.svg"
    svg.write_bytes(drawing_svg(d))
    png = tmp_path / "sheet-svg.png"
    w, h = raster_size(d.width_mm, d.height_mm, 100)
    run_tool("rsvg-convert", "-w", str(w), "-h", str(h), "-b", "white", str(svg), "-o", str(png))
    got = ink(read_png(png))
    pin = ink(drawing_rgba(d, dpi=100))
    # not black blobs: about as much ink as the pin plot, in the same places
    assert 0.7 < got.sum() / pin.sum() < 1.4
    assert similar(got, pin, tolerance_px=2) > 0.9


@pytest.mark.rsvg
def test_rsvg_draws_every_script(scripts_map, tmp_path):
    d = build_drawing(scripts_map, library=LIB)
    svg = tmp_path / "eu.svg"
    svg.write_bytes(drawing_svg(d))
    png = tmp_path / "eu.png"
    w, h = raster_size(d.width_mm, d.height_mm, 150)
    run_tool("rsvg-convert", "-w", str(w), "-h", str(h), "-b", "white", str(svg), "-o", str(png))
    got = ink(read_png(png))
    pin = ink(drawing_rgba(d, dpi=150))
    k = 150 / 25.4
    for t in (it for it in d.items if isinstance(it, PaperText) and it.text in SCRIPTS):
        r0, r1 = int(h - (t.y + t.height) * k), int(h - (t.y - 1.0) * k)
        c0, c1 = int(t.x * k), int((t.x + t.width) * k) + 1
        a, b = got[r0:r1, c0:c1], pin[r0:r1, c0:c1]
        assert a.sum() > 20, t.text  # drawn, not tofu-free blank
        assert similar(a, b, tolerance_px=2) > 0.8, t.text


# --------------------------------------------------------------------------- PDF


def test_pdf_of_the_sample(sheet):
    _, d, _ = sheet
    pdf = drawing_pdf(d)
    assert pdf.startswith(b"%PDF-")
    assert pdf.rstrip().endswith(b"%%EOF")
    assert len(re.findall(rb"/Type\s*/Page\b", pdf)) == 1
    box = re.search(rb"/MediaBox\s*\[\s*([^\]]*)\]", pdf).group(1).split()
    assert [float(v) for v in box] == pytest.approx([0, 0, 594 * 72 / 25.4, 420 * 72 / 25.4])
    assert b"/FontFile2" in pdf
    assert b"DejaVuSans" in pdf
    assert b"/BaseFont /Helvetica" not in pdf
    assert b"ZH1091 1:5000" in pdf  # the title
    assert drawing_pdf(d) == pdf  # no dates: the same drawing, the same bytes


@pytest.mark.poppler
def test_pdftotext_reads_every_text(sheet, tmp_path):
    m, d, _ = sheet
    f = tmp_path / "sheet.pdf"
    f.write_bytes(drawing_pdf(d))
    text = run_tool("pdftotext", "-raw", str(f), "-").stdout.decode("utf-8")
    for t in (it.text for it in d.items if isinstance(it, PaperText)):
        assert t in text, t
    for r in m.layers["r"].texts:
        assert str(r["text"]) in text


@pytest.mark.poppler
def test_pdf_keeps_every_script(scripts_map, tmp_path):
    d = build_drawing(scripts_map, library=LIB)
    f = tmp_path / "eu.pdf"
    f.write_bytes(drawing_pdf(d))
    text = run_tool("pdftotext", "-raw", str(f), "-").stdout.decode("utf-8")
    for word in SCRIPTS:
        assert word in text, word
    fonts = run_tool("pdffonts", str(f)).stdout.decode()
    assert "DejaVuSans" in fonts
    assert " yes yes yes " in fonts


@pytest.mark.poppler
def test_pdftoppm_renders_the_pdf_as_drawn(sheet, tmp_path):
    _, d, _ = sheet
    f = tmp_path / "sheet.pdf"
    f.write_bytes(drawing_pdf(d))
    run_tool("pdftoppm", "-r", "100", "-png", "-singlefile", str(f), str(tmp_path / "p"))
    got = ink(read_png(tmp_path / "p.png"))
    pin = ink(drawing_rgba(d, dpi=100))
    h = min(got.shape[0], pin.shape[0])
    w = min(got.shape[1], pin.shape[1])
    assert abs(got.shape[0] - pin.shape[0]) <= 1
    assert abs(got.shape[1] - pin.shape[1]) <= 1
    assert similar(got[:h, :w], pin[:h, :w], tolerance_px=2) > 0.9


def test_texts_the_font_lacks_are_counted(caplog):
    m = apygis.MapFile("CJK", scale=1000)
    m.layer("r").add_text(10, 10, 0, "東京 Tokyo")
    d = build_drawing(m, library=LIB)
    assert d.stats["texts_missing_glyphs"] == 1
    assert "1 text with characters the font lacks" in d.summary()
    assert "lacks '東京'" in caplog.text


# --------------------------------------------------------------------------- the pin plot


def test_png_pin_plot(sheet):
    m, d, _ = sheet
    data = drawing_png(d, dpi=120)
    import cv2

    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    w, h = raster_size(d.width_mm, d.height_mm, 120)
    assert img.shape[:2] == (h, w)
    # the resolution is recorded: pHYs in dots per metre
    phys = data[data.index(b"pHYs") + 4 : data.index(b"pHYs") + 12]
    assert int.from_bytes(phys[:4], "big") == round(120 / 0.0254)
    # antialiased: grey levels between ink and paper
    assert len(np.unique(img)) > 20
    # a building corner of the model lies on ink
    b = next(pl for pl in export_lines(m.layers["r"]) if pl.code == 21)
    x, y = paper_mm(d, b.coords[0, 0], b.coords[0, 1])
    k = 120 / 25.4
    r, c = round(h - y * k), round(x * k)
    assert ink(img)[r - 1 : r + 2, c - 1 : c + 2].any()


def test_tiff_pin_plot_is_georeferenced(sheet):
    from rasterio.io import MemoryFile

    m, d, _ = sheet
    data = drawing_tiff(d, dpi=100)
    with MemoryFile(data) as mem, mem.open() as ds:
        assert ds.crs.to_epsg() == 2056
        assert ds.count == 3
        assert ds.dtypes[0] == "uint8"
        assert (ds.width, ds.height) == raster_size(d.width_mm, d.height_mm, 100)
        rgb = ds.read()
        # a trig point of the control layer: its pixel, by the file's transform, is inked
        s = m.layers["c"].symbols[0]
        row, col = ds.index(float(s["x"]), float(s["y"]))
        assert (rgb[:, row - 2 : row + 3, col - 2 : col + 3].min(axis=0) < 200).any()
        # and the sheet's corner is the neat line's corner
        row, col = ds.index(d.window[0], d.window[1])
        assert (rgb[:, row - 1 : row + 2, col - 1 : col + 2].min(axis=0) < 120).any()


def test_a_pin_plot_too_large_is_refused_before_drawing(sheet):
    _, d, _ = sheet
    w, h = raster_size(d.width_mm, d.height_mm, 2400)
    assert w * h > MAX_PIXELS
    with pytest.raises(FormatError, match=r"at 2400 dpi would be .*use \d+ dpi or less"):
        drawing_png(d, dpi=2400)
    with pytest.raises(FormatError, match="positive dpi"):
        drawing_png(d, dpi=0)


# --------------------------------------------------------------------------- the print-out


def test_text_pages_pdf_of_the_printout(sample_map):
    text = printout_text(sample_map, LIB)
    lines = text.splitlines()
    assert text_page_capacity() == (94, 68)
    assert max(map(len, lines)) <= 94
    n = len(text_pages(text))
    pdf = text_pages_pdf(text, title="APY print-out ZH1091")
    assert len(re.findall(rb"/Type\s*/Page\b", pdf)) == n == -(-len(lines) // 68)
    assert re.search(rb"/MediaBox\s*\[\s*0 0 595\.27", pdf)
    assert abs(A4_PT[0] - 595.2756) < 1e-3


@pytest.mark.poppler
def test_printout_pdf_text_and_legend(sample_map, tmp_path):
    m = sample_map.copy()
    m.layer("r").add_text(2684000.0, 1248000.0, 450.0, "Łódź Ελλάδα")
    text = printout_text(m, LIB)
    f = tmp_path / "p.pdf"
    f.write_bytes(text_pages_pdf(text, title="APY print-out ZH1091"))
    got = run_tool("pdftotext", "-layout", str(f), "-").stdout.decode("utf-8")
    assert "SYMBOL LEGEND" in got
    assert "Łódź Ελλάδα" in got
    want = [ln.split() for ln in text.splitlines() if ln.strip()]
    have = [ln.split() for ln in got.splitlines() if ln.strip()]
    have = [h for h in have if not (h[:2] == ["APY", "print-out"] or h[:1] == ["page"])]
    assert have == want


def test_text_pages_wrap_and_form_feed():
    long = "x" * 200
    pages = text_pages(f"{long}\nshort\n\fnext page\n")
    assert pages == [["x" * 94, "x" * 94, "x" * 12, "short"], ["next page"]]
    pdf = text_pages_pdf("")
    assert len(re.findall(rb"/Type\s*/Page\b", pdf)) == 1
    assert io.BytesIO(pdf).read(5) == b"%PDF-"
