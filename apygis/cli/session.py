"""``apygis session``: a map-revision session, live on an instrument or replayed."""

from __future__ import annotations

import click

from apygis.cli._common import run_guarded


def _copy_map(src_base, out_dir, overwrite: bool):
    """Copy the APY layer files of ``src_base`` into ``out_dir``; returns the new base."""
    from pathlib import Path

    import apygis
    from apygis.errors import FileOverwriteError

    src_base = Path(src_base)
    out = Path(out_dir) / src_base.name
    if Path(str(out) + ".journal").exists():
        return out  # a session was interrupted there: recover it
    existing = [p for p in out.parent.glob(out.name + ".*")] if out.parent.is_dir() else []
    if existing and not overwrite:
        raise FileOverwriteError(
            f"{existing[0]} exists; use --overwrite to start over in {out_dir}"
        )
    for p in existing:
        p.unlink()
    try:
        m = apygis.read(src_base, driver="apy")
    except apygis.ApygisError:
        if any(src_base.parent.glob(src_base.name + ".*")):
            raise
        return out  # a new map
    apygis.write(m, out, driver="apy")
    return out


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
@click.option("--library", type=click.Path(), help="Symbol library.")
@click.option(
    "--pad", type=click.Path(dir_okay=False), help="Button pad file (docs/button-pad.md)."
)
@click.option("--realtime", is_flag=True, help="Replay at the recorded pace.")
@run_guarded
def session(
    map_path, orientation, layer, tablet, motors, replay, record, output, overwrite,
    recover_only, library, pad, realtime,
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
    journal was left behind by a crash recovers it first.
    """
    from pathlib import Path

    from apygis.compile.oriented import OrientedGeometry
    from apygis.compile.session import ReportDecoder, Session, run_tablet_stream
    from apygis.instrument.replay import Replayer, read_recording
    from apygis.instrument.simulator import BUTTONS
    from apygis.instrument.tablet import TabletConfig, make_parser
    from apygis.model.symbols import load_library
    from apygis.orient.io import load_orientation

    if sum(bool(x) for x in (tablet, replay, recover_only)) != 1:
        raise click.UsageError("give one of --tablet, --replay or --recover-only")
    base = Path(map_path)
    if output:
        base = _copy_map(base, output, overwrite)
    orient = load_orientation(orientation)
    geometry = OrientedGeometry(orient)
    meta = {}
    if replay:
        meta, _ = read_recording(replay)
    protocol = (tablet.split(":", 1)[0] if tablet else meta.get("protocol", "calcomp")).lower()
    config = TabletConfig(counts_per_mm=float(meta.get("counts_per_mm", 40.0)))
    ctl = None
    if motors and not recover_only:
        from apygis.instrument.motors import SimulatedGrbl, open_controller

        if motors == "sim":
            sim = SimulatedGrbl()
            ctl = open_controller(sim.serve_tcp())
        elif motors.startswith("grbl:"):
            ctl = open_controller(motors[5:])
        else:
            raise click.BadParameter("grbl:URL or sim", param_hint="--motors")
    sess = Session(
        base,
        geometry,
        layer=layer,
        motors=ctl,
        monitor=click.echo,
        library=load_library(library),
    )
    try:
        if recover_only:
            return
        parser = make_parser(protocol, config)
        if pad:
            from apygis.instrument.pad import load_pad

            decoder = ReportDecoder(config, load_pad(pad))
        else:
            decoder = ReportDecoder(config, BUTTONS)
        if replay:
            run_tablet_stream(sess, Replayer(replay, realtime=realtime).chunks(), parser, decoder)
        else:
            _live(sess, tablet.split(":", 1)[1], parser, decoder, record, protocol, config)
    finally:
        if not sess.finished:
            sess.close()
        if ctl is not None:
            ctl.close()
        stats = parser.stats if not recover_only else {}
        if stats:
            click.echo(
                f"tablet: {stats['packets']} reports, {stats['discarded_bytes']} bytes discarded, "
                f"{stats['resyncs']} resyncs",
            )


def _live(sess, url, parser, decoder, record, protocol, config):
    """Read the tablet, and typed lines on standard input, until the session ends."""
    import queue
    import sys
    import threading

    import serial

    from apygis.compile.session import run_live
    from apygis.errors import InstrumentError
    from apygis.instrument.replay import Recorder

    try:
        port = serial.serial_for_url(url, timeout=0.002)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise InstrumentError(f"cannot open the tablet port {url}: {exc}") from exc
    rec = None
    if record:
        rec = Recorder(record, meta={"protocol": protocol, "counts_per_mm": config.counts_per_mm})
        port = rec.wrap(port, "tablet")
    click.echo(f"tablet {protocol} on {url}: ready")
    typed: queue.Queue = queue.Queue()

    def keyboard():
        for line in sys.stdin:
            typed.put(line.rstrip("\n"))

    threading.Thread(target=keyboard, daemon=True).start()
    try:
        run_live(sess, port, parser, decoder, typed, rec)
    except KeyboardInterrupt:
        click.echo("interrupted")
    finally:
        port.close()
        if rec is not None:
            rec.close()
