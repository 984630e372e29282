"""``apygis symbols``: list, show and design the 99 point symbols.

The commands work on the user's symbol library (``$APYGIS_SYMBOLS`` or
``~/.config/apygis/symbols.apysym``), or on the file given with
``--library``. Where that file does not exist yet, the default topographic
set is shown, and ``set`` creates the file from it on the first change.
"""

from __future__ import annotations

from pathlib import Path
from typing import cast

import click

from apygis.cli._common import run_guarded
from apygis.formats._readguard import ascii_int
from apygis.model.symbols import (
    SIZE,
    SPOT_HEIGHT,
    SymbolLibrary,
    load_library,
    user_library_path,
)

__all__ = ["symbols"]

CODE = click.IntRange(0, 99)


class _Cell(click.ParamType):
    """A cell given as ``ROW,COL``, 1-based; converted to a 0-based tuple."""

    name = "ROW,COL"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        parts = str(value).replace(" ", "").split(",")
        nums = [ascii_int(p, max_digits=2) for p in parts]  # no '²', no 5000-digit strings
        if len(parts) != 2 or None in nums:
            self.fail(f"{value!r} is not ROW,COL (two whole numbers 1-15, e.g. 8,8)", param, ctx)
        row, col = cast(list[int], nums)  # no None: checked above
        if not (1 <= row <= SIZE and 1 <= col <= SIZE):
            self.fail(
                f"{value!r} is off the 15x15 grid; rows and columns run from 1 to 15",
                param,
                ctx,
            )
        return row - 1, col - 1


def _library_option(func):
    return click.option(
        "--library",
        "library_path",
        type=click.Path(path_type=Path),  # a directory is refused by load_library
        default=None,
        help="The symbol library file to use instead of the user library "
        "($APYGIS_SYMBOLS or ~/.config/apygis/symbols.apysym).",
    )(func)


def _load(library_path: Path | None) -> tuple[SymbolLibrary, Path]:
    """The library and its path; a path that cannot be read is a FormatError (run_guarded)."""
    path = user_library_path() if library_path is None else library_path
    lib = load_library(path)
    if library_path is not None and not path.exists():
        click.echo(f"note: {path} does not exist; using the default symbol set", err=True)
    return lib, path


@click.group("symbols")
def symbols() -> None:
    """The symbol library: 99 named 15x15 point symbols, codes 01-99.

    Code 00 is reserved for the spot height (a tiny cross and its height)
    and cannot be changed. Free codes are named "free" and have an empty
    bitmap, ready to be designed with `apygis symbols set`.
    """


@symbols.command("list")
@_library_option
@run_guarded
def list_(library_path: Path | None) -> None:
    """List the codes 00-99 with their names and painted-cell counts."""
    lib, _ = _load(library_path)
    for code in lib:
        sym = lib[code]
        if sym.is_free:
            click.echo(f"{code:02d}  free")
            continue
        note = "  (reserved)" if sym.is_reserved else ""
        click.echo(f"{code:02d}  {sym.name:<24}  {sym.painted:3d} cells{note}")


@symbols.command("show")
@click.argument("code", type=CODE)
@_library_option
@run_guarded
def show(code: int, library_path: Path | None) -> None:
    """Draw symbol CODE (0-99) as a 15x15 chessboard with its name.

    Rows and columns are numbered 1-15, as `apygis symbols set` takes them.
    """
    lib, _ = _load(library_path)
    click.echo(lib.render(code))


@symbols.command("set")
@click.argument("code", type=CODE)
@click.option("--name", help="A new name, 1-24 printable characters.")
@click.option(
    "--paint",
    "paint",
    type=_Cell(),
    multiple=True,
    help="Paint the cell at ROW,COL (1-based, 1-15). Repeatable.",
)
@click.option(
    "--clear",
    "clear",
    type=_Cell(),
    multiple=True,
    help="Clear the cell at ROW,COL (1-based, 1-15). Repeatable.",
)
@click.option("--blank", is_flag=True, help="Clear every cell first.")
@click.option("--dry-run", is_flag=True, help="Show the result but do not save it.")
@_library_option
@run_guarded
def set_(
    code: int,
    name: str | None,
    paint: tuple[tuple[int, int], ...],
    clear: tuple[tuple[int, int], ...],
    blank: bool,
    dry_run: bool,
    library_path: Path | None,
) -> None:
    """Name or draw symbol CODE (1-99) and save it in the library.

    Rows and columns are 1-based, 1-15, row 1 at the top: `--paint 8,8`
    paints the centre cell. The changes apply in this order: --blank,
    --name, --paint, --clear. The resulting symbol is printed for approval.
    The user library is created from the default set on the first change.
    Symbol 00, the spot height, is reserved and cannot be changed.
    """
    if code == SPOT_HEIGHT:
        raise click.ClickException(
            "symbol 00 is reserved for the spot height and cannot be changed"
        )
    if name is None and not paint and not clear and not blank:
        raise click.UsageError("nothing to change: give --name, --paint, --clear or --blank")
    lib, path = _load(library_path)
    if blank:
        lib.set_bitmap(code, ["." * SIZE] * SIZE)
    if name is not None:
        lib.set_name(code, name)
    for row, col in paint:
        lib.paint(code, row, col)
    for row, col in clear:
        lib.clear(code, row, col)
    click.echo(lib.render(code))
    if dry_run:
        click.echo("(dry run: not saved)")
        return
    try:
        if library_path is None:
            path.parent.mkdir(parents=True, exist_ok=True)
        lib.write(path)
    except OSError as exc:
        raise click.ClickException(f"cannot write {path}: {exc.strerror or exc}") from exc
    click.echo(f"saved to {path}")
