"""Between APY's referenced line points and the plain polylines of GIS and CAD files.

:func:`export_lines` turns each chain of a layer into a polyline for a
writer (a branch's polyline ends on its junction's vertex); :func:`rebuild`
turns polylines read from a file into line points with references again,
rebuilding the topology that plain geometry lost. It is the one rebuild:
every reader of plain geometry (GENERATE, E00 arcs, DXF, OGR/GeoPackage
features and the edited lines of an apygis GeoPackage) calls it through
:meth:`Layer.add_polylines <apygis.model.map.Layer.add_polylines>`, and
logs its :class:`RebuildReport`. Its rules (snapping in metres, duplicate
vertices, rings, merging ends that meet, junctions, and what it refuses)
are stated in :func:`rebuild`.

Polylines travel as shapely's ``linestrings(coords, indices=...)`` do, in
CSR form: one ``(N, 2|3)`` coordinate array and ``offsets`` (``m + 1``
entries; line ``k`` is ``coords[offsets[k]:offsets[k + 1]]``);
:func:`to_csr` builds them from a list of arrays.

Exporting a layer and rebuilding the polylines in an empty layer gives the
same vertices, chains, closed lines and branches again (point numbers may
differ), except where plain geometry is ambiguous: a branch joined to the
end point of a line of its code comes back merged with that line.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from apygis.model import topology
from apygis.model.records import LINE_DTYPE, MAX_CODE, NO_REF

__all__ = [
    "DEFAULT_SNAP_M",
    "REFUSALS",
    "LineSet",
    "Polyline",
    "RebuildReport",
    "check_polylines",
    "export_lines",
    "metres_per_unit_at",
    "rebuild",
    "to_csr",
    "tolerance_in_crs",
]

log = logging.getLogger(__name__)


class Polyline(NamedTuple):
    """One line for a writer: vertices (n, 3) in metres, code, closed flag, point numbers."""

    coords: np.ndarray
    code: int
    closed: bool
    nums: tuple[int, ...]


@dataclass(frozen=True)
class LineSet(Sequence):
    """The lines of a layer in CSR form; a sequence of :class:`Polyline`.

    ``coords[offsets[k]:offsets[k + 1]]`` are the vertices of line ``k`` and
    ``nums[...]`` the same slice of point numbers; ``rows`` are the vertices'
    rows in the layer's line-point table and ``own`` is False for a junction
    vertex added to a branch end. A closed line does not repeat its first
    vertex. Writers that build geometries for a whole layer
    at once use the arrays (``shapely.linestrings(coords, indices=...)``).
    """

    coords: np.ndarray
    nums: np.ndarray
    offsets: np.ndarray
    codes: np.ndarray
    closed: np.ndarray
    rows: np.ndarray
    own: np.ndarray

    def __len__(self) -> int:
        return len(self.codes)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        if k < 0:
            k += len(self)
        if not 0 <= k < len(self):
            raise IndexError(k)
        a, b = self.offsets[k], self.offsets[k + 1]
        return Polyline(
            self.coords[a:b],
            int(self.codes[k]),
            bool(self.closed[k]),
            tuple(int(v) for v in self.nums[a:b]),
        )

    def line_index(self) -> np.ndarray:
        """Line index of every vertex (for ``shapely.linestrings(..., indices=)``)."""
        return np.repeat(np.arange(len(self)), np.diff(self.offsets))


def export_lines(layer) -> LineSet:
    """Every chain of ``layer`` as a polyline, branch ends extended to their junctions.

    A chain whose first point's backward reference (or last point's forward
    reference) names a point outside the chain gets that point's coordinates
    and number as an extra first (or last) vertex. The code of a line is the
    code of its first own point.

    >>> from apygis.model.map import Layer
    >>> lay = Layer("h")
    >>> main = lay.add_line([(0, 0, 0), (10, 0, 0), (20, 0, 0)], code=31)
    >>> trib = lay.add_line([(10, 9, 1), (10, 4, 1)], code=32)
    >>> lay.join(trib[-1], main[1])
    'branch'
    >>> [pl.nums for pl in export_lines(lay)]
    [(1, 2, 3), (4, 5, 2)]
    """
    lp = layer.line_points
    cs = topology.chains(lp)
    k = len(cs)
    xyz = np.column_stack([lp["x"], lp["y"], lp["z"]]) if len(lp) else np.zeros((0, 3))
    if k == 0:
        return LineSet(
            np.zeros((0, 3)),
            np.zeros(0, np.int64),
            np.zeros(1, np.int64),
            np.zeros(0, np.int16),
            np.zeros(0, bool),
            np.zeros(0, np.int64),
            np.zeros(0, bool),
        )
    first = cs.order[cs.offsets[:-1]]
    last = cs.order[cs.offsets[1:] - 1]
    open_ = ~cs.closed
    pre = np.where(open_, topology.lookup(lp["num"], lp["back"][first]), -1)
    post = np.where(open_, topology.lookup(lp["num"], lp["fwd"][last]), -1)
    # a one-point chain whose both references name the same point: keep one
    post = np.where((post >= 0) & (post == pre) & (first == last), -1, post)
    has_pre, has_post = pre >= 0, post >= 0
    lengths = cs.lengths() + has_pre + has_post
    offsets = np.r_[0, np.cumsum(lengths)].astype(np.int64)
    src = np.empty(offsets[-1], dtype=np.int64)
    cid = np.repeat(np.arange(k), cs.lengths())
    pos = np.arange(len(cs.order)) - cs.offsets[cid]
    src[offsets[cid] + has_pre[cid] + pos] = cs.order
    src[offsets[:-1][has_pre]] = pre[has_pre]
    src[offsets[1:][has_post] - 1] = post[has_post]
    own = np.ones(len(src), dtype=bool)
    own[offsets[:-1][has_pre]] = False
    own[offsets[1:][has_post] - 1] = False
    return LineSet(
        coords=xyz[src],
        nums=lp["num"][src].astype(np.int64),
        offsets=offsets,
        codes=lp["code"][first].astype(np.int16),
        closed=cs.closed.copy(),
        rows=src,
        own=own,
    )


def metres_per_unit_at(crs, lat: float | None = None) -> tuple[float, float]:
    """Metres of one CRS unit ``(east, north)`` at latitude ``lat`` (degrees).

    1, 1 for metres (and for no CRS: apygis's model is in metres); the foot's
    length for a CRS in feet; for a geographic CRS the length of a degree of
    longitude and of latitude on its ellipsoid at ``lat`` (0 when not given).

    >>> metres_per_unit_at("EPSG:2056")
    (1.0, 1.0)
    >>> [round(v) for v in metres_per_unit_at("EPSG:4326", 47.0)]
    [76056, 111171]
    """
    if crs is None:
        return 1.0, 1.0
    from pyproj import CRS

    c = crs if isinstance(crs, CRS) else CRS.from_user_input(crs)
    axes = c.axis_info
    if not axes:
        return 1.0, 1.0
    factor = float(axes[0].unit_conversion_factor or 1.0)
    if not c.is_geographic:
        return factor, factor
    ell = c.ellipsoid
    a = float(ell.semi_major_metre) if ell is not None else 6378137.0
    e2 = 1.0 - (float(ell.semi_minor_metre) / a) ** 2 if ell is not None else 0.00669438
    phi = np.radians(0.0 if lat is None or not np.isfinite(lat) else float(lat))
    w = np.sqrt(1.0 - e2 * np.sin(phi) ** 2)
    east = a * np.cos(phi) / w  # radius of the parallel
    north = a * (1.0 - e2) / w**3  # meridian radius of curvature
    return float(east * factor), float(north * factor)


def tolerance_in_crs(tolerance_m: float, crs, lat: float | None = None) -> float:
    """``tolerance_m`` metres in the units of ``crs``, never longer than that on the ground.

    For a geographic CRS: degrees at latitude ``lat``, by the smaller of a
    degree of longitude and of latitude there.

    >>> tolerance_in_crs(0.005, "EPSG:2056")
    0.005
    >>> round(tolerance_in_crs(1.0, "EPSG:4326", 47.0) * 1e6, 2)  # 1 m in micro-degrees
    13.15
    """
    east, north = metres_per_unit_at(crs, lat)
    return float(tolerance_m) / min(east, north)


DEFAULT_SNAP_M = 0.005
"""The default snapping distance of the rebuild, in metres (5 mm)."""

REFUSALS = {
    "ring-too-short": "a closed line needs three distinct vertices; added open",
    "two-point-loop": "merging would close two points into a loop; the lines stay apart",
    "no-free-side": "the junction already has two branches; the end stays free",
    "already-joined": "the line is already joined there (a segment digitised twice)",
}
"""Why the rebuild refused to join, by the key :attr:`RebuildReport.refused` counts."""


@dataclass
class RebuildReport:
    """What :func:`rebuild` did with a batch of polylines.

    ``nums`` gives, for every input vertex (aligned with the input
    coordinates), the number of the line point it became: a removed
    duplicate, a fused end or a dropped branch end names the point it went
    into (a junction may be a point that was in the layer before).
    """

    lines: int = 0
    empty: int = 0
    duplicates_removed: int = 0
    merged: int = 0
    rings: int = 0
    joined: int = 0
    refused: dict = field(default_factory=dict)
    nums: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def refuse(self, why: str, count: int = 1) -> None:
        if count:
            self.refused[why] = self.refused.get(why, 0) + int(count)

    def message(self) -> str:
        """One line for a log: the counts, then each refusal and why."""
        parts = [
            f"{self.lines} polyline(s)",
            f"{self.merged} meeting point(s) merged",
            f"{self.rings} closed line(s)",
            f"{self.joined} end(s) joined as branches",
            f"{self.duplicates_removed} duplicate vertices removed",
        ]
        if self.empty:
            parts.append(f"{self.empty} empty polyline(s) skipped")
        for why, k in sorted(self.refused.items()):
            parts.append(f"{k} refused: {REFUSALS[why]}")
        return "; ".join(parts)

    def __str__(self) -> str:
        return self.message()


def check_polylines(coords, offsets, codes, closed=None):
    """Validated ``(xyz (N, 3), offsets (m + 1,), codes (m,), closed (m,))``.

    ``coords`` is ``(N, 2)`` or ``(N, 3)`` (a missing Z is 0), finite and at
    most :data:`~apygis.model.records.MAX_COORD` in magnitude; ``offsets``
    start at 0, never decrease and end at N (line ``k`` is
    ``coords[offsets[k]:offsets[k + 1]]``); ``codes`` is one code 0-99 or
    one per line; ``closed`` is None, one flag or one per line.
    """
    from apygis.errors import RecordError
    from apygis.model.records import MAX_COORD

    try:
        xyz = np.asarray(coords, dtype=float)
        off = np.asarray(offsets)
    except (TypeError, ValueError):
        raise RecordError("polylines are an (N, 2|3) coordinate array and offsets") from None
    if xyz.ndim != 2 or xyz.shape[1] not in (2, 3):
        if xyz.size == 0:
            xyz = np.zeros((0, 3))
        else:
            raise RecordError(f"coordinates are an (N, 2) or (N, 3) array, not {xyz.shape}")
    if xyz.shape[1] == 2:
        xyz = np.column_stack([xyz, np.zeros(len(xyz))])
    bad = ~(np.abs(xyz) <= MAX_COORD).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise RecordError(
            f"vertex {k + 1}: coordinates {xyz[k].tolist()} are not finite or exceed "
            f"{MAX_COORD:g} in magnitude"
        )
    if off.ndim != 1 or len(off) < 1 or not np.issubdtype(off.dtype, np.integer):
        raise RecordError("offsets are a 1-D integer array [0, ..., N] of m + 1 entries")
    off = off.astype(np.int64)
    if off[0] != 0 or off[-1] != len(xyz) or (np.diff(off) < 0).any():
        raise RecordError(
            f"offsets must start at 0, never decrease and end at {len(xyz)} (the vertex count)"
        )
    m = len(off) - 1
    c = np.asarray(codes)
    if c.dtype == bool or not (np.issubdtype(c.dtype, np.integer) or c.size == 0):
        raise RecordError(f"line codes are integers 0-{MAX_CODE}")
    try:
        c = np.broadcast_to(c.astype(np.int64), (m,)).copy()
    except ValueError:
        raise RecordError(f"one line code or one per line ({m}), not {c.shape}") from None
    if ((c < 0) | (c > MAX_CODE)).any():
        raise RecordError(f"line codes are 0-99, not {int(c[(c < 0) | (c > MAX_CODE)][0])}")
    cl = np.zeros(m, bool) if closed is None else np.asarray(closed)
    if cl.size and cl.dtype != bool:
        raise RecordError("closed flags are booleans")
    cl = cl.astype(bool)
    try:
        cl = np.broadcast_to(cl, (m,)).copy()
    except ValueError:
        raise RecordError(f"one closed flag or one per line ({m}), not {cl.shape}") from None
    return xyz, off, c, cl


def to_csr(lines) -> tuple[np.ndarray, np.ndarray]:
    """A list of vertex arrays (``(n, 2)`` or ``(n, 3)`` each) as ``(coords, offsets)``."""
    from apygis.errors import RecordError

    arrs = []
    for ln in lines:
        a = np.asarray(ln, dtype=float)
        if a.size == 0:
            a = a.reshape(0, 3)
        if a.ndim != 2 or a.shape[1] not in (2, 3):
            raise RecordError(f"a line is an (n, 2) or (n, 3) array of vertices, not {a.shape}")
        if a.shape[1] == 2:
            a = np.column_stack([a, np.zeros(len(a))])
        arrs.append(a)
    lens = [len(a) for a in arrs]
    coords = np.concatenate(arrs) if arrs else np.zeros((0, 3))
    return coords, np.r_[0, np.cumsum(lens, dtype=np.int64)].astype(np.int64)


class _Plan(NamedTuple):
    rows: np.ndarray  # new line-point records
    sides: list  # (existing row, "side1" | "side2", new number)
    report: RebuildReport


def rebuild(
    existing: np.ndarray,
    coords,
    offsets,
    codes,
    closed=None,
    *,
    snap_m: float = DEFAULT_SNAP_M,
    crs=None,
    join: bool = True,
    numbers=None,
) -> _Plan:
    """The topology rebuild: line-point records for plain polylines.

    The one place that decides how plain geometry (GIS features, CAD
    entities, ARC/INFO arcs) becomes referenced line points;
    :meth:`Layer.add_polylines <apygis.model.map.Layer.add_polylines>`
    applies its result (``existing`` are the layer's line points, ``numbers``
    its numbering function). The rules, in order:

    1. **Snapping** is planimetric: two vertices *meet* when their (X, Y)
       distance is at most ``snap_m`` metres, whatever the CRS (``crs``:
       :func:`tolerance_in_crs` converts it, at the mean latitude of the
       data for a geographic CRS, never longer than ``snap_m`` on the
       ground). Z never decides.
    2. **Duplicates**: a vertex meeting the vertex before it on its line is
       removed (counted in ``duplicates_removed``); its point is that one.
    3. **Rings**: a line is closed when flagged closed or when its last
       vertex meets its first; the repeated last vertex goes. A ring needs
       three distinct vertices: a flagged line with fewer is added open and
       counted as refused (``ring-too-short``).
    4. **Merging** (``join``): the ends (first and last vertices) of open
       lines of two vertices or more are grouped where they meet (transitively).
       Where a group meets no other vertex (of a new line's interior, a ring,
       a one-vertex line or the layer's line points), two of its ends are
       fused into one point and their lines into one chain: ends of lines
       with the same code only, an end and a start in preference (no line
       reversed), else the first two in reading order. The fused point keeps
       the vertex read first. A merged chain runs the way its first line
       (in reading order) runs; lines against it are reversed. A chain
       whose ends are fused becomes a closed line (counted in ``rings``),
       unless it would have fewer than three points: then none of its
       fusions is made and its lines stay apart as read (``two-point-loop``:
       a line and its reverse, or a line A-B-A).
    5. **Junctions** (``join``): every other end in a group joins as a
       **branch**: to the nearest vertex it meets that is not an end (ties:
       the one read first, new lines before the layer's own points), else to
       the group's fused point, else (codes differ) to the first end's
       vertex. The end vertex is dropped and its neighbour on the line
       references the junction (free backward, else forward reference);
       the junction takes it on a free side reference. A line keeps at least
       one vertex: its last one is linked to the junction, not dropped.
       Refused, the end staying free: a junction with both side references
       used (``no-free-side``; the next nearest is tried first), and linking
       a line's last vertex to the line it is already joined to
       (``already-joined``). Lines already in the layer are never merged
       with or reversed; their points are junctions only.

    Every refusal is counted in the report, never silent. This is the
    inverse of :func:`export_lines` up to what plain geometry cannot
    tell: a branch joined to the *end* of a line of its code exports as two
    lines meeting end to end, which step 4 merges.
    """
    from scipy.spatial import cKDTree

    from apygis.errors import RecordError

    xyz0, offsets, codes, closed = check_polylines(coords, offsets, codes, closed)
    m, big_n = len(codes), len(xyz0)
    rep = RebuildReport(lines=m)
    tol = (
        float(snap_m) if isinstance(snap_m, (int, float, np.integer, np.floating)) else float("nan")
    )
    if not tol >= 0 or not np.isfinite(tol):
        raise RecordError(f"the snapping distance is a distance in metres >= 0, not {snap_m!r}")
    if crs is not None and tol > 0 and big_n:
        tol = tolerance_in_crs(tol, crs, float(xyz0[:, 1].mean()))
    lens0 = np.diff(offsets)
    rep.empty = int((lens0 == 0).sum())
    line0 = np.repeat(np.arange(m), lens0)

    # 2. duplicates: clean_of maps every input vertex to its vertex in xyz
    if big_n > 1:
        step = np.hypot(np.diff(xyz0[:, 0]), np.diff(xyz0[:, 1]))
        dup = np.r_[False, (line0[1:] == line0[:-1]) & (step <= tol)]
    else:
        dup = np.zeros(big_n, bool)
    rep.duplicates_removed = int(dup.sum())
    clean_of = np.cumsum(~dup) - 1
    xyz, line_of = xyz0[~dup], line0[~dup]
    lens = np.bincount(line_of, minlength=m)
    starts = np.r_[0, np.cumsum(lens)[:-1]].astype(np.int64)
    lasts = starts + lens - 1

    # 3. rings
    meet = np.zeros(m, bool)
    two = np.flatnonzero(lens >= 2)
    d = xyz[lasts[two], :2] - xyz[starts[two], :2]
    meet[two] = np.hypot(d[:, 0], d[:, 1]) <= tol
    ring = (meet & (lens >= 4)) | (closed & ~meet & (lens >= 3))
    rep.refuse("ring-too-short", int((closed & ~ring & (lens > 0)).sum()))
    closing = ring & meet
    if closing.any():
        drop = np.zeros(len(xyz), bool)
        drop[lasts[closing]] = True
        idx = np.cumsum(~drop) - 1
        idx[lasts[closing]] = idx[starts[closing]]
        clean_of = idx[clean_of]
        xyz, line_of = xyz[~drop], line_of[~drop]
        lens = np.bincount(line_of, minlength=m)
        starts = np.r_[0, np.cumsum(lens)[:-1]].astype(np.int64)
        lasts = starts + lens - 1
    rep.rings = int(ring.sum())
    n = len(xyz)

    # references by row: rows 0..n-1 new, n.. the layer's existing line points
    pos = np.arange(n) - starts[line_of]
    last_pos = lens[line_of] - 1
    vring = ring[line_of]
    fwd = np.where(pos < last_pos, np.arange(n) + 1, -1)
    back = np.where(pos > 0, np.arange(n) - 1, -1)
    fwd = np.where(vring & (pos == last_pos), starts[line_of], fwd)
    back = np.where(vring & (pos == 0), starts[line_of] + last_pos, back)
    side = np.full((n, 2), -1, dtype=np.int64)
    ex = existing
    e_n = len(ex)
    alias = np.arange(n + e_n)
    dropped = np.zeros(n, bool)
    ex_sides: list[tuple[int, str, int]] = []  # (existing row, side field, new row)

    open_ = np.flatnonzero(~ring & (lens >= 2)) if join else np.zeros(0, np.int64)
    if len(open_):
        ev = np.column_stack([starts[open_], lasts[open_]]).reshape(-1)  # end vertices
        k2 = len(ev)
        e_line = np.repeat(open_, 2)
        e_code = codes[e_line]
        e_start = np.tile([True, False], len(open_))
        end_of = np.full(n, -1, np.int64)
        end_of[ev] = np.arange(k2)
        ex_xy = np.column_stack([ex["x"], ex["y"]]) if e_n else np.zeros((0, 2))
        all_xy = np.r_[xyz[:, :2], ex_xy]
        tree = cKDTree(all_xy)
        near = tree.query_ball_point(xyz[ev, :2], tol)
        parent = np.arange(k2)

        def find(a):
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        solid_near: dict[int, list[int]] = {}
        for j in range(k2):
            lst = near[j]
            if len(lst) == 1:
                continue
            for t in lst:
                o = end_of[t] if t < n else -1
                if o >= 0:
                    if o != j:
                        ra, rb = find(j), find(o)
                        if ra != rb:
                            parent[max(ra, rb)] = min(ra, rb)
                else:
                    solid_near.setdefault(j, []).append(t)
        groups: dict[int, list[int]] = {}
        for j in range(k2):
            if len(near[j]) > 1:
                groups.setdefault(find(j), []).append(j)
        partner = np.full(k2, -1, np.int64)
        fusion_order = np.full(k2, -1, np.int64)
        requests: list[tuple[int, list[int]]] = []  # (end, candidate junctions)
        for ends in groups.values():
            solids = sorted({t for j in ends for t in solid_near.get(j, ())})
            if solids:
                requests += [(j, solids) for j in ends]
                continue
            if len(ends) < 2:
                continue
            pairs = [
                (a, b) for i, a in enumerate(ends) for b in ends[i + 1 :] if e_code[a] == e_code[b]
            ]
            pair = next((p for p in pairs if e_start[p[0]] != e_start[p[1]]), None)
            pair = pair or (pairs[0] if pairs else None)
            if pair is None:
                requests += [(j, [int(ev[ends[0]])]) for j in ends[1:]]
                continue
            a, b = pair
            partner[a], partner[b] = b, a
            fusion_order[a] = fusion_order[b] = a
            hub = int(min(ev[a], ev[b]))
            requests += [(j, [hub]) for j in ends if j not in pair]

        # 4. chains of merged lines
        chain_of = line_of.copy()
        line_pos = {int(ln): i for i, ln in enumerate(open_)}
        seen = np.zeros(m, bool)
        for ln in open_[partner[0::2] >= 0].tolist() + open_[partner[1::2] >= 0].tolist():
            if seen[ln]:
                continue
            comp, stack = [], [ln]
            seen[ln] = True
            while stack:
                cur = stack.pop()
                comp.append(cur)
                for e in (2 * line_pos[cur], 2 * line_pos[cur] + 1):
                    p = partner[e]
                    if p >= 0 and not seen[e_line[p]]:
                        seen[e_line[p]] = True
                        stack.append(int(e_line[p]))
            comp.sort()
            c_ends = np.r_[[2 * line_pos[c] for c in comp], [2 * line_pos[c] + 1 for c in comp]]
            cycle = bool((partner[c_ends] >= 0).all())
            if cycle and int(lens[comp].sum()) - len(comp) < 3:
                partner[c_ends] = -1  # the lines stay apart, as read
                rep.refuse("two-point-loop")
                continue
            first = comp[0]
            # a cycle from its first line's start, a path from a free end
            e_in = 2 * line_pos[first] if cycle else next(int(e) for e in c_ends if partner[e] < 0)
            seq: list[np.ndarray] = []
            flips = {}
            while True:
                cur = int(e_line[e_in])
                fw = bool(e_start[e_in])
                flips[cur] = not fw
                verts = np.arange(starts[cur], lasts[cur] + 1)
                verts = verts if fw else verts[::-1]
                if seq:
                    u, w = int(seq[-1][-1]), int(verts[0])
                    keep_v, gone = min(u, w), max(u, w)
                    seq[-1] = np.r_[seq[-1][:-1], keep_v]
                    verts = verts[1:]
                    alias[gone], dropped[gone] = keep_v, True
                    rep.merged += 1
                seq.append(verts)
                e_out = e_in ^ 1
                nxt = partner[e_out]
                if nxt < 0 or (cycle and int(e_line[nxt]) == first):
                    break
                e_in = int(nxt)
            s = np.concatenate(seq)
            if cycle:
                u, w = int(s[-1]), int(s[0])
                keep_v, gone = min(u, w), max(u, w)
                s = np.r_[keep_v, s[1:-1]]
                alias[gone], dropped[gone] = keep_v, True
                rep.merged += 1
                rep.rings += 1
            if flips[first]:
                s = s[::-1]
            fwd[s[:-1]], back[s[1:]] = s[1:], s[:-1]
            if cycle:
                fwd[s[-1]], back[s[0]] = s[0], s[-1]
            else:
                fwd[s[-1]] = back[s[0]] = -1
            chain_of[s] = first

        # 5. branches
        remaining = np.bincount(chain_of[~dropped], minlength=m)
        ex_chain = np.full(e_n, -1, np.int64)
        if e_n:
            from apygis.model import topology

            cs = topology.chains(ex)
            ex_chain[cs.order] = m + np.repeat(np.arange(len(cs)), cs.lengths())
        ex_free = (
            np.column_stack([ex["side1"] == NO_REF, ex["side2"] == NO_REF])
            if e_n
            else np.zeros((0, 2), bool)
        )

        def chain(t: int) -> int:
            return int(chain_of[t]) if t < n else int(ex_chain[t - n])

        def refs(v: int) -> tuple[int, ...]:
            return (int(fwd[v]), int(back[v]), int(side[v, 0]), int(side[v, 1]))

        for j, cands in sorted(requests):
            v = int(ev[j])
            if dropped[v]:
                continue
            if back[v] < 0:
                nb, ref = int(fwd[v]), "back"
            elif fwd[v] < 0:
                nb, ref = int(back[v]), "fwd"
            else:
                continue  # no longer an end: a ring closed through it
            c = chain(v)
            can_drop = nb >= 0 and remaining[c] > 1
            me = nb if can_drop else v
            other = int(fwd[me] if ref == "back" else back[me])  # me's link along its line
            order = sorted(cands, key=lambda t: (float(np.hypot(*(all_xy[t] - xyz[v, :2]))), t))
            target, why = None, "no-free-side"
            for t in order:
                if t in (me, v) or (t < n and dropped[t]):
                    continue
                free = (side[t] < 0).any() if t < n else bool(ex_free[t - n].any())
                if not free:
                    continue
                linked = t in refs(me) or (t < n and me in refs(t))
                twice = not can_drop and other >= 0 and other != v and chain(other) == chain(t)
                if linked or twice:
                    why = "already-joined"
                    continue
                target = t
                break
            if target is None:
                rep.refuse(why)
                continue
            t = target
            if can_drop:
                dropped[v], alias[v] = True, t
                remaining[c] -= 1
            if ref == "back":
                back[me] = t
            else:
                fwd[me] = t
            if t < n:
                side[t, int(np.flatnonzero(side[t] < 0)[0])] = me
            else:
                k = int(np.flatnonzero(ex_free[t - n])[0])
                ex_free[t - n, k] = False
                ex_sides.append((t - n, ("side1", "side2")[k], me))
            rep.joined += 1

    # numbers for the kept rows, references from rows to numbers
    keep = ~dropped
    if numbers is None:
        from apygis.model.records import next_numbers

        def numbers(count):
            return next_numbers(ex["num"] if e_n else np.zeros(0, np.int64), count)

    nums_new = np.full(n, NO_REF, dtype=np.int64)
    nums_new[keep] = numbers(int(keep.sum()))
    num_of = np.r_[nums_new, ex["num"].astype(np.int64) if e_n else np.zeros(0, np.int64)]

    def to_num(r):
        out = np.full(r.shape, NO_REF, dtype=np.int64)
        out[r >= 0] = num_of[r[r >= 0]]
        return out

    rows = np.zeros(int(keep.sum()), LINE_DTYPE)
    rows["num"] = nums_new[keep]
    rows["x"], rows["y"], rows["z"] = xyz[keep, 0], xyz[keep, 1], xyz[keep, 2]
    rows["code"] = codes[line_of[keep]] if n else 0
    rows["fwd"] = to_num(fwd[keep])
    rows["back"] = to_num(back[keep])
    rows["side1"] = to_num(side[keep, 0])
    rows["side2"] = to_num(side[keep, 1])
    while True:
        nxt = alias[alias]
        if np.array_equal(nxt, alias):
            break
        alias = nxt
    rep.nums = num_of[alias[clean_of]] if big_n else np.zeros(0, np.int64)
    sides = [(r, f, int(nums_new[me])) for r, f, me in ex_sides]
    return _Plan(rows, sides, rep)
