"""The plot of a map on paper: a sheet of drawing primitives in paper millimetres.

:func:`build_drawing` lays a map out once; the back-ends
(:mod:`~apygis.plot.hpgl`, :mod:`~apygis.plot.svg`, :mod:`~apygis.plot.pdf`,
:mod:`~apygis.plot.raster`) only render the primitives
(:mod:`~apygis.plot.primitives`). Paper coordinates are millimetres from the
paper's lower-left corner, x to the right (ground X, east) and y up (ground
Y, north)::

    x_mm = (X - X0) * mm_per_unit        y_mm = (Y - Y0) * mm_per_unit
    mm_per_unit = unit_m * 1000 / scale

with ``(X0, Y0)`` the ground point at the paper's lower-left corner and
``unit_m`` the metres in one unit of the map's CRS (1 for metres). At
1:5000 in metres, 1 m on the ground is 0.2 mm on paper.

The sheet (:mod:`~apygis.plot.layout`): the map window inside the neat
line, the grid's ticks and labels around it (:mod:`~apygis.plot.margin`),
and a panel beside or below it with the map's heading, north arrow and
scale bar, the legend of what is drawn, and the title block.

What falls outside the neat line: lines are clipped at it (a line leaving
and re-entering becomes several pieces); symbols whose centre lies outside
are dropped, and the painted cells of a kept symbol are cut at the neat
line; texts whose point lies outside are dropped. :attr:`Drawing.stats`
counts what was drawn, clipped and dropped.

Labels (texts and spot heights, a control plot's point numbers) are placed
by :mod:`~apygis.plot.labels` off lines, symbols, the neat line and each
other where an alternative position exists; those that could not be placed
free are counted (``labels_overlapping``) and listed in
:attr:`Drawing.unplaced`.

A map in a geographic CRS (longitude, latitude) is plotted in the UTM zone
of its centre (the title block says so); a CRS in feet is plotted in feet
(its grid labelled in feet, its scale bar in feet). A map without a CRS is
taken to be in metres.
"""

from __future__ import annotations

import datetime as _dt
import logging
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from apygis.errors import FormatError, RecordError
from apygis.model.map import MapFile, crs_string
from apygis.plot.fonts import missing_glyphs, text_size
from apygis.plot.labels import LabelRequest, place_labels
from apygis.plot.layout import COLUMN_MM, PanelSpec, plan_layout
from apygis.plot.margin import (
    CONTROL_MARK_MM,
    Block,
    LegendEntry,
    control_mark,
    grid_interval,
    grid_items,
    heading_block,
    legend_blocks,
    orientation_block,
    title_block,
)
from apygis.plot.plotdef import PenDef, PlotterDef
from apygis.plot.primitives import (
    FilledPolygon,
    FilledRects,
    PaperLine,
    PaperText,
    clip_polyline,
    make_text,
    symbol_rects,
    symbol_runs,
)
from apygis.progress import Progress, phase

__all__ = [
    "MIN_GRID_MM",
    "SPOT_HEIGHT_CODE",
    "ControlPoint",
    "Drawing",
    "FilledPolygon",
    "FilledRects",
    "PaperLine",
    "PaperText",
    "build_drawing",
    "clip_polyline",
    "plot_date",
    "symbol_runs",
]

log = logging.getLogger(__name__)

#: The symbol code of the spot height.
SPOT_HEIGHT_CODE = 0
#: The closest grid lines may be on paper, mm.
MIN_GRID_MM = 2.0

_EPS = 1e-9  # mm: points this close outside the neat line count as on it
_UNIT_NAMES = {
    "metre": "m",
    "meter": "m",
    "kilometre": "km",
    "US survey foot": "ftUS",
    "foot": "ft",
    "international foot": "ft",
}


@dataclass(frozen=True)
class ControlPoint:
    """A control point of a control plot: its id, ground X, Y (CRS units) and Z (nan: none)."""

    id: str
    x: float
    y: float
    z: float = math.nan


@dataclass
class Drawing:
    """A laid-out plot: paper, placement, pens and primitives.

    Attributes
    ----------
    width_mm, height_mm : float
        The paper.
    paper : str
        The paper in words (``"A2 landscape"``, ``"600 x 400 mm"``).
    scale : int
        Plot scale denominator.
    origin : (float, float)
        Ground X, Y (CRS units) at the paper's lower-left corner.
    frame : (float, float, float, float)
        The neat line ``x0, y0, x1, y1`` in mm.
    pens : dict of int to PenDef
        All pens of the plotter definition.
    items : list
        The primitives of :mod:`apygis.plot.primitives`, in drawing order.
    map_id : str
        The map's identification.
    stats : dict
        Counts: ``layers`` (the extensions plotted), ``lines`` (map lines
        drawn, whole or in part), ``line_pieces``, ``lines_clipped``,
        ``lines_dropped``, ``symbols``, ``symbols_dropped``, ``spot_heights``,
        ``texts``, ``texts_dropped``, ``control_points``, ``labels`` (texts,
        spot heights and point numbers placed), ``labels_moved`` (not at
        their preferred position), ``labels_overlapping`` (could not be placed
        free of lines, symbols, the neat line and other labels),
        ``texts_missing_glyphs`` (texts with characters the font lacks).
    mm_per_unit : float
        Paper mm per ground unit (``unit_m * 1000 / scale``).
    window : (float, float, float, float)
        The ground the neat line encloses.
    crs_name : str
        The CRS plotted, in words.
    unit : str
        The CRS's unit (``m``, ``ftUS``...).
    grid_interval : float or None
        The grid's interval in CRS units (None: no grid).
    crs : pyproj.CRS or None
        The CRS plotted (the map's, or the UTM zone a geographic map is
        plotted in).
    unplaced : list of str
        One line per label that could not be placed free: what it says and
        what it collides with.
    labels : list of (int, int, float, float)
        Each placed label: the index of its :class:`PaperText` in
        :attr:`items`, the index of the symbol it labels (-1: a text of the
        map), and its anchor (the symbol's centre, or the text's point), mm.
    """

    width_mm: float
    height_mm: float
    paper: str
    scale: int
    origin: tuple[float, float]
    frame: tuple[float, float, float, float]
    pens: dict[int, PenDef]
    items: list = field(default_factory=list)
    map_id: str = ""
    stats: dict = field(default_factory=dict)
    mm_per_unit: float = 0.0
    window: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    crs_name: str = ""
    unit: str = "m"
    grid_interval: float | None = None
    unplaced: list[str] = field(default_factory=list)
    crs: Any = None
    labels: list[tuple[int, int, float, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.mm_per_unit:
            self.mm_per_unit = 1000.0 / self.scale

    @property
    def mm_per_m(self) -> float:
        """Paper millimetres per ground metre (1000 / scale)."""
        return 1000.0 / self.scale

    def to_paper(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Ground X, Y (CRS units) to paper x, y (mm).

        >>> d = Drawing(100, 100, "", 5000, (1000.0, 2000.0), (0, 0, 100, 100), {})
        >>> [float(v) for v in d.to_paper(1100.0, 2050.0)]
        [20.0, 10.0]
        """
        f = self.mm_per_unit
        return (
            (np.asarray(x, dtype=float) - self.origin[0]) * f,
            (np.asarray(y, dtype=float) - self.origin[1]) * f,
        )

    def used_pens(self) -> list[int]:
        """The pen numbers the items use, ascending."""
        return sorted({it.pen for it in self.items})

    def count(self, kind: type[Any], role: str | None = None) -> int:
        """Number of items of class ``kind`` (and ``role``)."""
        return sum(1 for it in self.items if isinstance(it, kind) and role in (None, it.role))

    def summary(self) -> str:
        """One line: paper, scale, counts, and what could not be placed or drawn.

        Example: ``A2 landscape (594 x 420 mm), 1:5000, layers c e h r:
        18 lines, 115 symbols (96 spot heights), 14 texts; 110 labels
        (31 moved), all placed free``.
        """
        s = self.stats
        out = (
            f"{self.paper} ({self.width_mm:g} x {self.height_mm:g} mm), 1:{self.scale}, "
            f"layers {' '.join(s.get('layers', [])) or 'none'}: {s.get('lines', 0)} lines, "
            f"{s.get('symbols', 0)} symbols ({s.get('spot_heights', 0)} spot heights), "
            f"{s.get('texts', 0)} texts"
        )
        if s.get("control_points"):
            out += f", {s['control_points']} control points"

        def n(k: str) -> str:
            word = k.split("_")[0]
            return f"{s[k]} {word if s[k] != 1 else word[:-1]}"

        labels = s.get("labels", 0)
        if labels:
            over = s.get("labels_overlapping", 0)
            out += f"; {labels} labels ({s.get('labels_moved', 0)} moved), "
            out += "all placed free" if not over else f"{over} could not be placed free"
        if s.get("lines_clipped"):
            out += f"; {n('lines_clipped')} clipped at the neat line"
        keys = ("lines_dropped", "symbols_dropped", "texts_dropped")
        dropped = [n(k) for k in keys if s.get(k)]
        if dropped:
            out += "; outside the neat line: " + ", ".join(dropped)
        if s.get("texts_missing_glyphs"):
            k = s["texts_missing_glyphs"]
            out += f"; {k} text{'s' if k != 1 else ''} with characters the font lacks"
        return out


# --------------------------------------------------------------------------- helpers


def plot_date(date: str | _dt.date | None = None) -> str:
    """The date a plot shows: ``date``, else $SOURCE_DATE_EPOCH's (reproducible builds), else today.

    >>> plot_date(_dt.date(2024, 5, 1))
    '2024-05-01'
    """
    if isinstance(date, _dt.date):
        return date.isoformat()
    if date:
        return str(date)
    epoch = os.environ.get("SOURCE_DATE_EPOCH", "").strip()
    if epoch.isdigit():
        return _dt.datetime.fromtimestamp(int(epoch), _dt.UTC).date().isoformat()
    return _dt.date.today().isoformat()


def _inside(x, y, rect) -> np.ndarray:
    return (
        (x >= rect[0] - _EPS)
        & (x <= rect[2] + _EPS)
        & (y >= rect[1] - _EPS)
        & (y <= rect[3] + _EPS)
    )


def _fallback_bitmap() -> np.ndarray:
    """An open square of 5x5 cells: the mark of a code with no bitmap."""
    bm = np.zeros((15, 15), dtype=bool)
    bm[5, 5:10] = bm[9, 5:10] = True
    bm[5:10, 5] = bm[5:10, 9] = True
    return bm


def _crs_words(crs) -> str:
    auth = crs_string(crs)
    name = crs.name
    if auth and not auth.startswith(("PROJCRS", "GEOGCRS", "COMPOUNDCRS", "{", "BOUNDCRS")):
        return f"{name} ({auth})"
    return name


def _horizontal(crs):
    if crs.is_compound and crs.sub_crs_list:
        return crs.sub_crs_list[0]
    return crs


def _plot_crs(m: MapFile) -> tuple[MapFile, Any, str]:
    """The map to plot (reprojected to UTM if geographic), its CRS and the CRS in words."""
    if m.crs is None:
        return m, None, "none (coordinates taken as metres)"
    h = _horizontal(m.crs)
    if not h.is_geographic:
        return m, m.crs, _crs_words(m.crs)
    from pyproj import CRS

    from apygis.model.reproject import reproject

    boxes = [e for e in (lay.extent() for lay in m) if e is not None]
    if not boxes:
        return m, m.crs, _crs_words(m.crs)
    lon = (min(b[0] for b in boxes) + max(b[3] for b in boxes)) / 2.0
    lat = (min(b[1] for b in boxes) + max(b[4] for b in boxes)) / 2.0
    if abs(lat) <= 84.0:
        zone = int((lon + 180.0) // 6.0) % 60 + 1
        target = CRS.from_epsg((32600 if lat >= 0 else 32700) + zone)
    else:
        target = CRS.from_proj4(
            f"+proj=aeqd +lat_0={lat:.6f} +lon_0={lon:.6f} +datum=WGS84 +units=m"
        )
    log.info("map %s is in longitude/latitude: plotted in %s", m.id, target.name)
    words = f"{_crs_words(target)}, from {_crs_words(m.crs)}"
    return reproject(m, target), target, words


def _unit(crs) -> tuple[float, str]:
    """Metres per CRS unit and the unit's short name."""
    if crs is None:
        return 1.0, "m"
    axis = _horizontal(crs).axis_info[0]
    factor = float(axis.unit_conversion_factor or 1.0)
    return factor, _UNIT_NAMES.get(axis.unit_name, axis.unit_name)


def _north(crs, window) -> str:
    """Grid north, and the angle to true north at the window's centre."""
    if crs is None:
        return "grid north (no CRS: true north unknown)"
    try:
        from pyproj import Transformer

        h = _horizontal(crs)
        geo = h.geodetic_crs
        if geo is None:
            return "grid north"
        cx, cy = (window[0] + window[2]) / 2.0, (window[1] + window[3]) / 2.0
        to_geo = Transformer.from_crs(h, geo, always_xy=True)
        to_grid = Transformer.from_crs(geo, h, always_xy=True)
        lon, lat = to_geo.transform(cx, cy)
        x2, y2 = to_grid.transform(lon, min(lat + 0.001, 89.999))
        theta = math.degrees(math.atan2(x2 - cx, y2 - cy))
    except Exception:  # a CRS PROJ cannot invert: the arrow still shows grid north
        return "grid north"
    if not math.isfinite(theta):
        return "grid north"
    if abs(theta) < 0.005:
        return "grid north = true north"
    side = "east" if theta > 0 else "west"
    return f"grid north; true north {abs(theta):.2f} deg {side} of it"


def _extent(layers, points: Sequence[ControlPoint]):
    xs0, ys0, xs1, ys1 = [], [], [], []
    for lay in layers:
        e = lay.extent()
        if e is not None:
            xs0.append(e[0])
            ys0.append(e[1])
            xs1.append(e[3])
            ys1.append(e[4])
    for p in points:
        xs0.append(p.x)
        ys0.append(p.y)
        xs1.append(p.x)
        ys1.append(p.y)
    if not xs0:
        return None
    return (min(xs0), min(ys0), max(xs1), max(ys1))


def _label_reach(m: MapFile, exts, pdef: PlotterDef, control: bool) -> np.ndarray:
    """Anchors of the labels and how far their preferred positions reach right and up, mm.

    (n, 4): ground X, Y and the paper mm right and above: a text starts at its point, a
    spot height's or control point's label starts right of its symbol.
    """
    th = pdef.text_height_mm
    gap = max(pdef.symbol_size_mm / 2.0, pdef.symbol_size_mm * 2.5 / 15.0) + 0.4 * th
    rows = []
    for e in exts:
        lay = m.layers[e]
        sym = lay.symbols
        if len(sym):
            labelled = np.ones(len(sym), dtype=bool) if control else sym["code"] == SPOT_HEIGHT_CODE
            for r in sym[labelled]:
                z = f"{float(r['z']):.{pdef.height_decimals}f}"
                text = f"{int(r['num'])}  {z}" if control else z
                rows.append((float(r["x"]), float(r["y"]), gap + text_size(text, th)[0], th / 2.0))
        if not control:
            for r in lay.texts:
                rows.append((float(r["x"]), float(r["y"]), text_size(str(r["text"]), th)[0], th))
    return np.array(rows, dtype=float).reshape(-1, 4)


def _in_window(x, y, window) -> np.ndarray:
    if window is None:
        return np.ones(np.shape(x), dtype=bool)
    return (x >= window[0]) & (x <= window[2]) & (y >= window[1]) & (y <= window[3])


def _legend_entries(
    m: MapFile, exts, pdef: PlotterDef, lib, window, control: bool, points
) -> list[LegendEntry]:
    """The symbols and line codes the plot draws (those inside ``window`` when given)."""
    from apygis.model.polylines import export_lines

    sym_keys: dict[tuple[int, int], None] = {}
    line_keys: dict[tuple[int, int, str], bool] = {}
    for e in exts:
        lay = m.layers[e]
        s = lay.symbols
        if len(s):
            inside = _in_window(s["x"], s["y"], window)
            for code in np.unique(s["code"][inside]).tolist():
                sym_keys.setdefault((int(code), pdef.pen_for(e, "symbols", int(code))), None)
        if control:
            continue
        ls = export_lines(lay)
        for k in range(len(ls)):
            a, b = int(ls.offsets[k]), int(ls.offsets[k + 1])
            pts = ls.coords[a:b]
            if window is not None and not _in_window(pts[:, 0], pts[:, 1], window).any():
                continue
            code = int(ls.codes[k])
            key = (code, pdef.pen_for(e, "lines", code), e)
            line_keys[key] = line_keys.get(key, True) and bool(ls.closed[k])
    out = []
    for code, pen in sorted(sym_keys):
        bm = np.asarray(lib[code].bitmap, dtype=bool)
        if not bm.any():
            bm = _fallback_bitmap()
        name = lib.name(code) if code != SPOT_HEIGHT_CODE else "spot height"
        out.append(LegendEntry("symbol", code, pen, f"{code:02d} {name}", bm))
    for (code, pen, e), closed in sorted(line_keys.items(), key=lambda kv: (kv[0][0], kv[0][2])):
        what = "closed line" if closed else "line"
        out.append(LegendEntry("line", code, pen, f"{what} {code:02d} (layer {e})", None, closed))
    if points:
        out.append(LegendEntry("control", 0, pdef.frame_pen, "control point (number, height)"))
    return out


# --------------------------------------------------------------------------- the sheet


def build_drawing(
    m: MapFile,
    plotdef: PlotterDef | None = None,
    library=None,
    layers: Sequence[str] | None = None,
    *,
    control: bool = False,
    control_points: Sequence[ControlPoint] = (),
    grid: str | None = None,
    sources: Sequence[str] = (),
    date: str | _dt.date | None = None,
    progress: Progress | None = None,
) -> Drawing:
    """Lay out map ``m`` on a sheet.

    Parameters
    ----------
    m : MapFile
        The map.
    plotdef : PlotterDef, optional
        Plotter parameters (paper, scale, window or origin, margins, pens,
        sizes, grid); default :meth:`PlotterDef.default`.
    library : SymbolLibrary, optional
        Symbol bitmaps; default :func:`apygis.model.symbols.load_library`.
    layers : sequence of str, optional
        Layer extensions to plot (default: all, in alphabetical order; for
        a control plot the control layer ``c``).
    control : bool
        A control-point and grid plot (the seed's "control points- and or
        grid-plot" for orienting a map): only the symbols of the layers
        (the control points), each labelled with its point number and
        height, the ``control_points`` given, and the grid as lines.
    control_points : sequence of ControlPoint
        Control points to draw too (from an orientation control file), each
        a circle and cross labelled with its id and height.
    grid : str, optional
        ``"crosses"``, ``"lines"`` or ``"off"``; default the plotter
        definition's (``"lines"`` for a control plot).
    sources : sequence of str
        The files the map was read from, for the title block.
    date : str or datetime.date, optional
        The date in the title block (:func:`plot_date`).
    progress : Progress, optional
        ``progress(done, total)`` as the sheet is laid out (:mod:`apygis.progress`).

    Returns
    -------
    Drawing

    Raises
    ------
    RecordError
        If ``layers`` names a layer the map lacks.
    FormatError
        If the plotter definition is inconsistent, or the margins leave no
        room on the paper.

    Examples
    --------
    >>> m = MapFile("T1", scale=1000)
    >>> _ = m.layer("r").add_line([(0, 0, 0), (100, 0, 0), (100, 50, 0)], code=12)
    >>> d = build_drawing(m, date="2024-01-01")
    >>> d.paper, d.scale, d.stats["lines"]
    ('A4 landscape', 1000, 1)
    >>> line = next(it for it in d.items if isinstance(it, PaperLine) and it.role == "line")
    >>> [[round(v, 3) for v in p] for p in (line.points - line.points[0]).tolist()]
    [[0.0, 0.0], [100.0, 0.0], [100.0, 50.0]]
    """
    from apygis.model.polylines import export_lines
    from apygis.model.symbols import load_library

    pdef = PlotterDef.default() if plotdef is None else plotdef
    problems = pdef.problems()
    if problems:
        raise FormatError("plotter definition: " + problems[0])
    if grid is not None and grid not in ("crosses", "lines", "off"):
        raise FormatError(f"grid must be crosses, lines or off, not {grid!r}")
    lib = load_library() if library is None else library
    if layers is None:
        exts = (["c"] if "c" in m.layers else []) if control else sorted(m.layers)
    else:
        exts = [e.lower() for e in layers]
        missing = [e for e in exts if e not in m.layers]
        if missing:
            raise RecordError(
                f"map {m.id} has no layer {', '.join(missing)} "
                f"(its layers: {' '.join(sorted(m.layers)) or 'none'})"
            )
    style = grid or pdef.grid
    if control and grid is None and style == "crosses":
        style = "lines"
    pm, crs, crs_words = _plot_crs(m)
    points = list(control_points)
    if points and pm is not m:  # control points are in the map's CRS: reproject them too
        from pyproj import Transformer

        tr = Transformer.from_crs(m.crs, crs, always_xy=True)
        xs, ys = tr.transform([p.x for p in points], [p.y for p in points])
        points = [
            ControlPoint(p.id, float(x), float(y), p.z)
            for p, x, y in zip(points, xs, ys, strict=True)
        ]
    unit_m, unit = _unit(crs)
    # a control plot covers the whole map, so that its grid orients the sheet
    extent = _extent(list(pm.layers.values()) if control else [pm.layers[e] for e in exts], points)
    label_reach = _label_reach(pm, exts, pdef, control)

    def extent_at(f: float):
        """The data and its labels at their preferred positions (they are sized on paper)."""
        if extent is None or not len(label_reach):
            return extent
        x = label_reach[:, 0] + label_reach[:, 2] / f
        y = label_reach[:, 1] + label_reach[:, 3] / f
        return (
            extent[0],
            extent[1],
            max(extent[2], float(x.max())),
            max(extent[3], float(y.max())),
        )

    scale_for_layout = pdef.scale or m.scale

    # the margin panel's blocks (their heights decide the layout)
    entries = (
        _legend_entries(pm, exts, pdef, lib, pdef.window, control, points) if pdef.legend else []
    )
    fpen = pdef.frame_pen
    gpen = pdef.grid_pen or fpen
    subtitle = "control point and grid plot" if control else ""

    def blocks_for(scale: int, f: float, interval: float | None, north: str) -> list[Block]:
        out: list[Block] = []
        if pdef.title or pdef.legend:
            out.append(heading_block(m.id, scale, subtitle, fpen))
        if pdef.legend:
            out.append(orientation_block(f, unit, fpen, COLUMN_MM, scale))
            out += legend_blocks(entries, pdef.symbol_size_mm, fpen, COLUMN_MM)
        if pdef.title:
            out.append(title_block(_title_rows(scale, interval, north), fpen, COLUMN_MM))
        return out

    sources_text = ", ".join(sources[:8]) + (
        f" and {len(sources) - 8} more" if len(sources) > 8 else ""
    )

    def _title_rows(scale: int, interval: float | None, north: str) -> list[tuple[str, str]]:
        sc = f"1:{scale}"
        if m.scale and m.scale != scale:
            sc += f" (compiled at 1:{m.scale})"
        rows = [("map", m.id), ("scale", sc), ("CRS", crs_words)]
        if interval is not None:
            rows.append(("grid", f"{interval:g} {unit}, {style}"))
        rows += [
            ("north", north),
            ("date", plot_date(date)),
            ("source", sources_text or "(not from a file)"),
            ("layers", " ".join(exts) or "none"),
        ]
        return rows

    provisional_scale = int(scale_for_layout or 5000)
    pf = unit_m * 1000.0 / provisional_scale
    interval0 = None if style == "off" else (pdef.grid_interval or grid_interval(pf))
    blocks = blocks_for(provisional_scale, pf, interval0, "grid north")
    spec = PanelSpec(COLUMN_MM, tuple(b.height for b in blocks), pdef.title) if blocks else None
    band = 6.0 if style != "off" else 2.0
    lay = plan_layout(extent_at, pdef, m.scale, unit_m, spec, band)
    f = lay.mm_per_unit
    interval = None if style == "off" else (pdef.grid_interval or grid_interval(f))
    if interval is not None and interval * f < MIN_GRID_MM:
        raise FormatError(
            f"the grid interval {interval:g} {unit} is {interval * f:.3g} mm on paper at "
            f"1:{lay.scale}; it must be at least {MIN_GRID_MM:g} mm "
            f"({MIN_GRID_MM / f:.3g} {unit}), or the grid off"
        )
    north = _north(crs, lay.window)
    blocks = blocks_for(lay.scale, f, interval, north)

    d = Drawing(
        width_mm=lay.width_mm,
        height_mm=lay.height_mm,
        paper=lay.paper,
        scale=lay.scale,
        origin=lay.origin,
        frame=lay.frame,
        pens=dict(pdef.pens),
        map_id=m.id,
        mm_per_unit=f,
        window=lay.window,
        crs_name=crs_words,
        unit=unit,
        grid_interval=interval,
        crs=crs,
    )
    stats: dict[str, Any] = dict.fromkeys(
        (
            "lines",
            "line_pieces",
            "lines_clipped",
            "lines_dropped",
            "symbols",
            "symbols_dropped",
            "spot_heights",
            "texts",
            "texts_dropped",
            "control_points",
            "labels",
            "labels_moved",
            "labels_overlapping",
            "texts_missing_glyphs",
        ),
        0,
    )
    stats["layers"] = exts
    items = d.items
    frame = lay.frame
    x0, y0, x1, y1 = frame

    # the grid under the map
    soft = np.zeros((0, 4))
    grid_over: list = []
    if interval is not None:
        under, grid_over, soft = grid_items(frame, lay.window, interval, style, gpen)
        items.extend(under)

    size = pdef.symbol_size_mm
    th = pdef.text_height_mm
    warned: set[int] = set()
    requests: list[LabelRequest] = []
    label_meta: list[tuple[int, str, str, int]] = []  # pen, role, description, symbol item
    obstacle_lines: list[np.ndarray] = []
    symbol_boxes: list[tuple[float, float, float, float]] = []
    data_progress = phase(progress, 0, 3)
    for k, e in enumerate(exts):
        if data_progress is not None:
            data_progress(k, len(exts))
        layer = pm.layers[e]
        # -- lines
        ls = export_lines(layer) if not control else None
        if ls is not None and len(ls):
            px, py = d.to_paper(ls.coords[:, 0], ls.coords[:, 1])
            xy = np.column_stack([px, py])
            inside = _inside(px, py, frame)
            outside_count = np.add.reduceat((~inside).astype(np.int64), ls.offsets[:-1])
            pens = {int(c): pdef.pen_for(e, "lines", int(c)) for c in np.unique(ls.codes)}
            for j in range(len(ls)):
                a, b = int(ls.offsets[j]), int(ls.offsets[j + 1])
                pts = xy[a:b]
                pen = pens[int(ls.codes[j])]
                closed = bool(ls.closed[j])
                if outside_count[j] == 0:
                    if len(pts) == 1:
                        pts = np.vstack([pts, pts])
                    items.append(PaperLine(pen, pts, closed))
                    obstacle_lines.append(np.vstack([pts, pts[:1]]) if closed else pts)
                    stats["lines"] += 1
                    stats["line_pieces"] += 1
                    continue
                pieces = clip_polyline(pts, frame, closed)
                if not pieces:
                    stats["lines_dropped"] += 1
                    continue
                stats["lines"] += 1
                stats["lines_clipped"] += 1
                for p in pieces:
                    if len(p) == 1:
                        p = np.vstack([p, p])
                    items.append(PaperLine(pen, p, False))
                    obstacle_lines.append(p)
                    stats["line_pieces"] += 1
        # -- symbols (spot heights and control points get a label)
        sym = layer.symbols
        if len(sym):
            sx, sy = d.to_paper(sym["x"], sym["y"])
            keep = _inside(sx, sy, frame)
            stats["symbols_dropped"] += int((~keep).sum())
            for i in np.flatnonzero(keep):
                code = int(sym["code"][i])
                bm = np.asarray(lib[code].bitmap, dtype=bool)
                if not bm.any():
                    if code not in warned:
                        log.warning("symbol code %02d has no bitmap; drawn as a square", code)
                        warned.add(code)
                    bm = _fallback_bitmap()
                rects = symbol_rects(bm, float(sx[i]), float(sy[i]), size)
                if len(rects):
                    symbol_boxes.append(
                        (rects[:, 0].min(), rects[:, 1].min(), rects[:, 2].max(), rects[:, 3].max())
                    )
                else:
                    symbol_boxes.append((sx[i], sy[i], sx[i], sy[i]))
                own = len(symbol_boxes) - 1
                rects[:, 0] = np.maximum(rects[:, 0], x0)
                rects[:, 1] = np.maximum(rects[:, 1], y0)
                rects[:, 2] = np.minimum(rects[:, 2], x1)
                rects[:, 3] = np.minimum(rects[:, 3], y1)
                rects = rects[(rects[:, 2] > rects[:, 0]) & (rects[:, 3] > rects[:, 1])]
                spen = pdef.pen_for(e, "symbols", code)
                sym_item = len(items)
                items.append(FilledRects(spen, rects))
                stats["symbols"] += 1
                half = (symbol_boxes[own][2] - symbol_boxes[own][0]) / 2.0
                gap = max(half, size * 2.5 / 15.0) + 0.4 * th
                if code == SPOT_HEIGHT_CODE and not control:
                    stats["spot_heights"] += 1
                    text = f"{float(sym['z'][i]):.{pdef.height_decimals}f}"
                    role = "spot-height"
                    what = f"spot height {e} {int(sym['num'][i])} ({text})"
                elif control:
                    stats["control_points"] += 1
                    z = float(sym["z"][i])
                    text = f"{int(sym['num'][i])}  {z:.{pdef.height_decimals}f}"
                    role = "control"
                    what = f"control point {e} {int(sym['num'][i])}"
                else:
                    continue
                w, dsc = text_size(text, th)
                requests.append(
                    LabelRequest(text, float(sx[i]), float(sy[i]), th, w, dsc, "point", gap, own)
                )
                label_meta.append((spen, role, what, sym_item))
        # -- texts
        tx_ = layer.texts
        if len(tx_) and not control:
            px, py = d.to_paper(tx_["x"], tx_["y"])
            keep = _inside(px, py, frame)
            stats["texts_dropped"] += int((~keep).sum())
            pen = pdef.pen_for(e, "texts")
            for i in np.flatnonzero(keep):
                text = str(tx_["text"][i])
                lack = missing_glyphs(text)
                if lack:
                    stats["texts_missing_glyphs"] += 1
                    log.warning(
                        "text %s.%s %d %r: the font (DejaVu Sans) lacks %r; they show as boxes",
                        m.id,
                        e,
                        int(tx_["num"][i]),
                        text,
                        lack,
                    )
                w, dsc = text_size(text, th)
                requests.append(
                    LabelRequest(text, float(px[i]), float(py[i]), th, w, dsc, "text", 0.5)
                )
                label_meta.append((pen, "text", f"text {e} {int(tx_['num'][i])} {text!r}", -1))
                stats["texts"] += 1
    # control points from a file
    if points:
        px, py = d.to_paper([p.x for p in points], [p.y for p in points])
        keep = _inside(px, py, frame)
        stats["symbols_dropped"] += int((~keep).sum())
        for i in np.flatnonzero(keep):
            cp = points[int(i)]
            x, y = float(px[i]), float(py[i])
            mark_item = len(items)
            items.extend(control_mark(x, y, fpen))
            r = CONTROL_MARK_MM * 1.6
            symbol_boxes.append((x - r, y - r, x + r, y + r))
            own = len(symbol_boxes) - 1
            text = cp.id if not math.isfinite(cp.z) else f"{cp.id}  {cp.z:.{pdef.height_decimals}f}"
            w, dsc = text_size(text, th)
            requests.append(LabelRequest(text, x, y, th, w, dsc, "point", r + 0.4 * th, own))
            label_meta.append((fpen, "control", f"control point {cp.id}", mark_item))
            stats["control_points"] += 1
    if data_progress is not None:
        data_progress(len(exts), len(exts))

    # the labels, placed
    placement = place_labels(
        requests,
        obstacle_lines,
        np.array(symbol_boxes, dtype=float).reshape(-1, 4),
        frame,
        soft,
        progress=phase(progress, 1, 3),
    )
    for k, req in enumerate(requests):
        pen, role, what, own_item = label_meta[k]
        d.labels.append((len(items), own_item, req.x, req.y))
        free = bool(placement.free[k])
        items.append(
            make_text(
                pen, placement.x[k], placement.y[k], req.height, req.text, role, halo=not free
            )
        )
        if not free:
            hits = []
            for name, arr in (
                ("line", placement.lines),
                ("symbol", placement.symbols),
                ("label", placement.labels),
            ):
                v = int(arr[k])
                if v:
                    hits.append(f"{v} {name}{'s' if v != 1 else ''}")
            if placement.frame[k]:
                hits.append("the neat line")
            d.unplaced.append(f"{what}: crosses {', '.join(hits)}")
    stats["labels"] = len(requests)
    stats["labels_moved"] = placement.moved
    stats["labels_overlapping"] = placement.overlapping
    margin_progress = phase(progress, 2, 3)

    # the neat line, the grid's ticks and labels, and the panel
    if pdef.frame:
        corners = np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], dtype=float)
        items.append(PaperLine(fpen, corners, True, "frame"))
    items.extend(grid_over)
    if lay.panel is not None and lay.columns:
        px0, _, _, py1 = lay.panel
        from apygis.plot.layout import BLOCK_GAP_MM, GAP_MM

        for c, col in enumerate(lay.columns):
            cx = px0 + c * (COLUMN_MM + GAP_MM)
            top = py1
            for j in col:
                if j >= len(blocks):
                    continue
                blk = blocks[j]
                if blk.name == "title" and j == len(blocks) - 1:
                    top = lay.panel[1] + blk.height  # the title block sits at the bottom
                items.extend(blk.draw(cx, top, COLUMN_MM))
                top -= blk.height + BLOCK_GAP_MM
    d.stats = stats
    if d.unplaced:
        log.info("labels that could not be placed free:\n  %s", "\n  ".join(d.unplaced))
    if margin_progress is not None:
        margin_progress(1, 1)
    log.info("plot of %s: %s", m.id, d.summary())
    return d
