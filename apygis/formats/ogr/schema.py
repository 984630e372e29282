"""Names of the OGR schema (docs/formats/ogr.md, "The schema").

The four formats and what differs between them (:class:`_Format`), the OGR
layer names ``[PREFIX_]L_<kind>`` and ``apygis_map`` (:func:`_parse_name`),
the file names of the single-layer formats' sets, the ``points`` field of
``L_lines`` / ``L_areas``, and the reader's mapping of OGR layers to map layers
(``layer_map``, fallback extensions, a default map ID).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from apygis.errors import DriverError
from apygis.model.map import MapFile

SCHEMA_VERSION = 1


MAP_TABLE = "apygis_map"


KINDS = ("symbols", "lines", "areas", "texts", "line_points")


_EXACT = ("symbols", "texts", "line_points")


_NAME_RE = re.compile(
    r"^(?:(?P<prefix>.+)_)?(?P<ext>[a-z]{1,3})_(?P<kind>symbols|lines|areas|texts|line_points)$"
)


_MAP_RE = re.compile(r"^(?:(?P<prefix>.+)_)?apygis_map$")


_ID_BAD = re.compile(r"[^A-Za-z0-9_-]")


_DBF_BYTES = 254  # longest string a DBF field holds


_SHP_CHUNK = 60  # characters per header row in a Shapefile (<= 240 bytes of UTF-8)


_SHP_SIDECARS = ("shp", "shx", "dbf", "prj", "cpg", "qix", "sbn", "sbx")


@dataclass(frozen=True)
class _Format:
    """What differs between the four OGR formats."""

    name: str
    ogr: str
    extensions: tuple[str, ...]
    multi: bool  # one file holds every OGR layer (GeoPackage)
    layer_options: dict = field(default_factory=dict)
    containers: tuple[str, ...] = ()  # multi-layer files this driver also reads (zip)
    dataset_version: str | None = None  # GeoPackage: the VERSION written (None: the default)

    @property
    def ext(self) -> str:
        return self.extensions[0]


_GPKG = _Format("gpkg", "GPKG", ("gpkg",), multi=True)


_SHP = _Format("shp", "ESRI Shapefile", ("shp",), multi=False, containers=("shz", "zip"))


# written by apygis.formats.ogr.geojson (RFC 7946 in EPSG:4326; every float64 exactly)
_GEOJSON = _Format("geojson", "GeoJSON", ("geojson", "json"), multi=False)


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


def _split_target(map_: MapFile, path, fmt: _Format) -> tuple[Path, str, str]:
    """For the single-layer formats: ``(directory, prefix, file extension)``."""
    p = Path(path)
    suffix = p.suffix[1:].lower()
    if suffix in fmt.extensions and not p.is_dir():
        return p.parent, p.stem, suffix
    return p, map_.id, fmt.ext


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


def _parse_name(name: str) -> tuple[str | None, str, str] | None:
    """``(prefix, ext, kind)`` of a name of the schema (``kind`` ``"map"``: the header)."""
    m = _MAP_RE.match(name)
    if m:
        return m["prefix"], "", "map"
    m = _NAME_RE.match(name)
    if m:
        return m["prefix"], m["ext"], m["kind"]
    return None


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


def _default_id(stem: str) -> str:
    s = _ID_BAD.sub("_", stem)[:32]
    return s or "MAP"
