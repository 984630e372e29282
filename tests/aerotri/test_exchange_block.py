"""A block exchanged with other programs: exported from the block database in every format
(read back by apygis and, for COLMAP, by pycolmap), a COLMAP model imported as a block and
adjusted, control measurements imported from OpenDroneMap and MicMac files."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from apygis.aerotri.adjust import adjust_block
from apygis.aerotri.block import Block
from apygis.aerotri.exchange import bluh, micmac, odm, patb
from apygis.aerotri.exchange.convert import block_to_exchange
from apygis.aerotri.gcp import measure, read_measurements
from apygis.aerotri.synth import SynthSpec, load_truth, synth_block
from apygis.cli import main


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture
def adjusted(tiny_copy, tiny_block_dir):
    with Block.open(tiny_copy) as b:
        b.set_meta("crs", "EPSG:2056")  # the synthetic blocks' (at synth prints it)
        measure(b, read_measurements(tiny_block_dir / "gcp.csv"))
        adjust_block(b)
    return tiny_copy


def test_every_format_is_exported_and_reads_back(adjusted, tmp_path):
    out = tmp_path / "x"
    r = CliRunner().invoke(main, ["at", "export", str(adjusted), "--bluh", str(out / "b")])
    assert r.exit_code == 1  # control names such as C01 are no BLUH point numbers
    assert "C01" in r.output
    r = _run(
        "at",
        "export",
        adjusted,
        "--patb",
        out / "b",
        "--bluh",
        out / "b",
        "--renumber",
        "--colmap",
        out / "colmap",
        "--odm",
        out / "gcp_list.txt",
        "--micmac",
        out / "mm",
    )
    assert r.exit_code == 0, r.output
    names = (out / "b.names.csv").read_text().splitlines()
    assert names[0] == "name,number"
    assert "C01,9000000" in "".join(names)
    with Block.open(adjusted) as b:
        xb = block_to_exchange(b)
        n_rej = b.conn.execute("SELECT COUNT(*) FROM residuals WHERE rejected = 1").fetchone()[0]
        n_obs = b.conn.execute("SELECT COUNT(*) FROM observations").fetchone()[0]
        control = {n for (n,) in b.conn.execute(
            "SELECT name FROM points WHERE kind IN ('full', 'planimetric')")}  # fmt: skip
    assert len(xb.observations) == n_obs - n_rej
    if n_rej:
        assert f"left out: {n_rej} observations rejected" in r.output
    back = patb.read_patb(out / "b")
    assert len(back.observations) == len(xb.observations)
    assert {im.image for im in back.images if im.eo is not None} == {
        im.image for im in xb.images if im.eo is not None
    }
    # the orientations as PAT-B holds them (.ori: centres to 0.01 mm, angles to 1e-12)
    ori = {im.image: im.eo for im in back.images}
    for im in xb.images:
        np.testing.assert_allclose(ori[im.image][:3], im.eo[:3], atol=1e-4)
    assert len(bluh.read_bluh(out / "b").observations) == len(xb.observations)
    g = odm.read_odm(out / "gcp_list.txt")
    assert {p.name for p in g.points} == control
    mm = micmac.read_micmac(out / "mm")
    assert {p.name for p in mm.points if p.kind != "tie"} >= control
    pycolmap = pytest.importorskip("pycolmap")
    rec = pycolmap.Reconstruction(str(out / "colmap"))
    assert rec.num_images() == len(xb.images)
    tracks = sum(len(p.track.elements) for p in rec.points3D.values())
    n_named = sum(1 for o in xb.observations if o.point.startswith("1"))
    assert tracks >= 0.9 * n_named


def test_a_colmap_model_imports_as_a_block(tmp_path):
    """A digital block exported as a COLMAP model, imported as a new block (its poses in a
    frame of their own, as COLMAP's are), its control measured and adjusted: the truth
    within three standard deviations."""
    d = tmp_path / "dig"
    synth_block(d, SynthSpec(strips=2, images_per_strip=3, size_px=900, camera="digital",
                             seed=4))  # fmt: skip
    truth = load_truth(d / "truth.json")
    blk = tmp_path / "dig.block"
    for args in (
        ("at", "init", blk, "--camera", d / "camera.toml", "--images", d / "images.csv",
         "--control", d / "control.csv"),
        ("at", "match", blk, "--scheduler", "sync"),
        ("at", "gcp", blk, "--measure", d / "gcp.csv"),
        ("at", "adjust", blk),
        ("at", "export", blk, "--colmap", tmp_path / "model"),
    ):  # fmt: skip
        r = _run(*args)
        assert r.exit_code == 0, (args, r.output)
    with Block.open(blk) as b:
        pixel_um = b.cameras()[1].pixel_um
    new = tmp_path / "imported.block"
    r = _run("at", "import", new, "--colmap", tmp_path / "model", "--images", d,
             "--pixel-um", pixel_um, "--crs", "EPSG:2056")  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "6 images (6 oriented)" in r.output
    with Block.open(new) as b:
        # a model in a frame of its own, as COLMAP's are: shrunk, moved and turned
        c, s = math.cos(0.3), math.sin(0.3)
        with b.conn:
            b.conn.execute(
                "UPDATE exterior SET X = (? * X - ? * Y) / 3 + 100, Y = (? * X + ? * Y) / 3 - 50, "
                "Z = Z / 3, kappa = kappa + 0.3",
                (c, s, s, c),
            )
        # the control of the original block
        b.add_points(
            {"name": c["name"], "kind": c["kind"], "X": c["X"], "Y": c["Y"], "Z": c["Z"],
             "sigma_xy_m": c["sigma_xy_m"], "sigma_z_m": c["sigma_z_m"]}
            for c in truth.control
        )  # fmt: skip
        measure(b, read_measurements(d / "gcp.csv"))
        rep = adjust_block(b)
    assert any("imported orientations were placed" in n for n in rep.notes)
    assert rep.sigma0_px < 0.1
    for e in rep.exterior:
        t = truth.exterior[e["image"]]
        for a, b_, s in ((e["X"], t.Xo, e["sX"]), (e["Y"], t.Yo, e["sY"]), (e["Z"], t.Zo, e["sZ"])):
            assert abs(a - b_) <= 3 * s


def test_control_from_opendronemap_and_micmac(adjusted, tiny_copy, matched_tiny, tmp_path):
    """The control measurements of an adjusted block, exported as gcp_list.txt and MicMac
    files, import into the unmeasured block as the same measurements."""
    out = tmp_path / "x"
    assert _run("at", "export", adjusted, "--odm", out / "gcp_list.txt", "--micmac",
                out / "mm").exit_code == 0  # fmt: skip
    with Block.open(adjusted) as b:
        want = sorted(
            (n, i, round(x, 3), round(y, 3))
            for n, i, x, y in b.conn.execute(
                "SELECT p.name, o.image, o.x_px, o.y_px FROM observations o JOIN points p ON "
                "p.id = o.point WHERE p.kind IN ('full', 'planimetric')"
            )
        )
    for opt, args in (
        ("--odm", [out / "gcp_list.txt"]),
        ("--micmac", [out / "mm_3d_gcp.xml", "--micmac", out / "mm_2d_gcp.xml"]),
    ):
        fresh = tmp_path / f"fresh{opt}.block"
        shutil.copy(matched_tiny, fresh)
        fresh.with_name(fresh.name + ".pyramids").symlink_to(
            matched_tiny.with_name(matched_tiny.name + ".pyramids")
        )
        r = _run("at", "gcp", fresh, opt, *args)
        assert r.exit_code == 0, r.output
        with Block.open(fresh) as b:
            got = sorted(
                (n, i, round(x, 3), round(y, 3))
                for n, i, x, y in b.conn.execute(
                    "SELECT p.name, o.image, o.x_px, o.y_px FROM observations o JOIN points p "
                    "ON p.id = o.point WHERE p.kind IN ('full', 'planimetric')"
                )
            )
        assert got == want, opt
