"""Fully automatic tie points (``apygis at match``): the seed's block formation and point tracking.

The pipeline, stage by stage; every stage is a set of independent tasks
(:class:`~apygis.tasks.Runner`: local processes, a Dask cluster, or
this process), and each task's result is committed to the block as it
arrives, so an interrupted run continues where it stopped:

1. **pyramids** (per image): luminance, tiled, overviews by factors of 2
   (:mod:`apygis.aerotri.pyramid`).
2. **interior orientation** (per image): fiducials of scanned film
   (:mod:`apygis.aerotri.interior`), or the fixed transform of a digital camera.
3. **interest points** (per image) at the intermediate level ``L`` (the first
   level whose long side is at most ``intermediate_px``): Förstner points
   spread over the image (:mod:`apygis.aerotri.interest`).
4. **block formation** (per planned pair): area-based matching of the
   Förstner points in search areas predicted from the approximate
   orientations (vertical photos at the plan's centres and headings over the
   mean terrain), outliers removed by a robust relative orientation (pairs in a
   strip) or a robust homography (cross-strip pairs) (:mod:`apygis.aerotri.fbm`);
   then manifold points by linking the same Förstner point across models
   (:mod:`apygis.aerotri.tracks`). Two-fold points are kept selectively (at
   most ``max_twofold_per_pair`` per pair, spread over the model); points seen
   in three or more images all.
5. **point tracking** (per pair of reference and search image): each point's
   reference image is the one where it lies closest to the centre; there the
   Förstner operator is applied again at full resolution, in the window that
   the level-``L`` point covers, and the strongest point becomes the
   reference point. It is then measured in every other image of the point by
   least-squares matching (6 affine + 2 radiometric parameters, cubic-spline
   resampling) from level ``L`` down to full resolution
   (:func:`apygis.aerotri.lsm.track`), starting from the block-formation
   positions and the local affine map of the pair's homography. A measurement
   is kept when it converged, its correlation is at least ``corr_min`` and it
   stayed within ``2**L`` full-resolution pixels of the block-formation
   position (a jump to another feature is a gross error); a point keeps at
   least two images or is dropped.
6. **names, observations and gaps**: tie point names from the block's start
   value and interval (never issued twice); every observation in pixels and
   photo millimetres (through the image's interior orientation; not corrected
   for distortion) with its precision (the LSM's standard deviation, pixels;
   the reference observation gets the median of its partners', as the
   reference point's own definition has no error of its own); von Gruber gap
   counts per model (:func:`apygis.aerotri.plan.gap_report`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from apygis.aerotri import plan as planning
from apygis.aerotri.block import Block, BlockError
from apygis.aerotri.camera import Camera, PixelTransform
from apygis.aerotri.imagery import full_to_level, level_to_full
from apygis.aerotri.interest import InterestPoints, foerstner
from apygis.aerotri.project import block_plan, terrain_height
from apygis.aerotri.pyramid import PyramidSource, build_pyramid
from apygis.errors import OrientationError
from apygis.orient.collinearity import ExteriorOrientation
from apygis.tasks import Runner

__all__ = ["MatchOptions", "MatchReport", "match_block"]

log = logging.getLogger(__name__)


@dataclass
class MatchOptions:
    """Options of :func:`match_block` (defaults suit 60-80 % / 20-60 % overlap blocks)."""

    intermediate_px: int = 1100
    points_per_image: int = 5000
    search_px: float = 30.0
    ncc_min: float = 0.7
    half: int = 10
    corr_min: float = 0.8
    max_twofold_per_pair: int = 60
    min_points_per_image: int = 1000
    scheduler: str | None = None
    workers: int | None = None
    interior_model: str = "affine"
    subblock: int | None = None


@dataclass
class MatchReport:
    """What :func:`match_block` did."""

    level: int
    images: int
    pairs: int
    pairs_failed: list[tuple[int, int, str]]
    points: int
    observations: int
    multiplicity: dict[int, int]
    rejected: dict[str, int] = field(default_factory=dict)
    flagged_interior: list[int] = field(default_factory=list)
    gaps: dict[tuple[int, int], list[int]] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    guided: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    #: median over the image pairs of the RMS distance (full-resolution pixels) of the
    #: accepted measurements from their epipolar lines: the relative orientations' residual
    epipolar_rms_px: float | None = None


# --- tasks (module level: they run in worker processes) ---------------------------------


def _task_pyramid(image: str, pyramid: str) -> str:
    return str(build_pyramid(image, pyramid))


def _task_interior(pyramid: str, camera: dict, image: int, model: str) -> dict:
    from apygis.aerotri.interior import interior_orientation

    src = PyramidSource(pyramid)
    try:
        res = interior_orientation(src, Camera.from_dict(camera), model=model, name=str(image))
    finally:
        src.close()
    return res.to_dict()


def _task_features(pyramid: str, level: int, n: int) -> np.ndarray:
    src = PyramidSource(pyramid)
    try:
        h, w = src.shape(level)
        img = src.read(level, 0, 0, w, h)
    finally:
        src.close()
    grid = max(1, round(math.sqrt(n / 60)))
    pts = foerstner(img, max_points=n, grid=grid, w_factor=0.5, radius=3)
    return pts.xy.astype(np.float32)


def _task_pair(
    pyr_a: str,
    pyr_b: str,
    level: int,
    xy_a: np.ndarray,
    xy_b: np.ndarray,
    predict: np.ndarray | None,
    kind: str,
    t_a: list[float],
    t_b: list[float],
    focal_mm: float,
    options: MatchOptions,
) -> dict:
    from apygis.aerotri.fbm import match_pair

    sa, sb = PyramidSource(pyr_a), PyramidSource(pyr_b)
    try:
        ha, wa = sa.shape(level)
        hb, wb = sb.shape(level)
        img_a, img_b = sa.read(level, 0, 0, wa, ha), sb.read(level, 0, 0, wb, hb)
    finally:
        sa.close()
        sb.close()
    Ta = _level_transform(PixelTransform.from_list(t_a), level)
    Tb = _level_transform(PixelTransform.from_list(t_b), level)
    one_a, one_b = np.ones(len(xy_a)), np.ones(len(xy_b))
    m = match_pair(
        img_a,
        img_b,
        InterestPoints(np.asarray(xy_a, float), one_a, one_a),
        InterestPoints(np.asarray(xy_b, float), one_b, one_b),
        predict=predict,
        search_px=options.search_px,
        kind=kind,
        photo_a=Ta.to_mm,
        photo_b=Tb.to_mm,
        focal_mm=focal_mm,
        ncc_min=options.ncc_min,
    )
    return {
        "idx_a": np.asarray(m.idx_a, int),
        "idx_b": np.asarray(m.idx_b, int),
        "ncc": np.asarray(m.ncc, float),
        "sigma_px": float(m.sigma_px) if np.isfinite(m.sigma_px) else None,
        "reason": m.reason,
        "predicted_by": m.predicted_by,
    }


def _task_refs(pyramid: str, level: int, xy_level: np.ndarray) -> np.ndarray:
    """Förstner's strongest full-resolution point in the window each level point covers."""
    src = PyramidSource(pyramid)
    try:
        out = level_to_full(xy_level, level)
        f = 2**level
        half = max(2, f)  # search +- one level pixel around the mapped point
        H, W = src.shape(0)
        tile = 512
        centre = np.rint(out).astype(int)
        keys = (centre[:, 1] // tile) * (W // tile + 1) + centre[:, 0] // tile
        for key in np.unique(keys):
            sel = np.nonzero(keys == key)[0]
            c0 = int(centre[sel, 0].min()) - half - 16
            r0 = int(centre[sel, 1].min()) - half - 16
            c1 = int(centre[sel, 0].max()) + half + 17
            r1 = int(centre[sel, 1].max()) + half + 17
            win = src.read(0, c0, r0, c1 - c0, r1 - r0)
            pts = foerstner(win, radius=2, border=6)
            if len(pts) == 0:
                continue
            pxy = pts.xy + np.array([c0, r0], dtype=float)
            d = np.abs(pxy[None, :, :] - out[sel, None, :]).max(axis=2)  # Chebyshev distance
            w = np.where(d <= half, pts.w[None, :], -np.inf)
            best = np.argmax(w, axis=1)
            okay = np.isfinite(w[np.arange(len(sel)), best])
            inside = (pxy[best, 0] >= 0) & (pxy[best, 0] <= W - 1) & (pxy[best, 1] >= 0)
            inside &= pxy[best, 1] <= H - 1
            okay &= inside
            out[sel[okay]] = pxy[best[okay]]
    finally:
        src.close()
    return out


def _task_track(
    pyr_ref: str,
    pyr_search: str,
    ref_xy0: np.ndarray,
    search_xy_level: np.ndarray,
    affine: np.ndarray,
    level: int,
    options: MatchOptions,
) -> dict:
    from apygis.aerotri.lsm import track

    ref, search = PyramidSource(pyr_ref), PyramidSource(pyr_search)
    try:
        res = track(
            ref,
            search,
            ref_xy0,
            search_xy_level,
            affine,
            start=level,
            half=options.half,
            corr_min=options.corr_min,
        )
    finally:
        ref.close()
        search.close()
    return {
        "xy": res.xy,
        "sigma": res.sigma,
        "corr": res.corr,
        "ok": res.ok,
        "reason": np.asarray(res.reason, int),
    }


# --- helpers ------------------------------------------------------------------------------


def _level_transform(T: PixelTransform, level: int) -> PixelTransform:
    """Pixel -> photo transform of a pyramid level: ``T L_k`` (``L_k`` = level_to_full)."""
    f = 2.0**level
    L = np.array([[f, 0.0, (f - 1) / 2], [0.0, f, (f - 1) / 2], [0.0, 0.0, 1.0]])
    return PixelTransform(T.matrix @ L)


def intermediate_level(source_shape: tuple[int, int], levels: int, max_px: int) -> int:
    """The first pyramid level whose long side is at most ``max_px``."""
    h, w = source_shape
    for k in range(levels):
        if max(-(-h // 2**k), -(-w // 2**k)) <= max_px:
            return k
    return levels - 1


def _x_azimuth(im, bplan) -> float:
    """The azimuth of an image's photo x axis: as matched, else the flight direction."""
    return bplan.headings[im.image] if im.x_azimuth_deg is None else im.x_azimuth_deg


def _approx_eo(X: float, Y: float, Z: float, heading_deg: float) -> ExteriorOrientation:
    return ExteriorOrientation(X, Y, Z, 0.0, 0.0, math.radians(90.0 - heading_deg))


def _homography_fit(xa: np.ndarray, xb: np.ndarray) -> np.ndarray | None:
    import cv2

    if len(xa) < 8:
        return None
    H, _ = cv2.findHomography(xa.astype(np.float64), xb.astype(np.float64), cv2.LMEDS)
    return None if H is None else H / H[2, 2]


def _jacobian(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """The 2 x 2 derivative of the homography ``H`` at the points ``xy`` (n x 2)."""
    x, y = xy[:, 0], xy[:, 1]
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    u = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w
    v = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
    J = np.empty((len(xy), 2, 2))
    J[:, 0, 0] = (H[0, 0] - u * H[2, 0]) / w
    J[:, 0, 1] = (H[0, 1] - u * H[2, 1]) / w
    J[:, 1, 0] = (H[1, 0] - v * H[2, 0]) / w
    J[:, 1, 1] = (H[1, 1] - v * H[2, 1]) / w
    return J


#: Gross-error test of the point tracking: a measurement whose Sampson distance to the
#: epipolar line exceeds EPIPOLAR_K robust standard deviations (and EPIPOLAR_MIN_PX) is rejected.
EPIPOLAR_K = 5.0
EPIPOLAR_MIN_PX = 0.3


def _refined(E: np.ndarray, ur: np.ndarray, us: np.ndarray, threshold: float) -> np.ndarray:
    """``E`` refined by least squares (5 parameters, Sampson distances) over the rays within
    ``threshold`` (normalised units) of their epipolar lines."""
    import cv2

    from apygis.aerotri.fbm import refine_essential

    line = ur @ E.T
    d = np.abs(np.einsum("ij,ij->i", us, line)) / np.hypot(line[:, 0], line[:, 1])
    inl = d <= threshold
    if inl.sum() < 8:
        return E
    _, R, t, _ = cv2.recoverPose(E, ur[inl, :2], us[inl, :2], np.eye(3))
    return refine_essential(R, t.ravel(), ur[inl], us[inl])


#: The median of a chi-square variable with one degree of freedom.
_CHI2_1_MEDIAN = 0.4549364231195724


def _extra_variance(z: np.ndarray, var: np.ndarray) -> float:
    """The variance ``s2`` to add to ``var`` so that ``median(z^2 / (var + s2))`` is the
    median of a chi-square with one degree of freedom (0 if the spread is not larger)."""
    r = z * z
    if np.median(r / var) <= _CHI2_1_MEDIAN:
        return 0.0
    lo, hi = 0.0, float(np.max(r))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if np.median(r / (var + mid)) > _CHI2_1_MEDIAN:
            lo = mid
        else:
            hi = mid
    return hi


def _epipolar_check(
    cam: Camera, mm_ref: np.ndarray, mm_search: np.ndarray, ok, pixel_mm: float, sigma
) -> tuple[np.ndarray, float, float]:
    """The measurements consistent with the pair's relative orientation, and the variance
    (px^2) that the measurements' own sigmas lack.

    The rays ``u = (-(x - x0) / c, -(y - y0) / c, 1)`` (photo coordinates
    corrected for the camera's radial distortion) of the reference and search
    measurements satisfy ``u_s^T E u_r = 0`` for the pair's essential matrix
    ``E``, found by RANSAC (five-point) over the measurements that converged and
    refined by least squares on its inliers (five parameters, Sampson distances;
    a linear eight-point fit would be degenerate for the nearly flat scenes of
    aerial photos). The signed distance ``z`` of each search
    measurement from its epipolar line (pixels) is the part of its error that the
    relative orientation sees. A measurement is rejected when
    ``|z| > max(EPIPOLAR_K * s, EPIPOLAR_MIN_PX)``, ``s`` the robust (MAD)
    standard deviation of ``z``. Errors along the epipolar line are left to the
    local test.

    Variance component: if the accepted ``z`` spread more than the LSM sigmas
    say (image noise is not the only error: resampling, texture the affine model
    does not follow), the extra variance ``s2`` solves
    ``median(z^2 / (sigma^2 + s2)) = chi2_1 median``, and the caller reports
    ``sqrt(sigma^2 + s2)``: precisions that match the errors. Fewer than 15
    measurements are neither tested nor used for ``s2``.
    """
    import cv2

    ok = np.asarray(ok, bool)
    out = ok.copy()
    if ok.sum() < 15:
        return out, 0.0, float("nan")
    c = cam.focal_mm

    def rays(mm):
        v = (cam.undistort(mm) - (cam.x0_mm, cam.y0_mm)) / -c
        return np.column_stack([v, np.ones(len(v))])

    ur, us = rays(mm_ref), rays(mm_search)
    scale = c / pixel_mm  # normalised units -> pixels
    E, _ = cv2.findEssentialMat(
        ur[ok, :2], us[ok, :2], focal=1.0, pp=(0.0, 0.0), method=cv2.RANSAC, prob=0.999,
        threshold=1.0 / scale,
    )  # fmt: skip
    if E is None or E.shape != (3, 3):
        return out, 0.0, float("nan")
    E = _refined(E, ur[ok], us[ok], 3.0 / scale)

    def distances(E):
        line = ur @ E.T  # epipolar lines E u_r in the search image
        return np.einsum("ij,ij->i", us, line) / np.hypot(line[:, 0], line[:, 1]) * scale

    z = distances(E)
    robust = 1.4826 * np.median(np.abs(z[ok] - np.median(z[ok])))
    out = ok & (np.abs(z) <= max(EPIPOLAR_K * robust, EPIPOLAR_MIN_PX))
    if out.sum() < 15:
        return out, 0.0, float(robust)
    rms = float(np.sqrt(np.mean(z[out] ** 2)))
    var = np.asarray(sigma, float)[out] ** 2
    good = np.isfinite(var) & (var > 0)
    if good.sum() < 15:
        return out, 0.0, rms
    return out, _extra_variance(z[out][good], var[good]), rms


#: Local test: a measurement farther than LOCAL_K robust standard deviations (and
#: LOCAL_MIN_PX) from the affine map of its LOCAL_NEIGHBOURS nearest neighbours is rejected.
LOCAL_K = 6.0
LOCAL_MIN_PX = 1.0
LOCAL_NEIGHBOURS = 10


def _local_check(ref_xy: np.ndarray, xy: np.ndarray, ok) -> np.ndarray:
    """Measurements that agree with their neighbours (bool per measurement).

    For each measurement, the affine map reference -> search image of its
    ``LOCAL_NEIGHBOURS`` nearest neighbours (in the reference image) predicts
    its position; the terrain is smooth at the neighbours' spacing, so a
    measurement far off the prediction (by more than ``LOCAL_K`` robust standard
    deviations of all such residuals, and at least ``LOCAL_MIN_PX``) is a wrong
    match, typically one along the epipolar line that the relative orientation
    cannot see (repetitive texture).
    """
    from scipy.spatial import cKDTree

    ok = np.asarray(ok, bool)
    out = ok.copy()
    idx = np.nonzero(ok)[0]
    k = LOCAL_NEIGHBOURS
    if len(idx) <= k + 3:
        return out
    r, q = ref_xy[idx], xy[idx]
    _, nb = cKDTree(r).query(r, k + 1)
    nb = nb[:, 1:]
    centre = r[nb].mean(axis=1, keepdims=True)
    X = np.concatenate([r[nb] - centre, np.ones((len(idx), k, 1))], axis=2)  # (m, k, 3)
    Y = q[nb]  # (m, k, 2)
    XtX = np.einsum("mki,mkj->mij", X, X) + 1e-9 * np.eye(3)
    XtY = np.einsum("mki,mkj->mij", X, Y)
    coef = np.linalg.solve(XtX, XtY)  # (m, 3, 2)
    x0 = np.concatenate([r - centre[:, 0], np.ones((len(idx), 1))], axis=1)
    pred = np.einsum("mi,mij->mj", x0, coef)
    d = np.hypot(*(q - pred).T)
    robust = 1.4826 * np.median(d)
    out[idx] = d <= max(LOCAL_K * robust, LOCAL_MIN_PX)
    return out


def _local_affines(tree, src: np.ndarray, dst: np.ndarray, at: np.ndarray):
    """Local affine maps src -> dst at the points ``at`` from their nearest correspondences.

    Returns ``(A (n, 2, 2), predicted (n, 2), reach (n,))``: the linear part, the
    mapped points, and the distance to the farthest neighbour used (how far the
    prediction extrapolates).
    """
    k = LOCAL_NEIGHBOURS
    dist, nb = tree.query(at, k)
    centre = src[nb].mean(axis=1, keepdims=True)
    X = np.concatenate([src[nb] - centre, np.ones((len(at), k, 1))], axis=2)
    XtX = np.einsum("mki,mkj->mij", X, X) + 1e-6 * np.eye(3)
    coef = np.linalg.solve(XtX, np.einsum("mki,mkj->mij", X, dst[nb]))  # (n, 3, 2)
    x0 = np.concatenate([at - centre[:, 0], np.ones((len(at), 1))], axis=1)
    pred = np.einsum("mi,mij->mj", x0, coef)
    A = np.transpose(coef[:, :2, :], (0, 2, 1))
    return A, pred, dist[:, -1]


def _spread_pick(xy: np.ndarray, n: int, cell: float, *, ordered: bool = False) -> np.ndarray:
    """Indices of at most ``n`` points, spread: one per grid cell first, then the rest.

    ``ordered``: return them in that order (a prefix of any length is spread),
    otherwise sorted. The choice within a round is pseudo-random with a fixed seed.
    """
    m = len(xy)
    if m == 0:
        return np.arange(0)
    key = np.floor(np.asarray(xy) / cell).astype(np.int64)
    cells = key[:, 0] * 1_000_003 + key[:, 1]
    rng = np.random.default_rng(0)
    perm = rng.permutation(m)
    # the rank of each point within its cell (in random order): round 0 takes one per cell
    c = cells[perm]
    srt = np.argsort(c, kind="stable")
    starts = np.searchsorted(c[srt], c[srt], side="left")
    rank = np.empty(m, dtype=np.int64)
    rank[srt] = np.arange(m) - starts
    out = perm[np.lexsort((np.arange(m), rank))][:n]
    return out if ordered else np.sort(out)


# --- the pipeline -------------------------------------------------------------------------


def match_block(
    block: Block, options: MatchOptions | None = None, *, progress=None, terrain_z=None
) -> MatchReport:
    """Measure tie points in a block (module docstring); returns a report.

    ``progress(done, total)`` (:mod:`apygis.progress`) runs once over the whole
    pipeline, its stages (pyramids, interior orientation, interest points, pairs,
    tracking) as equal parts.
    """
    from apygis.progress import STEPS, phase

    opt = options or MatchOptions()
    images = {im.image: im for im in block.images()}
    if not images:
        raise BlockError(f"{block.path}: the block has no images")
    cams = block.cameras()
    bplan = block_plan(block, terrain_z=terrain_z)
    if not bplan.pairs:
        raise BlockError(f"{block.path}: the plan has no overlapping image pairs")
    block.set_pairs((p.a, p.b, p.kind, p.overlap) for p in bplan.pairs)
    todo_plan = bplan
    work = images
    if opt.subblock is not None:
        subblocks = block.subblocks() or bplan.subblocks
        if not 1 <= opt.subblock <= len(subblocks):
            raise BlockError(
                f"{block.path}: subblock {opt.subblock} does not exist "
                f"(the plan has {len(subblocks)}; 'apygis at plan --subblock-strips N' makes them)"
            )
        strips = set(subblocks[opt.subblock - 1])
        work = {n: im for n, im in images.items() if bplan_strip(bplan, n) in strips}
        todo_plan = dataclasses.replace(
            bplan, pairs=[p for p in bplan.pairs if p.a in work and p.b in work]
        )
    tz = terrain_height(block, terrain_z)
    run = block.start_run("match", {k: v for k, v in vars(opt).items()})
    steps = 5

    def stage(i: int):
        return phase(progress, i, steps) if progress is not None else None

    seconds: dict[str, float] = {}
    clock = [time.perf_counter()]

    def lap(name: str) -> None:
        now = time.perf_counter()
        seconds[name] = round(now - clock[0], 3)
        clock[0] = now

    try:
        with Runner(opt.scheduler, opt.workers) as runner:
            lap("start")
            pyr = _stage_pyramids(block, work, runner, stage(0))
            lap("pyramids")
            transforms, flagged = _stage_interior(block, work, cams, pyr, runner, stage(1), opt)
            lap("interior")
            src0 = PyramidSource(next(iter(pyr.values())))
            level = intermediate_level(src0.shape(0), src0.levels, opt.intermediate_px)
            src0.close()
            feats = _stage_features(block, work, pyr, level, opt, runner, stage(2))
            lap("features")
            failed = _stage_pairs(
                block, todo_plan, work, cams, pyr, transforms, feats, level, tz, opt, runner,
                stage(3),
            )  # fmt: skip
            lap("pairs")
            # tracking joins everything matched so far (other subblocks through their
            # common strips): the images already prepared by earlier runs take part
            pyr, transforms, feats = _prepared(block, images, level)
            notes = _stage_azimuths(block, bplan, transforms, feats, level)
            images = {im.image: im for im in block.images() if im.image in feats}
            bplan = block_plan(block, terrain_z=terrain_z)
            report = _stage_tracking(
                block, bplan, images, pyr, transforms, feats, level, opt, runner, stage(4)
            )
            lap("tracking")
        report.pairs_failed = failed
        report.flagged_interior = flagged
        report.notes = notes
        report.gaps = _stage_gaps(block, bplan, images, tz)
        lap("gaps")
        report.seconds = seconds
        if progress is not None:
            progress(STEPS, STEPS)
    except BaseException as exc:
        block.finish_run(run, "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed",
                         {"error": str(exc)})  # fmt: skip
        raise
    block.finish_run(
        run,
        "done",
        {
            "points": report.points,
            "observations": report.observations,
            "level": level,
            "epipolar_rms_px": report.epipolar_rms_px,
        },
    )
    return report


def bplan_strip(bplan, image: int) -> int:
    """The strip of an image in a plan."""
    return int(bplan.images[image].strip)


def _prepared(block: Block, images, level: int):
    """Pyramid paths, pixel transforms and level-``level`` features of every image that an
    earlier stage (of this run or an earlier one) prepared."""
    interior = block.interior()
    pyr, transforms, feats = {}, {}, {}
    for n in images:
        xy = block.features(n, level)
        path = block.pyramid_folder / f"{n}.tif"
        if xy is None or n not in interior or not path.is_file():
            continue
        pyr[n] = str(path)
        transforms[n] = PixelTransform.from_list(interior[n]["transform"])
        feats[n] = xy
    return pyr, transforms, feats


def _stage_pyramids(block: Block, images, runner: Runner, progress) -> dict[int, str]:
    folder = block.pyramid_folder
    out = {n: str(folder / f"{n}.tif") for n in images}
    todo = [
        (n, (str(im.path), out[n]))
        for n, im in images.items()
        if not (block.task_done("pyramid", str(n)) and Path(out[n]).is_file())
    ]
    for k, (n, _) in enumerate(runner.run(_task_pyramid, todo), 1):
        block.mark_task("pyramid", str(n))
        if progress is not None:
            progress(k, len(todo))
    return out


def _stage_interior(block: Block, images, cams, pyr, runner: Runner, progress, opt):
    done = block.interior()
    todo = []
    for n, im in images.items():
        cam = cams[im.camera]
        if n in done:
            continue
        if cam.kind == "digital":
            T = PixelTransform.digital(im.width, im.height, float(cam.pixel_um or 0))
            block.set_interior(
                n,
                {"model": "digital", "transform": T.to_list(), "rms_um": None, "max_um": None,
                 "flagged": False},
            )  # fmt: skip
        else:
            todo.append((n, (pyr[n], cam.to_dict(), n, opt.interior_model)))
    for k, (n, res) in enumerate(runner.run(_task_interior, todo), 1):
        block.set_interior(int(n), res)
        if progress is not None:
            progress(k, len(todo))
    interior = block.interior()
    transforms = {n: PixelTransform.from_list(interior[n]["transform"]) for n in images}
    flagged = sorted(n for n in images if interior[n].get("flagged"))
    return transforms, flagged


def _stage_features(block: Block, images, pyr, level: int, opt: MatchOptions, runner, progress):
    feats: dict[int, np.ndarray] = {}
    todo = []
    for n in images:
        xy = block.features(n, level)
        if xy is None:
            todo.append((n, (pyr[n], level, opt.points_per_image)))
        else:
            feats[n] = xy
    for k, (n, xy) in enumerate(runner.run(_task_features, todo), 1):
        block.set_features(int(n), level, xy)
        feats[int(n)] = np.asarray(xy, float)
        if progress is not None:
            progress(k, len(todo))
    return feats


#: Least overlap for which a cross-strip pair is checked by a relative orientation (as the
#: pairs of a strip) rather than a homography, which relief bends.
RO_MIN_OVERLAP = 0.2


def _model_kind(p) -> str:
    """The outlier model of a pair for :func:`apygis.aerotri.fbm.match_pair`."""
    return "strip" if p.kind == "strip" or p.overlap >= RO_MIN_OVERLAP else "cross"


def _stage_pairs(
    block, bplan, images, cams, pyr, transforms, feats, level, tz, opt, runner, progress
):
    from apygis.aerotri.fbm import homography_from_orientations

    status = {(p["a"], p["b"]): p["status"] for p in block.pairs()}
    todo = []
    for p in bplan.pairs:
        if status.get((p.a, p.b)) in ("matched", "failed"):
            continue
        ia, ib = images[p.a], images[p.b]
        cam = cams[ia.camera]
        predict = None
        try:
            predict = homography_from_orientations(
                _approx_eo(ia.X, ia.Y, ia.Z, _x_azimuth(ia, bplan)),
                _approx_eo(ib.X, ib.Y, ib.Z, _x_azimuth(ib, bplan)),
                cam.focal_mm,
                transforms[p.a],
                transforms[p.b],
                tz,
                level=level,
                principal_point_mm=(cam.x0_mm, cam.y0_mm),
            )
        except OrientationError:
            predict = None
        todo.append(
            (
                (p.a, p.b),
                (pyr[p.a], pyr[p.b], level, feats[p.a], feats[p.b], predict, _model_kind(p),
                 transforms[p.a].to_list(), transforms[p.b].to_list(), cam.focal_mm, opt),
            )
        )  # fmt: skip
    for k, (key, res) in enumerate(runner.run(_task_pair, todo), 1):
        a, b = key
        st = "matched" if len(res["idx_a"]) else "failed"
        block.set_pair_matches(a, b, res["idx_a"], res["idx_b"], st, res["sigma_px"], res["reason"])
        if progress is not None:
            progress(k, len(todo))
    return [(p["a"], p["b"], p["reason"]) for p in block.pairs() if p["status"] == "failed"]


#: Photo x axes turned by more than this from the flight direction are reported.
AZIMUTH_NOTE_DEG = 20.0


def _stage_azimuths(block: Block, bplan, transforms, feats, level: int) -> list[str]:
    """The azimuth of each image's photo x axis, from the matches of its strip neighbours.

    Between consecutive images ``a``, ``b`` of a strip (``b`` later along the
    flight) the ground moves backwards through the frame. The pair's similarity
    ``p_b = R p_a + t`` is fitted (RANSAC over the block-formation matches) in
    photo coordinates, each image's matches mapped through its own interior
    orientation (so that scans turned or mirrored differently agree): the ground
    under a's principal point appears in b at ``t``, so ``s = t`` points against
    the flight in b's frame, and ``s = R^-1 t`` in a's. The flight direction
    makes the angle ``theta = atan2(-s_y, -s_x)`` with the photo x axis
    (counter-clockwise), so the x axis has the azimuth ``heading + theta``
    (degrees clockwise from north; 0 when the photo x axis points along the
    flight, as film cameras fly). Each image takes the circular mean over its
    strip pairs; images without a matched strip neighbour keep the flight
    direction. Stored as ``x_azimuth_deg``.
    """
    import cv2

    estimates: dict[int, list[float]] = {}
    matches = {(a, b): (ia, ib) for a, b, ia, ib in block.pair_matches()}
    for strip in bplan.strips.values():
        for a, b in zip(strip.images, strip.images[1:], strict=False):
            key = (min(a, b), max(a, b))
            if key not in matches or len(matches[key][0]) < 8:
                continue
            ia, ib = matches[key]
            pa, pb = feats[key[0]][ia], feats[key[1]][ib]
            if key[0] != a:
                pa, pb = pb, pa
            # photo millimetres: a mirrored or turned scan is undone by its interior orientation
            ma = transforms[a].to_mm(level_to_full(pa, level)).astype(np.float32)
            mb = transforms[b].to_mm(level_to_full(pb, level)).astype(np.float32)
            M, _ = cv2.estimateAffinePartial2D(
                ma,
                mb,
                method=cv2.RANSAC,
                ransacReprojThreshold=3 * 2**level * transforms[a].pixel_mm,
            )
            if M is None:
                continue
            R, t = M[:, :2], M[:, 2]
            if abs(np.linalg.det(R)) < 1e-12:
                continue
            for img, s_mm in ((b, t), (a, np.linalg.solve(R, t))):
                theta = math.degrees(math.atan2(-s_mm[1], -s_mm[0]))
                estimates.setdefault(img, []).append(bplan.headings[img] + theta)
    values: dict[int, dict] = {}
    turned = []
    for img, est in estimates.items():
        r = np.radians(est)
        az = math.degrees(math.atan2(np.mean(np.sin(r)), np.mean(np.cos(r)))) % 360.0
        values[img] = {"x_azimuth_deg": az}
        off = (az - bplan.headings[img] + 180.0) % 360.0 - 180.0
        if abs(off) > AZIMUTH_NOTE_DEG:
            turned.append((img, off))
    block.update_images(values)
    notes = []
    if turned:
        offs = sorted({round(o / 5) * 5 for _, o in turned})
        notes.append(
            f"{len(turned)} images have their photo x axis turned against the flight "
            f"direction (by about {', '.join(f'{o:+.0f}' for o in offs)} degrees: a camera "
            "yawed against its course); their approximate orientations are corrected"
        )
    return notes


def _stage_tracking(block, bplan, images, pyr, transforms, feats, level, opt, runner, progress):
    cams = block.cameras()
    from scipy.spatial import cKDTree

    from apygis.aerotri.lsm import LsmReason
    from apygis.aerotri.tracks import link

    matches = block.pair_matches()
    tracks = link([(a, b, ia, ib) for a, b, ia, ib in matches if len(ia)])
    mult = tracks.multiplicity
    # two-fold tracks: a spread selection (guided measurement may add images to them; the
    # final two-fold points are chosen after tracking)
    keep = mult >= 3
    two = np.nonzero(mult == 2)[0]
    if len(two):
        first = tracks.offsets[two]
        ia = np.array([tracks.images[i] for i in tracks.image[first]])
        ib = np.array([tracks.images[i] for i in tracks.image[first + 1]])
        for a, b in set(zip(ia.tolist(), ib.tolist(), strict=True)):
            sel = two[(ia == a) & (ib == b)]
            xy = feats[a][tracks.point[tracks.offsets[sel]]]
            h, w = PyramidSource(pyr[a]).shape(level)
            pick = _spread_pick(xy, 5 * opt.max_twofold_per_pair, max(h, w) / 25)
            keep[sel[pick]] = True
    kept = np.nonzero(keep)[0]
    # reference image of each point: the one where it lies closest to the image centre
    nodes: list[list[tuple[int, int]]] = [
        [(int(i), int(p)) for i, p in tracks[int(t)]]  # type: ignore[call-overload]
        for t in kept
    ]
    ref_of: list[tuple[int, int]] = []
    for nd in nodes:
        best, bd = nd[0], np.inf
        for img, pi in nd:
            h, w = images[img].height / 2**level, images[img].width / 2**level
            x, y = feats[img][pi]
            d = (x / w - 0.5) ** 2 + (y / h - 0.5) ** 2
            if d < bd:
                best, bd = (img, pi), d
        ref_of.append(best)
    # refine reference points at full resolution (Förstner again), per image
    by_ref: dict[int, list[int]] = {}
    for t, (img, _) in enumerate(ref_of):
        by_ref.setdefault(img, []).append(t)
    todo = [
        (img, (pyr[img], level, feats[img][[ref_of[t][1] for t in ts]]))
        for img, ts in by_ref.items()
    ]
    ref_xy0 = np.zeros((len(nodes), 2))
    for img, xy0 in runner.run(_task_refs, todo):
        ref_xy0[by_ref[int(img)]] = xy0
    # correspondences (level L) of every ordered image pair that shares linked points
    corr: dict[tuple[int, int], tuple[list[int], list[int]]] = {}
    for nd in nodes:
        for i1, p1 in nd:
            for i2, p2 in nd:
                if i1 != i2:
                    c1, c2 = corr.setdefault((i1, i2), ([], []))
                    c1.append(p1)
                    c2.append(p2)
    corr_xy = {
        k: (feats[k[0]][np.array(c1)], feats[k[1]][np.array(c2)]) for k, (c1, c2) in corr.items()
    }
    trees = {k: cKDTree(v[0]) for k, v in corr_xy.items() if len(v[0]) >= LOCAL_NEIGHBOURS}
    neighbours: dict[int, set[int]] = {n: set() for n in images}
    for p in bplan.pairs:
        if p.a in neighbours and p.b in neighbours:
            neighbours[p.a].add(p.b)
            neighbours[p.b].add(p.a)
    # measurements to make: the linked images of each point (block formation), and the
    # neighbouring images of its reference image that should see it too (guided)
    ref_L_all = full_to_level(ref_xy0, level)
    items: dict[tuple[int, int], list[tuple[int, int]]] = {}  # (ref, img) -> [(t, node or -1)]
    for t, nd in enumerate(nodes):
        r_img = ref_of[t][0]
        have = {img for img, _ in nd}
        for img, pi in nd:
            if img != r_img:
                items.setdefault((r_img, img), []).append((t, pi))
        for img in neighbours[r_img] - have:
            if (r_img, img) in trees:
                items.setdefault((r_img, img), []).append((t, -1))
    tasks = []
    index: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for (r_img, img), its in items.items():
        ts = np.array([t for t, _ in its])
        pis = np.array([p for _, p in its])
        ref_L = ref_L_all[ts]
        h, w = images[img].height / 2**level, images[img].width / 2**level
        if (r_img, img) in trees:
            src, dst = corr_xy[(r_img, img)]
            A, pred, reach = _local_affines(trees[(r_img, img)], src, dst, ref_L)
        else:
            A, pred, reach = np.tile(np.eye(2), (len(ts), 1, 1)), ref_L.copy(), np.zeros(len(ts))
        fbm = pis >= 0
        start = pred.copy()
        ref_feat = feats[r_img][[ref_of[t][1] for t in ts]]
        start[fbm] = feats[img][pis[fbm]] + np.einsum(
            "nij,nj->ni", A[fbm], ref_L[fbm] - ref_feat[fbm]
        )
        # a guided point must lie inside the other image and near known correspondences
        margin = opt.half + 3
        inside = (start[:, 0] >= margin) & (start[:, 0] <= w - 1 - margin)
        inside &= (start[:, 1] >= margin) & (start[:, 1] <= h - 1 - margin)
        keep = fbm | (inside & (reach <= max(h, w) / 6))
        if not keep.any():
            continue
        ts, pis, start, A = ts[keep], pis[keep], start[keep], A[keep]
        index[(r_img, img)] = (ts, pis, start)
        tasks.append(((r_img, img), (pyr[r_img], pyr[img], ref_xy0[ts], start, A, level, opt)))
    results: dict[tuple[int, int], dict] = {}
    for k, (key, res) in enumerate(runner.run(_task_track, tasks), 1):
        results[key] = res
        if progress is not None:
            progress(k, len(tasks))
    # assemble observations
    jump = 2.0**level * 2.0
    rejected = {"jumped": 0, "epipolar": 0, "local": 0, "fewer than 2 images": 0}
    guided = {"tried": 0, "measured": 0}
    epipolar: list[float] = []
    obs: dict[int, list[tuple[int, float, float, float, float]]] = {
        t: [] for t in range(len(nodes))
    }
    for (r_img, img), (ts, pis, start) in index.items():
        res = results[(r_img, img)]
        cam = cams[images[img].camera]
        xy = np.where(np.isfinite(res["xy"]), res["xy"], 0.0)
        epi_ok, extra, epi_rms = _epipolar_check(
            cam,
            transforms[r_img].to_mm(ref_xy0[ts]),
            transforms[img].to_mm(xy),
            res["ok"],
            transforms[img].pixel_mm,
            res["sigma"],
        )
        sigma = np.sqrt(np.asarray(res["sigma"], float) ** 2 + extra)
        if np.isfinite(epi_rms):
            epipolar.append(epi_rms)
        local_ok = _local_check(ref_xy0[ts], res["xy"], res["ok"])
        near = np.abs(xy - level_to_full(start, level)).max(axis=1) <= jump
        for j, t in enumerate(ts):
            is_guided = pis[j] < 0
            guided["tried"] += int(is_guided)
            why = ""
            if not res["ok"][j]:
                why = "lsm: " + LsmReason(int(res["reason"][j])).name.lower().replace("_", " ")
            elif not near[j]:
                why = "jumped"
            elif not epi_ok[j]:
                why = "epipolar"
            elif not local_ok[j]:
                why = "local"
            if why:
                if not is_guided:
                    rejected[why] = rejected.get(why, 0) + 1
                continue
            guided["measured"] += int(is_guided)
            obs[int(t)].append((img, float(xy[j][0]), float(xy[j][1]),
                                float(sigma[j]), float(res["corr"][j])))  # fmt: skip
    _select_twofold(obs, ref_of, ref_xy0, images, opt, rejected)
    good = [t for t in range(len(nodes)) if len(obs[t]) >= 1]
    rejected["fewer than 2 images"] = len(nodes) - len(good)
    names = block.tie_names(len(good))
    rows_pts = [
        {"name": nm, "kind": "tie", "ref_image": ref_of[t][0]}
        for nm, t in zip(names, good, strict=True)
    ]
    with block.conn:
        block.conn.execute("DELETE FROM points WHERE kind = 'tie'")
    ids = block.add_points(rows_pts)
    rows = []
    mult_table: dict[int, int] = {}
    for nm, t in zip(names, good, strict=True):
        pid = ids[nm]
        r_img = ref_of[t][0]
        sig = [o[3] for o in obs[t]]
        allobs = [(r_img, float(ref_xy0[t][0]), float(ref_xy0[t][1]), float(np.median(sig)), 1.0)]
        allobs += obs[t]
        mult_table[len(allobs)] = mult_table.get(len(allobs), 0) + 1
        for img, x, y, s, c in allobs:
            mm = transforms[img].to_mm([[x, y]])[0]
            src = "lsm-ref" if img == r_img else "lsm"
            rows.append((pid, img, x, y, float(mm[0]), float(mm[1]), s, c, src))
    with block.conn:
        block.conn.executemany("INSERT INTO observations VALUES (?,?,?,?,?,?,?,?,?)", rows)
    return MatchReport(
        level=level,
        images=len(images),
        pairs=len(bplan.pairs),
        pairs_failed=[],
        points=len(good),
        observations=len(rows),
        multiplicity=dict(sorted(mult_table.items())),
        rejected=rejected,
        guided=guided,
        epipolar_rms_px=float(np.median(epipolar)) if epipolar else None,
    )


def _select_twofold(obs, ref_of, ref_xy0, images, opt: MatchOptions, rejected: dict) -> None:
    """Keep two-fold points selectively (the seed: "tracked only selectively").

    Each model keeps at most ``max_twofold_per_pair`` two-fold points, spread over
    it (one per cell of a 20 x 20 grid of the reference image first); an image
    that still has fewer than ``min_points_per_image`` observations then takes
    more two-fold points of its models, spread likewise, up to its deficit.
    The others are dropped (counted as "two-fold not needed").
    """
    twofold: dict[tuple[int, int], list[int]] = {}
    count: dict[int, int] = dict.fromkeys(images, 0)
    for t, o in obs.items():
        if len(o) == 1:
            twofold.setdefault((ref_of[t][0], o[0][0]), []).append(t)
        elif len(o) > 1:
            count[ref_of[t][0]] += 1
            for img, *_ in o:
                count[img] += 1
    order: dict[tuple[int, int], list[int]] = {}
    for (r_img, img), ts in twofold.items():
        cell = max(images[r_img].width, images[r_img].height) / 20
        pick = _spread_pick(ref_xy0[ts], len(ts), cell, ordered=True)
        order[(r_img, img)] = [ts[k] for k in pick]
    taken: dict[tuple[int, int], int] = {}
    for key, ts in order.items():
        taken[key] = min(len(ts), opt.max_twofold_per_pair)
        count[key[0]] += taken[key]
        count[key[1]] += taken[key]
    for n in sorted(images, key=lambda n: count[n]):
        deficit = opt.min_points_per_image - count[n]
        models = [k for k in order if n in k and taken[k] < len(order[k])]
        while deficit > 0 and models:
            for k in list(models):
                if taken[k] >= len(order[k]):
                    models.remove(k)
                    continue
                taken[k] += 1
                count[k[0]] += 1
                count[k[1]] += 1
                deficit -= 1
    for key, ts in order.items():
        for t in ts[taken[key] :]:
            obs[t] = []
            rejected["two-fold not needed"] = rejected.get("two-fold not needed", 0) + 1


def _stage_gaps(block: Block, bplan, images, tz: float) -> dict[tuple[int, int], list[int]]:
    """Von Gruber counts per model from the tie points seen in both images."""
    from apygis.orient.collinearity import InteriorOrientation, photo_to_ground

    cams = block.cameras()
    rows = block.conn.execute(
        "SELECT o.point, o.image, o.x_mm, o.y_mm FROM observations o "
        "JOIN points p ON p.id = o.point WHERE p.kind = 'tie'"
    ).fetchall()
    per_image: dict[int, dict[int, tuple[float, float]]] = {}
    for pid, img, x, y in rows:
        per_image.setdefault(img, {})[pid] = (x, y)
    gaps: dict[tuple[int, int], list[int]] = {}
    with block.conn:
        block.conn.execute("DELETE FROM gaps")
    matched = {(p["a"], p["b"]) for p in block.pairs() if p["status"] == "matched"}
    for p in bplan.pairs:
        a, b = p.a, p.b
        if (a, b) not in matched:
            continue
        common = sorted(set(per_image.get(a, {})) & set(per_image.get(b, {})))
        im = images[a]
        cam = cams[im.camera]
        io = InteriorOrientation(cam.focal_mm, cam.x0_mm, cam.y0_mm)
        eo = _approx_eo(im.X, im.Y, im.Z, _x_azimuth(im, bplan))
        if common:
            mm = np.array([per_image[a][c] for c in common])
            ground = photo_to_ground(mm, tz, eo, io)[:, :2]
        else:
            ground = np.empty((0, 2))
        rep = planning.gap_report(bplan, p, ground)
        with block.conn:
            block.conn.executemany(
                "INSERT INTO gaps VALUES (?, ?, ?, ?)",
                [(a, b, k, int(c)) for k, c in enumerate(rep.counts)],
            )
        if rep.gaps:
            gaps[(a, b)] = list(rep.gaps)
    return gaps
