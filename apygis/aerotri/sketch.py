"""Point sketches (``apygis at sketch``): one page per control or new point, as PHODIS AT
made them (seed ``phodis-at.txt`` 5.1).

Each page (A4 portrait, PDF through matplotlib's PDF backend, fonts embedded) holds:

* the **overview**: the whole image in which the point lies nearest the centre, from a
  coarse pyramid level, the point circled;
* the **detail**: that image at full resolution around the point (``detail_px`` pixels
  square) with the measured position as a cross;
* the point's other measurements as smaller details, up to :data:`MAX_OTHERS`;
* the name, kind, given and adjusted coordinates with their standard deviations, the
  image numbers, files and pixel positions with their sigmas, the block, and the date.

Images are read from the block's pyramids (by window), never whole at full resolution.
"""

from __future__ import annotations

import io
import math
import time
from pathlib import Path

import numpy as np

from apygis.aerotri.block import Block, BlockError
from apygis.fileio import atomic_write

__all__ = ["MAX_OTHERS", "sketch_points"]

#: At most this many further images per page (smaller details).
MAX_OTHERS = 4
_KINDS = ("full", "planimetric", "height", "check", "new")


def _points(block: Block, names) -> list[dict]:
    rows = block.conn.execute(
        "SELECT p.id, p.name, p.kind, p.X, p.Y, p.Z, p.sigma_xy_m, p.sigma_z_m, "
        "a.X, a.Y, a.Z, a.sX, a.sY, a.sZ FROM points p LEFT JOIN adjusted_points a "
        "ON a.point = p.id WHERE p.kind IN (?, ?, ?, ?, ?) ORDER BY p.name",
        _KINDS,
    ).fetchall()
    keys = ("id", "name", "kind", "X", "Y", "Z", "sxy", "sz", "aX", "aY", "aZ", "asX", "asY",
            "asZ")  # fmt: skip
    pts = [dict(zip(keys, r, strict=True)) for r in rows]
    if names:
        known = {p["name"] for p in pts}
        unknown = [n for n in names if n not in known]
        if unknown:
            raise BlockError(f"{block.path}: no control or new point named {', '.join(unknown)}")
        pts = [p for p in pts if p["name"] in set(names)]
    for p in pts:
        p["obs"] = block.conn.execute(
            "SELECT image, x_px, y_px, sigma_px, source FROM observations WHERE point = ? "
            "ORDER BY image",
            (p["id"],),
        ).fetchall()
    return [p for p in pts if p["obs"]]


def sketch_points(block: Block, path, *, names=(), detail_px: int = 96, progress=None) -> int:
    """Write the point sketches of ``names`` (default: every measured control and new point)
    to the PDF ``path`` (atomically); returns the number of pages.

    ``progress(done, total)`` (:mod:`apygis.progress`) counts pages.
    """
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure

    from apygis.aerotri.pyramid import PyramidSource, build_pyramid

    path = Path(path)
    if path.suffix.lower() != ".pdf":
        raise BlockError(f"{path}: point sketches are written as PDF (.pdf)")
    pts = _points(block, names)
    if not pts:
        raise BlockError(f"{block.path}: no control or new point is measured yet ('apygis at gcp')")
    images = {im.image: im for im in block.images()}
    sources: dict[int, PyramidSource] = {}

    def src(n: int) -> PyramidSource:
        if n not in sources:
            f = block.pyramid_folder / f"{n}.tif"
            if not f.is_file():
                build_pyramid(images[n].path, f)
            sources[n] = PyramidSource(f)
        return sources[n]

    buf = io.BytesIO()
    today = time.strftime("%Y-%m-%d")
    try:
        with PdfPages(buf, metadata={"Title": f"Point sketches of {block.path.name}",
                                     "Creator": "apygis at sketch"}) as pdf:  # fmt: skip
            for k, p in enumerate(pts):
                fig = Figure(figsize=(8.27, 11.69))
                _page(fig, block, p, images, src, detail_px, today)
                pdf.savefig(fig)
                if progress is not None:
                    progress(k + 1, len(pts))
    finally:
        for s in sources.values():
            s.close()
    atomic_write(path, buf.getvalue(), parents=True)
    return len(pts)


def _nearest_centre(p, images) -> tuple:
    def off(o):
        im = images[o[0]]
        return (o[1] / im.width - 0.5) ** 2 + (o[2] / im.height - 0.5) ** 2

    return min(p["obs"], key=off)


def _window(src, level: int, cx: float, cy: float, size: int):
    """A ``size`` square window of a level around ``(cx, cy)`` (level pixels) and its
    extent for imshow."""
    c0, r0 = round(cx) - size // 2, round(cy) - size // 2
    a = src.read(level, c0, r0, size, size)
    return a, (c0 - 0.5, c0 + size - 0.5, r0 + size - 0.5, r0 - 0.5)


def _page(fig, block: Block, p: dict, images, src, detail_px: int, today: str) -> None:
    from matplotlib.patches import Circle

    from apygis.aerotri.imagery import full_to_level

    main = _nearest_centre(p, images)
    n, x, y, _, _ = main
    im = images[n]
    S = src(n)
    fig.text(0.06, 0.955, f"Point {p['name']}", fontsize=20, weight="bold")
    fig.text(0.06, 0.935, f"{_kind(p['kind'])}  -  block {block.path.name}  -  {today}",
             fontsize=10)  # fmt: skip
    # overview: the coarsest level at least 700 px on its long side
    lvl = 0
    while lvl + 1 < S.levels and max(S.shape(lvl + 1)) >= 700:
        lvl += 1
    H, W = S.shape(lvl)
    ov = S.read(lvl, 0, 0, W, H)
    ax = fig.add_axes((0.06, 0.5, 0.5, 0.41))
    ax.imshow(ov, cmap="gray", extent=(-0.5, W - 0.5, H - 0.5, -0.5))
    c = full_to_level(np.array([[x, y]]), lvl)[0]
    ax.add_patch(Circle((c[0], c[1]), 0.04 * max(W, H), fill=False, ec="#ff2020", lw=2))
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"overview: image {n} ({Path(im.path).name})", fontsize=9)
    # detail at full resolution
    ax = fig.add_axes((0.6, 0.62, 0.34, 0.29))
    a, ext = _window(S, 0, x, y, detail_px)
    ax.imshow(a, cmap="gray", extent=ext, interpolation="nearest")
    ax.plot([x], [y], "+", color="#ff2020", ms=22, mew=1.2)
    ax.add_patch(Circle((x, y), 6, fill=False, ec="#ff2020", lw=1))
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"detail, full resolution ({detail_px} px)", fontsize=9)
    ax.text(0.02, 0.02, f"x {x:.2f}  y {y:.2f} px", transform=ax.transAxes, fontsize=8,
            color="white", backgroundcolor=(0, 0, 0, 0.5))  # fmt: skip
    # other measurements
    others = [o for o in p["obs"] if o is not main][:MAX_OTHERS]
    for k, (n2, x2, y2, _s2, _src2) in enumerate(others):
        ax = fig.add_axes((0.06 + k * 0.225, 0.3, 0.2, 0.16))
        a, ext = _window(src(n2), 0, x2, y2, detail_px)
        ax.imshow(a, cmap="gray", extent=ext, interpolation="nearest")
        ax.plot([x2], [y2], "+", color="#ff2020", ms=14, mew=1.0)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"image {n2}", fontsize=8)
    # the table
    lines = []
    if p["X"] is not None or p["Z"] is not None:
        lines.append(("given", _xyz(p["X"], p["Y"], p["Z"]),
                      f"sigma {_f(p['sxy'])} / {_f(p['sz'])} m"))  # fmt: skip
    if p["aX"] is not None:
        lines.append(("adjusted", _xyz(p["aX"], p["aY"], p["aZ"]),
                      f"sigma {_f(p['asX'])} {_f(p['asY'])} {_f(p['asZ'])} m"))  # fmt: skip
    y0 = 0.25
    for label, xyz, sig in lines:
        fig.text(0.06, y0, f"{label:<9}", fontsize=10, family="monospace")
        fig.text(0.18, y0, xyz, fontsize=10, family="monospace")
        fig.text(0.66, y0, sig, fontsize=9)
        y0 -= 0.022
    y0 -= 0.01
    fig.text(0.06, y0, "measurements", fontsize=10, weight="bold")
    y0 -= 0.02
    for n2, x2, y2, s2, src2 in p["obs"][:12]:
        name = Path(images[n2].path).name
        fig.text(0.06, y0, f"image {n2:<8} {name[:28]:<28} x {x2:9.2f}  y {y2:9.2f} px  "
                 f"sigma {_f(s2, 3)} px  ({src2})", fontsize=8, family="monospace")  # fmt: skip
        y0 -= 0.016
    if len(p["obs"]) > 12:
        fig.text(0.06, y0, f"... and {len(p['obs']) - 12} more", fontsize=8)


def _kind(k: str) -> str:
    return {"full": "full control point", "planimetric": "planimetric control point",
            "height": "height control point", "check": "check point",
            "new": "new point"}.get(k, k)  # fmt: skip


def _xyz(X, Y, Z) -> str:
    return "  ".join("-" if v is None else f"{v:.3f}" for v in (X, Y, Z))


def _f(v, nd: int = 3) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"
