"""Every import is declared: a fresh ``pip install -e ".[test]"`` brings what the code needs.

The package may import only the standard library, itself and its runtime dependencies;
the tests also the ``test`` extra; the benchmarks also the ``bench`` extra. Distribution
names come from the installed metadata (``serial`` is provided by ``pyserial``), so a
module imported but provided by no declared distribution fails here, on the developer's
machine, before it fails on a fresh one.
"""

from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
import tomllib

import pytest

from tests.conftest import ROOT

PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _names(requirements: list[str]) -> set[str]:
    return {
        re.split(r"[\s\[<>=!~;]", r, maxsplit=1)[0].lower().replace("_", "-") for r in requirements
    }


RUNTIME = _names(PYPROJECT["project"]["dependencies"])
EXTRAS = {k: _names(v) for k, v in PYPROJECT["project"]["optional-dependencies"].items()}
ALLOWED = {
    "apygis": RUNTIME,
    "samples": RUNTIME,
    "tests": RUNTIME | EXTRAS["test"],
    "benchmarks": RUNTIME | EXTRAS["test"] | EXTRAS.get("bench", set()),
}


# Modules of Debian packages that scripts run by the system Python (/usr/bin/python3, not
# the virtual environment) import; the tests that run them carry a marker and skip with
# a reason where the package is missing (.ci/run installs it under CI=true).
SYSTEM = {
    "tests": {
        "qgis": "python3-qgis (tests marked qgis)",
        "osgeo": "python3-gdal (with python3-qgis)",
    }
}


def _imports(path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def _providers() -> dict[str, set[str]]:
    return {
        mod: {d.lower().replace("_", "-") for d in dists}
        for mod, dists in importlib.metadata.packages_distributions().items()
    }


@pytest.mark.parametrize("folder", sorted(ALLOWED))
def test_every_import_is_declared(folder):
    providers = _providers()
    local = {"apygis", "tests"} | {p.stem for p in (ROOT / folder).glob("*.py")}
    missing = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for mod in sorted(_imports(path)):
            if mod in sys.stdlib_module_names or mod in local or mod == "__future__":
                continue
            if mod in SYSTEM.get(folder, {}):
                continue
            # a module not installed here counts as provided by the distribution of its name
            dists = providers.get(mod) or {mod.lower().replace("_", "-")}
            if not dists & ALLOWED[folder]:
                missing.append(f"{path.relative_to(ROOT)}: {mod} (from {', '.join(sorted(dists))})")
    assert not missing, "imports not declared in pyproject.toml:\n" + "\n".join(missing)


def test_ci_runs_the_readme_commands_in_a_fresh_environment():
    readme = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```sh\n(.*?)```", readme, flags=re.S)
    setup, tests = blocks[0].strip(), blocks[2].strip()
    assert setup == 'python3 -m pip install -e ".[test]"'
    assert tests == "python3 -m pytest"
    ci = (ROOT / ".ci" / "run").read_text()
    assert "python3 -m venv" in ci
    lines = [line.split("#")[0].strip() for line in ci.splitlines()]
    assert setup in lines
    assert tests in lines
