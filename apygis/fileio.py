"""The file floor of apygis: atomic writes, guarded reads and guarded JSON.

Every part of apygis that writes or reads a file of its own goes through this
module (it imports only :mod:`apygis.errors` and the standard library, so that
the lowest layers, :mod:`apygis.orient` and :mod:`apygis.model`, can use it):

:func:`atomic_write` / :func:`atomic_write_many`
    Files written so that none is ever half-written: each one in full to a
    temporary file beside its real target (same directory: the rename cannot
    cross file systems), flushed and synced, then renamed over the target
    with :func:`os.replace`, and the directory synced.

    * **Targets** (:func:`check_target`): a symlink is written through (the
      file it points to is replaced, the link stays); anything that exists
      and is not a regular file (a device such as ``/dev/full``, a directory,
      a pipe) is refused with :class:`~apygis.errors.FileOverwriteError`.
    * **Permissions**, one policy: a new file gets the default of the
      process's umask (``0o666 & ~umask``, as :func:`open` would give); a file
      that is replaced keeps its mode.
    * **Failures**: any ``OSError`` (a full disk, no permission, a missing
      folder) becomes one :class:`~apygis.errors.WriteError` naming the target
      and the reason (:func:`write_failed`); it is also the built-in subclass
      that fits (``FileNotFoundError``, ``PermissionError``...). The old file
      is left as it was and no temporary file is left behind.
    * **Leftovers**: the temporary files of a write that was killed (their
      names carry the writing process's id) are removed by the next write to
      the same target (:func:`remove_stale_temps`).

:func:`read_bytes`
    The content of a regular file, everything a user can get wrong about the
    path (missing, a directory, a link loop, no permission, a device or FIFO,
    too large) a :class:`~apygis.errors.FormatError` naming it.

:func:`loads_json`
    JSON from a file without any of :mod:`json`'s escapes: text that is not
    UTF-8, nesting deeper than :data:`MAX_JSON_DEPTH` (checked in linear time
    before parsing: no ``RecursionError``), ``NaN``/``Infinity``, numbers
    that overflow a double, integers of more than :data:`MAX_INT_DIGITS`
    digits (no ``ValueError`` from Python's int-string limit) and strings or
    keys holding lone surrogates (:func:`check_str`). A refused value is named
    by its key path (``photos[0].Xo``), a syntax error by its line and column.
"""

from __future__ import annotations

import contextlib
import errno
import itertools
import json
import logging
import operator
import os
import re
import secrets
import stat
from collections.abc import Iterable
from pathlib import Path
from typing import NoReturn

from apygis.errors import FileOverwriteError, FormatError, WriteError

__all__ = [
    "MAX_INT_DIGITS",
    "MAX_JSON_DEPTH",
    "TEMP_DIR_PREFIX",
    "Pending",
    "atomic_write",
    "atomic_write_many",
    "check_str",
    "check_target",
    "discard",
    "fsync_dir",
    "loads_json",
    "prepare",
    "read_bytes",
    "remove_stale_temps",
    "replace_all",
    "write_failed",
]

log = logging.getLogger(__name__)

MAX_JSON_DEPTH = 32
"""The deepest nesting of arrays and objects in the JSON that files carry."""
MAX_INT_DIGITS = 18
"""The most digits of a JSON integer accepted (fits 64 bits)."""

TEMP_DIR_PREFIX = ".apygis-"
"""Temporary folders are ``.apygis-<pid>-<random>.tmp`` (see ``formats._io.make_temp_dir``)."""

_TMP_SUFFIX = ".apygis-tmp"
# .NAME.<pid>-<random>.apygis-tmp (files), .apygis-<pid>-<random>.tmp (folders)
_TMP_FILE_RE = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)-[0-9a-f]{8}\.apygis-tmp$")
_TMP_DIR_RE = re.compile(r"^\.apygis-(?P<pid>\d+)-[0-9a-f]{8}\.tmp$")
# what earlier versions left: mkstemp's ".NAME.XXXXXXXX.tmp", symbols.py's
# ".NAME.<pid>.<random>.tmp" and mkdtemp's ".apygis-XXXXXXXX.tmp"
_OLD_FILE_RE = re.compile(r"^\.(?P<name>.+?)\.(?:(?P<pid>\d+)\.[0-9a-f]{8}|[a-z0-9_]{8})\.tmp$")
_OLD_DIR_RE = re.compile(r"^\.apygis-[a-z0-9_]{8}\.tmp$")

_KINDS = (
    (stat.S_ISDIR, "directory"),
    (stat.S_ISCHR, "character device"),
    (stat.S_ISBLK, "block device"),
    (stat.S_ISFIFO, "named pipe"),
    (stat.S_ISSOCK, "socket"),
)


# --------------------------------------------------------------------------- errors

_WRITE_ERRORS: dict[type, type] = {}


def _write_error_class(exc: OSError) -> type:
    """WriteError, also the built-in ``OSError`` subclass of ``exc``'s errno."""
    builtin = type(OSError(exc.errno, "")) if exc.errno is not None else OSError
    if builtin is OSError:
        return WriteError
    cls = _WRITE_ERRORS.get(builtin)
    if cls is None:
        cls = type("WriteError", (WriteError, builtin), {"__module__": WriteError.__module__})
        _WRITE_ERRORS[builtin] = cls
    return cls


def write_failed(target, exc: OSError, what: str = "cannot write") -> WriteError:
    """The :class:`WriteError` for an ``OSError`` met while writing ``target``.

    The message is ``"TARGET: WHAT: reason"``; ``errno``, ``strerror`` (the
    reason) and ``filename`` are set, and the error is also the built-in
    subclass of the errno (a missing folder is a ``FileNotFoundError``).
    """
    reason = exc.strerror or str(exc) or type(exc).__name__
    if exc.errno == errno.ENOSPC:
        reason = "no space left on device"
    elif exc.strerror:
        reason = reason.lower()
    err = _write_error_class(exc)(f"{target}: {what}: {reason}")
    err.errno = exc.errno
    err.strerror = reason
    err.filename = str(target)
    return err


# --------------------------------------------------------------------------- targets


def check_target(target) -> Path:
    """The file to write for ``target``: symlinks followed, a regular file or none.

    A symlink is written through (the file it points to is replaced, the link
    stays). Anything that exists and is not a regular file (a device such as
    ``/dev/full``, a directory, a pipe) is refused.

    Raises
    ------
    FileOverwriteError
        The target is not a regular file.
    WriteError
        The target cannot be looked at (no permission on its folder).
    """
    p = Path(target)
    real = Path(os.path.realpath(p))
    try:
        st = os.stat(real)
    except FileNotFoundError:
        return real
    except OSError as exc:
        raise write_failed(p, exc) from None
    if stat.S_ISREG(st.st_mode):
        return real
    kind = next((name for test, name in _KINDS if test(st.st_mode)), "special file")
    via = f" (the target of the link {p})" if real != p.absolute() and p.is_symlink() else ""
    raise FileOverwriteError(
        f"{real if via else p}{via}: is a {kind}, not a regular file; "
        "apygis writes or replaces regular files only"
    )


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: a process of another user
        return True
    return True


def remove_stale_temps(directory, names: Iterable[str] | None = None) -> list[Path]:
    """Remove temporary files (and folders) of apygis writes killed in ``directory``.

    Only apygis's own temporary names are touched: files ``.NAME.<pid>-*.apygis-tmp``
    of a target in ``names`` (any target if None) and folders
    ``.apygis-<pid>-*.tmp``, whose writing process is gone; and the names of
    earlier apygis versions. One still being written by a live process is
    left alone and reported. Returns what was removed.
    """
    import shutil

    d = Path(directory)
    wanted = None if names is None else set(names)
    removed: list[Path] = []
    try:
        entries = list(os.scandir(d))
    except OSError:
        return removed
    for e in entries:
        m = _TMP_FILE_RE.match(e.name) or _OLD_FILE_RE.match(e.name)
        is_dir = False
        if m is not None and wanted is not None and m["name"] not in wanted:
            continue
        if m is None:
            m = _TMP_DIR_RE.match(e.name) or _OLD_DIR_RE.match(e.name)
            is_dir = True
            if m is None:
                continue
        pid = m["pid"] if "pid" in m.re.groupindex else None
        pid = int(pid) if pid is not None else None
        if pid is not None and _alive(pid):
            if pid != os.getpid():  # a parallel job writing beside us: not a leftover
                log.info("%s: left alone, still being written by process %d", e.path, pid)
            continue
        try:
            size = _tree_size(Path(e.path)) if is_dir else e.stat(follow_symlinks=False).st_size
            if is_dir and e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path)
            elif not is_dir and e.is_file(follow_symlinks=False):
                os.unlink(e.path)
            else:
                continue
        except OSError as exc:
            log.warning("%s: left by an interrupted write; cannot remove it: %s", e.path, exc)
            continue
        log.warning(
            "removed %s (%s), left by an interrupted write%s",
            e.path,
            _size_text(size),
            f" (process {pid})" if pid is not None else "",
        )
        removed.append(Path(e.path))
    return removed


def _tree_size(p: Path) -> int:
    total = 0
    for root, _, files in os.walk(p):
        for f in files:
            with contextlib.suppress(OSError):
                total += os.lstat(os.path.join(root, f)).st_size
    return total


def _size_text(n: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} bytes"  # pragma: no cover


def temp_name(target: Path) -> Path:
    """``.NAME.<pid>-<random>.apygis-tmp`` beside ``target``."""
    return target.with_name(f".{target.name}.{os.getpid()}-{secrets.token_hex(4)}{_TMP_SUFFIX}")


def fsync_dir(d) -> None:
    """Sync a folder (its entries: a rename into it), where the platform allows."""
    with contextlib.suppress(OSError):
        fd = os.open(d, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _write_temp(path: Path, data: bytes, target) -> None:
    # 0o666: the kernel applies the umask, as open() would for a new file
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags, 0o666)
    except OSError as exc:
        raise write_failed(target, exc) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(path)
        raise write_failed(target, exc) from None


def _keep_mode(tmp: Path, real: Path) -> None:
    """Give ``tmp`` the mode of the file ``real`` it is about to replace (if any)."""
    try:
        mode = stat.S_IMODE(os.stat(real).st_mode)
    except OSError:  # no file yet: the new file keeps the umask's default
        return
    with contextlib.suppress(OSError):  # a file system without modes
        os.chmod(tmp, mode)


# --------------------------------------------------------------------------- writing

Pending = tuple  # (temporary file, real target, target as named)


def prepare(contents: dict, *, parents: bool = False) -> list[Pending]:
    """Write each ``{target: bytes}`` to a synced temporary file beside its real target.

    Returns ``(temporary file, real target, target as named)`` triples for
    :func:`replace_all`. On any failure the temporary files written so far
    are removed and a :class:`WriteError` (or ``FileOverwriteError``) raised.
    ``parents``: create missing folders (else a missing folder is a
    ``FileNotFoundError``).
    """
    pending: list[Pending] = []
    try:
        reals = []
        for target in contents:
            target = Path(target)
            real = check_target(target)
            if parents:
                try:
                    real.parent.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise write_failed(target, exc) from None
            reals.append((target, real))
        by_dir: dict[Path, list[str]] = {}
        for _, real in reals:
            by_dir.setdefault(real.parent, []).append(real.name)
        for directory, names in by_dir.items():  # one listing per folder, not per file
            remove_stale_temps(directory, names)
        for (target, real), data in zip(reals, contents.values(), strict=True):
            tmp = temp_name(real)
            _write_temp(tmp, data, target)
            pending.append((tmp, real, target))
    except BaseException:
        discard(pending)
        raise
    return pending


def discard(pending: Iterable[Pending]) -> None:
    """Remove the temporary files of ``pending`` (those still there)."""
    for tmp, _, _ in pending:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def replace_all(pending: list[Pending], on_error=None) -> None:
    """Rename each temporary file over its target, in order, then sync the folders.

    A replaced file's mode is kept. An ``OSError`` is a :class:`WriteError`
    naming the target; ``on_error(err, done)`` may return another error to
    raise instead (``done``: how many files were already replaced). The
    temporary files not renamed are removed.
    """
    for done, (tmp, real, target) in enumerate(pending):
        try:
            _keep_mode(tmp, real)
            os.replace(tmp, real)
        except OSError as exc:
            discard(pending[done:])
            err = write_failed(target, exc)
            if on_error is not None:
                err = on_error(err, done) or err
            raise err from None
    for d in {real.parent for _, real, _ in pending}:
        fsync_dir(d)


def atomic_write_many(contents: dict, *, parents: bool = False) -> list[Path]:
    """Write several files (``{path: bytes}``), none ever half-written; the targets, as given.

    Each file is either its old self or wholly new; a failure part way
    through the renames leaves the files before it new and the rest old
    (use ``formats._io.atomic_write_many`` for sets that a reader must see
    whole). See the module docstring for targets, permissions and failures.
    """
    pending = prepare(contents, parents=parents)
    try:
        replace_all(pending)
    except BaseException:
        discard(pending)
        raise
    return [Path(t) for t in contents]


def atomic_write(target, data: bytes | str, *, parents: bool = False) -> Path:
    """Write one file atomically (``str`` is written as UTF-8); ``target`` as a Path.

    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.txt"
    >>> atomic_write(p, "hello\\n").read_text()
    'hello\\n'
    """
    if isinstance(data, str):
        data = data.encode("utf-8")
    return atomic_write_many({Path(target): bytes(data)}, parents=parents)[0]


# --------------------------------------------------------------------------- reading


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror.lower() if exc.errno is not None else exc.strerror
    return str(exc)


def read_bytes(path, what: str = "file", max_bytes: int | None = None) -> bytes:
    """The content of the regular file ``path`` (at most ``max_bytes``, if given).

    Raises
    ------
    FormatError
        Naming the path: no such file, a directory, a symbolic-link loop, no
        permission, not a regular file (a FIFO would block, ``/dev/zero``
        would never end), larger than ``max_bytes``.
    """
    a = "an" if what[:1] in "aeiou" else "a"
    try:
        flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
        fd = os.open(Path(path), flags)  # non-blocking: a FIFO must not hang the reader
    except FileNotFoundError:
        raise FormatError(f"no such {what}", path) from None
    except IsADirectoryError:
        raise FormatError(f"is a directory, not {a} {what}", path) from None
    except PermissionError:
        raise FormatError(f"cannot read the {what}: permission denied", path) from None
    except (OSError, ValueError, TypeError) as exc:
        raise FormatError(f"cannot open the {what}: {_reason(exc)}", path) from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise FormatError(f"is a directory, not {a} {what}", path)
        if not stat.S_ISREG(st.st_mode):
            raise FormatError(
                f"is not a regular file (a device, FIFO or socket), not {a} {what}", path
            )
        if max_bytes is None:
            with open(fd, "rb", closefd=False) as fh:
                return fh.read()
        if st.st_size > max_bytes:
            raise FormatError(
                f"{st.st_size} bytes is larger than the {max_bytes} bytes {a} {what} may have", path
            )
        chunks = []
        size = 0
        while True:
            b = os.read(fd, min(1 << 20, max_bytes + 1 - size))
            if not b:
                break
            chunks.append(b)
            size += len(b)
            if size > max_bytes:
                raise FormatError(
                    f"larger than the {max_bytes} bytes {a} {what} may have (it grew while read)",
                    path,
                )
        return b"".join(chunks)
    except OSError as exc:
        raise FormatError(f"cannot read the {what}: {_reason(exc)}", path) from None
    finally:
        os.close(fd)


# --------------------------------------------------------------------------- strings and JSON

_SURROGATE = re.compile("[\ud800-\udfff]")
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_BRACKETS = re.compile(r"[\[\]{}]")
_STEP = str.maketrans({"[": "\x02", "{": "\x02", "]": "\x00", "}": "\x00"})


def check_str(s: str, what: str, path=None, record: str | None = None) -> str:
    """``s``, refused if it holds a lone surrogate (a string that cannot be encoded).

    Such strings come from JSON escapes (``"\\udcfc"``) or from bytes decoded
    with ``surrogateescape``; a value holding one could not be written back.
    """
    m = _SURROGATE.search(s)
    if m is not None:
        raise FormatError(
            f"{what} holds an undecodable character (lone surrogate U+{ord(m.group()):04X} "
            f"at character {m.start() + 1}): not valid Unicode text",
            path=path,
            record=record,
        )
    return s


class _Refused:
    """A JSON number the hooks refused; reported with its key path after parsing."""

    __slots__ = ("reason",)

    def __init__(self, reason: str):
        self.reason = reason


def _parse_int(s: str):
    body = s[1:] if s[:1] == "-" else s
    if not (body.isascii() and body.isdigit()):  # the pure-Python scanner takes any \d
        return _Refused(f"{s[:24]!r} is not an integer of ASCII digits")
    if len(body) > MAX_INT_DIGITS:  # JSON has no leading zeros
        return _Refused(
            f"an integer of {len(body)} digits is out of range (at most {MAX_INT_DIGITS} digits)"
        )
    return int(s)


def _parse_float(s: str):
    v = float(s)
    if v - v != 0.0:  # inf
        shown = s if len(s) <= 24 else s[:20] + "..."
        return _Refused(f"the number {shown} is out of range: it overflows a double (±1.8e308)")
    return v


def _parse_constant(s: str):
    return _Refused(f"{s} is not a number JSON allows (numbers must be finite)")


def _json_depth(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` outside strings (an upper bound for bad JSON).

    Linear and in C: the brackets become bytes 2 (open) and 0 (close), whose
    running sum less the count so far is the depth.
    """
    brackets = "".join(_BRACKETS.findall(_JSON_STRING.sub("", text)))
    if not brackets:
        return 0
    steps = brackets.translate(_STEP).encode("ascii")
    return max(0, max(map(operator.sub, itertools.accumulate(steps), itertools.count(1))))


def loads_json(text: str | bytes, what: str | None = None, path=None, record: str | None = None):
    """Parse JSON from a file, every failure a :class:`FormatError`.

    Refused (see the module docstring): text that is not UTF-8, nesting
    deeper than :data:`MAX_JSON_DEPTH`, ``NaN`` and ``Infinity``, numbers that
    overflow a double, integers of more than :data:`MAX_INT_DIGITS` digits,
    and strings or keys holding lone surrogates. The caller checks the types
    of the values it takes.

    Parameters
    ----------
    what : str, optional
        What the JSON is ("metadata block"): messages then read ``"WHAT is
        not UTF-8 JSON: ..."``.
    path, record
        Where it is (the file, and a record in it); a refused value adds its
        key path (``photos[0].Xo``) to the record, a syntax error its line
        and column.

    >>> loads_json('{"a": [1, 2.5, "x"]}', "metadata")
    {'a': [1, 2.5, 'x']}
    >>> loads_json('{"photos": [{"Xo": 1e400}]}', path="o.json")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    apygis.errors.FormatError: o.json: photos[0].Xo: the number 1e400 is out of range: ...
    """

    def fail(why: str, where: str | None = None) -> NoReturn:
        at = ": ".join(w for w in (record, where) if w) or None
        msg = f"{what} is not UTF-8 JSON: {why}" if what else why
        raise FormatError(msg, path=path, record=at)

    if isinstance(text, bytes | bytearray | memoryview):
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError as exc:
            fail(f"not UTF-8 text ({exc.reason} at byte {exc.start})")
    depth = _json_depth(text)
    if depth > MAX_JSON_DEPTH:
        fail(
            f"JSON nested {depth} deep: arrays and objects nested too deeply "
            f"(at most {MAX_JSON_DEPTH} levels)"
        )
    try:
        value = json.loads(
            text,
            parse_constant=_parse_constant,
            parse_int=_parse_int,
            parse_float=_parse_float,
        )
    except json.JSONDecodeError as exc:
        fail(f"invalid JSON: {exc.msg}", f"line {exc.lineno} column {exc.colno}")
    except RecursionError:  # pragma: no cover - the depth check comes first
        fail(f"JSON nested too deeply (at most {MAX_JSON_DEPTH} levels)")
    except ValueError as exc:  # pragma: no cover - the hooks do not raise
        fail(f"invalid JSON ({exc})")
    _check_tree(value, what or "a JSON string", fail, path, record)
    return value


def _check_tree(value, what: str, fail, path, record) -> None:
    """Refused numbers and lone surrogates, with their key paths (iteratively)."""
    stack = [(value, "")]
    while stack:
        v, where = stack.pop()
        if isinstance(v, str):
            if _SURROGATE.search(v):
                check_str(v, what, path, ": ".join(w for w in (record, where) if w) or None)
        elif isinstance(v, _Refused):
            fail(v.reason, where or None)
        elif isinstance(v, dict):
            items = []
            for k, x in v.items():
                kw = f"{where}.{k}" if where else str(k)
                if _SURROGATE.search(k):
                    check_str(k, what, path, ": ".join(w for w in (record, where) if w) or None)
                items.append((x, kw))
            stack.extend(reversed(items))
        elif isinstance(v, list):
            stack.extend(reversed([(x, f"{where}[{i}]") for i, x in enumerate(v)]))
