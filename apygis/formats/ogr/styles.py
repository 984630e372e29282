"""What QGIS users look for in a GeoPackage apygis wrote: layer descriptions and styles.

Descriptions go to ``gpkg_contents.description`` (QGIS shows them as the
layer's abstract, GDAL as ``DESCRIPTION``). Styles go to the table
``layer_styles`` that QGIS reads (and writes with "Save as default in the
datasource"): one default style per spatial table, QGIS's own QML, so the
GeoPackage opens in QGIS looking like the plot:

* ``L_symbols``: a categorised renderer on ``code``; each code used is drawn
  from the symbol library's 15x15 bitmap (an embedded SVG), 3 mm wide, in
  the pen of the layer; spot heights (00) labelled with their height;
* ``L_lines`` and ``L_areas``: lines in the colour and width of the layer's
  pen (areas unfilled);
* ``L_texts``: the text, 2.5 mm high, in the pen's colour, no marker;
* ``L_line_points``: small grey dots (the topology records).

The pens are the plotter's default pens (``apygis.plot.plotdef``: layer
``h`` blue 0.25 mm, ``e`` brown 0.25 mm, every other layer black 0.35 mm;
sizes as the plot draws them, ``SYMBOL_SIZE_MM`` and ``TEXT_HEIGHT_MM``).
"""

from __future__ import annotations

import base64
from xml.sax.saxutils import quoteattr

import numpy as np

from apygis.model.records import MAX_CODE

__all__ = ["PENS", "description", "pen_of", "qml"]

SYMBOL_SIZE_MM = 3.0
TEXT_HEIGHT_MM = 2.5

# (colour RGB, width mm) of the plotter's default pens per map layer (plotdef)
PENS = {"h": ((0, 112, 192), 0.25), "e": ((150, 80, 20), 0.25)}
DEFAULT_PEN = ((0, 0, 0), 0.35)

_WHAT = {
    "symbols": "symbols (point number num, symbol code 00-99 and its name)",
    "lines": "open lines (line code, point numbers of the vertices)",
    "areas": "closed lines (line code, point numbers of the vertices)",
    "texts": "texts (point number, text)",
    "line_points": "line points with their references fwd, back, side1, side2 (the topology)",
}


def pen_of(ext: str) -> tuple[tuple[int, int, int], float]:
    """The default pen (RGB, width in mm) of map layer ``ext``."""
    return PENS.get(ext, DEFAULT_PEN)


def description(table: str, kind: str, ext: str, map_id: str) -> str:
    """The ``gpkg_contents.description`` of an OGR table of the schema."""
    if kind == "map":
        return f"apygis map {map_id}: header (id, scale, CRS, notes, layers)"
    return f"apygis map {map_id}, layer {ext}: {_WHAT[kind]}"


def _rgba(rgb, alpha: int = 255) -> str:
    return f"{rgb[0]},{rgb[1]},{rgb[2]},{alpha}"


def _props(layer_class: str, props: dict[str, object]) -> str:
    inner = "".join(f"<prop k={quoteattr(k)} v={quoteattr(str(v))}/>" for k, v in props.items())
    return f'<layer class="{layer_class}" enabled="1" locked="0" pass="0">{inner}</layer>'


def _symbol(name: str, kind: str, layers: list[str]) -> str:
    return (
        f'<symbol name="{name}" type="{kind}" alpha="1" clip_to_extent="1" force_rhr="0">'
        + "".join(layers)
        + "</symbol>"
    )


def bitmap_svg(bitmap: np.ndarray, rgb) -> str:
    """A 15x15 bitmap as an SVG of filled cells (row 0 at the top)."""
    rows, cols = np.nonzero(np.asarray(bitmap, dtype=bool))
    fill = "#{:02x}{:02x}{:02x}".format(*rgb)
    cells = "".join(
        f'<rect x="{c}" y="{r}" width="1" height="1"/>' for r, c in zip(rows, cols, strict=True)
    )
    return (
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 15 15" width="15" height="15">'
        f'<g fill="{fill}" shape-rendering="crispEdges">{cells}</g></svg>'
    )


def _svg_marker(bitmap, rgb) -> str:
    data = base64.b64encode(bitmap_svg(bitmap, rgb).encode()).decode()
    return _props(
        "SvgMarker",
        {
            "name": f"base64:{data}",
            "size": SYMBOL_SIZE_MM,
            "size_unit": "MM",
            "color": _rgba(rgb),
            "outline_color": _rgba(rgb),
            "outline_width": 0,
            "scale_method": "diameter",
            "horizontal_anchor_point": 1,
            "vertical_anchor_point": 1,
            "angle": 0,
            "offset": "0,0",
            "offset_unit": "MM",
        },
    )


def _simple_marker(rgb, size: float) -> str:
    return _props(
        "SimpleMarker",
        {
            "name": "circle",
            "size": size,
            "size_unit": "MM",
            "color": _rgba(rgb),
            "outline_style": "no",
            "angle": 0,
            "offset": "0,0",
            "offset_unit": "MM",
        },
    )


def _line(rgb, width: float) -> str:
    return _props(
        "SimpleLine",
        {
            "line_color": _rgba(rgb),
            "line_width": width,
            "line_width_unit": "MM",
            "line_style": "solid",
            "capstyle": "round",
            "joinstyle": "round",
        },
    )


def _outline(rgb, width: float) -> str:
    return _props(
        "SimpleFill",
        {
            "color": _rgba(rgb, 0),
            "style": "no",
            "outline_color": _rgba(rgb),
            "outline_width": width,
            "outline_width_unit": "MM",
            "outline_style": "solid",
        },
    )


def _single(symbol: str) -> str:
    return (
        '<renderer-v2 type="singleSymbol" forceraster="0" symbollevels="0" enableorderby="0">'
        f"<symbols>{symbol}</symbols></renderer-v2>"
    )


def _labels(expression: str, is_expression: bool, rgb, placement: int) -> str:
    return (
        '<labeling type="simple"><settings calloutType="simple">'
        f"<text-style fieldName={quoteattr(expression)} isExpression="
        f'"{int(is_expression)}" fontSize="{TEXT_HEIGHT_MM}" fontSizeUnit="MM" '
        f'textColor="{_rgba(rgb)}" fontFamily="DejaVu Sans" fontWeight="50" '
        'textOpacity="1" multilineHeight="1"/>'
        '<text-format wrapChar="" multilineAlign="0" formatNumbers="0" decimals="2"/>'
        f'<placement placement="{placement}" dist="1" distUnits="MM" quadOffset="5" '
        'xOffset="0" yOffset="0" offsetUnits="MM" priority="5"/>'
        '<rendering drawLabels="1" obstacle="1" scaleVisibility="0" upsidedownLabels="0" '
        'displayAll="1"/>'
        "</settings></labeling>"
    )


def qml(kind: str, ext: str, codes=(), library=None) -> str:
    """QGIS's style (QML) for an OGR table of the schema of map layer ``ext``.

    ``kind`` is ``symbols``, ``lines``, ``areas``, ``texts`` or
    ``line_points``; ``codes`` the symbol codes used (``symbols`` only),
    drawn from ``library`` (default: the user's symbol library).
    """
    rgb, width = pen_of(ext)
    labels = ""
    if kind == "symbols":
        if library is None:
            from apygis.model.symbols import load_library

            library = load_library()
        cats, syms = [], []
        for i, code in enumerate(sorted({int(c) for c in codes})):
            sym = library[code] if 0 <= code <= MAX_CODE else None
            bitmap = sym.bitmap if sym is not None and sym.bitmap.any() else np.eye(15, dtype=bool)
            name = sym.name if sym is not None else "?"
            cats.append(
                f'<category symbol="{i}" value="{code}" render="true" '
                f"label={quoteattr(f'{code:02d} {name}')}/>"
            )
            syms.append(_symbol(str(i), "marker", [_svg_marker(bitmap, rgb)]))
        renderer = (
            '<renderer-v2 type="categorizedSymbol" attr="code" forceraster="0" '
            'symbollevels="0" enableorderby="0">'
            f"<categories>{''.join(cats)}</categories><symbols>{''.join(syms)}</symbols>"
            "</renderer-v2>"
        )
        if 0 in {int(c) for c in codes}:  # spot heights: their height, right of the cross
            expr = 'CASE WHEN "code" = 0 THEN format_number(z($geometry), 1) END'
            labels = _labels(expr, True, rgb, 1)
        geometry = 0
    elif kind in ("lines", "areas"):
        layer = _line(rgb, width) if kind == "lines" else _outline(rgb, width)
        renderer = _single(_symbol("0", "line" if kind == "lines" else "fill", [layer]))
        geometry = 1 if kind == "lines" else 2
    elif kind == "texts":
        renderer = _single(_symbol("0", "marker", [_simple_marker(rgb, 0.0)]))
        labels = _labels("text", False, rgb, 1)
        geometry = 0
    elif kind == "line_points":
        renderer = _single(_symbol("0", "marker", [_simple_marker((128, 128, 128), 0.6)]))
        geometry = 0
    else:
        raise ValueError(f"no style for {kind!r}")
    enabled = "1" if labels else "0"
    return (
        "<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>"
        f'<qgis version="3.22.0" styleCategories="Symbology|Labeling" labelsEnabled="{enabled}">'
        f"{renderer}{labels}<blendMode>0</blendMode><featureBlendMode>0</featureBlendMode>"
        f"<layerGeometryType>{geometry}</layerGeometryType></qgis>"
    )
