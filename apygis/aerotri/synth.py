"""Synthetic aerial photo blocks with truth (teaching, testing a set-up, accuracy tests).

:func:`synth_block` writes a complete block — images, camera file, image list,
control points — together with ``truth.json`` (and ``dem.tif``) that holds
everything needed to score an aerotriangulation; :func:`load_truth` reads it
back as a :class:`Truth`.

Geometry (conventions of :mod:`apygis.aerotri` and :mod:`apygis.orient.rotation`)
    Ground X east, Y north, Z up (metres, ``spec.crs``, near E 2 600 000,
    N 1 200 000, heights ~ 500 m). Strips run east-west, strip 1 in the north,
    flown alternately east (heading 90 deg) and west (heading 270 deg); cross
    strips run north-south (headings 0 / 180). Photo x lies along the flight, so
    the nominal ``kappa = radians(90 - heading)``; the attitude adds random
    omega, phi (s.d. 0.3 deg) and kappa (+-1 deg). Flying height above the
    mean terrain ``H = c * scale``; base ``B = (1 - forward_overlap) * F_along``,
    strip spacing ``(1 - side_overlap) * F_across`` with ``F = format * scale``.
    Image number of strip ``s``, image ``i`` (both 1-based): ``100 s + i``.
Scan
    Film: pixel -> photo mm is a similarity (rotation < 1 deg, offset of a few
    mm, pixel ``240 mm / size_px``) with a slight affinity (x/y scales differing
    by 1e-4), composed with the dihedral transform of the pixel grid given by
    ``spec.rotated_scans[n]``: code ``k`` in 0..7 means that the stored image is
    ``np.rot90(base, k % 4)``, then ``np.fliplr`` if ``k >= 4``, of the image
    ``base`` scanned the normal way. Digital: ``PixelTransform.digital``.
Terrain
    A DEM grid (``dem.tif``, float32, north-up) with nodes at
    ``X = x0 + j * spacing``, ``Y = y0 - i * spacing`` (column ``j``, row ``i``);
    the height between nodes is the bilinear interpolation of the four
    surrounding nodes (clamped at the grid's border). Smooth hills (a sum of
    Gaussians), flat under the lake.
Ground texture
    A deterministic function ``g(X, Y)`` (grey values 30..220) evaluated
    procedurally for any point: fields (sheared rectangular parcels, each with
    its grey level, stripes and noise), hedges along the parcel edges, roads
    (straight lines), buildings (a bright and a darker roof half and a cast
    shadow; flat, no height in the DEM, hence no occlusion), forest (tree
    crowns), meadows and a textureless lake. Detail reaches the ground sampling
    distance (GSD): value noise with lattice spacings of 1.5, 3, 6 and 12 GSD,
    bilinear in a 256 x 256 random tile (``cv2.remap``, positions quantised to
    1/32 of a lattice cell: still a fixed function of ``(X, Y)``). Periodic
    detail finer than twice the sub-sample spacing fades to its mean (a
    level-of-detail rule), so that no component aliases.
Rendering (:func:`render_image`)
    For pixel ``(c, r)``: photo mm ``scan.to_mm``, the ray
    ``P(Z) = C + (Z - Zo) / D_z D`` with ``D = R (x - x0, y - y0, -c)``,
    intersected with the DEM by Newton's method on ``f(Z) = h(X(Z), Y(Z)) - Z``
    (the same as :meth:`Truth.ground`). The pixel value is the mean of ``g`` at
    ``ss x ss`` sub-pixel positions ``(c + a, r + b)``, ``a, b`` in
    ``(k + 1/2) / ss - 1/2``, located through the local linear map
    pixel -> ground (central differences of the exact pixel-centre points;
    exact to second order); the smooth detail noise (lattices >= 1.5 GSD) is
    evaluated once, at the pixel centre. Then a Gaussian blur (``blur_px``, the film's MTF),
    the dark film outside the 230 mm format (DN 15, area coverage), the fiducial
    marks (:func:`apygis.aerotri.fiducials.draw_marks`), Gaussian grain noise
    (``noise_dn``) and rounding to 8 bits.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from apygis.aerotri.camera import Camera, PixelTransform
from apygis.errors import FormatError
from apygis.orient.collinearity import (
    ExteriorOrientation,
    InteriorOrientation,
    ground_to_photo,
)

__all__ = [
    "SynthSpec",
    "Truth",
    "dihedral",
    "dihedral_matrix",
    "load_truth",
    "render_image",
    "synth_block",
]

FILM_FORMAT_MM = 230.0
FILM_SCAN_MM = 240.0
FILM_DARK_DN = 15.0
STANDARD_FIDUCIALS = {
    "1": (-106.0, 106.0),
    "2": (106.0, 106.0),
    "3": (106.0, -106.0),
    "4": (-106.0, -106.0),
    "5": (0.0, 110.0),
    "6": (110.0, 0.0),
    "7": (0.0, -110.0),
    "8": (-110.0, 0.0),
}
ORIENTATION_MARK = (-12.0, 110.0)
LAKE_DN = 62.0


@dataclass
class SynthSpec:
    """What to synthesise; ``None`` fields take the defaults named here.

    ``size_px``: film — the scan is ``size_px x size_px`` pixels covering 240 mm;
    digital — the sensor's long side (along photo x; the short side is 2/3 of
    it, a 36 x 24 mm sensor unless ``pixel_um`` is given). ``focal_mm``: film
    153, digital 50. ``scale``: the photo scale number (film 8000, digital
    20000). ``relief_m``: peak-to-peak terrain relief (8 % of the flying height).
    ``approx_error_m``: s.d. of the noise on the approximate centres in
    ``images.csv`` (0.5 % of the flying height). ``rotated_scans``: image number
    -> dihedral code 0..7 (see the module docstring). ``origin``: the block
    centre ``(E, N)`` and the mean terrain height.
    """

    strips: int = 3
    images_per_strip: int = 6
    forward_overlap: float = 0.6
    side_overlap: float = 0.3
    size_px: int = 3000
    camera: str = "film"
    focal_mm: float | None = None
    pixel_um: float | None = None
    scale: float | None = None
    relief_m: float | None = None
    cross_strips: int = 0
    rotated_scans: dict[int, int] = field(default_factory=dict)
    noise_dn: float = 2.0
    lake: bool = True
    seed: int = 0
    approx_error_m: float | None = None
    crs: str = "EPSG:2056"
    origin: tuple[float, float, float] = (2_600_000.0, 1_200_000.0, 500.0)
    blur_px: float = 0.5
    supersample: int = 2

    def __post_init__(self):
        if self.camera not in ("film", "digital"):
            raise FormatError(f"SynthSpec: camera must be 'film' or 'digital', got {self.camera!r}")
        if self.strips < 1 or self.images_per_strip < 2:
            raise FormatError("SynthSpec: need at least 1 strip of at least 2 images")
        if not (0.0 <= self.forward_overlap < 0.95 and 0.0 <= self.side_overlap < 0.95):
            raise FormatError("SynthSpec: overlaps must lie in 0 .. 0.95")
        if not 64 <= self.size_px <= 30000:
            raise FormatError(f"SynthSpec: size_px {self.size_px} is not in 64..30000")
        for n, code in self.rotated_scans.items():
            if int(code) not in range(8):
                raise FormatError(f"SynthSpec: rotated_scans[{n}] = {code} is not in 0..7")
        self.rotated_scans = {int(k): int(v) for k, v in self.rotated_scans.items()}
        self.origin = (float(self.origin[0]), float(self.origin[1]), float(self.origin[2]))

    # resolved values -------------------------------------------------------
    @property
    def focal(self) -> float:
        """Principal distance c, mm."""
        if self.focal_mm is not None:
            return float(self.focal_mm)
        return 153.0 if self.camera == "film" else 50.0

    @property
    def scale_number(self) -> float:
        """Photo scale number (1 : scale)."""
        if self.scale is not None:
            return float(self.scale)
        return 8000.0 if self.camera == "film" else 20000.0

    @property
    def flying_height(self) -> float:
        """Flying height above the mean terrain, metres: ``c * scale``."""
        return self.focal * self.scale_number / 1000.0

    @property
    def relief(self) -> float:
        """Peak-to-peak terrain relief, metres."""
        return float(self.relief_m) if self.relief_m is not None else 0.08 * self.flying_height

    @property
    def approx_error(self) -> float:
        """S.d. of the approximate centres' noise, metres."""
        if self.approx_error_m is not None:
            return float(self.approx_error_m)
        return 0.005 * self.flying_height

    @property
    def image_px(self) -> tuple[int, int]:
        """``(width, height)`` of an unrotated image, pixels."""
        if self.camera == "film":
            return self.size_px, self.size_px
        return self.size_px, round(self.size_px * 2 / 3)

    @property
    def pixel_mm(self) -> float:
        """Pixel size in the image plane, mm."""
        if self.camera == "film":
            return FILM_SCAN_MM / self.size_px
        if self.pixel_um is not None:
            return float(self.pixel_um) / 1000.0
        return 36.0 / self.size_px

    @property
    def format_mm(self) -> tuple[float, float]:
        """Image format along photo x and y, mm."""
        if self.camera == "film":
            return FILM_FORMAT_MM, FILM_FORMAT_MM
        w, h = self.image_px
        return w * self.pixel_mm, h * self.pixel_mm

    @property
    def gsd(self) -> float:
        """Ground sampling distance at the mean terrain, metres."""
        return self.pixel_mm * self.scale_number / 1000.0

    def to_dict(self) -> dict:
        """A JSON-ready dict (the inverse is :meth:`from_dict`)."""
        d = asdict(self)
        d["rotated_scans"] = {str(k): v for k, v in self.rotated_scans.items()}
        d["origin"] = list(self.origin)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> SynthSpec:
        """The inverse of :meth:`to_dict`."""
        d = dict(d)
        d["rotated_scans"] = {int(k): int(v) for k, v in d.get("rotated_scans", {}).items()}
        d["origin"] = tuple(d.get("origin", (2_600_000.0, 1_200_000.0, 500.0)))
        return cls(**d)


# --------------------------------------------------------------------------
# dihedral transforms of the pixel grid


def dihedral(a: np.ndarray, code: int) -> np.ndarray:
    """The image ``a`` turned by dihedral ``code``: ``np.rot90(a, code % 4)``, mirrored
    left-right (``np.fliplr``) after that when ``code >= 4``."""
    b = np.rot90(a, code % 4)
    return np.fliplr(b) if code >= 4 else b


def dihedral_matrix(code: int, width: int, height: int) -> np.ndarray:
    """3 x 3 matrix ``M`` with ``[c, r, 1] = M [c', r', 1]``: the pixel ``(c, r)`` of the
    unrotated ``height x width`` image shown at ``(c', r')`` of ``dihedral(image, code)``.

    One ``np.rot90`` of an ``h x w`` array maps ``(c', r') <- (c, r) = (w - 1 - r', c')``;
    ``np.fliplr`` maps ``(c', r') <- (w - 1 - c', r')``; the steps compose left to right.
    """
    M = np.eye(3)
    w, h = width, height
    for _ in range(code % 4):
        M = M @ np.array([[0.0, -1.0, w - 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        w, h = h, w
    if code >= 4:
        M = M @ np.array([[-1.0, 0.0, w - 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    return M


# --------------------------------------------------------------------------
# hashing and noise


def _hash(i, j, salt: int) -> np.ndarray:
    """A uniform number in [0, 1) for integer lattice coordinates ``(i, j)`` (vectorised;
    32-bit multiply-xorshift mixing, wrapping arithmetic)."""
    a = np.asarray(i).astype(np.int32).view(np.uint32)
    b = np.asarray(j).astype(np.int32).view(np.uint32)
    with np.errstate(over="ignore"):
        h = a * np.uint32(0x9E3779B1) + b * np.uint32(0x85EBCA77)
        h += np.uint32((salt * 0x27D4EB2F + 1) & 0xFFFFFFFF)
        h ^= h >> np.uint32(15)
        h *= np.uint32(0x2C1B3C6D)
        h ^= h >> np.uint32(12)
        h *= np.uint32(0x297A2D39)
        h ^= h >> np.uint32(15)
    return h.astype(np.float64) * (1.0 / 4294967296.0)


def _fade(period, spacing: float):
    """Level of detail: 1 for detail coarser than 4 sub-samples, 0 below 2."""
    return np.clip(np.asarray(period) / spacing / 2.0 - 1.0, 0.0, 1.0)


@dataclass
class _Road:
    nx: float
    ny: float
    d: float
    half_width: float


class _Scene:
    """The ground texture ``g(x, y)`` (local metres, relative to the block centre)."""

    def __init__(self, spec: SynthSpec, lake: tuple[float, float, float, float] | None, roads):
        rng = np.random.default_rng([spec.seed, 11])
        self.spacing = spec.gsd / spec.supersample  # sub-sample spacing on the ground
        self.gsd = spec.gsd
        tile = rng.normal(0.0, 1.0, (256, 256)).astype(np.float32)
        self.tile = np.pad(tile, ((0, 2), (0, 2)), mode="wrap")  # periodic, for remap
        a = math.radians(rng.uniform(-20.0, 20.0))
        self.ca, self.sa = math.cos(a), math.sin(a)
        self.row_h = float(rng.uniform(90.0, 140.0))
        lam0 = max(1.5 * spec.gsd, 0.4)
        self.octaves = [
            (lam0 * 2**k, amp, math.radians(rng.uniform(0, 360)), rng.uniform(0, 256, 2))
            for k, amp in enumerate((0.6, 0.9, 1.0, 1.0))
        ]
        self.zone = [(math.radians(rng.uniform(0, 360)), rng.uniform(0, 256, 2)) for _ in range(2)]
        self.lake = lake
        self.roads: list[_Road] = roads

    # -- helpers -------------------------------------------------------------
    def _tile(self, x, y, lam, angle, off):
        """Periodic value noise (period 256 lattice cells of ``lam`` metres, rotated)."""
        c, s = math.cos(angle) / lam, math.sin(angle) / lam
        u = x * c + y * s + off[0]
        u -= 256.0 * np.floor(u * (1.0 / 256.0))
        v = y * c - x * s + off[1]
        v -= 256.0 * np.floor(v * (1.0 / 256.0))
        import cv2

        u32, v32 = u.astype(np.float32), v.astype(np.float32)
        shp = u.shape
        if u32.size == 0:
            return u32
        if u32.ndim == 2 and 0 < shp[1] < 30000 and shp[0] < 30000:
            return cv2.remap(self.tile, u32, v32, cv2.INTER_LINEAR)
        # cv2 takes 2-D maps of fewer than 32767 rows and columns: rows of 4096 points
        m = u32.size
        pad = -m % 4096
        u32 = np.pad(u32.ravel(), (0, pad)).reshape(-1, 4096)
        v32 = np.pad(v32.ravel(), (0, pad)).reshape(-1, 4096)
        out = cv2.remap(self.tile, u32, v32, cv2.INTER_LINEAR)
        return out.ravel()[:m].reshape(shp)

    def detail(self, x, y) -> np.ndarray:
        """The fine detail noise (unit amplitude, lattices of 1.5 .. 12 GSD)."""
        n = np.zeros(np.shape(x), np.float32)
        for lam, a, ang, off in self.octaves:
            n += np.float32(a * float(_fade(lam, self.spacing))) * self._tile(x, y, lam, ang, off)
        return n

    def road_distance(self, x, y):
        """Signed distance to the nearest road's edge (negative on the road), metres."""
        d = np.full(np.shape(x), np.inf)
        for r in self.roads:
            np.minimum(d, np.abs(x * r.nx + y * r.ny - r.d) - r.half_width, out=d)
        return d

    def in_lake(self, x, y, grow: float = 1.0):
        """Boolean: inside the lake's ellipse (scaled by ``grow``)."""
        if self.lake is None:
            return np.zeros(np.shape(x), bool)
        lx, ly, ax, ay = self.lake
        return ((x - lx) / ax) ** 2 + ((y - ly) / ay) ** 2 < grow * grow

    # -- the texture ------------------------------------------------------------
    def base(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """The texture without its fine detail: grey value ``g`` and the detail's
        amplitude ``a`` (both float64, DN) at local ``(x, y)``."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        sp = self.spacing
        u, v, h1, edge, forest = self._parcels(x, y)
        h2 = np.modf(h1 * 256.0)[0]  # further 24 and 16 bits of the same hash
        h3 = np.modf(h1 * 65536.0)[0]
        meadow = ~forest & (h1 < 0.40)
        # fields: grey level, stripes along or across the parcel
        g = 85.0 + 95.0 * h2
        period = 2.5 + 4.0 * h3
        t = np.where(h3 < 0.5, u, v)
        amp = (6.0 + 12.0 * h1) * _fade(period, sp)
        g += amp * np.sin(t * (2.0 * np.pi) / period)
        g = np.where(meadow, 105.0 + 35.0 * h2, g)
        namp = np.where(meadow, 9.0, 6.0)
        # forest: tree crowns on two lattices, the brighter wins
        fi = np.flatnonzero(forest)
        if fi.size:
            xf, yf = x.ravel()[fi], y.ravel()[fi]
            crowns = np.maximum(
                self._crowns(xf, yf, 4.3, 0.23, 5), self._crowns(xf, yf, 5.9, 0.91, 6)
            )
            k = _fade(4.3, sp)
            g.ravel()[fi] = 67.0 + k * (crowns - 67.0)  # 67: the crowns' mean
            namp.ravel()[fi] = 5.0
        # hedges / furrows along the parcel edges
        hedge = edge < 1.0
        g = np.where(hedge & ~forest, 62.0, g)
        # roads (with a dark shoulder) and buildings
        dr = self.road_distance(x, y)
        bi = np.flatnonzero(dr > 1.0)
        if bi.size:
            gb, nb = self._buildings(u.ravel()[bi], v.ravel()[bi], g.ravel()[bi])
            g.ravel()[bi] = gb
            namp.ravel()[bi] = np.where(nb, 2.0, namp.ravel()[bi])
        g = np.where(dr < 0.0, 138.0, np.where(dr < 1.0, 58.0, g))
        namp = np.where(dr < 1.0, 3.0, namp)
        if self.lake is not None:
            lake = self.in_lake(x, y)
            g = np.where(lake, LAKE_DN, g)
            namp = np.where(lake, 0.0, namp)
        return g, namp

    def value(self, x, y) -> np.ndarray:
        """Grey value (float32, 30..220) of the ground at local ``(x, y)`` (any shape):
        ``clip(g + a * detail, 30, 220)`` with ``(g, a) = base(x, y)``."""
        g, a = self.base(x, y)
        return np.clip(g + a * self.detail(x, y), 30.0, 220.0).astype(np.float32)

    def _crowns(self, x, y, cell: float, angle: float, salt: int):
        """Tree crowns: one per cell of a lattice turned by ``angle``, jittered, with
        its own size and brightness, lit from the north-west."""
        c, s = math.cos(angle), math.sin(angle)
        p = (x * c + y * s) / cell
        q = (y * c - x * s) / cell
        ci, cj = np.floor(p), np.floor(q)
        h = _hash(ci, cj, salt)
        du = p - (ci + 0.5 + 0.4 * (h - 0.5))
        dv = q - (cj + 0.5 + 0.4 * (np.modf(h * 256.0)[0] - 0.5))
        r = 0.28 + 0.12 * np.modf(h * 65536.0)[0]
        k = (du * du + dv * dv) / (r * r)
        lit = (0.7 * (dv * c + du * s) - 0.7 * (du * c - dv * s)) / r  # towards NW
        bright = 0.75 + 0.35 * np.modf(h * 16.0)[0]
        return np.where(k < 1.0, 40.0 + 120.0 * bright * (1.0 - k) * (0.8 + 0.2 * lit), 36.0)

    def _parcels(self, x, y):
        """Parcel coordinates ``(u, v)``, the parcel's hash, the distance to its edge and
        whether it is forest. Parcels: rows of height ``row_h`` across the direction
        ``(ca, sa)``, each row cut into parcels of its own width (70..270 m), shifted."""
        u = x * self.ca + y * self.sa
        v = y * self.ca - x * self.sa
        row = np.floor(v / self.row_h)
        hr = _hash(row, 0, 1)
        width = 70.0 + 200.0 * hr
        u2 = u + 977.0 * hr
        col = np.floor(u2 / width)
        h1 = _hash(col, row, 2)
        fv = v - row * self.row_h
        fu = u2 - col * width
        edge = np.minimum(np.minimum(fv, self.row_h - fv), np.minimum(fu, width - fu))
        zone_f = self._tile(x, y, 350.0, *self.zone[0])
        forest = (h1 < 0.08) | ((zone_f > 0.7) & (h1 < 0.7))
        return u, v, h1, edge, forest

    def _buildings(self, u, v, ground):
        """Ground with buildings at parcel coordinates ``(u, v)``; and the roof mask.

        One building per 30 m cell of the parcel grid, with probability 0.75 where
        the village noise at the cell's building centre exceeds 0.75, 0.25 within 4..40 m
        of a road, none in forest, near a road (closer than its half sizes' sum + 2 m)
        or the lake; half sizes 4..9 x 3..6 m, the roof's ``v > 0`` half bright, its
        shadow the roof shifted by (3, -3) m (ground darkened to 40 %). Every decision
        is taken at the building's centre, so buildings are never cut."""
        cell, s = 30.0, 3.0
        bi, bj = np.floor(u / cell), np.floor(v / cell)
        h = _hash(bi, bj, 20)
        out = ground.copy()
        roof = np.zeros(u.shape, bool)
        k = np.flatnonzero(h < 0.75)
        if not k.size:
            return out, roof
        bi, bj, h = bi[k], bj[k], h[k]
        h2 = np.modf(h * 256.0)[0]
        h3 = np.modf(h * 65536.0)[0]
        h4 = _hash(bi, bj, 21)
        cu = (bi + 0.5 + 0.2 * (h2 - 0.5)) * cell
        cv = (bj + 0.5 + 0.2 * (h3 - 0.5)) * cell
        hx = 4.0 + 5.0 * h4
        hy = 3.0 + 3.0 * np.modf(h4 * 256.0)[0]
        du, dv = u[k] - cu, v[k] - cv
        near = (np.abs(du - 0.5 * s) < hx + 0.5 * s) & (np.abs(dv + 0.5 * s) < hy + 0.5 * s)
        k, h, cu, cv, hx, hy, du, dv = (a[near] for a in (k, h, cu, cv, hx, hy, du, dv))
        # decisions at the building's centre
        xc = cu * self.ca - cv * self.sa
        yc = cu * self.sa + cv * self.ca
        dr = self.road_distance(xc, yc)
        village = self._tile(xc, yc, 300.0, *self.zone[1]) > 0.75
        ok = (dr > hx + hy + 2.0) & ~self.in_lake(xc, yc, 1.3)
        ok &= village | ((h < 0.25) & (dr < 40.0))
        ok &= ~self._parcels(xc, yc)[4]
        r = ok & (np.abs(du) < hx) & (np.abs(dv) < hy)
        sh = ok & ~r & (np.abs(du - s) < hx) & (np.abs(dv + s) < hy)
        out[k] = np.where(sh, 0.4 * out[k], np.where(r, np.where(dv > 0.0, 205.0, 158.0), out[k]))
        roof[k] = r
        return out, roof


# --------------------------------------------------------------------------
# the DEM


@dataclass
class _Dem:
    z: np.ndarray  # float32 (rows north -> south)
    x0: float
    y0: float
    spacing: float

    def eval(self, X, Y):
        """Bilinear height and its gradient (dh/dX, dh/dY) at ``(X, Y)`` (clamped)."""
        nr, nc = self.z.shape
        fj = np.clip((np.asarray(X, float) - self.x0) / self.spacing, 0.0, nc - 1.000001)
        fi = np.clip((self.y0 - np.asarray(Y, float)) / self.spacing, 0.0, nr - 1.000001)
        j = fj.astype(np.intp)
        i = fi.astype(np.intp)
        ax = fj - j
        ay = fi - i
        flat = self.z.ravel()
        k = i * nc + j
        z00 = flat[k].astype(float)
        z01 = flat[k + 1].astype(float)
        z10 = flat[k + nc].astype(float)
        z11 = flat[k + nc + 1].astype(float)
        top = z00 + ax * (z01 - z00)
        bot = z10 + ax * (z11 - z10)
        h = top + ay * (bot - top)
        hx = ((1.0 - ay) * (z01 - z00) + ay * (z11 - z10)) / self.spacing
        hy = -(bot - top) / self.spacing
        return h, hx, hy


# --------------------------------------------------------------------------
# truth


@dataclass
class Truth:
    """The true geometry of a synthetic block (see the module docstring).

    ``exterior[n]`` and ``scan[n]`` (pixel -> photo mm, including the dihedral
    code ``dihedral_code[n]``) per image number ``n``; ``size[n]`` its
    ``(width, height)``; ``control`` the control points (dicts as in
    ``control.csv``).
    """

    spec: SynthSpec
    camera: Camera
    images: list[int]
    strip: dict[int, int]
    heading: dict[int, float]
    exterior: dict[int, ExteriorOrientation]
    scan: dict[int, PixelTransform]
    scan_base: dict[int, PixelTransform]
    dihedral_code: dict[int, int]
    size: dict[int, tuple[int, int]]
    dem: _Dem
    control: list[dict]
    lake: tuple[float, float, float, float] | None
    roads: list[_Road]
    _scene: _Scene | None = field(default=None, repr=False)

    @property
    def origin(self) -> tuple[float, float]:
        """``(E, N)`` of the block centre (the texture's local origin)."""
        return self.spec.origin[0], self.spec.origin[1]

    @property
    def interior(self) -> InteriorOrientation:
        """The camera's interior orientation (principal distance and point)."""
        return InteriorOrientation(self.camera.focal_mm, self.camera.x0_mm, self.camera.y0_mm)

    @property
    def scene(self) -> _Scene:
        if self._scene is None:
            self._scene = _Scene(self.spec, self.lake, self.roads)
        return self._scene

    def height(self, X, Y) -> np.ndarray:
        """DEM height at ``(X, Y)`` (bilinear between the grid's nodes; any shape)."""
        return self.dem.eval(X, Y)[0]

    def texture(self, X, Y) -> np.ndarray:
        """The ground's grey value at ``(X, Y)`` (before blur and grain)."""
        e, n = self.origin
        return self.scene.value(np.asarray(X, float) - e, np.asarray(Y, float) - n)

    def project(self, n: int, XYZ) -> np.ndarray:
        """Pixel ``(col, row)`` (m x 2) of ground points in image ``n`` (collinearity)."""
        mm = ground_to_photo(np.asarray(XYZ, float).reshape(-1, 3), self.exterior[n], self.interior)
        return self.scan[n].to_px(mm)

    def ground(self, n: int, px, tol: float = 1e-6) -> np.ndarray:
        """Ground points (m x 3) of pixels ``(col, row)`` of image ``n``: each pixel's ray
        intersected with the DEM (Newton on ``h(X(Z), Y(Z)) - Z``, to ``tol`` metres)."""
        mm = self.scan[n].to_mm(np.asarray(px, float).reshape(-1, 2))
        X, Y, Z = self._intersect(n, mm[:, 0], mm[:, 1], tol)
        return np.column_stack([X, Y, Z])

    def _intersect(self, n: int, x, y, tol: float):
        eo = self.exterior[n]
        cam = self.camera
        R = eo.rotation
        vx, vy, vz = x - cam.x0_mm, y - cam.y0_mm, -cam.focal_mm
        dx = R[0, 0] * vx + R[0, 1] * vy + R[0, 2] * vz
        dy = R[1, 0] * vx + R[1, 1] * vy + R[1, 2] * vz
        dz = R[2, 0] * vx + R[2, 1] * vy + R[2, 2] * vz
        kx, ky = dx / dz, dy / dz
        Z = np.full(np.shape(x), self.spec.origin[2])
        for _ in range(50):
            X = eo.Xo + (Z - eo.Zo) * kx
            Y = eo.Yo + (Z - eo.Zo) * ky
            h, hx, hy = self.dem.eval(X, Y)
            f = h - Z
            if not np.any(np.abs(f) > tol):
                break
            Z = Z - f / (hx * kx + hy * ky - 1.0)
        X = eo.Xo + (Z - eo.Zo) * kx
        Y = eo.Yo + (Z - eo.Zo) * ky
        return X, Y, Z

    def visible(self, n: int, XYZ) -> np.ndarray:
        """Boolean (m,): in front of the camera, inside the image and (film) the format."""
        g = np.asarray(XYZ, float).reshape(-1, 3)
        px = self.project(n, g)
        w, h = self.size[n]
        ok = (px[:, 0] >= -0.5) & (px[:, 0] <= w - 0.5) & (px[:, 1] >= -0.5) & (px[:, 1] <= h - 0.5)
        ok &= (g - self.exterior[n].centre) @ self.exterior[n].rotation[:, 2] < 0
        if self.camera.kind == "film":
            mm = self.scan[n].to_mm(px)
            ok &= np.all(np.abs(mm) <= FILM_FORMAT_MM / 2, axis=1)
        return ok


# --------------------------------------------------------------------------
# rendering


def render_image(
    truth: Truth, n: int, *, noise: bool = True, rows_per_chunk: int = 64
) -> np.ndarray:
    """The uint8 image of number ``n`` (see the module docstring for the model).

    Deterministic for a given truth (the grain is seeded by ``(spec.seed, n)``);
    ``noise=False`` leaves the grain out. Memory: a float32 image and a few
    float64 arrays of ``rows_per_chunk`` rows.
    """
    from scipy.ndimage import gaussian_filter

    spec = truth.spec
    scene = truth.scene
    code = truth.dihedral_code[n]
    base = truth.scan_base[n]
    w, h = spec.image_px
    e0, n0 = truth.origin
    ss = spec.supersample
    offs = (np.arange(ss) + 0.5) / ss - 0.5
    img = np.empty((h, w), np.float32)
    cols = np.arange(w, dtype=float)
    half = FILM_FORMAT_MM / 2
    pix = spec.pixel_mm
    for r0 in range(0, h, rows_per_chunk):
        r1 = min(h, r0 + rows_per_chunk)
        rows = np.arange(r0 - 1, r1 + 1, dtype=float)
        cc, rr = np.meshgrid(cols, rows)
        mm = base.to_mm(np.column_stack([cc.ravel(), rr.ravel()]))
        X, Y, _ = truth._intersect(n, mm[:, 0], mm[:, 1], 1e-4)
        X = X.reshape(cc.shape) - e0
        Y = Y.reshape(cc.shape) - n0
        Xr = 0.5 * (X[2:] - X[:-2])
        Yr = 0.5 * (Y[2:] - Y[:-2])
        Xc = np.gradient(X[1:-1], axis=1)
        Yc = np.gradient(Y[1:-1], axis=1)
        Xm, Ym = X[1:-1], Y[1:-1]
        acc = np.zeros(Xm.shape, np.float32)
        nc = scene.detail(Xm, Ym)  # smooth detail noise: point-sampled at the pixel centre
        for a in offs:
            for b in offs:
                g, amp = scene.base(Xm + a * Xc + b * Xr, Ym + a * Yc + b * Yr)
                acc += np.clip(g + amp * nc, 30.0, 220.0).astype(np.float32)
        acc /= ss * ss
        img[r0:r1] = acc
        if spec.camera == "film":
            m = mm.reshape(*cc.shape, 2)[1:-1]
            cov = np.clip(0.5 + (half - np.abs(m[..., 0])) / pix, 0, 1) * np.clip(
                0.5 + (half - np.abs(m[..., 1])) / pix, 0, 1
            )
            img[r0:r1] = cov * img[r0:r1] + (1.0 - cov) * FILM_DARK_DN
    if spec.blur_px > 0:
        img = gaussian_filter(img, spec.blur_px, mode="nearest")
    if spec.camera == "film":
        try:
            from apygis.aerotri.fiducials import draw_marks
        except ImportError:  # pragma: no cover - the marks module is optional
            pass
        else:
            img = draw_marks(img, base, truth.camera)
    if noise and spec.noise_dn > 0:
        rng = np.random.default_rng([spec.seed, 1000 + n])
        img += rng.normal(0.0, spec.noise_dn, img.shape).astype(np.float32)
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(dihedral(out, code))


# --------------------------------------------------------------------------
# building a block


def _camera(spec: SynthSpec) -> Camera:
    if spec.camera == "film":
        return Camera(
            name="synthetic film camera",
            kind="film",
            focal_mm=spec.focal,
            fiducials=dict(STANDARD_FIDUCIALS),
            orientation_mark_mm=ORIENTATION_MARK,
        )
    w, h = spec.image_px
    return Camera(
        name="synthetic digital camera",
        kind="digital",
        focal_mm=spec.focal,
        pixel_um=spec.pixel_mm * 1000.0,
        sensor_px=(w, h),
    )


def _layout(spec: SynthSpec):
    """Nominal centres (local metres), strips and headings: ``[(n, strip, heading, x, y)]``,
    the main strips' centre lines ``ys`` and image abscissae ``xs``."""
    fx, fy = spec.format_mm
    along = fx * spec.scale_number / 1000.0
    across = fy * spec.scale_number / 1000.0
    base = (1.0 - spec.forward_overlap) * along
    gap = (1.0 - spec.side_overlap) * across
    ni, ns = spec.images_per_strip, spec.strips
    xs = (np.arange(ni) - (ni - 1) / 2) * base
    ys = ((ns - 1) / 2 - np.arange(ns)) * gap
    out = []
    for s in range(ns):
        east = s % 2 == 0
        order = xs if east else xs[::-1]
        for i, x in enumerate(order):
            out.append((100 * (s + 1) + i + 1, s + 1, 90.0 if east else 270.0, float(x), ys[s]))
    if spec.cross_strips:
        span = ys[0] - ys[-1] + across * 0.5
        m = max(2, math.ceil(span / base) + 1)
        yc = (np.arange(m) - (m - 1) / 2) * base
        xc = np.linspace(xs[0], xs[-1], spec.cross_strips + 2)[1:-1]
        if spec.cross_strips == 1:
            xc = np.array([0.5 * (xs[0] + xs[-1])])
        for k, x in enumerate(xc):
            s = ns + k + 1
            north = k % 2 == 0
            order = yc if north else yc[::-1]
            for i, y in enumerate(order):
                out.append((100 * s + i + 1, s, 0.0 if north else 180.0, float(x), float(y)))
    return out, xs, ys, along, across


def _scene_layout(spec: SynthSpec):
    """Lake ellipse and roads (local metres), deterministic in ``spec``."""
    _, xs, ys, along, across = _layout(spec)
    rng = np.random.default_rng([spec.seed, 23])
    lake = None
    if spec.lake:
        # at the outer von Gruber point (photo y ~ 76 mm for film) of strip 1 at image 2:
        # in the models (1, 2) and (2, 3)
        lake = (float(xs[1]), float(ys[0] + 0.33 * across), 0.1 * along, 0.07 * across)
    mids = 0.5 * (xs[:-1] + xs[1:])
    xr = list(mids[::2]) + ([mids[-1]] if len(mids) % 2 == 0 else [])
    if len(xr) < 2:  # two images: roads through both nadirs
        xr = [xs[0], xs[-1]]
    yr = [ys[0] - 0.15 * across, *(0.5 * (ys[:-1] + ys[1:])), ys[-1] + 0.15 * across]
    if len(ys) == 1:
        yr = [ys[0] - 0.2 * across, ys[0] + 0.2 * across]
    ns_roads, ew_roads = [], []
    for x in xr:
        t = math.radians(rng.uniform(-4, 4))  # direction (sin t, cos t): roughly north
        nx, ny = math.cos(t), -math.sin(t)
        ns_roads.append(_Road(nx, ny, x * nx, float(rng.uniform(2.5, 4.0))))
    for y in yr:
        t = math.radians(rng.uniform(-4, 4))  # direction (cos t, sin t): roughly east
        nx, ny = -math.sin(t), math.cos(t)
        ew_roads.append(_Road(nx, ny, y * ny, float(rng.uniform(2.5, 4.0))))
    t = math.radians(rng.uniform(25, 65))
    diag = _Road(-math.sin(t), math.cos(t), float(rng.uniform(-0.2, 0.2)) * across, 3.0)
    roads = ns_roads + ew_roads + [diag]
    if lake is not None:  # keep the roads off the lake
        lx, ly, ax, ay = lake
        for r in roads:
            dist = lx * r.nx + ly * r.ny - r.d
            if abs(dist) < max(ax, ay) + 40.0:
                r.d -= math.copysign(max(ax, ay) + 60.0 - abs(dist), dist)
    crossings = []
    for i, a in enumerate(ns_roads):
        for j, b in enumerate(ew_roads):
            p = np.linalg.solve([[a.nx, a.ny], [b.nx, b.ny]], [a.d, b.d])
            edge = i in (0, len(ns_roads) - 1) or j in (0, len(ew_roads) - 1)
            corner = i in (0, len(ns_roads) - 1) and j in (0, len(ew_roads) - 1)
            crossings.append((float(p[0]), float(p[1]), edge, corner))
    return lake, roads, crossings


def _dem(spec: SynthSpec, extent, lake) -> _Dem:
    rng = np.random.default_rng([spec.seed, 31])
    xmin, xmax, ymin, ymax = extent
    sp = max(2.0, min(10.0, (xmax - xmin) / 600.0))
    xs = np.arange(xmin, xmax + sp, sp)
    ys = np.arange(ymax, ymin - sp, -sp)
    X, Y = np.meshgrid(xs, ys)
    size = 0.5 * ((xmax - xmin) + (ymax - ymin)) / 2
    g = np.zeros_like(X)
    for _ in range(16):
        cx, cy = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
        s = rng.uniform(0.12, 0.35) * size
        g += rng.uniform(-1.0, 1.0) * np.exp(-((X - cx) ** 2 + (Y - cy) ** 2) / (2 * s * s))
    g = (g - g.mean()) / max(np.ptp(g), 1e-9) * spec.relief
    if lake is not None:
        lx, ly, ax, ay = lake
        q = np.sqrt(((X - lx) / ax) ** 2 + ((Y - ly) / ay) ** 2)
        level = float(g[np.unravel_index(np.argmin(q), q.shape)])
        t = np.clip((q - 1.25) / (2.5 - 1.25), 0.0, 1.0)
        wgt = 1.0 - t * t * (3.0 - 2.0 * t)
        g = wgt * level + (1.0 - wgt) * g
    e0, n0, z0 = spec.origin
    return _Dem((g + z0).astype(np.float32), e0 + xs[0], n0 + ys[0], sp)


def _scan_base(spec: SynthSpec, rng) -> PixelTransform:
    w, h = spec.image_px
    if spec.camera == "digital":
        return PixelTransform.digital(w, h, spec.pixel_mm * 1000.0)
    p = spec.pixel_mm
    th = math.radians(rng.uniform(-0.8, 0.8))
    sx, sy = p * (1.0 + 5e-5), p * (1.0 - 5e-5)
    tx, ty = rng.uniform(-3.0, 3.0, 2)
    c, s = math.cos(th), math.sin(th)
    # u = sx (col - cx), v = -sy (row - cy); (x, y) = rot(th) (u, v) + (tx, ty)
    cx, cy = (w - 1) / 2, (h - 1) / 2
    a, b = c * sx, s * sy
    cc, d = s * sx, -c * sy
    return PixelTransform.affine(a, b, cc, d, tx - a * cx - b * cy, ty - cc * cx - d * cy)


def _build_truth(spec: SynthSpec) -> Truth:
    rng = np.random.default_rng([spec.seed, 41])
    layout, _, _, along, across = _layout(spec)
    unknown = sorted(set(spec.rotated_scans) - {r[0] for r in layout})
    if unknown:
        raise FormatError(f"SynthSpec: rotated_scans names image {unknown[0]}, not in the block")
    lake, roads, crossings = _scene_layout(spec)
    e0, n0, z0 = spec.origin
    H = spec.flying_height
    w, h = spec.image_px
    camera = _camera(spec)
    pad = 0.6 * max(along, across) + 0.2 * H
    allx = [r[3] for r in layout]
    ally = [r[4] for r in layout]
    dem = _dem(spec, (min(allx) - pad, max(allx) + pad, min(ally) - pad, max(ally) + pad), lake)
    images, strip, heading, ext, scan, scan0, codes, size = [], {}, {}, {}, {}, {}, {}, {}
    jit = 0.01 * along
    for n, s, hd, x, y in layout:
        images.append(n)
        strip[n], heading[n] = s, hd
        om, ph = np.radians(rng.normal(0.0, 0.3, 2))
        ka = math.radians(90.0 - hd + rng.uniform(-1.0, 1.0))
        ka = math.atan2(math.sin(ka), math.cos(ka))
        dx, dy = rng.normal(0.0, jit, 2)
        ext[n] = ExteriorOrientation(
            e0 + x + dx, n0 + y + dy, z0 + H + rng.normal(0.0, 0.005 * H), om, ph, ka
        )
        base = _scan_base(spec, rng)
        code = spec.rotated_scans.get(n, 0)
        scan0[n] = base
        scan[n] = PixelTransform(base.matrix @ dihedral_matrix(code, w, h))
        codes[n] = code
        size[n] = (w, h) if code % 2 == 0 else (h, w)
    ztab = _Dem(dem.z, dem.x0, dem.y0, dem.spacing)
    control = []
    full = [c for c in crossings if c[2]]
    inner = [c for c in crossings if not c[2]]
    if len(inner) < 2:  # small blocks: edge points that are no corner become checks
        inner += [c for c in full if not c[3]][: 2 - len(inner)]
        full = [c for c in full if c not in inner]
    # the control's sigmas include the identification of the point in the images: a fifth
    # (plan) and a third (height) of the ground pixel, at least 3 and 5 cm
    sxy = round(max(0.03, 0.2 * spec.gsd), 3)
    sz = round(max(0.05, 0.3 * spec.gsd), 3)
    for k, (x, y, *_) in enumerate(full[:10] + inner[:4]):
        X, Y = e0 + x, n0 + y
        Z = float(ztab.eval(np.array([X]), np.array([Y]))[0][0])
        kind = "full" if k < len(full[:10]) else "check"
        control.append(
            {"name": f"C{k + 1:02d}", "X": X, "Y": Y, "Z": Z, "sigma_xy_m": sxy,
             "sigma_z_m": sz, "kind": kind}
        )  # fmt: skip
    return Truth(spec, camera, images, strip, heading, ext, scan, scan0, codes, size, dem,
                 control, lake, roads)  # fmt: skip


def synth_block(
    out_dir, spec: SynthSpec | None = None, progress: Callable[[int, int], None] | None = None
) -> Path:
    """Write a synthetic block into ``out_dir`` (created) and return the path of ``truth.json``.

    Files: ``img_<n>.tif`` (8-bit grey, tiled 256 x 256, no georeferencing),
    ``camera.toml``, ``images.csv`` (approximate centres = truth + Gaussian noise of
    ``spec.approx_error``), ``control.csv``, ``gcp.csv`` (a simulated operator's
    measurements of the control points, :func:`_operator_measurements`), ``dem.tif`` and
    ``truth.json``.
    ``progress(done, total)`` counts rendered images.
    """
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning
    from rasterio.transform import Affine

    spec = spec or SynthSpec()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    truth = _build_truth(spec)
    total = len(truth.images)
    if progress:
        progress(0, total)
    files = {}
    for k, n in enumerate(truth.images):
        img = render_image(truth, n)
        files[n] = f"img_{n}.tif"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(
                out / files[n], "w", driver="GTiff", width=img.shape[1], height=img.shape[0],
                count=1, dtype="uint8", tiled=True, blockxsize=256, blockysize=256,
            ) as ds:  # fmt: skip
                ds.write(img, 1)
        if progress:
            progress(k + 1, total)
    d = truth.dem
    sp = d.spacing
    with rasterio.open(
        out / "dem.tif", "w", driver="GTiff", width=d.z.shape[1], height=d.z.shape[0], count=1,
        dtype="float32", crs=spec.crs,
        transform=Affine(sp, 0.0, d.x0 - sp / 2, 0.0, -sp, d.y0 + sp / 2),
    ) as ds:  # fmt: skip
        ds.write(d.z, 1)
    (out / "camera.toml").write_text(truth.camera.to_toml(), encoding="utf-8")
    rng = np.random.default_rng([spec.seed, 53])
    lines = ["image,strip,file,X,Y,Z,heading_deg"]
    for n in truth.images:
        xyz = truth.exterior[n].centre + rng.normal(0.0, spec.approx_error, 3)
        lines.append(
            f"{n},{truth.strip[n]},{files[n]},{xyz[0]:.3f},{xyz[1]:.3f},{xyz[2]:.3f},"
            f"{truth.heading[n]:g}"
        )
    (out / "images.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    lines = ["name,X,Y,Z,sigma_xy_m,sigma_z_m,kind"]
    for c in truth.control:
        lines.append(
            f"{c['name']},{c['X']:.4f},{c['Y']:.4f},{c['Z']:.4f},{c['sigma_xy_m']},"
            f"{c['sigma_z_m']},{c['kind']}"
        )
    (out / "control.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (out / "gcp.csv").write_text(_operator_measurements(truth, rng), encoding="utf-8")
    doc = {
        "format": "apygis synthetic block truth",
        "version": 1,
        "crs": spec.crs,
        "spec": spec.to_dict(),
        "camera": truth.camera.to_dict(),
        "gsd_m": spec.gsd,
        "images": [
            {
                "number": n,
                "strip": truth.strip[n],
                "file": files[n],
                "heading_deg": truth.heading[n],
                "exterior": truth.exterior[n].to_dict(),
                "scan": truth.scan[n].to_list(),
                "scan_base": truth.scan_base[n].to_list(),
                "dihedral": truth.dihedral_code[n],
                "size_px": list(truth.size[n]),
            }
            for n in truth.images
        ],
        "dem": {
            "file": "dem.tif",
            "x0": d.x0,
            "y0": d.y0,
            "spacing": d.spacing,
            "shape": list(d.z.shape),
        },
        "control": truth.control,
        "lake": list(truth.lake) if truth.lake else None,
        "roads": [asdict(r) for r in truth.roads],
    }
    path = out / "truth.json"
    path.write_text(json.dumps(doc, indent=1), encoding="utf-8")
    return path


#: The simulated operator of ``gcp.csv``: pointing error (px) of a precise and of an
#: approximate measurement, and the margin (px) a point must keep from the image's edge.
OPERATOR_PRECISE_PX = 0.15
OPERATOR_APPROX_PX = 3.0
OPERATOR_MARGIN_PX = 40


def _operator_measurements(truth: Truth, rng) -> str:
    """``gcp.csv`` (the input of ``apygis at gcp --measure``): a simulated operator's
    measurements of every control and check point, digitised precisely (pointing error
    :data:`OPERATOR_PRECISE_PX`) in the image where the point lies nearest the centre and
    approximately (:data:`OPERATOR_APPROX_PX`) in the others that see it."""
    lines = ["point,image,x_px,y_px,mode"]
    for c in truth.control:
        XYZ = np.array([[c["X"], c["Y"], c["Z"]]])
        seen = []
        for n in truth.images:
            w, h = truth.size[n]
            px = truth.project(n, XYZ)[0]
            m = OPERATOR_MARGIN_PX
            if m <= px[0] <= w - 1 - m and m <= px[1] <= h - 1 - m:
                seen.append((float(np.hypot(px[0] / w - 0.5, px[1] / h - 0.5)), n, px))
        if len(seen) < 2:
            continue
        seen.sort(key=lambda t: t[0])
        for k, (_, n, px) in enumerate(seen):
            sd = OPERATOR_PRECISE_PX if k == 0 else OPERATOR_APPROX_PX
            x, y = px + rng.normal(0.0, sd, 2)
            lines.append(f"{c['name']},{n},{x:.2f},{y:.2f},{'precise' if k == 0 else 'approx'}")
    return "\n".join(lines) + "\n"


def load_truth(path) -> Truth:
    """Read ``truth.json`` (and the ``dem.tif`` it names) written by :func:`synth_block`."""
    import rasterio

    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        spec = SynthSpec.from_dict(doc["spec"])
        camera = Camera.from_dict(doc["camera"], str(path))
        with rasterio.open(path.parent / doc["dem"]["file"]) as ds:
            z = ds.read(1).astype(np.float32)
        dem = _Dem(
            z, float(doc["dem"]["x0"]), float(doc["dem"]["y0"]), float(doc["dem"]["spacing"])
        )
        images, strip, heading, ext, scan, scan0, codes, size = [], {}, {}, {}, {}, {}, {}, {}
        for rec in doc["images"]:
            n = int(rec["number"])
            images.append(n)
            strip[n], heading[n] = int(rec["strip"]), float(rec["heading_deg"])
            ext[n] = ExteriorOrientation.from_dict(rec["exterior"])
            scan[n] = PixelTransform.from_list(rec["scan"])
            scan0[n] = PixelTransform.from_list(rec["scan_base"])
            codes[n] = int(rec["dihedral"])
            size[n] = (int(rec["size_px"][0]), int(rec["size_px"][1]))
        lake = tuple(doc["lake"]) if doc.get("lake") else None
        roads = [_Road(**r) for r in doc["roads"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise FormatError(f"{path}: not a synthetic block truth file ({exc})") from None
    return Truth(spec, camera, images, strip, heading, ext, scan, scan0, codes, size, dem,
                 doc["control"], lake, roads)  # fmt: skip
