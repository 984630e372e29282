"""File helpers of the drivers: atomic writes of file sets, set stamps, CRS units.

The atomic write itself, the target checks, the guarded read and the guarded
JSON are :mod:`apygis.fileio` (the floor every layer shares; its names are
re-exported here); this module adds what is format-specific. Every writer
goes through :func:`atomic_write_many` (bytes in memory) or :func:`commit`
(files a library such as GDAL wrote into a temporary folder):

* the target is resolved through symlinks (the file a link points to is
  written, the link stays) and must be a regular file or not exist: a device,
  a directory or a pipe is refused (:class:`~apygis.errors.FileOverwriteError`);
* every file is written in full to a temporary file beside its final target
  (same directory: the rename cannot cross file systems), flushed and synced;
  a new file gets the umask's default mode, a replaced file keeps its mode;
* a set of several files (an APY map, a Shapefile folder, a GENERATE set)
  gets a **set stamp** ``.NAME.apyset``, written (atomically) *before* the
  files are renamed into place, listing every file of the new set with its
  size and SHA-256, and the files it replaces as they were. A reader calls
  :func:`verify_set`: a crash at any moment leaves either the old set with
  its old stamp (or none), or the new stamp with the files all old, all new,
  or part new and part old, which the read refuses, naming them;
* any ``OSError`` (a full disk, no permission) becomes one
  :class:`~apygis.errors.WriteError` naming the target and the reason, with
  the temporary files removed;
* temporary files and folders left by a write that was killed (their names
  carry the writing process's id) are removed by the next write to the same
  place.
"""

from __future__ import annotations

import errno
import hashlib
import json
import logging
import math
import os
import secrets
import stat
import time
from collections.abc import Iterable
from pathlib import Path

from apygis.errors import FormatError, WriteError
from apygis.fileio import (
    TEMP_DIR_PREFIX,
    check_target,
    discard,
    fsync_dir,
    loads_json,
    prepare,
    read_bytes,
    remove_stale_temps,
    replace_all,
    write_failed,
)

__all__ = [
    "STAMP_SUFFIX",
    "atomic_write_many",
    "check_resolution",
    "check_target",
    "commit",
    "crs_unit",
    "diagnose_write_failure",
    "make_temp_dir",
    "metres_per_unit",
    "read_bytes",
    "remove_stale_temps",
    "stamp_entries",
    "stamp_path",
    "verify_set",
    "write_failed",
]

log = logging.getLogger(__name__)

STAMP_SUFFIX = ".apyset"
"""A set stamp is ``.NAME.apyset`` (hidden) beside the files of the set ``NAME``."""
STAMP_FORMAT = "apygis-set"


def diagnose_write_failure(folder) -> OSError | None:
    """The ``OSError`` behind a library's failed write into ``folder``, where one can be told.

    GDAL and SQLite report a full disk as whatever failed next ("no such
    table: gpkg_contents", "failed to commit transaction"). This looks at the
    file system of ``folder`` (no space left) and at the process's file size
    limit (``ulimit -f``) against the files written there. None: neither.
    """
    import contextlib
    import resource

    d = Path(folder)
    try:
        st = os.statvfs(d)
        if st.f_bavail * st.f_frsize < 64 * 1024:
            return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        if st.f_favail == 0 and st.f_files:
            return OSError(errno.ENOSPC, "no free inodes left on device")
    except OSError:
        pass
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY:
        with contextlib.suppress(OSError):
            biggest = max((p.stat().st_size for p in d.rglob("*") if p.is_file()), default=0)
            if biggest + 64 * 1024 >= soft:
                return OSError(
                    errno.EFBIG, f"File too large (the process's file size limit is {soft} bytes)"
                )
    return None


def stamp_path(base) -> Path:
    """The set stamp ``dir/.NAME.apyset`` of the set ``dir/NAME``."""
    b = Path(base)
    return b.with_name(f".{b.name}{STAMP_SUFFIX}")


def make_temp_dir(directory) -> Path:
    """A new temporary folder in ``directory`` with a name :func:`remove_stale_temps` knows."""
    d = Path(directory)
    while True:
        tmp = d / f"{TEMP_DIR_PREFIX}{os.getpid()}-{secrets.token_hex(4)}.tmp"
        try:
            tmp.mkdir(mode=0o700)
            return tmp
        except FileExistsError:  # pragma: no cover - 32 random bits
            continue


# --------------------------------------------------------------------------- writing


def atomic_write_many(
    contents: dict, stamp=None, *, complete: bool = True, remove: Iterable = ()
) -> list[Path]:
    """Write several files so that none is ever half-written.

    Parameters
    ----------
    contents : dict of path -> bytes
        The files to write.
    stamp : path, optional
        The set stamp of a multi-file set (``NAME.apyset``). With
        ``complete`` (the whole set is written), the stamp lists exactly these
        files; otherwise (some files of a set are replaced) an existing stamp
        is updated for them, and none is made where there was none.
    remove : iterable of path
        Files of the set that the new set no longer has; removed after the
        renames (the stamp, written first, no longer lists them).

    Returns
    -------
    list of Path
        The targets, as given.
    """
    pairs = prepare(contents, parents=True)
    try:
        entries = (
            {Path(t).name: _entry(data) for t, data in contents.items()}
            if stamp is not None
            else {}
        )
        commit(pairs, stamp, entries, complete=complete, remove=remove)
    except BaseException:
        discard(pairs)
        raise
    return [Path(t) for t in contents]


def _entry(data: bytes) -> dict:
    return {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def _identity(path: Path) -> dict:
    """``{ino, mtime_ns}`` of a file: who it is, as long as nobody rewrote it.

    As strings: nanosecond times have 19 digits, more than the guarded JSON
    reader takes as a number.
    """
    try:
        st = os.stat(path)
    except OSError:
        return {}
    return {"ino": str(st.st_ino), "mtime_ns": str(st.st_mtime_ns)}


def _file_entry(path: Path) -> dict:
    h = hashlib.sha256()
    size = 0
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            h.update(chunk)
            size += len(chunk)
    return {"size": size, "sha256": h.hexdigest()}


def stamp_entries(files: dict) -> dict:
    """Stamp entries ``{name: {size, sha256}}`` of files on disk (``{name: path}``)."""
    return {name: _file_entry(Path(p)) for name, p in files.items()}


def commit(
    pairs: list,
    stamp=None,
    entries: dict | None = None,
    *,
    complete: bool = True,
    remove: Iterable = (),
) -> None:
    """Rename written temporary files over their targets, stamping the set first.

    ``pairs`` are ``(temporary file, real target, target as named)``; the
    temporary files are complete and synced. ``entries`` are the stamp entries
    of the new files (by name). Any ``OSError`` is a :class:`WriteError`
    naming the target; one during the renames also says the set is now
    inconsistent (the stamp tells a reader so).
    """
    stamp_path = None
    remove = [Path(p) for p in remove]
    if stamp is not None:
        stamp_path = check_target(stamp)
        old = _read_stamp(stamp_path) if stamp_path.exists() else None
        if complete or old is not None:
            files = {} if complete or old is None else dict(old.get("files", {}))
            for p in remove:
                files.pop(p.name, None)
            files.update(entries or {})
            # the file's identity after the rename (a rename keeps the inode and the
            # modification time), so that a reader need not hash an untouched set
            for tmp, real, _ in pairs:
                if isinstance(files.get(real.name), dict):
                    files[real.name] = {**files[real.name], **_identity(Path(tmp))}
            # what each touched file is now (null: none), so that a reader can tell
            # the files this write replaced from those it did not get to
            # a partial write keeps what the last stamp knew of the other files, so
            # that an earlier interrupted write is not hidden by this one
            before = {} if complete or old is None else dict(old.get("before", {}))
            for real in [real for _, real, _ in pairs] + remove:
                try:
                    before[real.name] = _file_entry(real) if real.is_file() else None
                except OSError:
                    before[real.name] = None
            _write_stamp(stamp_path, files, before, Path(stamp))
        else:
            stamp_path = None

    def incomplete(err: WriteError, done: int) -> WriteError | None:
        if not done or stamp_path is None:
            return None
        more = WriteError(
            f"{err}; {done} of {len(pairs)} files of the set were replaced, so "
            f"{stamp_path.name} now marks the set as incomplete: write it again"
        )
        more.errno, more.strerror, more.filename = err.errno, err.strerror, err.filename
        return more

    replace_all(pairs, incomplete)
    for p in remove:
        if p.is_file() and all(p != real for _, real, _ in pairs):
            log.info("removing %s: not part of the set just written", p)
            try:
                os.unlink(p)
            except OSError as exc:
                raise write_failed(p, exc, "cannot remove the old file") from None
    for d in {p.parent for p in remove}:
        fsync_dir(d)


def _write_stamp(real: Path, files: dict, before: dict, named: Path) -> None:
    doc = {
        "format": STAMP_FORMAT,
        "version": 1,
        "write_id": secrets.token_hex(8),
        "written": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "files": dict(sorted(files.items())),
        "before": dict(sorted(before.items())),
    }
    data = (json.dumps(doc, indent=1) + "\n").encode("utf-8")
    replace_all(prepare({named: data}))


def _read_stamp(path: Path) -> dict:
    try:
        doc = loads_json(read_bytes(path), "set stamp", path)
    except FormatError:
        doc = None
    if (
        not isinstance(doc, dict)
        or doc.get("format") != STAMP_FORMAT
        or not isinstance(doc.get("files"), dict)
        or not isinstance(doc.get("before", {}), dict)
    ):
        raise FormatError(
            "not an apygis set stamp (JSON with format apygis-set and files); "
            "delete it to read the files of the set as they are",
            path=path,
        )
    return doc


# --------------------------------------------------------------------------- reading


def verify_set(stamp, members: Iterable, complete: bool = True) -> None:
    """Refuse a set that an interrupted write left part new, part old.

    The stamp lists the files of the set as the last write made them and as
    they were before it (``before``: the files it replaced or removed; null
    for one that did not exist). Each file of the set is new (as listed), old
    (as before) or neither (changed since by another program: left to the
    reader). A set with both new and old files was left half-replaced by a
    write that was killed or failed during its renames.

    Parameters
    ----------
    stamp : path
        ``.NAME.apyset``; without one there is nothing to check.
    members : iterable of path
        The files a reader takes as the set.
    complete : bool
        False when one file of the set is read: one file is always whole
        (it was renamed into place in one step), so nothing is checked.

    Raises
    ------
    FormatError
        Naming the files that are new and those that are still old.
    """
    stamp = Path(stamp)
    if not complete or not stamp.is_file():
        return
    doc = _read_stamp(stamp)
    files: dict = doc["files"]
    before: dict = doc.get("before", {})
    folder = stamp.parent
    names = set(files) | set(before) | {Path(p).name for p in members}
    new, old = [], []
    for name in sorted(names):
        p = folder / name
        cur = _Current(p)
        is_new = cur.matches(files.get(name))
        is_old = cur.matches(before[name]) if name in before else is_new
        if is_new and not is_old:
            new.append(name)
        elif is_old and not is_new:
            old.append(name)
        elif not is_new:
            log.debug("%s: neither as written at %s nor as before", p, doc.get("written"))
    if new and old:
        raise FormatError(
            f"the write of {doc.get('written', '?')} was interrupted: {_names(new)} "
            f"{'is' if len(new) == 1 else 'are'} new, but {_names(old)} "
            f"{'is' if len(old) == 1 else 'are'} still as before (old, or missing), so the "
            "files do not make one map; write the set again (or delete "
            f"{stamp.name} to read the files as they are)",
            path=stamp,
        )


class _Current:
    """A file as it is now, hashed only when its size matches and its identity does not.

    A stamp entry that carries the file's identity (inode and modification
    time, kept by the rename that put it in place) matches an untouched file
    without reading it; a copied set (new inodes) is compared by its hashes.
    """

    def __init__(self, p: Path):
        self.p = p
        self.size: int | None = None
        self.ident: tuple[str, str] | None = None
        try:
            st = os.stat(p)
        except OSError:
            st = None
        if st is not None and stat.S_ISREG(st.st_mode):
            self.size = st.st_size
            self.ident = (str(st.st_ino), str(st.st_mtime_ns))
        self._hash: str | None = None

    def matches(self, e: dict | None) -> bool:
        if e is None or self.size is None:
            return e is None and self.size is None
        if not isinstance(e, dict) or e.get("size") != self.size:
            return False
        if self._hash is None and self.ident == (e.get("ino"), e.get("mtime_ns")):
            self._hash = e.get("sha256")  # the very file that was written, unread
            return True
        if self._hash is None:
            try:
                self._hash = _file_entry(self.p)["sha256"]
            except OSError:
                return False
        return self._hash == e.get("sha256")


def _names(names: list[str]) -> str:
    names = sorted(set(names))
    return ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")


# --------------------------------------------------------------------------- CRS units


def crs_unit(crs) -> tuple[str, float, bool]:
    """``(unit name, metres per unit, geographic)`` of a CRS's first (X) axis.

    For angular units the metres are those of an arc of one unit along the
    equator (111.3 km for a degree on WGS 84).

    >>> crs_unit("EPSG:2056")
    ('metre', 1.0, False)
    >>> name, m, geo = crs_unit("EPSG:4326"); name, round(m), geo
    ('degree', 111319, True)
    """
    from pyproj import CRS

    c = crs if isinstance(crs, CRS) else CRS.from_user_input(crs)
    axes = c.axis_info
    if not axes:
        return "metre", 1.0, False
    ax = axes[0]
    factor = float(ax.unit_conversion_factor or 1.0)
    if c.is_geographic or ax.unit_name in ("degree", "radian", "grad", "arc-second"):
        ell = c.ellipsoid
        a = float(ell.semi_major_metre) if ell is not None else 6378137.0
        return ax.unit_name, a * factor, True
    return ax.unit_name, factor, False


def metres_per_unit(crs) -> float:
    """Metres of one CRS unit (1 for metres, 0.3048 for feet, ~111 km for a degree)."""
    return crs_unit(crs)[1]


_SYMBOL = {"degree": "°", "metre": " m", "foot": " ft", "US survey foot": " ftUS"}


def _length(m: float) -> str:
    if m >= 1000:
        return f"{m / 1000:.3g} km"
    if m >= 1:
        return f"{m:.3g} m"
    return f"{m * 100:.3g} cm"


def check_resolution(
    map_, path, step: float, what: str, limit_m: float = 0.01, hint: str | None = None
) -> None:
    """Refuse a map whose CRS unit makes ``step`` (in CRS units) coarser than ``limit_m``.

    ``what`` says how the format stores coordinates ("APY ASCII stores
    coordinates in hundredths of a unit"). A map without a CRS is taken to be
    in metres, as apygis's model is.
    """
    crs = getattr(map_, "crs", None)
    if crs is None:
        return
    name, m_per_unit, geographic = crs_unit(crs)
    lost = step * m_per_unit
    if lost <= limit_m * (1 + 1e-9):
        return
    from apygis.model.map import crs_string

    unit = "degrees" if name == "degree" else f"{name}s"
    sym = _SYMBOL.get(name, f" {name}")
    step_txt = f"{step:g}{sym}"
    if hint is None:
        hint = "choose a projected CRS" if geographic else "choose a CRS in metres or feet"
    raise FormatError(
        f"{what}; {crs_string(crs)} is in {unit}, so {step_txt} ≈ {_length(lost)} "
        f"would be lost: {hint}",
        path=path,
    )


def significant_step(values, digits: int) -> float:
    """The step of ``digits`` significant decimal digits at the largest ``|value|``."""
    import numpy as np

    v = np.asarray(values, dtype=np.float64)
    top = float(np.abs(v).max()) if v.size else 0.0
    if not math.isfinite(top) or top == 0.0:
        return 0.0
    return 10.0 ** (math.floor(math.log10(top)) - (digits - 1))
