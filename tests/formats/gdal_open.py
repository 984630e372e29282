"""Open files with the system's GDAL (Debian 12: GDAL 3.6, what QGIS LTR builds use) and
report every warning or error it gives, and what it reads.

Run by the system Python (``/usr/bin/python3 gdal_open.py FILE...``) from
``tests/formats/test_qgis.py``; it imports nothing of apygis. Prints one JSON
object: GDAL's version, and per file the messages GDAL emitted while opening it
and reading every feature of every layer, the layers with their feature
counts and CRS, and the texts of a ``Text`` field (DXF).
"""

from __future__ import annotations

import json
import sys

from osgeo import gdal, ogr

gdal.UseExceptions()


def main(paths: list[str]) -> None:
    out: dict = {"gdal": gdal.__version__}
    for path in paths:
        messages: list[str] = []

        def handler(level, code, msg, messages=messages):
            if level >= gdal.CE_Warning:
                messages.append(f"{level}:{code}:{msg}")

        gdal.PushErrorHandler(handler)
        try:
            ds = gdal.OpenEx(path, gdal.OF_VECTOR)
            layers = {}
            texts = []
            for i in range(ds.GetLayerCount()):
                lay = ds.GetLayer(i)
                srs = lay.GetSpatialRef()
                n = 0
                defn = lay.GetLayerDefn()
                has_text = defn.GetFieldIndex("Text") >= 0
                for f in lay:
                    n += 1
                    if has_text and f.GetField("Text"):
                        texts.append(f.GetField("Text"))
                layers[lay.GetName()] = {
                    "features": n,
                    "crs": srs.GetAuthorityCode(None) if srs is not None else None,
                    "geometry": ogr.GeometryTypeToName(lay.GetGeomType()),
                }
            ds = None
        finally:
            gdal.PopErrorHandler()
        out[path] = {"messages": messages, "layers": layers, "texts": texts}
    print(json.dumps(out, ensure_ascii=False))


if __name__ == "__main__":
    main(sys.argv[1:])
