"""Block preparation: ``apygis at init`` and ``apygis at plan`` as library calls.

:func:`init_block` creates the block database from a camera protocol (or the
images' EXIF), an image list (or a folder of images with EXIF GPS) and
optional control points. Approximate projection centres from EXIF GPS
(WGS 84 latitude/longitude/altitude) are transformed to the block CRS (the
UTM zone of the block's centre unless ``crs`` is given); images without a
strip get one from the flight track (:func:`apygis.aerotri.plan.strips_from_track`,
in EXIF time order).

:func:`plan` computes footprints, overlaps, strips, the pairs to match and
subblocks (:mod:`apygis.aerotri.plan`), stores strips, subblocks and pairs in
the block, and returns the plan.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from apygis.aerotri import plan as planning
from apygis.aerotri.block import Block, BlockError
from apygis.aerotri.camera import Camera, read_camera
from apygis.aerotri.inputs import (
    ImageEntry,
    image_folder,
    read_control,
    read_exif,
    read_image_list,
    utm_crs,
)
from apygis.errors import CRSError, FormatError

__all__ = ["InitReport", "block_plan", "camera_from_exif", "init_block", "plan", "terrain_height"]

#: The diagonal of the 36 x 24 mm frame that "35 mm equivalent" focal lengths refer to.
DIAGONAL_35MM = math.hypot(36.0, 24.0)


@dataclass
class InitReport:
    """What :func:`init_block` did (for the CLI to print)."""

    block: Path
    images: int
    strips: int
    control: int
    crs: str
    camera: str
    positions_from_exif: int
    notes: list[str]


def camera_from_exif(
    focal_mm: float, focal_35mm: float, width: int, height: int, name: str
) -> Camera:
    """A digital camera from EXIF: the sensor diagonal is ``43.27 mm * f / f35``.

    The 35 mm equivalent focal length ``f35`` scales the 36 x 24 mm frame's
    diagonal to the sensor's, so the pixel pitch is
    ``p = 43.27 mm * f / f35 / hypot(W, H)`` for a raster of ``W x H`` pixels
    (the raster as it is, whatever the EXIF size fields say). Principal point
    at the centre and no distortion: a first approximation that a
    self-calibrating adjustment refines.
    """
    diag = DIAGONAL_35MM * focal_mm / focal_35mm
    pixel_um = diag / math.hypot(width, height) * 1000.0
    return Camera(name, "digital", focal_mm, pixel_um=pixel_um, sensor_px=(width, height))


def _raster_size(path: Path) -> tuple[int, int]:
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as src:
                return src.width, src.height
    except RasterioIOError as exc:
        raise FormatError(f"{path}: cannot read the image ({exc})") from None


def init_block(
    block_path,
    *,
    camera,
    images,
    control=None,
    crs: str | None = None,
    overwrite: bool = False,
    terrain_z: float | None = None,
    tie_names: tuple[int, int] = (1000000, 1),
    progress=None,
) -> InitReport:
    """Create a block (see the module docstring).

    ``camera`` is a camera file or ``"exif"``; ``images`` an image list (CSV)
    or a folder of images (numbered in name order, positions from EXIF).
    ``progress(done, total)`` (:mod:`apygis.progress`) counts the images read.
    """
    notes: list[str] = []
    images = Path(images)
    entries: list[ImageEntry] = image_folder(images) if images.is_dir() else read_image_list(images)
    sizes: dict[int, tuple[int, int]] = {}
    exif = {}
    for k, e in enumerate(entries):
        if not e.path.is_file():
            raise FormatError(f"{images}: image {e.image}: file {e.path} not found")
        sizes[e.image] = _raster_size(e.path)
        if e.from_exif or str(camera) == "exif":
            exif[e.image] = read_exif(e.path)
        if progress is not None:
            progress(k + 1, len(entries) + 1)
    # the camera
    if str(camera) == "exif":
        first = exif[entries[0].image]
        if first.focal_mm is None or first.focal_35mm is None:
            raise FormatError(
                f"{entries[0].path}: EXIF has no focal length and 35 mm equivalent "
                "(give a camera file with --camera)"
            )
        w, h = sizes[entries[0].image]
        cam = camera_from_exif(
            first.focal_mm, first.focal_35mm, w, h, f"{first.make} {first.model}".strip()
        )
        notes.append(
            f"camera from EXIF: f = {cam.focal_mm} mm, pixel {cam.pixel_um:.3f} um "
            f"(from the 35 mm equivalent {first.focal_35mm} mm), principal point at the centre"
        )
    else:
        cam = read_camera(camera)
    for e in entries:
        w, h = sizes[e.image]
        if cam.kind == "digital" and cam.sensor_px and (w, h) != tuple(cam.sensor_px):
            raise FormatError(
                f"{e.path}: image {e.image} is {w} x {h} pixels, the camera's sensor "
                f"{cam.sensor_px[0]} x {cam.sensor_px[1]}"
            )
    # positions from EXIF, in the block CRS
    wanted = [e for e in entries if e.from_exif]
    if wanted:
        missing = [
            e.image for e in wanted if exif[e.image].lat is None or exif[e.image].lon is None
        ]
        if missing:
            raise FormatError(
                f"{entries[0].path.parent}: images {missing[:5]} have no EXIF GPS position "
                "(give an image list with X, Y, Z)"
            )
        lat = np.array([exif[e.image].lat for e in wanted], dtype=float)
        lon = np.array([exif[e.image].lon for e in wanted], dtype=float)
        if not crs:
            crs = utm_crs(float(lon.mean()), float(lat.mean()))
            notes.append(f"block CRS {crs} (the UTM zone of the EXIF positions)")
        from pyproj import CRS, Transformer
        from pyproj.exceptions import CRSError as ProjCRSError

        try:
            t = Transformer.from_crs(CRS.from_epsg(4326), CRS.from_user_input(crs), always_xy=True)
        except ProjCRSError as exc:
            raise CRSError(f"--crs {crs}: not a CRS pyproj knows ({exc})") from None
        X, Y = t.transform(lon, lat)
        for e, x, y in zip(wanted, X, Y, strict=True):
            e.X, e.Y = float(x), float(y)
            e.Z = exif[e.image].alt_m
        notes.append(
            "EXIF GPS altitudes are taken as projection-centre heights; consumer drones record "
            "height above take-off, so give --terrain-height accordingly (metres: consumer GPS)"
        )
    # strips from the track where the list has none
    if any(e.strip is None for e in entries):
        known = [e for e in entries if e.X is not None and e.Y is not None]
        if len(known) != len(entries):
            raise FormatError(f"{images}: images without strip numbers need approximate positions")

        def when(e: ImageEntry):
            t = exif.get(e.image).time if e.image in exif else None  # type: ignore[union-attr]
            return (t or "", e.image)

        order = sorted(entries, key=when)
        track = [planning.PlanImage(e.image, 0, e.X or 0.0, e.Y or 0.0, e.Z or 0.0) for e in order]
        lines = planning.strips_from_track(track)
        for e in entries:
            e.strip = lines.get(e.image, 0)
        notes.append(f"strips from the flight track: {len(set(lines.values()))} lines")
    block = Block.create(block_path, crs=crs or "", overwrite=overwrite)
    try:
        cam_id = block.add_camera(cam)
        block.add_images(
            {
                "image": e.image,
                "strip": e.strip,
                "camera": cam_id,
                "path": e.path,
                "width": sizes[e.image][0],
                "height": sizes[e.image][1],
                "X": e.X,
                "Y": e.Y,
                "Z": e.Z,
                "heading_deg": e.heading_deg,
                "position_source": "exif" if e.from_exif else ("list" if e.X is not None else ""),
                "exif_time": exif[e.image].time if e.image in exif else None,
            }
            for e in entries
        )
        points = read_control(control) if control else []
        block.add_points(
            {
                "name": p.name,
                "kind": p.kind,
                "X": p.X,
                "Y": p.Y,
                "Z": p.Z,
                "sigma_xy_m": p.sigma_xy_m,
                "sigma_z_m": p.sigma_z_m,
            }
            for p in points
        )
        if terrain_z is not None:
            block.set_meta("terrain_z", terrain_z)
        block.set_meta("tie_name_start", tie_names[0])
        block.set_meta("tie_name_next", tie_names[0])
        block.set_meta("tie_name_interval", tie_names[1])
        block.set_meta("notes", "\n".join(notes))
        run = block.start_run("init", {"camera": str(camera), "images": str(images)})
        block.finish_run(run, "done", {"images": len(entries), "control": len(points)})
    except BaseException:
        block.close()
        Path(block_path).unlink(missing_ok=True)
        raise
    block.close()
    if progress is not None:
        progress(len(entries) + 1, len(entries) + 1)
    return InitReport(
        Path(block_path),
        len(entries),
        len({e.strip for e in entries}),
        len(points),
        crs or "",
        cam.name,
        len(wanted),
        notes,
    )


def terrain_height(block: Block, override: float | None = None) -> float:
    """The mean terrain height of a block: the option, the stored value, or the control's mean."""
    if override is not None:
        return float(override)
    stored = block.meta("terrain_z")
    if stored:
        return float(stored)
    zs = [p["Z"] for p in block.control() if p["Z"] is not None]
    if zs:
        return float(np.mean(zs))
    if all(im.position_source == "exif" for im in block.images()):
        return 0.0  # consumer drones: altitudes above take-off, terrain near 0
    raise BlockError(
        f"{block.path}: the mean terrain height is unknown "
        "(give --terrain-height, or control points)"
    )


def block_plan(
    block: Block,
    *,
    terrain_z: float | None = None,
    subblock_strips: int | None = None,
    max_pairs_per_image: int | None = None,
    min_overlap: float = 0.1,
) -> planning.BlockPlan:
    """The plan of an open block (nothing stored)."""
    images = block.images()
    missing = [im.image for im in images if im.X is None or im.Y is None or im.Z is None]
    if missing:
        raise BlockError(
            f"{block.path}: images {missing[:5]} have no approximate projection centre "
            "(planning needs X, Y, Z in the image list or EXIF GPS)"
        )
    cams = block.cameras()
    cam = cams[images[0].camera]
    frame = planning.Frame.from_camera(cam)
    pimages = [
        planning.PlanImage(
            im.image,
            im.strip or 0,
            float(im.X or 0),
            float(im.Y or 0),
            float(im.Z or 0),
            im.heading_deg,
            im.x_azimuth_deg,
        )
        for im in images
    ]
    z = terrain_height(block, terrain_z)
    if max_pairs_per_image is None and len(images) > 2:
        max_pairs_per_image = 10
    return planning.plan_block(
        pimages,
        frame,
        z,
        min_overlap=min_overlap,
        subblock_strips=subblock_strips,
        max_pairs_per_image=max_pairs_per_image,
    )


def plan(block: Block, **kw) -> planning.BlockPlan:
    """Plan a block and store strips, subblocks, derived headings and pairs in it."""
    p = block_plan(block, **kw)
    block.set_strips({s.number: (s.kind, s.direction_deg) for s in p.strips.values()})
    block.set_subblocks(p.subblocks)
    block.set_pairs((pr.a, pr.b, pr.kind, pr.overlap) for pr in p.pairs)
    block.update_images(
        {
            im.image: {"heading_deg": p.headings[im.image]}
            for im in block.images()
            if im.heading_deg is None
        }
    )
    if kw.get("terrain_z") is not None:
        block.set_meta("terrain_z", kw["terrain_z"])
    return p
