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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ExCamera", "ExImage", "ExObservation", "ExPoint", "ExchangeBlock"]


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
    oriented, its exterior orientation ``eo`` (6,) and its standard deviations ``eo_std``."""

    image: int
    name: str
    camera: int
    pixel_to_mm: np.ndarray
    width_px: int
    height_px: int
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
    distortion), pixels, and the standard deviation of one coordinate in pixels."""

    point: str
    image: int
    x_mm: float
    y_mm: float
    x_px: float
    y_px: float
    sigma_px: float | None = None


@dataclass
class ExchangeBlock:
    """A block as other programs exchange it (see the module docstring)."""

    crs: str = ""
    cameras: list[ExCamera] = field(default_factory=list)
    images: list[ExImage] = field(default_factory=list)
    points: list[ExPoint] = field(default_factory=list)
    observations: list[ExObservation] = field(default_factory=list)
