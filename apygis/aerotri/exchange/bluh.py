"""BLUH: a block as BLUH's photo coordinate and control files.

``write_bluh(block, "out/blk")`` writes ``out/blk.pho`` (the photo coordinates of every
observation, mm) and ``out/blk.ctl`` (full, planimetric and height control) when the
block has control; the record layouts are :mod:`apygis.formats.bluh`'s (an ASSUMED
layout: ``docs/formats/bluh.md`` says what is known and what is not).
``read_bluh("out/blk")`` (or either file, or a photo coordinate file of another name)
reads the files of the set that exist.

BLUH numbers its photos and points: a point name that is not a whole number from 1
to 2147483647 written without leading zeros is refused (never renumbered). What the
two files cannot hold is left out and counted in the
:class:`~apygis.aerotri.exchange.WriteReport` (and logged): cameras, pixel transforms,
exterior orientations, sigmas, check points, adjusted coordinates of tie and new
points; and observations without photo coordinates (and no pixel transform).
"""

from __future__ import annotations

from pathlib import Path

from apygis.aerotri.exchange import ExchangeBlock, ExImage, ExObservation, ExPoint, WriteReport
from apygis.aerotri.exchange._common import (
    CONTROL,
    Index,
    base_path,
    control_xyz_ok,
    finite_xyz,
    photo_rows,
    read_set,
)
from apygis.fileio import atomic_write_many, read_bytes
from apygis.formats import bluh as layout
from apygis.formats._records import MAX_BYTES

__all__ = ["SUFFIXES", "read_bluh", "write_bluh"]

SUFFIXES = (".pho", ".ctl")
"""The files of a BLUH set: photo coordinates, control."""
_CODE = {kind: code for code, kind in layout.CODES.items()}


def write_bluh(block: ExchangeBlock, target) -> WriteReport:
    """Write ``block`` as BLUH files ``<target>.pho`` and ``.ctl`` (see the module
    docstring), atomically, after every check passed.

    Raises :class:`~apygis.errors.ValueRangeError` naming the file and the record for a
    point name or image number that is not a BLUH number, a value that does not fit its
    field.
    """
    base = base_path(target, SUFFIXES)
    files = {s: base.with_name(base.name + s) for s in SUFFIXES}
    idx = Index(block, base)
    report = WriteReport()
    pho = files[".pho"]
    rows, n_obs = photo_rows(
        idx,
        report,
        lambda ob, image: layout.point_number(ob.point, pho, f"photo {image}"),
        "BLUH's photo file",
    )
    contents: dict[Path, bytes] = {pho: layout.encode_photo_coordinates(rows, pho)}
    control = []
    ctl = files[".ctl"]
    for p in block.points:
        xyz = finite_xyz(p)
        if p.kind in CONTROL and control_xyz_ok(p, xyz):
            num = layout.point_number(p.name, ctl, f"point {p.name!r}")
            control.append((num, *xyz.tolist(), _CODE[p.kind]))  # type: ignore[union-attr]  # checked
            if p.sigma is not None:
                report.skip("control sigmas (BLUH's control file has none)")
        elif p.kind in CONTROL:
            report.skip("control points without the coordinates their kind needs")
        elif p.kind == "check":
            report.skip("check points (BLUH's control file has control only)")
        elif xyz is not None:
            report.skip("adjusted coordinates of tie and new points (BLUH computes them)")
    if control:
        contents[ctl] = layout.encode_control(control, ctl)
    report.skip("cameras (BLUH keeps them in its own input)", len(block.cameras))
    report.skip(
        "pixel transforms (BLUH takes photo coordinates)",
        sum(im.pixel_to_mm is not None for im in block.images),
    )
    report.skip(
        "exterior orientations (not part of BLUH's input files)",
        sum(im.eo is not None for im in block.images),
    )
    report.files = atomic_write_many(contents, parents=True)
    report.written = {"photos": len(rows), "observations": n_obs, "control points": len(control)}
    report.log("BLUH")
    return report


def read_bluh(source) -> ExchangeBlock:
    """Read a BLUH set: ``source`` names the set (``out/blk``) or one of its files; the
    photo coordinate and control files that exist beside it are read.

    Point and image names are the numbers as text; observations get photo coordinates
    only; control points their kind from the control code.
    """
    files = read_set(source, SUFFIXES)
    block = ExchangeBlock()
    images: dict[int, ExImage] = {}
    points: dict[str, ExPoint] = {}
    if files[".pho"].is_file():
        f = files[".pho"]
        data = read_bytes(f, "BLUH photo coordinate file", max_bytes=MAX_BYTES)
        for ph in layout.decode_photo_coordinates(data, f):
            images.setdefault(ph.photo, ExImage(image=ph.photo, name=str(ph.photo)))
            for num, (x, y) in zip(ph.numbers, ph.xy_mm.tolist(), strict=True):
                nm = str(num)
                points.setdefault(nm, ExPoint(nm, "tie"))
                block.observations.append(ExObservation(nm, ph.photo, x, y, None, None))
    if files[".ctl"].is_file():
        f = files[".ctl"]
        for num, xyz, code, _ in layout.decode_control(
            read_bytes(f, "BLUH control file", max_bytes=MAX_BYTES), f
        ):
            nm = str(num)
            p = points.setdefault(nm, ExPoint(nm))
            p.kind, p.xyz = layout.CODES[code], xyz
    block.images = [images[n] for n in sorted(images)]
    block.points = list(points.values())
    return block
