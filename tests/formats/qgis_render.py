"""Open a GeoPackage in QGIS (Debian's python3-qgis, offscreen) and render it to a PNG.

Run by the system Python (``/usr/bin/python3 qgis_render.py GPKG PNG``) from
``tests/formats/test_qgis.py``; it imports nothing of apygis. Every spatial
layer is loaded as QGIS loads it (its default style from the GeoPackage's
``layer_styles``), all are rendered together to the PNG, and one JSON object
is printed: per layer the feature count, CRS, description (abstract),
renderer type, its categories or symbol colours and whether labels are on;
and the PNG's size and colours counted.
"""

from __future__ import annotations

import json
import os
import sys

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from qgis.core import (
    QgsApplication,
    QgsMapRendererParallelJob,
    QgsMapSettings,
    QgsRectangle,
    QgsVectorLayer,
)
from qgis.PyQt.QtCore import QSize
from qgis.PyQt.QtGui import QColor, QImage


def main(gpkg: str, png: str) -> None:
    app = QgsApplication([], False)
    app.initQgis()
    probe = QgsVectorLayer(gpkg, "probe", "ogr")
    names = [s.split("!!::!!")[1] for s in probe.dataProvider().subLayers()]
    report: dict = {}
    layers = []
    extent = QgsRectangle()
    for name in names:
        lay = QgsVectorLayer(f"{gpkg}|layername={name}", name, "ogr")
        if not lay.isValid() or not lay.isSpatial():
            continue
        r = lay.renderer()
        info = {
            "features": lay.featureCount(),
            "crs": lay.crs().authid(),
            "abstract": lay.metadata().abstract(),
            "renderer": r.type() if r else None,
            "labels": bool(lay.labelsEnabled()),
        }
        if r is not None and r.type() == "categorizedSymbol":
            info["attr"] = r.classAttribute()
            info["categories"] = {
                str(c.value()): {
                    "label": c.label(),
                    "layer": c.symbol().symbolLayer(0).layerType(),
                    "svg": c.symbol().symbolLayer(0).properties().get("name", "")[:7],
                }
                for c in r.categories()
            }
        elif r is not None and r.type() == "singleSymbol":
            sym = r.symbol()
            sl = sym.symbolLayer(0)
            props = sl.properties()
            colour = props.get("line_color") or props.get("outline_color") or props.get("color")
            info["symbol"] = {"layer": sl.layerType(), "colour": colour}
        report[name] = info
        layers.append(lay)
        if lay.featureCount():
            extent.combineExtentWith(lay.extent())
    settings = QgsMapSettings()
    settings.setLayers(list(reversed(layers)))
    settings.setDestinationCrs(layers[0].crs())
    extent.scale(1.05)
    settings.setExtent(extent)
    settings.setOutputSize(QSize(1200, 1200))
    settings.setBackgroundColor(QColor(255, 255, 255))
    job = QgsMapRendererParallelJob(settings)
    job.start()
    job.waitForFinished()
    img = job.renderedImage()
    img.save(png, "PNG")
    img = QImage(png)
    counts = {"blue": 0, "brown": 0, "dark": 0}
    for y in range(0, img.height(), 2):
        for x in range(0, img.width(), 2):
            c = QColor(img.pixel(x, y))
            r, g, b = c.red(), c.green(), c.blue()
            if b > 150 and r < 60 and 80 < g < 150:
                counts["blue"] += 1
            elif 120 < r < 180 and 60 < g < 110 and b < 50:
                counts["brown"] += 1
            elif r < 60 and g < 60 and b < 60:
                counts["dark"] += 1
    report["png"] = {"width": img.width(), "height": img.height(), "pixels": counts}
    print(json.dumps(report), flush=True)
    os._exit(0)  # QGIS's own teardown (exitQgis) can crash in a headless process


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
