"""The one progress callback of apygis: ``progress(done, total)``.

The library never draws progress (it never prints); a long operation takes an
optional ``progress`` argument and calls it as it goes, and the CLI draws the
bar. Every public function that takes ``progress=`` — the drivers' readers
and writers, :func:`apygis.read` and :func:`apygis.write`, batch conversion,
:func:`apygis.plot.drawing.build_drawing` — calls it the same way
(:class:`Progress`):

* ``progress(done, total)`` with two ints, ``0 <= done <= total``: ``done``
  units of work of ``total`` are finished. The unit is the callee's (layers,
  files, DXF entities, conversions) and is not part of the contract; only
  ``done / total`` is (:func:`fraction`).
* ``total`` is the same in every call of one operation, and ``done`` never
  goes down.
* The last call of an operation that succeeds has ``done == total``; an
  operation with nothing to do may call ``progress(0, 0)`` (done: fraction 1).
  An operation that fails raises and need not make a last call.
* Calls are made in the calling thread (batch conversion in worker processes
  reports from the parent), and may be sparse (every thousand entities): a
  callback must not assume one call per unit.
* A callback returns ``None``; it may raise to abandon the operation (the
  exception propagates, and writes are atomic, so nothing is left half
  written).

:func:`phase` maps the progress of one step of a longer operation onto a
part of the whole, so that nested work still reports one ``(done, total)``
sequence.

Examples
--------
>>> calls = []
>>> def record(done: int, total: int) -> None:
...     calls.append((done, total))
>>> read_half = phase(record, 0, 2)   # reading: the first of two equal steps
>>> write_half = phase(record, 1, 2)
>>> read_half(2, 4); read_half(4, 4); write_half(1, 1)
>>> calls
[(250, 1000), (500, 1000), (1000, 1000)]
>>> fraction(250, 1000), fraction(0, 0)
(0.25, 1.0)
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

__all__ = ["STEPS", "Progress", "fraction", "phase"]

#: The ``total`` of a composed progress (:func:`phase`): fine enough for any bar.
STEPS = 1000


@runtime_checkable
class Progress(Protocol):
    """A progress callback: ``progress(done, total)``, ``0 <= done <= total``."""

    def __call__(self, done: int, total: int, /) -> None:
        """``done`` units of ``total`` are finished (see the module's conventions)."""


def fraction(done: int, total: int) -> float:
    """The part done, 0 to 1; an operation with nothing to do (``total == 0``) is done.

    >>> fraction(3, 4)
    0.75
    """
    if total <= 0:
        return 1.0
    return min(max(done / total, 0.0), 1.0)


def phase(progress: Progress | None, index: int, count: int) -> Progress | None:
    """A callback for step ``index`` (0-based) of ``count`` equal steps of one operation.

    The step's own ``(done, total)`` calls become calls of ``progress`` with
    ``total`` :data:`STEPS`, ``done`` from ``index * STEPS / count`` to
    ``(index + 1) * STEPS / count``, never going down. ``None`` gives
    ``None`` (no callback to wrap).
    """
    if progress is None:
        return None
    if not 0 <= index < count:
        raise ValueError(f"step {index} of {count}: expected 0 <= index < count")
    last = [0]

    def step(done: int, total: int, /) -> None:
        at = round((index + fraction(done, total)) * STEPS / count)
        at = max(at, last[0])
        last[0] = at
        progress(at, STEPS)

    return step
