"""The bundle block adjustment of a block (``apygis at adjust``).

PHODIS AT relied on external programs (PAT-B, BLUH); apygis adjusts itself
(:mod:`apygis.orient.bundle`) and also exchanges with them
(:mod:`apygis.aerotri.exchange`).

What goes in
------------
* **Image observations**: every measurement of the block (tie points from
  ``at match``, control and new points from ``at gcp``) in photo millimetres
  through the image's interior orientation, corrected for the camera's radial
  distortion table, weighted by its own precision: the LSM ``sigma_px`` with
  ``model_sigma_px`` added in quadrature (measurements without one get
  ``default_sigma_px``), times the image's pixel size. The LSM's covariance
  holds the image noise only; interpolation, the aliasing of sharp edges and
  the affine model's misfit add errors of 0.02-0.07 px whatever that
  covariance says (measured against the truth of synthetic blocks: tie points
  with a noise sigma of 0.015 px err by 0.02 px, control points at road
  crossings by 0.05 px with 0.015 px), hence the floor of 0.03 px.
* **Control points** as weighted observations of their coordinates: ``full``
  (X, Y, Z), ``planimetric`` (X, Y), ``height`` (Z), with the sigmas of the
  control file; ``check`` points are adjusted as tie points and compared with
  their given coordinates afterwards (the expected object rms there is the
  adjusted points' precision and the given coordinates' own sigmas together).
* **Projection centres** (GPS) as observations with sigmas: ``gps="auto"``
  uses them only when the control gives no datum (the positions of EXIF: 5 m
  in plan, 10 m in height; of an image list: 1 m and 2 m), ``gps=(sxy, sz)``
  always, ``gps=None`` never.
* **Self-calibration** (``calibrate``): fixed by default. A list of
  parameter names (:data:`~apygis.orient.bundle.CALIBRATION_PARAMETERS`) frees
  them; ``"auto"`` frees ``c, x0, y0, k1, k2, p1, p2`` (and ``b1, b2`` for
  film) and then fixes, one at a time, the one most correlated (``|r| >
  0.9``) with an orientation element or another calibration parameter, until
  the block determines all that remain.

Approximate values
------------------
From the last adjustment of the block where it covers every image; otherwise
from the block plan: the approximate projection centres of the image list
(or EXIF) with vertical photos (``omega = phi = 0``, ``kappa = 90 deg - az``
with ``az`` the azimuth of the photo x axis found by matching, or the flight
direction); images without an approximate centre are placed by a chain of
relative orientations (:func:`_chain`), scaled and placed on the control
by an absolute orientation. Points are intersected from those orientations.

Robust estimation
-----------------
:func:`apygis.orient.bundle.robust_adjust` (data snooping with a robust
variance factor, threshold ``threshold``); every rejection is stored with its
residual, test value and reason. ``robust=False`` adjusts all observations
once.

Subblocks
---------
``subblocks=True`` adjusts each subblock of the block plan as an independent
task (:class:`apygis.tasks.Runner`: local processes or a Dask cluster), each
on its own control or centres, then joins them: the subblocks' orientations
and points are the approximate values of one adjustment of the whole block,
tied through the common strips' points.

What comes out
--------------
Stored in the block (schema in ``docs/aerotri.md``): the run in
``adjustments`` (options and the report), the exterior orientations with
their standard deviations, the adjusted points with theirs, and every
observation's residual (pixels), test value and verdict. The report
(:class:`AdjustReport`) is the seed's Table 3 and more.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from apygis.aerotri.block import Block, BlockError
from apygis.aerotri.camera import Camera, PixelTransform
from apygis.errors import ConvergenceError, DegenerateGeometryError
from apygis.orient.bundle import (
    CALIBRATION_PARAMETERS,
    SNOOPING_THRESHOLD,
    BundleProblem,
    BundleSolution,
    Rejection,
    adjust,
    intersect_rays,
    robust_adjust,
)
from apygis.orient.rotation import rotation_matrix

__all__ = [
    "AdjustOptions",
    "AdjustReport",
    "adjust_block",
    "load_problem",
]

log = logging.getLogger(__name__)

#: Default sigmas (m, plan and height) of projection centres, by the source of the position.
GPS_SIGMAS = {"exif": (5.0, 10.0), "list": (1.0, 2.0)}

#: Parameters that ``calibrate="auto"`` frees (film cameras also b1, b2).
AUTO_CALIBRATION = ("c", "x0", "y0", "k1", "k2", "p1", "p2")

#: Calibration parameters correlated above this with another unknown are not determined.
CORRELATION_LIMIT = 0.9
#: ... and those whose change from the camera file is below this many sigmas not significant.
SIGNIFICANCE = 3.0


@dataclass
class AdjustOptions:
    """Options of :func:`adjust_block` (module docstring)."""

    robust: bool = True
    threshold: float = SNOOPING_THRESHOLD
    calibrate: tuple[str, ...] | str = ()
    gps: tuple[float, float] | str | None = "auto"
    model_sigma_px: float = 0.03
    default_sigma_px: float = 0.3
    max_iter: int = 30
    restart: bool = False
    subblocks: bool = False
    scheduler: str | None = None
    workers: int | None = None

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(self).items()}


@dataclass
class Loaded:
    """A block's adjustment problem and the names behind its indices."""

    problem: BundleProblem
    images: list[int]  # image numbers, in the problem's order
    point_ids: list[int]  # point ids (database), in the problem's order
    point_names: list[str]
    point_kinds: list[str]
    cameras: list[int]  # camera ids, in the problem's order
    transforms: list[PixelTransform]  # per image
    check: list[int]  # problem indices of check points
    check_xyz: np.ndarray  # their given coordinates
    check_sigma: np.ndarray  # and those coordinates' own sigmas
    control_index: list[int]  # problem point index of each control entry
    gps_used: bool
    notes: list[str] = field(default_factory=list)
    sigma_ref_mm: float = 0.0  # median a priori sigma of the image observations
    groups: np.ndarray | None = None  # observation kind (index into group_names)
    group_names: list[str] = field(default_factory=list)
    block_cameras: list[Camera] = field(default_factory=list)  # in the problem's order
    calibration0: np.ndarray = field(default_factory=lambda: np.zeros((0, 10)))  # the files'


@dataclass
class AdjustReport:
    """What :func:`adjust_block` did: the seed's Table 3 and more (``to_dict`` for JSON)."""

    adjustment: int
    images: int
    cameras: int
    control: dict[str, int]
    multiplicity: dict[int, int]
    observations: int
    rejected: int
    sigma0: float
    sigma0_um: float
    sigma0_px: float
    image_rms_um: tuple[float, float]
    object_rms_m: tuple[float, float, float] | None
    object_rms_predicted_m: tuple[float, float, float] | None
    redundancy: int
    iterations: int
    seconds: float
    gps_used: bool
    variance_factors: dict[str, float]
    calibration: list[dict]
    rejections: list[dict]
    control_residuals: list[dict]
    check_residuals: list[dict]
    exterior: list[dict]
    notes: list[str]
    subblocks: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = dict(vars(self))
        d["multiplicity"] = {str(k): v for k, v in sorted(self.multiplicity.items())}
        return _jsonable(d)


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


# --- loading the problem -------------------------------------------------------------------


def _camera_radius(cam: Camera) -> float:
    """The normalising radius of the additional parameters: half the format's diagonal."""
    if cam.kind == "film":
        f = cam.fiducial_array
        return float(np.max(np.hypot(f[:, 0], f[:, 1])))
    if cam.sensor_px is None or cam.pixel_um is None:
        raise BlockError(f"camera {cam.name!r}: a digital camera needs pixel_um and sensor_px")
    return 0.5 * math.hypot(*cam.sensor_px) * cam.pixel_um / 1000.0


def load_problem(block: Block, options: AdjustOptions | None = None) -> Loaded:
    """The block's bundle problem with approximate values (module docstring)."""
    opt = options or AdjustOptions()
    cams = block.cameras()
    interior = block.interior()
    images = {im.image: im for im in block.images()}
    rows = block.conn.execute(
        "SELECT o.point, o.image, o.x_mm, o.y_mm, o.sigma_px, p.kind, o.source "
        "FROM observations o JOIN points p ON p.id = o.point ORDER BY o.point, o.image"
    ).fetchall()
    if not rows:
        raise BlockError(f"{block.path}: no observations to adjust (run 'apygis at match')")
    pts_info = {
        pid: (name, kind, X, Y, Z, sxy, sz)
        for pid, name, kind, X, Y, Z, sxy, sz in block.conn.execute(
            "SELECT id, name, kind, X, Y, Z, sigma_xy_m, sigma_z_m FROM points"
        )
    }
    obs_pt = np.array([r[0] for r in rows], np.int64)
    obs_img = np.array([r[1] for r in rows], np.int64)
    missing = sorted({int(i) for i in obs_img} - set(interior))
    if missing:
        raise BlockError(
            f"{block.path}: images {missing[:10]} have observations but no interior orientation"
        )
    kinds = np.array([r[5] for r in rows])
    # points to adjust: two rays, or control with observed coordinates and one ray
    rays: dict[int, int] = {}
    for p in obs_pt:
        rays[int(p)] = rays.get(int(p), 0) + 1
    control_kinds = ("full", "planimetric", "height")
    keep_pt = {
        p
        for p, n in rays.items()
        if n >= 2 or (pts_info[p][1] in control_kinds and _has_coords(pts_info[p]))
    }
    sel = np.array([int(p) in keep_pt for p in obs_pt])
    dropped_single = len(set(rays) - keep_pt)
    rows = [r for r, s in zip(rows, sel, strict=True) if s]
    obs_pt, obs_img, kinds = obs_pt[sel], obs_img[sel], kinds[sel]
    image_list = sorted({int(i) for i in obs_img})
    img_index = {n: k for k, n in enumerate(image_list)}
    point_ids = sorted(keep_pt)
    pt_index = {p: k for k, p in enumerate(point_ids)}
    cam_list = sorted({images[n].camera for n in image_list})
    cam_index = {c: k for k, c in enumerate(cam_list)}
    transforms = [PixelTransform.from_list(interior[n]["transform"]) for n in image_list]
    # observations: undistorted photo mm, sigma mm
    xy = np.array([[r[2], r[3]] for r in rows], float)
    sig_px = np.array([np.nan if r[4] is None else r[4] for r in rows], float)
    sig_px = np.where(np.isfinite(sig_px), np.hypot(sig_px, opt.model_sigma_px),
                      opt.default_sigma_px)  # fmt: skip
    oi = np.array([img_index[int(i)] for i in obs_img], np.int64)
    op = np.array([pt_index[int(p)] for p in obs_pt], np.int64)
    scale = np.array([t.pixel_mm for t in transforms])
    for n in image_list:
        cam = cams[images[n].camera]
        m = oi == img_index[n]
        xy[m] = cam.undistort(xy[m])
    sig_mm = sig_px * scale[oi]
    sources = [r[6] for r in rows]
    group_names = sorted(set(sources))
    groups = np.array([group_names.index(x) for x in sources], np.int64)
    # cameras
    K = len(cam_list)
    calib = np.zeros((K, len(CALIBRATION_PARAMETERS)))
    radius = np.zeros(K)
    for c, k in cam_index.items():
        cam = cams[c]
        calib[k, :3] = (cam.focal_mm, cam.x0_mm, cam.y0_mm)
        radius[k] = _camera_radius(cam)
    free = _free_mask(opt.calibrate, [cams[c] for c in cam_list])
    # control
    ctrl_pt, ctrl_xyz, ctrl_sig, check, check_xyz, check_sig = [], [], [], [], [], []
    for p in point_ids:
        _, kind, X, Y, Z, sxy, sz = pts_info[p]
        if kind in control_kinds:
            s = [np.inf, np.inf, np.inf]
            if kind in ("full", "planimetric"):
                s[0] = s[1] = float(sxy if sxy is not None else 0.05)
            if kind in ("full", "height"):
                s[2] = float(sz if sz is not None else 0.05)
            v = [0.0 if X is None else X, 0.0 if Y is None else Y, 0.0 if Z is None else Z]
            ctrl_pt.append(pt_index[p])
            ctrl_xyz.append(v)
            ctrl_sig.append(s)
        elif kind == "check" and None not in (X, Y, Z):
            check.append(pt_index[p])
            check_xyz.append([X, Y, Z])
            sxy0, sz0 = (0.0 if sxy is None else sxy), (0.0 if sz is None else sz)
            check_sig.append([sxy0, sxy0, sz0])
    notes = []
    if dropped_single:
        notes.append(f"{dropped_single} points with a single ray are not adjusted")
    # datum: the control, else the centres
    full = sum(1 for s in ctrl_sig if np.isfinite(s).all())
    plan_c = sum(1 for s in ctrl_sig if np.isfinite(s[0]))
    height_c = sum(1 for s in ctrl_sig if np.isfinite(s[2]))
    control_datum = plan_c >= 2 and height_c >= 3 and (full >= 1 or plan_c >= 3)
    gps_image, gps_xyz, gps_sig = [], [], []
    use_gps = opt.gps is not None and (opt.gps != "auto" or not control_datum)
    if use_gps:
        for n in image_list:
            im = images[n]
            if None in (im.X, im.Y, im.Z):
                continue
            if isinstance(opt.gps, tuple):
                sxy, sz = opt.gps
            else:
                sxy, sz = GPS_SIGMAS.get(im.position_source, GPS_SIGMAS["list"])
            gps_image.append(img_index[n])
            gps_xyz.append([im.X, im.Y, im.Z])
            gps_sig.append([sxy, sxy, sz])
        if gps_image and opt.gps == "auto":
            notes.append(
                f"the control gives no datum: {len(gps_image)} approximate projection centres "
                "are used as observations (sigmas by their source; --gps-sigma to set them)"
            )
    if not control_datum and not gps_image:
        raise BlockError(
            f"{block.path}: the block has no datum: measure control points in the images "
            "('apygis at gcp': at least two in plan and three in height) or give projection "
            "centres (--gps-sigma)"
        )
    # approximate values
    cam_of_image = np.array([cam_index[images[n].camera] for n in image_list], np.int64)
    chain_data = (xy, oi, op, calib, cam_of_image, ctrl_pt, ctrl_xyz, ctrl_sig)
    eo0 = _approximate_eo(block, images, image_list, cams, opt, chain_data, notes)
    P = len(point_ids)
    R = rotation_matrix(eo0[:, 3], eo0[:, 4], eo0[:, 5])
    k_obs = np.array([cam_index[images[n].camera] for n in image_list], np.int64)[oi]
    d = np.einsum("nij,nj->ni", R[oi], np.c_[xy - calib[k_obs, 1:3], -calib[k_obs, 0]])
    xyz0, ok = intersect_rays(eo0[oi, :3], d, op, P)
    # control with given coordinates: start there
    for k, v, s in zip(ctrl_pt, ctrl_xyz, ctrl_sig, strict=True):
        for a in range(3):
            if np.isfinite(s[a]):
                xyz0[k, a] = v[a]
        ok[k] = ok[k] or np.isfinite(s).all()
    # points that did not intersect (or lie behind a camera): on the mean terrain
    tz = _terrain(block)
    bad = ~ok | _behind(xyz0, eo0, R, oi, op)
    if bad.any():
        xyz0[bad] = _on_terrain(eo0, R, oi, op, d, bad, tz)
    problem = BundleProblem(
        calibration=calib,
        radius_mm=radius,
        camera=np.array([cam_index[images[n].camera] for n in image_list], np.int64),
        eo=eo0,
        xyz=xyz0,
        obs_image=oi,
        obs_point=op,
        obs_xy=xy,
        obs_sigma=sig_mm,
        free=free,
        ctrl_point=np.array(ctrl_pt, np.int64),
        ctrl_xyz=np.array(ctrl_xyz, float).reshape(-1, 3),
        ctrl_sigma=np.array(ctrl_sig, float).reshape(-1, 3),
        gps_image=np.array(gps_image, np.int64),
        gps_xyz=np.array(gps_xyz, float).reshape(-1, 3),
        gps_sigma=np.array(gps_sig, float).reshape(-1, 3),
    )
    return Loaded(
        problem=problem,
        images=image_list,
        point_ids=point_ids,
        point_names=[pts_info[p][0] for p in point_ids],
        point_kinds=[pts_info[p][1] for p in point_ids],
        cameras=cam_list,
        transforms=transforms,
        check=check,
        check_xyz=np.array(check_xyz, float).reshape(-1, 3),
        check_sigma=np.array(check_sig, float).reshape(-1, 3),
        control_index=ctrl_pt,
        gps_used=bool(gps_image),
        notes=notes,
        sigma_ref_mm=float(np.median(sig_mm)),
        groups=groups,
        group_names=group_names,
        block_cameras=[cams[c] for c in cam_list],
        calibration0=calib.copy(),
    )


def _has_coords(info) -> bool:
    _, kind, X, Y, Z, _, _ = info
    if kind == "height":
        return Z is not None
    if kind == "planimetric":
        return X is not None and Y is not None
    return None not in (X, Y, Z)


def _free_mask(calibrate, cams: list[Camera]) -> np.ndarray:
    mask = np.zeros((len(cams), len(CALIBRATION_PARAMETERS)), bool)
    if not calibrate or calibrate == "auto":
        return mask  # "auto": chosen by _select_calibration, from a fixed camera
    for k in range(len(cams)):
        for n in calibrate:
            if n not in CALIBRATION_PARAMETERS:
                raise BlockError(
                    f"calibration parameter {n!r} is not one of {', '.join(CALIBRATION_PARAMETERS)}"
                )
            mask[k, CALIBRATION_PARAMETERS.index(n)] = True
    return mask


def _terrain(block: Block) -> float:
    from apygis.aerotri.project import terrain_height

    try:
        return terrain_height(block)
    except BlockError:
        return 0.0


def _approximate_eo(block: Block, images, image_list, cams, opt: AdjustOptions, chain_data,
                    notes: list[str]) -> np.ndarray:  # fmt: skip
    """Approximate exterior orientations (module docstring), ``(M, 6)``."""
    M = len(image_list)
    eo = np.full((M, 6), np.nan)
    if not opt.restart:
        prev = {
            r[0]: r[1:]
            for r in block.conn.execute(
                "SELECT image, X, Y, Z, omega, phi, kappa FROM exterior"
            ).fetchall()
        }
        if prev and all(n in prev for n in image_list):
            start = np.array([prev[n] for n in image_list], float)
            if block.meta("exterior_frame") != "local":
                return start
            # imported orientations in a frame of their own (a COLMAP model): placed on the
            # control, as the end of a chain of relative orientations
            xy, oi, op, calib, cam_of_image, ctrl_pt, ctrl_xyz, ctrl_sig = chain_data
            P = int(op.max()) + 1 if len(op) else 0
            xyz = _intersect_oriented(start, xy, oi, op, calib, cam_of_image, P)
            centres = _centres(images, image_list)
            what = _place(block, centres, start, xyz, ctrl_pt, ctrl_xyz, ctrl_sig)
            notes.append(f"the imported orientations were placed on {what}")
            return centres
    from apygis.aerotri.project import block_plan

    try:
        bplan = block_plan(block)
        headings = bplan.headings
    except (BlockError, ValueError):
        headings = {}
    tz = _terrain(block)
    for k, n in enumerate(image_list):
        im = images[n]
        az = im.x_azimuth_deg if im.x_azimuth_deg is not None else headings.get(n, im.heading_deg)
        if None in (im.X, im.Y) or az is None:
            continue
        Z = im.Z
        if Z is None:
            cam = cams[im.camera]
            Z = tz + cam.focal_mm * 10.0  # unknown flying height: 1:10 000
        eo[k] = (im.X, im.Y, Z, 0.0, 0.0, math.radians(90.0 - az))
    if np.isnan(eo).any():
        n_missing = int(np.isnan(eo).any(axis=1).sum())
        chained = _chain(block, image_list, eo, *chain_data)
        notes.append(
            f"{n_missing} images had no approximate projection centre: the block was put "
            "together by a chain of relative orientations and placed by an absolute "
            f"orientation on {chained}"
        )
    return eo


def _chain(block: Block, image_list, eo, xy, oi, op, calib, cam_of_image, ctrl_pt, ctrl_xyz,
           ctrl_sig) -> str:  # fmt: skip
    """Orient the block without approximate values, into ``eo`` (in place); returns what it was
    placed on.

    The image pair with the most common points is oriented relatively (coplanarity,
    :func:`apygis.orient.relative.relative_orientation`) in a model system (left photo at
    the origin, the base 1); their points are intersected. Then, one at a time, the image
    that sees most of the intersected points is resected (DLT, then collinearity,
    :func:`apygis.orient.resection.resect`; points off by more than five times the median
    residual are left out) and the points it adds are intersected. Finally the model is
    placed by a 3-D similarity (:func:`apygis.orient.absolute.similarity_closed_form`) on
    the control points it holds (three or more full ones), else on the images' approximate
    centres where three or more have one.
    """
    from apygis.errors import OrientationError
    from apygis.orient.collinearity import InteriorOrientation
    from apygis.orient.relative import relative_orientation
    from apygis.orient.resection import resect

    M = len(image_list)
    P = int(op.max()) + 1 if len(op) else 0
    ios = [InteriorOrientation(*calib[cam_of_image[k], :3]) for k in range(M)]
    by_image = [np.nonzero(oi == k)[0] for k in range(M)]
    pts_of = [op[o] for o in by_image]
    # the seed pair
    best, pair = -1, (0, 1)
    for a in range(M):
        sa = set(pts_of[a].tolist())
        for b in range(a + 1, M):
            n = len(sa.intersection(pts_of[b].tolist()))
            if n > best:
                best, pair = n, (a, b)
    if best < 8:
        raise BlockError(
            f"{block.path}: no image pair shares 8 tie points: the block cannot be put together "
            "without approximate projection centres"
        )
    a, b = pair
    common = np.intersect1d(pts_of[a], pts_of[b])
    xa = xy[by_image[a]][np.searchsorted(pts_of[a], common)]
    xb = xy[by_image[b]][np.searchsorted(pts_of[b], common)]
    keep = np.ones(len(common), bool)
    ro = None
    for _ in range(3):
        try:
            ro = relative_orientation(xa[keep], xb[keep], ios[a], ios[b])
        except OrientationError as exc:
            raise BlockError(
                f"{block.path}: the relative orientation of images {image_list[a]} and "
                f"{image_list[b]} failed ({exc})"
            ) from None
        res = np.abs(ro.residuals_mm)
        bad = res > 5.0 * max(float(np.median(res)), 1e-6)
        if not bad.any():
            break
        idx = np.nonzero(keep)[0]
        keep[idx[bad]] = False
    assert ro is not None
    model = np.full((M, 6), np.nan)
    model[a] = ro.left.parameters
    model[b] = ro.right.parameters
    xyz = _intersect_oriented(model, xy, oi, op, calib, cam_of_image, P)
    for _ in range(M - 2):
        known = np.isfinite(xyz).all(axis=1)
        cand = [(int(known[pts_of[k]].sum()), k) for k in range(M) if np.isnan(model[k]).any()]
        n, k = max(cand)
        if n < 6:
            missing = [image_list[j] for _, j in cand]
            raise BlockError(
                f"{block.path}: images {missing[:10]} share fewer than 6 points with the "
                "images oriented so far: the chain of orientations breaks there"
            )
        sel = by_image[k][known[pts_of[k]]]
        g, m = xyz[op[sel]], xy[sel]
        use = np.ones(len(sel), bool)
        for _ in range(3):
            try:
                r = resect(g[use], m[use], ios[k])
            except OrientationError as exc:
                raise BlockError(
                    f"{block.path}: image {image_list[k]} could not be resected in the chain "
                    f"({exc})"
                ) from None
            v = np.hypot(r.residuals_mm[:, 0], r.residuals_mm[:, 1])
            bad = v > 5.0 * max(float(np.median(v)), 1e-6)
            if not bad.any():
                break
            idx = np.nonzero(use)[0]
            use[idx[bad]] = False
        model[k] = r.exterior.parameters
        xyz = _intersect_oriented(model, xy, oi, op, calib, cam_of_image, P)
    return _place(block, eo, model, xyz, ctrl_pt, ctrl_xyz, ctrl_sig)


def _place(block: Block, eo, model, xyz, ctrl_pt, ctrl_xyz, ctrl_sig) -> str:
    """Place orientations ``model`` (``(M, 6)``, a frame of their own; points ``xyz`` in it)
    into ``eo`` by a 3-D similarity on the control points they hold (three or more full
    ones), else on the approximate centres of three or more images in ``eo``; returns what
    it was placed on."""
    from apygis.orient.absolute import similarity_closed_form
    from apygis.orient.rotation import angles_from_matrix

    M = len(model)
    full = [j for j, s in enumerate(ctrl_sig) if np.isfinite(s).all()]
    mc = [(xyz[ctrl_pt[j]], ctrl_xyz[j]) for j in full if np.isfinite(xyz[ctrl_pt[j]]).all()]
    have = [k for k in range(M) if np.isfinite(eo[k, :3]).all()]
    if len(mc) >= 3:
        S = similarity_closed_form([m for m, _ in mc], [g for _, g in mc])
        what = f"{len(mc)} control points"
    elif len(have) >= 3:
        S = similarity_closed_form(model[have, :3], eo[have, :3])
        what = f"the approximate centres of {len(have)} images"
    else:
        raise BlockError(
            f"{block.path}: the block's orientations are in a frame of their own and cannot be "
            "placed: measure three or more full control points ('apygis at gcp') or give "
            "approximate centres of three images"
        )
    Rs = S.rotation
    for k in range(M):
        C = S.forward(model[k, :3])
        Rk = Rs @ rotation_matrix(*model[k, 3:])
        eo[k] = (*C, *angles_from_matrix(Rk))
    return what


def _intersect_oriented(model, xy, oi, op, calib, cam_of_image, P) -> np.ndarray:
    """Points intersected from the oriented images (NaN where fewer than two rays)."""
    ok_img = np.isfinite(model).all(axis=1)
    m = ok_img[oi]
    xyz = np.full((P, 3), np.nan)
    if not m.any():
        return xyz
    R = rotation_matrix(model[ok_img, 3], model[ok_img, 4], model[ok_img, 5])
    Rfull = np.zeros((len(model), 3, 3))
    Rfull[ok_img] = R
    k = cam_of_image[oi[m]]
    d = np.einsum("nij,nj->ni", Rfull[oi[m]], np.c_[xy[m] - calib[k, 1:3], -calib[k, 0]])
    pts, ok = intersect_rays(model[oi[m], :3], d, op[m], P)
    xyz[ok] = pts[ok]
    return xyz


def _centres(images, image_list) -> np.ndarray:
    """``(M, 6)``: the approximate centres where known (angles and the rest NaN)."""
    out = np.full((len(image_list), 6), np.nan)
    for k, n in enumerate(image_list):
        im = images[n]
        if None not in (im.X, im.Y, im.Z):
            out[k, :3] = (im.X, im.Y, im.Z)
    return out


def _behind(xyz, eo, R, oi, op) -> np.ndarray:
    q = np.einsum("nk,nkl->nl", xyz[op] - eo[oi, :3], R[oi])
    out = np.zeros(len(xyz), bool)
    np.logical_or.at(out, op, q[:, 2] >= 0)
    return out


def _on_terrain(eo, R, oi, op, d, bad, tz) -> np.ndarray:
    """Points on the plane ``Z = tz`` along the first ray of each."""
    first: dict[int, int] = {}
    for k, p in enumerate(op):
        if bad[p] and p not in first:
            first[int(p)] = k
    out = np.zeros((int(bad.sum()), 3))
    idx = np.nonzero(bad)[0]
    for j, p in enumerate(idx):
        if int(p) not in first:
            continue
        k = first[int(p)]
        C, v = eo[oi[k], :3], d[k]
        t = (tz - C[2]) / v[2] if v[2] != 0 else 0.0
        out[j] = C + t * v
    return out


# --- the adjustment ------------------------------------------------------------------------


def adjust_block(block: Block, options: AdjustOptions | None = None, *, progress=None):
    """Adjust the block (module docstring); returns an :class:`AdjustReport`.

    ``progress(done, total)`` (:mod:`apygis.progress`) counts the rounds of
    data snooping (and calibration selection).
    """
    from apygis.progress import STEPS, phase

    opt = options or AdjustOptions()
    t0 = time.perf_counter()
    started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    with block.conn:
        cur = block.conn.execute(
            "INSERT INTO adjustments (started, options) VALUES (?, ?)",
            (started, json.dumps(opt.to_dict())),
        )
    adj_id = int(cur.lastrowid or 0)
    run = block.start_run("adjust", opt.to_dict())
    try:
        ld = load_problem(block, opt)
        sub_reports: list[dict] = []
        if opt.subblocks:
            sub_reports = _subblock_start(block, ld, opt)
        pb = ld.problem
        steps = 2 if opt.calibrate == "auto" else 1
        sol, rej = _solve(pb, opt, ld.groups, phase(progress, 0, steps))
        if sol.variance_factors:
            pb.obs_sigma = sol.obs_sigma.copy()  # weighted by the variance components
        if opt.calibrate == "auto":
            sol, rej, dropped = _select_calibration(ld, opt, sol, rej, phase(progress, 1, steps))
            ld.notes += dropped
        report = _report(block, ld, sol, rej, adj_id, time.perf_counter() - t0, sub_reports)
        _store(block, ld, sol, rej, adj_id, report)
        if progress is not None:
            progress(STEPS, STEPS)
    except BaseException as exc:
        block.finish_run(run, "failed" if not isinstance(exc, KeyboardInterrupt)
                         else "interrupted", {"error": str(exc)})  # fmt: skip
        with block.conn:
            block.conn.execute("DELETE FROM adjustments WHERE id = ?", (adj_id,))
        raise
    block.finish_run(run, "done", {"adjustment": adj_id, "sigma0": report.sigma0})
    return report


def _solve(pb: BundleProblem, opt: AdjustOptions, groups, progress):
    if opt.robust:
        return robust_adjust(pb, threshold=opt.threshold, max_iter=opt.max_iter,
                             groups=groups, progress=progress)  # fmt: skip
    sol = adjust(pb, max_iter=opt.max_iter, progress=progress)
    return sol, []


def _select_calibration(ld: Loaded, opt: AdjustOptions, sol: BundleSolution, rej, progress):
    """Forward selection of the self-calibration (``calibrate="auto"``).

    From the solution with the camera fixed, each candidate parameter
    (:data:`AUTO_CALIBRATION`, and ``b1``, ``b2`` for film) is freed in turn together
    with those kept so far; it is kept when the adjustment converges, its largest
    correlation with an orientation element or a kept parameter is at most
    :data:`CORRELATION_LIMIT` (determined) and its change from the camera file is at
    least :data:`SIGNIFICANCE` standard deviations (significant), else fixed again with
    a note saying why.
    Returns ``(solution, rejections, notes)``.
    """
    pb = ld.problem
    notes = []
    weight = np.ones(len(pb.obs_image))
    for r in rej:
        if r.obs >= 0:
            weight[r.obs] = 0.0
    cams = ld.block_cameras
    candidates = [
        (k, par)
        for k in range(len(ld.cameras))
        for par in list(AUTO_CALIBRATION) + (["b1", "b2"] if cams[k].kind == "film" else [])
    ]
    for step, (cam, par) in enumerate(candidates):
        if progress is not None:
            progress(step, len(candidates))
        i = CALIBRATION_PARAMETERS.index(par)
        pb.free[cam, i] = True
        pb.eo, pb.xyz, pb.calibration = sol.eo.copy(), sol.xyz.copy(), sol.calibration.copy()
        why = ""
        try:
            trial = adjust(pb, weight=weight, max_iter=opt.max_iter)
        except (ConvergenceError, DegenerateGeometryError) as exc:
            trial, why = None, f"the adjustment does not settle with it ({exc})"
        if trial is not None:
            j = trial.calibration_names.index((cam, par))
            corr = np.abs(trial.calibration_corr[j].copy())
            corr[j] = 0.0
            worst_other = float(corr.max()) if len(corr) > 1 else 0.0
            worst_eo = float(trial.calibration_eo_corr[j])
            if max(worst_other, worst_eo) > CORRELATION_LIMIT:
                other = (
                    "an orientation element"
                    if worst_eo >= worst_other
                    else trial.calibration_names[int(np.argmax(corr))][1]
                )
                why = f"correlation {max(worst_other, worst_eo):.2f} with {other}"
            else:
                dv = float(trial.calibration[cam, i]) - _initial(ld, cam, par)
                sd = float(trial.calibration_std[cam, i])
                if not abs(dv) >= SIGNIFICANCE * sd:
                    notes.append(
                        f"camera {ld.cameras[cam]}: {par} is determined but not significant "
                        f"({dv:+.3g} +- {sd:.2g}); fixed"
                    )
                    pb.free[cam, i] = False
                    pb.calibration[cam, i] = _initial(ld, cam, par)
                    continue
        if why:
            notes.append(
                f"camera {ld.cameras[cam]}: {par} is not determined by this block ({why}); fixed"
            )
            pb.free[cam, i] = False
            pb.calibration[cam, i] = _initial(ld, cam, par)
            continue
        assert trial is not None
        sol = trial
    pb.calibration = sol.calibration.copy()
    if progress is not None:
        progress(len(candidates), len(candidates))
    return sol, rej, notes


def _initial(ld: Loaded, cam: int, par: str) -> float:
    """The camera file's value of a calibration parameter (0 for the additional ones)."""
    return float(ld.calibration0[cam, CALIBRATION_PARAMETERS.index(par)])


def _subblock_start(block: Block, ld: Loaded, opt: AdjustOptions) -> list[dict]:
    """Adjust each subblock as an independent task, and start the whole block from them."""
    from apygis.tasks import Runner

    subblocks = block.subblocks()
    if not subblocks:
        raise BlockError(
            f"{block.path}: the block has no subblocks ('apygis at plan --subblock-strips N')"
        )
    strip_of = {im.image: im.strip for im in block.images()}
    pb = ld.problem
    tasks = []
    members = []
    for k, strips in enumerate(subblocks, 1):
        imgs = [i for i, n in enumerate(ld.images) if strip_of.get(n) in set(strips)]
        sub = _restrict(pb, imgs)
        if sub is None:
            continue
        members.append((k, imgs, sub[1], sub[2]))
        tasks.append((k, (sub[0], opt.threshold, opt.max_iter, opt.robust)))
    out = []
    eo_sum = np.zeros_like(pb.eo)
    eo_n = np.zeros(len(pb.eo))
    xyz_sum = np.zeros_like(pb.xyz)
    xyz_n = np.zeros(len(pb.xyz))
    results = {}
    with Runner(opt.scheduler, opt.workers) as runner:
        for k, res in runner.run(_task_subblock, tasks):
            results[k] = res
    for k, imgs, pts, _ in members:
        res = results.get(k)
        if res is None or "error" in res:
            out.append({"subblock": k, "images": len(imgs), "error": (res or {}).get("error")})
            continue
        eo_sum[imgs] += res["eo"]
        eo_n[imgs] += 1
        xyz_sum[pts] += res["xyz"]
        xyz_n[pts] += 1
        out.append({"subblock": k, "images": len(imgs), "points": len(pts),
                    "sigma0": res["sigma0"], "rejected": res["rejected"]})  # fmt: skip
    have = eo_n > 0
    pb.eo[have] = eo_sum[have] / eo_n[have, None]
    havep = xyz_n > 0
    pb.xyz[havep] = xyz_sum[havep] / xyz_n[havep, None]
    return out


def _restrict(pb: BundleProblem, imgs: list[int]):
    """The sub-problem of images ``imgs``: points with two rays there (or control)."""
    img_set = np.zeros(pb.n_images, bool)
    img_set[imgs] = True
    m = img_set[pb.obs_image]
    rays = np.bincount(pb.obs_point[m], minlength=pb.n_points)
    ctrl = np.zeros(pb.n_points, bool)
    ctrl[pb.ctrl_point[np.isfinite(pb.ctrl_sigma).any(axis=1)]] = True
    keep_pt = (rays >= 2) | (ctrl & (rays >= 1))
    m &= keep_pt[pb.obs_point]
    if not m.any():
        return None
    pts = np.nonzero(keep_pt)[0]
    pidx = np.full(pb.n_points, -1)
    pidx[pts] = np.arange(len(pts))
    iidx = np.full(pb.n_images, -1)
    iidx[imgs] = np.arange(len(imgs))
    cm = keep_pt[pb.ctrl_point]
    gm = img_set[pb.gps_image]
    sub = BundleProblem(
        calibration=pb.calibration, radius_mm=pb.radius_mm, camera=pb.camera[imgs],
        eo=pb.eo[imgs], xyz=pb.xyz[pts], obs_image=iidx[pb.obs_image[m]],
        obs_point=pidx[pb.obs_point[m]], obs_xy=pb.obs_xy[m], obs_sigma=pb.obs_sigma[m],
        free=np.zeros_like(pb.free), ctrl_point=pidx[pb.ctrl_point[cm]],
        ctrl_xyz=pb.ctrl_xyz[cm], ctrl_sigma=pb.ctrl_sigma[cm],
        gps_image=iidx[pb.gps_image[gm]], gps_xyz=pb.gps_xyz[gm], gps_sigma=pb.gps_sigma[gm],
    )  # fmt: skip
    return sub, pts, m


def _task_subblock(problem: BundleProblem, threshold: float, max_iter: int, robust: bool):
    from apygis.errors import ApygisError

    try:
        if robust:
            sol, rej = robust_adjust(problem, threshold=threshold, max_iter=max_iter)
        else:
            sol, rej = adjust(problem, max_iter=max_iter, covariance=False), []
    except ApygisError as exc:
        return {"error": str(exc)}
    return {"eo": sol.eo, "xyz": sol.xyz, "sigma0": sol.sigma0, "rejected": len(rej)}


# --- the report and the block's tables -----------------------------------------------------


def _residual_px(ld: Loaded, sol: BundleSolution) -> np.ndarray:
    """Residuals in pixels ``(N, 2)`` (col, row) through each image's linear transform."""
    pb = ld.problem
    out = np.empty_like(sol.residuals)
    for k, t in enumerate(ld.transforms):
        m = pb.obs_image == k
        if m.any():
            Ainv = np.linalg.inv(t.matrix[:2, :2])
            out[m] = sol.residuals[m] @ Ainv.T
    return out


def _report(block, ld: Loaded, sol: BundleSolution, rej: list[Rejection], adj_id: int,
            seconds: float, sub_reports) -> AdjustReport:  # fmt: skip
    pb = ld.problem
    weight = np.ones(len(pb.obs_image))
    ctrl_off = set()
    for r in rej:
        if r.obs >= 0:
            weight[r.obs] = 0.0
        else:
            ctrl_off.add(r.control)
    used = weight > 0
    rays = np.bincount(pb.obs_point[used], minlength=pb.n_points)
    mult: dict[int, int] = {}
    for n in rays[rays >= 1]:
        mult[int(n)] = mult.get(int(n), 0) + 1
    res_um = sol.residuals[used] * 1000.0
    image_rms = tuple(float(np.sqrt(np.mean(res_um[:, a] ** 2))) for a in range(2))
    px = float(np.median([t.pixel_mm for t in ld.transforms]))
    kinds = {"full": 0, "planimetric": 0, "height": 0, "check": len(ld.check)}
    for k in ld.control_index:
        kinds[ld.point_kinds[k]] += 1
    obj_rms = obj_pred = None
    check_res = []
    if ld.check:
        ci = np.array(ld.check)
        e = sol.xyz[ci] - ld.check_xyz
        rm = np.sqrt(np.mean(e**2, axis=0))
        # expected: the adjusted point's precision and the given coordinates' own
        pr = np.sqrt(np.nanmean(sol.xyz_std[ci] ** 2 + ld.check_sigma**2, axis=0))
        obj_rms = (float(rm[0]), float(rm[1]), float(rm[2]))
        obj_pred = (float(pr[0]), float(pr[1]), float(pr[2]))
        for j, k in enumerate(ci):
            check_res.append({
                "point": ld.point_names[k], "dX": e[j, 0], "dY": e[j, 1], "dZ": e[j, 2],
                "sX": sol.xyz_std[k, 0], "sY": sol.xyz_std[k, 1], "sZ": sol.xyz_std[k, 2],
                "rays": int(rays[k]),
            })  # fmt: skip
    ctrl_res = []
    for c, k in enumerate(ld.control_index):
        v = sol.ctrl_residuals[c]
        s = pb.ctrl_sigma[c]
        ctrl_res.append({
            "point": ld.point_names[k], "kind": ld.point_kinds[k],
            "vX": v[0] if np.isfinite(s[0]) else None, "vY": v[1] if np.isfinite(s[1]) else None,
            "vZ": v[2] if np.isfinite(s[2]) else None, "rays": int(rays[k]),
            "rejected": c in ctrl_off,
        })  # fmt: skip
    rejections = []
    for r in rej:
        if r.obs >= 0:
            o = r.obs
            k = int(pb.obs_image[o])
            v_px = np.asarray(r.residual) @ np.linalg.inv(ld.transforms[k].matrix[:2, :2]).T
            rejections.append({
                "point": ld.point_names[int(pb.obs_point[o])], "image": ld.images[k],
                "residual_px": [float(v_px[0]), float(v_px[1])], "w": r.w, "round": r.round,
                "reason": r.reason,
            })  # fmt: skip
        else:
            k = ld.control_index[r.control]
            rejections.append({
                "point": ld.point_names[k], "image": None, "residual_m": list(r.residual),
                "w": r.w, "round": r.round, "reason": r.reason,
            })  # fmt: skip
    exterior = []
    for k, n in enumerate(ld.images):
        e, s = sol.eo[k], sol.eo_std[k]
        exterior.append({
            "image": n, "X": e[0], "Y": e[1], "Z": e[2], "omega_rad": e[3], "phi_rad": e[4],
            "kappa_rad": e[5], "sX": s[0], "sY": s[1], "sZ": s[2], "somega_rad": s[3],
            "sphi_rad": s[4], "skappa_rad": s[5],
        })  # fmt: skip
    calibration = []
    for j, (cam, par) in enumerate(sol.calibration_names):
        i = CALIBRATION_PARAMETERS.index(par)
        calibration.append({
            "camera": ld.cameras[cam], "parameter": par, "value": sol.calibration[cam, i],
            "std": sol.calibration_std[cam, i], "initial": ld.calibration0[cam, i],
            "max_corr_orientation": sol.calibration_eo_corr[j],
            "corr": {n2[1]: sol.calibration_corr[j, j2]
                     for j2, n2 in enumerate(sol.calibration_names) if j2 != j},
        })  # fmt: skip
    s0 = sol.sigma0
    # the a posteriori sigma of one photo coordinate of a typical measurement
    sig_ref = float(np.median(sol.obs_sigma[used])) if used.any() else ld.sigma_ref_mm
    return AdjustReport(
        adjustment=adj_id,
        images=len(ld.images),
        cameras=len(ld.cameras),
        control=kinds,
        multiplicity=mult,
        observations=int(used.sum()),
        rejected=sum(1 for r in rej if r.obs >= 0),
        sigma0=s0,
        sigma0_um=s0 * sig_ref * 1000.0,
        sigma0_px=s0 * sig_ref / px,
        variance_factors={ld.group_names[g]: v for g, v in sol.variance_factors.items()},
        image_rms_um=(image_rms[0], image_rms[1]),
        object_rms_m=obj_rms,
        object_rms_predicted_m=obj_pred,
        redundancy=sol.dof,
        iterations=sol.iterations,
        seconds=round(seconds, 3),
        gps_used=ld.gps_used,
        calibration=calibration,
        rejections=rejections,
        control_residuals=ctrl_res,
        check_residuals=check_res,
        exterior=exterior,
        notes=ld.notes,
        subblocks=sub_reports,
    )


def _store(block: Block, ld: Loaded, sol: BundleSolution, rej, adj_id: int, report) -> None:
    pb = ld.problem
    rej_reason = {r.obs: r.reason for r in rej if r.obs >= 0}
    v_px = _residual_px(ld, sol)
    w = np.nan_to_num(sol.w_obs, nan=-1.0)
    weight = np.ones(len(pb.obs_image))
    for o in rej_reason:
        weight[o] = 0.0
    rays = np.bincount(pb.obs_point[weight > 0], minlength=pb.n_points)
    with np.errstate(invalid="ignore", divide="ignore"):
        rxy = sol.xyz_cov[:, 0, 1] / (sol.xyz_std[:, 0] * sol.xyz_std[:, 1])
    with block.conn:
        c = block.conn
        c.execute("DELETE FROM exterior")
        c.executemany(
            "INSERT INTO exterior VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            [(n, adj_id, *map(float, sol.eo[k]), *map(_f, sol.eo_std[k]))
             for k, n in enumerate(ld.images)],
        )  # fmt: skip
        c.execute("DELETE FROM adjusted_points")
        c.executemany(
            "INSERT INTO adjusted_points VALUES (?,?,?,?,?,?,?,?,?,?)",
            [(pid, adj_id, *map(float, sol.xyz[k]), *map(_f, sol.xyz_std[k]), _f(rxy[k]),
              int(rays[k])) for k, pid in enumerate(ld.point_ids)],
        )  # fmt: skip
        c.execute("DELETE FROM residuals")
        c.executemany(
            "INSERT INTO residuals VALUES (?,?,?,?,?,?,?,?)",
            [
                (ld.point_ids[int(pb.obs_point[o])], ld.images[int(pb.obs_image[o])], adj_id,
                 float(v_px[o, 0]), float(v_px[o, 1]), None if w[o] < 0 else float(w[o]),
                 int(o in rej_reason), rej_reason.get(o, ""))
                for o in range(len(pb.obs_image))
            ],
        )  # fmt: skip
        c.execute("INSERT OR REPLACE INTO meta VALUES ('exterior_frame', 'crs')")
        c.execute(
            "UPDATE adjustments SET finished = ?, report = ? WHERE id = ?",
            (time.strftime("%Y-%m-%dT%H:%M:%S%z"), json.dumps(report.to_dict()), adj_id),
        )


def _f(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None
