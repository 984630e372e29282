"""Fixtures for the instrument tests: pty pairs, simulated controllers, in-process ports."""

from __future__ import annotations

import contextlib
import os
import select
import time
import tty

import pytest

from apygis.instrument.motors import SimulatedGrbl


class PtyPair:
    """A pseudo-terminal: ``path`` for ``serial_for_url``, ``master`` fd for the other end."""

    def __init__(self):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)

    def read_master(self, nbytes: int, timeout: float = 5.0) -> bytes:
        """Read from the master until ``nbytes`` came or ``timeout`` passed."""
        out = bytearray()
        deadline = time.monotonic() + timeout
        while len(out) < nbytes:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            r, _, _ = select.select([self.master], [], [], min(left, 0.05))
            if r:
                out += os.read(self.master, 65536)
        return bytes(out)

    def close(self):
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


@pytest.fixture
def pty_pair():
    pair = PtyPair()
    try:
        yield pair
    finally:
        pair.close()


class DirectPort:
    """A pyserial stand-in wired straight to a SimulatedGrbl (no thread, no OS port)."""

    def __init__(self, sim: SimulatedGrbl, name: str = "direct://sim"):
        self.sim = sim
        self.port = name
        self._buf = bytearray()
        self.written = bytearray()
        self.closed = False

    def write(self, data: bytes) -> int:
        self.written += data
        self._buf += self.sim.handle(bytes(data))
        return len(data)

    @property
    def in_waiting(self) -> int:
        self._buf += self.sim.take_output()
        return len(self._buf)

    def read(self, size: int = 1) -> bytes:
        self._buf += self.sim.take_output()
        if not self._buf:
            time.sleep(0.002)
            return b""
        out = bytes(self._buf[:size])
        del self._buf[:size]
        return out

    def reset_input_buffer(self):
        self._buf.clear()

    def close(self):
        self.closed = True


@pytest.fixture
def direct():
    """(sim, port): a simulated controller and a port that talks to it in-process."""
    sim = SimulatedGrbl()
    return sim, DirectPort(sim)


@pytest.fixture(params=["tcp", "pty"])
def served_sim(request):
    """A SimulatedGrbl serving on a loopback socket or a pty; yields (sim, url)."""
    sim = SimulatedGrbl()
    try:
        url = sim.serve_tcp("127.0.0.1", 0) if request.param == "tcp" else sim.serve_pty()
        yield sim, url
    finally:
        sim.stop()
