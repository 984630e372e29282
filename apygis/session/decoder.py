"""What the operator's hands send, as engine events.

:class:`ReportDecoder` turns tablet reports (position, proximity, button
code) into :class:`~apygis.compile.events.Mark` and
:class:`~apygis.compile.events.Press` events; :func:`decode_typed` turns a
line typed on the keyboard (bytes, in whatever the terminal's encoding) into
the text of a :class:`~apygis.compile.events.Keys` event.
"""

from __future__ import annotations

import logging

from apygis.compile.events import Event, Mark, Press

__all__ = ["ReportDecoder", "decode_typed"]

log = logging.getLogger(__name__)


class ReportDecoder:
    """Tablet reports -> engine events.

    A report in proximity whose position differs from the last one is a
    :class:`~apygis.compile.events.Mark` (tablet millimetres). A **press** is a
    report whose button code is not 0 and differs from the previous report's;
    UP and DOWN also act on every report while held. A report out of
    proximity (the cursor lifted) moves nothing and presses nothing.
    """

    def __init__(self, config, buttons: dict[int, str], repeat=("UP", "DOWN")):
        self.config = config
        self.buttons = buttons
        self.repeat = frozenset(repeat)
        self._prev_button = 0
        self._prev_xy: tuple | None = None

    def events(self, report) -> list:
        out: list[Event] = []
        if not report.proximity:
            self._prev_button = 0
            return out
        if (report.x_counts, report.y_counts) != self._prev_xy:
            self._prev_xy = (report.x_counts, report.y_counts)
            out.append(Mark(*self.config.report_mm(report)))
        b = report.button or 0
        if b and (b != self._prev_button or self.buttons.get(b) in self.repeat):
            name = self.buttons.get(b)
            if name is None:
                log.warning("tablet button code %d is not on the pad; ignored", b)
            else:
                out.append(Press(name))
        self._prev_button = b
        return out


def decode_typed(raw) -> tuple[str, str | None]:
    """A typed line as text, and a note for the operator when it was not clean UTF-8.

    ``raw`` is bytes from the keyboard (or a str that may carry
    ``surrogateescape`` characters, as ``sys.stdin`` gives on a Latin-1
    terminal). Bytes that are not UTF-8 are read as Latin-1 (the usual
    8-bit terminal encoding: ``b"M\\xfcller"`` is ``"Müller"``) and the note
    says so.

    >>> decode_typed(b"M\\xfcller")[0], decode_typed("Kirchweg")
    ('Müller', ('Kirchweg', None))
    """
    if isinstance(raw, str):
        try:
            raw = raw.encode("utf-8", "surrogateescape")
        except UnicodeEncodeError:  # a surrogate that no decoder made: not text at all
            raw = raw.encode("utf-8", "replace")
    try:
        return raw.decode("utf-8"), None
    except UnicodeDecodeError as exc:
        text = raw.decode("latin-1")
        return text, (
            f"typed text is not UTF-8 (byte 0x{raw[exc.start]:02x} at {exc.start + 1}); "
            f"read as Latin-1: {text!r}"
        )
