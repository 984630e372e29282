"""Whatever escapes a command ends in one line on standard error, never a traceback."""

from __future__ import annotations

import errno

import click
import pytest
from click.testing import CliRunner

from apygis.cli import main


def _raising(exc: BaseException):
    @click.command("raise-it")
    def command():
        raise exc

    return command


@pytest.fixture
def run_raising():
    def run(exc):
        main.add_command(_raising(exc))
        try:
            return CliRunner().invoke(main, ["raise-it"])
        finally:
            main.commands.pop("raise-it")

    return run


@pytest.mark.parametrize(
    ("exc", "code", "text"),
    [
        (OSError(errno.ENOSPC, "No space left on device", "out/x.gpkg"), 1,
         "Error: out/x.gpkg: No space left on device\n"),
        (KeyboardInterrupt(), 130, "apygis: interrupted\n"),
        (MemoryError(), 1, "Error: out of memory: the input is too large for this machine\n"),
        (RecursionError(), 1, "Error: the input is nested too deeply to be processed\n"),
        (ValueError("x"), 1, "Error: internal error (ValueError: x); this is a bug in apygis: "
         "please report it with the output of the same command run with -vv\n"),
    ],
)  # fmt: skip
def test_one_line_and_exit_code(run_raising, exc, code, text):
    result = run_raising(exc)
    assert result.exit_code == code
    assert result.output == text
    assert "Traceback" not in result.output
