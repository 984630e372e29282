"""The APY native binary format: one file ``ID.ext`` per layer.

The byte layout is specified in ``docs/formats/apy-binary.md``. In short: a
64-byte little-endian header (magic ``APYL``, version, extension, map ID,
scale, record counts, CRC-32 of the body), a UTF-8 JSON metadata block (CRS,
notes), then fixed-size records: symbols (16 bytes), line points (24 bytes)
and texts (40 bytes), coordinates in integer centimetres.

Addressing a map:

* ``read("dir/ID.r")`` reads one layer file; the layer takes the file name's
  extension (APY's workflow renames ``ID.c`` to ``ID.e`` to move a layer),
  or the header's if the name has none that is a layer extension.
* ``read("dir/ID")`` (no such file) reads every layer file ``dir/ID.*``.
* ``write(m, "dir/ID")`` writes every layer to ``dir/ID.<ext>`` and removes
  APY layer files ``dir/ID.*`` of layers the map no longer has; an existing
  directory as target means ``dir/<map id>``. ``write(m, "dir/ID.r")``
  writes a map of one layer to that file.
"""

from __future__ import annotations

import json
import logging
import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from apygis.errors import DriverError, FormatError
from apygis.formats import Driver, Option
from apygis.formats._apycommon import (
    MAX_XY_CM,
    MAX_Z_CM,
    check_layer_for_apy,
    cm_to_m,
    decode_latin1,
    encode_latin1,
    fit_texts,
    m_to_cm,
)
from apygis.formats._io import (
    atomic_write_many,
    check_resolution,
    check_target,
    read_bytes,
    stamp_path,
)
from apygis.formats._readguard import loads_json
from apygis.model.map import Layer, MapFile, check_ext, check_map_id, crs_string
from apygis.model.records import (
    APY_CAPACITY,
    APY_MAX_NUM,
    LINE_DTYPE,
    NO_REF,
    REF_FIELDS,
    SYMBOL_DTYPE,
    TEXT_DTYPE,
    TEXT_LEN,
)

__all__ = ["DRIVER", "HEADER", "LINE_REC", "MAGIC", "SYMBOL_REC", "TEXT_REC", "read", "write"]

log = logging.getLogger(__name__)

MAGIC = b"APYL"
VERSION = 1
HEADER = struct.Struct("<4sHH4s32sIIHHHHI")
HEADER_SIZE = HEADER.size  # 64
NO_REF_U16 = 0xFFFF

SYMBOL_REC = np.dtype(
    [("num", "<u2"), ("x", "<i4"), ("y", "<i4"), ("z", "<i4"), ("code", "u1"), ("pad", "u1")]
)
LINE_REC = np.dtype(
    [
        ("num", "<u2"),
        ("x", "<i4"),
        ("y", "<i4"),
        ("z", "<i4"),
        ("code", "u1"),
        ("pad", "u1"),
        ("fwd", "<u2"),
        ("back", "<u2"),
        ("side1", "<u2"),
        ("side2", "<u2"),
    ]
)
TEXT_REC = np.dtype(
    [("num", "<u2"), ("x", "<i4"), ("y", "<i4"), ("z", "<i4"), ("pad", "<u2"), ("text", "u1", 24)]
)
assert HEADER_SIZE == 64
assert (SYMBOL_REC.itemsize, LINE_REC.itemsize, TEXT_REC.itemsize) == (16, 24, 40)


# --------------------------------------------------------------------------- encode


def encode_layer(map_: MapFile, layer: Layer, path=None) -> bytes:
    """The bytes of one layer file. Raises CapacityError / ValueRangeError first."""
    check_layer_for_apy(layer, path)
    sym, lp, tx = layer.symbols, layer.line_points, layer.texts
    meta = {}
    if map_.crs is not None:
        meta["crs"] = crs_string(map_.crs)
    if map_.notes:
        meta["notes"] = map_.notes
    meta_b = json.dumps(meta, ensure_ascii=False, sort_keys=True).encode("utf-8") if meta else b""

    s = np.zeros(len(sym), SYMBOL_REC)
    s["num"] = sym["num"]
    s["x"], s["y"], s["z"] = m_to_cm(sym["x"]), m_to_cm(sym["y"]), m_to_cm(sym["z"])
    s["code"] = sym["code"]

    ln = np.zeros(len(lp), LINE_REC)
    ln["num"] = lp["num"]
    ln["x"], ln["y"], ln["z"] = m_to_cm(lp["x"]), m_to_cm(lp["y"]), m_to_cm(lp["z"])
    ln["code"] = lp["code"]
    for ref in REF_FIELDS:
        ln[ref] = np.where(lp[ref] == NO_REF, NO_REF_U16, lp[ref])

    t = np.zeros(len(tx), TEXT_REC)
    t["num"] = tx["num"]
    t["x"], t["y"], t["z"] = m_to_cm(tx["x"]), m_to_cm(tx["y"]), m_to_cm(tx["z"])
    t["text"] = encode_latin1(tx["text"], TEXT_LEN)

    body = meta_b + s.tobytes() + ln.tobytes() + t.tobytes()
    header = HEADER.pack(
        MAGIC,
        VERSION,
        HEADER_SIZE,
        layer.ext.encode("ascii"),
        map_.id.encode("ascii"),
        map_.scale or 0,
        len(meta_b),
        len(sym),
        len(lp),
        len(tx),
        0,
        zlib.crc32(body),
    )
    return header + body


# --------------------------------------------------------------------------- decode


def _ascii_field(raw: bytes, path, what: str) -> str:
    text, _, pad = raw.partition(b"\0")
    if pad.strip(b"\0"):
        raise FormatError(f"header: the {what} field has bytes after its NUL padding", path=path)
    try:
        return text.decode("ascii")
    except UnicodeDecodeError:
        raise FormatError(f"header: the {what} is not ASCII: {text!r}", path=path) from None


def decode_layer(data: bytes, path=None) -> tuple[dict[str, Any], Layer]:
    """Parse one layer file. Returns ``(header facts, layer)``; raises FormatError."""
    if len(data) < HEADER_SIZE:
        raise FormatError(
            f"truncated: {len(data)} bytes, an APY layer file has a {HEADER_SIZE}-byte header",
            path=path,
        )
    (magic, version, hsize, ext_b, id_b, scale, meta_len, ns, nl, nt, reserved, crc) = (
        HEADER.unpack_from(data)
    )
    if magic != MAGIC:
        raise FormatError(f"not an APY layer file (magic {magic!r}, expected {MAGIC!r})", path=path)
    if version != VERSION:
        raise FormatError(
            f"APY format version {version}; this apygis reads version {VERSION}", path=path
        )
    if hsize != HEADER_SIZE or reserved != 0:
        raise FormatError(f"header: size {hsize} / reserved {reserved}, expected 64 / 0", path=path)
    ext = _ascii_field(ext_b, path, "layer extension")
    map_id = _ascii_field(id_b, path, "map ID")
    for count, table in ((ns, "symbols"), (nl, "line_points"), (nt, "texts")):
        if count > APY_CAPACITY[table]:
            raise FormatError(
                f"header: {count} {table.replace('_', ' ')}, more than the APY capacity of "
                f"{APY_CAPACITY[table]}",
                path=path,
            )
    expected = (
        HEADER_SIZE
        + meta_len
        + ns * SYMBOL_REC.itemsize
        + nl * LINE_REC.itemsize
        + nt * TEXT_REC.itemsize
    )
    if len(data) != expected:
        how = "truncated" if len(data) < expected else "has trailing bytes"
        raise FormatError(
            f"{how}: {len(data)} bytes, but the header announces {ns} symbols, {nl} line points, "
            f"{nt} texts and {meta_len} bytes of metadata ({expected} bytes)",
            path=path,
        )
    if zlib.crc32(memoryview(data)[HEADER_SIZE:]) != crc:
        raise FormatError("checksum mismatch: the file is corrupt", path=path)
    facts: dict[str, Any] = {"ext": ext, "id": map_id, "scale": scale or None}
    try:
        facts["ext"] = check_ext(ext)
        facts["id"] = check_map_id(map_id)
    except ValueError as exc:
        raise FormatError(f"header: {exc}", path=path) from None

    pos = HEADER_SIZE
    meta = {}
    if meta_len:
        meta = loads_json(data[pos : pos + meta_len], "metadata block", path=path)
        if not isinstance(meta, dict):
            raise FormatError("metadata block is not a JSON object", path=path)
    for key in ("crs", "notes"):
        if key in meta and not isinstance(meta[key], str):
            raise FormatError(f"metadata: {key!r} must be a string", path=path)
    facts["crs"] = meta.get("crs")
    facts["notes"] = meta.get("notes", "")
    pos += meta_len

    s = np.frombuffer(data, SYMBOL_REC, ns, pos)
    pos += ns * SYMBOL_REC.itemsize
    ln = np.frombuffer(data, LINE_REC, nl, pos)
    pos += nl * LINE_REC.itemsize
    t = np.frombuffer(data, TEXT_REC, nt, pos)

    _check_records(s, "symbol", path, codes=True)
    _check_records(ln, "line point", path, codes=True)
    _check_records(t, "text", path, codes=False)
    for ref in REF_FIELDS:
        bad = (ln[ref] != NO_REF_U16) & (ln[ref] > APY_MAX_NUM)
        _fail_first(bad, ln, "line point", f"{ref} reference outside 0-9999", path)
    codes = t["text"]
    nul = codes == 0
    # after the first NUL only NULs; no control characters (C0, DEL, C1)
    after_nul = np.cumsum(nul, axis=1) > 0
    ctrl = (codes < 32) | ((codes >= 127) & (codes < 160))
    _fail_first(
        (after_nul & ~nul).any(axis=1) | (ctrl & ~after_nul).any(axis=1),
        t,
        "text",
        "text field holds control characters or bytes after its NUL padding",
        path,
    )

    sym = np.zeros(ns, SYMBOL_DTYPE)
    sym["num"] = s["num"]
    sym["x"], sym["y"], sym["z"] = cm_to_m(s["x"]), cm_to_m(s["y"]), cm_to_m(s["z"])
    sym["code"] = s["code"]
    lp = np.zeros(nl, LINE_DTYPE)
    lp["num"] = ln["num"]
    lp["x"], lp["y"], lp["z"] = cm_to_m(ln["x"]), cm_to_m(ln["y"]), cm_to_m(ln["z"])
    lp["code"] = ln["code"]
    for ref in REF_FIELDS:
        r = ln[ref].astype(np.int64)
        lp[ref] = np.where(r == NO_REF_U16, NO_REF, r)
    tx = np.zeros(nt, TEXT_DTYPE)
    tx["num"] = t["num"]
    tx["x"], tx["y"], tx["z"] = cm_to_m(t["x"]), cm_to_m(t["y"]), cm_to_m(t["z"])
    tx["text"] = decode_latin1(codes, TEXT_LEN)
    # no coordinate check here: int32 centimetres are finite and within 2.2e7 m,
    # far inside the model's bound (MAX_COORD), which from_arrays checks anyway
    return facts, Layer.from_arrays(facts["ext"], sym, lp, tx)


def _check_records(rec: np.ndarray, word: str, path, codes: bool) -> None:
    _fail_first(rec["num"] > APY_MAX_NUM, rec, word, "point number outside 0-9999", path)
    _fail_first(rec["pad"] != 0, rec, word, "padding bytes are not zero", path)
    for axis, lim in (("x", MAX_XY_CM), ("y", MAX_XY_CM), ("z", MAX_Z_CM)):
        v = rec[axis].astype(np.int64)
        _fail_first(
            np.abs(v) > lim, rec, word, f"{axis.upper()} has more digits than allowed", path
        )
    if codes:
        _fail_first(rec["code"] > 99, rec, word, "code outside 0-99", path)


def _fail_first(bad: np.ndarray, rec: np.ndarray, word: str, what: str, path) -> None:
    if len(bad) and bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FormatError(what, path=path, record=f"{word} record {i + 1} (number {rec['num'][i]})")


# --------------------------------------------------------------------------- paths


def _layer_files(base: Path) -> list[Path]:
    """APY layer files ``base.*`` (content checked) in extension order."""
    if not base.parent.is_dir():
        return []
    out = []
    prefix = base.name + "."
    for p in sorted(base.parent.iterdir()):
        ext = p.name[len(prefix) :]
        if p.name.startswith(prefix) and _is_layer_name(ext) and p.is_file() and _has_magic(p):
            out.append(p)
    return out


def _is_layer_name(ext: str) -> bool:
    try:
        check_ext(ext)
    except ValueError:
        return False
    return True


def _has_magic(p: Path) -> bool:
    try:
        with open(p, "rb") as fh:
            return fh.read(4) == MAGIC
    except OSError:
        return False


def probe(path) -> bool:
    """True for an APY layer file, or for ``dir/ID`` naming APY layer files ``dir/ID.*``."""
    p = Path(path)
    if p.is_file():
        return _has_magic(p)
    if p.exists():
        return False
    return bool(_layer_files(p))


def _split_target(map_: MapFile, path) -> tuple[Path, list[Layer], bool]:
    """Where each layer goes: ``(base, layers, whole_map)``."""
    p = Path(path)
    if p.is_dir():
        return p / map_.id, list(map_.layers.values()), True
    ext = p.suffix[1:]
    if ext and _is_layer_name(ext):
        if len(map_.layers) != 1:
            raise DriverError(
                f"{p}: names one layer file, but map {map_.id} has {len(map_.layers)} layers "
                f"({', '.join(sorted(map_.layers)) or 'none'}); name the map as "
                f"{p.with_suffix('')} to write one file per layer"
            )
        (layer,) = map_.layers.values()
        if layer.ext != ext.lower():
            layer = Layer.from_arrays(ext, layer.symbols, layer.line_points, layer.texts)
        return p.with_suffix(""), [layer], False
    if ext:
        raise DriverError(
            f"{p}: .{ext} is neither an APY layer extension (1-3 letters) nor a known format"
        )
    return p, list(map_.layers.values()), True


def _stamp(base: Path) -> Path:
    return stamp_path(base)


def members(path) -> tuple[Path, list[Path], bool]:
    """The set stamp and the layer files a read of ``path`` takes (see :func:`read`)."""
    p = Path(path)
    if p.exists():
        ext = p.suffix[1:]
        base = p.with_suffix("") if ext and _is_layer_name(ext) else p
        return _stamp(base), [p], False
    return _stamp(p), _layer_files(p), True


def outputs(map_: MapFile, path) -> list[Path]:
    base, layers, _ = _split_target(map_, path)
    return [base.with_name(f"{base.name}.{lay.ext}") for lay in layers]


# --------------------------------------------------------------------------- API


def read(path, progress=None) -> MapFile:
    """Read an APY layer file, or all layer files of a map (``dir/ID``)."""
    p = Path(path)
    files = [p] if p.exists() else _layer_files(p)
    if not files:
        raise FormatError("no such file, nor APY layer files named like it", path=p)
    m = None
    for k, f in enumerate(files):
        facts, layer = decode_layer(read_bytes(f), f)
        name_ext = f.name.rsplit(".", 1)[-1] if "." in f.name else ""
        if _is_layer_name(name_ext) and name_ext.lower() != layer.ext:
            layer = Layer.from_arrays(name_ext, layer.symbols, layer.line_points, layer.texts)
        if m is None:
            try:
                m = MapFile(
                    facts["id"], scale=facts["scale"], crs=facts["crs"], notes=facts["notes"]
                )
            except ValueError as exc:
                raise FormatError(f"metadata: {exc}", path=f) from None
        else:
            for key, mine in (("id", m.id), ("scale", m.scale), ("notes", m.notes)):
                if facts[key] != mine:
                    log.warning(
                        "%s: %s %r differs from %r in %s; kept the latter",
                        f,
                        key,
                        facts[key],
                        mine,
                        files[0],
                    )
            if facts["crs"] != crs_string(m.crs):
                log.warning("%s: CRS differs from %s; kept the latter", f, files[0])
        if layer.ext in m.layers:
            raise FormatError(f"a second file for layer {layer.ext}", path=f)
        m.add_layer(layer)
        if progress:
            progress(k + 1, len(files))
    assert m is not None  # files is not empty
    return m


def write(map_: MapFile, path, progress=None, cut_texts: bool = False) -> list[Path]:
    """Write the map's layers as APY layer files, atomically; returns the files written.

    All layers are checked (capacity, digits, texts of at most 24
    characters) before any file is written; ``cut_texts`` cuts longer texts
    to 24 characters (with a warning) instead of refusing them.
    """
    map_ = fit_texts(map_, path, cut_texts)
    base, layers, whole = _split_target(map_, path)
    if not layers:
        raise DriverError(f"{path}: map {map_.id} has no layers: nothing to write")
    if whole and base.exists():  # dir/ID names the map: a device there is a mistake
        check_target(base)
    check_resolution(map_, path, 0.01, "APY binary stores coordinates in hundredths of a unit")
    contents = {}
    for k, lay in enumerate(layers):
        target = base.with_name(f"{base.name}.{lay.ext}")
        contents[target] = encode_layer(map_, lay, target)
        if progress:
            progress(k + 1, 2 * len(layers))
    # layer files of layers the map no longer has would be read back as its own
    stale = [old for old in _layer_files(base) if old not in contents] if whole else []
    for old in stale:
        log.info("removing %s: map %s has no layer %s", old, map_.id, old.suffix[1:])
    written = atomic_write_many(contents, _stamp(base), complete=whole, remove=stale)
    if progress:
        progress(2 * len(layers), 2 * len(layers))
    return written


DRIVER = Driver(
    name="apy",
    description="APY native binary: one file ID.ext per layer (docs/formats/apy-binary.md)",
    extensions=(),
    reader=read,
    writer=write,
    probe=probe,
    outputs=outputs,
    members=members,
    options=(Option("cut_texts", "w", "bool", "cut texts to APY's 24 characters"),),
)
