"""The APY way to a bundle file: the photo measurements of a densification map.

The seed's DATA EXCHANGE: "Bundle measurements are compiled in the text mode. This
format can be transformed here into a Bundle file for direct use in the BLUH or PAT-B
programs." The convention apygis implements (``docs/formats/patb.md``, "The APY
way"):

* the map has **no CRS**: its X, Y are photo coordinates in millimetres (the photo on
  the tablet was oriented on its fiducials), x right, y up; Z is not used;
* every record is a **text** ``PHOTO POINT``: the photo number (a whole number
  written without leading zeros) and the point's name, separated by one or more
  blanks, at the point's position;
* a map holding anything else (symbols, line points, a text of another form, a
  coordinate beyond the 150 mm of a 300 x 300 mm photo, a point measured twice in
  one photo) is refused, naming the layer, the record and what was expected.

The PAT-B and BLUH map drivers (:mod:`apygis.formats.patb`, :mod:`apygis.formats.bluh`)
write what :func:`photo_measurements` returns in their layouts.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from apygis.errors import FormatError
from apygis.formats._readguard import ascii_int

__all__ = ["PHOTO_HALF_MM", "PhotoMeasurements", "photo_measurements"]

PHOTO_HALF_MM = 150.0
"""The largest photo coordinate (mm): the seed's photos are at most 300 x 300 mm."""


class PhotoMeasurements(NamedTuple):
    """The points measured in one photo: names and photo coordinates ``(n, 2)`` in mm,
    and where each came from (``"layer c text 3"``)."""

    photo: int
    names: list[str]
    xy_mm: np.ndarray
    origins: list[str]


def photo_measurements(map_, *, max_photo: int) -> list[PhotoMeasurements]:
    """The photo measurements of a densification map, photos in ascending number, points
    in the order of the layers and their texts.

    ``max_photo`` is the largest photo number the target format holds. Raises
    :class:`FormatError` naming the map, the layer and the record for anything that
    is not a bundle measurement (see the module docstring).
    """
    where = f"map {map_.id}"
    if map_.crs is not None:
        raise FormatError(
            f"the map has a CRS ({map_.crs_string()}): a bundle measurement map holds photo "
            "coordinates in millimetres and has no CRS",
            record=where,
        )
    photos: dict[int, tuple[list[str], list[tuple[float, float]], list[str]]] = {}
    seen: dict[tuple[int, str], str] = {}
    for layer in sorted(map_, key=lambda lay: lay.ext):
        for table, what in (("symbols", "symbols"), ("line_points", "line points")):
            n = len(layer.table(table))
            if n:
                raise FormatError(
                    f"layer {layer.ext} holds {n} {what}: a bundle measurement map holds only "
                    "texts 'PHOTO POINT' at photo coordinates (mm)",
                    record=where,
                )
        texts = layer.texts
        for num, x, y, text in zip(
            texts["num"].tolist(),
            texts["x"].tolist(),
            texts["y"].tolist(),
            texts["text"].tolist(),
            strict=True,
        ):
            origin = f"layer {layer.ext} text {num}"
            rec = f"{where} {origin}"
            parts = text.split()
            if len(parts) != 2:
                raise FormatError(
                    f"text {text!r} is not a bundle measurement: expected 'PHOTO POINT' "
                    "(the photo number and the point's name, separated by a blank)",
                    record=rec,
                )
            photo = ascii_int(parts[0], max_digits=18)
            if photo is None or photo < 1 or photo > max_photo or str(photo) != parts[0]:
                raise FormatError(
                    f"text {text!r}: photo number {parts[0]!r} is not a whole number from 1 to "
                    f"{max_photo} written without leading zeros (expected 'PHOTO POINT')",
                    record=rec,
                )
            for label, v in (("X", x), ("Y", y)):
                if not (math.isfinite(v) and abs(v) <= PHOTO_HALF_MM):
                    raise FormatError(
                        f"text {text!r}: {label} = {v!r} is not a photo coordinate in mm "
                        f"(|{label.lower()}| <= {PHOTO_HALF_MM:g} mm: photos of at most "
                        "300 x 300 mm)",
                        record=rec,
                    )
            key = (photo, parts[1])
            if key in seen:
                raise FormatError(
                    f"point {parts[1]!r} is measured twice in photo {photo} (also at {seen[key]})",
                    record=rec,
                )
            seen[key] = origin
            names, xy, origins = photos.setdefault(photo, ([], [], []))
            names.append(parts[1])
            xy.append((x, y))
            origins.append(origin)
    if not photos:
        raise FormatError(
            "the map holds no bundle measurements (texts 'PHOTO POINT' at photo coordinates)",
            record=where,
        )
    return [
        PhotoMeasurements(p, photos[p][0], np.array(photos[p][1], dtype=float), photos[p][2])
        for p in sorted(photos)
    ]
