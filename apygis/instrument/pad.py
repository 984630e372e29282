"""The 27-button cursor pad: button names and codes, and pad files.

:data:`BUTTONS` is the default pad, code -> name: the single definition of
the button names (their meanings are in ``docs/button-pad.md``; the
simulator, the session and the CLI take them from here).
:data:`BUTTON_CODES` and :func:`button_code` go from a name (or an alias)
to its code.

A cursor whose buttons send other codes is described by a pad file (UTF-8
text; one ``CODE NAME`` pair per line, ``;`` starts a comment, blank lines
ignored)::

    ; a 16-button puck: the digits on 1-10, then the functions we use most
    11 ENTER
    12 PROCEED
    13 DESCR
    14 DELETE

Codes are 1-255 (what the tablet sends; 0 is "no button"); names are those
of the default pad (``docs/button-pad.md``), each at most once. Codes a pad
file does not name keep their default meaning unless ``--pad-only`` (the
``replace`` argument) asks for the file's buttons alone.
"""

from __future__ import annotations

import re
from pathlib import Path

from apygis.errors import FormatError, ProtocolError

__all__ = ["BUTTONS", "BUTTON_CODES", "button_code", "load_pad", "parse_pad"]

#: The 27-button cursor pad: button code -> name (0 is "no button").
#: Meanings in ``docs/button-pad.md``.
BUTTONS: dict[int, str] = {
    1: "1",
    2: "2",
    3: "3",
    4: "4",
    5: "5",
    6: "6",
    7: "7",
    8: "8",
    9: "9",
    10: "0",
    11: "ENTER",
    12: "DELETE",
    13: "PROCEED",
    14: "DESCR",
    15: "SEARCH",
    16: "SAMPLE",
    17: "LS",
    18: "AREA",
    19: "DHI",
    20: "UP",
    21: "DOWN",
    22: "UNDO",
    23: "POINT",
    24: "PLUS",
    25: "MINUS",
    26: "SHUTTER",
    27: "STEP",
}

#: Button name -> code, with a few aliases (``.``, ``+``, ``-``, long names).
BUTTON_CODES: dict[str, int] = {name: code for code, name in BUTTONS.items()}
BUTTON_CODES.update(
    {
        ".": 23,
        "+": 24,
        "-": 25,
        "DESCRIPTIVES": 14,
        "LINESPLIT": 17,
    }
)


def button_code(name) -> int:
    """The code (1-27) of a button name (``"ENTER"``, ``"5"``, ``"up"``), or of a code.

    Examples
    --------
    >>> button_code("enter"), button_code("0"), button_code(24)
    (11, 10, 24)
    """
    if isinstance(name, int) and not isinstance(name, bool):
        if name in BUTTONS:
            return name
        raise ProtocolError(f"button code {name} is not on the pad (1-27)")
    key = str(name).strip().upper()
    try:
        return BUTTON_CODES[key]
    except KeyError:
        raise ProtocolError(
            f"unknown button {name!r}; the pad has: {', '.join(BUTTONS.values())}"
        ) from None


#: A button code: ASCII digits only (``str.isdigit`` also takes '²', which ``int`` refuses).
_ASCII_DIGITS = re.compile(r"[0-9]+")


def parse_pad(text: str, path=None, *, replace: bool = False) -> dict[int, str]:
    """The code -> name mapping of a pad file's text (see the module docstring).

    >>> pad = parse_pad("11 PROCEED\\n13 ENTER\\n")
    >>> pad[11], pad[13], pad[1]
    ('PROCEED', 'ENTER', '1')
    """
    names = set(BUTTONS.values())
    pad: dict[int, str] = {} if replace else dict(BUTTONS)
    seen: dict[str, int] = {}
    for no, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(";", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        if len(parts) != 2 or not _ASCII_DIGITS.fullmatch(parts[0]):
            raise FormatError(
                "expected 'CODE NAME', CODE in ASCII digits 0-9", path=path, record=f"line {no}"
            )
        if len(parts[0].lstrip("0")) > 3:  # int() of thousands of digits is slow, then refused
            raise FormatError(
                f"button code {parts[0][:20]}... is outside 1-255", path=path, record=f"line {no}"
            )
        code, name = int(parts[0]), parts[1].upper() if parts[1].isalpha() else parts[1]
        if not 1 <= code <= 255:
            raise FormatError(
                f"button code {code} is outside 1-255", path=path, record=f"line {no}"
            )
        if name not in names:
            raise FormatError(
                f"unknown button {parts[1]!r}; the buttons are {', '.join(BUTTONS.values())}",
                path=path,
                record=f"line {no}",
            )
        if name in seen:
            raise FormatError(
                f"{name} is already on code {seen[name]}", path=path, record=f"line {no}"
            )
        seen[name] = code
        if not replace:  # the name leaves its default code
            for c in [c for c, n in pad.items() if n == name and c != code]:
                del pad[c]
        pad[code] = name
    return pad


def load_pad(path, *, replace: bool = False) -> dict[int, str]:
    """Read a pad file; a missing or undecodable file is a :class:`FormatError`."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"cannot read the pad file: {exc}", path=path) from None
    return parse_pad(text, path, replace=replace)
