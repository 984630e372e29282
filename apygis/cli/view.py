"""``apygis view``: the map on a local web page; the helpers ``session`` and ``orient`` share.

The page is served on 127.0.0.1 (this machine) at a free port, under a
random token printed with the URL; ``--host`` serves it elsewhere, with a
warning. It is opened in a browser where there is a graphical display, and
served until Ctrl-C.
"""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

import click

from apygis.cli._common import run_guarded

__all__ = ["serve_until_interrupted", "start_view", "view", "view_server"]


def view_server(host: str, port: int, process: bool = False):
    """A bound view server (no hub yet); warns when not this machine only.

    A :class:`~apygis.view.ViewServer` on a thread of this process, or with
    ``process`` (a session's view) a :class:`~apygis.view.ViewProcess`.
    """
    from apygis.view import ViewProcess, ViewServer, is_loopback

    if not is_loopback(host):
        click.echo(
            f"warning: the view is served on {host}, not only to this machine: anyone who can "
            "reach it and has the URL (with its token) can watch the map",
            err=True,
        )
    server = (ViewProcess if process else ViewServer)(None, host=host, port=port)
    server.bind()
    return server


def start_view(server, hub, what: str, no_browser: bool) -> str:
    """Start ``server`` with ``hub``, print the URL, open a browser where there is a display."""
    server.hub = hub
    url = server.start()
    click.echo(f"view of {what}: {url}")
    if not no_browser and _has_display():
        import webbrowser

        threading.Thread(target=webbrowser.open, args=(url,), daemon=True).start()
    return url


def _has_display() -> bool:
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def serve_until_interrupted(server, note: str = "Ctrl-C to stop") -> None:
    """Serve until Ctrl-C (or SIGTERM), then stop the server; exit status 0."""
    import signal
    import time

    def _term(signum, frame):
        raise KeyboardInterrupt

    old = None
    if threading.current_thread() is threading.main_thread():
        old = signal.signal(signal.SIGTERM, _term)
    click.echo(note)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        click.echo("view stopped")
    finally:
        server.stop()
        if old is not None:
            signal.signal(signal.SIGTERM, old)


def host_options(prefix: str = ""):
    """Options ``--host``, ``--port`` (``--view-host``, ``--view-port``), ``--no-browser``."""

    def deco(f):
        f = click.option(
            "--no-browser", is_flag=True, help="Do not open a browser (the URL is printed)."
        )(f)
        f = click.option(
            f"--{prefix}port",
            type=click.IntRange(0, 65535),
            default=0,
            show_default=True,
            help="Port of the page (0: a free one).",
        )(f)
        f = click.option(
            f"--{prefix}host",
            default="127.0.0.1",
            show_default=True,
            help="Address to serve the page on; anything but 127.0.0.1 is reachable by others "
            "(a warning is printed).",
        )(f)
        return f

    return deco


def plotter_and_library(plotter, library):
    """The plotter definition (pens) and the symbol library the page draws with."""
    from apygis.model.symbols import load_library
    from apygis.plot.plotdef import read_plotdef

    pdef = read_plotdef(plotter) if plotter else None
    return pdef, load_library(library)


@click.command("view")
@click.argument("map_path", metavar="MAP", type=click.Path(path_type=Path))
@click.option("--driver", default=None, help="Read MAP with this driver (apygis formats).")
@click.option(
    "--plotter",
    type=click.Path(dir_okay=False, path_type=Path),
    help="PLOTTER.DEF whose pens draw the map (default: the built-in pens).",
)
@click.option("--library", type=click.Path(path_type=Path), help="Symbol library.")
@host_options()
@run_guarded
def view(map_path, driver, plotter, library, host, port, no_browser):
    """Show MAP on a local web page: layers, symbols, texts, spot heights; pan and zoom.

    \b
      apygis view samples/ZH1091
      apygis view out/sheet.gpkg --plotter samples/PLOTTER.DEF --port 8765

    The page is served on 127.0.0.1 at a free port under a random token (in
    the printed URL; without it the server answers 403) until Ctrl-C. It
    shows every layer in the plot's pens (switch layers on and off), the
    coordinates under the pointer in the map's CRS, and a clicked record's
    number, code and references.
    """
    import apygis
    from apygis.view import map_hub

    server = view_server(host, port)
    try:
        pdef, lib = plotter_and_library(plotter, library)
        m = apygis.read(map_path, driver=driver)
        hub = map_hub(m, plotdef=pdef, library=lib, source=str(map_path))
        n = sum(len(lay) for lay in m)
        start_view(server, hub, f"map {m.id} ({len(m.layers)} layers, {n} records)", no_browser)
    except BaseException:
        server.stop()
        raise
    serve_until_interrupted(server)
