"""The sheet: scale, map window, paper, and where the map and its margin panel go.

:func:`plan_layout` decides, from the data's extent, the plotter definition
and what the margin panel needs (:class:`PanelSpec`), the plot's

* **scale**: the plotter definition's (or ``--scale``), else the map's
  compilation scale, else the largest round scale (1, 2, 2.5 or 5 times a
  power of ten) at which the sheet fits the paper (``A3`` when the paper is
  ``auto``);
* **map window** (ground, CRS units): the definition's ``window``
  (``--bbox``), else the data's extent padded by :data:`PAD_MM` on paper and
  rounded outward to a round step of about :data:`ROUND_MM` on paper, at
  least :data:`MIN_WINDOW_MM` wide and high; with an ``origin`` the window is
  what the neat line encloses;
* **paper**: the definition's, else the smallest ISO A sheet (A4 to A0, the
  orientation that fits) that holds the neat line, the grid-label band
  around it and the panel, inside the margins;
* **panel**: a column (or several) of :data:`COLUMN_MM` beside the map
  (right) or below it (bottom), whichever fits the smaller paper (right when
  both fit), holding the margin's blocks in flow order.

The map and its panel are centred on the paper as one composition, the map
vertically (right panel) or horizontally (bottom panel) centred within it.
Paper millimetres run from the paper's lower-left corner, x east, y north::

    x_mm = (X - X0) * mm_per_unit        mm_per_unit = unit_m * 1000 / scale

with ``(X0, Y0)`` the ground point at the paper's lower-left corner and
``unit_m`` the metres in one CRS unit (1 for metres, 0.3048006 for US
survey feet).

When the sheet cannot fit the paper at a fixed scale (a named paper too
small, or a map larger than A0), the window is cut around its centre to
what fits and :attr:`Layout.cut` says so; what then lies outside is clipped
and counted by the drawing.

Examples
--------
>>> from apygis.plot.plotdef import PlotterDef
>>> spec = PanelSpec(60.0, (14.0, 22.0, 40.0))
>>> lay = plan_layout((0.0, 0.0, 2400.0, 1500.0), PlotterDef(), 5000, 1.0, spec, 6.0)
>>> lay.paper, lay.scale, lay.side, lay.window
('A2 landscape', 5000, 'right', (-20.0, -20.0, 2420.0, 1520.0))
>>> [round(v, 1) for v in lay.frame]
[20.0, 56.0, 508.0, 364.0]
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

from apygis.errors import FormatError
from apygis.plot.plotdef import ISO_A_SIZES, PlotterDef

__all__ = [
    "COLUMN_MM",
    "GAP_MM",
    "MIN_WINDOW_MM",
    "PAD_MM",
    "ROUND_MM",
    "Layout",
    "PanelSpec",
    "flow_columns",
    "nice_step",
    "plan_layout",
    "round_scales",
]

log = logging.getLogger(__name__)

#: Width of one panel column, mm.
COLUMN_MM = 62.0
#: Space between the map's grid-label band and the panel, and between columns, mm.
GAP_MM = 6.0
#: Data are padded by this much on paper before the window is rounded, mm.
PAD_MM = 3.0
#: The window's edges are rounded outward to a round step about this long on paper, mm.
ROUND_MM = 2.0
#: The smallest window side on paper, mm.
MIN_WINDOW_MM = 40.0
#: Space between two blocks of a panel column, mm.
BLOCK_GAP_MM = 3.0


@dataclass(frozen=True)
class PanelSpec:
    """What the margin panel holds: blocks of ``heights`` mm, in flow order, in columns.

    The last block (the title block when there is one) goes to the bottom of
    the last column when ``last_at_bottom``.
    """

    column_mm: float
    heights: tuple[float, ...]
    last_at_bottom: bool = True


@dataclass(frozen=True)
class Layout:
    """A planned sheet (all lengths mm, ground in CRS units).

    Attributes
    ----------
    width_mm, height_mm : float
        The paper.
    paper : str
        The paper in words.
    scale : int
        The plot scale denominator.
    mm_per_unit : float
        Paper mm per ground unit.
    origin : (float, float)
        Ground X, Y at the paper's lower-left corner.
    frame : (float, float, float, float)
        The neat line ``x0, y0, x1, y1``.
    window : (float, float, float, float)
        The ground the neat line encloses, ``X0, Y0, X1, Y1``.
    side : str or None
        ``"right"`` or ``"bottom"``: where the panel is; None without one.
    panel : (float, float, float, float) or None
        The panel's box.
    columns : list of list of int
        The panel's blocks (indices into :attr:`PanelSpec.heights`) by column.
    cut : bool
        The window had to be cut to fit the paper.
    """

    width_mm: float
    height_mm: float
    paper: str
    scale: int
    mm_per_unit: float
    origin: tuple[float, float]
    frame: tuple[float, float, float, float]
    window: tuple[float, float, float, float]
    side: str | None
    panel: tuple[float, float, float, float] | None
    columns: list[list[int]]
    cut: bool = False


def round_scales(lo: float = 1, hi: float = 1e8) -> list[int]:
    """Round scale denominators 1, 2, 2.5, 5 x 10^k from ``lo`` to ``hi``, ascending.

    >>> round_scales(1000, 10000)
    [1000, 2000, 2500, 5000, 10000]
    >>> round_scales(1, 30)
    [1, 2, 5, 10, 20, 25]
    """
    out: list[int] = []
    k = math.floor(math.log10(lo))
    while True:
        for m in (1, 2, 2.5, 5):
            v = m * 10**k
            if v > hi:
                return out
            if v >= lo and v == int(v):  # a denominator is a whole number: no 1:2.5
                out.append(int(v))
        k += 1


def nice_step(target: float, series: Sequence[float] = (1, 2, 2.5, 5)) -> float:
    """The smallest round number (``series`` x 10^k) at least ``target`` (> 0).

    >>> nice_step(12.5), nice_step(0.031), nice_step(200)
    (20, 0.05, 200)
    """
    if not (target > 0 and math.isfinite(target)):
        raise ValueError(f"a step must be positive, not {target!r}")
    k = math.floor(math.log10(target))
    for kk in (k, k + 1):
        for m in series:
            v = m * 10.0**kk
            if v >= target * (1 - 1e-12):
                return round(v, 12) if kk < 0 else (int(v) if v == int(v) else v)
    raise AssertionError("unreachable")  # pragma: no cover


def flow_columns(
    heights: Sequence[float], column_height: float, last_at_bottom: bool = True
) -> list[list[int]] | None:
    """Blocks of ``heights`` flowed top-down into columns of ``column_height`` mm.

    Blocks are separated by :data:`BLOCK_GAP_MM`; a block that does not fit
    the rest of a column starts the next. Returns the block indices by
    column, or None when one block is taller than a column.

    >>> flow_columns([10, 10, 30], 40)
    [[0, 1], [2]]
    >>> flow_columns([10, 50], 40) is None
    True
    """
    if any(h > column_height + 1e-9 for h in heights):
        return None
    cols: list[list[int]] = [[]]
    used = 0.0
    for i, h in enumerate(heights):
        need = h + (BLOCK_GAP_MM if cols[-1] else 0.0)
        if cols[-1] and used + need > column_height + 1e-9:
            cols.append([])
            used, need = 0.0, h
        cols[-1].append(i)
        used += need
    if last_at_bottom and len(heights) > 1 and cols[-1] == [len(heights) - 1] and len(cols) > 1:
        # the last block alone in a column: it would still fit under the previous ones?
        prev = sum(heights[i] for i in cols[-2]) + BLOCK_GAP_MM * len(cols[-2])
        if prev + heights[-1] <= column_height + 1e-9:
            cols[-2].append(cols.pop()[0])
    return [c for c in cols if c]


def _panel_width(cols: list[list[int]], spec: PanelSpec) -> float:
    n = len(cols)
    return n * spec.column_mm + (n - 1) * GAP_MM


def _papers(pdef: PlotterDef, target_a3: bool) -> list[tuple[float, float, str]]:
    """The papers to try, smallest first."""
    spec = pdef.paper
    if spec.name == "custom":
        return [(spec.width_mm, spec.height_mm, spec.label())]
    if spec.name == "auto":
        names = ["A3"] if target_a3 else list(ISO_A_SIZES)[::-1]
    else:
        names = [spec.name]
    out = []
    for name in names:
        for o in (spec.orientation,) if spec.orientation else ("landscape", "portrait"):
            w, h = ISO_A_SIZES[name] if o == "portrait" else ISO_A_SIZES[name][::-1]
            out.append((w, h, f"{name} {o}"))
    return out


def _window_from_extent(extent, f: float) -> tuple[float, float, float, float]:
    """The data's extent padded by PAD_MM, rounded outward, at least MIN_WINDOW_MM.

    ``extent`` may be a callable of ``f`` (paper mm per ground unit): the data with
    what is sized on paper (labels at their preferred positions) around it.
    """
    if callable(extent):
        extent = extent(f)
    if extent is None:
        half = MIN_WINDOW_MM / 2.0 / f
        return (-half, -half, half, half)
    x0, y0, x1, y1 = extent
    step = nice_step(ROUND_MM / f)
    pad = PAD_MM / f
    wx0 = math.floor((x0 - pad) / step) * step
    wy0 = math.floor((y0 - pad) / step) * step
    wx1 = math.ceil((x1 + pad) / step) * step
    wy1 = math.ceil((y1 + pad) / step) * step
    min_side = MIN_WINDOW_MM / f
    if wx1 - wx0 < min_side:
        c = (wx0 + wx1) / 2.0
        wx0 = math.floor((c - min_side / 2) / step) * step
        wx1 = math.ceil((c + min_side / 2) / step) * step
    if wy1 - wy0 < min_side:
        c = (wy0 + wy1) / 2.0
        wy0 = math.floor((c - min_side / 2) / step) * step
        wy1 = math.ceil((c + min_side / 2) / step) * step
    return (float(wx0), float(wy0), float(wx1), float(wy1))


def _fit(
    map_w: float,
    map_h: float,
    avail_w: float,
    avail_h: float,
    spec: PanelSpec | None,
) -> tuple[str | None, float, float, list[list[int]]] | None:
    """Where the panel goes so that the map block (``map_w`` x ``map_h``) and it fit.

    Returns ``(side, panel_w, panel_h, columns)`` or None.
    """
    if spec is None or not spec.heights:
        return (None, 0.0, 0.0, []) if map_w <= avail_w + 1e-6 and map_h <= avail_h + 1e-6 else None
    # right: columns as tall as the map block (or the tallest block)
    col_h = max(map_h, max(spec.heights))
    cols = flow_columns(spec.heights, col_h, spec.last_at_bottom)
    if cols is not None:
        pw = _panel_width(cols, spec)
        if map_w + GAP_MM + pw <= avail_w + 1e-6 and col_h <= avail_h + 1e-6:
            return ("right", pw, col_h, cols)
    # bottom: as many columns as the map block is wide, as low as the blocks allow
    tallest = max(spec.heights)
    per_row = max(1, int((max(map_w, spec.column_mm) + GAP_MM) // (spec.column_mm + GAP_MM)))
    col_h = tallest
    while True:
        cols = flow_columns(spec.heights, col_h, spec.last_at_bottom)
        if cols is not None and len(cols) <= per_row:
            break
        col_h += 5.0
        if col_h > avail_h:
            return None
    pw = _panel_width(cols, spec)
    if max(map_w, pw) <= avail_w + 1e-6 and map_h + GAP_MM + col_h <= avail_h + 1e-6:
        return ("bottom", pw, col_h, cols)
    return None


def plan_layout(
    extent,
    pdef: PlotterDef,
    map_scale: int | None,
    unit_m: float,
    panel: PanelSpec | None,
    band_mm: float,
) -> Layout:
    """Plan the sheet (see the module's rules).

    Parameters
    ----------
    extent : (float, float, float, float), callable or None
        The plotted data's ``X0, Y0, X1, Y1`` (CRS units); None for no data; or
        a callable giving it for ``mm_per_unit`` (the data and its labels).
    pdef : PlotterDef
        Paper, scale, origin or window, margins.
    map_scale : int or None
        The map's compilation scale.
    unit_m : float
        Metres per CRS unit.
    panel : PanelSpec or None
        The margin panel's blocks (None: no panel).
    band_mm : float
        Room around the neat line for the grid's ticks and labels.

    Raises
    ------
    FormatError
        When the margins leave no room on the paper.
    """
    fixed = pdef.scale or map_scale
    scales = [int(fixed)] if fixed else round_scales()
    papers = _papers(pdef, target_a3=not fixed)
    ml, mb, mr, mt = pdef.margins_mm
    roomy = [p for p in papers if p[0] - ml - mr > 2 * band_mm and p[1] - mb - mt > 2 * band_mm]
    if not roomy:
        W, H, _ = papers[-1]
        raise FormatError(
            f"the margins ({ml:g}, {mb:g}, {mr:g}, {mt:g} mm) leave no room "
            f"on {W:g} x {H:g} mm paper"
        )
    papers = roomy
    if pdef.origin is not None:
        return _plan_with_origin(extent, pdef, int(scales[0]), unit_m, panel, band_mm, papers)
    for s in scales:
        f = unit_m * 1000.0 / s
        window = pdef.window if pdef.window is not None else _window_from_extent(extent, f)
        map_w = (window[2] - window[0]) * f + 2 * band_mm
        map_h = (window[3] - window[1]) * f + 2 * band_mm
        for W, H, label in papers:
            fit = _fit(map_w, map_h, W - ml - mr, H - mb - mt, panel)
            if fit is not None:
                return _place(W, H, label, s, f, window, map_w, map_h, band_mm, pdef, fit)
    # nothing fits: the largest paper allowed, the window cut around its centre
    s = scales[0] if fixed else scales[-1]
    f = unit_m * 1000.0 / s
    window = pdef.window if pdef.window is not None else _window_from_extent(extent, f)
    largest = max(p[0] * p[1] for p in papers)
    biggest = [p for p in papers if p[0] * p[1] == largest]
    wide = (window[2] - window[0]) >= (window[3] - window[1])
    W, H, label = next((p for p in biggest if (p[0] >= p[1]) == wide), biggest[0])
    avail_w, avail_h = W - ml - mr, H - mb - mt
    side: str | None = None
    cols: list[list[int]] = []
    pw = 0.0
    col_h = avail_h - 2 * band_mm
    if panel is not None and panel.heights:
        got = flow_columns(panel.heights, col_h, panel.last_at_bottom)
        if got is not None:
            side, cols = "right", got
            pw = _panel_width(cols, panel) + GAP_MM
    max_w = (avail_w - pw - 2 * band_mm) / f
    max_h = (avail_h - 2 * band_mm) / f
    if max_w <= 0 or max_h <= 0:
        side, cols, pw = None, [], 0.0
        max_w = (avail_w - 2 * band_mm) / f
    cx, cy = (window[0] + window[2]) / 2.0, (window[1] + window[3]) / 2.0
    ww = min(window[2] - window[0], max_w)
    wh = min(window[3] - window[1], max_h)
    cut_window = (cx - ww / 2, cy - wh / 2, cx + ww / 2, cy + wh / 2)
    log.warning(
        "the map window (%.0f x %.0f mm at 1:%d) does not fit on %s; it is cut to %.0f x %.0f mm "
        "around its centre, and what lies outside is clipped",
        (window[2] - window[0]) * f,
        (window[3] - window[1]) * f,
        s,
        label,
        ww * f,
        wh * f,
    )
    map_w, map_h = ww * f + 2 * band_mm, wh * f + 2 * band_mm
    fit = (side, pw - GAP_MM if side else 0.0, max(map_h, col_h) if side else map_h, cols)
    lay = _place(W, H, label, s, f, cut_window, map_w, map_h, band_mm, pdef, fit)
    return Layout(**{**lay.__dict__, "cut": True})


def _place(W, H, label, s, f, window, map_w, map_h, band, pdef, fit) -> Layout:
    """Centre the map block and its panel inside the margins."""
    side, pw, ph, cols = fit
    ml, mb, mr, mt = pdef.margins_mm
    avail_w, avail_h = W - ml - mr, H - mb - mt
    if side == "right":
        total_w, total_h = map_w + GAP_MM + pw, max(map_h, ph)
        x = ml + (avail_w - total_w) / 2.0
        y = mb + (avail_h - total_h) / 2.0
        mx, my = x, y + (total_h - map_h) / 2.0
        panel = (x + map_w + GAP_MM, y, x + map_w + GAP_MM + pw, y + total_h)
    elif side == "bottom":
        total_w, total_h = max(map_w, pw), map_h + GAP_MM + ph
        x = ml + (avail_w - total_w) / 2.0
        y = mb + (avail_h - total_h) / 2.0
        mx, my = x + (total_w - map_w) / 2.0, y + ph + GAP_MM
        px = x + (total_w - pw) / 2.0
        panel = (px, y, px + pw, y + ph)
    else:
        mx = ml + (avail_w - map_w) / 2.0
        my = mb + (avail_h - map_h) / 2.0
        panel = None
    frame = (mx + band, my + band, mx + map_w - band, my + map_h - band)
    origin = (window[0] - frame[0] / f, window[1] - frame[1] / f)
    return Layout(
        width_mm=float(W),
        height_mm=float(H),
        paper=label,
        scale=int(s),
        mm_per_unit=f,
        origin=(float(origin[0]), float(origin[1])),
        frame=tuple(float(v) for v in frame),  # type: ignore[arg-type]
        window=tuple(float(v) for v in window),  # type: ignore[arg-type]
        side=side,
        panel=None if panel is None else tuple(float(v) for v in panel),  # type: ignore[arg-type]
        columns=cols,
    )


def _plan_with_origin(extent, pdef, s, unit_m, panel, band, papers) -> Layout:
    """An ``origin`` fixes the ground on the paper; the neat line takes what the panel leaves."""
    f = unit_m * 1000.0 / s
    if callable(extent):
        extent = extent(f)
    X0, Y0 = pdef.origin
    ml, mb, mr, mt = pdef.margins_mm
    chosen = None
    for W, H, label in papers:
        avail_h = H - mb - mt
        cols: list[list[int]] = []
        pw = 0.0
        side = None
        if panel is not None and panel.heights:
            got = flow_columns(panel.heights, avail_h, panel.last_at_bottom)
            if got is not None:
                cols, side = got, "right"
                pw = _panel_width(cols, panel) + GAP_MM
        frame = (ml + band, mb + band, W - mr - band - pw, H - mt - band)
        if frame[2] <= frame[0]:
            continue
        chosen = (W, H, label, frame, side, cols, pw)
        if extent is None:
            break
        if (extent[2] - X0) * f <= frame[2] + 1e-6 and (extent[3] - Y0) * f <= frame[3] + 1e-6:
            break
    if chosen is None:
        raise FormatError(f"the margins and the panel leave no room for the map on {papers[-1][2]}")
    W, H, label, frame, side, cols, pw = chosen
    window = (X0 + frame[0] / f, Y0 + frame[1] / f, X0 + frame[2] / f, Y0 + frame[3] / f)
    panel_box = (W - mr - pw + GAP_MM, mb, W - mr, H - mt) if side else None
    return Layout(
        width_mm=float(W),
        height_mm=float(H),
        paper=label,
        scale=int(s),
        mm_per_unit=f,
        origin=(float(X0), float(Y0)),
        frame=tuple(float(v) for v in frame),  # type: ignore[arg-type]
        window=tuple(float(v) for v in window),  # type: ignore[arg-type]
        side=side,
        panel=panel_box,
        columns=cols,
    )
