"""The ``apygis`` command line.

One module per command, in the manner of rasterio's ``rio``: each module
defines one click command (or group), and every command, built-in or from a
third-party package, is registered through the entry-point group
``apygis.commands``. The commands are thin: they parse options, call the
library and print; the library itself never prints.

``-v`` / ``-q`` set the log level of the ``apygis`` logger (WARNING by
default, INFO with ``-v``, DEBUG with ``-vv``, ERROR with ``-q``).
"""

from __future__ import annotations

import logging
from importlib.metadata import entry_points

import click

__all__ = ["main"]

log = logging.getLogger(__name__)

COMMAND_GROUP = "apygis.commands"


class _PluginGroup(click.Group):
    """A click group whose sub-commands come from the ``apygis.commands`` entry points.

    Commands are loaded lazily, so ``apygis formats`` does not import the
    orientation or DXF code. A plug-in that fails to load is reported as a
    broken command instead of breaking the whole CLI.
    """

    def _eps(self):
        return {ep.name: ep for ep in entry_points(group=COMMAND_GROUP)}

    def list_commands(self, ctx):
        return sorted(set(self._eps()) | set(self.commands))

    def get_command(self, ctx, cmd_name):
        if cmd_name in self.commands:
            return self.commands[cmd_name]
        ep = self._eps().get(cmd_name)
        if ep is None:
            return None
        try:
            return ep.load()
        except Exception as exc:  # a broken plug-in must not break the CLI
            msg = f"the command {cmd_name!r} ({ep.value}) failed to load: {exc}"

            @click.command(cmd_name, help=f"(broken) {msg}")
            def broken():
                raise click.ClickException(msg)

            return broken


@click.group(cls=_PluginGroup)
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
