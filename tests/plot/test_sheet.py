"""The sheet: scale, window, paper, centring, clipping, grid, legend, scale bar, north, title.

Expected values are computed here from the map, the font's measure and the documented
rules, not by calling the layout code again.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

import apygis
from apygis.errors import FormatError, RecordError
from apygis.model.polylines import export_lines
from apygis.model.symbols import default_library
from apygis.plot.drawing import ControlPoint, build_drawing, plot_date
from apygis.plot.fonts import text_size
from apygis.plot.layout import flow_columns, nice_step, round_scales
from apygis.plot.margin import format_coordinate, grid_interval, scale_bar_length, wrap_text
from apygis.plot.plotdef import parse_plotdef, read_plotdef
from apygis.plot.primitives import (
    FilledPolygon,
    FilledRects,
    PaperLine,
    PaperText,
    clip_polyline,
    symbol_runs,
    text_box,
)
from tests.plot.helpers import PLOTTER_DEF, count_runs, expected_counts

LIB = default_library()


def texts(d, role):
    return [it for it in d.items if isinstance(it, PaperText) and it.role == role]


def all_boxes(d):
    """Every primitive's bounding box, mm."""
    for it in d.items:
        if isinstance(it, PaperLine | FilledPolygon):
            yield it.role, (*it.points.min(axis=0), *it.points.max(axis=0))
        elif isinstance(it, FilledRects):
            if len(it.rects):
                yield it.role, (*it.rects[:, :2].min(axis=0), *it.rects[:, 2:].max(axis=0))
        else:
            yield it.role, text_box(it)


# --------------------------------------------------------------------------- layout


def test_default_layout_of_the_sample(sample_map):
    d = build_drawing(sample_map, library=LIB)
    assert (d.width_mm, d.height_mm, d.paper, d.scale) == (594.0, 420.0, "A2 landscape", 5000)
    # the window: the data (and the labels at their preferred positions: texts from their
    # points, spot heights right of their crosses) padded by 3 mm (15 m) and rounded
    # outward to 10 m (2 mm)
    ext = [lay.extent() for lay in sample_map]
    reach = max(e[3] for e in ext)
    for s in sample_map.layers["e"].symbols:
        label = text_size(f"{float(s['z']):.1f}", 2.5)[0]
        reach = max(reach, float(s["x"]) + (1.5 + 1.0 + label) / 0.2)  # gap: half symbol + 0.4 h
    for lay in sample_map:  # a text starts at its point and runs right
        for t in lay.texts:
            reach = max(reach, float(t["x"]) + text_size(str(t["text"]), 2.5)[0] / 0.2)
    x0 = math.floor((min(e[0] for e in ext) - 15) / 10) * 10
    y0 = math.floor((min(e[1] for e in ext) - 15) / 10) * 10
    x1 = math.ceil((reach + 15) / 10) * 10
    y1 = math.ceil((max(e[4] for e in ext) + 15) / 10) * 10
    assert d.window == (x0, y0, x1, y1)
    f = d.mm_per_unit
    assert f == pytest.approx(0.2)
    fx0, fy0, fx1, fy1 = d.frame
    assert (fx1 - fx0, fy1 - fy0) == pytest.approx(((x1 - x0) * f, (y1 - y0) * f))
    # the window's corners are the neat line's
    assert [float(v) for v in d.to_paper(x0, y0)] == pytest.approx([fx0, fy0])
    assert [float(v) for v in d.to_paper(x1, y1)] == pytest.approx([fx1, fy1])
    # centred: the map vertically on the paper; map and panel together horizontally
    assert (fy0 + fy1) / 2 == pytest.approx(210.0)
    boxes = list(all_boxes(d))
    left = min(b[0] for _, b in boxes)
    right = max(b[2] for _, b in boxes)
    assert left >= 10.0
    assert right <= 584.0
    panel = [b for r, b in boxes if r in ("heading", "legend", "title", "scalebar", "north")]
    assert min(b[0] for b in panel) > fx1 + 6.0  # right of the map and its grid labels
    exp = expected_counts(sample_map)
    s = d.stats
    assert (s["lines"], s["symbols"], s["texts"]) == (exp["lines"], exp["symbols"], exp["texts"])
    assert s["spot_heights"] == exp["spots"] == 96
    assert s["lines_clipped"] == s["lines_dropped"] == s["symbols_dropped"] == 0
    assert s["labels"] == exp["texts"] + exp["spots"]
    assert "A2 landscape (594 x 420 mm), 1:5000, layers c e h r: 18 lines" in d.summary()


def test_plotter_def_window_is_the_sheet(sample_map):
    d = build_drawing(sample_map, read_plotdef(PLOTTER_DEF), LIB)
    assert d.window == (2683000.0, 1247000.0, 2685400.0, 1248600.0)
    fx0, fy0, fx1, fy1 = d.frame
    assert (fx1 - fx0, fy1 - fy0) == pytest.approx((480.0, 320.0))
    assert [float(v) for v in d.to_paper(2683000.0, 1247000.0)] == pytest.approx([fx0, fy0])
    assert (fy0 + fy1) / 2 == pytest.approx(210.0)  # vertically centred
    assert d.stats["lines_clipped"] == 0


def test_origin_fixes_the_ground_on_the_paper():
    m = apygis.MapFile("O", scale=1000)
    m.layer("r").add_line([(50, 50, 0), (120, 80, 0)], code=1)
    d = build_drawing(m, parse_plotdef("origin 0 0\npaper A4 landscape\n"), LIB)
    assert d.origin == (0.0, 0.0)
    line = next(it for it in d.items if isinstance(it, PaperLine) and it.role == "line")
    assert line.points.tolist() == [[50.0, 50.0], [120.0, 80.0]]  # 1:1000: 1 m = 1 mm
    assert d.window == pytest.approx(d.frame)  # the window is what the neat line encloses


def test_auto_paper_and_orientation():
    m = apygis.MapFile("T", scale=1000)
    # 1:1000: 100 x 250 mm of data, 106 x 256 mm of window, 118 x 268 mm with the grid
    # labels, and the 62 mm panel beside it: A4 portrait (190 x 277 mm inside the margins)
    m.layer("r").add_line([(0, 0, 0), (100, 250, 0)], code=1)
    assert build_drawing(m, library=LIB).paper == "A4 portrait"
    # 406 x 256 mm of window: A2 landscape (574 x 400 mm inside the margins)
    m.layer("r").add_line([(0, 0, 0), (400, 10, 0)], code=1)
    assert build_drawing(m, library=LIB).paper == "A2 landscape"
    d = build_drawing(m, parse_plotdef("paper A0"), LIB)
    assert d.paper == "A0 landscape"
    d = build_drawing(m, parse_plotdef("paper A1 portrait"), LIB)
    assert d.paper == "A1 portrait"


def test_a_sheet_too_big_for_its_paper_is_cut_and_says_so(caplog):
    m = apygis.MapFile("T", scale=1000)
    m.layer("r").add_line([(0, 0, 0), (400, 250, 0)], code=1)  # both cross the centre
    m.layer("r").add_line([(0, 250, 0), (400, 0, 0)], code=1)
    with caplog.at_level(logging.WARNING, logger="apygis.plot.layout"):
        d = build_drawing(m, parse_plotdef("paper A4"), LIB)
    assert d.paper == "A4 landscape"
    assert "does not fit on A4 landscape" in caplog.text
    assert d.stats["lines_clipped"] == 2
    assert "2 lines clipped at the neat line" in d.summary()


def test_scale_when_the_map_has_none():
    m = apygis.MapFile("NOSCALE")
    m.layer("r").add_line([(0, 0, 0), (3000, 2000, 0)], code=1)
    d = build_drawing(m, library=LIB)
    # the largest round scale at which the sheet fits A3: 1:10000 (300 x 200 mm) is too big
    assert d.scale in round_scales()
    assert d.paper.startswith("A3")
    smaller = [s for s in round_scales() if s < d.scale]
    assert smaller
    assert smaller[-1] < d.scale
    frame_w = d.frame[2] - d.frame[0]
    assert frame_w == pytest.approx((d.window[2] - d.window[0]) * 1000 / d.scale)
    assert build_drawing(m, parse_plotdef("scale 50000"), LIB).scale == 50000


def test_helpers_of_the_layout():
    assert round_scales(500, 5000) == [500, 1000, 2000, 2500, 5000]
    assert [nice_step(v) for v in (0.7, 3, 11, 240, 2600)] == [1, 5, 20, 250, 5000]
    assert flow_columns([20, 20, 20, 50], 60) == [[0, 1], [2], [3]]
    assert flow_columns([10] * 3 + [15], 60) == [[0, 1, 2, 3]]
    assert grid_interval(0.2) == 200
    assert grid_interval(0.04) == 1000
    assert grid_interval(0.2 * 0.3048006) == 1000  # 1:5000 in US feet: 1000 ft = 61 mm
    assert scale_bar_length(0.2, 44.0) == 200
    assert scale_bar_length(0.02, 44.0) == 2000
    assert format_coordinate(1247000.0, 200) == "1247000"
    assert format_coordinate(7.5, 0.5) == "7.5"
    assert wrap_text("a b c", 2.0, 1000.0) == ["a b c"]
    lines = wrap_text("ZH1091.c, ZH1091.e, ZH1091.h, ZH1091.r", 2.0, 25.0)
    assert len(lines) > 1
    assert " ".join(lines) == "ZH1091.c, ZH1091.e, ZH1091.h, ZH1091.r"


# --------------------------------------------------------------------------- clipping


def test_clipping_at_the_neat_line():
    m = apygis.MapFile("CLIP", scale=1000)
    lay = m.layer("r")
    # the window 10..90 m at 1:1000: the neat line encloses 10..90 mm of the frame
    pdef = parse_plotdef(
        "paper 120 x 120\nwindow 10 10 90 90\nmargin 5\ngrid off\nlegend off\ntitle off\n"
    )
    lay.add_line([(0, 50, 0), (50, 50, 0), (50, 200, 0), (60, 200, 0), (60, 50, 0)], code=1)
    lay.add_line([(20, 20, 0), (120, 20, 0), (120, 40, 0), (20, 40, 0)], code=2, closed=True)
    lay.add_line([(-10, -10, 0), (-5, -20, 0)], code=3)  # wholly outside
    lay.add_line([(0, 0, 0), (100, 100, 0)], code=4)  # both ends outside, crosses
    lay.add_symbol(50, 95, 0, code=1)  # outside: dropped
    lay.add_symbol(89.9, 50, 0, code=1)  # inside, cells cut at the neat line
    lay.add_text(95, 50, 0, "off")
    lay.add_text(85, 50, 0, "on")
    d = build_drawing(m, pdef, LIB)
    ox, oy = d.to_paper(0.0, 0.0)
    lines = [
        it.points - (ox, oy) for it in d.items if isinstance(it, PaperLine) and it.role == "line"
    ]
    assert d.stats["lines"] == 3
    assert d.stats["lines_dropped"] == 1
    assert d.stats["lines_clipped"] == 3
    assert d.stats["symbols_dropped"] == 1
    assert d.stats["symbols"] == 1
    assert d.stats["texts_dropped"] == 1
    assert d.stats["texts"] == 1
    got = [np.round(p, 9).tolist() for p in lines]
    assert got == [
        [[10.0, 50.0], [50.0, 50.0], [50.0, 90.0]],
        [[60.0, 90.0], [60.0, 50.0]],
        [[90.0, 40.0], [20.0, 40.0], [20.0, 20.0], [90.0, 20.0]],  # ring joined at its start
        [[10.0, 10.0], [90.0, 90.0]],
    ]
    for it in d.items:
        if isinstance(it, FilledRects) and it.role == "symbol":
            assert it.rects[:, 2].max() <= d.frame[2] + 1e-9
    assert "outside the neat line: 1 line, 1 symbol, 1 text" in d.summary()


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
    for code in range(100):
        bm = LIB[code].bitmap
        runs = symbol_runs(bm)
        cover = np.zeros((15, 15), dtype=int)
        for r0, c0, r1, c1 in runs:
            assert r0 == r1 or c0 == c1
            cover[r0 : r1 + 1, c0 : c1 + 1] += 1
        assert np.array_equal(cover, bm.astype(int)), code
        assert len(runs) == count_runs(bm), code


def test_no_layer_and_no_room(sample_map):
    with pytest.raises(RecordError, match="no layer x"):
        build_drawing(sample_map, layers=["x"], library=LIB)
    with pytest.raises(FormatError, match="leave no room"):
        build_drawing(sample_map, parse_plotdef("paper 50 x 50\nmargin 24"), LIB)
    with pytest.raises(FormatError, match="grid must be"):
        build_drawing(sample_map, grid="dots", library=LIB)


def test_empty_map_has_frame_and_title():
    d = build_drawing(apygis.MapFile("EMPTY", scale=1000), library=LIB, date="2024-01-01")
    assert d.paper == "A4 landscape"
    assert d.count(PaperLine, "frame") == 1
    title = [t.text for t in texts(d, "title")]
    assert "EMPTY" in title
    assert "2024-01-01" in title
    assert d.stats["labels"] == 0


# --------------------------------------------------------------------------- grid


def test_grid_crosses_and_labels_at_the_neat_line(sample_map):
    d = build_drawing(sample_map, read_plotdef(PLOTTER_DEF), LIB)
    assert d.grid_interval == 200
    fx0, fy0, fx1, fy1 = d.frame
    labels = texts(d, "grid-label")
    east = sorted({int(t.text) for t in labels if t.angle == 0})
    north = sorted({int(t.text) for t in labels if t.angle == 90})
    # every round 200 m inside the sheet (the corners are the neat line itself)
    assert east == list(range(2683200, 2685400, 200))
    assert north == list(range(1247200, 1248600, 200))
    for t in labels:
        x, y = d.to_paper(float(t.text), float(t.text))
        if t.angle == 0:  # centred under (and over) its grid line, outside the neat line
            assert t.x + t.width / 2 == pytest.approx(float(x), abs=1e-6)
            assert t.y + t.height < fy0 or t.y > fy1
        else:  # turned to read upward, beside the neat line
            assert t.y + t.width / 2 == pytest.approx(float(y), abs=1e-6)
            assert t.x < fx0 or t.x - t.height > fx1
    assert sum(1 for t in labels if t.angle == 0) == 2 * len(east)
    # crosses: two strokes at each grid intersection inside the neat line
    centres = set()
    for it in d.items:
        if isinstance(it, PaperLine) and it.role == "grid" and len(it.points) == 2:
            a, b = it.points
            if a[1] == b[1] and fx0 < a[0] and b[0] < fx1 and b[0] - a[0] == pytest.approx(5.0):
                centres.add((round((a[0] + b[0]) / 2, 6), round(a[1], 6)))
    want = {
        (round(float(d.to_paper(x, 0)[0]), 6), round(float(d.to_paper(0, y)[1]), 6))
        for x in east
        for y in north
    }
    # all but those within a cross's arm of the neat line
    assert centres <= want
    assert len(centres) >= len(want) - 2 * (len(east) + len(north))


def test_grid_lines_and_off(sample_map):
    d = build_drawing(sample_map, read_plotdef(PLOTTER_DEF), LIB, grid="lines")
    grid = [it for it in d.items if isinstance(it, PaperLine) and it.role == "grid"]
    full = [g for g in grid if np.ptp(g.points[:, 1]) == pytest.approx(320.0)]
    assert len(full) == 11  # 2683200 ... 2685200
    d = build_drawing(sample_map, read_plotdef(PLOTTER_DEF), LIB, grid="off")
    assert d.count(PaperLine, "grid") == 0
    assert not texts(d, "grid-label")
    assert d.grid_interval is None


# ------------------------------------------------------------------ legend, scale bar, north


def test_legend_shows_what_is_drawn(sample_map):
    pdef = read_plotdef(PLOTTER_DEF)
    d = build_drawing(sample_map, pdef, LIB)
    legend = [t.text for t in texts(d, "legend")]
    assert legend[0] == "Legend"
    codes = sorted({int(c) for lay in sample_map for c in lay.symbols["code"]})
    for c in codes:
        name = "spot height" if c == 0 else LIB.name(c)
        assert f"{c:02d} {name}" in legend
    for ext in sorted(sample_map.layers):
        ls = export_lines(sample_map.layers[ext])
        for code in sorted({int(c) for c in ls.codes}):
            closed = all(bool(ls.closed[k]) for k in range(len(ls)) if ls.codes[k] == code)
            word = "closed line" if closed else "line"
            assert f"{word} {code:02d} (layer {ext})" in legend
    n_symbols = len(codes)
    n_lines = sum(len({int(c) for c in export_lines(lay).codes}) for lay in sample_map)
    assert len(legend) == 1 + n_symbols + n_lines
    # each symbol entry is drawn from its bitmap, in its pen
    entries = [it for it in d.items if isinstance(it, FilledRects) and it.role == "legend"]
    assert sorted(len(e.rects) for e in entries) == sorted(count_runs(LIB[c].bitmap) for c in codes)
    pens = {it.pen for it in d.items if isinstance(it, PaperLine) and it.role == "legend"}
    assert {3, 5, 6, 2} <= pens  # main road, paths/buildings, main stream, water


def test_scale_bar_is_round_and_to_scale(sample_map):
    d = build_drawing(sample_map, read_plotdef(PLOTTER_DEF), LIB)
    bar = next(it for it in d.items if isinstance(it, PaperLine) and it.role == "scalebar")
    length_mm = np.ptp(bar.points[:, 0])
    length_m = length_mm / d.mm_per_unit
    assert length_m == pytest.approx(200.0)
    labels = [t.text for t in texts(d, "scalebar")]
    assert labels[0] == "0"
    assert labels[-1] == "200 m"
    filled = next(it for it in d.items if isinstance(it, FilledRects) and it.role == "scalebar")
    assert len(filled.rects) == 2  # 4 segments of 50 m, every other one filled
    assert np.ptp(filled.rects[:, [0, 2]]) == pytest.approx(length_mm * 3 / 4)
    # km from 1000 m: a 1:50000 sheet
    m = apygis.MapFile("K", scale=50000, crs="EPSG:2056")
    m.layer("r").add_line([(2600000, 1200000, 0), (2615000, 1210000, 0)], code=1)
    kms = [t.text for t in texts(build_drawing(m, library=LIB), "scalebar")]
    assert kms[-1].endswith(" km")
    assert float(kms[-1].split()[0]) >= 1


def test_north_arrow_and_true_north():
    def north(crs, lon):
        from pyproj import Transformer

        x, y = Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(lon, 47.0)
        m = apygis.MapFile("N", scale=25000, crs=crs)
        m.layer("r").add_line([(x - 1000, y - 1000, 0), (x + 1000, y + 1000, 0)], code=1)
        d = build_drawing(m, library=LIB)
        assert d.count(FilledPolygon, "north") == 1
        assert "N" in [t.text for t in texts(d, "north")]
        rows = " ".join(t.text for t in texts(d, "title"))
        return rows[rows.index("grid north") : rows.index(" date")]

    # UTM 32N, central meridian 9 E: east of it true north lies west of grid north
    assert "west" in north("EPSG:32632", 11.0)
    assert "east" in north("EPSG:32632", 7.0)
    # convergence ~ (lon - lon0) sin(lat): 2 * sin(47 deg) = 1.46 deg
    text = north("EPSG:32632", 11.0)
    angle = float(text.split("true north ")[1].split()[0])
    assert angle == pytest.approx(2 * math.sin(math.radians(47)), abs=0.02)


# --------------------------------------------------------------------------- title block, CRSs


def test_title_block(sample_map):
    d = build_drawing(sample_map, library=LIB, sources=["ZH1091.c", "ZH1091.e"], date="2025-03-04")
    rows = " ".join(t.text for t in texts(d, "title"))
    for want in (
        "ZH1091",
        "1:5000",
        "CH1903+ / LV95 (EPSG:2056)",
        "200 m, crosses",
        "2025-03-04",
        "ZH1091.c, ZH1091.e",
        "c e h r",
    ):
        assert want in rows, want
    heading = [t.text for t in texts(d, "heading")]
    assert heading[:2] == ["ZH1091", "1:5000"]
    d = build_drawing(sample_map, parse_plotdef("scale 10000"), LIB)
    assert "1:10000 (compiled at 1:5000)" in " ".join(t.text for t in texts(d, "title"))


def test_plot_date(monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    assert plot_date() == "2023-11-14"
    monkeypatch.delenv("SOURCE_DATE_EPOCH")
    assert len(plot_date()) == 10


def test_a_crs_in_feet_is_plotted_in_feet():
    m = apygis.MapFile("FT", scale=2400, crs="EPSG:2229")  # California zone 5, US feet
    m.layer("r").add_line([(6500000, 1850000, 0), (6504000, 1852500, 0)], code=1)
    d = build_drawing(m, library=LIB)
    assert d.unit == "ftUS"
    assert d.mm_per_unit == pytest.approx(0.3048006096 * 1000 / 2400)
    line = next(it for it in d.items if isinstance(it, PaperLine) and it.role == "line")
    assert np.ptp(line.points[:, 0]) == pytest.approx(4000 * d.mm_per_unit)
    assert texts(d, "scalebar")[-1].text.endswith(" ftUS")
    assert "ftUS, crosses" in " ".join(t.text for t in texts(d, "title"))


def test_a_geographic_map_is_plotted_in_utm():
    from pyproj import Transformer

    m = apygis.MapFile("GEO", scale=10000, crs="EPSG:4326")
    m.layer("r").add_line([(8.50, 47.37, 0), (8.54, 47.39, 0)], code=1)
    d = build_drawing(m, library=LIB)
    assert "UTM zone 32N" in d.crs_name
    assert "from WGS 84 (EPSG:4326)" in d.crs_name
    tr = Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True)
    (xa, xb), (ya, yb) = tr.transform([8.50, 8.54], [47.37, 47.39])
    line = next(it for it in d.items if isinstance(it, PaperLine) and it.role == "line")
    want = np.column_stack(d.to_paper([xa, xb], [ya, yb]))
    assert np.allclose(line.points, want, atol=1e-6)


def test_no_crs_is_said():
    m = apygis.MapFile("NOCRS", scale=1000)
    m.layer("r").add_line([(0, 0, 0), (100, 0, 0)], code=1)
    d = build_drawing(m, library=LIB)
    assert d.crs_name == "none (coordinates taken as metres)"
    assert "true north unknown" in " ".join(t.text for t in texts(d, "title"))


# --------------------------------------------------------------------------- control plot


def test_control_plot(sample_map):
    pts = [
        ControlPoint("9001", 2683000.0, 1247000.0),
        ControlPoint("201", 2683465.23, 1248462.84, 526.43),
    ]
    d = build_drawing(sample_map, read_plotdef(PLOTTER_DEF), LIB, control=True, control_points=pts)
    assert d.stats["layers"] == ["c"]
    assert d.stats["lines"] == 0
    assert d.stats["texts"] == 0
    c = sample_map.layers["c"].symbols
    assert d.stats["control_points"] == len(c) + 2
    labels = {t.text for t in texts(d, "control")}
    for r in c:
        assert f"{int(r['num'])}  {float(r['z']):.1f}" in labels
    assert {"9001", "201  526.4"} <= labels
    # the grid as full lines, the subtitle says what the plot is
    assert d.count(PaperLine, "grid") >= 11 + 7
    assert "control point and grid plot" in [t.text for t in texts(d, "heading")]
    marks = [it for it in d.items if isinstance(it, PaperLine) and it.role == "control"]
    ring = marks[0].points
    centre = ring.mean(axis=0)
    assert centre == pytest.approx([float(v) for v in d.to_paper(2683000.0, 1247000.0)])
