"""Constants shared by the E00 writer and reader, and the width of an INFO item in E00."""

from __future__ import annotations

import logging
import re

log = logging.getLogger("apygis.formats.e00")

DEFAULT_LAYER = "a"
"""Layer extension of the records of an E00 file that apygis did not write."""

SINGLE, DOUBLE = 2, 3
"""E00 precision codes: single (7 decimals) and double (14) precision."""

T_DATE, T_CHAR, T_FIXINT, T_FIXNUM, T_BININT, T_BINFLOAT = 10, 20, 30, 40, 50, 60
"""INFO item types (the tens digit of the E00 type field)."""

_TERM = b"        -1         0"
_NL, _SP = 10, 32
_MAX_COUNT = 10 * 1024 * 1024
_COVER_RE = re.compile(r"[^A-Z0-9_]")
_SECTION_RE = re.compile(rb"^([A-Za-z0-9]{3})  ([0-9])\s*$")
# sections apygis does not use, and the line that ends each
_SKIP_UNTIL = {b"SIN": b"EOX", b"LOG": b"EOL", b"MTD": b"EOD"}
_SKIP_TO_TERM = {b"CNT", b"TXT"}
_SUPER = {b"TX6", b"TX7", b"RXP", b"RPL"}


def _e00_width(type_: int, size: int) -> int | None:
    if type_ in (T_DATE, T_CHAR, T_FIXINT):
        return size
    if type_ == T_BININT:
        return {4: 11, 2: 6}.get(size)
    if type_ == T_BINFLOAT:
        return {4: 14, 8: 24}.get(size)
    if type_ == T_FIXNUM:
        return 14
    return None
