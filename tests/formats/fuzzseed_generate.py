"""Fuzz seed for the ARC/INFO GENERATE reader: a lines file with a few features."""

from __future__ import annotations

import apygis
from tests.formats import strategies


def _seed_generate(tmp_path):
    """The open lines of ``small_map()``'s road layer, as the writer makes them."""
    apygis.write(strategies.small_map(), tmp_path / "FUZZ.gen")
    name = "FUZZ_r_lines.gen"
    data = (tmp_path / name).read_bytes()
    assert data.count(b"END") >= 3  # two features and the final END
    return data, name


SEEDS = {"generate": _seed_generate}
