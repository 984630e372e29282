"""Only apygis.model touches the model's private parts (issue 10: one owner for every invariant).

The record tables, the numbering helper and every other name the model keeps
private (``self._x = ...`` attributes, ``__slots__`` entries, ``def _x``
functions and methods) are collected from ``apygis/model`` by ast; every
other module under ``apygis/`` is scanned for an attribute access ``.<name>``
of one of them, or an import of a ``_name`` from ``apygis.model``. A module's
own ``self._x`` / ``cls._x`` is its own business when it defines that name
itself.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "apygis"
MODEL = ROOT / "model"


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _defined(tree: ast.AST) -> set[str]:
    """Private names a module defines: self/cls attributes, slots, functions and methods."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and _private(node.name):
            out.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                for el in t.elts if isinstance(t, ast.Tuple) else [t]:
                    if (
                        isinstance(el, ast.Attribute)
                        and isinstance(el.value, ast.Name)
                        and el.value.id in ("self", "cls")
                        and _private(el.attr)
                    ):
                        out.add(el.attr)
                    if isinstance(el, ast.Name) and el.id == "__slots__":
                        value = node.value
                        if isinstance(value, (ast.Tuple, ast.List)):
                            out.update(
                                e.value
                                for e in value.elts
                                if isinstance(e, ast.Constant) and _private(str(e.value))
                            )
    return out


def _model_private() -> set[str]:
    names: set[str] = set()
    for p in MODEL.rglob("*.py"):
        names |= _defined(ast.parse(p.read_text(encoding="utf-8")))
    return names


def violations(path: Path, private: set[str]) -> list[str]:
    """``path``'s accesses to the model's private names, as ``"line: what"``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    own = _defined(tree)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr in private:
            mine = isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")
            if not (mine and node.attr in own):
                out.append(f"{node.lineno}: .{node.attr}")
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("apygis.model"):
            out += [f"{node.lineno}: import {a.name}" for a in node.names if _private(a.name)]
    return sorted(out, key=lambda v: int(v.split(":")[0]))


OTHERS = sorted(p for p in ROOT.rglob("*.py") if MODEL not in p.parents)


def test_the_model_has_private_parts_to_guard():
    private = _model_private()
    assert {"_tables", "_allocate", "_buf", "_line_row"} <= private


@pytest.mark.parametrize("path", OTHERS, ids=lambda p: str(p.relative_to(ROOT.parent)))
def test_no_module_outside_the_model_touches_its_private_parts(path):
    assert violations(path, _model_private()) == []


def test_the_scan_catches_what_it_guards(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text(
        "from apygis.model.map import _allocate\n"
        "def f(layer):\n"
        "    layer._tables['symbols'].append(None)\n"
        "class C:\n"
        "    def g(self):\n"
        "        return self._buf\n",
        encoding="utf-8",
    )
    assert violations(bad, _model_private()) == [
        "1: import _allocate",
        "3: ._tables",
        "6: ._buf",
    ]
