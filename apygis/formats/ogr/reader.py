"""Reading OGR layers (see :func:`apygis.formats.ogr.read`).

The sources a path names (a file, a folder, a set ``dir/NAME.<ext>``), one
layer's columns through pyogrio, the exact schema (``L_symbols``, ``L_texts``,
``L_line_points``: record for record, features a GIS drew numbered anew), the
header table, and foreign data: points, lines and polygon rings collected in a
:class:`_Foreign` and added through the model's one rebuild,
:meth:`apygis.model.Layer.add_polylines`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from apygis.errors import FormatError
from apygis.formats._report import warn
from apygis.formats.ogr._common import (
    _codes,
    _field,
    _gdal,
    _int_column,
    _null_mask,
    _rec,
    _require,
    _Source,
    _texts,
    log,
)
from apygis.formats.ogr.schema import SCHEMA_VERSION, _Format, _member_files, _parse_name
from apygis.formats.ogr.wkb import _from_wkb, _point_coords
from apygis.model.map import Layer, check_ext
from apygis.model.polylines import to_csr
from apygis.model.records import (
    LINE_DTYPE,
    MAX_CODE,
    REF_FIELDS,
    SYMBOL_DTYPE,
    TEXT_DTYPE,
    next_numbers,
)
from apygis.model.symbols import SPOT_HEIGHT

if TYPE_CHECKING:  # edits.py imports this module
    from apygis.formats.ogr.edits import _EditReport


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
        only = next(iter(prefixes), None)  # at most one here
        default_id = only if only is not None else p.name
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


def _foreign_codes(columns: dict, n: int, src: _Source, opts: dict):
    """The code of each of ``n`` features from ``code_field``, and a mask of those without.

    NULL or no such field: no code. A value outside 0-99 takes ``default_code``
    (counted and reported) or, without it, is refused naming the feature.
    """
    name = opts["code_field"]
    col = _field(columns, name)
    missing = np.ones(n, dtype=bool)
    codes = np.zeros(n, dtype=np.int64)
    if col is None:
        return codes, missing
    null = _null_mask(col)
    vals = _int_column(col, name, src, nullable=True)
    bad = ~null & ((vals < 0) | (vals > MAX_CODE))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        default = opts["default_code"]
        if default is None:
            raise FormatError(
                f"feature {k + 1}: {name} {vals[k]} is not a code 0-99 (give a default code "
                "for such features, or name another code field)",
                src.dataset,
                _rec(src.name),
            )
        warn(
            log,
            f"{src.dataset}: layer {src.name}: {int(bad.sum())} features have {name} outside "
            f"0-99 (e.g. {vals[k]}): given the default code {default}",
            "recoded",
            int(bad.sum()),
            src.name,
        )
        vals = np.where(bad, default, vals)
    codes[~null] = vals[~null]
    missing = null
    return codes, missing


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
    codes, missing = _foreign_codes(columns, len(geoms), src, opts)
    default = opts["default_code"]
    if default is not None:
        codes = np.where(missing, default, codes)
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
            pcodes = codes[feat[pts]].copy()
            if default is None:  # no code: a spot height where a height is known
                none = missing[feat[pts]]
                pcodes[none] = np.where(xyz[none, 2] != 0, SPOT_HEIGHT, opts["point_code"])
            acc.symbols.append((xyz, pcodes.astype(np.int16)))

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
    """Coordinates of geometries from :func:`_from_wkb` (which checked every one), with
    the NaN z of 2-D geometries as 0."""
    xyz = np.array(xyz, dtype=float).reshape(-1, 3)
    xyz[:, 2] = np.where(np.isnan(xyz[:, 2]), 0.0, xyz[:, 2])
    return xyz


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
            text = f"{path}: layer {lay.ext}: lines rebuilt: {rep.message()}"
            if rep.refused or rep.duplicates_removed or rep.empty:
                warn(log, text, "rebuilt", None, "lines")
            else:
                log.info("%s", text)
    except FormatError:
        raise
    except (ValueError, TypeError) as exc:  # a bad tolerance_m, a record the model refuses
        raise FormatError(f"layer {lay.ext}: {exc}", path=path) from None
    return lay
