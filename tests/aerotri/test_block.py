"""The block database: creation, reopening, versions, paths, resumable tasks."""

from __future__ import annotations

import json
import sqlite3

import numpy as np
import pytest

from apygis.aerotri import block as blockmod
from apygis.aerotri.block import SCHEMA_VERSION, Block, BlockError
from apygis.aerotri.camera import Camera
from apygis.errors import ApygisError, FileOverwriteError

CAM = Camera("c", "digital", 50.0, pixel_um=6.0, sensor_px=(600, 400))


def _image(tmp_path, n=1):
    p = tmp_path / "imgs" / f"i{n}.tif"
    p.parent.mkdir(exist_ok=True)
    p.write_bytes(b"x")
    return {"image": n, "strip": 1, "camera": 1, "path": p, "width": 600, "height": 400,
            "X": 1.0, "Y": 2.0, "Z": 3.0}  # fmt: skip


def test_create_reopen_and_refuse_overwrite(tmp_path):
    path = tmp_path / "b.block"
    with Block.create(path, crs="EPSG:2056") as b:
        assert b.add_camera(CAM) == 1
        b.add_images([_image(tmp_path)])
    with pytest.raises(FileOverwriteError):
        Block.create(path)
    with Block.open(path) as b:
        assert b.crs == "EPSG:2056"
        assert b.cameras()[1] == CAM
        (im,) = b.images()
        assert im.path.resolve() == (tmp_path / "imgs" / "i1.tif").resolve()
        # stored relative to the block's folder, so the block moves with its images
        (stored,) = b.conn.execute("SELECT path FROM images").fetchone()
        assert stored == "imgs/i1.tif"
        assert b.conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    with Block.create(path, overwrite=True) as b:
        assert b.images() == []


def test_moved_block_keeps_its_images(tmp_path):
    with Block.create(tmp_path / "a" / "b.block") as b:
        b.add_camera(CAM)
        b.add_images([_image(tmp_path / "a")])
    (tmp_path / "a").rename(tmp_path / "moved")
    with Block.open(tmp_path / "moved" / "b.block") as b:
        assert b.images()[0].path.is_file()


def test_not_a_block(tmp_path):
    p = tmp_path / "x.block"
    p.write_text("hello")
    with pytest.raises(BlockError, match="not a block database"):
        Block.open(p)
    with pytest.raises(BlockError, match="no such block"):
        Block.open(tmp_path / "missing.block")
    con = sqlite3.connect(tmp_path / "other.db")
    con.execute("CREATE TABLE t (a)")
    con.commit()
    con.close()
    with pytest.raises(ApygisError, match="not a block database"):
        Block.open(tmp_path / "other.db")


def test_newer_schema_is_refused(tmp_path):
    path = tmp_path / "b.block"
    Block.create(path).close()
    con = sqlite3.connect(path)
    con.execute(
        "UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION + 1),)
    )
    con.commit()
    con.close()
    with pytest.raises(BlockError, match="newer apygis"):
        Block.open(path)


def test_older_schema_is_migrated(tmp_path, monkeypatch):
    """A block of schema N opened by an apygis of schema N + 1 runs the migration once."""
    path = tmp_path / "b.block"
    Block.create(path).close()
    monkeypatch.setattr(blockmod, "SCHEMA_VERSION", SCHEMA_VERSION + 1)
    monkeypatch.setitem(
        blockmod.MIGRATIONS, SCHEMA_VERSION, "ALTER TABLE images ADD COLUMN note TEXT;"
    )
    with Block.open(path) as b:
        assert b.meta("schema_version") == str(SCHEMA_VERSION + 1)
        cols = [r[1] for r in b.conn.execute("PRAGMA table_info(images)")]
        assert "note" in cols
    with Block.open(path) as b:  # not migrated twice
        assert b.meta("schema_version") == str(SCHEMA_VERSION + 1)


def test_tie_names_never_repeat(tmp_path):
    with Block.create(tmp_path / "b.block") as b:
        b.set_meta("tie_name_start", 500)
        b.set_meta("tie_name_next", 500)
        b.set_meta("tie_name_interval", 10)
        first = b.tie_names(3)
        assert first == ["500", "510", "520"]
    with Block.open(tmp_path / "b.block") as b:
        assert b.tie_names(2) == ["530", "540"]
        b.add_points([{"name": "530", "kind": "tie"}])
        with pytest.raises(BlockError, match="taken"):
            b.add_points([{"name": "530", "kind": "tie"}])


def test_features_matches_tasks_roundtrip(tmp_path):
    with Block.create(tmp_path / "b.block") as b:
        b.add_camera(CAM)
        b.add_images([_image(tmp_path, 1), _image(tmp_path, 2)])
        xy = np.array([[1.5, 2.25], [3.0, 4.0]])
        b.set_features(1, 2, xy)
        assert np.allclose(b.features(1, 2), xy)
        assert b.features(2, 2) is None
        b.set_pairs([(1, 2, "strip", 0.6)])
        b.set_pair_matches(1, 2, [0, 1], [1, 0], "matched", 0.3, "")
        ((a, c, ia, ib),) = b.pair_matches()
        assert (a, c, ia.tolist(), ib.tolist()) == (1, 2, [0, 1], [1, 0])
        assert b.pairs()[0]["n_matches"] == 2
        assert not b.task_done("pyramid", "1")
        b.mark_task("pyramid", "1")
        assert b.task_done("pyramid", "1")
        run = b.start_run("match", {"x": 1})
        b.finish_run(run, "done", {"points": 3})
        assert b.runs()[-1]["status"] == "done"


def test_a_version_1_block_is_migrated(tmp_path):
    """A block written with schema 1 (no x_azimuth_deg, no adjustment tables) opens, migrated
    step by step, its data kept."""
    path = tmp_path / "v1.block"
    con = sqlite3.connect(path)
    con.executescript(blockmod.SCHEMA_V1)
    con.execute("INSERT INTO meta VALUES ('schema_version', '1')")
    con.execute("INSERT INTO cameras VALUES (1, 'c', ?)", (json.dumps(CAM.to_dict()),))
    con.execute("INSERT INTO images VALUES (5, 1, 1, 'a.tif', 600, 400, 1, 2, 3, 90, 'list', NULL)")
    con.commit()
    con.close()
    with Block.open(path) as b:
        assert b.meta("schema_version") == str(SCHEMA_VERSION) == "3"
        tables = {r[0] for r in b.conn.execute("SELECT name FROM sqlite_master")}
        assert {"adjustments", "exterior", "adjusted_points", "residuals"} <= tables
        (im,) = b.images()
        assert (im.image, im.heading_deg, im.x_azimuth_deg) == (5, 90.0, None)
        b.update_images({5: {"x_azimuth_deg": 270.0}})
        assert b.images()[0].x_azimuth_deg == 270.0
