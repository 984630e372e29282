"""apygis ships ``py.typed``: its annotations are checked with mypy and must hold.

mypy runs with the ``[tool.mypy]`` configuration of pyproject.toml (the files,
the strictness and the per-module overrides), from the repository root, with
its cache in ``.mypy_cache`` there (git-ignored): a cold run takes some 30 s, a
warm one a few.
"""

from __future__ import annotations

from mypy import api

from tests.conftest import ROOT


def test_mypy_passes(monkeypatch):
    monkeypatch.chdir(ROOT)  # the config's ``files`` are relative to the repository root
    stdout, stderr, status = api.run(
        ["--config-file", "pyproject.toml", "--cache-dir", ".mypy_cache", "--no-pretty"]
    )
    assert status == 0, f"mypy (exit status {status}):\n{stdout}{stderr}"
