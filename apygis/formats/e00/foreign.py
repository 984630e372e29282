"""E00 coverages that apygis did not write: arcs, polygons and label points to the map.

A coverage has up to three parts, its source layers as GDAL's AVCE00 driver
names them: ``ARC`` (arcs, attributes in the ``.AAT`` table), ``PAL`` (the
polygons of a polygon coverage, each a list of arcs, attributes in ``.PAT``)
and ``LAB`` (label points). They become map layers by the rule of every
reader (:mod:`apygis.formats._layers`: ``arc``, ``pal``, ``lab`` unless
``layer_map`` says otherwise):

* arcs become lines (topology rebuilt by the model's one rebuild);
* each polygon but the outside one (polygon 1, the "universe") becomes a
  closed line along its outer boundary, with its PAT record's code, so that
  AREA works on it. Its islands are polygons of their own (closed lines
  too), so a polygon's holes are not repeated;
* label points become symbols. In a polygon coverage the PAT has one record
  per polygon (the universe included), joined to a label through the
  label's polygon ID, as GDAL does; in a point coverage (no polygons) one
  record per label, in label order.

Codes come from the item ``code_field`` (default ``CODE``) of the AAT or PAT;
a value outside 0-99 takes ``default_code`` (counted and reported) or, without
it, is refused naming the table and record. Without such an item, lines get
``default_code`` or 00, points ``default_code`` or ``point_code`` (90,
imported point: E00 has no heights).
"""

from __future__ import annotations

import numpy as np

from apygis.errors import FormatError
from apygis.formats._layers import LayerNames
from apygis.formats._report import warn
from apygis.formats.e00._common import log
from apygis.formats.e00.mapping import (
    _add_records,
    _arc_arrays,
    _int_col,
    _table,
    label_numbers,
    rebuild_report,
)
from apygis.formats.e00.parse import _Table
from apygis.model import topology
from apygis.model.map import MapFile
from apygis.model.records import MAX_CODE

__all__ = ["foreign_to_map"]


def _code_item(t: _Table | None, field: str | None) -> str | None:
    if t is None or not field:
        return None
    low = field.lower()
    return next((it[0] for it in t.items if it[0].lower() == low), None)


def _codes(t: _Table | None, rows: np.ndarray, opts: dict, fallback: int, what: str, path):
    """Codes of the records ``rows`` of ``t`` (-1: no record), by the rules of the module."""
    default = opts["default_code"]
    out = np.full(len(rows), default if default is not None else fallback, np.int64)
    item = _code_item(t, opts["code_field"])
    if t is None or item is None or not len(rows):
        return out
    have = rows >= 0
    vals = _int_col(t, item, path)[rows[have]]
    bad = (vals < 0) | (vals > MAX_CODE)
    if bad.any():
        k = int(rows[have][np.flatnonzero(bad)[0]])
        if default is None:
            raise FormatError(
                f"INFO table {t.name}, record {k + 1}: {item} {int(vals[bad][0])} is not a code "
                "0-99 (give a default code for such features, or another code item)",
                path=path,
            )
        warn(
            log,
            f"{path}: {int(bad.sum())} {what} of INFO table {t.name} have {item} outside 0-99 "
            f"(e.g. {int(vals[bad][0])}): given the default code {default}",
            "recoded",
            int(bad.sum()),
            what,
        )
        vals = np.where(bad, default, vals)
    out[have] = vals
    return out


def _rings(info: dict, ids, off, xy, path) -> tuple[list[np.ndarray], list[int]]:
    """The outer ring of each polygon but the universe, and its polygon index (0-based)."""
    rings, polys = [], []
    for k, entries in enumerate(info["pal"]):
        if k == 0:
            continue  # polygon 1: the outside of the coverage
        arcs = entries[:, 0]
        stop = np.flatnonzero(arcs == 0)
        outer = arcs[: stop[0]] if len(stop) else arcs
        if not len(outer):
            continue
        pts: list[np.ndarray] = []
        for a in outer.tolist():
            row = topology.lookup(ids, np.array([abs(a)]))[0]
            if row < 0:
                raise FormatError(
                    f"PAL: polygon {k + 1} names arc {abs(a)}, which the ARC section lacks",
                    path=path,
                )
            seg = xy[off[row] : off[row + 1]]
            seg = seg[::-1] if a < 0 else seg
            if pts and len(seg) and np.array_equal(pts[-1][-1], seg[0]):
                seg = seg[1:]
            pts.append(seg)
        ring = np.concatenate(pts) if pts else np.zeros((0, 2))
        if len(ring) > 1 and np.array_equal(ring[0], ring[-1]):
            ring = ring[:-1]
        rings.append(ring)
        polys.append(k)
    return rings, polys


def foreign_to_map(info: dict, tables: list[_Table], mp: MapFile, path, opts: dict) -> None:
    """The arcs, polygons and labels of a foreign coverage into ``mp`` (module docstring)."""
    ids, off, xy = _arc_arrays(info["arcs"])
    lab = info["labels"]
    lab_ids = np.concatenate(lab["ids"]) if lab["ids"] else np.zeros(0, np.int64)
    lab_poly = np.concatenate(lab["poly"]) if lab["poly"] else np.zeros(0, np.int64)
    lab_xy = np.concatenate(lab["xy"]) if lab["xy"] else np.zeros((0, 2))
    npoly = len(info["pal"])
    present = [
        name
        for name, n in (("ARC", len(ids)), ("PAL", max(npoly - 1, 0)), ("LAB", len(lab_ids)))
        if n
    ]
    names = LayerNames(opts["layer_map"], present, where=path)
    names.check_used(present)
    chosen = names.select(opts["layers"], present, names.groups(present))

    def target(name: str):
        if name not in present or (chosen is not None and name not in chosen):
            return None
        ext = names(name)
        return None if ext is None else mp.layer(ext)

    aat = _table(tables, ".AAT", path)
    pat = _table(tables, ".PAT", path)
    tol, crs = opts["tolerance_m"], mp.crs

    if aat is not None and len(aat) != len(ids):
        raise FormatError(
            f"INFO table {aat.name} has {len(aat)} records for {len(ids)} arcs", path=path
        )
    polygons = npoly > 1
    if pat is not None and polygons and len(pat) != npoly:
        raise FormatError(
            f"INFO table {pat.name} has {len(pat)} records for {npoly} polygons (the outside "
            "one included)",
            path=path,
        )
    if pat is not None and not polygons and len(pat) != len(lab_ids):
        raise FormatError(
            f"INFO table {pat.name} has {len(pat)} records for {len(lab_ids)} label points and "
            "no polygons",
            path=path,
        )

    lay = target("ARC")
    if lay is not None:
        codes = _codes(aat, np.arange(len(ids)), opts, 0, "arcs", path)
        rep = lay.add_polylines(xy, off, codes, snap_m=tol, crs=crs)
        rebuild_report(path, lay.ext, rep)

    lay = target("PAL")
    if lay is not None:
        rings, polys = _rings(info, ids, off, xy, path)
        if rings:
            rows = np.array(polys) if pat is not None else np.full(len(polys), -1)
            codes = _codes(pat, rows, opts, 0, "polygons", path)
            from apygis.model.polylines import to_csr

            z = [np.column_stack([r, np.zeros(len(r))]) for r in rings]
            coords, offsets = to_csr(z)
            rep = lay.add_polylines(
                coords, offsets, codes, np.ones(len(rings), bool), snap_m=tol, crs=crs
            )
            rebuild_report(path, lay.ext, rep, "polygons")

    lay = target("LAB")
    if lay is not None:
        n = len(lab_ids)
        if pat is None:
            rows = np.full(n, -1)
        elif polygons:
            rows = np.where((lab_poly >= 1) & (lab_poly <= npoly), lab_poly - 1, -1)
        else:
            rows = np.arange(n)
        codes = _codes(pat, rows, opts, opts["point_code"], "label points", path)
        nums = label_numbers(lab_ids, path)
        xyz = np.column_stack([lab_xy, np.zeros(n)])
        _add_records(lay.add_symbols, path, xyz, codes, nums)
