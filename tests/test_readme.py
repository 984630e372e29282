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


def test_readme_command_line_examples_run_and_write_only_under_out(tmp_path):
    """Every command of the README's command-line section runs (all but the one that
    needs a real tablet and motors) and writes nothing outside ``out/``."""
    text = (ROOT / "README.md").read_text()
    block = next(b for b in _sh_blocks(text) if "apygis formats" in b)
    commands = [c for c in _apygis_commands(block) if "/dev/tty" not in c]
    assert len(commands) >= 10
    root = _sandbox(tmp_path)
    (root / "home").mkdir()
    before = _files(root)
    _run_readme_commands(commands, root)
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
    assert [c.split()[:2] for c in commands] == [
        ["apygis", "at"],
        ["apygis", "at"],
        ["apygis", "at"],
        ["apygis", "at"],
    ]
    root = _sandbox(tmp_path)
    (root / "home").mkdir()
    before = _files(root)
    _run_readme_commands(commands, root)
    new = {p for p in _files(root) - before if p.parts[0] != "home"}
    assert all(p.parts[0] == "out" for p in new), sorted(map(str, new))
    assert (root / "out" / "at-demo.png").is_file()
    assert (root / "out" / "at-demo.block").is_file()
