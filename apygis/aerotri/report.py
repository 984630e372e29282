"""What a block holds, as numbers (``apygis at info``), text, the block display, and CSV.

:func:`block_info` gathers images, interior orientations, pairs, points by
multiplicity (the seed's Table 3: how many points are measured in 2, 3, ...
images), observations per image and the von Gruber gaps per model.
:func:`export_tiepoints` writes one row per observation::

    point,image,x_px,y_px,x_mm,y_mm,sigma_px

``point`` the tie point name, ``image`` the image number of the image list,
``x_px, y_px`` pixel coordinates (column right, row down, centre of the
top-left pixel at 0, 0) at full resolution, ``x_mm, y_mm`` photo coordinates
(x right, y up, millimetres; through the image's interior orientation, not
corrected for distortion), ``sigma_px`` the measurement's standard deviation
(pixels, from least-squares matching).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from apygis.aerotri.block import Block
from apygis.fileio import atomic_write

__all__ = ["block_display_for", "block_info", "export_tiepoints", "info_text"]

EXPORT_COLUMNS = ("point", "image", "x_px", "y_px", "x_mm", "y_mm", "sigma_px")


def export_tiepoints(block: Block, path) -> int:
    """Write the tie point observations to ``path`` (CSV, atomically); returns the rows."""
    rows = block.conn.execute(
        "SELECT p.name, o.image, o.x_px, o.y_px, o.x_mm, o.y_mm, o.sigma_px "
        "FROM observations o JOIN points p ON p.id = o.point WHERE p.kind = 'tie' "
        "ORDER BY p.id, o.image"
    ).fetchall()
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(EXPORT_COLUMNS)
    for name, image, x, y, xm, ym, s in rows:
        w.writerow(
            [name, image, f"{x:.4f}", f"{y:.4f}", f"{xm:.5f}", f"{ym:.5f}",
             "" if s is None else f"{s:.4f}"]
        )  # fmt: skip
    atomic_write(Path(path), buf.getvalue(), parents=True)
    return len(rows)


def block_info(block: Block) -> dict:
    """The block's state as a JSON-ready dict (see the module docstring)."""
    images = block.images()
    interior = block.interior()
    pairs = block.pairs()
    mult = dict(
        block.conn.execute(
            "SELECT n, COUNT(*) FROM (SELECT COUNT(*) AS n FROM observations o "
            "JOIN points p ON p.id = o.point WHERE p.kind = 'tie' GROUP BY o.point) "
            "GROUP BY n ORDER BY n"
        ).fetchall()
    )
    per_image = dict(
        block.conn.execute(
            "SELECT o.image, COUNT(*) FROM observations o JOIN points p ON p.id = o.point "
            "WHERE p.kind = 'tie' GROUP BY o.image"
        ).fetchall()
    )
    gaps: dict[str, list[int]] = {}
    for a, b, region, count in block.conn.execute("SELECT a, b, region, count FROM gaps"):
        if count < 3:
            gaps.setdefault(f"{a}-{b}", []).append(region)
    points = sum(mult.values())
    rays = sum(k * v for k, v in mult.items())
    control = block.control()
    cams = block.cameras()
    return {
        "block": str(block.path),
        "crs": block.crs,
        "cameras": [c.to_dict() for c in cams.values()],
        "images": [
            {
                "image": im.image,
                "strip": im.strip,
                "file": str(im.path),
                "width": im.width,
                "height": im.height,
                "centre": [im.X, im.Y, im.Z],
                "heading_deg": im.heading_deg,
                "position_source": im.position_source,
                "interior": _interior_summary(interior.get(im.image)),
                "observations": int(per_image.get(im.image, 0)),
            }
            for im in images
        ],
        "strips": {
            str(k): {"kind": v[0], "direction_deg": v[1]} for k, v in block.strips().items()
        },
        "subblocks": block.subblocks(),
        "pairs": {
            "planned": len(pairs),
            "matched": sum(p["status"] == "matched" for p in pairs),
            "failed": [
                f"{p['a']}-{p['b']}: {p['reason']}" for p in pairs if p["status"] == "failed"
            ],
        },
        "control": {
            k: sum(c["kind"] == k for c in control)
            for k in ("full", "planimetric", "height", "check")
        },
        "tie_points": {
            "points": points,
            "observations": rays,
            "multiplicity": {str(k): int(v) for k, v in mult.items()},
            "rays_per_point": round(rays / points, 3) if points else None,
            "share_3_or_more": round(sum(v for k, v in mult.items() if k >= 3) / points, 4)
            if points
            else None,
            "per_image_mean": round(float(np.mean(list(per_image.values()))), 1)
            if per_image
            else 0,
            "per_image_min": int(min(per_image.values())) if per_image else 0,
        },
        "gaps": gaps,
        "runs": [
            {k: r[k] for k in ("id", "command", "started", "finished", "status")}
            for r in block.runs()
        ],
    }


def _interior_summary(d: dict | None) -> dict | None:
    if d is None:
        return None
    return {
        "model": d.get("model"),
        "rms_um": d.get("rms_um"),
        "max_um": d.get("max_um"),
        "flagged": bool(d.get("flagged")),
        "dihedral": d.get("dihedral"),
        "missing": d.get("missing", []),
    }


def info_text(info: dict) -> str:
    """The block as text, with the multiplicity table laid out like the seed's Table 3."""
    lines = [f"block {info['block']}  CRS {info['crs'] or '(none)'}"]
    for c in info["cameras"]:
        extra = (
            f"{len(c['fiducials'])} fiducials"
            if c["kind"] == "film"
            else f"pixel {c['pixel_um']:.3f} um, {c['sensor_px'][0]} x {c['sensor_px'][1]} px"
        )
        lines.append(f"camera {c['name']}: {c['kind']}, c = {c['focal_mm']} mm, {extra}")
    ims = info["images"]
    lines.append(f"images: {len(ims)} in {len({i['strip'] for i in ims})} strips")
    io_done = [i for i in ims if i["interior"] is not None]
    if io_done:
        film = [i for i in io_done if i["interior"]["rms_um"] is not None]
        if film:
            rms = [i["interior"]["rms_um"] for i in film]
            lines.append(
                f"interior orientation: {len(film)} scans, rms {np.mean(rms):.2f} um "
                f"(max {max(i['interior']['max_um'] for i in film):.2f} um)"
            )
            for i in film:
                if i["interior"]["flagged"]:
                    lines.append(
                        f"  image {i['image']}: FLAGGED, "
                        f"max residual {i['interior']['max_um']:.1f} um"
                    )
        else:
            lines.append(f"interior orientation: {len(io_done)} digital images (fixed)")
    p = info["pairs"]
    lines.append(
        f"pairs: {p['planned']} planned, {p['matched']} matched, {len(p['failed'])} failed"
    )
    lines += [f"  failed {f}" for f in p["failed"]]
    c = info["control"]
    lines.append(
        f"control: {c['full']} full, {c['planimetric']} planimetric, {c['height']} height, "
        f"{c['check']} check points"
    )
    t = info["tie_points"]
    if t["points"]:
        mult = t["multiplicity"]
        keys = sorted(mult, key=int)
        lines.append("tie points by multiplicity (images per point):")
        lines.append("  " + "".join(f"{k + '-fold':>9}" for k in keys) + f"{'total':>9}")
        lines.append("  " + "".join(f"{mult[k]:>9}" for k in keys) + f"{t['points']:>9}")
        lines.append(
            f"  {t['observations']} observations, {t['rays_per_point']} rays per point, "
            f"{100 * t['share_3_or_more']:.1f} % in 3 or more images"
        )
        lines.append(f"  per image: mean {t['per_image_mean']}, least {t['per_image_min']}")
    else:
        lines.append("tie points: none yet (run 'apygis at match')")
    if info["gaps"]:
        lines.append(
            f"gaps (von Gruber regions with fewer than 3 points): {len(info['gaps'])} models"
        )
        for k, regions in sorted(info["gaps"].items()):
            lines.append(f"  model {k}: regions {', '.join(str(r) for r in regions)}")
    return "\n".join(lines) + "\n"


def points_per_model(block: Block) -> dict[tuple[int, int], int]:
    """Tie points measured in both images of each planned pair (model)."""
    planned = {(p["a"], p["b"]) for p in block.pairs()}
    rows = block.conn.execute(
        "SELECT o1.image, o2.image, COUNT(*) FROM observations o1 "
        "JOIN observations o2 ON o1.point = o2.point AND o1.image < o2.image "
        "JOIN points p ON p.id = o1.point WHERE p.kind = 'tie' GROUP BY 1, 2"
    ).fetchall()
    return {(a, b): int(n) for a, b, n in rows if (a, b) in planned}


def block_display_for(block: Block, plan, path) -> Path:
    """The block display of an open block: plan, control, tie points per model and gaps."""
    from apygis.aerotri import plan as planning
    from apygis.aerotri.display import block_display

    control = [(c["name"], c["X"], c["Y"], c["kind"]) for c in block.control()]
    counts = points_per_model(block)
    gaps: dict[tuple[int, int], list] = {}
    for a, b, region, count in block.conn.execute("SELECT a, b, region, count FROM gaps"):
        if count < 3:
            gaps.setdefault((a, b), []).append(region)
    gap_polys = {}
    for (a, b), regions in gaps.items():
        try:
            polys = planning.gruber_regions(plan, (a, b))
        except Exception:  # a pair no longer in the plan
            continue
        gap_polys[(a, b)] = [polys[r] for r in regions]
    return block_display(
        plan,
        path,
        control=control or None,
        points_per_pair=counts or None,
        gaps=gap_polys or None,
        title=f"{block.path.name}: {len(plan.images)} images",
        crs=block.crs or None,
    )
