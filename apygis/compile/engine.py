"""The compilation engine: APY's COMPILATION program as a pure state machine.

The engine takes **events** and returns **effects**; it does no I/O, so a
session, a test and a replay drive it alike, and the same events always give
the same map.

Events
    :class:`Mark` (the floating mark moved to a tablet position, mm),
    :class:`Press` (one of the 27 cursor buttons, by name: ``"0"``-``"9"``,
    ``"ENTER"``, ``"DELETE"``, ``"PROCEED"``, ``"DESCR"``, ``"SEARCH"``,
    ``"SAMPLE"``, ``"LS"``, ``"AREA"``, ``"DHI"``, ``"UP"``, ``"DOWN"``,
    ``"UNDO"``, ``"POINT"``, ...; see ``docs/button-pad.md``),
    :class:`Keys` (text typed on the keyboard).
Effects
    :class:`Added` / :class:`Deleted` (records), :class:`Linked` (a line
    end joined by SEARCH), :class:`Undone`,
    :class:`Message` (for the operator's monitor), :class:`Status` (mode,
    item, counts, mark), :class:`Plates` (motor positions for the four
    correction plates), :class:`ZeroPlates` (eliminate parallax),
    :class:`Save` (autosave after every 50 entries, on PROCEED, at the end),
    :class:`Terminate`.

An **entry** is an event that changes records (an ENTER that adds, a
deletion, a split, an automatically sampled point, an UNDO). A session
journals an entry before it acknowledges it (``apygis.compile.session``).

Modes follow the seed's COMPILATION section; the compilation menu is the
start. DESCR then an item number and ENTER chooses 1 symbol, 2 line, 3 text;
LS, AREA, DHI, DELETE and PROCEED are buttons of their own. Digits are
collected and confirmed with ENTER; DELETE in a number entry clears it.

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

Heights: UP/DOWN change the mark's model height by ``geometry.height_step_m``
(ten times that after STEP, which toggles fine and coarse); recorded heights
are ``geometry.correct_z`` (the dpZ correction) of it. SHUTTER toggles where
the floating mark is seen (map or model); PLUS and MINUS are for symbol
creation and do nothing here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from apygis.compile.geometry import Geometry
from apygis.errors import ApygisError, OrientationError
from apygis.model import topology
from apygis.model.map import MapFile, check_ext
from apygis.model.records import APY_CAPACITY

__all__ = [
    "Added",
    "Deleted",
    "Engine",
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

DIGITS = frozenset("0123456789")
ITEMS = {1: "symbol", 2: "line", 3: "text"}
PROCEED_ITEMS = {
    1: "display scale factor",
    2: "eliminate parallax",
    3: "crosshair scale",
    4: "terminate compilation",
    5: "return to compilation",
    6: "change layer",
}


# --------------------------------------------------------------------------- events


@dataclass(frozen=True)
class Mark:
    """The floating mark is at tablet position (x_mm, y_mm)."""

    x_mm: float
    y_mm: float


@dataclass(frozen=True)
class Press:
    """A cursor button was pressed."""

    button: str


@dataclass(frozen=True)
class Keys:
    """Text typed on the keyboard."""

    text: str


def event_to_dict(ev) -> dict:
    """A JSON-ready form of an event (the session journal's records)."""
    if isinstance(ev, Mark):
        return {"mark": [ev.x_mm, ev.y_mm]}
    if isinstance(ev, Press):
        return {"press": ev.button}
    return {"keys": ev.text}


def event_from_dict(d: dict):
    if "mark" in d:
        x, y = d["mark"]
        return Mark(float(x), float(y))
    if "press" in d:
        return Press(str(d["press"]))
    if "keys" in d:
        return Keys(str(d["keys"]))
    raise ValueError(f"not an event: {d!r}")


# --------------------------------------------------------------------------- effects


@dataclass(frozen=True)
class Added:
    layer: str
    table: str
    num: int


@dataclass(frozen=True)
class Deleted:
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
    layer: str


@dataclass(frozen=True)
class Message:
    text: str


@dataclass(frozen=True)
class Status:
    mode: str
    layer: str
    prompt: str
    mark: tuple[float, float, float] | None
    counts: dict = field(hash=False, compare=False, default_factory=dict)


@dataclass(frozen=True)
class Plates:
    steps: tuple


@dataclass(frozen=True)
class ZeroPlates:
    """Eliminate parallax: the plates' present position becomes their zero."""


@dataclass(frozen=True)
class Save:
    reason: str


@dataclass(frozen=True)
class Terminate:
    """The operator terminated compilation (PROCEED menu, item 4)."""


RECORD_EFFECTS = (Added, Deleted, Linked, Undone)


# --------------------------------------------------------------------------- engine


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
        self.mode = "menu"
        self.buf = ""
        self.mark_xy: tuple[float, float] | None = None
        self.z_model = float(start_z_m)
        self.entries = 0
        self.since_save = 0
        self.display_scale = 1.0
        self.crosshair_scale = 1.0
        self.symbol_code: int | None = None
        self.text: str | None = None
        self.line_code = 0
        self.decimals = 2
        self.line_first: int | None = None
        self.line_end: int | None = None
        self.branch_from: int | None = None
        self.sampling = False
        self.last_inside: tuple[float, float, float] | None = None
        self.first_pick: tuple | None = None
        self.delete_kind: str | None = None
        self.proceed_item: int | None = None
        self.terminated = False
        self.coarse = False
        self.view = "map"
        self.plates_held = False  # the real-time loop refused the mark: the plates wait
        self._undo: list[tuple] = []
        self._snaps = 0  # snapshots taken: an edit that fails after its snapshot drops it

    # ------------------------------------------------------------------ helpers

    @property
    def layer(self):
        return self.map.layer(self.layer_ext)

    def mark(self) -> tuple[float, float, float] | None:
        """The mark in ground coordinates, height corrected (metres)."""
        if self.mark_xy is None:
            return None
        X, Y = self.mark_xy
        return (X, Y, self.geometry.correct_z(X, Y, self.z_model))

    def _line_z(self, z: float) -> float:
        f = 10.0**self.decimals
        return math.floor(round(z * f, 6)) / f

    def _status(self, prompt: str = "") -> Status:
        lay = self.layer
        counts = {t: len(lay.table(t)) for t in APY_CAPACITY}
        return Status(self.mode, self.layer_ext, prompt, self.mark(), counts)

    def _snapshot(self):
        state = (self.line_first, self.line_end, self.sampling, self.last_inside)
        self._undo.append((self.layer_ext, self.layer.copy(), state))
        del self._undo[: -self.undo_depth]
        self._snaps += 1

    def _restore(self, snapshot) -> None:
        ext, layer, state = snapshot
        self.map.add_layer(layer)
        self.layer_ext = ext
        self.line_first, self.line_end, self.sampling, self.last_inside = state

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

    # ------------------------------------------------------------------ dispatch

    def handle(self, event) -> list:
        """Process one event; returns the effects, in order."""
        out: list = []
        if self.terminated:
            out.append(Message("compilation terminated"))
            return out
        if isinstance(event, Mark):
            self._on_mark(event, out)
            return out
        if isinstance(event, Keys):
            self._on_keys(event.text, out)
            out.append(self._status())
            return out
        b = event.button
        if b in ("UP", "DOWN"):
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
            handler = getattr(self, f"_mode_{self.mode}")
            snaps = self._snaps
            try:
                handler(b, out)
            except ApygisError as exc:  # an edit the model refused: tell, do not crash
                if self._snaps != snaps:  # it had begun: take it back whole, keep no undo step
                    self._restore(self._undo.pop())
                out.append(Message(str(exc)))
        out.append(self._status(self.buf))
        return out

    def _on_mark(self, ev: Mark, out: list) -> None:
        self.mark_xy = self.geometry.ground(ev.x_mm, ev.y_mm)
        self._plates(out)
        if self.mode == "line" and self.sampling:
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
        if self.mode == "text":
            self.text = text
            out.append(Message(f"text {text!r}: place the mark and ENTER"))
        elif self.mode in ("proceed_value", "layer_choose") or self.buf == "":
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

    # ------------------------------------------------------------------ menu

    def _mode_menu(self, b: str, out: list) -> None:
        if b == "DESCR":
            self.mode = "descr"
            out.append(Message("item: 1 symbol, 2 line, 3 text; ENTER"))
        elif b == "LS":
            self.mode = "split"
            out.append(Message("LS: place the mark on a line side, ENTER"))
        elif b == "AREA":
            self.mode, self.first_pick = "area", None
            out.append(Message("AREA: first point of the line, ENTER (clockwise)"))
        elif b == "DHI":
            self.mode, self.first_pick = "dhi", None
            out.append(Message("DHI: first point, ENTER"))
        elif b == "DELETE":
            self.mode = "delete_choose"
            out.append(Message("DELETE: item 1 symbol, 2 line point, 3 text; ENTER"))
        elif b == "PROCEED":
            self._enter_proceed(out)
        else:
            out.append(Message(f"{b}: not in the compilation menu"))

    def _mode_descr(self, b: str, out: list) -> None:
        if b == "ENTER":
            item = self._take_number(out, 1, 3, "item")
            if item is None:
                return
            if item == 1:
                self.mode = "symbol_choose"
                out.append(Message("symbol number, ENTER (PROCEED lists the symbols)"))
            elif item == 2:
                self.mode = "line_round"
                out.append(Message("height rounding: decimals 0-2, ENTER"))
            else:
                self.mode, self.text = "text", None
                out.append(Message("type the text, place the mark, ENTER"))
        elif b == "PROCEED":
            self.mode = "menu"
        else:
            out.append(Message(f"{b}: choose an item number"))

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
                self.symbol_code = code
                self.mode = "symbol_place"
                out.append(Message(f"symbol {code:02d} {self._symbol_name(code)}".rstrip()))
        elif b == "PROCEED":
            if self.library is None:
                out.append(Message("no symbol library loaded"))
            else:
                names = [f"{c:02d} {s.name}" for c, s in self.library.items() if not s.is_free]
                out.append(Message("symbols: " + ", ".join(names)))
        else:
            out.append(Message(f"{b}: choose a symbol number"))

    def _mode_symbol_place(self, b: str, out: list) -> None:
        if b == "ENTER":
            if not (self._need_mark(out) and self._capacity_ok("symbols", out)):
                return
            self._snapshot()
            X, Y, Z = self.mark()
            num = self.layer.add_symbol(X, Y, Z, self.symbol_code)
            out.append(Added(self.layer_ext, "symbols", num))
            self._entry(out)
        elif b == "DELETE":
            self.mode = "symbol_choose"
            out.append(Message("symbol number, ENTER"))
        elif b == "PROCEED":
            self._to_menu(out)
        else:
            out.append(Message(f"{b}: ENTER places symbol {self.symbol_code:02d}"))

    # ------------------------------------------------------------------ lines

    def _mode_line_round(self, b: str, out: list) -> None:
        if b == "ENTER":
            if self.buf == "":
                self.decimals = 2
            else:
                d = self._take_number(out, 0, 2, "decimals")
                if d is None:
                    return
                self.decimals = d
            self.buf = ""
            self.mode = "line_code"
            out.append(
                Message(f"heights rounded down to {self.decimals} decimals; line code, ENTER")
            )
        elif b == "PROCEED":
            self._to_menu(out)

    def _mode_line_code(self, b: str, out: list) -> None:
        if b == "ENTER":
            code = self._take_number(out, 0, 99, "line code")
            if code is not None:
                self.line_code = code
                self.mode = "line"
                self._reset_line()
                out.append(Message(f"line code {code:02d}: ENTER points, SEARCH, SAMPLE, PROCEED"))
        elif b == "PROCEED":
            self._to_menu(out)

    def _reset_line(self) -> None:
        self.line_first = self.line_end = self.branch_from = None
        self.last_inside = None

    def _add_point(self, xyz, out: list) -> int | None:
        if not self._capacity_ok("line_points", out):
            return None
        X, Y, Z = xyz
        Z = self._line_z(Z)
        if self.line_end is None:
            (num,) = self.layer.add_line([(X, Y, Z)], self.line_code)
            self.line_first = num
            if self.branch_from is not None:  # SEARCH picked a junction before this point
                self.layer.join(num, self.branch_from)
                self.branch_from = None
        else:
            (num,) = self.layer.extend_line(self.line_end, [(X, Y, Z)])
        self.line_end = num
        self.last_inside = None
        out.append(Added(self.layer_ext, "line_points", num))
        self._entry(out)
        return num

    def _mode_line(self, b: str, out: list) -> None:
        if b == "ENTER":
            if self._need_mark(out) and self._capacity_ok("line_points", out):
                self._snapshot()
                self._add_point(self.mark(), out)
        elif b == "SEARCH":
            self._search(out)
        elif b == "SAMPLE":
            self.sampling = not self.sampling
            self.last_inside = None
            out.append(Message(f"sampling {'on' if self.sampling else 'off'}"))
        elif b == "PROCEED":
            if self.line_end is not None:
                self._reset_line()
                out.append(Message("line left open; ENTER starts a new line, PROCEED: menu"))
            else:
                self._to_menu(out)
        else:
            out.append(Message(f"{b}: not in line mode"))

    def _search(self, out: list) -> None:
        hit = self._nearest("line_points")
        if hit is None:
            out.append(Message(f"SEARCH: no line point within {self.snap_m:.2f} m"))
            return
        lp = self.layer.line_points
        target = int(lp["num"][hit[0]])
        if self.line_end is None:
            if lp["fwd"][hit[0]] == -1:  # a line end: continue that line
                self.line_first, self.line_end = None, target
                out.append(Message(f"SEARCH: continuing the line at point {target}"))
            else:  # a junction: the next ENTER starts a branch of it
                self.branch_from = target
                out.append(Message(f"SEARCH: a branch starts at point {target}; ENTER its points"))
            return
        if target == self.line_end:
            out.append(Message("SEARCH: that is the line's last point"))
            return
        self._snapshot()
        how = self.layer.join(self.line_end, target)
        out.append(Linked(self.layer_ext, self.line_end, target, how))
        out.append(Message(f"SEARCH: line {'closed' if how == 'closed' else 'joined'} at {target}"))
        self._entry(out)
        self._reset_line()

    def _sample(self, out: list) -> None:
        if self.line_end is None:
            return
        lp = self.layer.line_points
        row_b = lp[lp["num"] == self.line_end][0]
        back = int(row_b["back"])
        if back == -1 or not (lp["num"] == back).any():
            return
        row_a = lp[lp["num"] == back][0]
        ax, ay, bx, by = row_a["x"], row_a["y"], row_b["x"], row_b["y"]
        mx, my, mz = self.mark()
        length = math.hypot(bx - ax, by - ay)
        if length == 0:
            return
        across = abs((bx - ax) * (my - ay) - (by - ay) * (mx - ax)) / length
        if across <= self.sample_tol_m:
            self.last_inside = (mx, my, mz)
            return
        point = self.last_inside or (mx, my, mz)
        if not self._capacity_ok("line_points", out):
            return
        self._snapshot()
        self._add_point(point, out)
        if point != (mx, my, mz):
            self._sample(out)  # test the mark against the new track

    # ------------------------------------------------------------------ text

    def _mode_text(self, b: str, out: list) -> None:
        if b == "ENTER":
            if self.text is None:
                out.append(Message("type the text first"))
                return
            if not (self._need_mark(out) and self._capacity_ok("texts", out)):
                return
            self._snapshot()
            X, Y, Z = self.mark()
            num = self.layer.add_text(X, Y, Z, self.text)
            out.append(Added(self.layer_ext, "texts", num))
            self._entry(out)
        elif b == "PROCEED":
            self._to_menu(out)

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
            X, Y, Z = self.mark()
            num = self.layer.split(a, b2, (X, Y, Z))
            out.append(Added(self.layer_ext, "line_points", num))
            out.append(Message(f"LS: point {num} between {a} and {b2}"))
            self._entry(out)
        elif b == "PROCEED":
            self._to_menu(out)

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
            hit = self._nearest("line_points")
            if hit is None:
                out.append(Message(f"AREA: no line point within {self.snap_m:.2f} m"))
                return
            num = int(self.layer.line_points["num"][hit[0]])
            if self.first_pick is None:
                self.first_pick = (num,)
                out.append(Message(f"AREA: point {num}; next point clockwise, ENTER"))
                return
            first = self.first_pick[0]
            self.first_pick = None
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
        elif b == "PROCEED":
            self._to_menu(out)

    def _mode_dhi(self, b: str, out: list) -> None:
        if b == "ENTER":
            if not self._need_mark(out):
                return
            if self.first_pick is None:
                self.first_pick = self.mark()
                out.append(Message("DHI: second point, ENTER"))
                return
            d = self.layer.dhi(self.first_pick, self.mark())
            self.first_pick = None
            pct = "vertical" if d.inclination_pct is None else f"{d.inclination_pct:.2f} %"
            out.append(
                Message(
                    f"DHI distance {d.distance_m:.2f} m, height difference {d.dz_m:+.2f} m, "
                    f"inclination {d.inclination_deg:+.3f} deg ({pct})"
                )
            )
        elif b == "PROCEED":
            self._to_menu(out)

    # ------------------------------------------------------------------ delete

    def _mode_delete_choose(self, b: str, out: list) -> None:
        if b == "ENTER":
            item = self._take_number(out, 1, 3, "item")
            if item is not None:
                self.delete_kind = {1: "symbols", 2: "line_points", 3: "texts"}[item]
                self.mode = "delete_place"
                out.append(Message("place the crosshairs on it, ENTER"))
        elif b == "PROCEED":
            self._to_menu(out)

    def _mode_delete_place(self, b: str, out: list) -> None:
        if b == "ENTER":
            hit = self._nearest(self.delete_kind)
            if hit is None:
                out.append(Message(f"DELETE: nothing within {self.snap_m:.2f} m"))
                return
            num = int(self.layer.table(self.delete_kind)["num"][hit[0]])
            self._snapshot()
            if self.delete_kind == "symbols":
                self.layer.delete_symbol(num)
            elif self.delete_kind == "texts":
                self.layer.delete_text(num)
            else:
                self.layer.delete_line_point(num)
            out.append(Deleted(self.layer_ext, self.delete_kind, num))
            self._entry(out)
        elif b == "PROCEED":
            self._to_menu(out)

    # ------------------------------------------------------------------ PROCEED menu

    def _to_menu(self, out: list) -> None:
        self.mode = "menu"
        self._reset_line()
        self.sampling = False
        self.since_save = 0
        out.append(Save("proceed"))

    def _enter_proceed(self, out: list) -> None:
        self.mode = "proceed"
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
            out.append(Message(f"{b}: choose 1-6 and ENTER"))
            return
        item = self._take_number(out, 1, 6, "PROCEED item")
        if item is None:
            return
        if item in (1, 3):
            self.proceed_item = item
            self.mode = "proceed_value"
            rng = "0.25-25" if item == 1 else "0.25-4"
            out.append(Message(f"{PROCEED_ITEMS[item]} ({rng}), ENTER"))
        elif item == 2:
            out.append(ZeroPlates())
            out.append(Message("parallax eliminated: correction plates re-zeroed"))
        elif item == 4:
            self.terminated = True
            out.append(Save("terminate"))
            out.append(Terminate())
        elif item == 5:
            self.mode = "menu"
        else:
            self.mode = "layer_choose"
            out.append(Message("layer extension (type it), ENTER"))

    def _mode_proceed_value(self, b: str, out: list) -> None:
        if b != "ENTER":
            return
        try:
            v = float(self.buf)
        except ValueError:
            v = float("nan")
        self.buf = ""
        lo, hi = (0.25, 25.0) if self.proceed_item == 1 else (0.25, 4.0)
        if not lo <= v <= hi:
            out.append(Message(f"a value from {lo} to {hi}, please"))
            return
        if self.proceed_item == 1:
            self.display_scale = v
        else:
            self.crosshair_scale = v
        out.append(Message(f"{PROCEED_ITEMS[self.proceed_item]} {v:g}"))
        self.mode = "proceed"

    def _mode_layer_choose(self, b: str, out: list) -> None:
        if b != "ENTER":
            return
        ext, self.buf = self.buf, ""
        try:
            self.layer_ext = check_ext(ext)
        except ApygisError as exc:
            out.append(Message(str(exc)))
            return
        self.map.layer(self.layer_ext)
        out.append(Message(f"compiling into {self.map.id}.{self.layer_ext}"))
        self.mode = "menu"
