"""What the page draws, as JSON-ready data: the map's records, its pens and symbols.

A record travels as one list, in the field order of
:mod:`apygis.model.records` (coordinates in metres of the map's CRS, exact:
JSON numbers round-trip a float64)::

    symbols       [num, x, y, z, code]
    line_points   [num, x, y, z, code, fwd, back, side1, side2]    (-1: no reference)
    texts         [num, x, y, z, text]

The page draws every layer as the plot would (``apygis plot``): lines in the
pen of their layer and line code, symbols as the painted cells of their 15x15
bitmaps, texts and spot heights, all sized in paper millimetres at the
display scale. Pens come from a :class:`~apygis.plot.plotdef.PlotterDef`
(the built-in one unless ``--plotter`` names a PLOTTER.DEF), symbols from the
symbol library.

>>> from apygis.model.map import MapFile
>>> m = MapFile("T1", scale=1000)
>>> _ = m.layer("r").add_line([(0, 0, 1), (100, 0, 2)], code=12)
>>> layer_rows(m.layers["r"])["line_points"]
[[1, 0.0, 0.0, 1.0, 12, 2, -1, -1, -1], [2, 100.0, 0.0, 2.0, 12, -1, 1, -1, -1]]
>>> Pens().layer("r")["lines"][12], Pens().layer("h")["lines"][31]
(1, 2)
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from apygis.model.map import Layer, MapFile
from apygis.model.records import TABLES
from apygis.plot.plotdef import PlotterDef

__all__ = ["TABLE_NAMES", "Pens", "layer_rows", "map_meta", "rows_of", "symbol_table"]

log = logging.getLogger(__name__)

#: The record tables, in the order the page lists them.
TABLE_NAMES = tuple(TABLES)


def rows_of(table: np.ndarray) -> list[list]:
    """A record table (numpy structured array) as a list of row lists."""
    return [list(r) for r in table.tolist()]


def layer_rows(layer: Layer) -> dict[str, list[list]]:
    """A layer's three tables as row lists (see the module's docstring)."""
    return {name: rows_of(layer.table(name)) for name in TABLE_NAMES}


def map_meta(m: MapFile, source: str = "") -> dict[str, Any]:
    """The map's identification, scale, CRS (its code and name) and extent (metres)."""
    crs = m.crs_string()
    name = None
    if m.crs is not None:
        try:
            name = m.crs.name
        except AttributeError:  # pragma: no cover - the model keeps a pyproj CRS
            name = None
    ext = None
    exts = [lay.extent() for lay in m if len(lay)]
    exts = [e for e in exts if e is not None]
    if exts:
        a = np.array(exts, dtype=float)
        ext = [
            float(a[:, 0].min()),
            float(a[:, 1].min()),
            float(a[:, 3].max()),
            float(a[:, 4].max()),
        ]
    return {
        "id": m.id,
        "scale": m.scale,
        "crs": crs if crs is None or len(crs) <= 40 else "custom CRS",
        "crs_name": name,
        "extent": ext,
        "source": source,
    }


class Pens:
    """The plot's pens for the page: which pen draws what, and each pen's colour and width.

    Parameters
    ----------
    plotdef : PlotterDef, optional
        The plotter definition (default: the built-in one). A pen that a rule
        names but the definition does not define draws black, 0.25 mm.
    """

    def __init__(self, plotdef: PlotterDef | None = None):
        self.plotdef = PlotterDef.default() if plotdef is None else plotdef
        self._layers: dict[str, dict[str, Any]] = {}

    def pens(self) -> dict[str, dict[str, Any]]:
        """Pen number (as a string, for JSON) -> ``{"colour": "#rrggbb", "width_mm": w}``."""
        out = {
            str(n): {"colour": p.hex, "width_mm": float(p.width_mm)}
            for n, p in self.plotdef.pens.items()
        }
        for lay in self._layers.values():
            for n in {*lay["symbols"], *lay["lines"], lay["texts"]}:
                out.setdefault(str(n), {"colour": "#000000", "width_mm": 0.25})
        return out

    def layer(self, ext: str) -> dict[str, Any]:
        """The pens of layer ``ext``: ``symbols`` and ``lines`` by code (0-99), ``texts``."""
        got = self._layers.get(ext)
        if got is None:
            pf = self.plotdef.pen_for
            got = {
                "symbols": [pf(ext, "symbols", c) for c in range(100)],
                "lines": [pf(ext, "lines", c) for c in range(100)],
                "texts": pf(ext, "texts"),
            }
            self._layers[ext] = got
        return got

    def style(self) -> dict[str, Any]:
        """Sizes of the plot, paper millimetres: symbols, text height, spot-height decimals."""
        p = self.plotdef
        return {
            "symbol_size_mm": float(p.symbol_size_mm),
            "text_height_mm": float(p.text_height_mm),
            "height_decimals": int(p.height_decimals),
        }


def symbol_table(library) -> dict[str, dict[str, Any]]:
    """The library's designed symbols: code -> ``{"name", "rows"}``.

    ``rows`` are the 15 bitmap rows, top first, each an integer whose bit
    ``14 - col`` is the cell of column ``col`` (column 0 leftmost). Free slots
    are left out; the page draws a code without a bitmap as an open square,
    as the plot does.
    """
    out = {}
    for code in library:
        sym = library[code]
        bm = np.asarray(sym.bitmap, dtype=bool)
        if not bm.any():
            continue
        weights = 1 << np.arange(bm.shape[1] - 1, -1, -1)
        out[str(code)] = {"name": sym.name, "rows": [int(v) for v in (bm * weights).sum(axis=1)]}
    return out
