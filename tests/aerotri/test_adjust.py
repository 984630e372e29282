"""Control point measurement and the block's bundle adjustment, end to end on the tiny
synthetic block, scored against its truth.

The tiny block (2 strips x 3 images, 900 px scans of 240 mm: 0.27 mm pixels, 2.7 m on
the ground) carries a simulated operator's measurements of its control points
(``gcp.csv``: precise to 0.15 px in one image, approximate to 3 px in the others).
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from apygis.aerotri.adjust import AdjustOptions, adjust_block
from apygis.aerotri.block import Block, BlockError
from apygis.aerotri.camera import PixelTransform
from apygis.aerotri.gcp import Measurement, guide, measure, read_measurements
from apygis.aerotri.synth import load_truth
from apygis.cli import main
from apygis.errors import FormatError


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _transfer_errors(blk, truth):
    """Errors (px) of the LSM measurements of control points against the truth of the point
    their reference (precise) measurement defines: its ray on the true DEM, projected."""
    with Block.open(blk) as b:
        rows = b.conn.execute(
            "SELECT p.name, o.image, o.x_px, o.y_px, o.sigma_px, o.source FROM observations o "
            "JOIN points p ON p.id = o.point WHERE o.source IN ('manual', 'lsm-gcp')"
        ).fetchall()
    ref = {r[0]: (r[1], r[2], r[3]) for r in rows if r[5] == "manual"}
    out = []
    for name, img, x, y, s, src in rows:
        if src != "lsm-gcp":
            continue
        ri, rx, ry = ref[name]
        g = truth.ground(ri, [[rx, ry]])
        t = truth.project(img, g)[0]
        out.append((x - t[0], y - t[1], s))
    return np.array(out)


def test_semi_automatic_measurement_reaches_a_tenth_of_a_pixel(tiny_copy, tiny_block_dir):
    truth = load_truth(tiny_block_dir / "truth.json")
    r = _run("at", "gcp", tiny_copy, "--measure", tiny_block_dir / "gcp.csv")
    assert r.exit_code == 0, r.output
    assert "failed" in r.output
    e = _transfer_errors(tiny_copy, truth)
    assert len(e) >= 8, r.output
    assert np.sqrt(np.mean(e[:, :2] ** 2)) <= 0.10, e


def test_adjustment_end_to_end(tiny_copy, tiny_block_dir, tmp_path):
    """gcp -> adjust: sigma0 <= 0.1 px, the orientations within three of their estimated
    standard deviations of the truth, check points within what is expected, the report
    (Table 3), pictures and exports."""
    truth = load_truth(tiny_block_dir / "truth.json")
    assert _run("at", "gcp", tiny_copy, "--measure", tiny_block_dir / "gcp.csv").exit_code == 0
    out = tmp_path / "out"
    r = _run("at", "adjust", tiny_copy, "--report", out / "adjust.txt", "--display",
             out / "adjust.png", "--residuals", out / "residuals.png")  # fmt: skip
    assert r.exit_code == 0, r.output
    for row in ("No. of images", "2-fold points", "3-fold points", "sigma0 (um)",
                "sigma0 (px)", "Image rms x/y (um)", "Object rms x/y/z (m)"):  # fmt: skip
        assert row in r.output
    assert (out / "adjust.txt").read_text().startswith("Bundle block adjustment")
    for pic in ("adjust.png", "residuals.png"):
        assert (out / pic).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    r = _run("at", "adjust", tiny_copy, "--json")
    rep = json.loads(r.output)
    assert rep["sigma0_px"] <= 0.1
    assert rep["images"] == len(truth.images)
    assert rep["control"]["full"] >= 3
    for e in rep["exterior"]:
        t = truth.exterior[e["image"]]
        dk = (e["kappa_rad"] - t.kappa_rad + math.pi) % (2 * math.pi) - math.pi
        d = [e["X"] - t.Xo, e["Y"] - t.Yo, e["Z"] - t.Zo, e["omega_rad"] - t.omega_rad,
             e["phi_rad"] - t.phi_rad, dk]  # fmt: skip
        s = [e[k] for k in ("sX", "sY", "sZ", "somega_rad", "sphi_rad", "skappa_rad")]
        assert all(abs(a) <= 3 * b for a, b in zip(d, s, strict=True)), (e, d)
    if rep["object_rms_m"]:
        for got, exp in zip(rep["object_rms_m"], rep["object_rms_predicted_m"], strict=True):
            assert got <= 3 * exp
    # every rejection names the point, the image, its residual and why
    for x in rep["rejections"]:
        assert x["point"]
        assert x["reason"]
        assert x["w"] > 0
    r = _run("at", "export", tiny_copy, "--points", out / "points.csv", "--exterior",
             out / "exterior.csv")  # fmt: skip
    assert r.exit_code == 0, r.output
    with open(out / "exterior.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert {int(r["image"]) for r in rows} == set(truth.images)
    with open(out / "points.csv", newline="") as f:
        pts = list(csv.DictReader(f))
    assert {"C01", "C05"} <= {p["point"] for p in pts}


def test_automatic_measurement_and_guidance(tiny_copy, tiny_block_dir, tmp_path):
    """After an adjustment, a point digitised in one image only is found in all the others
    (the seed's automatic mode); the guide predicts the points still to measure."""
    truth = load_truth(tiny_block_dir / "truth.json")
    ms = read_measurements(tiny_block_dir / "gcp.csv")
    first = [m for m in ms if m.point in ("C01", "C02", "C03", "C04")]
    later = [m for m in ms if m.mode == "precise" and m.point in ("C05", "C06")]
    with Block.open(tiny_copy) as b:
        measure(b, first)
        g = guide(b, thumbnails=tmp_path / "thumbs")
        names = {p["point"] for p in g}
        assert names == {"C05", "C06"}
        adjust_block(b)
        g = guide(b, thumbnails=tmp_path / "thumbs")
        for p in g:
            assert p["prediction"] == "adjustment"
            for e in p["images"]:
                XYZ = [[p["X"], p["Y"], p["Z"]]]
                t = truth.project(e["image"], XYZ)[0]
                assert math.hypot(e["x_px"] - t[0], e["y_px"] - t[1]) < 3.0
                assert (tmp_path / "thumbs" / f"{p['point']}-{e['image']}.png").is_file()
        r = measure(b, later, automatic=True)
    assert {s[0] for s in r.stored if s[5] == "lsm-gcp"} == {"C05", "C06"}
    e = _transfer_errors(tiny_copy, truth)
    assert np.sqrt(np.mean(e[:, :2] ** 2)) <= 0.10


def test_new_points_and_manual_measurements(tiny_copy):
    with Block.open(tiny_copy) as b:
        r = measure(b, [Measurement("N1", 101, 450.0, 450.0, "manual", 0.5),
                        Measurement("N1", 102, 120.0, 450.0, "manual")])  # fmt: skip
        assert r.new_points == ["N1"]
        kind = b.conn.execute("SELECT kind FROM points WHERE name = 'N1'").fetchone()[0]
        sig = sorted(s for (s,) in b.conn.execute(
            "SELECT sigma_px FROM observations o JOIN points p ON p.id = o.point "
            "WHERE p.name = 'N1'"))  # fmt: skip
    assert kind == "new"
    assert sig == [0.3, 0.5]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("point,image,x\n", "header"),
        ("point,image,x_px,y_px,mode\nC01,101,1,2,guess\n", "mode"),
        ("point,image,x_px,y_px,mode\nC01,abc,1,2,precise\n", "line 2"),
        ("point,image,x_px,y_px,mode\nC01,101,nan,2,precise\n", "finite"),
        ("point,image,x_px,y_px,mode\n", "no measurements|line"),
    ],
)
def test_bad_measurement_files(tmp_path, text, match):
    p = tmp_path / "m.csv"
    p.write_text(text)
    with pytest.raises(FormatError, match=match):
        read_measurements(p)


def test_measurement_errors_are_one_line(tiny_copy, tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("point,image,x_px,y_px,mode\nC01,999,10,10,precise\n")
    r = CliRunner().invoke(main, ["at", "gcp", str(tiny_copy), "--measure", str(p)])
    assert r.exit_code == 1
    assert "image 999 is not in the block" in r.output
    p.write_text("point,image,x_px,y_px,mode\nC01,101,5000,10,precise\n")
    r = CliRunner().invoke(main, ["at", "gcp", str(tiny_copy), "--measure", str(p)])
    assert r.exit_code == 1
    assert "outside image 101" in r.output
    p.write_text("point,image,x_px,y_px,mode\nC01,102,100,100,approx\n")
    r = CliRunner().invoke(main, ["at", "gcp", str(tiny_copy), "--measure", str(p)])
    assert r.exit_code == 1
    assert "need one precise" in r.output


def test_no_datum_is_refused(tiny_copy):
    """Without measured control the approximate centres (from an image list: 1 m, 2 m) are
    the datum; refusing them leaves none."""
    with Block.open(tiny_copy) as b:
        rep = adjust_block(b)
        assert rep.gps_used
        assert any("no datum" in n for n in rep.notes)
        with pytest.raises(BlockError, match="no datum"):
            adjust_block(b, AdjustOptions(gps=None))


def test_gross_errors_in_the_block_are_rejected_and_named(tiny_copy, tiny_block_dir):
    """Tie point observations moved by 3-10 px are rejected (those in points of three or
    more rays) and named with their point and image."""
    assert _run("at", "gcp", tiny_copy, "--measure", tiny_block_dir / "gcp.csv").exit_code == 0
    rng = np.random.default_rng(1)
    with Block.open(tiny_copy) as b:
        rows = b.conn.execute(
            "SELECT o.point, o.image, o.x_px, o.y_px, p.name FROM observations o JOIN points p "
            "ON p.id = o.point WHERE o.source = 'lsm' AND o.point IN (SELECT point FROM "
            "observations GROUP BY point HAVING COUNT(*) >= 4)"
        ).fetchall()
        pick = [rows[i] for i in rng.choice(len(rows), 40, replace=False)]
        T = {n: PixelTransform.from_list(v["transform"]) for n, v in b.interior().items()}
        with b.conn:
            for pid, img, x, y, _ in pick:
                a, d = rng.uniform(0, 2 * math.pi), rng.uniform(3, 10)
                px = (x + d * math.cos(a), y + d * math.sin(a))
                mm = T[img].to_mm([px])[0]
                b.conn.execute(
                    "UPDATE observations SET x_px = ?, y_px = ?, x_mm = ?, y_mm = ? "
                    "WHERE point = ? AND image = ?",
                    (px[0], px[1], float(mm[0]), float(mm[1]), pid, img),
                )
        rep = adjust_block(b).to_dict()
    found = {(x["point"], x["image"]) for x in rep["rejections"] if x["image"] is not None}
    moved = {(name, img) for _, img, _, _, name in pick}
    assert len(moved & found) >= 0.95 * len(moved)
    assert rep["sigma0_px"] <= 0.1


def test_a_block_without_approximate_centres_is_chained(tiny_copy, tiny_block_dir):
    """No projection centres at all: relative orientations, resections and an absolute
    orientation on the control give the approximate values; the adjustment then finds the
    truth within three of its standard deviations."""
    truth = load_truth(tiny_block_dir / "truth.json")
    with Block.open(tiny_copy) as b:
        measure(b, read_measurements(tiny_block_dir / "gcp.csv"))
        b.update_images({im.image: {"X": None, "Y": None, "Z": None} for im in b.images()})
        rep = adjust_block(b, AdjustOptions(restart=True))
    assert any("chain of relative orientations" in n for n in rep.notes)
    assert not rep.gps_used
    for e in rep.exterior:
        t = truth.exterior[e["image"]]
        for a, b_, s in ((e["X"], t.Xo, e["sX"]), (e["Y"], t.Yo, e["sY"]), (e["Z"], t.Zo, e["sZ"])):
            assert abs(a - b_) <= 3 * s


def test_models_for_compilation(tiny_copy, tiny_block_dir, tmp_path):
    """Every strip pair becomes an orientation file that the session's geometry loads: the
    photos' adjusted orientations, their split into relative and absolute orientation (which
    composes back exactly), the instrument's map orientation and stage motors; a tie point of
    the model seen through the real-time loop lands on its measurements."""
    from apygis.aerotri.models import split_model, stereo_models
    from apygis.compile.oriented import OrientedGeometry
    from apygis.orient.collinearity import ExteriorOrientation
    from apygis.orient.io import load_orientation, save_orientation
    from apygis.orient.realtime import MotorCalibration
    from apygis.orient.transforms import AffineTransform

    assert _run("at", "gcp", tiny_copy, "--measure", tiny_block_dir / "gcp.csv").exit_code == 0
    assert _run("at", "adjust", tiny_copy).exit_code == 0
    with Block.open(tiny_copy) as b:
        models = stereo_models(b)
        ext = {r[0]: r[1:] for r in b.conn.execute(
            "SELECT image, X, Y, Z, omega, phi, kappa FROM exterior")}  # fmt: skip
        X0, Y0 = np.mean([v[0] for v in ext.values()]), np.mean([v[1] for v in ext.values()])
    assert len(models) == 4  # two strips of three images
    # an instrument file: a map orientation over the block (5 m per tablet mm) and two stages
    from apygis.orient.io import Orientation

    inst = Orientation(
        map_transform=AffineTransform(5.0, 0.0, X0 - 1000.0, 0.0, 5.0, Y0 - 1000.0),
        motors=(MotorCalibration("L", step_um=2.0), MotorCalibration("R", step_um=2.0)),
    )
    save_orientation(inst, tmp_path / "plotter.json")
    out = tmp_path / "models"
    r = _run("at", "export", tiny_copy, "--models", out, "--instrument", tmp_path / "plotter.json")
    assert r.exit_code == 0, r.output
    assert f"{len(models)} stereo models" in r.output
    r = CliRunner().invoke(main, ["at", "export", str(tiny_copy), "--models", str(out)])
    assert r.exit_code == 1
    assert "exists" in r.output
    a, b_ = models[0]
    o = load_orientation(out / f"model-{a}-{b_}.json")
    assert [p.photo_id for p in o.photos] == [str(a), str(b_)]
    left, right = o.photos[0].exterior, o.photos[1].exterior
    split = split_model(left, right)
    l2, r2 = split.compose()
    np.testing.assert_allclose(l2.parameters, left.parameters, atol=1e-9)
    np.testing.assert_allclose(r2.centre, right.centre, atol=1e-6)
    np.testing.assert_allclose(r2.rotation, right.rotation, atol=1e-12)
    assert o.quality["model"]["relative"]["bx"] == 1.0
    np.testing.assert_allclose(ExteriorOrientation(*ext[a]).parameters, left.parameters)
    geo = OrientedGeometry(o)
    assert geo.loop is not None
    # a tie point of the model: the loop's photo coordinates are its measurements plus the
    # adjustment's residuals there (projection minus measurement, px; a pixel is 0.23 mm)
    with Block.open(tiny_copy) as b:
        row = b.conn.execute(
            "SELECT ap.point, ap.X, ap.Y, ap.Z FROM adjusted_points ap "
            "JOIN observations o1 ON o1.point = ap.point AND o1.image = ? "
            "JOIN observations o2 ON o2.point = ap.point AND o2.image = ? LIMIT 1", (a, b_),
        ).fetchone()  # fmt: skip
        seen = {}
        for image in (a, b_):
            x, y, vx, vy = b.conn.execute(
                "SELECT o.x_mm, o.y_mm, r.vx_px, r.vy_px FROM observations o JOIN residuals r "
                "ON r.point = o.point AND r.image = o.image WHERE o.point = ? AND o.image = ?",
                (row[0], image),
            ).fetchone()
            (tr,) = b.conn.execute(
                "SELECT transform FROM interior WHERE image = ?", (image,)
            ).fetchone()
            linear = np.reshape(json.loads(tr), (3, 3))[:2, :2]  # pixel -> mm
            seen[image] = (x, y, linear @ [vx, vy])
    u = geo.loop.update(row[1], row[2], row[3])
    for (x, y), image in (((u.x_left, u.y_left), a), ((u.x_right, u.y_right), b_)):
        mx, my, residual_mm = seen[image]
        np.testing.assert_allclose([x - mx, y - my], residual_mm, atol=0.001)
    assert all(isinstance(v, int) for v in geo.plates(row[1], row[2], row[3]))


def test_point_sketches(tiny_copy, tiny_block_dir, tmp_path):
    """One PDF page per measured control point, with its name, coordinates and images."""
    import re
    import shutil
    import subprocess

    assert _run("at", "gcp", tiny_copy, "--measure", tiny_block_dir / "gcp.csv").exit_code == 0
    assert _run("at", "adjust", tiny_copy).exit_code == 0
    out = tmp_path / "s" / "sketches.pdf"
    r = _run("at", "sketch", tiny_copy, "-o", out)
    assert r.exit_code == 0, r.output
    n = int(re.search(r"(\d+) point sketches", r.output).group(1))
    with Block.open(tiny_copy) as b:
        measured = b.conn.execute(
            "SELECT COUNT(DISTINCT o.point) FROM observations o JOIN points p ON p.id = o.point "
            "WHERE p.kind != 'tie'"
        ).fetchone()[0]
    assert n == measured
    data = out.read_bytes()
    assert data.startswith(b"%PDF")
    assert len(re.findall(rb"/Type\s*/Page\b", data)) == n
    r = _run("at", "sketch", tiny_copy, "-o", out, "--points", "C01,NOPE")
    assert r.exit_code == 1
    assert "NOPE" in r.output
    if shutil.which("pdftotext"):
        text = subprocess.run(["pdftotext", str(out), "-"], capture_output=True, text=True).stdout
        assert re.search(r"Point\s+C01", text)
        assert "full control point" in text
        assert "adjusted" in text


def test_subblocks_are_adjusted_as_tasks_then_joined(tiny_copy, tiny_block_dir):
    """Each subblock is adjusted on its own (a task), the whole block then starts from their
    results; a subblock without a datum of its own is reported and the rest goes on."""
    assert _run("at", "gcp", tiny_copy, "--measure", tiny_block_dir / "gcp.csv").exit_code == 0
    with Block.open(tiny_copy) as b:
        b.set_subblocks([[1, 2], [2]])
        rep = adjust_block(b, AdjustOptions(subblocks=True, scheduler="sync"))
        whole = adjust_block(b, AdjustOptions(restart=True))
    subs = {s["subblock"]: s for s in rep.subblocks}
    assert (subs[1]["images"], subs[2]["images"]) == (6, 3)
    assert subs[1]["sigma0"] > 0
    # strip 2 alone holds too little control for a datum: reported, the rest goes on
    assert "datum" in subs[2]["error"]
    for e, w in zip(rep.exterior, whole.exterior, strict=True):
        assert abs(e["X"] - w["X"]) < 0.1 * e["sX"]  # the same solution either way
    r = CliRunner().invoke(main, ["at", "adjust", str(tiny_copy), "--subblocks", "--scheduler",
                                  "sync"])  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "Subblocks" in r.output


def test_self_calibration_auto_frees_only_what_the_block_determines(tiny_copy, tiny_block_dir):
    """'--calibrate auto' on a two-strip block of vertical photos: the principal distance
    and point go with the projection centres (fixed again, with the correlation named);
    what stays free is reported with its precision and correlations."""
    assert _run("at", "gcp", tiny_copy, "--measure", tiny_block_dir / "gcp.csv").exit_code == 0
    r = _run("at", "adjust", tiny_copy, "--calibrate", "auto", "--json")
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    fixed = [n for n in rep["notes"] if "is not determined by this block" in n]
    insignificant = [n for n in rep["notes"] if "is determined but not significant" in n]
    assert fixed
    assert any(" c is not determined" in n for n in fixed)
    assert len(fixed) + len(insignificant) + len(rep["calibration"]) == 9  # film: b1, b2 too
    for c in rep["calibration"]:
        assert c["std"] is not None
        assert abs(c["value"] - c["initial"]) >= 3 * c["std"]
        assert c["max_corr_orientation"] <= 0.9
        assert all(abs(v) <= 0.9 for v in c["corr"].values())
    bad = CliRunner().invoke(main, ["at", "adjust", str(tiny_copy), "--calibrate", "k9"])
    assert bad.exit_code == 1
    assert "k9" in bad.output
