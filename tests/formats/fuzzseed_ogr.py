"""Fuzz seeds for the OGR drivers (see tests/test_fuzz.py).

Each seed is one file of a valid dataset that the reader takes alone:

* ``gpkg``: the whole GeoPackage (SQLite) of the small map.
* ``shp``: the whole small map as a zipped Shapefile set (``.shz``, stored
  uncompressed so that mutations reach the ``.shp``, ``.shx`` and ``.dbf``
  bytes; GDAL does not check the ZIP checksums). A lone ``.shp`` would be
  refused before any parsing, for want of its ``.shx``.
* ``geojson``: the ``r_line_points`` file: the exact schema, references included.
* ``fgb``: the ``r_lines`` file: a foreign-looking line layer whose topology
  the reader rebuilds (``Layer.add_polylines``).
"""

from __future__ import annotations

import zipfile

import apygis
from tests.formats.strategies import small_map


def _seed_gpkg(tmp_path):
    apygis.write(small_map(), tmp_path / "FUZZ.gpkg")
    return (tmp_path / "FUZZ.gpkg").read_bytes(), "FUZZ.gpkg"


def _seed_shp(tmp_path):
    written = apygis.write(small_map(), tmp_path / "set", driver="shp")
    with zipfile.ZipFile(tmp_path / "FUZZ.shz", "w", zipfile.ZIP_STORED) as z:
        for p in sorted(written):
            z.write(p, p.name)
    return (tmp_path / "FUZZ.shz").read_bytes(), "FUZZ.shz"


def _seed_geojson(tmp_path):
    apygis.write(small_map(), tmp_path / "set", driver="geojson")
    name = "FUZZ_r_line_points.geojson"
    return (tmp_path / "set" / name).read_bytes(), name


def _seed_fgb(tmp_path):
    apygis.write(small_map(), tmp_path / "set", driver="fgb")
    return (tmp_path / "set" / "FUZZ_r_lines.fgb").read_bytes(), "FUZZ_r_lines.fgb"


SEEDS = {"gpkg": _seed_gpkg, "shp": _seed_shp, "geojson": _seed_geojson, "fgb": _seed_fgb}
