"""PAT-B: a block as PAT-B's image-coordinate, control and exterior orientation files.

``write_patb(block, "out/blk")`` writes ``out/blk.im`` (the photo coordinates of every
observation, micrometres), ``out/blk.con`` (the full control points) when the block
has any, and ``out/blk.ori`` (the exterior orientations) when any image has one; the
record layouts are :mod:`apygis.formats.patb`'s, the format ``docs/formats/patb.md``.
``read_patb("out/blk")`` (or any one of the files, or an image-coordinate file of
another name such as the ``.patb`` the map driver writes) reads the files of the set
that exist.

What PAT-B's three files cannot hold is left out and counted in the
:class:`~apygis.aerotri.exchange.WriteReport` (and logged): cameras and pixel
transforms (PAT-B keeps the camera in its own camera file), observation sigmas,
planimetric, height and check points (the control file has full control only),
adjusted coordinates of tie and new points (PAT-B writes those itself), and the
standard deviations of the orientations. Observations without photo coordinates and
without a pixel transform to make them are left out too.

Conventions: photo coordinates x right, y up, mm in the block (micrometres in the
file); ground metres; the rotation matrix of :mod:`apygis.orient.rotation`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from apygis.aerotri.exchange import (
    ExchangeBlock,
    ExImage,
    ExObservation,
    ExPoint,
    WriteReport,
)
from apygis.aerotri.exchange._common import (
    Index,
    base_path,
    control_xyz_ok,
    finite_xyz,
    photo_rows,
    read_set,
)
from apygis.errors import DegenerateGeometryError, FormatError
from apygis.fileio import atomic_write_many, read_bytes
from apygis.formats import patb as layout
from apygis.formats._records import MAX_BYTES
from apygis.orient.rotation import angles_from_matrix, nearest_rotation, rotation_matrix

__all__ = ["SUFFIXES", "read_patb", "write_patb"]

SUFFIXES = (".im", ".con", ".ori")
"""The files of a PAT-B set: image coordinates, control, exterior orientations."""


def write_patb(block: ExchangeBlock, target) -> WriteReport:
    """Write ``block`` as PAT-B files ``<target>.im``, ``.con`` and ``.ori`` (see the module
    docstring); ``target`` may carry one of those suffixes. All files are written
    atomically, after every check passed.

    Raises :class:`~apygis.errors.ValueRangeError` naming the file and the record for a
    point name of more than 15 characters or holding a blank, a photo number beyond
    I16, a value that does not fit its field.
    """
    base = base_path(target, SUFFIXES)
    files = {s: base.with_name(base.name + s) for s in SUFFIXES}
    idx = Index(block, base)
    report = WriteReport()
    rows, n_obs = photo_rows(idx, report, lambda ob, image: ob.point, "PAT-B's image file")
    contents: dict[Path, bytes] = {
        files[".im"]: layout.encode_image_coordinates(rows, files[".im"])
    }
    control = []
    for p in block.points:
        xyz = finite_xyz(p)
        if p.kind == "full" and control_xyz_ok(p, xyz):
            control.append((p.name, *xyz.tolist()))  # type: ignore[union-attr]  # checked
            if p.sigma is not None:
                report.skip("control sigmas (PAT-B's control file has none)")
        elif p.kind == "full":
            report.skip("full control points without coordinates")
        elif p.kind in ("planimetric", "height", "check"):
            report.skip(f"{p.kind} points (PAT-B's control file has full control only)")
        elif xyz is not None:
            report.skip("adjusted coordinates of tie and new points (PAT-B computes them)")
    if control:
        contents[files[".con"]] = layout.encode_control(control, files[".con"])
    oris = []
    for im in sorted(block.images, key=lambda i: i.image):
        if im.eo is None:
            continue
        eo = np.asarray(im.eo, dtype=float).reshape(6)
        oris.append((im.image, eo[:3].tolist(), rotation_matrix(*eo[3:])))
        if im.eo_std is not None:
            report.skip("orientation standard deviations (PAT-B's file has none)")
    if oris:
        contents[files[".ori"]] = layout.encode_orientations(oris, files[".ori"])
    report.skip("cameras (PAT-B keeps them in its camera file)", len(block.cameras))
    report.skip(
        "pixel transforms (PAT-B takes photo coordinates)",
        sum(im.pixel_to_mm is not None for im in block.images),
    )
    report.files = atomic_write_many(contents, parents=True)
    report.written = {
        "photos": len(rows),
        "observations": n_obs,
        "control points": len(control),
        "orientations": len(oris),
    }
    report.log("PAT-B")
    return report


def read_patb(source) -> ExchangeBlock:
    """Read a PAT-B set: ``source`` names the set (``out/blk``) or one of its files; the
    image-coordinate, control and orientation files that exist beside it are read.

    Observations get photo coordinates only (pixels None), images their numbers as names
    (no camera, no pixel transform), control points the kind "full".
    """
    files = read_set(source, SUFFIXES)
    block = ExchangeBlock()
    images: dict[int, ExImage] = {}
    points: dict[str, ExPoint] = {}

    def image(n: int) -> ExImage:
        if n not in images:
            images[n] = ExImage(image=n, name=str(n))
        return images[n]

    if files[".im"].is_file():
        f = files[".im"]
        for ph in layout.decode_image_coordinates(
            read_bytes(f, "PAT-B image-coordinate file", max_bytes=MAX_BYTES), f
        ):
            image(ph.photo)
            for nm, (x, y) in zip(ph.names, ph.xy_mm.tolist(), strict=True):
                points.setdefault(nm, ExPoint(nm, "tie"))
                block.observations.append(ExObservation(nm, ph.photo, x, y, None, None))
    if files[".con"].is_file():
        f = files[".con"]
        for nm, xyz, _ in layout.decode_control(
            read_bytes(f, "PAT-B control file", max_bytes=MAX_BYTES), f
        ):
            p = points.setdefault(nm, ExPoint(nm, "full"))
            p.kind, p.xyz = "full", xyz
    if files[".ori"].is_file():
        f = files[".ori"]
        for o in layout.decode_orientations(
            read_bytes(f, "PAT-B orientation file", max_bytes=MAX_BYTES), f
        ):
            R = nearest_rotation(o.rotation)
            try:
                angles = angles_from_matrix(R)
            except DegenerateGeometryError as exc:  # gimbal lock: phi at +-90 degrees
                raise FormatError(f"photo {o.photo}: {exc}", f, f"line {o.line}") from None
            image(o.photo).eo = np.array([*o.centre.tolist(), *angles])
    block.images = [images[n] for n in sorted(images)]
    block.points = list(points.values())
    return block
