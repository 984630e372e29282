"""The driver registry: entry points, choice by content and extension."""

from __future__ import annotations

from importlib.metadata import entry_points

import pytest

import apygis
from apygis.errors import DriverError
from apygis.formats import DRIVER_GROUP, driver_for, drivers, get_driver


def test_builtins_come_through_the_entry_point_group():
    names = {ep.name for ep in entry_points(group=DRIVER_GROUP)}
    assert {"apy", "ascii"} <= names
    assert {"apy", "ascii"} <= set(drivers())
    assert get_driver("ASCII").extensions == ("apa",)
    assert get_driver("apy").modes == "rw"


def test_choice_by_content_beats_extension(sample_dir, tmp_path):
    assert driver_for(sample_dir / "ZH1091.apa", "r").name == "ascii"
    assert driver_for(sample_dir / "ZH1091.r", "r").name == "apy"
    assert driver_for(sample_dir / "ZH1091", "r").name == "apy"  # all layers
    odd = tmp_path / "ZH1091.apa"  # a binary layer named like an ASCII file
    odd.write_bytes((sample_dir / "ZH1091.c").read_bytes())
    assert driver_for(odd, "r").name == "apy"


def test_choice_for_writing(tmp_path):
    assert driver_for(tmp_path / "x.apa", "w").name == "ascii"
    assert driver_for(tmp_path / "MAP", "w").name == "apy"
    assert driver_for(tmp_path / "MAP.r", "w").name == "apy"


def test_unknown_names_and_files(tmp_path):
    with pytest.raises(DriverError, match="no driver named 'nope'; known drivers: apy, ascii"):
        get_driver("nope")
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\0\1\2")
    with pytest.raises(DriverError, match="no driver recognises this file"):
        apygis.read(junk)
    with pytest.raises(DriverError, match="no such file"):
        apygis.read(tmp_path / "missing.apa")
    m = apygis.MapFile("M")
    m.layer("r")
    with pytest.raises(DriverError, match=r"\.xlsx is neither"):
        apygis.write(m, tmp_path / "m.xlsx")


def test_source_tree_fallback_matches_the_registered_drivers():
    import tomllib

    from apygis.formats import _BUILTIN
    from tests.conftest import ROOT

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["entry-points"]["apygis.drivers"] == _BUILTIN
