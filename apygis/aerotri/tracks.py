"""Manifold tie points (tracks) from pairwise matches, and automatic point names.

Linking (seed, section 3.1: "a manifold tie point can be obtained by finding
out the same feature in the common image of the neighbouring models")
    The nodes are ``(image, point index)``; every match of a pair is an edge.
    A track is a connected component of this graph (union-find, here
    :func:`scipy.sparse.csgraph.connected_components`). A component that holds
    two different points of the same image is inconsistent (a wrong match
    somewhere in a loop). It is split: its edges are added again in the order
    of decreasing weight (the matches' NCC, or equal weights) by a union-find
    that refuses an edge joining two sets that share an image (Kruskal's
    order), so the weakest links that close an inconsistency are dropped; or,
    with ``inconsistent="drop"``, the whole component is dropped. Parts with a
    single node are not tracks.

Point names (seed: names generated "from a start value and an interval, never twice")
    :class:`PointNames` issues ``start, start + interval, start + 2 interval,
    ...`` either as plain numbers (``100000, 100001, ...``) or as a prefix with
    a zero-padded numeric tail (``"T0001"`` -> ``T0001, T0002, ...``; the tail
    widens when it overflows). Names marked :meth:`~PointNames.taken` are
    skipped; the counter never goes back, so no name is issued twice.
"""

from __future__ import annotations

import re
from collections.abc import Hashable, Iterable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ["PointNames", "Tracks", "link"]


@dataclass(frozen=True, eq=False)
class Tracks:
    """Tracks in a flat layout: track ``t`` is ``image[offsets[t]:offsets[t+1]]`` etc.

    Attributes
    ----------
    images : list
        The image identifiers, in the order of their codes.
    image : numpy.ndarray of int
        Per node, the code of its image (index into ``images``).
    point : numpy.ndarray of int
        Per node, the point index in its image.
    offsets : numpy.ndarray of int
        ``len(tracks) + 1`` start offsets of the tracks in ``image``/``point``.
    n_inconsistent : int
        Components that held two points of one image.
    n_links_dropped : int
        Matches dropped to split them (``inconsistent="split"``).
    n_tracks_dropped : int
        Inconsistent components dropped whole (``inconsistent="drop"``).
    """

    images: list
    image: np.ndarray
    point: np.ndarray
    offsets: np.ndarray
    n_inconsistent: int = 0
    n_links_dropped: int = 0
    n_tracks_dropped: int = 0

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def __getitem__(self, t: int) -> list[tuple[Hashable, int]]:
        """Track ``t`` as a list of ``(image, point index)``, sorted by image code."""
        s = slice(int(self.offsets[t]), int(self.offsets[t + 1]))
        return [
            (self.images[int(i)], int(p)) for i, p in zip(self.image[s], self.point[s], strict=True)
        ]

    @property
    def multiplicity(self) -> np.ndarray:
        """Number of images of each track."""
        return np.diff(self.offsets)

    def multiplicity_table(self) -> dict[int, int]:
        """``{2: n, 3: n, ...}``: how many tracks are seen in 2, 3, ... images."""
        k, n = np.unique(self.multiplicity, return_counts=True)
        return {int(a): int(b) for a, b in zip(k, n, strict=True)}


class _Sets:
    """Union-find that refuses to join two sets holding the same image."""

    def __init__(self, images: np.ndarray):
        self.parent = list(range(len(images)))
        self.imgs = [{int(i)} for i in images]

    def find(self, x: int) -> int:
        while self.parent[x] != x:
            self.parent[x] = self.parent[self.parent[x]]
            x = self.parent[x]
        return x

    def join(self, a: int, b: int) -> bool:
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return True
        if self.imgs[ra] & self.imgs[rb]:
            return False
        if len(self.imgs[ra]) < len(self.imgs[rb]):
            ra, rb = rb, ra
        self.parent[rb] = ra
        self.imgs[ra] |= self.imgs[rb]
        return True


def link(matches: Iterable, *, inconsistent: str = "split") -> Tracks:
    """Link pairwise matches into tracks (module docstring).

    Parameters
    ----------
    matches : iterable of tuples
        ``(image_a, image_b, idx_a, idx_b)`` or ``(image_a, image_b, idx_a,
        idx_b, weight)``: the images' identifiers (hashable, e.g. image
        numbers), the matched point indices (equal-length integer arrays) and
        optionally a weight per match (higher = stronger, e.g. the NCC).
    inconsistent : "split" or "drop"
        What to do with a component holding two points of one image.
    """
    if inconsistent not in ("split", "drop"):
        raise ValueError(f"inconsistent must be 'split' or 'drop', got {inconsistent!r}")
    codes: dict[Hashable, int] = {}
    ea, eb, wt = [], [], []
    for m in matches:
        ia, ib, pa, pb = m[0], m[1], np.asarray(m[2], dtype=np.int64), np.asarray(m[3], np.int64)
        if pa.shape != pb.shape or pa.ndim != 1:
            raise ValueError(f"matches {ia!r}-{ib!r}: idx_a and idx_b must be equal 1-D arrays")
        if ia == ib:
            raise ValueError(f"matches {ia!r}-{ib!r}: an image cannot be matched with itself")
        ca = codes.setdefault(ia, len(codes))
        cb = codes.setdefault(ib, len(codes))
        w = np.ones(len(pa)) if len(m) < 5 else np.asarray(m[4], dtype=float).reshape(len(pa))
        ea.append(np.column_stack([np.full(len(pa), ca), pa]))
        eb.append(np.column_stack([np.full(len(pb), cb), pb]))
        wt.append(w)
    images = list(codes)
    if not ea or sum(len(e) for e in ea) == 0:
        z = np.empty(0, dtype=np.int64)
        return Tracks(images, z, z.copy(), np.zeros(1, dtype=np.int64))
    A, B, W = np.concatenate(ea), np.concatenate(eb), np.concatenate(wt)
    nodes, inv = np.unique(np.concatenate([A, B]), axis=0, return_inverse=True)
    inv = inv.ravel()
    u, v = inv[: len(A)], inv[len(A) :]
    n = len(nodes)
    g = coo_matrix((np.ones(len(u)), (u, v)), shape=(n, n))
    _, comp = connected_components(g, directed=False)
    comp = np.asarray(comp, dtype=np.int64)
    # inconsistent components: more nodes than distinct images
    size = np.bincount(comp)
    distinct = np.unique(np.column_stack([comp, nodes[:, 0]]), axis=0)[:, 0]
    n_img = np.bincount(distinct, minlength=len(size))
    bad = np.flatnonzero(n_img < size)
    dropped_links = dropped_tracks = 0
    label = comp.copy()
    if len(bad):
        isbad = np.zeros(len(size), dtype=bool)
        isbad[bad] = True
        if inconsistent == "drop":
            label[isbad[comp]] = -1
            dropped_tracks = len(bad)
        else:
            e = np.flatnonzero(isbad[comp[u]])
            e = e[np.argsort(-W[e], kind="stable")]
            sub = np.flatnonzero(isbad[comp])
            local = {int(x): k for k, x in enumerate(sub)}
            sets = _Sets(nodes[sub, 0])
            for k in e:
                if not sets.join(local[int(u[k])], local[int(v[k])]):
                    dropped_links += 1
            roots = np.array([sets.find(k) for k in range(len(sub))], dtype=np.int64)
            label[sub] = len(size) + roots
    keep = label >= 0
    lab, idx = label[keep], np.flatnonzero(keep)
    _, tl, counts = np.unique(lab, return_inverse=True, return_counts=True)
    tl = tl.ravel()
    single = counts[tl] < 2
    idx, tl = idx[~single], tl[~single]
    order = np.lexsort((nodes[idx, 0], tl))
    idx, tl = idx[order], tl[order]
    _, tl = np.unique(tl, return_inverse=True)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(tl.ravel()))]).astype(np.int64)
    return Tracks(
        images=images,
        image=nodes[idx, 0].astype(np.int64),
        point=nodes[idx, 1].astype(np.int64),
        offsets=offsets,
        n_inconsistent=len(bad),
        n_links_dropped=dropped_links,
        n_tracks_dropped=dropped_tracks,
    )


_TAIL = re.compile(r"^(.*?)(\d+)$")


class PointNames:
    """Automatic point names from a start value and an interval, never twice.

    ``PointNames(100000, 1)`` issues ``"100000", "100001", ...``;
    ``PointNames("T0001", 1)`` issues ``"T0001", "T0002", ...`` (the prefix is
    kept, the numeric tail is zero-padded to the start's width and widens when
    it overflows). The state (:meth:`to_dict` / :meth:`from_dict`) is the
    start, the interval, the next counter value and the taken tail values.

    Examples
    --------
    >>> names = PointNames("T0098", 1)
    >>> names.taken(["T0099", "X5"])
    >>> names.next(3)
    ['T0098', 'T0100', 'T0101']
    """

    def __init__(self, start: int | str, interval: int = 1):
        if isinstance(interval, bool) or not isinstance(interval, int) or interval < 1:
            raise ValueError(f"interval must be a positive whole number, got {interval!r}")
        if isinstance(start, bool):
            raise ValueError(f"start must be a whole number or a name ending in digits: {start!r}")
        if isinstance(start, int):
            if start < 0:
                raise ValueError(f"start must not be negative, got {start}")
            self.prefix, self.width, first = "", 0, start
        else:
            mt = _TAIL.match(str(start))
            if mt is None:
                raise ValueError(f"start name {start!r} must end in digits (e.g. 'T0001')")
            self.prefix, self.width, first = mt.group(1), len(mt.group(2)), int(mt.group(2))
        self.start = start
        self.interval = interval
        self._next = first
        self._taken: set[int] = set()

    def _format(self, v: int) -> str:
        return f"{self.prefix}{v:0{self.width}d}" if self.width else str(v)

    def _tail(self, name) -> int | None:
        if isinstance(name, int | np.integer) and not isinstance(name, bool):
            return int(name) if not self.prefix else None
        mt = _TAIL.match(str(name))
        if mt is None or mt.group(1) != self.prefix:
            return None
        if self.width and len(mt.group(2)) < self.width:
            return None  # "T1" is not "T0001"
        if not self.width and (len(mt.group(2)) > 1 and mt.group(2)[0] == "0"):
            return None  # "0123" is not 123
        return int(mt.group(2))

    def taken(self, names: Iterable) -> None:
        """Mark existing names so that they are never issued."""
        for nm in names:
            v = self._tail(nm)
            if v is not None and self._format(v) == str(nm):
                self._taken.add(v)

    def next(self, k: int = 1) -> list[str]:
        """``k`` new names (in increasing order)."""
        out: list[str] = []
        while len(out) < k:
            v = self._next
            self._next += self.interval
            if v not in self._taken:
                out.append(self._format(v))
        return out

    def to_dict(self) -> dict:
        """The state, JSON-ready (for the block database)."""
        return {
            "start": self.start,
            "interval": self.interval,
            "next": self._next,
            "taken": sorted(v for v in self._taken if v >= self._next),
        }

    @classmethod
    def from_dict(cls, d: dict) -> PointNames:
        """The inverse of :meth:`to_dict`."""
        p = cls(d["start"], int(d["interval"]))
        p._next = int(d["next"])
        p._taken = {int(v) for v in d.get("taken", [])}
        return p
