"""Plotting: PLOTTER.DEF, the paper layout, and the HP-GL, SVG and PDF back-ends.

Expected counts and coordinates are computed here from the map and the
symbol bitmaps by plain loops, not by calling the layout code again.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
import zlib

import numpy as np
import pytest

import apygis
from apygis.errors import FormatError, RecordError
from apygis.model.polylines import export_lines
from apygis.model.symbols import default_library
from apygis.plot.drawing import (
    FilledRects,
    PaperLine,
    PaperText,
    build_drawing,
    clip_polyline,
    symbol_runs,
)
from apygis.plot.hpgl import ascii_label, drawing_hpgl, hatch_strokes
from apygis.plot.pdf import (
    A4_PT,
    drawing_pdf,
    pdf_string,
    text_page_capacity,
    text_pages,
    text_pages_pdf,
)
from apygis.plot.plotdef import (
    PaperSpec,
    PenRule,
    PlotterDef,
    parse_plotdef,
    read_plotdef,
)
from apygis.plot.printout import printout_text
from apygis.plot.svg import SVG_NS, drawing_svg
from tests.conftest import SAMPLES

PLOTTER_DEF = SAMPLES / "PLOTTER.DEF"
UNITS = 40  # plotter units per mm

# --------------------------------------------------------------------------- helpers


def count_runs(bitmap) -> int:
    """Strokes for a bitmap by the documented rule, counted cell by cell."""
    painted = {(r, c) for r in range(15) for c in range(15) if bitmap[r][c]}
    n = 0
    in_hrun = set()
    for r in range(15):
        for c in range(15):
            starts = (r, c) in painted and (r, c - 1) not in painted
            if starts and (r, c + 1) in painted:
                n += 1
                k = c
                while (r, k) in painted:
                    in_hrun.add((r, k))
                    k += 1
    rest = painted - in_hrun
    n += sum(1 for (r, c) in rest if (r - 1, c) not in rest)
    return n


def parse_hpgl(data: bytes) -> list[tuple[str, str]]:
    """(mnemonic, parameters) of every instruction; a label's text as its parameter."""
    text = data.decode("ascii")
    out = []
    i = 0
    while i < len(text):
        if text[i] in " \n\r;":
            i += 1
            continue
        op = text[i : i + 2]
        assert re.fullmatch("[A-Z]{2}", op), f"bad instruction at {i}: {text[i : i + 20]!r}"
        if op == "LB":
            end = text.index("\x03", i)
            out.append((op, text[i + 2 : end]))
            i = end + 1
        elif op == "DT":
            out.append((op, text[i + 2]))
            i += 3
        else:
            end = text.index(";", i)
            out.append((op, text[i + 2 : end]))
            i = end + 1
    return out


def hpgl_strokes(instr) -> list[tuple[int, list[tuple[int, int]]]]:
    """(pen, points) of every PU...PD polyline; checks all points for the caller."""
    pen, pos, out = 0, None, []
    for op, args in instr:
        if op == "SP":
            pen = int(args)
        elif op == "PU":
            pos = tuple(int(v) for v in args.split(",")) if args else pos
        elif op == "PD":
            vals = [int(v) for v in args.split(",")]
            pts = [pos, *zip(vals[::2], vals[1::2], strict=True)]
            out.append((pen, pts))
            pos = pts[-1]
    return out


def pdf_objects(pdf: bytes) -> dict[int, bytes]:
    """Check header, xref and trailer; return each object's body by number."""
    assert pdf.startswith(b"%PDF-1.4\n")
    assert pdf.rstrip().endswith(b"%%EOF")
    m = re.search(rb"startxref\n(\d+)\n%%EOF\n$", pdf)
    assert m
    xref = int(m.group(1))
    assert pdf[xref:].startswith(b"xref\n")
    head = re.match(rb"xref\n0 (\d+)\n", pdf[xref:])
    n = int(head.group(1))
    table = pdf[xref + head.end() :]
    entries = [table[20 * k : 20 * (k + 1)] for k in range(n)]
    assert entries[0] == b"0000000000 65535 f \n"
    trailer = table[20 * n :]
    assert trailer.startswith(b"trailer\n")
    assert re.search(rb"/Size %d\b" % n, trailer)
    objs = {}
    for k in range(1, n):
        e = entries[k]
        assert re.fullmatch(rb"\d{10} 00000 n \n", e), e
        off = int(e[:10])
        assert pdf[off:].startswith(b"%d 0 obj\n" % k), (k, pdf[off : off + 20])
        end = pdf.index(b"\nendobj\n", off)
        objs[k] = pdf[off + len(b"%d 0 obj\n" % k) : end]
    return objs


def pdf_stream(body: bytes) -> bytes:
    m = re.match(rb"<< /Length (\d+)( /Filter /FlateDecode)? >>\nstream\n", body)
    assert m, body[:80]
    length = int(m.group(1))
    data = body[m.end() : m.end() + length]
    assert body[m.end() + length :] == b"\nendstream"
    return zlib.decompress(data) if m.group(2) else data


def pdf_pages(objs) -> list[tuple[bytes, bytes]]:
    """(page dictionary, decoded content) of every page, in page-tree order."""
    root = next(b for b in objs.values() if b.startswith(b"<< /Type /Catalog"))
    tree = objs[int(re.search(rb"/Pages (\d+) 0 R", root).group(1))]
    kids = [
        int(k) for k in re.findall(rb"(\d+) 0 R", re.search(rb"/Kids \[(.*?)\]", tree).group(1))
    ]
    assert int(re.search(rb"/Count (\d+)", tree).group(1)) == len(kids)
    out = []
    for k in kids:
        page = objs[k]
        assert page.startswith(b"<< /Type /Page ")
        content = objs[int(re.search(rb"/Contents (\d+) 0 R", page).group(1))]
        out.append((page, pdf_stream(content)))
    return out


_PDF_STRING = re.compile(rb"\((?:\\.|[^\\)])*\)")


def pdf_ops(content: bytes) -> dict[str, int]:
    """How often each operator occurs in a content stream (strings blanked)."""
    counts: dict[str, int] = {}
    for tok in _PDF_STRING.sub(b"()", content).split():
        t = tok.decode("ascii")
        if re.fullmatch(r"[A-Za-z*']+", t):
            counts[t] = counts.get(t, 0) + 1
    return counts


def pdf_unescape(s: bytes) -> str:
    body = s[1:-1]
    out = bytearray()
    i = 0
    while i < len(body):
        if body[i] == 0x5C:
            nxt = body[i + 1 : i + 4]
            if re.fullmatch(rb"[0-7]{3}", nxt):
                out.append(int(nxt, 8))
                i += 4
            else:
                out.append(body[i + 1])
                i += 2
        else:
            out.append(body[i])
            i += 1
    return out.decode("cp1252")


def expected_counts(m, layers=None):
    """Lines, symbols, spot heights, texts and symbol strokes of a map, by plain loops."""
    lib = default_library()
    exts = sorted(m.layers) if layers is None else layers
    lines = sum(len(export_lines(m.layers[e])) for e in exts)
    sym = [s for e in exts for s in m.layers[e].symbols]
    texts = sum(len(m.layers[e].texts) for e in exts)
    spots = sum(1 for s in sym if s["code"] == 0)
    strokes = sum(count_runs(lib[int(s["code"])].bitmap) for s in sym)
    return {"lines": lines, "symbols": len(sym), "spots": spots, "texts": texts, "strokes": strokes}


@pytest.fixture
def plotdef():
    return read_plotdef(PLOTTER_DEF)


@pytest.fixture
def drawing(sample_map, plotdef):
    return build_drawing(sample_map, plotdef, default_library())


# --------------------------------------------------------------------------- PLOTTER.DEF


def test_sample_plotter_def_is_read(plotdef):
    assert plotdef.paper == PaperSpec("A2", "landscape")
    assert plotdef.paper.size_mm() == (594.0, 420.0)
    assert plotdef.scale == 5000
    assert plotdef.origin == (2682925.0, 1246925.0)
    assert plotdef.margins_mm == (15.0, 15.0, 15.0, 15.0)
    assert plotdef.symbol_size_mm == 3.0
    assert plotdef.text_height_mm == 2.5
    assert plotdef.pens[2].hex == "#0070c0"
    assert plotdef.pens[3].width_mm == 0.5
    assert plotdef.pens[4].colour == (150, 80, 20)
    assert plotdef.pen_for("r", "lines", 11) == 3
    assert plotdef.pen_for("r", "symbols", 11) == 1  # the rule is for lines only
    assert plotdef.pen_for("h", "lines", 31) == 6
    assert plotdef.pen_for("h", "lines", 32) == 2
    assert plotdef.pen_for("e", "symbols", 0) == 4
    assert plotdef.pen_for("x", "texts") == 1


def test_empty_file_is_the_default():
    assert parse_plotdef("") == PlotterDef.default()
    assert parse_plotdef("; only a comment\n\n   # another\n") == PlotterDef.default()


def test_values_and_comments():
    pdef = parse_plotdef(
        "\ufeffPAPER 600 x 400 mm   # custom\n"
        "scale 1:2500 ; a comment\n"
        "margin 10 20 30 40\n"
        "pendef 7 #A0b0C0 0.13   ; hex colour is no comment\n"
        "pen * 21 7 lines\n"
        "Title Off\n"
        "frame no\n"
        "height-decimals 2\r\n"
    )
    assert pdef.paper.size_mm() == (600.0, 400.0)
    assert pdef.paper.label() == "600 x 400 mm"
    assert pdef.scale == 2500
    assert pdef.margins_mm == (10.0, 20.0, 30.0, 40.0)
    assert pdef.pens[7].colour == (0xA0, 0xB0, 0xC0)
    assert pdef.title is False
    assert pdef.frame is False
    assert pdef.height_decimals == 2
    assert pdef.pen_for("r", "lines", 21) == 7
    assert pdef.pen_for("h", "lines", 21) == 2  # an exact layer outweighs an exact code


def test_rule_precedence():
    pdef = PlotterDef(
        rules=(
            PenRule("*", None, 1),
            PenRule("r", None, 2, "lines"),
            PenRule("*", 21, 3),
            PenRule("r", 21, 4),
            PenRule("r", 21, 5),  # same weight, later: wins
        ),
        pens={n: PlotterDef.default().pens[min(n, 6)] for n in range(1, 6)},
    )
    assert pdef.pen_for("r", "lines", 21) == 5
    assert pdef.pen_for("r", "lines", 11) == 2
    assert pdef.pen_for("h", "symbols", 21) == 3
    assert pdef.pen_for("h", "texts") == 1


def test_clear_pen_rules_and_round_trip():
    pdef = parse_plotdef("clear-pen-rules\npen * * 5\npendef 9 red 1\norigin 10.5 -3\n")
    assert pdef.rules == (PenRule("*", None, 5),)
    assert pdef.pen_for("h", "lines", 31) == 5
    assert parse_plotdef(pdef.to_text()) == pdef
    custom = parse_plotdef("paper 500x300\nscale 1000\ntitle off\nmargin 5\n")
    assert parse_plotdef(custom.to_text()) == custom


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("paper B5\n", 1, "paper: expected A0-A4"),
        ("paper A4 sideways\n", 1, "portrait"),
        ("paper 0 x 100\n", 1, "paper width"),
        ("scale 5000\nscale 2500\n", 2, "given twice (first on line 1)"),
        ("scale -5\n", 1, "scale"),
        ("scale 1:x\n", 1, "whole number"),
        ("origin 1\n", 1, "origin: expected ground X and Y"),
        ("origin 1 nan\n", 1, "expected a number"),
        ("margin 1 2\n", 1, "one value or four"),
        ("symbol-size 0\n", 1, "outside (0, 100]"),
        ("text-height big\n", 1, "expected a number"),
        ("height-decimals 4\n", 1, "outside 0-3"),
        ("title maybe\n", 1, "expected 'on' or 'off'"),
        ("\n\nwidth 3\n", 3, "unknown key 'width'"),
        ("pendef 2 mauve 0.3\n", 1, "unknown colour 'mauve'"),
        ("pendef 2 red 0\n", 1, "pen width"),
        ("pendef 8 red 1\npendef 8 red 2\n", 2, "defined twice"),
        ("pen r 21\n", 1, "expected 'pen LAYER CODE PEN [KIND]'"),
        ("pen roads 21 1\n", 1, "layer must be"),
        ("pen r 100 1\n", 1, "code: 100 is outside 0-99"),
        ("pen r 21 1 areas\n", 1, "kind must be one of"),
        ("\npen r 21 42\n", 2, "pen 42 is used but not defined"),
        ("margin 10\n", 1, "too small for the title block"),
        ("clear-pen-rules now\n", 1, "takes no value"),
        ("\nframe-pen 42\n", 2, "pens used but not defined with 'pendef': [42]"),
    ],
)
def test_errors_name_the_line(text, line, words):
    with pytest.raises(FormatError) as exc:
        parse_plotdef(text, path="PLOTTER.DEF")
    assert exc.value.path == "PLOTTER.DEF"
    assert exc.value.record == f"line {line}"
    assert words in str(exc.value)


def test_file_errors(tmp_path):
    bad = tmp_path / "PLOTTER.DEF"
    bad.write_bytes(b"paper A4\nscale \xff\n")
    with pytest.raises(FormatError, match="line 2: not UTF-8"):
        read_plotdef(bad)
    with pytest.raises(FormatError, match="no such file"):
        read_plotdef(tmp_path / "missing.def")
    # the title fits once it is off
    assert parse_plotdef("margin 10\ntitle off\n").margins_mm == (10.0,) * 4


# --------------------------------------------------------------------------- layout


def test_default_layout_of_the_sample(sample_map):
    d = build_drawing(sample_map, library=default_library())
    # data 2400 x 1500 m = 480 x 300 mm, plus 15 mm margins: A3 is too small
    assert (d.width_mm, d.height_mm, d.paper) == (594.0, 420.0, "A2 landscape")
    assert d.scale == 5000
    xmin = min(lay.extent()[0] for lay in sample_map)
    ymin = min(lay.extent()[1] for lay in sample_map)
    assert d.origin == pytest.approx((xmin - 75.0, ymin - 75.0))
    assert d.frame == (15.0, 15.0, 579.0, 405.0)
    exp = expected_counts(sample_map)
    s = d.stats
    assert (s["lines"], s["symbols"], s["texts"]) == (exp["lines"], exp["symbols"], exp["texts"])
    assert s["spot_heights"] == exp["spots"] == 96
    assert s["lines_clipped"] == s["lines_dropped"] == s["symbols_dropped"] == 0
    assert "A2 landscape (594 x 420 mm), 1:5000, layers c e h r: 18 lines" in d.summary()


def test_auto_paper_and_orientation():
    m = apygis.MapFile("T", scale=1000)
    m.layer("r").add_line([(0, 0, 0), (100, 250, 0)], code=1)
    assert build_drawing(m, library=default_library()).paper == "A4 portrait"
    m.layer("r").add_line([(0, 0, 0), (400, 10, 0)], code=1)
    assert build_drawing(m, library=default_library()).paper == "A2 landscape"
    d = build_drawing(m, parse_plotdef("paper A1"), default_library())
    assert d.paper == "A1 landscape"
    d = build_drawing(m, parse_plotdef("paper A4"), default_library())  # too small: clipped
    assert d.paper == "A4 landscape"
    assert d.stats["lines_clipped"] == 2


def test_clipping_at_the_neat_line():
    m = apygis.MapFile("CLIP", scale=1000)
    lay = m.layer("r")
    # paper 100 x 100 mm, origin 0 0, margins 10: neat line 10..90 mm = 10..90 m
    pdef = parse_plotdef("paper 100 x 100\norigin 0 0\nmargin 10\ntitle off\n")
    lay.add_line([(0, 50, 0), (50, 50, 0), (50, 200, 0), (60, 200, 0), (60, 50, 0)], code=1)
    lay.add_line([(20, 20, 0), (120, 20, 0), (120, 40, 0), (20, 40, 0)], code=2, closed=True)
    lay.add_line([(-10, -10, 0), (-5, -20, 0)], code=3)  # wholly outside
    lay.add_line([(0, 0, 0), (100, 100, 0)], code=4)  # both ends outside, crosses
    lay.add_symbol(50, 95, 0, code=1)  # outside: dropped
    lay.add_symbol(89.9, 50, 0, code=1)  # inside, cells cut at the neat line
    lay.add_text(95, 50, 0, "off")
    lay.add_text(85, 50, 0, "on")
    d = build_drawing(m, pdef, default_library())
    lines = [it for it in d.items if isinstance(it, PaperLine) and it.role == "line"]
    assert d.stats["lines"] == 3
    assert d.stats["lines_dropped"] == 1
    assert d.stats["lines_clipped"] == 3
    assert d.stats["symbols_dropped"] == 1
    assert d.stats["symbols"] == 1
    assert d.stats["texts_dropped"] == 1
    assert d.stats["texts"] == 1
    got = [np.round(it.points, 9).tolist() for it in lines]
    assert got == [
        [[10.0, 50.0], [50.0, 50.0], [50.0, 90.0]],
        [[60.0, 90.0], [60.0, 50.0]],
        [[90.0, 40.0], [20.0, 40.0], [20.0, 20.0], [90.0, 20.0]],  # ring joined at its start
        [[10.0, 10.0], [90.0, 90.0]],
    ]
    for it in d.items:
        if isinstance(it, FilledRects):
            assert it.rects[:, 2].max() <= 90.0
            assert it.rects[:, 0].min() >= 10.0


def test_clip_polyline_cases():
    rect = (0.0, 0.0, 10.0, 10.0)
    assert clip_polyline([(5, 5)], rect)[0].tolist() == [[5.0, 5.0]]
    assert clip_polyline([(15, 5)], rect) == []
    assert clip_polyline([(-1, 0), (-1, 10)], rect) == []
    assert [p.tolist() for p in clip_polyline([(0, 0), (10, 0)], rect)] == [
        [[0.0, 0.0], [10.0, 0.0]]
    ]  # along the edge: kept
    ring = clip_polyline([(5, 5), (15, 5), (15, 8), (5, 8)], rect, closed=True)
    assert [p.tolist() for p in ring] == [[[10.0, 8.0], [5.0, 8.0], [5.0, 5.0], [10.0, 5.0]]]


def test_symbol_runs_cover_every_painted_cell_once():
    lib = default_library()
    for code in range(100):
        bm = lib[code].bitmap
        runs = symbol_runs(bm)
        cover = np.zeros((15, 15), dtype=int)
        for r0, c0, r1, c1 in runs:
            assert r0 == r1 or c0 == c1
            cover[r0 : r1 + 1, c0 : c1 + 1] += 1
        assert np.array_equal(cover, bm.astype(int)), code
        assert len(runs) == count_runs(bm), code


def test_hatching_covers_wide_rects():
    assert len(hatch_strokes([(0, 0, 1, 0.2)], 0.35)) == 1
    st = hatch_strokes([(0, 0, 0.2, 2.0)], 0.25)  # vertical run
    assert st.tolist() == [[[0.1, 0.125], [0.1, 1.875]]]
    st = hatch_strokes([(0, 0, 4, 1)], 0.25)
    assert len(st) == 4
    assert st[:, 0, 1].tolist() == pytest.approx([0.125, 0.375, 0.625, 0.875])
    assert hatch_strokes([(0, 0, 0.1, 0.1)], 0.35).tolist() == [[[0.05, 0.05], [0.05, 0.05]]]


def test_no_scale_and_unknown_layer(sample_map):
    m = apygis.MapFile("NOSCALE")
    m.layer("r").add_symbol(0, 0, 0, 1)
    with pytest.raises(FormatError, match="no compilation scale"):
        build_drawing(m, library=default_library())
    assert build_drawing(m, parse_plotdef("scale 500"), default_library()).scale == 500
    with pytest.raises(RecordError, match="no layer x"):
        build_drawing(sample_map, layers=["x"], library=default_library())
    with pytest.raises(FormatError, match="leave no room"):
        build_drawing(sample_map, parse_plotdef("paper 50 x 50\nmargin 30"), default_library())


def test_empty_map_has_frame_and_title():
    d = build_drawing(apygis.MapFile("EMPTY", scale=1000), library=default_library())
    assert d.paper == "A4 portrait"
    assert [type(it).__name__ for it in d.items] == [
        "PaperLine",
        "PaperLine",
        "PaperText",
        "PaperText",
    ]
    assert b"LBEMPTY   1:1000\x03" in drawing_hpgl(d)


# --------------------------------------------------------------------------- HP-GL


def test_hpgl_of_the_sample(sample_map, plotdef, drawing):
    data = drawing_hpgl(drawing)
    assert data.startswith(b"IN;")
    instr = parse_hpgl(data)
    ops = [op for op, _ in instr]
    assert ops[:3] == ["IN", "PA", "DT"]
    assert instr[2][1] == "\x03"
    exp = expected_counts(sample_map)
    # every symbol pen is at least a cell wide: one stroke per run of cells
    cell = plotdef.symbol_size_mm / 15
    assert all(plotdef.pens[it.pen].width_mm >= cell for it in drawing.items if it.role == "symbol")
    frame_and_title_box = 2
    assert ops.count("PD") == exp["lines"] + exp["strokes"] + frame_and_title_box
    title_lines = 2
    assert ops.count("LB") == exp["texts"] + exp["spots"] + title_lines
    # every coordinate on the paper, in plotter units
    W, H = 594 * UNITS, 420 * UNITS
    for op, args in instr:
        if op in ("PU", "PD") and args:
            v = [int(a) for a in args.split(",")]
            assert all(0 <= x <= W for x in v[::2])
            assert all(0 <= y <= H for y in v[1::2])
    # pens: PW for each, selected once each, in ascending order
    sp = [int(a) for op, a in instr if op == "SP"]
    assert sp == [1, 2, 3, 4, 5, 6, 0]
    pw = dict(reversed(a.split(",")) for op, a in instr if op == "PW")
    assert pw == {"1": "0.35", "2": "0.25", "3": "0.5", "4": "0.25", "5": "0.18", "6": "0.5"}


def test_hpgl_lines_in_their_pens_at_the_right_place(sample_map, drawing):
    strokes = hpgl_strokes(parse_hpgl(drawing_hpgl(drawing)))
    by_points = {tuple(pts): pen for pen, pts in strokes}
    X0, Y0 = 2682925.0, 1246925.0  # from samples/PLOTTER.DEF

    def units(x, y):  # 1:5000: 1 m = 0.2 mm = 8 plotter units
        return (round((x - X0) * 8), round((y - Y0) * 8))

    expected_pen = {("r", 11): 3, ("r", 13): 5, ("r", 21): 5, ("h", 31): 6}
    n = 0
    for ext in "hr":
        for pl in export_lines(sample_map.layers[ext]):
            pts = [units(x, y) for x, y, _ in pl.coords]
            if pl.closed:
                pts.append(pts[0])
            default = 2 if ext == "h" else 1
            assert by_points[tuple(pts)] == expected_pen.get((ext, pl.code), default)
            n += 1
    assert n == 18


def test_hpgl_known_point_and_labels(sample_map, drawing):
    instr = parse_hpgl(drawing_hpgl(drawing))
    labels = {}
    pos = None
    for op, args in instr:
        if op == "PU" and args:
            pos = tuple(int(v) for v in args.split(","))
        elif op == "LB":
            labels[args] = pos
    t = next(r for r in sample_map.layers["r"].texts if r["text"] == "Kirchweg")
    assert labels["Kirchweg"] == (
        round((t["x"] - 2682925.0) * 8),
        round((t["y"] - 1246925.0) * 8),
    )
    # a spot height: its label to the right of the cross, vertically centred
    s = sample_map.layers["e"].symbols[0]
    text = f"{s['z']:.1f}"
    x_mm = (s["x"] - 2682925.0) * 0.2 + 3 * 2.5 / 15 + 0.4 * 2.5
    y_mm = (s["y"] - 1246925.0) * 0.2 - 2.5 / 2
    assert labels[text] == (round(x_mm * 40), round(y_mm * 40))
    assert labels["ZH1091   1:5000"] is not None
    assert any(k.startswith("CRS EPSG:2056   layers c e h r") for k in labels)
    assert next(a for op, a in instr if op == "SI") == "0.125,0.25"


def test_hpgl_labels_are_ascii():
    m = apygis.MapFile("U", scale=1000)
    m.layer("r").add_text(10, 10, 0, "Zürich (Süd) ñ ©")
    data = drawing_hpgl(build_drawing(m, library=default_library()))
    assert b"LBZuerich (Sued) n ?\x03" in data
    assert ascii_label("Straße") == "Strasse"


# --------------------------------------------------------------------------- SVG


def test_svg_of_the_sample(sample_map, drawing):
    data = drawing_svg(drawing)
    root = ET.fromstring(data)
    ns = {"s": SVG_NS}
    assert root.tag == f"{{{SVG_NS}}}svg"
    assert (root.get("width"), root.get("height")) == ("594mm", "420mm")
    assert root.get("viewBox") == "0 0 594 420"
    exp = expected_counts(sample_map)
    assert len(root.findall(".//s:polyline", ns)) == exp["lines"] + 2
    assert len(root.findall(".//s:rect", ns)) == exp["strokes"]
    assert len(root.findall("s:g[@data-role='symbol']", ns)) == exp["symbols"]
    texts = root.findall(".//s:text", ns)
    assert len(texts) == exp["texts"] + exp["spots"] + 2
    # north up: y is flipped
    t = next(r for r in sample_map.layers["r"].texts if r["text"] == "Kirchweg")
    el = next(e for e in texts if e.text == "Kirchweg")
    assert float(el.get("x")) == pytest.approx((t["x"] - 2682925.0) * 0.2, abs=1e-3)
    assert float(el.get("y")) == pytest.approx(420 - (t["y"] - 1246925.0) * 0.2, abs=1e-3)
    frame = root.find("s:polyline[@data-role='frame']", ns)
    pts = [tuple(map(float, p.split(","))) for p in frame.get("points").split()]
    assert pts == [(15, 405), (579, 405), (579, 15), (15, 15), (15, 405)]
    # pens: the Hauptstrasse (code 11) is red and 0.5 mm wide
    red = root.findall(".//s:polyline[@class='pen-3']", ns)
    assert len(red) == 1
    assert red[0].get("stroke") == "#c00000"
    assert red[0].get("stroke-width") == "0.5"


def test_svg_escapes_text():
    m = apygis.MapFile("X", scale=1000)
    m.layer("r").add_text(10, 10, 0, 'A<B & "C" Zürich')
    root = ET.fromstring(drawing_svg(build_drawing(m, library=default_library())))
    assert next(t.text for t in root.iter(f"{{{SVG_NS}}}text")) == 'A<B & "C" Zürich'


# --------------------------------------------------------------------------- PDF


@pytest.mark.parametrize("compress", [True, False])
def test_pdf_of_the_sample(sample_map, drawing, compress):
    pdf = drawing_pdf(drawing, compress=compress)
    objs = pdf_objects(pdf)
    pages = pdf_pages(objs)
    assert len(pages) == 1
    page, content = pages[0]
    box = [float(v) for v in re.search(rb"/MediaBox \[([^\]]*)\]", page).group(1).split()]
    assert box == pytest.approx([0, 0, 594 * 72 / 25.4, 420 * 72 / 25.4], abs=1e-3)
    fonts = [b for b in objs.values() if b"/Type /Font" in b]
    assert fonts == [
        b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica /Encoding /WinAnsiEncoding >>"
    ]
    exp = expected_counts(sample_map)
    ops = pdf_ops(content)
    assert ops["S"] == exp["lines"] + 2
    assert ops["h"] == 8 + 1 + 2  # closed lines (buildings, pond) + frame + title box
    assert ops["re"] == exp["strokes"]
    assert ops["f"] == exp["symbols"]
    assert ops["Tj"] == ops["BT"] == ops["ET"] == exp["texts"] + exp["spots"] + 2
    assert content.startswith(b"q\n2.834646 0 0 2.834646 0 0 cm\n")
    assert b"(Kirchweg) Tj" in content
    assert b"/Title (ZH1091 1:5000)" in pdf


def test_pdf_strings():
    assert pdf_string("a(b)c\\") == b"(a\\(b\\)c\\\\)"
    assert pdf_string("Zürich €") == b"(Z\\374rich \\200)"
    assert pdf_string("Łódź") == b"(?\\363d?)"  # outside WinAnsi: replaced


def test_pdf_texts_round_trip():
    m = apygis.MapFile("T", scale=1000)
    m.layer("r").add_text(10, 10, 0, "Sägerei (alt) \\ Nord")
    pdf = drawing_pdf(build_drawing(m, library=default_library()), compress=False)
    ((_, content),) = pdf_pages(pdf_objects(pdf))
    strings = [pdf_unescape(s) for s in _PDF_STRING.findall(content)]
    assert "Sägerei (alt) \\ Nord" in strings


def test_text_pages_pdf_of_the_printout(sample_map):
    text = printout_text(sample_map, default_library())
    lines = text.splitlines()
    assert text_page_capacity() == (94, 68)
    assert max(map(len, lines)) <= 94
    n = math.ceil(len(lines) / 68)
    pdf = text_pages_pdf(text, title="APY print-out ZH1091")
    objs = pdf_objects(pdf)
    pages = pdf_pages(objs)
    assert len(pages) == n == len(text_pages(text))
    got = []
    for i, (page, content) in enumerate(pages, start=1):
        box = [float(v) for v in re.search(rb"/MediaBox \[([^\]]*)\]", page).group(1).split()]
        assert box == pytest.approx([0, 0, *A4_PT], abs=1e-3)
        strings = [pdf_unescape(s) for s in _PDF_STRING.findall(content)]
        assert strings[-2:] == ["APY print-out ZH1091", f"page {i} of {n}"]
        got += strings[:-2]
        assert len(strings) - 2 == (68 if i < n else len(lines) - 68 * (n - 1))
    assert got == lines
    assert any(b"/BaseFont /Courier " in b for b in objs.values())


def test_text_pages_wrap_and_form_feed():
    long = "x" * 200
    pages = text_pages(f"{long}\nshort\n\fnext page\n")
    assert pages == [["x" * 94, "x" * 94, "x" * 12, "short"], ["next page"]]
    pdf = text_pages_pdf("", compress=False)
    assert len(pdf_pages(pdf_objects(pdf))) == 1


def test_pdf_output_is_deterministic(drawing):
    assert drawing_pdf(drawing) == drawing_pdf(drawing)
    assert isinstance(drawing.items[-1], PaperText)
