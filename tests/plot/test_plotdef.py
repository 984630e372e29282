"""PLOTTER.DEF: the sample file, every key, the precedence of pen rules, and the errors."""

from __future__ import annotations

import pytest

from apygis.errors import FormatError
from apygis.plot.plotdef import (
    PaperSpec,
    PenRule,
    PlotterDef,
    parse_paper,
    parse_plotdef,
    read_plotdef,
)
from tests.plot.helpers import PLOTTER_DEF


@pytest.fixture
def plotdef():
    return read_plotdef(PLOTTER_DEF)


def test_sample_plotter_def_is_read(plotdef):
    assert plotdef.paper == PaperSpec("A2", "landscape")
    assert plotdef.paper.size_mm() == (594.0, 420.0)
    assert plotdef.scale == 5000
    assert plotdef.origin is None
    assert plotdef.window == (2683000.0, 1247000.0, 2685400.0, 1248600.0)
    assert plotdef.margins_mm == (15.0, 15.0, 15.0, 15.0)
    assert plotdef.symbol_size_mm == 3.0
    assert plotdef.text_height_mm == 2.5
    assert (plotdef.grid, plotdef.grid_interval, plotdef.grid_pen) == ("crosses", 200.0, 5)
    assert plotdef.title
    assert plotdef.legend
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
    d = PlotterDef.default()
    assert (d.margins_mm, d.grid, d.grid_interval, d.window, d.origin) == (
        (10.0,) * 4,
        "crosses",
        None,
        None,
        None,
    )


def test_values_and_comments():
    pdef = parse_plotdef(
        "\ufeffPAPER 600 x 400 mm   # custom\n"
        "scale 1:2500 ; a comment\n"
        "margin 10 20 30 40\n"
        "pendef 7 #A0b0C0 0.13   ; hex colour is no comment\n"
        "pen * 21 7 lines\n"
        "Title Off\n"
        "legend no\n"
        "grid LINES\n"
        "grid_interval 250\n"
        "grid-pen 7\n"
        "window 10 20 1010.5 820\n"
        "frame no\n"
        "height-decimals 2\r\n"
    )
    assert pdef.paper.size_mm() == (600.0, 400.0)
    assert pdef.paper.label() == "600 x 400 mm"
    assert pdef.scale == 2500
    assert pdef.margins_mm == (10.0, 20.0, 30.0, 40.0)
    assert pdef.pens[7].colour == (0xA0, 0xB0, 0xC0)
    assert pdef.title is False
    assert pdef.legend is False
    assert (pdef.grid, pdef.grid_interval, pdef.grid_pen) == ("lines", 250.0, 7)
    assert pdef.window == (10.0, 20.0, 1010.5, 820.0)
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
    custom = parse_plotdef(
        "paper 500x300\nscale 1000\ntitle off\nmargin 5\nwindow 1 2 3 4.25\n"
        "grid off\ngrid-interval 0.5\nlegend off\ngrid-pen 2\n"
    )
    assert parse_plotdef(custom.to_text()) == custom
    assert parse_plotdef(read_plotdef(PLOTTER_DEF).to_text()) == read_plotdef(PLOTTER_DEF)


def test_parse_paper():
    assert parse_paper("a3") == PaperSpec("A3", None)
    assert parse_paper("A1 Portrait").size_mm() == (594.0, 841.0)
    assert parse_paper("700x500").size_mm() == (700.0, 500.0)
    with pytest.raises(ValueError, match="expected A0-A4, auto or a size"):
        parse_paper("letter")


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
        ("window 1 2 3\n", 1, "window: expected ground X0 Y0 X1 Y1"),
        ("window 0 0 -5 10\n", 1, "X1 > X0 and Y1 > Y0"),
        ("window 0 0 10 10\norigin 5 5\n", 2, "'origin' and 'window' both"),
        ("origin 5 5\n\nwindow 0 0 10 10\n", 3, "'origin' and 'window' both"),
        ("grid dots\n", 1, "grid: expected one of crosses, lines, off"),
        ("grid-interval 0\n", 1, "outside (0, 1e+09]"),
        ("legend maybe\n", 1, "expected 'on' or 'off'"),
        ("\ngrid-pen 42\n", 2, "grid-pen 42 is not defined"),
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
    # a small bottom margin is fine: the title block sits in the margin panel
    assert parse_plotdef("margin 5\n").margins_mm == (5.0,) * 4
