"""Feeding the view: a map as it is, a session as it goes, an orientation's control points.

:func:`map_hub` makes the :class:`~apygis.view.hub.ViewHub` of a map.
A running session is followed from the view's process
(:mod:`apygis.view.process`): :class:`SessionReplica` replays the session's
journal in an engine of its own and :class:`ChangeFeed` turns its effects
into the hub's changes, while the session's side, :class:`SessionFeed`,
only sends the floating mark and the status line. :func:`control_overlays`
turns a map orientation's control points and residuals into overlays.

Which records an entry changed: the records its effects name, and for line
points their neighbours before (the references the feed last sent) and after
(the references they have now), since adding, splitting, joining and
deleting line points re-link their neighbours. After an UNDO (the layer as it
was) and at every save (a check), the layers concerned are sent whole and the
hub compares them with what the pages have, so the pages end equal to the
session's map whatever the topology.
"""

from __future__ import annotations

import logging
import os
import threading
from typing import Any

import numpy as np

from apygis.compile.events import (
    Added,
    AreaShown,
    CrosshairScale,
    Deleted,
    DhiShown,
    DisplayScale,
    Ignored,
    Linked,
    Message,
    Plates,
    Save,
    Status,
    Terminate,
    Undone,
    ZeroPlates,
)
from apygis.model.map import MapFile
from apygis.model.records import LINE_DTYPE, REF_FIELDS
from apygis.model.symbols import load_library
from apygis.plot.plotdef import PlotterDef
from apygis.view.hub import DEFAULT_QUEUE_LIMIT, DELIVERY_INTERVAL_S, ViewHub
from apygis.view.scene import TABLE_NAMES, Pens, layer_rows, map_meta, rows_of, symbol_table

__all__ = [
    "ChangeFeed",
    "SessionFeed",
    "SessionReplica",
    "control_overlays",
    "deliver",
    "map_hub",
    "session_hub",
]

log = logging.getLogger(__name__)

#: Effects that change nothing a page shows from the replica (the status line and the
#: mark come from the session itself).
_NOT_CHANGES = (Status, Plates, ZeroPlates)
_LINE_FIELDS: tuple[str, ...] = tuple(LINE_DTYPE.names or ())
#: Where the references begin in a line point's row (``num, x, y, z, code, fwd, ...``).
_REF_AT = _LINE_FIELDS.index("fwd")


def map_hub(
    m: MapFile,
    *,
    kind: str = "map",
    plotdef: PlotterDef | None = None,
    library=None,
    source: str = "",
    queue_limit: int = DEFAULT_QUEUE_LIMIT,
) -> ViewHub:
    """The hub of a view of map ``m`` (its records loaded; no viewer yet).

    ``library`` is a :class:`~apygis.model.symbols.SymbolLibrary` (default:
    :func:`~apygis.model.symbols.load_library`), ``plotdef`` the pens
    (default: the built-in plotter definition).
    """
    lib = load_library() if library is None else library
    hub = ViewHub(
        kind, Pens(plotdef), symbol_table(lib), map_meta(m, source), queue_limit=queue_limit
    )
    hub.load_layers({lay.ext: layer_rows(lay) for lay in m})
    return hub


def _status_dict(mode, layer: str, prompt: str, mark, counts: dict, map_id: str) -> dict:
    return {
        "mode": str(mode),
        "layer": layer,
        "prompt": prompt,
        "mark": None if mark is None else [float(v) for v in mark],
        "counts": dict(counts),
        "map": map_id,
    }


def session_hub(session, *, plotdef=None, library=None, queue_limit=DEFAULT_QUEUE_LIMIT):
    """The hub of a view of ``session`` as it is now (after a recovery, if any)."""
    hub = map_hub(
        session.map,
        kind="session",
        plotdef=plotdef,
        library=library if library is not None else session.library,
        source=str(session.base),
        queue_limit=queue_limit,
    )
    eng = session.engine
    lay = session.map.layer(eng.layer_ext)
    counts = {t: len(lay.table(t)) for t in TABLE_NAMES}
    hub.entries_before = int(session.entries)
    hub.status = _status_dict(eng.mode, eng.layer_ext, "", eng.mark(), counts, session.map.id)
    hub.display = {"scale": session.display.scale, "crosshair": session.display.crosshair}
    hub.ended = bool(session.finished)
    return hub


class SessionFeed:
    """The view of a running session, fed from the session's process.

    ``server`` is a started :class:`~apygis.view.process.ViewProcess` whose
    hub was made from ``session`` (:func:`session_hub`); make the feed at
    once after, on the session's thread (the journal is where the view's
    process starts following).

    The session does nothing for it: the view's process follows the
    session's journal (:class:`SessionReplica`), which holds every event the
    session acted on, entries on disk before they are acknowledged. A thread
    of the feed's own reads the floating mark, the status line and the
    display settings from the session at most every
    :data:`~apygis.view.hub.DELIVERY_INTERVAL_S` (a tablet moves the mark
    with every report; a page needs it no more often than a screen shows)
    and sends them when they changed. The session never waits for it.
    """

    def __init__(self, server, session):
        self.server = server
        self.map_id = session.map.id
        self._session = session
        self._geometry = session.geometry
        self._counts: dict[str, int] = {}  # of the layer compiled into (the last known)
        self._sent_key: tuple | None = None
        self._stop = threading.Event()
        offset = session.journal.flush()  # every event so far where the view's process reads it
        fd = os.open(session.journal_path, os.O_RDONLY)
        try:
            server.follow(
                {
                    "path": str(session.journal_path),
                    "offset": offset,
                    "entries": int(session.entries),
                    "display": _display(session),
                    "geometry": session.geometry,
                    "library": session.library,
                },
                fd,
            )
        finally:
            os.close(fd)
        self._thread = threading.Thread(target=self._run, name="apygis-view-feed", daemon=True)
        self._thread.start()

    def end(self, session) -> None:
        """The session is over: the rest of its journal, a last check of every layer, ``ended``."""
        self.close()
        why = (
            "compilation terminated"
            if session.finished
            else "session not terminated: the journal is kept for a resume"
        )
        if not session.journal.closed:
            session.journal.flush()
        change = {
            "full": {lay.ext: _copies(lay) for lay in session.map},
            "ended": True,
            "display": _display(session),
            "messages": [why],
        }
        self.server.send([change], *self._status())

    def close(self, timeout: float = 5.0) -> None:
        """Stop the feed's thread (idempotent)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    # ------------------------------------------------------------------ the feed's thread

    def _run(self) -> None:
        while not self._stop.wait(DELIVERY_INTERVAL_S):
            try:
                status, display = self._status(changed_only=True)
                if status is not None:
                    if not self.server.send([], status, display):
                        return
                elif self.server.closed:
                    return
            except Exception:
                log.exception("view: the status line could not be delivered")
                return

    def _status(self, changed_only: bool = False):
        """``(status, display)`` as the session has them now; None, None if unchanged."""
        sess = self._session
        eng = sess.engine
        d = sess.display
        key = (eng.mode, eng.layer_ext, eng.buf, eng.mark_xy, eng.z_model, d.scale, d.crosshair)
        if changed_only and key == self._sent_key:
            return None, None
        self._sent_key = key
        xy, z_model = key[3], key[4]
        mark = None
        if xy is not None:
            mark = (xy[0], xy[1], self._geometry.correct_z(xy[0], xy[1], z_model))
        lay = sess.map.layers.get(eng.layer_ext)
        if lay is not None:
            self._counts = {t: len(lay.table(t)) for t in TABLE_NAMES}
        status = _status_dict(eng.mode, eng.layer_ext, eng.buf, mark, self._counts, self.map_id)
        return status, {"scale": key[5], "crosshair": key[6]}


class SessionReplica:
    """A session's engine replayed from its journal, in the view's process.

    The engine is deterministic (a journal recovers a session exactly, see
    :mod:`apygis.session.journal`): replaying the journal's events over the
    map of its head, with the session's geometry, symbol library and
    settings, gives the same records, entries and effects as the session's
    own engine, without costing the session anything. :meth:`catch_up`
    replays what the journal has gained since the last call and returns the
    hub's changes (:class:`ChangeFeed`).

    Parameters
    ----------
    fh : file
        The journal opened for reading (binary, from its start).
    spec : dict
        ``path`` (for messages), ``offset`` (the journal's size when the view
        started: the events up to it are replayed without changes, the hub
        holds their result already), ``entries`` (the session's entries
        then), ``display``, ``geometry`` and ``library``.
    """

    def __init__(self, fh, spec: dict):
        from apygis.session.journal import JournalTail
        from apygis.session.runner import DisplayState, keep_effect, session_engine

        self._keep = keep_effect
        self.tail = JournalTail(fh, spec["path"])
        self.map = self.tail.map
        self.geometry = spec["geometry"]
        self.engine = session_engine(
            self.map, self.tail.layer, self.geometry, spec["library"], self.tail.settings
        )
        self.display = DisplayState(**spec["display"])
        self.entries = 0
        self.finished = False
        for ev in self.tail.read(upto=spec["offset"]):
            self._handle(ev)
        self.entries = int(spec["entries"])
        self.feed = ChangeFeed(self)

    def _handle(self, ev) -> list:
        effects = self.engine.handle(ev)
        for e in effects:  # what the session keeps of them
            self.entries += self._keep(e, self.display)
            if isinstance(e, Terminate):
                self.finished = True
        return effects

    def catch_up(self) -> list[dict]:
        """Replay the events the journal gained; the hub's changes they make."""
        feed = self.feed
        for ev in self.tail.read():
            feed(self, self._handle(ev))
        return feed.take()


class ChangeFeed:
    """What the pages need from a replayed session's effects: the hub's changes.

    Which records an entry changed: the records its effects name, and for
    line points their neighbours before (the references the feed last sent)
    and after (the references they have now), since adding, splitting,
    joining and deleting line points re-link their neighbours. After an UNDO
    (the layer as it was) and at every save (a check), the layers concerned
    are sent whole and the hub compares them with what the pages have, so the
    pages end equal to the session's map whatever the topology.
    """

    def __init__(self, session):
        self._refs: dict[str, dict[int, tuple]] = {
            lay.ext: _refs_of(lay.line_points) for lay in session.map
        }
        self._touched: set[str] = set()
        self._pos: dict[tuple[str, str], dict[int, int]] = {}  # where a number was found last
        self._out: list[dict] = []

    def __call__(self, session, effects: list) -> None:
        changes = [e for e in effects if type(e) not in _NOT_CHANGES]
        if changes:
            self._send(session, changes)

    def take(self) -> list[dict]:
        """The changes made since the last call."""
        out, self._out = self._out, []
        return out

    def _send(self, session, changes: list) -> None:
        m = session.map
        entries: list[list] = []
        nums: dict[tuple[str, str], set[int]] = {}
        full: set[str] = set()
        messages: list[str] = []
        overlays: list[dict] = []
        display = None
        ended = False
        for e in changes:
            t = type(e)
            if t is Added or t is Deleted:
                what = "added" if t is Added else "deleted"
                entries.append([0, what, e.layer, e.table, e.num, None])
                nums.setdefault((e.layer, e.table), set()).add(e.num)
                self._touched.add(e.layer)
            elif t is Linked:
                entries.append(
                    [0, "linked", e.layer, "line_points", e.num, {"target": e.target, "how": e.how}]
                )
                nums.setdefault((e.layer, "line_points"), set()).update((e.num, e.target))
                self._touched.add(e.layer)
            elif t is Undone:
                entries.append([0, "undone", e.layer, None, None, None])
                full.update(lay.ext for lay in m)
            elif t is Message or t is Ignored:
                messages.extend(e.text.split("\n"))
            elif t is DisplayScale or t is CrosshairScale:
                display = _display(session)
            elif t is AreaShown:
                overlays.append(
                    {
                        "kind": "area",
                        "layer": e.layer,
                        "points": list(e.points),
                        "ring": [list(p) for p in e.ring],
                        "area_m2": e.area_m2,
                        "perimeter_m": e.perimeter_m,
                        "clockwise": e.clockwise,
                    }
                )
            elif t is DhiShown:
                overlays.append(
                    {
                        "kind": "dhi",
                        "a": list(e.a),
                        "b": list(e.b),
                        "distance_m": e.distance_m,
                        "dz_m": e.dz_m,
                        "inclination_deg": e.inclination_deg,
                    }
                )
            elif t is Save:
                full.update(self._touched)
                self._touched.clear()
            elif t is Terminate:
                ended = True
        first = session.entries - len(entries) + 1
        for k, row in enumerate(entries):
            row[0] = first + k
        change: dict[str, Any] = {}
        upsert: dict[str, dict[str, list]] = {}
        remove: dict[str, dict[str, list]] = {}
        for (ext, table), want in nums.items():
            if ext in full:
                continue
            lay = m.layers.get(ext)
            if lay is None:  # the layer went (an UNDO of a layer change): sent whole below
                full.add(ext)
                continue
            if table == "line_points":
                found, gone = self._line_points(ext, lay.line_points, want)
            else:
                found, gone = self._rows(ext, table, lay.table(table), want)
            if found:
                upsert.setdefault(ext, {})[table] = found
            if gone:
                remove.setdefault(ext, {})[table] = gone
        if full:
            change["full"] = {ext: _copies(m.layers[ext]) for ext in full if ext in m.layers}
            for ext in full:
                lay = m.layers.get(ext)
                self._refs[ext] = _refs_of(lay.line_points) if lay is not None else {}
        for key, value in (
            ("entries", entries),
            ("upsert", upsert),
            ("remove", remove),
            ("messages", messages),
            ("overlays", overlays),
        ):
            if value:
                change[key] = value
        if display is not None:
            change["display"] = display
        if ended or session.finished:
            change["ended"] = True
        if change:
            self._post(change)

    def _line_points(self, ext: str, lp: np.ndarray, want: set[int]):
        """The rows of ``want`` and of their neighbours (before and now), and the numbers gone."""
        refs = self._refs.setdefault(ext, {})
        ask = set(want)
        for n in want:
            old = refs.get(n)
            if old is not None:
                ask.update(r for r in old if r >= 0)
        found, gone = self._rows(ext, "line_points", lp, ask)
        more = {r for t in found for r in t[_REF_AT:] if r >= 0} - ask
        if more:
            found.extend(self._rows(ext, "line_points", lp, more)[0])
        for n in gone:
            refs.pop(n, None)
        for t in found:
            refs[t[0]] = t[_REF_AT:]
        return found, gone

    def _rows(self, ext: str, table: str, arr: np.ndarray, want: set[int]):
        """The rows (tuples) of the numbers in ``want`` in table ``arr``, and the numbers not there.

        An entry names a few records of a table of any size: each is looked
        for first where it was found last (a new record: the last row), which
        costs a row's read; only those not there (rows shifted by a deletion)
        are searched for.
        """
        pos = self._pos.setdefault((ext, table), {})
        size = len(arr)
        item = arr.item
        rows: list[tuple] = []
        missing: list[int] = []
        for n in want:
            i = pos.get(n, size - 1)
            if 0 <= i < size:
                t = item(i)
                if t[0] == n:
                    pos[n] = i
                    rows.append(t)
                    continue
            missing.append(n)
        if not missing:
            return rows, []
        nums = arr["num"]
        if len(missing) == 1:
            idx = np.flatnonzero(nums == missing[0]).tolist()
        else:
            idx = np.flatnonzero(np.isin(nums, missing)).tolist()
        found = set()
        for i in idx:
            t = item(i)
            pos[t[0]] = i
            found.add(t[0])
            rows.append(t)
        gone = [n for n in missing if n not in found]
        for n in gone:
            pos.pop(n, None)
        return rows, gone

    def _post(self, change: dict) -> None:
        self._out.append(change)


def deliver(hub: ViewHub, changes: list[dict], status: dict | None, display: dict | None) -> None:
    """On the server's loop: a feed's changes (arrays to rows) to the hub, then its status line.

    The changes become one delta (:meth:`ViewHub.apply_all`).
    """
    if changes:
        _apply(hub, changes)
    if status is not None:
        hub.set_status(status, display)


def _display(session) -> dict[str, float]:
    return {"scale": session.display.scale, "crosshair": session.display.crosshair}


def _copies(layer) -> dict[str, np.ndarray]:
    return {t: layer.table(t).copy() for t in TABLE_NAMES}


def _refs_of(lp: np.ndarray) -> dict[int, tuple]:
    if not len(lp):
        return {}
    return dict(
        zip(
            lp["num"].tolist(),
            zip(*(lp[f].tolist() for f in REF_FIELDS), strict=True),
            strict=True,
        )
    )


def _apply(hub: ViewHub, changes: list[dict]) -> None:
    """On the server's loop: arrays to rows, then :meth:`ViewHub.apply_all`."""
    for change in changes:
        for key in ("upsert", "full"):
            if key in change:
                change[key] = {
                    ext: {
                        t: rows_of(a) if isinstance(a, np.ndarray) else [list(r) for r in a]
                        for t, a in tables.items()
                    }
                    for ext, tables in change[key].items()
                }
    hub.apply_all(changes)


def control_overlays(ids, ground, residuals, rejected: dict | None = None) -> list[dict]:
    """Overlays of a map orientation: control points with their residual vectors.

    ``ids`` (n), ``ground`` (n, 2 or 3; metres) and ``residuals`` (n, 2: vX,
    vY in metres) of the points used; ``rejected`` maps the id of a point left
    out to its ground position (drawn without a residual).
    """
    out: list[dict] = []
    g = np.asarray(ground, dtype=float).reshape(len(ids), -1)
    v = np.asarray(residuals, dtype=float).reshape(len(ids), -1)
    for pid, p, r in zip(ids, g, v, strict=True):
        out.append(
            {
                "kind": "control",
                "id": str(pid),
                "x": float(p[0]),
                "y": float(p[1]),
                "residual": [float(r[0]), float(r[1])] if np.all(np.isfinite(r[:2])) else None,
                "rejected": False,
            }
        )
    for pid, p in (rejected or {}).items():
        out.append(
            {
                "kind": "control",
                "id": str(pid),
                "x": float(p[0]),
                "y": float(p[1]),
                "residual": None,
                "rejected": True,
            }
        )
    return out
