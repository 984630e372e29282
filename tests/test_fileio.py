"""apygis.fileio: the one atomic write, guarded read and guarded JSON of every layer."""

from __future__ import annotations

import errno
import os
import stat
import sys

import pytest

from apygis import fileio
from apygis.errors import FileOverwriteError, FormatError, WriteError

posix_only = pytest.mark.skipif(sys.platform == "win32", reason="POSIX modes, links, devices")


def _names(d):
    return sorted(p.name for p in d.iterdir())


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


# --------------------------------------------------------------------------- permissions


@posix_only
def test_a_new_file_gets_the_umask_default(tmp_path, umask_022):
    p = fileio.atomic_write(tmp_path / "new.txt", b"x")
    assert stat.S_IMODE(os.stat(p).st_mode) == 0o644
    os.umask(0o077)
    q = fileio.atomic_write(tmp_path / "private.txt", "y")
    assert stat.S_IMODE(os.stat(q).st_mode) == 0o600
    assert q.read_text() == "y"


@posix_only
@pytest.mark.parametrize("mode", [0o600, 0o640, 0o664, 0o444])
def test_a_replaced_file_keeps_its_mode(tmp_path, umask_022, mode):
    p = tmp_path / "old.txt"
    p.write_bytes(b"old")
    os.chmod(p, mode)
    fileio.atomic_write_many({p: b"new", tmp_path / "other.txt": b"o"})
    assert p.read_bytes() == b"new"
    assert stat.S_IMODE(os.stat(p).st_mode) == mode
    assert stat.S_IMODE(os.stat(tmp_path / "other.txt").st_mode) == 0o644
    assert _names(tmp_path) == ["old.txt", "other.txt"]


# --------------------------------------------------------------------------- targets


@posix_only
def test_a_symlink_is_written_through(tmp_path):
    real = tmp_path / "real.txt"
    real.write_bytes(b"old")
    os.chmod(real, 0o640)
    link = tmp_path / "link.txt"
    link.symlink_to(real.name)
    fileio.atomic_write(link, b"new")
    assert link.is_symlink()
    assert real.read_bytes() == b"new"
    assert stat.S_IMODE(os.stat(real).st_mode) == 0o640
    assert _names(tmp_path) == ["link.txt", "real.txt"]


@posix_only
def test_a_dangling_symlink_creates_its_target(tmp_path):
    link = tmp_path / "link.txt"
    link.symlink_to("made.txt")
    fileio.atomic_write(link, b"x")
    assert link.is_symlink()
    assert (tmp_path / "made.txt").read_bytes() == b"x"


@posix_only
@pytest.mark.skipif(not os.path.exists("/dev/null"), reason="no /dev/null")
def test_a_device_is_refused():
    with pytest.raises(FileOverwriteError, match="/dev/null: is a character device, not a regular"):
        fileio.atomic_write("/dev/null", b"x")


def test_a_directory_is_refused_and_left_alone(tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    with pytest.raises(FileOverwriteError, match="is a directory, not a regular file"):
        fileio.atomic_write(d, b"x")
    assert d.is_dir()
    assert _names(tmp_path) == ["d"]


@posix_only
def test_a_fifo_is_refused(tmp_path):
    f = tmp_path / "pipe"
    os.mkfifo(f)
    with pytest.raises(FileOverwriteError, match="named pipe"):
        fileio.atomic_write(f, b"x")


def test_a_missing_folder_is_a_file_not_found_write_error(tmp_path):
    with pytest.raises(WriteError) as ei:
        fileio.atomic_write(tmp_path / "no" / "a.txt", b"x")
    assert isinstance(ei.value, FileNotFoundError)
    assert ei.value.errno == errno.ENOENT
    assert str(ei.value).startswith(f"{tmp_path / 'no' / 'a.txt'}: cannot write: ")
    fileio.atomic_write(tmp_path / "no" / "a.txt", b"x", parents=True)
    assert (tmp_path / "no" / "a.txt").read_bytes() == b"x"


# --------------------------------------------------------------------------- failures


def test_a_failed_rename_leaves_the_old_file_and_no_temporaries(tmp_path, monkeypatch):
    p = tmp_path / "a.txt"
    p.write_bytes(b"old")

    def full(src, dst):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(WriteError, match=r"a\.txt: cannot write: no space left on device") as ei:
        fileio.atomic_write_many({p: b"new", tmp_path / "b.txt": b"b"})
    assert ei.value.filename == str(p)
    assert ei.value.strerror == "no space left on device"
    assert p.read_bytes() == b"old"
    assert _names(tmp_path) == ["a.txt"]


def test_a_failed_write_leaves_the_old_file_and_no_temporaries(tmp_path, monkeypatch):
    p = tmp_path / "a.txt"
    p.write_bytes(b"old")

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(WriteError, match="no space left on device"):
        fileio.atomic_write(p, b"new")
    assert p.read_bytes() == b"old"
    assert _names(tmp_path) == ["a.txt"]


def test_the_temporaries_of_a_killed_write_are_removed(tmp_path):
    p = tmp_path / "a.txt"
    dead = 2**22 + 12345  # above the usual pid_max: no such process
    leftovers = [
        f".a.txt.{dead}-0123abcd.apygis-tmp",  # this module's name
        ".a.txt.abcd_123.tmp",  # mkstemp's (orient.io before)
        f".a.txt.{dead}.0123abcd.tmp",  # symbols.py's before
    ]
    for name in leftovers:
        (tmp_path / name).write_bytes(b"half")
    live = tmp_path / f".a.txt.{os.getpid()}-0123abcd.apygis-tmp"  # our own: being written
    other = tmp_path / f".b.txt.{dead}-0123abcd.apygis-tmp"  # another target's
    live.write_bytes(b"")
    other.write_bytes(b"")
    fileio.atomic_write(p, b"x")
    assert _names(tmp_path) == sorted([live.name, other.name, "a.txt"])


# --------------------------------------------------------------------------- reading


def test_read_bytes_names_what_is_wrong(tmp_path):
    p = tmp_path / "a.bin"
    p.write_bytes(b"abc")
    assert fileio.read_bytes(p) == b"abc"
    with pytest.raises(FormatError, match=r"missing: no such file$"):
        fileio.read_bytes(tmp_path / "missing")
    with pytest.raises(FormatError, match="is a directory, not an orientation file"):
        fileio.read_bytes(tmp_path, "orientation file")
    with pytest.raises(FormatError, match="3 bytes is larger than the 2 bytes a file may have"):
        fileio.read_bytes(p, max_bytes=2)


@posix_only
def test_read_bytes_refuses_a_fifo_without_blocking(tmp_path):
    f = tmp_path / "pipe"
    os.mkfifo(f)
    with pytest.raises(FormatError, match="not a regular file"):
        fileio.read_bytes(f)


# --------------------------------------------------------------------------- JSON


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[" * 100_000, "JSON nested 100000 deep: arrays and objects nested too deeply"),
        ("[" * 33 + "]" * 33, "nested 33 deep"),
        ('{"a": "' + "[" * 100 + '"}', None),  # brackets in strings do not count
        ("[" * 32 + "]" * 32, None),
        ('{"n": ' + "7" * 19 + "}", r"n: an integer of 19 digits is out of range"),
        ('{"n": -' + "7" * 18 + "}", None),
        ('{"n": ' + "9" * 5000 + "}", "an integer of 5000 digits"),
        ('{"photos": [{"Xo": 1e400}]}', r"photos\[0\]\.Xo: the number 1e400 is out of range"),
        ('{"x": 1e999}', "overflows"),
        ('{"x": [NaN]}', r"x\[0\]: NaN is not a number JSON allows"),
        ('{"x": -Infinity}', "x: -Infinity is not a number JSON allows"),
        ('{"notes": "caf\\udcfc"}', "lone surrogate U\\+DCFC"),
        ('{"\\ud800": 1}', "lone surrogate U\\+D800"),
        ('"caf\\u00e9 \\ud83d\\ude00"', None),  # a surrogate pair is one character
        ('{"a": 1,\n  }', r"line 2 column 3: invalid JSON"),
        (b'\xff{"a": 1}', r"not UTF-8 text \(invalid start byte at byte 0\)"),
    ],
)
def test_loads_json_guards(text, match):
    if match is None:
        fileio.loads_json(text)
        return
    with pytest.raises(FormatError, match=match) as ei:
        fileio.loads_json(text, path="f.json")
    assert ei.value.path == "f.json"


def test_loads_json_names_what_and_keeps_the_record():
    with pytest.raises(FormatError) as ei:
        fileio.loads_json(b'{"scale": 1e999}', "metadata block", "T.r", "header")
    assert str(ei.value).startswith("T.r: header: scale: metadata block is not UTF-8 JSON: ")
    assert ei.value.record == "header: scale"
    assert fileio.loads_json('{"a": [1, 2.5, "x", null, true]}') == {"a": [1, 2.5, "x", None, True]}


def test_one_json_guard_for_formats_and_orient():
    from apygis.formats import _readguard
    from apygis.orient import _files

    assert _readguard.loads_json is fileio.loads_json
    assert _readguard.check_str is fileio.check_str
    with pytest.raises(FormatError, match=r"o\.json: map_id: NaN"):
        _files.parse_json('{"map_id": NaN}', "o.json")
