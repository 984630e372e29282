"""Pyramids on disk: luminance, levels by 2, windows with edge padding, reuse, pickling."""

from __future__ import annotations

import os
import pickle
import warnings

import numpy as np
import pytest
import rasterio
from rasterio.errors import NotGeoreferencedWarning

from apygis.aerotri.imagery import ArraySource, number_of_levels
from apygis.aerotri.pyramid import PyramidSource, build_pyramid
from apygis.errors import FormatError


def _write(path, a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        bands = a if a.ndim == 3 else a[None]
        c, h, w = bands.shape
        drv = kw.pop("driver", "GTiff")
        with rasterio.open(
            path, "w", driver=drv, width=w, height=h, count=c, dtype=a.dtype, **kw
        ) as d:
            d.write(bands)


@pytest.fixture
def grey(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (1100, 1500), dtype=np.uint8)
    p = tmp_path / "g.tif"
    _write(p, a)  # striped (not tiled) on purpose
    return p, a


def test_levels_windows_and_padding(grey, tmp_path):
    src_path, a = grey
    pyr = build_pyramid(src_path, tmp_path / "p" / "g.tif")
    s = PyramidSource(pyr)
    assert s.levels == number_of_levels(1100, 1500) == 3
    assert [s.shape(k) for k in range(3)] == [(1100, 1500), (550, 750), (275, 375)]
    assert np.array_equal(s.read(0, 10, 20, 30, 40), a[20:60, 10:40])
    # level 1 is the mean of 2 x 2 blocks (GDAL rounds to the integer type)
    mean = a[:4, :4].reshape(2, 2, 2, 2).mean(axis=(1, 3))
    assert np.abs(s.read(1, 0, 0, 2, 2) - mean).max() <= 0.5
    # outside the image the edge repeats
    w = s.read(0, -3, -2, 5, 4)
    assert np.array_equal(w[2:, 3:], a[:2, :2])
    assert np.array_equal(w[0], w[2])
    assert np.array_equal(w[:, 0], w[:, 3])
    far = s.read(0, 2000, 5000, 3, 3)
    assert np.all(far == a[-1, -1])
    s2 = pickle.loads(pickle.dumps(s))
    assert np.array_equal(s2.read(2, 5, 5, 8, 8), s.read(2, 5, 5, 8, 8))


def test_reused_when_current_rebuilt_when_changed(grey, tmp_path):
    src_path, a = grey
    pyr = build_pyramid(src_path, tmp_path / "g.pyr.tif")
    before = os.stat(pyr).st_mtime_ns
    build_pyramid(src_path, pyr)
    assert os.stat(pyr).st_mtime_ns == before
    _write(src_path, 255 - a)
    build_pyramid(src_path, pyr)
    assert np.array_equal(PyramidSource(pyr).read(0, 0, 0, 4, 4), (255 - a)[:4, :4])


def test_colour_jpeg_becomes_luminance(tmp_path):
    rng = np.random.default_rng(1)
    rgb = np.zeros((3, 300, 400), np.uint8)
    rgb[0], rgb[1], rgb[2] = 200, 100, 50
    rgb[:, 100:200, 100:300] = rng.integers(0, 255, (3, 100, 200), dtype=np.uint8)
    p = tmp_path / "c.tif"
    _write(p, rgb)
    s = PyramidSource(build_pyramid(p, tmp_path / "c.pyr.tif"))
    y = 0.299 * 200 + 0.587 * 100 + 0.114 * 50
    assert abs(s.read(0, 0, 0, 1, 1)[0, 0] - round(y)) < 1e-6
    ref = ArraySource(rgb.transpose(1, 2, 0).astype(float))
    assert np.abs(s.read(0, 100, 100, 50, 50) - ref.read(0, 100, 100, 50, 50)).max() <= 0.5


def test_unreadable_image(tmp_path):
    p = tmp_path / "bad.tif"
    p.write_bytes(b"II*\x00garbage")
    with pytest.raises(FormatError, match="cannot read the image"):
        build_pyramid(p, tmp_path / "x.tif")
    assert not (tmp_path / "x.tif").exists()
    assert not any(q.name.endswith(".tmp") for q in tmp_path.iterdir())
