"""Tests of ``apygis symbols list|show|set``."""

from __future__ import annotations

import os

import pytest
from click.testing import CliRunner

from apygis.cli import main
from apygis.cli.symbols import symbols
from apygis.model.symbols import SymbolLibrary, default_library


@pytest.fixture(autouse=True)
def user_lib(tmp_path, monkeypatch):
    """The user library lives in tmp_path, never in the real home."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    path = tmp_path / "user" / "symbols.apysym"
    monkeypatch.setenv("APYGIS_SYMBOLS", str(path))
    return path


def run(*args):
    return CliRunner().invoke(symbols, [str(a) for a in args], catch_exceptions=False)


# -- list -----------------------------------------------------------------------------


def test_list_default(user_lib):
    result = run("list")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert len(lines) == 100
    assert lines[0].split()[:3] == ["00", "spot", "height"]
    assert "reserved" in lines[0]
    assert lines[6].startswith("06  church ")
    assert lines[6].split()[-2:] == [str(default_library()[6].painted), "cells"]
    assert lines[99] == "99  free"
    assert not user_lib.exists()
    assert result.stderr == ""


def test_list_explicit_library(tmp_path):
    lib = SymbolLibrary()
    lib.set_name(5, "mine")
    lib.paint(5, 0, 0)
    path = tmp_path / "x.apysym"
    lib.write(path)
    result = run("list", "--library", path)
    assert result.exit_code == 0
    lines = result.stdout.splitlines()
    assert lines[5] == "05  mine                        1 cells"
    assert lines[6] == "06  free"


def test_list_missing_explicit_library_shows_default(tmp_path):
    path = tmp_path / "nope.apysym"
    result = run("list", "--library", path)
    assert result.exit_code == 0
    assert "06  church" in result.stdout
    assert "does not exist" in result.stderr
    assert not path.exists()


def test_list_bad_library(tmp_path):
    path = tmp_path / "bad.apysym"
    path.write_text("APYSYM 1\n[01] x\n###\n")
    result = run("list", "--library", path)
    assert result.exit_code == 1
    assert f"{path}: line 3:" in result.stderr
    assert "expected 15 characters" in result.stderr
    assert "Traceback" not in result.output


@pytest.mark.parametrize("command", [("list",), ("show", "5"), ("set", "5", "--name", "x")])
def test_unreadable_library_is_one_line_exit_1(tmp_path, command):
    """Issue 9: a directory or a symlink loop as --library: one line naming it, exit 1."""
    loop = tmp_path / "loop.apysym"
    os.symlink(loop, loop)
    for path, why in ((tmp_path, "is a directory"), (loop, "loop of symbolic links")):
        result = CliRunner().invoke(symbols, [*command, "--library", str(path)])
        assert result.exit_code == 1, result.output
        assert result.exception is None or isinstance(result.exception, SystemExit)
        assert result.stderr.count("\n") == 1
        assert str(path) in result.stderr
        assert why in result.stderr
        assert "does not exist" not in result.stderr
    assert loop.is_symlink()  # set did not replace the link


def test_cell_with_superscript_or_huge_digits_is_refused(tmp_path):
    lib = tmp_path / "l.apysym"
    for cell in ("8,\u00b2", "8," + "9" * 5000, "\u0663,3"):
        result = CliRunner().invoke(symbols, ["set", "5", "--paint", cell, "--library", lib])
        assert result.exit_code == 2, result.output
        assert "is not ROW,COL" in result.stderr
    assert not lib.exists()


def test_list_env_library(user_lib):
    lib = SymbolLibrary()
    lib.set_name(3, "from env")
    user_lib.parent.mkdir()
    lib.write(user_lib)
    result = run("list")
    assert result.exit_code == 0
    assert "03  from env" in result.stdout
    assert "06  free" in result.stdout


def test_main_group_knows_symbols():
    result = CliRunner().invoke(main, ["symbols", "list"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert "01  trig point" in result.stdout


# -- show -----------------------------------------------------------------------------


def test_show():
    result = run("show", "06")
    assert result.exit_code == 0
    lines = result.stdout.splitlines()
    assert lines[0].startswith("[06] church")
    assert lines[1].split() == [str(i) for i in range(1, 16)]
    assert len(lines) == 19
    assert result.stdout.strip() == default_library().render(6)


def test_show_zero_and_free():
    assert run("show", "0").stdout.startswith("[00] spot height  (reserved")
    assert run("show", "99").stdout.startswith("[99] free  (free)")


@pytest.mark.parametrize("code", ["100", "-1", "x", "1.5"])
def test_show_bad_code(code):
    result = run("show", code)
    assert result.exit_code == 2
    assert "CODE" in result.stderr


# -- set ------------------------------------------------------------------------------


def test_set_creates_user_library_from_default(user_lib):
    result = run("set", "41", "--name", "shrine", "--paint", "8,8", "--paint", "1,15")
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith("[41] shrine  (2 cells painted)")
    assert f"saved to {user_lib}" in result.stdout
    lib = SymbolLibrary.read(user_lib)
    assert lib.name(41) == "shrine"
    assert lib[41].bitmap[7, 7]
    assert lib[41].bitmap[0, 14]
    assert lib[41].painted == 2
    # the rest is the default set
    expected = default_library()
    expected.set_name(41, "shrine")
    expected.paint(41, 7, 7)
    expected.paint(41, 0, 14)
    assert lib == expected
    # and list now shows it
    assert "41  shrine" in run("list").stdout


def test_set_edits_existing_library(tmp_path):
    path = tmp_path / "lib.apysym"
    assert run("set", "7", "--paint", "1,1", "--library", path).exit_code == 0
    assert run("set", "7", "--paint", "2,2", "--clear", "1,1", "--library", path).exit_code == 0
    lib = SymbolLibrary.read(path)
    assert lib.name(7) == "chapel"
    assert lib[7].bitmap[1, 1]
    assert not lib[7].bitmap[0, 0]
    assert lib[7].painted == default_library()[7].painted + 1


def test_set_blank_then_paint_then_clear(tmp_path):
    path = tmp_path / "lib.apysym"
    result = run(
        "set", "6", "--blank", "--paint", "3,3", "--paint", "4,4", "--clear", "4,4",
        "--library", path,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    lib = SymbolLibrary.read(path)
    assert lib.name(6) == "church"
    assert lib[6].painted == 1
    assert lib[6].bitmap[2, 2]


def test_set_blank_and_free_name_makes_a_free_slot(tmp_path):
    path = tmp_path / "lib.apysym"
    assert run("set", "6", "--blank", "--name", "free", "--library", path).exit_code == 0
    assert "06  free" in run("list", "--library", path).stdout


def test_set_dry_run(user_lib):
    result = run("set", "50", "--name", "test", "--dry-run")
    assert result.exit_code == 0
    assert "[50] test" in result.stdout
    assert "not saved" in result.stdout
    assert not user_lib.exists()


@pytest.mark.parametrize("code", ["0", "00"])
def test_set_spot_height_refused(user_lib, code):
    result = run("set", code, "--name", "height")
    assert result.exit_code == 1
    assert "symbol 00 is reserved for the spot height" in result.stderr
    assert not user_lib.exists()
    result = run("set", code, "--paint", "1,1")
    assert result.exit_code == 1
    assert not user_lib.exists()


@pytest.mark.parametrize("cell", ["0,1", "1,16", "16,1", "1", "1,2,3", "a,b", "-1,2", "1.5,2", ""])
def test_set_bad_cells(user_lib, cell):
    result = run("set", "41", "--paint", cell)
    assert result.exit_code == 2
    assert "ROW,COL" in result.stderr or "grid" in result.stderr
    result = run("set", "41", "--clear", cell)
    assert result.exit_code == 2
    assert not user_lib.exists()


def test_set_cell_with_spaces(tmp_path):
    path = tmp_path / "lib.apysym"
    assert run("set", "41", "--paint", " 2, 3 ", "--library", path).exit_code == 0
    assert SymbolLibrary.read(path)[41].bitmap[1, 2]


@pytest.mark.parametrize("name", ["", "x" * 25, "a\tb", " lead"])
def test_set_bad_name(user_lib, name):
    result = run("set", "41", "--name", name)
    assert result.exit_code == 1
    assert "name" in result.stderr
    assert not user_lib.exists()


def test_set_nothing_to_do(user_lib):
    result = run("set", "41")
    assert result.exit_code == 2
    assert "nothing to change" in result.stderr
    assert not user_lib.exists()


def test_set_bad_code():
    assert run("set", "100", "--name", "x").exit_code == 2


def test_set_bad_existing_library_is_not_overwritten(tmp_path):
    path = tmp_path / "lib.apysym"
    path.write_text("not a library\n")
    result = run("set", "41", "--name", "x", "--library", path)
    assert result.exit_code == 1
    assert "line 1" in result.stderr
    assert path.read_text() == "not a library\n"


def test_set_unwritable_location(tmp_path):
    path = tmp_path / "missing-dir" / "lib.apysym"
    result = run("set", "41", "--name", "x", "--library", path)
    assert result.exit_code == 1
    assert "cannot write" in result.stderr


def test_set_help_says_one_based():
    result = run("set", "--help")
    assert result.exit_code == 0
    assert "1-based" in result.stdout
