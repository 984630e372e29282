"""Line topology: chains, branches, validation, closure, margin points, AREA, DHI.

APY stores lines as points with four references: forward, backward and two
side (branch) references. The rules this module reads them by:

* A **link** p -> q is *mutual* when ``p.fwd == q`` and ``q.back == p``.
  Mutual links join points into **chains**; a chain whose mutual links form a
  cycle (3 points at least) is a **closed line** (a ring).
* A **branch** hangs off a junction J of another chain: its first point's
  backward reference (or its last point's forward reference) is J, and J holds
  the reciprocal in ``side1`` or ``side2``. A point has room for two branches.
  The junction may lie on the branch's own line (a loop hanging on one of its
  points), and a branch end may itself be a junction. A point holds one
  backward and one forward reference, so a line whose first point hangs on a
  junction by its backward reference cannot also be closed there.
* Two points reference each other by one link at most: a mutual link, or a
  branch end and its junction. The editing methods of
  :class:`~apygis.model.map.Layer` keep it so.
* **Margin points** lack a forward or a backward reference: the ends of lines
  that are open (APY's margin file, used to join lines across sheet edges).
  A branch's end at its junction is not a margin point.

Coordinates are metres: X east, Y north, Z up. Areas are planimetric (in the
X, Y plane, square metres); "clockwise" is seen from above (+Z), i.e. with X
to the right and Y up.

All whole-table functions are vectorised: a million line points take array
operations, not a Python loop per point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from apygis.errors import RecordNotFoundError, TopologyError
from apygis.model.records import NO_REF, REF_FIELDS, TABLE_WORDS

__all__ = [
    "DHI",
    "AreaResult",
    "ChainSet",
    "Closure",
    "Issue",
    "area",
    "branches",
    "chains",
    "closure",
    "dhi",
    "line_geometries",
    "lookup",
    "margin_mask",
    "mutual_links",
    "row_of",
    "validate_line_points",
    "validate_numbers",
]


# --------------------------------------------------------------------------- lookups


def lookup(nums: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """Row index of each number of ``wanted`` in ``nums``; -1 where absent.

    With duplicate numbers the first row (in ``nums`` order) wins.

    >>> lookup(np.array([5, 3, 9]), np.array([9, 4, 5, -1])).tolist()
    [2, -1, 0, -1]
    """
    nums = np.asarray(nums)
    wanted = np.asarray(wanted)
    if len(nums) == 0:
        return np.full(wanted.shape, -1, dtype=np.int64)
    order = np.argsort(nums, kind="stable")
    snums = nums[order]
    pos = np.searchsorted(snums, wanted)
    pos_c = np.minimum(pos, len(snums) - 1)
    found = snums[pos_c] == wanted
    return np.where(found, order[pos_c], -1).astype(np.int64)


def _row(lp: np.ndarray, num: int) -> int:
    rows = np.flatnonzero(lp["num"] == num)
    if len(rows) == 0:
        raise RecordNotFoundError(f"no line point number {num}")
    return int(rows[0])


def mutual_links(lp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Successor and predecessor row of every line point along mutual links.

    Returns ``succ, pred`` (int64 arrays, -1 where there is none), with
    ``succ[i] == j`` exactly when ``pred[j] == i``.
    """
    n = len(lp)
    if n == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty.copy()
    j = lookup(lp["num"], lp["fwd"])
    i = np.arange(n)
    ok = j >= 0
    ok[ok] = lp["back"][j[ok]] == lp["num"][ok]
    ok &= j != i
    pred = np.full(n, -1, dtype=np.int64)
    pred[j[ok]] = i[ok]  # with duplicate numbers one candidate wins
    succ = np.full(n, -1, dtype=np.int64)
    has = pred >= 0
    succ[pred[has]] = np.flatnonzero(has)
    return succ, pred


# --------------------------------------------------------------------------- chains


@dataclass(frozen=True)
class ChainSet:
    """The chains of a line-point table, in CSR form.

    ``order[offsets[k]:offsets[k + 1]]`` are the rows of chain ``k`` from its
    first point to its last (for a closed line: from its lowest-row point, in
    forward direction, without repeating the first point). ``closed[k]`` says
    whether chain ``k`` is a ring.
    """

    order: np.ndarray
    offsets: np.ndarray
    closed: np.ndarray

    def __len__(self) -> int:
        return len(self.closed)

    def __iter__(self):
        for k in range(len(self)):
            yield self.rows(k)

    def rows(self, k: int) -> np.ndarray:
        return self.order[self.offsets[k] : self.offsets[k + 1]]

    def lengths(self) -> np.ndarray:
        return np.diff(self.offsets)

    def chain_of_row(self) -> np.ndarray:
        """Chain index of every row of the table."""
        out = np.empty(len(self.order), dtype=np.int64)
        out[self.order] = np.repeat(np.arange(len(self)), self.lengths())
        return out


def _rank(pred: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """List ranking by pointer doubling: head row and distance from it.

    Nodes on a cycle never reach a head; they are returned in ``on_cycle``.
    """
    n = len(pred)
    idx = np.arange(n)
    root = np.where(pred < 0, idx, pred)
    rank = (pred >= 0).astype(np.int64)
    steps = max(1, math.ceil(math.log2(max(n, 2))) + 1)
    for _ in range(steps):
        nxt = root[root]
        if np.array_equal(nxt, root):
            break
        rank = rank + rank[root]
        root = nxt
    on_cycle = pred[root] >= 0
    return root, rank, on_cycle


def chains(lp: np.ndarray) -> ChainSet:
    """Split a line-point table into chains of mutual links.

    >>> from apygis.model.records import LINE_DTYPE
    >>> lp = np.zeros(5, LINE_DTYPE)
    >>> lp["num"] = [1, 2, 3, 7, 8]
    >>> lp["fwd"] = [2, 3, -1, 8, -1]
    >>> lp["back"] = [-1, 1, 2, -1, 7]
    >>> lp["side1"] = lp["side2"] = -1
    >>> cs = chains(lp)
    >>> [lp["num"][r].tolist() for r in cs], cs.closed.tolist()
    ([[1, 2, 3], [7, 8]], [False, False])
    """
    n = len(lp)
    if n == 0:
        z = np.zeros(0, dtype=np.int64)
        return ChainSet(z, np.zeros(1, dtype=np.int64), np.zeros(0, dtype=bool))
    _, pred = mutual_links(lp)
    root, rank, on_cycle = _rank(pred)
    closed_row = np.zeros(n, dtype=bool)
    if on_cycle.any():
        # Label each cycle by its lowest row: min-propagation by doubling.
        cyc = np.flatnonzero(on_cycle)
        label = np.arange(n)
        p = np.where(on_cycle, pred, np.arange(n))
        for _ in range(math.ceil(math.log2(max(n, 2))) + 1):
            label = np.minimum(label, label[p])
            p = p[p]
        # Cut each cycle before its lowest row and rank again.
        pred2 = pred.copy()
        heads = cyc[label[cyc] == cyc]
        pred2[heads] = -1
        root2, rank2, _ = _rank(pred2)
        root = np.where(on_cycle, root2, root)
        rank = np.where(on_cycle, rank2, rank)
        closed_row = on_cycle
    order = np.lexsort((rank, root))
    heads_sorted = root[order]
    starts = np.flatnonzero(np.r_[True, heads_sorted[1:] != heads_sorted[:-1]])
    offsets = np.r_[starts, n].astype(np.int64)
    closed = closed_row[order[starts]]
    # A two-point "cycle" (p.fwd = q, q.fwd = p) is no ring: mutual_links keeps it,
    # report it open here and let validation flag it.
    closed &= np.diff(offsets) >= 3
    return ChainSet(order.astype(np.int64), offsets, closed)


def branches(lp: np.ndarray, cs: ChainSet | None = None) -> list[dict]:
    """Branch connections: chain ends that reference a junction on a side reference.

    Returns one dict per connection: ``chain`` (index), ``end`` (``"start"`` or
    ``"end"``), ``point`` (the chain's end point number) and ``junction`` (the
    junction's point number).
    """
    if cs is None:
        cs = chains(lp)
    out: list[dict] = []
    if len(lp) == 0:
        return out
    first = cs.order[cs.offsets[:-1]]
    last = cs.order[cs.offsets[1:] - 1]
    for end, rows, ref in (("start", first, "back"), ("end", last, "fwd")):
        target = lp[ref][rows]
        j = lookup(lp["num"], target)
        hit = (j >= 0) & ~cs.closed
        jj = j[hit]
        nums = lp["num"][rows[hit]]
        is_branch = (lp["side1"][jj] == nums) | (lp["side2"][jj] == nums)
        for k, p, q in zip(
            np.flatnonzero(hit)[is_branch], nums[is_branch], target[hit][is_branch], strict=True
        ):
            out.append({"chain": int(k), "end": end, "point": int(p), "junction": int(q)})
    out.sort(key=lambda d: (d["chain"], d["end"] != "start"))
    return out


def margin_mask(lp: np.ndarray) -> np.ndarray:
    """True for line points lacking a forward or a backward reference."""
    return (lp["fwd"] == NO_REF) | (lp["back"] == NO_REF)


# --------------------------------------------------------------------------- validation


@dataclass(frozen=True)
class Issue:
    """One finding of a validation: severity ``"error"`` or ``"warning"``."""

    severity: str
    table: str
    num: int
    kind: str
    message: str

    def __str__(self) -> str:
        return f"{self.severity}: {self.message}"


def validate_numbers(table: str, nums: np.ndarray) -> list[Issue]:
    """Duplicate and negative point numbers in one table."""
    out = []
    word = TABLE_WORDS[table]
    uniq, counts = np.unique(nums, return_counts=True)
    for num, c in zip(uniq[counts > 1], counts[counts > 1], strict=True):
        out.append(
            Issue(
                "error",
                table,
                int(num),
                "duplicate-number",
                f"{word} number {num} is used {c} times",
            )
        )
    for num in uniq[uniq < 0]:
        out.append(
            Issue("error", table, int(num), "negative-number", f"{word} number {num} is negative")
        )
    return out


def validate_line_points(lp: np.ndarray) -> list[Issue]:
    """Check every reference of a line-point table.

    Errors: a reference to a number that does not exist (dangling), to the
    point itself, a reference that its target does not return (asymmetric:
    ``p.fwd == q`` needs ``q.back == p`` or ``p`` among ``q``'s side
    references; ``p.side == q`` needs ``q`` to reference ``p`` by any
    reference), the same neighbour on both side references, and forward
    cycles of fewer than three points (no closed line can be that small).
    """
    out: list[Issue] = []
    if len(lp) == 0:
        return out
    out += validate_numbers("line_points", lp["num"])
    num = lp["num"]
    refs = {f: lp[f] for f in REF_FIELDS}
    for f in REF_FIELDS:
        r = refs[f]
        has = r != NO_REF
        j = lookup(num, r)
        dang = has & (j < 0)
        for i in np.flatnonzero(dang):
            out.append(
                Issue(
                    "error",
                    "line_points",
                    int(num[i]),
                    "dangling-reference",
                    f"line point {num[i]}: {f} reference {r[i]} does not exist",
                )
            )
        self_ref = has & (r == num)
        for i in np.flatnonzero(self_ref):
            out.append(
                Issue(
                    "error",
                    "line_points",
                    int(num[i]),
                    "self-reference",
                    f"line point {num[i]}: {f} reference points to itself",
                )
            )
        ok = has & (j >= 0) & ~self_ref
        jj = j[ok]
        me = num[ok]
        back_side = (refs["side1"][jj] == me) | (refs["side2"][jj] == me)
        if f == "fwd":
            good = (refs["back"][jj] == me) | back_side
            need = "backward or side reference back to it"
        elif f == "back":
            good = (refs["fwd"][jj] == me) | back_side
            need = "forward or side reference back to it"
        else:
            good = (refs["fwd"][jj] == me) | (refs["back"][jj] == me) | back_side
            need = "reference back to it"
        for i in np.flatnonzero(ok)[~good]:
            out.append(
                Issue(
                    "error",
                    "line_points",
                    int(num[i]),
                    "asymmetric-reference",
                    f"line point {num[i]}: {f} reference {r[i]}, but point {r[i]} has no {need}",
                )
            )
    both = (refs["side1"] != NO_REF) & (refs["side1"] == refs["side2"])
    for i in np.flatnonzero(both):
        out.append(
            Issue(
                "error",
                "line_points",
                int(num[i]),
                "duplicate-side",
                f"line point {num[i]}: both side references are {refs['side1'][i]}",
            )
        )
    # Two-point forward cycles: p.fwd = q and q.fwd = p.
    j = lookup(num, refs["fwd"])
    ok = j >= 0
    two = np.zeros(len(lp), dtype=bool)
    two[ok] = (refs["fwd"][j[ok]] == num[ok]) & (j[ok] != np.flatnonzero(ok))
    for i in np.flatnonzero(two & (num < refs["fwd"])):
        out.append(
            Issue(
                "error",
                "line_points",
                int(num[i]),
                "short-cycle",
                f"line points {num[i]} and {refs['fwd'][i]} reference each other forward: "
                "a closed line needs at least three points",
            )
        )
    return out


# --------------------------------------------------------------------------- closure


@dataclass(frozen=True)
class Closure:
    """Whether the line through a point is closed, and if not, where it is open.

    ``points`` are the chain's point numbers in forward order. For an open line
    ``start`` and ``end`` are its first and last point numbers and ``gap_m``
    the planimetric distance between them.
    """

    closed: bool
    points: tuple[int, ...]
    start: int | None = None
    end: int | None = None
    gap_m: float | None = None

    def __str__(self) -> str:
        if self.closed:
            return f"line {self.points[0]}..: closed, {len(self.points)} points"
        return (
            f"line {self.start}..{self.end}: not closed between point {self.end} and "
            f"point {self.start} (gap {self.gap_m:.2f} m)"
        )


def row_of(nums: np.ndarray, num: int) -> int | None:
    """The first row holding point number ``num``, or None (also for ``NO_REF``)."""
    if num == NO_REF:
        return None
    rows = np.flatnonzero(nums == num)
    return int(rows[0]) if len(rows) else None


def closure(lp: np.ndarray, num: int) -> Closure:
    """Closure check of the line through point ``num``.

    >>> from apygis.model.map import Layer
    >>> lay = Layer("r")
    >>> nums = lay.add_line([(0, 0, 0), (10, 0, 0), (10, 10, 0)], code=1)
    >>> str(closure(lay.line_points, nums[0]))
    'line 1..3: not closed between point 3 and point 1 (gap 14.14 m)'
    """
    row = _row(lp, num)
    cs = chains(lp)
    k = int(cs.chain_of_row()[row])
    rows = cs.rows(k)
    pts = tuple(int(v) for v in lp["num"][rows])
    if cs.closed[k]:
        return Closure(True, pts)
    a, b = rows[0], rows[-1]
    gap = float(math.hypot(lp["x"][b] - lp["x"][a], lp["y"][b] - lp["y"][a]))
    return Closure(False, pts, start=pts[0], end=pts[-1], gap_m=gap)


# --------------------------------------------------------------------------- AREA


@dataclass(frozen=True)
class AreaResult:
    """AREA of a closed line.

    ``area_m2`` is the planimetric area (always positive); ``clockwise`` says
    whether the two given points ran clockwise (seen from above), as APY asks
    the operator to enter them; ``perimeter_m`` is the planimetric length of
    the ring; ``points`` the ring's point numbers in the walking direction.
    """

    area_m2: float
    perimeter_m: float
    clockwise: bool
    points: tuple[int, ...]


def area(lp: np.ndarray, first: int, second: int) -> AreaResult:
    """APY's AREA: start at two neighbouring line points, walk the ring, sum the area.

    The walk starts at ``first``, goes to its neighbour ``second`` and goes on
    in that direction (forward references if ``second`` is ``first``'s forward
    neighbour, backward ones otherwise) until it returns to ``first``. The area
    is the shoelace sum ``A = 1/2 |sum(x_i y_(i+1) - x_(i+1) y_i)|`` over the
    ring, computed about the ring's first point for numerical accuracy.

    Raises
    ------
    TopologyError
        The points are not neighbours, or the ring does not close; the message
        names the two end points of the gap and its length. A loop whose
        last point hangs on its first as a branch is not closed (see
        :func:`chains`), wherever the walk starts.

    >>> from apygis.model.map import Layer
    >>> lay = Layer("r")
    >>> n = lay.add_line([(0, 0, 0), (0, 10, 0), (20, 10, 0), (20, 0, 0)], code=5, closed=True)
    >>> r = area(lay.line_points, n[0], n[1])
    >>> r.area_m2, r.clockwise, r.perimeter_m
    (200.0, True, 60.0)
    """
    nums = lp["num"]
    i = _row(lp, first)
    j = _row(lp, second)
    if lp["fwd"][i] == second and lp["back"][j] == first:
        step, other = "fwd", "back"
    elif lp["back"][i] == second and lp["fwd"][j] == first:
        step, other = "back", "fwd"
    else:
        raise TopologyError(f"AREA: line points {first} and {second} are not neighbours on a line")
    rows = [i, j]
    seen = {i, j}
    cur = j
    while True:
        nxt_num = lp[step][cur]
        k = row_of(nums, nxt_num)
        if k is not None and k == i:
            if lp[other][i] == nums[cur]:
                break
            k = None  # the last point hangs on the first as a branch: no closed line
        if k is None or lp[other][k] != nums[cur] or k in seen:
            # The ring is open after `cur`: find the other end by walking back from first.
            back_rows = [i]
            c = i
            while True:
                m = row_of(nums, lp[other][c])
                if m is None or lp[step][m] != nums[c] or m in seen or m in back_rows:
                    break
                back_rows.append(m)
                c = m
            end_a, end_b = cur, back_rows[-1]
            gap = math.hypot(lp["x"][end_b] - lp["x"][end_a], lp["y"][end_b] - lp["y"][end_a])
            hint = ""
            for end, ref in ((end_a, step), (end_b, other)):
                hang = row_of(nums, lp[ref][end])
                if hang is not None and (hang in seen or hang in back_rows):
                    hint = (
                        f" (point {nums[end]} hangs on point {nums[hang]} of the same line as "
                        "a branch, which does not close a line)"
                    )
            raise TopologyError(
                f"AREA: the line is not closed: it ends at point {nums[end_a]} "
                f"({lp['x'][end_a]:.2f}, {lp['y'][end_a]:.2f}) and at point {nums[end_b]} "
                f"({lp['x'][end_b]:.2f}, {lp['y'][end_b]:.2f}), gap {gap:.2f} m{hint}"
            )
        rows.append(k)
        seen.add(k)
        cur = k
    if len(rows) < 3:
        raise TopologyError(f"AREA: the ring through {first} has fewer than three points")
    x = lp["x"][rows] - lp["x"][i]
    y = lp["y"][rows] - lp["y"][i]
    signed = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    per = float(np.sum(np.hypot(np.roll(x, -1) - x, np.roll(y, -1) - y)))
    return AreaResult(
        area_m2=abs(signed),
        perimeter_m=per,
        clockwise=signed < 0,
        points=tuple(int(v) for v in nums[rows]),
    )


# --------------------------------------------------------------------------- DHI


@dataclass(frozen=True)
class DHI:
    """Distance, height difference and inclination from point A to point B.

    ``distance_m`` is horizontal, ``slope_distance_m`` spatial, ``dz_m`` is
    ``Z_B - Z_A``, ``inclination_deg`` is ``atan2(dz, distance)`` and
    ``inclination_pct`` is ``100 * dz / distance`` (None for a vertical).
    """

    distance_m: float
    slope_distance_m: float
    dz_m: float
    inclination_deg: float
    inclination_pct: float | None = field(default=None)


def dhi(a, b) -> DHI:
    """APY's DHI between two positions ``(x, y, z)``.

    >>> d = dhi((0.0, 0.0, 400.0), (30.0, 40.0, 405.0))
    >>> d.distance_m, d.dz_m, d.inclination_pct
    (50.0, 5.0, 10.0)
    """
    ax, ay, az = (float(v) for v in a)
    bx, by, bz = (float(v) for v in b)
    dist = math.hypot(bx - ax, by - ay)
    dz = bz - az
    return DHI(
        distance_m=dist,
        slope_distance_m=math.hypot(dist, dz),
        dz_m=dz,
        inclination_deg=math.degrees(math.atan2(dz, dist)),
        inclination_pct=(100.0 * dz / dist) if dist > 0 else None,
    )


# --------------------------------------------------------------------------- geometry


def line_geometries(lp: np.ndarray, cs: ChainSet | None = None) -> np.ndarray:
    """Shapely geometries of all chains: LineString Z, or Polygon Z for closed lines.

    Returns an object array aligned with the chains of ``cs`` (computed if not
    given). A one-point chain gives an empty LineString.
    """
    import shapely

    if cs is None:
        cs = chains(lp)
    out = np.empty(len(cs), dtype=object)
    if len(cs) == 0:
        return out
    coords = np.column_stack([lp["x"], lp["y"], lp["z"]])[cs.order]
    chain_idx = np.repeat(np.arange(len(cs)), cs.lengths())
    lengths = cs.lengths()
    open_ok = (~cs.closed) & (lengths >= 2)
    sel = open_ok[chain_idx]
    if sel.any():
        which, dense = np.unique(chain_idx[sel], return_inverse=True)
        out[which] = shapely.linestrings(coords[sel], indices=dense)
    if cs.closed.any():
        # Close each ring explicitly by repeating its first vertex.
        ring_rows = np.flatnonzero(cs.closed[chain_idx])
        ring_ids = np.flatnonzero(cs.closed)
        firsts = cs.offsets[:-1][ring_ids]
        all_ids = np.r_[chain_idx[ring_rows], ring_ids]
        all_pos = np.r_[ring_rows, firsts]
        # stable sort by chain keeps each ring's vertices in order, its first vertex last
        order = np.lexsort((np.r_[np.zeros(len(ring_rows)), np.ones(len(ring_ids))], all_ids))
        which, dense = np.unique(all_ids[order], return_inverse=True)
        rings = shapely.linearrings(coords[all_pos[order]], indices=dense)
        out[which] = shapely.polygons(rings)
    for k in np.flatnonzero(lengths < 2):
        out[k] = shapely.LineString()
    return out
