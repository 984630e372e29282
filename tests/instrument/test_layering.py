"""The instrument's place in the layers, and its public names where code imports them.

``apygis.instrument`` turns bytes into events and commands into bytes: it
imports neither the map model, the compile engine, the orientation nor the
file formats (nor the session, the plot code or the CLI, which sit above
it). Checked with ``ast`` over every module of the package, so that an
import inside a function or under ``TYPE_CHECKING`` counts too.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import apygis.instrument

PACKAGE = "apygis.instrument"
ROOT = Path(apygis.instrument.__file__).parent

#: Packages the instrument must not import (the rule of issue 10, and the layers above it).
FORBIDDEN = (
    "apygis.model",
    "apygis.compile",
    "apygis.orient",
    "apygis.formats",
    "apygis.session",
    "apygis.plot",
    "apygis.cli",
)

MODULES = sorted(ROOT.rglob("*.py"))


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join([PACKAGE, *parts])


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in a module, relative ones resolved."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            out.append((node.lineno, module))
            # ``from apygis import model`` imports a package by its attribute name
            out += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None))
            in ("import_module", "__import__")
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            out.append((node.lineno, node.args[0].value))
    return out


def _forbidden(module: str) -> str | None:
    for f in FORBIDDEN:
        if module == f or module.startswith(f + "."):
            return f
    return None


def test_every_module_is_checked():
    names = {_module_name(p) for p in MODULES}
    assert {
        "apygis.instrument",
        "apygis.instrument.grbl",
        "apygis.instrument.motors",
        "apygis.instrument.simgrbl",
        "apygis.instrument.pad",
        "apygis.instrument.ports",
        "apygis.instrument.simulator",
        "apygis.instrument.tablet",
        "apygis.instrument.replay",
    } <= names


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.name)
def test_instrument_imports_no_model_compile_orient_formats(path):
    bad = [
        f"{path.name}:{line}: imports {module}"
        for line, module in _imports(path)
        if _forbidden(module)
    ]
    assert not bad, "the instrument layer must not import these:\n" + "\n".join(bad)


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("import apygis.model.map\n", "apygis.model"),
        ("from apygis.compile.engine import Press\n", "apygis.compile"),
        ("from apygis import orient\n", "apygis.orient"),
        ("def f():\n    from ..formats import ogr\n", "apygis.formats"),
        ("importlib.import_module('apygis.session.runner')\n", "apygis.session"),
        ("from apygis.errors import ProtocolError\n", None),
        ("from .tablet import Report\n", None),
    ],
)
def test_the_check_sees_every_kind_of_import(tmp_path, monkeypatch, source, expected):
    path = ROOT / "_probe_not_a_module.py"
    monkeypatch.setattr(Path, "read_text", lambda self, **kw: source)
    found = {_forbidden(m) for _, m in _imports(path)} - {None}
    assert found == ({expected} if expected else set())


# --------------------------------------------------------------------------- public names

#: Names other code imports from the module they were first defined in (issue 10 split
#: motors.py and moved the button names to pad.py): they stay importable there.
KEPT = {
    "apygis.instrument.motors": [
        "AXES",
        "GRBL_ALARMS",
        "GRBL_ERRORS",
        "MotorController",
        "MotorStatus",
        "SimulatedGrbl",
        "format_move",
        "open_controller",
        "parse_status",
    ],
    "apygis.instrument.simulator": ["BUTTONS", "BUTTON_CODES", "button_code"],
}


@pytest.mark.parametrize(("module", "name"), [(m, n) for m, names in KEPT.items() for n in names])
def test_old_import_paths_still_work(module, name):
    mod = importlib.import_module(module)
    assert name in mod.__all__
    assert getattr(mod, name) is getattr(apygis.instrument, name, getattr(mod, name))


def test_package_names_come_from_their_home_modules():
    from apygis.instrument import grbl, motors, pad, simgrbl, simulator

    assert apygis.instrument.SimulatedGrbl is motors.SimulatedGrbl is simgrbl.SimulatedGrbl
    assert apygis.instrument.parse_status is motors.parse_status is grbl.parse_status
    assert apygis.instrument.BUTTONS is simulator.BUTTONS is pad.BUTTONS
    assert apygis.instrument.button_code is simulator.button_code is pad.button_code
    for name in apygis.instrument.__all__:
        assert getattr(apygis.instrument, name) is not None, name


def test_the_button_names_are_defined_once():
    """Only pad.py spells out the pad: no other instrument module has a "PROCEED" literal."""
    holders = []
    for path in MODULES:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)}
        if names & {"PROCEED", "SHUTTER"}:
            holders.append(path.name)
    assert holders == ["pad.py"]
