"""OGR drivers through pyogrio: GeoPackage, Shapefile, GeoJSON and FlatGeobuf.

The schema is specified in ``docs/formats/ogr.md``. In short, every map layer
``L`` becomes up to five OGR layers (only the non-empty ones are written):

============== ============= ==================================================
OGR layer      geometry      fields
============== ============= ==================================================
L_symbols      Point Z       num, code, name (symbol name, default library)
L_lines        LineString Z  code, npoints, points (``"1,2,3"``): open lines
L_areas        Polygon Z     code, npoints, points: closed lines
L_texts        Point Z       num, text
L_line_points  Point Z       num, code, fwd, back, side1, side2 (-1: none)
============== ============= ==================================================

plus a table ``apygis_map`` without geometry (apygis, id, scale, crs, notes,
layers) for the map header. ``L_lines`` and ``L_areas`` are for GIS users; a
reader rebuilds the map from ``L_symbols``, ``L_texts`` and ``L_line_points``
(record for record, point numbers and references included), taking the edits
a GIS user made to ``L_lines`` / ``L_areas`` (they win over ``L_line_points``,
which keeps the topology of the lines whose feature still agrees with it) and
to ``L_symbols`` / ``L_texts``; what was taken is logged (see
:mod:`apygis.formats.ogr.edits` and docs/formats/ogr.md, "Edited files").

GeoPackage holds all of them in one file, OGR layer names as above. The
single-layer formats write one file per OGR layer into a directory:
``write(m, "out/")`` gives ``out/<map id>_r_symbols.shp``, ...,
``out/<map id>_apygis_map.dbf``; ``write(m, "out/NAME.shp")`` uses the prefix
``NAME`` instead of the map ID. Reading ``out/NAME.shp`` (when no such file
exists) or the directory ``out/`` reads the whole set; reading one existing
file reads that OGR layer alone.

Files apygis did not write are imported too: points become symbols (or
texts, when the layer has a ``text`` field), lines and polygon rings become
line points whose references are rebuilt by the model's one rebuild,
:meth:`apygis.model.Layer.add_polylines` (its report logged). Writes go through pyogrio's vectorised
numpy path (whole columns of WKB and attributes), into a temporary file or
directory beside the target that is then renamed over it.

The package: this module holds the four drivers (``GPKG``, ``SHP``,
``GEOJSON``, ``FGB``, registered as ``apygis.formats.ogr:GPKG`` etc.), their
probes, :func:`read`, :func:`write`, :func:`outputs` and :func:`members`;
``schema`` the names of the schema and the formats table, ``wkb`` the WKB
encoding and decoding, ``writer`` the tables a write produces, ``reader`` the
exact schema and foreign data, ``edits`` the GIS edits and their report, and
``_common`` the logger, the pyogrio guards and the column checks they share.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from apygis.errors import DriverError, FormatError
from apygis.formats import READ_OPTIONS, Driver, Option
from apygis.formats._io import (
    check_target,
    commit,
    diagnose_write_failure,
    make_temp_dir,
    remove_stale_temps,
    stamp_entries,
    stamp_path,
    write_failed,
)
from apygis.formats._layers import LayerNames, parse_layer_map
from apygis.formats._report import warn
from apygis.formats.ogr._common import _rec, log
from apygis.formats.ogr.edits import _EditReport, _line_edits, _relink
from apygis.formats.ogr.reader import (
    _add_foreign,
    _exact_table,
    _Foreign,
    _foreign_layer,
    _header,
    _read_layer,
    _sources,
)
from apygis.formats.ogr.schema import (
    _EXACT,
    _FGB,
    _GEOJSON,
    _GPKG,
    _SHP,
    KINDS,
    MAP_TABLE,
    SCHEMA_VERSION,
    _default_id,
    _fmt,
    _Format,
    _member_files,
    _parse_name,
    _schema_files,
    _split_target,
)
from apygis.formats.ogr.writer import (
    _file_names,
    _fsync,
    _sqlite_unsynced,
    _stale,
    _tables,
    _tables_skeleton,
    _write_tables,
)
from apygis.model.map import Layer, MapFile, check_map_id, crs_string
from apygis.model.records import MAX_CODE
from apygis.model.symbols import IMPORTED_POINT

__all__ = [
    "FGB",
    "GEOJSON",
    "GPKG",
    "KINDS",
    "MAP_TABLE",
    "SCHEMA_VERSION",
    "SHP",
    "outputs",
    "read",
    "write",
]


def outputs(map_: MapFile, path, fmt="gpkg") -> list[Path]:
    """Every file a write of ``map_`` to ``path`` in format ``fmt`` creates (or replaces)."""
    fmt = _fmt(fmt)
    if fmt.multi:
        return [Path(path)]
    directory, prefix, ext = _split_target(map_, path, fmt)
    crs = crs_string(map_.crs)
    return [
        directory / name
        for table in _tables_skeleton(map_)
        for name in _file_names(table, fmt, prefix, ext, crs)
    ]


def write(
    map_: MapFile,
    path,
    fmt="gpkg",
    progress=None,
    spatial_index: bool = True,
    version: str | None = None,
    styles: bool = True,
) -> list[Path]:
    """Write ``map_`` in an OGR format, atomically; returns the files written.

    Parameters
    ----------
    map_ : MapFile
        The map.
    path : str or os.PathLike
        GeoPackage: the file. Shapefile, GeoJSON, FlatGeobuf: a directory (the
        files are named ``<map id>_<layer>``) or ``dir/NAME.<ext>`` (named
        ``NAME_<layer>``).
    fmt : str
        ``"gpkg"``, ``"shp"``, ``"geojson"`` or ``"fgb"``.
    progress : callable, optional
        ``progress(done, total)`` after each OGR layer.
    spatial_index : bool
        GeoPackage only: give every spatial layer an R-tree index (GDAL's
        default). Without, a map of many layers is written about a third
        faster; GIS programs draw small layers as fast either way.
    version : str, optional
        GeoPackage only: ``"1.2"`` (default, which GDAL 3.6 and QGIS LTR
        builds open without warnings), ``"1.3"`` or ``"1.4"``.
    styles : bool
        GeoPackage only: QGIS styles in ``layer_styles`` and descriptions
        in ``gpkg_contents`` (default; :mod:`apygis.formats.ogr.styles`).

    Returns
    -------
    list of Path
    """
    fmt = _fmt(fmt)
    if fmt.multi and not spatial_index:
        fmt = replace(fmt, layer_options={**fmt.layer_options, "SPATIAL_INDEX": "NO"})
    if version is not None and version not in ("1.2", "1.3", "1.4"):
        raise DriverError(f"GeoPackage version {version!r}: 1.2, 1.3 or 1.4")
    crs = crs_string(map_.crs)
    if fmt.multi:
        target = Path(path)
        if target.is_dir():
            raise DriverError(f"{target}: is a directory; a {fmt.ogr} target is a file")
        directory = target.parent
    else:
        directory, prefix, ext = _split_target(map_, path, fmt)
        if directory.exists() and not directory.is_dir():
            raise DriverError(f"{directory}: is a file; {fmt.ogr} writes into a directory")
    tables = _tables(map_, fmt, crs)
    names = {} if fmt.multi else {t.name: _file_names(t, fmt, prefix, ext, crs) for t in tables}
    if fmt.multi:
        real = check_target(target)  # a regular file or none; a symlink is written through
        directory = real.parent
    else:
        for ns in names.values():
            for n in ns:
                check_target(directory / n)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_failed(directory, exc) from None
    remove_stale_temps(directory, [])  # only folders: OGR writes into one
    try:
        tmp = make_temp_dir(directory)
    except OSError as exc:
        raise write_failed(target if fmt.multi else directory, exc) from None
    try:
        try:
            with _sqlite_unsynced(fmt):
                _write_tables(
                    tmp,
                    fmt if version is None else replace(fmt, dataset_version=version),
                    tables,
                    names,
                    target.name if fmt.multi else None,
                    crs,
                    progress,
                    target.parent if fmt.multi else directory,
                    _gpkg_extras(map_, tables, styles) if fmt.multi else None,
                )
            if fmt.multi:
                _fsync(tmp / target.name)
                commit([(tmp / target.name, real, target)])
                return [target]
            made = sorted(p.name for p in tmp.iterdir())
            expected = sorted(n for ns in names.values() for n in ns)
            if made != expected:  # pragma: no cover - a GDAL that writes other side files
                log.warning("%s: GDAL wrote %s, expected %s", directory, made, expected)
            for name in made:
                _fsync(tmp / name)
        except OSError as exc:
            raise write_failed(target if fmt.multi else directory, exc) from None
        except DriverError as exc:  # GDAL's own message; a full disk gives odd SQLite errors
            cause = diagnose_write_failure(tmp)
            if cause is not None:
                raise write_failed(target if fmt.multi else directory, cause) from None
            raise exc from None
        pairs = [(tmp / n, check_target(directory / n), directory / n) for n in made]
        entries = stamp_entries({n: tmp / n for n in made})
        stale = _stale(directory, prefix, fmt, set(made))
        commit(pairs, stamp_path(directory / prefix), entries, remove=stale)
        return [directory / n for n in made]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _gpkg_extras(map_: MapFile, tables, styles: bool) -> dict:
    """Descriptions of every table and, with ``styles``, QGIS styles of the spatial ones."""
    from apygis.formats.ogr import styles as st

    desc, qml = {}, {}
    library = None
    for t in tables:
        parsed = _parse_name(t.name)
        if parsed is None:
            continue
        _, ext, kind = parsed
        desc[t.name] = st.description(t.name, kind, ext, map_.id)
        if styles and kind != "map":
            codes = map_.layers[ext].symbols["code"].tolist() if kind == "symbols" else ()
            if kind == "symbols" and library is None:
                from apygis.model.symbols import load_library

                library = load_library()
            qml[t.name] = st.qml(kind, ext, codes, library)
    return {"descriptions": desc, "styles": qml}


def members(path, fmt) -> tuple[Path, list[Path], bool] | None:
    """The set stamp and the files a read of ``path`` takes (folder formats only)."""
    fmt = _fmt(fmt)
    if fmt.multi:
        return None
    p = Path(path)
    if p.is_file():
        parsed = _parse_name(p.stem)
        if parsed is None or parsed[0] is None:
            return None
        return stamp_path(p.parent / parsed[0]), [p], False
    if p.is_dir():
        files = _schema_files(p, None, fmt)
        prefixes = {parsed[0] for f in files if (parsed := _parse_name(f.stem))}
        (prefix,) = prefixes if len(prefixes) == 1 else (None,)
        if prefix is None:
            return None  # the reader refuses several maps; no prefix: not apygis's set
        return stamp_path(p / prefix), files, True
    if p.suffix[1:].lower() in fmt.extensions and p.parent.is_dir():
        files = _schema_files(p.parent, p.stem, fmt)
        return stamp_path(p.parent / p.stem), files, True
    return None


def read(
    path,
    fmt="gpkg",
    layer_map=None,
    layers=None,
    tolerance_m: float = 0.005,
    default_code: int | None = None,
    code_field: str | None = "code",
    text_field: str | None = "text",
    point_code: int = IMPORTED_POINT,
    crs=None,
    progress=None,
) -> MapFile:
    """Read a map from an OGR dataset.

    Parameters
    ----------
    path : str or os.PathLike
        GeoPackage: the file. Shapefile, GeoJSON, FlatGeobuf: one file (one
        OGR layer), a directory (every file of the format in it), or
        ``dir/NAME.<ext>`` naming the set ``dir/NAME_*.<ext>`` that
        :func:`write` made. Shapefile also reads zipped sets (``.shz``,
        ``.shp.zip``).
    fmt : str
        ``"gpkg"``, ``"shp"``, ``"geojson"`` or ``"fgb"``.
    layer_map : dict or str, optional
        OGR layer name -> map layer extension, or None / ``"-"`` to skip it
        (``{"roads": "r"}`` or ``"roads=r,rivers=h"``); a name the dataset
        does not have is refused. Other layers: the extension in an apygis
        name (``r_lines`` -> ``r``), else one map layer per OGR layer named
        from it (:mod:`apygis.formats._layers`).
    layers : list of str, optional
        Read only these OGR layers (one the dataset lacks is refused).
    tolerance_m : float
        Distance in metres within which line ends of foreign lines join (see
        :func:`apygis.model.polylines.rebuild`).
    default_code : int or None
        Code of foreign features whose code field is missing, NULL or not
        0-99 (the latter counted and reported). None: codes outside 0-99 are
        refused; lines without a code get 00, points 00 (spot height) where
        they have a height (Z, not 0), else ``point_code``.
    code_field, text_field : str or None
        Field names for codes and texts in foreign layers (None: not used;
        compared without regard to case).
    point_code : int
        Code of foreign points without a code or a height (default 90,
        "imported point").
    crs : optional
        The CRS of data that has none (or instead of the dataset's).
    progress : callable, optional
        ``progress(done, total)`` after each OGR layer.

    Edits a GIS user made to a file apygis wrote are taken: ``L_lines`` /
    ``L_areas`` win over ``L_line_points`` (deleted, changed and new lines;
    unchanged ones keep their exact topology), ``L_symbols`` / ``L_texts``
    features without ``num`` get new numbers. What was taken is reported as
    one warning per map layer (docs/formats/ogr.md, "Edited files").

    Returns
    -------
    MapFile

    Raises
    ------
    FormatError
        The file is missing, not of the format, or a layer or feature does
        not fit (the message names the file, the layer and the feature).
    """
    fmt = _fmt(fmt)
    lmap = parse_layer_map(layer_map)
    for name, value in (("default_code", default_code), ("point_code", point_code)):
        if value is None and name == "default_code":
            continue
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise DriverError(f"{name} is an integer 0-{MAX_CODE}, not {value!r}")
        if not 0 <= value <= MAX_CODE:
            raise DriverError(f"{name} is 0-{MAX_CODE}, not {value}")
    opts: dict[str, Any] = {
        "default_code": None if default_code is None else int(default_code),
        "code_field": code_field,
        "text_field": text_field,
        "point_code": int(point_code),
    }
    sources, default_id = _sources(path, fmt)
    present = [src.name for src in sources]
    # apygis's own names keep their map layer; the others are named from themselves
    own = [src.name for src in sources if _parse_name(src.name)]
    names = LayerNames(lmap, [n for n in present if n not in own], where=path)
    names.check_used(present)
    groups: dict[str, list[str]] = {}
    for n in own:
        parsed = _parse_name(n)
        if parsed is not None and parsed[2] != "map":
            groups.setdefault(parsed[1], []).append(n)
    chosen = names.select(layers, present, groups)

    # which map layer and kind each source is
    plan = []
    header_src = None
    prefixes = set()
    for src in sources:
        parsed = _parse_name(src.name)
        kind = parsed[2] if parsed else None
        if parsed is not None and kind == "map":
            header_src = header_src or src
            prefixes.add(parsed[0])
            continue
        if chosen is not None and src.name.upper() not in chosen:
            continue
        if not src.spatial and parsed is None:
            log.info("%s: layer %s has no geometry; skipped", src.dataset, src.name)
            continue
        mapped = next((v for k, v in lmap.items() if k.upper() == src.name.upper()), "")
        if mapped is None:
            continue  # skipped by the layer map
        ext = mapped or (parsed[1] if parsed else names(src.name))
        if ext is None:
            continue
        if parsed:
            prefixes.add(parsed[0])
        plan.append((src, ext, kind))
    # L_lines and L_areas of a map layer with L_line_points are checked against it: a GIS
    # user's edits of them are taken (_line_edits), the rest keeps its exact topology
    exact_lines = {ext for _, ext, kind in plan if kind == "line_points"}

    header = None
    total = len(plan) + (header_src is not None)
    done = 0
    if header_src is not None:
        _, _, columns = _read_layer(header_src)
        header = _header(columns, header_src)
        done += 1
        if progress:
            progress(done, total)

    exact: dict[str, dict[str, np.ndarray]] = {}
    foreign: dict[str, _Foreign] = {}
    edited: dict[str, dict[str, tuple]] = {}  # ext -> kind -> (wkb, columns, source)
    reports: dict[str, _EditReport] = {}
    order: list[str] = list(header["layers"]) if header and chosen is None else []
    layer_crs = None
    for src, ext, kind in plan:
        meta, wkb, columns = _read_layer(src)
        if layer_crs is None and wkb is not None and isinstance(meta.get("crs"), str):
            layer_crs = meta["crs"]
        if ext not in order:
            order.append(ext)
        if kind in _EXACT:
            tables = exact.setdefault(ext, {})
            if kind in tables:
                raise FormatError(
                    f"a second {kind} layer for map layer {ext}", src.dataset, _rec(src.name)
                )
            report = reports.setdefault(ext, _EditReport())
            code0 = opts["default_code"] if opts["default_code"] is not None else 0
            tables[kind] = _exact_table(kind, wkb, columns, src, code0, report)
        elif kind in ("lines", "areas") and ext in exact_lines:
            kinds = edited.setdefault(ext, {})
            if kind in kinds:
                raise FormatError(
                    f"a second {kind} layer for map layer {ext}", src.dataset, _rec(src.name)
                )
            kinds[kind] = (wkb, columns, src)
        else:
            _foreign_layer(wkb, columns, src, foreign.setdefault(ext, _Foreign()), opts)
        done += 1
        if progress:
            progress(done, total)

    if header is not None:
        map_id, scale, map_crs = header["id"], header["scale"], header["crs"]
        notes = header["notes"]
    else:
        (only,) = prefixes if len(prefixes) == 1 else (None,)
        stem = only if only is not None else default_id
        map_id, scale, map_crs, notes = _default_id(stem), None, _known_crs(layer_crs), ""
    if crs is not None:
        map_crs = crs
    try:
        m = MapFile(check_map_id(map_id), scale=scale, crs=map_crs, notes=notes)
    except ValueError as exc:
        raise FormatError(f"map header: {exc}", path=path) from None

    for ext in order:
        tables = exact.get(ext, {})
        lp = tables.get("line_points")
        relinks: list = []
        report = reports.setdefault(ext, _EditReport())
        if ext in edited and lp is not None:
            acc = _Foreign()
            lp, relinks = _line_edits(lp, ext, edited[ext], opts, acc, report)
            if acc.lines or acc.symbols or acc.texts:
                more = foreign.setdefault(ext, _Foreign())
                for name in ("symbols", "texts", "lines", "line_codes", "line_closed"):
                    getattr(more, name)[:0] = getattr(acc, name)  # the map's own lines first
        lay = Layer.from_arrays(
            ext,
            symbols=tables.get("symbols"),
            line_points=lp,
            texts=tables.get("texts"),
        )
        imported = foreign.get(ext)
        if imported is not None:
            lay = _add_foreign(lay, imported, tolerance_m, path, m.crs)
        if relinks:
            lay = _relink(lay, relinks, report)
        if report.parts:
            warn(log, f"{path}: layer {ext}: edits taken: {report.message()}", "edited")
        m.add_layer(lay)
    return m


def _known_crs(crs):
    """The CRS GDAL reports for a layer, or None for the "unknown" CRS apygis writes
    into a GeoJSON of a map without one (GDAL would otherwise assume WGS 84)."""
    if not isinstance(crs, str):
        return None
    head = crs.lstrip().upper()
    if head.startswith(("LOCAL_CS", "ENGCRS", "ENGCS")) and "UNKNOWN" in head[:40]:
        return None
    return crs


def _head(p: Path, n: int) -> bytes:
    try:
        with open(p, "rb") as fh:
            return fh.read(n)
    except OSError:
        return b""


def _probe_gpkg(path) -> bool:
    p = Path(path)
    if not p.is_file():
        return False
    head = _head(p, 72)
    return head.startswith(b"SQLite format 3\0") and head[68:72] in (b"GPKG", b"GP10", b"GP11")


def _probe_set(path, fmt: _Format, content: Callable[[Path], bool]) -> bool:
    p = Path(path)
    if p.is_file():
        return content(p)
    if p.is_dir():
        return any(q.is_file() and q.suffix[1:].lower() in fmt.extensions for q in p.iterdir())
    if p.suffix[1:].lower() in fmt.extensions and p.parent.is_dir():
        return bool(_member_files(p.parent, fmt, p.stem))
    return False


def _is_shp(p: Path) -> bool:
    head = _head(p, 4)
    if head == b"\x00\x00\x27\x0a":
        return True
    if p.suffix[1:].lower() in _SHP.containers and head.startswith(b"PK"):
        import zipfile

        try:
            with zipfile.ZipFile(p) as z:
                return any(n.lower().endswith(".shp") for n in z.namelist())
        except (zipfile.BadZipFile, OSError, ValueError):
            return False
    return False


def _is_geojson(p: Path) -> bool:
    head = _head(p, 4096).lstrip(b"\xef\xbb\xbf \t\r\n")
    return head.startswith(b"{") and (b'"FeatureCollection"' in head or b'"Feature"' in head)


def _is_fgb(p: Path) -> bool:
    head = _head(p, 8)
    return len(head) == 8 and head[:3] == b"fgb" and head[4:7] == b"fgb"


def _driver(fmt: _Format, description: str, probe: Callable) -> Driver:
    def reader(path, **options):
        return read(path, fmt, **options)

    def writer(map_, path, **options):
        return write(map_, path, fmt, **options)

    def outs(map_, path):
        return outputs(map_, path, fmt)

    def set_members(path):
        return members(path, fmt)

    reader.__doc__ = f"Read a map from {fmt.ogr} (see :func:`apygis.formats.ogr.read`)."
    writer.__doc__ = f"Write a map as {fmt.ogr} (see :func:`apygis.formats.ogr.write`)."
    read_opts = tuple(
        READ_OPTIONS[k]
        for k in (
            "layers",
            "layer_map",
            "tolerance_m",
            "crs",
            "code_field",
            "default_code",
            "text_field",
            "point_code",
        )
    )
    write_opts: tuple[Option, ...] = ()
    if fmt.multi:
        write_opts = (
            Option("version", "w", "choice", "GeoPackage version", choices=("1.2", "1.3", "1.4")),
            Option("spatial_index", "w", "bool", "an R-tree index per spatial layer (default YES)"),
            Option("styles", "w", "bool", "QGIS styles in layer_styles (default YES)"),
        )
    return Driver(
        name=fmt.name,
        description=description,
        extensions=fmt.extensions,  # zipped Shapefiles are recognised by content
        reader=reader,
        writer=writer,
        probe=probe,
        outputs=outs,
        members=None if fmt.multi else set_members,
        options=read_opts + write_opts,
    )


GPKG = _driver(_GPKG, "GeoPackage: every layer in one file (docs/formats/ogr.md)", _probe_gpkg)


SHP = _driver(
    _SHP,
    "ESRI Shapefile: one .shp set per OGR layer in a directory (docs/formats/ogr.md)",
    lambda p: _probe_set(p, _SHP, _is_shp),
)


GEOJSON = _driver(
    _GEOJSON,
    "GeoJSON: one file per OGR layer in a directory (docs/formats/ogr.md)",
    lambda p: _probe_set(p, _GEOJSON, _is_geojson),
)


FGB = _driver(
    _FGB,
    "FlatGeobuf: one file per OGR layer in a directory (docs/formats/ogr.md)",
    lambda p: _probe_set(p, _FGB, _is_fgb),
)
