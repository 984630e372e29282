"""The session journal: no acknowledged entry is ever lost.

A revision session appends every event it gives the engine to a journal
file ``<dir>/<ID>.journal`` (JSON lines, UTF-8, specified in
``docs/formats/session-journal.md``):

* line 1, the head: ``{"journal": 2, "map": <the map at session start as APY
  ASCII text>, "layer": <first layer>, "settings": {...}, "files": {...}}``,
  where ``files`` gives the size and SHA-256 of each APY layer file on disk
  when the session started;
* then one line per event: ``{"mark": [x_mm, y_mm]}``, ``{"press": "ENTER"}``
  or ``{"keys": "text"}``; and before each save of the layer files a line
  ``{"files": {...}}`` with the files as that save leaves them.

Events are written as they come; the file is **fsynced before an entry is
acknowledged** (an event that changed records), so an acknowledged entry is
on disk whatever happens next. Marks between entries are not synced one by
one (that would cost the real-time loop a disk flush per tablet report); a
crash loses at most the mark movements after the last entry, which change no
record.

Recovery replays the journal into a fresh engine over the map of the head:
the engine is deterministic, so the map and the engine's state (mode, line
in progress, undo stack) come back exactly as they were after the last
journaled event. It is allowed only while every layer file on disk is one
the journal knows (:func:`check_files`): a file changed by other means
after the session started would be overwritten by the replay. A last line
cut short by the crash is ignored (and reported); any other damage is a
:class:`~apygis.errors.FormatError` naming the file and the line.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import math
import os
import re
from pathlib import Path

from apygis.compile.events import Keys, Mark, Press, event_to_dict
from apygis.errors import ApygisError, FormatError
from apygis.fileio import atomic_write

__all__ = [
    "MAX_MARK_MM",
    "SETTINGS",
    "Journal",
    "JournalContents",
    "JournalTail",
    "JournalWriteError",
    "StaleJournalError",
    "check_files",
    "check_settings",
    "layer_file_states",
    "read_journal",
    "upgrade_journal",
]

log = logging.getLogger(__name__)

#: The journal version written; version 1 (no file states) is read, but not recovered
#: without ``trust``.
VERSION = 2
_READ_VERSIONS = (1, 2)

#: Largest tablet coordinate a journaled mark may have, in millimetres (a tablet is
#: a metre or two wide; anything beyond this is damage, not a position).
MAX_MARK_MM = 100_000.0

#: Longest text a ``keys`` event may carry (characters).
MAX_KEYS = 10_000

#: Engine settings a journal (and a session) may carry: name -> (kind, low, high).
SETTINGS: dict[str, tuple[type, float, float]] = {
    "snap_mm": (float, 0.0, 1000.0),
    "sample_tolerance_mm": (float, 0.0, 1000.0),
    "autosave_every": (int, 1, 1_000_000),
    "start_z_m": (float, -100_000.0, 100_000.0),
}

_SHA = re.compile(r"[0-9a-f]{64}\Z")
_EXT = re.compile(r"[a-z]{1,3}\Z")


class StaleJournalError(ApygisError, RuntimeError):
    """A journal cannot be recovered safely: the layer files changed after it was written,
    or it is too old to tell."""


class JournalWriteError(ApygisError, OSError):
    """The journal could not be written (a full disk, an I/O error): the entry is not safe."""


def _button_names() -> frozenset[str]:
    from apygis.instrument.pad import BUTTONS

    return frozenset(BUTTONS.values())


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def check_settings(settings, where: str = "settings") -> dict:
    """The engine settings, type- and range-checked; raises ValueError naming the key."""
    if not isinstance(settings, dict):
        raise ValueError(f"{where} must be an object, not {type(settings).__name__}")
    out = {}
    for key, value in settings.items():
        if key not in SETTINGS:
            raise ValueError(f"{where}: unknown setting {key!r}; expected {', '.join(SETTINGS)}")
        kind, lo, hi = SETTINGS[key]
        ok = _is_number(value) and (kind is float or isinstance(value, int))
        # compare before converting: a 400-digit integer must not reach float()
        if not ok or not (lo <= value <= hi):
            what = "a whole number" if kind is int else "a number"
            raise ValueError(f"{where}: {key} must be {what} from {lo:g} to {hi:g}, not {value!r}")
        out[key] = kind(value)
    return out


def _file_state(data: bytes) -> dict:
    return {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def layer_file_states(base) -> dict[str, dict]:
    """``{ext: {"size": n, "sha256": hex}}`` of the APY layer files ``base.<ext>`` on disk.

    The files the ``apy`` driver reads as the map: a 1-3 letter extension and
    the APY magic number (so that ``ID.apa``, ``ID.journal`` and ``ID.lock``
    are not among them).
    """
    from apygis.formats.apy import MAGIC

    base = Path(base)
    out: dict[str, dict] = {}
    if not base.parent.is_dir():
        return out
    prefix = base.name + "."
    for p in sorted(base.parent.iterdir()):
        ext = p.name[len(prefix) :]
        if not (p.name.startswith(prefix) and _EXT.match(ext.lower()) and p.is_file()):
            continue
        try:
            data = p.read_bytes()
        except OSError as exc:
            raise FormatError(f"cannot read the layer file: {exc.strerror}", path=p) from None
        if data[: len(MAGIC)] == MAGIC:
            out[ext.lower()] = _file_state(data)
    return out


def planned_file_states(contents: dict[str, bytes]) -> dict[str, dict]:
    """The file states a save of ``{ext: bytes}`` will leave (other layer files removed)."""
    return {ext: _file_state(data) for ext, data in contents.items()}


def _check_file_states(obj, where: str) -> dict:
    if not isinstance(obj, dict):
        raise ValueError(f"{where} must be an object of layer files, not {obj!r:.60}")
    for ext, st in obj.items():
        if not (isinstance(ext, str) and _EXT.match(ext)):
            raise ValueError(f"{where}: {ext!r:.40} is not a layer extension (1-3 letters)")
        if (
            not isinstance(st, dict)
            or set(st) != {"size", "sha256"}
            or not isinstance(st["size"], int)
            or isinstance(st["size"], bool)
            or not 0 <= st["size"] <= 1 << 40
            or not (isinstance(st["sha256"], str) and _SHA.match(st["sha256"]))
        ):
            raise ValueError(
                f'{where}: layer {ext}: expected {{"size": bytes, "sha256": 64 hex digits}}, '
                f"not {st!r:.80}"
            )
    return obj


class JournalContents:
    """What a journal holds: the starting map, the first layer, settings, events.

    ``file_states`` lists the states of the layer files the journal knows,
    oldest first: those at session start (the head), then one per save
    (empty for a version 1 journal, which did not record them).
    """

    def __init__(
        self,
        map_,
        layer: str,
        settings: dict,
        events: list,
        truncated: bool,
        *,
        version: int = VERSION,
        file_states: list | None = None,
        path=None,
    ):
        self.map = map_
        self.layer = layer
        self.settings = settings
        self.events = events
        self.truncated = truncated
        self.version = version
        self.file_states = list(file_states or [])
        self.path = None if path is None else Path(path)


def _loads(raw: bytes):
    """One JSON line; ValueError for anything that is not (deep nesting, huge numbers too)."""
    try:
        return json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ValueError(f"not UTF-8 ({exc.reason} at byte {exc.start})") from None
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None
    except ValueError as exc:  # bad JSON, or an integer beyond Python's digit limit
        raise ValueError(f"bad JSON ({exc})") from None


def _event(obj, buttons: frozenset[str]):
    """An engine event, or ``("files", states)`` for a save record; ValueError if neither."""
    if not isinstance(obj, dict) or len(obj) != 1:
        raise ValueError(
            'expected one of {"mark": [x, y]}, {"press": NAME}, {"keys": TEXT}, {"files": {...}}, '
            f"not {obj!r:.80}"
        )
    ((key, v),) = obj.items()
    if key == "mark":
        if not (isinstance(v, list) and len(v) == 2 and all(_is_number(c) for c in v)):
            raise ValueError(f"a mark is [x_mm, y_mm], two numbers, not {v!r:.80}")
        # compare before float(): a 400-digit integer would overflow it
        if not all(-MAX_MARK_MM <= c <= MAX_MARK_MM for c in v) or not all(
            math.isfinite(c) for c in v
        ):
            raise ValueError(
                f"a mark's coordinates must be finite and within +-{MAX_MARK_MM:g} mm, "
                f"not {v!r:.80}"
            )
        return Mark(float(v[0]), float(v[1]))
    if key == "press":
        if not isinstance(v, str) or v not in buttons:
            raise ValueError(f"{v!r:.40} is not a button name (docs/button-pad.md)")
        return Press(v)
    if key == "keys":
        if not isinstance(v, str) or len(v) > MAX_KEYS:
            raise ValueError(f"typed text must be a string of at most {MAX_KEYS} characters")
        try:
            v.encode("utf-8")
        except UnicodeEncodeError:
            raise ValueError("typed text holds an unpaired surrogate (not text)") from None
        return Keys(v)
    if key == "files":
        return ("files", _check_file_states(v, "files"))
    raise ValueError(f"unknown journal record {key!r:.40}")


_NUMBER = rb"(-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?)"
#: A mark line as :class:`Journal` writes it (JSON numbers only; anything else, such as
#: NaN, takes the general parser and its checks).
_MARK_LINE = re.compile(rb'\{"mark": \[' + _NUMBER + rb", " + _NUMBER + rb"\]\}")


def _line_event(raw: bytes, buttons: frozenset[str], path, k: int):
    """The event of journal line ``k`` (or ``("files", states)``); FormatError naming it.

    Most lines are marks, written by :class:`Journal` in one form: those are
    read without the general parser (the same values; anything else, such as
    a mark out of range, takes the general parser and its message).
    """
    got = _MARK_LINE.fullmatch(raw)
    if got is not None:
        x, y = float(got[1]), float(got[2])
        if -MAX_MARK_MM <= x <= MAX_MARK_MM and -MAX_MARK_MM <= y <= MAX_MARK_MM:
            return Mark(x, y)
    try:
        return _event(_loads(raw), buttons)
    except ValueError as exc:
        raise FormatError(f"bad journal event: {exc}", path=path, record=f"line {k}") from None


def _head(raw: bytes, path) -> tuple:
    """The head line: ``(map, layer, settings, version, [file states])``; FormatError if bad."""
    from apygis.formats import ascii as apa
    from apygis.model.map import check_ext

    try:
        head = _loads(raw)
        if not isinstance(head, dict):
            raise ValueError("the head must be a JSON object")
        version = head.get("journal")
        if not isinstance(version, int) or isinstance(version, bool):
            raise ValueError(f'"journal" must be the version number, not {version!r:.40}')
        if version not in _READ_VERSIONS:
            raise ValueError(f"journal version {version} is not supported (expected 1 or 2)")
        if not isinstance(head.get("map"), str):
            raise ValueError('"map" must be the map as APY ASCII text')
        layer = head.get("layer")
        if not isinstance(layer, str):
            raise ValueError(f'"layer" must be a layer extension, not {layer!r:.40}')
        check_ext(layer)
        settings = check_settings(head.get("settings", {}), '"settings"')
        states = []
        if version >= 2:
            if "files" not in head:
                raise ValueError('a version 2 head needs "files"')
            states.append(_check_file_states(head["files"], '"files"'))
        m = apa.decode(head["map"].encode("utf-8"), path)
    except (ValueError, OverflowError, RecursionError, UnicodeEncodeError) as exc:
        reason = exc.reason if isinstance(exc, FormatError) else str(exc)
        raise FormatError(f"bad journal head: {reason}", path=path, record="line 1") from None
    return m, layer, settings, version, states


def read_journal(path) -> JournalContents:
    """Parse and check a journal; a torn last line is dropped with a warning.

    Raises :class:`~apygis.errors.FormatError` naming the file and the line for
    anything else: bad JSON, JSON nested too deeply, numbers beyond range, a
    head or an event of the wrong shape or type.
    """
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
    m, layer, settings, version, states = _head(lines[0], path)
    buttons = _button_names()
    events = []
    for k, raw in enumerate(lines[1:], start=2):
        ev = _line_event(raw, buttons, path, k)
        if isinstance(ev, tuple):
            if version < 2:
                raise FormatError(
                    'bad journal event: "files" records need a version 2 journal',
                    path=path,
                    record=f"line {k}",
                )
            states.append(ev[1])
        else:
            events.append(ev)
    return JournalContents(
        m,
        layer.lower(),
        settings,
        events,
        truncated,
        version=version,
        file_states=states,
        path=path,
    )


class JournalTail:
    """A journal read while its session writes it: the head, then the events as they come.

    ``fh`` is the journal opened for reading (binary; from its start); it
    may have been unlinked since (a terminated session removes its journal:
    what was written can still be read). :attr:`map`, :attr:`layer` and
    :attr:`settings` come from the head; :meth:`read` returns the events of
    the lines completed since the last call (a line still being written
    waits for its newline). Save records (``files``) are skipped. A bad line
    is a :class:`~apygis.errors.FormatError` naming the file and the line.
    """

    def __init__(self, fh, path):
        self.path = Path(path)
        self._fh = fh
        self._rest = b""
        raw = b""
        while not raw.endswith(b"\n"):  # the head is written whole, at once
            more = fh.readline()
            if not more:
                raise FormatError("the journal has no head line", path=self.path, record="line 1")
            raw += more
        self.position = len(raw)  # bytes consumed (to the end of the last complete line)
        self.line = 1
        self.map, layer, self.settings, _, _ = _head(raw[:-1], self.path)
        self.layer = layer.lower()
        self._buttons = _button_names()

    def read(self, upto: int | None = None) -> list:
        """The events of the lines completed since the last call (up to byte ``upto``)."""
        want = -1 if upto is None else max(0, upto - self.position - len(self._rest))
        data = self._fh.read(want) if want else b""
        if not data:
            return []
        lines = (self._rest + data).split(b"\n")
        self._rest = lines.pop()
        out = []
        for raw in lines:
            self.line += 1
            self.position += len(raw) + 1
            ev = _line_event(raw, self._buttons, self.path, self.line)
            if not isinstance(ev, tuple):
                out.append(ev)
        return out

    def close(self) -> None:
        self._fh.close()


def check_files(contents: JournalContents, base) -> None:
    """Refuse recovery unless every layer file on disk is one the journal knows.

    A layer file may be as the session found it or as any of its saves left
    it (a crash during a save leaves some files old, some new); a file in any
    other state was changed by other means after the session started, and
    replaying the journal would overwrite that change.
    """
    path = contents.path
    how = (
        "run the session again with --discard-journal (the journal is renamed aside), or "
        f"rename or remove {path} yourself"
    )
    if contents.version < 2:
        raise StaleJournalError(
            f"{path}: a version {contents.version} journal, left by an older apygis: it does not "
            "record the layer files it started from, so it cannot tell whether they changed "
            "since. To replay it over the files anyway, use --trust-journal; to start from the "
            f"files as they are, {how}"
        )
    now = layer_file_states(base)
    exts = sorted(set(now).union(*contents.file_states))
    for ext in exts:
        known = [st.get(ext) for st in contents.file_states]
        if now.get(ext) not in known:
            f = Path(base).with_name(f"{Path(base).name}.{ext}")
            change = "appeared" if ext in now and all(k is None for k in known) else "changed"
            if ext not in now:
                change = "was removed"
            raise StaleJournalError(
                f"{path}: the layer file {f} {change} after this journal's session started "
                "(it is neither the file the session started from nor one it saved); "
                f"recovering would overwrite that change. To keep the files as they are, {how}; "
                "to replay the journal over them anyway, use --trust-journal"
            )


def upgrade_journal(path, files: dict) -> None:
    """Rewrite a version 1 journal as version 2, atomically: the same head and events, with
    ``files`` (the layer files now, which the operator chose to trust) in the head."""
    path = Path(path)
    try:
        data = path.read_bytes()
        first, _, rest = data.partition(b"\n")
        rest = rest[: rest.rfind(b"\n") + 1]  # without a torn last line
        head = json.loads(first.decode("utf-8"))
        head["journal"] = VERSION
        head["files"] = files
        atomic_write(path, json.dumps(head, ensure_ascii=False).encode("utf-8") + b"\n" + rest)
    except OSError as exc:
        raise JournalWriteError(
            f"{path}: cannot rewrite the journal as version {VERSION}: {exc.strerror or exc}"
        ) from exc


class Journal:
    """An open journal for appending events (see the module docstring).

    Use :meth:`create` for a new session and :meth:`reopen` after recovery.
    Write failures raise :class:`JournalWriteError`.
    """

    def __init__(self, path, fh):
        self.path = Path(path)
        self._fh = fh
        self.events = 0
        self.syncs = 0

    @classmethod
    def create(cls, path, map_, layer: str, settings: dict, files: dict | None = None) -> Journal:
        """Start a journal with the map as it is now; the head is synced at once.

        ``files``: the layer file states on disk (:func:`layer_file_states`).
        """
        from apygis.formats import ascii as apa

        path = Path(path)
        head = {
            "journal": VERSION,
            "map": apa.encode(map_).decode("utf-8"),
            "layer": layer,
            "settings": settings,
            "files": files or {},
        }
        try:
            atomic_write(path, json.dumps(head, ensure_ascii=False).encode("utf-8") + b"\n")
            return cls(path, open(path, "ab"))
        except OSError as exc:
            raise JournalWriteError(
                f"{path}: cannot create the journal: {exc.strerror or exc}"
            ) from exc

    @classmethod
    def reopen(cls, path) -> Journal:
        """Append to an existing journal, first cutting off a torn last line."""
        path = Path(path)
        try:
            data = path.read_bytes()
            if data and not data.endswith(b"\n"):
                with open(path, "r+b") as fh:
                    fh.truncate(data.rfind(b"\n") + 1)
                    os.fsync(fh.fileno())
            return cls(path, open(path, "ab"))
        except OSError as exc:
            raise JournalWriteError(
                f"{path}: cannot reopen the journal: {exc.strerror or exc}"
            ) from exc

    def _write(self, obj: dict) -> None:
        line = json.dumps(obj, ensure_ascii=False).encode("utf-8") + b"\n"
        try:
            self._fh.write(line)
        except OSError as exc:
            raise JournalWriteError(
                f"{self.path}: cannot write the journal: {exc.strerror or exc}"
            ) from exc

    def append(self, event, sync: bool) -> None:
        """Write one event; with ``sync`` the file is on disk when this returns."""
        self._write(event_to_dict(event))
        self.events += 1
        if sync:
            self.sync()

    def record_files(self, states: dict) -> None:
        """Journal the layer file states a save is about to leave, synced."""
        self._write({"files": states})
        self.sync()

    def flush(self) -> int:
        """Hand what is written to the operating system (no disk flush); the size so far."""
        try:
            self._fh.flush()
            return self._fh.tell()
        except OSError as exc:
            raise JournalWriteError(
                f"{self.path}: cannot write the journal: {exc.strerror or exc}"
            ) from exc

    def sync(self) -> None:
        try:
            self._fh.flush()
            os.fsync(self._fh.fileno())
        except OSError as exc:
            raise JournalWriteError(
                f"{self.path}: cannot write the journal to disk: {exc.strerror or exc}; "
                "the last entry is not safe"
            ) from exc
        self.syncs += 1

    @property
    def closed(self) -> bool:
        return self._fh.closed

    def close(self, remove: bool = False) -> None:
        """Close; ``remove`` after the session ended cleanly and its files are saved."""
        if self._fh.closed:
            return
        try:
            self.sync()
        finally:
            with contextlib.suppress(OSError):
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
