"""The driver registry: read and write maps by format name or file extension.

A driver is one module that defines a :class:`Driver` named ``DRIVER``. Every
driver, built-in or third-party, is registered through the entry-point group
``apygis.drivers``::

    [project.entry-points."apygis.drivers"]
    myformat = "mypackage.myformat:DRIVER"

Choosing a driver for a path (when none is named):

1. an existing file whose content a driver recognises (``probe``) — content
   beats name, so an APY layer file ``ID.gen`` is still read as APY;
2. the path's extension, among the drivers' ``extensions``;
3. a driver whose ``probe`` accepts the path otherwise (the APY native driver
   accepts ``dir/ID``, naming all layer files ``dir/ID.*`` of a map);
4. for writing, a path without a known extension goes to the APY native
   driver (``dir/ID`` writes every layer, ``dir/ID.r`` one).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from apygis.errors import ApygisError, DriverError

__all__ = [
    "DRIVER_GROUP",
    "Driver",
    "driver_for",
    "drivers",
    "get_driver",
    "read",
    "verify_set",
    "write",
]

log = logging.getLogger(__name__)

DRIVER_GROUP = "apygis.drivers"

# The built-in drivers, as pyproject.toml registers them; loaded directly only
# when apygis runs from a source tree that was never installed.
_BUILTIN = {
    "apy": "apygis.formats.apy:DRIVER",
    "ascii": "apygis.formats.ascii:DRIVER",
    "dxf": "apygis.formats.dxf:DRIVER",
    "generate": "apygis.formats.arcinfo:DRIVER",
    "e00": "apygis.formats.e00:DRIVER",
    "patb": "apygis.formats.patb:DRIVER",
    "bluh": "apygis.formats.bluh:DRIVER",
    "gpkg": "apygis.formats.ogr:GPKG",
    "shp": "apygis.formats.ogr:SHP",
    "geojson": "apygis.formats.ogr:GEOJSON",
    "fgb": "apygis.formats.ogr:FGB",
}


@dataclass(frozen=True)
class Driver:
    """What a format driver declares.

    Attributes
    ----------
    name : str
        Short name used with ``--driver`` (``"apy"``, ``"gpkg"``).
    description : str
        One line for ``apygis formats``.
    extensions : tuple of str
        File extensions, lower case, without the dot.
    reader : callable, optional
        ``reader(path, **options) -> MapFile``.
    writer : callable, optional
        ``writer(map, path, **options) -> list[Path]`` (the files written).
        Readers and writers take ``progress=None``, called as
        ``progress(done, total)`` (:mod:`apygis.progress`).
    probe : callable, optional
        ``probe(path) -> bool``: True if ``path`` holds (or names) data of this format.
    outputs : callable, optional
        ``outputs(map, path) -> list[Path]``: the files a write would create, so
        that the CLI can refuse to overwrite them. Default: ``[path]``.
    members : callable, optional
        For formats that write a set of files: ``members(path) -> (stamp,
        files, complete)`` or None, the set stamp and the files a read of
        ``path`` takes (``complete``: all of the set, not one file of it);
        :func:`read` checks them with :func:`apygis.formats._io.verify_set`.
    """

    name: str
    description: str
    extensions: tuple[str, ...] = ()
    reader: Callable | None = None
    writer: Callable | None = None
    probe: Callable | None = None
    outputs: Callable | None = None
    members: Callable | None = None

    @property
    def modes(self) -> str:
        return ("r" if self.reader else "") + ("w" if self.writer else "")

    def function(self, mode: str) -> Callable:
        """The ``reader`` (mode ``"r"``) or ``writer`` (``"w"``); DriverError if it has none.

        For a driver chosen by :func:`get_driver` or :func:`driver_for` with
        that mode the function is there (they check it).
        """
        func = self.reader if mode == "r" else self.writer
        if func is None:
            what = "read" if mode == "r" else "write"
            raise DriverError(f"the {self.name} driver cannot {what}")
        return func

    def targets(self, map_, path) -> list[Path]:
        if self.outputs is not None:
            return [Path(p) for p in self.outputs(map_, path)]
        return [Path(path)]


_cache: dict[str, Driver] | None = None


def _load(name: str, value: str) -> Driver | None:
    import importlib

    mod, _, attr = value.partition(":")
    try:
        drv = getattr(importlib.import_module(mod), attr)
    except ModuleNotFoundError as exc:
        if exc.name == mod:  # a stale registration: the module is gone, nothing is broken
            log.debug("driver %s: module %s is not installed", name, mod)
            return None
        log.warning("driver %s (%s) failed to load: %s", name, value, exc)
        return None
    except Exception as exc:
        log.warning("driver %s (%s) failed to load: %s", name, value, exc)
        return None
    if not isinstance(drv, Driver):
        log.warning("driver %s (%s) is not an apygis Driver", name, value)
        return None
    return drv


def drivers() -> dict[str, Driver]:
    """All drivers by name, in name order.

    Loaded from the ``apygis.drivers`` entry points. When apygis runs from a
    source tree that was never installed (no entry points), the built-in
    drivers are loaded directly.
    """
    global _cache
    if _cache is None:
        found: dict[str, Driver] = {}
        for ep in entry_points(group=DRIVER_GROUP):
            drv = _load(ep.name, ep.value)
            if drv is not None:
                found[drv.name] = drv
        for name, value in _BUILTIN.items():
            if name not in found:
                log.debug("built-in driver %s not registered; loading it directly", name)
                drv = _load(name, value)
                if drv is not None:
                    found[drv.name] = drv
        _cache = dict(sorted(found.items()))
    return _cache


def get_driver(name: str, mode: str | None = None) -> Driver:
    """The driver called ``name``; ``mode`` ``"r"`` or ``"w"`` must be supported."""
    drvs = drivers()
    try:
        drv = drvs[name.lower()]
    except KeyError:
        raise DriverError(f"no driver named {name!r}; known drivers: {', '.join(drvs)}") from None
    if mode and mode not in drv.modes:
        what = "read" if mode == "r" else "write"
        raise DriverError(f"the {drv.name} driver cannot {what}")
    return drv


def driver_for(path, mode: str) -> Driver:
    """The driver for ``path`` in ``mode`` (``"r"`` or ``"w"``), by the rules above."""
    p = Path(path)
    candidates = [d for d in drivers().values() if mode in d.modes]
    if mode == "r" and not p.exists():
        for d in candidates:  # names that stand for several files (dir/ID of APY layers)
            if d.probe is not None and _safe_probe(d, p):
                return d
        raise DriverError(f"{p}: no such file (nor a map of APY layer files {p}.*)")
    if mode == "r" and p.is_file():
        for d in candidates:
            if d.probe is not None and _safe_probe(d, p):
                return d
    ext = p.suffix[1:].lower()
    if ext:
        for d in candidates:
            if ext in d.extensions:
                return d
    for d in candidates:
        if d.probe is not None and _safe_probe(d, p):
            return d
    if mode == "w" and "apy" in drivers():
        return drivers()["apy"]
    exts = sorted({e for d in candidates for e in d.extensions})
    raise DriverError(
        f"{p}: no driver recognises this file; known extensions: {', '.join(exts)} "
        "(or name one with driver=...)"
    )


def _safe_probe(d: Driver, p: Path) -> bool:
    if d.probe is None:
        return False
    try:
        return bool(d.probe(p))
    except OSError:
        return False


def read(path, driver: str | None = None, **options):
    """Read a map.

    Parameters
    ----------
    path : str or os.PathLike
        The file (or, for the APY native format, ``dir/ID`` for all layers).
    driver : str, optional
        A driver name; by default chosen from the content and the extension.
    **options
        Passed to the driver (``progress=callable(done, total)`` for long reads).

    Returns
    -------
    MapFile
    """
    drv = get_driver(driver, "r") if driver else driver_for(path, "r")
    log.debug("reading %s with the %s driver", path, drv.name)
    verify_set(drv, path)
    return drv.function("r")(os.fspath(path), **options)


def verify_set(drv: Driver, path) -> None:
    """Refuse to read a set of files that an interrupted write left half-replaced.

    For drivers that write sets (:attr:`Driver.members`): the files a read of
    ``path`` takes are checked against the set stamp ``NAME.apyset`` the
    writer made (:func:`apygis.formats._io.verify_set`); a
    :class:`~apygis.errors.FormatError` names the files that do not match.
    """
    if drv.members is None:
        return
    from apygis.formats._io import verify_set as _verify

    try:
        spec = drv.members(os.fspath(path))
    except OSError:
        return  # the reader reports an unreadable path itself
    if spec is not None:
        stamp, files, complete = spec
        _verify(stamp, files, complete)


def write(map, path, driver: str | None = None, **options) -> list[Path]:
    """Write a map, atomically (each file is written beside its target, then renamed).

    Existing files are replaced; the CLI refuses that unless ``--overwrite``.
    Only regular files are replaced (a symlink is written through). A set of
    files gets a set stamp (see :mod:`apygis.formats._io`). Any ``OSError``
    is a :class:`~apygis.errors.WriteError` naming the target.
    ``**options`` go to the driver (``progress(done, total)``, :mod:`apygis.progress`).
    Returns the paths written.
    """
    drv = get_driver(driver, "w") if driver else driver_for(path, "w")
    log.debug("writing %s with the %s driver", path, drv.name)
    try:
        out = drv.function("w")(map, os.fspath(path), **options)
    except ApygisError:
        raise
    except OSError as exc:  # a driver's own file handling: name the target, not the source
        from apygis.formats._io import write_failed

        raise write_failed(exc.filename or path, exc) from None
    return [Path(p) for p in (out or [path])]
