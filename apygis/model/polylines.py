"""Between APY's referenced line points and the plain polylines of GIS and CAD files.

:func:`export_lines` turns each chain of a layer into a polyline for a
writer; :func:`add_lines` turns polylines read from a file into line points
with references again, rebuilding the topology that plain geometry lost:

* A polyline whose first and last vertices coincide is a **closed line**
  (the repeated vertex is dropped).
* An **end vertex** (first or last) of an open polyline that coincides with a
  vertex of another line (or of a line already in the layer) is dropped, and
  the line is joined there instead:

  - end to start (or start to end) of another line: the two lines are
    **merged** into one chain by forward/backward references;
  - anywhere else: the line becomes a **branch** of that vertex (its free
    forward or backward reference points to the junction, which takes the
    line on a free side reference; two branches at most per junction).

  A vertex that has become a junction or a merge point stays. A line keeps
  at least one vertex: if its last remaining vertex coincides with another
  line, it is linked there without being dropped (a short connector between
  two lines is joined at both ends), unless that line is already joined to
  it (a segment digitised twice is not folded onto itself).
* "Coincide" means a planimetric (X, Y) distance of at most ``tolerance_m``
  metres; the nearest candidate wins, ties going to the one read first. The
  tolerance is converted to the units of the layer's CRS (``crs=``) by
  :func:`tolerance_in_crs`: feet for a CRS in feet, and for a geographic CRS
  degrees at the data's mean latitude, taking the smaller of a degree of
  latitude and of longitude, so that no two vertices further apart than
  ``tolerance_m`` metres are ever joined.

This is the inverse of :func:`export_lines`, which appends each branch's
junction vertex to the branch's polyline so that the drawn line touches its
junction: exporting a layer and adding the polylines to an empty layer gives
the same chains, closed lines and branches again (point numbers may differ).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from apygis.model import topology
from apygis.model.records import LINE_DTYPE, MAX_CODE, NO_REF

__all__ = [
    "LineSet",
    "Polyline",
    "add_lines",
    "export_lines",
    "metres_per_unit_at",
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


def add_lines(
    layer,
    lines: Iterable,
    codes: Iterable[int] | int,
    closed: Iterable[bool] | None = None,
    tolerance_m: float = 0.005,
    crs=None,
) -> list[list[int]]:
    """Add polylines to ``layer`` as line points, rebuilding their topology.

    Parameters
    ----------
    layer : Layer
        The layer to add to; its existing line points can be junctions.
    lines : iterable of array-like (n, 2) or (n, 3)
        Vertices in the units of ``crs`` (metres without one); a missing Z is 0.
    codes : int or iterable of int
        Line code (0-99) per line, or one for all.
    closed : iterable of bool, optional
        Lines known to be closed (polygon rings). Other lines are closed when
        their first and last vertices coincide.
    tolerance_m : float
        Planimetric distance in metres within which vertices coincide.
    crs : optional
        The CRS of the coordinates (anything pyproj takes); ``tolerance_m`` is
        converted to its units (:func:`tolerance_in_crs`, at the mean latitude
        of the lines for a geographic CRS). None: the coordinates are metres.

    Returns
    -------
    list of list of int
        The point numbers of each line's remaining vertices, in order.
    """
    from scipy.spatial import cKDTree

    from apygis.errors import RecordError
    from apygis.model.map import _allocate

    arrs = []
    for ln in lines:
        a = np.asarray(ln, dtype=float)
        if a.ndim != 2 or a.shape[1] not in (2, 3):
            raise RecordError(f"a line is an (n, 2) or (n, 3) array of vertices, not {a.shape}")
        if a.shape[1] == 2:
            a = np.column_stack([a, np.zeros(len(a))])
        if not np.isfinite(a).all():
            raise RecordError("line coordinates must be finite")
        arrs.append(a)
    m = len(arrs)
    code_arr = np.broadcast_to(np.asarray(codes if not isinstance(codes, int) else [codes]), (m,))
    code_arr = np.asarray(code_arr) if m else np.zeros(0, int)
    if m and ((code_arr < 0) | (code_arr > MAX_CODE)).any():
        raise RecordError("line codes are 0-99")
    want_closed = np.zeros(m, bool) if closed is None else np.asarray(list(closed), bool)
    tol = float(tolerance_m)
    if not tol >= 0:
        raise RecordError(f"the tolerance is a distance in metres >= 0, not {tolerance_m!r}")
    if crs is not None and tol > 0:
        ys = [a[:, 1].mean() for a in arrs if len(a)]
        lat = float(np.mean(ys)) if ys else 0.0
        tol = tolerance_in_crs(tol, crs, lat)

    # 1. closed lines: drop a repeated last vertex
    for i, a in enumerate(arrs):
        if len(a) >= 2 and np.hypot(*(a[-1, :2] - a[0, :2])) <= tol and len(a) >= 4:
            arrs[i] = a[:-1]
            want_closed[i] = True
        elif want_closed[i] and len(a) >= 2 and np.hypot(*(a[-1, :2] - a[0, :2])) <= tol:
            arrs[i] = a[:-1]
    lens = np.array([len(a) for a in arrs], dtype=np.int64)
    want_closed &= lens >= 3
    keep_line = lens > 0
    n = int(lens.sum())
    starts = np.r_[0, np.cumsum(lens)][:-1]
    xyz = np.concatenate(arrs) if n else np.zeros((0, 3))
    line_of = np.repeat(np.arange(m), lens)

    # 2. references by row (new rows 0..n-1)
    pos = np.arange(n) - starts[line_of] if n else np.zeros(0, np.int64)
    last_pos = lens[line_of] - 1
    fwd = np.where(pos < last_pos, np.arange(n) + 1, -1)
    back = np.where(pos > 0, np.arange(n) - 1, -1)
    ring = want_closed[line_of]
    fwd = np.where(ring & (pos == last_pos), starts[line_of], fwd)
    back = np.where(ring & (pos == 0), starts[line_of] + last_pos, back)
    side = np.full((n, 2), -1, dtype=np.int64)
    dropped = np.zeros(n, bool)
    pinned = np.zeros(n, bool)
    remaining = lens.copy()

    # existing line points of the layer can be junctions; they are rows n.. in the tree
    old = layer.line_points
    ex_xy = np.column_stack([old["x"], old["y"]]) if len(old) else np.zeros((0, 2))
    ex_side_free = (
        (old["side1"] == NO_REF).astype(int) + (old["side2"] == NO_REF).astype(int)
        if len(old)
        else np.zeros(0, int)
    )
    ex_updates: list[tuple[int, int]] = []  # (old row, new row joined on a side reference)
    tree = cKDTree(np.r_[xyz[:, :2], ex_xy]) if n + len(ex_xy) else None

    def side_free(t: int) -> bool:
        if t >= n:
            return ex_side_free[t - n] > 0
        return (side[t] < 0).any()

    joined: set[frozenset] = set()
    ends = []
    for i in np.flatnonzero(keep_line & ~want_closed & (lens >= 2)):
        ends += [(starts[i], "start", i), (starts[i] + lens[i] - 1, "end", i)]
    for v, which, i in ends:
        if pinned[v] or dropped[v]:
            continue
        inner = v + 1 if which == "start" else v - 1
        if dropped[inner]:  # the line shrank to this vertex from the other side
            inner = -1
        # the line's own other end is not a junction: ends that meet close a line, and
        # step 1 decided that (a line of three coincident vertices stays open)
        other = starts[i] + lens[i] - 1 if which == "start" else starts[i]
        cands = [
            t
            for t in tree.query_ball_point(xyz[v, :2], tol)
            if t != v and t != inner and t != other and (t >= n or not dropped[t])
        ]
        can_drop = remaining[i] > 1 and inner >= 0
        if not can_drop:
            # the line's last vertex: joining it to a line it is already joined to would
            # only fold the two onto each other (a segment digitised twice)
            cands = [t for t in cands if t >= n or frozenset((i, line_of[t])) not in joined]
        if not cands:
            continue
        d = np.hypot(*(np.r_[xyz[:, :2], ex_xy][cands] - xyz[v, :2]).T)
        order = np.lexsort((cands, d))
        target = None
        for j in order:
            t = cands[j]
            merge = (
                t < n
                and line_of[t] != i
                and (
                    (which == "end" and back[t] < 0 and not ring[t])
                    or (which == "start" and fwd[t] < 0 and not ring[t])
                )
            )
            if merge or side_free(t):
                target = (t, merge)
                break
        if target is None:
            log.info("line end at %.3f, %.3f: the junction has no free side reference", *xyz[v, :2])
            continue
        t, merge = target
        me = inner if can_drop else v
        if can_drop:
            dropped[v] = True
            remaining[i] -= 1
        if which == "end":
            fwd[me] = t
            if merge:
                back[t] = me
        else:
            back[me] = t
            if merge:
                fwd[t] = me
        if not merge:
            if t >= n:
                ex_updates.append((t - n, me))
                ex_side_free[t - n] -= 1
            else:
                side[t, np.flatnonzero(side[t] < 0)[0]] = me
        if t < n:
            pinned[t] = True  # a junction or merge point stays
            joined.add(frozenset((i, line_of[t])))

    # 3. numbers for the kept rows, references from rows to numbers
    keep = ~dropped
    nums_new = np.full(n, -1, dtype=np.int64)
    nums_new[keep] = _allocate(old["num"], int(keep.sum()))

    def to_num(r):
        out = np.full(r.shape, NO_REF, dtype=np.int64)
        new = (r >= 0) & (r < n)
        out[new] = nums_new[r[new]]
        ex = r >= n
        out[ex] = old["num"][r[ex] - n]
        return out

    rows = np.zeros(int(keep.sum()), LINE_DTYPE)
    rows["num"] = nums_new[keep]
    rows["x"], rows["y"], rows["z"] = xyz[keep, 0], xyz[keep, 1], xyz[keep, 2]
    rows["code"] = code_arr[line_of[keep]] if n else 0
    rows["fwd"] = to_num(fwd[keep])
    rows["back"] = to_num(back[keep])
    rows["side1"] = to_num(side[keep, 0])
    rows["side2"] = to_num(side[keep, 1])
    table = layer._tables["line_points"]
    if ex_updates:
        lp = table.rows()
        for r, me in ex_updates:
            f = "side1" if lp["side1"][r] == NO_REF else "side2"
            lp[f][r] = nums_new[me]
    table.append(rows)
    return [[int(v) for v in nums_new[starts[i] : starts[i] + lens[i]] if v >= 0] for i in range(m)]
