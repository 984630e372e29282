"""The README's Python example runs as written and prints what it says."""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT


def test_readme_python_example_runs(tmp_path, monkeypatch):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks
    monkeypatch.chdir(tmp_path)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for block in blocks:
            exec(compile(block, "README.md", "exec"), {})
    lines = out.getvalue().splitlines()
    assert lines[0] == "1600.0"
    assert "'closed_lines': 1" in lines[1]
    assert (tmp_path / "out" / "ZH1091.h").exists()


def _sh_blocks(text: str) -> list[str]:
    return re.findall(r"```sh\n(.*?)```", text, flags=re.S)


def _apygis_commands(block: str) -> list[str]:
    """The ``apygis ...`` lines of a shell block, without their trailing comments."""
    out = []
    for line in block.splitlines():
        line = line.split("  #")[0].strip()
        if line.startswith("apygis "):
            out.append(line)
    return out


def _run_readme_commands(commands: list[str], cwd: Path) -> None:
    exe = Path(sys.executable).with_name("apygis")
    prefix = [str(exe)] if exe.exists() else [sys.executable, "-m", "apygis"]
    env = {**os.environ, "HOME": str(cwd / "home"), "APYGIS_SYMBOLS": str(cwd / "out" / "s.apysym")}
    for command in commands:
        argv = prefix + shlex.split(command)[1:]
        done = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"{command}\n{done.stdout}\n{done.stderr}"
        assert "Traceback" not in done.stderr, f"{command}\n{done.stderr}"


def _sandbox(tmp_path: Path) -> Path:
    """A folder holding a copy of the samples, as the repository root has them."""
    shutil.copytree(ROOT / "samples", tmp_path / "samples")
    return tmp_path


def _files(root: Path) -> set[Path]:
    return {p.relative_to(root) for p in root.rglob("*") if p.is_file()}


def test_readme_main_job_runs_and_writes_only_under_out(tmp_path):
    """The README's main job (its first ``apygis`` command) works as written."""
    text = (ROOT / "README.md").read_text()
    setup, main_job = _sh_blocks(text)[:2]
    assert "pip install" in setup
    commands = _apygis_commands(main_job)
    assert len(commands) == 1
    assert commands[0].startswith("apygis session ")
    root = _sandbox(tmp_path)
    before = _files(root)
    _run_readme_commands(commands, root)
    new = _files(root) - before
    assert new, "the main job wrote nothing"
    assert all(p.parts[0] == "out" for p in new), sorted(map(str, new))
    assert (root / "out" / "ZH1091-margin.apa").is_file()


def _serves(command: str) -> bool:
    """A command that serves the graphic display until Ctrl-C (not run as a plain command)."""
    return command.startswith("apygis view ") or " --view" in command


def _run_served(command: str, cwd: Path) -> None:
    """Run a README command that serves a page as a user would: it prints its URL, the page
    loads with the token and is refused without it, a page connects (so a ``--view-wait``
    ends), a session ends, and Ctrl-C stops it with exit status 0."""
    import json
    import signal
    import urllib.error
    import urllib.request

    from tests.view.wsclient import WsClient

    exe = Path(sys.executable).with_name("apygis")
    prefix = [str(exe)] if exe.exists() else [sys.executable, "-m", "apygis"]
    env = {**os.environ, "HOME": str(cwd / "home"), "DISPLAY": "", "WAYLAND_DISPLAY": ""}
    env["APYGIS_SYMBOLS"] = str(cwd / "out" / "s.apysym")
    proc = subprocess.Popen(
        prefix + shlex.split(command)[1:], cwd=cwd, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    lines: list[str] = []
    client = None
    try:
        assert proc.stdout is not None
        url = None
        while url is None:
            line = proc.stdout.readline()
            assert line, f"{command}: ended without a URL\n{''.join(lines)}\n{proc.stderr.read()}"
            lines.append(line)
            m = re.search(r"(http://127\.0\.0\.1:\d+/\S+/)", line)
            url = m.group(1) if m else None
        with urllib.request.urlopen(url, timeout=10) as r:
            assert r.status == 200
        with urllib.request.urlopen(url + "state.json", timeout=10) as r:
            assert json.loads(r.read())["t"] == "state"
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(url.rsplit("/", 2)[0] + "/", timeout=10)
        assert refused.value.code == 403
        client = WsClient(url)
        if command.startswith("apygis session "):
            while "session ended" not in lines[-1]:
                line = proc.stdout.readline()
                assert line, f"{command}\n{''.join(lines)}\n{proc.stderr.read()}"
                lines.append(line)
            client.wait(lambda m: m.ended and len(m.entries) > 20, timeout=30)
        else:
            client.wait(lambda m: m.seq >= 0)
    finally:
        if client is not None:
            client.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, f"{command}\n{''.join(lines)}{out}\n{err}"
    assert "Traceback" not in err, f"{command}\n{err}"


def test_readme_command_line_examples_run_and_write_only_under_out(tmp_path):
    """Every command of the README's command-line section runs (all but the one that
    needs a real tablet and motors) and writes nothing outside ``out/``; the commands that
    serve the graphic display are run as servers (loaded, then stopped with Ctrl-C)."""
    text = (ROOT / "README.md").read_text()
    block = next(b for b in _sh_blocks(text) if "apygis formats" in b)
    commands = [c for c in _apygis_commands(block) if "/dev/tty" not in c]
    served = [c for c in commands if _serves(c)]
    assert len(commands) - len(served) >= 10
    assert any(c.startswith("apygis view ") for c in served)
    assert any(c.startswith("apygis session ") for c in served)
    root = _sandbox(tmp_path)
    (root / "home").mkdir()
    before = _files(root)
    _run_readme_commands([c for c in commands if not _serves(c)], root)
    for command in served:
        _run_served(command, root)
    new = {p for p in _files(root) - before if p.parts[0] != "home"}
    assert new
    assert all(p.parts[0] == "out" for p in new), sorted(map(str, new))


def test_readme_aerotriangulation_demo_runs_and_writes_only_under_out(tmp_path):
    """The README's aerotriangulation demo (one command line of ``&&``-joined ``apygis at``
    commands) runs as written, writes only under ``out/`` and ends with tie points."""
    text = (ROOT / "README.md").read_text()
    block = next(b for b in _sh_blocks(text) if b.startswith("apygis at synth out/"))
    (line,) = [ln for ln in block.splitlines() if ln.strip()]
    commands = [c.strip() for c in line.split("&&")]
    assert [c.split()[:3] for c in commands] == [
        ["apygis", "at", "synth"],
        ["apygis", "at", "init"],
        ["apygis", "at", "match"],
        ["apygis", "at", "gcp"],
        ["apygis", "at", "adjust"],
    ]
    root = _sandbox(tmp_path)
    (root / "home").mkdir()
    before = _files(root)
    _run_readme_commands(commands, root)
    new = {p for p in _files(root) - before if p.parts[0] != "home"}
    assert all(p.parts[0] == "out" for p in new), sorted(map(str, new))
    assert (root / "out" / "at-demo.png").is_file()
    assert (root / "out" / "at-demo.block").is_file()
    assert (root / "out" / "at-demo-adjust.png").is_file()
