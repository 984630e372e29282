"""The four plate stepper motors, driven with G-code over a serial line (grbl / grblHAL).

Each photo of the APY has a pair of optical plates between it and the beam
uniters: one plate turns about a vertical axis and shifts the image in x,
the other turns about a horizontal axis and shifts it in y. A stepper motor
turns each plate. The four motors are four axes of one grblHAL controller:

====  ==============================================
axis  motor
====  ==============================================
X     left photo, x plate (shifts the image in x)
Y     left photo, y plate (shifts the image in y)
Z     right photo, x plate
A     right photo, y plate
====  ==============================================

The dialect (``docs/protocols.md`` has it in full):

- positions are **absolute motor steps**, integers. The controller is set
  up with one step per unit on every axis (``$100=1 $101=1 $102=1
  $103=1``), so a G-code coordinate *is* a step count; the client puts the
  controller in ``G21 G90`` (millimetre units, absolute distances) when it
  connects;
- one move is one line: ``G0 X120 Y-35 Z98 A-40`` (rapid) or
  ``G1 X120 Y-35 F6000`` (feed in steps per minute), only the axes that
  move; ``G92 X0 Y0 Z0 A0`` sets the current position (the plates' zero,
  "eliminate parallax" in the seed);
- lines end with LF alone (grbl answers a CR LF pair with two ``ok``);
  every line is answered by ``ok`` or ``error:N``; ``ALARM:N``, ``[MSG:...]``
  and the banner ``Grbl ...`` / ``GrblHAL ...`` come unasked;
- ``?`` (no LF: a real-time command) asks for a status report
  ``<Idle|MPos:120.000,-35.000,98.000,-40.000|FS:0,0>``; Ctrl-X (0x18) is a
  soft reset, answered by the banner.

:class:`MotorController` speaks the client side, :class:`SimulatedGrbl` the
controller side (on a pty or a loopback TCP socket), so that no test needs
hardware.

Examples
--------
>>> format_move(x=120, y=-35)
'G0 X120 Y-35'
>>> format_move(z=98, a=-40, feed=6000)
'G1 Z98 A-40 F6000'
>>> parse_status("<Idle|MPos:120.000,-35.000,0.000,0.000|FS:0,0>").steps
(120, -35, 0, 0)
"""

from __future__ import annotations

import collections
import contextlib
import logging
import operator
import os
import re
import select
import socket
import threading
import time
from dataclasses import dataclass, field

from apygis.errors import InstrumentError, MotorError, ProtocolError

__all__ = [
    "AXES",
    "GRBL_ALARMS",
    "GRBL_ERRORS",
    "MotorController",
    "MotorStatus",
    "SimulatedGrbl",
    "format_move",
    "open_controller",
    "parse_status",
]

log = logging.getLogger(__name__)

#: The four axes: left photo x, y plates, right photo x, y plates.
AXES = ("X", "Y", "Z", "A")

#: grbl 1.1 error codes (the ones a plate driver meets).
GRBL_ERRORS = {
    1: "G-code words consist of a letter and a value; letter was not found",
    2: "missing the expected G-code word value or numeric value format is not valid",
    3: "grbl '$' system command was not recognized or supported",
    5: "homing cycle failure; homing is not enabled via settings",
    8: "grbl '$' command cannot be used unless grbl is idle",
    9: "G-code commands are locked out during alarm or jog state",
    11: "max characters per line exceeded; received command line was not executed",
    15: "jog target exceeds machine travel (soft limits)",
    20: "unsupported or invalid g-code command found in block",
    21: "more than one g-code command from same modal group found in block",
    22: "feed rate has not yet been set or is undefined",
    24: "two G-code commands that both require the use of the XYZ axis words were detected",
    25: "a G-code word was repeated in the block",
    26: "a G-code command implicitly or explicitly requires XYZ axis words in the block",
}

#: grbl 1.1 alarm codes.
GRBL_ALARMS = {
    1: "hard limit triggered",
    2: "soft limit: motion target exceeds machine travel",
    3: "reset while in motion; position may be lost",
    4: "probe fail",
    5: "probe fail",
    6: "homing fail: reset during active homing cycle",
    7: "homing fail: safety door was opened during homing",
    8: "homing fail: pull off travel failed to clear limit switch",
    9: "homing fail: could not find limit switch",
    10: "homing fail: second dual axis limit switch failed",
    11: "homing required",
}

_BANNER = re.compile(r"^(Grbl|GrblHAL)\s+\S+")
_REALTIME = frozenset("?!~\x18")
RESET = b"\x18"


def _int(name: str, value) -> int:
    try:
        return operator.index(value)
    except TypeError:
        raise ProtocolError(f"{name} must be an integer number of steps, not {value!r}") from None


def format_move(x=None, y=None, z=None, a=None, *, feed=None, word: str | None = None) -> str:
    """One G-code move line to absolute step positions (only the given axes).

    ``G0`` (rapid) without ``feed``, ``G1 ... F<feed>`` with it (steps per
    minute); ``word`` overrides the G word (``"G92"`` to set the position).
    """
    parts = [word or ("G0" if feed is None else "G1")]
    for axis, value in zip(AXES, (x, y, z, a), strict=True):
        if value is not None:
            parts.append(f"{axis}{_int(axis, value)}")
    if len(parts) == 1:
        raise ProtocolError("a move needs at least one of the axes X, Y, Z, A")
    if feed is not None and word is None:
        f = float(feed)
        if not f > 0:
            raise ProtocolError(f"feed must be positive, not {feed!r}")
        parts.append(f"F{f:g}")
    return " ".join(parts)


@dataclass(frozen=True)
class MotorStatus:
    """A parsed grbl status report ``<State|MPos:...|...>``.

    Attributes
    ----------
    state : str
        ``Idle``, ``Run``, ``Hold``, ``Jog``, ``Alarm``, ``Door``, ``Check``,
        ``Home`` or ``Sleep``.
    substate : int or None
        The number after ``Hold:`` or ``Door:``.
    mpos : tuple of float
        Machine position (one value an axis), when reported.
    wpos : tuple of float or None
        Work position, when reported (or derived from ``MPos`` and ``WCO``).
    fields : dict
        Every field as text (``{"FS": "0,0", ...}``).
    raw : str
        The report line.
    """

    state: str
    substate: int | None
    mpos: tuple[float, ...] | None
    wpos: tuple[float, ...] | None
    fields: dict[str, str] = field(default_factory=dict)
    raw: str = ""

    @property
    def steps(self) -> tuple[int, ...] | None:
        """Machine position rounded to whole steps."""
        return None if self.mpos is None else tuple(round(v) for v in self.mpos)

    @property
    def idle(self) -> bool:
        return self.state == "Idle"


def _floats(text: str, raw: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ProtocolError(f"bad number in grbl status report {raw!r}") from None


def parse_status(line: str) -> MotorStatus:
    """Parse a grbl 1.1 status report line, ``<Idle|MPos:0.000,0.000,0.000,0.000|FS:0,0>``."""
    raw = line.strip()
    if not (raw.startswith("<") and raw.endswith(">")) or len(raw) < 3:
        raise ProtocolError(f"not a grbl status report: {line!r}")
    parts = raw[1:-1].split("|")
    state, _, sub = parts[0].partition(":")
    if not state.isalpha():
        raise ProtocolError(f"bad machine state in grbl status report {line!r}")
    substate = int(sub) if sub.isdigit() else None
    fields = {}
    for p in parts[1:]:
        key, sep, value = p.partition(":")
        if not sep:
            raise ProtocolError(f"bad field {p!r} in grbl status report {line!r}")
        fields[key] = value
    mpos = _floats(fields["MPos"], raw) if "MPos" in fields else None
    wpos = _floats(fields["WPos"], raw) if "WPos" in fields else None
    if "WCO" in fields:
        wco = _floats(fields["WCO"], raw)
        if mpos is None and wpos is not None:
            mpos = tuple(w + o for w, o in zip(wpos, wco, strict=False))
        elif wpos is None and mpos is not None:
            wpos = tuple(m - o for m, o in zip(mpos, wco, strict=False))
    return MotorStatus(state, substate, mpos, wpos, fields, raw)


# --------------------------------------------------------------------------- client


class _Sent:
    """A line sent and not yet answered."""

    __slots__ = ("error", "info", "line", "nbytes", "waited")

    def __init__(self, line: str):
        self.line = line
        self.nbytes = len(line) + 1
        self.info: list[str] = []
        self.error: MotorError | None = None
        self.waited = False


class MotorController:
    """Client for a grbl / grblHAL controller driving the four plate motors.

    Parameters
    ----------
    port : serial.Serial or compatible
        An open port (``read``, ``write``, ``in_waiting``); open it with
        :func:`open_controller` or ``serial.serial_for_url(url, timeout=0.05)``
        -- a short read timeout, the answer deadline is ``timeout``.
    timeout : float
        Seconds to wait for an answer (``ok``, ``error:``, a status report,
        the banner) before raising :class:`MotorError`.
    rx_buffer : int
        Size of the controller's receive buffer (128 for grbl, 1024 for
        grblHAL): lines sent with ``wait=False`` are kept within it
        (character counting).
    name : str, optional
        The port name used in messages (default: the port's ``port``).

    Attributes
    ----------
    banner : str or None
        The controller's last startup line.
    alarm : int or None
        The last ``ALARM:N`` code, until :meth:`unlock`.
    locked : bool
        The controller refuses G-code (alarm state, ``error:9``) until
        :meth:`unlock`.
    position : dict
        The step positions last commanded, by axis (with ``wait=True``: last
        accepted).
    last_status : MotorStatus or None
        The last status report.
    messages : deque of str
        The last 100 ``[MSG:...]``, ``[GC:...]``, ``$`` lines.

    Examples
    --------
    >>> sim = SimulatedGrbl()
    >>> url = sim.serve_tcp()
    >>> with open_controller(url, timeout=2.0) as ctl:
    ...     _ = ctl.move_to(x=120, y=-35, z=98, a=-40)
    ...     ctl.status().steps
    (120, -35, 98, -40)
    >>> sim.stop()
    """

    def __init__(self, port, *, timeout: float = 2.0, rx_buffer: int = 128, name=None):
        self.port = port
        self.name = str(name or getattr(port, "port", None) or getattr(port, "name", None) or port)
        if getattr(port, "timeout", 0) is None:
            log.debug("%s: the port has no read timeout; setting 0.05 s", self.name)
            port.timeout = 0.05  # a blocking read would never reach the answer deadline
        self.timeout = float(timeout)
        self.rx_buffer = int(rx_buffer)
        self.banner: str | None = None
        self.alarm: int | None = None
        self.last_status: MotorStatus | None = None
        self.locked = False
        self.messages: collections.deque[str] = collections.deque(maxlen=100)
        self.position: dict[str, int] = {}
        self._rx = bytearray()
        self._sent: collections.deque[_Sent] = collections.deque()
        self._failed: collections.deque[_Sent] = collections.deque()
        self._connecting = False

    # ---- life cycle

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        """Close the port."""
        with contextlib.suppress(Exception):
            self.port.close()

    def connect(self, *, reset: bool = True, unlock: bool = False) -> str | None:
        """Start a session: soft reset, wait for the banner, set ``G21 G90``.

        Parameters
        ----------
        reset : bool
            Send Ctrl-X and wait for the ``Grbl``/``GrblHAL`` banner (the port
            may have been opened after the controller printed it).
        unlock : bool
            Send ``$X`` after the banner (clears an alarm state).

        Returns
        -------
        str or None
            The banner. A controller that comes up in the alarm state
            (``error:9`` to ``G21 G90``) leaves :attr:`locked` set: call
            :meth:`unlock`.
        """
        self._connecting = True
        try:
            if reset:
                with contextlib.suppress(Exception):
                    self.port.reset_input_buffer()
                self._rx.clear()
                self._sent.clear()
                self.banner = None
                self._write(RESET)
                deadline = time.monotonic() + self.timeout
                while self.banner is None:
                    if not self._process_one(deadline):
                        raise MotorError(
                            f"no Grbl banner within {self.timeout:g} s after a soft reset",
                            port=self.name,
                            line="^X",
                        )
            if unlock:
                self.command("$X")
                self.alarm = None
            try:
                self.command("G21 G90")
                self.locked = False
            except MotorError as exc:
                if exc.code != 9:
                    raise
                self.locked = True
                log.warning(
                    "%s: the controller is in the alarm state; unlock() to go on", self.name
                )
        finally:
            self._connecting = False
        return self.banner

    # ---- commands

    def command(self, line: str, *, timeout: float | None = None) -> list[str]:
        """Send one line and wait for its ``ok``; return the lines it printed before.

        Raises
        ------
        MotorError
            ``error:N`` (``code``), ``ALARM:N`` (``alarm``), a controller
            reset, or no answer within the timeout; or an earlier line sent
            with ``wait=False`` that failed.
        """
        entry = self._send(line)
        return self._wait(entry, timeout)

    def send(self, line: str) -> None:
        """Send one line without waiting for its answer (see :meth:`drain`)."""
        self._send(line)

    def move_to(self, x=None, y=None, z=None, a=None, *, feed=None, wait: bool = True) -> str:
        """Move the plates to absolute step positions; return the line sent.

        With ``wait=False`` the line is written as soon as the controller's
        receive buffer has room, and its answer is checked later by
        :meth:`poll`, :meth:`drain` or the next waited command.
        """
        line = format_move(x, y, z, a, feed=feed)
        entry = self._send(line)
        if wait:
            self._wait(entry, None)
        for axis, value in zip(AXES, (x, y, z, a), strict=True):
            if value is not None:
                self.position[axis] = int(value)
        return line

    def set_position(self, x=None, y=None, z=None, a=None) -> None:
        """Declare the current plate positions (``G92``), e.g. ``set_position(0, 0, 0, 0)``."""
        self.command(format_move(x, y, z, a, word="G92"))
        for axis, value in zip(AXES, (x, y, z, a), strict=True):
            if value is not None:
                self.position[axis] = int(value)

    def unlock(self) -> None:
        """``$X``: leave the alarm state (then ``G21 G90`` again)."""
        self.command("$X")
        self.alarm = None
        self.locked = False
        self.command("G21 G90")

    def reset(self) -> str | None:
        """Soft reset (Ctrl-X); wait for the banner. Lines not yet answered are lost."""
        return self.connect(reset=True)

    def status(self, *, timeout: float | None = None) -> MotorStatus:
        """Ask for a status report (``?``) and return it parsed."""
        self._raise_failed()
        self.last_status = None
        self._write(b"?")
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while self.last_status is None:
            if not self._process_one(deadline):
                limit = self.timeout if timeout is None else timeout
                raise MotorError(f"no status report within {limit:g} s", port=self.name, line="?")
        return self.last_status

    def wait_idle(self, *, timeout: float | None = None, interval: float = 0.02) -> MotorStatus:
        """Wait until every line is answered and the controller reports ``Idle``."""
        limit = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + limit
        self.drain(timeout=limit)
        while True:
            st = self.status(timeout=max(0.0, deadline - time.monotonic()) or 0.001)
            if st.state == "Idle":
                return st
            if st.state == "Alarm":
                raise MotorError(
                    "controller is in the alarm state", port=self.name, alarm=self.alarm
                )
            if time.monotonic() > deadline:
                raise MotorError(f"not idle within {limit:g} s (state {st.state})", port=self.name)
            time.sleep(interval)

    def poll(self) -> None:
        """Read the answers that have arrived, without waiting; raise for a failed line."""
        while self._process_one(None):
            pass
        self._raise_failed()

    def drain(self, *, timeout: float | None = None) -> None:
        """Wait until every line sent has been answered; raise for a failed one."""
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while self._sent:
            if not self._process_one(deadline):
                raise MotorError(
                    f"no answer within {self.timeout if timeout is None else timeout:g} s "
                    f"to {self._sent[0].line!r}",
                    port=self.name,
                    line=self._sent[0].line,
                )
        self._raise_failed()

    @property
    def pending(self) -> int:
        """Lines sent and not yet answered."""
        return len(self._sent)

    # ---- internals

    def _write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except Exception as exc:  # serial.SerialException, OSError
            raise MotorError(f"cannot write to the controller: {exc}", port=self.name) from exc

    def _send(self, line: str) -> _Sent:
        self._raise_failed()
        line = line.strip()
        if not line or any(c in _REALTIME or c in "\r\n" for c in line):
            raise ProtocolError(
                f"{self.name}: a G-code line must be one non-empty line without the "
                f"real-time characters ? ! ~ ^X: {line!r}"
            )
        try:
            data = line.encode("ascii") + b"\n"
        except UnicodeEncodeError:
            raise ProtocolError(f"{self.name}: G-code must be ASCII: {line!r}") from None
        entry = _Sent(line)
        if entry.nbytes > self.rx_buffer:
            raise ProtocolError(
                f"{self.name}: line of {entry.nbytes} bytes exceeds the controller's "
                f"{self.rx_buffer}-byte buffer: {line!r}"
            )
        deadline = time.monotonic() + self.timeout
        while sum(s.nbytes for s in self._sent) + entry.nbytes > self.rx_buffer:
            if not self._process_one(deadline):
                raise MotorError(
                    f"no answer within {self.timeout:g} s to {self._sent[0].line!r}",
                    port=self.name,
                    line=self._sent[0].line,
                )
        self._sent.append(entry)
        log.debug("%s > %s", self.name, line)
        self._write(data)
        return entry

    def _wait(self, entry: _Sent, timeout: float | None) -> list[str]:
        entry.waited = True
        limit = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + limit
        while entry in self._sent:
            if not self._process_one(deadline):
                raise MotorError(
                    f"no answer within {limit:g} s to {entry.line!r}",
                    port=self.name,
                    line=entry.line,
                )
        if entry.error is not None:
            raise entry.error
        self._raise_failed()
        return entry.info

    def _raise_failed(self) -> None:
        if self._failed:
            entry = self._failed.popleft()
            raise entry.error

    def _readline(self, deadline: float | None) -> str | None:
        """The next line from the controller, or None at the deadline (None: no wait)."""
        while True:
            i = self._rx.find(b"\n")
            if i >= 0:
                line = bytes(self._rx[:i])
                del self._rx[: i + 1]
                return line.decode("ascii", "replace").strip()
            try:
                n = self.port.in_waiting
                if not n and (deadline is None or time.monotonic() >= deadline):
                    return None
                data = self.port.read(n or 1)
            except Exception as exc:
                raise MotorError(f"cannot read from the controller: {exc}", port=self.name) from exc
            if data:
                self._rx += data
            elif deadline is None or time.monotonic() >= deadline:
                return None

    def _process_one(self, deadline: float | None) -> bool:
        """Read and handle one line; False when none came before the deadline."""
        line = self._readline(deadline)
        if line is None:
            return False
        if line:
            log.debug("%s < %s", self.name, line)
            self._handle(line)
        return True

    def _resolve(self, error: MotorError | None) -> None:
        if not self._sent:
            log.warning("%s: an answer with no line waiting for one", self.name)
            return
        entry = self._sent.popleft()
        if entry.error is None:
            entry.error = error
        if entry.error is not None and not entry.waited:
            self._failed.append(entry)

    def _fail_all(self, make) -> None:
        while self._sent:
            entry = self._sent[0]
            self._resolve(make(entry))

    def _handle(self, line: str) -> None:
        if line == "ok":
            self._resolve(None)
        elif line.startswith("error:"):
            code_text = line[6:].strip()
            code = int(code_text) if code_text.isdigit() else None
            if code == 9:
                self.locked = True
            what = GRBL_ERRORS.get(code, "unknown error") if code is not None else code_text
            entry = self._sent[0] if self._sent else None
            sent = entry.line if entry else None
            self._resolve(
                MotorError(
                    f"grbl error:{code_text} ({what}) for {sent!r}",
                    port=self.name,
                    line=sent,
                    code=code,
                )
            )
        elif line.startswith("ALARM:"):
            code_text = line[6:].strip()
            self.alarm = int(code_text) if code_text.isdigit() else -1
            what = GRBL_ALARMS.get(self.alarm, "unknown alarm")
            log.error("%s: ALARM:%s (%s)", self.name, code_text, what)
            self._fail_all(
                lambda e: MotorError(
                    f"grbl ALARM:{code_text} ({what}) while {e.line!r} was pending; "
                    "soft reset and $X to continue",
                    port=self.name,
                    line=e.line,
                    alarm=self.alarm,
                )
            )
        elif line.startswith("<"):
            try:
                self.last_status = parse_status(line)
            except ProtocolError as exc:
                log.warning("%s: %s", self.name, exc)
        elif _BANNER.match(line):
            self.banner = line
            if self._connecting:
                log.info("%s: %s", self.name, line)
            else:
                log.warning("%s: controller reset (%s)", self.name, line)
                self._fail_all(
                    lambda e: MotorError(
                        f"controller reset ({line}) while {e.line!r} was pending",
                        port=self.name,
                        line=e.line,
                    )
                )
        else:
            if line.startswith("[MSG:"):
                log.info("%s: %s", self.name, line)
                if "to unlock" in line:
                    self.locked = True
            self.messages.append(line)
            if self._sent:
                self._sent[0].info.append(line)


def open_controller(
    url: str, *, timeout: float = 2.0, connect: bool = True, baudrate: int = 115200, **kwargs
) -> MotorController:
    """Open a port with ``serial.serial_for_url`` and return a connected :class:`MotorController`.

    ``url`` is a device (``/dev/ttyACM0``, a pty) or a pyserial URL
    (``socket://127.0.0.1:PORT``, ``spy://...``). ``kwargs`` go to
    :class:`MotorController` (``rx_buffer``).
    """
    import serial

    try:
        port = serial.serial_for_url(url, baudrate=baudrate, timeout=0.05, write_timeout=timeout)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise MotorError(f"cannot open the motor controller port: {exc}", port=url) from exc
    ctl = MotorController(port, timeout=timeout, name=url, **kwargs)
    if connect:
        try:
            ctl.connect()
        except BaseException:
            ctl.close()
            raise
    return ctl


# --------------------------------------------------------------------------- simulator

_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")


class SimulatedGrbl:
    """A grblHAL controller for four axes, in software: the other end of :class:`MotorController`.

    It answers the protocol of a real controller: the banner after Ctrl-X,
    ``ok``, ``error:N`` (bad words, unsupported commands, ``G1`` without a
    feed rate, lines too long, a move beyond the soft limits), ``?`` status
    reports with the machine position, ``$X``, ``$$``, ``$G``, ``G92``.
    Moves complete at once (the state is always ``Idle``).

    Parameters
    ----------
    banner : str
        The startup line.
    limits : (float, float) or dict
        Soft limits in steps, one range for every axis or one per axis.
    soft_limit_alarm : bool
        False: a move beyond the limits is refused with ``error:15`` and the
        position kept. True (what grbl does for G-code moves): ``ALARM:2``,
        no answer to anything until a soft reset, then the alarm state until
        ``$X``.
    banner_on_connect : bool
        Print the banner when a TCP client connects (a controller that
        boots on connection).

    Attributes
    ----------
    mpos : dict
        Machine position in steps, by axis.
    mute : bool
        Set True to stop answering (to test timeouts).
    received : list of str
        Every line received, in order.

    Examples
    --------
    >>> sim = SimulatedGrbl()
    >>> sim.handle(b"G0 X5 A-2\\n?")
    b'ok\\r\\n<Idle|MPos:5.000,0.000,0.000,-2.000|FS:0,0>\\r\\n'
    >>> sim.handle(b"G1 X1\\n")
    b'error:22\\r\\n'
    """

    def __init__(
        self,
        *,
        banner: str = "GrblHAL 1.1f ['$' or '$HELP' for help]",
        limits=(-100000, 100000),
        soft_limit_alarm: bool = False,
        banner_on_connect: bool = False,
    ):
        self.banner = banner
        if isinstance(limits, dict):
            self.limits = {ax: tuple(limits[ax]) for ax in AXES}
        else:
            self.limits = dict.fromkeys(AXES, tuple(limits))
        self.soft_limit_alarm = soft_limit_alarm
        self.banner_on_connect = banner_on_connect
        self.mpos = dict.fromkeys(AXES, 0.0)
        self.wco = dict.fromkeys(AXES, 0.0)
        self.absolute = True
        self.motion = "G0"
        self.feed: float | None = None
        self.alarm: int | None = None
        self.critical = False
        self.mute = False
        self.received: list[str] = []
        self._line = bytearray()
        self._outbox = bytearray()
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._closers: list = []
        self.url: str | None = None

    # ---- protocol core

    def handle(self, data: bytes) -> bytes:
        """Take bytes from the client; return the controller's answer bytes."""
        out = []
        with self._lock:
            if self._outbox:
                out.append(self.take_output().decode("ascii", "replace"))
            for c in data:
                if c == 0x18:
                    self._line.clear()
                    self._reset(out)
                elif c == 0x3F:  # ?
                    if not self.mute:
                        out.append(self._status())
                elif c in (0x21, 0x7E) or c >= 0x80:  # ! ~ and extended real-time commands
                    continue
                elif c in (0x0A, 0x0D):
                    line = self._line.decode("ascii", "replace")
                    self._line.clear()
                    if self.critical or self.mute:
                        continue
                    self.received.append(line)
                    out.append(self._execute(line))
                else:
                    self._line.append(c)
        return "".join(out).encode("ascii")

    def emit(self, data: bytes | str) -> None:
        """Send unasked bytes to the client (an ``ALARM:1``, a banner after a power glitch).

        The serving thread sends them within 50 ms; with :meth:`handle` alone
        they come out with the next answer (or :meth:`take_output`).
        """
        with self._lock:
            self._outbox += data.encode("ascii") if isinstance(data, str) else data

    def take_output(self) -> bytes:
        """The bytes given to :meth:`emit` and not yet sent."""
        with self._lock:
            out = bytes(self._outbox)
            self._outbox.clear()
            return out

    def _reset(self, out: list) -> None:
        self.motion, self.absolute, self.feed = "G0", True, None
        out.append(f"\r\n{self.banner}\r\n")
        if self.critical:
            self.critical = False
            self.alarm = 2
            out.append("[MSG:'$H'|'$X' to unlock]\r\n")

    def _status(self) -> str:
        state = "Alarm" if self.alarm else "Idle"
        mpos = ",".join(f"{self.mpos[a]:.3f}" for a in AXES)
        s = f"<{state}|MPos:{mpos}|FS:0,0"
        if any(self.wco.values()):
            s += "|WCO:" + ",".join(f"{self.wco[a]:.3f}" for a in AXES)
        return s + ">\r\n"

    def _execute(self, line: str) -> str:
        if len(line) > 255:
            return "error:11\r\n"
        text = re.sub(r"\([^)]*\)|;.*$", "", line).replace(" ", "").replace("\t", "").upper()
        if not text:
            return "ok\r\n"
        if text.startswith("$"):
            return self._system(text)
        words = []
        pos = 0
        while pos < len(text):
            m = _WORD.match(text, pos)
            if m is None:
                return "error:2\r\n" if "A" <= text[pos] <= "Z" else "error:1\r\n"
            words.append(m.groups())
            pos = m.end()
        if self.alarm:
            return "error:9\r\n"
        motion = None
        g92 = False
        absolute = self.absolute
        axes: dict[str, float] = {}
        feed = None
        seen = set()
        for letter, number in words:
            value = float(number)
            if letter == "G":
                code = number.lstrip("+")
                if code in ("0", "00", "1", "01"):
                    if motion is not None:
                        return "error:21\r\n"
                    motion = "G" + str(int(value))
                elif code == "90":
                    absolute = True
                elif code == "91":
                    absolute = False
                elif code == "21":
                    pass
                elif code == "92":
                    g92 = True
                else:
                    return "error:20\r\n"
            elif letter in AXES:
                if letter in axes:
                    return "error:25\r\n"
                axes[letter] = value
            elif letter == "F":
                if letter in seen:
                    return "error:25\r\n"
                if value <= 0:
                    return "error:2\r\n"
                feed = value
            elif letter == "N":
                pass
            else:
                return "error:20\r\n"
            seen.add(letter)
        if g92 and motion is not None:
            return "error:24\r\n"
        if g92:
            if not axes:
                return "error:26\r\n"
            for ax, v in axes.items():
                self.wco[ax] = self.mpos[ax] - v
            self.absolute = absolute
            return "ok\r\n"
        motion = motion or self.motion
        if feed is not None:
            self.feed = feed
        if axes and motion == "G1" and self.feed is None:
            return "error:22\r\n"
        target = dict(self.mpos)
        for ax, v in axes.items():
            target[ax] = v + self.wco[ax] if absolute else self.mpos[ax] + v
        for ax, v in target.items():
            lo, hi = self.limits[ax]
            if not lo <= v <= hi:
                if self.soft_limit_alarm:
                    self.critical = True
                    return "ALARM:2\r\n[MSG:Reset to continue]\r\n"
                return "error:15\r\n"
        self.absolute = absolute
        self.motion = motion
        self.mpos = target
        return "ok\r\n"

    def _system(self, text: str) -> str:
        if text == "$X":
            msg = "[MSG:Caution: Unlocked]\r\n" if self.alarm else ""
            self.alarm = None
            return msg + "ok\r\n"
        if text == "$$":
            lines = [f"${n}=1.000" for n in (100, 101, 102, 103)]
            return "\r\n".join(lines) + "\r\nok\r\n"
        if text == "$G":
            mode = "G90" if self.absolute else "G91"
            feed = f"{self.feed:g}" if self.feed else "0"
            return f"[GC:{self.motion} G54 G17 G21 {mode} G94 M5 M9 T0 F{feed} S0]\r\nok\r\n"
        if text in ("$I",):
            return f"[VER:{self.banner.split()[1]}:apygis simulator]\r\nok\r\n"
        if text == "$H":
            return "error:5\r\n"
        return "error:3\r\n"

    # ---- transports

    def serve_pty(self) -> str:
        """Serve on a new pseudo-terminal in a daemon thread; return the slave's path.

        Open the path with ``serial.serial_for_url(path)``.
        """
        self._check_idle()
        import tty

        master, slave = os.openpty()
        tty.setraw(slave)
        path = os.ttyname(slave)
        self._closers = [lambda: os.close(master), lambda: os.close(slave)]
        self.url = path
        self._start(self._run_pty, master)
        return path

    def serve_tcp(self, host: str = "127.0.0.1", port: int = 0) -> str:
        """Serve on a TCP socket in a daemon thread; return ``socket://HOST:PORT``.

        One client at a time; port 0 picks a free port.
        """
        self._check_idle()
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            srv.bind((host, port))
            srv.listen(1)
        except OSError as exc:
            srv.close()
            raise InstrumentError(f"cannot listen on {host}:{port}: {exc}") from exc
        srv.settimeout(0.05)
        self._closers = [srv.close]
        h, p = srv.getsockname()[:2]
        self.url = f"socket://{h}:{p}"
        self._start(self._run_tcp, srv)
        return self.url

    def stop(self, timeout: float = 2.0) -> None:
        """Stop serving and close the pty or socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        for close in self._closers:
            with contextlib.suppress(OSError):
                close()
        self._closers = []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()

    def _check_idle(self) -> None:
        if self._thread is not None:
            raise InstrumentError("the simulated controller is already serving")
        self._stop.clear()

    def _start(self, target, *args) -> None:
        self._thread = threading.Thread(target=target, args=args, name="SimulatedGrbl", daemon=True)
        self._thread.start()

    def _run_pty(self, fd: int) -> None:
        try:
            while not self._stop.is_set():
                r, _, _ = select.select([fd], [], [], 0.05)
                if self._outbox:
                    os.write(fd, self.take_output())
                if not r:
                    continue
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    time.sleep(0.01)
                    continue
                reply = self.handle(data)
                if reply:
                    os.write(fd, reply)
        except Exception:  # pragma: no cover - a thread must not die silently
            log.exception("simulated controller (pty) stopped")

    def _run_tcp(self, srv: socket.socket) -> None:
        try:
            while not self._stop.is_set():
                try:
                    conn, _ = srv.accept()
                except TimeoutError:
                    continue
                except OSError:
                    return
                with conn:
                    self._serve_conn(conn)
        except Exception:  # pragma: no cover
            log.exception("simulated controller (tcp) stopped")

    def _serve_conn(self, conn: socket.socket) -> None:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if self.banner_on_connect:
            conn.sendall(f"\r\n{self.banner}\r\n".encode("ascii"))
        while not self._stop.is_set():
            r, _, _ = select.select([conn], [], [], 0.05)
            if self._outbox:
                try:
                    conn.sendall(self.take_output())
                except OSError:
                    return
            if not r:
                continue
            try:
                data = conn.recv(4096)
            except OSError:
                return
            if not data:
                return
            reply = self.handle(data)
            if reply:
                try:
                    conn.sendall(reply)
                except OSError:
                    return
