"""What a sheet carries besides the map: grid, legend, scale bar, north arrow, title block.

Everything here returns drawing primitives in paper millimetres
(:mod:`apygis.plot.primitives`); :func:`apygis.plot.drawing.build_drawing`
decides where they go.

* **Grid** (:func:`grid_items`): lines, or crosses (arms of
  :data:`CROSS_MM`) at every intersection, at a round interval
  (:func:`grid_interval`: 1, 2, 2.5 or 5 x 10^k CRS units, the first at
  least :data:`GRID_TARGET_MM` on paper); outward ticks at the neat line,
  and each line labelled outside the neat line with its coordinate in the
  CRS's units: eastings under and over the map, northings left and right,
  turned to read upward. A label that would run past the neat line's
  corner is left out.
* **Panel blocks** (:class:`Block`): the heading (map ID and scale), the
  north arrow beside the scale bar, the legend (a heading and one block per
  entry: each symbol code used, drawn from its bitmap in its pen, and each
  line code used, drawn in its pen, a closed line as a small square), and
  the title block (map ID, scale, CRS name, grid interval, north, date,
  source files, layers), each a fixed height so that the layout can flow
  them into columns.
* **Scale bar** (:func:`scale_bar_length`): the longest round length (1, 2
  or 5 x 10^k CRS units) that fits the room, in 4 or 5 alternately filled
  segments, labelled at each division; kilometres from 1000 m.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from apygis.plot.fonts import text_size
from apygis.plot.layout import nice_step
from apygis.plot.primitives import FilledPolygon, FilledRects, PaperLine, make_text, symbol_rects

__all__ = [
    "CONTROL_MARK_MM",
    "CROSS_MM",
    "GRID_LABEL_MM",
    "GRID_TARGET_MM",
    "Block",
    "LegendEntry",
    "control_mark",
    "format_coordinate",
    "grid_interval",
    "grid_items",
    "heading_block",
    "legend_blocks",
    "orientation_block",
    "scale_bar_length",
    "title_block",
    "wrap_text",
]

#: Length of a grid cross's arm on each side of its centre, mm.
CROSS_MM = 2.5
#: Cap height of grid labels, mm.
GRID_LABEL_MM = 2.0
#: A round grid interval at least this long on paper is chosen, mm.
GRID_TARGET_MM = 35.0
#: Radius of a control point's circle (control plots), mm.
CONTROL_MARK_MM = 1.6
#: Length of the ticks outside the neat line, mm.
TICK_MM = 1.5

_TEXT_MM = 2.0  # cap height of the panel's small texts
_PITCH = 1.75  # line pitch of the panel's texts, in cap heights


@dataclass(frozen=True)
class Block:
    """A panel block ``height`` mm tall; ``draw(x, top, width)`` gives its primitives."""

    height: float
    draw: Callable[[float, float, float], list]
    name: str = ""


@dataclass(frozen=True)
class LegendEntry:
    """One legend entry: a symbol (``code`` and its ``bitmap``) or a line code."""

    kind: str  # "symbol" or "line"
    code: int
    pen: int
    label: str
    bitmap: np.ndarray | None = None
    closed: bool = False


def grid_interval(mm_per_unit: float, target_mm: float = GRID_TARGET_MM) -> float:
    """The round grid interval (CRS units) at least ``target_mm`` long on paper.

    >>> grid_interval(0.2)   # 1:5000 in metres: 200 m = 40 mm
    200
    >>> grid_interval(0.04)  # 1:25000: 1 km
    1000
    """
    return nice_step(target_mm / mm_per_unit)


def format_coordinate(v: float, interval: float) -> str:
    """A grid coordinate with as many decimals as the interval needs.

    >>> format_coordinate(2683000.0, 200), format_coordinate(46.25, 0.25)
    ('2683000', '46.25')
    """
    dec = 0 if interval >= 1 else min(9, max(0, -math.floor(math.log10(interval) + 1e-9)))
    if dec and round(interval * 10**dec) % 10 and dec < 9:
        dec += 1 if round(interval, dec) != interval else 0
    s = f"{v:.{dec}f}"
    return "0" if s in ("-0", "-0.0") else s


def grid_items(
    frame: tuple[float, float, float, float],
    window: tuple[float, float, float, float],
    interval: float,
    style: str,
    pen: int,
) -> tuple[list, list, np.ndarray]:
    """The grid: ``(under, over, soft)``.

    ``under`` is drawn before the map (lines or crosses), ``over`` after it
    (ticks and labels outside the neat line), ``soft`` the crosses' boxes
    (k, 4) for the label placement.
    """
    x0, y0, x1, y1 = frame
    wx0, wy0, wx1, wy1 = window
    fx = (x1 - x0) / (wx1 - wx0)
    fy = (y1 - y0) / (wy1 - wy0)
    eps = 0.5  # mm: a grid line closer than this to the neat line is the neat line
    xs = [
        k * interval
        for k in range(math.ceil(wx0 / interval), math.floor(wx1 / interval) + 1)
        if x0 + eps < x0 + (k * interval - wx0) * fx < x1 - eps
    ]
    ys = [
        k * interval
        for k in range(math.ceil(wy0 / interval), math.floor(wy1 / interval) + 1)
        if y0 + eps < y0 + (k * interval - wy0) * fy < y1 - eps
    ]
    px = [x0 + (v - wx0) * fx for v in xs]
    py = [y0 + (v - wy0) * fy for v in ys]
    under: list = []
    soft = []
    if style == "lines":
        for x in px:
            under.append(PaperLine(pen, np.array([(x, y0), (x, y1)]), False, "grid"))
        for y in py:
            under.append(PaperLine(pen, np.array([(x0, y), (x1, y)]), False, "grid"))
    elif style == "crosses":
        a = CROSS_MM
        for x in px:
            for y in py:
                if min(x - x0, x1 - x, y - y0, y1 - y) < a + 0.5:
                    continue  # at the neat line the edge ticks mark it
                across = np.array([(max(x - a, x0), y), (min(x + a, x1), y)])
                up = np.array([(x, max(y - a, y0)), (x, min(y + a, y1))])
                under.append(PaperLine(pen, across, False, "grid"))
                under.append(PaperLine(pen, up, False, "grid"))
                soft.append((x - a, y - a, x + a, y + a))
        # inward ticks at the neat line, so that the grid can be read along the edge
        for x in px:
            under.append(PaperLine(pen, np.array([(x, y0), (x, y0 + a)]), False, "grid"))
            under.append(PaperLine(pen, np.array([(x, y1 - a), (x, y1)]), False, "grid"))
        for y in py:
            under.append(PaperLine(pen, np.array([(x0, y), (x0 + a, y)]), False, "grid"))
            under.append(PaperLine(pen, np.array([(x1 - a, y), (x1, y)]), False, "grid"))
    over: list = []
    if style == "off":
        return under, over, np.zeros((0, 4))
    h = GRID_LABEL_MM
    t = TICK_MM
    for v, x in zip(xs, px, strict=True):
        over.append(PaperLine(pen, np.array([(x, y0 - t), (x, y0)]), False, "grid"))
        over.append(PaperLine(pen, np.array([(x, y1), (x, y1 + t)]), False, "grid"))
        s = format_coordinate(v, interval)
        w, _ = text_size(s, h)
        if x - w / 2 < x0 or x + w / 2 > x1:
            continue
        over.append(make_text(pen, x - w / 2, y0 - t - 1.0 - h, h, s, "grid-label"))
        over.append(make_text(pen, x - w / 2, y1 + t + 1.0, h, s, "grid-label"))
    for v, y in zip(ys, py, strict=True):
        over.append(PaperLine(pen, np.array([(x0 - t, y), (x0, y)]), False, "grid"))
        over.append(PaperLine(pen, np.array([(x1, y), (x1 + t, y)]), False, "grid"))
        s = format_coordinate(v, interval)
        w, _ = text_size(s, h)
        if y - w / 2 < y0 or y + w / 2 > y1:
            continue
        # turned to read upward: the glyphs lie left of the baseline
        over.append(make_text(pen, x0 - t - 1.0, y - w / 2, h, s, "grid-label", angle=90.0))
        over.append(make_text(pen, x1 + t + 1.0 + h, y - w / 2, h, s, "grid-label", angle=90.0))
    return under, over, np.array(soft, dtype=float).reshape(-1, 4)


# --------------------------------------------------------------------------- text helpers


def wrap_text(text: str, height: float, width: float) -> list[str]:
    """``text`` broken at blanks (and after commas) into lines no wider than ``width`` mm.

    A word wider than the whole width is broken between characters.

    >>> wrap_text("ZH1091.c, ZH1091.e, ZH1091.h", 2.0, 30.0)
    ['ZH1091.c, ZH1091.e,', 'ZH1091.h']
    """
    words = text.split(" ")
    lines: list[str] = []
    cur = ""
    for word in words:
        cand = f"{cur} {word}" if cur else word
        if text_size(cand, height)[0] <= width:
            cur = cand
            continue
        if cur:
            lines.append(cur)
        cur = word
        while text_size(cur, height)[0] > width and len(cur) > 1:
            k = len(cur) - 1
            while k > 1 and text_size(cur[:k], height)[0] > width:
                k -= 1
            lines.append(cur[:k])
            cur = cur[k:]
    if cur or not lines:
        lines.append(cur)
    return lines


# --------------------------------------------------------------------------- panel blocks


def heading_block(map_id: str, scale: int, subtitle: str, pen: int) -> Block:
    """The map ID (5 mm), the scale (3 mm) and a subtitle (2 mm) if any."""
    height = 5.0 + 1.6 * 3.0 + (1.8 * _TEXT_MM if subtitle else 0.0) + 1.0

    def draw(x: float, top: float, width: float) -> list:
        y = top - 5.0
        items = [make_text(pen, x, y, 5.0, map_id, "heading")]
        y -= 1.6 * 3.0
        items.append(make_text(pen, x, y, 3.0, f"1:{scale}", "heading"))
        if subtitle:
            y -= 1.8 * _TEXT_MM
            items.append(make_text(pen, x, y, _TEXT_MM, subtitle, "heading"))
        return items

    return Block(height, draw, "heading")


def scale_bar_length(mm_per_unit: float, room_mm: float) -> float:
    """The longest round length (1, 2, 5 x 10^k CRS units) no longer than ``room_mm`` on paper.

    >>> scale_bar_length(0.2, 44.0)  # 1:5000: 200 m = 40 mm
    200
    """
    target = room_mm / mm_per_unit
    k = math.floor(math.log10(target))
    best = None
    for kk in (k - 1, k):
        for m in (1, 2, 5):
            v = m * 10.0**kk
            if v <= target * (1 + 1e-12):
                best = v
    assert best is not None
    return int(best) if best >= 1 and best == int(best) else best


def _scale_bar(x: float, y: float, length: float, f: float, unit: str, pen: int) -> list:
    """A scale bar of ``length`` CRS units starting at (x, y) (its lower-left), with labels."""
    lead = int(f"{length:e}"[0])
    n = {1: 5, 2: 4, 5: 5}.get(lead, 4)
    seg = length / n
    bar_h = 1.5
    items: list = []
    km = unit == "m" and length >= 1000
    div = 1000.0 if km else 1.0
    shown_unit = "km" if km else unit
    filled = []
    for k in range(n):
        a, b = x + k * seg * f, x + (k + 1) * seg * f
        if k % 2 == 0:
            filled.append((a, y, b, y + bar_h))
    items.append(FilledRects(pen, np.array(filled), "scalebar"))
    box = np.array([(x, y), (x + length * f, y), (x + length * f, y + bar_h), (x, y + bar_h)])
    items.append(PaperLine(pen, box, True, "scalebar"))
    h = 1.8
    step = 1 if seg * f >= 7.0 else (2 if seg * f >= 3.5 else n)
    for k in range(0, n + 1, step):
        v = k * seg / div
        s = f"{v:g}"
        if k == n:
            s += f" {shown_unit}"
        w, _ = text_size(s, h)
        lx = x + k * seg * f - (text_size(f"{v:g}", h)[0] / 2)
        items.append(make_text(pen, lx, y + bar_h + 1.0, h, s, "scalebar"))
        del w
    if n % step:
        v = length / div
        s = f"{v:g} {shown_unit}"
        lx = x + length * f - text_size(f"{v:g}", h)[0] / 2
        items.append(make_text(pen, lx, y + bar_h + 1.0, h, s, "scalebar"))
    return items


def _north_arrow(cx: float, y: float, height: float, pen: int) -> list:
    """A grid north arrow, its foot at (cx, y): left half filled, right outlined, N on top."""
    w = height * 0.32
    tip = (cx, y + height - 5.0)
    foot = y
    notch = (cx, foot + height * 0.22)
    left = np.array([tip, (cx - w / 2, foot), notch])
    right = np.array([tip, (cx + w / 2, foot), notch])
    items: list = [
        FilledPolygon(pen, left, "north"),
        PaperLine(pen, right, True, "north"),
        PaperLine(pen, left, True, "north"),
    ]
    nw, _ = text_size("N", 3.0)
    items.append(make_text(pen, cx - nw / 2, tip[1] + 1.2, 3.0, "N", "north"))
    return items


def orientation_block(
    mm_per_unit: float, unit: str, pen: int, column_mm: float, scale: int
) -> Block:
    """The north arrow (grid north) beside the scale bar and the scale as a ratio."""
    height = 20.0

    def draw(x: float, top: float, width: float) -> list:
        items = _north_arrow(x + 4.0, top - height, height, pen)
        room = width - 14.0 - 8.0  # the arrow's side, and room for the last label
        length = scale_bar_length(mm_per_unit, room)
        items += _scale_bar(x + 14.0, top - height + 8.0, length, mm_per_unit, unit, pen)
        return items

    return Block(height, draw, "orientation")


def legend_blocks(
    entries: Sequence[LegendEntry], symbol_mm: float, pen: int, column_mm: float
) -> list[Block]:
    """The legend's heading and one block per entry (a long label wraps onto more rows)."""
    if not entries:
        return []
    head_h = 3.0

    def draw_head(x: float, top: float, width: float) -> list:
        return [make_text(pen, x, top - head_h, head_h, "Legend", "legend")]

    blocks = [Block(head_h + 1.5, draw_head, "legend")]
    for e in entries:
        lines = wrap_text(e.label, _TEXT_MM, column_mm - _LEGEND_TEXT_X)
        row = max(symbol_mm, 2.0 * _TEXT_MM) + 1.2 + (len(lines) - 1) * _PITCH * _TEXT_MM
        blocks.append(Block(row, _entry_drawer(e, lines, symbol_mm, pen), "legend"))
    return blocks


_LEGEND_TEXT_X = 12.0  # mm from the column's left edge to an entry's text


def _entry_drawer(e: LegendEntry, lines: list[str], symbol_mm: float, pen: int):
    def draw(x: float, top: float, width: float) -> list:
        first = max(symbol_mm, 2.0 * _TEXT_MM) + 1.2
        yc = top - first / 2.0
        cx = x + 5.0
        items: list = []
        if e.kind == "symbol" and e.bitmap is not None:
            items.append(FilledRects(e.pen, symbol_rects(e.bitmap, cx, yc, symbol_mm), "legend"))
        elif e.kind == "control":
            items.extend(control_mark(cx, yc, e.pen, "legend"))
        elif e.closed:
            s = min(symbol_mm, 3.0)
            sq = np.array(
                [
                    (cx - s, yc - s / 2),
                    (cx + s, yc - s / 2),
                    (cx + s, yc + s / 2),
                    (cx - s, yc + s / 2),
                ]
            )
            items.append(PaperLine(e.pen, sq, True, "legend"))
        else:
            seg = np.array([(cx - 4.0, yc), (cx + 4.0, yc)])
            items.append(PaperLine(e.pen, seg, False, "legend"))
        y = yc - _TEXT_MM / 2
        for line in lines:
            items.append(make_text(pen, x + _LEGEND_TEXT_X, y, _TEXT_MM, line, "legend"))
            y -= _PITCH * _TEXT_MM
        return items

    return draw


def control_mark(x: float, y: float, pen: int, role: str = "control") -> list:
    """A control point from a file: a circle of :data:`CONTROL_MARK_MM` with a cross through it."""
    r = CONTROL_MARK_MM
    t = np.linspace(0.0, 2 * math.pi, 25)[:-1]
    ring = np.column_stack([x + r * np.cos(t), y + r * np.sin(t)])
    return [
        PaperLine(pen, ring, True, role),
        PaperLine(pen, np.array([(x - 1.6 * r, y), (x + 1.6 * r, y)]), False, role),
        PaperLine(pen, np.array([(x, y - 1.6 * r), (x, y + 1.6 * r)]), False, role),
    ]


def title_block(rows: Sequence[tuple[str, str]], pen: int, width: float) -> Block:
    """A boxed table of ``(key, value)`` rows; values wrap within the box."""
    h = _TEXT_MM
    key_w = max(text_size(k, h)[0] for k, _ in rows) + 2.5
    pad = 2.0
    value_w = width - 2 * pad - key_w
    wrapped = [(k, wrap_text(v, h, value_w)) for k, v in rows]
    nlines = sum(len(v) for _, v in wrapped)
    height = 2 * pad + h + (nlines - 1) * _PITCH * h + 0.5

    def draw(x: float, top: float, w: float) -> list:
        box = np.array([(x, top - height), (x + w, top - height), (x + w, top), (x, top)])
        items: list = [PaperLine(pen, box, True, "title")]
        y = top - pad - h
        for k, vals in wrapped:
            items.append(make_text(pen, x + pad, y, h, k, "title"))
            for v in vals:
                items.append(make_text(pen, x + pad + key_w, y, h, v, "title"))
                y -= _PITCH * h
        return items

    return Block(height, draw, "title")
