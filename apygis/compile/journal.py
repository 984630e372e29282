"""The session journal: no acknowledged entry is ever lost.

A revision session appends every event it gives the engine to a journal
file ``<dir>/<ID>.journal`` (JSON lines, UTF-8, specified in
``docs/formats/session-journal.md``):

* line 1, the head: ``{"journal": 1, "map": <the map at session start as APY
  ASCII text>, "layer": <first layer>, "settings": {...}}``;
* then one line per event: ``{"mark": [x_mm, y_mm]}``, ``{"press": "ENTER"}``
  or ``{"keys": "text"}``.

Events are written as they come; the file is **fsynced before an entry is
acknowledged** (an event that changed records), so an acknowledged entry is
on disk whatever happens next. Marks between entries are not synced one by
one (that would cost the real-time loop a disk flush per tablet report); a
crash loses at most the mark movements after the last entry, which change no
record.

Recovery replays the journal into a fresh engine over the map of the head:
the engine is deterministic, so the map and the engine's state (mode, line
in progress, undo stack) come back exactly as they were after the last
journaled event. A last line cut short by the crash is ignored (and
reported); any other damage is a :class:`~apygis.errors.FormatError` naming
the line.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

from apygis.compile.engine import event_from_dict, event_to_dict
from apygis.errors import FormatError

__all__ = ["Journal", "JournalContents", "read_journal"]

log = logging.getLogger(__name__)

VERSION = 1


class JournalContents:
    """What a journal holds: the starting map, the first layer, settings, events."""

    def __init__(self, map_, layer: str, settings: dict, events: list, truncated: bool):
        self.map = map_
        self.layer = layer
        self.settings = settings
        self.events = events
        self.truncated = truncated


def read_journal(path) -> JournalContents:
    """Parse a journal; a torn last line is dropped with a warning."""
    from apygis.formats import ascii as apa

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FormatError(f"cannot read the journal: {exc.strerror}", path=path) from None
    lines = data.split(b"\n")
    truncated = False
    if lines and lines[-1] == b"":
        lines.pop()
    elif lines:
        truncated = True  # no newline after the last line: the crash cut it
        log.warning("%s: the last journal line is incomplete and is ignored", path)
        lines.pop()
    if not lines:
        raise FormatError("the journal has no head line", path=path, record="line 1")
    try:
        head = json.loads(lines[0].decode("utf-8"))
        if not isinstance(head, dict) or head.get("journal") != VERSION:
            raise ValueError(f"not a version {VERSION} journal head")
        m = apa.decode(head["map"].encode("utf-8"), path)
        layer = str(head["layer"])
        settings = dict(head.get("settings", {}))
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise FormatError(f"bad journal head: {exc}", path=path, record="line 1") from None
    events = []
    for k, raw in enumerate(lines[1:], start=2):
        try:
            events.append(event_from_dict(json.loads(raw.decode("utf-8"))))
        except (ValueError, TypeError, UnicodeDecodeError) as exc:
            raise FormatError(f"bad journal event: {exc}", path=path, record=f"line {k}") from None
    return JournalContents(m, layer, settings, events, truncated)


class Journal:
    """An open journal for appending events (see the module docstring).

    Use :meth:`create` for a new session and :meth:`reopen` after recovery.
    """

    def __init__(self, path, fh):
        self.path = Path(path)
        self._fh = fh
        self.events = 0
        self.syncs = 0

    @classmethod
    def create(cls, path, map_, layer: str, settings: dict) -> Journal:
        """Start a journal with the map as it is now; the head is synced at once."""
        from apygis.formats import ascii as apa

        path = Path(path)
        head = {
            "journal": VERSION,
            "map": apa.encode(map_).decode("utf-8"),
            "layer": layer,
            "settings": settings,
        }
        tmp = path.with_name(path.name + ".new")
        with open(tmp, "wb") as fh:
            fh.write(json.dumps(head, ensure_ascii=False).encode("utf-8") + b"\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _sync_dir(path.parent)
        return cls(path, open(path, "ab"))

    @classmethod
    def reopen(cls, path) -> Journal:
        """Append to an existing journal, first cutting off a torn last line."""
        path = Path(path)
        data = path.read_bytes()
        if data and not data.endswith(b"\n"):
            with open(path, "r+b") as fh:
                fh.truncate(data.rfind(b"\n") + 1)
                os.fsync(fh.fileno())
        return cls(path, open(path, "ab"))

    def append(self, event, sync: bool) -> None:
        """Write one event; with ``sync`` the file is on disk when this returns."""
        self._fh.write(json.dumps(event_to_dict(event), ensure_ascii=False).encode() + b"\n")
        self.events += 1
        if sync:
            self.sync()

    def sync(self) -> None:
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self.syncs += 1

    def close(self, remove: bool = False) -> None:
        """Close; ``remove`` after the session ended cleanly and its files are saved."""
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self._fh.close()
        if remove:
            os.unlink(self.path)
            _sync_dir(self.path.parent)


def _sync_dir(d: Path) -> None:
    """Make a rename or unlink in ``d`` durable (POSIX; a no-op where unsupported)."""
    try:
        fd = os.open(d, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
