"""The symbol library: 99 named point symbols drawn on 15x15 bitmaps.

APY compiles point features with a two-digit code, 00 to 99. Code 00 is the
spot height, "a tiny cross and its height": it is reserved and can never be
changed. Codes 01 to 99 are the 99 named items the operator chooses from; each
has a name of 1 to 24 printable characters and a 15x15 bitmap (the
"chessboard" of APY's Symbol Creation program). A code nobody has designed yet
is a *free slot*: its name is ``"free"`` and its bitmap is empty.

Bitmaps are numpy ``bool`` arrays of shape ``(15, 15)``; ``True`` is a painted
cell, row 0 is the top row and column 0 the leftmost. Rows and columns given to
this API are 0-based (the command line uses 1-based numbers).

Libraries are kept in ``.apysym`` text files (UTF-8, one block of 16 lines per
symbol, ``#`` painted and ``.`` clear), specified in
``docs/formats/symbol-library.md``. apygis ships a default topographic set in
the style of Swiss and German topographic maps (trig point, church, conifer,
...); the user's own library lives in :func:`user_library_path`, and
:func:`load_library` returns it, or the default set where there is none.

Examples
--------
>>> lib = default_library()
>>> lib[6].name
'church'
>>> lib[0].name, lib[0].is_free
('spot height', False)
>>> lib.set_name(70, "shrine")
>>> lib.paint(70, 7, 7)
>>> lib[70].painted
1
>>> SymbolLibrary.from_text(lib.to_text()) == lib
True
"""

from __future__ import annotations

import errno
import functools
import logging
import operator
import os
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import NoReturn

import numpy as np

from apygis.errors import FormatError, SymbolLibraryError
from apygis.fileio import atomic_write

__all__ = [
    "ENV_VAR",
    "FREE_NAME",
    "HEADER",
    "IMPORTED_POINT",
    "MAX_NAME_LENGTH",
    "NCODES",
    "SIZE",
    "SPOT_HEIGHT",
    "SPOT_HEIGHT_SYMBOL",
    "Symbol",
    "SymbolLibrary",
    "default_library",
    "load_library",
    "user_library_path",
]

log = logging.getLogger(__name__)

#: Rows and columns of a symbol bitmap.
SIZE = 15
#: Number of codes, 00 to 99.
NCODES = 100
#: The longest name a symbol may have, in characters.
MAX_NAME_LENGTH = 24
#: The name of a free (not yet designed) slot.
FREE_NAME = "free"
#: The first line of an ``.apysym`` file.
HEADER = "APYSYM 1"
#: The environment variable that names the user library file.
ENV_VAR = "APYGIS_SYMBOLS"

PAINT = "#"
CLEAR = "."

_SPOT_HEIGHT_NAME = "spot height"
_SPOT_HEIGHT_ROWS = (
    ".......#.......",
    ".......#.......",
    ".....#####.....",
    ".......#.......",
    ".......#.......",
)


class _UnknownCodeError(SymbolLibraryError, KeyError):
    """A code outside 00-99 (a KeyError too, so the library behaves as a mapping)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


def _spot_height_bitmap() -> np.ndarray:
    bm = np.zeros((SIZE, SIZE), dtype=bool)
    for i, row in enumerate(_SPOT_HEIGHT_ROWS):
        bm[5 + i] = [ch == PAINT for ch in row]
    bm.flags.writeable = False
    return bm


def _check_code(code) -> int:
    try:
        c = operator.index(code)
    except TypeError:
        raise _UnknownCodeError(
            f"a symbol code must be an integer 0-99, not {type(code).__name__}"
        ) from None
    if not 0 <= c < NCODES:
        raise _UnknownCodeError(f"symbol code {c} is out of range; codes run from 00 to 99")
    return c


def _name_problem(name) -> str | None:
    """Why ``name`` is not a valid symbol name, or None if it is."""
    if not isinstance(name, str):
        return f"a symbol name must be a string, not {type(name).__name__}"
    if not name:
        return "a symbol name must have 1 to 24 characters, not none"
    if len(name) > MAX_NAME_LENGTH:
        return f"a symbol name must have 1 to 24 characters, not {len(name)}"
    if not name.isprintable():
        bad = next(ch for ch in name if not ch.isprintable())
        return f"a symbol name must be printable; it contains {bad!r}"
    if name[0] == " " or name[-1] == " ":
        return "a symbol name must not begin or end with a space"
    return None


def _check_name(name) -> str:
    problem = _name_problem(name)
    if problem:
        raise SymbolLibraryError(f"{problem} (name {name!r})")
    return name


def _check_cell(row, col) -> tuple[int, int]:
    try:
        r, c = operator.index(row), operator.index(col)
    except TypeError:
        raise SymbolLibraryError(
            f"a cell is given by integer row and column, not {row!r}, {col!r}"
        ) from None
    if not (0 <= r < SIZE and 0 <= c < SIZE):
        raise SymbolLibraryError(
            f"cell (row {r}, column {c}) is off the 15x15 grid; rows and columns run from 0 to 14"
        )
    return r, c


def _as_bitmap(value) -> np.ndarray:
    """A new writable (15, 15) bool array from an array-like or 15 text rows."""
    if isinstance(value, str):
        raise SymbolLibraryError("a bitmap is a 15x15 array or a sequence of 15 text rows")
    if isinstance(value, list | tuple) and value and all(isinstance(r, str) for r in value):
        if len(value) != SIZE or any(len(r) != SIZE for r in value):
            raise SymbolLibraryError(
                "a bitmap given as text needs 15 rows of 15 characters '#' or '.'"
            )
        bad = {ch for r in value for ch in r} - {PAINT, CLEAR}
        if bad:
            raise SymbolLibraryError(
                f"a bitmap row may hold only '#' (painted) and '.' (clear), not {sorted(bad)!r}"
            )
        return np.array([[ch == PAINT for ch in r] for r in value], dtype=bool)
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged nesting and the like
        raise SymbolLibraryError(f"cannot make a 15x15 bitmap of this value: {exc}") from None
    if arr.shape != (SIZE, SIZE):
        raise SymbolLibraryError(f"a bitmap must have shape (15, 15), not {arr.shape}")
    if arr.dtype == bool:
        return arr.copy()
    if arr.dtype.kind not in "iuf" or not np.isin(arr, (0, 1)).all():
        raise SymbolLibraryError("a bitmap must hold booleans, or only the numbers 0 and 1")
    return arr != 0


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=bool, copy=True)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False, repr=False)
class Symbol:
    """One symbol of a library: its code, name and 15x15 bitmap.

    Parameters
    ----------
    code : int
        0 to 99.
    name : str
        1 to 24 printable characters, not beginning or ending with a space.
    bitmap : array_like or sequence of str
        A (15, 15) array of booleans (or of 0 and 1), row 0 at the top; or
        15 strings of 15 characters ``'#'`` (painted) and ``'.'`` (clear).
        The symbol keeps a read-only copy.

    Raises
    ------
    SymbolLibraryError
        If a field is invalid.

    Examples
    --------
    >>> s = Symbol(41, "free", np.zeros((15, 15), dtype=bool))
    >>> s.is_free, s.painted
    (True, 0)
    >>> s.bitmap.flags.writeable
    False
    >>> Symbol(5, "x", ["#" * 15] + ["." * 15] * 14).painted
    15
    """

    code: int
    name: str
    bitmap: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "code", _check_code(self.code))
        object.__setattr__(self, "name", _check_name(self.name))
        object.__setattr__(self, "bitmap", _readonly(_as_bitmap(self.bitmap)))

    @property
    def is_free(self) -> bool:
        """True for a free slot: named ``"free"`` with nothing painted."""
        return self.name == FREE_NAME and not self.bitmap.any()

    @property
    def is_reserved(self) -> bool:
        """True for code 00, the spot height, which cannot be changed."""
        return self.code == SPOT_HEIGHT

    @property
    def painted(self) -> int:
        """The number of painted cells."""
        return int(np.count_nonzero(self.bitmap))

    @property
    def rows(self) -> tuple[str, ...]:
        """The bitmap as 15 strings of ``'#'`` (painted) and ``'.'`` (clear)."""
        cells = np.where(self.bitmap, ord(PAINT), ord(CLEAR)).astype(np.uint8)
        return tuple(row.tobytes().decode("ascii") for row in cells)

    def render(self, *, base: int = 1) -> str:
        """The symbol drawn as a text chessboard with row and column numbers.

        Parameters
        ----------
        base : {1, 0}
            The number of the first row and column: 1 (as the command line
            counts) or 0 (as this API counts).

        Examples
        --------
        >>> print(SPOT_HEIGHT_SYMBOL.render().splitlines()[0])
        [00] spot height  (reserved, 9 cells painted)
        """
        if self.is_free:
            state = "free"
        else:
            state = f"{self.painted} cell{'s' if self.painted != 1 else ''} painted"
            if self.is_reserved:
                state = f"reserved, {state}"
        lines = [f"[{self.code:02d}] {self.name}  ({state})"]
        lines.append(" " * 5 + "".join(f"{c + base:>2} " for c in range(SIZE)).rstrip())
        border = "    +" + "-" * (3 * SIZE) + "+"
        lines.append(border)
        for r, row in enumerate(self.bitmap):
            cells = "".join(f" {PAINT if v else CLEAR} " for v in row)
            lines.append(f"{r + base:>3} |{cells}|")
        lines.append(border)
        return "\n".join(lines)

    def __eq__(self, other):
        if not isinstance(other, Symbol):
            return NotImplemented
        return (
            self.code == other.code
            and self.name == other.name
            and np.array_equal(self.bitmap, other.bitmap)
        )

    def __hash__(self):
        return hash((self.code, self.name, self.bitmap.tobytes()))

    def __repr__(self):
        return f"Symbol(code={self.code}, name={self.name!r}, painted={self.painted})"


#: The reserved code of the spot height.
SPOT_HEIGHT = 0
IMPORTED_POINT = 90
"""The code of a point read from another program's file that says nothing more of it
(no code, no height): "imported point" in the default library (a small ring)."""
SPOT_HEIGHT_SYMBOL = Symbol(SPOT_HEIGHT, _SPOT_HEIGHT_NAME, _spot_height_bitmap())


def _reserved_error(what: str) -> SymbolLibraryError:
    return SymbolLibraryError(
        f"symbol 00 is reserved for the spot height and cannot be changed ({what})"
    )


class SymbolLibrary(Mapping):
    """The 100 symbols 00-99, as a mapping from code to :class:`Symbol`.

    Every code is always present: an undesigned code is a free slot.
    Code 00 is always the spot height; every attempt to change it raises
    :class:`~apygis.errors.SymbolLibraryError`.

    Parameters
    ----------
    symbols : iterable of Symbol, optional
        Symbols to put in the library; the codes not given are free slots.
        A symbol for code 00 must be the reserved spot height.

    Raises
    ------
    SymbolLibraryError
        If a code is given twice or a code-00 symbol is not the reserved one.

    Examples
    --------
    >>> lib = SymbolLibrary()
    >>> len(lib), lib[7].is_free, lib.name(7)
    (100, True, 'free')
    >>> lib.set_name(7, "church")
    >>> lib.set_bitmap(7, np.eye(15, dtype=bool))
    >>> lib[7]
    Symbol(code=7, name='church', painted=15)
    >>> lib.set_name(0, "height")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    apygis.errors.SymbolLibraryError: symbol 00 is reserved for the spot height and cannot ...
    """

    def __init__(self, symbols: Iterable[Symbol] | None = None):
        self._names = [FREE_NAME] * NCODES
        self._bitmaps = np.zeros((NCODES, SIZE, SIZE), dtype=bool)
        self._names[SPOT_HEIGHT] = SPOT_HEIGHT_SYMBOL.name
        self._bitmaps[SPOT_HEIGHT] = SPOT_HEIGHT_SYMBOL.bitmap
        seen = set()
        for sym in symbols or ():
            if not isinstance(sym, Symbol):
                raise SymbolLibraryError(f"expected a Symbol, not {type(sym).__name__}")
            if sym.code in seen:
                raise SymbolLibraryError(f"symbol {sym.code:02d} is given twice")
            seen.add(sym.code)
            if sym.code == SPOT_HEIGHT:
                if sym != SPOT_HEIGHT_SYMBOL:
                    raise _reserved_error("a different symbol 00 was given")
                continue
            self._names[sym.code] = sym.name
            self._bitmaps[sym.code] = sym.bitmap

    # -- mapping ------------------------------------------------------------------

    def __getitem__(self, code) -> Symbol:
        c = _check_code(code)
        if c == SPOT_HEIGHT:
            return SPOT_HEIGHT_SYMBOL
        return Symbol(c, self._names[c], self._bitmaps[c])

    def __iter__(self) -> Iterator[int]:
        return iter(range(NCODES))

    def __len__(self) -> int:
        return NCODES

    def __contains__(self, code) -> bool:
        try:
            _check_code(code)
        except SymbolLibraryError:
            return False
        return True

    def __eq__(self, other):
        if not isinstance(other, SymbolLibrary):
            return NotImplemented
        return self._names == other._names and np.array_equal(self._bitmaps, other._bitmaps)

    __hash__ = None  # type: ignore[assignment]  # mutable, so unhashable

    def __repr__(self):
        free = sum(self[c].is_free for c in range(1, NCODES))
        return f"<SymbolLibrary: {NCODES - 1 - free} designed, {free} free>"

    def copy(self) -> SymbolLibrary:
        """An independent copy of this library."""
        new = SymbolLibrary()
        new._names = list(self._names)
        new._bitmaps = self._bitmaps.copy()
        return new

    @property
    def free_codes(self) -> list[int]:
        """The codes of the free slots, ascending."""
        return [c for c in range(1, NCODES) if self[c].is_free]

    # -- editing ------------------------------------------------------------------

    def _editable(self, code, what: str) -> int:
        c = _check_code(code)
        if c == SPOT_HEIGHT:
            raise _reserved_error(what)
        return c

    def name(self, code) -> str:
        """The name of symbol ``code`` (``"free"`` for a free slot)."""
        return self._names[_check_code(code)]

    def set_name(self, code, name: str) -> None:
        """Give symbol ``code`` (1-99) a name of 1 to 24 printable characters.

        Raises
        ------
        SymbolLibraryError
            If ``code`` is 00 or out of range, or the name is invalid.
        """
        c = self._editable(code, "name")
        self._names[c] = _check_name(name)

    def paint(self, code, row: int, col: int) -> None:
        """Paint the cell at 0-based ``row``, ``col`` of symbol ``code`` (1-99).

        Examples
        --------
        >>> lib = SymbolLibrary()
        >>> lib.paint(12, 0, 14)
        >>> lib[12].rows[0]
        '..............#'
        >>> lib.paint(12, 15, 0)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        apygis.errors.SymbolLibraryError: cell (row 15, column 0) is off the 15x15 grid; ...
        """
        c = self._editable(code, "paint")
        r, k = _check_cell(row, col)
        self._bitmaps[c, r, k] = True

    def clear(self, code, row: int, col: int) -> None:
        """Clear the cell at 0-based ``row``, ``col`` of symbol ``code`` (1-99)."""
        c = self._editable(code, "clear")
        r, k = _check_cell(row, col)
        self._bitmaps[c, r, k] = False

    def set_bitmap(self, code, bitmap) -> None:
        """Replace the whole bitmap of symbol ``code`` (1-99).

        Parameters
        ----------
        bitmap : array_like or sequence of str
            A (15, 15) array of booleans or of 0 and 1, or 15 strings of 15
            characters ``'#'`` and ``'.'``.
        """
        c = self._editable(code, "bitmap")
        self._bitmaps[c] = _as_bitmap(bitmap)

    def render(self, code, *, base: int = 1) -> str:
        """Symbol ``code`` drawn as a text chessboard with its name.

        Row and column numbers start at ``base`` (1, as the command line
        counts, by default; 0 as this API counts).

        Examples
        --------
        >>> print(default_library().render(8))
        [08] wayside cross  (26 cells painted)
              1  2  3  4  5  6  7  8  9 10 11 12 13 14 15
            +---------------------------------------------+
          1 | .  .  .  .  .  .  .  .  .  .  .  .  .  .  . |
          2 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
          3 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
          4 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
          5 | .  .  .  #  #  #  #  #  #  #  #  #  .  .  . |
          6 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
          7 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
          8 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
          9 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
         10 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
         11 | .  .  .  .  .  .  .  #  .  .  .  .  .  .  . |
         12 | .  .  .  .  .  .  #  #  #  .  .  .  .  .  . |
         13 | .  .  .  .  .  #  #  #  #  #  .  .  .  .  . |
         14 | .  .  .  .  .  .  .  .  .  .  .  .  .  .  . |
         15 | .  .  .  .  .  .  .  .  .  .  .  .  .  .  . |
            +---------------------------------------------+
        """
        return self[code].render(base=base)

    # -- text ---------------------------------------------------------------------

    def to_text(self) -> str:
        """The library as ``.apysym`` text: all 100 codes in ascending order.

        Examples
        --------
        >>> print("\\n".join(SymbolLibrary().to_text().splitlines()[:6]))
        APYSYM 1
        ; apygis symbol library: one block per code 00-99, a line "[NN] name"
        ; then 15 rows of 15 cells, '#' painted and '.' clear. Symbol 00 (the
        ; spot height) is reserved and cannot be changed. Comments start with ';'.
        <BLANKLINE>
        [00] spot height
        """
        out = [
            HEADER,
            '; apygis symbol library: one block per code 00-99, a line "[NN] name"',
            "; then 15 rows of 15 cells, '#' painted and '.' clear. Symbol 00 (the",
            "; spot height) is reserved and cannot be changed. Comments start with ';'.",
        ]
        cells = np.where(self._bitmaps, ord(PAINT), ord(CLEAR)).astype(np.uint8)
        for c in range(NCODES):
            out.append("")
            out.append(f"[{c:02d}] {self._names[c]}")
            out.extend(row.tobytes().decode("ascii") for row in cells[c])
        return "\n".join(out) + "\n"

    @classmethod
    def from_text(cls, text: str | bytes, path=None) -> SymbolLibrary:
        """Parse ``.apysym`` text (``bytes`` are decoded as UTF-8).

        Parameters
        ----------
        text : str or bytes
            The file's content.
        path : str or os.PathLike, optional
            Named in error messages.

        Raises
        ------
        FormatError
            If the text does not follow the format; the message names the
            line and what was expected there.

        Examples
        --------
        >>> text = "APYSYM 1\\n[05] dot\\n" + "." * 15 + "\\n" + (
        ...     "......." + "#" + "......." + "\\n") + ("." * 15 + "\\n") * 13
        >>> lib = SymbolLibrary.from_text(text)
        >>> lib.name(5), lib[5].painted, lib[6].is_free
        ('dot', 1, True)
        >>> SymbolLibrary.from_text("APYSYM 1\\n[05] dot\\n#\\n")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        apygis.errors.FormatError: line 3: symbol 05, bitmap row 1 of 15: expected 15 characters ...
        """
        if isinstance(text, bytes | bytearray | memoryview):
            text = _decode(bytes(text), path)
        elif not isinstance(text, str):
            raise TypeError(f"expected str or bytes, not {type(text).__name__}")
        names, bitmaps = _parse(text, path)
        lib = cls()
        lib._names = names
        lib._bitmaps = bitmaps
        return lib

    @classmethod
    def read(cls, path) -> SymbolLibrary:
        """Read an ``.apysym`` file.

        Raises
        ------
        FormatError
            If the file is not a valid symbol library, or cannot be read
            (missing, a directory, a symbolic link loop, no permission); the
            message names the path.
        """
        data = _read_library_bytes(Path(path))
        log.debug("read symbol library %s", path)
        return cls.from_text(data, path=path)

    def write(self, path) -> None:
        """Write the library to ``path`` atomically.

        The text goes to a temporary file beside the target, which then
        replaces the target with :func:`os.replace`, so that readers see the
        old or the new library, never half of one. An existing file keeps
        its permissions; a symbolic link is written through.

        Raises
        ------
        WriteError
            If the file cannot be written (an ``OSError``; the target's
            directory must exist: a missing one is a ``FileNotFoundError``).
        FileOverwriteError
            If the path is a directory, a device or a pipe.
        """
        path = Path(path)
        atomic_write(path, self.to_text().encode("utf-8"))  # apygis.fileio: the one atomic write
        log.debug("wrote symbol library %s", path)


# -- the reader -----------------------------------------------------------------------

_HEADER_RE = re.compile(r"\[([0-9]{2})\] (.*)")
_LOOSE_HEADER_RE = re.compile(r"\[(-?[0-9]*)\]")
_ROW_CHARS = frozenset(PAINT + CLEAR)
_BLANK = " \t"
_TRAILING = " \t\r"


def _unreadable(path: Path, exc: OSError) -> FormatError:
    """The FormatError for a library path that cannot be read, naming the path."""
    if isinstance(exc, IsADirectoryError):
        why = "is a directory, not a symbol library file"
    elif isinstance(exc, FileNotFoundError):
        why = "no such symbol library file"
    elif exc.errno == errno.ELOOP:
        why = "a loop of symbolic links: no symbol library file can be reached"
    elif exc.errno == errno.ENOTDIR:
        why = "a part of the path is not a directory"
    else:
        why = f"cannot read the symbol library: {exc.strerror or exc}"
    return FormatError(why, path=path)


def _read_library_bytes(path: Path) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError as exc:
        raise _unreadable(path, exc) from None


def _decode(data: bytes, path) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise FormatError(
            f"not UTF-8 text: byte 0x{data[exc.start]:02x} cannot be decoded; "
            "a symbol library must be encoded in UTF-8",
            path=path,
            record=f"line {line}",
        ) from None


def _show(s: str, limit: int = 30) -> str:
    return repr(s if len(s) <= limit else s[:limit] + "...")


def _parse(text: str, path) -> tuple[list[str], np.ndarray]:
    def fail(lineno: int, message: str) -> NoReturn:
        raise FormatError(message, path=path, record=f"line {lineno}")

    if text.startswith("\ufeff"):
        text = text[1:]
    lines = text.split("\n")
    if lines[-1] == "":
        lines.pop()  # the final line terminator
    lines = [ln.rstrip(_TRAILING) for ln in lines]

    if not lines:
        fail(1, f"the file is empty; expected the header line {HEADER!r}")
    if lines[0] != HEADER:
        if re.fullmatch(r"APYSYM [0-9]{1,9}", lines[0]):
            fail(1, f"unsupported version {lines[0][7:]}; this reader knows {HEADER!r}")
        hint = " (lines must end with LF or CR LF)" if "\r" in lines[0] else ""
        fail(1, f"expected the header line {HEADER!r}, found {_show(lines[0])}{hint}")

    names = [FREE_NAME] * NCODES
    bitmaps = np.zeros((NCODES, SIZE, SIZE), dtype=bool)
    names[SPOT_HEIGHT] = SPOT_HEIGHT_SYMBOL.name
    bitmaps[SPOT_HEIGHT] = SPOT_HEIGHT_SYMBOL.bitmap
    defined: dict[int, int] = {}
    last_block: int | None = None  # the code of the block that just ended

    i = 1
    n = len(lines)
    while i < n:
        line = lines[i]
        lineno = i + 1
        stripped = line.lstrip(_BLANK)
        if not stripped or stripped.startswith(";"):
            last_block = None
            i += 1
            continue
        m = _HEADER_RE.fullmatch(line)
        if m is None:
            loose = _LOOSE_HEADER_RE.match(line)
            digits = loose.group(1) if loose else ""
            if digits not in ("", "-"):
                if digits.startswith("-") or len(digits.lstrip("0")) > 2:
                    fail(
                        lineno,
                        f"symbol code {_show(digits, 8)} is out of range; codes run from 00 to 99",
                    )
                if len(digits) != 2:
                    fail(
                        lineno,
                        f"symbol code {digits!r} must be written with two digits "
                        f"([{int(digits.lstrip('0') or '0'):02d}]), then one space and the name",
                    )
            if line.startswith("["):
                fail(
                    lineno,
                    "expected a symbol header '[NN] name' (two digits in brackets, "
                    f"one space, a name), found {_show(line)}",
                )
            if last_block is not None and set(line) <= {PAINT, CLEAR}:
                fail(lineno, f"symbol {last_block:02d} has more than 15 bitmap rows")
            fail(
                lineno,
                "expected a symbol header '[NN] name', a comment starting with ';' "
                f"or a blank line, found {_show(line)}",
            )
        code = int(m.group(1))
        name = m.group(2)
        if code in defined:
            fail(lineno, f"duplicate symbol {code:02d} (first defined on line {defined[code]})")
        problem = _name_problem(name)
        if problem:
            fail(lineno, f"symbol {code:02d}: {problem} (found {_show(name)})")
        defined[code] = lineno

        bm = np.zeros((SIZE, SIZE), dtype=bool)
        for r in range(SIZE):
            j = i + 1 + r
            if j >= n:
                fail(
                    j + 1,
                    f"symbol {code:02d}: expected 15 bitmap rows, found {r} before the end of file",
                )
            row = lines[j]
            if len(row) != SIZE:
                what = "an empty line" if not row.strip(_BLANK) else f"{len(row)}"
                fail(
                    j + 1,
                    f"symbol {code:02d}, bitmap row {r + 1} of 15: "
                    f"expected 15 characters '#' or '.', found {what}",
                )
            if not _ROW_CHARS.issuperset(row):
                k, ch = next((k, ch) for k, ch in enumerate(row) if ch not in _ROW_CHARS)
                fail(
                    j + 1,
                    f"symbol {code:02d}, bitmap row {r + 1}: bad character {ch!r} in "
                    f"column {k + 1}; expected '#' (painted) or '.' (clear)",
                )
            bm[r] = np.frombuffer(row.encode("ascii"), dtype=np.uint8) == ord(PAINT)
        if code == SPOT_HEIGHT and (
            name != SPOT_HEIGHT_SYMBOL.name or not np.array_equal(bm, SPOT_HEIGHT_SYMBOL.bitmap)
        ):
            fail(
                lineno,
                "symbol 00 is reserved for the spot height and cannot be changed: "
                f"expected the name {SPOT_HEIGHT_SYMBOL.name!r} and the reserved cross "
                "(or leave symbol 00 out)",
            )
        names[code] = name
        bitmaps[code] = bm
        last_block = code
        i += 1 + SIZE
    return names, bitmaps


# -- the default and the user library ------------------------------------------------


@functools.cache
def _default_parsed() -> tuple[tuple[str, ...], np.ndarray]:
    res = resources.files("apygis").joinpath("model").joinpath("default.apysym")
    lib = SymbolLibrary.from_text(res.read_bytes(), path=str(res))
    bitmaps = lib._bitmaps
    bitmaps.flags.writeable = False
    return tuple(lib._names), bitmaps


def default_library() -> SymbolLibrary:
    """A new copy of the default topographic symbol set shipped with apygis.

    Examples
    --------
    >>> lib = default_library()
    >>> [lib.name(c) for c in (1, 23, 24)]
    ['trig point', 'deciduous tree', 'conifer']
    >>> lib[99].is_free
    True
    """
    names, bitmaps = _default_parsed()
    lib = SymbolLibrary()
    lib._names = list(names)
    lib._bitmaps = bitmaps.copy()
    return lib


def user_library_path() -> Path:
    """Where the user's symbol library lives.

    The file named by the environment variable ``APYGIS_SYMBOLS`` if it is
    set and not empty, else ``~/.config/apygis/symbols.apysym``. The file need
    not exist.
    """
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env).expanduser()
    return Path.home() / ".config" / "apygis" / "symbols.apysym"


def load_library(path=None) -> SymbolLibrary:
    """The library in ``path`` (default :func:`user_library_path`) or the default set.

    If the file does not exist (nor does the target of a symbolic link to
    it), a copy of :func:`default_library` is returned.

    Raises
    ------
    FormatError
        If the file exists but is not a valid symbol library, or the path
        cannot be read: a directory, a symbolic link loop, a part of it
        that is not a directory, no permission. The message names the path.
    """
    p = user_library_path() if path is None else Path(path)
    try:
        os.stat(p)
    except FileNotFoundError:
        log.debug("no symbol library at %s, using the default set", p)
        return default_library()
    except OSError as exc:  # a symlink loop, ENOTDIR, EACCES: Path.exists() says False
        raise _unreadable(p, exc) from None
    return SymbolLibrary.read(p)
