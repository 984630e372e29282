"""Image pyramids on disk, built once per image and read by window.

:func:`build_pyramid` reads an image (any raster GDAL reads: TIFF tiled or
striped, JPEG, JPEG 2000, ...) in bands of rows, reduces colour to one
luminance band (ITU-R BT.601: ``0.299 R + 0.587 G + 0.114 B``; 8-bit stays
8-bit, 16-bit stays 16-bit, rounded), writes it as a tiled GeoTIFF in the
block's pyramid folder, and adds overviews by factors of 2 (GDAL's AVERAGE:
the mean of ``2**k x 2**k`` blocks) down to about 256 pixels. Memory stays at a
few bands of rows whatever the image size; the source image is never written
to (it may be read-only).

:class:`PyramidSource` is the :class:`~apygis.aerotri.imagery.ImageSource` of
such a file: ``read(level, col0, row0, width, height)`` reads one window of
one level, padded by repeating the edge outside the image. It keeps its
datasets open, and pickles as its path (so Dask workers reopen it where the
task runs).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from apygis.aerotri.imagery import number_of_levels
from apygis.errors import FormatError

__all__ = ["PyramidSource", "build_pyramid", "pyramid_is_current"]

TILE = 256
_ROWS = 512


def _luminance(a: np.ndarray, dtype) -> np.ndarray:
    if a.shape[0] >= 3:
        y = 0.299 * a[0].astype(np.float32) + 0.587 * a[1] + 0.114 * a[2]
    else:
        y = a[0].astype(np.float32)
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        return np.clip(np.rint(y), info.min, info.max).astype(dtype)
    return y.astype(dtype)


def _stamp(src: Path) -> str:
    st = src.stat()
    return f"{st.st_size}:{st.st_mtime_ns}"


def pyramid_is_current(image: Path, pyramid: Path) -> bool:
    """Whether ``pyramid`` was built from ``image`` as it is now (size and mtime)."""
    import rasterio

    if not pyramid.is_file():
        return False
    try:
        with _Quiet(), rasterio.open(pyramid) as ds:
            return ds.tags().get("APYGIS_SOURCE") == _stamp(image)
    except Exception:  # a damaged or foreign file: rebuild
        return False


class _Quiet:
    """Silence rasterio's NotGeoreferencedWarning (aerial scans have no georeferencing)."""

    def __enter__(self):
        from rasterio.errors import NotGeoreferencedWarning

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", NotGeoreferencedWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


def build_pyramid(image, pyramid, *, smallest: int = 256, progress=None) -> Path:
    """Build (or reuse, when current) the pyramid file of ``image`` at ``pyramid``.

    ``progress(done, total)`` (:mod:`apygis.progress`) counts rows of the full
    resolution written, with a third more for the overviews; a current pyramid
    reports ``(0, 0)`` (nothing to do).
    """
    import rasterio
    from rasterio.enums import Resampling
    from rasterio.errors import RasterioIOError
    from rasterio.windows import Window

    image, pyramid = Path(image), Path(pyramid)
    if pyramid_is_current(image, pyramid):
        if progress is not None:
            progress(0, 0)
        return pyramid
    pyramid.parent.mkdir(parents=True, exist_ok=True)
    tmp = pyramid.with_name(f".{pyramid.name}.{os.getpid()}.tmp")
    try:
        with _Quiet(), rasterio.open(image) as src:
            if src.count not in (1, 2, 3, 4):
                raise FormatError(f"{image}: {src.count} bands (expected grey or RGB)")
            dt = np.dtype(src.dtypes[0])
            if dt not in (np.uint8, np.uint16):
                dt = np.dtype(np.float32)
            H, W = src.height, src.width
            if min(H, W) < 32:
                raise FormatError(f"{image}: {W} x {H} pixels is too small for an aerial image")
            profile = {
                "driver": "GTiff",
                "width": W,
                "height": H,
                "count": 1,
                "dtype": dt.name,
                "tiled": True,
                "blockxsize": TILE,
                "blockysize": TILE,
                "compress": "deflate",
                "predictor": 2,
                "BIGTIFF": "IF_SAFER",
            }
            bands = list(range(1, min(src.count, 3) + 1))
            total = H + H // 3
            with rasterio.open(tmp, "w", **profile) as dst:
                for r0 in range(0, H, _ROWS):
                    h = min(_ROWS, H - r0)
                    a = src.read(bands, window=Window(0, r0, W, h))
                    dst.write(_luminance(a, dt), 1, window=Window(0, r0, W, h))
                    if progress is not None:
                        progress(min(r0 + h, H), total)
                n = number_of_levels(H, W, smallest)
                if n > 1:
                    dst.build_overviews([2**k for k in range(1, n)], Resampling.average)
                dst.update_tags(APYGIS_SOURCE=_stamp(image))
        os.replace(tmp, pyramid)
    except RasterioIOError as exc:
        raise FormatError(f"{image}: cannot read the image ({exc})") from None
    finally:
        if tmp.exists():
            tmp.unlink()
    if progress is not None:
        progress(total, total)
    return pyramid


class PyramidSource:
    """Windows of a pyramid file at any level (an ImageSource; see the module docstring)."""

    def __init__(self, path):
        self.path = Path(path)
        self._ds: dict[int, Any] = {}
        import rasterio

        with _Quiet(), rasterio.open(self.path) as ds:
            self._shapes = [(ds.height, ds.width)]
            for f in ds.overviews(1):
                self._shapes.append((-(-ds.height // f), -(-ds.width // f)))

    def __getstate__(self):
        return {"path": self.path}

    def __setstate__(self, state):
        fresh = PyramidSource(state["path"])
        self.__dict__.update(fresh.__dict__)

    @property
    def levels(self) -> int:
        return len(self._shapes)

    def shape(self, level: int) -> tuple[int, int]:
        return self._shapes[level]

    def _dataset(self, level: int):
        ds = self._ds.get(level)
        if ds is None:
            import rasterio

            with _Quiet():
                kw = {} if level == 0 else {"overview_level": level - 1}
                ds = rasterio.open(self.path, **kw)
            self._ds[level] = ds
        return ds

    def read(self, level: int, col0: int, row0: int, width: int, height: int) -> np.ndarray:
        from rasterio.windows import Window

        H, W = self._shapes[level]
        rows = np.clip(np.arange(row0, row0 + height), 0, H - 1)
        cols = np.clip(np.arange(col0, col0 + width), 0, W - 1)
        r0, c0 = int(rows[0]), int(cols[0])
        win = Window(c0, r0, int(cols[-1]) - c0 + 1, int(rows[-1]) - r0 + 1)
        a = self._dataset(level).read(1, window=win).astype(np.float32)
        if a.shape == (height, width):
            return a
        return a[np.ix_(rows - r0, cols - c0)]

    def close(self) -> None:
        for ds in self._ds.values():
            ds.close()
        self._ds.clear()
