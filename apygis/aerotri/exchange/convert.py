"""The block database and the neutral :class:`~apygis.aerotri.exchange.ExchangeBlock`.

* :func:`block_to_exchange`: cameras, images (with their interior orientations and, once
  adjusted, exterior orientations and standard deviations), points (control and check
  points with their given coordinates and sigmas, tie and new points with their adjusted
  ones) and observations (pixels and photo millimetres, as measured). Observations the
  last adjustment rejected are left out unless ``rejected=True`` (counted in
  ``skipped``).
* :func:`import_block`: a new block from an exchange block that carries images, cameras
  and pixel transforms (a COLMAP model): its tie points and observations (``source``
  ``import``), its poses as the starting values of the adjustment. A model in a frame of
  its own (COLMAP's, unless georeferenced: ``frame="local"``) is placed on the control by
  the adjustment (``meta.exterior_frame``); ``frame="crs"`` takes it as in the block CRS.
* :func:`import_control`: control points and their image measurements (OpenDroneMap's
  ``gcp_list.txt``, MicMac's files) into an existing block: images matched by file name,
  points added where new (``full``; ``planimetric`` without height), measurements as
  manual ones.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from apygis.aerotri.block import Block, BlockError
from apygis.aerotri.camera import Camera, PixelTransform
from apygis.aerotri.exchange import (
    ExCamera,
    ExchangeBlock,
    ExImage,
    ExObservation,
    ExPoint,
    complete_observations,
)

__all__ = ["block_to_exchange", "import_block", "import_control"]

#: Sigmas (m, plan and height) of imported control points that carry none.
IMPORT_CONTROL_SIGMA = (0.05, 0.1)


def block_to_exchange(block: Block, *, rejected: bool = False) -> ExchangeBlock:
    """The block as an :class:`ExchangeBlock` (module docstring)."""
    cams = block.cameras()
    interior = block.interior()
    xb = ExchangeBlock(crs=block.crs)
    for cid, c in cams.items():
        xb.cameras.append(
            ExCamera(
                id=cid, name=c.name, focal_mm=c.focal_mm, x0_mm=c.x0_mm, y0_mm=c.y0_mm,
                kind=c.kind, width_px=c.sensor_px[0] if c.sensor_px else None,
                height_px=c.sensor_px[1] if c.sensor_px else None,
                pixel_mm=c.pixel_um / 1000.0 if c.pixel_um else None,
                radial_mm=tuple(c.distortion_radius_mm), radial_um=tuple(c.distortion_dr_um),
            )
        )  # fmt: skip
    ext = {
        r[0]: (np.array(r[1:7], float), np.array([np.nan if v is None else v for v in r[7:]]))
        for r in block.conn.execute(
            "SELECT image, X, Y, Z, omega, phi, kappa, sX, sY, sZ, somega, sphi, skappa "
            "FROM exterior"
        )
    }
    for im in block.images():
        T = interior.get(im.image)
        eo, sd = ext.get(im.image, (None, None))
        xb.images.append(
            ExImage(
                image=im.image, name=Path(im.path).name, camera=im.camera,
                pixel_to_mm=None if T is None else PixelTransform.from_list(T["transform"]).matrix,
                width_px=im.width, height_px=im.height, eo=eo, eo_std=sd,
            )
        )  # fmt: skip
    adj = {
        r[0]: (np.array(r[1:4], float), np.array([np.nan if v is None else v for v in r[4:]]))
        for r in block.conn.execute("SELECT point, X, Y, Z, sX, sY, sZ FROM adjusted_points")
    }
    names = {}
    for pid, name, kind, X, Y, Z, sxy, sz in block.conn.execute(
        "SELECT id, name, kind, X, Y, Z, sigma_xy_m, sigma_z_m FROM points ORDER BY id"
    ):
        names[pid] = name
        if kind in ("full", "planimetric", "height", "check"):
            xyz = np.array([np.nan if v is None else v for v in (X, Y, Z)], float)
            s = np.array([np.nan if v is None else v for v in (sxy, sxy, sz)], float)
            xb.points.append(ExPoint(name, kind, xyz, s))
        elif pid in adj:
            xb.points.append(ExPoint(name, kind, adj[pid][0], adj[pid][1]))
        else:
            xb.points.append(ExPoint(name, kind))
    bad = {
        (p, i)
        for p, i in block.conn.execute("SELECT point, image FROM residuals WHERE rejected = 1")
    }
    left_out = 0
    for pid, img, x, y, xm, ym, s in block.conn.execute(
        "SELECT point, image, x_px, y_px, x_mm, y_mm, sigma_px FROM observations "
        "ORDER BY point, image"
    ):
        if not rejected and (pid, img) in bad:
            left_out += 1
            continue
        xb.observations.append(ExObservation(names[pid], img, xm, ym, x, y, s))
    if left_out:
        xb.skipped["observations rejected by the last adjustment"] = left_out
    return xb


def import_block(
    xb: ExchangeBlock, path, *, images_folder, frame: str = "local", overwrite: bool = False
) -> dict:
    """Create a block at ``path`` from ``xb`` (module docstring); image files are looked up
    in ``images_folder`` by name. Returns counts."""
    if frame not in ("local", "crs"):
        raise BlockError(f"frame is 'local' or 'crs', not {frame!r}")
    folder = Path(images_folder)
    complete_observations(xb)
    missing = [im.name for im in xb.images if not (folder / im.name).is_file()]
    if missing:
        raise BlockError(
            f"{folder}: {len(missing)} images of the model are not there (first: {missing[0]})"
        )
    for im in xb.images:
        if im.camera is None or im.pixel_to_mm is None or im.width_px is None:
            raise BlockError(
                f"image {im.image} ({im.name}): the model gives no camera or raster size; "
                "only a model with cameras (COLMAP) imports as a block"
            )
    block = Block.create(path, crs=xb.crs, overwrite=overwrite)
    try:
        cam_ids = {}
        for c in xb.cameras:
            if c.pixel_mm is None or c.width_px is None or c.height_px is None:
                raise BlockError(f"camera {c.id} ({c.name}): no pixel pitch or sensor size")
            cam = Camera(
                name=c.name or f"camera {c.id}", kind="digital", focal_mm=c.focal_mm,
                x0_mm=c.x0_mm, y0_mm=c.y0_mm, pixel_um=c.pixel_mm * 1000.0,
                sensor_px=(int(c.width_px), int(c.height_px)),
                distortion_radius_mm=tuple(c.radial_mm), distortion_dr_um=tuple(c.radial_um),
            )  # fmt: skip
            cam_ids[c.id] = block.add_camera(cam)
        block.add_images(
            {
                "image": im.image, "strip": None, "camera": cam_ids[int(im.camera or 0)],
                "path": folder / im.name, "width": im.width_px, "height": im.height_px,
                "position_source": "import",
            }
            for im in xb.images
        )  # fmt: skip
        for im in xb.images:
            block.set_interior(
                im.image,
                {"model": "imported", "transform": np.asarray(im.pixel_to_mm).tolist(),
                 "rms_um": None, "max_um": None, "flagged": False},
            )  # fmt: skip
        ids = block.add_points(
            {"name": p.name, "kind": p.kind if p.kind != "tie" else "tie"} for p in xb.points
        )
        rows = [
            (ids[o.point], o.image, o.x_px, o.y_px, o.x_mm, o.y_mm, o.sigma_px, None, "import")
            for o in xb.observations
            if o.point in ids and o.x_px is not None and o.x_mm is not None
        ]
        with block.conn:
            block.conn.executemany("INSERT INTO observations VALUES (?,?,?,?,?,?,?,?,?)", rows)
        oriented = [im for im in xb.images if im.eo is not None]
        if oriented:
            with block.conn:
                cur = block.conn.execute(
                    "INSERT INTO adjustments (started, finished, options, report) "
                    "VALUES (datetime('now'), datetime('now'), ?, NULL)",
                    ('{"import": "exchange model"}',),
                )
                adj = int(cur.lastrowid or 0)
                block.conn.executemany(
                    "INSERT INTO exterior VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                    [(im.image, adj, *(float(v) for v in np.asarray(im.eo)), None, None, None,
                      None, None, None) for im in oriented],
                )  # fmt: skip
            block.set_meta("exterior_frame", frame)
    finally:
        block.close()
    return {
        "images": len(xb.images),
        "points": len(xb.points),
        "observations": len(rows),
        "oriented": len(oriented),
    }


def import_control(block: Block, xb: ExchangeBlock) -> dict:
    """Control points and their image measurements from ``xb`` into ``block`` (module
    docstring). Returns counts; images not in the block and points without coordinates are
    counted as skipped."""
    by_name = {Path(im.path).name: im.image for im in block.images()}
    xb_images = {im.image: im.name for im in xb.images}
    existing = {
        n: (pid, kind) for pid, n, kind in block.conn.execute("SELECT id, name, kind FROM points")
    }
    new = []
    skipped: dict[str, int] = dict(xb.skipped)
    for p in xb.points:
        if p.name in existing:
            continue
        xyz = p.xyz
        if xyz is None or not np.isfinite(xyz[:2]).all():
            skipped["points without coordinates"] = skipped.get("points without coordinates", 0) + 1
            continue
        kind = p.kind if p.kind in ("full", "planimetric", "height", "check") else "full"
        if kind == "full" and not math.isfinite(float(xyz[2])):
            kind = "planimetric"
        sxy, sz = IMPORT_CONTROL_SIGMA
        if p.sigma is not None and np.isfinite(p.sigma[0]):
            sxy = float(p.sigma[0])
        if p.sigma is not None and len(p.sigma) > 2 and np.isfinite(p.sigma[2]):
            sz = float(p.sigma[2])
        new.append({
            "name": p.name, "kind": kind, "X": float(xyz[0]), "Y": float(xyz[1]),
            "Z": float(xyz[2]) if math.isfinite(float(xyz[2])) else None,
            "sigma_xy_m": sxy, "sigma_z_m": sz,
        })  # fmt: skip
    if new:
        block.add_points(new)
    ids = {n: pid for pid, n in block.conn.execute("SELECT id, name FROM points")}
    interior = block.interior()
    rows = []
    for o in xb.observations:
        img = by_name.get(xb_images.get(o.image, ""))
        if img is None:
            skipped["measurements in images not in the block"] = (
                skipped.get("measurements in images not in the block", 0) + 1
            )
            continue
        if o.point not in ids or o.x_px is None or o.y_px is None:
            skipped["measurements of unknown points or without pixels"] = (
                skipped.get("measurements of unknown points or without pixels", 0) + 1
            )
            continue
        if img not in interior:
            raise BlockError(
                f"{block.path}: image {img} has no interior orientation yet ('apygis at match')"
            )
        mm = PixelTransform.from_list(interior[img]["transform"]).to_mm([[o.x_px, o.y_px]])[0]
        s = o.sigma_px if o.sigma_px is not None else 0.3
        rows.append((ids[o.point], img, o.x_px, o.y_px, float(mm[0]), float(mm[1]), s, None,
                     "manual"))  # fmt: skip
    with block.conn:
        block.conn.executemany(
            "INSERT OR REPLACE INTO observations VALUES (?,?,?,?,?,?,?,?,?)", rows
        )
    return {"points_added": len(new), "measurements": len(rows), "skipped": skipped}
