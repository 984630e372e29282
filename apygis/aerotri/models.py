"""Stereo models for compilation: a triangulated block split into the orientation files that
``apygis session`` loads (the seed's PHOREX/PEX files of PHODIS AT, section 5.2).

Every pair of neighbouring images of a strip with adjusted exterior orientations is a
model. Its exterior orientations are split into a **relative** orientation (dependent,
in the model system of the left photo: the left photo at the origin with angles 0, the
right photo at the base ``(1, by, bz)`` with its rotation ``R_left^T R_right``; model
unit: the base's x component) and an **absolute** orientation (the 3-D similarity
``X = C_left + s R_left m`` with ``s`` the base's x component in metres), so that their
composition gives the adjusted orientations back exactly.

The orientation file (``docs/formats/orientation.md``) holds the two photos in stage
order (left first) with the adjusted orientations and the superposition scales
``sx = sy = -(c / (Zo - Zm)) cos(kappa)`` (``Zm`` the median height of the model's
adjusted points: the superposition of the map on a photo flown with ``kappa`` near 0 or
180 degrees, which is how the APY stages hold photos), the split in ``quality.model``,
and, from an instrument file (``instrument``: an orientation file of the plotter, as
``apygis orient`` writes it), the map's tablet orientation and the motor calibrations of
the left and right stages. Without a map orientation the model file is completed by
``apygis orient map ... -o MODEL.json --overwrite`` before compiling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from itertools import pairwise
from pathlib import Path

import numpy as np

from apygis.aerotri.block import Block, BlockError
from apygis.orient.collinearity import ExteriorOrientation, InteriorOrientation
from apygis.orient.rotation import angles_from_matrix, rotation_matrix

__all__ = ["ModelSplit", "model_orientation", "split_model", "stereo_models", "write_models"]


@dataclass(frozen=True)
class ModelSplit:
    """Relative (``by, bz, omega, phi, kappa`` of the right photo; ``bx = 1``) and absolute
    (``scale``, the left photo's rotation angles and centre) orientation of a model."""

    by: float
    bz: float
    omega_rad: float
    phi_rad: float
    kappa_rad: float
    scale_m: float
    left_angles_rad: tuple[float, float, float]
    left_centre: tuple[float, float, float]

    def compose(self) -> tuple[ExteriorOrientation, ExteriorOrientation]:
        """The two exterior orientations back from the split."""
        Rl = rotation_matrix(*self.left_angles_rad)
        Cl = np.array(self.left_centre)
        left = ExteriorOrientation.from_parameters([*self.left_centre, *self.left_angles_rad])
        b = np.array([1.0, self.by, self.bz])
        Cr = Cl + self.scale_m * Rl @ b
        Rr = Rl @ rotation_matrix(self.omega_rad, self.phi_rad, self.kappa_rad)
        return left, ExteriorOrientation.from_parameters([*Cr, *angles_from_matrix(Rr)])

    def to_dict(self) -> dict:
        return {
            "relative": {"bx": 1.0, "by": self.by, "bz": self.bz, "omega_rad": self.omega_rad,
                         "phi_rad": self.phi_rad, "kappa_rad": self.kappa_rad},
            "absolute": {"scale_m": self.scale_m,
                         "omega_rad": self.left_angles_rad[0], "phi_rad": self.left_angles_rad[1],
                         "kappa_rad": self.left_angles_rad[2], "X": self.left_centre[0],
                         "Y": self.left_centre[1], "Z": self.left_centre[2]},
        }  # fmt: skip


def split_model(left: ExteriorOrientation, right: ExteriorOrientation) -> ModelSplit:
    """Split two exterior orientations into relative and absolute orientation (module
    docstring); refused when the base has no component along the left photo's x axis."""
    Rl = left.rotation
    b = Rl.T @ (right.centre - left.centre)
    if abs(b[0]) < 1e-9 * max(float(np.linalg.norm(b)), 1e-300):
        raise BlockError("a model whose base is across the left photo's x axis cannot be split")
    Rrel = Rl.T @ right.rotation
    om, ph, ka = angles_from_matrix(Rrel)
    return ModelSplit(
        by=float(b[1] / b[0]), bz=float(b[2] / b[0]), omega_rad=om, phi_rad=ph, kappa_rad=ka,
        scale_m=float(b[0]), left_angles_rad=(left.omega_rad, left.phi_rad, left.kappa_rad),
        left_centre=(left.Xo, left.Yo, left.Zo),
    )  # fmt: skip


def stereo_models(block: Block) -> list[tuple[int, int]]:
    """The models of an adjusted block: neighbouring images of each strip (plan order)."""
    from apygis.aerotri.project import block_plan

    ext = {r[0] for r in block.conn.execute("SELECT image FROM exterior")}
    if not ext:
        raise BlockError(f"{block.path}: the block is not adjusted yet (run 'apygis at adjust')")
    plan = block_plan(block)
    out = []
    for strip in plan.strips.values():
        imgs = [n for n in strip.images if n in ext]
        out += list(pairwise(imgs))
    return out


def model_orientation(block: Block, a: int, b: int, instrument=None):
    """The orientation file content (``apygis.orient.io.Orientation``) of the model of images
    ``a`` (left) and ``b`` (right); see the module docstring."""
    from apygis.orient.io import Orientation
    from apygis.orient.photo import PhotoOrientation

    rows = {
        r[0]: r[1:]
        for r in block.conn.execute(
            "SELECT image, X, Y, Z, omega, phi, kappa FROM exterior WHERE image IN (?, ?)", (a, b)
        )
    }
    if a not in rows or b not in rows:
        raise BlockError(f"{block.path}: images {a} and {b} are not both adjusted")
    cams = block.cameras()
    images = {im.image: im for im in block.images()}
    zm = _model_height(block, a, b)
    photos = []
    for n in (a, b):
        eo = ExteriorOrientation(*rows[n])
        cam = cams[images[n].camera]
        H = eo.Zo - zm
        if not H > 0:
            raise BlockError(f"{block.path}: image {n} is not above its model's points")
        s = -(cam.focal_mm / H) * math.cos(eo.kappa_rad)
        if abs(s) < 1e-6:
            s = -(cam.focal_mm / H)  # kappa near 90 degrees: no superposition either way
        photos.append(
            PhotoOrientation(
                str(n), InteriorOrientation(cam.focal_mm, cam.x0_mm, cam.y0_mm), eo, s, s
            )
        )
    split = split_model(photos[0].exterior, photos[1].exterior)
    rep = block.conn.execute(
        "SELECT id, report FROM adjustments WHERE report IS NOT NULL ORDER BY id DESC LIMIT 1"
    ).fetchone()
    quality = {
        "model": {
            "block": block.path.name, "left": a, "right": b, "mean_height_m": zm,
            "adjustment": rep[0] if rep else None, **split.to_dict(),
        }
    }  # fmt: skip
    o = Orientation(photos=tuple(photos), quality=quality)
    if instrument is not None:
        o = _with_instrument(o, instrument, str(a), str(b))
    return o


def _model_height(block: Block, a: int, b: int) -> float:
    row = block.conn.execute(
        "SELECT a.Z FROM adjusted_points a JOIN observations o1 ON o1.point = a.point AND "
        "o1.image = ? JOIN observations o2 ON o2.point = a.point AND o2.image = ?",
        (a, b),
    ).fetchall()
    if row:
        return float(np.median([r[0] for r in row]))
    from apygis.aerotri.project import terrain_height

    return terrain_height(block)


def _with_instrument(o, instrument, left: str, right: str):
    """The map orientation and the first two motor calibrations of an instrument file."""
    from apygis.orient.io import load_orientation

    inst = instrument if not isinstance(instrument, str | Path) else load_orientation(instrument)
    motors = list(inst.motors)
    if len(motors) < 2:
        raise BlockError(
            f"{instrument}: the instrument file needs the motor calibrations of two stages "
            f"(it has {len(motors)})"
        )
    ms = (replace(motors[0], photo_id=left), replace(motors[1], photo_id=right))
    return o.replace(map_transform=inst.map_transform, map_id=inst.map_id, motors=ms,
                     height_correction=inst.height_correction)  # fmt: skip


def write_models(block: Block, folder, *, instrument=None, overwrite: bool = False) -> list[Path]:
    """Write ``<folder>/model-<a>-<b>.json`` for every stereo model; returns the paths. An
    existing file is refused unless ``overwrite``."""
    from apygis.errors import FileOverwriteError
    from apygis.orient.io import save_orientation

    folder = Path(folder)
    models = stereo_models(block)
    if not models:
        raise BlockError(f"{block.path}: no strip has two neighbouring adjusted images")
    paths = [folder / f"model-{a}-{b}.json" for a, b in models]
    if not overwrite:
        taken = [p for p in paths if p.exists()]
        if taken:
            raise FileOverwriteError(f"{taken[0]} exists (use --overwrite to replace it)")
    folder.mkdir(parents=True, exist_ok=True)
    for (a, b), p in zip(models, paths, strict=True):
        save_orientation(model_orientation(block, a, b, instrument), p)
    return paths
