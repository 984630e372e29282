"""Feeding the view: a map as it is, a session as it goes, an orientation's control points.

:func:`map_hub` makes the :class:`~apygis.view.hub.ViewHub` of a map.
:class:`SessionFeed` follows a running session
(:meth:`apygis.session.Session.subscribe`): on the session's thread it reads
only the records an event changed, and hands them to the server's loop,
which never makes the session wait. :func:`control_overlays` turns a map
orientation's control points and residuals into overlays.

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
)
from apygis.model.map import MapFile
from apygis.model.symbols import load_library
from apygis.plot.plotdef import PlotterDef
from apygis.view.hub import DEFAULT_QUEUE_LIMIT, ViewHub
from apygis.view.scene import TABLE_NAMES, Pens, layer_rows, map_meta, rows_of, symbol_table

__all__ = ["SessionFeed", "control_overlays", "map_hub", "session_hub"]

log = logging.getLogger(__name__)

_REFS = ["fwd", "back", "side1", "side2"]


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
    """The session observer that feeds a :class:`~apygis.view.server.ViewServer`.

    Subscribe it with ``session.subscribe(feed)`` right after the server's hub
    was made from the session (:func:`session_hub`), on the session's thread.
    It costs the session a few microseconds per event: the floating mark and
    status line are handed over as the latest value only, and an entry's
    records are read from the map and handed over without waiting.
    """

    def __init__(self, server, session):
        self.server = server
        self.map_id = session.map.id
        self._refs: dict[str, dict[int, tuple]] = {
            lay.ext: _refs_of(lay.line_points) for lay in session.map
        }
        self._touched: set[str] = set()
        self._box = server.mailbox(self._apply, self._flush_status)
        self._geometry = session.geometry
        eng = session.engine
        self._last = Status(eng.mode, eng.layer_ext, "", eng.mark(), {})
        self.batches = 0

    # ------------------------------------------------------------------ session thread

    def __call__(self, session, event, effects: list) -> None:
        changes = None
        for e in effects:
            t = type(e)
            if t is Status:
                self._last = e
            elif t is not Plates:
                if changes is None:
                    changes = []
                changes.append(e)
        if changes is not None:
            self._send(session, changes)
        eng = session.engine
        d = session.display
        # the floating mark moves with every tablet report: the latest one is handed over
        self._box.put((self._last, eng.mark_xy, eng.z_model, d.scale, d.crosshair))

    def end(self, session) -> None:
        """The session is over: a last check of every layer, and ``ended`` for the pages."""
        why = (
            "compilation terminated"
            if session.finished
            else "session not terminated: the journal is kept for a resume"
        )
        self._post(
            {
                "full": {lay.ext: _copies(lay) for lay in session.map},
                "ended": True,
                "display": _display(session),
                "messages": [why],
            }
        )

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
                arr = lay.table(table)
                found = arr[_having(arr["num"], want)]
                have = set(found["num"].tolist())
                gone = [n for n in want if n not in have]
            if len(found):
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
        nums = lp["num"]
        mask = _having(nums, ask)
        found_nums = set(nums[mask].tolist())
        now = lp[mask]
        more = {int(r) for f in _REFS for r in now[f].tolist() if r >= 0} - found_nums - ask
        if more:
            mask |= _having(nums, more)
            now = lp[mask]
            found_nums = set(nums[mask].tolist())
        gone = [n for n in ask if n not in found_nums]
        for n in gone:
            refs.pop(n, None)
        refs.update(_refs_of(now))
        return now.copy(), gone

    def _post(self, change: dict) -> None:
        self.batches += 1
        self._box.add(change)

    def _apply(self, changes: list[dict]) -> None:  # on the server's loop
        _apply(self.server.hub, changes)

    # ------------------------------------------------------------------ server loop

    def _flush_status(self, value) -> None:
        st, xy, z_model, scale, crosshair = value
        mark = None
        if xy is not None:
            mark = (xy[0], xy[1], self._geometry.correct_z(xy[0], xy[1], z_model))
        counts = st.counts or self.server.hub.status.get("counts", {})
        self.server.hub.set_status(
            _status_dict(st.mode, st.layer, st.prompt, mark, counts, self.map_id),
            {"scale": scale, "crosshair": crosshair},
        )


def _having(nums: np.ndarray, wanted: set[int]) -> np.ndarray:
    """The mask of the rows whose number is in ``wanted`` (an entry names a few)."""
    if len(wanted) > 8:
        return np.isin(nums, np.fromiter(wanted, np.int64, len(wanted)))
    mask = np.zeros(len(nums), dtype=bool)
    for n in wanted:
        mask |= nums == n
    return mask


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
            zip(*(lp[f].tolist() for f in _REFS), strict=True),
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
                        t: rows_of(a) if isinstance(a, np.ndarray) else a for t, a in tables.items()
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
