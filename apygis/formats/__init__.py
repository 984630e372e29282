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
    "READ_OPTIONS",
    "Driver",
    "Option",
    "driver_for",
    "drivers",
    "get_driver",
    "parse_options",
    "read",
    "select_layers",
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


_TRUE = {"yes", "true", "on", "1"}
_FALSE = {"no", "false", "off", "0"}


@dataclass(frozen=True)
class Option:
    """An option a driver's reader (mode ``"r"``) or writer (``"w"``) takes.

    ``name`` is the keyword of the reader or writer function (lower case);
    on the command line it is ``--co NAME=VALUE`` in any case. ``kind`` is
    ``"bool"`` (YES/NO, TRUE/FALSE, ON/OFF, 1/0), ``"int"``, ``"float"``,
    ``"str"`` or ``"choice"`` (one of ``choices``, compared without regard
    to case); ``low`` and ``high`` bound numbers (inclusive). Options with
    ``flag`` have a command-line option of their own (``--snap``), which is
    what messages name.
    """

    name: str
    mode: str
    kind: str
    help: str
    choices: tuple[str, ...] = ()
    low: float | None = None
    high: float | None = None
    flag: str | None = None

    def parse(self, text: str, shown: str):
        """The value of ``text`` (as typed: ``shown`` names it in the message)."""
        t = text.strip()
        try:
            if self.kind == "bool":
                if t.lower() in _TRUE:
                    return True
                if t.lower() in _FALSE:
                    return False
                raise ValueError
            if self.kind == "int":
                value: object = int(t)
            elif self.kind == "float":
                value = float(t)
                if value != value or value in (float("inf"), float("-inf")):
                    raise ValueError
            elif self.kind == "choice":
                match = [c for c in self.choices if c.lower() == t.lower()]
                if not match:
                    raise ValueError
                return match[0]
            else:
                return text
        except ValueError:
            raise DriverError(f"{shown}: {self.expects()}, not {text!r}") from None
        if (self.low is not None and value < self.low) or (  # type: ignore[operator]
            self.high is not None and value > self.high  # type: ignore[operator]
        ):
            raise DriverError(f"{shown}: {self.expects()}, not {text!r}")
        return value

    def expects(self) -> str:
        if self.kind == "bool":
            return "YES or NO expected"
        if self.kind == "choice":
            return f"one of {', '.join(self.choices)} expected"
        what = "a whole number" if self.kind == "int" else "a number"
        if self.low is not None and self.high is not None:
            return f"{what} from {self.low:g} to {self.high:g} expected"
        if self.low is not None:
            return f"{what} >= {self.low:g} expected"
        return f"{what} expected"


READ_OPTIONS = {
    "layers": Option(
        "layers", "r", "str", "source layers to read (a list of names)", flag="--layer"
    ),
    "layer_map": Option(
        "layer_map", "r", "str", "source layer -> map layer (NAME=ext,...)", flag="--layer-map"
    ),
    "tolerance_m": Option(
        "tolerance_m",
        "r",
        "float",
        "distance in metres within which line ends join (topology rebuild)",
        low=0.0,
        flag="--snap",
    ),
    "crs": Option("crs", "r", "str", "the CRS of data that has none", flag="--src-crs"),
    "code_field": Option(
        "code_field", "r", "str", "attribute holding the code 0-99", flag="--code-field"
    ),
    "default_code": Option(
        "default_code",
        "r",
        "int",
        "code of features whose code is missing or not 0-99",
        low=0,
        high=99,
        flag="--default-code",
    ),
    "text_field": Option(
        "text_field", "r", "str", "attribute holding the text of points", flag="--text-field"
    ),
    "point_code": Option(
        "point_code",
        "r",
        "int",
        "code of points without a code or a height (default 90, imported point)",
        low=0,
        high=99,
    ),
}
"""The reading options several drivers share (a driver lists those it takes)."""


def parse_options(drv: Driver, mode: str, given: dict[str, str], shown=None) -> dict:
    """``{NAME: "VALUE"}`` as typed (``--co``) to the keywords of ``drv``'s reader or writer.

    Unknown names are refused with the options the driver has. ``shown``
    maps a name to how the user typed it (default ``--co NAME=VALUE``).
    """
    out = {}
    for name, text in given.items():
        opt = drv.option(mode, name)
        where = (shown or {}).get(name, f"--co {name.upper()}={text}")
        if opt is None:
            raise DriverError(f"{where}: {drv.no_option(mode, name, cli=True)}")
        out[opt.name] = opt.parse(text, where)
    return out


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
    options : tuple of Option
        The keywords its reader and writer take besides ``path`` and
        ``progress``; :func:`read` and :func:`write` refuse others.
    stream : bool
        The writer writes one file that can go to standard output (``-``).
    """

    name: str
    description: str
    extensions: tuple[str, ...] = ()
    reader: Callable | None = None
    writer: Callable | None = None
    probe: Callable | None = None
    outputs: Callable | None = None
    members: Callable | None = None
    options: tuple[Option, ...] = ()
    stream: bool = False

    @property
    def modes(self) -> str:
        return ("r" if self.reader else "") + ("w" if self.writer else "")

    def option(self, mode: str, name: str) -> Option | None:
        """The option ``name`` (any case) of the reader (``"r"``) or writer (``"w"``)."""
        low = name.lower()
        return next((o for o in self.options if o.mode == mode and o.name == low), None)

    def no_option(self, mode: str, name: str, cli: bool = False) -> str:
        """The message for an option ``name`` that the reader or writer does not take.

        ``cli``: the options are listed as typed at the command line (their own
        flags, else ``--co NAME``), otherwise as the keywords of the function.
        """
        verb = "reader" if mode == "r" else "writer"
        have = [
            (o.flag or f"--co {o.name.upper()}") if cli else o.name
            for o in self.options
            if o.mode == mode
        ]
        known = f"it takes {', '.join(have)}" if have else "it takes none"
        return f"the {self.name} {verb} has no option {name!r} ({known})"

    def check_options(self, mode: str, options: dict) -> None:
        """Refuse keywords the reader or writer does not declare (``progress`` is always taken)."""
        for name in options:
            if name != "progress" and self.option(mode, name) is None:
                raise DriverError(self.no_option(mode, name))

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
    what = "is a folder of no known format" if p.is_dir() else "no driver recognises this file"
    raise DriverError(f"{p}: {what}; known extensions: {', '.join(exts)} (or name a driver)")


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
    from apygis.formats._report import collecting

    drv = get_driver(driver, "r") if driver else driver_for(path, "r")
    log.debug("reading %s with the %s driver", path, drv.name)
    generic = {k: options.pop(k) for k in ("layers", "crs") if k in options}
    for k, v in generic.items():
        if drv.option("r", k) is not None and v is not None:
            options[k] = v
    drv.check_options("r", options)
    verify_set(drv, path)
    with collecting() as notes:
        m = drv.function("r")(os.fspath(path), **options)
        if generic.get("layers") is not None and "layers" not in options:
            m = select_layers(m, generic["layers"], path)
        if generic.get("crs") is not None and "crs" not in options:
            _assign_crs(m, generic["crs"], path)
    m.read_warnings = notes
    return m


def select_layers(m, names, path):
    """``m`` with only the map layers ``names`` (extensions); an unknown name is refused."""
    from apygis.model.map import check_ext

    wanted = [names] if isinstance(names, str) else list(names)
    keep = []
    for n in wanted:
        ext = n.lower() if isinstance(n, str) else n
        if ext not in m.layers:
            have = ", ".join(m.layers) or "none"
            raise DriverError(f"{path}: no layer {n!r} (its layers: {have})")
        keep.append(check_ext(ext))
    for ext in list(m.layers):
        if ext not in keep:
            del m.layers[ext]
    return m


def _assign_crs(m, crs, path) -> None:
    from apygis.formats._report import warn
    from apygis.model.map import crs_string

    old = crs_string(m.crs)
    m.crs = crs
    if old is not None and old != crs_string(m.crs):
        warn(log, f"{path}: its CRS {old} replaced by {crs_string(m.crs)}", "crs")


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
    drv.check_options("w", options)
    try:
        out = drv.function("w")(map, os.fspath(path), **options)
    except ApygisError:
        raise
    except OSError as exc:  # a driver's own file handling: name the target, not the source
        from apygis.formats._io import write_failed

        raise write_failed(exc.filename or path, exc) from None
    return [Path(p) for p in (out or [path])]
