"""The inputs of a block: image lists, control points, EXIF (documented in ``docs/aerotri.md``).

Image list (CSV, UTF-8, header required, ``#`` comment lines allowed)::

    image,strip,file,X,Y,Z,heading_deg
    101,1,img_101.tif,2600123.4,1200456.7,1725.0,90
    102,1,img_102.tif,,,,             <- no approximate centre: from EXIF GPS or none
    103,1,img_103.tif,exif,exif,exif, <- "exif": from the image's EXIF GPS

``image`` a positive whole number (the image number), ``strip`` a whole number,
``file`` relative to the list's folder (or absolute), ``X, Y, Z`` the
approximate projection centre in the block CRS (metres), ``heading_deg`` the
flight direction (degrees clockwise from grid north; empty: from the strip's
line of centres).

Control points (CSV)::

    name,X,Y,Z,sigma_xy_m,sigma_z_m,kind
    GCP1,2600100.00,1200200.00,512.30,0.02,0.03,full

``kind`` is ``full``, ``planimetric`` (Z unknown: empty), ``height`` (X, Y
approximate, weight 0 in planimetry) or ``check`` (not used in the adjustment,
only compared).

EXIF: GPS latitude/longitude/altitude (WGS 84) and the focal length (and its
35 mm equivalent) from the image's EXIF tags, as GDAL reports them.
"""

from __future__ import annotations

import csv
import io
import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

from apygis.errors import FormatError
from apygis.fileio import read_bytes

__all__ = [
    "ControlPoint",
    "ExifInfo",
    "ImageEntry",
    "read_control",
    "read_exif",
    "read_image_list",
]

IMAGE_COLUMNS = ("image", "strip", "file", "X", "Y", "Z", "heading_deg")
CONTROL_COLUMNS = ("name", "X", "Y", "Z", "sigma_xy_m", "sigma_z_m", "kind")
CONTROL_KINDS = ("full", "planimetric", "height", "check")
IMAGE_SUFFIXES = {".tif", ".tiff", ".jpg", ".jpeg", ".jp2", ".png", ".img", ".vrt"}


@dataclass
class ImageEntry:
    """One row of an image list (``X``/``Y``/``Z`` None where unknown)."""

    image: int
    strip: int | None
    path: Path
    X: float | None = None
    Y: float | None = None
    Z: float | None = None
    heading_deg: float | None = None
    from_exif: bool = False


@dataclass(frozen=True)
class ControlPoint:
    """A control (or check) point in the block CRS."""

    name: str
    X: float
    Y: float
    Z: float | None
    sigma_xy_m: float
    sigma_z_m: float
    kind: str


@dataclass(frozen=True)
class ExifInfo:
    """What EXIF tells about an image (None where the tag is absent)."""

    lat: float | None
    lon: float | None
    alt_m: float | None
    focal_mm: float | None
    focal_35mm: float | None
    make: str
    model: str
    time: str | None


def _rows(path: Path, what: str, columns: tuple[str, ...], required: int):
    data = read_bytes(path, what, max_bytes=64 << 20)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FormatError(f"{path}: {what} is not UTF-8 text (byte {exc.start})") from None
    lines = [
        (n, ln) for n, ln in enumerate(text.splitlines(), 1) if not ln.lstrip().startswith("#")
    ]
    lines = [(n, ln) for n, ln in lines if ln.strip()]
    if not lines:
        raise FormatError(f"{path}: {what} is empty (expected a header {','.join(columns)})")
    header = [h.strip() for h in next(csv.reader(io.StringIO(lines[0][1])))]
    if header[:required] != list(columns[:required]) or any(h not in columns for h in header):
        raise FormatError(
            f"{path}: line {lines[0][0]}: header {','.join(header)!r} is not a {what} header "
            f"(expected {','.join(columns)})"
        )
    for n, ln in lines[1:]:
        cells = [c.strip() for c in next(csv.reader(io.StringIO(ln)))]
        if len(cells) > len(header):
            raise FormatError(
                f"{path}: line {n}: {len(cells)} fields, the header has {len(header)}"
            )
        cells += [""] * (len(header) - len(cells))
        yield n, dict(zip(header, cells, strict=True))


def _float(v: str, path: Path, n: int, name: str, *, optional: bool = False) -> float | None:
    if v == "":
        if optional:
            return None
        raise FormatError(f"{path}: line {n}: {name} is empty (expected a number)")
    try:
        f = float(v)
    except ValueError:
        raise FormatError(f"{path}: line {n}: {name} {v!r} is not a number") from None
    if not math.isfinite(f) or abs(f) > 1e12:
        raise FormatError(f"{path}: line {n}: {name} {v!r} is not a finite coordinate")
    return f


def _int(v: str, path: Path, n: int, name: str, lo: int = 0) -> int:
    if not re.fullmatch(r"[+-]?\d{1,12}", v):
        raise FormatError(f"{path}: line {n}: {name} {v!r} is not a whole number")
    i = int(v)
    if i < lo:
        raise FormatError(f"{path}: line {n}: {name} {i} must be at least {lo}")
    return i


def read_image_list(path) -> list[ImageEntry]:
    """Read an image list (see the module docstring); errors name the file and line."""
    path = Path(path)
    out: list[ImageEntry] = []
    seen: dict[int, int] = {}
    for n, row in _rows(path, "image list", IMAGE_COLUMNS, 3):
        image = _int(row["image"], path, n, "image", 1)
        if image in seen:
            raise FormatError(
                f"{path}: line {n}: image {image} is listed twice (first on line {seen[image]})"
            )
        seen[image] = n
        strip = _int(row["strip"], path, n, "strip") if row["strip"] else None
        if not row["file"]:
            raise FormatError(f"{path}: line {n}: file is empty (expected the image file)")
        f = Path(row["file"])
        f = f if f.is_absolute() else path.parent / f
        xyz = [row.get(k, "") for k in ("X", "Y", "Z")]
        exif = any(v.lower() == "exif" for v in xyz)
        if exif and not all(v.lower() == "exif" for v in xyz):
            raise FormatError(f"{path}: line {n}: X, Y and Z must all be 'exif' or numbers")
        X = Y = Z = None
        if not exif:
            X, Y, Z = (
                _float(v, path, n, k, optional=True) for v, k in zip(xyz, "XYZ", strict=True)
            )
            if (X is None) != (Y is None):
                raise FormatError(f"{path}: line {n}: X and Y must both be given or both be empty")
        heading = _float(row.get("heading_deg", ""), path, n, "heading_deg", optional=True)
        out.append(ImageEntry(image, strip, f, X, Y, Z, heading, exif))
    if not out:
        raise FormatError(f"{path}: the image list has a header but no images")
    return out


def image_folder(folder) -> list[ImageEntry]:
    """Every image file of a folder, numbered 1, 2, ... in name order, positions from EXIF."""
    folder = Path(folder)
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise FormatError(f"{folder}: no image files ({', '.join(sorted(IMAGE_SUFFIXES))})")
    return [ImageEntry(i, None, p, from_exif=True) for i, p in enumerate(files, 1)]


def read_control(path) -> list[ControlPoint]:
    """Read control points (see the module docstring); errors name the file and line."""
    path = Path(path)
    out: list[ControlPoint] = []
    seen: set[str] = set()
    for n, row in _rows(path, "control file", CONTROL_COLUMNS, 4):
        name = row["name"]
        if not name or len(name) > 64:
            raise FormatError(f"{path}: line {n}: name must be 1 to 64 characters")
        if name in seen:
            raise FormatError(f"{path}: line {n}: control point {name!r} is listed twice")
        seen.add(name)
        kind = row.get("kind", "") or "full"
        if kind not in CONTROL_KINDS:
            raise FormatError(
                f"{path}: line {n}: kind {kind!r} (expected one of {', '.join(CONTROL_KINDS)})"
            )
        X = _float(row["X"], path, n, "X")
        Y = _float(row["Y"], path, n, "Y")
        Z = _float(row["Z"], path, n, "Z", optional=kind == "planimetric")
        sxy = _float(row.get("sigma_xy_m", ""), path, n, "sigma_xy_m", optional=True)
        sz = _float(row.get("sigma_z_m", ""), path, n, "sigma_z_m", optional=True)
        for s, k in ((sxy, "sigma_xy_m"), (sz, "sigma_z_m")):
            if s is not None and not 0 < s <= 1000:
                raise FormatError(f"{path}: line {n}: {k} {s} must be in (0, 1000] m")
        out.append(
            ControlPoint(name, float(X or 0), float(Y or 0), Z, sxy or 0.05, sz or 0.05, kind)
        )
    return out


_RATIONAL = re.compile(r"\(([^)]*)\)")


def _exif_numbers(v: str | None) -> list[float]:
    if not v:
        return []
    parts = _RATIONAL.findall(v) or v.split()
    out = []
    for p in parts:
        try:
            out.append(float(p))
        except ValueError:
            return []
    return out


def _dms(v: str | None, ref: str | None, neg: str) -> float | None:
    n = _exif_numbers(v)
    if not n or not all(math.isfinite(a) for a in n):
        return None
    deg = n[0] + (n[1] / 60 if len(n) > 1 else 0) + (n[2] / 3600 if len(n) > 2 else 0)
    return -deg if (ref or "").strip().upper() == neg else deg


def read_exif(path) -> ExifInfo:
    """The EXIF GPS position, focal length and time of an image (GDAL's EXIF tags)."""
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as src:
                t = src.tags()
    except RasterioIOError as exc:
        raise FormatError(f"{path}: cannot read the image ({exc})") from None
    lat = _dms(t.get("EXIF_GPSLatitude"), t.get("EXIF_GPSLatitudeRef"), "S")
    lon = _dms(t.get("EXIF_GPSLongitude"), t.get("EXIF_GPSLongitudeRef"), "W")
    alt_n = _exif_numbers(t.get("EXIF_GPSAltitude"))
    alt = alt_n[0] if alt_n else None
    if alt is not None and t.get("EXIF_GPSAltitudeRef", "").strip() in ("0x01", "1"):
        alt = -alt
    f = _exif_numbers(t.get("EXIF_FocalLength"))
    f35 = _exif_numbers(t.get("EXIF_FocalLengthIn35mmFilm"))
    if (lat is not None and not -90 <= lat <= 90) or (lon is not None and not -180 <= lon <= 180):
        raise FormatError(f"{path}: EXIF GPS position {lat}, {lon} is not a latitude/longitude")
    return ExifInfo(
        lat,
        lon,
        alt,
        f[0] if f and f[0] > 0 else None,
        f35[0] if f35 and f35[0] > 0 else None,
        t.get("EXIF_Make", "").strip(),
        t.get("EXIF_Model", "").strip(),
        t.get("EXIF_DateTimeOriginal") or t.get("EXIF_DateTime"),
    )


def utm_crs(lon: float, lat: float) -> str:
    """The EPSG code of the WGS 84 / UTM zone of a point (for blocks from EXIF GPS)."""
    zone = min(60, max(1, int((lon + 180) // 6) + 1))
    return f"EPSG:{(32600 if lat >= 0 else 32700) + zone}"
