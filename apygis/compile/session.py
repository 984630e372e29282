"""A map-revision session: the engine, the instrument, the journal and the files.

:class:`Session` wires the parts: tablet reports become engine events
(:class:`ReportDecoder`), every event is journaled (an entry is on disk
before it is acknowledged: see :mod:`apygis.compile.journal`), plate
positions go to the motor controller, and the layer files are saved,
atomically, after every 50 entries, on PROCEED and at the end, with the
margin file (the line points lacking a forward or backward reference).

Files of a session on the map ``dir/ID``:

* ``dir/ID.<ext>``: the APY layer files (read at the start, saved);
* ``dir/ID.journal``: the journal, removed when the session terminates
  cleanly; a session started on a map with a journal recovers it first;
* ``dir/ID-margin.apa``: the margin file (APY ASCII), written at the end.

The session never prints: it hands the operator's monitor lines to a
``monitor`` callback (the CLI prints them).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from pathlib import Path

from apygis.compile.engine import (
    RECORD_EFFECTS,
    Added,
    Engine,
    Keys,
    Linked,
    Mark,
    Message,
    Plates,
    Press,
    Save,
    Status,
    Terminate,
    Undone,
    ZeroPlates,
)
from apygis.compile.journal import Journal, read_journal
from apygis.model.map import MapFile
from apygis.model.topology import margin_mask

__all__ = ["ReportDecoder", "Session", "margin_map", "run_live", "run_tablet_stream"]

log = logging.getLogger(__name__)

_WORD = {"symbols": "symbol", "line_points": "line point", "texts": "text"}


class ReportDecoder:
    """Tablet reports -> engine events.

    A report in proximity whose position differs from the last one is a
    :class:`~apygis.compile.engine.Mark` (tablet millimetres). A **press** is a
    report whose button code is not 0 and differs from the previous report's;
    UP and DOWN also act on every report while held. A report out of
    proximity (the cursor lifted) moves nothing and presses nothing.
    """

    def __init__(self, config, buttons: dict[int, str], repeat=("UP", "DOWN")):
        self.config = config
        self.buttons = buttons
        self.repeat = frozenset(repeat)
        self._prev_button = 0
        self._prev_xy = None

    def events(self, report) -> list:
        out = []
        if not report.proximity:
            self._prev_button = 0
            return out
        if (report.x_counts, report.y_counts) != self._prev_xy:
            self._prev_xy = (report.x_counts, report.y_counts)
            out.append(Mark(*self.config.report_mm(report)))
        b = report.button or 0
        if b and (b != self._prev_button or self.buttons.get(b) in self.repeat):
            name = self.buttons.get(b)
            if name is None:
                log.warning("tablet button code %d is not on the pad; ignored", b)
            else:
                out.append(Press(name))
        self._prev_button = b
        return out


def margin_map(m: MapFile) -> MapFile:
    """A map of the margin points of every layer (references kept as they are)."""
    from apygis.model.map import Layer

    out = MapFile(m.id, scale=m.scale, crs=m.crs, notes=f"margin points of {m.id}")
    for ext, lay in m.layers.items():
        lp = lay.line_points
        out.add_layer(Layer.from_arrays(ext, line_points=lp[margin_mask(lp)]))
    return out


class Session:
    """A revision session over the map ``base`` (``dir/ID``).

    Parameters
    ----------
    base : path
        ``dir/ID``: the map's layer files are ``dir/ID.<ext>``; if there are
        none, a new map ``ID`` is started with ``scale`` and ``crs``.
    geometry : Geometry
        From the orientation (:class:`~apygis.compile.oriented.OrientedGeometry`).
    layer : str
        The layer to compile into first.
    motors : MotorController, optional
        Receives the plate positions (``G0`` moves, not waited for).
    monitor : callable(str), optional
        Receives the operator's monitor lines.
    settings : dict
        Engine settings (``snap_mm``, ``sample_tolerance_mm``, ``autosave_every``).
    """

    def __init__(
        self,
        base,
        geometry,
        *,
        layer: str = "c",
        motors=None,
        monitor: Callable[[str], None] | None = None,
        library=None,
        scale: int | None = None,
        crs=None,
        settings: dict | None = None,
    ):
        import apygis

        self.base = Path(base)
        self.geometry = geometry
        self.motors = motors
        self.monitor = monitor or (lambda line: None)
        self.library = library
        self.settings = dict(settings or {})
        self.journal_path = self.base.with_name(self.base.name + ".journal")
        self.entries = 0
        self.saves = 0
        self.finished = False
        self._closed = False
        self._last_status = None
        if self.journal_path.exists():
            j = read_journal(self.journal_path)
            self.settings = j.settings
            self.map = j.map
            self.engine = self._engine(j.layer)
            self._replaying = True
            for ev in j.events:
                self._apply(ev, journal=False)
            self._replaying = False
            self.journal = Journal.reopen(self.journal_path)
            self.recovered = len(j.events)
            self.monitor(
                f"recovered {len(j.events)} journaled events of map {self.map.id}: "
                f"{self.engine.entries} entries, mode {self.engine.mode}"
            )
            self.save("recovery")
        else:
            files = [p for p in self.base.parent.glob(self.base.name + ".*")]
            if any(p.suffix not in (".journal", ".apa") for p in files):
                self.map = apygis.read(self.base, driver="apy")
            else:
                self.map = MapFile(self.base.name, scale=scale, crs=crs)
                self.base.parent.mkdir(parents=True, exist_ok=True)
            self.settings.setdefault("start_z_m", _mean_height(self.map))
            self.engine = self._engine(layer)
            self.journal = Journal.create(self.journal_path, self.map, layer, self.settings)
            self.recovered = 0
            self._replaying = False
        self.monitor(
            f"map {self.map.id}, compiling into layer {self.engine.layer_ext}; "
            f"journal {self.journal_path.name}"
        )

    def _engine(self, layer: str) -> Engine:
        s = self.settings
        return Engine(
            self.map,
            layer,
            self.geometry,
            library=self.library,
            snap_mm=s.get("snap_mm", 1.0),
            sample_tolerance_mm=s.get("sample_tolerance_mm", 0.2),
            autosave_every=s.get("autosave_every", 50),
            start_z_m=s.get("start_z_m", 0.0),
        )

    # ------------------------------------------------------------------ input

    def handle(self, event) -> list:
        """One event through the engine; journaled, then acted on. Returns the effects."""
        if self.finished:
            return []
        return self._apply(event, journal=True)

    def handle_all(self, events: Iterable) -> None:
        for ev in events:
            self.handle(ev)
            if self.finished:
                break

    def _apply(self, event, journal: bool) -> list:
        effects = self.engine.handle(event)
        entry = any(isinstance(e, RECORD_EFFECTS) for e in effects)
        if journal:
            # on disk before anything is acknowledged
            self.journal.append(event, sync=entry or any(isinstance(e, Terminate) for e in effects))
        for e in effects:
            self._effect(e)
        return effects

    def _effect(self, e) -> None:
        if isinstance(e, RECORD_EFFECTS):
            self.entries += 1
        if self._replaying or self.finished:  # recovery, or after the end: act on nothing
            return
        if isinstance(e, Plates):
            if self.motors is not None:
                x, y, z, a = e.steps
                self.motors.move_to(x, y, z, a, wait=False)
        elif isinstance(e, RECORD_EFFECTS):
            self.monitor(_entry_line(self.entries, self.map.id, e))
        elif isinstance(e, Message):
            for line in e.text.split("\n"):
                self.monitor(f"  {line}")
        elif isinstance(e, Status):
            key = (e.mode, e.layer, e.prompt)
            if key != self._last_status:
                self._last_status = key
                mark = "" if e.mark is None else " mark {:.2f} {:.2f} {:.2f}".format(*e.mark)
                c = e.counts
                self.monitor(
                    f"[{e.mode}] {self.map.id}.{e.layer} {e.prompt}".rstrip()
                    + f" | {c['symbols']} sym {c['line_points']} pts {c['texts']} txt{mark}"
                )
        elif isinstance(e, ZeroPlates):
            if self.motors is not None:
                self.motors.drain()
                self.motors.set_position(*self._current_steps())
        elif isinstance(e, Save):
            if e.reason != "terminate":  # finish() saves once, with the margin file
                self.save(e.reason)
        elif isinstance(e, Terminate):
            self.finish()

    def _current_steps(self):
        m = self.engine.mark()
        steps = None if m is None else self.geometry.plates(*m)
        return steps or (0, 0, 0, 0)

    # ------------------------------------------------------------------ files

    def save(self, reason: str) -> list[Path]:
        """Write the layer files atomically (all layers that hold records)."""
        import apygis

        layers = [lay for lay in self.map if len(lay)]
        if not layers:
            return []
        m = MapFile(self.map.id, self.map.scale, self.map.crs, self.map.notes)
        for lay in layers:
            m.add_layer(lay)
        written = apygis.write(m, self.base, driver="apy")
        self.saves += 1
        self.monitor(f"saved ({reason}): {', '.join(p.name for p in written)}")
        return written

    def finish(self) -> None:
        """Terminate: final save, margin file, journal removed."""
        import apygis

        self.save("terminate")
        margin = self.base.with_name(self.base.name + "-margin.apa")
        mm = margin_map(self.map)
        apygis.write(mm, margin, driver="ascii")
        n = sum(len(lay.line_points) for lay in mm)
        self.monitor(f"margin file {margin.name}: {n} margin points")
        self.journal.close(remove=True)
        self.finished = True
        self.monitor("compilation terminated")

    def close(self) -> None:
        """End without terminating (input ended): save, keep the journal for a resume."""
        if not self.finished and not self._closed:
            self._closed = True
            self.save("end of input")
            self.journal.close(remove=False)
            self.monitor(f"session not terminated: journal {self.journal_path.name} kept")


def _mean_height(m: MapFile) -> float:
    """Mean Z of all records, rounded to the centimetre (0 for an empty map)."""
    import numpy as np

    zs = [lay.table(t)["z"] for lay in m for t in ("symbols", "line_points", "texts")]
    zs = [z for z in zs if len(z)]
    return round(float(np.mean(np.concatenate(zs))), 2) if zs else 0.0


def _entry_line(n: int, map_id: str, e) -> str:
    if isinstance(e, Undone):
        return f"entry {n}: undo in {map_id}.{e.layer}"
    if isinstance(e, Linked):
        what = "closing the line" if e.how == "closed" else "a branch"
        return f"entry {n}: line point {e.num} joined to {e.target} in {map_id}.{e.layer} ({what})"
    verb = "added" if isinstance(e, Added) else "deleted"
    return f"entry {n}: {_WORD[e.table]} {e.num} {verb} in {map_id}.{e.layer}"


def run_tablet_stream(session: Session, chunks: Iterable, parser, decoder: ReportDecoder) -> None:
    """Feed recorded or live chunks (``Chunk`` objects: tablet and keyboard channels)."""
    for ch in chunks:
        if session.finished:
            break
        if ch.channel == "tablet" and ch.direction == "rx":
            for report in parser.feed(ch.data):
                session.handle_all(decoder.events(report))
        elif ch.channel == "keyboard" and ch.direction == "rx":
            for line in ch.data.decode("utf-8", errors="replace").splitlines():
                session.handle(Keys(line))
    if not session.finished:
        for report in parser.flush():
            session.handle_all(decoder.events(report))


def run_live(session: Session, port, parser, decoder: ReportDecoder, keys=None, recorder=None):
    """Read a live tablet port (and typed lines from the queue ``keys``) until the end.

    The loop reads what the port has (``read_reports``: a quiet line flushes
    a packet that waits for its successor), hands the reports to the
    session, then any typed lines. It ends when the session terminates or the
    port closes; KeyboardInterrupt propagates to the caller.
    """
    import queue

    from apygis.instrument.tablet import read_reports

    while not session.finished:
        try:
            reports = read_reports(port, parser)
        except (OSError, ValueError) as exc:  # the port went away
            log.warning("tablet port closed: %s", exc)
            break
        for report in reports:
            session.handle_all(decoder.events(report))
        while keys is not None and not session.finished:
            try:
                text = keys.get_nowait()
            except queue.Empty:
                break
            if recorder is not None:
                recorder.record("keyboard", text.encode("utf-8") + b"\n")
            session.handle(Keys(text))
