"""The pin plot: the drawing rasterised, antialiased, as PNG or (Geo)TIFF.

APY's "neat NEC Pin-Plot" was the quick raster check plot beside the pen
plotter. Here it is the very figure the PDF comes from
(:mod:`apygis.plot._mpl`) rendered by matplotlib's Agg at ``dpi`` dots per
inch, antialiased, on white:

* ``.png``: 8-bit RGBA, the resolution recorded (pHYs);
* ``.tif``: an RGB GeoTIFF (deflate) whose pixels carry the plot's ground
  coordinates (the paper is a linear image of the ground: the affine
  transform and the CRS are written, so GIS software overlays it in
  place); written through rasterio.

A raster larger than :data:`MAX_PIXELS` (or :data:`MAX_SIDE` on a side)
is refused before anything is drawn, naming the dpi that would fit.

Examples
--------
>>> raster_size(210.0, 297.0, 300)
(2480, 3507)
"""

from __future__ import annotations

import io
import math

import numpy as np

from apygis.errors import FormatError
from apygis.plot._mpl import RC, drawing_figure
from apygis.plot.fonts import quiet_missing_glyphs
from apygis.progress import Progress

__all__ = ["MAX_PIXELS", "MAX_SIDE", "drawing_png", "drawing_rgba", "drawing_tiff", "raster_size"]

#: The largest pin plot, in pixels (about 1 GB of RGBA while it is drawn).
MAX_PIXELS = 250_000_000
#: The longest side of a pin plot, in pixels (the renderer's limit).
MAX_SIDE = 65_000


def raster_size(width_mm: float, height_mm: float, dpi: float) -> tuple[int, int]:
    """Pixels ``(width, height)`` of a sheet at ``dpi``: whole pixels, as the renderer cuts them.

    A pixel is exactly 25.4 / ``dpi`` mm; the paper's last fraction of a pixel (right and
    top) is left off.
    """
    return (math.floor(width_mm / 25.4 * dpi + 1e-6), math.floor(height_mm / 25.4 * dpi + 1e-6))


def _check(d, dpi: float) -> tuple[int, int]:
    if not (math.isfinite(dpi) and dpi > 0):
        raise FormatError(f"the pin plot's resolution must be a positive dpi, not {dpi!r}")
    w, h = raster_size(d.width_mm, d.height_mm, dpi)
    if w * h > MAX_PIXELS or max(w, h) > MAX_SIDE:
        fit = min(
            dpi * math.sqrt(MAX_PIXELS / max(w * h, 1)),
            dpi * MAX_SIDE / max(w, h, 1),
        )
        raise FormatError(
            f"a pin plot of {d.paper} ({d.width_mm:g} x {d.height_mm:g} mm) at {dpi:g} dpi "
            f"would be {w} x {h} pixels ({w * h / 1e6:.0f} Mpx); the limit is "
            f"{MAX_PIXELS / 1e6:.0f} Mpx and {MAX_SIDE} pixels a side: "
            f"use {math.floor(fit)} dpi or less"
        )
    if w < 1 or h < 1:
        raise FormatError(f"a pin plot at {dpi:g} dpi of {d.paper} would have no pixels")
    return w, h


def drawing_png(d, dpi: float = 300, progress: Progress | None = None) -> bytes:
    """The drawing as a PNG at ``dpi`` (antialiased, white background).

    ``progress(done, total)`` follows the rendering (:mod:`apygis.progress`).
    """
    import matplotlib

    _check(d, dpi)
    with matplotlib.rc_context(RC), quiet_missing_glyphs():
        fig = drawing_figure(d, progress)
        buf = io.BytesIO()
        fig.savefig(
            buf,
            format="png",
            dpi=dpi,
            facecolor="white",
            metadata={"Software": "apygis", "Title": f"{d.map_id} 1:{d.scale}"},
        )
    return buf.getvalue()


def drawing_rgba(d, dpi: float = 300, progress: Progress | None = None) -> np.ndarray:
    """The drawing rendered at ``dpi``: an (rows, cols, 4) uint8 RGBA array, row 0 at the top.

    ``progress(done, total)`` follows the rendering (:mod:`apygis.progress`).
    """
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    _check(d, dpi)
    with matplotlib.rc_context(RC), quiet_missing_glyphs():
        fig = drawing_figure(d, progress)
        fig.set_dpi(dpi)
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        return np.asarray(canvas.buffer_rgba()).copy()


def drawing_tiff(d, dpi: float = 300, progress: Progress | None = None) -> bytes:
    """The drawing as an RGB GeoTIFF at ``dpi``, georeferenced to the ground in the plot's CRS.

    A drawing without a CRS gets the transform only.
    ``progress(done, total)`` follows the rendering (:mod:`apygis.progress`).
    """
    import rasterio
    from rasterio.io import MemoryFile
    from rasterio.transform import Affine

    rgba = drawing_rgba(d, dpi, progress)
    rows, cols = rgba.shape[:2]
    # a pixel is 25.4 / dpi mm of paper; row 0 starts `rows` pixels above the paper's bottom
    px = 25.4 / dpi / d.mm_per_unit
    transform = Affine(px, 0.0, d.origin[0], 0.0, -px, d.origin[1] + rows * px)
    profile = {
        "driver": "GTiff",
        "width": cols,
        "height": rows,
        "count": 3,
        "dtype": "uint8",
        "compress": "deflate",
        "photometric": "RGB",
        "transform": transform,
        "tiled": True,
    }
    if d.crs is not None:
        profile["crs"] = rasterio.crs.CRS.from_wkt(d.crs.to_wkt())
    with MemoryFile() as mem:
        with mem.open(**profile) as dst:
            dst.write(np.moveaxis(rgba[:, :, :3], 2, 0))
            dst.update_tags(
                TIFFTAG_SOFTWARE="apygis", TIFFTAG_DOCUMENTNAME=f"{d.map_id} 1:{d.scale}"
            )
        return mem.read()
