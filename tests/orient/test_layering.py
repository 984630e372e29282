"""apygis.orient imports nothing of apygis but apygis.errors and apygis.fileio (the layer rule)."""

from __future__ import annotations

import ast
from pathlib import Path

import apygis.orient

PKG = Path(apygis.orient.__file__).parent


def test_orient_imports_only_errors():
    for f in PKG.glob("*.py"):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for n in names:
                if n.startswith("apygis"):
                    assert n in ("apygis.errors", "apygis.fileio") or n.startswith(
                        "apygis.orient"
                    ), (f.name, n)
                else:
                    assert n.split(".")[0] in {
                        "__future__",
                        "functools",
                        "numpy",
                        "scipy",
                        "math",
                        "dataclasses",
                        "collections",
                        "typing",
                        "json",
                        "os",
                        "tempfile",
                        "pathlib",
                        "contextlib",
                        "re",
                        "stat",
                        "warnings",
                    }, (f.name, n)


def test_every_module_has_all():
    for f in PKG.glob("*.py"):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        assert any(
            isinstance(n, ast.Assign)
            and any(getattr(t, "id", None) == "__all__" for t in n.targets)
            for n in tree.body
        ), f.name
        assert ast.get_docstring(tree), f.name
