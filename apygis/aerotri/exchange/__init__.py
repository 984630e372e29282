"""Exchange of photogrammetric blocks with other programs (PAT-B, BLUH, COLMAP, OpenDroneMap,
MicMac): one neutral data structure, one module per format.

Every reader returns, and every writer takes, an :class:`ExchangeBlock`; the
conversion between the block database and an :class:`ExchangeBlock` lives in
:mod:`apygis.aerotri.exchange.convert`, so the format modules know no database.

Conventions (as everywhere in :mod:`apygis.aerotri` and :mod:`apygis.orient.rotation`):
photo coordinates ``(x, y)`` in millimetres, x right and y up, origin at the
fiducial centre (film) or sensor centre (digital), principal point ``(x0, y0)``
in that system; pixel coordinates ``(col, row)``, the centre of the top-left
pixel at ``(0, 0)``; ground ``X, Y, Z`` in metres in the block CRS; exterior
orientation ``(X0, Y0, Z0, omega, phi, kappa)`` with ``R = R_omega R_phi
R_kappa`` turning image vectors into ground directions, the image at ``z = -c``,
angles in radians.

A format carries only part of a block (PAT-B and BLUH have no pixels, OpenDroneMap and
MicMac no photo millimetres, COLMAP no names of points): a reader leaves what its
format does not carry as ``None`` (an image's camera, pixel transform and raster size;
an observation's photo or pixel coordinates), and :func:`complete_observations` fills
one of an observation's coordinate pairs from the other where the image's pixel
transform is known. What a reader skips is counted in :attr:`ExchangeBlock.skipped`
and logged; what a writer cannot put into its format is counted in the
:class:`WriteReport` it returns, and logged.

Format modules: :mod:`~apygis.aerotri.exchange.patb`, :mod:`~apygis.aerotri.exchange.bluh`,
:mod:`~apygis.aerotri.exchange.colmap`, :mod:`~apygis.aerotri.exchange.odm`,
:mod:`~apygis.aerotri.exchange.micmac` (each ``write_<fmt>(block, target) -> WriteReport``
and ``read_<fmt>(source) -> ExchangeBlock``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "POINT_KINDS",
    "ExCamera",
    "ExImage",
    "ExObservation",
    "ExPoint",
    "ExchangeBlock",
    "WriteReport",
    "complete_observations",
]

log = logging.getLogger(__name__)

POINT_KINDS = ("tie", "new", "full", "planimetric", "height", "check")
"""The kinds of :class:`ExPoint`: "full", "planimetric" and "height" are control points
(a planimetric point's Z is NaN; a height point's X, Y are approximate), "check" points
have known coordinates that the adjustment does not use."""


@dataclass
class ExCamera:
    """A camera: ``id`` (a positive whole number), ``name``, principal distance and principal
    point (mm), ``kind`` ("film" or "digital"), for a digital camera the sensor size in pixels
    and the pixel pitch (mm); ``radial_mm``/``radial_um`` an optional radial distortion table
    (radius in mm, displacement in micrometres, outwards positive, as the camera file's
    ``[distortion]``)."""

    id: int
    name: str
    focal_mm: float
    x0_mm: float = 0.0
    y0_mm: float = 0.0
    kind: str = "digital"
    width_px: int | None = None
    height_px: int | None = None
    pixel_mm: float | None = None
    radial_mm: tuple[float, ...] = ()
    radial_um: tuple[float, ...] = ()


@dataclass
class ExImage:
    """An image: its number (a positive whole number), file name, camera id, the pixel -> photo
    mm transform (3 x 3, ``[x, y, 1] ~ T @ [col, row, 1]``), the raster size and, once
    oriented, its exterior orientation ``eo`` (6,) and its standard deviations ``eo_std``.

    ``camera``, ``pixel_to_mm`` and the raster size are None where the format read does not
    carry them (PAT-B, BLUH, OpenDroneMap, MicMac)."""

    image: int
    name: str
    camera: int | None = None
    pixel_to_mm: np.ndarray | None = None
    width_px: int | None = None
    height_px: int | None = None
    eo: np.ndarray | None = None
    eo_std: np.ndarray | None = None


@dataclass
class ExPoint:
    """A point: ``name`` (text), ``kind`` one of "tie", "new", "full", "planimetric",
    "height", "check"; ``xyz`` (3,) ground coordinates where known (control: given; tie and
    new points: adjusted) and ``sigma`` (3,) their standard deviations (m)."""

    name: str
    kind: str = "tie"
    xyz: np.ndarray | None = None
    sigma: np.ndarray | None = None


@dataclass
class ExObservation:
    """One image measurement of a point: photo mm (as measured, not corrected for
    distortion), pixels, and the standard deviation of one coordinate in pixels.

    A pair is None where the format read does not carry it (PAT-B and BLUH: pixels;
    OpenDroneMap and MicMac: millimetres); see :func:`complete_observations`."""

    point: str
    image: int
    x_mm: float | None
    y_mm: float | None
    x_px: float | None
    y_px: float | None
    sigma_px: float | None = None


@dataclass
class ExchangeBlock:
    """A block as other programs exchange it (see the module docstring).

    ``skipped``: what the reader that made it left out, ``{what: count}`` (empty for a
    block built in memory)."""

    crs: str = ""
    cameras: list[ExCamera] = field(default_factory=list)
    images: list[ExImage] = field(default_factory=list)
    points: list[ExPoint] = field(default_factory=list)
    observations: list[ExObservation] = field(default_factory=list)
    skipped: dict[str, int] = field(default_factory=dict)

    def image_by_number(self) -> dict[int, ExImage]:
        """The images by their numbers."""
        return {im.image: im for im in self.images}

    def point_by_name(self) -> dict[str, ExPoint]:
        """The points by their names."""
        return {p.name: p for p in self.points}


@dataclass
class WriteReport:
    """What a writer did: the ``files`` written, the ``written`` counts (``{what: n}``),
    what the format could not hold and was left out (``skipped``, ``{what and why: n}``)
    and ``notes`` (conversions a reader of the files must know, such as COLMAP's virtual
    pixel grid). Every ``skipped`` entry is also logged as a warning."""

    files: list[Path] = field(default_factory=list)
    written: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def skip(self, what: str, n: int = 1) -> None:
        """Count ``n`` more of ``what`` as left out."""
        if n:
            self.skipped[what] = self.skipped.get(what, 0) + n

    def log(self, fmt: str) -> None:
        """Log the skipped entries as warnings (the writer calls this once, at the end)."""
        for what, n in self.skipped.items():
            log.warning("%s: %d %s", fmt, n, what)


def complete_observations(block: ExchangeBlock) -> int:
    """Fill each observation's missing coordinate pair (photo mm or pixels) from the other,
    through its image's pixel transform; returns how many observations were completed.

    Observations whose image has no pixel transform are left as they are.
    """
    from apygis.aerotri.camera import PixelTransform

    transforms = {
        im.image: PixelTransform(im.pixel_to_mm)
        for im in block.images
        if im.pixel_to_mm is not None
    }
    to_mm: dict[int, list[ExObservation]] = {}
    to_px: dict[int, list[ExObservation]] = {}
    for ob in block.observations:
        if ob.image not in transforms:
            continue
        if ob.x_mm is None and ob.x_px is not None and ob.y_px is not None:
            to_mm.setdefault(ob.image, []).append(ob)
        elif ob.x_px is None and ob.x_mm is not None and ob.y_mm is not None:
            to_px.setdefault(ob.image, []).append(ob)
    done = 0
    for image, obs in to_mm.items():
        mm = transforms[image].to_mm([(ob.x_px, ob.y_px) for ob in obs])
        for ob, (x, y) in zip(obs, mm.tolist(), strict=True):
            ob.x_mm, ob.y_mm = x, y
        done += len(obs)
    for image, obs in to_px.items():
        px = transforms[image].to_px([(ob.x_mm, ob.y_mm) for ob in obs])
        for ob, (c, r) in zip(obs, px.tolist(), strict=True):
            ob.x_px, ob.y_px = c, r
        done += len(obs)
    return done
