"""The DXF writer: a map to one DXF file (see ``docs/formats/dxf.md``)."""

from __future__ import annotations

import io
import json
import zlib
from pathlib import Path

import numpy as np

from apygis.errors import DriverError, FormatError, ValueRangeError
from apygis.formats._io import atomic_write_many
from apygis.formats.dxf._common import (
    _CHUNK,
    _CTRL,
    _ENTITIES_END,
    _ENTITIES_START,
    _GRID,
    APPID,
    BLOCK_PREFIX,
    DEFAULT_SCALE,
    DXF_VERSIONS,
    FORMAT_NAME,
    FORMAT_VERSION,
    SYMBOL_SIZE_MM,
    TEXT_HEIGHT_MM,
)
from apygis.formats.dxf.templates import (
    _INSERT,
    _POLYLINE,
    _SEQEND,
    _TEXT,
    _VERTEX,
    _VERTEX_OWN,
    _fallback_bitmap,
    block_rects,
)
from apygis.model.map import Layer, MapFile, crs_string
from apygis.model.polylines import export_lines
from apygis.model.records import MAX_CODE

# The file is UTF-8 (as every DXF from R2007 on), but ezdxf declares ANSI_1252.
# GDAL's DXF driver ignores $ACADVER and decodes by $DWGCODEPAGE (ANSI_1252 as
# Latin-1): ANSI_65001 (UTF-8) makes it read the texts as written; ezdxf and
# AutoCAD read R2007+ files as UTF-8 whatever the code page. encode() declares
# ANSI_65001 only for a file with characters beyond ASCII: GDAL builds whose
# iconv lacks CP65001 (glibc's: Debian's GDAL 3.6, QGIS) recode every string
# with a warning (keeping the UTF-8 text, which is right), and a pure ASCII
# file reads the same in every code page, so it keeps ANSI_1252, warning-free.
_CODEPAGE_EZDXF = "\n$DWGCODEPAGE\n  3\nANSI_1252\n"
_CODEPAGE = "\n$DWGCODEPAGE\n  3\nANSI_65001\n"


def _check_writable(layer: Layer, path) -> None:
    for name in ("symbols", "line_points", "texts"):
        t = layer.table(name)
        if len(t):
            bad = ~(np.isfinite(t["x"]) & np.isfinite(t["y"]) & np.isfinite(t["z"]))
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ValueRangeError(
                    f"layer {layer.ext}: {name.replace('_', ' ')} record {i + 1} "
                    f"(number {t['num'][i]}) has a coordinate that is not finite",
                    path=path,
                )
    codes = layer.symbols["code"]
    bad = (codes < 0) | (codes > MAX_CODE)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueRangeError(
            f"layer {layer.ext}: symbol {layer.symbols['num'][i]} has code {codes[i]}, "
            f"outside 00-{MAX_CODE}",
            path=path,
        )
    for t in layer.texts["text"].tolist():
        if _CTRL.search(t):
            raise ValueRangeError(
                f"layer {layer.ext}: text {t!r} holds control characters", path=path
            )
        try:
            t.encode("utf-8")
        except UnicodeEncodeError:
            raise ValueRangeError(
                f"layer {layer.ext}: text {t!r} cannot be encoded as UTF-8", path=path
            ) from None


def _json_chunks(value) -> list[str]:
    # ASCII JSON; '+' escaped so that no "\U+XXXX" (a DXF unicode escape that
    # DXF readers decode) can appear in the file.
    s = json.dumps(value, ensure_ascii=True).replace("+", "\\u002b")
    return [s[i : i + _CHUNK] for i in range(0, len(s), _CHUNK)] or [""]


def _header_tags(map_: MapFile, entities: bytes) -> list[tuple[int, str]]:
    fields = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "id": map_.id,
        "scale": map_.scale,
        "crs": crs_string(map_.crs),
        "notes": map_.notes,
        "layers": list(map_.layers),
        "entities": [len(entities), zlib.crc32(entities)],
    }
    tags: list[tuple[int, str]] = []
    for key, value in fields.items():
        tags.append((1, key))
        tags.extend((3, chunk) for chunk in _json_chunks(value))
    return tags


# $INSUNITS codes of the linear units a CRS can have (DXF has none for degrees)
_INSUNITS = {
    "metre": 6,
    "foot": 2,
    "US survey foot": 21,
    "kilometre": 7,
    "centimetre": 5,
    "millimetre": 4,
    "inch": 1,
    "yard": 10,
    "mile": 3,
}
_IMPERIAL = {"foot", "US survey foot", "inch", "yard", "mile"}


def drawing_units(map_: MapFile) -> tuple[int, int, float]:
    """``($INSUNITS, $MEASUREMENT, metres per drawing unit)`` for the map's CRS.

    The drawing is in the CRS's units: metres (6) without a CRS or in a
    metric CRS, feet (2) or US survey feet (21) in a CRS in feet; a
    geographic CRS draws in degrees, which DXF cannot name: ``$INSUNITS`` 0
    (unitless), and a drawing unit is a degree of latitude at the data's mean
    latitude (sizes of texts and symbols are converted with it).

    >>> drawing_units(MapFile("A", crs="EPSG:2056"))
    (6, 1, 1.0)
    >>> drawing_units(MapFile("A", crs="EPSG:2229"))[:2]
    (21, 0)
    """
    from apygis.model.polylines import metres_per_unit_at

    if map_.crs is None:
        return 6, 1, 1.0
    axes = map_.crs.axis_info
    name = axes[0].unit_name if axes else "metre"
    ys = [lay.table(t)["y"] for lay in map_ for t in ("symbols", "line_points", "texts")]
    ys = [y for y in ys if len(y)]
    lat = float(np.mean(np.concatenate(ys))) if ys else 0.0
    _, north = metres_per_unit_at(map_.crs, lat)
    if map_.crs.is_geographic:
        return 0, 1, north
    return _INSUNITS.get(name, 0), 0 if name in _IMPERIAL else 1, north


def _skeleton(
    map_: MapFile,
    library,
    dxfversion: str,
    cell_m: float,
    text_m: float,
    insunits: int = 6,
    measurement: int = 1,
):
    """The ezdxf document: header, layers, symbol blocks, the header record."""
    import ezdxf

    doc = ezdxf.new(dxfversion, setup=False)
    doc.header["$INSUNITS"] = insunits  # the CRS's unit (0: degrees, which DXF cannot name)
    doc.header["$MEASUREMENT"] = measurement
    doc.header["$PROJECTNAME"] = map_.id
    doc.appids.add(APPID)
    for name, colour in layer_colours(map_.layers).items():
        doc.layers.add(name, color=colour)
    codes = sorted({int(c) for lay in map_.layers.values() for c in np.unique(lay.symbols["code"])})
    for code in codes:
        sym = library[code]
        bitmap = sym.bitmap if sym.bitmap.any() else _fallback_bitmap()
        blk = doc.blocks.new(f"{BLOCK_PREFIX}{code:02d}", base_point=(0, 0, 0))
        for x0, y0, x1, y1 in (block_rects(bitmap) * cell_m).tolist():
            blk.add_solid([(x0, y0), (x1, y0), (x0, y1), (x1, y1)])
        for tag, prompt in (("NUM", "point number"), ("CODE", sym.name), ("Z", "height (m)")):
            blk.add_attdef(tag, (0, 0), dxfattribs={"flags": 1, "height": text_m, "prompt": prompt})
    doc.rootdict.add_new_dict(APPID).add_xrecord("HEADER")  # filled in by encode()
    return doc


def _symbol_entities(layer: Layer, owner: int, start: int, text_m: float, cell_m: float):
    """INSERT + 3 ATTRIB + SEQEND per symbol, and a TEXT label per spot height."""
    s = layer.symbols
    if not len(s):
        return [], start
    code = s["code"].astype(np.int64)
    spot = code == 0
    count = 5 + spot.astype(np.int64)
    base = start + np.r_[0, np.cumsum(count)[:-1]]
    lay = layer.ext
    out = []
    for h, num, c, x, y, z, sp in zip(
        base.tolist(),
        s["num"].tolist(),
        code.tolist(),
        s["x"].tolist(),
        s["y"].tolist(),
        s["z"].tolist(),
        spot.tolist(),
        strict=True,
    ):
        zs = f"{z:.2f}"
        out.append(
            _INSERT
            % (
                h, owner, lay, f"{BLOCK_PREFIX}{c:02d}", x, y, z,
                h + 1, h, lay, x, y, z, text_m, num,
                h + 2, h, lay, x, y, z, text_m, f"{c:02d}",
                h + 3, h, lay, x, y, z, text_m, zs,
                h + 4, h, lay,
            )
        )  # fmt: skip
        if sp:
            out.append(
                _TEXT % (h + 5, owner, lay, x + 4 * cell_m, y - text_m / 2, z, text_m, zs, "H")
            )
    return out, start + int(count.sum())


def _set_extents(doc, map_: MapFile) -> None:
    """``$EXTMIN`` / ``$EXTMAX``: the 3-D extent of every record's position.

    ezdxf writes the header's extents from the model space's, so they are set
    there. The drawn symbol cells and labels reach a little beyond the points
    (a few paper millimetres at the map's scale); CAD programs use the extent
    for zooming to the drawing, for which the records' extent is what counts.
    Without records, the header keeps ezdxf's empty extent.
    """
    cols = [
        np.column_stack([t["x"], t["y"], t["z"]])
        for lay in map_.layers.values()
        for t in (lay.symbols, lay.line_points, lay.texts)
        if len(t)
    ]
    if not cols:
        return
    xyz = np.concatenate(cols)
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    msp = doc.modelspace()
    msp.dxf.extmin = tuple(float(v) for v in lo)
    msp.dxf.extmax = tuple(float(v) for v in hi)
    doc.header["$EXTMIN"] = msp.dxf.extmin
    doc.header["$EXTMAX"] = msp.dxf.extmax


def escape_text(text: str) -> str:
    """A text as a DXF ``TEXT`` string that CAD programs and GIS show as written.

    A caret starts a control character in DXF (``^J``, ``^I``): it is written
    ``^ `` (caret, space), a literal caret for AutoCAD, ezdxf and GDAL. ``%%``
    starts a control code (``%%d`` degree, ``%%c`` diameter, ``%%p`` plus-minus,
    ``%%u`` underline, ...): in a text with ``%%``, every ``%`` is written
    ``%%%``, AutoCAD's literal percent (which ezdxf follows; GDAL does not
    know it, see ``docs/formats/dxf.md``). Other texts are written unchanged.

    >>> escape_text("a^Jb"), escape_text("50%"), escape_text("50%%d")
    ('a^ Jb', '50%', '50%%%%%%d')
    """
    if "^" in text:
        text = text.replace("^", "^ ")
    if "%%" in text:
        text = text.replace("%", "%%%")
    return text


# Colours (AutoCAD Color Index) of the DXF layers: the plotter's default pens
# where it has one for the layer (h blue, e brown; apygis.plot.plotdef), else the
# palette in map order; see docs/formats/dxf.md.
LAYER_COLOURS = {"h": 5, "e": 34}
LAYER_PALETTE = (1, 3, 6, 30, 4, 8, 2, 200, 140, 40)


def layer_colours(exts) -> dict[str, int]:
    """The ACI colour of each map layer's DXF layer.

    >>> layer_colours(["c", "e", "h", "r"])
    {'c': 1, 'e': 34, 'h': 5, 'r': 3}
    """
    out = {}
    k = 0
    for ext in exts:
        if ext in LAYER_COLOURS:
            out[ext] = LAYER_COLOURS[ext]
        else:
            out[ext] = LAYER_PALETTE[k % len(LAYER_PALETTE)]
            k += 1
    return out


def _text_entities(layer: Layer, owner: int, start: int, text_m: float):
    t = layer.texts
    out = []
    for k, (num, x, y, z, text) in enumerate(
        zip(
            t["num"].tolist(),
            t["x"].tolist(),
            t["y"].tolist(),
            t["z"].tolist(),
            t["text"].tolist(),
            strict=True,
        )
    ):
        # DXF readers decode "\U+XXXX" in strings, and the escaped text differs
        # from the text: keep such texts exact in the XDATA
        written = escape_text(text)
        exact = "\\" in text or written != text
        xd = f"T {num} {text.encode('utf-8').hex()}" if exact else f"T {num}"
        out.append(_TEXT % (start + k, owner, layer.ext, x, y, z, text_m, written, xd))
    return out, start + len(t)


def _line_entities(layer: Layer, owner: int, start: int):
    """POLYLINE, VERTEXes and SEQEND per chain, formatted in bulk."""
    lp = layer.line_points
    if not len(lp):
        return [], start
    ls = export_lines(layer)  # branch ends carry their junction's vertex (no XDATA)
    nverts = np.diff(ls.offsets)
    ents = nverts + 2  # POLYLINE + vertices + SEQEND
    eoff = np.r_[0, np.cumsum(ents)]  # entity slots per chain
    pl_handle = start + eoff[:-1]
    cid = ls.line_index()
    slot = eoff[cid] + 1 + np.arange(len(ls.rows)) - ls.offsets[cid]  # slot of every vertex
    lay = layer.ext
    pieces = np.empty(int(eoff[-1]), dtype=object)
    own = ls.own
    rows, oslot, ocid = ls.rows[own], slot[own], cid[own]
    pieces[oslot] = [
        _VERTEX_OWN % t
        for t in zip(
            (start + oslot).tolist(),
            pl_handle[ocid].tolist(),
            [lay] * len(rows),
            lp["x"][rows].tolist(),
            lp["y"][rows].tolist(),
            lp["z"][rows].tolist(),
            lp["num"][rows].tolist(),
            lp["code"][rows].tolist(),
            lp["fwd"][rows].tolist(),
            lp["back"][rows].tolist(),
            lp["side1"][rows].tolist(),
            lp["side2"][rows].tolist(),
            rows.tolist(),
            strict=True,
        )
    ]
    r, xslot, xcid = ls.rows[~own], slot[~own], cid[~own]
    pieces[xslot] = [
        _VERTEX % t
        for t in zip(
            (start + xslot).tolist(),
            pl_handle[xcid].tolist(),
            [lay] * len(r),
            lp["x"][r].tolist(),
            lp["y"][r].tolist(),
            lp["z"][r].tolist(),
            strict=True,
        )
    ]
    flags = np.where(ls.closed, 9, 8)
    pieces[eoff[:-1]] = [
        _POLYLINE % (h, owner, lay, f)
        for h, f in zip(pl_handle.tolist(), flags.tolist(), strict=True)
    ]
    pieces[eoff[1:] - 1] = [
        _SEQEND % (h, p, lay)
        for h, p in zip((start + eoff[1:] - 1).tolist(), pl_handle.tolist(), strict=True)
    ]
    return pieces.tolist(), start + int(eoff[-1])


def encode(map_: MapFile, library=None, dxfversion: str = "R2010", path=None, progress=None):
    """The DXF file of a map, as bytes (UTF-8).

    Parameters
    ----------
    map_ : MapFile
    library : SymbolLibrary, optional
        The symbols to draw the blocks from; :func:`~apygis.model.symbols.load_library`
        by default (the user's library, or the default set).
    dxfversion : {"R2010", "R2013", "R2018"}
    path : optional
        Named in error messages.
    progress : callable, optional
        ``progress(done, total)`` after each layer.
    """
    from apygis.model.symbols import load_library

    if dxfversion not in DXF_VERSIONS:
        raise DriverError(
            f"dxf: DXF version {dxfversion!r} is not written; choose one of "
            f"{', '.join(DXF_VERSIONS)}"
        )
    for lay in map_.layers.values():
        _check_writable(lay, path)
    if library is None:
        library = load_library()
    scale = map_.scale or DEFAULT_SCALE
    insunits, measurement, unit_m = drawing_units(map_)
    # sizes on paper at the map's scale, in the drawing's (the CRS's) units
    cell_m = SYMBOL_SIZE_MM / _GRID * scale / 1000.0 / unit_m
    text_m = TEXT_HEIGHT_MM * scale / 1000.0 / unit_m
    doc = _skeleton(map_, library, dxfversion, cell_m, text_m, insunits, measurement)
    owner = int(doc.modelspace().block_record_handle, 16)
    start = int(str(doc.entitydb.handles), 16)
    h = start
    parts: list[str] = []
    n = len(map_.layers)
    for k, lay in enumerate(map_.layers.values()):
        out, h = _symbol_entities(lay, owner, h, text_m, cell_m)
        parts += out
        out, h = _line_entities(lay, owner, h)
        parts += out
        out, h = _text_entities(lay, owner, h, text_m)
        parts += out
        if progress:
            progress(k + 1, n + 1)
    entities = "".join(parts).encode("utf-8")
    del parts
    _set_extents(doc, map_)
    doc.rootdict[APPID]["HEADER"].reset(_header_tags(map_, entities))
    doc.entitydb.handles.reset(f"{h:X}")  # the handles above are taken
    buf = io.StringIO()
    doc.write(buf)
    skeleton = buf.getvalue()
    if _CODEPAGE_EZDXF not in skeleton:  # pragma: no cover - ezdxf's layout
        raise FormatError("ezdxf wrote no $DWGCODEPAGE ANSI_1252", path=path)
    if not (entities.isascii() and skeleton.isascii()):  # see _CODEPAGE
        skeleton = skeleton.replace(_CODEPAGE_EZDXF, _CODEPAGE, 1)
    sec = skeleton.find(_ENTITIES_START)
    end = skeleton.find(_ENTITIES_END, sec)
    if sec < 0 or end != sec + len(_ENTITIES_START):  # pragma: no cover - ezdxf's layout
        raise FormatError("ezdxf wrote no empty ENTITIES section", path=path)
    data = b"".join([skeleton[:end].encode("utf-8"), entities, skeleton[end:].encode("utf-8")])
    if progress:
        progress(n + 1, n + 1)
    return data


def write(map_: MapFile, path, progress=None, version: str = "R2010") -> list[Path]:
    """Write a map as one DXF file, atomically; returns ``[path]``.

    ``version``: ``"R2010"`` (default), ``"R2013"`` or ``"R2018"``; see
    :func:`encode`. The symbol blocks are drawn from the user's symbol library.
    """
    data = encode(map_, dxfversion=version, path=path, progress=progress)
    return atomic_write_many({Path(path): data})
