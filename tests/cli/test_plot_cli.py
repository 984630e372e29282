"""``apygis plot`` and ``apygis printout -o NAME.pdf`` as a user runs them."""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET

import pytest
from click.testing import CliRunner

from apygis.cli import main
from apygis.model.symbols import ENV_VAR
from tests.conftest import SAMPLES
from tests.plot import hpgl_view
from tests.plot.helpers import run_tool

SUMMARY = "A2 landscape (594 x 420 mm), 1:5000, layers c e h r: 18 lines, 115 symbols"


@pytest.fixture
def run(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "no-user-library.apysym"))  # the default set
    runner = CliRunner()

    def _run(*args, code=0):
        res = runner.invoke(main, [str(a) for a in args], catch_exceptions=False)
        assert res.exit_code == code, res.output
        return res

    return _run


@pytest.mark.parametrize("ext", ["pdf", "svg", "plt", "hpgl", "png", "tif"])
def test_plot_writes_each_format(run, sample_dir, tmp_path, ext):
    out = tmp_path / f"sheet.{ext}"
    res = run("plot", sample_dir / "ZH1091", "-o", out, "--dpi", "50")
    assert res.output.count("\n") == 1
    assert res.output.startswith(f"wrote {out} (")
    assert SUMMARY in res.output
    assert "110 labels" in res.output
    assert "all placed free" in res.output
    data = out.read_bytes()
    if ext == "pdf":
        assert data.startswith(b"%PDF-")
    elif ext == "svg":
        assert ET.fromstring(data).get("width") == "594mm"
    elif ext == "png":
        assert data.startswith(b"\x89PNG")
        assert "(PNG, 50 dpi)" in res.output
    elif ext == "tif":
        assert data[:4] in (b"II*\x00", b"MM\x00*")
    else:
        assert data.startswith(b"IN;")
        assert "(HP-GL)" in res.output
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries left


def test_plot_refuses_to_overwrite(run, sample_dir, tmp_path):
    out = tmp_path / "sheet.svg"
    out.write_text("keep me")
    res = run("plot", sample_dir / "ZH1091", "-o", out, code=1)
    assert "exists; use --overwrite" in res.output
    assert out.read_text() == "keep me"
    run("plot", sample_dir / "ZH1091", "-o", out, "--overwrite")
    assert out.read_bytes().startswith(b"<?xml")


def test_plot_with_plotter_def_and_layers(run, sample_dir, tmp_path):
    out = tmp_path / "hr.plt"
    res = run(
        "plot",
        sample_dir / "ZH1091",
        "-o",
        out,
        "--plotter",
        SAMPLES / "PLOTTER.DEF",
        "--layers",
        "h, R",
    )
    assert "layers h r: 18 lines, 9 symbols (0 spot heights), 8 texts" in res.output
    plot = hpgl_view.interpret(out.read_bytes(), version=1)
    assert [a for op, a in plot.instructions if op == "SP"] == ["1", "2", "3", "5", "6", "0"]
    texts = {lab.text for lab in plot.labels}
    assert {"Kirchweg", "Dorfbach", "Weiher", "ZH1091", "1:5000"} <= texts


def test_plot_options_override_the_plotter_def(run, sample_dir, tmp_path):
    out = tmp_path / "x.svg"
    res = run(
        "plot",
        sample_dir / "ZH1091",
        "-o",
        out,
        "--plotter",
        SAMPLES / "PLOTTER.DEF",
        "--scale",
        "10000",
        "--paper",
        "A3",
        "--bbox",
        "2683000,1247000,2685400,1248600",
        "--grid",
        "lines",
        "--grid-interval",
        "500",
    )
    assert "A3 landscape (420 x 297 mm), 1:10000" in res.output
    root = ET.fromstring(out.read_bytes())
    ns = {"s": "http://www.w3.org/2000/svg"}
    grid = [t.text for t in root.findall("s:text[@data-role='grid-label']", ns)]
    assert "2683500" in grid
    assert "2684000" in grid
    assert all(int(v) % 500 == 0 for v in grid)


def test_hpgl2_on_request(run, sample_dir, tmp_path):
    out = tmp_path / "x.hpgl"
    res = run("plot", sample_dir / "ZH1091", "-o", out, "--hpgl", "2")
    assert "(HP-GL/2)" in res.output
    plot = hpgl_view.interpret(out.read_bytes(), version=2)
    assert plot.widths_mm
    assert plot.colours


def test_control_plot_from_the_map_and_a_file(run, sample_dir, tmp_path):
    out = tmp_path / "control.svg"
    res = run("plot", sample_dir / "ZH1091", "-o", out, "--control")
    assert "layers c: 0 lines, 10 symbols (0 spot heights), 0 texts, 10 control points" in (
        res.output
    )
    control = SAMPLES / "orient" / "ZH1091-control.txt"
    res = run("plot", sample_dir / "ZH1091", "-o", out, "--control-file", control, "--overwrite")
    n = sum(1 for ln in control.read_text().splitlines() if ln.strip() and ln[0] != "#")
    assert f"{10 + n} control points" in res.output
    root = ET.fromstring(out.read_bytes())
    ns = {"s": "http://www.w3.org/2000/svg"}
    labels = [t.text for t in root.findall("s:text[@data-role='control']", ns)]
    assert "9001" in labels
    assert any(t.startswith("201  526.4") for t in labels)
    bad = tmp_path / "bad.txt"
    bad.write_text("201 2683465.23\n")
    res = run(
        "plot", sample_dir / "ZH1091", "-o", tmp_path / "c2.svg", "--control-file", bad, code=1
    )
    assert f"{bad}: line 1: expected 4 fields" in res.output
    assert "Traceback" not in res.output


def test_src_crs_and_a_map_without_scale(run, tmp_path):
    import apygis

    m = apygis.MapFile("FOREIGN")
    m.layer("r").add_line([(2683000, 1247000, 0), (2684000, 1247600, 0)], code=1)
    apygis.write(m, tmp_path / "f.gpkg")
    out = tmp_path / "f.pdf"
    res = run("plot", tmp_path / "f.gpkg", "-o", out, "--src-crs", "EPSG:2056")
    assert "A3" in res.output  # no scale anywhere: the largest round scale that fits A3
    res = run("plot", tmp_path / "f.gpkg", "-o", out, "--scale", "2500", "--overwrite")
    assert "1:2500" in res.output
    res = run(
        "plot", tmp_path / "f.gpkg", "-o", out, "--src-crs", "EPSG:99999999", "--overwrite", code=1
    )
    assert "not a coordinate reference system: 'EPSG:99999999'" in res.output


def test_plot_errors(run, sample_dir, tmp_path):
    res = run("plot", sample_dir / "ZH1091", "-o", tmp_path / "x.jpg", code=1)
    assert "cannot tell the plot format" in res.output
    assert not (tmp_path / "x.jpg").exists()
    res = run("plot", sample_dir / "ZH1091", "-o", tmp_path / "x.pdf", "--layers", "h,q", code=2)
    assert "no layer q" in res.output
    bad = tmp_path / "PLOTTER.DEF"
    bad.write_text("paper A3\n\nscale five\n")
    res = run("plot", sample_dir / "ZH1091", "-o", tmp_path / "x.pdf", "--plotter", bad, code=1)
    assert f"{bad}: line 3: scale: expected a whole number" in res.output
    assert not (tmp_path / "x.pdf").exists()
    res = run("plot", sample_dir / "ZH1091", code=2)
    assert "--output" in res.output
    for opt, value, words in [
        ("--bbox", "1,2,3", "expected four numbers"),
        ("--bbox", "5,5,1,1", "lower-left corner then the upper-right"),
        ("--paper", "letter", "expected A0-A4"),
        ("--scale", "0", "0 is not in the range"),
        ("--grid", "dots", "'dots' is not one of"),
        ("--dpi", "5", "5.0 is not in the range"),
    ]:
        res = run("plot", sample_dir / "ZH1091", "-o", tmp_path / "x.png", opt, value, code=2)
        assert words in res.output, (opt, res.output)
    res = run("plot", sample_dir / "ZH1091", "-o", tmp_path / "x.png", "--dpi", "2400", code=1)
    assert "use " in res.output
    assert "dpi or less" in res.output
    assert not (tmp_path / "x.png").exists()


def test_plot_vocabulary(run, sample_dir, tmp_path):
    short = run("plot", "-h").output
    assert short == run("plot", "--help").output
    for opt in (
        "-o, --output",
        "--overwrite",
        "--scale",
        "--paper",
        "--bbox",
        "--control",
        "--dpi",
        "--hpgl",
        "--src-driver",
        "--src-crs",
    ):
        assert opt in short, opt
    out = tmp_path / "v.svg"
    res = run("plot", sample_dir / "ZH1091", "-o", out, "-q")
    assert res.output.startswith("wrote ")


@pytest.mark.poppler
def test_plot_pdf_of_every_script(run, tmp_path):
    import apygis

    m = apygis.MapFile("EU", scale=25000, crs="EPSG:3035")
    r = m.layer("r")
    r.add_line([(4200000, 3000000, 0), (4210000, 3004000, 0)], code=11)
    for i, t in enumerate(("Zürich", "Łódź", "Ελλάδα", "Plzeň")):
        r.add_text(4201000 + 2000 * i, 3001500 + 500 * i, 0, t)
    apygis.write(m, tmp_path / "eu.gpkg")
    out = tmp_path / "eu.pdf"
    run("plot", tmp_path / "eu.gpkg", "-o", out)
    text = run_tool("pdftotext", "-raw", str(out), "-").stdout.decode("utf-8")
    for word in ("Zürich", "Łódź", "Ελλάδα", "Plzeň"):
        assert word in text
    res = run("plot", tmp_path / "eu.gpkg", "-o", tmp_path / "eu.plt")
    assert "4 labels drawn as outlines" in res.output


def test_printout_pdf_has_the_pages_the_text_needs(run, sample_dir, tmp_path):
    text = run("printout", sample_dir / "ZH1091").output
    pages = math.ceil(len(text.splitlines()) / 68)
    out = tmp_path / "listing.pdf"
    res = run("printout", sample_dir / "ZH1091", "-o", out)
    assert res.output == f"print-out of ZH1091 written to {out} ({pages} A4 pages)\n"
    data = out.read_bytes()
    assert len(re.findall(rb"/Type\s*/Page\b", data)) == pages
    assert b"DejaVuSansMono" in data
    run("printout", sample_dir / "ZH1091", "-o", out, code=1)  # no overwrite
    txt = tmp_path / "listing.txt"
    run("printout", sample_dir / "ZH1091", "-o", txt)
    assert txt.read_text(encoding="utf-8") == text


class _Bar:
    """A stand-in for the terminal's progress bar that keeps what it was told."""

    made: list[_Bar] = []  # noqa: RUF012

    def __init__(self, length, label):
        self.length, self.label, self.pos, self.updates = length, label, 0, []
        _Bar.made.append(self)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def update(self, n):
        self.pos += n
        self.updates.append(self.pos)


@pytest.mark.parametrize("ext", ["pdf", "png", "svg"])
def test_plot_shows_progress_on_a_terminal(run, sample_dir, tmp_path, monkeypatch, ext):
    import apygis.cli.plot as plot_cli

    _Bar.made.clear()
    monkeypatch.setattr(plot_cli, "progress_bar", _Bar)
    run("plot", sample_dir / "ZH1091", "-o", tmp_path / f"p.{ext}", "--dpi", "40")
    (bar,) = _Bar.made
    assert bar.label == "plotting ZH1091"
    assert bar.updates == sorted(bar.updates)
    assert bar.pos == bar.length  # the bar ends full
    assert len(set(bar.updates)) > 5  # and moved on the way: layout and rendering


def test_printout_pdf_shows_progress(run, sample_dir, tmp_path, monkeypatch):
    import apygis.cli.printout as printout_cli

    _Bar.made.clear()
    monkeypatch.setattr(printout_cli, "progress_bar", _Bar)
    run("printout", sample_dir / "ZH1091", "-o", tmp_path / "p.pdf")
    (bar,) = _Bar.made
    assert bar.pos == bar.length
    assert len(bar.updates) > 3


def test_control_plot_of_a_map_without_a_control_layer_is_a_grid_plot(run, sample_dir, tmp_path):
    out = tmp_path / "grid.svg"
    res = run(
        "plot",
        sample_dir / "ZH1091",
        "-o",
        out,
        "--control",
        "--layers",
        "e",
        "--bbox",
        "2683000,1247000,2685400,1248600",
    )
    assert "layers e: 0 lines, 96 symbols" in res.output
    import apygis

    m = apygis.MapFile("BARE", scale=5000, crs="EPSG:2056")
    m.layer("r").add_line([(2683000, 1247000, 0), (2684000, 1248000, 0)], code=1)
    apygis.write(m, tmp_path / "bare.gpkg")
    res = run("plot", tmp_path / "bare.gpkg", "-o", out, "--control", "--overwrite")
    assert "layers none: 0 lines, 0 symbols" in res.output
    root = ET.fromstring(out.read_bytes())
    ns = {"s": "http://www.w3.org/2000/svg"}
    assert len(root.findall("s:polyline[@data-role='grid']", ns)) >= 8  # the grid, as lines
    assert root.findall("s:text[@data-role='grid-label']", ns)
