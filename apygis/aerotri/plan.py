"""Block planning: footprints, strips, image pairs, subblocks and von Gruber gaps.

Pure functions on plain data: the caller reads the block (image list, camera)
and passes :class:`PlanImage` and :class:`Frame` objects; nothing here reads a
file or a database.

Conventions (those of :mod:`apygis.aerotri` and :mod:`apygis.orient.rotation`):
ground X east, Y north, Z up, metres; photo x right, y up, millimetres.

Flight direction
    ``heading_deg`` is the azimuth of the flight, degrees clockwise from grid
    north (+Y): ``heading = atan2(dX, dY)``. Photos are taken with the photo
    x axis along the flight, so a vertical photo (``omega = phi = 0``) has
    ``kappa = radians(90 - heading_deg)``.
Footprint
    The four frame corners ``(+-w/2, +-h/2)`` (photo mm) intersected with the
    plane ``Z = terrain_z`` by :func:`apygis.orient.collinearity.photo_to_ground`;
    for a vertical photo a rectangle of ``w * m`` (along the flight) by
    ``h * m`` (across), ``m = (Z - terrain_z) / c`` the image scale number.
Overlap of two images
    ``area(F_a & F_b) / min(area(F_a), area(F_b))``: for two equal footprints
    along a strip the forward overlap ``p``, across strips the side overlap
    ``q``, and ``p * q`` for diagonal neighbours.
Strip kinds
    The block's main direction is the most common strip direction modulo 180
    degrees (weighted by the number of images); a strip whose direction differs
    from it by more than 45 degrees (mod 180) is a *cross* strip, the others are
    *normal* strips (alternating flight directions are normal).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from shapely.geometry import Polygon

from apygis.errors import OrientationError
from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation, photo_to_ground

__all__ = [
    "BlockPlan",
    "Frame",
    "GapReport",
    "Overlaps",
    "Pair",
    "PlanImage",
    "Strip",
    "azimuth_deg",
    "derive_headings",
    "footprint",
    "gap_report",
    "gruber_regions",
    "plan_block",
    "plan_text",
    "strips_from_track",
]

#: Turn (degrees) beyond which :func:`strips_from_track` starts a new line.
TRACK_TURN_DEG = 30.0
#: Difference (degrees, mod 180) from the main direction beyond which a strip is a cross strip.
CROSS_STRIP_DEG = 45.0


@dataclass(frozen=True)
class PlanImage:
    """One image of the block as planning needs it.

    Parameters
    ----------
    image : int
        Image number (positive).
    strip : int
        Strip (flight line) number.
    X, Y, Z : float
        Approximate projection centre, metres; ``Z`` the flying height above datum.
    heading_deg : float or None
        Flight azimuth (module docstring); ``None``: derived from the strip
        (:func:`derive_headings`).
    x_azimuth_deg : float or None
        Azimuth of the photo x axis when it is known not to point along the
        flight (a drone's camera yawed against its course, found by matching);
        ``None``: along the flight. Only the footprint uses it.
    """

    image: int
    strip: int
    X: float
    Y: float
    Z: float
    heading_deg: float | None = None
    x_azimuth_deg: float | None = None


@dataclass(frozen=True)
class Frame:
    """The image format of the camera: principal distance and frame size.

    ``width_mm`` is the extent along the photo x axis, which points along the
    flight; ``height_mm`` the extent along y (across the flight). Film: 230 x
    230 mm; digital: the sensor size ``W * pixel`` by ``H * pixel``.
    """

    focal_mm: float
    width_mm: float = 230.0
    height_mm: float = 230.0

    def __post_init__(self):
        for name in ("focal_mm", "width_mm", "height_mm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise OrientationError(f"frame: {name} must be a positive number, got {v!r}")

    @classmethod
    def from_camera(cls, camera) -> Frame:
        """The frame of an :class:`apygis.aerotri.camera.Camera` (film 230 x 230 mm,
        digital ``sensor_px * pixel_um``)."""
        if camera.kind == "digital" and camera.pixel_um and camera.sensor_px:
            p = camera.pixel_um / 1000.0
            return cls(camera.focal_mm, camera.sensor_px[0] * p, camera.sensor_px[1] * p)
        return cls(camera.focal_mm)


@dataclass(frozen=True)
class Strip:
    """A strip: its images ordered along the flight, its azimuth and kind."""

    number: int
    images: list[int]
    direction_deg: float
    kind: str  # "normal" | "cross"


@dataclass(frozen=True)
class Pair:
    """An image pair (model) ``a < b`` to be matched; ``overlap`` as in the module docstring."""

    a: int
    b: int
    kind: str  # "strip" | "cross"
    overlap: float


@dataclass
class Overlaps:
    """Overlap statistics, fractions in 0..1.

    ``forward[strip]``: mean overlap of consecutive images of the strip.
    ``side[(s1, s2)]``: side overlap of neighbouring normal strips (ordered
    across the main direction): ``area(U1 & U2) / (L * w)`` with ``U`` the
    union of a strip's footprints, ``L`` the length of ``U1 & U2`` along the
    main direction and ``w`` the mean footprint width across it (exact for a
    regular block).
    """

    forward: dict[int, float] = field(default_factory=dict)
    side: dict[tuple[int, int], float] = field(default_factory=dict)


@dataclass
class BlockPlan:
    """The plan of a block (see :func:`plan_block`)."""

    images: dict[int, PlanImage]
    headings: dict[int, float]
    footprints: dict[int, Polygon]
    strips: dict[int, Strip]
    main_direction_deg: float
    pairs: list[Pair]
    subblocks: list[list[int]]
    overlaps: Overlaps
    connected: list[list[int]]

    def pair(self, a: int, b: int) -> Pair:
        """The pair of images ``a`` and ``b`` (either order)."""
        a, b = min(a, b), max(a, b)
        for p in self.pairs:
            if p.a == a and p.b == b:
                return p
        raise OrientationError(f"images {a} and {b} are not a pair of the block plan")


@dataclass
class GapReport:
    """Tie points in the six von Gruber regions of a model (:func:`gruber_regions`).

    ``counts[k]``: points in region ``k``; ``gaps``: indices of the regions
    with fewer than ``min_points``; ``regions``: the six polygons.
    """

    counts: list[int]
    gaps: list[int]
    regions: list[Polygon]


# --- directions -----------------------------------------------------------------------


def azimuth_deg(dx, dy):
    """Azimuth of the vector ``(dx, dy)``, degrees clockwise from +Y, in ``[0, 360)``."""
    return np.mod(np.degrees(np.arctan2(dx, dy)), 360.0)


def _angdiff(a, b, period: float = 360.0):
    """Absolute difference of angles (degrees) modulo ``period``, in ``[0, period/2]``."""
    d = np.mod(np.asarray(a, dtype=float) - b, period)
    return np.minimum(d, period - d)


def _circ_mean(deg, weights=None, period: float = 360.0) -> float:
    """Circular mean of angles (degrees) of the given period."""
    t = np.radians(np.asarray(deg, dtype=float)) * (360.0 / period)
    w = np.ones_like(t) if weights is None else np.asarray(weights, dtype=float)
    m = math.atan2(float(np.sum(w * np.sin(t))), float(np.sum(w * np.cos(t))))
    return float(np.mod(math.degrees(m) * period / 360.0, period))


def _main_axis(directions, weights) -> float:
    """The most common direction modulo 180 (degrees in ``[0, 180)``).

    Each direction is a candidate; the one with the largest weight within
    +-22.5 degrees (mod 180) wins, and the result is the weighted axial mean
    of the directions in that window.
    """
    d = np.mod(np.asarray(directions, dtype=float), 180.0)
    w = np.asarray(weights, dtype=float)
    near = _angdiff(d[:, None], d[None, :], 180.0) <= 22.5
    best = int(np.argmax(near @ w))
    sel = near[best]
    return _circ_mean(d[sel], w[sel], 180.0)


def _line_azimuth(xy: np.ndarray) -> float | None:
    """Azimuth of the line of centres ``xy`` (in flight order), or None if degenerate.

    The direction is the principal axis of the centres (total least squares),
    oriented from the first towards the last centre.
    """
    if len(xy) < 2:
        return None
    c = xy - xy.mean(axis=0)
    _, s, vt = np.linalg.svd(c, full_matrices=False)
    if s[0] <= 1e-9 * max(1.0, float(np.abs(xy).max())):
        return None
    u = vt[0]
    if np.dot(xy[-1] - xy[0], u) < 0:
        u = -u
    return float(azimuth_deg(u[0], u[1]))


def derive_headings(images: Iterable[PlanImage]) -> dict[int, float]:
    """Headings (degrees) of all images: the given ones, and for images without
    heading the azimuth of their strip's line of centres.

    The line of a strip is the principal axis of its centres, oriented from
    the lowest to the highest image number (the flight order). A strip whose
    centres do not define a line (a single image) gets the block's main
    direction: the most common azimuth of the other strips (weighted by their
    images), or of the given headings; 90 (east) if there is none.
    """
    imgs = list(images)
    by_strip: dict[int, list[PlanImage]] = {}
    for im in imgs:
        by_strip.setdefault(im.strip, []).append(im)
    line: dict[int, float | None] = {}
    for s, members in by_strip.items():
        members.sort(key=lambda im: im.image)
        xy = np.array([(im.X, im.Y) for im in members], dtype=float)
        line[s] = _line_azimuth(xy)
    dirs = [(az, len(by_strip[s])) for s, az in line.items() if az is not None]
    if not dirs:
        dirs = [(im.heading_deg, 1) for im in imgs if im.heading_deg is not None]
    if dirs:
        # Most common azimuth: the axis by _main_axis, then its sense by majority.
        az = np.array([d for d, _ in dirs])
        w = np.array([n for _, n in dirs], dtype=float)
        axis = _main_axis(az, w)
        along = _angdiff(az, axis) <= 90.0
        main = axis if w[along].sum() >= w[~along].sum() else axis + 180.0
    else:
        main = 90.0
    out: dict[int, float] = {}
    for im in imgs:
        if im.heading_deg is not None:
            out[im.image] = float(im.heading_deg) % 360.0
        else:
            az_s = line[im.strip]
            out[im.image] = float(main % 360.0) if az_s is None else az_s
    return out


def strips_from_track(images: Sequence[PlanImage], turn_deg: float = TRACK_TURN_DEG):
    """Split a flight track (images in time order) into lines: ``{image: line}``.

    Segments join consecutive centres; a segment starts a new run when its
    azimuth differs from the run's mean azimuth by more than ``turn_deg``.
    A run of at least two segments is a line (a lone run is a line too); a
    one-segment run between lines is the turn (connecting leg) and forms no
    line. Interior images of a run belong to its line; an image where two
    lines meet (a turn image) belongs to the line whose direction is closer
    to the image's own direction: its ``heading_deg`` if given, else the
    chord from the previous to the next image (ties: the earlier line).
    Images that belong to no line (between two connecting legs) are lines of
    their own. Lines are numbered 1, 2, ... in track order. Zero-length
    segments (repeated positions) take the previous segment's direction.
    """
    imgs = list(images)
    n = len(imgs)
    if n == 0:
        return {}
    if n == 1:
        return {imgs[0].image: 1}
    xy = np.array([(im.X, im.Y) for im in imgs], dtype=float)
    d = np.diff(xy, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    seg = azimuth_deg(d[:, 0], d[:, 1])
    ok = length > 1e-9 * max(1.0, float(np.abs(xy).max()))
    if not ok.any():
        return {im.image: 1 for im in imgs}
    first = int(np.argmax(ok))
    for j in range(n - 1):
        if not ok[j]:
            seg[j] = seg[j - 1] if j > 0 else seg[first]
    # runs of segments
    run_of = np.zeros(n - 1, dtype=int)
    runs: list[list[int]] = [[0]]
    for j in range(1, n - 1):
        mean = _circ_mean(seg[runs[-1]])
        if ok[j] and _angdiff(seg[j], mean) > turn_deg:
            runs.append([j])
        else:
            runs[-1].append(j)
        run_of[j] = len(runs) - 1
    is_line = [len(r) >= 2 or len(runs) == 1 for r in runs]
    run_dir = [_circ_mean(seg[r]) for r in runs]
    owner: list[int | None] = [None] * n
    for i in range(n):
        before = int(run_of[i - 1]) if i > 0 else None
        after = int(run_of[i]) if i < n - 1 else None
        cands = [r for r in dict.fromkeys((before, after)) if r is not None and is_line[r]]
        if len(cands) == 1:
            owner[i] = cands[0]
        elif len(cands) == 2:
            h = imgs[i].heading_deg
            if h is None:
                c = xy[i + 1] - xy[i - 1]
                h = float(azimuth_deg(c[0], c[1]))
            d0, d1 = _angdiff(h, run_dir[cands[0]]), _angdiff(h, run_dir[cands[1]])
            owner[i] = cands[1] if d1 < d0 - 1e-9 else cands[0]
    out: dict[int, int] = {}
    number: dict[object, int] = {}
    for i, im in enumerate(imgs):
        key: object = ("run", owner[i]) if owner[i] is not None else ("image", i)
        if key not in number:
            number[key] = len(number) + 1
        out[im.image] = number[key]
    return out


# --- footprints -------------------------------------------------------------------------


def footprint(
    img: PlanImage, frame: Frame, terrain_z: float, heading_deg: float | None = None
) -> Polygon:
    """Ground footprint of a vertical photo at the height ``terrain_z``.

    ``omega = phi = 0``, ``kappa = radians(90 - heading)``; the corners
    ``(-w/2, -h/2), (w/2, -h/2), (w/2, h/2), (-w/2, h/2)`` (photo mm, counter-
    clockwise on the photo) are intersected with ``Z = terrain_z`` by
    :func:`~apygis.orient.collinearity.photo_to_ground`. ``heading_deg``
    overrides the image's own heading (needed when that is None).
    """
    h = img.heading_deg if heading_deg is None else heading_deg
    if h is None:
        raise OrientationError(
            f"image {img.image}: no heading (derive it with derive_headings or plan_block)"
        )
    if not terrain_z < img.Z:
        raise OrientationError(
            f"image {img.image}: projection centre Z {img.Z} m is not above the terrain "
            f"height {terrain_z} m"
        )
    eo = ExteriorOrientation(img.X, img.Y, img.Z, 0.0, 0.0, math.radians(90.0 - h))
    w, hh = frame.width_mm / 2, frame.height_mm / 2
    corners = np.array([(-w, -hh), (w, -hh), (w, hh), (-w, hh)])
    g = photo_to_ground(corners, terrain_z, eo, InteriorOrientation(frame.focal_mm))
    return Polygon(g[:, :2])


# --- the plan ---------------------------------------------------------------------------


def _overlap_ratio(fa, fb) -> np.ndarray:
    """Vectorised ``area(a & b) / min(area(a), area(b))`` for arrays of polygons."""
    inter = shapely.area(shapely.intersection(fa, fb))
    smaller = np.minimum(shapely.area(fa), shapely.area(fb))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(smaller > 0, inter / smaller, 0.0)


def _components(nodes: list[int], edges: list[tuple[int, int]]) -> list[list[int]]:
    """Connected components (sorted image lists, largest first)."""
    index = {v: i for i, v in enumerate(nodes)}
    n = len(nodes)
    if n == 0:
        return []
    r = [index[a] for a, _ in edges]
    c = [index[b] for _, b in edges]
    g = coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n))
    k, labels = connected_components(g, directed=False)
    comps = [sorted(nodes[i] for i in np.flatnonzero(labels == j)) for j in range(k)]
    comps.sort(key=lambda m: (-len(m), m[0]))
    return comps


def _thin_pairs(nodes: list[int], pairs: list[Pair], k: int) -> list[Pair]:
    """At most ``k`` pairs per image, the largest overlaps, keeping the block connected.

    A maximum spanning forest of the pair graph (weights: overlap) is kept
    first, so that thinning never splits a component (an image may keep more
    than ``k`` pairs where the forest needs them); then pairs by decreasing
    overlap are added while both images have fewer than ``k``.
    """
    if not pairs:
        return pairs
    index = {v: i for i, v in enumerate(nodes)}
    n = len(nodes)
    r = np.array([index[p.a] for p in pairs])
    c = np.array([index[p.b] for p in pairs])
    # minimum spanning tree of (2 - overlap) = maximum spanning tree of overlap (all weights > 0)
    w = 2.0 - np.array([p.overlap for p in pairs])
    mst = minimum_spanning_tree(coo_matrix((w, (r, c)), shape=(n, n)).tocsr()).tocoo()
    tree = {(min(i, j), max(i, j)) for i, j in zip(mst.row.tolist(), mst.col.tolist(), strict=True)}
    keep = np.zeros(len(pairs), dtype=bool)
    count = np.zeros(n, dtype=int)
    for e, (i, j) in enumerate(zip(r.tolist(), c.tolist(), strict=True)):
        if (min(i, j), max(i, j)) in tree:
            keep[e] = True
            count[i] += 1
            count[j] += 1
    for e in np.argsort(-np.array([p.overlap for p in pairs]), kind="stable"):
        i, j = int(r[e]), int(c[e])
        if not keep[e] and count[i] < k and count[j] < k:
            keep[e] = True
            count[i] += 1
            count[j] += 1
    return [p for p, kp in zip(pairs, keep, strict=True) if kp]


def _subblocks(order: list[int], size: int | None, extra: dict[int, int]) -> list[list[int]]:
    """Windows of ``size`` strips of ``order``, consecutive windows sharing one strip;
    each strip of ``extra`` (cross strips) joins the window with index ``extra[strip]``."""
    if size is None or size >= len(order):
        windows = [list(order)]
    else:
        windows = []
        start = 0
        while True:
            end = min(start + size, len(order))
            windows.append(list(order[max(0, end - size) : end]))
            if end >= len(order):
                break
            start = end - 1
    for s, w in extra.items():
        windows[min(w, len(windows) - 1)].append(s)
    return windows


def plan_block(
    images: Iterable[PlanImage],
    frame: Frame,
    terrain_z: float,
    *,
    min_overlap: float = 0.1,
    subblock_strips: int | None = None,
    max_pairs_per_image: int | None = None,
) -> BlockPlan:
    """Plan a block: footprints, strips, pairs, subblocks, overlaps, connectivity.

    Parameters
    ----------
    images : iterable of PlanImage
        Image numbers must be unique. Missing headings are derived
        (:func:`derive_headings`).
    frame : Frame
    terrain_z : float
        Mean terrain height, metres.
    min_overlap : float
        Least overlap (module docstring) of second in-strip neighbours and of
        pairs from different strips.
    subblock_strips : int or None
        Normal strips per subblock (>= 2); consecutive subblocks (strips
        ordered across the main direction, in the sense of increasing strip
        numbers) share one strip. Each cross strip joins
        the subblock with which it has the most pairs. None: one subblock.
    max_pairs_per_image : int or None
        Thin dense blocks (drones) to at most this many pairs per image, those
        of largest overlap, never disconnecting the block.

    Pairs
    -----
    In a strip (ordered along the flight) the neighbours ``i, i+1`` (when
    their footprints overlap at all) and the second neighbours ``i, i+2`` when
    their overlap is at least ``min_overlap`` (triple overlap); kind "strip".
    Images of different strips whose overlap is at least ``min_overlap``;
    kind "cross". A plan whose pair graph is not connected is not an error:
    ``connected`` lists its parts, largest first.
    """
    imgs = list(images)
    if not imgs:
        raise OrientationError("plan_block: the block has no images")
    by_number: dict[int, PlanImage] = {}
    for im in imgs:
        if im.image in by_number:
            raise OrientationError(f"plan_block: image number {im.image} occurs twice")
        by_number[im.image] = im
    if subblock_strips is not None and subblock_strips < 2:
        raise OrientationError(
            f"plan_block: subblock_strips must be at least 2 (subblocks share a strip), "
            f"got {subblock_strips}"
        )
    headings = derive_headings(imgs)
    numbers = sorted(by_number)
    fps = {
        i: footprint(
            by_number[i],
            frame,
            terrain_z,
            headings[i] if by_number[i].x_azimuth_deg is None else by_number[i].x_azimuth_deg,
        )
        for i in numbers
    }

    # strips: ordered along their flight direction (mean heading of their images)
    members: dict[int, list[int]] = {}
    for i in numbers:
        members.setdefault(by_number[i].strip, []).append(i)
    sdir: dict[int, float] = {}
    sorder: dict[int, list[int]] = {}
    for s, ims in members.items():
        az = _circ_mean([headings[i] for i in ims])
        u = np.array([math.sin(math.radians(az)), math.cos(math.radians(az))])
        xy = np.array([(by_number[i].X, by_number[i].Y) for i in ims])
        t = xy @ u
        sorder[s] = [ims[k] for k in np.lexsort((np.array(ims), np.round(t, 6)))]
        sdir[s] = az
    snums = sorted(members)
    main = _main_axis([sdir[s] for s in snums], [len(members[s]) for s in snums])
    strips = {
        s: Strip(
            s,
            sorder[s],
            sdir[s],
            "cross" if _angdiff(sdir[s], main, 180.0) > CROSS_STRIP_DEG else "normal",
        )
        for s in snums
    }

    # pairs in strips
    pairs: dict[tuple[int, int], Pair] = {}
    forward: dict[int, float] = {}
    for s in snums:
        o = sorder[s]
        for step in (1, 2):
            if len(o) <= step:
                continue
            fa = np.array([fps[i] for i in o[:-step]])
            fb = np.array([fps[i] for i in o[step:]])
            ov = _overlap_ratio(fa, fb)
            if step == 1:
                forward[s] = float(ov.mean())
            for a, b, v in zip(o[:-step], o[step:], ov.tolist(), strict=True):
                if v > 0 if step == 1 else v >= min_overlap:
                    key = (min(a, b), max(a, b))
                    pairs[key] = Pair(key[0], key[1], "strip", v)
    # pairs between strips: candidates from an STR tree
    geoms = np.array([fps[i] for i in numbers])
    tree = shapely.STRtree(geoms)
    ia, ib = tree.query(geoms, predicate="intersects")
    strip_of = np.array([by_number[i].strip for i in numbers])
    sel = (ia < ib) & (strip_of[ia] != strip_of[ib])
    ia, ib = ia[sel], ib[sel]
    if len(ia):
        ov = _overlap_ratio(geoms[ia], geoms[ib])
        for a, b, v in zip(ia.tolist(), ib.tolist(), ov.tolist(), strict=True):
            if v >= min_overlap:
                pairs[(numbers[a], numbers[b])] = Pair(numbers[a], numbers[b], "cross", v)
    pair_list = [pairs[k] for k in sorted(pairs)]
    if max_pairs_per_image is not None:
        if max_pairs_per_image < 1:
            raise OrientationError(
                f"plan_block: max_pairs_per_image must be at least 1, got {max_pairs_per_image}"
            )
        pair_list = _thin_pairs(numbers, pair_list, max_pairs_per_image)

    # normal strips across the main direction; side overlaps of neighbours
    mr = math.radians(main)
    along = np.array([math.sin(mr), math.cos(mr)])
    across = np.array([along[1], -along[0]])  # to the right of the main direction
    normal = [s for s in snums if strips[s].kind == "normal"]

    def centre_of(s: int) -> np.ndarray:
        return np.mean([(by_number[i].X, by_number[i].Y) for i in members[s]], axis=0)

    normal.sort(key=lambda s: float(centre_of(s) @ across))
    if len(normal) > 1 and normal[0] > normal[-1]:
        normal.reverse()  # across the block in the sense of increasing strip numbers
    unions = {s: shapely.union_all([fps[i] for i in members[s]]) for s in snums}
    side: dict[tuple[int, int], float] = {}
    for s1, s2 in itertools.pairwise(normal):
        inter = shapely.intersection(unions[s1], unions[s2])
        if inter.is_empty or inter.area <= 0:
            side[(s1, s2)] = 0.0
            continue
        pts = np.asarray(shapely.get_coordinates(inter))
        length = float(np.ptp(pts @ along))
        fw = [fps[i] for i in members[s1] + members[s2]]
        widths = [float(np.ptp(np.asarray(f.exterior.coords) @ across)) for f in fw]
        side[(s1, s2)] = float(inter.area / (length * float(np.mean(widths))))

    # subblocks: cross strips join the window they have most pairs with
    extra: dict[int, int] = {}
    if subblock_strips is not None:
        windows = _subblocks(normal, subblock_strips, {})
        for s in snums:
            if strips[s].kind != "cross":
                continue
            mine = set(members[s])
            score = []
            for w in windows:
                other = {i for t in w for i in members[t]}
                score.append(
                    sum(
                        1
                        for p in pair_list
                        if (p.a in mine and p.b in other) or (p.b in mine and p.a in other)
                    )
                )
            extra[s] = int(np.argmax(score)) if score else 0
        if not normal:  # only cross strips (cannot happen: main is most common); keep all
            extra = {}
    subblocks = _subblocks(normal, subblock_strips, extra) if normal else [list(snums)]

    connected = _components(numbers, [(p.a, p.b) for p in pair_list])
    return BlockPlan(
        images=by_number,
        headings=headings,
        footprints=fps,
        strips=strips,
        main_direction_deg=main,
        pairs=pair_list,
        subblocks=subblocks,
        overlaps=Overlaps(forward, side),
        connected=connected,
    )


# --- von Gruber regions -----------------------------------------------------------------


def _largest_polygon(g) -> Polygon:
    if isinstance(g, Polygon):
        return g
    polys = [p for p in getattr(g, "geoms", []) if isinstance(p, Polygon)]
    if not polys:
        return Polygon()
    return max(polys, key=lambda p: p.area)


def gruber_regions(plan: BlockPlan, pair: Pair | tuple[int, int]) -> list[Polygon]:
    """The six standard (von Gruber) tie point regions of the model ``a-b``, ground coordinates.

    Model area ``M = F_a & F_b`` (footprints). With ``u`` the unit vector of
    the base (nadir of ``a`` to nadir of ``b``; for vertical photos the nadir
    is the projection centre's ``(X, Y)``), turned to the nearer side of the
    smallest rectangle around ``M`` (so that the squares are aligned with the
    frame edges also for diagonal pairs between strips; for a pair along a
    strip this changes nothing), and ``v`` the unit vector 90 degrees
    counter-clockwise from it, ``M`` spans ``[v0, v1]`` across the base,
    width ``W = v1 - v0``. The regions are squares (sides parallel to ``u`` and
    ``v``) of side ``s = min(W / 4, |u_b - u_a|)`` (the two columns never
    overlap), centred at

    * columns ``u_a`` and ``u_b``: the nadirs along the base; a nadir outside
      ``[u0, u1]`` (``M``'s extent along the base: models across strips, or
      forward overlaps below 50 %) is moved to the nearest position of
      ``[u0 + s/2, u1 - s/2]``, so that its squares lie inside the model;
    * rows ``v1 - s/2`` (top), ``(v0 + v1) / 2`` (centre) and ``v0 + s/2``
      (bottom): the standard positions at the model's edges across the base,
      moved in by half a square so that a square lies inside ``M``;

    and clipped to ``M``. Order: ``a``-top, ``a``-centre, ``a``-bottom,
    ``b``-top, ``b``-centre, ``b``-bottom.
    """
    a, b = (pair.a, pair.b) if isinstance(pair, Pair) else (min(pair), max(pair))
    try:
        fa, fb = plan.footprints[a], plan.footprints[b]
    except KeyError as exc:
        raise OrientationError(f"gruber_regions: image {exc.args[0]} is not in the plan") from None
    model = _largest_polygon(fa.intersection(fb))
    if model.is_empty or model.area <= 0:
        raise OrientationError(f"gruber_regions: the footprints of {a} and {b} do not overlap")
    na = np.array([plan.images[a].X, plan.images[a].Y])
    nb = np.array([plan.images[b].X, plan.images[b].Y])
    base = nb - na
    if np.hypot(*base) <= 1e-9 * max(1.0, float(np.abs(na).max())):
        h = math.radians(plan.headings[a])
        base = np.array([math.sin(h), math.cos(h)])
    u = base / np.hypot(*base)
    # snap u to the nearer side direction of the model's minimum rotated rectangle
    rect = np.asarray(model.minimum_rotated_rectangle.exterior.coords)
    sides = np.diff(rect[:3], axis=0)
    norms = np.hypot(sides[:, 0], sides[:, 1])
    if np.all(norms > 0):
        sides = sides / norms[:, None]
        k = int(np.argmax(np.abs(sides @ u)))
        u = sides[k] * np.sign(sides[k] @ u)
    v = np.array([-u[1], u[0]])
    pts = np.asarray(model.exterior.coords)
    pu, pv = pts @ u, pts @ v
    u0, u1, v0, v1 = float(pu.min()), float(pu.max()), float(pv.min()), float(pv.max())
    width = v1 - v0
    ua, ub = float(na @ u), float(nb @ u)
    sep = abs(ub - ua)
    s = width / 4 if sep <= 0 else min(width / 4, sep)

    def clamp(t: float) -> float:
        if u0 <= t <= u1:
            return t
        lo, hi = u0 + s / 2, u1 - s / 2
        return (lo + hi) / 2 if lo > hi else min(max(t, lo), hi)

    cols = [clamp(ua), clamp(ub)]
    if abs(cols[1] - cols[0]) < s:  # clamping pushed both into a short model: spread them
        mid = (cols[0] + cols[1]) / 2
        sgn = 1.0 if ub >= ua else -1.0
        cols = [mid - sgn * s / 2, mid + sgn * s / 2]
    rows = [v1 - s / 2, (v0 + v1) / 2, v0 + s / 2]
    half = s / 2
    square = np.array([(-half, -half), (half, -half), (half, half), (-half, half)])
    out = []
    for cu in cols:
        for cv in rows:
            corners = (cu + square[:, 0])[:, None] * u + (cv + square[:, 1])[:, None] * v
            out.append(_largest_polygon(Polygon(corners).intersection(model)))
    return out


def gap_report(
    plan: BlockPlan, pair: Pair | tuple[int, int], ground_xy, min_points: int = 3
) -> GapReport:
    """Count tie points (ground ``X, Y`` of shape (n, 2)) in the six von Gruber regions.

    A point on a region's boundary counts; regions with fewer than
    ``min_points`` points are gaps.
    """
    regions = gruber_regions(plan, pair)
    xy = np.asarray(ground_xy, dtype=float).reshape(-1, 2)
    counts = [
        int(np.count_nonzero(shapely.intersects_xy(r, xy[:, 0], xy[:, 1])))
        if not r.is_empty and len(xy)
        else 0
        for r in regions
    ]
    return GapReport(counts, [k for k, c in enumerate(counts) if c < min_points], regions)


# --- text -------------------------------------------------------------------------------


def _ranges(nums: Sequence[int]) -> str:
    """``[1, 2, 3, 5]`` -> ``"1-3, 5"`` (in the given order, runs of +-1)."""
    if not nums:
        return "-"
    parts = []
    start = prev = nums[0]
    for x in [*list(nums[1:]), None]:
        if x is not None and abs(x - prev) == 1 and (prev - start) * (x - prev) >= 0:
            prev = x
            continue
        parts.append(str(start) if start == prev else f"{start}-{prev}")
        if x is not None:
            start = prev = x
    return ", ".join(parts)


def plan_text(
    plan: BlockPlan,
    *,
    points_per_pair: dict[tuple[int, int], int] | None = None,
    gaps: dict[tuple[int, int], list[int]] | None = None,
) -> str:
    """The block plan as text: strips (images, direction, kind, forward overlap),
    side overlaps, pairs, subblocks, disconnected parts, and per model the tie
    points and the gap regions (indices of :func:`gruber_regions`) when given."""
    lines = [
        f"block: {len(plan.images)} images, {len(plan.strips)} strips, "
        f"main direction {plan.main_direction_deg:.1f} deg (mod 180)",
        "strips:",
    ]
    for s, st in sorted(plan.strips.items()):
        fwd = plan.overlaps.forward.get(s)
        f = f", forward overlap {100 * fwd:.0f}%" if fwd is not None else ""
        lines.append(
            f"  strip {s}: {st.kind}, heading {st.direction_deg:.1f} deg, "
            f"{len(st.images)} images ({_ranges(st.images)}){f}"
        )
    if plan.overlaps.side:
        lines.append("side overlaps:")
        for (s1, s2), q in plan.overlaps.side.items():
            lines.append(f"  strips {s1}-{s2}: {100 * q:.0f}%")
    n_strip = sum(p.kind == "strip" for p in plan.pairs)
    lines.append(
        f"pairs: {len(plan.pairs)} ({n_strip} in strips, {len(plan.pairs) - n_strip} across strips)"
    )
    lines.append(f"subblocks: {len(plan.subblocks)}")
    for k, sb in enumerate(plan.subblocks, 1):
        n = sum(len(plan.strips[s].images) for s in sb)
        lines.append(f"  subblock {k}: strips {', '.join(map(str, sb))} ({n} images)")
    if len(plan.connected) > 1:
        lines.append(f"NOT CONNECTED: {len(plan.connected)} parts")
        for k, part in enumerate(plan.connected, 1):
            lines.append(f"  part {k}: {len(part)} images ({_ranges(part)})")
    else:
        lines.append("connected: yes")
    if points_per_pair is not None or gaps is not None:
        names = ("a-top", "a-centre", "a-bottom", "b-top", "b-centre", "b-bottom")
        lines.append("models:")
        for p in plan.pairs:
            key = (p.a, p.b)
            txt = f"  {p.a}-{p.b} ({p.kind}, overlap {100 * p.overlap:.0f}%)"
            if points_per_pair is not None:
                txt += f": {points_per_pair.get(key, 0)} points"
            g = (gaps or {}).get(key)
            if g:
                txt += "; gaps " + ", ".join(names[k] if 0 <= k < 6 else str(k) for k in g)
            lines.append(txt)
    return "\n".join(lines) + "\n"
