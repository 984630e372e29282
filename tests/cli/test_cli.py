"""The command line as a user runs it: formats, info, convert, validate, printout."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest
from click.testing import CliRunner

import apygis
from apygis.cli import main
from tests.conftest import SAMPLES


@pytest.fixture
def run():
    runner = CliRunner()

    def _run(*args, code=0):
        res = runner.invoke(main, [str(a) for a in args], catch_exceptions=False)
        assert res.exit_code == code, res.output
        return res

    return _run


def test_formats_lists_drivers_with_modes(run):
    out = run("formats").output
    assert "apy        rw" in out
    assert ".apa" in out
    d = json.loads(run("formats", "--json").output)
    assert d["ascii"] == {
        "modes": "rw",
        "extensions": ["apa"],
        "description": d["ascii"]["description"],
        "stdout": True,
        "options": [
            {
                "name": "CUT_TEXTS",
                "mode": "w",
                "kind": "bool",
                "choices": [],
                "flag": None,
                "help": "cut texts to APY's 24 characters",
            }
        ],
    }
    assert d["gpkg"]["stdout"] is False
    assert {o["name"] for o in d["dxf"]["options"]} >= {"CHORD_M", "POINT_CODE", "VERSION"}
    text = run("formats", "--options").output
    assert "--co VERSION=R2010|R2013|R2018" in text
    assert "--code-field" in text


def test_info_json_matches_what_the_sample_script_made(run, sample_dir):
    expected = json.loads((sample_dir / "ZH1091.expected.json").read_text())
    for target in (sample_dir / "ZH1091", sample_dir / "ZH1091.apa"):
        info = json.loads(run("info", "--json", target).output)
        assert info["id"] == expected["id"]
        assert info["scale"] == expected["scale"]
        assert info["crs"] == expected["crs"]
        assert info["crs_name"] == "CH1903+ / LV95"
        assert info["valid"] is True
        assert info["errors"] == info["warnings"] == 0
        for ext, counts in expected["layers"].items():
            got = info["layers"][ext]
            assert {k: got[k] for k in counts} == counts, ext
            assert got["issues"] == []
        r = info["layers"]["r"]
        assert r["capacity_pct"]["line_points"] == round(100 * r["line_points"] / 10000, 2)
        e = info["extent"]
        assert 2_683_000 <= e["xmin"] < e["xmax"] <= 2_685_400
        assert 1_247_000 <= e["ymin"] < e["ymax"] <= 1_248_600
        assert info["totals"]["symbols"] == sum(v["symbols"] for v in expected["layers"].values())


def test_info_text_is_readable(run, sample_dir):
    out = run("info", sample_dir / "ZH1091").output
    assert "map ZH1091" in out
    assert "1:5000" in out
    assert "EPSG:2056 (CH1903+ / LV95)" in out
    assert "no validation findings" in out


def test_convert_round_trip_and_overwrite_protection(run, sample_dir, tmp_path):
    out = tmp_path / "sheet.apa"
    res = run("convert", sample_dir / "ZH1091", out)
    assert "4 layers" in res.output
    res = run("convert", sample_dir / "ZH1091", out, code=1)
    assert "exists; use --overwrite" in res.output
    run("convert", sample_dir / "ZH1091", out, "--overwrite")
    run("convert", out, tmp_path / "bin" / "ZH1091")
    for ext in "cehr":
        assert (tmp_path / "bin" / f"ZH1091.{ext}").read_bytes() == (
            sample_dir / f"ZH1091.{ext}"
        ).read_bytes()
    res = run("convert", out, tmp_path / "bin" / "ZH1091", code=1)
    assert "ZH1091.c" in res.output
    res = run("convert", out, tmp_path / "x.apa", "--driver", "nope", code=1)
    assert "no driver named 'nope'" in res.output


def test_validate_exit_codes(run, sample_dir, tmp_path):
    res = run("validate", sample_dir / "ZH1091")
    assert "valid: 0 errors" in res.output
    m = apygis.read(sample_dir / "ZH1091.apa")
    text = (sample_dir / "ZH1091.apa").read_text()
    # break one reference: point 2 of the stream no longer points back to point 1
    table = text.index("LINEPOINTS", text.index("LAYER h"))
    row = text.index("\n0002 ", table) + 1
    broken = text[:row] + text[row : row + 46] + "0009" + text[row + 50 :]
    (tmp_path / "broken.apa").write_text(broken)
    res = run("validate", tmp_path / "broken.apa", code=1)
    assert (
        "layer h: error: line point 1: fwd reference 2, but point 2 has no backward" in res.output
    )
    assert "INVALID" in res.output
    assert m.layers["h"].validate() == []


def test_unreadable_input_is_one_clear_line(run, tmp_path):
    bad = tmp_path / "bad.apa"
    bad.write_text("APY ASCII 1\nMAP T\nLAYER r\nSYMBOLS 1\n0001 nonsense\nEND\n")
    res = run("info", bad, code=1)
    assert res.output.startswith("Error: ")
    assert "line 5" in res.output
    assert "Traceback" not in res.output


def test_printout_to_stdout_and_file(run, sample_dir, tmp_path):
    out = run("printout", sample_dir / "ZH1091").output
    assert out.startswith("APY PRINT-OUT   map ZH1091   scale 1:5000   CRS EPSG:2056")
    assert "SYMBOL LEGEND" in out
    assert "01  trig point" in out
    assert "LINE POINTS (112)" in out
    assert "Dorfbach" in out
    f = tmp_path / "listing.txt"
    run("printout", sample_dir / "ZH1091", "-o", f)
    assert f.read_text() == out
    assert "exists" in run("printout", sample_dir / "ZH1091", "-o", f, code=1).output


def test_console_script_is_installed(sample_dir):
    exe = shutil.which("apygis")
    cmd = [exe] if exe else [sys.executable, "-m", "apygis"]
    res = subprocess.run(
        [*cmd, "-q", "info", "--json", str(sample_dir / "ZH1091")],
        capture_output=True,
        text=True,
        check=True,
    )
    assert json.loads(res.stdout)["id"] == "ZH1091"


def test_bundled_samples_are_what_the_script_makes(sample_dir):
    """The committed samples are current: re-running the script gives the same bytes."""
    for name in (
        "ZH1091.c",
        "ZH1091.e",
        "ZH1091.h",
        "ZH1091.r",
        "ZH1091.apa",
        "ZH1091.expected.json",
    ):
        assert (SAMPLES / name).read_bytes() == (sample_dir / name).read_bytes(), name
