"""What the exchange writers and readers share: the checks of a block, coordinates, paths."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from apygis.aerotri.exchange import (
    POINT_KINDS,
    ExchangeBlock,
    ExImage,
    ExObservation,
    ExPoint,
    WriteReport,
)
from apygis.errors import FormatError, ValueRangeError

CONTROL = ("full", "planimetric", "height")


class Index:
    """A checked block: images by number, points by name, observations in block order.

    Raises :class:`ValueRangeError` naming ``path`` and the offending record for an image
    number that is not a positive whole number or is given twice, a point name that is
    not text or is given twice, an unknown point kind, coordinates that are not three
    numbers, an observation of an unknown point or image, a point observed twice in one
    image.
    """

    def __init__(self, block: ExchangeBlock, path):
        self.block = block
        self._groups: dict[int, list[ExObservation]] | None = None
        self.images: dict[int, ExImage] = {}
        for im in block.images:
            n = im.image
            if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
                raise ValueRangeError(
                    f"image number {n!r} is not a positive whole number", path, f"image {n!r}"
                )
            if n in self.images:
                raise ValueRangeError(f"image {n} is given twice", path, f"image {n}")
            self.images[int(n)] = im
        self.points: dict[str, ExPoint] = {}
        for p in block.points:
            if not isinstance(p.name, str):
                raise ValueRangeError(
                    f"point name {p.name!r} is not text", path, f"point {p.name!r}"
                )
            if p.name in self.points:
                raise ValueRangeError(f"point {p.name!r} is given twice", path, f"point {p.name!r}")
            if p.kind not in POINT_KINDS:
                raise ValueRangeError(
                    f"point kind {p.kind!r} is not one of {', '.join(POINT_KINDS)}",
                    path,
                    f"point {p.name!r}",
                )
            if p.xyz is not None and np.asarray(p.xyz).shape != (3,):
                raise ValueRangeError(
                    "coordinates are not three numbers X, Y, Z", path, f"point {p.name!r}"
                )
            self.points[p.name] = p
        seen: set[tuple[str, int]] = set()
        for k, ob in enumerate(block.observations):
            rec = f"observation {k + 1} (point {ob.point!r}, image {ob.image!r})"
            if ob.point not in self.points:
                raise ValueRangeError("the block has no such point", path, rec)
            if ob.image not in self.images:
                raise ValueRangeError("the block has no such image", path, rec)
            key = (ob.point, ob.image)
            if key in seen:
                raise ValueRangeError("the point is observed twice in the image", path, rec)
            seen.add(key)

    def by_image_of(self, image: int) -> list[ExObservation]:
        """The observations of one image, in block order."""
        if self._groups is None:
            self._groups = self.by_image()
        return self._groups.get(image, [])

    def by_image(self) -> dict[int, list[ExObservation]]:
        """The observations grouped by image number (images in ascending number)."""
        out: dict[int, list[ExObservation]] = {n: [] for n in sorted(self.images)}
        for ob in self.block.observations:
            out[ob.image].append(ob)
        return out


def photo_mm(ob: ExObservation, image: ExImage) -> tuple[float, float] | None:
    """The observation's photo coordinates (mm): as given, or through the image's pixel
    transform from its pixels; None when neither can be had."""
    if ob.x_mm is not None and ob.y_mm is not None:
        return float(ob.x_mm), float(ob.y_mm)
    if ob.x_px is not None and ob.y_px is not None and image.pixel_to_mm is not None:
        m = np.asarray(image.pixel_to_mm, dtype=float).reshape(3, 3)
        h = m @ np.array([ob.x_px, ob.y_px, 1.0])
        return float(h[0] / h[2]), float(h[1] / h[2])
    return None


def photo_rows(
    idx: Index, report: WriteReport, label: Callable[[ExObservation, int], object], file: str
) -> tuple[list[tuple[int, list, np.ndarray]], int]:
    """The photo-coordinate rows of a bundle-program file: per image (ascending number)
    with observations, ``(image, labels, xy_mm)``, and the number of observations written.

    ``label(ob, image)`` gives each observation's point label in the file's form (it may
    refuse one); observations without photo coordinates are skipped, and so are their
    sigmas (``file`` names the file that holds none), each counted in ``report``.
    """
    rows = []
    n_obs = 0
    for image, obs in idx.by_image().items():
        labels, xy = [], []
        for ob in obs:
            mm = photo_mm(ob, idx.images[image])
            if mm is None:
                report.skip("observations without photo coordinates (and no pixel transform)")
                continue
            labels.append(label(ob, image))
            xy.append(mm)
        report.skip(
            f"observation sigmas ({file} has none)", sum(ob.sigma_px is not None for ob in obs)
        )
        if labels:
            rows.append((image, labels, np.array(xy)))
            n_obs += len(labels)
    return rows, n_obs


def pixels(ob: ExObservation, image: ExImage) -> tuple[float, float] | None:
    """The observation's pixel coordinates (column, row; centre of the top-left pixel at
    0, 0): as given, or through the inverse pixel transform from its photo mm."""
    if ob.x_px is not None and ob.y_px is not None:
        return float(ob.x_px), float(ob.y_px)
    if ob.x_mm is not None and ob.y_mm is not None and image.pixel_to_mm is not None:
        m = np.linalg.inv(np.asarray(image.pixel_to_mm, dtype=float).reshape(3, 3))
        h = m @ np.array([ob.x_mm, ob.y_mm, 1.0])
        return float(h[0] / h[2]), float(h[1] / h[2])
    return None


def finite_xyz(p: ExPoint) -> np.ndarray | None:
    """The point's coordinates as a float array, None where it has none."""
    if p.xyz is None:
        return None
    return np.asarray(p.xyz, dtype=float).reshape(3)


def control_xyz_ok(p: ExPoint, xyz: np.ndarray | None) -> bool:
    """Whether a control or check point has the coordinates its kind needs (finite X, Y;
    a finite Z unless planimetric)."""
    if xyz is None or not (math.isfinite(xyz[0]) and math.isfinite(xyz[1])):
        return False
    return p.kind == "planimetric" or math.isfinite(xyz[2])


def base_path(target, suffixes: tuple[str, ...]) -> Path:
    """``target`` without one of the format's ``suffixes`` (the base of a file set)."""
    p = Path(target)
    return p.with_suffix("") if p.suffix.lower() in suffixes else p


def read_set(source, suffixes: tuple[str, ...]) -> dict[str, Path]:
    """The files of a set to read: a file that is not one of the other members
    (``suffixes[1:]``) is the first member whatever its suffix, the others beside it;
    else the set named by ``source``. Refused when none of them exists."""
    src = Path(source)
    if src.is_file() and src.suffix.lower() not in suffixes[1:]:
        base = src.with_suffix("")
        files = {suffixes[0]: src, **{s: base.with_name(base.name + s) for s in suffixes[1:]}}
    else:
        base = base_path(src, suffixes)
        files = {s: base.with_name(base.name + s) for s in suffixes}
    need_files(files, source)
    return files


def need_files(files: dict[str, Path], source) -> None:
    """Refuse a read where none of the set's files exists."""
    if not any(f.is_file() for f in files.values()):
        listed = ", ".join(str(f) for f in files.values())
        raise FormatError(f"no such file (looked for {listed})", source)
