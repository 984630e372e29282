"""DXF: a whole map as one AutoCAD drawing exchange file (APY's "make DXF files").

The mapping is specified in ``docs/formats/dxf.md``; in short:

Writing (DXF R2010 by default, readable by CAD programs, GDAL and ezdxf):

* one DXF layer per map layer, named like the layer's extension (``r``);
* a line (chain) is a 3-D ``POLYLINE``, closed lines closed; a branch gets
  its junction's vertex as an extra first or last vertex so that the drawn
  line touches it;
* a symbol is an ``INSERT`` of the block ``APY_SYM_NN`` (its code, two
  digits) with the invisible attributes ``NUM``, ``CODE`` and ``Z``; the
  block draws the 15x15 bitmap of the symbol library as filled ``SOLID``
  rectangles, :data:`SYMBOL_SIZE_MM` wide on paper at the map's scale;
* a spot height (code 00) is also labelled with its height as a ``TEXT``;
  a text is a ``TEXT`` (:data:`TEXT_HEIGHT_MM` high on paper) at its 3-D
  position;
* point numbers, codes, the four references and the table order of every
  line point are kept as XDATA (application ``APYGIS``) on each ``VERTEX``;
  a text's point number as XDATA on its ``TEXT``;
* the map header (ID, scale, CRS, notes, layer list) is an ``XRECORD``
  ``HEADER`` in the dictionary ``APYGIS`` of the objects section.

So apygis reads its own DXF back record for record. The entities are
formatted as text in bulk (a few string operations per vertex) and spliced
into a document that ezdxf builds (header, tables, blocks, objects): a
million line points take seconds, not minutes.

Reading any DXF (through :func:`ezdxf.recover.read`, which repairs broken
legacy files; what it repaired is logged): model-space ``POINT`` and
``INSERT`` become symbols, ``LINE``, ``LWPOLYLINE``, ``POLYLINE`` (2-D in
their object coordinate system, or 3-D) and flattened ``ARC``, ``CIRCLE``,
``ELLIPSE`` and ``SPLINE`` become lines, ``TEXT`` and ``MTEXT`` texts. DXF
layers map to map layers by ``layer_map``; lines without apygis XDATA get
their topology rebuilt by the model's one rebuild, :meth:`apygis.model.Layer.add_polylines`
(its report logged). A file that
apygis wrote and nobody changed since (the header record holds the size and
CRC-32 of the entities section) is parsed by the writer's own templates
instead of ezdxf: the same records, a hundred times faster.

Examples
--------
>>> import tempfile, os
>>> from apygis.model.map import MapFile
>>> m = MapFile("T1", scale=5000, crs="EPSG:2056")
>>> _ = m.layer("r").add_line([(0, 0, 400), (50, 0, 401), (50, 30, 402)], code=12)
>>> _ = m.layer("r").add_symbol(10.0, 5.0, 400.5, code=6)
>>> with tempfile.TemporaryDirectory() as d:
...     _ = write(m, os.path.join(d, "t1.dxf"))
...     read(os.path.join(d, "t1.dxf")) == m
True
>>> parse_layer_map("ROADS=r, WATER=h, Defpoints=-")
{'ROADS': 'r', 'WATER': 'h', 'DEFPOINTS': None}
"""

from __future__ import annotations

import io
import json
import logging
import math
import re
import zlib
from collections import Counter
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from apygis.errors import (
    ApygisError,
    DriverError,
    FormatError,
    RecordError,
    TopologyError,
    ValueRangeError,
)
from apygis.formats import Driver
from apygis.formats._io import atomic_write_many, read_bytes
from apygis.formats._readguard import MAX_COORD, ascii_int, check_str, loads_json
from apygis.model.map import Layer, MapFile, check_ext, check_map_id, crs_string
from apygis.model.polylines import export_lines, to_csr
from apygis.model.records import (
    LINE_DTYPE,
    MAX_CODE,
    TEXT_LEN,
    next_numbers,
)

__all__ = [
    "APPID",
    "BLOCK_PREFIX",
    "DEFAULT_SCALE",
    "DRIVER",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "SYMBOL_SIZE_MM",
    "TEXT_HEIGHT_MM",
    "block_rects",
    "encode",
    "parse_layer_map",
    "probe",
    "read",
    "write",
]

log = logging.getLogger(__name__)

APPID = "APYGIS"
"""The registered application name of apygis's XDATA and objects dictionary."""
FORMAT_NAME = "apygis-dxf"
FORMAT_VERSION = 1
BLOCK_PREFIX = "APY_SYM_"
"""Symbol blocks are named ``APY_SYM_NN`` (NN: the code, two digits)."""
SYMBOL_SIZE_MM = 3.0
"""Width of a symbol (its 15x15 grid) on paper at the map's scale, in mm."""
TEXT_HEIGHT_MM = 2.5
"""Height of texts, spot-height labels and attributes on paper, in mm."""
DEFAULT_SCALE = 1000
"""The scale denominator the sizes are computed for when a map has no scale."""
DXF_VERSIONS = {"R2010": "AC1024", "R2013": "AC1027", "R2018": "AC1032"}

_GRID = 15
_CHUNK = 250  # characters per string tag of the header record
_BINARY_SENTINEL = b"AutoCAD Binary DXF\r\n\x1a\x00"
_BLOCK_RE = re.compile(rf"^{BLOCK_PREFIX}([0-9][0-9])$", re.IGNORECASE)
_EXT_LIKE = re.compile(r"^[A-Za-z]{1,3}$")
_CTRL = re.compile("[\x00-\x1f\x7f-\x9f]")
_ENTITIES_START = "\n  2\nENTITIES\n"
_ENTITIES_END = "  0\nENDSEC\n"
_CURVE_TYPES = ("ARC", "CIRCLE", "ELLIPSE", "SPLINE")


# =========================================================================== symbols


def block_rects(bitmap) -> np.ndarray:
    """The painted cells of a 15x15 bitmap as few rectangles, in cell units.

    Returns ``(k, 4)`` floats ``x0, y0, x1, y1`` with the grid centred on
    the origin (the centre of cell row 7, column 7), x to the right and y up
    (row 0 is the top). Runs of painted cells in a row make one rectangle;
    identical runs in consecutive rows are merged.

    >>> bm = np.zeros((15, 15), bool)
    >>> bm[7, 5:10] = True
    >>> bm[5:10, 7] = True
    >>> block_rects(bm).tolist()
    [[-0.5, 0.5, 0.5, 2.5], [-2.5, -0.5, 2.5, 0.5], [-0.5, -2.5, 0.5, -0.5]]
    """
    bm = np.asarray(bitmap, dtype=bool)
    runs: list[list[int]] = []  # [row0, row1, col0, col1], col1 exclusive
    open_runs: dict[tuple[int, int], list[int]] = {}
    for r in range(bm.shape[0]):
        row = np.r_[False, bm[r], False].astype(np.int8)
        edges = np.flatnonzero(np.diff(row))
        here = {}
        for c0, c1 in zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True):
            run = open_runs.get((c0, c1))
            if run is not None and run[1] == r - 1:
                run[1] = r
            else:
                run = [r, r, c0, c1]
                runs.append(run)
            here[(c0, c1)] = run
        open_runs = here
    half = _GRID / 2.0
    out = [(c0 - half, half - r1 - 1, c1 - half, half - r0) for r0, r1, c0, c1 in runs]
    return np.array(out, dtype=float).reshape(-1, 4)


def _fallback_bitmap() -> np.ndarray:
    """An open square of 5x5 cells, drawn for a code the library leaves free."""
    bm = np.zeros((_GRID, _GRID), dtype=bool)
    bm[5, 5:10] = bm[9, 5:10] = True
    bm[5:10, 5] = bm[5:10, 9] = True
    return bm


# =========================================================================== options


def parse_layer_map(value) -> dict[str, str | None]:
    """A layer map from a dict or from the CLI form ``"ROADS=r,WATER=h"``.

    Keys are DXF layer names (compared without regard to case, as DXF
    does); values are layer extensions (1-3 letters), or ``None`` / ``"-"``
    / ``""`` to skip the layer's entities. Returned with upper-case keys.

    >>> parse_layer_map({"Roads": "R", "0": "-"})
    {'ROADS': 'r', '0': None}
    """
    if value is None:
        return {}
    if isinstance(value, str):
        items = []
        for part in value.split(","):
            if not part.strip():
                continue
            name, sep, ext = part.rpartition("=")
            if not sep or not name.strip():
                raise DriverError(
                    f"dxf layer_map: expected DXF-LAYER=ext pairs separated by commas, "
                    f"not {part.strip()!r}"
                )
            items.append((name.strip(), ext.strip()))
    elif isinstance(value, Mapping):
        items = list(value.items())
    else:
        raise DriverError(f"dxf layer_map: a dict or a string 'A=x,B=y', not {value!r}")
    out: dict[str, str | None] = {}
    for name, ext in items:
        if not isinstance(name, str):
            raise DriverError(f"dxf layer_map: a DXF layer name is a string, not {name!r}")
        if ext is None or ext in ("", "-"):
            out[name.upper()] = None
            continue
        try:
            out[name.upper()] = check_ext(ext)
        except ValueError as exc:
            raise DriverError(f"dxf layer_map: layer {name!r}: {exc}") from None
    return out


class _LayerNames:
    """DXF layer name -> map layer extension (or None: skip)."""

    def __init__(self, layer_map, default_ext):
        self.map = parse_layer_map(layer_map)
        if default_ext is not None and default_ext not in ("", "-"):
            try:
                default_ext = check_ext(default_ext)
            except ValueError as exc:
                raise DriverError(f"dxf default_ext: {exc}") from None
        else:
            default_ext = None
        self.default = default_ext
        self._cache: dict[str, str | None] = {}

    def __call__(self, name: str) -> str | None:
        try:
            return self._cache[name]
        except KeyError:
            pass
        key = name.upper()
        if key in self.map:
            ext = self.map[key]
        elif _EXT_LIKE.fullmatch(name):
            ext = name.lower()
        else:
            ext = self.default
        self._cache[name] = ext
        return ext


# =========================================================================== write

_HEAD = "  0\n%s\n  5\n%X\n330\n%X\n100\nAcDbEntity\n  8\n%s\n"
_INSERT = (
    _HEAD
    + "100\nAcDbBlockReference\n 66\n1\n  2\n%s\n 10\n%r\n 20\n%r\n 30\n%r\n"
    + "".join(
        _HEAD.replace("%s", "ATTRIB", 1)
        + "100\nAcDbText\n 10\n%r\n 20\n%r\n 30\n%r\n 40\n%r\n  1\n%s\n"
        + f"100\nAcDbAttribute\n  2\n{tag}\n 70\n1\n"
        for tag in ("NUM", "CODE", "Z")
    )
    + _HEAD.replace("%s", "SEQEND", 1)
).replace("%s", "INSERT", 1)
_TEXT = (
    _HEAD.replace("%s", "TEXT", 1)
    + "100\nAcDbText\n 10\n%r\n 20\n%r\n 30\n%r\n 40\n%r\n  1\n%s\n100\nAcDbText\n"
    + f"1001\n{APPID}\n1000\n%s\n"
)
_POLYLINE = (
    _HEAD.replace("%s", "POLYLINE", 1)
    + "100\nAcDb3dPolyline\n 66\n1\n 10\n0.0\n 20\n0.0\n 30\n0.0\n 70\n%d\n"
)
_VERTEX = (
    _HEAD.replace("%s", "VERTEX", 1)
    + "100\nAcDbVertex\n100\nAcDb3dPolylineVertex\n 10\n%r\n 20\n%r\n 30\n%r\n 70\n32\n"
)
_VERTEX_OWN = _VERTEX + f"1001\n{APPID}\n1000\n%d %d %d %d %d %d %d\n"
_SEQEND = _HEAD.replace("%s", "SEQEND", 1)


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
    for ext in map_.layers:
        doc.layers.add(ext)
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
        # DXF readers decode "\U+XXXX" in strings: keep such texts exact in the XDATA
        xd = f"T {num} {text.encode('utf-8').hex()}" if "\\" in text else f"T {num}"
        out.append(_TEXT % (start + k, owner, layer.ext, x, y, z, text_m, text, xd))
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
    doc.rootdict[APPID]["HEADER"].reset(_header_tags(map_, entities))
    doc.entitydb.handles.reset(f"{h:X}")  # the handles above are taken
    buf = io.StringIO()
    doc.write(buf)
    skeleton = buf.getvalue()
    sec = skeleton.find(_ENTITIES_START)
    end = skeleton.find(_ENTITIES_END, sec)
    if sec < 0 or end != sec + len(_ENTITIES_START):  # pragma: no cover - ezdxf's layout
        raise FormatError("ezdxf wrote no empty ENTITIES section", path=path)
    data = b"".join([skeleton[:end].encode("utf-8"), entities, skeleton[end:].encode("utf-8")])
    if progress:
        progress(n + 1, n + 1)
    return data


def write(
    map_: MapFile, path, progress=None, library=None, dxfversion: str = "R2010"
) -> list[Path]:
    """Write a map as one DXF file, atomically; returns ``[path]``.

    See :func:`encode` for the options.
    """
    data = encode(map_, library=library, dxfversion=dxfversion, path=path, progress=progress)
    return atomic_write_many({Path(path): data})


# =========================================================================== read


def _sniff(data: bytes, path) -> None:
    """Raise FormatError unless ``data`` begins like a DXF file."""
    if not data.strip():
        raise FormatError("empty file, not a DXF file", path=path)
    if data.startswith(_BINARY_SENTINEL):
        if not data.rstrip(b"\0").endswith(b"EOF"):
            raise FormatError("truncated: the binary DXF file does not end with EOF", path=path)
        return
    if not _looks_like_dxf(data[:4096]):
        raise FormatError(
            "not a DXF file: it does not begin with group code 0 and SECTION", path=path
        )
    # ezdxf's recovery accepts a file cut short and returns what it could
    # read; a DXF file ends with the tags 0 and EOF, so refuse one without.
    tail = [ln.strip().upper() for ln in data[-256:].rstrip(b" \t\r\n\0\x1a").splitlines()]
    if tail[-2:] != [b"0", b"EOF"]:
        raise FormatError("truncated: the file does not end with the tags 0 and EOF", path=path)


def _looks_like_dxf(head: bytes) -> bool:
    if head.startswith(_BINARY_SENTINEL):
        return True
    text = head.decode("latin-1")
    if text.startswith("\xef\xbb\xbf"):
        text = text[3:]
    lines = [ln.strip() for ln in text.splitlines()]
    while lines and not lines[0]:
        lines.pop(0)
    i = 0
    while i + 1 < len(lines) and lines[i] == "999":  # comments
        i += 2
    return i + 1 < len(lines) and lines[i] == "0" and lines[i + 1].upper() == "SECTION"


def probe(path) -> bool:
    """True if ``path`` is a file that begins like a DXF file (ASCII or binary)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    return _looks_like_dxf(head)


def _load(data: bytes, path):
    """The ezdxf document, recovered and audited; problems are logged."""
    from ezdxf import recover
    from ezdxf.lldxf.const import DXFStructureError

    try:
        if data.startswith(_BINARY_SENTINEL):  # ezdxf's recovery reads ASCII DXF only
            doc, auditor = _load_binary(data)
        else:
            doc, auditor = recover.read(io.BytesIO(data))
    except DXFStructureError as exc:
        raise FormatError(f"not a readable DXF file: {exc}", path=path) from None
    except MemoryError:
        raise
    except Exception as exc:
        # ezdxf's repair can itself fail on odd files (seen: duplicate handles
        # in blocks); load the recovered sections without the audit.
        log.debug("%s: ezdxf recover failed", path, exc_info=True)
        return _load_unaudited(data, path, exc)
    for err in auditor.errors[:20]:
        log.warning("%s: DXF error left unrepaired: %s", path, err.message)
    if auditor.fixes:
        log.info("%s: ezdxf repaired %d problems", path, len(auditor.fixes))
        for fix in auditor.fixes[:20]:
            log.debug("%s: repaired: %s", path, fix.message)
    return doc


def _load_binary(data: bytes):
    from ezdxf.document import Drawing
    from ezdxf.lldxf.tagger import binary_tags_loader

    doc = Drawing.load(binary_tags_loader(data, errors="surrogateescape"))
    return doc, doc.audit()


def _section_tags(section_dict):
    """The tag stream of a recovered section dict (each section's entities, ENDSEC; EOF)."""
    from ezdxf.lldxf.types import DXFTag

    for entities in section_dict.values():
        for entity in entities:  # the first holds (0, SECTION), (2, name)
            yield from entity
        yield DXFTag(0, "ENDSEC")
    yield DXFTag(0, "EOF")


def _load_unaudited(data: bytes, path, first: Exception):
    """The document of ezdxf's recovered sections, loaded without the audit that failed.

    ``recover.read`` is ``Recover.run`` (the structure repairs) and the
    audit; the recovered sections go to :meth:`Drawing.from_tags` as a tag
    stream (no private ``Drawing._load_section_dict``).
    """
    from ezdxf import recover
    from ezdxf.document import Drawing

    try:
        if data.startswith(_BINARY_SENTINEL):
            raise first
        tool = recover.Recover.run(io.BytesIO(data))
        doc = Drawing.from_tags(_section_tags(tool.section_dict))
        doc.modelspace()
    except MemoryError:
        raise
    except Exception as exc:
        raise FormatError(
            f"not a readable DXF file: {type(first).__name__}: {first}", path=path
        ) from exc
    log.warning(
        "%s: ezdxf could not audit this file (%s: %s); read without repairs",
        path,
        type(first).__name__,
        first,
    )
    return doc


# --------------------------------------------------------------------------- the header record


def _header_from_tags(tags, path) -> dict:
    """The HEADER record's ``(code, value)`` tags, checked, as a dict."""
    raw: dict[str, list[str]] = {}
    key = None
    for code, value in tags:
        if code == 1:
            key = str(value)
            raw[key] = []
        elif code == 3 and key is not None:
            raw[key].append(str(value))
        else:
            raise FormatError(f"{APPID} header record: unexpected tag ({code}, {value!r})", path)
    out = {}
    for key, chunks in raw.items():
        out[key] = loads_json("".join(chunks), f"{APPID} header record: {key!r}", path=path)
    if out.get("format") != FORMAT_NAME:
        raise FormatError(f"{APPID} header record: format is not {FORMAT_NAME!r}", path=path)
    version = out.get("version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise FormatError(f"{APPID} header record: bad version {version!r}", path=path)
    if version > FORMAT_VERSION:
        raise FormatError(
            f"written by a newer apygis (DXF mapping version {version}; this one reads "
            f"{FORMAT_VERSION})",
            path=path,
        )
    expect = {
        "id": (str,),
        "scale": (int, type(None)),
        "crs": (str, type(None)),
        "notes": (str,),
        "layers": (list,),
    }
    for key, types in expect.items():
        if key not in out:
            raise FormatError(
                f"{APPID} header record: no {key!r} entry (expected {', '.join(expect)})",
                path=path,
            )
        v = out[key]
        if not isinstance(v, types) or isinstance(v, bool):
            raise FormatError(f"{APPID} header record: bad {key} {v!r}", path=path)
    try:
        check_map_id(out["id"])
        if not all(isinstance(e, str) for e in out["layers"]):
            raise ValueError("layer extensions are strings")
        out["layers"] = [check_ext(e) for e in out["layers"]]
    except ValueError as exc:
        raise FormatError(f"{APPID} header record: {exc}", path=path) from None
    ent = out.get("entities")
    ok = (
        isinstance(ent, list)
        and len(ent) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) for v in ent)
    )
    out["entities"] = tuple(ent) if ok else None
    return out


def _read_header(doc, path) -> dict | None:
    """The APYGIS header record of an ezdxf document, or None if it has none."""
    try:
        d = doc.rootdict.get(APPID)
    except Exception:  # a damaged objects section
        return None
    if d is None:
        return None
    rec = d.get("HEADER") if hasattr(d, "get") else None
    if rec is None or getattr(rec, "dxftype", lambda: "")() != "XRECORD":
        raise FormatError(f"the {APPID} dictionary has no HEADER record", path=path)
    return _header_from_tags([(t[0], t[1]) for t in rec.tags], path)


# --------------------------------------------------------------------------- records


class _Collect:
    """What the entities of one map layer give, before it becomes a Layer."""

    def __init__(self):
        self.sym: list[tuple] = []  # (num or None, x, y, z, code)
        self.txt: list[tuple] = []  # (num or None, x, y, z, text)
        self.own: list[tuple] = []  # (row, num, code, fwd, back, s1, s2, x, y, z)
        self.own_arr: list[tuple[np.ndarray, np.ndarray]] = []  # (ints (n, 7), xyz (n, 3))
        self.own_nums: set[int] = set()  # line-point numbers read so far from own lines
        self.lines: list[np.ndarray] = []
        self.closed: list[bool] = []


def _seed_layers(header: dict | None, names) -> dict[str, _Collect]:
    collected: dict[str, _Collect] = {}
    for ext in header["layers"] if header else []:
        ext = names(ext)
        if ext is not None:
            collected.setdefault(ext, _Collect())
    return collected


def _xyz(v, what) -> tuple[float, float, float]:
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    if not (abs(x) <= MAX_COORD and abs(y) <= MAX_COORD and abs(z) <= MAX_COORD):
        raise FormatError(
            f"{what}: coordinates ({x!r}, {y!r}, {z!r}) are not finite or exceed "
            f"{MAX_COORD:g} in magnitude"
        )
    return x, y, z


def _int_or_none(s) -> int | None:
    """An optionally signed integer of ASCII digits (no '²', no '1_0'), else None."""
    return ascii_int(str(s).strip(), signed=True)


def _clean_text(s: str, stats: Counter) -> str:
    s = _CTRL.sub(" ", s)
    if len(s) > TEXT_LEN:
        stats["truncated"] += 1
        if stats["truncated"] == 1:
            stats["first_truncated"] = s  # type: ignore[assignment]
        s = s[:TEXT_LEN]
    return s


def _symbol_code(code_text, block_name, default: int) -> int:
    """A symbol's code: attribute CODE, else block APY_SYM_NN, else the default."""
    code = _int_or_none(code_text) if code_text is not None else None
    if code is not None and 0 <= code <= MAX_CODE:
        return code
    m = _BLOCK_RE.match(str(block_name))
    return int(m.group(1)) if m else default


def _own_text(xd: str, raw_text: str, what: str) -> tuple[int, str] | None:
    """Number and text of a TEXT with apygis XDATA; None for a spot-height label."""
    parts = xd.split()
    if parts == ["H"]:
        return None
    num = _int_or_none(parts[1]) if len(parts) in (2, 3) and parts[0] == "T" else None
    if num is None:
        raise FormatError(f"{what}: bad {APPID} XDATA {xd!r}")
    if len(parts) == 3:
        try:
            return num, bytes.fromhex(parts[2]).decode("utf-8")
        except ValueError:
            raise FormatError(f"{what}: bad text in {APPID} XDATA") from None
    return num, raw_text


# --------------------------------------------------------------------------- through ezdxf


def _own_xdata(e) -> list | None:
    if not e.has_xdata(APPID):
        return None
    return [t[1] for t in e.get_xdata(APPID) if t[0] == 1000]


def _entity(e, c: _Collect, opts: dict, stats: Counter) -> None:
    kind = e.dxftype()
    what = f"{kind} #{e.dxf.get('handle', '?')}"
    if kind == "POINT":
        c.sym.append((None, *_xyz(e.dxf.location, what), opts["symbol_code"]))
    elif kind == "INSERT":
        _insert(e, c, opts, what)
    elif kind in ("TEXT", "MTEXT"):
        _text(e, c, stats, what)
    elif kind == "POLYLINE":
        _polyline(e, c, stats, what)
    elif kind == "LINE":
        pts = [_xyz(e.dxf.start, what), _xyz(e.dxf.end, what)]
        c.lines.append(np.array(pts))
        c.closed.append(False)
    elif kind == "LWPOLYLINE":
        pts = [_xyz(v, what) for v in e.vertices_in_wcs()]
        if any(b for *_, b in e.get_points("xyb")):
            stats["bulges"] += 1
        if pts:
            c.lines.append(np.array(pts))
            c.closed.append(bool(e.closed))
    elif kind in _CURVE_TYPES:
        pts = [_xyz(v, what) for v in e.flattening(opts["sagitta_m"])]
        if kind == "SPLINE":
            closed = bool(e.closed)
        elif kind == "ELLIPSE":
            span = (e.dxf.end_param - e.dxf.start_param) % (2 * math.pi)
            closed = math.isclose(span, 0.0, abs_tol=1e-9)
        else:
            closed = kind == "CIRCLE"
        if pts:
            c.lines.append(np.array(pts))
            c.closed.append(closed)
    else:
        stats[f"skip:{kind}"] += 1


def _insert(e, c: _Collect, opts: dict, what: str) -> None:
    attribs = {}
    for a in e.attribs:
        attribs.setdefault(str(a.dxf.get("tag", "")).upper(), a.dxf.get("text", ""))
    code = _symbol_code(attribs.get("CODE"), e.dxf.get("name", ""), opts["symbol_code"])
    num = _int_or_none(attribs["NUM"]) if "NUM" in attribs else None
    if e.mcount > 1:
        for k, v in enumerate(e.multi_insert()):
            pos = _xyz(v.ocs().to_wcs(v.dxf.insert), what)
            c.sym.append((num if k == 0 else None, *pos, code))
    else:
        c.sym.append((num, *_xyz(e.ocs().to_wcs(e.dxf.insert), what), code))


def _text(e, c: _Collect, stats: Counter, what: str) -> None:
    xd = _own_xdata(e) if e.dxftype() == "TEXT" else None
    if xd is not None:
        if len(xd) != 1:
            raise FormatError(f"{what}: bad {APPID} XDATA {xd!r}")
        own = _own_text(xd[0], str(e.dxf.get("text", "")), what)
        if own is not None:
            check_str(own[1], f"{what}: the text")
            pos = _xyz(e.ocs().to_wcs(e.dxf.insert), what)
            c.txt.append((own[0], *pos, _clean_text(own[1], stats)))
        return
    if e.dxftype() == "TEXT":
        text = e.plain_text()
        pos = _xyz(e.ocs().to_wcs(e.dxf.insert), what)
    else:  # MTEXT: its insertion point is in WCS
        text = " ".join(ln.strip() for ln in e.plain_text(split=True) if ln.strip())
        pos = _xyz(e.dxf.insert, what)
    check_str(text, f"{what}: the text")
    c.txt.append((None, *pos, _clean_text(text, stats)))


def _polyline(e, c: _Collect, stats: Counter, what: str) -> None:
    if e.is_poly_face_mesh or e.is_polygon_mesh:
        stats["skip:POLYLINE mesh"] += 1
        return
    verts = list(e.vertices)
    pts = list(e.points_in_wcs()) if e.is_2d_polyline else [v.dxf.location for v in verts]
    if len(pts) != len(verts):  # pragma: no cover - ezdxf yields one point per vertex
        raise FormatError(f"{what}: vertices and points differ")
    xds = [_own_xdata(v) for v in verts]
    if all(xd is None for xd in xds):
        if pts:
            c.lines.append(np.array([_xyz(p, what) for p in pts]))
            c.closed.append(bool(e.is_closed))
        return
    own = []
    for i, (v, p, xd) in enumerate(zip(verts, pts, xds, strict=True)):
        vwhat = f"VERTEX #{v.dxf.get('handle', '?')} of {what}"
        if xd is None:
            if i in (0, len(verts) - 1):
                continue  # a junction's vertex, drawn so that a branch touches it
            raise FormatError(f"{vwhat}: a vertex without {APPID} XDATA inside an apygis line")
        ints = [_int_or_none(s) for s in xd[0].split()] if len(xd) == 1 else []
        if len(ints) != 7 or None in ints:
            raise FormatError(f"{vwhat}: bad {APPID} XDATA {xd!r}")
        num, code, fwd, back, s1, s2, row = ints
        if not 0 <= code <= MAX_CODE:
            raise FormatError(f"{vwhat}: line code {code} outside 00-{MAX_CODE}")
        own.append((row, num, code, fwd, back, s1, s2, *_xyz(p, vwhat)))
    nums = {o[1] for o in own}
    if len(nums) < len(own) or nums & c.own_nums:
        # a copy made in CAD, XDATA and all: its numbers are taken, so it is new geometry
        stats["copied lines"] += 1
        c.lines.append(np.array([_xyz(p, what) for p in pts]))
        c.closed.append(bool(e.is_closed))
        return
    c.own_nums |= nums
    c.own += own


def _slow_read(data: bytes, path, names, opts: dict, stats: Counter, progress):
    """Header and records of any DXF, through ezdxf's document model."""
    doc = _load(data, path)
    header = _read_header(doc, path)
    collected = _seed_layers(header, names)
    try:
        entities = list(doc.modelspace())
    except MemoryError:
        raise
    except Exception as exc:
        raise FormatError(f"cannot read the model space: {exc}", path=path) from None
    total = len(entities)
    for i, e in enumerate(entities):
        try:
            ext = names(str(e.dxf.get("layer", "0")))
            if ext is None:
                stats["skip:layer"] += 1
                continue
            _entity(e, collected.setdefault(ext, _Collect()), opts, stats)
        except ApygisError as exc:
            if isinstance(exc, FormatError) and exc.path is None:
                raise FormatError(exc.reason, path=path, record=exc.record) from None
            raise
        except MemoryError:
            raise
        except Exception as exc:
            handle = getattr(getattr(e, "dxf", None), "handle", "?")
            raise FormatError(
                f"{type(exc).__name__}: {exc}", path=path, record=f"{e.dxftype()} #{handle}"
            ) from None
        if progress and (i % 1000 == 999 or i == total - 1):
            progress(i + 1, total)
    return header, collected


# --------------------------------------------------------------------------- fast path


def _template_re(template: str) -> re.Pattern:
    """A regular expression matching what a writer template formats, fields captured."""
    pat = re.escape(template)
    pat = pat.replace(re.escape("%d %d %d %d %d %d %d"), r"(-?[0-9]+(?: -?[0-9]+){6})")
    pat = pat.replace("%X", "[0-9A-F]+").replace("%d", "(-?[0-9]+)")
    pat = pat.replace("%r", r"([^\n]*)").replace("%s", r"([^\n]*)")
    return re.compile(pat)


_FAST_VERTEX, _FAST_INSERT, _FAST_TEXT = 0, 4, 5
_FAST_RES = [_template_re(t) for t in (_VERTEX_OWN, _VERTEX, _POLYLINE, _SEQEND, _INSERT, _TEXT)]
_FAST_XREC = b"\n100\nAcDbXrecord\n280\n1\n"


def _fast_header(data: bytes, path) -> dict | None:
    k = data.find(_FAST_XREC + b'  1\nformat\n  3\n"' + FORMAT_NAME.encode() + b'"\n')
    if k < 0:
        return None
    start = k + len(_FAST_XREC)
    end = data.find(b"\n  0\n", start)
    lines = data[start:end].decode("utf-8").split("\n")
    if end < 0 or len(lines) % 2:
        return None
    codes = [ascii_int(lines[i].strip()) for i in range(0, len(lines), 2)]  # no '٣' as 3
    if None in codes:
        return None
    tags = [(c, lines[2 * k + 1]) for k, c in enumerate(codes)]
    return _header_from_tags(tags, path)


def _fast_read(data: bytes, path, names, opts: dict, stats: Counter):
    """Header and records of an apygis DXF untouched since it was written, or None.

    The header record holds the size and CRC-32 of the ENTITIES section as
    written; when they match, the section is apygis's own text and is parsed
    by the writer's templates, without ezdxf (100x faster). Anything
    unexpected returns None: the caller reads the file through ezdxf.
    """
    try:
        header = _fast_header(data, path)
    except (ValueError, UnicodeDecodeError):  # FormatError too: ezdxf's path reports it
        return None
    if header is None or header["entities"] is None:
        return None
    size, crc = header["entities"]
    a = data.find(_ENTITIES_START.encode())
    a = a + len(_ENTITIES_START) if a >= 0 else -1
    if a < 0 or data[a + size : a + size + len(_ENTITIES_END)] != _ENTITIES_END.encode():
        return None
    section = data[a : a + size]
    if zlib.crc32(section) != crc:
        return None
    try:
        return header, _fast_entities(section.decode("utf-8"), header, names, opts, stats)
    except (ValueError, OverflowError, UnicodeDecodeError, IndexError) as exc:
        log.debug("%s: fast path failed (%s); reading through ezdxf", path, exc)
        return None


def _fast_entities(text: str, header: dict, names, opts: dict, stats: Counter):
    verts: list[tuple] = []
    inserts: list[tuple] = []
    texts: list[tuple] = []
    keep = {_FAST_VERTEX: verts.append, _FAST_INSERT: inserts.append, _FAST_TEXT: texts.append}
    pos, n = 0, len(text)
    while pos < n:
        kind, m = -1, None
        for k, rx in enumerate(_FAST_RES):
            m = rx.match(text, pos)
            if m is not None:
                kind = k
                break
        if m is None:
            raise ValueError(f"no entity template matches at {pos}")
        if kind in keep:
            keep[kind](m.groups())
        pos = m.end()
    collected = _seed_layers(header, names)

    def target(layer_name: str) -> _Collect | None:
        ext = names(layer_name)
        return None if ext is None else collected.setdefault(ext, _Collect())

    for g in inserts:  # layer, block, x, y, z, 5 + 6 per ATTRIB (NUM, CODE, Z), layer
        c = target(g[0])
        if c is not None:
            code = _symbol_code(g[16], g[1], opts["symbol_code"])
            c.sym.append((_int_or_none(g[10]), *_xyz(g[2:5], "INSERT"), code))
    for layer_name, x, y, z, _h, raw, xd in texts:
        c = target(layer_name)
        own = _own_text(xd, raw, "TEXT")
        if c is not None and own is not None:
            c.txt.append((own[0], *_xyz((x, y, z), "TEXT"), _clean_text(own[1], stats)))
    if verts:
        layers, xs, ys, zs, ints = zip(*verts, strict=True)
        del verts
        xyz = np.column_stack(
            [np.array(xs, dtype=float), np.array(ys, dtype=float), np.array(zs, dtype=float)]
        )
        vals = np.array(" ".join(ints).split(), dtype=np.int64).reshape(-1, 7)
        if (
            not (np.abs(xyz) <= MAX_COORD).all()
            or ((vals[:, 1] < 0) | (vals[:, 1] > MAX_CODE)).any()
        ):
            raise ValueError("non-finite coordinates or line codes outside 0-99")
        # XDATA order: num code fwd back side1 side2 row -> row first, as _Collect.own
        vals = vals[:, [6, 0, 1, 2, 3, 4, 5]]
        uniq, inv = np.unique(np.array(layers), return_inverse=True)
        for k, name in enumerate(uniq.tolist()):
            c = target(name)
            if c is not None:
                sel = inv == k
                c.own_arr.append((vals[sel], xyz[sel]))
    return collected


# --------------------------------------------------------------------------- layers


def _numbers(given: list, path, what: str) -> np.ndarray:
    """Point numbers: the given ones, new ones by the model's numbering rule for the rest."""
    missing = np.array([g is None for g in given], dtype=bool)
    try:
        known = np.array([g for g in given if g is not None], dtype=np.int64)
    except OverflowError:
        raise FormatError(f"a {what} number does not fit 64 bits", path=path) from None
    nums = np.full(len(given), -1, dtype=np.int64)
    nums[~missing] = known
    # a later copy of a number in use (an entity copied in CAD with its XDATA) or a
    # negative number is numbered anew, and the log says how many
    order = np.argsort(nums, kind="stable")
    repeat = np.zeros(len(nums), dtype=bool)
    repeat[order[1:]] = nums[order][1:] == nums[order][:-1]
    renumber = ~missing & (repeat | (nums < 0))
    if renumber.any():
        log.warning(
            "%s: %d %s number(s) repeated or negative (e.g. %d): numbered anew",
            path,
            int(renumber.sum()),
            what,
            int(nums[renumber][0]),
        )
    new = missing | renumber
    nums[new] = next_numbers(nums[~new], int(new.sum()))
    return nums


def _make_layer(ext: str, c: _Collect, opts: dict, path) -> Layer:
    layer = Layer(ext)
    try:
        if c.sym:
            arr = np.array([s[1:4] for s in c.sym], dtype=float)
            nums = _numbers([s[0] for s in c.sym], path, "symbol")
            layer.add_symbols(arr, np.array([s[4] for s in c.sym], np.int64), nums)
        if c.txt:
            arr = np.array([t[1:4] for t in c.txt], dtype=float)
            nums = _numbers([t[0] for t in c.txt], path, "text")
            layer.add_texts(arr, [t[4] for t in c.txt], nums)
        chunks = list(c.own_arr)
        if c.own:
            try:
                ints = np.array([o[:7] for o in c.own], dtype=np.int64)
            except OverflowError:
                raise FormatError("a line point number does not fit 64 bits", path=path) from None
            chunks.append((ints, np.array([o[7:] for o in c.own], dtype=float)))
        if chunks:
            ints = np.concatenate([ch[0] for ch in chunks])
            xyz = np.concatenate([ch[1] for ch in chunks])
            order = np.argsort(ints[:, 0], kind="stable")  # table order, from the rows
            ints, xyz = ints[order], xyz[order]
            lp = np.zeros(len(ints), LINE_DTYPE)
            for j, name in enumerate(("num", "code", "fwd", "back", "side1", "side2"), start=1):
                lp[name] = ints[:, j]
            lp["x"], lp["y"], lp["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
            layer.add_line_points(lp)
        if c.lines:
            coords, offsets = to_csr(c.lines)
            rep = layer.add_polylines(
                coords,
                offsets,
                opts["line_code"],
                np.array(c.closed, dtype=bool),
                snap_m=opts["tolerance_m"],
                crs=opts.get("crs"),
                join=bool(opts["topology"]),
            )
            say = log.warning if rep.refused or rep.duplicates_removed or rep.empty else log.info
            say("%s: layer %s: lines rebuilt: %s", path, ext, rep.message())
    except (RecordError, TopologyError) as exc:
        msg = str(exc) if str(exc).startswith(f"layer {ext}:") else f"layer {ext}: {exc}"
        raise FormatError(msg, path=path) from None
    return layer


def _map_id(path) -> str:
    stem = Path(path).stem
    mid = re.sub(r"[^A-Za-z0-9_-]", "_", stem)[:32]
    return mid or "DXF"


def read(
    path,
    progress=None,
    layer_map=None,
    default_ext: str | None = "x",
    symbol_code: int = 0,
    line_code: int = 0,
    tolerance_m: float = 0.005,
    topology: bool = True,
    sagitta_m: float = 0.01,
    crs=None,
    fast: bool = True,
) -> MapFile:
    """Read a DXF file as a map.

    Parameters
    ----------
    path : str or os.PathLike
    progress : callable, optional
        ``progress(done, total)`` over the model-space entities.
    layer_map : dict or str, optional
        DXF layer name -> layer extension (see :func:`parse_layer_map`);
        ``"ROADS=r,WATER=h,0=-"`` in the CLI form.
    default_ext : str or None
        The layer for entities of DXF layers that neither ``layer_map`` names
        nor are named like an extension (1-3 letters); None skips them.
    symbol_code : int
        Code of symbols from POINTs and from INSERTs that carry no code
        (attribute ``CODE``, block name ``APY_SYM_NN``). 0 is the spot height.
    line_code : int
        Code of lines read from plain DXF geometry.
    tolerance_m : float
        Distance within which line ends join other lines (see
        :meth:`apygis.model.Layer.add_polylines`).
    topology : bool
        Rebuild junctions and merge lines whose ends meet (default); with
        False every DXF line becomes one chain as it is.
    sagitta_m : float
        Largest distance of a chord from the curve when ARC, CIRCLE,
        ELLIPSE and SPLINE are flattened to line points.
    crs : optional
        The CRS of a DXF that apygis did not write (DXF has none), or one
        that overrides the header's.
    fast : bool
        Read a DXF that apygis wrote and nobody changed since (the header
        record's checksum of the entities matches) by apygis's own parser,
        not through ezdxf (the same result, 100 times faster). False always
        reads through ezdxf.

    Returns
    -------
    MapFile

    Raises
    ------
    FormatError
        The file is missing, not DXF, or damaged beyond repair; or apygis's
        own records in it (XDATA, header record) are malformed.
    DriverError
        An option is invalid.
    """
    for name, value in (("symbol_code", symbol_code), ("line_code", line_code)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise DriverError(f"dxf {name}: an integer 0-{MAX_CODE}, not {value!r}")
        if not 0 <= value <= MAX_CODE:
            raise DriverError(f"dxf {name}: {value} is outside 0-{MAX_CODE}")
    try:
        tolerance_m = float(tolerance_m)
        sagitta_m = float(sagitta_m)
    except (TypeError, ValueError):
        raise DriverError("dxf tolerance_m and sagitta_m are numbers") from None
    if not sagitta_m > 0 or not tolerance_m >= 0:
        raise DriverError("dxf: sagitta_m must be > 0 and tolerance_m >= 0")
    names = _LayerNames(layer_map, default_ext)
    opts = {
        "symbol_code": int(symbol_code),
        "line_code": int(line_code),
        "tolerance_m": tolerance_m,
        "topology": bool(topology),
        "sagitta_m": sagitta_m,
    }
    data = read_bytes(path)
    _sniff(data, path)
    stats: Counter = Counter()
    got = _fast_read(data, path, names, opts, stats) if fast else None
    if got is None:
        stats.clear()
        header, collected = _slow_read(data, path, names, opts, stats, progress)
    else:
        header, collected = got
        log.debug("%s: read by apygis's own parser (the entities are as written)", path)
        if progress:
            progress(1, 1)
    del data
    try:
        if header is not None:
            m = MapFile(header["id"], header["scale"], header["crs"], header["notes"])
        else:
            m = MapFile(_map_id(path))
        if crs is not None:
            m.crs = crs
    except ValueError as exc:  # RecordError
        raise FormatError(f"map header: {exc}", path=path) from None
    _report(path, stats)
    opts["crs"] = m.crs  # tolerance_m is metres: the rebuild converts it to the CRS's units
    for ext, c in collected.items():
        m.add_layer(_make_layer(ext, c, opts, path))
    return m


def _report(path, stats: Counter) -> None:
    skipped = {k[5:]: v for k, v in stats.items() if k.startswith("skip:")}
    if skipped:
        log.info(
            "%s: entities not read: %s",
            path,
            ", ".join(f"{k} x{v}" for k, v in sorted(skipped.items())),
        )
    if stats["truncated"]:
        log.warning(
            "%s: %d texts longer than %d characters were truncated (first: %r)",
            path,
            stats["truncated"],
            TEXT_LEN,
            stats.get("first_truncated"),
        )
    if stats["copied lines"]:
        log.warning(
            "%s: %d apygis line(s) repeat point numbers read before (copied in CAD): "
            "read as new lines, their topology rebuilt",
            path,
            stats["copied lines"],
        )
    if stats["bulges"]:
        log.info(
            "%s: %d LWPOLYLINEs have arcs (bulges); read as their vertices only",
            path,
            stats["bulges"],
        )


DRIVER = Driver(
    name="dxf",
    description="AutoCAD DXF R2010: layers, 3-D polylines, symbol blocks, texts; reads any DXF "
    "(docs/formats/dxf.md)",
    extensions=("dxf",),
    reader=read,
    writer=write,
    probe=probe,
)
