"""Images read by window, at any pyramid level.

Every matching and measuring step sees an image through :class:`ImageSource`:
``source.shape(level)`` and ``source.read(level, col0, row0, width, height)``,
a float32 luminance window of pyramid level ``level`` (level 0 = full
resolution; level ``k`` averages ``2**k x 2**k`` blocks, see the pixel
conventions of :mod:`apygis.aerotri`). Windows reaching outside the image are
padded by repeating the edge, so callers need not clip.

:class:`ArraySource` holds an array in memory (tests, small images);
:mod:`apygis.aerotri.pyramid` gives the file-backed source that never holds a
whole image.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

__all__ = ["ArraySource", "ImageSource", "full_to_level", "level_to_full", "reduce2"]


class ImageSource(Protocol):
    """What a measuring step needs from an image (see the module docstring)."""

    @property
    def levels(self) -> int:
        """Number of pyramid levels (level 0 included)."""
        ...

    def shape(self, level: int) -> tuple[int, int]:
        """``(height, width)`` of a level, pixels."""
        ...

    def read(self, level: int, col0: int, row0: int, width: int, height: int) -> np.ndarray:
        """A ``height x width`` float32 window of a level (edge-padded outside)."""
        ...


def level_to_full(xy, level: int) -> np.ndarray:
    """Level-0 pixel coordinates of level-``level`` pixel coordinates (n x 2)."""
    f = 2.0**level
    return np.asarray(xy, dtype=float) * f + (f - 1.0) / 2.0


def full_to_level(xy, level: int) -> np.ndarray:
    """Level-``level`` pixel coordinates of level-0 pixel coordinates (n x 2)."""
    f = 2.0**level
    return (np.asarray(xy, dtype=float) - (f - 1.0) / 2.0) / f


def reduce2(a: np.ndarray) -> np.ndarray:
    """The next pyramid level: the mean of 2 x 2 blocks (an odd last row/column is dropped)."""
    h, w = a.shape[0] // 2 * 2, a.shape[1] // 2 * 2
    a = a[:h, :w].astype(np.float32)
    return 0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])


def number_of_levels(height: int, width: int, smallest: int = 256) -> int:
    """Levels of a pyramid by factors of 2 down to about ``smallest`` pixels (long side)."""
    n, side = 1, max(height, width)
    while side // 2 >= smallest:
        side //= 2
        n += 1
    return n


def window(a: np.ndarray, col0: int, row0: int, width: int, height: int) -> np.ndarray:
    """A window of ``a`` with edge padding outside (float32)."""
    H, W = a.shape
    r = np.clip(np.arange(row0, row0 + height), 0, H - 1)
    c = np.clip(np.arange(col0, col0 + width), 0, W - 1)
    if row0 >= 0 and row0 + height <= H and col0 >= 0 and col0 + width <= W:
        return np.asarray(a[row0 : row0 + height, col0 : col0 + width], dtype=np.float32)
    return np.asarray(a[np.ix_(r, c)], dtype=np.float32)


class ArraySource:
    """An :class:`ImageSource` over an in-memory array (a pyramid built at once)."""

    def __init__(self, image, smallest: int = 256):
        a = np.asarray(image)
        if a.ndim == 3:  # colour: luminance (ITU-R BT.601)
            a = a[..., 0] * 0.299 + a[..., 1] * 0.587 + a[..., 2] * 0.114
        self._levels = [np.asarray(a, dtype=np.float32)]
        for _ in range(number_of_levels(a.shape[0], a.shape[1], smallest) - 1):
            self._levels.append(reduce2(self._levels[-1]))

    @property
    def levels(self) -> int:
        return len(self._levels)

    def shape(self, level: int) -> tuple[int, int]:
        h, w = self._levels[level].shape
        return int(h), int(w)

    def read(self, level: int, col0: int, row0: int, width: int, height: int) -> np.ndarray:
        return window(self._levels[level], col0, row0, width, height)

    def array(self, level: int) -> np.ndarray:
        """The whole level (for small images and tests)."""
        return self._levels[level]
