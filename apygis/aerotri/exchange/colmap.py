"""COLMAP's text model: ``cameras.txt``, ``images.txt`` and ``points3D.txt`` in a folder.

The format is COLMAP's (https://colmap.github.io/format.html, "Text format");
``docs/formats/colmap.md`` states every conversion. In short:

Poses
    COLMAP stores ``cam_from_world``: ``x_cam = R_cw X + t`` with the camera frame x right,
    y **down**, z forward (the viewing direction), as the quaternion ``QW QX QY QZ`` of
    ``R_cw`` and the vector ``t``. apygis's image space has x right, y up and looks down
    its negative z axis (:mod:`apygis.orient.rotation`), so with ``D = diag(1, -1, -1)``::

        R_cw = D R^T        t = -R_cw X0        (R, X0: apygis's rotation and centre)

Pixels
    COLMAP's pixel origin is the **corner** of the top-left pixel (its centre is at
    0.5, 0.5); apygis's is that pixel's centre: ``u = col + 0.5``, ``v = row + 0.5``.

Cameras
    A digital frame camera whose pixel transform is the centred one of
    :meth:`~apygis.aerotri.camera.PixelTransform.digital` (pixel pitch ``p_x``, ``p_y``)
    is written exactly, in its own pixels: ``f_x = c / p_x``, ``f_y = c / p_y``,
    ``c_x = x0 / p_x + W / 2``, ``c_y = -y0 / p_y + H / 2`` (``SIMPLE_PINHOLE`` when
    ``f_x = f_y``, else ``PINHOLE``). Any other pixel transform (a film scan: rotated,
    sheared, off-centre) cannot be a COLMAP camera; its images are written in a **virtual
    pixel grid** over their photo coordinates: a centred digital grid of pitch ``s`` (the
    camera's mean scan pixel rounded to 0.01 um, or ``pixel_um``) large enough to hold the
    photo, so the photo coordinates come back exactly and the scan's own pixels are not
    in the model (:attr:`WriteReport.notes` says which camera got which grid).
    COLMAP has no millimetres: reading needs the pixel pitch (``pixel_um``, one number
    or one per camera id), and gives each image the centred digital pixel transform of
    that pitch.

Distortion
    apygis's radial distortion table is not a COLMAP model: a camera that has one is
    refused, or with ``distortion="undistort"`` its observations are written corrected
    by the table (``x_c = x0 + (x - x0)(1 - dr(r) / r)``) and the camera is a pinhole.
    Reading takes ``SIMPLE_PINHOLE``, ``PINHOLE`` and ``OPENCV``; an ``OPENCV`` camera
    with distortion is refused, or with ``distortion="undistort"`` its observations are
    undistorted by COLMAP's own model (iterated to 1e-12 of a focal length).

Points
    ``POINT3D_ID`` is the point's name where every point written is named by a whole
    number from 1 to 2^63 - 1 without leading zeros; otherwise points are numbered 1..N
    in block order (a note says so). Colour is written 0 0 0 and the error -1 (unknown).

What COLMAP's model cannot hold is counted in the report: images without exterior
orientation (COLMAP writes registered images only), points without complete
coordinates and their observations, point kinds, sigmas, standard deviations, the
CRS.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from apygis.aerotri.exchange import (
    ExCamera,
    ExchangeBlock,
    ExImage,
    ExObservation,
    ExPoint,
    WriteReport,
)
from apygis.aerotri.exchange._common import Index, finite_xyz, photo_mm, pixels
from apygis.errors import DegenerateGeometryError, FormatError, ValueRangeError
from apygis.fileio import atomic_write_many, read_bytes, write_failed
from apygis.formats._records import MAX_BYTES, number, numbers, text_lines, whole
from apygis.orient.rotation import angles_from_matrix, rotation_matrix

__all__ = [
    "FILES",
    "MAX_OBSERVATIONS",
    "MODELS",
    "read_cameras",
    "read_colmap",
    "read_images",
    "read_points3d",
    "write_colmap",
]

FILES = ("cameras.txt", "images.txt", "points3D.txt")
MODELS = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4, "OPENCV": 8}
"""The camera models read, with their numbers of parameters."""
MAX_ID = 2**32 - 1  # COLMAP's camera_t / image_t
MAX_POINT_ID = 2**63 - 1  # point3D_t (uint64; kept to int64 here)
MAX_SIZE = 1_000_000  # pixels, as apygis's camera files allow
MAX_OBSERVATIONS = 4_000_000
"""The most observations read from one model (an object each: bounded memory)."""
_D = np.diag([1.0, -1.0, -1.0])
_LINE = 1 << 16  # cameras.txt and image header lines
_LONG_LINE = 8 << 20  # a points2D or track line: 8 MiB (some 250 000 observations)


# ------------------------------------------------------------------ conversions


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return -q if q[0] < 0 else q


def _matrix_from_quat(q: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    w, x, y, z = q
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def _digital_pitch(T: np.ndarray, W: int | None, H: int | None) -> tuple[float, float] | None:
    """``(p_x, p_y)`` if ``T`` is the centred digital transform of a W x H raster."""
    if W is None or H is None:
        return None
    px, py = T[0, 0], -T[1, 1]
    if not (px > 0 and py > 0) or T[0, 1] != 0 or T[1, 0] != 0 or T[2, 0] != 0 or T[2, 1] != 0:
        return None
    scale = max(abs(T[0, 2]), abs(T[1, 2]), px, py)
    tol = 1e-12 * scale
    if abs(T[0, 2] + (W - 1) / 2 * px) > tol or abs(T[1, 2] - (H - 1) / 2 * py) > tol:
        return None
    return float(px), float(py)


def _undistort_table(cam: ExCamera, xy: np.ndarray) -> np.ndarray:
    """Photo coordinates corrected by the camera's radial table (as Camera.undistort)."""
    c = np.array([cam.x0_mm, cam.y0_mm])
    v = xy - c
    r = np.hypot(v[:, 0], v[:, 1])
    dr = np.interp(r, cam.radial_mm, cam.radial_um) / 1000.0
    f = np.where(r > 0, 1.0 - dr / np.where(r > 0, r, 1.0), 1.0)
    return c + v * f[:, None]


def _f(v: float) -> str:
    """A float as the shortest text that reads back to it exactly."""
    return repr(float(v))


# ------------------------------------------------------------------ writing


def write_colmap(
    block: ExchangeBlock,
    folder,
    *,
    distortion: str = "refuse",
    pixel_um: float | None = None,
) -> WriteReport:
    """Write ``block`` as a COLMAP text model into ``folder`` (created if missing, with its
    parents). See the module docstring for the conversions.

    Parameters
    ----------
    distortion : {"refuse", "undistort"}
        What to do with a camera that has a radial distortion table.
    pixel_um : float, optional
        The pitch of the virtual pixel grids (default: each camera's mean scan pixel,
        rounded to 0.01 um); needed when images have no pixel transform.

    Raises :class:`~apygis.errors.ValueRangeError` naming the file and the record for
    an image without a camera, an image name holding a blank, a camera with a
    distortion table (unless ``distortion="undistort"``), a folder holding a
    ``rigs.txt`` or ``frames.txt`` that COLMAP would combine with the new files.
    """
    if distortion not in ("refuse", "undistort"):
        raise ValueError(f"distortion is 'refuse' or 'undistort', not {distortion!r}")
    out = Path(folder)
    files = {n: out / n for n in FILES}
    idx = Index(block, out)
    report = WriteReport()
    cams = {c.id: c for c in block.cameras}
    # images written: registered ones with a camera
    written: list[ExImage] = []
    cam_of: dict[int, ExCamera] = {}
    for im in sorted(block.images, key=lambda i: i.image):
        rec = f"image {im.image}"
        if im.eo is None:
            report.skip(
                "images without exterior orientation (COLMAP writes registered images only)"
            )
            continue
        if im.image > MAX_ID:
            raise ValueRangeError(
                f"image number {im.image} is beyond COLMAP's {MAX_ID}", files["images.txt"], rec
            )
        if im.camera is None or im.camera not in cams:
            raise ValueRangeError(
                f"image {im.image} has no camera of the block: COLMAP needs its principal distance",
                files["images.txt"],
                rec,
            )
        if (
            not isinstance(im.name, str)
            or not im.name
            or im.name.split() != [im.name]
            or not im.name.isprintable()
        ):
            raise ValueRangeError(
                f"image name {im.name!r} is empty or holds a blank or a control character "
                "(COLMAP's images.txt separates fields by blanks)",
                files["images.txt"],
                rec,
            )
        cam = cams[im.camera]
        if cam.radial_mm and distortion == "refuse":
            raise ValueRangeError(
                f"camera {cam.id} ({cam.name}) has a radial distortion table that no COLMAP camera "
                "model holds exactly; pass distortion='undistort' to write distortion-free "
                "photo coordinates",
                files["cameras.txt"],
                f"camera {cam.id}",
            )
        written.append(im)
        cam_of[im.image] = cam
    grids = _grids(written, cam_of, idx, pixel_um, report, files["cameras.txt"])
    for cid in sorted({cam_of[im.image].id for im in written}):
        if cams[cid].radial_mm:
            report.notes.append(
                f"the observations of camera {cid} ({cams[cid].name}) are written corrected for "
                "its radial distortion table (distortion='undistort'): COLMAP's camera is a pinhole"
            )
    # points written: finite X, Y, Z and observed in a written image
    in_written = {im.image for im in written}
    obs_of: dict[str, list[ExObservation]] = {}
    for ob in block.observations:
        if ob.image in in_written:
            obs_of.setdefault(ob.point, []).append(ob)
    pts: list[ExPoint] = []
    for p in block.points:
        xyz = finite_xyz(p)
        if xyz is None or not np.isfinite(xyz).all():
            report.skip("points without X, Y and Z, and their observations", 1)
            continue
        if not obs_of.get(p.name):
            report.skip("points observed in no written image")
            continue
        pts.append(p)
    names = [p.name for p in pts]
    if all(
        n.isascii() and n.isdigit() and n == str(int(n)) and 1 <= int(n) <= MAX_POINT_ID
        for n in names
    ):
        ids = {n: int(n) for n in names}
    else:
        ids = {n: k + 1 for k, n in enumerate(names)}
        report.notes.append(
            "point names are not all COLMAP point ids (whole numbers without leading zeros): "
            f"the {len(names)} points are numbered 1..{len(names)} in block order"
        )
    # points2D per image and tracks
    rows_2d: dict[int, list[str]] = {im.image: [] for im in written}
    tracks: dict[str, list[str]] = {n: [] for n in names}
    for im in written:
        grid = grids[im.image]
        obs = [ob for ob in idx.by_image_of(im.image) if ob.point in tracks]
        uv = grid.uv(obs, im, cam_of[im.image], distortion == "undistort", files["images.txt"])
        for ob, (u, v) in zip(obs, uv, strict=True):
            tracks[ob.point].append(f"{im.image} {len(rows_2d[im.image])}")
            rows_2d[im.image].append(f"{_f(u)} {_f(v)} {ids[ob.point]}")
    n_obs = sum(len(r) for r in rows_2d.values())
    report.skip(
        "observations of points not written",
        sum(1 for ob in block.observations if ob.image in in_written and ob.point not in tracks),
    )
    # text
    cam_lines = [
        "# Camera list with one line of data per camera:",
        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
        f"# Number of cameras: {len(grids.cameras)}",
    ]
    for cid, (model, W, H, params) in grids.cameras.items():
        cam_lines.append(f"{cid} {model} {W} {H} " + " ".join(_f(v) for v in params))
    img_lines = [
        "# Image list with two lines of data per image:",
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
        "#   POINTS2D[] as (X, Y, POINT3D_ID)",
        f"# Number of images: {len(written)}, written by apygis",
    ]
    for im in written:
        eo = np.asarray(im.eo, dtype=float).reshape(6)
        R_cw = _D @ rotation_matrix(*eo[3:]).T
        t = -R_cw @ eo[:3]
        q = _quat_from_matrix(R_cw)
        img_lines.append(
            f"{im.image} "
            + " ".join(_f(v) for v in [*q, *t])
            + f" {grids[im.image].camera_id} {im.name}"
        )
        img_lines.append(" ".join(rows_2d[im.image]))
    pt_lines = [
        "# 3D point list with one line of data per point:",
        "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
        f"# Number of points: {len(pts)}, written by apygis (colour and error unknown)",
    ]
    for p in pts:
        xyz = finite_xyz(p)
        assert xyz is not None  # checked above
        pt_lines.append(
            f"{ids[p.name]} "
            + " ".join(_f(v) for v in xyz)
            + " 0 0 0 -1 "
            + " ".join(tracks[p.name])
        )
    # the unread and unwritable
    report.skip(
        "observation sigmas (COLMAP has none)",
        sum(
            ob.sigma_px is not None
            for ob in block.observations
            if ob.point in tracks and ob.image in in_written
        ),
    )
    report.skip(
        "point kinds of control and check points (COLMAP has none)",
        sum(p.kind != "tie" for p in pts),
    )
    report.skip(
        "point standard deviations (COLMAP has none)", sum(p.sigma is not None for p in pts)
    )
    report.skip(
        "orientation standard deviations (COLMAP has none)",
        sum(im.eo_std is not None for im in written),
    )
    if block.crs:
        report.skip("the CRS (COLMAP has none)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_failed(out, exc) from None
    for stale in ("rigs.txt", "frames.txt"):
        if (out / stale).exists():
            raise ValueRangeError(
                f"the folder holds a {stale} of another model, which COLMAP would combine with "
                "the new files: remove it or write into another folder",
                out / stale,
            )
    contents = {
        files["cameras.txt"]: ("\n".join(cam_lines) + "\n").encode(),
        files["images.txt"]: ("\n".join(img_lines) + "\n").encode(),
        files["points3D.txt"]: ("\n".join(pt_lines) + "\n").encode(),
    }
    report.files = atomic_write_many(contents, parents=True)
    report.written = {
        "cameras": len(grids.cameras),
        "images": len(written),
        "points": len(pts),
        "observations": n_obs,
    }
    report.log("COLMAP")
    return report


class _Grid:
    """How one image's observations become COLMAP pixels: its COLMAP camera and the
    pixel transform of that camera (the image's own, or a virtual grid)."""

    def __init__(self, camera_id: int, T: np.ndarray, virtual: bool):
        self.camera_id = camera_id
        self.T = T
        self.Tinv = np.linalg.inv(T)
        self.virtual = virtual

    def uv(self, obs, im: ExImage, cam: ExCamera, undistort: bool, path) -> list:
        if not obs:
            return []
        use_mm = self.virtual or (undistort and bool(cam.radial_mm))
        out = np.empty((len(obs), 2))
        for k, ob in enumerate(obs):
            got = photo_mm(ob, im) if use_mm else pixels(ob, im)
            if got is None:
                raise ValueRangeError(
                    "the observation has no coordinates COLMAP's pixels can be made of",
                    path,
                    f"image {im.image} point {ob.point!r}",
                )
            out[k] = got
        if use_mm:
            if undistort and cam.radial_mm:
                out = _undistort_table(cam, out)
            h = np.c_[out, np.ones(len(out))] @ self.Tinv.T
            out = h[:, :2] / h[:, 2:]
        return (out + 0.5).tolist()


class _Grids(dict):
    cameras: dict[int, tuple[str, int, int, list[float]]]


def _grids(
    written, cam_of: dict[int, ExCamera], idx, pixel_um, report: WriteReport, path
) -> _Grids:
    """The COLMAP camera of every written image (exact where the pixel transform is a
    centred digital one, else a virtual grid per apygis camera)."""
    from apygis.aerotri.camera import PixelTransform

    grids = _Grids()
    grids.cameras = {}
    exact: dict[tuple, int] = {}
    virtual_members: dict[int, list[ExImage]] = {}
    for im in written:
        T = (
            None
            if im.pixel_to_mm is None
            else np.asarray(im.pixel_to_mm, dtype=float).reshape(3, 3)
        )
        pitch = None if T is None else _digital_pitch(T / T[2, 2], im.width_px, im.height_px)
        cam = cam_of[im.image]
        if pitch is None or T is None:
            virtual_members.setdefault(cam.id, []).append(im)
            continue
        key = (cam.id, im.width_px, im.height_px, *pitch)
        if key not in exact:
            cid = len(grids.cameras) + 1
            exact[key] = cid
            grids.cameras[cid] = _pinhole(cam, im.width_px, im.height_px, *pitch, path)
        grids[im.image] = _Grid(exact[key], T / T[2, 2], False)
    for camera, members in virtual_members.items():
        cam = cam_of[members[0].image]
        if pixel_um is not None:
            s = float(pixel_um) / 1000.0
            if not (math.isfinite(s) and 1e-5 <= s <= 1.0):
                raise ValueError(f"pixel_um is a pitch from 0.01 to 1000 um, not {pixel_um!r}")
        else:
            sizes = [
                math.sqrt(
                    abs(np.linalg.det(np.asarray(m.pixel_to_mm, float).reshape(3, 3)[:2, :2]))
                )
                for m in members
                if m.pixel_to_mm is not None
            ]
            if not sizes:
                raise ValueRangeError(
                    f"the images of camera {camera} have no pixel transform: pass pixel_um= for "
                    "the pitch of a virtual pixel grid over their photo coordinates",
                    path,
                    f"camera {camera}",
                )
            s = round(float(np.mean(sizes)) * 1e5) / 1e5 or 1e-5
        hx = hy = s
        for m in members:
            if m.pixel_to_mm is not None and m.width_px and m.height_px:
                corners = np.array(
                    [
                        [-0.5, -0.5],
                        [m.width_px - 0.5, -0.5],
                        [-0.5, m.height_px - 0.5],
                        [m.width_px - 0.5, m.height_px - 0.5],
                    ]
                )
                mm = PixelTransform(np.asarray(m.pixel_to_mm, float)).to_mm(corners)
                hx, hy = (
                    max(hx, float(np.abs(mm[:, 0]).max())),
                    max(hy, float(np.abs(mm[:, 1]).max())),
                )
            for ob in idx.by_image_of(m.image):
                got = photo_mm(ob, m)
                if got is not None:
                    hx, hy = max(hx, abs(got[0])), max(hy, abs(got[1]))
        W, H = math.ceil(2 * hx / s) + 2, math.ceil(2 * hy / s) + 2
        if max(W, H) > MAX_SIZE:
            raise ValueRangeError(
                f"a virtual pixel grid of {s * 1000:g} um over the photos of camera {camera} "
                f"would be {W} x {H} pixels, beyond the {MAX_SIZE} a camera may have: pass a "
                "larger pixel_um",
                path,
                f"camera {camera}",
            )
        T = PixelTransform.digital(W, H, s * 1000.0).matrix
        cid = len(grids.cameras) + 1
        grids.cameras[cid] = _pinhole(cam, W, H, s, s, path)
        for m in members:
            grids[m.image] = _Grid(cid, T, True)
        report.notes.append(
            f"COLMAP camera {cid} is a virtual pixel grid of {s * 1000:.2f} um, {W} x {H} pixels, "
            f"over the photo coordinates of camera {camera} ({cam.name}): its images' pixel "
            "transforms are not COLMAP cameras; read the model back with "
            f"pixel_um={s * 1000:.2f} for this camera"
        )
    return grids


def _pinhole(cam: ExCamera, W, H, px: float, py: float, path) -> tuple[str, int, int, list[float]]:
    if not (
        isinstance(W, int) and isinstance(H, int) and 1 <= W <= MAX_SIZE and 1 <= H <= MAX_SIZE
    ):
        raise ValueRangeError(
            f"raster size {W} x {H} is not 1 to {MAX_SIZE} pixels", path, f"camera {cam.id}"
        )
    if not (math.isfinite(cam.focal_mm) and cam.focal_mm > 0):
        raise ValueRangeError(
            f"principal distance {cam.focal_mm!r} is not a positive number",
            path,
            f"camera {cam.id}",
        )
    fx, fy = cam.focal_mm / px, cam.focal_mm / py
    cx, cy = cam.x0_mm / px + W / 2, -cam.y0_mm / py + H / 2
    if fx == fy:
        return "SIMPLE_PINHOLE", W, H, [fx, cx, cy]
    return "PINHOLE", W, H, [fx, fy, cx, cy]


# ------------------------------------------------------------------ reading


def _records(data: bytes, path, what: str, max_line: int):
    """The lines that are not blank and not comments, with their numbers."""
    for k, text in text_lines(data, path, what, max_line=max_line):
        s = text.strip()
        if s and not s.startswith("#"):
            yield k, s


def read_cameras(path) -> dict[int, tuple[str, int, int, np.ndarray, int]]:
    """``cameras.txt``: ``{camera_id: (model, width, height, params, line)}``, models of
    :data:`MODELS` only."""
    data = read_bytes(path, "COLMAP cameras file", max_bytes=MAX_BYTES)
    out: dict[int, tuple[str, int, int, np.ndarray, int]] = {}
    for k, s in _records(data, path, "COLMAP's cameras.txt", _LINE):
        rec = f"line {k}"
        tok = s.split()
        if len(tok) < 4:
            raise FormatError(
                f"expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS..., found {len(tok)} fields",
                path,
                rec,
            )
        cid = whole(tok[0], path, rec, "camera id", hi=MAX_ID)
        if cid in out:
            raise FormatError(
                f"camera {cid} is given twice (also at line {out[cid][4]})", path, rec
            )
        model = tok[1]
        if model not in MODELS:
            raise FormatError(
                f"camera model {model[:40]!r} is not one apygis reads ({', '.join(MODELS)})",
                path,
                rec,
            )
        W = whole(tok[2], path, rec, "width", hi=MAX_SIZE)
        H = whole(tok[3], path, rec, "height", hi=MAX_SIZE)
        if len(tok) != 4 + MODELS[model]:
            raise FormatError(
                f"a {model} camera has {MODELS[model]} parameters, found {len(tok) - 4}", path, rec
            )
        params = numbers(tok[4:], path, rec, "camera parameter", limit=1e9)
        f = params[:2] if model != "SIMPLE_PINHOLE" else params[:1]
        if not (f > 0).all():
            raise FormatError(f"focal length {f.tolist()} is not positive", path, rec)
        out[cid] = (model, W, H, params, k)
    return out


def read_images(
    path,
) -> dict[int, tuple[np.ndarray, np.ndarray, int, str, np.ndarray, np.ndarray, int]]:
    """``images.txt``: ``{image_id: (q, t, camera_id, name, uv (n, 2), point3D_ids (n,),
    line)}``; the quaternion normalised."""
    data = read_bytes(path, "COLMAP images file", max_bytes=MAX_BYTES)
    lines = text_lines(data, path, "COLMAP's images.txt", max_line=_LONG_LINE)
    out: dict[int, tuple[np.ndarray, np.ndarray, int, str, np.ndarray, np.ndarray, int]] = {}
    names: dict[str, int] = {}
    for k, text in lines:
        s = text.strip()
        if not s or s.startswith("#"):
            continue
        rec = f"line {k}"
        if len(s) > _LINE:
            raise FormatError(f"an image line of {len(s)} characters is too long", path, rec)
        tok = s.split()
        if len(tok) != 10:
            raise FormatError(
                f"expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (10 fields, a name without "
                f"blanks), found {len(tok)}",
                path,
                rec,
            )
        iid = whole(tok[0], path, rec, "image id", hi=MAX_ID)
        if iid in out:
            raise FormatError(f"image {iid} is given twice (also at line {out[iid][6]})", path, rec)
        q = numbers(tok[1:5], path, rec, "quaternion", limit=1e3)
        t = numbers(tok[5:8], path, rec, "translation")
        norm = float(np.linalg.norm(q))
        if norm < 1e-6:
            raise FormatError("the quaternion is zero: not a rotation", path, rec)
        cid = whole(tok[8], path, rec, "camera id", hi=MAX_ID)
        name = tok[9]
        if not name.isprintable():
            raise FormatError(f"image name {name[:40]!r} holds a control character", path, rec)
        if name in names:
            raise FormatError(
                f"image name {name[:40]!r} is given twice (also at line {names[name]})", path, rec
            )
        names[name] = k
        nxt = next(lines, None)
        if nxt is None:
            raise FormatError(f"image {iid} has no POINTS2D line: the file is truncated", path, rec)
        k2, pts_text = nxt
        tok2 = pts_text.split()
        if len(tok2) % 3:
            raise FormatError(
                f"POINTS2D holds {len(tok2)} values, not triples X Y POINT3D_ID", path, f"line {k2}"
            )
        uv = numbers(tok2[0::3] + tok2[1::3], path, f"line {k2}", "point2D coordinate", limit=1e7)
        uv = uv.reshape(2, -1).T
        ids = np.array(
            [
                -1
                if v == "-1"
                else whole(v, path, f"line {k2}", "POINT3D_ID (or -1)", hi=MAX_POINT_ID)
                for v in tok2[2::3]
            ],
            dtype=np.int64,
        )
        out[iid] = (q / norm, t, cid, name, uv, ids, k)
    return out


def read_points3d(path) -> dict[int, tuple[np.ndarray, np.ndarray, int]]:
    """``points3D.txt``: ``{point3D_id: (xyz, track (m, 2) of image id and point2D index,
    line)}``."""
    data = read_bytes(path, "COLMAP points file", max_bytes=MAX_BYTES)
    out: dict[int, tuple[np.ndarray, np.ndarray, int]] = {}
    for k, s in _records(data, path, "COLMAP's points3D.txt", _LONG_LINE):
        rec = f"line {k}"
        tok = s.split()
        if len(tok) < 8 or (len(tok) - 8) % 2:
            raise FormatError(
                "expected POINT3D_ID X Y Z R G B ERROR and pairs IMAGE_ID POINT2D_IDX, "
                f"found {len(tok)} fields",
                path,
                rec,
            )
        pid = whole(tok[0], path, rec, "point id", hi=MAX_POINT_ID)
        if pid in out:
            raise FormatError(f"point {pid} is given twice (also at line {out[pid][2]})", path, rec)
        xyz = numbers(tok[1:4], path, rec, "coordinate")
        for c in tok[4:7]:
            whole(c, path, rec, "colour", lo=0, hi=255)
        number(tok[7], path, rec, "error", limit=1e12)
        track = np.array(
            [whole(v, path, rec, "track index", lo=0, hi=MAX_POINT_ID) for v in tok[8:]],
            dtype=np.int64,
        ).reshape(-1, 2)
        out[pid] = (xyz, track, k)
    return out


def _undistort_opencv(params: np.ndarray, uv: np.ndarray, path, rec: str) -> np.ndarray:
    """Pixels (COLMAP's, corner origin) of an OPENCV camera, undistorted by its model."""
    fx, fy, cx, cy, k1, k2, p1, p2 = params.tolist()
    xd = np.c_[(uv[:, 0] - cx) / fx, (uv[:, 1] - cy) / fy]
    x = xd.copy()
    for _ in range(200):
        u, v = x[:, 0], x[:, 1]
        r2 = u * u + v * v
        radial = k1 * r2 + k2 * r2 * r2
        du = u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u)
        dv = v * radial + 2 * p2 * u * v + p1 * (r2 + 2 * v * v)
        new = xd - np.c_[du, dv]
        step = float(np.abs(new - x).max()) if len(x) else 0.0
        x = new
        if not math.isfinite(step):
            break
        if step < 1e-12:
            return np.c_[x[:, 0] * fx + cx, x[:, 1] * fy + cy]
    raise FormatError(
        "the OPENCV distortion cannot be inverted at the image's points (the iteration does not "
        "converge): the distortion is too strong for this reader",
        path,
        rec,
    )


def read_colmap(folder, *, pixel_um, distortion: str = "refuse") -> ExchangeBlock:
    """Read a COLMAP text model (the folder holding ``cameras.txt``, ``images.txt`` and
    ``points3D.txt``).

    Parameters
    ----------
    pixel_um : float or dict of int to float
        The pixel pitch in micrometres (COLMAP has no millimetres): one for every camera,
        or one per COLMAP camera id.
    distortion : {"refuse", "undistort"}
        What to do with an OPENCV camera that has distortion.

    Images get the centred digital pixel transform of their camera's pitch and their
    COLMAP pose as exterior orientation; points are named by their ids, kind "tie";
    observations carry pixels (apygis's centre convention) and photo mm. Pixels that no
    3-D point's track refers to are counted in :attr:`ExchangeBlock.skipped`, as are the
    rigs and frames of a COLMAP 3.12+ model (each image's pose is in ``images.txt``).
    """
    if distortion not in ("refuse", "undistort"):
        raise ValueError(f"distortion is 'refuse' or 'undistort', not {distortion!r}")
    from apygis.aerotri.camera import PixelTransform

    d = Path(folder)
    if not d.is_dir():
        raise FormatError(
            "not a folder holding a COLMAP text model (cameras.txt, images.txt, points3D.txt)", d
        )
    cam_path, img_path, pt_path = (d / n for n in FILES)
    cameras = read_cameras(cam_path)
    images = read_images(img_path)
    points = read_points3d(pt_path)
    block = ExchangeBlock()
    pitch: dict[int, float] = {}
    for cid, (model, W, H, params, k) in cameras.items():
        um = pixel_um.get(cid) if isinstance(pixel_um, dict) else pixel_um
        if um is None:
            raise FormatError(f"no pixel_um given for camera {cid}", cam_path, f"line {k}")
        um = float(um)
        if not (math.isfinite(um) and 0.01 <= um <= 1000.0):
            raise ValueError(f"pixel_um is a pitch from 0.01 to 1000 um, not {um!r}")
        px = um / 1000.0
        if model == "SIMPLE_PINHOLE":
            fx = fy = params[0]
            cx, cy = params[1:3]
        else:
            fx, fy, cx, cy = params[:4]
        if model == "OPENCV" and np.any(params[4:] != 0) and distortion == "refuse":
            raise FormatError(
                f"camera {cid} is an OPENCV camera with distortion {params[4:].tolist()}: apygis's "
                "cameras have a radial table only; pass distortion='undistort' to read "
                "distortion-free coordinates",
                cam_path,
                f"line {k}",
            )
        c = float(fx) * px
        py = c / float(fy)
        pitch[cid] = px
        block.cameras.append(
            ExCamera(
                id=cid,
                name=f"COLMAP camera {cid} ({model})",
                focal_mm=c,
                x0_mm=px * (float(cx) - W / 2),
                y0_mm=-py * (float(cy) - H / 2),
                kind="digital",
                width_px=W,
                height_px=H,
                pixel_mm=px if fx == fy else None,
            )
        )
    cam_by_id = {c.id: c for c in block.cameras}
    uv_of: dict[int, np.ndarray] = {}
    transforms = {}
    for iid, (q, t, cid, name, uv, _ids, k) in sorted(images.items()):
        if cid not in cameras:
            raise FormatError(
                f"image {iid} names camera {cid}, which cameras.txt does not have",
                img_path,
                f"line {k}",
            )
        model, W, H, params, _ = cameras[cid]
        if model == "OPENCV" and np.any(params[4:] != 0) and len(uv):
            uv = _undistort_opencv(params, uv, img_path, f"line {k}")
        uv_of[iid] = uv
        R_cw = _matrix_from_quat(q)
        R = R_cw.T @ _D
        centre = -R_cw.T @ t
        try:
            angles = angles_from_matrix(R)
        except DegenerateGeometryError as exc:
            raise FormatError(f"image {iid}: {exc}", img_path, f"line {k}") from None
        cam = cam_by_id[cid]
        py = cam.focal_mm / (float(params[1]) if model != "SIMPLE_PINHOLE" else float(params[0]))
        px = pitch[cid]
        T = np.array([[px, 0.0, -(W - 1) / 2 * px], [0.0, -py, (H - 1) / 2 * py], [0.0, 0.0, 1.0]])
        transforms[iid] = PixelTransform(T)
        block.images.append(
            ExImage(
                image=iid, name=name, camera=cid, pixel_to_mm=T, width_px=W, height_px=H,
                eo=np.array([*centre.tolist(), *angles]),
            )
        )  # fmt: skip
    used = {iid: np.zeros(len(uv), dtype=bool) for iid, uv in uv_of.items()}
    total = sum(len(track) for _, track, _ in points.values())
    if total > MAX_OBSERVATIONS:
        raise FormatError(
            f"the tracks hold {total} observations, more than the {MAX_OBSERVATIONS} apygis reads "
            "from one model",
            pt_path,
        )
    for pid, (xyz, track, k) in points.items():
        nm = str(pid)
        block.points.append(ExPoint(nm, "tie", xyz))
        seen: set[int] = set()
        for iid, j in track.tolist():
            if iid not in uv_of:
                raise FormatError(
                    f"point {pid}'s track names image {iid}, which images.txt does not have",
                    pt_path,
                    f"line {k}",
                )
            if j >= len(uv_of[iid]):
                raise FormatError(
                    f"point {pid}'s track names point2D {j} of image {iid}, which has "
                    f"{len(uv_of[iid])}",
                    pt_path,
                    f"line {k}",
                )
            if iid in seen:
                raise FormatError(
                    f"point {pid} is observed twice in image {iid}: apygis keeps one observation "
                    "of a point per image",
                    pt_path,
                    f"line {k}",
                )
            seen.add(iid)
            used[iid][j] = True
            u, v = uv_of[iid][j].tolist()
            x, y = transforms[iid].to_mm([[u - 0.5, v - 0.5]])[0].tolist()
            block.observations.append(ExObservation(nm, iid, x, y, u - 0.5, v - 0.5))
    unused = sum(int((~u).sum()) for u in used.values())
    if unused:
        block.skipped["points2D that no 3-D point's track names"] = unused
    for extra in ("rigs.txt", "frames.txt"):
        if (d / extra).is_file():
            block.skipped[f"{extra} (not read: each image's pose is in images.txt)"] = 1
    return block
