"""The GeoPackage's layer descriptions and QGIS styles, as stored (QGIS itself opens them
in test_qgis.py); the pens of the styles are the plot's default pens."""

from __future__ import annotations

import base64
import sqlite3
import xml.etree.ElementTree as ET

import numpy as np

import apygis
from apygis.formats.ogr import styles
from apygis.model.symbols import default_library
from apygis.plot.plotdef import PlotterDef


def test_descriptions_and_styles_are_stored(sample_map, tmp_path):
    path = tmp_path / "s.gpkg"
    apygis.write(sample_map, path)
    con = sqlite3.connect(path)
    desc = dict(con.execute("SELECT table_name, description FROM gpkg_contents"))
    assert (
        desc["h_lines"]
        == "apygis map ZH1091, layer h: open lines (line code, point numbers of the vertices)"
    )
    assert desc["apygis_map"].startswith("apygis map ZH1091: header")
    rows = con.execute(
        "SELECT f_table_name, f_geometry_column, useAsDefault, styleQML FROM layer_styles"
    ).fetchall()
    spatial = {t for t in desc if t not in ("apygis_map", "layer_styles")}
    assert {r[0] for r in rows} == spatial
    for _, column, default, qml in rows:
        assert column == "geom"
        assert default == 1
        ET.fromstring(qml.split(">", 1)[1])  # well-formed after the DOCTYPE
    assert apygis.read(path) == sample_map  # the extra table changes nothing for apygis
    plain = tmp_path / "plain.gpkg"
    apygis.write(sample_map, plain, styles=False)
    names = {r[0] for r in sqlite3.connect(plain).execute("SELECT table_name FROM gpkg_contents")}
    assert "layer_styles" not in names


def test_symbols_are_drawn_from_the_library_bitmaps():
    lib = default_library()
    qml = styles.qml("symbols", "r", [6, 0], lib)
    root = ET.fromstring(qml.split(">", 1)[1])
    svgs = {}
    for cat in root.iter("category"):
        sym = root.find(f".//symbol[@name='{cat.get('symbol')}']")
        name = next(p.get("v") for p in sym.iter("prop") if p.get("k") == "name")
        svgs[int(cat.get("value"))] = base64.b64decode(name.removeprefix("base64:")).decode()
    svg = ET.fromstring(svgs[6])
    cells = {
        (int(r.get("y")), int(r.get("x"))) for r in svg.iter("{http://www.w3.org/2000/svg}rect")
    }
    assert cells == {tuple(map(int, rc)) for rc in np.argwhere(lib[6].bitmap)}
    assert len(cells) == lib[6].painted


def test_pens_are_the_plots_default_pens():
    pdef = PlotterDef.default()
    for ext in ("h", "e", "r", "c"):
        pen = pdef.pens[pdef.pen_for(ext, "lines", 1)]
        assert styles.pen_of(ext) == (pen.colour, pen.width_mm), ext
