"""PLOTTER.DEF: the plotter parameters of ``apygis plot``.

APY's Print & Plot read "a PLOTTER.DEF file to set the plotter parameters as
required". apygis keeps that idea in a small text format, specified in
``docs/plotter-def.md``: one ``key value ...`` setting per line, comments
after ``;`` (or after a ``#`` that does not start a ``#rrggbb`` colour)::

    paper A3 landscape        ; A0-A4, auto, or W x H in mm
    scale 5000                ; plot scale denominator (default: the map's)
    window 2683000 1247000 2685400 1248600   ; the map window, ground X0 Y0 X1 Y1
    margin 10                 ; mm, or: left bottom right top
    grid crosses              ; crosses, lines or off; grid-interval in CRS units
    symbol-size 3             ; mm, the width of a 15x15 symbol bitmap
    text-height 2.5           ; mm, the cap height of texts
    pendef 2 #0070c0 0.25     ; pen number, colour, width in mm
    pen h * 2                 ; layer, code or *, pen [symbols|lines|texts]

A file is read on top of :meth:`PlotterDef.default`: every key it gives
replaces the default, ``pendef`` adds or redefines a pen, ``pen`` adds an
assignment rule and ``clear-pen-rules`` drops the rules given so far (the
built-in ones included).

Examples
--------
>>> pdef = parse_plotdef("paper A3 landscape\\nscale 2500\\npen r 21 3\\n")
>>> pdef.paper.size_mm(), pdef.scale
((420.0, 297.0), 2500)
>>> pdef.pen_for("r", "lines", 21), pdef.pen_for("h", "lines", 31)
(3, 2)
>>> parse_plotdef("paper B5\\n", path="PLOTTER.DEF")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
apygis.errors.FormatError: PLOTTER.DEF: line 1: paper: expected A0-A4, auto or ...
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from apygis.errors import FormatError
from apygis.formats._io import read_bytes

__all__ = [
    "COLOURS",
    "GRID_STYLES",
    "ISO_A_SIZES",
    "KINDS",
    "PaperSpec",
    "PenDef",
    "PenRule",
    "PlotterDef",
    "parse_colour",
    "parse_paper",
    "parse_plotdef",
    "read_plotdef",
]

#: ISO 216 A sizes in mm, portrait (width, height).
ISO_A_SIZES = {
    "A0": (841.0, 1189.0),
    "A1": (594.0, 841.0),
    "A2": (420.0, 594.0),
    "A3": (297.0, 420.0),
    "A4": (210.0, 297.0),
}

#: Colour names a ``pendef`` may use (RGB 0-255); ``#rrggbb`` works too.
COLOURS = {
    "black": (0, 0, 0),
    "white": (255, 255, 255),
    "grey": (128, 128, 128),
    "gray": (128, 128, 128),
    "red": (200, 0, 0),
    "green": (0, 140, 60),
    "blue": (0, 90, 200),
    "cyan": (0, 160, 200),
    "magenta": (190, 0, 150),
    "yellow": (230, 190, 0),
    "orange": (240, 120, 0),
    "brown": (150, 80, 20),
}

#: The record kinds a ``pen`` rule may be limited to.
KINDS = ("symbols", "lines", "texts")

#: The styles of the coordinate grid (``grid`` key).
GRID_STYLES = ("crosses", "lines", "off")

_HEX_COLOUR = re.compile(r"#[0-9A-Fa-f]{6}")
_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?")


@dataclass(frozen=True)
class PaperSpec:
    """The paper: an ISO A size or ``auto`` with an orientation, or a custom size.

    Attributes
    ----------
    name : str
        ``"A0"`` ... ``"A4"``, ``"auto"`` (the smallest A size that holds the
        plot) or ``"custom"``.
    orientation : str or None
        ``"portrait"``, ``"landscape"`` or None (the one that fits the plot
        better). Custom sizes have None: their width and height are as given.
    width_mm, height_mm : float
        The custom size (0 for A sizes and ``auto``).
    """

    name: str = "auto"
    orientation: str | None = None
    width_mm: float = 0.0
    height_mm: float = 0.0

    def size_mm(self, orientation: str | None = None) -> tuple[float, float]:
        """(width, height) in mm; an A size in ``orientation`` (default its own, else portrait).

        >>> PaperSpec("A4", "landscape").size_mm()
        (297.0, 210.0)
        """
        if self.name == "custom":
            return (self.width_mm, self.height_mm)
        if self.name == "auto":
            raise ValueError("paper 'auto' has no size until the plot is laid out")
        w, h = ISO_A_SIZES[self.name]
        if (orientation or self.orientation) == "landscape":
            return (h, w)
        return (w, h)

    def label(self, orientation: str | None = None) -> str:
        """Paper in words: ``"A3 landscape"`` or ``"600 x 400 mm"``."""
        if self.name == "custom":
            return f"{self.width_mm:g} x {self.height_mm:g} mm"
        o = orientation or self.orientation
        return f"{self.name} {o}" if o else self.name


@dataclass(frozen=True)
class PenDef:
    """A pen: its number (HP-GL ``SP n``), colour (RGB 0-255, for SVG/PDF) and width in mm."""

    number: int
    colour: tuple[int, int, int]
    width_mm: float

    @property
    def hex(self) -> str:
        """The colour as ``#rrggbb``.

        >>> PenDef(2, (0, 112, 192), 0.25).hex
        '#0070c0'
        """
        return "#{:02x}{:02x}{:02x}".format(*self.colour)


@dataclass(frozen=True)
class PenRule:
    """Records of ``layer`` (or ``"*"``) with ``code`` (or None: any) of ``kind`` get ``pen``.

    ``kind`` is ``"symbols"``, ``"lines"``, ``"texts"`` or None (any). The
    most specific matching rule wins: an exact layer counts 4, an exact code
    2 and an exact kind 1; between rules of equal weight the later one wins.
    """

    layer: str
    code: int | None
    pen: int
    kind: str | None = None

    def weight(self) -> int:
        return 4 * (self.layer != "*") + 2 * (self.code is not None) + (self.kind is not None)

    def matches(self, layer: str, kind: str, code: int | None) -> bool:
        return (
            (self.layer == "*" or self.layer == layer)
            and (self.kind is None or self.kind == kind)
            and (self.code is None or self.code == code)
        )


def _default_pens() -> dict[int, PenDef]:
    return {
        1: PenDef(1, COLOURS["black"], 0.35),
        2: PenDef(2, (0, 112, 192), 0.25),
        3: PenDef(3, COLOURS["red"], 0.5),
        4: PenDef(4, COLOURS["brown"], 0.25),
        5: PenDef(5, COLOURS["green"], 0.25),
        6: PenDef(6, COLOURS["grey"], 0.18),
    }


def _default_rules() -> tuple[PenRule, ...]:
    return (
        PenRule("*", None, 1),
        PenRule("e", None, 4),
        PenRule("h", None, 2),
    )


@dataclass(frozen=True)
class PlotterDef:
    """The plotter parameters. Build one with :func:`parse_plotdef` or :meth:`default`.

    Attributes
    ----------
    paper : PaperSpec
        The paper (default ``auto``: the smallest A size that holds the plot).
    scale : int or None
        Plot scale denominator; None plots at the map's compilation scale.
    origin : (float, float) or None
        Ground X, Y (CRS units) at the paper's lower-left corner: fixes where
        the ground lies on the paper; the map window is then what the neat
        line encloses. None (the default) centres the window on the paper.
    window : (float, float, float, float) or None
        The map window ``X0, Y0, X1, Y1`` (ground, CRS units): what the neat
        line encloses. None: the plotted data, padded and rounded outward.
    margins_mm : (float, float, float, float)
        Left, bottom, right, top margins: paper left white at its edges.
    symbol_size_mm : float
        Width (and height) of a symbol's 15x15 bitmap on paper.
    text_height_mm : float
        Cap height of map texts and spot-height labels.
    height_decimals : int
        Decimals of spot-height labels (0 to 3).
    title : bool
        Draw the title block (map ID, scale, CRS, date, sources) in the margin.
    legend : bool
        Draw the legend of the symbols and line codes used, the scale bar and
        the north arrow in the margin.
    grid : str
        The coordinate grid: ``"crosses"``, ``"lines"`` or ``"off"``; it is
        labelled at the neat line unless off.
    grid_interval : float or None
        Grid interval in CRS units; None chooses a round one (at least 35 mm
        on paper).
    frame : bool
        Draw the neat line.
    frame_pen : int
        Pen of the neat line and the margin's drawing and texts.
    grid_pen : int or None
        Pen of the grid and its labels; None: the frame pen.
    pens : dict of int to PenDef
        The pens by number.
    rules : tuple of PenRule
        Pen assignments, in file order (see :class:`PenRule`).
    """

    paper: PaperSpec = field(default_factory=PaperSpec)
    scale: int | None = None
    origin: tuple[float, float] | None = None
    window: tuple[float, float, float, float] | None = None
    margins_mm: tuple[float, float, float, float] = (10.0, 10.0, 10.0, 10.0)
    symbol_size_mm: float = 3.0
    text_height_mm: float = 2.5
    height_decimals: int = 1
    title: bool = True
    legend: bool = True
    grid: str = "crosses"
    grid_interval: float | None = None
    frame: bool = True
    frame_pen: int = 1
    grid_pen: int | None = None
    pens: dict[int, PenDef] = field(default_factory=_default_pens)
    rules: tuple[PenRule, ...] = field(default_factory=_default_rules)

    @classmethod
    def default(cls) -> PlotterDef:
        """The built-in plotter definition (what an empty PLOTTER.DEF gives).

        >>> d = PlotterDef.default()
        >>> d.paper.name, d.symbol_size_mm, d.text_height_mm, d.pen_for("h", "lines", 31)
        ('auto', 3.0, 2.5, 2)
        """
        return cls()

    def pen_for(self, layer: str, kind: str, code: int | None = None) -> int:
        """The pen for a record of ``kind`` (symbols, lines, texts) and ``code`` in ``layer``."""
        best, best_w = 1, -1
        for rule in self.rules:
            if rule.matches(layer, kind, code):
                w = rule.weight()
                if w >= best_w:
                    best, best_w = rule.pen, w
        return best

    def problems(self) -> list[str]:
        """What is inconsistent in this definition (empty if nothing)."""
        out = []
        if self.origin is not None and self.window is not None:
            out.append("'origin' and 'window' both place the map on the paper; give one of them")
        if self.window is not None:
            x0, y0, x1, y1 = self.window
            if not (x1 > x0 and y1 > y0):
                out.append(
                    f"the window {x0:g} {y0:g} {x1:g} {y1:g} is empty: "
                    "expected X0 Y0 X1 Y1 with X1 > X0 and Y1 > Y0"
                )
        if self.grid not in GRID_STYLES:
            out.append(f"grid must be one of {', '.join(GRID_STYLES)}, not {self.grid!r}")
        if self.grid_interval is not None and not (
            math.isfinite(self.grid_interval) and self.grid_interval > 0
        ):
            out.append(f"the grid interval must be positive, not {self.grid_interval!r}")
        used = {r.pen for r in self.rules} | {self.frame_pen}
        if self.grid_pen is not None and self.grid_pen not in self.pens:
            out.append(
                f"grid-pen {self.grid_pen} is not defined; "
                f"add 'pendef {self.grid_pen} COLOUR WIDTH'"
            )
        missing = sorted(used - set(self.pens))
        if missing:
            out.append(f"pens used but not defined with 'pendef': {missing}")
        return out

    def to_text(self) -> str:
        """This definition as PLOTTER.DEF text (parsing it gives an equal definition).

        >>> parse_plotdef(PlotterDef.default().to_text()) == PlotterDef.default()
        True
        """
        p = self.paper
        if p.name == "custom":
            paper = f"{p.width_mm:g} x {p.height_mm:g}"
        else:
            paper = p.name + (f" {p.orientation}" if p.orientation else "")
        out = ["; PLOTTER.DEF written by apygis", f"paper {paper}"]
        if self.scale is not None:
            out.append(f"scale {self.scale}")
        if self.origin is not None:
            out.append(f"origin {self.origin[0]!r} {self.origin[1]!r}")
        if self.window is not None:
            out.append("window " + " ".join(repr(v) for v in self.window))
        out += [
            "margin " + " ".join(f"{v:g}" for v in self.margins_mm),
            f"grid {self.grid}",
            f"symbol-size {self.symbol_size_mm:g}",
            f"text-height {self.text_height_mm:g}",
            f"height-decimals {self.height_decimals}",
            f"title {'on' if self.title else 'off'}",
            f"legend {'on' if self.legend else 'off'}",
            f"frame {'on' if self.frame else 'off'}",
            f"frame-pen {self.frame_pen}",
        ]
        if self.grid_interval is not None:
            out.append(f"grid-interval {self.grid_interval!r}")
        if self.grid_pen is not None:
            out.append(f"grid-pen {self.grid_pen}")
        out += [f"pendef {n} {pd.hex} {pd.width_mm:g}" for n, pd in sorted(self.pens.items())]
        out.append("clear-pen-rules")
        for r in self.rules:
            code = "*" if r.code is None else f"{r.code:02d}"
            out.append(f"pen {r.layer} {code} {r.pen}" + (f" {r.kind}" if r.kind else ""))
        return "\n".join(out) + "\n"


# --------------------------------------------------------------------------- parsing


def parse_colour(word: str) -> tuple[int, int, int]:
    """A colour name of :data:`COLOURS` or ``#rrggbb`` as RGB 0-255.

    >>> parse_colour("#0070C0"), parse_colour("Brown")
    ((0, 112, 192), (150, 80, 20))
    """
    if _HEX_COLOUR.fullmatch(word):
        return (int(word[1:3], 16), int(word[3:5], 16), int(word[5:7], 16))
    try:
        return COLOURS[word.lower()]
    except KeyError:
        raise ValueError(
            f"unknown colour {word!r}; use #rrggbb or one of {', '.join(COLOURS)}"
        ) from None


def _tokens(line: str) -> list[str]:
    """The words of a line without its comment."""
    line = line.split(";", 1)[0]
    words = []
    for w in line.split():
        if w.startswith("#") and not _HEX_COLOUR.fullmatch(w):
            break
        words.append(w)
    return words


def _number(word: str, what: str, lo: float, hi: float, lo_open: bool = False) -> float:
    if not _NUMBER.fullmatch(word):
        raise ValueError(f"{what}: expected a number, found {word!r}")
    v = float(word)
    if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
        left = "(" if lo_open else "["
        raise ValueError(f"{what}: {word} is outside {left}{lo:g}, {hi:g}]")
    return v


def _integer(word: str, what: str, lo: int, hi: int) -> int:
    if not re.fullmatch(r"[+-]?\d+", word):
        raise ValueError(f"{what}: expected a whole number, found {word!r}")
    v = int(word)
    if not lo <= v <= hi:
        raise ValueError(f"{what}: {v} is outside {lo}-{hi}")
    return v


def _onoff(args: list[str], key: str) -> bool:
    if len(args) != 1 or args[0].lower() not in ("on", "off", "yes", "no", "1", "0"):
        raise ValueError(f"{key}: expected 'on' or 'off', found {' '.join(args) or 'nothing'}")
    return args[0].lower() in ("on", "yes", "1")


def parse_paper(text: str) -> PaperSpec:
    """A paper given in words: ``A3``, ``A3 landscape``, ``auto``, ``600x400`` (mm).

    >>> parse_paper("a2 Landscape"), parse_paper("600 x 400 mm").size_mm()
    (PaperSpec(name='A2', orientation='landscape', width_mm=0.0, height_mm=0.0), (600.0, 400.0))

    Raises
    ------
    ValueError
        Naming what was expected.
    """
    return _paper(text.split())


def _paper(args: list[str]) -> PaperSpec:
    expected = (
        "paper: expected A0-A4, auto or a size 'W x H' in mm, then optionally "
        f"'portrait' or 'landscape'; found {' '.join(args) or 'nothing'!r}"
    )
    if not args:
        raise ValueError(expected)
    joined = " ".join(args).lower()
    m = re.fullmatch(r"([0-9.]+)\s*(?:x|\s)\s*([0-9.]+)(?:\s*mm)?", joined)
    if m:
        w = _number(m.group(1), "paper width (mm)", 0.0, 10000.0, lo_open=True)
        h = _number(m.group(2), "paper height (mm)", 0.0, 10000.0, lo_open=True)
        return PaperSpec("custom", None, w, h)
    name = args[0].upper()
    if name != "AUTO" and name not in ISO_A_SIZES:
        raise ValueError(expected)
    orientation = None
    if len(args) == 2 and args[1].lower() in ("portrait", "landscape"):
        orientation = args[1].lower()
    elif len(args) != 1:
        raise ValueError(expected)
    return PaperSpec("auto" if name == "AUTO" else name, orientation)


def _pen_rule(args: list[str], key: str) -> PenRule:
    if len(args) not in (3, 4):
        raise ValueError(
            f"{key}: expected 'pen LAYER CODE PEN [KIND]' (LAYER an extension or *, "
            f"CODE 0-99 or *, KIND one of {', '.join(KINDS)}), found {' '.join(args) or 'nothing'}"
        )
    layer = args[0].lower()
    if layer != "*" and not re.fullmatch(r"[a-z]{1,3}", layer):
        raise ValueError(f"{key}: layer must be an extension of 1-3 letters or *, not {args[0]!r}")
    code = None if args[1] == "*" else _integer(args[1], f"{key}: code", 0, 99)
    pen = _integer(args[2], f"{key}: pen number", 1, 99)
    kind = None
    if len(args) == 4:
        kind = args[3].lower()
        if kind not in KINDS:
            raise ValueError(f"{key}: kind must be one of {', '.join(KINDS)}, not {args[3]!r}")
    return PenRule(layer, code, pen, kind)


_SINGLE_KEYS = {
    "paper",
    "scale",
    "origin",
    "window",
    "margin",
    "grid",
    "grid-interval",
    "legend",
    "symbol-size",
    "text-height",
    "height-decimals",
    "title",
    "frame",
    "frame-pen",
    "grid-pen",
}
_ALIASES = {
    "margins": "margin",
    "symbol_size": "symbol-size",
    "text_height": "text-height",
    "grid_interval": "grid-interval",
}


def parse_plotdef(text: str | bytes, path=None) -> PlotterDef:
    """Parse PLOTTER.DEF text on top of :meth:`PlotterDef.default`.

    Parameters
    ----------
    text : str or bytes
        The file's content (bytes are decoded as UTF-8).
    path : str or os.PathLike, optional
        Named in error messages.

    Raises
    ------
    FormatError
        On an unknown key, a bad value, a key given twice, a pen used but not
        defined; the message names the line.
    """
    if isinstance(text, bytes | bytearray):
        raw = bytes(text)
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            bad = raw.count(b"\n", 0, exc.start) + 1
            raise FormatError(
                "not UTF-8 text; a plotter definition is UTF-8", path=path, record=f"line {bad}"
            ) from None
    if text.startswith("\ufeff"):
        text = text[1:]
    base = PlotterDef.default()
    values: dict = {}
    seen: dict[str, int] = {}
    pens = dict(base.pens)
    rules = list(base.rules)
    rule_lines: list[int] = [0] * len(rules)
    pen_lines: dict[int, int] = {}

    for lineno, line in enumerate(text.splitlines(), start=1):
        words = _tokens(line)
        if not words:
            continue
        key, args = words[0].lower(), words[1:]
        key = _ALIASES.get(key, key)
        try:
            if key in _SINGLE_KEYS:
                if key in seen:
                    raise ValueError(f"{key} is given twice (first on line {seen[key]})")
                seen[key] = lineno
            if key == "paper":
                values["paper"] = _paper(args)
            elif key == "scale":
                word = args[0][2:] if len(args) == 1 and args[0].startswith("1:") else None
                if len(args) != 1:
                    raise ValueError("scale: expected one denominator such as 5000 or 1:5000")
                values["scale"] = _integer(word or args[0], "scale", 1, 10**9)
            elif key == "origin":
                if len(args) != 2:
                    raise ValueError("origin: expected ground X and Y in metres")
                values["origin"] = (
                    _number(args[0], "origin X", -1e12, 1e12),
                    _number(args[1], "origin Y", -1e12, 1e12),
                )
            elif key == "window":
                if len(args) != 4:
                    raise ValueError(
                        "window: expected ground X0 Y0 X1 Y1 (lower-left, upper-right)"
                    )
                win = tuple(
                    _number(a, f"window {w}", -1e12, 1e12)
                    for a, w in zip(args, ("X0", "Y0", "X1", "Y1"), strict=True)
                )
                if not (win[2] > win[0] and win[3] > win[1]):
                    raise ValueError(
                        "window: expected X0 Y0 X1 Y1 with X1 > X0 and Y1 > Y0 "
                        f"(lower-left, upper-right), found {' '.join(args)}"
                    )
                values["window"] = win
            elif key == "grid":
                if len(args) != 1 or args[0].lower() not in GRID_STYLES:
                    raise ValueError(
                        f"grid: expected one of {', '.join(GRID_STYLES)}, "
                        f"found {' '.join(args) or 'nothing'}"
                    )
                values["grid"] = args[0].lower()
            elif key == "grid-interval":
                if len(args) != 1:
                    raise ValueError("grid-interval: expected one interval in CRS units")
                values["grid_interval"] = _number(args[0], "grid-interval", 0.0, 1e9, lo_open=True)
            elif key == "legend":
                values["legend"] = _onoff(args, key)
            elif key == "margin":
                if len(args) not in (1, 4):
                    raise ValueError(
                        "margin: expected one value or four (left bottom right top) in mm"
                    )
                vals = tuple(_number(a, "margin (mm)", 0.0, 1000.0) for a in args)
                values["margins_mm"] = vals * 4 if len(vals) == 1 else vals
            elif key == "symbol-size":
                if len(args) != 1:
                    raise ValueError("symbol-size: expected one size in mm")
                values["symbol_size_mm"] = _number(args[0], "symbol-size (mm)", 0.0, 100.0, True)
            elif key == "text-height":
                if len(args) != 1:
                    raise ValueError("text-height: expected one height in mm")
                values["text_height_mm"] = _number(args[0], "text-height (mm)", 0.0, 100.0, True)
            elif key == "height-decimals":
                if len(args) != 1:
                    raise ValueError("height-decimals: expected one number 0-3")
                values["height_decimals"] = _integer(args[0], "height-decimals", 0, 3)
            elif key == "title":
                values["title"] = _onoff(args, key)
            elif key == "frame":
                values["frame"] = _onoff(args, key)
            elif key == "frame-pen":
                if len(args) != 1:
                    raise ValueError("frame-pen: expected one pen number")
                values["frame_pen"] = _integer(args[0], "frame-pen", 1, 99)
            elif key == "grid-pen":
                if len(args) != 1:
                    raise ValueError("grid-pen: expected one pen number")
                values["grid_pen"] = _integer(args[0], "grid-pen", 1, 99)
            elif key == "pendef":
                if len(args) != 3:
                    raise ValueError(
                        "pendef: expected 'pendef NUMBER COLOUR WIDTH' "
                        "(e.g. 'pendef 2 #0070c0 0.25')"
                    )
                n = _integer(args[0], "pendef: pen number", 1, 99)
                if n in pen_lines:
                    raise ValueError(f"pen {n} is defined twice (first on line {pen_lines[n]})")
                pen_lines[n] = lineno
                pens[n] = PenDef(
                    n, parse_colour(args[1]), _number(args[2], "pen width (mm)", 0.0, 10.0, True)
                )
            elif key == "pen":
                rules.append(_pen_rule(args, key))
                rule_lines.append(lineno)
            elif key == "clear-pen-rules":
                if args:
                    raise ValueError("clear-pen-rules takes no value")
                rules.clear()
                rule_lines.clear()
            else:
                raise ValueError(
                    f"unknown key {words[0]!r}; expected one of "
                    f"{', '.join(sorted(_SINGLE_KEYS | {'pen', 'pendef', 'clear-pen-rules'}))}"
                )
        except ValueError as exc:
            raise FormatError(str(exc), path=path, record=f"line {lineno}") from None

    for rule, lineno in zip(rules, rule_lines, strict=True):
        if rule.pen not in pens:
            raise FormatError(
                f"pen {rule.pen} is used but not defined; add 'pendef {rule.pen} COLOUR WIDTH'",
                path=path,
                record=f"line {lineno}",
            )
    pdef = replace(base, pens=pens, rules=tuple(rules), **values)
    problems = pdef.problems()
    if problems:
        if "'origin' and 'window'" in problems[0]:
            where = "window" if seen["window"] > seen["origin"] else "origin"
        elif "window" in problems[0]:
            where = "window"
        elif "grid-pen" in problems[0]:
            where = "grid-pen"
        else:
            where = "frame-pen"
        record = f"line {seen[where]}" if where in seen else None
        raise FormatError(problems[0], path=path, record=record)
    return pdef


def read_plotdef(path) -> PlotterDef:
    """Read a PLOTTER.DEF file (see :func:`parse_plotdef`).

    Raises
    ------
    FormatError
        If the file is missing, unreadable or not a valid plotter definition.
    """
    return parse_plotdef(read_bytes(Path(path)), path=path)
