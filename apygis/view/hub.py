"""The view's state and its viewers: what every page is told, in order, and nothing lost.

A :class:`ViewHub` lives on the view server's event loop (one thread; no
locks). It keeps the current state of what the pages show (the records of
every layer, the entries so far, the status line, the overlays) and a
:class:`Viewer` per open page.

Messages to a page (JSON text, each with ``t`` its type):

``state``
    Everything: the map's identification, pens, symbols, records, entries,
    status, overlays, ``seq`` the number of the last change it holds. The
    first message on every connection, and again whenever a page fell behind.
``delta``
    One change (``seq`` one more than the last): the entries it makes
    (``[n, what, layer, table, num, extra]``, ``what`` one of ``added``,
    ``deleted``, ``linked``, ``undone``), the records it adds or replaces
    (``upsert``: layer -> table -> rows) and removes (``remove``: layer ->
    table -> numbers), overlays, monitor messages, display settings, and
    ``ended`` when the session is over.
``status``
    The status line and the floating mark, the latest only (a page is sent
    no more than it can draw).

A session's changes reach the hub at once after a pause, then at most every
:data:`DELIVERY_INTERVAL_S` (all that came meanwhile, in order, as one
delta), so that a busy session makes a bounded number of deltas a second.

Every page has a bounded queue (:attr:`Viewer.limit` messages). When a page
does not keep up (a slow network, a page in a background tab, a closed lid)
its queue is dropped and it is sent the whole ``state`` instead, which holds
every entry and record of the dropped deltas: the page loses nothing, and
the producer (the session) never waits.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any

from apygis.view.scene import TABLE_NAMES, Pens

__all__ = ["DEFAULT_QUEUE_LIMIT", "DELIVERY_INTERVAL_S", "ViewHub", "Viewer"]

log = logging.getLogger(__name__)

#: Messages a page may have waiting before it is resynchronised with the whole state.
DEFAULT_QUEUE_LIMIT = 256
#: A session's changes, and its status line and mark, are delivered at most this often,
#: seconds (changes after a pause at once): 40 a second are as smooth as a screen shows
#: and keep an entry's way to the page well under 50 ms.
DELIVERY_INTERVAL_S = 0.025
#: Monitor messages kept for a page that opens later.
MESSAGES_KEPT = 200
#: AREA and DHI results kept as overlays.
RESULTS_KEPT = 50


def _dumps(obj) -> str:
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


class Viewer:
    """One open page: its bounded queue of messages, and the flags of what it still needs.

    ``send`` is the coroutine that sends a text message to the page.
    """

    def __init__(self, send: Callable[[str], Awaitable[Any]], limit: int = DEFAULT_QUEUE_LIMIT):
        self.send = send
        self.limit = limit
        self.pending: deque[tuple[int, str]] = deque()
        self.resync = True  # the first message is the whole state
        self.status_dirty = False
        self.sent_seq = -1
        self.resyncs = 0  # times this page fell behind and was sent the whole state again
        self.sent = 0
        self.wake = asyncio.Event()
        self.wake.set()

    def push(self, seq: int, text: str) -> None:
        """Queue a delta; a full queue becomes one resynchronisation."""
        if self.resync:
            return  # the state it will be sent holds this change
        if len(self.pending) >= self.limit:
            self.pending.clear()
            self.resync = True
            self.resyncs += 1
        else:
            self.pending.append((seq, text))
        self.wake.set()

    def status(self) -> None:
        self.status_dirty = True
        self.wake.set()

    async def run(self, hub: ViewHub) -> None:
        """Send what the page needs, in order, until cancelled or the connection fails."""
        while True:
            await self.wake.wait()
            self.wake.clear()
            while True:
                if self.resync:
                    self.resync = False
                    self.pending.clear()
                    self.status_dirty = False
                    seq, text = hub.state_json()
                    await self.send(text)
                    self.sent_seq = seq
                    self.sent += 1
                elif self.pending:
                    seq, text = self.pending.popleft()
                    if seq > self.sent_seq:
                        await self.send(text)
                        self.sent_seq = seq
                        self.sent += 1
                elif self.status_dirty:
                    self.status_dirty = False
                    await self.send(hub.status_json())
                    self.sent += 1
                else:
                    break


class ViewHub:
    """The state the pages show, and the pages.

    Parameters
    ----------
    kind : str
        ``"map"`` (``apygis view``), ``"session"`` or ``"orientation"``: the
        page's title and which panels it shows.
    pens : Pens
        The plot's pens.
    symbols : dict
        :func:`~apygis.view.scene.symbol_table` of the symbol library.
    meta : dict
        :func:`~apygis.view.scene.map_meta` of the map.
    queue_limit : int
        Messages a page may have waiting before it is sent the whole state.
    """

    def __init__(
        self,
        kind: str,
        pens: Pens,
        symbols: dict,
        meta: dict,
        queue_limit: int = DEFAULT_QUEUE_LIMIT,
    ):
        self.kind = kind
        self.pens = pens
        self.symbols = symbols
        self.meta = meta
        self.queue_limit = queue_limit
        self.layers: dict[str, dict[str, dict[int, list]]] = {}
        self.entries: list[list] = []
        self.entries_before = 0  # entries made before this view started (a recovered journal)
        self.messages: deque[str] = deque(maxlen=MESSAGES_KEPT)
        self.overlays: list[dict] = []
        self.status: dict[str, Any] = {}
        self.display = {"scale": 1.0, "crosshair": 1.0}
        self.ended = False
        self.seq = 0
        self.viewers: set[Viewer] = set()
        self.corrections = 0  # records a full comparison found different (see apply)
        self._state_cache: tuple[int, str] | None = None
        self._status_cache: str | None = None

    # ------------------------------------------------------------------ loading

    def load_layers(self, layers: dict[str, dict[str, list[list]]]) -> None:
        """Replace the records (layer -> table -> rows) without a delta (before any viewer)."""
        self.layers = {
            ext: {t: {int(r[0]): r for r in tables.get(t, [])} for t in TABLE_NAMES}
            for ext, tables in layers.items()
        }
        for ext in self.layers:
            self.pens.layer(ext)
        self._changed()

    def set_overlays(self, overlays: list[dict]) -> None:
        """Replace the overlays (control points, residuals); viewers get the whole state."""
        self.overlays = list(overlays)
        self._changed()
        for v in self.viewers:
            v.resync = True
            v.wake.set()

    # ------------------------------------------------------------------ viewers

    def add(self, viewer: Viewer) -> None:
        self.viewers.add(viewer)

    def remove(self, viewer: Viewer) -> None:
        self.viewers.discard(viewer)

    def _changed(self) -> None:
        self._state_cache = None

    def state(self) -> dict[str, Any]:
        """Everything a page needs, as a JSON-ready dict (``t`` = ``"state"``)."""
        return {
            "t": "state",
            "seq": self.seq,
            "kind": self.kind,
            "map": self.meta,
            "pens": self.pens.pens(),
            "layer_pens": {ext: self.pens.layer(ext) for ext in self.layers},
            "style": self.pens.style(),
            "symbols": self.symbols,
            "layers": {
                ext: {t: list(rows.values()) for t, rows in tables.items()}
                for ext, tables in self.layers.items()
            },
            "entries": self.entries,
            "entries_before": self.entries_before,
            "messages": list(self.messages),
            "overlays": self.overlays,
            "status": self.status,
            "display": self.display,
            "ended": self.ended,
        }

    def state_json(self) -> tuple[int, str]:
        """``(seq, text)`` of :meth:`state`, built once per change for all pages."""
        if self._state_cache is None or self._state_cache[0] != self.seq:
            self._state_cache = (self.seq, _dumps(self.state()))
        return self._state_cache

    def status_json(self) -> str:
        if self._status_cache is None:
            self._status_cache = _dumps({"t": "status", **self.status, "display": self.display})
        return self._status_cache

    # ------------------------------------------------------------------ changes

    def set_status(self, status: dict[str, Any], display: dict[str, float] | None = None) -> None:
        """The latest status line and mark; pages are told (coalesced)."""
        self.status = status
        if display is not None:
            self.display = display
        self._status_cache = None
        self._changed()
        for v in self.viewers:
            v.status()

    def apply(self, change: dict[str, Any]) -> None:
        """One change from the producer: :meth:`apply_all` of ``[change]``."""
        self.apply_all([change])

    def apply_all(self, changes: list[dict[str, Any]]) -> None:
        """Changes from the producer, in order: update the state, queue one delta for every page.

        Each change may hold ``entries`` (rows as in the delta), ``upsert``
        (layer -> table -> rows read from the map), ``remove`` (layer ->
        table -> numbers), ``full`` (layer -> table -> all rows: the layer
        as it is now; compared with the state here, and what differs becomes
        part of the delta), ``overlays``, ``messages``, ``display`` and
        ``ended``.

        The changes become one delta: a record they touched is sent as it is
        after the last of them (upserted), or removed if it was there before
        them and is not now; one that came and went in between is not sent.
        A page that applies the delta to the state it had ends with this
        state, as if it had been sent one delta per change, in fewer messages.
        """
        before: dict[tuple[str, str], dict[int, bool]] = {}  # touched -> was there before
        new_layers: list[str] = []
        entries: list[list] = []
        msgs: list[str] = []
        overlays: list[dict] = []
        display = None
        ended = False

        def tables_of(ext: str) -> dict[str, dict[int, list]]:
            got = self.layers.get(ext)
            if got is None:
                got = self.layers[ext] = {t: {} for t in TABLE_NAMES}
                new_layers.append(ext)
            return got

        def touch(ext: str, t: str, mine: dict[int, list], n: int) -> None:
            seen = before.setdefault((ext, t), {})
            if n not in seen:
                seen[n] = n in mine

        for change in changes:
            for ext, tables in change.get("upsert", {}).items():
                mine_tables = tables_of(ext)
                for t, rows in tables.items():
                    mine = mine_tables[t]
                    for r in rows:
                        n = int(r[0])
                        touch(ext, t, mine, n)
                        mine[n] = r
            for ext, tables in change.get("remove", {}).items():
                mine_tables = tables_of(ext)
                for t, nums in tables.items():
                    mine = mine_tables[t]
                    for n in nums:
                        n = int(n)
                        if n in mine:
                            touch(ext, t, mine, n)
                            del mine[n]
            for ext, tables in change.get("full", {}).items():
                mine_tables = tables_of(ext)
                for t, rows in tables.items():
                    new = {int(r[0]): r for r in rows}
                    old = mine_tables[t]
                    changed = [n for n, r in new.items() if old.get(n) != r]
                    gone = [n for n in old if n not in new]
                    for n in changed:
                        touch(ext, t, old, n)
                    for n in gone:
                        touch(ext, t, old, n)
                    mine_tables[t] = new
                    if not change.get("entries") and (changed or gone):
                        self.corrections += len(changed) + len(gone)
                        log.debug("view of layer %s %s: %d records corrected", ext, t, len(changed))
            entries.extend(change.get("entries", ()))
            msgs.extend(change.get("messages", ()))
            overlays.extend(change.get("overlays", ()))
            if change.get("display") is not None:
                display = change["display"]
            if change.get("ended"):
                ended = True

        upsert: dict[str, dict[str, list]] = {}
        remove: dict[str, dict[str, list]] = {}
        for (ext, t), seen in before.items():
            mine = self.layers[ext][t]
            rows = [mine[n] for n in seen if n in mine]
            gone = [n for n, was in seen.items() if was and n not in mine]
            if rows:
                upsert.setdefault(ext, {})[t] = rows
            if gone:
                remove.setdefault(ext, {})[t] = gone
        self.entries.extend(entries)
        self.messages.extend(msgs)
        if overlays:
            self.overlays.extend(overlays)
            results = [o for o in self.overlays if o.get("kind") in ("area", "dhi")]
            if len(results) > RESULTS_KEPT:
                drop = {id(o) for o in results[: len(results) - RESULTS_KEPT]}
                self.overlays = [o for o in self.overlays if id(o) not in drop]
        if display is not None:
            self.display = dict(display)
            self._status_cache = None
        if ended:
            self.ended = True
        if not (upsert or remove or entries or msgs or overlays or display or ended or new_layers):
            return
        self.seq += 1
        delta: dict[str, Any] = {"t": "delta", "seq": self.seq}
        if entries:
            delta["entries"] = entries
        if upsert:
            delta["upsert"] = upsert
        if remove:
            delta["remove"] = remove
        if new_layers:
            delta["layer_pens"] = {ext: self.pens.layer(ext) for ext in new_layers}
            delta["pens"] = self.pens.pens()
        if msgs:
            delta["messages"] = msgs
        if overlays:
            delta["overlays"] = overlays
        if display is not None:
            delta["display"] = self.display
        if ended:
            delta["ended"] = True
        self._changed()
        text = _dumps(delta)
        for v in self.viewers:
            v.push(self.seq, text)

    def stats(self) -> dict[str, int]:
        """Pages open, resynchronisations so far, records corrected by full comparisons."""
        return {
            "viewers": len(self.viewers),
            "resyncs": sum(v.resyncs for v in self.viewers),
            "corrections": self.corrections,
            "seq": self.seq,
        }
