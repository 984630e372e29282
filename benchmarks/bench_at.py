"""apygis's tie points against COLMAP's SIFT matching, on one synthetic film block with truth.

The block (``apygis.aerotri.synth``: 3 strips x 6 images, 60 % / 30 % overlap,
3000 px scans by default) is rendered once into ``--folder`` (reused when it
is there). Then, in this process:

* **apygis**: ``apygis at init`` + ``match`` (pyramids, interior orientation,
  Förstner points, block formation, least-squares point tracking), local
  worker processes, one per core; timed from the image files to the tie points.
* **pycolmap** (``pip install apygis[bench]``): SIFT extraction (one camera
  for all images) and exhaustive matching with geometric verification, on the
  CPU; timed the same way. Its verified matches are linked into tracks with
  apygis's own linking.

Both are scored by :mod:`apygis.aerotri.score` the same way: a point's true
ground point is where the ray of its reference measurement (the one closest to
its image's centre) meets the true DEM; every other measurement is compared
with that ground point projected into its image. COLMAP's keypoints have the
origin at the corner of the top-left pixel and are shifted by half a pixel to
apygis's convention (centre of the top-left pixel at 0, 0).

``lsm_points_per_s`` times least-squares matching alone: all of apygis's
measurements of one image pair repeated at full resolution on one core (a
child process with one BLAS thread), from what the coarser pyramid level hands
over in the pipeline (a pass at level 1 from half a pixel off: its positions
and affine shapes);
``lsm_points_per_s_half_px`` from half a pixel off with level 1's affine shapes,
``lsm_points_per_s_identity_start`` from half a pixel off and the identity
affine (more iterations); measurements per second, each with its mean number
of iterations (``lsm_iterations_*``).

Run: ``python benchmarks/bench_at.py [--folder DIR] [--size PX] [--strips N] [--images N]``
Last line: one JSON object with the keys ``apygis_s``, ``pycolmap_s``,
``time_ratio``, ``apygis_rms_px``, ``apygis_median_px``, ``pycolmap_rms_px``,
``rms_ratio``, ``apygis_points_per_image``, ``pycolmap_points_per_image``,
``apygis_rays_per_point``, ``apygis_gross_pct`` and ``lsm_points_per_s``, and
more figures of both.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from apygis.aerotri.block import Block
from apygis.aerotri.match import MatchOptions, match_block
from apygis.aerotri.project import init_block, plan
from apygis.aerotri.score import score_block, score_tracks
from apygis.aerotri.synth import SynthSpec, load_truth, synth_block
from apygis.aerotri.tracks import link


def render(folder: Path, args) -> None:
    if (folder / "truth.json").is_file():
        return
    spec = SynthSpec(strips=args.strips, images_per_strip=args.images, size_px=args.size)
    t = time.perf_counter()
    synth_block(folder, spec)
    print(f"rendered {folder} in {time.perf_counter() - t:.0f} s", file=sys.stderr)


def run_apygis(folder: Path, work: Path, truth) -> dict:
    blk = work / "bench.block"
    t = time.perf_counter()
    init_block(
        blk,
        camera=folder / "camera.toml",
        images=folder / "images.csv",
        control=folder / "control.csv",
        overwrite=True,
    )
    with Block.open(blk) as b:
        plan(b)
        report = match_block(b, MatchOptions())
        seconds = time.perf_counter() - t
        score = score_block(b, truth)
        per_image = [n for _, n in b.conn.execute(
            "SELECT image, COUNT(*) FROM observations GROUP BY image")]  # fmt: skip
    rays = report.observations / max(report.points, 1)
    three = sum(v for k, v in report.multiplicity.items() if k >= 3) / max(report.points, 1)
    return {
        "seconds": seconds,
        "score": score.to_dict(),
        "points_per_image": float(np.mean(per_image)),
        "min_points_per_image": int(min(per_image)),
        "rays_per_point": rays,
        "share_3_or_more": three,
        "stages_s": report.seconds,
        "block": blk,
    }


def run_pycolmap(folder: Path, work: Path, truth) -> dict:
    import pycolmap

    db_path = work / "colmap.db"
    names = sorted(p.name for p in folder.glob("img_*.tif"))
    number = {name: int(name[4:-4]) for name in names}
    t = time.perf_counter()
    pycolmap.extract_features(
        db_path, folder, image_names=names, camera_mode=pycolmap.CameraMode.SINGLE,
        device=pycolmap.Device.cpu,
    )  # fmt: skip
    pycolmap.match_exhaustive(db_path, device=pycolmap.Device.cpu)
    seconds = time.perf_counter() - t
    db = pycolmap.Database.open(str(db_path))
    image_of = {im.image_id: number[im.name] for im in db.read_all_images()}
    keypoints = {i: db.read_keypoints(i)[:, :2] - 0.5 for i in image_of}
    pair_ids, geometries = db.read_two_view_geometries()
    matches = []
    for pid, g in zip(pair_ids, geometries, strict=True):
        m = np.asarray(g.inlier_matches)
        if len(m):
            i1, i2 = pycolmap.pair_id_to_image_pair(pid)
            matches.append((image_of[i1], image_of[i2], m[:, 0], m[:, 1]))
    db.close()
    kp = {image_of[i]: v for i, v in keypoints.items()}
    tracks = link(matches)
    scored = []
    for t_ in range(len(tracks)):
        nodes = tracks[t_]

        # the reference: the measurement closest to its image's centre (as apygis chooses)
        def off_centre(node):
            img, k = node
            w, h = truth.size[img]
            x, y = kp[img][k]
            return (x / w - 0.5) ** 2 + (y / h - 0.5) ** 2

        ref = min(nodes, key=off_centre)
        others = [(img, kp[img][k], None) for img, k in nodes if (img, k) != ref]
        scored.append((ref[0], kp[ref[0]][ref[1]], others))
    score = score_tracks(truth, scored)
    per_image: dict[int, int] = {}
    for t_ in range(len(tracks)):
        for img, _ in tracks[t_]:
            per_image[img] = per_image.get(img, 0) + 1
    mult = tracks.multiplicity
    return {
        "seconds": seconds,
        "score": score.to_dict(),
        "points_per_image": float(np.mean(list(per_image.values()))) if per_image else 0.0,
        "rays_per_point": float(mult.mean()) if len(mult) else 0.0,
        "points": len(tracks),
    }


def lsm_rate(blk: Path) -> dict[str, float]:
    """LSM measurements per second on one core at full resolution: the largest image pair's
    points again. Three starts: what level 1 hands over in the pipeline (a level-1 pass from
    half a pixel off, its positions and affine shapes mapped down), half a pixel off with
    level 1's affine shapes, half a pixel off with the identity affine. Each the best of
    three runs after a warm-up; with the mean number of iterations."""
    from apygis.aerotri.imagery import full_to_level
    from apygis.aerotri.lsm import FINE_SHIFT_PX, track
    from apygis.aerotri.pyramid import PyramidSource

    with Block.open(blk) as b:
        rows = b.conn.execute(
            "SELECT r.x_px, r.y_px, o.x_px, o.y_px, r.image, o.image FROM observations o "
            "JOIN observations r ON r.point = o.point AND r.source = 'lsm-ref' "
            "WHERE o.source = 'lsm'"
        ).fetchall()
        folder = b.pyramid_folder
    arr = np.array(rows)
    pairs, counts = np.unique(arr[:, 4:6], axis=0, return_counts=True)
    a, c = pairs[np.argmax(counts)]
    sel = arr[(arr[:, 4] == a) & (arr[:, 5] == c)]
    ref = PyramidSource(folder / f"{int(a)}.tif")
    search = PyramidSource(folder / f"{int(c)}.tif")
    rng = np.random.default_rng(0)
    start = sel[:, 2:4] + rng.normal(0, 0.5, (len(sel), 2))  # half a pixel off
    level1 = track(ref, search, sel[:, 0:2], full_to_level(start, 1), start=1, stop=1, half=10)
    keep = level1.ok  # the points level 1 hands over
    affine = level1.affine[keep]
    # below the start level the pipeline allows a move of FINE_SHIFT_PX (smaller atlases)
    starts = {
        "pipeline": (level1.xy[keep], affine, FINE_SHIFT_PX),
        "half_px": (start[keep], affine, None),
        "identity": (start[keep], None, None),
    }
    out = {}
    for name, (xy0, A, shift) in starts.items():
        r = []
        for _ in range(4):  # the first run warms caches and imports: the best of the others
            t = time.perf_counter()
            res = track(ref, search, sel[keep, 0:2], xy0, A, start=0, half=10, max_shift=shift)
            r.append(res.ok.sum() / (time.perf_counter() - t))
        out[name] = float(max(r[1:]))
        out[f"iterations_{name}"] = float(res.iterations.mean())
    return out


def lsm_rate_alone(blk: Path) -> dict[str, float]:
    """:func:`lsm_rate` in a child process with one BLAS thread: one core, as the goal is
    stated, and none of pycolmap's threads or memory left over in this process."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}  # fmt: skip
    out = subprocess.run(
        [sys.executable, __file__, "--lsm-rate", str(blk)],
        env=env, check=True, capture_output=True, text=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--folder", type=Path, default=None, help="synthetic block (rendered if absent)"
    )
    ap.add_argument("--size", type=int, default=3000)
    ap.add_argument("--strips", type=int, default=3)
    ap.add_argument("--images", type=int, default=6)
    ap.add_argument("--lsm-rate", type=Path, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.lsm_rate is not None:  # the child process of lsm_rate_alone
        print(json.dumps(lsm_rate(args.lsm_rate)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        folder = args.folder or work / "block"
        render(folder, args)
        truth = load_truth(folder / "truth.json")
        a = run_apygis(folder, work, truth)
        print(f"apygis:   {a['seconds']:.1f} s {a['score']}", file=sys.stderr)
        rates = lsm_rate_alone(a["block"])
        print(f"LSM at full resolution, one core: {rates}", file=sys.stderr)
        c = run_pycolmap(folder, work, truth)
        print(f"pycolmap: {c['seconds']:.1f} s {c['score']}", file=sys.stderr)
    out = {
        "images": len(truth.images),
        "size_px": args.size,
        "apygis_s": round(a["seconds"], 2),
        "pycolmap_s": round(c["seconds"], 2),
        "time_ratio": round(a["seconds"] / c["seconds"], 3),
        "apygis_rms_px": a["score"]["rms_px"],
        "apygis_median_px": a["score"]["median_px"],
        "apygis_p95_px": a["score"]["p95_px"],
        "apygis_sigma_ratio": a["score"]["sigma_ratio"],
        "pycolmap_rms_px": c["score"]["rms_px"],
        "pycolmap_median_px": c["score"]["median_px"],
        "pycolmap_p95_px": c["score"]["p95_px"],
        "pycolmap_gross_pct": c["score"]["gross_pct"],
        "rms_ratio": round(a["score"]["rms_px"] / c["score"]["rms_px"], 5),
        # against COLMAP's matches without its gross errors (> 1 px), which dominate its RMS
        "pycolmap_core_rms_px": c["score"]["core_rms_px"],
        "core_rms_ratio": round(a["score"]["core_rms_px"] / c["score"]["core_rms_px"], 3),
        "apygis_points_per_image": round(a["points_per_image"], 1),
        "apygis_min_points_per_image": a["min_points_per_image"],
        "pycolmap_points_per_image": round(c["points_per_image"], 1),
        "apygis_rays_per_point": round(a["rays_per_point"], 3),
        "apygis_share_3_or_more": round(a["share_3_or_more"], 3),
        "pycolmap_rays_per_point": round(c["rays_per_point"], 3),
        "apygis_gross_pct": a["score"]["gross_pct"],
        "lsm_points_per_s": round(rates["pipeline"], 1),
        "lsm_points_per_s_half_px": round(rates["half_px"], 1),
        "lsm_points_per_s_identity_start": round(rates["identity"], 1),
        "lsm_iterations_pipeline": round(rates["iterations_pipeline"], 2),
        "lsm_iterations_half_px": round(rates["iterations_half_px"], 2),
        "lsm_iterations_identity_start": round(rates["iterations_identity"], 2),
        "apygis_stages_s": a["stages_s"],
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
