"""The E00 decompressor: a compressed E00 file (``EXP  1``) to its plain text."""

from __future__ import annotations

from typing import NoReturn

from apygis.errors import FormatError
from apygis.formats.e00._common import _NL


def decompress(data: bytes, path=None) -> bytes:
    """The uncompressed text of a compressed E00 file (``EXP  1``).

    The compressed stream (everything after the header line, its own line
    ends ignored) encodes: ``~}`` a line end, ``~ `` and one character a run
    of ``ord(c) - 32`` spaces, ``~~`` and ``~-`` a literal ``~`` and ``-``,
    and ``~`` with a format character from ``!`` to ``z`` a number, whose
    digits follow in pairs, one character each (``!`` is 00, 92-99 take two
    characters), until a space or a ``~``. The format character ``f`` gives,
    with ``n = ord(f) - 33``, the position of the decimal point ``n % 15``
    (0: none), the exponent ``n // 15 % 3`` (0: none, 1: ``E+``, 2: ``E-``,
    before the last two digits) and an odd digit count ``n // 45`` (the last
    digit dropped). After a number, ``~`` followed by anything but ``}`` or a
    space only ends the number.

    >>> decompress(b"EXP  1 /X.E00\\nARC  2~}~ )1~}EOS~}").decode()
    'EXP  0 /X.E00\\nARC  2\\n         1\\nEOS\\n'
    """
    nl = data.find(b"\n")
    header = data[:nl] if nl >= 0 else data
    header = header.rstrip(b"\r")
    k = header.find(b" 1")
    if k >= 0:
        header = header[:k] + b" 0" + header[k + 2 :]
    body = b"" if nl < 0 else data[nl + 1 :]
    stream = body.replace(b"\r", b"").replace(b"\n", b"")
    out = bytearray()
    col = 0
    line_no = 1
    i, n = 0, len(stream)
    after_number = False

    def fail(msg: str) -> NoReturn:
        raise FormatError(msg, path=path, record=f"uncompressed line {line_no}")

    while i < n:
        c = stream[i]
        i += 1
        if c != 0x7E:
            out.append(c)
            col += 1
            after_number = False
        else:
            if i >= n:
                fail("the compressed data end inside a ~ code (is the file truncated?)")
            c = stream[i]
            i += 1
            if c == 0x20:
                if i >= n:
                    fail("the compressed data end inside a run of spaces")
                run = stream[i] - 32
                i += 1
                if run < 0:
                    fail(f"bad run of spaces code {stream[i - 1]!r}")
                out += b" " * run
                col += run
                after_number = False
            elif c == 0x7D:
                out.append(_NL)
                col = 0
                line_no += 1
                after_number = False
            elif after_number:
                out.append(c)
                col += 1
                after_number = False
            elif c in (0x7E, 0x2D):
                out.append(c)
                col += 1
            elif 0x21 <= c <= 0x7A:
                code = c - 33
                point, odd, expo = code % 15, code // 45, (code // 15) % 3
                digits = bytearray()
                ndigits = 0  # digits so far, the decimal point not counted (linear time)
                while i < n and stream[i] not in (0x20, 0x7E):
                    v = stream[i] - 33
                    i += 1
                    if v == 92 and i < n:
                        v += stream[i] - 33
                        i += 1
                    if not 0 <= v <= 99:
                        fail(f"bad digit pair code in a compressed number ({v})")
                    for d in (v // 10, v % 10):
                        digits.append(48 + d)
                        ndigits += 1
                        if ndigits == point:
                            digits.append(46)
                    if col + len(digits) > 82:  # stop at once, not at the end of the number
                        fail(
                            "an uncompressed line is longer than 80 characters: "
                            "corrupt compressed data"
                        )
                if odd and digits:
                    del digits[-1]
                if expo and len(digits) >= 2:
                    digits[-2:-2] = b"E+" if expo == 1 else b"E-"
                out += digits
                col += len(digits)
                after_number = True
            else:
                fail(f"unknown compression code '~{chr(c)}'")
        if col > 80:
            fail("an uncompressed line is longer than 80 characters: corrupt compressed data")
    if out and out[-1] != _NL:
        out.append(_NL)
    return bytes(header) + b"\n" + bytes(out)
