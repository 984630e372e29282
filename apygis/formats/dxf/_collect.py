"""What both DXF readers share: the layer map option, the header record, and the
records collected per layer."""

from __future__ import annotations

from collections import Counter

import numpy as np

from apygis.errors import FormatError
from apygis.formats._layers import LayerNames, parse_layer_map
from apygis.formats._readguard import MAX_COORD, ascii_int, loads_json
from apygis.formats.dxf._common import (
    _BLOCK_RE,
    _CTRL,
    APPID,
    FORMAT_NAME,
    FORMAT_VERSION,
)
from apygis.model.map import check_ext, check_map_id
from apygis.model.records import MAX_CODE
from apygis.model.symbols import SPOT_HEIGHT

# =========================================================================== options


class _Layers:
    """DXF layer name -> map layer extension (None: not read).

    The names follow :class:`apygis.formats._layers.LayerNames` (the rule of
    every reader: ``layer_map``, names like an extension, one map layer per
    other DXF layer named from it); ``layers`` (option) selects the DXF
    layers to read. :meth:`start` is given the file's layer names before the
    first entity, refusing ``layer_map`` and ``layers`` names it lacks.
    """

    def __init__(self, layer_map, layers, where=None):
        parse_layer_map(layer_map)  # a bad option fails before the file is read
        self.where = where
        self.layer_map = layer_map
        self.wanted = layers
        self.names = LayerNames(layer_map)
        self.selected: set[str] | None = None

    def start(self, present: list[str], header: dict | None) -> None:
        ordered = list(dict.fromkeys([*(header["layers"] if header else []), *present]))
        self.names = LayerNames(self.layer_map, ordered, where=self.where)
        self.names.check_used(ordered)
        groups = self.names.groups(ordered)  # --layer takes the map layer's name too
        self.selected = self.names.select(self.wanted, ordered, groups)

    def __call__(self, name: str) -> str | None:
        if self.selected is not None and name.upper() not in self.selected:
            return None
        return self.names(name)

    def collector(self, collected: dict):
        """``layer name -> _Collect`` (created on first use) or None for a layer not read."""

        def target(name: str) -> _Collect | None:
            ext = self(name)
            return None if ext is None else collected.setdefault(ext, _Collect())

        return target


# --------------------------------------------------------------------------- the header record


def _header_from_tags(tags, path) -> dict:
    """The HEADER record's ``(code, value)`` tags, checked, as a dict."""
    raw: dict[str, list[str]] = {}
    key = None
    for code, value in tags:
        if code == 1:
            key = str(value)
            raw[key] = []
        elif code == 3 and key is not None:
            raw[key].append(str(value))
        else:
            raise FormatError(f"{APPID} header record: unexpected tag ({code}, {value!r})", path)
    out = {}
    for key, chunks in raw.items():
        out[key] = loads_json("".join(chunks), f"{APPID} header record: {key!r}", path=path)
    if out.get("format") != FORMAT_NAME:
        raise FormatError(f"{APPID} header record: format is not {FORMAT_NAME!r}", path=path)
    version = out.get("version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise FormatError(f"{APPID} header record: bad version {version!r}", path=path)
    if version > FORMAT_VERSION:
        raise FormatError(
            f"written by a newer apygis (DXF mapping version {version}; this one reads "
            f"{FORMAT_VERSION})",
            path=path,
        )
    expect = {
        "id": (str,),
        "scale": (int, type(None)),
        "crs": (str, type(None)),
        "notes": (str,),
        "layers": (list,),
    }
    for key, types in expect.items():
        if key not in out:
            raise FormatError(
                f"{APPID} header record: no {key!r} entry (expected {', '.join(expect)})",
                path=path,
            )
        v = out[key]
        if not isinstance(v, types) or isinstance(v, bool):
            raise FormatError(f"{APPID} header record: bad {key} {v!r}", path=path)
    try:
        check_map_id(out["id"])
        if not all(isinstance(e, str) for e in out["layers"]):
            raise ValueError("layer extensions are strings")
        out["layers"] = [check_ext(e) for e in out["layers"]]
    except ValueError as exc:
        raise FormatError(f"{APPID} header record: {exc}", path=path) from None
    ent = out.get("entities")
    if (
        isinstance(ent, list)
        and len(ent) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) for v in ent)
    ):
        out["entities"] = tuple(ent)
    else:
        out["entities"] = None
    return out


# --------------------------------------------------------------------------- records


class _Collect:
    """What the entities of one map layer give, before it becomes a Layer."""

    def __init__(self):
        self.sym: list[tuple] = []  # (num or None, x, y, z, code)
        self.txt: list[tuple] = []  # (num or None, x, y, z, text)
        self.own: list[tuple] = []  # (row, num, code, fwd, back, s1, s2, x, y, z)
        self.own_arr: list[tuple[np.ndarray, np.ndarray]] = []  # (ints (n, 7), xyz (n, 3))
        self.own_nums: set[int] = set()  # line-point numbers read so far from own lines
        self.lines: list[np.ndarray] = []
        self.closed: list[bool] = []
        self.codes: list[int] = []


def _seed_layers(header: dict | None, names) -> dict[str, _Collect]:
    collected: dict[str, _Collect] = {}
    for ext in header["layers"] if header else []:
        ext = names(ext)
        if ext is not None:
            collected.setdefault(ext, _Collect())
    return collected


def _xyz(v, what) -> tuple[float, float, float]:
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    if not (abs(x) <= MAX_COORD and abs(y) <= MAX_COORD and abs(z) <= MAX_COORD):
        raise FormatError(
            f"{what}: coordinates ({x!r}, {y!r}, {z!r}) are not finite or exceed "
            f"{MAX_COORD:g} in magnitude"
        )
    return x, y, z


def _int_or_none(s) -> int | None:
    """An optionally signed integer of ASCII digits (no '²', no '1_0'), else None."""
    return ascii_int(str(s).strip(), signed=True)


def _clean_text(s: str, stats: Counter) -> str:
    """A text as the model takes it: whole, control characters (tabs) as blanks (counted)."""
    clean = _CTRL.sub(" ", s)
    if clean != s:
        stats["controls"] += 1
    return clean


def _point_code(z: float, opts: dict) -> int:
    """The code of a foreign point: ``default_code`` if given, else a spot height (00)
    where it has a height (Z not 0), else ``point_code`` (90, imported point)."""
    if opts["default_code"] is not None:
        return int(opts["default_code"])
    return SPOT_HEIGHT if z != 0.0 else int(opts["point_code"])


def _symbol_code(code_text, block_name, default: int) -> int:
    """A symbol's code: attribute CODE, else block APY_SYM_NN, else the default."""
    code = _int_or_none(code_text) if code_text is not None else None
    if code is not None and 0 <= code <= MAX_CODE:
        return code
    m = _BLOCK_RE.match(str(block_name))
    return int(m.group(1)) if m else default


def _own_text(xd: str, raw_text: str, what: str) -> tuple[int, str] | None:
    """Number and text of a TEXT with apygis XDATA; None for a spot-height label."""
    parts = xd.split()
    if parts == ["H"]:
        return None
    num = _int_or_none(parts[1]) if len(parts) in (2, 3) and parts[0] == "T" else None
    if num is None:
        raise FormatError(f"{what}: bad {APPID} XDATA {xd!r}")
    if len(parts) == 3:
        try:
            return num, bytes.fromhex(parts[2]).decode("utf-8")
        except ValueError:
            raise FormatError(f"{what}: bad text in {APPID} XDATA") from None
    return num, raw_text


_MAX_ARC_POINTS = 100_000  # per arc segment: a bound against absurd radii


def _flatten_bulges(xyb: np.ndarray, tol: float, closed: bool) -> np.ndarray:
    """The vertices ``(x, y, bulge)`` of a 2-D polyline with its arc segments as chords.

    A segment from vertex i to i+1 (and, closed, from the last to the
    first) with bulge ``b`` is the arc of included angle ``4 atan(b)``
    (counter-clockwise if positive); it is replaced by points on the arc
    whose chords stay within ``tol`` of it (sagitta ``r (1 - cos(phi / 2))
    <= tol``), computed on the true arc (not on a Bezier approximation).
    The vertices are kept exactly. Returns ``(n, 2)`` points in the
    polyline's own (object) coordinates; a closed polyline's first point is
    not repeated at the end.
    """
    n = len(xyb)
    out: list[np.ndarray] = []
    for i in range(n if closed else n - 1):
        p0, p1, b = xyb[i, :2], xyb[(i + 1) % n, :2], float(xyb[i, 2])
        out.append(p0[None, :])
        chord = p1 - p0
        length = float(np.hypot(*chord))
        if b == 0.0 or length == 0.0:
            continue
        theta = 4.0 * np.arctan(b)
        r = length / (2.0 * abs(np.sin(theta / 2.0)))
        left = np.array([-chord[1], chord[0]]) / length
        centre = (p0 + p1) / 2.0 + left * (length / 2.0) / np.tan(theta / 2.0)
        step = 2.0 * np.arccos(1.0 - tol / r) if tol < r else np.pi
        k = min(_MAX_ARC_POINTS, max(1, int(np.ceil(abs(theta) / step))))
        a0 = np.arctan2(p0[1] - centre[1], p0[0] - centre[0])
        ang = a0 + theta * np.arange(1, k) / k
        out.append(centre + r * np.column_stack([np.cos(ang), np.sin(ang)]))
    if not closed:
        out.append(xyb[-1:, :2])
    return np.concatenate(out) if out else np.zeros((0, 2))
