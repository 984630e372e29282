"""Digitiser tablet protocols: incremental parsers and their encoders.

The APY operator moves the floating mark over the map on a digitiser tablet
and presses the buttons of a 27-button cursor. The tablet reports position
and button state over a serial line in one of three families of formats,
each specified bit by bit in ``docs/protocols.md``:

``mm``
    Summagraphics MM series binary, 5 bytes a report. Byte 0 is
    ``1 P T Sx Sy B2 B1 B0`` (phasing bit, proximity -- *set* when the cursor
    is *out* of proximity --, tablet ID, X sign, Y sign -- *set* for a
    positive value --, button code 0-7); bytes 1-4 have bit 7 clear and carry
    ``X6..X0``, ``X13..X7``, ``Y6..Y0``, ``Y13..Y7`` (low group first).
    Coordinates are sign and magnitude, -16383..16383 counts. Three button
    bits carry codes 0-7 only: the 27-button pad needs ``calcomp`` or
    ``ascii``.
``calcomp``
    CalComp binary (Drawing Board), 6 bytes a report. Byte 0 is
    ``1 B4 B3 B2 B1 B0 X15 X14`` (phasing bit, 5-bit button code 0-31);
    bytes 1, 2 carry ``X13..X7``, ``X6..X0`` (high group first); byte 3 is
    ``0 P 0 0 0 0 Y15 Y14`` (proximity, *set* when out of proximity; bits 5-2
    reserved, zero); bytes 4, 5 carry ``Y13..Y7``, ``Y6..Y0``. Coordinates
    are unsigned 0..65535 counts.
``ascii``
    The GTCO / Summagraphics ASCII family: ``XXXXX,YYYYY,FF<CR><LF>``, an
    optional fourth field ``,P`` (``1`` in proximity, ``0`` out; absent means
    in proximity). Fixed width (the default, 5 characters a coordinate,
    2 for the button code) or variable width; signed or unsigned; spaces
    around (variable width) or inside (fixed width, as padding) the fields
    are tolerated.

Every parser is incremental: :meth:`Parser.feed` takes any chunk of bytes
(one byte, half a packet, a thousand packets) and returns the reports that
the chunk completed. Framing is recovered after garbage, a dropped byte, a
duplicated byte or a reconnect without inventing a point:

- a binary packet is the run of bytes from one phasing byte (bit 7 set) to
  the next. A run shorter or longer than the packet length (a dropped or an
  extra byte) is dropped whole, never decoded shifted;
- with ``confirm=True`` (the default) a packet of the right length is
  decoded only once the next phasing byte arrives, or when the caller calls
  :meth:`Parser.flush` because the line went quiet (the read timed out).
  That is what catches a duplicated or inserted data byte; it costs the
  latency of one packet (the next report) or of the idle timeout.
  ``confirm=False`` decodes as soon as the packet is long enough: the
  lowest latency, but a packet with an extra data byte inside is then
  decoded shifted;
- an ASCII report is a line; a line that does not match the format (with
  fixed width: a field of the wrong width) is dropped whole;
- plausibility checks: the coordinate ranges and the highest button code of
  :class:`TabletConfig`, and the reserved bits of the CalComp packet.

The counters ``packets`` (reports returned), ``discarded_bytes``,
``resyncs`` (episodes of lost framing: each run of discarded bytes between
two good reports counts once) and ``rejected`` (well-framed packets that
failed the plausibility checks) tell how clean the line is.

Examples
--------
>>> from apygis.instrument.tablet import CalCompBinaryParser, encode_calcomp
>>> p = CalCompBinaryParser()
>>> data = encode_calcomp(4000, 3000, button=11) + encode_calcomp(4001, 3000)
>>> [(r.x_counts, r.y_counts, r.button) for r in p.feed(b"\\x01junk" + data)]
[(4000, 3000, 11)]
>>> [(r.x_counts, r.y_counts, r.button) for r in p.flush()]
[(4001, 3000, 0)]
>>> p.packets, p.discarded_bytes, p.resyncs
(2, 5, 1)
"""

from __future__ import annotations

import abc
import functools
import logging
import math
import re
from dataclasses import dataclass, field
from typing import ClassVar, cast

from apygis.errors import ProtocolError

__all__ = [
    "PROTOCOLS",
    "AsciiParser",
    "CalCompBinaryParser",
    "MMBinaryParser",
    "Parser",
    "Report",
    "TabletConfig",
    "encode_ascii",
    "encode_calcomp",
    "encode_mm",
    "make_encoder",
    "make_parser",
    "read_reports",
]

log = logging.getLogger(__name__)

PHASING = 0x80
#: Bytes without the phasing bit, at the start of a buffer (stray bytes).
_HEADLESS = re.compile(rb"[\x00-\x7f]*")
#: A run: one phasing byte and the bytes without phasing bit that follow it.
_RUN = re.compile(rb"[\x80-\xff][\x00-\x7f]*")

MM_MAX = (1 << 14) - 1
CALCOMP_MAX = (1 << 16) - 1


@dataclass(frozen=True, slots=True)
class Report:
    """One tablet report.

    Attributes
    ----------
    x_counts, y_counts : int
        Position in tablet counts (see :meth:`TabletConfig.counts_to_mm`).
    button : int or None
        Button code: 0 no button, 1-27 a button of the 27-button cursor
        (names in :data:`apygis.instrument.pad.BUTTONS`); None where a
        format carries no button state.
    proximity : bool
        True while the cursor is on the tablet (in proximity).
    raw : bytes
        The bytes the report was decoded from (not compared by ``==``).
    """

    x_counts: int
    y_counts: int
    button: int | None = 0
    proximity: bool = True
    raw: bytes = field(default=b"", compare=False)


@dataclass(frozen=True)
class TabletConfig:
    """Tablet resolution and plausibility limits.

    Parameters
    ----------
    counts_per_mm : float
        Resolution: 40 counts/mm is 0.025 mm a count; 1000 lpi is
        1000 / 25.4 = 39.37 counts/mm (use :meth:`from_lpi`).
    x_range, y_range : (int, int) or None
        Inclusive range of plausible counts (the active area); a report
        outside it is rejected. None: no check.
    max_button : int
        Highest plausible button code (27 for the APY cursor).

    Examples
    --------
    >>> cfg = TabletConfig(counts_per_mm=40)
    >>> cfg.counts_to_mm(4001)
    100.025
    >>> cfg.mm_to_counts(100.025)
    4001
    >>> round(TabletConfig.from_lpi(1000).resolution_mm, 4)
    0.0254
    """

    counts_per_mm: float = 40.0
    x_range: tuple[int, int] | None = None
    y_range: tuple[int, int] | None = None
    max_button: int = 27

    def __post_init__(self):
        cpm = self.counts_per_mm
        # compared before anything converts it: a 400-digit integer must not reach float()
        if not (isinstance(cpm, int | float) and not isinstance(cpm, bool) and 0 < cpm <= 1e9):
            raise ProtocolError(f"counts_per_mm must be a positive number, not {cpm!r:.40}")
        for name in ("x_range", "y_range"):
            rng = getattr(self, name)
            if rng is not None:
                if not (
                    isinstance(rng, tuple | list)
                    and len(rng) == 2
                    and all(_is_count(v) for v in rng)
                ):
                    raise ProtocolError(f"{name} must be (low, high) in counts, not {rng!r:.60}")
                lo, hi = rng
                if lo > hi:
                    raise ProtocolError(f"{name} {rng!r}: the low end is above the high end")
                object.__setattr__(self, name, (int(lo), int(hi)))
        mb = self.max_button
        if not (_is_count(mb) and 0 <= mb <= 31):
            raise ProtocolError(f"max_button must be 0-31, not {mb!r:.40}")

    @classmethod
    def from_lpi(cls, lpi: float, **kwargs) -> TabletConfig:
        """The configuration of a tablet set to ``lpi`` lines (counts) per inch."""
        return cls(counts_per_mm=lpi / 25.4, **kwargs)

    @property
    def resolution_mm(self) -> float:
        """Size of one count in millimetres."""
        return 1.0 / self.counts_per_mm

    def counts_to_mm(self, counts):
        """Tablet counts to millimetres (a number or a numpy array)."""
        return counts / self.counts_per_mm

    def mm_to_counts(self, mm):
        """Millimetres to the nearest tablet count (int, or an int64 array)."""
        value = mm * self.counts_per_mm
        if hasattr(value, "shape"):
            import numpy as np

            return np.rint(value).astype(np.int64)
        return round(value)

    def report_mm(self, report: Report) -> tuple[float, float]:
        """A report's position in tablet millimetres."""
        return report.x_counts / self.counts_per_mm, report.y_counts / self.counts_per_mm


def _is_count(v) -> bool:
    """A finite real number that fits the counts of any tablet (numpy numbers too)."""
    import numbers

    return (
        isinstance(v, numbers.Real)
        and not isinstance(v, bool)
        and math.isfinite(v)
        and abs(cast(float, v)) <= 1 << 62  # a Real, not rounded by float()
    )


_DEFAULT_CONFIG = TabletConfig()
_BIG = 1 << 62


def _check_int(name: str, value, lo: int, hi: int, fmt: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ProtocolError(f"{fmt}: {name} must be an integer, not {value!r}")
    if not lo <= value <= hi:
        raise ProtocolError(f"{fmt}: {name} {value} is outside {lo}..{hi}")
    return value


# --------------------------------------------------------------------------- encoders


def encode_mm(
    x_counts: int, y_counts: int, button: int | None = 0, proximity: bool = True, *, tablet_id=0
) -> bytes:
    """Encode one Summagraphics MM binary report (5 bytes).

    Examples
    --------
    >>> encode_mm(200, 3, button=2).hex(" ")
    '9a 48 01 03 00'
    >>> encode_mm(-1, 0, proximity=False).hex(" ")
    'c8 01 00 00 00'
    """
    _check_int("x_counts", x_counts, -MM_MAX, MM_MAX, "MM binary")
    _check_int("y_counts", y_counts, -MM_MAX, MM_MAX, "MM binary")
    button = _check_int("button", button or 0, 0, 7, "MM binary (3 button bits)")
    _check_int("tablet_id", tablet_id, 0, 1, "MM binary")
    b0 = PHASING | button | (tablet_id << 5)
    if not proximity:
        b0 |= 0x40
    if x_counts >= 0:
        b0 |= 0x10
    if y_counts >= 0:
        b0 |= 0x08
    ax, ay = abs(x_counts), abs(y_counts)
    return bytes((b0, ax & 0x7F, ax >> 7, ay & 0x7F, ay >> 7))


def encode_calcomp(
    x_counts: int, y_counts: int, button: int | None = 0, proximity: bool = True
) -> bytes:
    """Encode one CalComp binary report (6 bytes).

    Examples
    --------
    >>> encode_calcomp(20000, 300, button=27).hex(" ")
    'ed 1c 20 00 02 2c'
    """
    _check_int("x_counts", x_counts, 0, CALCOMP_MAX, "CalComp binary")
    _check_int("y_counts", y_counts, 0, CALCOMP_MAX, "CalComp binary")
    button = _check_int("button", button or 0, 0, 31, "CalComp binary")
    b3 = (y_counts >> 14) | (0 if proximity else 0x40)
    return bytes(
        (
            PHASING | (button << 2) | (x_counts >> 14),
            (x_counts >> 7) & 0x7F,
            x_counts & 0x7F,
            b3,
            (y_counts >> 7) & 0x7F,
            y_counts & 0x7F,
        )
    )


def encode_ascii(
    x_counts: int,
    y_counts: int,
    button: int | None = 0,
    proximity: bool = True,
    *,
    width: int | None = 5,
    flag_width: int = 2,
    signed: bool = False,
) -> bytes:
    """Encode one ASCII report line, ``<CR><LF>`` included.

    Parameters
    ----------
    width : int or None
        Characters of a coordinate field (sign included), zero padded; None
        for variable width.
    flag_width : int
        Digits of the button code field with fixed width.
    signed : bool
        Write a sign (``+`` or ``-``) before every coordinate; without it a
        negative coordinate cannot be written.

    Examples
    --------
    >>> encode_ascii(1234, 56, button=11)
    b'01234,00056,11\\r\\n'
    >>> encode_ascii(-12, 5, width=None, signed=True, proximity=False)
    b'-12,+5,0,0\\r\\n'
    """
    fmt = "ASCII"
    if width is not None:
        if signed:
            hi = 10 ** (width - 1) - 1
            lo = -hi
        else:
            lo, hi = 0, 10**width - 1
        fb = _check_int("button", button or 0, 0, 10**flag_width - 1, fmt)
        flag = f"{fb:0{flag_width}d}"
    else:
        lo, hi = (-(10**9) + 1 if signed else 0), 10**9 - 1
        flag = str(_check_int("button", button or 0, 0, 99, fmt))
    _check_int("x_counts", x_counts, lo, hi, fmt)
    _check_int("y_counts", y_counts, lo, hi, fmt)
    spec = ("+" if signed else "") + (f"0{width}d" if width is not None else "d")
    line = f"{x_counts:{spec}},{y_counts:{spec}},{flag}"
    if not proximity:
        line += ",0"
    return (line + "\r\n").encode("ascii")


# --------------------------------------------------------------------------- parsers


class Parser(abc.ABC):
    """Incremental tablet parser: bytes in, :class:`Report` objects out.

    Parameters
    ----------
    config : TabletConfig, optional
        Plausibility limits (coordinate ranges, highest button code).

    Attributes
    ----------
    packets : int
        Reports returned so far.
    discarded_bytes : int
        Bytes thrown away: stray bytes, short or long packets, rejected
        packets, bad lines.
    resyncs : int
        Times framing was lost and had to be found again (one count for each
        run of discarded bytes between two good reports).
    rejected : int
        Well-framed packets that failed a plausibility check.
    """

    name: ClassVar[str] = ""

    def __init__(self, config: TabletConfig | None = None):
        self.config = config or _DEFAULT_CONFIG
        cfg = self.config
        self._xlo, self._xhi = cfg.x_range or (-_BIG, _BIG)
        self._ylo, self._yhi = cfg.y_range or (-_BIG, _BIG)
        self._maxb = cfg.max_button
        self.packets = 0
        self.discarded_bytes = 0
        self.resyncs = 0
        self.rejected = 0
        self._garbage = False
        self._pending = b""  # a report not yet complete: an open binary run, a line without LF

    @abc.abstractmethod
    def feed(self, data: bytes) -> list[Report]:
        """Take a chunk of bytes; return the reports it completed, in order."""

    @abc.abstractmethod
    def flush(self) -> list[Report]:
        """The line went quiet: decode a complete pending packet, drop a partial one."""

    def reset(self) -> None:
        """Forget any partial packet (after a reconnect); keep the counters."""
        self._garbage = False
        self._pending = b""

    @abc.abstractmethod
    def encode(self, report: Report) -> bytes:
        """The bytes this format sends for ``report``."""

    @property
    def stats(self) -> dict[str, int]:
        """The counters as a dict."""
        return {
            "packets": self.packets,
            "discarded_bytes": self.discarded_bytes,
            "resyncs": self.resyncs,
            "rejected": self.rejected,
        }

    def _discard(self, n: int) -> None:
        self.discarded_bytes += n
        if not self._garbage:
            self.resyncs += 1
            self._garbage = True

    def _plausible(self, x: int, y: int, button: int, proximity: bool, raw: bytes):
        """The report, if its position and button pass the configured limits; else None.

        A report that fails is counted as rejected (the caller discards its bytes).
        """
        if not (self._xlo <= x <= self._xhi and self._ylo <= y <= self._yhi):
            self._reject(raw, f"position {x}, {y} outside the active area")
            return None
        if button > self._maxb:
            self._reject(raw, f"button {button} above {self._maxb}")
            return None
        self._garbage = False
        return Report(x, y, button, proximity, raw)

    def _reject(self, raw: bytes, why: str) -> None:
        self.rejected += 1
        if log.isEnabledFor(logging.DEBUG):
            log.debug("%s: rejected report %s: %s", self.name, raw.hex(" "), why)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.stats}>"


class _BinaryParser(Parser):
    """Framing shared by the phasing-bit binary formats."""

    packet_len: ClassVar[int] = 0

    def __init__(self, config: TabletConfig | None = None, *, confirm: bool = True):
        super().__init__(config)
        self.confirm = bool(confirm)

    def feed(self, data: bytes) -> list[Report]:
        if self._pending:
            buf = self._pending + data
            start = 0
        else:
            buf = bytes(data)
            start = cast("re.Match[bytes]", _HEADLESS.match(buf)).end()  # matches b"" at least
            if start:
                self._discard(start)
        self._pending = b""
        runs = _RUN.findall(buf, start)
        if not runs:
            return []
        out = []
        n = self.packet_len
        decode = self._decode
        last = runs.pop()
        for run in runs:
            if len(run) == n:
                rep = decode(run)
                if rep is not None:
                    out.append(rep)
                    continue
            self._discard(len(run))
        k = len(last)
        if k < n or (k == n and self.confirm):
            self._pending = last
        else:
            rep = decode(last) if k == n else None
            if rep is not None:
                out.append(rep)
            else:
                self._discard(k)
        self.packets += len(out)
        return out

    def flush(self) -> list[Report]:
        run, self._pending = self._pending, b""
        if not run:
            return []
        if len(run) == self.packet_len:
            rep = self._decode(run)
            if rep is not None:
                self.packets += 1
                return [rep]
        self._discard(len(run))
        return []

    @abc.abstractmethod
    def _decode(self, run: bytes) -> Report | None:
        """The report a complete packet holds, or None (counted as rejected)."""


class MMBinaryParser(_BinaryParser):
    """Summagraphics MM series binary format, 5-byte packets.

    ========  ===========================================================
    byte      bits 7..0
    ========  ===========================================================
    0         ``1 P T Sx Sy B2 B1 B0``: phasing bit (1), proximity
              (``P`` = 1: out of proximity), tablet ID (ignored),
              X sign and Y sign (1: positive or zero), button code 0-7
    1         ``0 X6 X5 X4 X3 X2 X1 X0``
    2         ``0 X13 .. X7``
    3         ``0 Y6 .. Y0``
    4         ``0 Y13 .. Y7``
    ========  ===========================================================

    X = +/- (X13..X0), Y likewise: -16383..16383 counts.

    Parameters
    ----------
    config : TabletConfig, optional
        Plausibility limits.
    confirm : bool
        Decode a packet only when the next phasing byte (or :meth:`flush`)
        confirms its length (see the module docstring).

    Examples
    --------
    >>> p = MMBinaryParser(confirm=False)
    >>> p.feed(encode_mm(-200, 16383, button=7))
    [Report(x_counts=-200, y_counts=16383, button=7, proximity=True, raw=b'\\x8fH\\x01\\x7f\\x7f')]
    """

    name = "mm"
    packet_len = 5

    def _decode(self, run: bytes) -> Report | None:
        b0 = run[0]
        x = run[1] | (run[2] << 7)
        if not b0 & 0x10:
            x = -x
        y = run[3] | (run[4] << 7)
        if not b0 & 0x08:
            y = -y
        return self._plausible(x, y, b0 & 0x07, not b0 & 0x40, run)

    def encode(self, report: Report) -> bytes:
        return encode_mm(report.x_counts, report.y_counts, report.button, report.proximity)


class CalCompBinaryParser(_BinaryParser):
    """CalComp binary format (Drawing Board), 6-byte packets.

    ========  ===========================================================
    byte      bits 7..0
    ========  ===========================================================
    0         ``1 B4 B3 B2 B1 B0 X15 X14``: phasing bit (1), button code
              0-31 (0 none, 1-27 the APY cursor), X bits 15-14
    1         ``0 X13 .. X7``
    2         ``0 X6 .. X0``
    3         ``0 P 0 0 0 0 Y15 Y14``: proximity (``P`` = 1: out of
              proximity), reserved bits (must be 0), Y bits 15-14
    4         ``0 Y13 .. Y7``
    5         ``0 Y6 .. Y0``
    ========  ===========================================================

    X and Y are unsigned, 0..65535 counts.

    Parameters
    ----------
    config : TabletConfig, optional
        Plausibility limits.
    confirm : bool
        Decode a packet only when the next phasing byte (or :meth:`flush`)
        confirms its length (see the module docstring).
    """

    name = "calcomp"
    packet_len = 6

    def _decode(self, run: bytes) -> Report | None:
        b0 = run[0]
        b3 = run[3]
        if b3 & 0x3C:
            self._reject(run, "reserved bits of byte 3 set")
            return None
        x = ((b0 & 0x03) << 14) | (run[1] << 7) | run[2]
        y = ((b3 & 0x03) << 14) | (run[4] << 7) | run[5]
        return self._plausible(x, y, (b0 >> 2) & 0x1F, not b3 & 0x40, run)

    def encode(self, report: Report) -> bytes:
        return encode_calcomp(report.x_counts, report.y_counts, report.button, report.proximity)


_NUM = re.compile(rb" *([+-]?[0-9]{1,9}) *")
_FLAG = re.compile(rb" *([0-9]{1,2}) *")
_PROX = re.compile(rb" *([01]) *")


class AsciiParser(Parser):
    """ASCII reports ``XXXXX,YYYYY,FF[,P]<CR><LF>`` (GTCO / Summagraphics family).

    A report is one line ended by LF; CRs before the LF are ignored. Fields:
    X and Y counts (decimal, optional sign), the button code (decimal 0-99,
    checked against ``config.max_button``) and an optional proximity field
    (``1`` in proximity, ``0`` out; absent: in proximity).

    Parameters
    ----------
    config : TabletConfig, optional
        Plausibility limits.
    width : int or None
        Fixed width: each coordinate field is exactly ``width`` characters
        (sign and padding spaces or zeros included), the button field
        ``flag_width``, the proximity field one; anything else is dropped,
        which catches a dropped or a duplicated character. None: variable
        width, spaces around fields tolerated (a dropped digit then goes
        unnoticed).
    flag_width : int
        Width of the button code field with fixed width.
    signed : bool
        Whether coordinates may be negative (a ``-`` sign is then allowed;
        ``+`` is always allowed). The encoder writes a sign when True.
    max_line : int
        Longest line accepted; a longer run without LF is dropped up to the
        next LF.

    Examples
    --------
    >>> p = AsciiParser()
    >>> [(r.x_counts, r.y_counts, r.button) for r in p.feed(b"01234,00056,11\\r\\n0123")]
    [(1234, 56, 11)]
    >>> [(r.x_counts, r.y_counts, r.button) for r in p.feed(b"4,00056,00\\r\\n")]
    [(1234, 56, 0)]
    """

    name = "ascii"

    def __init__(
        self,
        config: TabletConfig | None = None,
        *,
        width: int | None = 5,
        flag_width: int = 2,
        signed: bool = False,
        max_line: int = 80,
    ):
        super().__init__(config)
        if width is not None and not 1 <= width <= 10:
            raise ProtocolError(f"ASCII width must be 1-10 or None, not {width!r}")
        if not 1 <= flag_width <= 2:
            raise ProtocolError(f"ASCII flag_width must be 1 or 2, not {flag_width!r}")
        self.width = width
        self.flag_width = flag_width
        self.signed = bool(signed)
        self.max_line = int(max_line)
        self._skip_line = False

    def reset(self) -> None:
        super().reset()
        self._skip_line = False

    def feed(self, data: bytes) -> list[Report]:
        buf = self._pending + data if self._pending else bytes(data)
        lines = buf.split(b"\n")
        pending = lines.pop()
        out = []
        parse = self._parse
        for line in lines:
            if self._skip_line:
                self._skip_line = False
                self._discard(len(line) + 1)
                continue
            rep = parse(line)
            if rep is not None:
                out.append(rep)
        if len(pending) > self.max_line:
            self._discard(len(pending))
            pending = b""
            self._skip_line = True
        self._pending = pending
        self.packets += len(out)
        return out

    def flush(self) -> list[Report]:
        """Drop a line without its LF: it may have been cut short."""
        if self._pending:
            self._discard(len(self._pending))
        self._pending = b""
        return []

    def _parse(self, line: bytes) -> Report | None:
        raw = line + b"\n"
        body = line.rstrip(b"\r")
        if not body.strip(b" "):
            self.discarded_bytes += len(raw)  # a blank line: skipped, not a resync
            return None
        parts = body.split(b",")
        if len(parts) not in (3, 4):
            self._discard(len(raw))
            return None
        w = self.width
        if w is not None and (
            len(parts[0]) != w
            or len(parts[1]) != w
            or len(parts[2]) != self.flag_width
            or (len(parts) == 4 and len(parts[3]) != 1)
        ):
            self._discard(len(raw))
            return None
        mx = _NUM.fullmatch(parts[0])
        my = _NUM.fullmatch(parts[1])
        mf = _FLAG.fullmatch(parts[2])
        mp = _PROX.fullmatch(parts[3]) if len(parts) == 4 else None
        if mx is None or my is None or mf is None or (len(parts) == 4 and mp is None):
            self._discard(len(raw))
            return None
        x = int(mx.group(1))
        y = int(my.group(1))
        if not self.signed and (x < 0 or y < 0 or b"-" in parts[0] or b"-" in parts[1]):
            self._reject(raw, "a negative coordinate, and the format is unsigned")
            rep = None
        else:
            rep = self._plausible(x, y, int(mf.group(1)), mp is None or mp.group(1) == b"1", raw)
        if rep is None:
            self._discard(len(raw))
        return rep

    def encode(self, report: Report) -> bytes:
        return encode_ascii(
            report.x_counts,
            report.y_counts,
            report.button,
            report.proximity,
            width=self.width,
            flag_width=self.flag_width,
            signed=self.signed,
        )


PROTOCOLS: dict[str, type[Parser]] = {
    "mm": MMBinaryParser,
    "calcomp": CalCompBinaryParser,
    "ascii": AsciiParser,
}


#: The encoder of each protocol: (x_counts, y_counts, button, proximity, **options) -> bytes.
_ENCODERS = {"mm": encode_mm, "calcomp": encode_calcomp, "ascii": encode_ascii}


def _protocol_class(protocol: str) -> type[Parser]:
    try:
        return PROTOCOLS[protocol.lower()]
    except (KeyError, AttributeError):
        raise ProtocolError(
            f"unknown tablet protocol {protocol!r}; expected one of {', '.join(PROTOCOLS)}"
        ) from None


def make_encoder(protocol: str, **options):
    """The encoder of a protocol named in :data:`PROTOCOLS`: ``(x, y, button, proximity) -> bytes``.

    ``options`` are the format options of ``ascii`` (``width``, ``flag_width``,
    ``signed``); the binary formats take none.

    Examples
    --------
    >>> make_encoder("ascii", width=None)(12, 5, 11, True)
    b'12,5,11\\r\\n'
    """
    cls = _protocol_class(protocol)
    if cls is not AsciiParser and options:
        raise ProtocolError(f"{protocol}: unexpected options {sorted(options)}")
    encode = _ENCODERS[cls.name]
    return functools.partial(encode, **options) if options else encode


def make_parser(protocol: str, config: TabletConfig | None = None, **options) -> Parser:
    """A parser for a protocol named in :data:`PROTOCOLS` (``mm``, ``calcomp``, ``ascii``).

    ``options`` go to the parser class (``confirm``, ``width``, ``signed``, ...).

    Examples
    --------
    >>> make_parser("ascii", width=None)
    <AsciiParser {'packets': 0, 'discarded_bytes': 0, 'resyncs': 0, 'rejected': 0}>
    """
    cls = _protocol_class(protocol)
    try:
        return cls(config, **options)
    except TypeError as exc:
        raise ProtocolError(f"tablet protocol {protocol!r}: {exc}") from None


def read_reports(port, parser: Parser, *, max_bytes: int = 4096) -> list[Report]:
    """Read what a tablet port has and parse it; on a quiet line, flush the parser.

    Reads the bytes waiting on ``port`` (a pyserial port with a read timeout,
    e.g. ``serial.serial_for_url(url, timeout=0.01)``), or waits up to the
    port's timeout for one byte. When nothing came, the line is quiet and
    :meth:`Parser.flush` releases a complete packet that was waiting for its
    successor (``confirm=True``). Call it in the tablet loop.

    Examples
    --------
    >>> import serial
    >>> port = serial.serial_for_url("loop://", timeout=0.01)
    >>> _ = port.write(encode_calcomp(10, 20, 11))
    >>> p = CalCompBinaryParser()
    >>> read_reports(port, p)  # the packet waits for its successor...
    []
    >>> [(r.x_counts, r.y_counts, r.button) for r in read_reports(port, p)]  # ...or a quiet line
    [(10, 20, 11)]
    """
    n = port.in_waiting
    data = port.read(min(n, max_bytes) if n else 1)
    if not data:
        return parser.flush()
    return parser.feed(data)
