"""From the parsed sections and INFO tables to the model: :func:`read`."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from apygis.errors import DriverError, FormatError, RecordError
from apygis.formats._io import read_bytes
from apygis.formats._readguard import MAX_COORD, ascii_int, bad_coord_rows, loads_json
from apygis.formats._report import warn
from apygis.formats.e00._common import DEFAULT_LAYER, T_BINFLOAT, T_FIXNUM, log
from apygis.formats.e00.parse import _Table, decode
from apygis.model import topology
from apygis.model.map import MapFile, check_ext, check_map_id, check_text
from apygis.model.records import LINE_DTYPE, MAX_CODE, NO_REF
from apygis.model.symbols import IMPORTED_POINT


def rebuild_report(path, ext: str, rep, what: str = "arcs") -> None:
    """The topology rebuild's report: a warning when it refused or removed anything."""
    text = f"{path}: layer {ext}: {what} rebuilt: {rep.message()}"
    if rep.refused or rep.duplicates_removed or rep.empty:
        warn(log, text, "rebuilt", None, "lines")
    else:
        log.info("%s", text)


def _table(tables: list[_Table], suffix: str, path) -> _Table | None:
    found = [t for t in tables if t.name.upper().endswith(suffix)]
    if len(found) > 1:
        warn(
            log,
            f"{path}: {len(found)} tables *{suffix}; using {found[0].name}",
            "skipped",
            len(found) - 1,
            "INFO tables",
        )
    return found[0] if found else None


def _int_col(t: _Table, name: str, path) -> np.ndarray:
    raw, it = t.raw(name)
    raw = np.where(np.char.strip(raw) == b"", b"0", raw)
    try:
        return raw.astype(np.float64 if it[1] in (T_FIXNUM, T_BINFLOAT) else np.int64).astype(
            np.int64
        )
    except (ValueError, OverflowError):
        pass
    for k, v in enumerate(raw):
        try:
            int(v)
        except ValueError:
            _bad(t, k, it, path, "an integer", v)
    raise FormatError(f"INFO table {t.name}: item {name} out of range", path=path)


def _float_col(t: _Table, name: str, path) -> np.ndarray:
    raw, it = t.raw(name)
    raw = np.where(np.char.strip(raw) == b"", b"0", raw)
    try:
        v = raw.astype(np.float64)
        if not len(bad_coord_rows(v)):
            return v
    except ValueError:
        pass
    for k, s in enumerate(raw):
        try:
            ok = abs(float(s)) <= MAX_COORD  # False for NaN
        except ValueError:
            ok = False
        if not ok:
            _bad(t, k, it, path, f"a finite number of at most {MAX_COORD:g} in magnitude", s)
    raise AssertionError  # pragma: no cover


def _decode_text(b: bytes) -> str:
    try:
        return b.decode("utf-8")
    except UnicodeDecodeError:
        return b.decode("latin-1")


def _str_col(t: _Table, name: str, nbytes: np.ndarray | None = None) -> np.ndarray:
    """A character item as an object array of str (trailing blanks dropped, or cut to nbytes)."""
    raw, _ = t.raw(name)
    if nbytes is not None:
        return np.array(
            [_decode_text(b[: int(n)]) for b, n in zip(raw.tolist(), nbytes, strict=True)],
            dtype=object,
        )
    uniq, inv = np.unique(raw, return_inverse=True)
    words = np.array([_decode_text(b.rstrip(b" ")) for b in uniq.tolist()], dtype=object)
    return words[inv.reshape(-1)] if len(raw) else np.zeros(0, object)


def _bad(t: _Table, k: int, it, path, expected: str, found) -> None:
    line = t.first_line + k * t.lines_per_record + it[3] // 80
    raise FormatError(
        f"INFO table {t.name}, record {k + 1}, item {it[0]}: expected {expected}, "
        f"found {bytes(found).decode('latin-1')!r}",
        path=path,
        record=f"line {line}",
    )


def _need_items(t: _Table, names: tuple[str, ...]) -> bool:
    return all(t.has(n) for n in names)


_LPT_ITEMS = ("ARC#", "VERTEX", "LAYER", "NUM", "HEIGHT", "CODE", "FWD", "BACK", "SIDE1", "SIDE2")
_PAT_ITEMS = ("LAYER", "KIND", "NUM", "CODE", "HEIGHT", "TXTLEN", "TEXT")


def _meta(tables, path) -> dict[str, Any]:
    t = _table(tables, ".APYMAP", path)
    if t is None or not _need_items(t, ("KEY", "VALUE", "NBYTES")):
        return {}
    keys = _str_col(t, "KEY")
    nbytes = _int_col(t, "NBYTES", path)
    bad = (nbytes < 0) | (nbytes > 61)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(t, k, t.raw("NBYTES")[1], path, "a length 0-61", str(nbytes[k]).encode())
    raw, _ = t.raw("VALUE")
    joined: dict[str, bytes] = {}
    for k, key in enumerate(keys):
        joined[key] = joined.get(key, b"") + raw[k][: int(nbytes[k])]
    out: dict[str, Any] = {}
    for key, b in joined.items():
        what = f"INFO table {t.name}: the {key} value"
        value = loads_json(b'"' + b + b'"', what, path=path)
        if not isinstance(value, str):  # pragma: no cover - quotes around it make a string
            raise FormatError(f"{what} is not an escaped string", path=path)
        out[key] = value
    if "SCALE" in out:
        scale = ascii_int(out["SCALE"].strip())
        if scale is None:
            raise FormatError(
                f"INFO table {t.name}: the SCALE value {out['SCALE'][:40]!r} is not a "
                "whole number (digits 0-9)",
                path=path,
            )
        out["SCALE"] = scale
    return out


def _crs_from_prj(entries: list[str] | None, path):
    """The CRS of a PRJ section, as GDAL translates it; None (with a warning) if it cannot.

    The section is ESRI WKT, or ARC/INFO's keyword form (``Projection
    LAMBERT``, ``Datum``, ``Units``, ``Zone``, ``Parameters`` and their
    values: UTM, State Plane, Lambert, Albers, Transverse Mercator,
    Polyconic, geographic and the other projections of ARC/INFO). It is
    translated by GDAL's own reader of E00 coverages (AVCE00, through
    pyogrio), so that apygis and every GDAL-based GIS agree; a projection
    GDAL cannot translate gives no CRS and a warning.
    """
    if not entries:
        return None
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    first = entries[0].lstrip().upper()
    if first.startswith(("PROJCS", "GEOGCS", "GEOCCS", "COMPD_CS", "PROJCRS", "GEOGCRS")):
        try:
            return CRS.from_wkt("".join(entries))
        except CRSError as exc:
            warn(log, f"{path}: PRJ section is not a readable WKT ({exc}); no CRS", "crs")
            return None
    wkt = _gdal_prj(entries)
    if wkt is None or wkt.lstrip().upper().startswith(("LOCAL_CS", "ENGCRS", "ENGCS")):
        shown = "; ".join(" ".join(e.split()) for e in entries[:4])
        warn(log, f"{path}: PRJ section ({shown}) is not a projection GDAL knows; no CRS", "crs")
        return None
    try:
        return CRS.from_user_input(wkt)
    except CRSError as exc:  # pragma: no cover - GDAL's own WKT
        warn(log, f"{path}: the CRS of the PRJ section is not readable ({exc}); no CRS", "crs")
        return None


def _gdal_prj(entries: list[str]) -> str | None:
    """GDAL's CRS (``AUTH:CODE`` or WKT) of PRJ keyword lines, or None.

    A minimal coverage (one arc and the PRJ section) in a temporary file read
    by GDAL's AVCE00 driver, whose translation (OGRSpatialReference's
    ``importFromESRI``) is the reference every GDAL-based program uses.
    """
    import os
    import tempfile
    import warnings

    import pyogrio

    term = f"{-1:10d}" + f"{0:10d}" * 6
    arc = f"{1:10d}{1:10d}{1:10d}{1:10d}{0:10d}{0:10d}{2:10d}\n" + " 0.0000000E+00" * 2
    arc += " 1.0000000E+00" * 2
    lines = "".join(f"{e.rstrip()}\n~\n" for e in entries if "\n" not in e)
    body = f"EXP  0 /PRJ.E00\nARC  2\n{arc}\n{term}\nPRJ  2\n{lines}EOP\nEOS\n"
    with tempfile.TemporaryDirectory(prefix="apygis-prj-") as tmp:
        probe = os.path.join(tmp, "prj.e00")
        with open(probe, "w", encoding="latin-1", errors="replace") as fh:
            fh.write(body)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                crs = pyogrio.read_info(probe, layer="ARC").get("crs")
        except Exception as exc:  # GDAL could not read it: no CRS, said by the caller
            log.debug("GDAL could not read the PRJ section: %s", exc)
            return None
    return crs if isinstance(crs, str) and crs else None


def _map_from(info: dict, meta: dict, path, opts: dict) -> MapFile:
    tables = info["tables"]
    stem = re.sub(r"[^A-Za-z0-9_-]", "_", Path(path).stem if path else "E00")[:32] or "E00"
    try:
        crs = meta.get("CRS")
        if crs is None:  # the option, else the PRJ section
            crs = opts["crs"] if opts["crs"] is not None else _crs_from_prj(info["prj"], path)
        scale = meta.get("SCALE")
        mp = MapFile(check_map_id(meta.get("ID", stem)), scale=scale, crs=crs)
        mp.notes = meta.get("NOTES", "")
        layers = meta.get("LAYERS", "").split()
        for ext in layers:
            mp.layer(ext)
    except (RecordError, ValueError) as exc:
        raise FormatError(f"map metadata: {exc}", path=path) from None
    if not meta:
        from apygis.formats.e00.foreign import foreign_to_map

        foreign_to_map(info, tables, mp, path, opts)
        return mp
    default = layers[0] if layers else DEFAULT_LAYER
    _lines_to_map(info, tables, mp, default, path, opts["tolerance_m"])
    _labels_to_map(info, tables, mp, default, path)
    if opts["layers"] is not None:  # a map apygis wrote: its source layers are map layers
        from apygis.formats import select_layers

        select_layers(mp, opts["layers"], path)
    if opts["layer_map"]:
        raise DriverError(
            f"{path}: a map apygis wrote keeps its layers; a layer map applies to coverages "
            "of other programs"
        )
    return mp


def _arc_arrays(arcs: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arc numbers, vertex offsets and vertices (CSR) of the ARC sections read."""
    ids = np.array([h[0] for h in arcs["heads"]], np.int64)
    lens = np.concatenate(arcs["lens"]) if arcs["lens"] else np.zeros(0, np.int64)
    xy = np.concatenate(arcs["xy"]) if arcs["xy"] else np.zeros((0, 2))
    return ids, np.r_[0, np.cumsum(lens)].astype(np.int64), xy


def _check_ext_col(t: _Table, values: np.ndarray, path) -> None:
    for ext in set(values.tolist()):
        try:
            check_ext(ext)
        except RecordError:
            k = int(np.flatnonzero(values == ext)[0])
            _bad(t, k, t.raw("LAYER")[1], path, "a layer extension (1-3 letters)", ext.encode())


def _lines_to_map(info, tables, mp: MapFile, default: str, path, tol: float) -> None:
    ids, off, xy = _arc_arrays(info["arcs"])
    narc = len(ids)
    aat = _table(tables, ".AAT", path)
    if aat is not None and len(aat) != narc:
        raise FormatError(
            f"INFO table {aat.name} has {len(aat)} records for {narc} arcs", path=path
        )
    lpt = _table(tables, ".LINEPT", path)
    if lpt is not None and _need_items(lpt, _LPT_ITEMS):
        _lines_from_lpt(lpt, ids, off, xy, mp, path)
        return
    if narc == 0:
        return
    codes = np.zeros(narc, np.int64)
    if aat is not None and aat.has("CODE"):
        codes = _int_col(aat, "CODE", path)
        bad = (codes < 0) | (codes > MAX_CODE)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            _bad(aat, k, aat.raw("CODE")[1], path, "a code 0-99", str(codes[k]).encode())
    layer = mp.layer(default)
    rep = layer.add_polylines(xy, off, codes, snap_m=tol, crs=mp.crs)
    rebuild_report(path, layer.ext, rep)


def _lines_from_lpt(t: _Table, ids, off, xy, mp: MapFile, path) -> None:
    n = len(t)
    arc = _int_col(t, "ARC#", path)
    vertex = _int_col(t, "VERTEX", path)
    row = topology.lookup(ids, arc)
    if n and (row < 0).any():
        k = int(np.flatnonzero(row < 0)[0])
        _bad(t, k, t.raw("ARC#")[1], path, "the number of an arc", str(arc[k]).encode())
    nverts = off[1:] - off[:-1]
    bad = (vertex < 1) | (vertex > nverts[row]) if n else np.zeros(0, bool)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(t, k, t.raw("VERTEX")[1], path, "a vertex of the arc", str(vertex[k]).encode())
    layers = _str_col(t, "LAYER")
    _check_ext_col(t, layers, path)
    codes = _int_col(t, "CODE", path)
    bad = (codes < 0) | (codes > MAX_CODE)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(t, k, t.raw("CODE")[1], path, "a code 0-99", str(codes[k]).encode())
    rows = np.zeros(n, LINE_DTYPE)
    rows["num"] = _int_col(t, "NUM", path)
    pos = off[:-1][row] + vertex - 1 if n else np.zeros(0, np.int64)
    rows["x"], rows["y"] = xy[pos, 0], xy[pos, 1]
    rows["z"] = _float_col(t, "HEIGHT", path)
    rows["code"] = codes
    for f, item in (("fwd", "FWD"), ("back", "BACK"), ("side1", "SIDE1"), ("side2", "SIDE2")):
        v = _int_col(t, item, path)
        rows[f] = np.where(v < 0, NO_REF, v)
    _, first = np.unique(layers, return_index=True)
    for ext in layers[np.sort(first)].tolist():
        _add_records(mp.layer(ext).add_line_points, path, rows[layers == ext])


def _add_records(add, path, *args) -> None:
    """A layer's bulk ``add_*`` method called with ``args``; what it refuses is a FormatError."""
    try:
        add(*args)
    except RecordError as exc:
        raise FormatError(str(exc), path=path) from None


def label_numbers(ids: np.ndarray, path) -> np.ndarray:
    """The symbol numbers of ``ids`` label points: their IDs, or 1..n (with a warning)
    where an ID is negative or repeated."""
    n = len(ids)
    if n and (ids.min() < 0 or len(np.unique(ids)) != n):
        warn(
            log,
            f"{path}: label IDs negative or repeated; symbols numbered 1..{n}",
            "renumbered",
            n,
            "symbols",
        )
        return np.arange(1, n + 1)
    return ids


def _labels_to_map(info, tables, mp: MapFile, default: str, path) -> None:
    lab = info["labels"]
    value = np.concatenate(lab["ids"]) if lab["ids"] else np.zeros(0, np.int64)
    xy = np.concatenate(lab["xy"]) if lab["xy"] else np.zeros((0, 2))
    n = len(value)
    pat = _table(tables, ".PAT", path)
    if pat is not None and len(pat) != n:
        raise FormatError(
            f"INFO table {pat.name} has {len(pat)} records for {n} label points", path=path
        )
    if n == 0:
        return
    x, y = xy[:, 0], xy[:, 1]
    if pat is None or not _need_items(pat, _PAT_ITEMS):
        nums = label_numbers(value, path)
        z = np.zeros(n)
        if pat is not None and pat.has("HEIGHT"):
            z = _float_col(pat, "HEIGHT", path)
        codes = np.zeros(n, np.int64)
        if pat is not None and pat.has("CODE"):
            codes = _int_col(pat, "CODE", path)
            bad = (codes < 0) | (codes > MAX_CODE)
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                _bad(pat, k, pat.raw("CODE")[1], path, "a code 0-99", str(codes[k]).encode())
        _add_records(mp.layer(default).add_symbols, path, np.column_stack([x, y, z]), codes, nums)
        return
    layers = _str_col(pat, "LAYER")
    _check_ext_col(pat, layers, path)
    kinds = _str_col(pat, "KIND")
    nums = _int_col(pat, "NUM", path)
    codes = _int_col(pat, "CODE", path)
    z = _float_col(pat, "HEIGHT", path)
    tlen = _int_col(pat, "TXTLEN", path)
    width = pat.raw("TEXT")[1][2]
    bad = (tlen < 0) | (tlen > width)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(pat, k, pat.raw("TXTLEN")[1], path, f"a length 0-{width}", str(tlen[k]).encode())
    bad = ~np.isin(kinds, ["S", "T"])
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(pat, k, pat.raw("KIND")[1], path, "S (symbol) or T (text)", kinds[k].encode())
    is_text = kinds == "T"
    bad = ~is_text & ((codes < 0) | (codes > MAX_CODE))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        _bad(pat, k, pat.raw("CODE")[1], path, "a code 0-99", str(codes[k]).encode())
    raw_text = pat.raw("TEXT")[0]
    texts = {}
    for k in np.flatnonzero(is_text).tolist():
        texts[k] = _decode_text(raw_text[k][: int(tlen[k])].ljust(int(tlen[k])))
        try:
            check_text(texts[k])
        except RecordError as exc:
            _bad(pat, k, pat.raw("TEXT")[1], path, f"a text ({exc})", texts[k].encode())
    _, first = np.unique(layers, return_index=True)
    for ext in layers[np.sort(first)].tolist():
        lay = mp.layer(ext)
        here = layers == ext
        sel = np.flatnonzero(here & ~is_text)
        xyz = np.column_stack([x, y, z])
        if len(sel):
            _add_records(lay.add_symbols, path, xyz[sel], codes[sel], nums[sel])
        sel = np.flatnonzero(here & is_text)
        if len(sel):
            _add_records(lay.add_texts, path, xyz[sel], [texts[k] for k in sel.tolist()], nums[sel])


# --------------------------------------------------------------------------- API


def read(
    path,
    progress=None,
    recover: bool = False,
    tolerance_m: float = 0.005,
    layer_map=None,
    layers=None,
    crs=None,
    code_field: str | None = "code",
    default_code: int | None = None,
    point_code: int = IMPORTED_POINT,
) -> MapFile:
    """Read an E00 file (compressed or not) into a map.

    Parameters
    ----------
    path : str or os.PathLike
    progress : callable, optional
        ``progress(done, total)``.
    recover : bool
        Read a damaged or truncated file as far as it goes (a warning names
        the damage) instead of raising.
    tolerance_m : float
        For files apygis did not write: distance within which arc ends join
        other arcs when the line topology is rebuilt.
    layer_map, layers : optional
        For files apygis did not write: the coverage's parts ``ARC`` (arcs),
        ``PAL`` (polygons) and ``LAB`` (label points) are its source layers,
        mapped to the map layers ``arc``, ``pal`` and ``lab`` unless
        ``layer_map`` says otherwise; ``layers`` reads only some of them.
    crs : optional
        The CRS of a coverage without a PRJ section (or instead of it).
    code_field : str or None
        The AAT / PAT item holding codes 0-99 (compared without regard to case).
    default_code : int or None
        Code of features whose code item is missing or not 0-99 (counted and
        reported); None refuses codes outside 0-99 and gives lines 00.
    point_code : int
        Code of label points without a code (default 90, imported point).

    Returns
    -------
    MapFile

    Raises
    ------
    FormatError
        Not an E00 file, a grid E00 file, or bad content (the message names
        the line and what was expected).
    """
    try:
        tol = float(tolerance_m)
    except (TypeError, ValueError):
        tol = math.nan
    if not math.isfinite(tol) or tol < 0:
        raise DriverError(f"tolerance_m is a distance in metres >= 0, not {tolerance_m!r}")
    for name, value in (("default_code", default_code), ("point_code", point_code)):
        if value is None and name == "default_code":
            continue
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise DriverError(f"e00 {name}: an integer 0-{MAX_CODE}, not {value!r}")
        if not 0 <= value <= MAX_CODE:
            raise DriverError(f"e00 {name}: {value} is outside 0-{MAX_CODE}")
    from apygis.formats._layers import parse_layer_map

    opts = {
        "tolerance_m": tol,
        "layer_map": parse_layer_map(layer_map),
        "layers": layers,
        "crs": crs,
        "code_field": code_field,
        "default_code": default_code,
        "point_code": int(point_code),
    }
    info = decode(read_bytes(path), path, recover=recover)
    if progress:
        progress(1, 2)
    meta = _meta(info["tables"], path)
    mp = _map_from(info, meta, path, opts)
    if progress:
        progress(2, 2)
    return mp
