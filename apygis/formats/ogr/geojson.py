"""Writing the GeoJSON files of the OGR schema (reading goes through GDAL like the others).

Why not GDAL's GeoJSON writer: it drops a CRS that has no EPSG code (a WKT
such as BC Albers is lost, and every reader then assumes WGS 84), writes no
``crs`` for a map without a CRS (read back as WGS 84 too), and shortens
coordinates even with 17 significant figures (``0.1 + 0.2`` comes back as
``0.3``). The files here are written with the standard library's ``json``
number formatting (the shortest text that reads back as the same float64),
so every coordinate comes back bit for bit, and:

* a map in EPSG:4326 (WGS 84 longitude, latitude) is written as RFC 7946
  asks: no ``crs`` member, exterior rings counter-clockwise, positions
  ``[longitude, latitude, height]``;
* a map in any other CRS names it in the pre-RFC ``crs`` member, as GDAL
  writes and reads it: ``{"type": "name", "properties": {"name":
  "urn:ogc:def:crs:EPSG::2056"}}`` for a CRS with an EPSG code, the CRS's
  WKT as the name otherwise (GDAL, and so QGIS, reads either);
* a map without a CRS gets the ``crs`` name ``LOCAL_CS["unknown",...]``, an
  engineering CRS that GDAL reads as "unknown" instead of assuming WGS 84
  (apygis reads it as no CRS).

>>> import numpy as np
>>> _number_list(np.array([0.1 + 0.2, 2683000.12]))
'0.30000000000000004,2683000.12'
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["UNKNOWN_CRS", "crs_member", "write_geojson"]

UNKNOWN_CRS = 'LOCAL_CS["unknown",UNIT["metre",1]]'
"""The ``crs`` name of a map without a CRS (GDAL reads it as an unknown local CRS)."""

_CHUNK = 20_000  # features formatted and written at a time


def crs_member(crs) -> dict | None:
    """The ``crs`` member for a map's CRS (a pyproj CRS or None); None for EPSG:4326."""
    from apygis.model.map import crs_string

    if crs is None:
        name = UNKNOWN_CRS
    else:
        auth = crs_string(crs)
        if auth == "EPSG:4326":
            return None
        if auth is not None and auth.startswith("EPSG:"):
            name = f"urn:ogc:def:crs:EPSG::{auth[5:]}"
        else:
            name = crs.to_wkt()
    return {"type": "name", "properties": {"name": name}}


def _number_list(values: np.ndarray) -> str:
    return ",".join(map(repr, values.tolist()))


def _positions(xyz: np.ndarray) -> str:
    return ",".join(f"[{_number_list(p)}]" for p in xyz)


def _geometries(wkb: np.ndarray, rfc7946: bool) -> list[str]:
    """GeoJSON geometry texts of WKB points, linestrings and one-ring polygons."""
    import shapely

    geoms = shapely.from_wkb(wkb)
    tid = shapely.get_type_id(geoms)
    xyz, which = shapely.get_coordinates(geoms, include_z=True, return_index=True)
    has_z = shapely.has_z(geoms)
    bounds = np.r_[0, np.cumsum(np.bincount(which, minlength=len(geoms)))]
    out = []
    for k in range(len(geoms)):
        c = xyz[bounds[k] : bounds[k + 1]]
        if not has_z[k]:
            c = c[:, :2]
        if tid[k] == 0:
            out.append(f'{{"type":"Point","coordinates":[{_number_list(c[0])}]}}')
        elif tid[k] == 1:
            out.append(f'{{"type":"LineString","coordinates":[{_positions(c)}]}}')
        elif tid[k] == 3:
            if rfc7946 and not shapely.is_ccw(shapely.linearrings(c)):
                c = c[::-1]
            out.append(f'{{"type":"Polygon","coordinates":[[{_positions(c)}]]}}')
        else:  # pragma: no cover - the schema writes these three types
            raise ValueError(f"geometry type {tid[k]} is not in the schema")
    return out


def _properties(fields: list[str], data: list, masks: list, n: int) -> list[str]:
    cols = []
    for name, values, mask in zip(fields, data, masks, strict=True):
        vals = np.asarray(values).tolist() if len(values) else []
        if mask is not None:
            vals = [None if m else v for v, m in zip(vals, np.asarray(mask).tolist(), strict=True)]
        key = json.dumps(name, ensure_ascii=False)
        cols.append([f"{key}:{json.dumps(v, ensure_ascii=False)}" for v in vals])
    return (
        ["{" + ",".join(parts) + "}" for parts in zip(*cols, strict=True)] if cols else ["{}"] * n
    )


def write_geojson(path: Path, name: str, table, crs) -> None:
    """One OGR table of the schema as a GeoJSON FeatureCollection in ``path``.

    ``table`` has ``wkb`` (or None for the header table), ``fields``,
    ``data`` and ``masks`` (see :class:`apygis.formats.ogr.writer._Table`);
    ``crs`` is the map's pyproj CRS or None.
    """
    member = crs_member(crs) if table.wkb is not None else None
    rfc7946 = table.wkb is not None and member is None
    n = len(table.wkb) if table.wkb is not None else (len(table.data[0]) if table.data else 0)
    head: dict[str, object] = {"type": "FeatureCollection", "name": name}
    if member is not None:
        head["crs"] = member
    text = json.dumps(head, ensure_ascii=False)[:-1]
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text + ',\n"features":[\n')
        for start in range(0, n, _CHUNK):
            stop = min(n, start + _CHUNK)
            data = [np.asarray(d)[start:stop] for d in table.data]
            masks = [None if m is None else np.asarray(m)[start:stop] for m in table.masks]
            props = _properties(table.fields, data, masks, stop - start)
            if table.wkb is not None:
                geoms = _geometries(table.wkb[start:stop], rfc7946)
            else:
                geoms = ["null"] * (stop - start)
            lines = [
                f'{{"type":"Feature","properties":{p},"geometry":{g}}}'
                for p, g in zip(props, geoms, strict=True)
            ]
            fh.write(",\n".join(lines))
            fh.write(",\n" if stop < n else "\n")
        fh.write("]}\n")
