"""Shared helpers of the OGR drivers.

The one logger of the package (``apygis.formats.ogr``: the edits report and
the rebuild's report are logged under the driver's name), the guards that turn
every pyogrio and GDAL failure into a :class:`~apygis.errors.FormatError`
naming the file and the layer, :class:`_Source` (one OGR layer to read) and the
checked conversions of its attribute columns (integers, codes, texts, NULLs)
that the exact reader, the foreign reader and the edits share.
"""

from __future__ import annotations

import contextlib
import logging
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from apygis.errors import FormatError
from apygis.model.map import check_text
from apygis.model.records import MAX_CODE, NO_REF

log = logging.getLogger("apygis.formats.ogr")  # one logger for the package (the edits report)


@contextlib.contextmanager
def _quiet():
    """Turn pyogrio's and GDAL's warnings into log records (the library never warns on stdout)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    for w in caught:
        log.debug("pyogrio: %s", w.message)


def _gdal(call: Callable, what: str, path, layer: str | None = None, error=FormatError):
    """Run a pyogrio call; every exception it raises becomes ``error`` (a FormatError)."""
    try:
        with _quiet():
            return call()
    except FormatError:
        raise
    except MemoryError:
        raise error(f"{what}: out of memory", path=path, record=_rec(layer)) from None
    except Exception as exc:  # pyogrio.errors.*, RuntimeError, ValueError, OSError, ...
        msg = _plain(str(exc).strip()) or type(exc).__name__
        raise error(f"{what}: {msg}", path=path, record=_rec(layer)) from None


_HINT = re.compile(r";?\s*It might help to specify the correct driver.*$", re.S)
_NOT_RECOGNISED = re.compile(r"^'[^']*' not recognized as being in a supported file format\.?")


def _plain(msg: str) -> str:
    """GDAL's message without what only GDAL's own tools take (``'<DRIVER>:' prefixes``)
    or what repeats the path (named before it)."""
    msg = _HINT.sub("", msg).strip()
    msg = _NOT_RECOGNISED.sub("GDAL does not recognise its content", msg)
    return msg.rstrip(";. ")


class _WriteError(FormatError):
    """Internal: GDAL failed while writing (re-raised as DriverError by :func:`write`)."""


def _rec(layer: str | None) -> str | None:
    return None if layer is None else f"layer {layer}"


def _xyz(table: np.ndarray) -> np.ndarray:
    return np.column_stack([table["x"], table["y"], table["z"]]) if len(table) else np.zeros((0, 3))


@dataclass(frozen=True)
class _Source:
    """One OGR layer to read: the dataset GDAL opens, the layer in it, the name we match."""

    dataset: str
    layer: str | None
    name: str
    spatial: bool = True


def _field(columns: dict, name: str | None):
    if name is None:
        return None
    if name in columns:
        return columns[name]
    low = name.lower()
    for k, v in columns.items():
        if k.lower() == low:
            return v
    return None


def _int_column(values, name: str, src: _Source, nullable: bool = False) -> np.ndarray:
    """An integer column; NULL is -1 where ``nullable``, else an error."""
    a = np.asarray(values)
    if a.dtype.kind in "iu":
        if a.dtype.kind == "u" and len(a) and a.max() > np.iinfo(np.int64).max:
            raise FormatError(f"field {name}: value out of range", src.dataset, _rec(src.name))
        return a.astype(np.int64)
    if a.dtype.kind == "f":
        null = np.isnan(a)
        with np.errstate(invalid="ignore"):
            bad = ~null & (~np.isfinite(a) | (a != np.round(a)) | (np.abs(a) > 2.0**62))
        if null.any() and not nullable:
            bad |= null
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise FormatError(
                f"feature {k + 1}: field {name} is {a[k].item()!r}, expected an integer",
                src.dataset,
                _rec(src.name),
            )
        return np.where(null, NO_REF, np.nan_to_num(a)).astype(np.int64)
    if a.dtype.kind == "O":
        out = np.empty(len(a), dtype=np.int64)
        for k, v in enumerate(a):
            iv = _as_int(v)
            if iv is None and nullable and v is None:
                iv = NO_REF
            if iv is None:
                raise FormatError(
                    f"feature {k + 1}: field {name} is {v!r}, expected an integer",
                    src.dataset,
                    _rec(src.name),
                )
            out[k] = iv
        return out
    raise FormatError(f"field {name} is not an integer field", src.dataset, _rec(src.name))


def _as_int(v) -> int | None:
    if isinstance(v, (bool, np.bool_)):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v) if abs(int(v)) <= 2**62 else None
    if isinstance(v, (float, np.floating)) and np.isfinite(v) and float(v).is_integer():
        return int(v) if abs(float(v)) <= 2.0**62 else None
    if isinstance(v, str):
        try:
            return _as_int(int(v.strip()))
        except ValueError:
            return None
    return None


def _codes(values, name: str, src: _Source, default: int | None = None) -> np.ndarray:
    codes = _int_column(values, name, src, nullable=default is not None)
    if default is not None:
        codes = np.where(_null_mask(values), default, codes)
    bad = (codes < 0) | (codes > MAX_CODE)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise FormatError(
            f"feature {k + 1}: {name} {codes[k]} is outside 0-{MAX_CODE}",
            src.dataset,
            _rec(src.name),
        )
    return codes.astype(np.int16)


def _null_mask(values) -> np.ndarray:
    a = np.asarray(values)
    if a.dtype.kind == "f":
        return np.isnan(a)
    if a.dtype.kind == "O":
        return np.array([v is None for v in a], dtype=bool)
    return np.zeros(len(a), dtype=bool)


def _texts(values, name: str, src: _Source) -> np.ndarray:
    """A text column as an object array of ``str`` (whole: the model has no length limit)."""
    out = np.empty(len(values), dtype=object)
    for k, v in enumerate(values):
        if v is None:
            v = ""
        elif not isinstance(v, str):
            if isinstance(v, (bytes, bytearray)):
                raise FormatError(
                    f"feature {k + 1}: field {name} is binary, expected a text",
                    src.dataset,
                    _rec(src.name),
                )
            v = str(v)
        try:
            out[k] = check_text(v)
        except ValueError as exc:
            raise FormatError(f"feature {k + 1}: {exc}", src.dataset, _rec(src.name)) from None
    return out


def _require(columns: dict, names, src: _Source) -> list:
    out = []
    for n in names:
        col = _field(columns, n)
        if col is None:
            raise FormatError(
                f"field {n} is missing (a layer named like {src.name} follows the apygis schema, "
                "docs/formats/ogr.md)",
                src.dataset,
                _rec(src.name),
            )
        out.append(col)
    return out
