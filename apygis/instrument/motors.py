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

Three modules, along the seams of the protocol:

- :mod:`apygis.instrument.grbl`: the dialect, no I/O -- G-code move lines
  (:func:`format_move`), status reports (:func:`parse_status`,
  :class:`MotorStatus`), the error and alarm codes;
- this module: the client, :class:`MotorController` (serial connection,
  flow control by character counting, the queue of unanswered lines) and
  :func:`open_controller`;
- :mod:`apygis.instrument.simgrbl`: :class:`SimulatedGrbl`, the controller
  side in software (on a pty or a loopback TCP socket), so that no test
  needs hardware.

The names of the dialect and the simulated controller are importable from
here too. ``docs/protocols.md`` specifies the dialect in full.

Examples
--------
>>> format_move(x=120, y=-35)
'G0 X120 Y-35'
>>> parse_status("<Idle|MPos:120.000,-35.000,0.000,0.000|FS:0,0>").steps
(120, -35, 0, 0)
"""

from __future__ import annotations

import collections
import contextlib
import logging
import time
from typing import cast

from apygis.errors import MotorError, ProtocolError
from apygis.instrument.grbl import (
    AXES,
    BANNER,
    GRBL_ALARMS,
    GRBL_ERRORS,
    REALTIME,
    RESET,
    STATUS_QUERY,
    MotorStatus,
    format_move,
    parse_status,
)
from apygis.instrument.ports import open_url
from apygis.instrument.simgrbl import SimulatedGrbl

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
        self._write(STATUS_QUERY)
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
        if not line or any(c in REALTIME or c in "\r\n" for c in line):
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
            raise cast(MotorError, entry.error)  # a failed entry has its error

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
        elif BANNER.match(line):
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
    port = open_url(
        url,
        lambda exc: MotorError(f"cannot open the motor controller port: {exc}", port=url),
        baudrate=baudrate,
        timeout=0.05,
        write_timeout=timeout,
    )
    ctl = MotorController(port, timeout=timeout, name=url, **kwargs)
    if connect:
        try:
            ctl.connect()
        except BaseException:
            ctl.close()
            raise
    return ctl
