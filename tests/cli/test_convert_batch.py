"""Batch conversion: many inputs, an output folder, parallel jobs, failures reported."""

from __future__ import annotations

from click.testing import CliRunner

import apygis
from apygis.cli import main
from apygis.formats.batch import convert_many, expand_sources


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _inputs(sample_dir, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for i in range(3):
        m = apygis.read(sample_dir / "ZH1091")
        m.id = f"S{i}"
        apygis.write(m, src / f"sheet{i}.apa")
    (src / "junk.apa").write_text("APY ASCII 1\nMAP X\nLAYER r\nSYMBOLS 1\nbroken\nEND\n")
    return src


def test_batch_with_jobs_reports_the_failure_and_converts_the_rest(sample_dir, tmp_path):
    src = _inputs(sample_dir, tmp_path)
    out = tmp_path / "out"
    res = _run("convert", "--to", "apy", "-j", "2", src / "*.apa", sample_dir / "ZH1091.c", out)
    assert res.exit_code == 1
    assert "FAILED" in res.output
    assert "junk.apa" in res.output
    assert "line 5" in res.output
    assert "4 converted, 1 failed" in res.output
    for i in range(3):
        m = apygis.read(out / f"sheet{i}")
        assert m.id == f"S{i}"
        assert sorted(m.layers) == ["c", "e", "h", "r"]
    assert sorted(apygis.read(out / "ZH1091.c").layers) == ["c"]


def test_batch_refuses_to_overwrite_then_overwrites(sample_dir, tmp_path):
    out = tmp_path / "out"
    folder = f"{out}/"  # a trailing slash: a folder that receives SRC under its own name
    assert _run("convert", "--to", "ascii", sample_dir / "ZH1091", folder).exit_code == 0
    res = _run("convert", "--to", "ascii", sample_dir / "ZH1091", folder)
    assert res.exit_code == 1
    assert "exists; use --overwrite" in res.output
    res = _run("convert", "--to", "ascii", "--overwrite", sample_dir / "ZH1091", out)
    assert res.exit_code == 0
    assert apygis.read(out / "ZH1091.apa") == apygis.read(sample_dir / "ZH1091")


def test_library_batch_results_in_source_order(sample_dir, tmp_path):
    srcs = [
        str(sample_dir / "ZH1091.apa"),
        str(tmp_path / "missing.apa"),
        str(sample_dir / "ZH1091"),
    ]
    seen, calls = [], []
    results = convert_many(
        srcs,
        tmp_path / "o",
        "apy",
        jobs=2,
        on_result=seen.append,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert [r.source for r in results] == srcs
    assert [r.ok for r in results] == [True, False, False]
    assert "no such file" in results[1].error
    assert "collide" in results[2].error  # ZH1091.apa and ZH1091 both make ZH1091
    assert len(seen) == 3
    assert calls == [(1, 3), (2, 3), (3, 3)]


def test_expand_sources_keeps_unmatched_globs(tmp_path):
    (tmp_path / "a.apa").write_text("")
    got = expand_sources([str(tmp_path / "*.apa"), str(tmp_path / "*.nothing")])
    assert got == [str(tmp_path / "a.apa"), str(tmp_path / "*.nothing")]


def test_usage_errors():
    res = _run("convert", "only-one")
    assert res.exit_code == 2
    res = _run("convert", "a.apa", "b.apa", "out")
    assert res.exit_code == 2
    assert "--to FORMAT" in res.output


def test_one_source_into_a_folder_with_a_folder_driver(sample_dir, tmp_path):
    out = tmp_path / "gj"
    out.mkdir()
    res = _run("convert", sample_dir / "ZH1091", out, "--driver", "geojson")
    assert res.exit_code == 0, res.output
    assert "files in" in res.output
    assert apygis.read(out / "ZH1091.geojson") == apygis.read(sample_dir / "ZH1091")
    res = _run("convert", sample_dir / "ZH1091", out, "--driver", "geojson")
    assert res.exit_code == 1
    assert "more files exist; use --overwrite" in res.output


def test_single_conversion_reports_progress(sample_dir, tmp_path):
    from apygis.formats.batch import convert_file

    seen = []
    res = convert_file(
        str(sample_dir / "ZH1091"),
        str(tmp_path / "x.gpkg"),
        progress=lambda done, total: seen.append((done, total)),
    )
    assert res.ok
    assert len(seen) > 4
    assert {t for _, t in seen} == {1000}
    assert seen == sorted(seen)
    assert seen[0][0] > 0
    assert seen[-1] == (1000, 1000)


def test_batch_failure_on_a_full_disk_names_the_target(sample_dir, tmp_path, monkeypatch):
    import errno
    import os

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)
    out = tmp_path / "out"
    res = _run("convert", "--to", "ascii", sample_dir / "ZH1091", sample_dir / "ZH1091.c", out)
    monkeypatch.undo()
    assert res.exit_code == 1
    failed = [ln for ln in res.output.splitlines() if ln.startswith("FAILED")]
    assert len(failed) == 2
    assert f"{out / 'ZH1091.apa'}: cannot write: no space left on device" in failed[0]
    assert f"{out / 'ZH1091.c.apa'}: cannot write: no space left on device" in failed[1]
    assert list(out.iterdir()) == []  # nothing half-written
