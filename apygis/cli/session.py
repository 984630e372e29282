"""``apygis session``: a map-revision session, live on an instrument or replayed."""

from __future__ import annotations

from typing import cast

import click

from apygis.cli._common import run_guarded
from apygis.cli.view import host_options


def _copy_map(src_base, out, overwrite: bool):
    """Copy the APY layer files of ``src_base`` to ``out`` (``dir/ID``); returns ``out``.

    Called with the session lock on ``out`` held. The source is read before
    anything in the output folder is touched.
    """
    from pathlib import Path

    import apygis
    from apygis.errors import FileOverwriteError

    src_base, out = Path(src_base), Path(out)
    if Path(str(out) + ".journal").exists():
        return out  # a session was interrupted there: recover it
    lock = out.name + ".lock"
    existing = (
        [p for p in sorted(out.parent.glob(out.name + ".*")) if p.name != lock]
        if out.parent.is_dir()
        else []
    )
    if existing and not overwrite:
        raise FileOverwriteError(
            f"{existing[0]} exists; use --overwrite to start over in {out.parent}"
        )
    m = None
    try:
        m = apygis.read(src_base, driver="apy")
    except apygis.ApygisError:
        if any(src_base.parent.glob(src_base.name + ".*")):
            raise
    for p in existing:
        p.unlink()
    if m is not None:
        apygis.write(m, out, driver="apy")
    return out  # without m: a new map


def _tablet_spec(tablet: str) -> tuple[str, str]:
    """``PROTOCOL:URL`` -> (protocol, url), both checked."""
    from apygis.errors import ProtocolError
    from apygis.instrument.tablet import PROTOCOLS

    protocol, sep, url = tablet.partition(":")
    protocol = protocol.strip().lower()
    if not sep or not url.strip():
        raise ProtocolError(
            f"--tablet {tablet!r}: expected PROTOCOL:URL, e.g. calcomp:/dev/ttyUSB0"
        )
    if protocol not in PROTOCOLS:
        raise ProtocolError(
            f"--tablet {tablet!r}: unknown tablet protocol {protocol!r}; expected one of "
            f"{', '.join(PROTOCOLS)}"
        )
    return protocol, url


@click.command()
@click.argument("map_path", metavar="MAP", type=click.Path())
@click.option(
    "--orientation",
    type=click.Path(exists=True, dir_okay=False),
    required=True,
    help="Orientation file (apygis orient ...).",
)
@click.option("--layer", default="c", show_default=True, help="Layer to compile into first.")
@click.option("--tablet", metavar="PROTOCOL:URL", help="Live tablet, e.g. calcomp:/dev/ttyUSB0.")
@click.option("--motors", metavar="grbl:URL|sim", help="Plate motor controller.")
@click.option("--replay", type=click.Path(exists=True, dir_okay=False), help="Replay a recording.")
@click.option("--record", type=click.Path(dir_okay=False), help="Record the tablet bytes.")
@click.option("-o", "--output", type=click.Path(file_okay=False), help="Work on a copy here.")
@click.option("--overwrite", is_flag=True, help="Replace files of an earlier run in --output.")
@click.option("--recover-only", is_flag=True, help="Recover a journal, save, and stop.")
@click.option(
    "--discard-journal",
    is_flag=True,
    help="Rename a journal left behind aside (MAP.journal.discarded) instead of recovering it.",
)
@click.option(
    "--trust-journal",
    is_flag=True,
    help="Recover a journal left behind even though the layer files changed since "
    "(or it is too old to tell): the replay overwrites those changes.",
)
@click.option("--library", type=click.Path(), help="Symbol library.")
@click.option(
    "--pad", type=click.Path(dir_okay=False), help="Button pad file (docs/button-pad.md)."
)
@click.option("--realtime", is_flag=True, help="Replay at the recorded pace.")
@click.option(
    "--view",
    "view_page",
    is_flag=True,
    help="Show the compilation live on a local web page (the graphic display); the page "
    "stays up after the session until Ctrl-C.",
)
@click.option(
    "--view-wait",
    type=click.FloatRange(0, 3600),
    default=0.0,
    help="With --view: wait up to this many seconds for a page to open before the input "
    "starts (a replay shown from its first entry).",
)
@click.option(
    "--plotter",
    type=click.Path(dir_okay=False),
    help="With --view: PLOTTER.DEF whose pens draw the page.",
)
@host_options("view-")
@run_guarded
def session(
    map_path, orientation, layer, tablet, motors, replay, record, output, overwrite,
    recover_only, discard_journal, trust_journal, library, pad, realtime, view_page, view_wait,
    plotter, view_host, view_port, no_browser,
):  # fmt: skip
    """Run a revision session on MAP (dir/ID), or replay a recorded one.

    \b
      apygis session samples/ZH1091 --orientation samples/session/ZH1091.orientation.json \\
          --replay samples/session/ZH1091-revision.rec -o out/
      apygis session maps/ZH1091 --orientation o.json --tablet calcomp:/dev/ttyUSB0 \\
          --motors grbl:/dev/ttyACM0 --record today.rec

    Every entry is journaled (MAP.journal) before it is acknowledged; the
    layer files are saved after every 50 entries, on PROCEED and at the end,
    with the margin file MAP-margin.apa. A session started on a map whose
    journal was left behind by a crash recovers it first -- if the layer
    files are still those the journal knows; if they changed since, it
    refuses (see --discard-journal and --trust-journal).

    One session at a time per map: a session holds the lock MAP.lock and a
    second one is refused. Everything (orientation, pad, tablet, recording,
    ports) is checked before any file is written.

    With --view the graphic display is served on a local web page (URL
    printed, token included): records appear as they are entered, the
    floating mark moves, the status line, the PROCEED menu's display scale
    factor and crosshair scale, AREA and DHI results are shown. The session
    never waits for the page.
    """
    import contextlib
    from pathlib import Path

    from apygis.compile.oriented import OrientedGeometry
    from apygis.errors import (
        ApygisError,
        FileOverwriteError,
        InstrumentError,
        ProtocolError,
        RecordError,
    )
    from apygis.instrument.pad import BUTTONS
    from apygis.instrument.replay import Replayer, check_recording
    from apygis.instrument.tablet import TabletConfig, make_parser
    from apygis.model.map import check_ext
    from apygis.model.symbols import load_library
    from apygis.orient.io import load_orientation
    from apygis.session import ReportDecoder, Session, SessionLock, run_tablet_stream

    if sum(bool(x) for x in (tablet, replay, recover_only)) != 1:
        raise click.UsageError("give one of --tablet, --replay or --recover-only")
    if discard_journal and trust_journal:
        raise click.UsageError("--discard-journal and --trust-journal exclude each other")
    if motors and not (motors == "sim" or (motors.startswith("grbl:") and motors[5:])):
        raise ProtocolError(f"--motors {motors!r}: expected grbl:URL or sim")
    try:
        check_ext(layer)
    except RecordError as exc:
        raise RecordError(f"--layer: {exc}") from None

    # 1. everything the session needs, checked before any file is read or written
    geometry = OrientedGeometry(load_orientation(orientation))
    lib = load_library(library)
    meta: dict = {}
    protocol = url = None
    if tablet:
        protocol, url = _tablet_spec(tablet)
    if replay:
        meta = check_recording(replay)
        protocol = str(meta.get("protocol", "calcomp")).lower()
    config = TabletConfig(counts_per_mm=float(meta.get("counts_per_mm", 40.0)))
    parser = decoder = None
    if not recover_only:
        parser = make_parser(cast(str, protocol), config)  # set by --tablet or --replay
        if pad:
            from apygis.instrument.pad import load_pad

            decoder = ReportDecoder(config, load_pad(pad))
        else:
            decoder = ReportDecoder(config, BUTTONS)
    if record and Path(record).exists():
        raise FileOverwriteError(f"{record}: exists; choose another name for --record")
    if record and not Path(record).resolve().parent.is_dir():
        raise InstrumentError(f"{record}: cannot record there: no folder {Path(record).parent}")
    source = Path(map_path)
    base = Path(output) / source.name if output else source
    made_dir = not base.parent.exists()
    server = pdef = None
    if view_page:
        from apygis.cli.view import plotter_and_library, view_server

        pdef, _ = plotter_and_library(plotter, None)
        # the address is taken before any file
        server = view_server(view_host, view_port, process=True)
    elif plotter or view_wait:
        raise click.UsageError("--plotter and --view-wait go with --view")

    # 2. the map's lock, then the instruments, then the files
    lock = SessionLock.acquire(base)
    port = ctl = sess = None
    try:
        if tablet:
            port = _open_tablet(url)
        if motors and not recover_only:
            ctl = _open_motors(motors)
        if output:
            _copy_map(source, base, overwrite)
        sess = Session(
            base,
            geometry,
            layer=layer,
            motors=ctl,
            monitor=click.echo,
            library=lib,
            lock=lock,
            discard_journal=discard_journal,
            trust_journal=trust_journal,
        )
    except BaseException:
        for thing in (port, ctl):
            if thing is not None:
                with contextlib.suppress(Exception):
                    thing.close()
        if server is not None:
            server.stop()
        lock.release()
        if made_dir:
            with contextlib.suppress(OSError):
                base.parent.rmdir()  # only if empty: nothing was written
        raise

    # 3. the display, then the session
    feed = None
    if server is not None:
        feed = _start_view(sess, server, pdef, lib, no_browser, view_wait)
    try:
        if not recover_only and not sess.finished:
            if replay:
                run_tablet_stream(
                    sess, Replayer(replay, realtime=realtime), parser, cast(ReportDecoder, decoder)
                )
            else:
                _live(sess, port, url, parser, decoder, record, protocol, config)
    except BaseException:
        with contextlib.suppress(ApygisError):  # it has told the operator what it could not save
            sess.close()
        if server is not None:
            server.stop()
        raise
    finally:
        if ctl is not None:
            with contextlib.suppress(Exception):
                ctl.close()
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()
        stats = parser.stats if parser is not None else {}
        if stats:
            click.echo(
                f"tablet: {stats['packets']} reports, {stats['discarded_bytes']} bytes discarded, "
                f"{stats['resyncs']} resyncs",
            )
    try:
        sess.close()  # input ended without terminating: save, keep the journal
    except BaseException:
        if server is not None:
            server.stop()
        raise
    if server is not None and feed is not None:
        from apygis.cli.view import serve_until_interrupted

        feed.end(sess)
        serve_until_interrupted(
            server, f"session ended; the view stays at {server.url} until Ctrl-C"
        )


def _start_view(sess, server, pdef, lib, no_browser: bool, wait: float):
    """Serve the session's page (its process follows the session's journal); returns the feed."""
    from apygis.cli.view import start_view
    from apygis.view import SessionFeed, session_hub

    try:
        hub = session_hub(sess, plotdef=pdef, library=lib)
        start_view(server, hub, f"session on {sess.map.id}", no_browser)
        feed = SessionFeed(server, sess)
    except BaseException:
        server.stop()
        sess.close()
        raise
    if wait > 0:
        click.echo(f"waiting up to {wait:g} s for the page to open")
        if not server.wait_for_viewer(wait):
            click.echo("no page opened; going on")
    return feed


def _open_tablet(url):
    from apygis.errors import InstrumentError
    from apygis.instrument.ports import open_url

    return open_url(
        url,
        lambda exc: InstrumentError(f"cannot open the tablet port {url}: {exc}"),
        timeout=0.002,
    )


def _open_motors(motors):
    from apygis.instrument.motors import SimulatedGrbl, open_controller

    if motors == "sim":
        return open_controller(SimulatedGrbl().serve_tcp())
    return open_controller(motors[5:])


def _live(sess, port, url, parser, decoder, record, protocol, config):
    """Read the tablet, and typed lines on standard input, until the session ends."""
    import queue
    import sys
    import threading

    from apygis.instrument.replay import Recorder
    from apygis.session import run_live

    rec = None
    if record:
        rec = Recorder(record, meta={"protocol": protocol, "counts_per_mm": config.counts_per_mm})
        port = rec.wrap(port, "tablet")
    click.echo(f"tablet {protocol} on {url}: ready")
    typed: queue.Queue = queue.Queue()

    def keyboard():
        # raw bytes: the session decodes them (UTF-8, else Latin-1, and tells the operator)
        stream = getattr(sys.stdin, "buffer", None)
        if stream is None:
            for line in sys.stdin:
                typed.put(line.rstrip("\n"))
            return
        for line in stream:
            typed.put(line.rstrip(b"\r\n"))

    threading.Thread(target=keyboard, daemon=True).start()
    try:
        run_live(sess, port, parser, decoder, typed, rec)
    except KeyboardInterrupt:
        click.echo("interrupted")
    finally:
        if rec is not None:
            rec.close()
