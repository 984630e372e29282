"""A simulated grblHAL controller for the four plate motors, on a pty or a TCP socket.

:class:`SimulatedGrbl` is the controller side of the dialect in
:mod:`apygis.instrument.grbl`, the other end of
:class:`~apygis.instrument.motors.MotorController`, so that no test (and no
demonstration session, ``apygis session --motors sim``) needs hardware.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import select
import socket
import threading
import time

from apygis.errors import InstrumentError
from apygis.instrument.grbl import AXES, RESET, STATUS_QUERY, format_status

__all__ = ["SimulatedGrbl"]

log = logging.getLogger(__name__)

_RESET = RESET[0]
_QUERY = STATUS_QUERY[0]

_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")


class SimulatedGrbl:
    """A grblHAL controller for four axes, in software: the other end of a ``MotorController``.

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
        reset, query = _RESET, _QUERY  # locals: this loop runs once a byte
        with self._lock:
            if self._outbox:
                out.append(self.take_output().decode("ascii", "replace"))
            for c in data:
                if c == reset:
                    self._line.clear()
                    self._reset(out)
                elif c == query:
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
        out.append(self._banner_text())
        if self.critical:
            self.critical = False
            self.alarm = 2
            out.append("[MSG:'$H'|'$X' to unlock]\r\n")

    def _banner_text(self) -> str:
        return f"\r\n{self.banner}\r\n"

    def _status(self) -> str:
        state = "Alarm" if self.alarm else "Idle"
        wco = [self.wco[a] for a in AXES]
        return format_status(state, [self.mpos[a] for a in AXES], wco) + "\r\n"

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
            conn.sendall(self._banner_text().encode("ascii"))
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
