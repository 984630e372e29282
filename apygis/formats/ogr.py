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
:func:`_line_edits` and docs/formats/ogr.md, "Edited files").

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
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import shutil
import string
import struct
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from apygis.errors import DriverError, FormatError
from apygis.formats import Driver
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
from apygis.formats._readguard import MAX_COORD, bad_coord_rows
from apygis.model.map import Layer, MapFile, check_ext, check_map_id, check_text, crs_string
from apygis.model.polylines import to_csr
from apygis.model.records import (
    LINE_DTYPE,
    MAX_CODE,
    NO_REF,
    REF_FIELDS,
    SYMBOL_DTYPE,
    TEXT_DTYPE,
    next_numbers,
)

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

log = logging.getLogger(__name__)

SCHEMA_VERSION = 1
"""Version of the schema in ``docs/formats/ogr.md`` (the ``apygis`` field of ``apygis_map``)."""

MAP_TABLE = "apygis_map"
"""Name of the header table (prefixed ``<prefix>_`` in the single-layer formats)."""

KINDS = ("symbols", "lines", "areas", "texts", "line_points")
"""OGR layer kinds per map layer, in the order they are written."""

_EXACT = ("symbols", "texts", "line_points")
_NAME_RE = re.compile(
    r"^(?:(?P<prefix>.+)_)?(?P<ext>[a-z]{1,3})_(?P<kind>symbols|lines|areas|texts|line_points)$"
)
_MAP_RE = re.compile(r"^(?:(?P<prefix>.+)_)?apygis_map$")
_ID_BAD = re.compile(r"[^A-Za-z0-9_-]")

# ISO WKB geometry type codes (Z variants)
_WKB_POINT_Z, _WKB_LINESTRING_Z, _WKB_POLYGON_Z = 1001, 1002, 1003
_POINT_WKB = np.dtype([("order", "u1"), ("type", "<u4"), ("xyz", "<f8", 3)])  # 29 bytes
_POINT_HEADERS = (b"\x01\xe9\x03\x00\x00", b"\x01\x01\x00\x00\x80")  # ISO, EWKB Point Z

_DBF_BYTES = 254  # longest string a DBF field holds
_SHP_CHUNK = 60  # characters per header row in a Shapefile (<= 240 bytes of UTF-8)
_SHP_SIDECARS = ("shp", "shx", "dbf", "prj", "cpg", "qix", "sbn", "sbx")


# --------------------------------------------------------------------------- formats


@dataclass(frozen=True)
class _Format:
    """What differs between the four OGR formats."""

    name: str
    ogr: str
    extensions: tuple[str, ...]
    multi: bool  # one file holds every OGR layer (GeoPackage)
    layer_options: dict = field(default_factory=dict)
    containers: tuple[str, ...] = ()  # multi-layer files this driver also reads (zip)

    @property
    def ext(self) -> str:
        return self.extensions[0]


_GPKG = _Format("gpkg", "GPKG", ("gpkg",), multi=True)
_SHP = _Format("shp", "ESRI Shapefile", ("shp",), multi=False, containers=("shz", "zip"))
# 17 significant digits: every float64 comes back bit for bit (GDAL writes 15 decimals)
_GEOJSON = _Format(
    "geojson",
    "GeoJSON",
    ("geojson", "json"),
    multi=False,
    layer_options={"SIGNIFICANT_FIGURES": "17"},
)
# no spatial index: it would reorder the features (and refuses NULL geometries)
_FGB = _Format("fgb", "FlatGeobuf", ("fgb",), multi=False, layer_options={"SPATIAL_INDEX": "NO"})
_FORMATS = {f.name: f for f in (_GPKG, _SHP, _GEOJSON, _FGB)}


def _fmt(name) -> _Format:
    if isinstance(name, _Format):
        return name
    try:
        return _FORMATS[str(name).lower()]
    except KeyError:
        raise DriverError(f"no OGR format named {name!r}; known: {', '.join(_FORMATS)}") from None


# --------------------------------------------------------------------------- pyogrio guards


@contextlib.contextmanager
def _quiet():
    """Turn pyogrio's and GDAL's warnings into log records (the library never warns on stdout)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    for w in caught:
        log.debug("pyogrio: %s", w.message)


def _gdal(call: Callable, what: str, path, layer: str | None = None, error=FormatError):
    """Run a pyogrio call; every exception it raises becomes ``error`` (a FormatError)."""
    try:
        with _quiet():
            return call()
    except FormatError:
        raise
    except MemoryError:
        raise error(f"{what}: out of memory", path=path, record=_rec(layer)) from None
    except Exception as exc:  # pyogrio.errors.*, RuntimeError, ValueError, OSError, ...
        msg = str(exc).strip() or type(exc).__name__
        raise error(f"{what}: {msg}", path=path, record=_rec(layer)) from None


class _WriteError(FormatError):
    """Internal: GDAL failed while writing (re-raised as DriverError by :func:`write`)."""


def _rec(layer: str | None) -> str | None:
    return None if layer is None else f"layer {layer}"


# --------------------------------------------------------------------------- WKB


def _points_wkb(xyz: np.ndarray) -> np.ndarray:
    """ISO WKB Point Z of every row of ``xyz`` (n, 3), as an object array of bytes."""
    rec = np.empty(len(xyz), _POINT_WKB)
    rec["order"] = 1
    rec["type"] = _WKB_POINT_Z
    rec["xyz"] = xyz
    out = np.empty(len(xyz), dtype=object)
    if len(xyz):
        out[:] = np.frombuffer(rec.tobytes(), f"V{_POINT_WKB.itemsize}").tolist()
    return out


def _lines_wkb(coords: np.ndarray, offsets: np.ndarray, closed: bool) -> np.ndarray:
    """ISO WKB LineString Z (or Polygon Z of one ring, repeating the first vertex)."""
    out = np.empty(len(offsets) - 1, dtype=object)
    head_line = struct.Struct("<BII")
    head_poly = struct.Struct("<BIII")
    for k in range(len(out)):
        a, b = int(offsets[k]), int(offsets[k + 1])
        pts = coords[a:b]
        if closed:
            out[k] = (
                head_poly.pack(1, _WKB_POLYGON_Z, 1, b - a + 1) + pts.tobytes() + pts[0].tobytes()
            )
        else:
            out[k] = head_line.pack(1, _WKB_LINESTRING_Z, b - a) + pts.tobytes()
    return out


def _point_coords(wkb: np.ndarray, path, layer: str) -> np.ndarray:
    """(n, 3) coordinates of a column of WKB points; Z missing -> 0. Raises FormatError.

    Fast path: every value is a 29-byte little-endian Point Z (ISO or EWKB
    type code), decoded as one structured array; anything else goes through
    shapely.
    """
    n = len(wkb)
    if n == 0:
        return np.zeros((0, 3))
    try:
        lengths = np.fromiter(map(len, wkb), dtype=np.int64, count=n)
        blob = b"".join(wkb)
    except TypeError:  # a NULL geometry
        lengths, blob = None, b""
    if lengths is not None and (lengths == _POINT_WKB.itemsize).all():
        heads = np.frombuffer(blob, "u1").reshape(n, _POINT_WKB.itemsize)[:, :5]
        for h in _POINT_HEADERS:
            if (heads == np.frombuffer(h, "u1")).all():
                xyz = np.frombuffer(blob, _POINT_WKB)["xyz"].astype(np.float64)
                _check_finite(xyz, path, layer)
                return xyz
    return _point_coords_slow(wkb, path, layer)


def _point_coords_slow(wkb: np.ndarray, path, layer: str) -> np.ndarray:
    import shapely

    geoms = _from_wkb(wkb, path, layer)
    for k, g in enumerate(geoms):
        if g is None:
            raise FormatError(
                f"feature {k + 1} has no geometry; expected a point", path, _rec(layer)
            )
    bad = (shapely.get_type_id(geoms) != 0) | shapely.is_empty(geoms)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise FormatError(
            f"feature {k + 1} is {'an empty' if geoms[k].is_empty else 'a'} {geoms[k].geom_type}; "
            "expected a point",
            path,
            _rec(layer),
        )
    xyz = shapely.get_coordinates(geoms, include_z=True)
    xyz[:, 2] = np.where(np.isnan(xyz[:, 2]), 0.0, xyz[:, 2])
    _check_finite(xyz, path, layer)
    return xyz


def _from_wkb(wkb: np.ndarray, path, layer: str) -> np.ndarray:
    import shapely

    try:
        with _quiet():
            geoms = shapely.from_wkb(wkb, on_invalid="raise")
    except Exception as exc:  # shapely.errors.GEOSException, TypeError
        raise FormatError(f"unreadable geometry: {exc}", path, _rec(layer)) from None
    # every coordinate of every geometry, before any of it reaches the model or scipy
    # (a 2-D geometry's z comes back as NaN: only a 3-D one's z must be a number)
    xyz, which = shapely.get_coordinates(geoms, include_z=True, return_index=True)
    z = xyz[:, 2]
    bad = np.zeros(len(xyz), bool)
    bad[bad_coord_rows(xyz[:, :2])] = True
    with np.errstate(invalid="ignore"):
        bad |= np.abs(z) > MAX_COORD
    bad |= np.isnan(z) & shapely.has_z(geoms)[which]
    rows = np.flatnonzero(bad)
    if len(rows):
        k = int(which[rows[0]])
        raise FormatError(
            f"feature {k + 1}: coordinates are not finite or exceed {MAX_COORD:g} in magnitude",
            path,
            _rec(layer),
        )
    return geoms


def _check_finite(xyz: np.ndarray, path, layer: str) -> None:
    rows = bad_coord_rows(xyz)
    if len(rows):
        k = int(rows[0])
        raise FormatError(
            f"feature {k + 1}: coordinates are not finite or exceed {MAX_COORD:g} in magnitude",
            path,
            _rec(layer),
        )


# --------------------------------------------------------------------------- writing


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


def _xyz(table: np.ndarray) -> np.ndarray:
    return np.column_stack([table["x"], table["y"], table["z"]]) if len(table) else np.zeros((0, 3))


def _points_text(nums: np.ndarray, offsets: np.ndarray, limit: int | None) -> np.ndarray:
    """The point numbers of each line as ``"1,2,3"`` (cut to ``limit`` bytes with ``,...``)."""
    out = np.empty(len(offsets) - 1, dtype=object)
    all_nums = nums.tolist()
    for k in range(len(out)):
        s = ",".join(map(str, all_nums[offsets[k] : offsets[k + 1]]))
        if limit is not None and len(s) > limit:
            s = s[: limit - 4].rsplit(",", 1)[0] + ",..."
        out[k] = s
    return out


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


def _write_table(path: Path, fmt: _Format, table: _Table, crs: str | None) -> None:
    import pyogrio.raw

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
        ),
        "cannot write",
        path,
        table.name,
        error=_WriteError,
    )


def _split_target(map_: MapFile, path, fmt: _Format) -> tuple[Path, str, str]:
    """For the single-layer formats: ``(directory, prefix, file extension)``."""
    p = Path(path)
    suffix = p.suffix[1:].lower()
    if suffix in fmt.extensions and not p.is_dir():
        return p.parent, p.stem, suffix
    return p, map_.id, fmt.ext


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


def write(map_: MapFile, path, fmt="gpkg", progress=None, spatial_index: bool = True) -> list[Path]:
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

    Returns
    -------
    list of Path
    """
    fmt = _fmt(fmt)
    if fmt.multi and not spatial_index:
        fmt = replace(fmt, layer_options={**fmt.layer_options, "SPATIAL_INDEX": "NO"})
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
                    fmt,
                    tables,
                    names,
                    target.name if fmt.multi else None,
                    crs,
                    progress,
                    target.parent if fmt.multi else directory,
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


def _write_tables(
    tmp: Path, fmt: _Format, tables, names, single: str | None, crs, progress, final: Path
):
    for k, table in enumerate(tables):
        name = single if single is not None else names[table.name][0]
        dest = tmp / name
        try:
            _write_table(dest, fmt, table, crs)
        except _WriteError as exc:  # named by the target, not the temporary folder
            where = ": ".join(x for x in (str(final / name), exc.record) if x)
            raise DriverError(f"{where}: {exc.reason}") from None
        if progress:
            progress(k + 1, len(tables))


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


def _schema_files(directory: Path, prefix: str | None, fmt: _Format) -> list[Path]:
    """Every file of the schema in ``directory`` with this prefix (any prefix: None)."""
    kinds = _SHP_SIDECARS if fmt is _SHP else fmt.extensions
    out = []
    for p in sorted(directory.iterdir()):
        stem, _, suffix = p.name.rpartition(".")
        if not stem or suffix.lower() not in kinds or not p.is_file():
            continue
        parsed = _parse_name(stem)
        if parsed is not None and (prefix is None or parsed[0] == prefix):
            out.append(p)
    return out


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
        if len(prefixes) != 1 or None in prefixes:
            return None  # the reader refuses several maps; no prefix: not apygis's set
        return stamp_path(p / prefixes.pop()), files, True
    if p.suffix[1:].lower() in fmt.extensions and p.parent.is_dir():
        files = _schema_files(p.parent, p.stem, fmt)
        return stamp_path(p.parent / p.stem), files, True
    return None


# --------------------------------------------------------------------------- reading: sources


@dataclass(frozen=True)
class _Source:
    """One OGR layer to read: the dataset GDAL opens, the layer in it, the name we match."""

    dataset: str
    layer: str | None
    name: str
    spatial: bool = True


def _parse_name(name: str) -> tuple[str | None, str, str] | None:
    """``(prefix, ext, kind)`` of a name of the schema (``kind`` ``"map"``: the header)."""
    m = _MAP_RE.match(name)
    if m:
        return m["prefix"], "", "map"
    m = _NAME_RE.match(name)
    if m:
        return m["prefix"], m["ext"], m["kind"]
    return None


def _dataset_layers(path: Path, fmt: _Format) -> list[_Source]:
    import pyogrio

    rows = _gdal(lambda: pyogrio.list_layers(str(path)), "not a readable GIS file", path)
    try:
        layers = [(str(r[0]), r[1] is not None) for r in rows]
    except (TypeError, IndexError):
        raise FormatError("GDAL listed no layers", path=path) from None
    if not layers:
        raise FormatError(f"no layers: nothing to read as {fmt.ogr}", path=path)
    if fmt.multi or path.suffix[1:].lower() in fmt.containers:
        return [_Source(str(path), n, n, spatial) for n, spatial in layers]
    name, spatial = layers[0]
    return [_Source(str(path), name, path.stem, spatial)]


def _member_files(directory: Path, fmt: _Format, prefix: str | None) -> list[Path]:
    exts = set(fmt.extensions)
    files = []
    for p in sorted(directory.iterdir()):
        stem, _, suffix = p.name.rpartition(".")
        if not stem or not p.is_file():
            continue
        suffix = suffix.lower()
        parsed = _parse_name(stem)
        member = suffix in exts or (
            fmt is _SHP and suffix == "dbf" and parsed is not None and parsed[2] == "map"
        )
        if member and (prefix is None or (parsed is not None and parsed[0] == prefix)):
            files.append(p)
    return files


def _sources(path, fmt: _Format) -> tuple[list[_Source], str]:
    """The OGR layers to read for ``path`` and a default map ID."""
    p = Path(path)
    if p.is_file():
        return _dataset_layers(p, fmt), p.stem.split(".")[0]
    if fmt.multi:
        what = "is a directory, not a file" if p.is_dir() else "no such file"
        raise FormatError(what, path=p)
    if p.is_dir():
        files = _member_files(p, fmt, None)
        prefixes = {parsed[0] for f in files if (parsed := _parse_name(f.stem))}
        if len(prefixes) > 1:
            names = ", ".join(sorted(str(x) for x in prefixes))
            raise FormatError(
                f"holds the files of several maps ({names}); read one of them as "
                f"{p / ('NAME.' + fmt.ext)}",
                path=p,
            )
        default_id = next(iter(prefixes)) if prefixes and None not in prefixes else p.name
        if not files:
            raise FormatError(f"no {fmt.ogr} files ({'/'.join(fmt.extensions)}) here", path=p)
    else:
        named_set = p.suffix[1:].lower() in fmt.extensions and p.parent.is_dir()
        files = _member_files(p.parent, fmt, p.stem) if named_set else []
        if not files:
            raise FormatError(f"no such file, nor files {p.stem}_*.{fmt.ext} of a map", path=p)
        default_id = p.stem
    out = []
    for f in files:
        out += _dataset_layers(f, fmt)
    return out, default_id


# --------------------------------------------------------------------------- reading: columns


def _check_declared_count(src: _Source) -> None:
    """Refuse a FlatGeobuf whose header claims more features than its bytes can hold.

    FlatGeobuf is the one format here whose header states the feature count,
    and GDAL sizes its buffers from it: a damaged header claiming two billion
    features in a 2 KB file made GDAL allocate 23 GB. Every feature takes at
    least its 4-byte length prefix, so a count above ``size / 4`` is a lie.
    (GeoPackage counts rows, Shapefile derives its count from the file length,
    GeoJSON parses: none of them trusts a header.)
    """
    import pyogrio

    if not src.dataset.lower().endswith(".fgb"):
        return
    info = _gdal(
        lambda: pyogrio.read_info(src.dataset, layer=src.layer, force_feature_count=False),
        "cannot read",
        src.dataset,
        src.name,
    )
    count = info.get("features") if isinstance(info, dict) else None
    size = os.path.getsize(src.dataset)
    if isinstance(count, int) and count > size // 4:
        raise FormatError(
            f"the header claims {count} features, but the file has only {size} bytes: "
            "the file is damaged",
            src.dataset,
            _rec(src.name),
        )


def _read_layer(src: _Source):
    """``(meta, wkb or None, {field: array})`` of one OGR layer."""
    import pyogrio.raw

    _check_declared_count(src)

    def call():
        return pyogrio.raw.read(src.dataset, layer=src.layer)

    result = _gdal(call, "cannot read", src.dataset, src.name)
    try:
        meta, _, wkb, data = result
        fields = [str(f) for f in meta["fields"]]
        columns = dict(zip(fields, data, strict=True))
    except (TypeError, ValueError, KeyError) as exc:
        raise FormatError(
            f"unexpected layer structure ({exc})", src.dataset, _rec(src.name)
        ) from None
    if wkb is not None and len(columns) and any(len(c) != len(wkb) for c in columns.values()):
        raise FormatError("columns of unequal length", src.dataset, _rec(src.name))
    return meta, wkb, columns


def _field(columns: dict, name: str | None):
    if name is None:
        return None
    if name in columns:
        return columns[name]
    low = name.lower()
    for k, v in columns.items():
        if k.lower() == low:
            return v
    return None


def _int_column(values, name: str, src: _Source, nullable: bool = False) -> np.ndarray:
    """An integer column; NULL is -1 where ``nullable``, else an error."""
    a = np.asarray(values)
    if a.dtype.kind in "iu":
        if a.dtype.kind == "u" and len(a) and a.max() > np.iinfo(np.int64).max:
            raise FormatError(f"field {name}: value out of range", src.dataset, _rec(src.name))
        return a.astype(np.int64)
    if a.dtype.kind == "f":
        null = np.isnan(a)
        with np.errstate(invalid="ignore"):
            bad = ~null & (~np.isfinite(a) | (a != np.round(a)) | (np.abs(a) > 2.0**62))
        if null.any() and not nullable:
            bad |= null
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise FormatError(
                f"feature {k + 1}: field {name} is {a[k]!r}, expected an integer",
                src.dataset,
                _rec(src.name),
            )
        return np.where(null, NO_REF, np.nan_to_num(a)).astype(np.int64)
    if a.dtype.kind == "O":
        out = np.empty(len(a), dtype=np.int64)
        for k, v in enumerate(a):
            iv = _as_int(v)
            if iv is None and nullable and v is None:
                iv = NO_REF
            if iv is None:
                raise FormatError(
                    f"feature {k + 1}: field {name} is {v!r}, expected an integer",
                    src.dataset,
                    _rec(src.name),
                )
            out[k] = iv
        return out
    raise FormatError(f"field {name} is not an integer field", src.dataset, _rec(src.name))


def _as_int(v) -> int | None:
    if isinstance(v, (bool, np.bool_)):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v) if abs(int(v)) <= 2**62 else None
    if isinstance(v, (float, np.floating)) and np.isfinite(v) and float(v).is_integer():
        return int(v) if abs(v) <= 2.0**62 else None
    if isinstance(v, str):
        try:
            return _as_int(int(v.strip()))
        except ValueError:
            return None
    return None


def _codes(values, name: str, src: _Source, default: int | None = None) -> np.ndarray:
    codes = _int_column(values, name, src, nullable=default is not None)
    if default is not None:
        codes = np.where(_null_mask(values), default, codes)
    bad = (codes < 0) | (codes > MAX_CODE)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise FormatError(
            f"feature {k + 1}: {name} {codes[k]} is outside 0-{MAX_CODE}",
            src.dataset,
            _rec(src.name),
        )
    return codes.astype(np.int16)


def _null_mask(values) -> np.ndarray:
    a = np.asarray(values)
    if a.dtype.kind == "f":
        return np.isnan(a)
    if a.dtype.kind == "O":
        return np.array([v is None for v in a], dtype=bool)
    return np.zeros(len(a), dtype=bool)


def _texts(values, name: str, src: _Source) -> np.ndarray:
    out = np.empty(len(values), dtype=TEXT_DTYPE["text"])
    for k, v in enumerate(values):
        if v is None:
            v = ""
        elif not isinstance(v, str):
            if isinstance(v, (bytes, bytearray)):
                raise FormatError(
                    f"feature {k + 1}: field {name} is binary, expected a text",
                    src.dataset,
                    _rec(src.name),
                )
            v = str(v)
        try:
            out[k] = check_text(v)
        except ValueError as exc:
            raise FormatError(f"feature {k + 1}: {exc}", src.dataset, _rec(src.name)) from None
    return out


def _require(columns: dict, names, src: _Source) -> list:
    out = []
    for n in names:
        col = _field(columns, n)
        if col is None:
            raise FormatError(
                f"field {n} is missing (a layer named like {src.name} follows the apygis schema, "
                "docs/formats/ogr.md)",
                src.dataset,
                _rec(src.name),
            )
        out.append(col)
    return out


def _exact_table(
    kind: str,
    wkb,
    columns: dict,
    src: _Source,
    default_code: int = 0,
    report: _EditReport | None = None,
) -> np.ndarray:
    """An apygis table (symbols, texts, line_points) from its OGR layer, record for record.

    In ``L_symbols`` and ``L_texts`` a feature with ``num`` NULL (drawn in a
    GIS) gets a new number, a NULL code there ``default_code``; a number used
    by an earlier feature too (a feature copied in a GIS) stays with the
    earlier one, the later gets a new number. Both go to ``report``.
    """
    if wkb is None:
        raise FormatError("the layer has no geometry", src.dataset, _rec(src.name))
    xyz = _point_coords(wkb, src.dataset, src.name)
    plain = kind != "line_points"
    if kind == "symbols":
        num, code = _require(columns, ("num", "code"), src)
        new = _null_mask(num)
        null_code = _null_mask(code) & new
        if null_code.any():
            code = np.asarray(code, dtype=object).copy()
            code[null_code] = default_code
        t = np.zeros(len(xyz), SYMBOL_DTYPE)
        t["code"] = _codes(code, "code", src)
    elif kind == "texts":
        num, text = _require(columns, ("num", "text"), src)
        new = _null_mask(num)
        t = np.zeros(len(xyz), TEXT_DTYPE)
        t["text"] = _texts(text, "text", src)
    else:
        num, code, *refs = _require(columns, ("num", "code", *REF_FIELDS), src)
        t = np.zeros(len(xyz), LINE_DTYPE)
        t["code"] = _codes(code, "code", src)
        for r, col in zip(REF_FIELDS, refs, strict=True):
            t[r] = _int_column(col, r, src, nullable=True)
    nums = _int_column(num, "num", src, nullable=plain)
    if plain:
        _number_new(nums, new, src, report)
    t["num"] = nums
    t["x"], t["y"], t["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    return t


def _number_new(nums: np.ndarray, new: np.ndarray, src: _Source, report) -> None:
    """Number (in place) features without a number and later copies of a number in use."""
    word = "symbol" if src.name.endswith("symbols") else "text"
    if new.any():
        nums[new] = next_numbers(nums[~new], int(new.sum()))
        if report is not None:
            report.add(src.name, int(new.sum()), word, "added", _numbered(nums[new]))
    order = np.argsort(nums, kind="stable")
    repeat = np.zeros(len(nums), dtype=bool)
    repeat[order[1:]] = nums[order][1:] == nums[order][:-1]
    if repeat.any():
        old = nums[repeat].copy()
        nums[repeat] = next_numbers(nums, int(repeat.sum()))
        if report is not None:
            shown = zip(old[:5], nums[repeat][:5], strict=True)
            pairs = ", ".join(f"{a} -> {b}" for a, b in shown)
            more = ", ..." if len(old) > 5 else ""
            report.add(
                src.name,
                int(repeat.sum()),
                word,
                f"renumbered (a number an earlier feature has: {pairs}{more})",
            )


def _numbered(nums: np.ndarray) -> str:
    shown = ", ".join(str(int(v)) for v in nums[:5])
    return f"numbered {shown}{', ...' if len(nums) > 5 else ''}"


# --------------------------------------------------------------------------- reading: edits


@dataclass
class _EditReport:
    """What a read took from a GIS user's edits of one map layer; logged as one message."""

    parts: dict = field(default_factory=dict)  # OGR layer name (or "") -> phrases

    def add(self, source: str, n: int, noun: str, how: str, detail: str = "") -> None:
        if n:
            words = f"{n} {noun if n == 1 else noun + 's'} {how}"
            self.parts.setdefault(source, []).append(f"{words} ({detail})" if detail else words)

    def message(self) -> str:
        return "; ".join(
            ", ".join(ph) + (f" (from {src})" if src else "") for src, ph in self.parts.items()
        )


# agreement of a line feature's vertices with its line points: float64 noise, no more
_AGREE_RTOL, _AGREE_ATOL = 1e-12, 1e-9


def _parse_points(value, k: int, src: _Source) -> tuple[tuple[int, ...], bool]:
    """The point numbers of a ``points`` value and whether it was cut (``,...``)."""
    if not isinstance(value, str):
        value = str(value)
    s = value.strip()
    cut = s.endswith("...")
    if cut:
        s = s[:-3].rstrip().rstrip(",")
    try:
        nums = tuple(int(v) for v in s.split(","))
    except ValueError:
        raise FormatError(
            f"feature {k + 1}: field points is {value!r}, expected point numbers like "
            "'12,13,14' (or NULL for a new line)",
            src.dataset,
            _rec(src.name),
        ) from None
    return nums, cut


def _line_edits(
    lp: np.ndarray, ext: str, feats: dict, opts: dict, acc: _Foreign, report: _EditReport
) -> tuple[np.ndarray, list]:
    """Take the edits of ``L_lines`` / ``L_areas`` against ``L_line_points``.

    ``feats`` maps ``"lines"`` / ``"areas"`` to ``(wkb, columns, source)``.
    A feature whose ``points`` name a line of ``lp`` and whose code and
    vertices agree with it keeps that line's rows; the rows of lines whose
    feature is gone or differs are dropped; changed and new features go to
    ``acc`` (rebuilt by ``Layer.add_polylines``). Returns the rows kept and the branch
    ends whose junction was dropped: ``(num, "fwd" | "back", junction xyz)``.
    """
    from apygis.model.polylines import export_lines

    ls = export_lines(Layer.from_arrays(ext, line_points=lp))
    lengths = np.diff(ls.offsets)
    texts = _points_text(ls.nums, ls.offsets, None)
    has_feature = {"lines": ~ls.closed & (lengths >= 2), "areas": ls.closed.copy()}
    covered = np.zeros(len(ls), dtype=bool)
    kept = np.zeros(len(ls), dtype=bool)
    claimed = np.zeros(len(ls), dtype=bool)
    replaced = np.zeros(len(ls), dtype=bool)
    line_of = np.repeat(np.arange(len(ls)), lengths)
    schema_opts = {**opts, "code_field": "code", "text_field": None}
    later = []  # (kind, feature, nums): features whose points name no line of lp exactly
    for kind in ("lines", "areas"):
        if kind not in feats:  # no such OGR layer: those lines stay as lp has them
            continue
        wkb, columns, src = feats[kind]
        if wkb is None:
            raise FormatError("the layer has no geometry", src.dataset, _rec(src.name))
        idx = np.flatnonzero(has_feature[kind])
        covered[idx] = True
        by_text = {texts[k]: int(k) for k in idx}
        by_first: dict[int, list[int]] = {}
        geoms = np.asarray(_from_wkb(wkb, src.dataset, src.name), dtype=object)
        pcol = _field(columns, "points")
        if pcol is None:
            log.warning(
                "%s: layer %s has no field points: its features are taken as new lines",
                src.dataset,
                src.name,
            )
        ccol = _field(columns, "code")
        codes = (
            _int_column(ccol, "code", src, nullable=True)
            if ccol is not None
            else np.full(len(geoms), NO_REF)
        )
        if ccol is not None:
            codes = np.where(_null_mask(ccol), NO_REF, codes)
        take = np.zeros(len(geoms), dtype=bool)
        empty = np.array([g is None or g.is_empty for g in geoms], dtype=bool)
        report.add(src.name, int(empty.sum()), "feature", "without geometry skipped")
        n_changed = n_added = 0
        for i in np.flatnonzero(~empty):
            v = None if pcol is None else pcol[i]
            if v is None or (isinstance(v, str) and not v.strip()):
                take[i] = True
                n_added += 1
                continue
            k = by_text.get(v) if isinstance(v, str) else None
            if k is None:
                nums, cut = _parse_points(v, int(i), src)
                if cut:
                    if not by_first:
                        for j in idx:
                            by_first.setdefault(int(ls.nums[ls.offsets[j]]), []).append(int(j))
                    k = next(
                        (
                            j
                            for j in by_first.get(nums[0], [])
                            if tuple(ls.nums[ls.offsets[j] : ls.offsets[j] + len(nums)]) == nums
                        ),
                        None,
                    )
                else:
                    k = by_text.get(",".join(map(str, nums)))
                if k is None:
                    later.append((kind, src, int(i), nums))
                    take[i] = True
                    continue
            if claimed[k]:  # a copy of a feature: a new line
                take[i] = True
                n_added += 1
                continue
            claimed[k] = True
            a, b = ls.offsets[k], ls.offsets[k + 1]
            if codes[i] == ls.codes[k] and _agrees(geoms[i], ls.coords[a:b], kind == "areas"):
                kept[k] = True
            else:
                take[i] = True
                n_changed += 1
        if take.any():
            sub = np.array(wkb, dtype=object)
            sub[~take] = None
            _foreign_layer(sub, columns, src, acc, schema_opts)
        report.add(src.name, n_changed, kind[:-1], "changed (topology rebuilt)")
        report.add(src.name, n_added, kind[:-1], "added")
    # points that name no line of lp exactly: a change where they name line points of a
    # line that is not kept, else new
    own_nums, own_line = ls.nums[ls.own], line_of[ls.own]
    for kind, src, _i, nums in later:
        hit = np.unique(own_line[np.isin(own_nums, nums)])
        hit = hit[covered[hit] & ~kept[hit]]
        replaced[hit] = True
        word = "changed (topology rebuilt)" if len(hit) else "added"
        report.add(src.name, 1, kind[:-1], word)
    drop_line = covered & ~kept
    gone = covered & ~claimed & ~replaced
    for kind in ("lines", "areas"):
        if kind in feats:
            n = int((gone & has_feature[kind]).sum())
            report.add(feats[kind][2].name, n, kind[:-1], "deleted")
    if not drop_line.any():
        return lp, []

    drop = np.zeros(len(lp), dtype=bool)
    drop[ls.rows[ls.own & drop_line[line_of]]] = True
    out = lp[~drop].copy()
    dropped = np.setdiff1d(lp["num"][drop], out["num"])
    rows = np.flatnonzero(drop)
    where = dict(zip(lp["num"][rows].tolist(), rows.tolist(), strict=True))
    relinks = []
    for ref in REF_FIELDS:
        hit = np.isin(out[ref], dropped)
        if ref in ("fwd", "back"):
            for r in np.flatnonzero(hit):
                j = where[int(out[ref][r])]
                if out["num"][r] in (lp["side1"][j], lp["side2"][j]):  # a branch end
                    relinks.append((int(out["num"][r]), ref, _xyz(lp[j : j + 1])[0]))
        out[ref][hit] = NO_REF
    return out, relinks


def _agrees(geom, coords: np.ndarray, closed: bool) -> bool:
    """Whether a feature's geometry has exactly the vertices ``coords`` (a ring: either way)."""
    import shapely

    tid = shapely.get_type_id(geom)
    if closed:
        if tid != 3 or shapely.get_num_interior_rings(geom) != 0:
            return False
        got = shapely.get_coordinates(shapely.get_exterior_ring(geom), include_z=True)
        if len(got) != len(coords) + 1:
            return False
        ring = np.r_[coords, coords[:1]]
        return _close(got, ring) or _close(got[::-1], ring)
    if tid not in (1, 2):
        return False
    got = shapely.get_coordinates(geom, include_z=True)
    return len(got) == len(coords) and _close(got, coords)


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.isclose(a, b, rtol=_AGREE_RTOL, atol=_AGREE_ATOL).all())


def _relink(lay: Layer, relinks: list, report: _EditReport) -> Layer:
    """Join branch ends whose junction was dropped to a line point where it was.

    A line point at the junction's place (within float64 noise) with a free
    side reference takes the end as its branch (a rebuilt line's vertex);
    where there is none, the end grows a new line point there, so the line
    still reaches it as the GIS user saw it.
    """
    from scipy.spatial import cKDTree

    from apygis.model.topology import lookup

    lp = lay.line_points.copy()
    tree = cKDTree(np.column_stack([lp["x"], lp["y"]]))
    extra = []
    joined = grown = 0
    for num, ref, xyz in relinks:
        r = int(lookup(lp["num"], np.array([num]))[0])
        reach = 2 * (_AGREE_ATOL + _AGREE_RTOL * float(np.abs(xyz[:2]).max()))
        near = np.array(sorted(tree.query_ball_point(xyz[:2], reach)), dtype=np.int64)
        near = near[near != r]
        here = near[
            np.isclose(lp["x"][near], xyz[0], rtol=_AGREE_RTOL, atol=_AGREE_ATOL)
            & np.isclose(lp["y"][near], xyz[1], rtol=_AGREE_RTOL, atol=_AGREE_ATOL)
        ]
        has_me = here[(lp["side1"][here] == num) | (lp["side2"][here] == num)]
        free = here[(lp["side1"][here] == NO_REF) | (lp["side2"][here] == NO_REF)]
        cands = has_me if len(has_me) else free
        if len(cands):
            t = int(cands[0])
            lp[ref][r] = lp["num"][t]
            if not len(has_me):
                side = "side1" if lp["side1"][t] == NO_REF else "side2"
                lp[side][t] = num
            joined += 1
            continue
        q = int(next_numbers(np.r_[lp["num"], [e["num"] for e in extra]].astype(np.int64), 1)[0])
        row = np.zeros(1, LINE_DTYPE)[0]
        row["num"] = q
        row["x"], row["y"], row["z"] = xyz
        row["code"] = lp["code"][r]
        row["fwd"] = num if ref == "back" else NO_REF
        row["back"] = num if ref == "fwd" else NO_REF
        row["side1"] = row["side2"] = NO_REF
        lp[ref][r] = q
        extra.append(row)
        grown += 1
    if extra:
        lp = np.concatenate([lp, np.array(extra, dtype=LINE_DTYPE)])
    report.add("", joined, "branch end", "joined again to its rebuilt junction")
    report.add("", grown, "branch end", "given a new line point where its junction was")
    return Layer.from_arrays(lay.ext, lay.symbols, lp, lay.texts)


# --------------------------------------------------------------------------- reading: foreign


@dataclass
class _Foreign:
    """What foreign OGR layers add to one map layer."""

    symbols: list = field(default_factory=list)  # (xyz, codes)
    texts: list = field(default_factory=list)  # (xyz, texts)
    lines: list = field(default_factory=list)  # arrays (n, 3)
    line_codes: list = field(default_factory=list)
    line_closed: list = field(default_factory=list)


def _explode(geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Single-part geometries and the feature index of each (multi-parts and collections split)."""
    import shapely

    ok = np.array([g is not None for g in geoms], dtype=bool)
    idx = np.flatnonzero(ok)
    parts = geoms[ok]
    if len(parts):
        parts = parts[~shapely.is_empty(parts)]
        idx = idx[~shapely.is_empty(geoms[ok])]
    for _ in range(8):
        tid = shapely.get_type_id(parts) if len(parts) else np.zeros(0, int)
        multi = tid >= 4
        if not multi.any():
            break
        sub, sub_idx = shapely.get_parts(parts[multi], return_index=True)
        parts = np.r_[parts[~multi], sub]
        idx = np.r_[idx[~multi], idx[multi][sub_idx]]
        keep = ~shapely.is_empty(parts)
        parts, idx = parts[keep], idx[keep]
    order = np.argsort(idx, kind="stable")
    return parts[order], idx[order]


def _foreign_layer(wkb, columns: dict, src: _Source, acc: _Foreign, opts: dict) -> None:
    import shapely

    if wkb is None:
        log.info("%s: layer %s has no geometry; skipped", src.dataset, src.name)
        return
    geoms = _from_wkb(wkb, src.dataset, src.name)
    parts, feat = _explode(np.asarray(geoms, dtype=object))
    if len(parts) == 0:
        return
    tid = shapely.get_type_id(parts)
    code_col = _field(columns, opts["code_field"])
    if code_col is not None:
        codes = _codes(code_col, opts["code_field"], src, default=opts["default_code"])
    else:
        codes = np.full(len(geoms), opts["default_code"], dtype=np.int16)
    text_col = _field(columns, opts["text_field"])
    kinds_known = np.isin(tid, (0, 1, 2, 3))
    if not kinds_known.all():
        k = int(feat[np.flatnonzero(~kinds_known)[0]])
        raise FormatError(
            f"feature {k + 1}: unsupported geometry type", src.dataset, _rec(src.name)
        )

    pts = tid == 0
    if pts.any():
        xyz = _coords3(shapely.get_coordinates(parts[pts], include_z=True), src)
        if text_col is not None:
            acc.texts.append(
                (
                    xyz,
                    _texts(np.asarray(text_col, dtype=object)[feat[pts]], opts["text_field"], src),
                )
            )
        else:
            acc.symbols.append((xyz, codes[feat[pts]]))

    lines = (tid == 1) | (tid == 2)
    polys = tid == 3
    geoms_l = parts[lines]
    feat_l = feat[lines]
    closed_l = np.zeros(len(geoms_l), dtype=bool)
    if polys.any():
        rings, ridx = shapely.get_rings(parts[polys], return_index=True)
        keep = ~shapely.is_empty(rings)
        geoms_l = np.r_[geoms_l, rings[keep]]
        feat_l = np.r_[feat_l, feat[polys][ridx[keep]]]
        closed_l = np.r_[closed_l, np.ones(int(keep.sum()), dtype=bool)]
        order = np.argsort(feat_l, kind="stable")
        geoms_l, feat_l, closed_l = geoms_l[order], feat_l[order], closed_l[order]
    if len(geoms_l):
        coords, which = shapely.get_coordinates(geoms_l, include_z=True, return_index=True)
        coords = _coords3(coords, src)
        bounds = np.r_[0, np.cumsum(np.bincount(which, minlength=len(geoms_l)))]
        for k in range(len(geoms_l)):
            acc.lines.append(coords[bounds[k] : bounds[k + 1]])
        acc.line_codes += codes[feat_l].tolist()
        acc.line_closed += closed_l.tolist()


def _coords3(xyz: np.ndarray, src: _Source) -> np.ndarray:
    xyz = np.array(xyz, dtype=float).reshape(-1, 3)
    xyz[:, 2] = np.where(np.isnan(xyz[:, 2]), 0.0, xyz[:, 2])
    _check_finite(xyz, src.dataset, src.name)
    return xyz


# --------------------------------------------------------------------------- reading: header


def _header(columns: dict, src: _Source) -> dict:
    """The map header from the ``apygis_map`` table."""
    ids = _field(columns, "id")
    if ids is None or len(ids) == 0:
        raise FormatError("the map table has no id", src.dataset, _rec(src.name))
    version = _field(columns, "apygis")
    if version is not None:
        v = _int_column(np.asarray(version)[:1], "apygis", src, nullable=True)[0]
        if v > SCHEMA_VERSION:
            raise FormatError(
                f"written in apygis OGR schema version {v}; this apygis reads version "
                f"{SCHEMA_VERSION}",
                src.dataset,
                _rec(src.name),
            )
    map_id = ids[0]
    if not isinstance(map_id, str):
        raise FormatError(f"map id {map_id!r} is not a text", src.dataset, _rec(src.name))
    scale = None
    scol = _field(columns, "scale")
    if scol is not None:
        s = _int_column(np.asarray(scol)[:1], "scale", src, nullable=True)[0]
        scale = None if _null_mask(np.asarray(scol)[:1])[0] else int(s)

    def text(name):
        col = _field(columns, name)
        if col is None:
            return None
        parts = []
        for v in col:
            if v is None:
                continue
            if not isinstance(v, str):
                raise FormatError(f"field {name} is not a text", src.dataset, _rec(src.name))
            parts.append(v)
        return "".join(parts) if parts else None

    layers = text("layers")
    exts = []
    for e in (layers or "").split(","):
        if e:
            try:
                exts.append(check_ext(e))
            except ValueError as exc:
                raise FormatError(f"field layers: {exc}", src.dataset, _rec(src.name)) from None
    return {
        "id": map_id,
        "scale": scale,
        "crs": text("crs"),
        "notes": text("notes") or "",
        "layers": exts,
    }


# --------------------------------------------------------------------------- reading: API


def _parse_layer_map(layer_map) -> dict[str, str]:
    if layer_map is None:
        return {}
    if isinstance(layer_map, str):
        pairs = {}
        for item in layer_map.split(","):
            if not item.strip():
                continue
            name, sep, ext = item.partition("=")
            if not sep:
                raise DriverError(f"layer_map: {item!r} is not NAME=EXT")
            pairs[name.strip()] = ext.strip()
        layer_map = pairs
    if not isinstance(layer_map, dict):
        raise DriverError(f"layer_map is a dict or 'NAME=EXT,...', not {layer_map!r}")
    out = {}
    for name, ext in layer_map.items():
        try:
            out[str(name)] = check_ext(ext)
        except ValueError as exc:
            raise DriverError(f"layer_map: {name}: {exc}") from None
    return out


def _fallback_exts(taken: set[str]):
    first = ["x", "y", "z"]
    more = [a + b for a in "xyz" for b in string.ascii_lowercase]
    for e in first + more:
        if e not in taken:
            yield e


def _default_id(stem: str) -> str:
    s = _ID_BAD.sub("_", stem)[:32]
    return s or "MAP"


def read(
    path,
    fmt="gpkg",
    layer_map=None,
    tolerance_m: float = 0.005,
    default_code: int = 0,
    code_field: str | None = "code",
    text_field: str | None = "text",
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
        OGR layer name -> map layer extension (``{"roads": "r"}`` or
        ``"roads=r,rivers=h"``). Default: the extension in an apygis name
        (``r_lines`` -> ``r``), else ``x``, ``y``, ``z``, ``xa``, ... in order.
    tolerance_m : float
        Distance in metres within which line ends of foreign lines join (see
        :func:`apygis.model.polylines.rebuild`).
    default_code : int
        Code of foreign points and lines without a code field (or with NULL).
    code_field, text_field : str or None
        Field names for codes and texts in foreign layers (None: not used).
    progress : callable, optional
        ``progress(done, total)`` after each OGR layer.

    Edits a GIS user made to a file apygis wrote are taken: ``L_lines`` /
    ``L_areas`` win over ``L_line_points`` (deleted, changed and new lines;
    unchanged ones keep their exact topology), ``L_symbols`` / ``L_texts``
    features without ``num`` get new numbers. What was taken is logged as one
    WARNING per map layer (docs/formats/ogr.md, "Edited files").

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
    lmap = _parse_layer_map(layer_map)
    if isinstance(default_code, bool) or not isinstance(default_code, (int, np.integer)):
        raise DriverError(f"default_code is an integer 0-{MAX_CODE}, not {default_code!r}")
    if not 0 <= default_code <= MAX_CODE:
        raise DriverError(f"default_code is 0-{MAX_CODE}, not {default_code}")
    opts = {"default_code": int(default_code), "code_field": code_field, "text_field": text_field}
    sources, default_id = _sources(path, fmt)

    # which map layer and kind each source is
    plan = []
    taken = set(lmap.values())
    for src in sources:
        parsed = _parse_name(src.name)
        if parsed is not None and parsed[2] != "map":
            taken.add(parsed[1])
    fallback = _fallback_exts(taken)
    header_src = None
    prefixes = set()
    for src in sources:
        parsed = _parse_name(src.name)
        kind = parsed[2] if parsed else None
        if kind == "map":
            header_src = header_src or src
            prefixes.add(parsed[0])
            continue
        if not src.spatial and parsed is None:
            log.info("%s: layer %s has no geometry; skipped", src.dataset, src.name)
            continue
        ext = lmap.get(src.name) or next(
            (e for n, e in lmap.items() if n.lower() == src.name.lower()), None
        )
        if ext is None:
            ext = parsed[1] if parsed else next(fallback)
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
    order: list[str] = list(header["layers"]) if header else []
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
            tables[kind] = _exact_table(kind, wkb, columns, src, opts["default_code"], report)
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
        map_id, scale, crs, notes = header["id"], header["scale"], header["crs"], header["notes"]
    else:
        stem = default_id
        if len(prefixes) == 1 and None not in prefixes:
            stem = next(iter(prefixes))
        map_id, scale, crs, notes = _default_id(stem), None, layer_crs, ""
    try:
        m = MapFile(check_map_id(map_id), scale=scale, crs=crs, notes=notes)
    except ValueError as exc:
        raise FormatError(f"map header: {exc}", path=path) from None

    for ext in order:
        tables = exact.get(ext, {})
        lp, relinks = tables.get("line_points"), []
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
        acc = foreign.get(ext)
        if acc is not None:
            lay = _add_foreign(lay, acc, tolerance_m, path, m.crs)
        if relinks:
            lay = _relink(lay, relinks, report)
        if report.parts:
            log.warning("%s: layer %s: edits taken: %s", path, ext, report.message())
        m.add_layer(lay)
    return m


def _add_foreign(lay: Layer, acc: _Foreign, tolerance_m, path, crs=None) -> Layer:
    """Foreign features into ``lay``: symbols and texts numbered anew, lines rebuilt.

    The lines go through the model's one topology rebuild (snapping
    ``tolerance_m`` metres in ``crs``'s units); its report is logged.
    """
    try:
        if acc.symbols:
            xyz = np.concatenate([a for a, _ in acc.symbols])
            lay.add_symbols(xyz, np.concatenate([c for _, c in acc.symbols]))
        if acc.texts:
            xyz = np.concatenate([a for a, _ in acc.texts])
            lay.add_texts(xyz, np.concatenate([t for _, t in acc.texts]).tolist())
        if acc.lines:
            coords, offsets = to_csr(acc.lines)
            rep = lay.add_polylines(
                coords,
                offsets,
                np.asarray(acc.line_codes, dtype=np.int64),
                np.asarray(acc.line_closed, dtype=bool),
                snap_m=tolerance_m,
                crs=crs,  # tolerance_m metres in the CRS's units (degrees for lon/lat)
            )
            say = log.warning if rep.refused or rep.duplicates_removed or rep.empty else log.info
            say("%s: layer %s: lines rebuilt: %s", path, lay.ext, rep.message())
    except FormatError:
        raise
    except (ValueError, TypeError) as exc:  # a bad tolerance_m, a record the model refuses
        raise FormatError(f"layer {lay.ext}: {exc}", path=path) from None
    return lay


# --------------------------------------------------------------------------- probes, drivers


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
    return Driver(
        name=fmt.name,
        description=description,
        extensions=fmt.extensions,  # zipped Shapefiles are recognised by content
        reader=reader,
        writer=writer,
        probe=probe,
        outputs=outs,
        members=None if fmt.multi else set_members,
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
