"""Helpers shared by the command modules: error reporting and progress bars."""

from __future__ import annotations

import functools
import sys
from typing import TextIO, cast

import click

from apygis.errors import ApygisError

__all__ = [
    "map_input_options",
    "progress_bar",
    "read_map",
    "reader_for",
    "reader_options",
    "run_guarded",
    "writer_options",
]


def run_guarded(func):
    """Decorate a command so that an :class:`ApygisError` ends it with a one-line message.

    The message goes to standard error and the exit code is 1; a traceback is
    shown only with ``-vv`` (log level DEBUG).
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except ApygisError as exc:
            import logging

            logging.getLogger("apygis").debug("traceback", exc_info=True)
            raise click.ClickException(str(exc)) from exc

    return wrapper


def progress_bar(length: int, label: str):
    """A click progress bar shown on a terminal only, silent in pipes and tests.

    Returns a context manager whose ``update(n)`` advances the bar; pass
    ``bar.update`` as the library's ``progress`` callback.
    """
    return click.progressbar(
        length=length,
        label=label,
        file=sys.stderr if sys.stderr.isatty() else cast(TextIO, _Null()),
    )


class _Null:
    def write(self, s):
        return len(s)

    def flush(self):
        """Nothing is buffered."""

    def isatty(self):
        return False


# --------------------------------------------------------------------------- reading maps

#: The reading options every command that reads a map takes (``map_input_options``),
#: by the reader keyword each one fills.
INPUT_FLAGS = {
    "layers": "--layer",
    "layer_map": "--layer-map",
    "tolerance_m": "--snap",
    "crs": "--src-crs",
    "code_field": "--code-field",
    "default_code": "--default-code",
    "text_field": "--text-field",
}


def _co_pairs(ctx, param, value) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in value or ():
        name, sep, val = item.partition("=")
        if not sep or not name.strip():
            raise click.BadParameter(f"expected NAME=VALUE, not {item!r}", param_hint="--co")
        out[name.strip().lower()] = val
    return out


def _layer_list(ctx, param, value):
    if not value:
        return None
    names = [n.strip() for v in value for n in v.split(",") if n.strip()]
    if not names:
        raise click.BadParameter("expected layer names", param_hint="--layer")
    return names


def map_input_options(func):
    """Add the options that choose and shape how a map is read (one vocabulary everywhere).

    ``--src-driver``, ``--src-crs``, ``--layer``, ``--layer-map``, ``--snap``,
    ``--code-field``, ``--default-code``, ``--text-field`` and ``--co NAME=VALUE``;
    the command gets them as one dict ``src`` for :func:`read_map`.
    """
    options = [
        click.option(
            "--src-driver",
            metavar="NAME",
            help="Read with this driver (apygis formats) instead of guessing.",
        ),
        click.option(
            "--src-crs",
            metavar="CRS",
            help="The CRS of data that has none (DXF, GENERATE): EPSG:XXXX, WKT, PROJ.",
        ),
        click.option(
            "--layer",
            "layers",
            multiple=True,
            callback=_layer_list,
            metavar="NAME[,NAME...]",
            help="Read only these source layers (repeat or separate by commas).",
        ),
        click.option(
            "--layer-map",
            metavar="SRC=ext,...",
            help="Source layer to map layer: ROADS=r,WATER=h (ext '-' skips the layer).",
        ),
        click.option(
            "--snap",
            type=click.FloatRange(min=0.0),
            metavar="METRES",
            help="Distance on the ground within which line ends join when topology is "
            "rebuilt (converted to feet or degrees for a source in such a CRS).",
        ),
        click.option(
            "--code-field", metavar="FIELD", help="Attribute holding the code 00-99 (default code)."
        ),
        click.option(
            "--default-code",
            type=click.IntRange(0, 99),
            metavar="CODE",
            help="Code of features whose code is missing or not 00-99 (else refused).",
        ),
        click.option(
            "--text-field", metavar="FIELD", help="Attribute holding the text of points (text)."
        ),
        click.option(
            "--co",
            "co",
            multiple=True,
            callback=_co_pairs,
            metavar="NAME=VALUE",
            help="A driver option (repeat); 'apygis formats --options' lists them.",
        ),
    ]
    names = ("src_driver", "src_crs", "layers", "layer_map", "snap", "code_field",
             "default_code", "text_field", "co")  # fmt: skip

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        src = {n: kwargs.pop(n) for n in names}
        return func(*args, src=src, **kwargs)

    for opt in reversed(options):
        wrapper = opt(wrapper)
    return wrapper


def reader_for(path, src: dict):
    """The input driver: ``--src-driver`` or the one the path's content and name call for."""
    from apygis.formats import driver_for, get_driver

    name = src.get("src_driver")
    if name:
        try:
            return get_driver(name, "r")
        except ApygisError as exc:
            raise ApygisError(f"--src-driver {name}: {exc}") from None
    return driver_for(path, "r")


def reader_options(drv, src: dict, writer=None) -> dict:
    """The reader keywords of the input options given, each checked against ``drv``.

    An option the reader does not take is refused naming the option as typed;
    ``--co`` names go to the reader that declares them (with ``writer``, a
    name only the writer declares is left for it).
    """
    from apygis.errors import DriverError
    from apygis.formats import parse_options

    values = {
        "layers": src.get("layers"),
        "layer_map": src.get("layer_map"),
        "tolerance_m": src.get("snap"),
        "crs": src.get("src_crs"),
        "code_field": src.get("code_field"),
        "default_code": src.get("default_code"),
        "text_field": src.get("text_field"),
    }
    out = {}
    for key, value in values.items():
        if value is None:
            continue
        if key in ("layers", "crs"):  # every driver: the map's layers, the CRS assigned
            out[key] = value
            continue
        if drv.option("r", key) is None:
            flag = INPUT_FLAGS[key]
            raise DriverError(f"{flag}: the {drv.name} reader does not take it")
        out[key] = value
    co = dict(src.get("co") or {})
    mine = {k: v for k, v in co.items() if drv.option("r", k) is not None}
    unknown = [k for k in co if k not in mine and (writer is None or writer.option("w", k) is None)]
    if unknown:
        name = unknown[0]
        msg = drv.no_option("r", name, cli=True)
        if writer is not None:
            msg += f"; {writer.no_option('w', name, cli=True)}"
        raise DriverError(f"--co {name.upper()}={co[name]}: {msg}")
    out.update(parse_options(drv, "r", mine))
    return out


def writer_options(drv, co: dict, reader=None) -> dict:
    """The writer keywords of ``--co`` names the writer declares (others: the reader's)."""
    from apygis.formats import parse_options

    mine = {k: v for k, v in (co or {}).items() if drv.option("w", k) is not None}
    if reader is None:
        rest = {k: v for k, v in (co or {}).items() if k not in mine}
        if rest:
            from apygis.errors import DriverError

            name, value = next(iter(rest.items()))
            raise DriverError(f"--co {name.upper()}={value}: {drv.no_option('w', name, cli=True)}")
    return parse_options(drv, "w", mine)


def read_map(path, src: dict):
    """Read the map at ``path`` with the input options ``src``; returns ``(map, driver)``."""
    import apygis

    drv = reader_for(path, src)
    return apygis.read(path, driver=drv.name, **reader_options(drv, src)), drv
