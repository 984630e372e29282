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
from tests.plot.test_plot import parse_hpgl, pdf_objects, pdf_pages


@pytest.fixture
def run(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "no-user-library.apysym"))  # the default set
    runner = CliRunner()

    def _run(*args, code=0):
        res = runner.invoke(main, [str(a) for a in args], catch_exceptions=False)
        assert res.exit_code == code, res.output
        return res

    return _run


@pytest.mark.parametrize("ext", ["pdf", "svg", "plt", "hpgl"])
def test_plot_writes_each_format(run, sample_dir, tmp_path, ext):
    out = tmp_path / f"sheet.{ext}"
    res = run("plot", sample_dir / "ZH1091", "-o", out)
    assert res.output.count("\n") == 1
    assert res.output.startswith(f"wrote {out} (")
    assert "A2 landscape (594 x 420 mm), 1:5000, layers c e h r: 18 lines, 115 symbols" in (
        res.output
    )
    data = out.read_bytes()
    if ext == "pdf":
        assert len(pdf_pages(pdf_objects(data))) == 1
    elif ext == "svg":
        assert ET.fromstring(data).get("width") == "594mm"
    else:
        assert data.startswith(b"IN;")
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
    instr = parse_hpgl(out.read_bytes())
    assert [a for op, a in instr if op == "SP"] == ["1", "2", "3", "5", "6", "0"]
    assert sum(op == "LB" for op, _ in instr) == 8 + 2


def test_plot_errors(run, sample_dir, tmp_path):
    res = run("plot", sample_dir / "ZH1091", "-o", tmp_path / "x.png", code=1)
    assert "cannot tell the plot format" in res.output
    assert not (tmp_path / "x.png").exists()
    res = run("plot", sample_dir / "ZH1091", "-o", tmp_path / "x.pdf", "--layers", "h,q", code=2)
    assert "no layer q" in res.output
    bad = tmp_path / "PLOTTER.DEF"
    bad.write_text("paper A3\n\nscale five\n")
    res = run("plot", sample_dir / "ZH1091", "-o", tmp_path / "x.pdf", "--plotter", bad, code=1)
    assert f"{bad}: line 3: scale: expected a whole number" in res.output
    assert not (tmp_path / "x.pdf").exists()
    res = run("plot", sample_dir / "ZH1091", code=2)
    assert "--output" in res.output


def test_printout_pdf_has_the_pages_the_text_needs(run, sample_dir, tmp_path):
    text = run("printout", sample_dir / "ZH1091").output
    pages = math.ceil(len(text.splitlines()) / 68)
    out = tmp_path / "listing.pdf"
    res = run("printout", sample_dir / "ZH1091", "-o", out)
    assert res.output == f"print-out of ZH1091 written to {out} ({pages} A4 pages)\n"
    got = pdf_pages(pdf_objects(out.read_bytes()))
    assert len(got) == pages
    for i, (_, content) in enumerate(got, start=1):
        assert f"(page {i} of {pages}) Tj".encode() in content
    assert b"(APY PRINT-OUT   map ZH1091" in got[0][1]
    assert re.search(rb"/BaseFont /Courier\b", out.read_bytes())
    run("printout", sample_dir / "ZH1091", "-o", out, code=1)  # no overwrite
    txt = tmp_path / "listing.txt"
    run("printout", sample_dir / "ZH1091", "-o", txt)
    assert txt.read_text(encoding="utf-8") == text
