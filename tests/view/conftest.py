"""Fixtures of the view's tests: a headless Chromium, and apygis servers run as a user runs them.

Tests marked ``browser`` need Debian's ``chromium`` and ``chromium-driver``
(``apt-get install chromium chromium-driver``); they are skipped, with that
reason, where either is missing, except under ``CI=true``, where ``.ci/run``
installs them and a missing one is an error.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import ROOT

BROWSER_WHY = (
    "needs headless Chromium and its WebDriver: Debian's packages chromium and chromium-driver "
    "(apt-get install chromium chromium-driver)"
)
URL_RE = re.compile(r"(http://\S+/)")


def chromium_paths() -> tuple[str, str] | None:
    binary = next(
        (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p),
        None,
    )
    driver = shutil.which("chromedriver")
    return (binary, driver) if binary and driver else None


def pytest_collection_modifyitems(config, items):
    marked = [item for item in items if item.get_closest_marker("browser")]
    if not marked or chromium_paths() is not None:
        return
    if os.environ.get("CI"):
        raise pytest.UsageError(
            f"CI is set and {len(marked)} collected tests are marked browser, but Chromium or "
            "chromedriver is missing: .ci/run installs them"
        )
    skip = pytest.mark.skip(reason=BROWSER_WHY)
    for item in marked:
        item.add_marker(skip)


@pytest.fixture(scope="session")
def chrome():
    """A headless Chromium driven through WebDriver (one for all browser tests)."""
    paths = chromium_paths()
    if paths is None:
        pytest.skip(BROWSER_WHY)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = paths[0]
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--window-size=1400,900",
        "--no-first-run",
        "--disable-background-networking",
    ):
        opts.add_argument(arg)
    drv = webdriver.Chrome(service=Service(executable_path=paths[1]), options=opts)
    drv.set_page_load_timeout(30)
    try:
        yield drv
    finally:
        drv.quit()


def apygis_argv(*args: str) -> list[str]:
    exe = Path(sys.executable).with_name("apygis")
    prefix = [str(exe)] if exe.exists() else [sys.executable, "-m", "apygis"]
    return [*prefix, *args]


class Served:
    """An apygis command that serves a page, run as a subprocess: its URL, its output, its end."""

    def __init__(self, args, cwd, timeout: float = 60.0):
        self.proc = subprocess.Popen(
            apygis_argv(*args),
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "DISPLAY": "", "WAYLAND_DISPLAY": ""},
        )
        self.lines: list[str] = []
        self.url = self.wait_for(URL_RE, timeout).group(1)

    def wait_for(self, pattern, timeout: float = 60.0):
        """Read standard output until a line matches ``pattern``; returns the match."""
        rx = re.compile(pattern) if isinstance(pattern, str) else pattern
        for line in self.lines:
            m = rx.search(line)
            if m:
                return m
        deadline = time.monotonic() + timeout
        assert self.proc.stdout is not None
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                err = self.proc.stderr.read() if self.proc.stderr else ""
                raise AssertionError(f"ended before {rx.pattern!r}:\n{''.join(self.lines)}\n{err}")
            self.lines.append(line)
            m = rx.search(line)
            if m:
                return m
        raise AssertionError(f"no {rx.pattern!r} within {timeout} s:\n{''.join(self.lines)}")

    def stop(self) -> tuple[int, str, str]:
        """Ctrl-C; returns (exit code, the rest of standard output, standard error)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        out, err = self.proc.communicate(timeout=30)
        return self.proc.returncode, "".join(self.lines) + out, err


@pytest.fixture
def sandbox(tmp_path):
    """A folder with a copy of the samples, as the repository root has them."""
    shutil.copytree(ROOT / "samples", tmp_path / "samples")
    return tmp_path


@pytest.fixture
def served():
    started: list[Served] = []

    def start(args, cwd, timeout: float = 60.0) -> Served:
        s = Served(args, cwd, timeout)
        started.append(s)
        return s

    yield start
    for s in started:
        if s.proc.poll() is None:
            s.proc.kill()
            s.proc.wait(timeout=10)
