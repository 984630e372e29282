"""Helpers shared by the command modules: error reporting and progress bars."""

from __future__ import annotations

import functools
import sys
from typing import TextIO, cast

import click

from apygis.errors import ApygisError

__all__ = ["progress_bar", "run_guarded"]


def run_guarded(func):
    """Decorate a command so that an :class:`ApygisError` ends it with a one-line message.

    The message goes to standard error and the exit code is 1; a traceback is
    shown only with ``-vv`` (log level DEBUG).
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except ApygisError as exc:
            import logging

            logging.getLogger("apygis").debug("traceback", exc_info=True)
            raise click.ClickException(str(exc)) from exc

    return wrapper


def progress_bar(length: int, label: str):
    """A click progress bar shown on a terminal only, silent in pipes and tests.

    Returns a context manager whose ``update(n)`` advances the bar; pass
    ``bar.update`` as the library's ``progress`` callback.
    """
    return click.progressbar(
        length=length,
        label=label,
        file=sys.stderr if sys.stderr.isatty() else cast(TextIO, _Null()),
    )


class _Null:
    def write(self, s):
        return len(s)

    def flush(self):
        """Nothing is buffered."""

    def isatty(self):
        return False
