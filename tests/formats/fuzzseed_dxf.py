"""Fuzz seed for the DXF driver (picked up by tests/test_fuzz.py)."""

from __future__ import annotations

import apygis
from tests.formats import strategies


def _seed_dxf(tmp_path):
    """The small fuzz map written as DXF: its bytes and file name."""
    apygis.write(strategies.small_map(), tmp_path / "FUZZ.dxf")
    return (tmp_path / "FUZZ.dxf").read_bytes(), "FUZZ.dxf"


SEEDS = {"dxf": _seed_dxf}
