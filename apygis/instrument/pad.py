"""Button pad files: which button code of the cursor means which button.

The default pad is :data:`apygis.instrument.simulator.BUTTONS`. A cursor
whose buttons send other codes is described by a pad file (UTF-8 text; one
``CODE NAME`` pair per line, ``;`` starts a comment, blank lines ignored)::

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

from apygis.errors import FormatError
from apygis.instrument.simulator import BUTTONS

__all__ = ["load_pad", "parse_pad"]

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
