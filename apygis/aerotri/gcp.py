"""Control and new point measurement (``apygis at gcp``): manual, semi-automatic, automatic.

As the seed describes (``phodis-at.txt`` 3.3), the operator identifies a point
and digitises it; least-squares matching takes over the precise measurement:

* **manual**: every measurement is taken as digitised (``sigma_px`` as given,
  else :data:`MANUAL_SIGMA_PX`).
* **semi-automatic**: the point is digitised precisely in one image
  (``precise``) and approximately in others (``approx``); each approximate
  one is measured by least-squares matching of the precise image's template
  (:func:`apygis.aerotri.lsm.track`, affine + radiometric, from the pyramid
  level at which the approximation is within two pixels down to full
  resolution), with the LSM's own precision.
* **automatic**: the point is digitised precisely in one image only; it is
  predicted in every other image and measured there by least-squares matching
  of the same template (each image matched to the one reference template: the
  block adjustment then enforces the geometry). The prediction comes from the
  last adjustment (the point's ground position, given for full control, or
  its reference ray intersected with the height of the adjusted points around
  it, projected by each image's exterior orientation), or, before any
  adjustment, from the tie points: the local affine map of the 12 tie points
  nearest the point that both images share (the seed's "automatic
  prepositioning").

Every match is accepted by the LSM's convergence, its correlation
(``corr_min``) and precision, and by its distance from the prediction (at
most :data:`MAX_JUMP_PX` times the prediction's uncertainty); failures are
reported with the reason and nothing is stored for them.

Measurements come from a file (CSV ``point,image,x_px,y_px,mode[,sigma_px]``,
``mode`` one of ``precise``, ``approx``, ``manual``; pixels of the full
resolution, the centre of the top-left pixel at 0, 0) or the command line, so
the workflow is scriptable; a point not in the block is added as a new point
(kind ``new``). Each stored measurement replaces the point's earlier one in
that image. ``source`` in the observations: ``manual`` (as digitised),
``lsm-gcp`` (semi-automatic or automatic).

Guidance (:func:`guide`): the control points not yet measured, each with its
predicted position in every image that should see it (from the last
adjustment; before one, from the approximate orientations: then only to tens
of pixels) and, on request, a thumbnail per image (PNG) with the prediction
marked.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from apygis.aerotri.block import Block, BlockError
from apygis.aerotri.camera import PixelTransform
from apygis.aerotri.imagery import full_to_level
from apygis.errors import FormatError
from apygis.fileio import read_bytes

__all__ = [
    "GcpResult",
    "Measurement",
    "guide",
    "measure",
    "read_measurements",
]

#: Standard deviation of a point digitised by hand (pixels), when the file gives none.
MANUAL_SIGMA_PX = 0.3
#: Expected error of an approximate measurement (pixels): sets the first pyramid level.
APPROX_ERROR_PX = 8.0
#: A match may lie at most this many times the prediction's uncertainty from it.
MAX_JUMP_PX = 2.0
MODES = ("precise", "approx", "manual")


@dataclass(frozen=True)
class Measurement:
    """One digitised measurement: point name, image number, pixel (col, row), mode, sigma."""

    point: str
    image: int
    x_px: float
    y_px: float
    mode: str
    sigma_px: float | None = None


@dataclass
class GcpResult:
    """What :func:`measure` did: stored measurements ``(point, image, x, y, sigma, source,
    corr)``, failures ``(point, image, reason)`` and notes."""

    stored: list[tuple[str, int, float, float, float, str, float | None]] = field(
        default_factory=list
    )
    failed: list[tuple[str, int, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    new_points: list[str] = field(default_factory=list)


def read_measurements(path) -> list[Measurement]:
    """Read a measurement file (module docstring); errors name the file and line."""
    path = Path(path)
    try:
        text = read_bytes(path, "measurement file", 64 * 1024 * 1024).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    rows = [
        (n, r)
        for n, r in enumerate(csv.reader(io.StringIO(text)), 1)
        if r and not r[0].lstrip().startswith("#")
    ]
    if not rows:
        raise FormatError(f"{path}: no measurements")
    head = [c.strip().lower() for c in rows[0][1]]
    need = ["point", "image", "x_px", "y_px", "mode"]
    if head[:5] != need:
        raise FormatError(
            f"{path}: line {rows[0][0]}: expected the header {','.join(need)}[,sigma_px]"
        )
    out = []
    for n, r in rows[1:]:
        if len(r) not in (5, 6):
            raise FormatError(f"{path}: line {n}: expected 5 or 6 fields, got {len(r)}")
        name = r[0].strip()
        if not name or len(name) > 64 or not name.isprintable():
            raise FormatError(f"{path}: line {n}: point name {r[0]!r} (1-64 printable characters)")
        try:
            image = int(r[1])
            x, y = float(r[2]), float(r[3])
            s = float(r[5]) if len(r) == 6 and r[5].strip() else None
        except ValueError:
            raise FormatError(
                f"{path}: line {n}: expected image (whole number), x_px, y_px, sigma_px numbers"
            ) from None
        mode = r[4].strip().lower()
        if mode not in MODES:
            raise FormatError(f"{path}: line {n}: mode {r[4]!r} is not one of {', '.join(MODES)}")
        if not (math.isfinite(x) and math.isfinite(y)) or (s is not None and not 0 < s < 1e3):
            raise FormatError(
                f"{path}: line {n}: coordinates must be finite, sigma_px in (0, 1000)"
            )
        out.append(Measurement(name, image, x, y, mode, s))
    if not out:
        raise FormatError(f"{path}: no measurements after the header")
    return out


# --- prediction ----------------------------------------------------------------------------


class _Block:
    """What measuring needs from a block, loaded once."""

    def __init__(self, block: Block):
        self.block = block
        self.images = {im.image: im for im in block.images()}
        self.cams = block.cameras()
        interior = block.interior()
        self.T = {n: PixelTransform.from_list(v["transform"]) for n, v in interior.items()}
        self.ext = {
            r[0]: np.array(r[1:], float)
            for r in block.conn.execute("SELECT image, X, Y, Z, omega, phi, kappa FROM exterior")
        }
        self.points = {
            name: (pid, kind, X, Y, Z)
            for pid, name, kind, X, Y, Z in block.conn.execute(
                "SELECT id, name, kind, X, Y, Z FROM points"
            )
        }
        self._pyr: dict[int, Any] = {}

    def pyramid(self, n: int):
        """Image ``n``'s pyramid (built now if missing, as ``at match`` builds them)."""
        from apygis.aerotri.pyramid import PyramidSource, build_pyramid

        if n not in self._pyr:
            path = self.block.pyramid_folder / f"{n}.tif"
            if not path.is_file():
                build_pyramid(self.images[n].path, path)
            self._pyr[n] = PyramidSource(path)
        return self._pyr[n]

    def close(self) -> None:
        for p in self._pyr.values():
            p.close()

    def project(self, n: int, XYZ: np.ndarray) -> tuple[np.ndarray, bool]:
        """Pixel position of ground points in image ``n`` by its adjusted orientation (with the
        camera's distortion), and whether they lie in front of the camera."""
        from apygis.orient.rotation import rotation_matrix

        X0, Y0, Z0, om, ph, ka = self.ext[n]
        cam = self.cams[self.images[n].camera]
        R = rotation_matrix(om, ph, ka)
        q = (np.atleast_2d(XYZ) - [X0, Y0, Z0]) @ R
        front = bool((q[:, 2] < 0).all())
        ideal = np.c_[cam.x0_mm - cam.focal_mm * q[:, 0] / q[:, 2],
                      cam.y0_mm - cam.focal_mm * q[:, 1] / q[:, 2]]  # fmt: skip
        # the measured (distorted) photo coordinates: undistort(m) = ideal, by iteration
        m = ideal.copy()
        for _ in range(10):
            m = m + (ideal - cam.undistort(m))
        return self.T[n].to_px(m), front

    def ray_on_height(self, n: int, px: np.ndarray, Z: float) -> np.ndarray:
        from apygis.orient.rotation import rotation_matrix

        X0, Y0, Z0, om, ph, ka = self.ext[n]
        cam = self.cams[self.images[n].camera]
        mm = cam.undistort(self.T[n].to_mm(np.atleast_2d(px)))[0]
        d = rotation_matrix(om, ph, ka) @ np.array([mm[0] - cam.x0_mm, mm[1] - cam.y0_mm,
                                                    -cam.focal_mm])  # fmt: skip
        t = (Z - Z0) / d[2]
        return np.array([X0 + t * d[0], Y0 + t * d[1], Z])


def _ground_of(bk: _Block, name: str, ref: int, ref_px: np.ndarray) -> np.ndarray | None:
    """The point's ground position for prediction: given (full control), else its reference
    ray at the median height of the adjusted points nearest it in the reference image."""
    info = bk.points.get(name)
    if info is not None and info[1] == "full" and None not in info[2:]:
        return np.array(info[2:], float)
    rows = bk.block.conn.execute(
        "SELECT o.x_px, o.y_px, a.Z FROM observations o JOIN adjusted_points a "
        "ON a.point = o.point WHERE o.image = ?",
        (ref,),
    ).fetchall()
    if not rows or ref not in bk.ext:
        return None
    a = np.array(rows, float)
    d = np.hypot(a[:, 0] - ref_px[0], a[:, 1] - ref_px[1])
    Z = float(np.median(a[np.argsort(d)[:12], 2]))
    if info is not None and info[1] == "height" and info[4] is not None:
        Z = float(info[4])
    return bk.ray_on_height(ref, ref_px, Z)


def _tie_transfer(bk: _Block, a: int, b: int, px: np.ndarray):
    """The point ``px`` of image ``a`` in image ``b`` by the local affine map of the 12 nearest
    tie points both images share: ``(position, affine 2 x 2, spread px)`` or None."""
    rows = bk.block.conn.execute(
        "SELECT oa.x_px, oa.y_px, ob.x_px, ob.y_px FROM observations oa JOIN observations ob "
        "ON oa.point = ob.point WHERE oa.image = ? AND ob.image = ?",
        (a, b),
    ).fetchall()
    if len(rows) < 6:
        return None
    arr = np.array(rows, float)
    d = np.hypot(arr[:, 0] - px[0], arr[:, 1] - px[1])
    near = np.argsort(d)[:12]
    src, dst = arr[near, :2], arr[near, 2:]
    G = np.c_[src - px, np.ones(len(src))]
    coef, *_ = np.linalg.lstsq(G, dst, rcond=None)
    A = coef[:2].T
    pred = coef[2]
    res = dst - G @ coef
    spread = float(np.sqrt(np.mean(np.sum(res**2, axis=1)))) if len(src) > 3 else 5.0
    reach = float(d[near].max())
    return pred, A, max(spread, 0.5) + 0.01 * reach


def _local_affine(bk: _Block, a: int, b: int, px: np.ndarray) -> np.ndarray:
    t = _tie_transfer(bk, a, b, px)
    if t is not None:
        return t[1]
    # no common tie points: the rotation between the two images' photo axes
    ka = bk.ext.get(a, [0] * 6)[5] if a in bk.ext else _kappa(bk, a)
    kb = bk.ext.get(b, [0] * 6)[5] if b in bk.ext else _kappa(bk, b)
    Ta, Tb = bk.T[a].matrix[:2, :2], bk.T[b].matrix[:2, :2]
    c, s = math.cos(kb - ka), math.sin(kb - ka)
    Rot = np.array([[c, s], [-s, c]])
    return np.linalg.inv(Tb) @ Rot @ Ta


def _kappa(bk: _Block, n: int) -> float:
    im = bk.images[n]
    az = im.x_azimuth_deg if im.x_azimuth_deg is not None else (im.heading_deg or 90.0)
    return math.radians(90.0 - az)


# --- measuring -----------------------------------------------------------------------------


def _lsm(bk: _Block, ref: int, ref_px, img: int, approx_px, A, err_px, half, corr_min):
    """LSM of the reference template into ``img`` from the level where ``err_px`` shrinks to
    two pixels; returns ``(xy, sigma, corr, reason or '')``."""
    from apygis.aerotri.lsm import LsmReason, track

    src_r, src_s = bk.pyramid(ref), bk.pyramid(img)
    levels = min(src_r.levels, src_s.levels)
    start = int(min(max(math.ceil(math.log2(max(err_px, 1.0) / 2.0)), 0), levels - 1))
    res = track(
        src_r, src_s, np.atleast_2d(ref_px), full_to_level(np.atleast_2d(approx_px), start),
        np.asarray(A)[None], start=start, half=half, corr_min=corr_min,
    )  # fmt: skip
    xy = res.xy[0]
    if not res.ok[0]:
        return (
            xy,
            np.nan,
            float(res.corr[0]),
            ("lsm: " + LsmReason(int(res.reason[0])).name.lower().replace("_", " ")),
        )
    jump = float(np.hypot(*(xy - np.asarray(approx_px))))
    if jump > MAX_JUMP_PX * max(err_px, 1.0) + 2.0:
        return xy, np.nan, float(res.corr[0]), f"jumped {jump:.1f} px from the prediction"
    return xy, float(res.sigma[0]), float(res.corr[0]), ""


def measure(
    block: Block,
    measurements: list[Measurement],
    *,
    automatic: bool = False,
    half: int = 12,
    corr_min: float = 0.8,
    progress=None,
) -> GcpResult:
    """Store measurements (module docstring); returns a :class:`GcpResult`.

    ``automatic``: points digitised precisely in one image are predicted and
    measured in every other image that sees them. ``progress(done, total)``
    (:mod:`apygis.progress`) counts points.
    """
    bk = _Block(block)
    out = GcpResult()
    try:
        by_point: dict[str, list[Measurement]] = {}
        for m in measurements:
            if m.image not in bk.images:
                raise BlockError(
                    f"{block.path}: point {m.point}: image {m.image} is not in the block"
                )
            w, h = bk.images[m.image].width, bk.images[m.image].height
            if not (0 <= m.x_px <= w - 1 and 0 <= m.y_px <= h - 1):
                raise BlockError(
                    f"{block.path}: point {m.point}: ({m.x_px}, {m.y_px}) lies outside image "
                    f"{m.image} ({w} x {h} px)"
                )
            if m.image not in bk.T:
                raise BlockError(
                    f"{block.path}: image {m.image} has no interior orientation yet "
                    "(run 'apygis at match')"
                )
            by_point.setdefault(m.point, []).append(m)
        total = len(by_point)
        for k, (name, ms) in enumerate(by_point.items()):
            _measure_point(bk, out, name, ms, automatic, half, corr_min)
            if progress is not None:
                progress(k + 1, total)
        if progress is not None and total == 0:
            progress(0, 0)
        _store(bk, out)
    finally:
        bk.close()
    return out


def _measure_point(bk: _Block, out: GcpResult, name, ms, automatic, half, corr_min) -> None:
    precise = [m for m in ms if m.mode == "precise"]
    if len(precise) > 1:
        raise BlockError(
            f"{bk.block.path}: point {name}: digitised precisely in {len(precise)} images "
            f"({', '.join(str(m.image) for m in precise)}); one is the reference"
        )
    for m in ms:
        if m.mode in ("manual", "precise"):
            s = m.sigma_px or MANUAL_SIGMA_PX
            out.stored.append((name, m.image, m.x_px, m.y_px, s, "manual", None))
    approx = [m for m in ms if m.mode == "approx"]
    if approx and not precise:
        raise BlockError(
            f"{bk.block.path}: point {name}: approximate measurements need one precise one "
            "(the template) in another image"
        )
    if not precise:
        return
    ref = precise[0].image
    ref_px = np.array([precise[0].x_px, precise[0].y_px])
    done = {m.image for m in ms if m.mode != "approx"}
    for m in approx:
        A = _local_affine(bk, ref, m.image, ref_px)
        xy, s, c, why = _lsm(bk, ref, ref_px, m.image, [m.x_px, m.y_px], A, APPROX_ERROR_PX,
                             half, corr_min)  # fmt: skip
        _record(out, name, m.image, xy, s, c, why)
        done.add(m.image)
    if automatic:
        for img, pred, A, err in _predictions(bk, name, ref, ref_px):
            if img in done:
                continue
            xy, s, c, why = _lsm(bk, ref, ref_px, img, pred, A, err, half, corr_min)
            _record(out, name, img, xy, s, c, why)


def _record(out: GcpResult, name, img, xy, s, c, why) -> None:
    if why:
        out.failed.append((name, img, why))
    else:
        out.stored.append((name, img, float(xy[0]), float(xy[1]), s, "lsm-gcp", c))


def _predictions(bk: _Block, name: str, ref: int, ref_px: np.ndarray):
    """``(image, predicted px, affine, uncertainty px)`` for every image that should see the
    point: by the adjustment where there is one, else by tie point transfer."""
    out = []
    g = _ground_of(bk, name, ref, ref_px) if bk.ext else None
    for n, im in bk.images.items():
        if n == ref or n not in bk.T:
            continue
        if g is not None and n in bk.ext:
            px, front = bk.project(n, g[None])
            px = px[0]
            err = 3.0
        else:
            t = _tie_transfer(bk, ref, n, ref_px)
            if t is None:
                continue
            px, _, err = t
            front = True
        margin = 20
        if not front or not (margin <= px[0] <= im.width - 1 - margin
                             and margin <= px[1] <= im.height - 1 - margin):  # fmt: skip
            continue
        out.append((n, px, _local_affine(bk, ref, n, ref_px), err))
    return out


def _store(bk: _Block, out: GcpResult) -> None:
    block = bk.block
    new = sorted({s[0] for s in out.stored} - set(bk.points))
    if new:
        block.add_points({"name": n, "kind": "new"} for n in new)
        out.new_points = new
    ids = {n: pid for pid, n in block.conn.execute("SELECT id, name FROM points")}
    rows = []
    for name, img, x, y, s, src, c in out.stored:
        mm = bk.T[img].to_mm([[x, y]])[0]
        rows.append((ids[name], img, x, y, float(mm[0]), float(mm[1]), s, c, src))
    with block.conn:
        block.conn.executemany(
            "INSERT OR REPLACE INTO observations VALUES (?,?,?,?,?,?,?,?,?)", rows
        )


# --- guidance ------------------------------------------------------------------------------


def guide(block: Block, *, thumbnails=None, size_px: int = 128) -> list[dict]:
    """The control points not measured yet, each with its predicted position in every image
    that should see it (module docstring); thumbnails (PNG) into the folder ``thumbnails``."""
    bk = _Block(block)
    try:
        measured = {
            r[0] for r in block.conn.execute(
                "SELECT DISTINCT p.name FROM observations o JOIN points p ON p.id = o.point "
                "WHERE p.kind != 'tie'"
            )
        }  # fmt: skip
        out = []
        for name, (_pid, kind, X, Y, Z) in sorted(bk.points.items()):
            if kind not in ("full", "planimetric", "height", "check") or name in measured:
                continue
            if None in (X, Y):
                continue
            Zg = Z if Z is not None else _mean_height(block)
            g = np.array([X, Y, Zg], float)
            source = "adjustment" if bk.ext else "approximate orientation"
            images = []
            for n, im in bk.images.items():
                if n not in bk.T:
                    continue
                if n in bk.ext:
                    px, front = bk.project(n, g[None])
                    err = 3.0
                else:
                    px, front = _approx_project(bk, n, g)
                    err = 0.05 * max(im.width, im.height)
                p = px[0] if px.ndim == 2 else px
                if not front or not (0 <= p[0] <= im.width - 1 and 0 <= p[1] <= im.height - 1):
                    continue
                entry: dict[str, object] = {"image": n, "x_px": float(p[0]),
                                            "y_px": float(p[1]), "uncertainty_px": err}  # fmt: skip
                if thumbnails is not None:
                    entry["thumbnail"] = str(_thumbnail(bk, name, n, p, err, Path(thumbnails),
                                                        size_px))  # fmt: skip
                images.append(entry)
            out.append({"point": name, "kind": kind, "X": X, "Y": Y, "Z": Z,
                        "prediction": source, "images": images})  # fmt: skip
        return out
    finally:
        bk.close()


def _mean_height(block: Block) -> float:
    from apygis.aerotri.project import terrain_height

    try:
        return terrain_height(block)
    except BlockError:
        return 0.0


def _approx_project(bk: _Block, n: int, g: np.ndarray):
    """Projection by the approximate orientation (vertical photo at the approximate centre)."""
    im = bk.images[n]
    if None in (im.X, im.Y, im.Z):
        return np.array([-1.0, -1.0]), False
    bk.ext[n] = np.array([im.X, im.Y, im.Z, 0.0, 0.0, _kappa(bk, n)])
    try:
        px, front = bk.project(n, g[None])
    finally:
        del bk.ext[n]
    return px[0], front


def _thumbnail(bk: _Block, name: str, n: int, p, err: float, folder: Path, size: int) -> Path:
    """A PNG of the image around the predicted position (the level where the uncertainty
    fits), the prediction marked by a cross and a circle of its uncertainty."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    from apygis.fileio import atomic_write

    src = bk.pyramid(n)
    levels = src.levels
    level = int(min(max(math.ceil(math.log2(max(4 * err, size) / size)), 0), levels - 1))
    c = full_to_level(np.array([p]), level)[0]
    half = size // 2
    win = src.read(level, int(c[0]) - half, int(c[1]) - half, size, size)
    fig = Figure(figsize=(2.4, 2.6))
    ax = fig.add_axes((0.02, 0.08, 0.96, 0.84))
    x0, y0 = int(c[0]) - half, int(c[1]) - half
    ax.imshow(win, cmap="gray", extent=(x0 - 0.5, x0 + size - 0.5, y0 + size - 0.5, y0 - 0.5))
    ax.plot([c[0]], [c[1]], "+", color="#ff2020", ms=14, mew=1.5)
    r = err / 2**level
    ax.add_patch(Circle((c[0], c[1]), r, fill=False, ec="#ffcc00", lw=1))
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"{name} in {n} (level {level})", fontsize=8)
    fig.text(0.5, 0.02, f"x {p[0]:.0f}  y {p[1]:.0f} px", ha="center", fontsize=7)
    buf = io.BytesIO()
    FigureCanvasAgg(fig).print_figure(buf, format="png", dpi=100)
    path = folder / f"{name}-{n}.png"
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write(path, buf.getvalue(), parents=True)
    return path
