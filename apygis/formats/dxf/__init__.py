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
``INSERT`` become symbols (the visible attributes of foreign blocks texts),
``LINE``, ``LWPOLYLINE``, ``POLYLINE`` (2-D in their object coordinate
system, or 3-D; bulges flattened on the true arcs), ``ARC``, ``CIRCLE``,
``ELLIPSE``, ``SPLINE`` (flattened within ``chord_m``), ``LEADER``, the
boundaries of ``HATCH`` and the outlines of ``SOLID``, ``TRACE`` and
``3DFACE`` become lines, ``TEXT`` and ``MTEXT`` texts, and ``DIMENSION``,
``MULTILEADER`` and ``MLINE`` give their lines and texts. Whatever else is
skipped is counted and reported per kind. Each DXF layer becomes a map layer
(``layer_map`` or a name derived from it: :mod:`apygis.formats._layers`);
lines without apygis XDATA get their topology rebuilt by the model's one
rebuild, :meth:`apygis.model.Layer.add_polylines` (its report logged). A file that
apygis wrote and nobody changed since (the header record holds the size and
CRC-32 of the entities section) is parsed by the writer's own templates
instead of ezdxf: the same records, a hundred times faster.

The package: :mod:`~apygis.formats.dxf.templates` (symbol blocks, the text of
each entity), :mod:`~apygis.formats.dxf.write`, and :mod:`~apygis.formats.dxf.read`
(:func:`probe`, :func:`read`, the map's layers) over
:mod:`~apygis.formats.dxf.read_fast` and :mod:`~apygis.formats.dxf.read_ezdxf`, which
share ``_collect`` (the layer map option, the header record, the records per layer);
``_common`` holds the constants.

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
{'ROADS': 'r', 'WATER': 'h', 'Defpoints': None}
"""

from __future__ import annotations

from apygis.formats import READ_OPTIONS, Driver, Option
from apygis.formats._layers import parse_layer_map
from apygis.formats.dxf._collect import _int_or_none as _int_or_none
from apygis.formats.dxf._collect import _symbol_code as _symbol_code
from apygis.formats.dxf._common import (
    APPID,
    BLOCK_PREFIX,
    DEFAULT_SCALE,
    FORMAT_NAME,
    FORMAT_VERSION,
    SYMBOL_SIZE_MM,
    TEXT_HEIGHT_MM,
)
from apygis.formats.dxf._common import DXF_VERSIONS as DXF_VERSIONS
from apygis.formats.dxf.read import probe, read
from apygis.formats.dxf.read_fast import _fast_header as _fast_header
from apygis.formats.dxf.templates import block_rects
from apygis.formats.dxf.write import drawing_units as drawing_units
from apygis.formats.dxf.write import encode, write

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


DRIVER = Driver(
    name="dxf",
    description="AutoCAD DXF R2010: layers, 3-D polylines, symbol blocks, texts; reads any DXF "
    "(docs/formats/dxf.md)",
    extensions=("dxf",),
    reader=read,
    writer=write,
    probe=probe,
    stream=True,
    options=(
        *(
            READ_OPTIONS[k]
            for k in ("layers", "layer_map", "tolerance_m", "crs", "default_code", "point_code")
        ),
        Option(
            "chord_m",
            "r",
            "float",
            "chord tolerance of flattened curves, drawing units (default 0.1 mm x scale / 4)",
            low=1e-9,
        ),
        Option("topology", "r", "bool", "rebuild junctions and merge lines whose ends meet"),
        Option("fast", "r", "bool", "read an untouched apygis DXF by apygis's own parser"),
        Option("version", "w", "choice", "DXF version written", choices=tuple(DXF_VERSIONS)),
    ),
)
