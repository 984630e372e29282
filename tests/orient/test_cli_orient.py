"""``apygis orient map`` and ``apygis orient photos`` through click's CliRunner."""

from __future__ import annotations

import filecmp
import importlib.util
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from apygis.cli.orient import orient
from apygis.orient.io import load_orientation

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "orient"
CONTROL = SAMPLES / "ZH1091-control.txt"
MAP = SAMPLES / "ZH1091-map.txt"
PHOTOS = SAMPLES / "ZH1091-photos.txt"
PMEAS = SAMPLES / "ZH1091-photo-measurements.txt"
TRUTH = SAMPLES / "ZH1091-truth.orientation.json"


def _run(*args):
    return CliRunner().invoke(orient, [str(a) for a in args], catch_exceptions=False)


def test_samples_are_reproducible(tmp_path):
    spec = importlib.util.spec_from_file_location(
        "make_orient_samples", SAMPLES / "make_orient_samples.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.make(tmp_path)
    for f in tmp_path.iterdir():
        assert filecmp.cmp(f, SAMPLES / f.name, shallow=False), f.name


@pytest.mark.parametrize("model", ["conformal", "affine", "bilinear"])
def test_orient_map(tmp_path, model):
    out = tmp_path / "o.json"
    r = _run("map", CONTROL, MAP, "--model", model, "-o", out, "--map-id", "ZH1091")
    assert r.exit_code == 0, r.output
    assert f"Map orientation: {model}, 8 points, 16 measurements" in r.output
    assert "RMSE in position" in r.output
    assert "pointing precision" in r.output
    assert "    9003   2685400.000   1248600.000" in r.output
    o = load_orientation(out)
    assert o.map_transform.model == model
    assert o.map_id == "ZH1091"
    truth = load_orientation(TRUTH).map_transform
    t = np.array([[100.0, 100.0], [500.0, 350.0]])
    assert np.abs(o.map_transform.forward(t) - truth.forward(t)).max() < 2.0


def test_orient_map_reject_and_errors(tmp_path):
    r = _run("map", CONTROL, MAP, "--reject", "9001,9002", "--reject", "201")
    assert r.exit_code == 0
    assert "5 points" in r.output
    assert "rejected: 9001, 9002, 201" in r.output
    once = tmp_path / "once.txt"
    once.write_text("9001 60.1 50.1\n9001 60.0 50.0\n9002 540.1 46.9\n")
    r = _run("map", CONTROL, once, "--model", "conformal")
    assert r.exit_code == 1
    assert (
        "point(s) 9002 measured once; the conformal map orientation needs each point measured twice"
        in r.output
    )
    bad = tmp_path / "bad.txt"
    bad.write_text("9001 60.1 50.1\n9002 x 46.9\n")
    r = _run("map", CONTROL, bad)
    assert r.exit_code == 1
    assert "bad.txt: line 2: x_mm must be a number, got 'x'" in r.output
    r = _run("map", CONTROL, MAP, "--reject", "7777")
    assert r.exit_code == 1
    assert "cannot reject point(s) 7777" in r.output
    collinear = tmp_path / "col.txt"
    collinear.write_text("9001 60 50\n9002 540 47\n")
    r = _run("map", CONTROL, collinear)
    assert r.exit_code == 1
    assert "at least 3 different points, got 2" in r.output


def test_orient_photos_and_merge(tmp_path):
    out = tmp_path / "o.json"
    assert _run("map", CONTROL, MAP, "-o", out).exit_code == 0
    r = _run("photos", PHOTOS, CONTROL, PMEAS, "-o", out)
    assert r.exit_code == 1
    assert f"{out} exists; use --overwrite to replace it" in r.output
    r = _run("photos", PHOTOS, CONTROL, PMEAS, "-o", out, "--overwrite")
    assert r.exit_code == 0, r.output
    assert (
        "Photo 4711: 8 control spots, solved Xo, Yo, Zo, omega, phi, kappa; known sx, sy"
        in r.output
    )
    assert "Photo 4712" in r.output
    assert "RMSE in position" in r.output
    o = load_orientation(out)
    assert o.map_transform is not None
    assert len(o.photos) == 2
    truth = load_orientation(TRUTH)
    for po in o.photos:
        t = truth.photo(po.photo_id)
        assert np.abs(po.exterior.centre - t.exterior.centre).max() < 15.0
        assert (
            abs(
                np.remainder(po.exterior.kappa_rad - t.exterior.kappa_rad + np.pi, 2 * np.pi)
                - np.pi
            )
            < 1e-3
        )
    assert set(o.quality) == {"map", "photos"}
    r = _run("photos", PHOTOS, CONTROL, PMEAS, "--reject", "208")
    assert r.exit_code == 0
    assert r.output.count("7 control spots") == 2


def test_orient_photos_errors(tmp_path):
    r = _run("photos", PHOTOS, CONTROL, PMEAS, "--reject", "201,202,203,204,205")
    assert r.exit_code == 1
    assert "at least 4 control spots, got 3" in r.output
    pm = tmp_path / "pm.txt"
    pm.write_text(PMEAS.read_text() + "  201 9999 0.1 0.1\n")
    r = _run("photos", PHOTOS, CONTROL, pm)
    assert r.exit_code == 1
    assert "photo(s) 9999 not in the photo file" in r.output
    pm.write_text("  555 4711 0.1 0.1\n")
    r = _run("photos", PHOTOS, CONTROL, pm)
    assert r.exit_code == 1
    assert "measured point 555 (photo 4711) is not in the control" in r.output
    ph = tmp_path / "ph.txt"
    ph.write_text("4711 153 frame Zo~2800\n4712 153 frime\n")
    r = _run("photos", ph, CONTROL, PMEAS)
    assert r.exit_code == 1
    assert "ph.txt: line 2: the third field must be 'frame' or 'scanned'" in r.output
    out = tmp_path / "corrupt.json"
    out.write_text("{")
    r = _run("map", CONTROL, MAP, "-o", out, "--overwrite")
    assert r.exit_code == 1
    assert "corrupt.json: line 1" in r.output


def test_unwritable_output_is_a_clean_error(tmp_path):
    r = _run("map", CONTROL, MAP, "-o", tmp_path / "no" / "such" / "dir.json")
    assert r.exit_code == 1
    assert "cannot write" in r.output
