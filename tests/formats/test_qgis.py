"""The GeoPackage apygis writes, opened in QGIS itself (Debian's python3-qgis, for the
system Python, offscreen): every layer with its description and the default style from
``layer_styles``, symbols from the symbol library, line colours from the pens; and the
rendered picture, saved under the test's folder to be looked at."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

import apygis
from apygis.formats.ogr.styles import PENS

pytestmark = pytest.mark.qgis

SCRIPT = Path(__file__).with_name("qgis_render.py")


def _render(gpkg: Path, png: Path) -> dict:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    res = subprocess.run(
        ["/usr/bin/python3", str(SCRIPT), str(gpkg), str(png)],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_qgis_opens_the_geopackage_styled_like_the_plot(sample_map, tmp_path):
    gpkg = tmp_path / "ZH1091.gpkg"
    apygis.write(sample_map, gpkg)
    got = _render(gpkg, tmp_path / "ZH1091-qgis.png")

    tables = {k: v for k, v in got.items() if k != "png"}
    expected = {
        f"{lay.ext}_{kind}"
        for lay in sample_map
        for kind, n in (
            ("symbols", len(lay.symbols)),
            ("texts", len(lay.texts)),
            ("line_points", len(lay.line_points)),
        )
        if n
    }
    assert expected <= set(tables)
    for name, t in tables.items():
        assert t["crs"] == "EPSG:2056", name
        assert t["abstract"].startswith("apygis map ZH1091, layer "), name

    # symbols: categorised by code, each code used drawn from the library's bitmap
    for lay in sample_map:
        if not len(lay.symbols):
            continue
        t = tables[f"{lay.ext}_symbols"]
        assert t["renderer"] == "categorizedSymbol"
        assert t["attr"] == "code"
        codes = {str(int(c)) for c in lay.symbols["code"]}
        assert set(t["categories"]) == codes
        for c, cat in t["categories"].items():
            assert cat["layer"] == "SvgMarker"
            assert cat["svg"] == "base64:"
            assert cat["label"].startswith(f"{int(c):02d} ")
    assert tables["e_symbols"]["labels"]  # spot heights carry their height
    assert tables["c_texts"]["labels"]
    # lines in the pens' colours: hydrography blue, roads black
    h = ",".join(map(str, PENS["h"][0]))
    assert tables["h_lines"]["symbol"] == {"layer": "SimpleLine", "colour": f"{h},255"}
    assert tables["r_lines"]["symbol"] == {"layer": "SimpleLine", "colour": "0,0,0,255"}
    assert tables["h_areas"]["symbol"]["layer"] == "SimpleFill"

    # the picture: blue water, brown heights, black roads and symbols all drawn
    px = got["png"]["pixels"]
    assert got["png"]["width"] == 1200
    assert px["blue"] > 50
    assert px["brown"] > 50
    assert px["dark"] > 200


def test_gdal_36_opens_what_apygis_writes_without_warnings(sample_map, tmp_path):
    """Debian 12's GDAL 3.6 (what QGIS LTR builds run on): the GeoPackage (version 1.2,
    merged from parts, with layer_styles), RFC 7946 GeoJSON and a DXF with umlauts."""
    from apygis.model.reproject import reproject

    m = sample_map.copy()
    m.layer("c").add_text(2684000.0, 1248000.0, 450.0, "Zürich Łódź Ελλάδα Plzeň")
    gpkg = tmp_path / "ZH1091.gpkg"
    apygis.write(m, gpkg)
    plain = tmp_path / "ascii.dxf"  # texts in ASCII: ANSI_1252, nothing to recode
    apygis.write(sample_map, plain)
    dxf = tmp_path / "ZH1091.dxf"  # umlauts and more: UTF-8 declared as ANSI_65001
    apygis.write(m, dxf)
    gj = tmp_path / "gj"
    apygis.write(reproject(m, "EPSG:4326"), gj, driver="geojson")
    areas = next(gj.glob("*_r_areas.geojson"))
    res = subprocess.run(
        [
            "/usr/bin/python3",
            str(SCRIPT.with_name("gdal_open.py")),
            *(str(p) for p in (gpkg, plain, dxf, areas)),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    got = json.loads(res.stdout)
    assert got["gdal"].startswith("3.")
    for path in (gpkg, plain, areas):
        assert got[str(path)]["messages"] == [], path
    # Debian's iconv has no CP65001: GDAL says so for each string and keeps the UTF-8
    # text as it is, which is right (the texts below); nothing else is said
    assert all("Recode from CP65001" in msg for msg in got[str(dxf)]["messages"])
    layers = got[str(gpkg)]["layers"]
    assert layers["h_lines"]["crs"] == "2056"
    assert layers["r_line_points"]["features"] == len(m.layers["r"].line_points)
    assert "layer_styles" in layers
    assert "Zürich Łódź Ελλάδα Plzeň" in got[str(dxf)]["texts"]
    assert got[str(areas)]["layers"][areas.stem]["crs"] in ("4326", "4979")
