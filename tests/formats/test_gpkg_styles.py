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


def _many_layers(n: int = 20) -> apygis.MapFile:
    """A map of ``n`` layers with every kind of record: 5 tables each, over 64 in all."""
    import itertools
    import string

    m = apygis.MapFile("MANY", scale=5000, crs="EPSG:2056")
    exts = ("".join(p) for p in itertools.product(string.ascii_lowercase, repeat=2))
    for k, ext in enumerate(itertools.islice(exts, n)):
        lay = m.layer(ext)
        x0 = 2683000.0 + 100 * k
        lay.add_line(
            [(x0, 1247000.0, 1.0), (x0 + 10, 1247000.0, 2.0), (x0 + 10, 1247010.0, 3.0)], 5
        )
        lay.add_line(
            [(x0, 1247050.0, 0), (x0 + 5, 1247050.0, 0), (x0 + 5, 1247055.0, 0)], 7, closed=True
        )
        lay.add_symbol(x0 + 1, 1247001.0, 400.0, 6)
        lay.add_text(x0 + 2, 1247002.0, 400.0, f"Text {ext}")
    return m


def test_a_map_of_many_layers_is_merged_into_one_valid_geopackage(tmp_path):
    import pyogrio

    m = _many_layers()
    path = tmp_path / "many.gpkg"
    apygis.write(m, path)
    assert not list(tmp_path.glob(".part*"))
    assert not list(tmp_path.glob(".apygis-*"))
    assert apygis.read(path) == m
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert con.execute("PRAGMA application_id").fetchone()[0] == 0x47504B47  # 'GPKG'
    assert con.execute("PRAGMA user_version").fetchone()[0] == 10200
    tables = {r[0] for r in con.execute("SELECT table_name FROM gpkg_contents")}
    assert len(tables) == 1 + 5 * 20 + 1  # the header, five per layer, layer_styles
    counts = dict(con.execute("SELECT table_name, feature_count FROM gpkg_ogr_contents"))
    assert counts["at_line_points"] == 6
    rtrees = {r[0] for r in con.execute("SELECT table_name FROM gpkg_extensions")}
    assert len(rtrees) == 5 * 20
    # GDAL sees every layer, and each R-tree answers a spatial filter
    listed = {str(n) for n, _ in pyogrio.list_layers(path)}
    assert listed == tables
    x0 = 2683000.0 + 100 * 7
    _, _, wkb, _ = pyogrio.raw.read(
        path, layer="ah_line_points", bbox=(x0 - 1, 1246999, x0 + 11, 1247011)
    )
    assert len(wkb) == 3
    info = pyogrio.read_info(path, layer="ah_symbols")
    assert info["capabilities"]["fast_spatial_filter"]
    assert info["layer_metadata"]["DESCRIPTION"].startswith("apygis map MANY, layer ah: symbols")
