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
SAMPLES = ROOT / "samples"
EXTERNAL = ROOT.parent / "shared" / "external"


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
