"""apygis writing 1 M line points to GeoPackage, against GDAL writing the same features.

GeoPackage, write against write: the map is 1 M line points in ``--layers``
layers (default 20; chains of 100 points, LV95 coordinates at centimetre
resolution, ``tests.formats.strategies.random_rows``). The script times

* ``apygis.write(map, "x.gpkg")``: everything from the in-memory map (the
  OGR tables of the schema, their geometries, the GeoPackage, its
  descriptions and QGIS styles), and
* GDAL alone writing the very same OGR layers and features, held in memory
  already (built by apygis's own ``_tables`` before the clock starts), into
  one GeoPackage with the same options (version 1.2, R-tree indexes, SQLite's
  per-transaction syncs off as apygis has them): ``pyogrio.write_arrow`` per
  layer (GDAL's bulk path, which apygis uses too),

and prints both times and their ratio (goal: apygis <= 1.2 x GDAL). Then a
map of 200 layers (the same 1 M points, 5 000 per layer) to GeoPackage:
``gpkg_many_layers_s`` (before the per-table GeoPackages merged by SQLite,
every table of such a map reopened the file, whose schema SQLite parsed
again each time: O(n²), 103 s).

DXF: apygis writing the 1 M points as DXF, against GDAL copying that DXF
(its read included), as before.

The GeoPackage figures are medians of ``--repeat`` (default 3) runs of apygis
and GDAL alternately, the others the best of ``--repeat`` runs
(``time.perf_counter``); files on the temporary directory's disk.

Run: ``python benchmarks/bench_convert.py [--repeat N] [--layers N]``
Last line: one JSON object with the keys ``gpkg_s``, ``gpkg_gdal_s``,
``gpkg_ratio``, ``gpkg_many_layers_s``, ``dxf_s``, ``dxf_gdal_s``, ``dxf_ratio``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import string
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pyogrio
import pyogrio.raw

import apygis
from apygis.formats import drivers

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench_native import best

from apygis.formats.ogr.schema import _GPKG
from apygis.formats.ogr.writer import GPKG_VERSION, _tables
from apygis.model.map import crs_string
from tests.formats.strategies import random_rows

try:
    import pyarrow as pa

    HAVE_ARROW = True
except ImportError:
    HAVE_ARROW = False

POINTS = 1_000_000


def make_map(n_layers: int, points: int = POINTS) -> apygis.MapFile:
    rng = np.random.default_rng(2)
    m = apygis.MapFile("BENCH", scale=5000, crs="EPSG:2056")
    exts = ("".join(p) for p in itertools.product(string.ascii_lowercase, repeat=2))
    per = points // n_layers
    for ext in itertools.islice(exts, n_layers):
        m.add_layer(apygis.Layer.from_arrays(ext, line_points=random_rows(rng, per)))
    return m


def _arrow_table(table):
    cols = {}
    for name, values, mask in zip(table.fields, table.data, table.masks, strict=True):
        arr = np.asarray(values)
        cols[name] = pa.array(arr.tolist() if arr.dtype == object else arr, mask=mask)
    if table.wkb is not None:
        cols["geom"] = pa.array(table.wkb.tolist(), type=pa.binary())
    return pa.table(cols)


def gdal_write(tables, crs: str, path: Path) -> None:
    """GDAL writing the prepared tables into one GeoPackage, as apygis's options."""
    opts = {"VERSION": GPKG_VERSION}
    for t in tables:
        kw = dict(
            layer=t.name,
            driver="GPKG",
            geometry_type=t.geometry_type,
            crs=crs if t.geometry_type else None,
            dataset_options=opts,
        )
        if HAVE_ARROW:
            pyogrio.write_arrow(
                t.arrow, path, geometry_name="geom" if t.wkb is not None else None, **kw
            )
        else:
            masks = t.masks if any(m is not None for m in t.masks) else None
            pyogrio.raw.write(path, t.wkb, t.data, t.fields, field_mask=masks, **kw)


def _unsynced(fn):
    key = "OGR_SQLITE_SYNCHRONOUS"
    before = pyogrio.get_gdal_config_option(key)
    pyogrio.set_gdal_config_options({key: "OFF"})
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fn()
    finally:
        pyogrio.set_gdal_config_options({key: before})


def gdal_copy(src: Path, dst: Path, driver: str) -> None:
    """GDAL alone copying every layer of ``src`` to ``dst`` (the DXF baseline)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, _ in pyogrio.list_layers(src):
            meta, _, wkb, data = pyogrio.raw.read(src, layer=str(name))
            pyogrio.raw.write(
                dst,
                wkb,
                data,
                list(meta["fields"]),
                layer=str(name),
                driver=driver,
                geometry_type=meta["geometry_type"],
                crs=meta["crs"],
            )


def interleaved(a, b, repeat: int) -> tuple[float, float]:
    """Median times of ``a`` and ``b`` run alternately ``repeat`` times each.

    Alternating, and the median rather than the best, so that a busy machine
    (other work starting or stopping) weighs on both sides alike.
    """
    ta, tb = [], []
    for _ in range(repeat):
        for fn, out in ((a, ta), (b, tb)):
            t0 = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t0)
    return float(np.median(ta)), float(np.median(tb))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--layers", type=int, default=20)
    args = ap.parse_args()
    m = make_map(args.layers)
    n = sum(len(lay.line_points) for lay in m)
    print(
        f"{n} line points in {args.layers} layers; GDAL writes through "
        f"{'Arrow' if HAVE_ARROW else 'numpy (pyarrow missing)'}"
    )
    figures: dict[str, float | None] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)

        def fresh(name: str) -> Path:
            p = tmp / name
            if p.exists():
                p.unlink()
            return p

        crs = crs_string(m.crs)
        tables = _tables(m, _GPKG, crs)
        for t in tables:
            t.arrow = _arrow_table(t) if HAVE_ARROW else None
        t_apy, t_gdal = interleaved(
            lambda: apygis.write(m, fresh("apygis.gpkg")),
            lambda: _unsynced(lambda: gdal_write(tables, crs, fresh("gdal.gpkg"))),
            args.repeat,
        )
        ratio = t_apy / t_gdal
        figures.update(
            gpkg_s=round(t_apy, 3), gpkg_gdal_s=round(t_gdal, 3), gpkg_ratio=round(ratio, 3)
        )
        print(
            f"gpkg  {len(tables)} OGR layers: apygis {t_apy:.3f} s, GDAL writing the same "
            f"features {t_gdal:.3f} s, ratio {ratio:.2f} (goal <= 1.2)"
        )
        many = make_map(200)
        t_many = best(lambda: apygis.write(many, fresh("many.gpkg")), args.repeat)
        figures["gpkg_many_layers_s"] = round(t_many, 3)
        print(f"gpkg  200 layers ({n} line points): apygis {t_many:.3f} s")

        if "dxf" not in drivers():
            print("dxf: no apygis driver installed; skipped")
            figures.update(dxf_s=None, dxf_gdal_s=None, dxf_ratio=None)
        else:
            target = tmp / "BENCH.dxf"
            t_dxf = best(lambda: apygis.write(m, target), args.repeat)
            try:
                t_copy = best(lambda: gdal_copy(target, fresh("COPY.dxf"), "DXF"), args.repeat)
            except Exception as exc:
                print(f"dxf: GDAL could not copy {target.name}: {exc}")
                figures.update(dxf_s=round(t_dxf, 3), dxf_gdal_s=None, dxf_ratio=None)
            else:
                figures.update(
                    dxf_s=round(t_dxf, 3),
                    dxf_gdal_s=round(t_copy, 3),
                    dxf_ratio=round(t_dxf / t_copy, 3),
                )
                print(
                    f"dxf   {target.stat().st_size / 1e6:.1f} MB: apygis {t_dxf:.3f} s, GDAL "
                    f"copying it {t_copy:.3f} s, ratio {t_dxf / t_copy:.2f}"
                )
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
