"""A session's view, served from a process of its own.

Serving pages takes CPU: turning changes into JSON, WebSocket frames, the
event loop, and reading what each entry changed. In the session's process
that work took the interpreter (the GIL) from the compilation: a replay at
full speed ran 13 % slower with one page open (``benchmarks/bench_session.py``,
``view_overhead_pct``). So a session's :class:`~apygis.view.server.ViewServer`
and :class:`~apygis.view.hub.ViewHub` run in a child process, which follows
the session's journal and replays it in a replica of the engine
(:class:`~apygis.view.feed.SessionReplica`): the session writes the journal
anyway (each entry on disk before it is acknowledged), and its engine is
deterministic. What the journal does not say soon enough (the floating mark
and the prompt, which are not flushed one by one) the session's side of the
view, the :class:`~apygis.view.feed.SessionFeed`'s thread, reads from the
session at most 40 times a second and pipes over when it changed.

The pipe (:func:`multiprocessing.Pipe`, pickled tuples):

* to the child: ``("follow", spec)`` followed by the journal's file
  descriptor (:func:`multiprocessing.reduction.send_handle`: the child can
  read it even after a terminated session removed the file), then
  ``("send", changes, status, display)`` as :func:`apygis.view.feed.deliver`
  takes them; the end of the pipe (the parent closed it, or died) stops the
  child;
* to the parent: ``("ready", url)`` once the page can be loaded (or
  ``("error", text)``, and the child exits), then ``("viewer", None)`` once,
  when the first page connected.

The address is bound here, before the child starts (so that a command can
refuse a port in use before it writes anything), and the child serves that
very socket. The child ignores Ctrl-C (it reaches every process of the
terminal's group; the parent decides when the view stops) and is started
with ``spawn``: a fresh interpreter, none of the parent's threads or locks.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import secrets
import signal
import socket
import threading
import time
from multiprocessing import reduction
from typing import Any

from apygis.errors import ViewError
from apygis.view.feed import SessionReplica
from apygis.view.hub import DELIVERY_INTERVAL_S, ViewHub
from apygis.view.server import ViewServer, bind_socket, page_url

__all__ = ["ViewProcess"]

log = logging.getLogger(__name__)

#: How often the child looks at the pipe and the journal, seconds.
FOLLOW_TICK_S = 0.004


class ViewProcess:
    """Serve ``hub``'s page from a child process, fed through a pipe.

    The same interface as :class:`~apygis.view.server.ViewServer` where a
    session uses it (:meth:`bind`, :meth:`start`, :attr:`url`, :meth:`send`,
    :meth:`wait_for_viewer`, :meth:`stop`); the hub is copied to the child
    when it starts and lives there.

    Parameters
    ----------
    hub : ViewHub, optional
        The state the pages start from (set :attr:`hub` before :meth:`start`
        where None).
    host, port, token
        As for :class:`~apygis.view.server.ViewServer`.
    """

    def __init__(
        self, hub: ViewHub | None = None, host: str = "127.0.0.1", port: int = 0, token=None
    ):
        self.hub = hub
        self.host = host
        self.port = port
        self.token = token or secrets.token_urlsafe(16)
        self._sock: socket.socket | None = None
        self._proc: Any = None
        self._conn: Any = None
        self._lock = threading.Lock()  # one sender on the pipe at a time
        self._closed = False
        self._gone = False
        self._viewer = False

    # ------------------------------------------------------------------ life

    @property
    def url(self) -> str:
        """The page's address, token included."""
        return page_url(self.host, self.port, self.token)

    @property
    def closed(self) -> bool:
        """Whether :meth:`stop` was called or the child has gone."""
        return self._closed or self._gone

    @property
    def pid(self) -> int | None:
        """The child's process id (None before :meth:`start`)."""
        return None if self._proc is None else self._proc.pid

    def bind(self) -> None:
        """Take the address now (as :meth:`apygis.view.server.ViewServer.bind`)."""
        if self._sock is None and self._proc is None:
            self._sock = bind_socket(self.host, self.port)
            self.port = self._sock.getsockname()[1]

    def start(self, timeout: float = 60.0) -> str:
        """Start the child and return the URL once the page can be loaded.

        Raises
        ------
        ViewError
            The address cannot be bound, or the server did not start.
        """
        if self.hub is None:
            raise ViewError("view: nothing to show (no hub)")
        if self._proc is not None:
            return self.url
        self.bind()
        ctx = multiprocessing.get_context("spawn")
        mine, theirs = ctx.Pipe(duplex=True)
        proc = ctx.Process(
            target=_child_main,
            args=(theirs, self._sock, self.hub, self.host, self.token),
            name="apygis-view",
            daemon=True,
        )
        with _sigint_ignored():
            proc.start()
        theirs.close()
        if self._sock is not None:
            self._sock.close()  # the child serves its own copy
            self._sock = None
        self._proc, self._conn = proc, mine
        why = "timed out"
        try:
            if mine.poll(timeout):
                kind, text = mine.recv()
                if kind == "ready":
                    return self.url
                why = text
        except (EOFError, OSError):
            proc.join(1.0)
            why = f"its process ended (exit status {proc.exitcode})"
        self.stop()
        raise ViewError(f"view: the server did not start: {why}")

    def stop(self, timeout: float = 5.0) -> None:
        """Close the pipe (the child closes its pages and exits), then wait for it (idempotent).

        A child that does not exit within ``timeout`` seconds is terminated.
        """
        if self._closed:
            return
        self._closed = True
        if self._sock is not None:  # bound, never started
            self._sock.close()
            self._sock = None
        proc, conn = self._proc, self._conn
        if proc is None:
            return
        if self._lock.acquire(timeout=1.0):  # a send blocked on a stuck child holds it
            try:
                conn.close()
            finally:
                self._lock.release()
        proc.join(timeout)
        if proc.is_alive():
            proc.terminate()
            proc.join(2.0)
        if proc.is_alive():  # a stopped child (SIGSTOP) leaves SIGTERM pending
            proc.kill()
            proc.join(2.0)
        if not conn.closed:
            with self._lock:  # the blocked send failed when the child went
                conn.close()

    # ------------------------------------------------------------------ feeding

    def send(self, changes: list[dict], status: dict | None, display: dict | None) -> bool:
        """Send a feed's changes and status line to the child (the feed's thread).

        Blocks only while the pipe is full (the child busy); False once the
        view is stopped or the child has gone (said once in the log: the
        session goes on without it).
        """
        return self._write(lambda conn: conn.send(("send", changes, status, display)))

    def follow(self, spec: dict, fd: int) -> None:
        """Have the child follow a session's journal (:class:`~apygis.view.feed.SessionReplica`).

        ``fd``: the journal open for reading, handed over (duplicated) with
        ``spec``; the caller closes its own.
        """

        def write(conn) -> None:
            conn.send(("follow", spec))
            reduction.send_handle(conn, fd, self._proc.pid)

        self._write(write)

    def _write(self, write) -> bool:
        """``write(conn)`` under the lock; False (the child gone, said once) if it cannot be."""
        with self._lock:
            if self.closed or self._conn is None:
                return False
            try:
                write(self._conn)
            except (OSError, ValueError, EOFError) as exc:
                self._gone = True
                log.warning("view: the page's server has gone (%s); the session goes on", exc)
                return False
        return True

    def wait_for_viewer(self, timeout: float) -> bool:
        """Wait until a page has connected (True), or ``timeout`` seconds (False)."""
        deadline = time.monotonic() + timeout
        while not self._viewer:
            left = deadline - time.monotonic()
            conn = self._conn
            if left <= 0 or conn is None or self.closed:
                return False
            try:
                if conn.poll(left) and conn.recv()[0] == "viewer":
                    self._viewer = True
            except (EOFError, OSError):
                self._gone = True
                return False
        return True


@contextlib.contextmanager
def _sigint_ignored():
    """SIGINT ignored meanwhile (on the main thread): a child started now inherits that."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _child_main(conn, sock: socket.socket, hub: ViewHub, host: str, token: str) -> None:
    """The child: serve ``hub`` on ``sock``; follow a session's journal; apply what comes.

    One loop, on the pipe and the journal. While the journal is quiet it is
    looked at every :data:`FOLLOW_TICK_S` seconds, so that an entry after a
    pause reaches the pages at once; after a read that found events the next
    comes :data:`~apygis.view.hub.DELIVERY_INTERVAL_S` later, so that a busy
    session is followed in a few longer stretches of work, not hundreds of
    short ones (each wake-up of this process lengthened the session's journal
    fsyncs on a two-core virtual machine: ``bench_session.py``). The changes
    of each read go to the hub together. The status line the parent sends is
    passed on as it comes; before changes the parent sends are applied (the
    end of the session), the journal is read to its end: the parent flushed
    it first, so the two arrive in order.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    server = ViewServer(hub, host=host, token=token, sock=sock)
    try:
        url = server.start()
    except Exception as exc:
        with contextlib.suppress(OSError):
            conn.send(("error", str(exc)))
        return
    conn.send(("ready", url))

    def tell_viewer() -> None:
        server.wait_for_viewer(1e9)
        with contextlib.suppress(OSError, ValueError):
            conn.send(("viewer", None))

    threading.Thread(target=tell_viewer, name="apygis-view-viewer", daemon=True).start()
    replica: SessionReplica | None = None
    next_read = 0.0

    def catch_up() -> list[dict]:
        """The changes of what the journal gained; the time of the next look at it set."""
        nonlocal replica, next_read
        if replica is None:
            return []
        start = replica.tail.position
        try:
            changes = replica.catch_up()
        except Exception as exc:  # a journal the replica cannot follow: the end corrects the page
            log.error("view: stopped following the session's journal: %s", exc)
            replica = None
            return []
        busy = replica.tail.position != start
        next_read = time.monotonic() + (DELIVERY_INTERVAL_S if busy else FOLLOW_TICK_S)
        return changes

    try:
        while True:
            wait = max(0.0, next_read - time.monotonic()) if replica is not None else None
            try:
                msg = conn.recv() if conn.poll(wait) else None
            except (EOFError, OSError):
                break
            if msg is None:
                changes = catch_up()
                if changes:
                    server.send(changes, None, None)
            elif msg[0] == "follow":
                try:
                    fd = reduction.recv_handle(conn)
                    replica = SessionReplica(os.fdopen(fd, "rb"), msg[1])
                except Exception as exc:
                    log.error("view: cannot follow the session's journal: %s", exc)
            else:  # ("send", changes, status, display)
                changes = catch_up() + msg[1] if msg[1] else []
                server.send(changes, msg[2], msg[3])
    finally:
        server.stop()
