"""What a reader reports about a file: skipped entities, cut or renumbered records.

A reader calls :func:`warn` for everything a user must hear about (an entity
type it cannot import, records it numbered anew, a damaged part it skipped).
The message is logged at level WARNING (so ``apygis convert`` shows it at the
default verbosity) and, while :func:`collecting` is active, also kept as a
:class:`ReadWarning`. :func:`apygis.formats.read` and the batch converter
collect them and hand them to the map as ``MapFile.read_warnings``, which
``apygis info --json`` lists under ``read_warnings`` and counts in
``warnings``.

>>> import logging
>>> with collecting() as got:
...     warn(logging.getLogger("apygis.doc"), "a.dxf: 3 HATCH skipped", "skipped", 3, "HATCH")
>>> got[0].as_dict()
{'kind': 'skipped', 'what': 'HATCH', 'count': 3, 'message': 'a.dxf: 3 HATCH skipped'}
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from contextvars import ContextVar
from dataclasses import dataclass

__all__ = ["ReadWarning", "collecting", "warn"]


@dataclass(frozen=True)
class ReadWarning:
    """One thing a reader reported.

    Attributes
    ----------
    kind : str
        ``"skipped"`` (records or entities not imported), ``"renumbered"``,
        ``"rebuilt"`` (the topology rebuild refused or removed something),
        ``"edited"`` (GIS edits taken), ``"damaged"`` (a damaged part ignored),
        ``"crs"`` (a CRS that could not be read), ``"differs"`` (parts of a set
        that disagree).
    message : str
        The line logged, naming the file.
    count : int or None
        How many records or entities, where it applies.
    what : str or None
        The entity type or table concerned (``"HATCH"``, ``"texts"``).
    """

    kind: str
    message: str
    count: int | None = None
    what: str | None = None

    def as_dict(self) -> dict:
        return {"kind": self.kind, "what": self.what, "count": self.count, "message": self.message}


_active: ContextVar[list[ReadWarning] | None] = ContextVar("apygis_read_warnings", default=None)


@contextlib.contextmanager
def collecting() -> Iterator[list[ReadWarning]]:
    """Collect the :func:`warn` calls made inside the block (nested blocks collect their own)."""
    got: list[ReadWarning] = []
    token = _active.set(got)
    try:
        yield got
    finally:
        _active.reset(token)


def warn(
    log: logging.Logger,
    message: str,
    kind: str,
    count: int | None = None,
    what: str | None = None,
) -> None:
    """Log ``message`` at WARNING and keep it for the active :func:`collecting` block."""
    log.warning("%s", message)
    got = _active.get()
    if got is not None:
        got.append(ReadWarning(kind, message, count, what))
