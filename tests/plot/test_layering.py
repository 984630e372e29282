"""``apygis.plot`` sits above the model: it imports only the layers below it.

Allowed: :mod:`apygis.model`, :mod:`apygis.errors`, :mod:`apygis.progress`,
the shared file helpers :mod:`apygis.fileio` (the one atomic write, the
guarded read) and :mod:`apygis.formats._io`, and itself. :mod:`apygis.model`
and :mod:`apygis.orient` must not import :mod:`apygis.plot`. Imports inside functions count too.
"""

from __future__ import annotations

import ast

import pytest

from tests.conftest import ROOT

PLOT_MAY_IMPORT = (
    "apygis.plot",
    "apygis.model",
    "apygis.errors",
    "apygis.progress",
    "apygis.formats._io",
    "apygis.fileio",
)


def _apygis_imports(path) -> set[str]:
    """Every ``apygis...`` module a file imports, at any depth in the file."""
    tree = ast.parse(path.read_text(), str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "apygis")
        elif isinstance(node, ast.ImportFrom) and node.module:
            if node.level:  # relative: resolve against the file's package
                pkg = ".".join(path.relative_to(ROOT).with_suffix("").parts[: -node.level])
                out.add(f"{pkg}.{node.module}")
            elif node.module.split(".")[0] == "apygis":
                out.add(node.module)
                # "from apygis import plot" imports the submodule apygis.plot
                out.update(f"{node.module}.{a.name}" for a in node.names if node.module == "apygis")
    return out


def _within(name: str, prefixes) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _files(package: str):
    files = sorted((ROOT / package.replace(".", "/")).rglob("*.py"))
    assert files, f"no modules found for {package}"
    return files


def test_plot_imports_only_the_layers_below_it():
    bad = [
        f"{path.relative_to(ROOT)}: {name}"
        for path in _files("apygis.plot")
        for name in sorted(_apygis_imports(path))
        if not _within(name, PLOT_MAY_IMPORT)
    ]
    assert not bad, "apygis.plot reaches outside its layer:\n" + "\n".join(bad)


@pytest.mark.parametrize("package", ["apygis.model", "apygis.orient"])
def test_lower_layers_do_not_import_plot(package):
    bad = [
        f"{path.relative_to(ROOT)}: {name}"
        for path in _files(package)
        for name in sorted(_apygis_imports(path))
        if _within(name, ["apygis.plot"])
    ]
    assert not bad, f"{package} imports apygis.plot:\n" + "\n".join(bad)


def test_importing_plot_loads_no_driver():
    """At run time too: the plot modules pull in no format driver (only _io)."""
    import subprocess
    import sys

    code = (
        "import sys, apygis.plot.drawing, apygis.plot.hpgl, apygis.plot.svg, "
        "apygis.plot.pdf, apygis.plot.raster, apygis.plot.printout, apygis.plot.plotdef, "
        "apygis.plot.labels, apygis.plot.layout, apygis.plot.margin, apygis.plot.fonts, "
        "apygis.plot.primitives, apygis.plot._mpl\n"
        "print(' '.join(sorted(m for m in sys.modules if m.startswith('apygis.'))))"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    loaded = res.stdout.split()
    allowed = (*PLOT_MAY_IMPORT, "apygis.formats", "apygis.formats._readguard")
    bad = [m for m in loaded if not (_within(m, allowed) and _allowed_formats(m))]
    assert not bad, f"importing apygis.plot loaded {bad}"


def _allowed_formats(name: str) -> bool:
    """Of apygis.formats only the package itself (the registry, no driver) and _io's helpers."""
    if not _within(name, ["apygis.formats"]):
        return True
    return name in ("apygis.formats", "apygis.formats._io", "apygis.formats._readguard")
