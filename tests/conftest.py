"""Shared fixtures: the sample sheet, built fresh, and the external sample files."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# CI (CI=true): the same examples every run, no timing-based health checks, so that
# a slow or busy machine cannot fail a property test; locally the search stays random.
settings.register_profile(
    "ci",
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
if os.environ.get("CI"):
    settings.load_profile("ci")

ROOT = Path(__file__).resolve().parent.parent

# scripts run by the system Python (QGIS, GDAL of the distribution), not by pytest
collect_ignore = ["formats/qgis_render.py", "formats/gdal_open.py"]
SAMPLES = ROOT / "samples"
EXTERNAL = ROOT.parent / "shared" / "external"
EXTERNAL_WHY = (
    "needs the real sample files other programs wrote (GDAL's and ezdxf's test data, "
    f"OpenDroneMap's drone images) in {EXTERNAL}: the project's shared/external folder, "
    "which sits beside the checkout (see its README.md)"
)


QGIS_WHY = (
    "needs QGIS for the system Python: Debian's python3-qgis "
    "(apt-get install python3-qgis; .ci/run installs it under CI=true)"
)


def _have_qgis() -> bool:
    import subprocess

    try:
        res = subprocess.run(
            ["/usr/bin/python3", "-c", "import qgis.core"],
            capture_output=True,
            timeout=60,
            env={**os.environ, "QT_QPA_PLATFORM": "offscreen"},
        )
    except (OSError, subprocess.SubprocessError):
        return False
    return res.returncode == 0


def _skip_without_qgis(items) -> None:
    """Tests marked ``qgis`` are skipped when /usr/bin/python3 cannot import qgis.core
    (an error under CI, where .ci/run installs python3-qgis)."""
    qgis = [item for item in items if item.get_closest_marker("qgis")]
    if qgis and not _have_qgis():
        if os.environ.get("CI"):
            raise pytest.UsageError(
                f"CI is set and {len(qgis)} collected tests are marked qgis, but "
                "/usr/bin/python3 cannot import qgis.core: .ci/run installs python3-qgis"
            )
        for item in qgis:
            item.add_marker(pytest.mark.skip(reason=QGIS_WHY))


#: Markers of tests that run Debian programs: marker -> (programs, package to install).
TOOLS = {
    "poppler": (("pdftotext", "pdftoppm"), "poppler-utils"),
    "rsvg": (("rsvg-convert",), "librsvg2-bin"),
}


def _skip_missing_tools(items) -> None:
    """Tests marked with a :data:`TOOLS` marker are skipped when its programs are missing.

    Under CI (``CI=true``, where ``.ci/run`` installs them) a missing program is an error.
    """
    import shutil

    for marker, (programs, package) in TOOLS.items():
        missing = [p for p in programs if shutil.which(p) is None]
        if not missing:
            continue
        marked = [item for item in items if item.get_closest_marker(marker)]
        if not marked:
            continue
        why = (
            f"needs {', '.join(missing)} from the Debian package {package} "
            f"(apt-get install {package}), which is not installed"
        )
        if os.environ.get("CI"):
            raise pytest.UsageError(f"CI is set and {len(marked)} collected tests {why}")
        for item in marked:
            item.add_marker(pytest.mark.skip(reason=why))


def pytest_collection_modifyitems(config, items):
    """Tests marked ``external`` are skipped, with the reason, when the folder is absent.

    Under CI (``CI`` set) an absent folder is an error instead, so CI always runs them.
    Tests that need Debian programs are handled by :func:`_skip_missing_tools`, tests
    marked ``qgis`` (QGIS for the system Python) by :func:`_skip_without_qgis`.
    """
    _skip_missing_tools(items)
    _skip_without_qgis(items)
    if EXTERNAL.is_dir():
        return
    marked = [item for item in items if item.get_closest_marker("external")]
    if not marked:
        return
    if os.environ.get("CI"):
        raise pytest.UsageError(
            f"CI is set and {len(marked)} collected tests are marked external, but {EXTERNAL} "
            "is missing: CI must run them (the folder sits beside the checkout)"
        )
    skip = pytest.mark.skip(reason=EXTERNAL_WHY)
    for item in marked:
        item.add_marker(skip)


def _load_make_samples():
    spec = importlib.util.spec_from_file_location("make_samples", SAMPLES / "make_samples.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="session")
def make_samples():
    return _load_make_samples()


@pytest.fixture(scope="session")
def sample_dir(tmp_path_factory, make_samples):
    """The sample sheet written by samples/make_samples.py into a fresh directory."""
    out = tmp_path_factory.mktemp("samples")
    make_samples.make(out)
    return out


@pytest.fixture
def sample_map(sample_dir):
    import apygis

    return apygis.read(sample_dir / "ZH1091")
