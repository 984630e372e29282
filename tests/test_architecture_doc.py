"""docs/architecture.md stays true: its layer table is the one tests/test_layering.py
holds, and every file it points to exists."""

from __future__ import annotations

import re

from tests.conftest import ROOT
from tests.test_layering import ALLOWED, FLOOR

DOC = (ROOT / "docs" / "architecture.md").read_text()


def _layer_table() -> dict[str, set[str]]:
    start = DOC.index("| part | may import")
    rows = {}
    for line in DOC[start:].splitlines()[2:]:
        if not line.startswith("|"):
            break
        part, allowed, _ = (c.strip() for c in line.strip("|").split("|", 2))
        names = set(re.findall(r"`(\w+)`", allowed))
        if "the floor" in allowed:
            names |= FLOOR
        rows[part.strip("`")] = names
    return rows


def test_the_layer_table_is_the_one_the_tests_hold():
    doc = _layer_table()
    held = {k: v for k, v in ALLOWED.items() if not k.startswith("__")}
    assert doc == held


def test_every_file_the_page_names_exists():
    paths = set(re.findall(r"`(apygis/[\w/.<>-]+)`", DOC))
    assert len(paths) > 10
    for path in paths:
        if "<" in path:  # a pattern such as apygis/formats/<name>.py
            continue
        assert (ROOT / path).exists(), path
    for name in re.findall(
        r"`((?:model|formats|orient|compile|session|instrument|plot)/[\w.]+)`", DOC
    ):
        assert (ROOT / "apygis" / name).exists(), name
