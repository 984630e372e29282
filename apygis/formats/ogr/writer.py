"""Writing a map as OGR layers (see :func:`apygis.formats.ogr.write`).

Each OGR layer is a :class:`_Table` of whole columns (WKB and attributes)
written with one call: ``pyogrio.write_arrow`` into a GeoPackage (GDAL's bulk
path), ``pyogrio.raw.write`` for Shapefile and FlatGeobuf, apygis's own writer
for GeoJSON (:mod:`apygis.formats.ogr.geojson`); the header table is cut into
rows for a Shapefile's DBF. Also the file names of a set, the files a write leaves
stale, and the GeoPackage's unsynced SQLite while its temporary file is written.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from apygis.errors import DriverError
from apygis.formats.ogr._common import _gdal, _WriteError, _xyz
from apygis.formats.ogr.schema import (
    _DBF_BYTES,
    _GEOJSON,
    _SHP,
    _SHP_CHUNK,
    MAP_TABLE,
    SCHEMA_VERSION,
    _Format,
    _points_text,
    _schema_files,
)
from apygis.formats.ogr.wkb import _lines_wkb, _points_wkb
from apygis.model.map import MapFile
from apygis.model.records import MAX_CODE, REF_FIELDS

#: The GeoPackage version written (GDAL's ``VERSION`` creation option). GDAL
#: 3.6 (Debian 12, QGIS LTR builds) warns at every open of a 1.4 file, and
#: the schema uses nothing newer than 1.2; set "1.4" (or "AUTO") to change it.
GPKG_VERSION = "1.2"


@dataclass
class _Table:
    """One OGR layer to write: whole columns."""

    name: str
    geometry_type: str | None
    wkb: np.ndarray | None
    fields: list[str]
    data: list[np.ndarray]
    masks: list[np.ndarray | None]


def _symbol_names() -> np.ndarray:
    from apygis.model.symbols import default_library

    lib = default_library()
    return np.array([lib.name(c) for c in range(MAX_CODE + 1)], dtype=object)


def _header_rows(map_: MapFile, fmt: _Format, crs: str | None) -> _Table:
    values = {
        "crs": crs,
        "notes": map_.notes,
        "layers": ",".join(map_.layers),
    }
    if fmt is _SHP:
        chunks = {k: _chunks(v or "") for k, v in values.items()}
        rows = max(1, *(len(c) for c in chunks.values()))
    else:
        chunks = {k: [v] if v else [] for k, v in values.items()}
        rows = 1
    n = rows

    def column(key):
        col = np.array([None] * n, dtype=object)
        for i, c in enumerate(chunks[key]):
            col[i] = c
        if key == "notes" and col[0] is None:
            col[0] = ""
        return col

    def first(value, dtype):
        arr = np.zeros(n, dtype=dtype)
        mask = np.ones(n, dtype=bool)
        if value is not None:
            arr[0] = value
            mask[0] = False
        return arr, mask

    version, vmask = first(SCHEMA_VERSION, np.int32)
    scale, smask = first(map_.scale, np.int64)
    ids = np.array([map_.id] + [None] * (n - 1), dtype=object)
    return _Table(
        name=MAP_TABLE,
        geometry_type=None,
        wkb=None,
        fields=["apygis", "id", "scale", "crs", "notes", "layers"],
        data=[version, ids, scale, column("crs"), column("notes"), column("layers")],
        masks=[vmask, None, smask, None, None, None],
    )


def _chunks(text: str) -> list[str]:
    """``text`` in pieces of about 60 characters, cut between two non-blank characters.

    A DBF field loses leading and trailing blanks, so no piece may start or
    end with one (only blanks at the very start or end of ``text`` are lost).
    """
    out = []
    i = 0
    n = len(text)
    while i < n:
        j = min(i + _SHP_CHUNK, n)
        while j < n and (text[j - 1] == " " or text[j] == " "):
            j += 1
        out.append(text[i:j])
        i = j
    return out


def _tables(map_: MapFile, fmt: _Format, crs: str | None) -> list[_Table]:
    """Every OGR layer of the schema for ``map_`` (non-empty ones only), header first."""
    from apygis.model.polylines import export_lines

    out = [_header_rows(map_, fmt, crs)]
    names = None
    limit = _DBF_BYTES if fmt is _SHP else None
    for lay in map_:
        ext = lay.ext
        sym = lay.symbols
        if len(sym):
            if names is None:
                names = _symbol_names()
            code = sym["code"].astype(np.int32)
            out.append(
                _Table(
                    f"{ext}_symbols",
                    "Point Z",
                    _points_wkb(_xyz(sym)),
                    ["num", "code", "name"],
                    [sym["num"].astype(np.int64), code, names[np.clip(code, 0, MAX_CODE)]],
                    [None, None, None],
                )
            )
        lp = lay.line_points
        if len(lp):
            ls = export_lines(lay)
            lengths = np.diff(ls.offsets)
            for kind, gtype, sel in (
                ("lines", "LineString Z", ~ls.closed & (lengths >= 2)),
                ("areas", "Polygon Z", ls.closed),
            ):
                if not sel.any():
                    continue
                idx = np.flatnonzero(sel)
                starts, stops = ls.offsets[idx], ls.offsets[idx + 1]
                sub_len = stops - starts
                sub_off = np.r_[0, np.cumsum(sub_len)].astype(np.int64)
                take = np.repeat(starts - sub_off[:-1], sub_len) + np.arange(sub_off[-1])
                coords = np.ascontiguousarray(ls.coords[take], dtype="<f8")
                nums = ls.nums[take]
                out.append(
                    _Table(
                        f"{ext}_{kind}",
                        gtype,
                        _lines_wkb(coords, sub_off, closed=kind == "areas"),
                        ["code", "npoints", "points"],
                        [
                            ls.codes[idx].astype(np.int32),
                            sub_len.astype(np.int32),
                            _points_text(nums, sub_off, limit),
                        ],
                        [None, None, None],
                    )
                )
        tx = lay.texts
        if len(tx):
            out.append(
                _Table(
                    f"{ext}_texts",
                    "Point Z",
                    _points_wkb(_xyz(tx)),
                    ["num", "text"],
                    [tx["num"].astype(np.int64), tx["text"].astype(object)],
                    [None, None],
                )
            )
        if len(lp):
            out.append(
                _Table(
                    f"{ext}_line_points",
                    "Point Z",
                    _points_wkb(_xyz(lp)),
                    ["num", "code", *REF_FIELDS],
                    [lp["num"].astype(np.int64), lp["code"].astype(np.int32)]
                    + [lp[r].astype(np.int64) for r in REF_FIELDS],
                    [None] * 6,
                )
            )
    return out


def _arrow(table: _Table):
    """The table as a pyarrow Table (geometry column ``geom``, WKB), nulls from the masks."""
    import pyarrow as pa

    cols = {}
    for name, values, mask in zip(table.fields, table.data, table.masks, strict=True):
        arr = np.asarray(values)
        if arr.dtype == object:
            cols[name] = pa.array(arr.tolist(), type=pa.string(), mask=mask)
        else:
            cols[name] = pa.array(arr, mask=None if mask is None else np.asarray(mask))
    if table.wkb is not None:
        cols["geom"] = pa.array(table.wkb.tolist(), type=pa.binary())
    return pa.table(cols)


def _write_table(path: Path, fmt: _Format, table: _Table, crs: str | None) -> None:
    import pyogrio
    import pyogrio.raw

    if fmt.multi:  # GeoPackage: GDAL's bulk (Arrow) path, 1.2x faster than feature by feature
        _gdal(
            lambda: pyogrio.write_arrow(
                _arrow(table),
                str(path),
                layer=table.name,
                driver=fmt.ogr,
                geometry_name="geom" if table.wkb is not None else None,
                geometry_type=table.geometry_type,
                crs=crs if table.geometry_type is not None else None,
                layer_options=fmt.layer_options or None,
                dataset_options={"VERSION": fmt.dataset_version or GPKG_VERSION},
            ),
            "cannot write",
            path,
            table.name,
            error=_WriteError,
        )
        return
    if fmt is _GEOJSON:
        from pyproj import CRS

        from apygis.formats.ogr.geojson import write_geojson

        write_geojson(path, path.stem, table, None if crs is None else CRS.from_user_input(crs))
        return

    masks = table.masks if any(m is not None for m in table.masks) else None
    _gdal(
        lambda: pyogrio.raw.write(
            str(path),
            table.wkb,
            table.data,
            table.fields,
            field_mask=masks,
            layer=table.name if fmt.multi else path.stem,
            driver=fmt.ogr,
            geometry_type=table.geometry_type,
            crs=crs if table.geometry_type is not None else None,
            layer_options=fmt.layer_options or None,
            dataset_options=(
                {"VERSION": fmt.dataset_version or GPKG_VERSION} if fmt.ogr == "GPKG" else None
            ),
        ),
        "cannot write",
        path,
        table.name,
        error=_WriteError,
    )


def _file_names(table: _Table, fmt: _Format, prefix: str, ext: str, crs) -> list[str]:
    base = f"{prefix}_{table.name}"
    if fmt is not _SHP:
        return [f"{base}.{ext}"]
    if table.geometry_type is None:
        return [f"{base}.dbf", f"{base}.cpg"]
    names = [f"{base}.shp", f"{base}.shx", f"{base}.dbf", f"{base}.cpg"]
    if crs is not None:
        names.append(f"{base}.prj")
    return names


def _tables_skeleton(map_: MapFile) -> list[_Table]:
    """The OGR layers a write produces, names and geometry types only (no data built)."""
    from apygis.model.polylines import export_lines

    out = [_Table(MAP_TABLE, None, None, [], [], [])]
    for lay in map_:
        if len(lay.symbols):
            out.append(_Table(f"{lay.ext}_symbols", "Point Z", None, [], [], []))
        if len(lay.line_points):
            ls = export_lines(lay)  # a branch end gains its junction: a 1-point branch is a line
            if (~ls.closed & (np.diff(ls.offsets) >= 2)).any():
                out.append(_Table(f"{lay.ext}_lines", "LineString Z", None, [], [], []))
            if ls.closed.any():
                out.append(_Table(f"{lay.ext}_areas", "Polygon Z", None, [], [], []))
        if len(lay.texts):
            out.append(_Table(f"{lay.ext}_texts", "Point Z", None, [], [], []))
        if len(lay.line_points):
            out.append(_Table(f"{lay.ext}_line_points", "Point Z", None, [], [], []))
    return out


def _write_tables(
    tmp: Path,
    fmt: _Format,
    tables,
    names,
    single: str | None,
    crs,
    progress,
    final: Path,
    extras: dict | None = None,
):
    """Every table into ``tmp``: one file each (folder formats), or one GeoPackage.

    A GeoPackage is not written by one ``pyogrio`` call per table into the
    same file: every call opens the file again, and SQLite then parses the
    schema of every table already in it, so a map of n layers took O(n²)
    (103 s for 200 layers). Each table goes into a GeoPackage of its own,
    written by GDAL as usual, and :func:`_merge_gpkg` copies them into the
    first one with SQLite, once. A part holds up to ``_PART_TABLES`` tables
    (creating a GeoPackage costs more than reopening a small one); a map of
    at most ``_ONE_FILE_TABLES`` tables is written into one file directly
    (reopening it costs less than copying the data).
    """
    parts: list[Path] = []
    steps = len(tables) + (1 if single is not None else 0)
    size = len(tables) if len(tables) <= _ONE_FILE_TABLES else _PART_TABLES
    for k, table in enumerate(tables):
        part = k // size
        name = f".part{part}.gpkg" if single is not None else names[table.name][0]
        dest = tmp / name
        try:
            _write_table(dest, fmt, table, crs)
        except _WriteError as exc:  # named by the target, not the temporary folder
            shown = single if single is not None else name
            where = ": ".join(x for x in (str(final / shown), exc.record) if x)
            raise DriverError(f"{where}: {exc.reason}") from None
        if not parts or parts[-1] != dest:
            parts.append(dest)
        if progress:
            progress(k + 1, steps)
    if single is not None:
        _merge_gpkg(parts, tmp / single, extras or {})
        if progress:
            progress(steps, steps)


_PART_TABLES = 8
_ONE_FILE_TABLES = 64

_GPKG_ROWS = ("gpkg_contents", "gpkg_geometry_columns", "gpkg_extensions", "gpkg_ogr_contents")


def _merge_gpkg(parts: list[Path], target: Path, extras: dict) -> None:
    """GeoPackages of one table each (all made by GDAL) as one GeoPackage ``target``.

    The first part becomes the target; from each other part, attached with
    SQLite, the table, its R-tree (the shadow tables copied as they are: no
    index is built again), its rows in ``gpkg_contents``,
    ``gpkg_geometry_columns``, ``gpkg_extensions`` and ``gpkg_ogr_contents``,
    its CRS in ``gpkg_spatial_ref_sys`` and then its triggers (created after
    the data: they call GDAL's SQL functions, which this connection lacks).
    ``extras``: ``descriptions`` (table -> text for ``gpkg_contents``) and
    ``styles`` (table -> QGIS QML for ``layer_styles``), see
    :mod:`apygis.formats.ogr.styles`.
    """
    import sqlite3

    os.replace(parts[0], target)
    con = sqlite3.connect(target, isolation_level=None)
    try:
        con.execute("PRAGMA synchronous=OFF")
        con.execute("PRAGMA journal_mode=OFF")
        con.execute("BEGIN")
        for part in parts[1:]:
            con.execute("ATTACH DATABASE ? AS part", (str(part),))
            _copy_part(con)
            con.execute("COMMIT")
            con.execute("DETACH DATABASE part")
            con.execute("BEGIN")
            part.unlink()
        for table, text in extras.get("descriptions", {}).items():
            con.execute(
                "UPDATE gpkg_contents SET description = ? WHERE table_name = ?", (text, table)
            )
        if extras.get("styles"):
            _layer_styles(con, extras["styles"])
        con.execute("COMMIT")
    finally:
        con.close()


def _layer_styles(con, styles: dict[str, str]) -> None:
    """QGIS's ``layer_styles`` table with one default style per table (QGIS's schema)."""
    con.execute(
        'CREATE TABLE "layer_styles" ("id" INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, '
        '"f_table_catalog" TEXT(256), "f_table_schema" TEXT(256), "f_table_name" TEXT(256), '
        '"f_geometry_column" TEXT(256), "styleName" TEXT(30), "styleQML" TEXT, '
        '"styleSLD" TEXT, "useAsDefault" BOOLEAN, "description" TEXT, "owner" TEXT(30), '
        '"ui" TEXT(30), "update_time" DATETIME DEFAULT '
        "(strftime('%Y-%m-%dT%H:%M:%fZ','now')))"
    )
    con.executemany(
        'INSERT INTO "layer_styles" ("f_table_catalog", "f_table_schema", "f_table_name", '
        '"f_geometry_column", "styleName", "styleQML", "styleSLD", "useAsDefault", '
        "\"description\", \"owner\") VALUES ('', '', ?, 'geom', ?, ?, '', 1, ?, 'apygis')",
        [(t, t, q, f"apygis default style of {t}") for t, q in styles.items()],
    )
    con.execute(
        "INSERT INTO gpkg_contents (table_name, data_type, identifier, description) "
        "VALUES ('layer_styles', 'attributes', 'layer_styles', 'QGIS styles of the layers')"
    )
    con.execute(
        "INSERT INTO gpkg_ogr_contents (table_name, feature_count) VALUES ('layer_styles', ?)",
        (len(styles),),
    )


def _copy_part(con) -> None:
    objects = con.execute("SELECT type, name, tbl_name, sql FROM part.sqlite_master").fetchall()
    main_tables = {r[0] for r in con.execute("SELECT name FROM main.sqlite_master")}
    shadow = {
        f"{n}_{s}"
        for t, n, _, sql in objects
        if t == "table" and sql and sql.upper().startswith("CREATE VIRTUAL TABLE")
        for s in ("node", "rowid", "parent")
    }
    system = {n for t, n, _, _ in objects if n.startswith(("gpkg_", "sqlite_"))}
    for t, n, _, sql in objects:  # GeoPackage system tables the target lacks (gpkg_extensions)
        if t == "table" and n in system and n not in main_tables and sql:
            con.execute(sql)
    user = [
        (n, sql)
        for t, n, _, sql in objects
        if t == "table" and n not in system and n not in shadow and sql
    ]
    for n, sql in user:
        con.execute(sql)  # the table, or the R-tree (with empty shadow tables)
        q = _quote(n)
        if sql.upper().startswith("CREATE VIRTUAL TABLE"):
            for suffix in ("node", "rowid", "parent"):
                qs = _quote(f"{n}_{suffix}")
                con.execute(f"DELETE FROM main.{qs}")
                con.execute(f"INSERT INTO main.{qs} SELECT * FROM part.{qs}")
        else:
            con.execute(f"INSERT INTO main.{q} SELECT * FROM part.{q}")
    con.execute(
        "INSERT OR IGNORE INTO main.gpkg_spatial_ref_sys SELECT * FROM part.gpkg_spatial_ref_sys"
    )
    for table in _GPKG_ROWS:
        if table in system:
            con.execute(f"INSERT INTO main.{table} SELECT * FROM part.{table}")
    names = [n for n, _ in user]
    if names and "sqlite_sequence" in system:
        marks = ",".join("?" * len(names))
        con.execute(
            f"INSERT INTO main.sqlite_sequence SELECT * FROM part.sqlite_sequence "
            f"WHERE name IN ({marks})",
            names,
        )
    for t, _, tbl, sql in objects:
        if t in ("trigger", "index") and sql and tbl not in system:
            con.execute(sql)


def _quote(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


@contextlib.contextmanager
def _sqlite_unsynced(fmt: _Format):
    """SQLite without a disk sync per transaction while a GeoPackage is written.

    The file is a temporary one, synced once when complete and only then
    renamed over the target, so the per-transaction syncs buy nothing (they
    take most of the time of a GeoPackage of many layers). GDAL's
    configuration is process-wide: the previous value is restored after.
    """
    if not fmt.multi:
        yield
        return
    import pyogrio

    key = "OGR_SQLITE_SYNCHRONOUS"
    before = pyogrio.get_gdal_config_option(key)
    pyogrio.set_gdal_config_options({key: "OFF"})
    try:
        yield
    finally:
        pyogrio.set_gdal_config_options({key: before})


def _fsync(p: Path) -> None:
    with open(p, "rb") as fh:
        os.fsync(fh.fileno())


def _stale(directory: Path, prefix: str, fmt: _Format, written: set[str]) -> list[Path]:
    """Files of this prefix's schema that the write did not produce (to be removed).

    They would be read back as part of the map: an OGR layer the map no
    longer has, a ``.prj`` left from a map that had a CRS, a stale spatial
    index. Only names of the schema with this prefix are touched.
    """
    return [p for p in _schema_files(directory, prefix, fmt) if p.name not in written]
