"""Fuzz seed for the E00 reader: what the writer makes of ``small_map()``."""

from __future__ import annotations

import apygis
from tests.formats import strategies


def _seed_e00(tmp_path):
    apygis.write(strategies.small_map(), tmp_path / "FUZZ.e00")
    return (tmp_path / "FUZZ.e00").read_bytes(), "FUZZ.e00"


SEEDS = {"e00": _seed_e00}
