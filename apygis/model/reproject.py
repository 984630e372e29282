"""Coordinate reference system changes of a whole map.

>>> from apygis.model.map import MapFile
>>> m = MapFile("BE", crs="EPSG:2056")
>>> _ = m.layer("c").add_symbol(2600000.0, 1200000.0, 550.0, code=1)
>>> w = reproject(m, "EPSG:4326")
>>> x, y, z = (float(w.layer("c").symbols[0][k]) for k in ("x", "y", "z"))
>>> round(x, 4), round(y, 4), z
(7.4386, 46.9511, 550.0)

Axis order is always X = east (easting or longitude), Y = north (northing
or latitude), whatever the CRS definition says (pyproj's ``always_xy``), as
everywhere in apygis.

Heights
-------
Z is transformed only when both CRSs are three-dimensional: they have three
axes, as a geographic 3-D CRS (EPSG:4979), a compound CRS of a horizontal
and a vertical one (``EPSG:2056+5728``, LV95 + LN02) or a geocentric CRS
has. Otherwise Z is copied unchanged: a 2-D CRS says nothing about heights,
and passing them through PROJ would treat them as ellipsoidal heights and
shift them by a datum change (tens of metres between CH1903+ and WGS 84).
"""

from __future__ import annotations

import logging

import numpy as np

from apygis.errors import CRSError
from apygis.model.map import Layer, MapFile, crs_string
from apygis.model.records import TABLE_WORDS, TABLES

__all__ = ["CRSError", "has_height", "reproject"]

log = logging.getLogger(__name__)


def _crs(value, what: str):
    from pyproj import CRS
    from pyproj.exceptions import CRSError as ProjCRSError

    if isinstance(value, CRS):
        return value
    try:
        return CRS.from_user_input(value)
    except (ProjCRSError, TypeError, ValueError) as exc:
        raise CRSError(f"{what}: not a coordinate reference system: {value!r} ({exc})") from None


def has_height(crs) -> bool:
    """True when ``crs`` has three axes (its Z is a height or a geocentric coordinate).

    >>> has_height("EPSG:2056"), has_height("EPSG:4979"), has_height("EPSG:2056+5728")
    (False, True, True)
    """
    return len(_crs(crs, "CRS").axis_info) == 3


def reproject(map_: MapFile, to_crs) -> MapFile:
    """A copy of ``map_`` with every table's coordinates in ``to_crs``.

    Parameters
    ----------
    map_ : MapFile
        The map; its :attr:`~MapFile.crs` must be set.
    to_crs : pyproj.CRS or anything ``pyproj.CRS.from_user_input`` takes
        The target CRS (``"EPSG:4326"``, WKT, a PROJ string, ...).

    Returns
    -------
    MapFile
        A new map (the input is not changed): same ID, scale, notes, layers
        and records, coordinates transformed, ``crs`` set to ``to_crs``.
        Z is transformed where both CRSs have a height axis (see the module
        docstring), otherwise copied.

    Raises
    ------
    CRSError
        The map has no CRS, ``to_crs`` is not a CRS, no transformation
        exists, or a point cannot be transformed (outside the CRS's domain);
        the message names the layer, the table and the point number.
    """
    from pyproj import Transformer
    from pyproj.exceptions import ProjError

    if map_.crs is None:
        raise CRSError(
            f"map {map_.id} has no CRS: it cannot be reprojected to "
            f"{crs_string(_crs(to_crs, 'target CRS'))} (give it its CRS first)"
        )
    src = map_.crs
    dst = _crs(to_crs, "target CRS")
    with_z = has_height(src) and has_height(dst)
    try:
        tr = Transformer.from_crs(src, dst, always_xy=True)
    except ProjError as exc:
        raise CRSError(
            f"no transformation from {crs_string(src)} to {crs_string(dst)}: {exc}"
        ) from None
    log.debug(
        "reprojecting map %s: %s -> %s (%s), heights %s",
        map_.id,
        crs_string(src),
        crs_string(dst),
        tr.description,
        "transformed" if with_z else "unchanged",
    )

    # one call for every coordinate of the map
    parts = [(lay, name, lay.table(name)) for lay in map_ for name in TABLES]
    x = np.concatenate([t["x"] for _, _, t in parts]) if parts else np.zeros(0)
    y = np.concatenate([t["y"] for _, _, t in parts]) if parts else np.zeros(0)
    z = np.concatenate([t["z"] for _, _, t in parts]) if parts else np.zeros(0)
    if len(x):
        try:
            if with_z:
                x2, y2, z2 = tr.transform(x, y, z, errcheck=False)
            else:
                x2, y2 = tr.transform(x, y, errcheck=False)
                z2 = z
        except ProjError as exc:
            raise CRSError(f"transformation failed: {exc}") from None
        x2, y2, z2 = (np.asarray(v, dtype=np.float64) for v in (x2, y2, z2))
    else:
        x2, y2, z2 = x, y, z
    bad = ~(np.isfinite(x2) & np.isfinite(y2) & np.isfinite(z2))

    out = MapFile(map_.id, map_.scale, dst, map_.notes)
    tables: dict[str, dict[str, np.ndarray]] = {}
    pos = 0
    for lay, name, t in parts:
        n = len(t)
        if bad[pos : pos + n].any():
            i = int(np.flatnonzero(bad[pos : pos + n])[0])
            raise CRSError(
                f"layer {lay.ext}: {TABLE_WORDS[name]} {t['num'][i]} at "
                f"({t['x'][i]:.3f}, {t['y'][i]:.3f}) cannot be transformed from "
                f"{crs_string(src)} to {crs_string(dst)} (outside the area of either CRS?)"
            )
        new = np.array(t, copy=True)
        new["x"], new["y"], new["z"] = x2[pos : pos + n], y2[pos : pos + n], z2[pos : pos + n]
        tables.setdefault(lay.ext, {})[name] = new
        pos += n
    for lay in map_:
        out.add_layer(Layer.from_arrays(lay.ext, **tables.get(lay.ext, {})))
    return out
