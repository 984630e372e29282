"""The compilation engine: APY's COMPILATION program as a pure state machine.

The engine takes **events** and returns **effects** (both in
:mod:`apygis.compile.events`, re-exported here); it does no I/O, so a
session, a test and a replay drive it alike, and the same events always give
the same map and the same engine state.

An **entry** is an event that changes records (an ENTER that adds, a
deletion, a split, a SEARCH that joins, an automatically sampled point, an
UNDO); it gives exactly one record effect (:data:`RECORD_EFFECTS`) per
record change. A session journals an entry before it acknowledges it
(:mod:`apygis.session.journal`).

States
    The engine is in one :class:`Mode` at a time and holds that mode's own
    state (:attr:`Engine.state`, an instance of ``MODE_STATE[mode]``:
    :class:`SymbolPlace`, :class:`LineCode`, :class:`Line`, :class:`Text`,
    :class:`AreaPick`, :class:`DhiPick`, :class:`DeletePlace`,
    :class:`ProceedValue`, or :class:`Idle` for a mode that keeps nothing).
    Only :meth:`Engine._enter` changes the mode, and it installs the new
    mode's state with it, so a mode never sees another mode's leftovers.
    What outlives modes belongs to the engine: the map and the layer compiled
    into, the mark and its model height, the digits typed so far (``buf``),
    the undo stack, the entry counters, the display settings
    (:attr:`Engine.display_scale`, :attr:`Engine.crosshair_scale`) and the
    fine/coarse height step and map/model view.

Buttons
    Digits and POINT collect a number that ENTER confirms; DELETE with
    digits typed clears them. UP, DOWN, STEP, SHUTTER and UNDO act the same
    in every mode. Every other button goes to the mode's handler
    (:data:`Engine.HANDLERS`), which either acts or answers
    :class:`Ignored` and changes nothing; which one, for every mode and
    button, is the table of ``docs/compilation.md`` (a test holds the engine
    to it). Once terminated, the engine ignores every button.

Line mode
    First the decimal rounding down of the height read-out (0-2 decimals,
    ENTER alone keeps 2: ``Z = floor(Z 10^d) / 10^d``), then the two-digit
    line code. ENTER adds a point at the mark (the first ENTER starts a line).
    SEARCH snaps to the nearest line point within the snap tolerance: with no
    line started, a line end (no forward reference) is continued and any
    other point starts a branch there; with a line started, the first point
    of the line closes the ring and any other point ends the line there as a
    branch. PROCEED leaves the line open; PROCEED again returns to the menu.
SAMPLE
    Toggles automatic sampling (across-track error rule). Once the line has
    two points A, B, the track is the straight line through them; when the
    mark leaves the corridor of half-width ``sample_tolerance_mm`` (at map
    scale) around the track, the last mark position that was still inside it
    is entered as a point (or the mark itself if there was none), and the
    track becomes (B, new point). ENTER, SEARCH and PROCEED keep working.
UNDO
    Takes back the last entry: the layer as it was before it, the layer
    compiled into, and the line in progress (first and last point, SAMPLE on
    or off, the last sampled position inside the corridor); not the mode.
    An UNDO outside line mode keeps the line progress it restores aside
    (:attr:`Engine.line_aside`) until a PROCEED returns to the menu: the next
    line mode starts with its SAMPLE setting, and an entry meanwhile records
    it for a later UNDO. (This is how the journals of earlier versions
    replay; see ``docs/compilation.md``.)

Heights: UP/DOWN change the mark's model height by ``geometry.height_step_m``
(ten times that after STEP, which toggles fine and coarse); recorded heights
are ``geometry.correct_z`` (the dpZ correction) of it. SHUTTER toggles where
the floating mark is seen (map or model).

The PROCEED menu's items 1 and 3 set the display scale factor (0.25-25) and
the crosshair scale (0.25-4): the engine keeps them and tells the display
with :class:`DisplayScale` / :class:`CrosshairScale` effects. AREA and DHI
results go to the monitor as a :class:`Message` and to the display as
:class:`AreaShown` / :class:`DhiShown` (what to draw over the map).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, TypeVar, cast

import numpy as np

from apygis.compile.events import (
    CROSSHAIR_SCALE_RANGE,
    DISPLAY_SCALE_RANGE,
    RECORD_EFFECTS,
    Added,
    AreaShown,
    CrosshairScale,
    Deleted,
    DhiShown,
    DisplayScale,
    Effect,
    Event,
    Ignored,
    Keys,
    Linked,
    Mark,
    Message,
    Plates,
    Press,
    Save,
    Status,
    Terminate,
    Undone,
    ZeroPlates,
    event_from_dict,
    event_to_dict,
)
from apygis.compile.geometry import Geometry
from apygis.errors import ApygisError, OrientationError
from apygis.model import topology
from apygis.model.map import MapFile, check_ext
from apygis.model.records import APY_CAPACITY, TEXT_LEN

__all__ = [
    "GLOBAL_BUTTONS",
    "MODE_BUTTONS",
    "MODE_STATE",
    "RECORD_EFFECTS",
    "Added",
    "AreaShown",
    "CrosshairScale",
    "Deleted",
    "DhiShown",
    "DisplayScale",
    "Effect",
    "Engine",
    "Event",
    "Ignored",
    "Keys",
    "Linked",
    "Mark",
    "Message",
    "Mode",
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

DIGITS = frozenset("0123456789")
PROCEED_ITEMS = {
    1: "display scale factor",
    2: "eliminate parallax",
    3: "crosshair scale",
    4: "terminate compilation",
    5: "return to compilation",
    6: "change layer",
}
_DELETE_TABLES = {1: "symbols", 2: "line_points", 3: "texts"}

#: Buttons that act the same in every mode but ``terminated`` (DELETE only while
#: digits are typed: it clears them).
GLOBAL_BUTTONS = (*sorted(DIGITS), "POINT", "UP", "DOWN", "STEP", "SHUTTER", "UNDO")
#: Buttons whose meaning depends on the mode (DELETE with no digits typed).
MODE_BUTTONS = (
    "ENTER", "DELETE", "PROCEED", "DESCR", "SEARCH", "SAMPLE", "LS", "AREA", "DHI", "PLUS",
    "MINUS",
)  # fmt: skip


class Mode(enum.StrEnum):
    """The engine's modes (the value is the name the monitor shows)."""

    MENU = "menu"
    DESCR = "descr"
    SYMBOL_CHOOSE = "symbol_choose"
    SYMBOL_PLACE = "symbol_place"
    LINE_ROUND = "line_round"
    LINE_CODE = "line_code"
    LINE = "line"
    TEXT = "text"
    SPLIT = "split"
    AREA = "area"
    DHI = "dhi"
    DELETE_CHOOSE = "delete_choose"
    DELETE_PLACE = "delete_place"
    PROCEED = "proceed"
    PROCEED_VALUE = "proceed_value"
    LAYER_CHOOSE = "layer_choose"
    TERMINATED = "terminated"


# --------------------------------------------------------------------------- mode states


@dataclass(slots=True)
class Idle:
    """The state of a mode that keeps nothing of its own."""


@dataclass(slots=True)
class SymbolPlace:
    """Placing symbols: the symbol code (00-99) chosen."""

    code: int


@dataclass(slots=True)
class LineCode:
    """Choosing the line code: the height rounding (0-2 decimals) already chosen."""

    decimals: int


#: A line in progress as the undo stack records it: (first, end, sampling, last_inside).
LineProgress = tuple[int | None, int | None, bool, tuple[float, float, float] | None]
_NO_LINE: LineProgress = (None, None, False, None)


@dataclass(slots=True)
class Line:
    """Line mode.

    ``code`` and ``decimals`` (height rounding) were chosen on the way in.
    ``first`` / ``end``: the first and last point of the line in progress
    (None before its first ENTER; ``first`` is None too while continuing a
    line found by SEARCH). ``branch_from``: the junction SEARCH picked for
    the next line's first point. ``sampling``: SAMPLE is on;
    ``last_inside``: the last mark position inside the corridor.
    """

    code: int
    decimals: int
    first: int | None = None
    end: int | None = None
    branch_from: int | None = None
    sampling: bool = False
    last_inside: tuple[float, float, float] | None = None

    def progress(self) -> LineProgress:
        return (self.first, self.end, self.sampling, self.last_inside)

    def restore(self, p: LineProgress) -> None:
        self.first, self.end, self.sampling, self.last_inside = p

    def reset(self) -> None:
        """No line in progress (SAMPLE stays as it is)."""
        self.first = self.end = self.branch_from = None
        self.last_inside = None


@dataclass(slots=True)
class Text:
    """Text mode: the text typed (None until typed)."""

    text: str | None = None


@dataclass(slots=True)
class AreaPick:
    """AREA: the line point of the first ENTER (None before it)."""

    first: int | None = None


@dataclass(slots=True)
class DhiPick:
    """DHI: the ground position (X, Y, Z) of the first ENTER (None before it)."""

    first: tuple[float, float, float] | None = None


@dataclass(slots=True)
class DeletePlace:
    """Deleting: the table ("symbols", "line_points" or "texts") chosen."""

    table: str


@dataclass(slots=True)
class ProceedValue:
    """PROCEED item 1 or 3: which, while its value is typed."""

    item: int


#: The state class each mode holds.
MODE_STATE: dict[Mode, type] = {
    Mode.MENU: Idle,
    Mode.DESCR: Idle,
    Mode.SYMBOL_CHOOSE: Idle,
    Mode.SYMBOL_PLACE: SymbolPlace,
    Mode.LINE_ROUND: Idle,
    Mode.LINE_CODE: LineCode,
    Mode.LINE: Line,
    Mode.TEXT: Text,
    Mode.SPLIT: Idle,
    Mode.AREA: AreaPick,
    Mode.DHI: DhiPick,
    Mode.DELETE_CHOOSE: Idle,
    Mode.DELETE_PLACE: DeletePlace,
    Mode.PROCEED: Idle,
    Mode.PROCEED_VALUE: ProceedValue,
    Mode.LAYER_CHOOSE: Idle,
    Mode.TERMINATED: Idle,
}

#: What each mode expects (the hint of an :class:`Ignored` answer).
HINTS: dict[Mode, str] = {
    Mode.MENU: "DESCR, LS, AREA, DHI, DELETE or PROCEED",
    Mode.DESCR: "item 1 symbol, 2 line, 3 text, ENTER (PROCEED: menu)",
    Mode.SYMBOL_CHOOSE: "symbol number, ENTER (PROCEED lists the symbols)",
    Mode.SYMBOL_PLACE: "ENTER places the symbol, DELETE re-chooses, PROCEED: menu",
    Mode.LINE_ROUND: "height rounding 0-2 decimals, ENTER (PROCEED: menu)",
    Mode.LINE_CODE: "line code, ENTER (PROCEED: menu)",
    Mode.LINE: "ENTER, SEARCH, SAMPLE or PROCEED",
    Mode.TEXT: "type the text, ENTER places it (PROCEED: menu)",
    Mode.SPLIT: "mark on a line side, ENTER (PROCEED: menu)",
    Mode.AREA: "mark on a line point, ENTER (PROCEED: menu)",
    Mode.DHI: "mark, ENTER (PROCEED: menu)",
    Mode.DELETE_CHOOSE: "item 1 symbol, 2 line point, 3 text, ENTER (PROCEED: menu)",
    Mode.DELETE_PLACE: "crosshairs on the record, ENTER (PROCEED: menu)",
    Mode.PROCEED: "item 1-6, ENTER",
    Mode.PROCEED_VALUE: "the value, ENTER",
    Mode.LAYER_CHOOSE: "type the layer extension, ENTER",
    Mode.TERMINATED: "compilation terminated",
}


# --------------------------------------------------------------------------- engine

_S = TypeVar("_S")


class Engine:
    """The compilation state machine over one map.

    Parameters
    ----------
    map : MapFile
        The map compiled into (changed in place).
    layer : str
        The layer compiled into first (created if absent).
    geometry : Geometry
        Tablet <-> ground transform, height correction, plate positions.
    library : SymbolLibrary, optional
        For symbol names in messages.
    snap_mm : float
        SEARCH, LS, AREA and DELETE find records within this distance, in
        millimetres at map scale.
    sample_tolerance_mm : float
        SAMPLE's corridor half-width, millimetres at map scale.
    autosave_every : int
        Entries between automatic saves.
    undo_depth : int
        Entries that UNDO can take back.
    start_z_m : float
        The floating mark's model height at the start (the session uses the
        mean height of the map's records), metres.
    """

    def __init__(
        self,
        map: MapFile,
        layer: str,
        geometry: Geometry,
        *,
        library=None,
        snap_mm: float = 1.0,
        sample_tolerance_mm: float = 0.2,
        autosave_every: int = 50,
        undo_depth: int = 100,
        start_z_m: float = 0.0,
    ):
        self.map = map
        self.layer_ext = check_ext(layer)
        map.layer(self.layer_ext)
        self.geometry = geometry
        self.library = library
        scale = map.scale or 1000
        self.snap_m = snap_mm * scale / 1000.0
        self.sample_tol_m = sample_tolerance_mm * scale / 1000.0
        self.autosave_every = autosave_every
        self.undo_depth = undo_depth
        self.mode = Mode.MENU
        self.state: object = Idle()
        self.buf = ""  # the digits (or typed number) collected for the next ENTER
        self.mark_xy: tuple[float, float] | None = None
        self.z_model = float(start_z_m)
        self.entries = 0
        self.since_save = 0
        self.display_scale = 1.0
        self.crosshair_scale = 1.0
        self.coarse = False
        self.view = "map"
        self.plates_held = False  # the real-time loop refused the mark: the plates wait
        #: The line progress an UNDO restored outside line mode (see the module docstring).
        self.line_aside: LineProgress = _NO_LINE
        self._undo: list[tuple] = []
        self._snaps = 0  # snapshots taken: an edit that fails after its snapshot drops it

    # ------------------------------------------------------------------ state

    @property
    def terminated(self) -> bool:
        return self.mode is Mode.TERMINATED

    @property
    def layer(self):
        return self.map.layer(self.layer_ext)

    def _enter(self, mode: Mode, state=None) -> None:
        """Switch to ``mode`` with its own state (a fresh one if not given)."""
        if state is None:
            state = MODE_STATE[mode]()
        elif type(state) is not MODE_STATE[mode]:
            raise TypeError(f"mode {mode} holds a {MODE_STATE[mode].__name__}, not {state!r}")
        self.mode, self.state = mode, state

    def _st(self, cls: type[_S]) -> _S:
        """The current mode's state, as the ``MODE_STATE`` class of the mode that needs it."""
        return cast(_S, self.state)

    def _line_progress(self) -> LineProgress:
        return self._st(Line).progress() if self.mode is Mode.LINE else self.line_aside

    def _set_line_progress(self, p: LineProgress) -> None:
        if self.mode is Mode.LINE:
            self._st(Line).restore(p)
        else:
            self.line_aside = p

    def mark(self) -> tuple[float, float, float] | None:
        """The mark in ground coordinates, height corrected (metres)."""
        if self.mark_xy is None:
            return None
        X, Y = self.mark_xy
        return (X, Y, self.geometry.correct_z(X, Y, self.z_model))

    def _status(self, prompt: str = "") -> Status:
        lay = self.layer
        counts = {t: len(lay.table(t)) for t in APY_CAPACITY}
        return Status(self.mode, self.layer_ext, prompt, self.mark(), counts)

    def _snapshot(self):
        self._undo.append((self.layer_ext, self.layer.copy(), self._line_progress()))
        del self._undo[: -self.undo_depth]
        self._snaps += 1

    def _restore(self, snapshot) -> None:
        ext, layer, progress = snapshot
        self.map.add_layer(layer)
        self.layer_ext = ext
        self._set_line_progress(progress)

    def _entry(self, out: list) -> None:
        self.entries += 1
        self.since_save += 1
        if self.since_save >= self.autosave_every:
            self.since_save = 0
            out.append(Save("autosave"))

    def _capacity_ok(self, table: str, out: list, extra: int = 1) -> bool:
        cap = APY_CAPACITY[table]
        n = len(self.layer.table(table))
        if n + extra > cap:
            out.append(Message(f"layer {self.layer_ext}: {table.replace('_', ' ')} full ({cap})"))
            return False
        return True

    def _marked(self) -> tuple[float, float, float]:
        """:meth:`mark` where the caller knows the mark is placed (see :meth:`_need_mark`)."""
        return cast(tuple[float, float, float], self.mark())

    def _need_mark(self, out: list) -> bool:
        if self.mark_xy is None:
            out.append(Message("place the mark first"))
            return False
        return True

    def _nearest(self, table: str):
        """Row and distance of the record of ``table`` nearest to the mark, or None."""
        t = self.layer.table(table)
        if self.mark_xy is None or len(t) == 0:
            return None
        d = np.hypot(t["x"] - self.mark_xy[0], t["y"] - self.mark_xy[1])
        i = int(np.argmin(d))
        if d[i] > self.snap_m:
            return None
        return i, float(d[i])

    def _take_number(self, out: list, lo: int, hi: int, what: str) -> int | None:
        try:
            v = int(self.buf)
        except ValueError:
            v = None
        self.buf = ""
        if v is None or not lo <= v <= hi:
            out.append(Message(f"{what}: a number from {lo} to {hi}, please"))
            return None
        return v

    def _ignored(self, b: str, out: list) -> None:
        out.append(Ignored(b, self.mode.value, HINTS[self.mode]))

    # ------------------------------------------------------------------ dispatch

    def handle(self, event: Event) -> list[Effect]:
        """Process one event; returns the effects, in order.

        A press ends with a :class:`Status`; a mark gives :class:`Plates`
        (and, sampling, entries); typed text ends with a :class:`Status`.
        An edit the model refuses (an :class:`~apygis.errors.ApygisError`)
        is taken back whole and told as a :class:`Message`.
        """
        out: list = []
        if self.mode is Mode.TERMINATED:
            if isinstance(event, Press):
                self._ignored(event.button, out)
            else:
                out.append(Message("compilation terminated"))
            return out
        if isinstance(event, Mark):
            self._on_mark(event, out)
            return out
        if isinstance(event, Keys):
            self._on_keys(cast(str, event.text), out)  # decoded by the session
            out.append(self._status())
            return out
        b = event.button
        if b == "UP" or b == "DOWN":
            step = self.geometry.height_step_m * (10 if self.coarse else 1)
            self.z_model += step if b == "UP" else -step
            self._plates(out)
        elif b == "STEP":
            self.coarse = not self.coarse
            out.append(Message(f"height step {'coarse (x10)' if self.coarse else 'fine'}"))
        elif b == "SHUTTER":
            self.view = "model" if self.view == "map" else "map"
            out.append(Message(f"floating mark seen in the {self.view}"))
        elif b == "UNDO":
            self._on_undo(out)
        elif b in DIGITS or b == "POINT":
            self.buf += "." if b == "POINT" else b
        elif b == "DELETE" and self.buf:
            self.buf = ""
        else:
            snaps = self._snaps
            try:
                self.HANDLERS[self.mode](self, b, out)
            except ApygisError as exc:  # an edit the model refused: tell, do not crash
                if self._snaps != snaps:  # it had begun: take it back whole, keep no undo step
                    self._restore(self._undo.pop())
                out.append(Message(str(exc)))
        out.append(self._status(self.buf))
        return out

    def _on_mark(self, ev: Mark, out: list) -> None:
        self.mark_xy = self.geometry.ground(ev.x_mm, ev.y_mm)
        self._plates(out)
        if self.mode is Mode.LINE and self._st(Line).sampling:
            self._sample(out)

    def _plates(self, out: list) -> None:
        """Plate positions for the mark; a mark the real-time loop refuses moves nothing.

        A refused mark (behind a projection centre, beyond the motors' range)
        is told once, and the plates stay where they are until the mark is
        back where they can follow it.
        """
        m = self.mark()
        if m is not None:
            try:
                steps = self.geometry.plates(*m)
            except OrientationError as exc:
                if not self.plates_held:
                    out.append(Message(f"the plates stay where they are: {exc}"))
                self.plates_held = True
                return
            self.plates_held = False
            if steps is not None:
                out.append(Plates(tuple(steps)))

    def _on_keys(self, text: str, out: list) -> None:
        if self.mode is Mode.TEXT:
            self._st(Text).text = text
            out.append(Message(f"text {text!r}: place the mark and ENTER"))
        elif self.mode in (Mode.PROCEED_VALUE, Mode.LAYER_CHOOSE) or self.buf == "":
            self.buf = text.strip()
        else:
            out.append(Message("typed text is for text mode"))

    def _on_undo(self, out: list) -> None:
        if not self._undo:
            out.append(Message("nothing to undo"))
            return
        self._restore(self._undo.pop())
        out.append(Undone(self.layer_ext))
        out.append(Message("last entry undone"))
        self._entry(out)

    def _to_menu(self, out: list) -> None:
        """PROCEED back to the menu: no line in progress (SAMPLE off), and a save."""
        self._enter(Mode.MENU)
        self.line_aside = _NO_LINE
        self.since_save = 0
        out.append(Save("proceed"))

    def _proceed_to_menu(self, b: str, out: list) -> bool:
        """PROCEED in a mode whose PROCEED returns to the menu; True if ``b`` was it."""
        if b == "PROCEED":
            self._to_menu(out)
            return True
        return False

    # ------------------------------------------------------------------ menu

    def _mode_menu(self, b: str, out: list) -> None:
        if b == "DESCR":
            self._enter(Mode.DESCR)
            out.append(Message("item: 1 symbol, 2 line, 3 text; ENTER"))
        elif b == "LS":
            self._enter(Mode.SPLIT)
            out.append(Message("LS: place the mark on a line side, ENTER"))
        elif b == "AREA":
            self._enter(Mode.AREA)
            out.append(Message("AREA: first point of the line, ENTER (clockwise)"))
        elif b == "DHI":
            self._enter(Mode.DHI)
            out.append(Message("DHI: first point, ENTER"))
        elif b == "DELETE":
            self._enter(Mode.DELETE_CHOOSE)
            out.append(Message("DELETE: item 1 symbol, 2 line point, 3 text; ENTER"))
        elif b == "PROCEED":
            self._enter_proceed(out)
        else:
            self._ignored(b, out)

    def _mode_descr(self, b: str, out: list) -> None:
        if b == "ENTER":
            item = self._take_number(out, 1, 3, "item")
            if item is None:
                return
            if item == 1:
                self._enter(Mode.SYMBOL_CHOOSE)
                out.append(Message("symbol number, ENTER (PROCEED lists the symbols)"))
            elif item == 2:
                self._enter(Mode.LINE_ROUND)
                out.append(Message("height rounding: decimals 0-2, ENTER"))
            else:
                self._enter(Mode.TEXT)
                out.append(Message("type the text, place the mark, ENTER"))
        elif b == "PROCEED":
            self._enter(Mode.MENU)  # nothing was entered: no save
        else:
            self._ignored(b, out)

    # ------------------------------------------------------------------ symbols

    def _symbol_name(self, code: int) -> str:
        if self.library is None:
            return ""
        try:
            return self.library.name(code)
        except Exception:
            return ""

    def _mode_symbol_choose(self, b: str, out: list) -> None:
        if b == "ENTER":
            code = self._take_number(out, 0, 99, "symbol")
            if code is not None:
                self._enter(Mode.SYMBOL_PLACE, SymbolPlace(code))
                out.append(Message(f"symbol {code:02d} {self._symbol_name(code)}".rstrip()))
        elif b == "PROCEED":
            if self.library is None:
                out.append(Message("no symbol library loaded"))
            else:
                names = [f"{c:02d} {s.name}" for c, s in self.library.items() if not s.is_free]
                out.append(Message("symbols: " + ", ".join(names)))
        else:
            self._ignored(b, out)

    def _mode_symbol_place(self, b: str, out: list) -> None:
        if b == "ENTER":
            if not (self._need_mark(out) and self._capacity_ok("symbols", out)):
                return
            self._snapshot()
            X, Y, Z = self._marked()
            num = self.layer.add_symbol(X, Y, Z, self._st(SymbolPlace).code)
            out.append(Added(self.layer_ext, "symbols", num))
            self._entry(out)
        elif b == "DELETE":
            self._enter(Mode.SYMBOL_CHOOSE)
            out.append(Message("symbol number, ENTER"))
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    # ------------------------------------------------------------------ lines

    def _mode_line_round(self, b: str, out: list) -> None:
        if b == "ENTER":
            if self.buf == "":
                decimals = 2
            else:
                taken = self._take_number(out, 0, 2, "decimals")
                if taken is None:
                    return
                decimals = taken
            self.buf = ""
            self._enter(Mode.LINE_CODE, LineCode(decimals))
            out.append(Message(f"heights rounded down to {decimals} decimals; line code, ENTER"))
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    def _mode_line_code(self, b: str, out: list) -> None:
        if b == "ENTER":
            code = self._take_number(out, 0, 99, "line code")
            if code is not None:
                sampling = self.line_aside[2]
                self.line_aside = _NO_LINE
                self._enter(Mode.LINE, Line(code, self._st(LineCode).decimals, sampling=sampling))
                out.append(Message(f"line code {code:02d}: ENTER points, SEARCH, SAMPLE, PROCEED"))
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    def _line_z(self, z: float) -> float:
        f = 10.0 ** self._st(Line).decimals
        return math.floor(round(z * f, 6)) / f

    def _add_point(self, xyz, out: list) -> int | None:
        line = self._st(Line)
        if not self._capacity_ok("line_points", out):
            return None
        X, Y, Z = xyz
        Z = self._line_z(Z)
        if line.end is None:
            (num,) = self.layer.add_line([(X, Y, Z)], line.code)
            line.first = num
            if line.branch_from is not None:  # SEARCH picked a junction before this point
                self.layer.join(num, line.branch_from)
                line.branch_from = None
        else:
            (num,) = self.layer.extend_line(line.end, [(X, Y, Z)])
        line.end = num
        line.last_inside = None
        out.append(Added(self.layer_ext, "line_points", num))
        self._entry(out)
        return num

    def _mode_line(self, b: str, out: list) -> None:
        line = self._st(Line)
        if b == "ENTER":
            if self._need_mark(out) and self._capacity_ok("line_points", out):
                self._snapshot()
                self._add_point(self._marked(), out)
        elif b == "SEARCH":
            self._search(out)
        elif b == "SAMPLE":
            line.sampling = not line.sampling
            line.last_inside = None
            out.append(Message(f"sampling {'on' if line.sampling else 'off'}"))
        elif b == "PROCEED":
            if line.end is not None:
                line.reset()
                out.append(Message("line left open; ENTER starts a new line, PROCEED: menu"))
            else:
                self._to_menu(out)
        else:
            self._ignored(b, out)

    def _search(self, out: list) -> None:
        line = self._st(Line)
        hit = self._nearest("line_points")
        if hit is None:
            out.append(Message(f"SEARCH: no line point within {self.snap_m:.2f} m"))
            return
        lp = self.layer.line_points
        target = int(lp["num"][hit[0]])
        if line.end is None:
            if lp["fwd"][hit[0]] == -1:  # a line end: continue that line
                line.first, line.end = None, target
                out.append(Message(f"SEARCH: continuing the line at point {target}"))
            else:  # a junction: the next ENTER starts a branch of it
                line.branch_from = target
                out.append(Message(f"SEARCH: a branch starts at point {target}; ENTER its points"))
            return
        if target == line.end:
            out.append(Message("SEARCH: that is the line's last point"))
            return
        self._snapshot()
        how = self.layer.join(line.end, target)
        out.append(Linked(self.layer_ext, line.end, target, how))
        out.append(Message(f"SEARCH: line {'closed' if how == 'closed' else 'joined'} at {target}"))
        self._entry(out)
        line.reset()

    def _sample(self, out: list) -> None:
        line = self._st(Line)
        if line.end is None:
            return
        lp = self.layer.line_points
        row_b = lp[lp["num"] == line.end][0]
        back = int(row_b["back"])
        if back == -1 or not (lp["num"] == back).any():
            return
        row_a = lp[lp["num"] == back][0]
        ax, ay, bx, by = row_a["x"], row_a["y"], row_b["x"], row_b["y"]
        mx, my, mz = self._marked()
        length = math.hypot(bx - ax, by - ay)
        if length == 0:
            return
        across = abs((bx - ax) * (my - ay) - (by - ay) * (mx - ax)) / length
        if across <= self.sample_tol_m:
            line.last_inside = (mx, my, mz)
            return
        point = line.last_inside or (mx, my, mz)
        if not self._capacity_ok("line_points", out):
            return
        self._snapshot()
        self._add_point(point, out)
        if point != (mx, my, mz):
            self._sample(out)  # test the mark against the new track

    # ------------------------------------------------------------------ text

    def _mode_text(self, b: str, out: list) -> None:
        if b == "ENTER":
            text = self._st(Text).text
            if text is None:
                out.append(Message("type the text first"))
                return
            if not (self._need_mark(out) and self._capacity_ok("texts", out)):
                return
            self._snapshot()
            if len(text) > TEXT_LEN:  # APY's text field; the model itself has no limit
                out.append(
                    Message(f"a text has at most {TEXT_LEN} characters, {text!r} has {len(text)}")
                )
                return
            X, Y, Z = self._marked()
            num = self.layer.add_text(X, Y, Z, text)
            out.append(Added(self.layer_ext, "texts", num))
            self._entry(out)
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    # ------------------------------------------------------------------ LS, AREA, DHI

    def _mode_split(self, b: str, out: list) -> None:
        if b == "ENTER":
            if not (self._need_mark(out) and self._capacity_ok("line_points", out)):
                return
            seg = self._nearest_segment()
            if seg is None:
                out.append(Message(f"LS: no line side within {self.snap_m:.2f} m"))
                return
            a, b2 = seg
            self._snapshot()
            X, Y, Z = self._marked()
            num = self.layer.split(a, b2, (X, Y, Z))
            out.append(Added(self.layer_ext, "line_points", num))
            out.append(Message(f"LS: point {num} between {a} and {b2}"))
            self._entry(out)
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    def _nearest_segment(self):
        lp = self.layer.line_points
        succ, _ = topology.mutual_links(lp)
        i = np.flatnonzero(succ >= 0)
        if len(i) == 0 or self.mark_xy is None:
            return None
        j = succ[i]
        ax, ay, bx, by = lp["x"][i], lp["y"][i], lp["x"][j], lp["y"][j]
        mx, my = self.mark_xy
        dx, dy = bx - ax, by - ay
        ll = dx * dx + dy * dy
        t = ((mx - ax) * dx + (my - ay) * dy) / np.where(ll > 0, ll, 1.0)
        t = np.clip(np.where(ll > 0, t, 0.0), 0.0, 1.0)
        d = np.hypot(ax + t * dx - mx, ay + t * dy - my)
        k = int(np.argmin(d))
        if d[k] > self.snap_m:
            return None
        return int(lp["num"][i[k]]), int(lp["num"][j[k]])

    def _mode_area(self, b: str, out: list) -> None:
        if b == "ENTER":
            pick = self._st(AreaPick)
            hit = self._nearest("line_points")
            if hit is None:
                out.append(Message(f"AREA: no line point within {self.snap_m:.2f} m"))
                return
            num = int(self.layer.line_points["num"][hit[0]])
            if pick.first is None:
                pick.first = num
                out.append(Message(f"AREA: point {num}; next point clockwise, ENTER"))
                return
            first, pick.first = pick.first, None
            try:
                r = self.layer.area(first, num)
            except ApygisError as exc:
                out.append(Message(str(exc)))
                return
            sense = "clockwise" if r.clockwise else "counter-clockwise"
            out.append(
                Message(
                    f"AREA {r.area_m2:.2f} m2 ({r.area_m2 / 10000:.4f} ha), perimeter "
                    f"{r.perimeter_m:.2f} m, {len(r.points)} points, walked {sense}"
                )
            )
            lp = self.layer.line_points
            rows = [int(np.flatnonzero(lp["num"] == n)[0]) for n in r.points]
            ring = tuple((float(lp["x"][i]), float(lp["y"][i])) for i in rows)
            out.append(
                AreaShown(
                    self.layer_ext, tuple(r.points), ring, r.area_m2, r.perimeter_m, r.clockwise
                )
            )
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    def _mode_dhi(self, b: str, out: list) -> None:
        if b == "ENTER":
            pick = self._st(DhiPick)
            if not self._need_mark(out):
                return
            if pick.first is None:
                pick.first = self.mark()
                out.append(Message("DHI: second point, ENTER"))
                return
            a, b2 = pick.first, self._marked()
            d = self.layer.dhi(a, b2)
            pick.first = None
            pct = "vertical" if d.inclination_pct is None else f"{d.inclination_pct:.2f} %"
            out.append(
                Message(
                    f"DHI distance {d.distance_m:.2f} m, height difference {d.dz_m:+.2f} m, "
                    f"inclination {d.inclination_deg:+.3f} deg ({pct})"
                )
            )
            out.append(DhiShown(a, b2, d.distance_m, d.dz_m, d.inclination_deg))
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    # ------------------------------------------------------------------ delete

    def _mode_delete_choose(self, b: str, out: list) -> None:
        if b == "ENTER":
            item = self._take_number(out, 1, 3, "item")
            if item is not None:
                self._enter(Mode.DELETE_PLACE, DeletePlace(_DELETE_TABLES[item]))
                out.append(Message("place the crosshairs on it, ENTER"))
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    def _mode_delete_place(self, b: str, out: list) -> None:
        if b == "ENTER":
            table = self._st(DeletePlace).table
            hit = self._nearest(table)
            if hit is None:
                out.append(Message(f"DELETE: nothing within {self.snap_m:.2f} m"))
                return
            num = int(self.layer.table(table)["num"][hit[0]])
            self._snapshot()
            if table == "symbols":
                self.layer.delete_symbol(num)
            elif table == "texts":
                self.layer.delete_text(num)
            else:
                self.layer.delete_line_point(num)
            out.append(Deleted(self.layer_ext, table, num))
            self._entry(out)
        elif not self._proceed_to_menu(b, out):
            self._ignored(b, out)

    # ------------------------------------------------------------------ PROCEED menu

    def _enter_proceed(self, out: list) -> None:
        self._enter(Mode.PROCEED)
        lines = []
        for ext in sorted(self.map.layers):
            c = self.map.layers[ext].counts()
            pct = {k: 100.0 * c[k] / cap for k, cap in APY_CAPACITY.items()}
            lines.append(
                f"{self.map.id}.{ext}: {c['symbols']} symbols ({pct['symbols']:.1f} %), "
                f"{c['line_points']} line points ({pct['line_points']:.1f} %), "
                f"{c['texts']} texts ({pct['texts']:.1f} %)"
            )
        out.append(Message("\n".join(lines)))
        out.append(Message("; ".join(f"{k} {v}" for k, v in PROCEED_ITEMS.items())))
        self.since_save = 0
        out.append(Save("proceed"))

    def _mode_proceed(self, b: str, out: list) -> None:
        if b != "ENTER":
            self._ignored(b, out)
            return
        item = self._take_number(out, 1, 6, "PROCEED item")
        if item is None:
            return
        if item in (1, 3):
            self._enter(Mode.PROCEED_VALUE, ProceedValue(item))
            lo, hi = DISPLAY_SCALE_RANGE if item == 1 else CROSSHAIR_SCALE_RANGE
            out.append(Message(f"{PROCEED_ITEMS[item]} ({lo:g}-{hi:g}), ENTER"))
        elif item == 2:
            out.append(ZeroPlates())
            out.append(Message("parallax eliminated: correction plates re-zeroed"))
        elif item == 4:
            self._enter(Mode.TERMINATED)
            out.append(Save("terminate"))
            out.append(Terminate())
        elif item == 5:
            self._enter(Mode.MENU)
        else:
            self._enter(Mode.LAYER_CHOOSE)
            out.append(Message("layer extension (type it), ENTER"))

    def _mode_proceed_value(self, b: str, out: list) -> None:
        if b != "ENTER":
            self._ignored(b, out)
            return
        try:
            v = float(self.buf)
        except ValueError:
            v = float("nan")
        self.buf = ""
        item = self._st(ProceedValue).item
        lo, hi = DISPLAY_SCALE_RANGE if item == 1 else CROSSHAIR_SCALE_RANGE
        if not lo <= v <= hi:
            out.append(Message(f"a value from {lo} to {hi}, please"))
            return
        if item == 1:
            self.display_scale = v
            out.append(DisplayScale(v))
        else:
            self.crosshair_scale = v
            out.append(CrosshairScale(v))
        self._enter(Mode.PROCEED)

    def _mode_layer_choose(self, b: str, out: list) -> None:
        if b != "ENTER":
            self._ignored(b, out)
            return
        ext, self.buf = self.buf, ""
        try:
            self.layer_ext = check_ext(ext)
        except ApygisError as exc:
            out.append(Message(str(exc)))
            return
        self.map.layer(self.layer_ext)
        out.append(Message(f"compiling into {self.map.id}.{self.layer_ext}"))
        self._enter(Mode.MENU)

    def _mode_terminated(self, b: str, out: list) -> None:
        self._ignored(b, out)

    #: The handler of each mode: ``handler(engine, button, effects)``.
    HANDLERS: ClassVar[dict[Mode, Callable[[Engine, str, list], None]]] = {
        Mode.MENU: _mode_menu,
        Mode.DESCR: _mode_descr,
        Mode.SYMBOL_CHOOSE: _mode_symbol_choose,
        Mode.SYMBOL_PLACE: _mode_symbol_place,
        Mode.LINE_ROUND: _mode_line_round,
        Mode.LINE_CODE: _mode_line_code,
        Mode.LINE: _mode_line,
        Mode.TEXT: _mode_text,
        Mode.SPLIT: _mode_split,
        Mode.AREA: _mode_area,
        Mode.DHI: _mode_dhi,
        Mode.DELETE_CHOOSE: _mode_delete_choose,
        Mode.DELETE_PLACE: _mode_delete_place,
        Mode.PROCEED: _mode_proceed,
        Mode.PROCEED_VALUE: _mode_proceed_value,
        Mode.LAYER_CHOOSE: _mode_layer_choose,
        Mode.TERMINATED: _mode_terminated,
    }
