"""Fiducial marks of scanned film: their design, drawing and detection.

The mark design (the block's convention, shared with the synthetic renderer)
is defined in photo millimetres around each calibrated fiducial position
``(xf, yf)``, with local offsets ``(u, v) = (x - xf, y - yf)``:

* fiducial mark: a dark square ``|u|, |v| <= 4`` mm (DN 15) holding a bright
  (DN 235) filled disk ``r <= 0.3`` mm and a bright ring ``1.0 <= r <= 1.3`` mm,
  ``r = sqrt(u^2 + v^2)``;
* orientation mark (optional, :attr:`Camera.orientation_mark_mm`): a dark square
  ``|u|, |v| <= 2`` mm (DN 15) with a bright disk ``r <= 0.5`` mm.

The shapes are painted in order (square, disk 1.3 bright, disk 1.0 dark, disk
0.3 bright), which gives the ring. A scan pixel's grey value is the mean of the
design over the pixel's area (area coverage): for pixel ``(col, row)`` the
square ``[col - 1/2, col + 1/2] x [row - 1/2, row + 1/2]`` mapped to photo mm by
the scan's :class:`PixelTransform`; the background shows where no shape covers.
"""

from __future__ import annotations

import numpy as np

from apygis.aerotri.camera import Camera, PixelTransform

__all__ = [
    "BRIGHT_DN",
    "DARK_DN",
    "FIDUCIAL_SHAPES",
    "ORIENTATION_SHAPES",
    "draw_marks",
    "render_design",
]

DARK_DN = 15.0
BRIGHT_DN = 235.0

# (kind, half side or radius in mm, DN), painted in order
FIDUCIAL_SHAPES: tuple[tuple[str, float, float], ...] = (
    ("square", 4.0, DARK_DN),
    ("disk", 1.3, BRIGHT_DN),
    ("disk", 1.0, DARK_DN),
    ("disk", 0.3, BRIGHT_DN),
)
ORIENTATION_SHAPES: tuple[tuple[str, float, float], ...] = (
    ("square", 2.0, DARK_DN),
    ("disk", 0.5, BRIGHT_DN),
)


def _design(u: np.ndarray, v: np.ndarray, shapes) -> np.ndarray:
    """The design's DN at local offsets (mm); NaN where no shape covers (background)."""
    val = np.full(u.shape, np.nan)
    r2 = u * u + v * v
    for kind, a, dn in shapes:
        inside = (np.abs(u) <= a) & (np.abs(v) <= a) if kind == "square" else r2 <= a * a
        val[inside] = dn
    return val


def _boundary_distance(u: np.ndarray, v: np.ndarray, shapes) -> np.ndarray:
    """A lower bound of the distance (mm) from ``(u, v)`` to the nearest shape boundary."""
    r = np.hypot(u, v)
    d = np.full(u.shape, np.inf)
    for kind, a, _ in shapes:
        sq = kind == "square"
        s = np.abs(np.maximum(np.abs(u) - a, np.abs(v) - a)) if sq else np.abs(r - a)
        np.minimum(d, s, out=d)
    return d


def _paint(
    out: np.ndarray,
    transform: PixelTransform,
    centre_mm: tuple[float, float],
    shapes,
    subsamples: int,
) -> None:
    """Paint one mark into ``out`` in place (area coverage, see the module docstring)."""
    h, w = out.shape
    half = max(a for _, a, _ in shapes)
    cx, cy = centre_mm
    corners = np.array([[cx - half, cy - half], [cx + half, cy - half],
                        [cx + half, cy + half], [cx - half, cy + half]])  # fmt: skip
    px = transform.to_px(corners)
    c0 = max(int(np.floor(px[:, 0].min())) - 1, 0)
    c1 = min(int(np.ceil(px[:, 0].max())) + 2, w)
    r0 = max(int(np.floor(px[:, 1].min())) - 1, 0)
    r1 = min(int(np.ceil(px[:, 1].max())) + 2, h)
    if c0 >= c1 or r0 >= r1:
        return
    cols, rows = np.meshgrid(np.arange(c0, c1, dtype=float), np.arange(r0, r1, dtype=float))
    pts = np.column_stack([cols.ravel(), rows.ravel()])
    mm = transform.to_mm(pts)
    u, v = mm[:, 0] - cx, mm[:, 1] - cy
    # half diagonal of a pixel in mm (local Jacobian at the mark by finite differences)
    c_px = transform.to_px([[cx, cy]])[0]
    jac = transform.to_mm(c_px + np.array([[0.5, 0.5], [0.5, -0.5]])) - transform.to_mm([c_px])
    reach = 1.05 * float(np.max(np.hypot(jac[:, 0], jac[:, 1])))
    edge = _boundary_distance(u, v, shapes) <= reach
    value = _design(u, v, shapes)
    block = out[r0:r1, c0:c1].ravel().astype(float)  # a copy
    uniform = ~edge & np.isfinite(value)
    block[uniform] = value[uniform]
    idx = np.flatnonzero(edge)
    k = subsamples
    offs = (np.arange(k) + 0.5) / k - 0.5
    ou = np.tile(offs, k)  # subsample column offsets, row-major k x k
    ov = np.repeat(offs, k)
    chunk = max(1, 2_000_000 // (k * k))
    for s in range(0, len(idx), chunk):
        ii = idx[s : s + chunk]
        sub = np.column_stack(
            [
                (pts[ii, 0][:, None] + ou[None, :]).ravel(),
                (pts[ii, 1][:, None] + ov[None, :]).ravel(),
            ]
        )
        smm = transform.to_mm(sub)
        sv = _design(smm[:, 0] - cx, smm[:, 1] - cy, shapes).reshape(len(ii), k * k)
        bg = np.isnan(sv)
        sv = np.where(bg, block[ii][:, None], sv)
        block[ii] = sv.mean(axis=1)
    out[r0:r1, c0:c1] = block.reshape(r1 - r0, c1 - c0)


def draw_marks(
    image: np.ndarray,
    transform: PixelTransform,
    camera: Camera,
    *,
    subsamples: int = 16,
) -> np.ndarray:
    """The scan ``image`` with the camera's fiducial marks (and orientation mark) drawn.

    ``transform`` maps scan pixels ``(col, row)`` to photo mm (it may include a
    90/180/270 degree rotation or a mirror of the pixel grid). Each pixel that a
    shape boundary may cross (the boundary within the pixel's half diagonal of
    its centre) is the mean of ``subsamples x subsamples`` point samples of the
    design over the pixel's area (coverage error <= 1/(2 subsamples^2) of the
    contrast per pixel, unbiased in position on average); every other pixel of
    a mark takes the design's value at its centre. Returns a new float array
    (float32 for a float32 input, float64 otherwise); the input is not changed.
    """
    a = np.asarray(image)
    out = a.astype(np.float32 if a.dtype == np.float32 else np.float64, copy=True)
    for xy in camera.fiducials.values():
        _paint(out, transform, (float(xy[0]), float(xy[1])), FIDUCIAL_SHAPES, subsamples)
    if camera.orientation_mark_mm is not None:
        m = camera.orientation_mark_mm
        _paint(out, transform, (float(m[0]), float(m[1])), ORIENTATION_SHAPES, subsamples)
    return out


def render_design(
    transform: PixelTransform,
    shape: tuple[int, int],
    centre_mm: tuple[float, float] = (0.0, 0.0),
    *,
    orientation: bool = False,
    background: float = DARK_DN,
    subsamples: int = 8,
) -> np.ndarray:
    """A ``shape`` (rows, cols) image of one mark (fiducial, or the orientation mark).

    ``transform`` maps the image's pixels to mm; the surround is ``background``.
    """
    img = np.full(shape, float(background))
    shapes = ORIENTATION_SHAPES if orientation else FIDUCIAL_SHAPES
    _paint(img, transform, centre_mm, shapes, subsamples)
    return img
