"""A GeoPackage is written as version 1.2, which GDAL 3.6 (Debian 12, QGIS LTR)
opens without the warning it gives at every open of a 1.4 file."""

from __future__ import annotations

import sqlite3

import apygis
from apygis.formats.ogr import writer
from tests.formats.strategies import small_map

GPKG_APPLICATION_ID = 0x47504B47  # 'GPKG'


def _version(path) -> tuple[int, int]:
    con = sqlite3.connect(path)
    try:
        (app,) = con.execute("PRAGMA application_id").fetchone()
        (user,) = con.execute("PRAGMA user_version").fetchone()
    finally:
        con.close()
    return app, user


def test_default_is_1_2():
    assert writer.GPKG_VERSION == "1.2"


def test_written_geopackage_is_version_1_2(tmp_path):
    (path,) = apygis.write(small_map(), tmp_path / "m.gpkg", driver="gpkg")
    assert _version(path) == (GPKG_APPLICATION_ID, 10200)


def test_rewrite_stays_1_2(tmp_path, sample_map):
    target = tmp_path / "m.gpkg"
    apygis.write(small_map(), target, driver="gpkg")
    (path,) = apygis.write(sample_map, target, driver="gpkg")
    assert _version(path) == (GPKG_APPLICATION_ID, 10200)
    assert apygis.read(path) == sample_map


def test_version_can_be_asked_for(tmp_path, monkeypatch):
    monkeypatch.setattr(writer, "GPKG_VERSION", "1.4")
    (path,) = apygis.write(small_map(), tmp_path / "m.gpkg", driver="gpkg")
    assert _version(path) == (GPKG_APPLICATION_ID, 10400)
