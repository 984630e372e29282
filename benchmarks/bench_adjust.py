"""apygis's bundle adjustment against pycolmap's (Ceres), and a block the size of Graz.

1. **The same problem, both programs** (``pip install apygis[bench]``): a
   simulated 100-image block (10 strips x 10 images, 60 % / 30 % overlap,
   ``--points`` tie points per image, 0.1 px noise; :mod:`apygis.aerotri.simulate`)
   with the same approximate values, the same observations and the same fixed
   intrinsics, adjusted by :func:`apygis.orient.bundle.adjust` (least squares,
   without and then with the precisions) and by ``pycolmap.bundle_adjustment``
   (Ceres, the camera fixed). COLMAP's camera looks down its +z axis with y
   down, apygis's down -z with y up: ``cam_from_world = D R^T`` with
   ``D = diag(1, -1, -1)``, pixels ``u = x / p + cx``, ``v = -y / p + cy``
   (pixel size ``p``). pycolmap has no control points: it fixes its own gauge,
   apygis adjusts on the block's control; the unknowns are the same otherwise.
2. **Graz**: 659 images (20 strips x 33; the seed's Graz block), about 300 tie
   points per image, adjusted with every precision (orientations, points,
   redundancy numbers), and again robustly with 5 % gross errors; each in a
   child process so that its peak memory is its own.

Run: ``python benchmarks/bench_adjust.py [--points 300]``. Last line: one JSON
object with ``apygis_s``, ``pycolmap_s``, ``time_ratio``, ``graz_s``,
``graz_peak_mb``, ``graz_sigma0_px`` and more.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np

from apygis.aerotri.simulate import simulate_block
from apygis.orient.bundle import adjust, robust_adjust
from apygis.orient.rotation import rotation_matrix


def pycolmap_problem(sb):
    """The simulated problem as a pycolmap Reconstruction (see the module docstring)."""
    import pycolmap

    pb = sb.problem
    p = sb.pixel_mm
    c = float(pb.calibration[0, 0])
    half = 115.0 / p  # principal point at the centre of a 230 mm format
    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera(
        model="PINHOLE", width=int(2 * half), height=int(2 * half),
        params=[c / p, c / p, half, half], camera_id=1,
    )  # fmt: skip
    rec.add_camera_with_trivial_rig(cam)
    D = np.diag([1.0, -1.0, -1.0])
    R = rotation_matrix(pb.eo[:, 3], pb.eo[:, 4], pb.eo[:, 5])
    uv = np.c_[pb.obs_xy[:, 0] / p + half, -pb.obs_xy[:, 1] / p + half]
    order = np.argsort(pb.obs_image, kind="stable")
    point2d_index = np.empty(len(order), np.int64)
    for i in range(pb.n_images):
        obs = order[pb.obs_image[order] == i]
        point2d_index[obs] = np.arange(len(obs))
        Rcw = D @ R[i].T
        t = -Rcw @ pb.eo[i, :3]
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(Rcw), t)
        img = pycolmap.Image(name=f"{i}", keypoints=uv[obs], camera_id=1, image_id=i + 1)
        rec.add_image_with_trivial_frame(img, pose)
    by_point = np.argsort(pb.obs_point, kind="stable")
    starts = np.r_[0, np.nonzero(np.diff(pb.obs_point[by_point]))[0] + 1, len(by_point)]
    for k in range(len(starts) - 1):
        obs = by_point[starts[k] : starts[k + 1]]
        track = pycolmap.Track()
        for o in obs:
            track.add_element(int(pb.obs_image[o]) + 1, int(point2d_index[o]))
        rec.add_point3D(pb.xyz[pb.obs_point[obs[0]]], track)
    return rec


def run_pycolmap(sb) -> dict:
    import pycolmap

    rec = pycolmap_problem(sb)
    opts = pycolmap.BundleAdjustmentOptions()
    opts.refine_focal_length = False
    opts.refine_principal_point = False
    opts.refine_extra_params = False
    t = time.perf_counter()
    pycolmap.bundle_adjustment(rec, opts)
    seconds = time.perf_counter() - t
    rec.update_point_3d_errors()
    return {"seconds": seconds, "rms_after_px": rec.compute_mean_reprojection_error()}


def run_apygis(sb) -> dict:
    pb = sb.problem
    adjust(simulate_block(2, 3, points_per_image=50, seed=1).problem)  # imports, caches
    t = time.perf_counter()
    sol = adjust(pb, covariance=False)
    seconds = time.perf_counter() - t
    t = time.perf_counter()
    sol2 = adjust(pb)
    with_cov = time.perf_counter() - t
    err = (sol2.eo - sb.eo) / sol2.eo_std
    return {
        "seconds": seconds,
        "seconds_with_precisions": with_cov,
        "iterations": sol.iterations,
        "sigma0": sol2.sigma0,
        "eo_normalised_rms": float(np.sqrt(np.mean(err**2))),
    }


def graz(robust: bool, points: int) -> dict:
    """Run in a child process: the Graz-sized block, its seconds and its own peak memory."""
    sb = simulate_block(20, 33, points_per_image=points, gross_fraction=0.05 if robust else 0.0,
                        seed=5)  # fmt: skip
    pb = sb.problem
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t = time.perf_counter()
    if robust:
        sol, rej = robust_adjust(pb)
    else:
        sol, rej = adjust(pb), []
    seconds = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {
        "images": pb.n_images,
        "points": pb.n_points,
        "observations": len(pb.obs_image),
        "seconds": seconds,
        "peak_mb": peak / 1024.0,
        "problem_mb": base / 1024.0,
        "sigma0": sol.sigma0,
        "sigma0_px": sol.sigma0 * sb.sigma_px,
        "rejected": len(rej),
        "iterations": sol.iterations,
    }


def _child(robust: bool, points: int) -> dict:
    out = subprocess.run(
        [sys.executable, __file__, "--graz", "robust" if robust else "plain", "--points",
         str(points)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=300, help="tie points per image")
    ap.add_argument("--graz", choices=["plain", "robust"], default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.graz:
        print(json.dumps(graz(args.graz == "robust", args.points)))
        return
    sb = simulate_block(10, 10, points_per_image=args.points, seed=3)
    a = run_apygis(sb)
    print(f"apygis:   {a}", file=sys.stderr)
    c = run_pycolmap(sb)
    print(f"pycolmap: {c}", file=sys.stderr)
    g = _child(False, args.points)
    print(f"graz:     {g}", file=sys.stderr)
    gr = _child(True, args.points)
    print(f"graz 5 % gross errors: {gr}", file=sys.stderr)
    out = {
        "images": sb.problem.n_images,
        "observations": len(sb.problem.obs_image),
        "apygis_s": round(a["seconds"], 3),
        "apygis_with_precisions_s": round(a["seconds_with_precisions"], 3),
        "pycolmap_s": round(c["seconds"], 3),
        "time_ratio": round(a["seconds"] / c["seconds"], 3),
        "apygis_sigma0": round(a["sigma0"], 4),
        "apygis_eo_normalised_rms": round(a["eo_normalised_rms"], 3),
        "pycolmap_rms_after_px": round(c["rms_after_px"], 4),
        "graz_images": g["images"],
        "graz_observations": g["observations"],
        "graz_s": round(g["seconds"], 2),
        "graz_peak_mb": round(g["peak_mb"], 1),
        "graz_sigma0_px": round(g["sigma0_px"], 4),
        "graz_robust_s": round(gr["seconds"], 2),
        "graz_robust_peak_mb": round(gr["peak_mb"], 1),
        "graz_robust_rejected": gr["rejected"],
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
