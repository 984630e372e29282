"""ISO WKB geometries as numpy columns.

Writing: Point Z of a whole (n, 3) array at once, LineString Z and Polygon Z
(one ring) per chain. Reading: a column of 29-byte Point Z values (ISO or EWKB)
decoded as one structured array, anything else through shapely; every
coordinate is checked (finite, within ``MAX_COORD``) before it reaches the model.
"""

from __future__ import annotations

import re
import struct

import numpy as np

from apygis.errors import FormatError
from apygis.formats._readguard import MAX_COORD, bad_coord_rows
from apygis.formats.ogr._common import _quiet, _rec

# ISO WKB geometry type codes (Z variants)
_WKB_POINT_Z, _WKB_LINESTRING_Z, _WKB_POLYGON_Z = 1001, 1002, 1003


_POINT_WKB = np.dtype([("order", "u1"), ("type", "<u4"), ("xyz", "<f8", 3)])  # 29 bytes


_POINT_HEADERS = (b"\x01\xe9\x03\x00\x00", b"\x01\x01\x00\x00\x80")  # ISO, EWKB Point Z


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
    xyz[:, 2] = np.where(np.isnan(xyz[:, 2]), 0.0, xyz[:, 2])  # _from_wkb checked them
    return xyz


_SURFACES = {15: "polyhedral surface", 16: "TIN", 17: "triangle"}
_UNKNOWN_TYPE = re.compile(r"Unknown WKB type (\d+)")


def _wkb_type(value) -> int | None:
    """The base geometry type (1 point ... 7 collection, 15-17 surfaces) of one WKB value."""
    if not isinstance(value, (bytes, bytearray, memoryview)) or len(value) < 5:
        return None
    order = "<" if value[0] == 1 else ">"
    (t,) = struct.unpack(order + "I", bytes(value[1:5]))
    return (t & 0x0FFFFFFF) % 1000


def _refuse_unreadable(wkb: np.ndarray, exc: Exception, path, layer: str):
    """The FormatError for a geometry column shapely cannot read: the feature and why."""
    import shapely

    k = None
    for i, value in enumerate(wkb):
        try:
            with _quiet():
                shapely.from_wkb(value, on_invalid="raise")
        except Exception as one:  # this feature is the one
            k, exc = i, one
            break
    where = f"feature {k + 1}: " if k is not None else ""
    base = _wkb_type(wkb[k]) if k is not None else None
    m = _UNKNOWN_TYPE.search(str(exc))
    nested = int(m.group(1)) % 1000 if m else None
    kind = _SURFACES.get(base) or _SURFACES.get(nested)  # type: ignore[arg-type]
    if kind is not None:
        return FormatError(
            f"{where}a {kind} (multipatch): surfaces are not supported; only points, lines "
            "and polygons can be imported",
            path,
            _rec(layer),
        )
    return FormatError(f"{where}unreadable geometry: {exc}", path, _rec(layer))


def _from_wkb(wkb: np.ndarray, path, layer: str) -> np.ndarray:
    import shapely

    try:
        with _quiet():
            geoms = shapely.from_wkb(wkb, on_invalid="raise")
    except Exception as exc:  # shapely.errors.GEOSException, TypeError
        raise _refuse_unreadable(wkb, exc, path, layer) from None
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
