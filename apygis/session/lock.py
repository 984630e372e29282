"""One session per map: the lock file ``dir/ID.lock``.

:class:`SessionLock` holds an OS file lock (``flock``) on the lock file, so
the kernel releases it when the holding process ends, however it ends: a lock
file left behind by a dead process blocks nobody. A second session on the
same map gets :class:`SessionLockedError` naming the holder (pid, host, start
time, as the holder wrote them into the file).
"""

from __future__ import annotations

import contextlib
import datetime
import fcntl
import json
import os
import socket
from pathlib import Path

from apygis.errors import ApygisError

__all__ = ["SessionLock", "SessionLockError", "SessionLockedError"]


class SessionLockedError(ApygisError, BlockingIOError):
    """Another session holds the map (its lock file names the process)."""


class SessionLockError(ApygisError, OSError):
    """The session lock file cannot be created."""


class SessionLock:
    """An exclusive lock on a map for one session: ``dir/ID.lock``.

    An OS file lock (``flock``) on the lock file, so the kernel releases it
    when the holding process ends, however it ends (``kill -9`` included):
    a lock file left behind by a dead process does not block. The holder
    writes its pid, host and start time into the file for the message a
    second session gets. :meth:`release` removes the file.
    """

    def __init__(self, path: Path, fd: int):
        self.path = path
        self._fd: int | None = fd

    @classmethod
    def acquire(cls, base) -> SessionLock:
        """Lock the map ``base`` (``dir/ID``), or raise :class:`SessionLockedError`."""
        base = Path(base)
        path = base.with_name(base.name + ".lock")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SessionLockError(f"{path.parent}: cannot create the folder: {exc}") from None
        for _ in range(100):
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
            except OSError as exc:
                raise SessionLockError(
                    f"{path}: cannot create the session lock file: {exc.strerror or exc}"
                ) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = _lock_holder(fd)
                os.close(fd)
                raise SessionLockedError(
                    f"{base}: the map is in use by another session ({holder}; lock file "
                    f"{path}); wait for it to end, or end it"
                ) from None
            try:  # the file we locked may have been removed by a releasing holder: retry
                same = os.stat(path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            info = {
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "started": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            }
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, (json.dumps(info) + "\n").encode("utf-8"), 0)
            except OSError:
                pass  # the lock holds without the note
            return cls(path, fd)
        raise SessionLockError(f"{path}: cannot take the session lock (the file keeps changing)")

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        """Remove the lock file and release the lock (idempotent)."""

        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        with contextlib.suppress(OSError):
            os.unlink(self.path)  # still holding it: nobody can lock this file meanwhile
        os.close(fd)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def _lock_holder(fd: int) -> str:

    try:
        info = json.loads(os.pread(fd, 4096, 0).decode("utf-8"))
        return f"pid {int(info['pid'])} on {info['host']}, started {info['started']}"
    except (OSError, ValueError, KeyError, TypeError):
        return "a process that has not yet written its pid"
