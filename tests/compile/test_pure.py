"""apygis.compile is pure: no module of it does I/O or imports what does.

Every module's source is parsed (``ast``), so an import inside a function
counts too. A session, a test and a replay drive the engine alike only
while this holds; the I/O around it lives in ``apygis.session``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import apygis.compile

ROOT = Path(apygis.compile.__file__).parent
MODULES = sorted(ROOT.rglob("*.py"))

#: Modules (and their submodules) no compile module may import.
FORBIDDEN = (
    "os",
    "io",
    "pathlib",
    "shutil",
    "tempfile",
    "socket",
    "fcntl",
    "subprocess",
    "serial",
    "apygis.formats",
    "apygis.instrument",
    "apygis.session",
    "apygis.cli",
)
#: Built-in names that do I/O.
FORBIDDEN_CALLS = ("open", "print", "input")


def _imports(tree: ast.AST, package: str) -> list[tuple[int, str]]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the package
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                mod = f"{base}.{node.module}" if node.module else base
            else:
                mod = node.module or ""
            out.append((node.lineno, mod))
            out += [(node.lineno, f"{mod}.{a.name}") for a in node.names]
    return out


def _forbidden(name: str) -> bool:
    return any(name == f or name.startswith(f + ".") for f in FORBIDDEN)


def test_the_rule_catches_what_it_should():
    tree = ast.parse("import os.path\nfrom apygis import formats\ndef f():\n    import serial\n")
    found = [n for _, n in _imports(tree, "apygis.compile") if _forbidden(n)]
    assert found == ["os.path", "apygis.formats", "serial"]
    assert not _forbidden("osgeo")
    assert not _forbidden("apygis.orient.realtime")


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.name)
def test_compile_module_does_no_io(path):
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    bad = [f"line {n}: import {m}" for n, m in _imports(tree, "apygis.compile") if _forbidden(m)]
    bad += [
        f"line {node.lineno}: {node.func.id}()"
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and isinstance(node.func, ast.Name)
        and node.func.id in FORBIDDEN_CALLS
    ]
    assert not bad, f"{path.name} does I/O: {'; '.join(bad)}"
