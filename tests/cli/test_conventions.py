"""Conventions every command keeps: ``-h`` for help, ``-v``/``-q`` before or after
the command, ``validate --json``, and no output file replaced without ``--overwrite``."""

from __future__ import annotations

import json
import logging

import click
import pytest
from click.testing import CliRunner

from apygis.cli import _PluginGroup, main
from tests.conftest import SAMPLES

ORIENT = SAMPLES / "orient"
CONTROL = ORIENT / "ZH1091-control.txt"
MAP = ORIENT / "ZH1091-map.txt"
PHOTOS = ORIENT / "ZH1091-photos.txt"
PMEAS = ORIENT / "ZH1091-photo-measurements.txt"


def _invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _command_paths(group: click.Group, prefix=()):
    ctx = click.Context(group)
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        assert cmd is not None, name
        yield (*prefix, name)
        if isinstance(cmd, click.Group):
            yield from _command_paths(cmd, (*prefix, name))


ALL_COMMANDS = list(_command_paths(main))


# --------------------------------------------------------------------------- -h


def test_every_command_is_listed():
    assert {("info",), ("validate",), ("orient", "map"), ("orient", "photos")} <= set(ALL_COMMANDS)


@pytest.mark.parametrize("path", [(), *ALL_COMMANDS], ids=lambda p: " ".join(p) or "apygis")
def test_h_is_help(path):
    short = _invoke(*path, "-h")
    long = _invoke(*path, "--help")
    assert short.exit_code == long.exit_code == 0, short.output
    assert short.output == long.output
    assert short.output.startswith("Usage: ")
    assert "-h, --help" in short.output


# --------------------------------------------------------------------------- -v / -q


@pytest.fixture
def levels(monkeypatch):
    """The log levels the group set, one per invocation."""
    got: list[int] = []
    monkeypatch.setattr(logging, "basicConfig", lambda **kw: got.append(kw["level"]))
    return got


@pytest.mark.parametrize(
    ("args", "level"),
    [
        (["info", "-v", SAMPLES / "ZH1091"], logging.INFO),
        (["info", SAMPLES / "ZH1091", "-vv"], logging.DEBUG),
        (["-v", "info", SAMPLES / "ZH1091", "--verbose"], logging.DEBUG),
        (["info", "-q", SAMPLES / "ZH1091"], logging.ERROR),
        (["info", "--quiet", SAMPLES / "ZH1091", "-v"], logging.WARNING),
        (["validate", SAMPLES / "ZH1091.apa", "-v", "--json"], logging.INFO),
        (["formats", "-q"], logging.ERROR),
        (["orient", "map", CONTROL, MAP, "-v"], logging.INFO),
        (["symbols", "-v", "list"], logging.INFO),
    ],
)
def test_v_q_after_the_command(levels, args, level):
    r = _invoke(*args)
    assert r.exit_code == 0, r.output
    assert levels == [level]


def test_log_options_stay_where_they_are_values_or_after_double_dash():
    g = _PluginGroup()

    @g.command("cmd")
    @click.option("--name")
    @click.option("-q", "--quick", is_flag=True)
    @click.argument("rest", nargs=-1)
    def cmd(name, quick, rest):
        """A command with an option taking a value and a -q of its own."""

    ctx = click.Context(g)
    hoist = g._hoist_log_options
    assert hoist(ctx, ["cmd", "--name", "-v", "x"]) == ["cmd", "--name", "-v", "x"]
    assert hoist(ctx, ["cmd", "-q", "-v", "x"]) == ["-v", "cmd", "-q", "x"]
    assert hoist(ctx, ["cmd", "--", "-v"]) == ["cmd", "--", "-v"]
    assert hoist(ctx, ["-v", "cmd", "x", "-vv"]) == ["-vv", "-v", "cmd", "x"]
    assert hoist(ctx, ["nosuch", "-v"]) == ["nosuch", "-v"]
    assert hoist(ctx, ["--version"]) == ["--version"]


def test_verbose_does_not_swallow_an_option_value(levels, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = _invoke("orient", "map", CONTROL, MAP, "-o", "-v", "--map-id", "X")
    assert r.exit_code == 0, r.output
    assert levels == [logging.WARNING]
    assert (tmp_path / "-v").is_file()


# --------------------------------------------------------------------------- validate --json


def test_validate_json_valid():
    r = _invoke("validate", "--json", SAMPLES / "ZH1091.apa")
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    assert d["valid"] is True
    assert d["errors"] == d["warnings"] == 0
    assert d["issues"] == []
    assert d["layers"] == 4


def test_validate_json_invalid_exits_1(tmp_path):
    text = (SAMPLES / "ZH1091.apa").read_text()
    # break one reference: point 2 of the stream no longer points back to point 1
    table = text.index("LINEPOINTS", text.index("LAYER h"))
    row = text.index("\n0002 ", table) + 1
    bad = tmp_path / "bad.apa"
    bad.write_text(text[:row] + text[row : row + 46] + "0009" + text[row + 50 :])
    r = _invoke("validate", "--json", bad)
    assert r.exit_code == 1, r.output
    d = json.loads(r.output)  # one object, nothing else
    assert d["valid"] is False
    assert d["errors"] >= 1
    assert d["errors"] == sum(i["severity"] == "error" for i in d["issues"])
    assert d["warnings"] == sum(i["severity"] == "warning" for i in d["issues"])
    issue = next(i for i in d["issues"] if i["severity"] == "error")
    assert issue["layer"] == "h"
    assert "fwd reference 2, but point 2 has no backward" in issue["message"]
    assert set(issue) == {"layer", "severity", "kind", "table", "num", "message"}
    text = _invoke("validate", bad)
    assert text.exit_code == 1
    assert "INVALID" in text.output


# --------------------------------------------------------------------------- --overwrite


@pytest.mark.parametrize(
    "args",
    [["orient", "map", CONTROL, MAP], ["orient", "photos", PHOTOS, CONTROL, PMEAS]],
    ids=["map", "photos"],
)
def test_orient_output_needs_overwrite(tmp_path, args):
    out = tmp_path / "o.json"
    out.write_text("keep")
    r = _invoke(*args, "-o", out)
    assert r.exit_code == 1
    assert r.output == f"Error: {out} exists; use --overwrite to replace it\n"  # before any work
    assert out.read_text() == "keep"


def test_orient_overwrite_updates_the_file(tmp_path):
    out = tmp_path / "o.json"
    assert _invoke("orient", "map", CONTROL, MAP, "-o", out).exit_code == 0
    r = _invoke("orient", "photos", PHOTOS, CONTROL, PMEAS, "-o", out, "--overwrite")
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    assert d["quality"].keys() == {"map", "photos"}
