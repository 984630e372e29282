"""OpenDroneMap's ground control file ``gcp_list.txt``.

The format is OpenDroneMap's (https://docs.opendronemap.org/gcp/, "GCP file format";
``docs/formats/odm.md``)::

    EPSG:2056                                          <- the projection: EPSG:n, a PROJ
    2600100.0 1200200.0 512.3 3044.5 2622.25 IMG_0525.jpg GCP1      string, WGS84 or
    geo_x geo_y geo_z im_x im_y image_name [gcp_name] [extras...]    WGS84 UTM <zone><N|S>

one line per measurement of a control point in an image, fields separated by blanks;
``geo_z`` may be ``NaN`` (a point without height); blank lines and lines starting with
``#`` are skipped (as OpenSfM, which reads the file for ODM, does). Pixel coordinates
have the centre of the top-left pixel at 0, 0 (OpenSfM normalises them with
``(px + 0.5 - size / 2)``), as apygis's: no shift.

Writing: one line per observation of a full or planimetric control point (``NaN``
height), coordinates in full precision; the header is the block's CRS as ``EPSG:n``
where it has an EPSG code, else as a PROJ string. Height control, check points (ODM
would use them as control), tie and new points are left out and counted in the
:class:`~apygis.aerotri.exchange.WriteReport`, as are observations without pixel
coordinates (and no pixel transform to make them).

Reading: points are named by ``gcp_name`` or, where a line has none, grouped by their
coordinates as OpenSfM groups them (``gcp-1``, ``gcp-2``, ... in file order); images
are numbered 1, 2, ... in order of first appearance and named by ``image_name``;
observations carry pixels only. Extra fields after ``gcp_name`` are not read
(counted in :attr:`ExchangeBlock.skipped`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from apygis.aerotri.exchange import ExchangeBlock, ExImage, ExObservation, ExPoint, WriteReport
from apygis.aerotri.exchange._common import Index, finite_xyz, pixels
from apygis.errors import CRSError, FormatError, ValueRangeError
from apygis.fileio import atomic_write, read_bytes
from apygis.formats._records import MAX_BYTES, check_name, name, number, numbers, text_lines

__all__ = ["crs_line", "read_odm", "write_odm"]

_MAX_LINE = 4096
_PX_LIMIT = 1e7


def crs_line(crs: str, path=None) -> str:
    """The projection line for a CRS given as apygis keeps it (``EPSG:n``, WKT, PROJ):
    ``EPSG:n`` where the CRS has an EPSG code, else its PROJ string."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError as ProjError

    try:
        c = CRS.from_user_input(crs)
    except ProjError as exc:
        raise CRSError(f"{path}: the block's CRS {crs[:60]!r} is not valid: {exc}") from None
    code = c.to_epsg(min_confidence=100)
    if code is not None:
        return f"EPSG:{code}"
    proj = c.to_proj4()
    if not proj:
        raise CRSError(f"{path}: the block's CRS cannot be written as EPSG:n or a PROJ string")
    return " ".join(proj.split())


def _read_crs(line: str, path) -> str:
    from pyproj import CRS
    from pyproj.exceptions import CRSError as ProjError

    s = line.strip()
    words = s.split()
    try:
        if s.upper() == "WGS84":
            return "EPSG:4326"
        if len(words) == 3 and words[0].upper() == "WGS84" and words[1].upper() == "UTM":
            zone = words[2].upper()
            south = zone.endswith("S")
            digits = zone[:-1] if zone[-1:] in ("N", "S") else zone
            if not (digits.isascii() and digits.isdigit() and 1 <= int(digits) <= 60):
                raise ProjError(f"UTM zone {words[2]!r} is not 1 to 60 with N or S")
            return f"EPSG:{(32700 if south else 32600) + int(digits)}"
        if s.upper().startswith("EPSG:") or "+proj" in s:
            CRS.from_user_input(s)
            return s
    except ProjError as exc:
        raise FormatError(
            f"the projection {s[:60]!r} is not valid: {exc}", path, "line 1"
        ) from None
    raise FormatError(
        f"the first line {s[:60]!r} is not a projection (EPSG:n, a PROJ string with +proj, "
        "WGS84 or WGS84 UTM <zone><N|S>)",
        path,
        "line 1",
    )


def write_odm(block: ExchangeBlock, target) -> WriteReport:
    """Write the block's control measurements as OpenDroneMap's ``gcp_list.txt`` (see the
    module docstring), atomically.

    Raises :class:`~apygis.errors.CRSError` for a block without a valid CRS and
    :class:`~apygis.errors.ValueRangeError` naming the file and record for an image or
    point name holding a blank.
    """
    path = Path(target)
    if not block.crs:
        raise CRSError(f"{path}: the block has no CRS: gcp_list.txt begins with the projection")
    header = crs_line(block.crs, path)
    idx = Index(block, path)
    report = WriteReport()
    lines = [header]
    written_points: set[str] = set()
    for ob in block.observations:
        p = idx.points[ob.point]
        if p.kind not in ("full", "planimetric"):
            what = {"height": "height control", "check": "check points"}.get(
                p.kind, "tie and new points"
            )
            report.skip(f"observations of {what} (ODM's file holds control with X, Y)")
            continue
        xyz = finite_xyz(p)
        if xyz is None or not (math.isfinite(xyz[0]) and math.isfinite(xyz[1])):
            report.skip("observations of control points without X, Y")
            continue
        im = idx.images[ob.image]
        px = pixels(ob, im)
        if px is None:
            report.skip("observations without pixel coordinates (and no pixel transform)")
            continue
        rec = f"point {p.name!r} image {im.image}"
        check_name(im.name, path, rec, "image name")
        check_name(p.name, path, rec, "point name")
        z = "NaN" if p.kind == "planimetric" or not math.isfinite(xyz[2]) else repr(float(xyz[2]))
        for v, what in ((px[0], "im_x"), (px[1], "im_y")):
            if not (math.isfinite(v) and abs(v) <= _PX_LIMIT):
                raise ValueRangeError(f"{what} {v!r} is not a pixel coordinate", path, rec)
        X, Y = float(xyz[0]), float(xyz[1])
        lines.append(f"{X!r} {Y!r} {z} {float(px[0])!r} {float(px[1])!r} {im.name} {p.name}")
        written_points.add(p.name)
    report.skip(
        "observation sigmas (ODM's file has none)",
        sum(
            1 for ob in block.observations if ob.point in written_points and ob.sigma_px is not None
        ),
    )
    report.skip(
        "control sigmas (ODM's file has none)",
        sum(1 for n in written_points if idx.points[n].sigma is not None),
    )
    report.skip(
        "exterior orientations (not part of gcp_list.txt)",
        sum(im.eo is not None for im in block.images),
    )
    report.files = [atomic_write(path, "\n".join(lines) + "\n", parents=True)]
    report.written = {"measurements": len(lines) - 1, "points": len(written_points)}
    report.log("OpenDroneMap")
    return report


def read_odm(source) -> ExchangeBlock:
    """Read an OpenDroneMap ``gcp_list.txt`` (see the module docstring)."""
    path = Path(source)
    data = read_bytes(path, "OpenDroneMap GCP file", max_bytes=MAX_BYTES)
    lines = [
        (k, t)
        for k, t in text_lines(data, path, "gcp_list.txt", max_line=_MAX_LINE)
        if t.strip() and not t.lstrip().startswith("#")
    ]
    if not lines:
        raise FormatError("empty: gcp_list.txt begins with the projection", path)
    block = ExchangeBlock(crs=_read_crs(lines[0][1], path))
    images: dict[str, ExImage] = {}
    points: dict[str, ExPoint] = {}
    where: dict[str, int] = {}
    by_coords: dict[tuple[float, float, float], str] = {}
    seen: dict[tuple[str, int], int] = {}
    extras = 0
    for k, text in lines[1:]:
        rec = f"line {k}"
        tok = text.split()
        if len(tok) < 6:
            raise FormatError(
                "expected geo_x geo_y geo_z im_x im_y image_name [gcp_name], "
                f"found {len(tok)} fields",
                path,
                rec,
            )
        x, y = numbers(tok[:2], path, rec, "geo coordinate").tolist()
        z = number(tok[2], path, rec, "geo_z", nan_ok=True)
        u, v = numbers(tok[3:5], path, rec, "pixel coordinate", limit=_PX_LIMIT).tolist()
        img = name(tok[5], path, rec, "image name")
        xyz = np.array([x, y, z])
        if len(tok) >= 7:
            nm = name(tok[6], path, rec, "gcp name")
            extras += len(tok) > 7
        else:
            key = (x, y, z if math.isfinite(z) else math.inf)
            if key not in by_coords:
                by_coords[key] = f"gcp-{len(by_coords) + 1}"
            nm = by_coords[key]
        p = points.get(nm)
        if p is None:
            p = points[nm] = ExPoint(nm, "full" if math.isfinite(z) else "planimetric", xyz)
            where[nm] = k
        elif p.xyz is None or not np.array_equal(p.xyz, xyz, equal_nan=True):
            raise FormatError(
                f"point {nm!r} has other coordinates than at line {where[nm]}", path, rec
            )
        im = images.get(img)
        if im is None:
            im = images[img] = ExImage(image=len(images) + 1, name=img)
        if (nm, im.image) in seen:
            raise FormatError(
                f"point {nm!r} is measured twice in image {img!r} "
                f"(also at line {seen[(nm, im.image)]})",
                path,
                rec,
            )
        seen[(nm, im.image)] = k
        block.observations.append(ExObservation(nm, im.image, None, None, u, v))
    if extras:
        block.skipped["extra fields after gcp_name (not read)"] = extras
    block.images = list(images.values())
    block.points = list(points.values())
    return block
