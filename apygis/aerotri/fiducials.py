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

from dataclasses import dataclass

import numpy as np

from apygis.aerotri.camera import Camera, PixelTransform

__all__ = [
    "BRIGHT_DN",
    "DARK_DN",
    "FIDUCIAL_SHAPES",
    "ORIENTATION_SHAPES",
    "MarkFit",
    "draw_marks",
    "find_candidates",
    "mark_template",
    "ncc_map",
    "refine_mark",
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


# --------------------------------------------------------------------------- detection

#: half width (mm) of the coarse-search templates: inside the dark squares, so the
#: template never sees the image around a mark
#: (a pixel size overestimated by 25 % still keeps them inside)
_TEMPLATE_HALF_MM = {False: 3.0, True: 1.5}
#: radius (mm) of the level-0 refinement window: inside the dark square (4 mm),
#: outside the ring (1.3 mm)
_REFINE_RADIUS_MM = 1.6


def mark_template(pixel_mm: float, *, orientation: bool = False) -> np.ndarray:
    """The inner part of a mark (fiducial or orientation mark) at ``pixel_mm`` per pixel.

    A square of side about ``2 * 3`` mm (fiducial) or ``2 * 1.5`` mm (orientation
    mark), odd size, centred on the mark: only the dark square, disk and ring, no
    surround (the squares' half sides are 4 and 2 mm).
    """
    half = _TEMPLATE_HALF_MM[orientation]
    n = 2 * max(2, int(np.floor(half / pixel_mm))) + 1
    p = float(pixel_mm)
    t = PixelTransform.affine(p, 0.0, 0.0, -p, -(n - 1) / 2 * p, (n - 1) / 2 * p)
    return render_design(t, (n, n), orientation=orientation, subsamples=4)


def ncc_map(image: np.ndarray, template: np.ndarray, *, min_std: float = 4.0) -> np.ndarray:
    """Normalised cross-correlation of ``template`` centred at every pixel of ``image``.

    ``rho(c, r) = sum (g - mean g)(t - mean t) / sqrt(sum (g - mean g)^2 sum (t - mean t)^2)``
    over the template's footprint centred at ``(c, r)`` (odd template; the image is
    reflected at its border). Where the image's standard deviation under the
    footprint is below ``min_std`` DN (flat areas, a blank scan) ``rho = 0``.
    """
    import cv2

    th, tw = template.shape
    ry, rx = th // 2, tw // 2
    img = np.asarray(image, dtype=np.float32)
    pad = cv2.copyMakeBorder(img, ry, ry, rx, rx, cv2.BORDER_REFLECT_101)
    tpl = np.asarray(template, dtype=np.float32)
    rho = cv2.matchTemplate(pad, tpl, cv2.TM_CCOEFF_NORMED)
    mean = cv2.boxFilter(pad, cv2.CV_64F, (tw, th), normalize=True, borderType=cv2.BORDER_ISOLATED)
    sq = cv2.boxFilter(
        pad.astype(np.float64) ** 2, cv2.CV_64F, (tw, th), normalize=True,
        borderType=cv2.BORDER_ISOLATED,
    )  # fmt: skip
    var = (sq - mean**2)[ry : ry + img.shape[0], rx : rx + img.shape[1]]
    rho = np.where((var >= min_std**2) & np.isfinite(rho), rho, 0.0)
    return np.asarray(rho, dtype=np.float64)


def find_candidates(
    image: np.ndarray,
    pixel_mm: float,
    *,
    orientation: bool = False,
    threshold: float = 0.5,
    max_candidates: int = 40,
    separation_mm: float = 5.0,
    scales: tuple[float, ...] = (1.0,),
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate marks in a (coarse) image: positions ``(n, 2)`` (col, row) and NCC scores.

    The local maxima of :func:`ncc_map` with the mark's template at ``pixel_mm``
    (the design is invariant to rotations by 90 degrees and mirrors, and nearly
    so to the scan's small rotation; with several ``scales``, templates at
    ``pixel_mm * scale`` each and the largest correlation per pixel, for a pixel
    size known only roughly) above ``threshold``, at least
    ``separation_mm`` apart, best first; positions to sub-pixel by a parabola
    through the maximum and its neighbours in each axis.
    """
    from scipy import ndimage

    rho = ncc_map(image, mark_template(pixel_mm * scales[0], orientation=orientation))
    for f in scales[1:]:
        more = ncc_map(image, mark_template(pixel_mm * f, orientation=orientation))
        np.maximum(rho, more, out=rho)
    size = max(3, 2 * int(separation_mm / pixel_mm / 2) + 1)
    peak = (rho == ndimage.maximum_filter(rho, size=size, mode="nearest")) & (rho >= threshold)
    rows, cols = np.nonzero(peak)
    order = np.argsort(-rho[rows, cols], kind="stable")[:max_candidates]
    rows, cols = rows[order], cols[order]
    score = rho[rows, cols]
    h, w = rho.shape
    rc, cc = np.clip(rows, 1, h - 2), np.clip(cols, 1, w - 2)

    def vertex(m, z, p):
        den = m - 2 * z + p
        return np.where(den < 0, 0.5 * (m - p) / np.where(den < 0, den, -1.0), 0.0)

    dc = vertex(rho[rc, cc - 1], rho[rc, cc], rho[rc, cc + 1])
    dr = vertex(rho[rc - 1, cc], rho[rc, cc], rho[rc + 1, cc])
    xy = np.column_stack([cols + np.clip(dc, -0.5, 0.5), rows + np.clip(dr, -0.5, 0.5)])
    return xy.astype(float), score.astype(float)


def _ramp(r: np.ndarray, radius: float, width: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coverage of the disk ``r <= radius`` smoothed over ``width`` and its r-derivative."""
    t = (radius - r) / width + 0.5
    inside = (t > 0.0) & (t < 1.0)
    return np.clip(t, 0.0, 1.0), np.where(inside, -1.0 / width, 0.0)


@dataclass(frozen=True)
class MarkFit:
    """A mark refined at full resolution (see :func:`refine_mark`).

    ``xy``: centre (col, row), level-0 pixels; ``sigma_px``: its standard
    deviations from the fit; ``background`` and ``contrast``: the fitted dark
    level and bright-minus-dark (DN); ``r2``: the share of the window's variance
    the model explains (1 for a perfect mark); ``ok``: converged with
    ``r2 >= 0.8`` and a contrast of at least 20 DN (converged: the last
    Gauss-Newton step below 0.01 px).
    """

    xy: tuple[float, float]
    sigma_px: tuple[float, float]
    background: float
    contrast: float
    r2: float
    ok: bool


def refine_mark(
    source,
    xy0,
    local_mm: np.ndarray,
    *,
    search_mm: float = 1.0,
    iterations: int = 10,
) -> MarkFit:
    """The centre of the fiducial mark near ``xy0`` (level-0 pixels), to sub-pixel.

    Reads one level-0 window of ``source`` (an :class:`ImageSource`) of radius
    ``1.6 mm + search_mm`` around ``xy0``. ``local_mm`` is the 2 x 2 linear part
    of the pixel -> mm transform near the mark (from the coarse orientation); the
    local radius of a pixel ``x`` from a centre ``c`` is ``r = |local_mm (x - c)|``.

    1. Start: iterated centroid of ``max(g - median, 0)`` over ``r <= 1.6`` mm (the
       median of that disk is the dark level: the bright disk and ring cover 20 %).
    2. Least-squares fit (Gauss-Newton) of the radial model over ``r <= 1.6`` mm::

           g(x) = a + b (R(r, 0.3) + R(r, 1.3) - R(r, 1.0)),
           R(r, rho) = clip((rho - r) / w + 1/2, 0, 1),

       the disk and ring with edges smoothed over the pixel's width ``w`` across
       the edge (``w = |local_mm| (|cos phi| + |sin phi|)`` in mm, ``phi`` the
       direction from the centre): unknowns ``c = (col, row)``, ``a``, ``b``. The
       model's small errors (the exact edge profile) are point-symmetric about the
       centre, so they do not bias ``c``.
    """
    xy0 = np.asarray(xy0, dtype=float).reshape(2)
    lm = np.asarray(local_mm, dtype=float).reshape(2, 2)
    pix_mm = float(np.sqrt(abs(np.linalg.det(lm))))
    half = int(np.ceil((_REFINE_RADIUS_MM + search_mm) / pix_mm)) + 2
    c0, r0 = int(np.rint(xy0[0])) - half, int(np.rint(xy0[1])) - half
    win = np.asarray(source.read(0, c0, r0, 2 * half + 1, 2 * half + 1), dtype=float)
    rows, cols = np.mgrid[r0 : r0 + 2 * half + 1, c0 : c0 + 2 * half + 1]
    pts = np.column_stack([cols.ravel(), rows.ravel()]).astype(float)
    g = win.ravel()
    fail = MarkFit((float(xy0[0]), float(xy0[1])), (np.inf, np.inf), 0.0, 0.0, 0.0, False)

    def radius(c):
        d = pts - c
        m = d @ lm.T
        return d, m, np.hypot(m[:, 0], m[:, 1])

    # 1. iterated centroid
    c = xy0.copy()
    for _ in range(6):
        _, _, r = radius(c)
        sel = r <= _REFINE_RADIUS_MM
        if sel.sum() < 9:
            return fail
        wgt = np.maximum(g[sel] - np.median(g[sel]), 0.0)
        if wgt.sum() <= 0:
            return fail
        new = (pts[sel] * wgt[:, None]).sum(axis=0) / wgt.sum()
        step = float(np.hypot(*(new - c)))
        c = new
        if step < 0.05:
            break
    if float(np.hypot(*(c - xy0))) * pix_mm > search_mm + 0.5:
        return fail
    # 2. Gauss-Newton on the radial model
    ata = lm.T @ lm
    sigma = np.array([np.inf, np.inf])
    a = b = r2 = 0.0
    converged = False
    for _ in range(iterations):
        d, m, r = radius(c)
        sel = r <= _REFINE_RADIUS_MM
        d, r, gs = d[sel], r[sel], g[sel]
        phi_c = np.abs(m[sel, 0]) + np.abs(m[sel, 1])
        wdt = pix_mm * np.where(r > 0, phi_c / np.where(r > 0, r, 1.0), 1.0)
        f1, d1 = _ramp(r, 0.3, wdt)
        f2, d2 = _ramp(r, 1.3, wdt)
        f3, d3 = _ramp(r, 1.0, wdt)
        prof, dprof = f1 + f2 - f3, d1 + d2 - d3
        design = np.column_stack([np.ones_like(prof), prof])
        (a, b), *_ = np.linalg.lstsq(design, gs, rcond=None)
        # dr/dc = -(A^T A (x - c)) / r
        rs = np.where(r > 0, r, 1.0)
        drdc = -(d @ ata) / rs[:, None]
        jac = np.column_stack([b * dprof[:, None] * drdc, design])
        res = gs - (a + b * prof)
        n = jac.T @ jac
        try:
            dx = np.linalg.solve(n, jac.T @ res)
        except np.linalg.LinAlgError:
            return fail
        c = c + dx[:2]
        dof = max(len(res) - 4, 1)
        s0 = float(res @ res) / dof
        cov = s0 * np.linalg.pinv(n)
        sigma = np.sqrt(np.abs(np.diag(cov)[:2]))
        sst = float(((gs - gs.mean()) ** 2).sum())
        r2 = 1.0 - float(res @ res) / sst if sst > 0 else 0.0
        step = float(np.hypot(dx[0], dx[1]))
        # converged: the last step far below the precision (the piecewise-linear edges
        # and the window's pixel set can leave a ~1e-3 px oscillation)
        converged = step < 0.01
        if step < 1e-4:
            break
    ok = bool(
        converged
        and r2 >= 0.8
        and b >= 20.0
        and float(np.hypot(*(c - xy0))) * pix_mm <= search_mm + 0.5
    )
    return MarkFit(
        (float(c[0]), float(c[1])),
        (float(sigma[0]), float(sigma[1])),
        float(a),
        float(b),
        float(r2),
        ok,
    )
