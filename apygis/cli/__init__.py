"""The ``apygis`` command line.

One module per command, in the manner of rasterio's ``rio``: each module
defines one click command (or group), and every command, built-in or from a
third-party package, is registered through the entry-point group
``apygis.commands``. The commands are thin: they parse options, call the
library and print; the library itself never prints.

``-v`` / ``-q`` set the log level of the ``apygis`` logger (WARNING by
default, INFO with ``-v``, DEBUG with ``-vv``, ERROR with ``-q``); they may
also follow the command (``apygis info -v MAP``). ``-h`` is ``--help``
everywhere.
"""

from __future__ import annotations

import logging
import re
from importlib.metadata import entry_points

import click

__all__ = ["main"]

log = logging.getLogger(__name__)

COMMAND_GROUP = "apygis.commands"

_LOG_OPTION = re.compile(r"-[vq]+|--verbose|--quiet")
HELP_OPTIONS = ["-h", "--help"]


class _PluginGroup(click.Group):
    """A click group whose sub-commands come from the ``apygis.commands`` entry points.

    Commands are loaded lazily, so ``apygis formats`` does not import the
    orientation or DXF code. A plug-in that fails to load is reported as a
    broken command instead of breaking the whole CLI.
    """

    def _eps(self):
        return {ep.name: ep for ep in entry_points(group=COMMAND_GROUP)}

    def parse_args(self, ctx, args):
        return super().parse_args(ctx, self._hoist_log_options(ctx, list(args)))

    def _hoist_log_options(self, ctx, args: list[str]) -> list[str]:
        """``args`` with the ``-v``/``-q`` given after the command moved before it.

        The values of the command's own options are stepped over (``--name -v``
        keeps its value), a command that defines ``-v``/``-q`` itself keeps
        them, and nothing after ``--`` moves.
        """
        i = 0
        while i < len(args) and args[i].startswith("-") and args[i] != "--":
            i += 1  # the group's own options take no value
        if i == len(args) or args[i] == "--":
            return args
        cmd = self.get_command(ctx, args[i])
        head, rest = args[: i + 1], args[i + 1 :]
        moved: list[str] = []
        tail: list[str] = []
        k = 0
        while cmd is not None and k < len(rest):
            a = rest[k]
            k += 1
            if a == "--":
                tail.append(a)
                break
            opts = _value_options(cmd)
            if _LOG_OPTION.fullmatch(a) and a not in opts and not _own_log_option(cmd, a):
                moved.append(a)
                continue
            tail.append(a)
            if a in opts and k < len(rest):
                tail.append(rest[k])
                k += 1
            elif isinstance(cmd, click.Group) and not a.startswith("-"):
                cmd = cmd.get_command(ctx, a)
        return moved + head + tail + rest[k:]

    def list_commands(self, ctx):
        return sorted(set(self._eps()) | set(self.commands))

    def invoke(self, ctx):
        """Run the command; whatever escapes it ends in one line on standard error.

        Commands turn an :class:`~apygis.errors.ApygisError` into a one-line
        message themselves; this is the net for the rest, so that a user never
        sees a traceback (``-vv`` logs it): an ``OSError`` names the file and the
        reason with exit code 1, Ctrl-C exits with 130 as shells expect, running
        out of memory or recursion says so, and anything else is reported as an
        internal error, exit code 1.
        """
        try:
            return super().invoke(ctx)
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except KeyboardInterrupt:
            click.echo("apygis: interrupted", err=True)
            ctx.exit(130)
        except Exception as exc:
            log.debug("traceback", exc_info=True)
            raise click.ClickException(_last_resort_message(exc)) from exc

    def get_command(self, ctx, cmd_name):
        if cmd_name in self.commands:
            return self.commands[cmd_name]
        ep = self._eps().get(cmd_name)
        if ep is None:
            return None
        try:
            return _help_everywhere(ep.load())
        except Exception as exc:  # a broken plug-in must not break the CLI
            msg = f"the command {cmd_name!r} ({ep.value}) failed to load: {exc}"

            @click.command(cmd_name, help=f"(broken) {msg}")
            def broken():
                raise click.ClickException(msg)

            return broken


def _help_everywhere(cmd: click.Command) -> click.Command:
    """``cmd`` and its sub-commands with ``-h`` and ``--help`` as their help option.

    The group's ``context_settings`` would pass them on, but click (8.1.8 and
    later) caches a command's help option when first built: a command invoked
    on its own first (a test, a library user) would keep ``--help`` alone.
    """
    cmd.context_settings.setdefault("help_option_names", HELP_OPTIONS)
    cached = getattr(cmd, "_help_option", None)
    if cached is not None and set(cached.opts) != set(cmd.context_settings["help_option_names"]):
        cmd._help_option = None
    if isinstance(cmd, click.Group):
        for sub in cmd.commands.values():
            _help_everywhere(sub)
    return cmd


def _value_options(cmd: click.Command) -> set[str]:
    """The option names of ``cmd`` that take a value (the next argument)."""
    return {
        name
        for p in cmd.params
        if isinstance(p, click.Option) and not p.is_flag and not p.count
        for name in (*p.opts, *p.secondary_opts)
    }


def _own_log_option(cmd: click.Command, arg: str) -> bool:
    """Whether ``cmd`` defines an option of ``arg``'s letters itself (it keeps them)."""
    names = {n for p in cmd.params for n in (*p.opts, *p.secondary_opts)}
    if arg.startswith("--"):
        return arg in names
    return any(f"-{c}" in names for c in set(arg[1:]))


@click.group(cls=_PluginGroup, context_settings={"help_option_names": HELP_OPTIONS})
@click.option("-v", "--verbose", count=True, help="More log output (-vv for debug).")
@click.option("-q", "--quiet", count=True, help="Less log output.")
@click.version_option(package_name="apygis")
def main(verbose: int, quiet: int) -> None:
    """apygis: photogrammetric map revision and aerotriangulation."""
    level = logging.WARNING - 10 * verbose + 10 * quiet
    logging.basicConfig(
        level=max(logging.DEBUG, min(logging.CRITICAL, level)),
        format="%(levelname)s %(name)s: %(message)s",
    )


def _last_resort_message(exc: BaseException) -> str:
    """One line for an exception that no command turned into a message of its own."""
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if exc.filename else ""
        return f"{where}{exc.strerror or exc}"
    if isinstance(exc, MemoryError):
        return "out of memory: the input is too large for this machine"
    if isinstance(exc, RecursionError):
        return "the input is nested too deeply to be processed"
    return (
        f"internal error ({type(exc).__name__}: {exc}); this is a bug in apygis: "
        "please report it with the output of the same command run with -vv"
    )
