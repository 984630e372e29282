"""What the text writers share: fixed-width number columns and the ESRI ``.prj`` text.

The APY ASCII, GENERATE (:mod:`~apygis.formats.arcinfo`) and E00 writers
format millions of numbers as byte matrices (one row a record, one column a
character), without a Python loop per number:

:func:`digit_columns`
    Zero-padded decimal digits (``0042``).
:func:`put_right`
    Right-aligned digits, spaces on the left and a ``-`` before the first
    digit of negative values (``   42``, `` -42``).

:func:`esri_wkt` is the CRS as ESRI WKT, as ``.prj`` files (GENERATE) and
E00's ``PRJ`` section hold it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["digit_columns", "esri_wkt", "put_right"]

_SP, _MINUS, _ZERO = 32, 45, 48


def digit_columns(values: np.ndarray, width: int) -> np.ndarray:
    """The last ``width`` decimal digits of non-negative integers, as ``(n, width)`` ASCII codes.

    The codes are integers (to be stored into a byte matrix, without a copy here).

    >>> digit_columns(np.array([42, 7]), 4).astype(np.uint8).tobytes()
    b'00420007'
    """
    pw = 10 ** np.arange(width - 1, -1, -1, dtype=np.int64)
    return _ZERO + (values[:, None] // pw[None, :]) % 10


def put_right(out: np.ndarray, col: int, width: int, a: np.ndarray, negative=None) -> None:
    """Write non-negative integers ``a`` right-aligned into ``out[:, col : col + width]``.

    Leading zeros become spaces (a value of 0 shows one ``0``); the rows
    where ``negative`` is true get a ``-`` just before their first digit.
    The columns left of the digits are not touched (``out`` is space-filled
    by the caller). The caller makes sure that the values, and the sign,
    fit ``width``.

    >>> out = np.full((3, 5), 32, np.uint8)
    >>> put_right(out, 0, 5, np.array([12, 1, 0]), np.array([False, True, False]))
    >>> out.tobytes()
    b'   12   -1    0'
    """
    top = int(a.max()) if len(a) else 0
    nd = min(width, len(str(top)))
    power = np.arange(nd - 1, -1, -1, dtype=np.int64)
    pw = 10**power
    show = (a[:, None] >= pw[None, :]) | (power[None, :] == 0)
    end = col + width
    out[:, end - nd : end] = np.where(show, _ZERO + (a[:, None] // pw[None, :]) % 10, _SP)
    if negative is not None:
        neg = np.flatnonzero(negative)
        out[neg, end - 1 - show[neg].sum(axis=1)] = _MINUS


def esri_wkt(crs) -> str:
    """The CRS as ESRI WKT (``WKT1_ESRI``); GDAL's WKT 1 (or WKT 2) where ESRI WKT cannot."""
    try:
        wkt = crs.to_wkt("WKT1_ESRI")
    except Exception:  # pyproj: CRSError, or None, where ESRI WKT cannot hold the CRS
        wkt = None
    if not wkt:
        wkt = crs.to_wkt("WKT1_GDAL") or crs.to_wkt()
    return wkt
