"""ARC/INFO interchange (E00): a map as one line coverage with INFO tables.

The mapping is specified in ``docs/formats/e00.md``. In short, writing
``out/ZH1091.e00`` creates one uncompressed, double-precision E00 file
holding coverage ``ZH1091``:

* ``ARC``: one arc per line (chain) of every layer, as
  :func:`apygis.model.polylines.export_lines` gives them (a branch starts or ends
  at its junction's vertex; a closed line repeats its first vertex).
* ``LAB``: one label point per symbol and per text.
* ``TOL``: the ten tolerances, unverified. ``PRJ``: the map's CRS as ESRI WKT.
* INFO tables (``IFO``): ``ZH1091.AAT`` (per arc: the standard items, then
  ``LAYER``, ``CODE``, ``CLOSED``), ``ZH1091.PAT`` (per label: the standard
  items, then ``LAYER``, ``KIND``, ``NUM``, ``CODE``, ``HEIGHT``,
  ``TXTLEN``, ``TEXT``), ``ZH1091.LINEPT`` (per line point, in table
  order: ``ARC#``, ``VERTEX``, ``LAYER``, ``NUM``, ``HEIGHT``, ``CODE`` and
  the references ``FWD``, ``BACK``, ``SIDE1``, ``SIDE2``) and
  ``ZH1091.APYMAP`` (map ID, scale, CRS, notes, layer list).

Reading an E00 file written this way gives the map back record for record:
point numbers, references, heights, codes and texts come from the INFO
tables, X and Y from the arcs and labels. Any other vector E00 file
(compressed or not, single or double precision; line, point and polygon
coverages) is read as GDAL reads it: arcs, polygons and label points as the
map layers ``arc``, ``pal`` and ``lab`` (:mod:`~apygis.formats.e00.foreign`),
the PRJ section translated as GDAL translates it. Grid E00 files (a ``GRD``
section) are refused.

GDAL's AVCE00 driver reads the files written here as layers ``ARC`` (the AAT
items joined) and ``LAB`` (the PAT items joined).

The package: :mod:`~apygis.formats.e00.write` (a map to E00 text),
:mod:`~apygis.formats.e00.compress` (the decompressor of ``EXP  1`` files),
:mod:`~apygis.formats.e00.parse` (E00 sections to plain arrays and INFO tables),
:mod:`~apygis.formats.e00.mapping` (those to the model: :func:`read`) and
:mod:`~apygis.formats.e00.foreign` (coverages apygis did not write); ``_common``
holds the constants they share.
"""

from __future__ import annotations

from apygis.formats import READ_OPTIONS, Driver, Option
from apygis.formats.e00._common import _TERM as _TERM
from apygis.formats.e00._common import DEFAULT_LAYER
from apygis.formats.e00._common import DOUBLE as DOUBLE
from apygis.formats.e00._common import SINGLE as SINGLE
from apygis.formats.e00.compress import decompress
from apygis.formats.e00.mapping import _arc_arrays as _arc_arrays
from apygis.formats.e00.mapping import read
from apygis.formats.e00.parse import decode
from apygis.formats.e00.write import encode, outputs, write

__all__ = [
    "DEFAULT_LAYER",
    "DRIVER",
    "decode",
    "decompress",
    "encode",
    "outputs",
    "probe",
    "read",
    "write",
]


def probe(path) -> bool:
    """True for a file that begins with an E00 ``EXP`` line."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return False
    return head[:4].upper() == b"EXP " and head[4:7].strip() in (b"0", b"1")


DRIVER = Driver(
    name="e00",
    description="ARC/INFO interchange file: writes a line coverage with INFO tables, reads "
    "line, point and polygon coverages (docs/formats/e00.md)",
    extensions=("e00",),
    reader=read,
    writer=write,
    probe=probe,
    outputs=outputs,
    stream=True,
    options=(
        *(
            READ_OPTIONS[k]
            for k in (
                "layers",
                "layer_map",
                "tolerance_m",
                "crs",
                "code_field",
                "default_code",
                "point_code",
            )
        ),
        Option("recover", "r", "bool", "read a damaged file as far as it goes"),
        Option("precision", "w", "int", "2 single, 3 double precision", low=2, high=3),
    ),
)
