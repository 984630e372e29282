"""Label placement: texts and spot heights placed off lines, symbols and each other.

The candidate-position method (Imhof's rules as cartographic programs use
them; Christensen, Marks & Shieber 1995 for the search):

1. Every label gets ranked **candidate positions** around its anchor
   (:func:`candidates`):

   * a *point label* (a spot height's height, a control point's number)
     sits beside its symbol: 8 positions at ``gap`` mm from the anchor,
     right first (E, NE, SE, W, NW, SW, N, S), then the same 8 at
     ``gap + 1.2 x cap height`` and at ``gap + 2.4 x cap height``: 24;
   * a *text* of the map starts where the operator put it (rank 0: its
     baseline starts at its point), then moves away from there in steps of
     0.8 x its cap height up and down (up to 3 steps) and a third of its
     width left and right, and to the 8 point positions around its start:
     up to 29 candidates, ranked by how far they move it.

2. Each candidate's **static conflicts** are counted: the map lines it
   crosses, the symbols it covers (a point label never counts its own),
   and the neat line when it does not lie wholly inside it. Soft obstacles
   (the grid's crosses) add a small cost and are not conflicts.

3. Candidates of different labels that overlap are **in conflict** with
   each other when both are chosen.

4. The search: labels with the fewest free candidates first, each takes
   its cheapest candidate given those already placed (greedy); then
   simulated annealing (random moves of labels in conflict, accepted by
   the Metropolis rule with a geometric cooling schedule, seeded, so the
   result is the same every run) improves the whole, and the best state
   seen is kept.

Cost of a placement: 1 per line crossed, 2 per symbol covered, 3 for
crossing the neat line and 3 per other label overlapped (an overlap of
labels is the least readable), 0.3 per soft obstacle, plus the candidate's
rank cost (0.002 per rank step; a text's moves cost 0.01 per mm): conflicts
dominate, and among free positions the preferred one wins.

A label whose chosen position still has a conflict **could not be placed
free**; :class:`Placement` counts them and says with what they collide.

Examples
--------
>>> import numpy as np
>>> reqs = [LabelRequest("A", 10.0, 10.0, 2.0, 1.4, 0.0, "point", 1.0)]
>>> line = np.array([(11.0, 0.0), (11.0, 30.0)])  # a line right of the point
>>> p = place_labels(reqs, [line], np.zeros((0, 4)), (0, 0, 50, 50))
>>> bool(p.x[0] < 10.0), p.overlapping
(True, 0)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from apygis.progress import Progress

__all__ = [
    "PAIR_BUDGET",
    "LabelRequest",
    "Placement",
    "candidates",
    "place_labels",
]

_POINT_ORDER = ((1, 0), (1, 1), (1, -1), (-1, 0), (-1, 1), (-1, -1), (0, 1), (0, -1))
_RANK_COST = 0.002
_MOVE_COST = 0.01  # per mm a text moves from where it was put
_SOFT_COST = 0.3
# what a conflict costs: a label over another label or across the neat line is the worst
# (unreadable, or in the margin), covering a symbol next, crossing a line the least
_W_LINE, _W_SYMBOL, _W_FRAME, _W_LABEL = 1.0, 2.0, 3.0, 3.0
_SA_SEED = 20240612
_MAX_MOVES_PER_STAGE = 5000
#: The most pairs of overlapping candidates weighed (both ways); beyond it, fewer
#: candidates per label (``candidates(level=1, 2)``): memory stays some 200 MB.
PAIR_BUDGET = 12_000_000  # bounds the search on big sheets: 40 stages of at most this


@dataclass(frozen=True)
class LabelRequest:
    """A label to place.

    Attributes
    ----------
    text : str
        What it says (for reports).
    x, y : float
        The anchor, mm: a point label's symbol centre, a text's point (the
        start of its baseline as compiled).
    height : float
        Cap height, mm.
    width, descent : float
        The text's ink width and its depth below the baseline, mm
        (:func:`apygis.plot.fonts.text_size`).
    kind : str
        ``"point"`` or ``"text"``.
    gap : float
        Room between the anchor and a point label (the symbol's half size
        plus a little), mm.
    own : int
        Index of the label's own symbol among the obstacle boxes (-1: none).
    """

    text: str
    x: float
    y: float
    height: float
    width: float
    descent: float
    kind: str
    gap: float = 0.0
    own: int = -1


@dataclass
class Placement:
    """Where the labels went.

    Attributes
    ----------
    x, y : ndarray
        Start of each label's baseline, mm.
    rank : ndarray of int
        The chosen candidate's rank (0: the preferred position).
    lines, symbols, labels, frame : ndarray of int
        What each label's position still collides with: map lines crossed,
        symbols covered, other labels overlapped, and 1 where it crosses the
        neat line.
    """

    x: np.ndarray
    y: np.ndarray
    rank: np.ndarray
    lines: np.ndarray
    symbols: np.ndarray
    labels: np.ndarray
    frame: np.ndarray
    cost: float = 0.0
    stats: dict = field(default_factory=dict)

    @property
    def free(self) -> np.ndarray:
        """True where a label collides with nothing."""
        return (self.lines + self.symbols + self.labels + self.frame) == 0

    @property
    def overlapping(self) -> int:
        """Number of labels that could not be placed free."""
        return int((~self.free).sum())

    @property
    def moved(self) -> int:
        """Number of labels not at their preferred position."""
        return int((self.rank > 0).sum())


def candidates(req: LabelRequest, level: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The candidate baselines ``(k, 2)`` (start x, y in mm) and their costs ``(k,)``, best first.

    ``level`` 0 gives the full set; 1 and 2 fewer (a point label's first ring,
    or its 4 sides; a text's vertical moves and first ring, or 4 positions),
    for sheets too crowded to weigh every pair of the full sets
    (:data:`PAIR_BUDGET`).

    >>> xy, cost = candidates(LabelRequest("12", 0.0, 0.0, 2.0, 2.0, 0.0, "point", 1.0))
    >>> xy[0].tolist(), len(xy)
    ([1.0, -1.0], 24)
    """
    h, w, d = req.height, req.width, req.descent
    out: list[tuple[float, float]] = []
    cost: list[float] = []

    def around(gap: float, base_cost: float, ax: float, ay: float) -> None:
        for ux, uy in _POINT_ORDER:
            g = gap * (0.7 if ux and uy else 1.0)
            if ux == 1:
                x0 = ax + g
            elif ux == -1:
                x0 = ax - g - w
            else:
                x0 = ax - w / 2.0
            if uy == 1:
                base = ay + g + d
            elif uy == -1:
                base = ay - g - h
            else:
                base = ay - h / 2.0
            out.append((x0, base))
            cost.append(base_cost + _RANK_COST * len(cost))

    if req.kind == "point":
        for ring in range(3 if level == 0 else 1):
            around(req.gap + 1.2 * h * ring, 0.05 * ring, req.x, req.y)
        if level == 2:  # right, left, above, below
            keep = [0, 3, 6, 7]
            out[:] = [out[k] for k in keep]
            cost[:] = [cost[k] for k in keep]
    else:
        seen = set()
        moves = []
        dys = (
            (0.0, 0.8, -0.8, 1.6, -1.6, 2.4, -2.4),
            (0.0, 0.8, -0.8, 1.6, -1.6),
            (0.0, 0.8, -0.8),
        )
        dxs = ((0.0, -1 / 3, 1 / 3), (0.0,), (0.0,))
        for dy in dys[level]:
            for dx in dxs[level]:
                moves.append((dx * w, dy * h))
        for dx, dy in moves:
            key = (round(dx, 6), round(dy, 6))
            if key in seen:
                continue
            seen.add(key)
            out.append((req.x + dx, req.y + dy))
            cost.append(_MOVE_COST * math.hypot(dx, dy))
        # around the text's start, as a point label (to the left of it, above, below)
        n0 = len(out)
        around(max(req.gap, 0.5), 0.0, req.x, req.y + h / 2.0)
        if level == 2:  # only the position left of the start
            del out[n0:], cost[n0:]
            out.append((req.x - max(req.gap, 0.5) - w, req.y))
            cost.append(0.0)
        for k in range(n0, len(out)):
            dx, dy = out[k][0] - req.x, out[k][1] - req.y
            cost[k] = _MOVE_COST * math.hypot(dx, dy) + 0.02
    xy = np.array(out, dtype=float)
    c = np.array(cost, dtype=float)
    order = np.argsort(c, kind="stable")
    return xy[order], c[order]


def _all_candidates(reqs: Sequence[LabelRequest], level: int):
    """Every label's candidates: positions, costs, owning label, first index of each label."""
    cand_xy, cand_cost, owner = [], [], []
    for i, r in enumerate(reqs):
        xy, costs = candidates(r, level)
        cand_xy.append(xy)
        cand_cost.append(costs)
        owner.append(np.full(len(xy), i))
    first = np.concatenate([[0], np.cumsum([len(c) for c in cand_xy])])
    return np.vstack(cand_xy), np.concatenate(cand_cost), np.concatenate(owner), first


def _pairs(geoms, own: np.ndarray, budget: int | None):
    """Overlapping candidates of different labels ``(a, b)``, both ways; None past ``budget``."""
    import shapely

    tree = shapely.STRtree(geoms)
    got_a, got_b, total = [], [], 0
    step = 20000
    for lo in range(0, len(geoms), step):
        ia, ib = tree.query(geoms[lo : lo + step], predicate="intersects")
        ia = ia + lo
        keep = own[ia] != own[ib]
        ia, ib = ia[keep].astype(np.int32), ib[keep].astype(np.int32)
        total += len(ia)
        if budget is not None and total > budget:
            return None
        got_a.append(ia)
        got_b.append(ib)
    if not got_a:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    return np.concatenate(got_a), np.concatenate(got_b)


def _boxes(reqs: Sequence[LabelRequest], xy: np.ndarray, owner: np.ndarray) -> np.ndarray:
    w = np.array([r.width for r in reqs])[owner]
    h = np.array([r.height for r in reqs])[owner]
    d = np.array([r.descent for r in reqs])[owner]
    return np.column_stack([xy[:, 0], xy[:, 1] - d, xy[:, 0] + w, xy[:, 1] + h])


def place_labels(
    reqs: Sequence[LabelRequest],
    lines: Sequence[np.ndarray],
    symbols: np.ndarray,
    frame: tuple[float, float, float, float],
    soft: np.ndarray | None = None,
    progress: Progress | None = None,
) -> Placement:
    """Place ``reqs`` avoiding ``lines``, ``symbols``, ``soft`` obstacles and each other.

    Parameters
    ----------
    reqs : sequence of LabelRequest
        The labels.
    lines : sequence of ndarray
        Map lines as polylines (n, 2) in mm.
    symbols : ndarray
        Symbol boxes (k, 4) ``x0, y0, x1, y1`` in mm.
    frame : (float, float, float, float)
        The neat line; a label must lie inside it to be free.
    soft : ndarray, optional
        Boxes (k, 4) that cost a little to cover (grid crosses).
    progress : Progress, optional
        ``progress(done, total)`` as the search goes (:mod:`apygis.progress`).

    Returns
    -------
    Placement
    """
    import shapely

    n = len(reqs)
    if n == 0:
        if progress is not None:
            progress(0, 0)
        e = np.zeros(0, dtype=np.int64)
        return Placement(np.zeros(0), np.zeros(0), e, e, e, e, e)
    # candidates, fewer where the full sets would overlap in too many pairs
    for level in range(3):
        xy, base_cost, own, first = _all_candidates(reqs, level)
        boxes = _boxes(reqs, xy, own)
        geoms = shapely.box(boxes[:, 0], boxes[:, 1], boxes[:, 2], boxes[:, 3])
        pairs = _pairs(geoms, own, PAIR_BUDGET if level < 2 else None)
        if pairs is not None:
            break
    assert pairs is not None
    nc = len(boxes)
    if progress is not None:
        progress(1, 10)

    # static conflicts: lines, symbols, the neat line, soft obstacles
    line_hits = np.zeros(nc, dtype=np.int64)
    pieces = [np.asarray(p, dtype=float).reshape(-1, 2) for p in lines if len(p) >= 2]
    if pieces:
        # segments, not whole lines, in the tree: small boxes prune well; a candidate
        # counts each line it crosses once
        starts = np.vstack([p[:-1] for p in pieces])
        ends = np.vstack([p[1:] for p in pieces])
        line_of = np.repeat(np.arange(len(pieces)), [len(p) - 1 for p in pieces])
        segs = shapely.linestrings(
            np.stack([starts, ends], axis=1).reshape(-1, 2),
            indices=np.repeat(np.arange(len(starts)), 2),
        )
        tree = shapely.STRtree(segs)
        ci, si = tree.query(geoms, predicate="intersects")
        if len(ci):
            hit_keys = np.unique(ci.astype(np.int64) * len(pieces) + line_of[si])
            line_hits = np.bincount(hit_keys // len(pieces), minlength=nc)
    sym_hits = np.zeros(nc, dtype=np.int64)
    symbols = np.asarray(symbols, dtype=float).reshape(-1, 4)
    if len(symbols):
        tree = shapely.STRtree(
            shapely.box(symbols[:, 0], symbols[:, 1], symbols[:, 2], symbols[:, 3])
        )
        ci, si = tree.query(geoms, predicate="intersects")
        own_sym = np.array([r.own for r in reqs])[own[ci]]
        keep = si != own_sym
        sym_hits = np.bincount(ci[keep], minlength=nc)
    fx0, fy0, fx1, fy1 = frame
    out_frame = (
        (boxes[:, 0] < fx0) | (boxes[:, 1] < fy0) | (boxes[:, 2] > fx1) | (boxes[:, 3] > fy1)
    ).astype(np.int64)
    soft_hits = np.zeros(nc)
    if soft is not None and len(soft):
        soft = np.asarray(soft, dtype=float).reshape(-1, 4)
        tree = shapely.STRtree(shapely.box(soft[:, 0], soft[:, 1], soft[:, 2], soft[:, 3]))
        ci, _ = tree.query(geoms, predicate="intersects")
        soft_hits = np.bincount(ci, minlength=nc).astype(float)
    static = (
        _W_LINE * line_hits
        + _W_SYMBOL * sym_hits
        + _W_FRAME * out_frame
        + _SOFT_COST * soft_hits
        + base_cost
    )
    if progress is not None:
        progress(3, 10)

    # candidate-candidate conflicts between different labels (CSR adjacency)
    a, b = pairs
    order = np.argsort(a, kind="stable")
    a, b = a[order], b[order]
    indptr = np.searchsorted(a, np.arange(nc + 1))
    nbrs = b
    if progress is not None:
        progress(4, 10)

    cur = np.full(n, -1, dtype=np.int64)
    occ = np.zeros(nc, dtype=np.int64)  # how many chosen candidates overlap each candidate

    def choose(c: int) -> None:
        occ[nbrs[indptr[c] : indptr[c + 1]]] += 1

    def unchoose(c: int) -> None:
        occ[nbrs[indptr[c] : indptr[c + 1]]] -= 1

    # greedy: labels with the fewest free candidates first, each at its cheapest candidate
    hard = line_hits + sym_hits + out_frame
    free_count = np.add.reduceat((hard == 0).astype(np.int64), first[:-1])
    for i in np.argsort(free_count, kind="stable").tolist():
        lo, hi = int(first[i]), int(first[i + 1])
        best = lo + int(np.argmin(static[lo:hi] + _W_LABEL * occ[lo:hi]))
        cur[i] = best
        choose(best)
    if progress is not None:
        progress(5, 10)

    # simulated annealing over the labels in conflict (Metropolis moves, geometric cooling)
    bad = np.flatnonzero((hard[cur] > 0) | (occ[cur] > 0))
    if len(bad):
        rng = np.random.default_rng(_SA_SEED)
        total = float((static[cur] + _W_LABEL * occ[cur]).sum())
        best_total, best_cur = total, cur.copy()
        temp = 1.0
        stages = 40
        moves_per_stage = min(max(50, 20 * len(bad)), _MAX_MOVES_PER_STAGE)
        picks = rng.integers(len(bad), size=(stages, moves_per_stage))
        draws = rng.random((stages, moves_per_stage))
        idle = 0
        for stage in range(stages):
            for k in range(moves_per_stage):
                i = int(bad[picks[stage, k]])
                lo, hi = int(first[i]), int(first[i + 1])
                old = int(cur[i])
                new = lo + int(draws[stage, k] * (hi - lo))
                if new == old:
                    continue
                delta = float(static[new] - static[old] + 2 * _W_LABEL * (occ[new] - occ[old]))
                if delta <= 0 or rng.random() < math.exp(-delta / temp):
                    unchoose(old)
                    choose(new)
                    cur[i] = new
                    total += delta
            temp *= 0.85
            if total < best_total - 1e-9:
                best_total, best_cur, idle = total, cur.copy(), 0
            else:
                idle += 1
            if progress is not None:
                progress(5 + (4 * (stage + 1)) // stages, 10)
            if idle >= 8:
                break
        cur = best_cur
        occ[:] = 0
        for c in cur.tolist():
            choose(c)
    # a last greedy pass: each label moves to its cheapest candidate given the others
    for _ in range(3):
        changed = False
        for i in range(n):
            old = int(cur[i])
            unchoose(old)
            lo, hi = int(first[i]), int(first[i + 1])
            seg = static[lo:hi] + _W_LABEL * occ[lo:hi]
            k = int(np.argmin(seg))
            best = lo + k if seg[k] < static[old] + _W_LABEL * occ[old] - 1e-9 else old
            cur[i] = best
            choose(best)
            changed |= best != old
        if not changed:
            break

    lab_hits = occ[cur].astype(np.int64)
    if progress is not None:
        progress(10, 10)
    return Placement(
        x=xy[cur, 0].copy(),
        y=xy[cur, 1].copy(),
        rank=(cur - first[:-1]).astype(np.int64),
        lines=line_hits[cur].astype(np.int64),
        symbols=sym_hits[cur].astype(np.int64),
        labels=lab_hits,
        frame=out_frame[cur].astype(np.int64),
        cost=float(static[cur].sum() + _W_LABEL * lab_hits.sum() / 2.0),
        stats={"candidates": nc, "conflict_pairs": len(a) // 2, "level": level},
    )
