"""A virtual instrument: a script of cursor moves, button presses and typing, as tablet bytes.

The simulator stands in for the operator's hand on the digitiser tablet.
It takes **tablet positions** (millimetres or counts on the tablet) -- never
ground coordinates: a caller that starts from the ground converts through
the inverse map orientation first -- and produces the bytes a tablet of a
chosen protocol (``mm``, ``calcomp``, ``ascii``; see
:mod:`apygis.instrument.tablet`) would send, with their times at a report
rate (100 reports a second by default). It can return them, or write them
to any port ``serial.serial_for_url`` opens (``loop://``, a pty,
``socket://``), at their pace or at once.

Keyboard input (texts of the text mode, typed on the keyboard) is a separate
channel, ``keyboard``, not tablet bytes.

The script format (``docs/protocols.md``, "Instrument scripts"): UTF-8
text, one command a line, keywords in any case, ``#`` starts a comment
(except in a ``type`` line), blank lines ignored::

    units mm              # mm (default) or counts: the unit of move / glide
    rate 100              # tablet reports per second from here on
    move 120.5 80.25      # one report at (120.5, 80.25), no button
    glide 130 80.25 0.5   # reports at the rate along the straight line, over 0.5 s
    button ENTER          # press and release: a report with the code, one with 0
    button 5              # the digit 5 (names in pad.BUTTONS)
    hold UP 0.3           # the button held for 0.3 s (reports at the rate), then released
    proximity out         # a report with the cursor lifted (``in`` to put it back)
    wait 0.2              # nothing for 0.2 s
    type Kirchweg         # keyboard channel: the rest of the line, verbatim
    type "two  spaces\\n"  # ... or a JSON string
    key ENTER             # keyboard channel: a named key (ENTER, ESC, BACKSPACE, TAB)

Examples
--------
>>> script = parse_script("move 100 50\\nbutton ENTER\\ntype Kirchweg\\n")
>>> vi = VirtualInstrument("calcomp")
>>> parser = vi.parser()
>>> reports = parser.feed(vi.tablet_bytes(script)) + parser.flush()
>>> [(r.x_counts, r.y_counts, BUTTONS.get(r.button, "-")) for r in reports]
[(4000, 2000, '-'), (4000, 2000, 'ENTER'), (4000, 2000, '-')]
>>> [(c.channel, c.data) for c in vi.chunks(script) if c.channel == "keyboard"]
[('keyboard', b'Kirchweg')]
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from apygis.errors import FormatError, InstrumentError, ProtocolError
from apygis.instrument.pad import BUTTON_CODES, BUTTONS, button_code
from apygis.instrument.ports import open_url
from apygis.instrument.replay import Chunk
from apygis.instrument.tablet import Parser, Report, TabletConfig, make_encoder, make_parser

__all__ = [
    "BUTTONS",
    "BUTTON_CODES",
    "KEYS",
    "MAX_DURATION_S",
    "MAX_REPORTS",
    "MAX_SCRIPT_BYTES",
    "MAX_TYPED",
    "KeyEvent",
    "Script",
    "ScriptBuilder",
    "TabletEvent",
    "VirtualInstrument",
    "button_code",
    "parse_script",
    "read_script",
]

log = logging.getLogger(__name__)

#: Most tablet reports one script may make, all commands together (a guard against
#: typos like ``hold UP 1e9`` or ``rate 100000``: each report costs memory and time).
MAX_REPORTS = 200_000
#: Longest a script may last, in seconds of script time (24 hours).
MAX_DURATION_S = 86_400.0
#: Most characters one script may type on the keyboard channel, all together.
MAX_TYPED = 1_000_000
#: Largest script file :func:`read_script` reads, in bytes.
MAX_SCRIPT_BYTES = 16 * 1024 * 1024

#: Named keyboard keys for the ``key`` command.
KEYS: dict[str, str] = {"ENTER": "\r", "ESC": "\x1b", "BACKSPACE": "\x08", "TAB": "\t"}


@dataclass(frozen=True, slots=True)
class TabletEvent:
    """One tablet report to send: time (s), position (counts), button code, proximity."""

    t: float
    x_counts: int
    y_counts: int
    button: int = 0
    proximity: bool = True
    line: int = 0

    def report(self) -> Report:
        """The :class:`~apygis.instrument.tablet.Report` a parser should return for it."""
        return Report(self.x_counts, self.y_counts, self.button, self.proximity)


@dataclass(frozen=True, slots=True)
class KeyEvent:
    """Text typed on the keyboard at time ``t`` (s)."""

    t: float
    text: str
    line: int = 0


@dataclass
class Script:
    """A parsed script: its events in time order.

    Attributes
    ----------
    events : list of TabletEvent and KeyEvent
        In order; times never decrease.
    path : str or None
        The file it came from.
    """

    events: list = field(default_factory=list)
    path: str | None = None

    @property
    def tablet_events(self) -> list[TabletEvent]:
        return [e for e in self.events if isinstance(e, TabletEvent)]

    @property
    def key_events(self) -> list[KeyEvent]:
        return [e for e in self.events if isinstance(e, KeyEvent)]

    def reports(self) -> list[Report]:
        """The reports a parser should return, in order."""
        return [e.report() for e in self.events if isinstance(e, TabletEvent)]

    @property
    def keyboard_text(self) -> str:
        """Everything typed, joined."""
        return "".join(e.text for e in self.events if isinstance(e, KeyEvent))

    @property
    def duration(self) -> float:
        return self.events[-1].t if self.events else 0.0


class ScriptBuilder:
    """Build a :class:`Script` in code (the script commands as methods).

    Parameters
    ----------
    config : TabletConfig, optional
        Converts millimetres to counts.
    rate : float
        Tablet reports per second.

    Examples
    --------
    >>> b = ScriptBuilder().move(10, 20).button("ENTER").type("A1")
    >>> [type(e).__name__ for e in b.build().events]
    ['TabletEvent', 'TabletEvent', 'TabletEvent', 'KeyEvent']
    """

    def __init__(self, config: TabletConfig | None = None, rate: float = 100.0):
        self.config = config or TabletConfig()
        self.events: list = []
        self.t = 0.0
        self.rate = 1.0
        self.set_rate(rate)
        self.pos: tuple[int, int] | None = None
        self.proximity_in = True
        self._line = 0
        self.typed = 0
        self._key_events = 0

    def set_rate(self, rate: float) -> ScriptBuilder:
        """Tablet reports per second from here on."""
        rate = float(rate)
        if not (math.isfinite(rate) and 0 < rate <= 100000):
            raise ProtocolError(f"rate must be 0 < rate <= 100000 reports/s, not {rate!r}")
        self.rate = rate
        return self

    @property
    def reports(self) -> int:
        """Tablet reports made so far."""
        return len(self.events) - self._key_events

    def _budget(self, n: int, what: str) -> None:
        """Refuse ``n`` more reports beyond :data:`MAX_REPORTS`, or a time beyond the cap."""
        if self.reports + n > MAX_REPORTS:
            raise ProtocolError(
                f"{what}: the script would make more than {MAX_REPORTS} tablet reports in all "
                f"({self.reports} so far, {n} more)"
            )
        self._check_time(self.t + n / self.rate, what)

    def _check_time(self, t: float, what: str) -> None:
        if not t <= MAX_DURATION_S:
            raise ProtocolError(
                f"{what}: the script would last more than {MAX_DURATION_S:g} s (up to {t:g} s)"
            )

    def _report(self, button: int = 0) -> None:
        x, y = self._where("a report")
        if self.reports >= MAX_REPORTS or self.t > MAX_DURATION_S:
            self._budget(1, "a report")
        self.events.append(TabletEvent(self.t, x, y, button, self.proximity_in, self._line))
        self.t += 1.0 / self.rate

    def _where(self, what: str) -> tuple[int, int]:
        if self.pos is None:
            raise ProtocolError(f"{what} before the cursor position is known: move first")
        return self.pos

    def move_counts(self, x_counts: int, y_counts: int) -> ScriptBuilder:
        """One report at (x, y) tablet counts, no button."""
        self.pos = (int(x_counts), int(y_counts))
        self._report()
        return self

    def move(self, x_mm: float, y_mm: float) -> ScriptBuilder:
        """One report at (x, y) tablet millimetres, no button."""
        cfg = self.config
        return self.move_counts(cfg.mm_to_counts(float(x_mm)), cfg.mm_to_counts(float(y_mm)))

    def _count(self, seconds: float, what: str) -> int:
        n = float(seconds) * self.rate
        if not (math.isfinite(n) and 0 <= n <= MAX_REPORTS):
            raise ProtocolError(
                f"{what} of {seconds!r} s at {self.rate:g} reports/s: more than "
                f"{MAX_REPORTS} reports, or a negative time"
            )
        n = max(1, round(n))
        self._budget(n, what)
        return n

    def glide_counts(self, x_counts: int, y_counts: int, seconds: float) -> ScriptBuilder:
        """Reports at the rate along a straight line to (x, y) counts, over ``seconds``."""
        x0, y0 = self._where("glide")
        n = self._count(seconds, "glide")
        for i in range(1, n + 1):
            f = i / n
            self.pos = (round(x0 + (x_counts - x0) * f), round(y0 + (y_counts - y0) * f))
            self._report()
        return self

    def glide(self, x_mm: float, y_mm: float, seconds: float) -> ScriptBuilder:
        """Reports at the rate along a straight line to (x, y) mm, over ``seconds``."""
        cfg = self.config
        return self.glide_counts(
            cfg.mm_to_counts(float(x_mm)), cfg.mm_to_counts(float(y_mm)), seconds
        )

    def button(self, name) -> ScriptBuilder:
        """Press and release a button: a report with its code, then one with 0."""
        code = button_code(name)
        self._report(code)
        self._report(0)
        return self

    def hold(self, name, seconds: float) -> ScriptBuilder:
        """Hold a button for ``seconds`` (reports with its code at the rate), then release."""
        code = button_code(name)
        for _ in range(self._count(seconds, "hold")):
            self._report(code)
        self._report(0)
        return self

    def proximity(self, inside: bool) -> ScriptBuilder:
        """Lift the cursor off the tablet (False) or put it back (True): one report."""
        self.proximity_in = bool(inside)
        self._report()
        return self

    def wait(self, seconds: float) -> ScriptBuilder:
        """Nothing for ``seconds``."""
        s = float(seconds)
        if not (math.isfinite(s) and s >= 0):
            raise ProtocolError(f"wait needs a non-negative number of seconds, not {seconds!r}")
        self._check_time(self.t + s, "wait")
        self.t += s
        return self

    def type(self, text: str) -> ScriptBuilder:
        """Text typed on the keyboard (the keyboard channel)."""
        if text:
            text = str(text)
            if self.typed + len(text) > MAX_TYPED:
                raise ProtocolError(
                    f"type: the script would type more than {MAX_TYPED} characters in all"
                )
            self.typed += len(text)
            self._key_events += 1
            self.events.append(KeyEvent(self.t, text, self._line))
        return self

    def key(self, name: str) -> ScriptBuilder:
        """A named key (``ENTER``, ``ESC``, ``BACKSPACE``, ``TAB``) on the keyboard channel."""
        try:
            return self.type(KEYS[name.strip().upper()])
        except KeyError:
            raise ProtocolError(
                f"unknown key {name!r}; expected one of {', '.join(KEYS)}"
            ) from None

    def build(self, path=None) -> Script:
        """The script so far."""
        return Script(list(self.events), None if path is None else str(path))


def _numbers(args: list[str], n: int, what: str) -> list[float]:
    if len(args) != n:
        raise ValueError(f"{what} needs {n} number{'s' if n > 1 else ''}, got {len(args)}")
    out = []
    for a in args:
        try:
            v = float(a)
        except ValueError:
            raise ValueError(f"{what}: {a!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"{what}: {a!r} is not a finite number")
        out.append(v)
    return out


def parse_script(
    text: str, *, path=None, config: TabletConfig | None = None, rate: float = 100.0
) -> Script:
    """Parse a script (see the module docstring).

    Raises
    ------
    FormatError
        For a bad line, naming the file (``path``) and the line.
    """
    b = ScriptBuilder(config, rate)
    units = "mm"
    for lineno, raw in enumerate(text.splitlines(), 1):
        b._line = lineno
        stripped = raw.strip()
        if not stripped or stripped.startswith("#"):
            continue
        keyword, _, rest = stripped.partition(" ")
        keyword = keyword.lower()
        try:
            if keyword == "type":
                body = raw.lstrip()[4:]
                body = body[1:] if body.startswith(" ") else body
                if body.lstrip().startswith('"'):
                    try:
                        value = json.loads(body.strip())
                    except ValueError as exc:
                        raise ValueError(f"type: bad JSON string ({exc})") from None
                    if not isinstance(value, str):
                        raise ValueError("type: a JSON value must be a string")
                    body = value
                if not body:
                    raise ValueError("type needs a text")
                b.type(body)
                continue
            args = rest.split("#", 1)[0].split()
            if keyword == "units":
                if len(args) != 1 or args[0].lower() not in ("mm", "counts"):
                    raise ValueError("units must be 'mm' or 'counts'")
                units = args[0].lower()
            elif keyword == "rate":
                (r,) = _numbers(args, 1, "rate")
                b.set_rate(r)
            elif keyword == "move":
                x, y = _numbers(args, 2, "move")
                if units == "mm":
                    b.move(x, y)
                else:
                    b.move_counts(_counts(x), _counts(y))
            elif keyword == "glide":
                x, y, s = _numbers(args, 3, "glide")
                if s < 0:
                    raise ValueError("glide: the duration must not be negative")
                if units == "mm":
                    b.glide(x, y, s)
                else:
                    b.glide_counts(_counts(x), _counts(y), s)
            elif keyword == "button":
                if len(args) != 1:
                    raise ValueError("button needs one button name, e.g. 'button ENTER'")
                b.button(args[0])
            elif keyword == "hold":
                if len(args) != 2:
                    raise ValueError("hold needs a button name and seconds, e.g. 'hold UP 0.5'")
                (s,) = _numbers(args[1:], 1, "hold")
                if s < 0:
                    raise ValueError("hold: the duration must not be negative")
                b.hold(args[0], s)
            elif keyword == "proximity":
                if len(args) != 1 or args[0].lower() not in ("in", "out"):
                    raise ValueError("proximity must be 'in' or 'out'")
                b.proximity(args[0].lower() == "in")
            elif keyword == "wait":
                (s,) = _numbers(args, 1, "wait")
                b.wait(s)
            elif keyword == "key":
                if len(args) != 1:
                    raise ValueError("key needs one key name")
                b.key(args[0])
            else:
                raise ValueError(
                    f"unknown command {keyword!r}; expected units, rate, move, glide, button, "
                    "hold, proximity, wait, type or key"
                )
        except ValueError as exc:  # ProtocolError is a ValueError too
            raise FormatError(str(exc), path, f"line {lineno}") from None
    return b.build(path)


def _counts(v: float) -> int:
    if v != int(v):
        raise ValueError(f"{v!r} is not a whole number of counts")
    return int(v)


def read_script(path, *, config: TabletConfig | None = None, rate: float = 100.0) -> Script:
    """Read and parse a script file (UTF-8)."""
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > MAX_SCRIPT_BYTES:
            raise FormatError(f"{size} bytes: a script may have at most {MAX_SCRIPT_BYTES}", p)
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(f"not UTF-8 text ({exc.reason} at byte {exc.start})", p) from None
    except OSError as exc:
        raise FormatError(f"cannot read the script: {exc.strerror or exc}", p) from exc
    return parse_script(text, path=p, config=config, rate=rate)


class VirtualInstrument:
    """Turns scripts into the bytes of a tablet protocol, and plays them on a port.

    Parameters
    ----------
    protocol : str
        ``mm``, ``calcomp`` or ``ascii``.
    config : TabletConfig, optional
        Resolution (for scripts in mm) and plausibility limits (for
        :meth:`parser`).
    rate : float
        Tablet reports per second for scripts parsed by this instrument.
    **options
        Format options: ``width``, ``flag_width``, ``signed`` for ``ascii``.
    """

    def __init__(
        self,
        protocol: str = "calcomp",
        *,
        config: TabletConfig | None = None,
        rate: float = 100.0,
        **options,
    ):
        protocol = str(protocol).lower()
        self._encode = make_encoder(protocol, **options)
        self.protocol = protocol
        self.config = config or TabletConfig()
        self.rate = rate
        self.options = options

    def parser(self, **kwargs) -> Parser:
        """A parser for this instrument's bytes (same protocol, options and config)."""
        opts = dict(self.options)
        opts.update(kwargs)
        return make_parser(self.protocol, self.config, **opts)

    def parse(self, text: str, path=None) -> Script:
        """Parse a script with this instrument's config and rate."""
        return parse_script(text, path=path, config=self.config, rate=self.rate)

    def read(self, path) -> Script:
        """Read a script file with this instrument's config and rate."""
        return read_script(path, config=self.config, rate=self.rate)

    def encode(self, event: TabletEvent, script: Script | None = None) -> bytes:
        """The bytes of one tablet report."""
        try:
            return self._encode(event.x_counts, event.y_counts, event.button, event.proximity)
        except ProtocolError as exc:
            where = ": ".join(
                p for p in ((script.path if script else None), f"line {event.line}") if p
            )
            raise ProtocolError(f"{where}: {exc}") from None

    def chunks(self, script: Script) -> list[Chunk]:
        """The script as timed chunks: one ``tablet`` chunk a report, ``keyboard`` chunks."""
        out = []
        for ev in script.events:
            if isinstance(ev, TabletEvent):
                out.append(Chunk(ev.t, "tablet", self.encode(ev, script)))
            else:
                out.append(Chunk(ev.t, "keyboard", ev.text.encode("utf-8")))
        return out

    def tablet_bytes(self, script: Script) -> bytes:
        """All the tablet bytes of a script, joined."""
        return b"".join(self.encode(ev, script) for ev in script.tablet_events)

    def play(
        self,
        script: Script,
        port,
        *,
        keyboard=None,
        realtime: bool = False,
        speed: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> int:
        """Write a script's tablet bytes to ``port``; return the number of bytes written.

        Parameters
        ----------
        port
            Anything with ``write(bytes)``: a port from ``serial.serial_for_url``.
        keyboard
            Where the keyboard channel goes: a port (``write``), a callable
            taking the text, or None (dropped, logged at debug level).
        realtime : bool
            Write each report at its time (divided by ``speed``); False: at once.
        """
        if not speed > 0:
            raise InstrumentError(f"speed must be positive, not {speed!r}")
        written = 0
        start = clock()
        for chunk in self.chunks(script):
            if realtime:
                delay = start + chunk.t / speed - clock()
                if delay > 0:
                    sleep(delay)
            if chunk.channel == "tablet":
                try:
                    n = port.write(chunk.data)
                except Exception as exc:
                    raise InstrumentError(f"cannot write the tablet bytes: {exc}") from exc
                written += len(chunk.data) if n is None else n
            elif keyboard is None:
                log.debug("keyboard text dropped (no keyboard sink): %r", chunk.data)
            elif callable(keyboard) and not hasattr(keyboard, "write"):
                keyboard(chunk.data.decode("utf-8"))
            else:
                keyboard.write(chunk.data)
        flush = getattr(port, "flush", None)
        if flush is not None:
            flush()
        return written

    def play_url(self, script: Script, url: str, *, baudrate: int = 9600, **kwargs) -> int:
        """Open ``url`` with ``serial.serial_for_url``, :meth:`play` the script, close it."""
        port = open_url(
            url,
            lambda exc: InstrumentError(f"{url}: cannot open the tablet port: {exc}"),
            baudrate=baudrate,
            timeout=1.0,
        )
        try:
            return self.play(script, port, **kwargs)
        finally:
            port.close()
