"""Writes that cannot leave a mixed or half-written result: crashes, odd targets, a full disk."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from click.testing import CliRunner

import apygis
from apygis.cli import main
from apygis.errors import FileOverwriteError, FormatError, WriteError

# every driver that writes a set of files, and the path naming the set
MULTI = [("apy", "M"), ("shp", "out"), ("geojson", "out"), ("fgb", "out"), ("generate", "M.gen")]
ALL = [
    ("apy", "M"),
    ("ascii", "M.apa"),
    ("dxf", "M.dxf"),
    ("e00", "M.e00"),
    ("generate", "M.gen"),
    ("gpkg", "M.gpkg"),
    ("shp", "out"),
    ("geojson", "out"),
    ("fgb", "out"),
]


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _old_and_new(sample_map):
    """Two maps whose every file differs: the new one moved 1 m, without c, with a layer x."""
    old = sample_map.copy()
    new = apygis.MapFile(old.id, old.scale, old.crs, "the new one")
    for lay in old:
        if lay.ext == "c":
            continue
        tables = {}
        for name in ("symbols", "line_points", "texts"):
            t = lay.table(name).copy()
            t["x"] += 1.0
            tables[name] = t
        new.add_layer(apygis.Layer.from_arrays(lay.ext, **tables))
    new.layer("x").add_symbol(2683500.0, 1247500.0, 500.0, code=6)
    return old, new


def _sig(m):
    """What tells the maps apart, whatever a format keeps of the topology."""
    return {
        ext: (sorted(lay.symbols["x"].round(3).tolist()), len(lay.line_points), len(lay.texts))
        for ext, lay in m.layers.items()
    }


def _leftovers(d):
    return [p for p in d.rglob("*") if "apygis-tmp" in p.name or p.name.startswith(".apygis-")]


def _count_replaces(monkeypatch, fn):
    real = os.replace
    n = [0]

    def counting(a, b):
        n[0] += 1
        return real(a, b)

    monkeypatch.setattr(os, "replace", counting)
    fn()
    monkeypatch.setattr(os, "replace", real)
    return n[0]


# --------------------------------------------------------------------------- item 4: crashes


@pytest.mark.parametrize(("driver", "name"), MULTI)
def test_a_write_failing_between_renames_never_reads_as_a_mix(
    sample_map, tmp_path, monkeypatch, driver, name
):
    old, new = _old_and_new(sample_map)
    probe = tmp_path / "probe"
    probe.mkdir()
    apygis.write(old, probe / name, driver=driver)
    total = _count_replaces(monkeypatch, lambda: apygis.write(new, probe / name, driver=driver))
    assert total >= 4  # the stamp and at least three files
    real_replace = os.replace
    outcomes = set()
    # the stamp's rename, the first file's, one in the middle, the last one
    for k in sorted({0, 1, 2, total // 2, total - 1}):
        d = tmp_path / f"k{k}"
        d.mkdir()
        target = d / name
        apygis.write(old, target, driver=driver)
        done = [0]

        def crashing(a, b, done=done, k=k):
            if done[0] >= k:
                raise OSError(errno.EIO, "Input/output error (simulated crash)")
            done[0] += 1
            return real_replace(a, b)

        monkeypatch.setattr(os, "replace", crashing)
        with pytest.raises(WriteError, match=r"cannot write: input/output error"):
            apygis.write(new, target, driver=driver)
        monkeypatch.setattr(os, "replace", real_replace)
        assert _leftovers(d) == []
        try:
            got = _sig(apygis.read(target, driver=driver))
        except FormatError as exc:
            message = str(exc)
            outcomes.add("error")
        else:
            message = None
        if message is not None:
            assert "was interrupted" in message
            assert "write the set again" in message
        else:
            assert got in (_sig(old), _sig(new)), k
            outcomes.add("old" if got == _sig(old) else "new")
        # writing again repairs it
        apygis.write(new, target, driver=driver)
        assert _sig(apygis.read(target, driver=driver)) == _sig(new)
    assert outcomes >= {"old", "error"}


_KILLER = textwrap.dedent(
    """
    import os, sys
    import apygis
    from tests.formats.test_write_safety import _old_and_new
    driver, target, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
    old, new = _old_and_new(apygis.read(sys.argv[4]))
    real = os.replace
    n = [0]
    def killing(a, b):
        if n[0] >= k:
            os.kill(os.getpid(), 9)
        n[0] += 1
        return real(a, b)
    os.replace = killing
    apygis.write(new, target, driver=driver)
    """
)


@pytest.mark.parametrize(("driver", "name", "k"), [("apy", "M", 3), ("shp", "out", 12)])
def test_a_killed_write_is_detected_and_its_temporaries_are_cleaned(
    sample_dir, sample_map, tmp_path, driver, name, k
):
    old, new = _old_and_new(sample_map)
    target = tmp_path / name
    apygis.write(old, target, driver=driver)
    proc = subprocess.run(
        [sys.executable, "-c", _KILLER, driver, str(target), str(k), str(sample_dir / "ZH1091")],
        cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))),
        capture_output=True,
        text=True,
    )
    assert proc.returncode == -9, proc.stderr
    assert _leftovers(tmp_path)  # the kill left temporary files (or a folder)
    res = _run("info", target) if driver == "apy" else _run("convert", target, tmp_path / "o.apa")
    assert res.exit_code == 1
    assert "was interrupted" in res.output
    apygis.write(new, target, driver=driver)
    assert _leftovers(tmp_path) == []
    assert _sig(apygis.read(target, driver=driver)) == _sig(new)


def test_temporaries_of_a_dead_process_go_those_of_a_live_one_stay(sample_dir, tmp_path, caplog):
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], text=True, capture_output=True
    ).stdout.strip()
    stale = tmp_path / f".x.apa.{dead}-0badf00d.apygis-tmp"
    legacy = tmp_path / ".x.apa.ab12cd34.tmp"
    folder = tmp_path / f".apygis-{dead}-0badf00d.tmp"
    live = tmp_path / f".x.apa.{os.getppid()}-0badf00d.apygis-tmp"
    other = tmp_path / ".y.apa.ab12cd34.tmp"  # another target's: not ours to judge
    for p in (stale, legacy, live, other):
        p.write_bytes(b"half")
    folder.mkdir()
    (folder / "big.gpkg").write_bytes(b"x" * 1000)
    res = _run("convert", sample_dir / "ZH1091", tmp_path / "x.apa")
    assert res.exit_code == 0, res.output
    assert not stale.exists()
    assert not legacy.exists()
    assert live.exists()
    assert other.exists()
    assert not folder.exists()  # an OGR write's folder, 1000 bytes
    removed = [r.getMessage() for r in caplog.records if "interrupted write" in r.getMessage()]
    assert len(removed) == 3, removed
    assert any(folder.name in r and "1000 bytes" in r for r in removed)


# --------------------------------------------------------------------------- item 5: targets


def test_a_device_is_not_replaced(sample_dir):
    for args in (["--driver", "ascii"], []):
        res = _run("convert", sample_dir / "ZH1091", "/dev/full", "--overwrite", *args)
        assert res.exit_code == 1
        assert "/dev/full: is a character device, not a regular file" in res.output
        assert os.path.exists("/dev/full")
        assert not os.path.exists("/dev/full.c")
    import stat

    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


@pytest.mark.parametrize(("driver", "name"), ALL)
def test_a_pipe_is_not_replaced(sample_map, tmp_path, driver, name):
    from apygis.formats import get_driver

    target = tmp_path / name
    fifo = get_driver(driver).targets(sample_map, target)[0]  # the first file of the write
    fifo.parent.mkdir(exist_ok=True)
    os.mkfifo(fifo)
    with pytest.raises(FileOverwriteError, match=rf"{fifo.name}: is a named pipe, not a regular"):
        apygis.write(sample_map, target, driver=driver)
    assert fifo.is_fifo()
    assert [p.name for p in fifo.parent.iterdir()] == [fifo.name]


@pytest.mark.parametrize("ext", ["apa", "gpkg", "dxf", "e00"])
def test_a_symlink_is_written_through(sample_dir, tmp_path, ext):
    real = tmp_path / "real"
    real.mkdir()
    (real / f"r.{ext}").write_bytes(b"old")
    link = tmp_path / f"link.{ext}"
    link.symlink_to(real / f"r.{ext}")
    res = _run("convert", sample_dir / "ZH1091", link)
    assert res.exit_code == 1  # the link names an existing file
    assert "exists; use --overwrite" in res.output
    res = _run("convert", sample_dir / "ZH1091", link, "--overwrite")
    assert res.exit_code == 0, res.output
    assert link.is_symlink()
    assert apygis.read(real / f"r.{ext}").id == "ZH1091"
    assert sorted(p.name for p in real.iterdir()) == [f"r.{ext}"]


# --------------------------------------------------------------------------- item 6: full disk


@pytest.mark.parametrize(("driver", "name"), ALL)
def test_a_full_disk_names_the_target_and_leaves_the_old_file(
    sample_dir, tmp_path, monkeypatch, driver, name
):
    target = tmp_path / name
    old, _ = _old_and_new(apygis.read(sample_dir / "ZH1091"))
    old.notes = "old"
    apygis.write(old, target, driver=driver)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)
    res = _run("convert", sample_dir / "ZH1091", target, "--driver", driver, "--overwrite")
    monkeypatch.undo()
    assert res.exit_code == 1
    lines = res.output.strip().splitlines()
    assert len(lines) == 1, res.output
    assert lines[0].startswith(f"Error: {tmp_path}"), lines[0]
    assert lines[0].endswith("no space left on device"), lines[0]
    assert "samples" not in lines[0]  # not the source
    after = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert after == before  # the old files as they were, nothing half-written beside them


_CLI = "import sys; from apygis.cli import main; sys.argv[0] = 'apygis'; main()"


def _file_size_limit(limit):
    def set_limit():  # in the child: writes past the limit fail with EFBIG, no SIGXFSZ kill
        import resource
        import signal

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return set_limit


@pytest.mark.parametrize(
    ("driver", "name", "limit"),
    [("gpkg", "M.gpkg", 60_000), ("shp", "out", 2_000), ("dxf", "M.dxf", 60_000)],
)
def test_a_real_write_failure_in_gdal_or_python_names_the_target(
    sample_dir, tmp_path, driver, name, limit
):
    """GDAL and SQLite meet a real OSError (the file size limit, as a full disk would be)."""
    target = tmp_path / name
    proc = subprocess.run(
        [sys.executable, "-c", _CLI, "convert", sample_dir / "ZH1091", target, "--driver", driver],
        preexec_fn=_file_size_limit(limit),
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"Error: {target}"), lines[0]
    assert "cannot write: file too large" in lines[0]
    assert list(tmp_path.iterdir()) == ([target] if driver == "shp" else [])
    if driver == "shp":  # the folder is made, nothing in it
        assert list(target.iterdir()) == []


def test_gpkg_on_a_full_disk_says_so(sample_map, tmp_path, monkeypatch):
    import pyogrio
    import pyogrio.errors

    def sqlite_fails(*a, **k):
        raise pyogrio.errors.DataSourceError("no such table: gpkg_contents")

    class Full:
        f_bavail, f_frsize = 0, 4096

    monkeypatch.setattr(pyogrio, "write_arrow", sqlite_fails)  # GeoPackages go through Arrow
    monkeypatch.setattr(os, "statvfs", lambda p: Full())
    with pytest.raises(WriteError, match=r"M.gpkg: cannot write: no space left on device"):
        apygis.write(sample_map, tmp_path / "M.gpkg")
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    # with space left, GDAL's own message, naming the target and not the temporary folder
    monkeypatch.setattr(pyogrio, "write_arrow", sqlite_fails)
    with pytest.raises(Exception, match=r"M.gpkg: layer apygis_map: cannot write: no such ") as ei:
        apygis.write(sample_map, tmp_path / "M.gpkg")
    assert ".apygis-" not in str(ei.value)
    assert list(tmp_path.iterdir()) == []


def test_the_stamp_lists_the_set(sample_map, tmp_path):
    import json

    apygis.write(sample_map, tmp_path / "M")
    doc = json.loads((tmp_path / ".M.apyset").read_text())
    assert sorted(doc["files"]) == ["M.c", "M.e", "M.h", "M.r"]
    for n, e in doc["files"].items():
        assert e["size"] == (tmp_path / n).stat().st_size
    # one layer written alone keeps the set's stamp up to date
    one = sample_map.copy()
    for ext in ("c", "e", "h"):
        del one.layers[ext]
    lay = one.layers["r"]
    t = lay.symbols.copy()
    t["x"] += 5
    one.layers["r"] = apygis.Layer.from_arrays("r", t, lay.line_points, lay.texts)
    apygis.write(one, tmp_path / "M.r")
    back = apygis.read(tmp_path / "M")
    np.testing.assert_array_equal(back.layers["r"].symbols["x"], t["x"])


def test_writing_one_layer_does_not_hide_an_interrupted_write(sample_map, tmp_path, monkeypatch):
    old, new = _old_and_new(sample_map)
    apygis.write(old, tmp_path / "M")
    real_replace = os.replace
    done = [0]

    def crashing(a, b):
        if done[0] >= 3:  # the stamp, M.e, M.h in place; M.r, M.x not; M.c not removed
            raise OSError(errno.EIO, "Input/output error")
        done[0] += 1
        return real_replace(a, b)

    monkeypatch.setattr(os, "replace", crashing)
    with pytest.raises(WriteError, match=r"2 of 4 files of the set were replaced"):
        apygis.write(new, tmp_path / "M")
    monkeypatch.undo()
    with pytest.raises(FormatError, match=r"M.e, M.h are new, but M.c, M.r, M.x are still"):
        apygis.read(tmp_path / "M")
    one = apygis.MapFile(new.id, new.scale, new.crs, new.notes)
    one.add_layer(new.layers["r"])
    apygis.write(one, tmp_path / "M.r")  # one layer: the others are still a mix
    with pytest.raises(FormatError, match=r"M.e, M.h, M.r are new, but M.c, M.x are still"):
        apygis.read(tmp_path / "M")
    apygis.write(new, tmp_path / "M")
    assert _sig(apygis.read(tmp_path / "M")) == _sig(new)


@pytest.mark.parametrize(
    "stamp", [b"[" * 100_000 + b"]" * 100_000, b'{"format": NaN}', b"\xff\xfe", b"[]"]
)
def test_a_hostile_stamp_is_one_clear_error(sample_map, tmp_path, stamp):
    apygis.write(sample_map, tmp_path / "ZH1091")
    (tmp_path / ".ZH1091.apyset").write_bytes(stamp)
    with pytest.raises(FormatError, match=r"\.ZH1091\.apyset: not an apygis set stamp"):
        apygis.read(tmp_path / "ZH1091")


def test_an_untouched_set_is_verified_without_hashing_a_copied_one_by_hash(
    sample_map, tmp_path, monkeypatch
):
    """The stamp records each file's inode and modification time (kept by the rename),
    so reading an untouched set hashes nothing; a copy (new inodes) is hashed."""
    import shutil

    from apygis.formats import _io

    apygis.write(sample_map, tmp_path / "a" / "ZH1091")
    shutil.copytree(tmp_path / "a", tmp_path / "b")  # copy2: same times, new inodes
    hashed = []
    real_entry = _io._file_entry
    monkeypatch.setattr(_io, "_file_entry", lambda p: hashed.append(p) or real_entry(p))
    assert apygis.read(tmp_path / "a" / "ZH1091") == sample_map
    assert hashed == []
    assert apygis.read(tmp_path / "b" / "ZH1091") == sample_map
    assert len(hashed) == len(sample_map.layers)
