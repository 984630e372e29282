"""Record the raw bytes of an instrument session and replay them exactly.

A recording is a UTF-8 text file of JSON lines (``docs/protocols.md``,
"Session recordings")::

    {"format": "apygis-recording", "version": 1, "created": "2026-03-01T09:30:00Z"}
    {"t": 0.000000, "ch": "tablet", "hex": "8c1f2000022c"}
    {"t": 0.010412, "ch": "keyboard", "hex": "4b69726368776567"}
    {"t": 0.010950, "ch": "motors", "dir": "tx", "hex": "4730205831320a"}

The first line is the header; every other line is one chunk of bytes as it
was read (``"dir": "rx"``, the default, left out) or written (``"tx"``) on
a channel, ``t`` seconds after the recording started (monotonic clock,
microseconds). Channels: ``tablet``, ``keyboard``, ``motors`` (others are
allowed: a letter, then letters, digits, ``_ . -``).

The :class:`Recorder` writes each chunk at once, flushes and fsyncs it, so
that a crash loses at most the line being written; the :class:`Replayer`
tolerates such a cut-off last line (a line without its newline) with a
logged warning, and raises :class:`~apygis.errors.FormatError` naming the
file and line for anything else that is wrong.

Examples
--------
>>> import tempfile, pathlib
>>> path = pathlib.Path(tempfile.mkdtemp()) / "session.rec"
>>> with Recorder(path) as rec:
...     _ = rec.record("tablet", b"\\x8c\\x1f\\x20\\x00\\x02\\x2c")
...     _ = rec.record("keyboard", b"Kirchweg")
>>> [(c.channel, c.data) for c in Replayer(path)]
[('tablet', b'\\x8c\\x1f \\x00\\x02,'), ('keyboard', b'Kirchweg')]
"""

from __future__ import annotations

import contextlib
import datetime
import json
import logging
import os
import re
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TypeGuard

from apygis.errors import FileOverwriteError, FormatError, InstrumentError

__all__ = [
    "FORMAT",
    "VERSION",
    "Chunk",
    "Recorder",
    "RecordingPort",
    "ReplayPort",
    "Replayer",
    "check_recording",
    "read_recording",
]

log = logging.getLogger(__name__)

FORMAT = "apygis-recording"
VERSION = 1
_CHANNEL = re.compile(r"[A-Za-z][A-Za-z0-9_.-]*\Z")
_DIRECTIONS = ("rx", "tx")
#: Latest chunk time a recording may give, in seconds (115 days): later is damage, and
#: would make a real-time replay sleep for ever.
MAX_T = 1e7
#: Plausible tablet resolutions for the header's ``counts_per_mm``.
COUNTS_PER_MM = (0.1, 10_000.0)


@dataclass(frozen=True, slots=True)
class Chunk:
    """Bytes on one channel at one time.

    Attributes
    ----------
    t : float
        Seconds since the start of the recording (or of the script).
    channel : str
        ``tablet``, ``keyboard``, ``motors``, ...
    data : bytes
        The bytes.
    direction : str
        ``rx``: read from the instrument; ``tx``: written to it.
    """

    t: float
    channel: str
    data: bytes
    direction: str = "rx"


def _check_channel(channel: str, direction: str) -> None:
    if not isinstance(channel, str) or not _CHANNEL.match(channel):
        raise InstrumentError(f"bad channel name {channel!r}: a letter, then letters, digits _ . -")
    if direction not in _DIRECTIONS:
        raise InstrumentError(f"bad direction {direction!r}: 'rx' or 'tx'")


class Recorder:
    """Append chunks of bytes to a recording file, crash-safe.

    Parameters
    ----------
    path : str or os.PathLike
        The recording to create.
    overwrite : bool
        Replace an existing file (else :class:`~apygis.errors.FileOverwriteError`).
    fsync : bool
        ``os.fsync`` after every chunk (the default; a crash then loses at
        most the chunk being written). False: flush to the OS only.
    clock : callable
        Monotonic clock in seconds (``time.monotonic``); ``t`` counts from
        the recorder's creation.
    meta : dict, optional
        Extra keys for the header line (tablet protocol, port names, ...).

    Thread-safe: the tablet reader and the motor client may record from
    their own threads; the times in the file never decrease.
    """

    def __init__(
        self,
        path,
        *,
        overwrite: bool = False,
        fsync: bool = True,
        clock: Callable[[], float] = time.monotonic,
        meta: dict | None = None,
    ):
        self.path = Path(path)
        self.fsync = fsync
        self._clock = clock
        self._lock = threading.Lock()
        self.count = 0
        try:
            self._file = open(self.path, "w" if overwrite else "x", encoding="utf-8", newline="\n")  # noqa: SIM115
        except FileExistsError:
            raise FileOverwriteError(f"{self.path}: exists; pass overwrite=True") from None
        except OSError as exc:
            raise InstrumentError(f"{self.path}: cannot create the recording: {exc}") from exc
        header = {
            "format": FORMAT,
            "version": VERSION,
            "created": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        }
        if meta:
            header.update({k: v for k, v in meta.items() if k not in ("format", "version")})
        self._t0 = clock()
        self._last = 0.0
        self._write(json.dumps(header) + "\n")

    def _write(self, text: str) -> None:
        self._file.write(text)
        self._file.flush()
        if self.fsync:
            os.fsync(self._file.fileno())

    def record(self, channel: str, data: bytes, direction: str = "rx", t: float | None = None):
        """Append one chunk; return it as a :class:`Chunk` (None for empty data)."""
        if not data:
            return None
        _check_channel(channel, direction)
        with self._lock:
            if self._file.closed:
                raise InstrumentError(f"{self.path}: the recording is closed")
            when = (self._clock() - self._t0) if t is None else float(t)
            when = max(when, self._last)
            self._last = when
            d = "" if direction == "rx" else f', "dir": "{direction}"'
            self._write(
                f'{{"t": {when:.6f}, "ch": "{channel}"{d}, "hex": "{bytes(data).hex()}"}}\n'
            )
            self.count += 1
        return Chunk(when, channel, bytes(data), direction)

    def wrap(self, port, channel: str = "tablet", *, record_writes: bool = False) -> RecordingPort:
        """A port that records every chunk read from ``port`` (and written, if asked)."""
        return RecordingPort(port, self, channel, record_writes=record_writes)

    def close(self) -> None:
        """Close the file."""
        with self._lock:
            if not self._file.closed:
                self._file.close()

    @property
    def closed(self) -> bool:
        return self._file.closed

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class RecordingPort:
    """A serial port whose reads (and, if asked, writes) go to a :class:`Recorder`.

    ``read``, ``read_until``, ``readline``, ``write`` and ``in_waiting`` are
    those of the wrapped port; every other attribute is passed through.
    """

    def __init__(self, port, recorder: Recorder, channel: str = "tablet", *, record_writes=False):
        _check_channel(channel, "rx")
        self.port = port
        self.recorder = recorder
        self.channel = channel
        self.record_writes = record_writes

    def _got(self, data: bytes) -> bytes:
        if data:
            self.recorder.record(self.channel, data, "rx")
        return data

    def read(self, size: int = 1) -> bytes:
        return self._got(self.port.read(size))

    def read_until(self, *args, **kwargs) -> bytes:
        return self._got(self.port.read_until(*args, **kwargs))

    def readline(self, *args, **kwargs) -> bytes:
        return self._got(self.port.readline(*args, **kwargs))

    def write(self, data: bytes):
        n = self.port.write(data)
        if self.record_writes and data:
            self.recorder.record(self.channel, bytes(data), "tx")
        return n

    @property
    def in_waiting(self) -> int:
        return self.port.in_waiting

    def close(self) -> None:
        self.port.close()

    def __getattr__(self, name):
        return getattr(self.port, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _bad(path, lineno: int, message: str) -> FormatError:
    return FormatError(message, path, f"line {lineno}")


def _is_number(v: object) -> TypeGuard[int | float]:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _parse_chunk(path, lineno: int, obj, last_t: float) -> Chunk:
    if not isinstance(obj, dict):
        raise _bad(path, lineno, 'expected a JSON object {"t": ..., "ch": ..., "hex": ...}')
    t = obj.get("t")
    # compared before any float(): a 400-digit integer must not overflow
    if not _is_number(t) or not 0 <= t <= MAX_T:
        raise _bad(
            path,
            lineno,
            f"'t' must be a non-negative number of seconds (at most {MAX_T:g}), not {t!r:.40}",
        )
    t = float(t)
    if t < last_t:
        raise _bad(path, lineno, f"time {t} goes back (the line before has {last_t})")
    ch = obj.get("ch")
    if not isinstance(ch, str) or not _CHANNEL.match(ch):
        raise _bad(path, lineno, f"'ch' must be a channel name such as \"tablet\", not {ch!r:.40}")
    direction = obj.get("dir", "rx")
    if direction not in _DIRECTIONS:
        raise _bad(path, lineno, f'\'dir\' must be "rx" or "tx", not {direction!r:.40}')
    hx = obj.get("hex")
    if not isinstance(hx, str):
        raise _bad(path, lineno, f"'hex' must be a string of hex digits, not {hx!r:.40}")
    try:
        data = bytes.fromhex(hx)
    except ValueError:
        raise _bad(
            path, lineno, f"'hex' is not an even number of hex digits: {hx[:40]!r}"
        ) from None
    return Chunk(t, ch, data, direction)


def _check_header(path, obj) -> dict:
    """The header, every field it may carry checked for its type and range."""
    from apygis.instrument.tablet import PROTOCOLS

    if not isinstance(obj, dict) or obj.get("format") != FORMAT:
        raise _bad(path, 1, f'not an apygis recording: the header needs "format": "{FORMAT}"')
    version = obj.get("version")
    if not isinstance(version, int) or isinstance(version, bool) or version != VERSION:
        raise _bad(
            path, 1, f"recording version {version!r:.40} is not supported (expected {VERSION})"
        )
    created = obj.get("created", "")
    if not isinstance(created, str):
        raise _bad(path, 1, f"'created' must be a date-time string, not {created!r:.40}")
    if "protocol" in obj:
        proto = obj["protocol"]
        if not isinstance(proto, str) or proto.lower() not in PROTOCOLS:
            raise _bad(
                path,
                1,
                f"'protocol' must be a tablet protocol ({', '.join(PROTOCOLS)}), not {proto!r:.40}",
            )
    if "counts_per_mm" in obj:
        cpm = obj["counts_per_mm"]
        lo, hi = COUNTS_PER_MM
        if not _is_number(cpm) or not lo <= cpm <= hi:
            raise _bad(
                path,
                1,
                f"'counts_per_mm' must be a number from {lo:g} to {hi:g} "
                f"(40 for 1000 lpi), not {cpm!r:.40}",
            )
    return obj


def _loads(raw: bytes):
    try:
        return json.loads(raw.decode("utf-8"))
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None


class Replayer:
    """The chunks of a recording, in order, optionally at their recorded pace.

    Parameters
    ----------
    path : str or os.PathLike
        The recording.
    channels : iterable of str, optional
        Only these channels (default: all).
    directions : iterable of str
        Only these directions (default: both ``rx`` and ``tx``).
    realtime : bool
        Sleep so that each chunk comes at its recorded time (divided by
        ``speed``); False: as fast as possible.
    speed : float
        Playback speed with ``realtime`` (2.0: twice as fast).

    Iterating reads the file lazily and may raise
    :class:`~apygis.errors.FormatError` at the first bad line.
    """

    def __init__(
        self,
        path,
        *,
        channels: Iterable[str] | None = None,
        directions: Iterable[str] = _DIRECTIONS,
        realtime: bool = False,
        speed: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ):
        self.path = Path(path)
        self.channels = None if channels is None else frozenset(channels)
        self.directions = frozenset(directions)
        self.realtime = realtime
        if not _is_number(speed) or not 0 < speed <= 1e6:
            raise InstrumentError(f"speed must be positive, not {speed!r}")
        self.speed = float(speed)
        self._clock = clock
        self._sleep = sleep
        self.header: dict | None = None

    def _records(self) -> Iterator[Chunk]:
        path = self.path
        try:
            f = open(path, "rb")  # noqa: SIM115
        except OSError as exc:
            raise FormatError(f"cannot open the recording: {exc.strerror or exc}", path) from exc
        with f:
            last_t = 0.0
            lineno = 0
            for raw in f:
                lineno += 1
                complete = raw.endswith(b"\n")
                try:
                    obj = _loads(raw)
                except (UnicodeDecodeError, ValueError) as exc:
                    if not complete:
                        log.warning(
                            "%s: line %d: cut off (no newline, %d bytes); ignored -- "
                            "the recording was probably interrupted",
                            path,
                            lineno,
                            len(raw),
                        )
                        return
                    reason = (
                        "not UTF-8" if isinstance(exc, UnicodeDecodeError) else f"bad JSON ({exc})"
                    )
                    raise _bad(path, lineno, reason) from None
                if lineno == 1:
                    self.header = _check_header(path, obj)
                    continue
                chunk = _parse_chunk(path, lineno, obj, last_t)
                last_t = chunk.t
                yield chunk
            if lineno == 0:
                raise FormatError("empty file: not an apygis recording", path)

    def __iter__(self) -> Iterator[Chunk]:
        start = None
        for chunk in self._records():
            if self.channels is not None and chunk.channel not in self.channels:
                continue
            if chunk.direction not in self.directions:
                continue
            if self.realtime:
                if start is None:
                    start = self._clock() - chunk.t / self.speed
                delay = start + chunk.t / self.speed - self._clock()
                if delay > 0:
                    self._sleep(delay)
            yield chunk

    def chunks(self) -> list[Chunk]:
        """All the (selected) chunks, read and checked at once."""
        return list(self)

    def data(self, channel: str = "tablet", direction: str = "rx") -> bytes:
        """All the bytes of one channel and direction, joined."""
        return b"".join(
            c.data for c in self._records() if c.channel == channel and c.direction == direction
        )

    def port(self, channel: str = "tablet") -> ReplayPort:
        """A read-only serial-port stand-in that serves one channel's recorded bytes."""
        return ReplayPort(c.data for c in self if c.channel == channel and c.direction == "rx")


def read_recording(path) -> tuple[dict, list[Chunk]]:
    """The header and every chunk of a recording (checked)."""
    rep = Replayer(path)
    chunks = rep.chunks()
    return rep.header or {}, chunks


def check_recording(path) -> dict:
    """Check every line of a recording without keeping its chunks; return the header.

    For a caller that must know a recording is sound before it starts
    anything (``apygis session --replay``).
    """
    rep = Replayer(path)
    for _ in rep._records():
        pass
    if rep.header is None:  # only a cut-off first line
        raise FormatError("no complete header line: not an apygis recording", path)
    return rep.header


class ReplayPort:
    """Serves recorded chunks through ``read(size)`` like a pyserial port.

    ``read`` returns at most ``size`` bytes and never more than one chunk,
    so a reader sees the recorded chunk boundaries (when it asks for enough);
    at the end it returns ``b""``. Writes are accepted and dropped.
    """

    def __init__(self, chunks: Iterable[bytes]):
        self._it = iter(chunks)
        self._buf = b""
        self._end = False
        self.is_open = True
        self.timeout = 0.0
        self.port = "replay://"

    def _fill(self) -> None:
        while not self._buf and not self._end:
            try:
                self._buf = next(self._it)
            except StopIteration:
                self._end = True

    def read(self, size: int = 1) -> bytes:
        self._fill()
        out, self._buf = self._buf[:size], self._buf[size:]
        return out

    @property
    def in_waiting(self) -> int:
        self._fill()
        return len(self._buf)

    @property
    def exhausted(self) -> bool:
        """True once every recorded byte has been read."""
        self._fill()
        return self._end and not self._buf

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        self.is_open = False
        with contextlib.suppress(Exception):
            self._it.close()  # type: ignore[attr-defined]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
