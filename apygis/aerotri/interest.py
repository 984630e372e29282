"""The Förstner interest operator: well-defined points, located to sub-pixel.

For the gradients ``g = (gx, gy)`` of a grey image, the structure tensor over a
window ``W`` around each pixel is ``N = sum_W g g^T``. Förstner's measures are

* the weight ``w = det N / trace N`` (the inverse of the mean error ellipse's
  size: large for a point that can be located precisely), and
* the roundness ``q = 4 det N / (trace N)^2`` in ``[0, 1]`` (1 for a round
  error ellipse, 0 for an edge).

A pixel is a point when ``q >= q_min``, ``w >= w_min`` and ``w`` is the largest
within the suppression radius. Its sub-pixel position is Förstner's optimal
corner point: the point ``p`` closest, in the least-squares sense, to all edge
lines through the window pixels ``x_i`` with normals ``g_i``::

    N p = sum_W g_i g_i^T x_i

(the intersection of the edge lines; for a junction of straight edges it is the
junction exactly). Positions are pixel coordinates ``(col, row)`` (see
:mod:`apygis.aerotri`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

__all__ = ["InterestPoints", "foerstner"]


@dataclass(frozen=True)
class InterestPoints:
    """Points of :func:`foerstner`: ``xy`` (n x 2, col/row), weight ``w``, roundness ``q``."""

    xy: np.ndarray
    w: np.ndarray
    q: np.ndarray

    def __len__(self) -> int:
        return len(self.w)


def foerstner(
    image,
    *,
    window: int = 5,
    sigma_gradient: float = 0.7,
    q_min: float = 0.5,
    w_factor: float = 1.0,
    radius: int = 4,
    max_points: int | None = None,
    grid: int = 1,
    border: int = 8,
) -> InterestPoints:
    """Förstner points of ``image`` (2-D array, any numeric type).

    Parameters
    ----------
    window : int
        Side of the (square) summation window ``W``, pixels (odd).
    sigma_gradient : float
        Gaussian smoothing of the derivative filters, pixels.
    q_min : float
        Least roundness.
    w_factor : float
        ``w_min = w_factor * median(w)`` over the pixels with ``w > 0``
        (a threshold relative to the image's contrast, so it needs no tuning
        per image).
    radius : int
        Non-maximum suppression radius, pixels.
    max_points, grid : int
        Keep at most ``max_points`` points, the strongest, spread over a
        ``grid x grid`` division of the image (equal share per cell), so that
        texture-rich corners do not take all points.
    border : int
        No point closer than this to the image edge, pixels.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2 or min(img.shape) < 2 * border + window:
        return InterestPoints(np.empty((0, 2)), np.empty(0), np.empty(0))
    gx = ndimage.gaussian_filter(img, sigma_gradient, order=(0, 1))
    gy = ndimage.gaussian_filter(img, sigma_gradient, order=(1, 0))
    gxx = ndimage.uniform_filter(gx * gx, window)
    gyy = ndimage.uniform_filter(gy * gy, window)
    gxy = ndimage.uniform_filter(gx * gy, window)
    det = gxx * gyy - gxy * gxy
    tr = gxx + gyy
    good = tr > 1e-12
    w = np.where(good, det / np.where(good, tr, 1.0), 0.0)
    q = np.where(good, 4.0 * det / np.where(good, tr * tr, 1.0), 0.0)
    positive = w[w > 0]
    if positive.size == 0:
        return InterestPoints(np.empty((0, 2)), np.empty(0), np.empty(0))
    w_min = w_factor * float(np.median(positive))
    peak = ndimage.maximum_filter(w, size=2 * radius + 1) == w
    cand = peak & (q >= q_min) & (w >= w_min)
    cand[:border, :] = False
    cand[-border:, :] = False
    cand[:, :border] = False
    cand[:, -border:] = False
    rows, cols = np.nonzero(cand)
    ws = w[rows, cols]
    if max_points is not None and len(ws) > max_points:
        keep = _spread(rows, cols, ws, img.shape, max_points, grid)
        rows, cols, ws = rows[keep], cols[keep], ws[keep]
    # Förstner's point: N p = sum g g^T x over the window (x = pixel position)
    r = np.arange(img.shape[0], dtype=np.float32)[:, None]
    c = np.arange(img.shape[1], dtype=np.float32)[None, :]
    bx = ndimage.uniform_filter(gx * gx * c + gx * gy * r, window)
    by = ndimage.uniform_filter(gx * gy * c + gy * gy * r, window)
    a, b, d = gxx[rows, cols], gxy[rows, cols], gyy[rows, cols]
    dt = a * d - b * b
    px = (d * bx[rows, cols] - b * by[rows, cols]) / dt
    py = (a * by[rows, cols] - b * bx[rows, cols]) / dt
    # the window's point must stay inside the window (otherwise keep the pixel)
    half = window / 2.0
    off = (np.abs(px - cols) > half) | (np.abs(py - rows) > half) | ~np.isfinite(px + py)
    px = np.where(off, cols, px)
    py = np.where(off, rows, py)
    xy = np.column_stack([px, py]).astype(float)
    return InterestPoints(xy, ws.astype(float), q[rows, cols].astype(float))


def _spread(rows, cols, ws, shape, n: int, grid: int) -> np.ndarray:
    """Indices of the strongest ``n`` points, an equal share per grid cell."""
    grid = max(1, int(grid))
    cell = (rows * grid // shape[0]) * grid + cols * grid // shape[1]
    share = max(1, n // (grid * grid))
    order = np.lexsort((-ws, cell))
    first = np.searchsorted(cell[order], np.arange(grid * grid))
    rank = np.arange(len(order)) - first[cell[order]]
    chosen = order[rank < share]
    if len(chosen) < n:  # cells with few points leave room for the strongest of the rest
        rest = np.setdiff1d(np.arange(len(ws)), chosen)
        rest = rest[np.argsort(-ws[rest])][: n - len(chosen)]
        chosen = np.concatenate([chosen, rest])
    return np.sort(chosen)
