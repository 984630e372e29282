"""apygis converting 1 M line points to GeoPackage and DXF, against GDAL copying the result.

The map is ``bench_native.make_map``: 100 layers of 10 000 line points each
(chains of 100 points), LV95 coordinates at centimetre resolution. For each
format the script times

* ``apygis.write(map, path)``: the conversion from the in-memory map, and
* GDAL alone copying the file apygis wrote to a new file of the same format,
  layer by layer (``pyogrio.read_arrow`` + ``pyogrio.write_arrow`` when
  pyarrow is installed, else ``pyogrio.raw.read`` + ``pyogrio.raw.write``),

and prints both times and their ratio (goal: apygis <= 1.5 x GDAL). apygis
writes a GeoPackage into a temporary file with SQLite's per-transaction
disk syncs off (``OGR_SQLITE_SYNCHRONOUS=OFF``), syncing once before the
rename; the GDAL copy that the ratio uses runs with the same setting, and
the copy with GDAL's default setting is printed too. Each
figure is the best of ``--repeat`` runs (``time.perf_counter``), files on the
temporary directory's disk. When no DXF driver is installed the DXF part is
skipped with a note and its figures are null.

Run: ``python benchmarks/bench_convert.py [--repeat N] [--layers N]``
Last line: one JSON object with the keys ``gpkg_s``, ``gpkg_gdal_s``,
``gpkg_ratio``, ``dxf_s``, ``dxf_gdal_s``, ``dxf_ratio``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from pathlib import Path

import pyogrio
import pyogrio.raw

import apygis
from apygis.formats import drivers

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_native import best, make_map

try:
    import pyarrow  # noqa: F401

    HAVE_ARROW = True
except ImportError:
    HAVE_ARROW = False


def gdal_copy(src: Path, dst: Path, driver: str, unsynced: bool = True) -> str:
    """Copy every layer of ``src`` to ``dst`` with GDAL (through pyogrio) alone.

    Arrow (``read_arrow`` + ``write_arrow``) where pyarrow is installed and
    GDAL's driver takes the Arrow fields; otherwise GDAL's numpy path
    (``raw.read`` + ``raw.write``). Returns the path used.
    """
    key = "OGR_SQLITE_SYNCHRONOUS"
    before = pyogrio.get_gdal_config_option(key)
    pyogrio.set_gdal_config_options({key: "OFF" if unsynced else None})
    try:
        for arrow in (True, False) if HAVE_ARROW else (False,):
            if dst.exists():
                dst.unlink()
            try:
                _copy_layers(src, dst, driver, arrow)
                return "Arrow" if arrow else "numpy"
            except Exception as exc:
                if not arrow:
                    raise
                print(f"{driver}: GDAL's Arrow write refused ({exc}); numpy path instead")
    finally:
        pyogrio.set_gdal_config_options({key: before})
    raise AssertionError("unreachable")


def _copy_layers(src: Path, dst: Path, driver: str, arrow: bool) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, _ in pyogrio.list_layers(src):
            name = str(name)
            if arrow:
                meta, table = pyogrio.read_arrow(src, layer=name)
                pyogrio.write_arrow(
                    table,
                    dst,
                    layer=name,
                    driver=driver,
                    geometry_name=meta["geometry_name"] or None,
                    geometry_type=meta["geometry_type"],
                    crs=meta["crs"],
                    encoding=meta["encoding"],
                )
            else:
                meta, _, wkb, data = pyogrio.raw.read(src, layer=name)
                pyogrio.raw.write(
                    dst,
                    wkb,
                    data,
                    list(meta["fields"]),
                    layer=name,
                    driver=driver,
                    geometry_type=meta["geometry_type"],
                    crs=meta["crs"],
                )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--layers", type=int, default=100)
    args = ap.parse_args()
    m = make_map(args.layers)
    n = sum(len(lay.line_points) for lay in m)
    print(
        f"{n} line points in {args.layers} layers; GDAL copy through "
        f"{'Arrow' if HAVE_ARROW else 'numpy (pyarrow not installed: pip install .[bench])'}"
    )
    figures: dict[str, float | None] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for fmt, ogr_driver in (("gpkg", "GPKG"), ("dxf", "DXF")):
            keys = (f"{fmt}_s", f"{fmt}_gdal_s", f"{fmt}_ratio")
            if fmt not in drivers():
                print(f"{fmt}: no apygis driver installed yet; skipped")
                figures.update(dict.fromkeys(keys))
                continue
            target = tmp / f"BENCH.{fmt}"
            copy = tmp / f"COPY.{fmt}"
            t_apy = best(lambda target=target: apygis.write(m, target), args.repeat)
            size = target.stat().st_size
            try:
                t_gdal = best(
                    lambda target=target, copy=copy, d=ogr_driver: gdal_copy(target, copy, d),
                    args.repeat,
                )
            except Exception as exc:
                print(f"{fmt}: GDAL could not copy {target.name}: {exc}")
                figures.update({keys[0]: round(t_apy, 3), keys[1]: None, keys[2]: None})
                continue
            if fmt == "gpkg":
                t_default = best(
                    lambda target=target, copy=copy: gdal_copy(target, copy, "GPKG", False),
                    args.repeat,
                )
                print(f"gpkg: GDAL copy with default SQLite syncs {t_default:.3f} s")
            ratio = t_apy / t_gdal
            figures.update(
                {keys[0]: round(t_apy, 3), keys[1]: round(t_gdal, 3), keys[2]: round(ratio, 3)}
            )
            print(
                f"{fmt:<5} {size / 1e6:.1f} MB: apygis {t_apy:.3f} s ({n / t_apy / 1e6:.2f} M "
                f"points/s), GDAL copy {t_gdal:.3f} s, ratio {ratio:.2f} (goal <= 1.5)"
            )
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
