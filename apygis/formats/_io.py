"""File helpers shared by the drivers: atomic writes and guarded reads."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from apygis.errors import FormatError

__all__ = ["atomic_write_many", "read_bytes"]


def atomic_write_many(contents: dict[Path, bytes]) -> list[Path]:
    """Write several files so that none is ever half-written.

    Every file is first written in full to a temporary file beside its target
    (same directory, so the rename cannot cross file systems) and flushed to
    disk; only when all are written are they renamed over their targets with
    :func:`os.replace`. If anything fails before the renames, the temporary
    files are removed and no target is touched.
    """
    temps: list[tuple[str, Path]] = []
    try:
        for target, data in contents.items():
            target = Path(target)
            target.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
            temps.append((tmp, target))
            os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; a plain open() would not
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        for tmp, target in temps:
            os.replace(tmp, target)
    except BaseException:
        for tmp, _ in temps:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise
    return [t for _, t in temps]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def read_bytes(path) -> bytes:
    """The whole file, with a missing or unreadable file reported as a FormatError."""
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except IsADirectoryError:
        raise FormatError("is a directory, not a file", path=path) from None
    except FileNotFoundError:
        raise FormatError("no such file", path=path) from None
    except OSError as exc:
        raise FormatError(f"cannot read: {exc.strerror}", path=path) from None
