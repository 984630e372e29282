"""Reading DXF: :func:`probe`, and :func:`read` by the fast path or through ezdxf,
then the map's layers."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import numpy as np

from apygis.errors import DriverError, FormatError, RecordError, TopologyError
from apygis.formats._io import read_bytes
from apygis.formats._report import warn
from apygis.formats.dxf._collect import _Collect, _Layers
from apygis.formats.dxf._common import _BINARY_SENTINEL, log
from apygis.formats.dxf.read_ezdxf import _slow_read, skip_reason
from apygis.formats.dxf.read_fast import _fast_read
from apygis.model.map import Layer, MapFile
from apygis.model.polylines import to_csr
from apygis.model.records import LINE_DTYPE, MAX_CODE, next_numbers
from apygis.model.symbols import IMPORTED_POINT


def _sniff(data: bytes, path) -> bytes:
    """The file's bytes up to its first ``0`` / ``EOF``; FormatError unless it is DXF.

    Content after the first ``0`` / ``EOF`` of an ASCII file (appended by a
    tool, a concatenation, a bad transfer) is dropped with a warning naming
    how many bytes and lines follow; whitespace, NUL and Ctrl-Z there are
    dropped silently.
    """
    if not data.strip():
        raise FormatError("empty file, not a DXF file", path=path)
    if data.startswith(_BINARY_SENTINEL):
        if not data.rstrip(b"\0").endswith(b"EOF"):
            raise FormatError("truncated: the binary DXF file does not end with EOF", path=path)
        return data
    if not _looks_like_dxf(data[:4096]):
        raise FormatError(
            "not a DXF file: it does not begin with group code 0 and SECTION", path=path
        )
    # ezdxf's recovery accepts a file cut short and returns what it could
    # read; a DXF file ends with the tags 0 and EOF, so refuse one without.
    end = _first_eof(data)
    if end is None:
        raise FormatError("truncated: the file does not end with the tags 0 and EOF", path=path)
    rest = data[end:]
    if rest.strip(b" \t\r\n\0\x1a"):
        warn(
            log,
            f"{path}: {len(rest)} bytes ({len(rest.splitlines())} lines) after the tags 0 and "
            "EOF ignored",
            "damaged",
            len(rest.splitlines()),
            "after EOF",
        )
    return data if end == len(data) else data[:end]


_EOF_LINE = re.compile(rb"[ \t]*EOF[ \t]*\r?(?:\n|\Z)", re.IGNORECASE)


def _first_eof(data: bytes) -> int | None:
    """The offset just past the line ``EOF`` of the first ``0`` / ``EOF`` pair, or None.

    A line ``EOF`` after a line ``0`` can only be that pair: group codes are
    integers, so ``EOF`` is never a group code line after a value ``0``.
    The search looks at each ``EOF`` (fast ``bytes.find``), not at every line.
    """
    for needle in (b"EOF", b"eof"):
        k = data.find(needle)
        while k >= 0:
            start = data.rfind(b"\n", 0, k) + 1  # the start of the line of this EOF
            m = _EOF_LINE.match(data, start)
            if m and start > 0:
                prev = data.rfind(b"\n", 0, start - 1) + 1  # the line before
                if data[prev:start].strip() == b"0":
                    return m.end()
            k = data.find(needle, k + 3)
    # any other case mix (Eof): rare, so one regular expression over the file
    m = re.search(rb"(?:\A|\n)[ \t]*0[ \t]*\r?\n[ \t]*EOF[ \t]*\r?(?:\n|\Z)", data, re.I)
    return m.end() if m else None


def _looks_like_dxf(head: bytes) -> bool:
    if head.startswith(_BINARY_SENTINEL):
        return True
    text = head.decode("latin-1")
    if text.startswith("\xef\xbb\xbf"):
        text = text[3:]
    lines = [ln.strip() for ln in text.splitlines()]
    while lines and not lines[0]:
        lines.pop(0)
    i = 0
    while i + 1 < len(lines) and lines[i] == "999":  # comments
        i += 2
    return i + 1 < len(lines) and lines[i] == "0" and lines[i + 1].upper() == "SECTION"


def probe(path) -> bool:
    """True if ``path`` is a file that begins like a DXF file (ASCII or binary)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    return _looks_like_dxf(head)


# --------------------------------------------------------------------------- layers


def _numbers(given: list, path, what: str) -> np.ndarray:
    """Point numbers: the given ones, new ones by the model's numbering rule for the rest."""
    missing = np.array([g is None for g in given], dtype=bool)
    try:
        known = np.array([g for g in given if g is not None], dtype=np.int64)
    except OverflowError:
        raise FormatError(f"a {what} number does not fit 64 bits", path=path) from None
    nums = np.full(len(given), -1, dtype=np.int64)
    nums[~missing] = known
    # a later copy of a number in use (an entity copied in CAD with its XDATA) or a
    # negative number is numbered anew, and the log says how many
    order = np.argsort(nums, kind="stable")
    repeat = np.zeros(len(nums), dtype=bool)
    repeat[order[1:]] = nums[order][1:] == nums[order][:-1]
    renumber = ~missing & (repeat | (nums < 0))
    if renumber.any():
        warn(
            log,
            f"{path}: {int(renumber.sum())} {what} number(s) repeated or negative (e.g. "
            f"{int(nums[renumber][0])}): numbered anew",
            "renumbered",
            int(renumber.sum()),
            what,
        )
    new = missing | renumber
    nums[new] = next_numbers(nums[~new], int(new.sum()))
    return nums


def _make_layer(ext: str, c: _Collect, opts: dict, path) -> Layer:
    layer = Layer(ext)
    try:
        if c.sym:
            arr = np.array([s[1:4] for s in c.sym], dtype=float)
            nums = _numbers([s[0] for s in c.sym], path, "symbol")
            layer.add_symbols(arr, np.array([s[4] for s in c.sym], np.int64), nums)
        if c.txt:
            arr = np.array([t[1:4] for t in c.txt], dtype=float)
            nums = _numbers([t[0] for t in c.txt], path, "text")
            layer.add_texts(arr, [t[4] for t in c.txt], nums)
        chunks = list(c.own_arr)
        if c.own:
            try:
                ints = np.array([o[:7] for o in c.own], dtype=np.int64)
            except OverflowError:
                raise FormatError("a line point number does not fit 64 bits", path=path) from None
            chunks.append((ints, np.array([o[7:] for o in c.own], dtype=float)))
        if chunks:
            ints = np.concatenate([ch[0] for ch in chunks])
            xyz = np.concatenate([ch[1] for ch in chunks])
            order = np.argsort(ints[:, 0], kind="stable")  # table order, from the rows
            ints, xyz = ints[order], xyz[order]
            lp = np.zeros(len(ints), LINE_DTYPE)
            for j, name in enumerate(("num", "code", "fwd", "back", "side1", "side2"), start=1):
                lp[name] = ints[:, j]
            lp["x"], lp["y"], lp["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
            layer.add_line_points(lp)
        if c.lines:
            coords, offsets = to_csr(c.lines)
            codes = np.array(c.codes, dtype=np.int64) if c.codes else opts["line_code"]
            rep = layer.add_polylines(
                coords,
                offsets,
                codes,
                np.array(c.closed, dtype=bool),
                snap_m=opts["tolerance_m"],
                crs=opts.get("crs"),
                join=bool(opts["topology"]),
            )
            _rebuild_report(path, ext, rep)
    except (RecordError, TopologyError) as exc:
        msg = str(exc) if str(exc).startswith(f"layer {ext}:") else f"layer {ext}: {exc}"
        raise FormatError(msg, path=path) from None
    return layer


def _rebuild_report(path, ext: str, rep) -> None:
    """The topology rebuild's report: a warning when it refused or removed anything."""
    text = f"{path}: layer {ext}: lines rebuilt: {rep.message()}"
    if rep.refused or rep.duplicates_removed or rep.empty:
        warn(log, text, "rebuilt", None, "lines")
    else:
        log.info("%s", text)


def _map_id(path) -> str:
    stem = Path(path).stem
    mid = re.sub(r"[^A-Za-z0-9_-]", "_", stem)[:32]
    return mid or "DXF"


def read(
    path,
    progress=None,
    layer_map=None,
    layers=None,
    default_code: int | None = None,
    point_code: int = IMPORTED_POINT,
    tolerance_m: float = 0.005,
    chord_m: float | None = None,
    topology: bool = True,
    crs=None,
    fast: bool = True,
) -> MapFile:
    """Read a DXF file as a map.

    Parameters
    ----------
    path : str or os.PathLike
    progress : callable, optional
        ``progress(done, total)`` over the model-space entities.
    layer_map : dict or str, optional
        DXF layer name -> map layer extension, or None / ``"-"`` to skip the
        DXF layer (``{"ROADS": "r"}`` or ``"ROADS=r,WATER=h,0=-"``). A name
        the file does not have is refused. Other DXF layers map by the rule of
        :mod:`apygis.formats._layers` (one map layer each, named from it).
    layers : list of str, optional
        Read only these DXF layers (names compared without regard to case;
        one the file does not have is refused).
    default_code : int or None
        Code (0-99) of every line and point read from plain DXF geometry.
        None: lines 00; points as ``point_code`` says.
    point_code : int
        Code of a POINT or foreign INSERT without a height (Z 0) when
        ``default_code`` is None; one with a height is a spot height (00).
        Default 90, "imported point".
    tolerance_m : float
        Distance within which line ends join other lines (see
        :meth:`apygis.model.Layer.add_polylines`), metres on the ground.
    chord_m : float or None
        Largest distance of a chord from the curve when arcs (ARC, CIRCLE,
        bulges of polylines and hatch boundaries), ellipses and splines are
        flattened to line points, on the true curves, in drawing units.
        None (default): a quarter of 0.1 mm at the compilation scale 1:S,
        ``0.1 mm x S / 4`` (S from the header record, 1000 for a DXF without
        one: 0.025 m).
    topology : bool
        Rebuild junctions and merge lines whose ends meet (default); with
        False every DXF line becomes one chain as it is.
    crs : optional
        The CRS of a DXF that apygis did not write (DXF has none), or one
        that overrides the header's.
    fast : bool
        Read a DXF that apygis wrote and nobody changed since (the header
        record's checksum of the entities matches) by apygis's own parser,
        not through ezdxf (the same result, 100 times faster). False always
        reads through ezdxf.

    Entities that are not imported (meshes, images, ...) are counted, and
    each kind is reported in one warning (:mod:`apygis.formats._report`).

    Returns
    -------
    MapFile

    Raises
    ------
    FormatError
        The file is missing, not DXF, or damaged beyond repair; or apygis's
        own records in it (XDATA, header record) are malformed.
    DriverError
        An option is invalid, or names a layer the file does not have.
    """
    codes = {"point_code": point_code}
    if default_code is not None:
        codes["default_code"] = default_code
    for name, value in codes.items():
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise DriverError(f"dxf {name}: an integer 0-{MAX_CODE}, not {value!r}")
        if not 0 <= value <= MAX_CODE:
            raise DriverError(f"dxf {name}: {value} is outside 0-{MAX_CODE}")
    try:
        tolerance_m = float(tolerance_m)
    except (TypeError, ValueError):
        raise DriverError(f"dxf tolerance_m: a distance in metres, not {tolerance_m!r}") from None
    if not tolerance_m >= 0 or not np.isfinite(tolerance_m):
        raise DriverError(f"dxf tolerance_m: a distance in metres >= 0, not {tolerance_m!r}")
    try:
        chord = None if chord_m is None else float(chord_m)
    except (TypeError, ValueError):
        raise DriverError(f"dxf chord_m: a distance > 0, not {chord_m!r}") from None
    if chord is not None and not (chord > 0 and np.isfinite(chord)):
        raise DriverError(f"dxf chord_m: a distance > 0, not {chord_m!r}")
    names = _Layers(layer_map, layers, path)
    opts = {
        "default_code": None if default_code is None else int(default_code),
        "point_code": int(point_code),
        "line_code": 0 if default_code is None else int(default_code),
        "tolerance_m": tolerance_m,
        "topology": bool(topology),
        "chord_m": chord,
    }
    data = _sniff(read_bytes(path), path)
    stats: Counter = Counter()
    got = _fast_read(data, path, names, opts, stats) if fast else None
    if got is None:
        stats.clear()
        names = _Layers(layer_map, layers, path)
        header, collected = _slow_read(data, path, names, opts, stats, progress)
    else:
        header, collected = got
        log.debug("%s: read by apygis's own parser (the entities are as written)", path)
        if progress:
            progress(1, 1)
    del data
    try:
        if header is not None:
            m = MapFile(header["id"], header["scale"], header["crs"], header["notes"])
        else:
            m = MapFile(_map_id(path))
        if crs is not None:
            m.crs = crs
    except ValueError as exc:  # RecordError, CRSError
        raise FormatError(f"map header: {exc}", path=path) from None
    _report(path, stats, names)
    opts["crs"] = m.crs  # tolerance_m is metres: the rebuild converts it to the CRS's units
    for ext, c in collected.items():
        m.add_layer(_make_layer(ext, c, opts, path))
    return m


def _report(path, stats: Counter, names: _Layers) -> None:
    """One warning per kind of entity not imported; the layer mapping at INFO."""
    for key, n in sorted(stats.items()):
        if not key.startswith("skip:") or key == "skip:layer":
            continue
        kind = key[5:]
        reason = skip_reason(kind.split(" ")[0])
        if kind.endswith("(no geometry)"):
            reason = "ezdxf could not render its parts"
        elif kind in ("POLYFACE", "POLYMESH"):
            reason = "surfaces are not supported"
        warn(log, f"{path}: {n} {kind} skipped ({reason})", "skipped", n, kind)
    if stats["skip:layer"]:
        log.info("%s: %d entities of layers not read (option)", path, stats["skip:layer"])
    if stats["paper space"]:
        warn(
            log,
            f"{path}: {stats['paper space']} paper-space entities skipped (only the model "
            "space is map data)",
            "skipped",
            stats["paper space"],
            "paper space",
        )
    if stats["controls"]:
        warn(
            log,
            f"{path}: {stats['controls']} texts held control characters (tabs, line "
            "breaks): read as blanks",
            "changed",
            stats["controls"],
            "texts",
        )
    if stats["copied lines"]:
        warn(
            log,
            f"{path}: {stats['copied lines']} apygis line(s) repeat point numbers read before "
            "(copied in CAD): read as new lines, their topology rebuilt",
            "renumbered",
            stats["copied lines"],
            "lines",
        )
    mapped = {k: v for k, v in names.names.mapping().items() if v is None or k.lower() != v}
    if mapped:
        log.info(
            "%s: DXF layers -> map layers: %s",
            path,
            ", ".join(f"{k} -> {v or '(skipped)'}" for k, v in mapped.items()),
        )
