"""A map-revision session: the engine, the instrument, the journal and the files.

:class:`Session` wires the parts: tablet reports become engine events
(:class:`~apygis.session.decoder.ReportDecoder`), every event is journaled
(an entry is on disk before it is acknowledged: see
:mod:`apygis.session.journal`), plate positions go to the motor controller,
the display settings are kept for a display (:attr:`Session.display`), and
the layer files are saved, atomically, after every 50 entries, on PROCEED
and at the end, with the margin file (the line points lacking a forward or
backward reference).

Files of a session on the map ``dir/ID``:

* ``dir/ID.<ext>``: the APY layer files (read at the start, saved);
* ``dir/ID.journal``: the journal, removed when the session terminates
  cleanly; a session started on a map with a journal recovers it first, if
  the layer files are still in a state the journal knows
  (:func:`~apygis.session.journal.check_files`);
* ``dir/ID.lock``: the session's lock
  (:class:`~apygis.session.lock.SessionLock`): one session per map, taken
  before anything is read, removed at the end;
* ``dir/ID-margin.apa``: the margin file (APY ASCII), written at the end.

A failed save (a full disk) does not end the session: the operator is told,
the journal still holds every entry, and the next save tries again; only a
failed final save is an error (:class:`SaveError`), with the journal kept.

The session never prints: it hands the operator's monitor lines to a
``monitor`` callback (the CLI prints them). A display follows the session
through :meth:`Session.subscribe`: an observer is called on the session's
thread after each event has been acted on (journaled, saved, sent to the
motors), with the event and its effects; it must return at once (a graphic
display hands the work to a thread of its own) and can never stop the
session: an observer that raises is dropped, and the session goes on.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from apygis.compile.engine import Engine
from apygis.compile.events import (
    RECORD_EFFECTS,
    Added,
    CrosshairScale,
    DisplayScale,
    Ignored,
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
from apygis.errors import ApygisError, OrientationError
from apygis.instrument.pad import BUTTONS
from apygis.model.map import MapFile
from apygis.model.records import TABLE_WORDS
from apygis.model.topology import margin_mask
from apygis.session.decoder import ReportDecoder, decode_typed
from apygis.session.journal import (
    MAX_KEYS,
    MAX_MARK_MM,
    Journal,
    JournalWriteError,
    check_files,
    check_settings,
    layer_file_states,
    planned_file_states,
    read_journal,
    upgrade_journal,
)
from apygis.session.lock import SessionLock

__all__ = [
    "DisplayState",
    "SaveError",
    "Session",
    "keep_effect",
    "margin_map",
    "run_live",
    "run_tablet_stream",
    "session_engine",
]

log = logging.getLogger(__name__)

_BUTTON_NAMES = frozenset(BUTTONS.values())


def keep_effect(e, display: DisplayState) -> int:
    """What a session keeps of effect ``e``, also while it replays a journal.

    The PROCEED menu's display settings go into ``display``; returns 1 for an
    entry (a record effect), else 0. A session and the view's replay of its
    journal (:class:`apygis.view.feed.SessionReplica`) both keep them here.
    """
    if isinstance(e, RECORD_EFFECTS):
        return 1
    if isinstance(e, DisplayScale):
        display.scale = e.factor
    elif isinstance(e, CrosshairScale):
        display.crosshair = e.factor
    return 0


def session_engine(map_, layer: str, geometry, library, settings: dict) -> Engine:
    """The engine of a session: over ``map_``, compiling into ``layer``, with its settings.

    A session, its recovery and the view's replay of its journal
    (:class:`apygis.view.feed.SessionReplica`) all build it here, so that
    the same journal gives the same engine.
    """
    s = settings
    return Engine(
        map_,
        layer,
        geometry,
        library=library,
        snap_mm=s.get("snap_mm", 1.0),
        sample_tolerance_mm=s.get("sample_tolerance_mm", 0.2),
        autosave_every=s.get("autosave_every", 50),
        start_z_m=s.get("start_z_m", 0.0),
    )


@dataclass
class DisplayState:
    """What a display of the session draws with: the PROCEED menu's settings.

    ``scale`` is the graphic display's scale factor (0.25-25, PROCEED item
    1), ``crosshair`` the crosshair scale (0.25-4, item 3); both start at 1.
    The session keeps them from the engine's :class:`DisplayScale` and
    :class:`CrosshairScale` effects, also while it replays a journal, so a
    recovered session shows what the operator had set.
    """

    scale: float = 1.0
    crosshair: float = 1.0


class SaveError(ApygisError, OSError):
    """The layer files could not be saved at the end; the journal keeps every entry."""


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
        Engine settings (``snap_mm``, ``sample_tolerance_mm``, ``autosave_every``,
        ``start_z_m``; :data:`apygis.session.journal.SETTINGS`).
    lock : SessionLock, optional
        The map's lock, already taken (the CLI takes it before it copies the
        map); else the session takes it first thing, and a map another
        session holds is a :class:`SessionLockedError`. Released at the end.
    discard_journal : bool
        A journal left behind is renamed aside (``ID.journal.discarded``,
        ``.discarded-2``, ...) instead of recovered.
    trust_journal : bool
        Recover a journal left behind even when the layer files changed
        since, or when it is a version 1 journal that cannot tell.

    Nothing is written before every check has passed: a bad journal, a
    changed file or a bad setting leaves the files as they were.
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
        lock: SessionLock | None = None,
        discard_journal: bool = False,
        trust_journal: bool = False,
    ):
        from apygis.errors import RecordError
        from apygis.model.map import check_ext

        self.base = Path(base)
        layer = check_ext(layer)
        try:
            settings = check_settings(dict(settings or {}))
        except ValueError as exc:
            raise RecordError(str(exc)) from None
        self.lock = lock if lock is not None else SessionLock.acquire(self.base)
        try:
            self._start(
                geometry, layer, motors, monitor, library, scale, crs, settings,
                discard_journal, trust_journal,
            )  # fmt: skip
        except BaseException:
            self.lock.release()
            raise

    def _start(
        self, geometry, layer, motors, monitor, library, scale, crs, settings,
        discard_journal, trust_journal,
    ):  # fmt: skip
        import apygis

        self.geometry = geometry
        self.motors = motors
        self.monitor = monitor or (lambda line: None)
        self.library = library
        self.settings = settings
        self.journal_path = self.base.with_name(self.base.name + ".journal")
        self.entries = 0
        self.saves = 0
        self.save_failures = 0
        self.finished = False
        self._closed = False
        self._failed: Exception | None = None
        self._last_status = None
        self._last_steps: tuple[int, int, int, int] = (0, 0, 0, 0)
        self._replaying = False
        self.display = DisplayState()
        self._observers: list[Callable[[Session, object, list], None]] = []
        if self.journal_path.exists() and discard_journal:
            aside = _aside(self.journal_path)
            self.journal_path.rename(aside)
            self.monitor(f"journal {self.journal_path.name} discarded: renamed to {aside.name}")
        if self.journal_path.exists():
            j = read_journal(self.journal_path)
            if not trust_journal:
                check_files(j, self.base)
            self.settings = j.settings
            self.map = j.map
            self.engine = self._engine(j.layer)
            self._replaying = True
            for ev in j.events:
                self._apply(ev, journal=False)
            self._replaying = False
            if j.version < 2:  # trusted: from now on it knows the files
                upgrade_journal(self.journal_path, layer_file_states(self.base))
            self.journal = Journal.reopen(self.journal_path)
            self.recovered = len(j.events)
            self.monitor(
                f"recovered {len(j.events)} journaled events of map {self.map.id}: "
                f"{self.engine.entries} entries, mode {self.engine.mode}"
            )
            self.save("recovery")
        else:
            files = layer_file_states(self.base)
            if files:
                self.map = apygis.read(self.base, driver="apy")
            else:
                self.map = MapFile(self.base.name, scale=scale, crs=crs)
                self.base.parent.mkdir(parents=True, exist_ok=True)
            self.settings.setdefault("start_z_m", _mean_height(self.map))
            self.engine = self._engine(layer)
            self.journal = Journal.create(self.journal_path, self.map, layer, self.settings, files)
            self.recovered = 0
        self.monitor(
            f"map {self.map.id}, compiling into layer {self.engine.layer_ext}; "
            f"journal {self.journal_path.name}"
        )
        if self.engine.terminated:  # the journal ends with TERMINATE: finish what it began
            self.finish()

    def _engine(self, layer: str) -> Engine:
        return session_engine(self.map, layer, self.geometry, self.library, self.settings)

    # ------------------------------------------------------------------ observers

    def subscribe(self, observer: Callable[[Session, object, list], None]) -> Callable[[], None]:
        """Call ``observer(session, event, effects)`` after every event; returns an unsubscribe.

        The observer runs on the session's thread once the event has been
        acted on (an entry is journaled and on disk by then), for every
        event that gave effects, journal recovery excepted (a subscriber
        reads the session's state, :attr:`map` and :attr:`display`, when it
        subscribes). It must not block: the session waits for nothing. An
        observer that raises is logged and dropped; the session goes on.
        """
        self._observers.append(observer)

        def unsubscribe() -> None:
            with contextlib.suppress(ValueError):
                self._observers.remove(observer)

        return unsubscribe

    def _notify(self, event, effects: list) -> None:
        for obs in tuple(self._observers):
            try:
                obs(self, event, effects)
            except Exception:
                log.exception("a session observer failed and was dropped")
                with contextlib.suppress(ValueError):
                    self._observers.remove(obs)

    # ------------------------------------------------------------------ input

    def handle(self, event) -> list:
        """One event through the engine; journaled, then acted on. Returns the effects.

        A :class:`Keys` event's text may be bytes, or a str carrying
        ``surrogateescape`` characters: it is decoded by :func:`decode_typed`.
        """
        if self._failed is not None:
            raise JournalWriteError(f"the session stopped: {self._failed}")
        if self.finished:
            return []
        if isinstance(event, Keys):
            text, note = decode_typed(event.text)
            if note is not None:
                self.monitor(note)
            if len(text) > MAX_KEYS:
                self.monitor(f"typed text of {len(text)} characters (at most {MAX_KEYS}): ignored")
                return []
            event = Keys(text)
        elif isinstance(event, Press) and event.button not in _BUTTON_NAMES:
            self.monitor(f"{event.button!r:.40} is not a button of the pad: ignored")
            return []
        elif isinstance(event, Mark) and not all(
            -MAX_MARK_MM <= v <= MAX_MARK_MM for v in (event.x_mm, event.y_mm)
        ):
            # a position no tablet gives (a wrong counts_per_mm, line noise): never journaled
            self.monitor(f"mark ({event.x_mm:g}, {event.y_mm:g}) mm is off any tablet: ignored")
            return []
        return self._apply(event, journal=True)

    def handle_all(self, events: Iterable) -> None:
        for ev in events:
            self.handle(ev)
            if self.finished:
                break

    def _apply(self, event, journal: bool) -> list:
        if journal:
            try:
                self.journal.append(event, sync=False)
            except JournalWriteError as exc:
                self._failed = exc
                raise
        effects = self.engine.handle(event)
        if journal and any(isinstance(e, (*RECORD_EFFECTS, Terminate)) for e in effects):
            try:
                self.journal.sync()  # on disk before anything is acknowledged
            except JournalWriteError as exc:
                self._failed = exc
                raise
        for e in effects:
            self._effect(e)
        if self._observers and journal and effects:
            self._notify(event, effects)
        return effects

    def _effect(self, e) -> None:
        self.entries += keep_effect(e, self.display)  # state, kept through a replay too
        if self._replaying or self.finished:  # recovery, or after the end: act on nothing
            return
        if isinstance(e, Plates):
            self._last_steps = e.steps
            if self.motors is not None:
                x, y, z, a = e.steps
                self.motors.move_to(x, y, z, a, wait=False)
        elif isinstance(e, RECORD_EFFECTS):
            self.monitor(_entry_line(self.entries, self.map.id, e))
        elif isinstance(e, (Message, Ignored)):
            for line in e.text.split("\n"):
                self.monitor(f"  {line}")
        elif isinstance(e, DisplayScale):
            self.monitor(f"  display scale factor {e.factor:g}x")
        elif isinstance(e, CrosshairScale):
            self.monitor(f"  crosshair scale {e.factor:g}x")
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
        """The plate positions of the mark, or the last ones sent where the loop refuses it."""
        m = self.engine.mark()
        try:
            steps = None if m is None else self.geometry.plates(*m)
        except OrientationError:
            steps = None
        return steps or self._last_steps

    # ------------------------------------------------------------------ files

    def save(self, reason: str) -> list[Path]:
        """Write the layer files atomically (all layers that hold records).

        The file states the save will leave are journaled first, so that a
        recovery knows them. A failure to write (a full disk) is told to the
        operator and the session goes on: the journal still holds every
        entry, and the next save tries again. Only the final save
        (``reason="terminate"``) raises :class:`SaveError`.
        """
        import apygis
        from apygis.formats.apy import encode_layer

        layers = [lay for lay in self.map if len(lay)]
        if not layers:
            return []
        m = MapFile(self.map.id, self.map.scale, self.map.crs, self.map.notes)
        for lay in layers:
            m.add_layer(lay)
        try:
            planned = {
                lay.ext: encode_layer(m, lay, self.base.with_name(f"{self.base.name}.{lay.ext}"))
                for lay in layers
            }
            self.journal.record_files(planned_file_states(planned))
            written = apygis.write(m, self.base, driver="apy")
        except OSError as exc:  # JournalWriteError too
            self.save_failures += 1
            why = getattr(exc, "strerror", None) or str(exc)
            if reason == "terminate":
                raise SaveError(
                    f"{self.base}: the layer files could not be saved at the end ({why}); "
                    f"the journal {self.journal_path} keeps every entry: make room (or fix the "
                    "cause) and run the same session command again (or with --recover-only) "
                    "to save them"
                ) from exc
            self.monitor(
                f"SAVE FAILED ({reason}): the layer files of {self.map.id} could not be written "
                f"({why}); the journal {self.journal_path.name} still holds every entry. "
                f"Make room in {self.base.parent}; the next save tries again"
            )
            return []
        self.saves += 1
        self.monitor(f"saved ({reason}): {', '.join(p.name for p in written)}")
        return written

    def finish(self) -> None:
        """Terminate: final save, margin file, journal removed, lock released.

        If the final save fails, the journal is kept (closed) and
        :class:`SaveError` is raised: the next session on the map recovers it.
        """
        import apygis

        try:
            self.save("terminate")
            margin = self.base.with_name(self.base.name + "-margin.apa")
            mm = margin_map(self.map)
            try:
                apygis.write(mm, margin, driver="ascii")
            except OSError as exc:
                raise SaveError(
                    f"{margin}: the margin file could not be written "
                    f"({getattr(exc, 'strerror', None) or exc}); the layer files are saved and "
                    f"the journal {self.journal_path} is kept: run the session again to write it"
                ) from exc
        except BaseException:
            self._closed = True
            try:
                with contextlib.suppress(JournalWriteError):  # the save's error says more
                    self.journal.close(remove=False)
            finally:
                self.lock.release()
            raise
        n = sum(len(lay.line_points) for lay in mm)
        self.monitor(f"margin file {margin.name}: {n} margin points")
        try:
            self.journal.close(remove=True)
        finally:
            self.lock.release()
        self.finished = True
        self.monitor("compilation terminated")

    def close(self) -> None:
        """End without terminating (input ended): save, keep the journal for a resume.

        Raises :class:`SaveError` when the layer files could not be saved (the
        journal is kept all the same, and the lock released).
        """
        if self.finished or self._closed:
            return
        self._closed = True
        try:
            failures = self.save_failures
            if self._failed is None:
                self.save("end of input")
            if not self.journal.closed:
                try:
                    self.journal.close(remove=False)
                except JournalWriteError as exc:
                    self.monitor(str(exc))
            self.monitor(f"session not terminated: journal {self.journal_path.name} kept")
            if self.save_failures > failures:
                raise SaveError(
                    f"{self.base}: the layer files could not be saved; the journal "
                    f"{self.journal_path} keeps every entry: make room and run the session "
                    "again (or with --recover-only) to save them"
                )
        finally:
            self.lock.release()


def _aside(path: Path) -> Path:
    """A free name beside ``path`` for a discarded journal."""
    cand = path.with_name(path.name + ".discarded")
    k = 1
    while cand.exists():
        k += 1
        cand = path.with_name(f"{path.name}.discarded-{k}")
    return cand


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
    return f"entry {n}: {TABLE_WORDS[e.table]} {e.num} {verb} in {map_id}.{e.layer}"


def run_tablet_stream(session: Session, chunks: Iterable, parser, decoder: ReportDecoder) -> None:
    """Feed recorded or live chunks (``Chunk`` objects: tablet and keyboard channels)."""
    for ch in chunks:
        if session.finished:
            break
        if ch.channel == "tablet" and ch.direction == "rx":
            for report in parser.feed(ch.data):
                session.handle_all(decoder.events(report))
        elif ch.channel == "keyboard" and ch.direction == "rx":
            for line in ch.data.splitlines():  # bytes: Session.handle decodes them
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
            raw = text if isinstance(text, bytes) else text.encode("utf-8", "surrogateescape")
            if recorder is not None:
                recorder.record("keyboard", raw + b"\n")
            session.handle(Keys(raw))
