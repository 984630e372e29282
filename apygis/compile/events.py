"""What goes into the compilation engine (events) and what comes out (effects).

Pure data: frozen dataclasses, no I/O. ``Event`` and ``Effect`` are the
unions of their kinds, so ``isinstance(x, Event)`` and a ``match`` over the
classes cover them all.

Events
    :class:`Mark` (the floating mark moved to a tablet position, mm),
    :class:`Press` (one of the 27 cursor buttons, by name;
    ``docs/button-pad.md``), :class:`Keys` (a line typed on the keyboard).

Effects
    Record effects (:data:`RECORD_EFFECTS`: one per entry): :class:`Added`,
    :class:`Deleted`, :class:`Linked`, :class:`Undone`.
    For the operator: :class:`Message`, :class:`Ignored` (a button that does
    nothing in the present mode), :class:`Status`.
    For the instrument: :class:`Plates`, :class:`ZeroPlates`.
    For the display: :class:`DisplayScale`, :class:`CrosshairScale`,
    :class:`AreaShown`, :class:`DhiShown` (results to draw over the map).
    For the session: :class:`Save`, :class:`Terminate`.

>>> event_from_dict(event_to_dict(Mark(1.5, -2.0)))
Mark(x_mm=1.5, y_mm=-2.0)
>>> DisplayScale(30.0)
Traceback (most recent call last):
...
apygis.errors.RecordError: display scale factor 30.0: must be from 0.25 to 25
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from apygis.errors import RecordError

__all__ = [
    "CROSSHAIR_SCALE_RANGE",
    "DISPLAY_SCALE_RANGE",
    "RECORD_EFFECTS",
    "Added",
    "AreaShown",
    "CrosshairScale",
    "Deleted",
    "DhiShown",
    "DisplayScale",
    "Effect",
    "Event",
    "Ignored",
    "Keys",
    "Linked",
    "Mark",
    "Message",
    "Plates",
    "Press",
    "Save",
    "Status",
    "Terminate",
    "Undone",
    "ZeroPlates",
    "event_from_dict",
    "event_to_dict",
]

#: PROCEED item 1: the graphic display's scale factor, lowest and highest.
DISPLAY_SCALE_RANGE = (0.25, 25.0)
#: PROCEED item 3: the crosshair scale, lowest and highest.
CROSSHAIR_SCALE_RANGE = (0.25, 4.0)


# --------------------------------------------------------------------------- events


@dataclass(frozen=True)
class Mark:
    """The floating mark is at tablet position (x_mm, y_mm)."""

    x_mm: float
    y_mm: float


@dataclass(frozen=True)
class Press:
    """A cursor button was pressed (its name, ``docs/button-pad.md``)."""

    button: str


@dataclass(frozen=True)
class Keys:
    """Text typed on the keyboard.

    Bytes (or a str with ``surrogateescape`` characters) only on the way into
    ``Session.handle``, which decodes them: the engine sees a str.
    """

    text: str | bytes


Event = Mark | Press | Keys


def event_to_dict(ev: Event) -> dict:
    """A JSON-ready form of an event (the session journal's records)."""
    if isinstance(ev, Mark):
        return {"mark": [ev.x_mm, ev.y_mm]}
    if isinstance(ev, Press):
        return {"press": ev.button}
    if isinstance(ev, Keys):
        return {"keys": ev.text}
    raise RecordError(f"not an event: {ev!r:.80}")


def event_from_dict(d: dict) -> Event:
    """The event of :func:`event_to_dict`'s form; :class:`RecordError` for anything else."""
    if isinstance(d, dict) and len(d) == 1:
        if "mark" in d:
            x, y = d["mark"]
            return Mark(float(x), float(y))
        if "press" in d:
            return Press(str(d["press"]))
        if "keys" in d:
            return Keys(str(d["keys"]))
    raise RecordError(f"not an event: {d!r:.80}")


# --------------------------------------------------------------------------- effects


@dataclass(frozen=True)
class Added:
    """Record ``num`` of ``table`` was added to ``layer`` (an entry)."""

    layer: str
    table: str
    num: int


@dataclass(frozen=True)
class Deleted:
    """Record ``num`` of ``table`` was deleted from ``layer`` (an entry)."""

    layer: str
    table: str
    num: int


@dataclass(frozen=True)
class Linked:
    """Line point ``num`` was joined to ``target`` (``how``: "closed" or "branch")."""

    layer: str
    num: int
    target: int
    how: str


@dataclass(frozen=True)
class Undone:
    """The last entry was taken back; ``layer`` is compiled into now (an entry)."""

    layer: str


@dataclass(frozen=True)
class Message:
    """A line (or lines) for the operator's monitor."""

    text: str


@dataclass(frozen=True)
class Ignored:
    """``button`` does nothing in ``mode``; ``hint`` says what the mode expects.

    Every button the engine does not act on in a mode gets this answer (and
    nothing else changes), so the operator always hears back; the table of
    ``docs/compilation.md`` lists which buttons act in which mode.
    """

    button: str
    mode: str
    hint: str

    @property
    def text(self) -> str:
        return f"{self.button}: ignored in {self.mode} mode; {self.hint}"


@dataclass(frozen=True)
class Status:
    """The prompt line: mode, layer, the digits typed so far, the mark, record counts."""

    mode: str
    layer: str
    prompt: str
    mark: tuple[float, float, float] | None
    counts: dict = field(hash=False, compare=False, default_factory=dict)


@dataclass(frozen=True)
class Plates:
    """Motor positions (steps: left x, left y, right x, right y) for the mark."""

    steps: tuple


@dataclass(frozen=True)
class ZeroPlates:
    """Eliminate parallax: the plates' present position becomes their zero."""


def _check_factor(what: str, factor, rng: tuple[float, float]) -> None:
    lo, hi = rng
    if not (isinstance(factor, float) and math.isfinite(factor) and lo <= factor <= hi):
        raise RecordError(f"{what} {factor!r:.20}: must be from {lo:g} to {hi:g}")


@dataclass(frozen=True)
class DisplayScale:
    """The graphic display's scale factor is now ``factor`` (PROCEED item 1).

    ``factor`` is a float within :data:`DISPLAY_SCALE_RANGE` (0.25-25): a
    display draws the map at ``factor`` times its plot scale. Constructing one
    out of range raises :class:`~apygis.errors.RecordError`.
    """

    factor: float

    def __post_init__(self):
        _check_factor("display scale factor", self.factor, DISPLAY_SCALE_RANGE)


@dataclass(frozen=True)
class CrosshairScale:
    """The crosshair is drawn at ``factor`` times its size (PROCEED item 3).

    ``factor`` is a float within :data:`CROSSHAIR_SCALE_RANGE` (0.25-4);
    out of range raises :class:`~apygis.errors.RecordError`.
    """

    factor: float

    def __post_init__(self):
        _check_factor("crosshair scale", self.factor, CROSSHAIR_SCALE_RANGE)


@dataclass(frozen=True)
class AreaShown:
    """AREA measured a closed line: for a display to draw (with the monitor's Message).

    ``points`` are the ring's line point numbers in the walking direction,
    ``ring`` their ground positions (X, Y) in metres, in the same order;
    ``area_m2`` the planimetric area, ``perimeter_m`` the ring's length,
    ``clockwise`` whether the operator walked it clockwise.
    """

    layer: str
    points: tuple[int, ...]
    ring: tuple[tuple[float, float], ...]
    area_m2: float
    perimeter_m: float
    clockwise: bool


@dataclass(frozen=True)
class DhiShown:
    """DHI measured from ``a`` to ``b`` (ground X, Y, Z in metres): for a display to draw.

    ``distance_m`` is horizontal, ``dz_m`` is ``Z_b - Z_a``, ``inclination_deg``
    is ``atan2(dz, distance)``.
    """

    a: tuple[float, float, float]
    b: tuple[float, float, float]
    distance_m: float
    dz_m: float
    inclination_deg: float


@dataclass(frozen=True)
class Save:
    """Save the layer files (``reason``: "autosave", "proceed" or "terminate")."""

    reason: str


@dataclass(frozen=True)
class Terminate:
    """The operator terminated compilation (PROCEED menu, item 4)."""


Effect = (
    Added
    | Deleted
    | Linked
    | Undone
    | Message
    | Ignored
    | Status
    | Plates
    | ZeroPlates
    | DisplayScale
    | CrosshairScale
    | AreaShown
    | DhiShown
    | Save
    | Terminate
)

#: The effects of an entry (an event that changed records): one each.
RECORD_EFFECTS = (Added, Deleted, Linked, Undone)
