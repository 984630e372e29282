"""The layer rules of docs/architecture.md, for every package of apygis, in one table.

Each package (and top-level module) of ``apygis`` may import only the parts of
apygis its row names; imports inside functions count, relative imports are
resolved. A package that is not in the table fails the test, so a new package
states its place in the layers when it is added.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import apygis

PKG = Path(apygis.__file__).parent

# part -> the other parts of apygis it may import (errors, progress, fileio and tasks are
# the floor)
FLOOR = {"errors", "progress", "fileio", "tasks"}
ALLOWED: dict[str, set[str]] = {
    "errors": set(),
    "progress": set(),
    "fileio": {"errors"},  # atomic writes, guarded reads and JSON, for every layer
    "tasks": set(),  # independent tasks in this process, local processes or a Dask cluster
    "model": FLOOR,
    "orient": {"errors", "fileio"},
    "instrument": {"errors", "fileio"},
    "formats": FLOOR | {"model"},
    "compile": FLOOR | {"model", "orient"},
    "plot": FLOOR | {"model", "formats"},
    "aerotri": FLOOR | {"orient", "formats"},  # aerotriangulation; formats: bundle record layouts
    "session": FLOOR | {"model", "orient", "compile", "instrument", "formats"},
    # the graphic display: draws the model with the plot's pens, shows the engine's effects
    # replayed from a session's journal in a process of its own; the session does not import it
    "view": FLOOR | {"model", "compile", "plot", "session"},
    "cli": FLOOR
    | {"model", "orient", "compile", "instrument", "formats", "plot", "session", "aerotri", "view"},
    "__init__": FLOOR,  # the public names are imported lazily, by name (PEP 562)
    "__main__": {"cli"},
}


def _part(path: Path) -> str:
    rel = path.relative_to(PKG)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _imported_parts(path: Path, source: str | None = None) -> set[str]:
    """The parts of apygis that the module at ``path`` (in the package) imports."""
    text = path.read_text(encoding="utf-8") if source is None else source
    tree = ast.parse(text, str(path))
    here = ["apygis", *path.relative_to(PKG).with_suffix("").parts]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # from . import x / from ..model import y
                base = here[: len(here) - node.level]
                names = [".".join([*base, node.module] if node.module else base)]
                if not node.module:
                    names = [".".join([*base, a.name]) for a in node.names]
            else:
                names = [node.module or ""]
        else:
            continue
        for name in names:
            parts = name.split(".")
            if parts[0] == "apygis" and len(parts) > 1:
                out.add(parts[1])
    return out


MODULES = sorted(PKG.rglob("*.py"))


def test_every_part_has_a_row():
    assert {_part(p) for p in MODULES} <= set(ALLOWED)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_imports_follow_the_layers(path):
    part = _part(path)
    wrong = _imported_parts(path) - ALLOWED[part] - {part}
    assert not wrong, f"{part} may not import {sorted(wrong)} (docs/architecture.md)"


def test_the_checker_sees_relative_and_nested_imports():
    source = (
        "import apygis.orient\ndef f():\n    from ..formats import apy\n    from . import map\n"
    )
    got = _imported_parts(PKG / "model" / "probe.py", source)
    assert got == {"orient", "formats", "model"}
