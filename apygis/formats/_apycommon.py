"""What the two APY native formats (binary and ASCII) share: limits and conversions.

APY stores coordinates as integer centimetres: X and Y in at most 9 digits,
Z in at most 6 (a sign is stored apart from the digits), point numbers in 4
digits (0-9999), codes in 2, texts in 24 characters of ISO 8859-1.
"""

from __future__ import annotations

import logging

import numpy as np

from apygis.errors import CapacityError, ValueRangeError
from apygis.model.records import (
    APY_CAPACITY,
    APY_MAX_NUM,
    NO_REF,
    REF_FIELDS,
    TABLE_WORDS,
    TEXT_LEN,
)

log = logging.getLogger("apygis.formats.apy")

__all__ = [
    "MAX_XY_CM",
    "MAX_Z_CM",
    "check_layer_for_apy",
    "cm_to_m",
    "encode_latin1",
    "fit_texts",
    "m_to_cm",
]

MAX_XY_CM = 999_999_999
MAX_Z_CM = 999_999


def m_to_cm(values: np.ndarray) -> np.ndarray:
    """Metres to integer centimetres, rounded half to even (exact for centimetre values)."""
    return np.rint(np.asarray(values, dtype=np.float64) * 100.0).astype(np.int64)


def cm_to_m(values: np.ndarray) -> np.ndarray:
    """Integer centimetres to metres (float64): the nearest double to ``cm / 100``."""
    return np.asarray(values, dtype=np.int64) / 100.0


def check_layer_for_apy(layer, path=None) -> None:
    """Raise if ``layer`` does not fit the APY native formats.

    Raises
    ------
    CapacityError
        More than 1000 symbols, 10000 line points or 500 texts.
    ValueRangeError
        A point number or reference outside 0-9999, a coordinate with more
        digits than the format has, a code outside 0-99, a text that is not
        ISO 8859-1; the message names the layer, the table and the record.
    """
    for table, cap in APY_CAPACITY.items():
        n = len(layer.table(table))
        if n > cap:
            raise CapacityError(
                f"{_where(path)}layer {layer.ext}: {n} {table.replace('_', ' ')} exceed the APY "
                f"capacity of {cap} per layer ({n - cap} too many); nothing was written"
            )
    for table in ("symbols", "line_points", "texts"):
        t = layer.table(table)
        if len(t) == 0:
            continue
        word = TABLE_WORDS[table]
        _range(
            t,
            "num",
            (t["num"] < 0) | (t["num"] > APY_MAX_NUM),
            layer,
            path,
            word,
            "point number outside 0-9999 (4 digits)",
        )
        for axis, lim, digits in (("x", MAX_XY_CM, 9), ("y", MAX_XY_CM, 9), ("z", MAX_Z_CM, 6)):
            v = t[axis]
            with np.errstate(invalid="ignore", over="ignore"):
                bad = ~np.isfinite(v) | (np.abs(np.rint(v * 100.0)) > lim)
            _range(
                t,
                "num",
                bad,
                layer,
                path,
                word,
                f"{axis.upper()} = {{value}} m does not fit {digits} digits of centimetres",
                values=v,
            )
        if table != "texts":
            _range(
                t,
                "num",
                (t["code"] < 0) | (t["code"] > 99),
                layer,
                path,
                word,
                "code {value} outside 0-99",
                values=t["code"],
            )
        if table == "line_points":
            for ref in REF_FIELDS:
                r = t[ref]
                bad = (r != NO_REF) & ((r < 0) | (r > APY_MAX_NUM))
                _range(
                    t,
                    "num",
                    bad,
                    layer,
                    path,
                    word,
                    f"{ref} reference {{value}} outside 0-9999",
                    values=r,
                )
        if table == "texts":
            for i, s in enumerate(t["text"]):
                if len(s) > TEXT_LEN:
                    raise ValueRangeError(
                        f"layer {layer.ext}: text {t['num'][i]} ({s!r}) has {len(s)} characters; "
                        f"APY holds {TEXT_LEN} (the writer option CUT_TEXTS=YES cuts longer "
                        "texts)",
                        path=path,
                    )
                try:
                    s.encode("latin-1")
                except UnicodeEncodeError:
                    raise ValueRangeError(
                        f"layer {layer.ext}: text {t['num'][i]} ({s!r}) has characters outside "
                        "ISO 8859-1, which the APY format stores",
                        path=path,
                    ) from None


def fit_texts(map_, path=None, cut_texts: bool = False):
    """``map_`` when every text fits APY's 24 characters; else refused, or cut.

    The model keeps texts of any length; the APY native formats hold
    :data:`~apygis.model.records.TEXT_LEN` characters. A longer text is a
    :class:`~apygis.errors.ValueRangeError` naming it (and how many more),
    unless ``cut_texts``: then a copy of the map whose texts are cut to 24
    characters is returned and a warning says how many were cut.
    """
    long = [
        (lay.ext, int(n), t)
        for lay in map_
        for n, t in zip(lay.texts["num"].tolist(), lay.texts["text"].tolist(), strict=True)
        if len(t) > TEXT_LEN
    ]
    if not long:
        return map_
    ext, num, text = long[0]
    more = f" (and {len(long) - 1} more)" if len(long) > 1 else ""
    if not cut_texts:
        raise ValueRangeError(
            f"layer {ext}: text {num} ({text!r}) has {len(text)} characters; APY holds "
            f"{TEXT_LEN}{more} (the writer option CUT_TEXTS=YES cuts longer texts)",
            path=path,
        )
    out = map_.copy()
    for lay in out:
        tx = lay.texts
        if len(tx) and any(len(t) > TEXT_LEN for t in tx["text"].tolist()):
            rows = tx.copy()
            rows["text"] = [t[:TEXT_LEN] for t in tx["text"].tolist()]
            out.add_layer(type(lay).from_arrays(lay.ext, lay.symbols, lay.line_points, rows))
    log.warning(
        "%s: %d texts longer than %d characters cut (first: layer %s, text %d, %r -> %r)",
        path,
        len(long),
        TEXT_LEN,
        ext,
        num,
        text,
        text[:TEXT_LEN],
    )
    return out


def _where(path) -> str:
    return f"{path}: " if path else ""


def _range(t, numfield, bad, layer, path, word, what, values=None) -> None:
    if not np.any(bad):
        return
    i = int(np.flatnonzero(bad)[0])
    value = values[i] if values is not None else t[numfield][i]
    count = int(np.count_nonzero(bad))
    more = f" (and {count - 1} more)" if count > 1 else ""
    raise ValueRangeError(
        f"layer {layer.ext}: {word} {t[numfield][i]}: " + what.format(value=value) + more,
        path=path,
    )


def encode_latin1(texts: np.ndarray, width: int) -> np.ndarray:
    """A ``U<width>`` array as an ``(n, width)`` uint8 array of ISO 8859-1 codes, NUL-padded.

    The caller has checked that every character is below U+0100.
    """
    n = len(texts)
    codes = np.ascontiguousarray(texts, dtype=f"<U{width}").view("<u4").reshape(n, width)
    return codes.astype(np.uint8)


def decode_latin1(codes: np.ndarray, width: int) -> np.ndarray:
    """The inverse of :func:`encode_latin1`: trailing NULs become the end of the string."""
    n = len(codes)
    wide = np.ascontiguousarray(codes, dtype="<u4").reshape(n, width)
    return wide.view(f"<U{width}").reshape(n)
