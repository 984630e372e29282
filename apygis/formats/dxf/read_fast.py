"""The fast DXF reader: a file apygis wrote and nobody changed since, parsed by the
writer's own templates."""

from __future__ import annotations

import re
import zlib
from collections import Counter

import numpy as np

from apygis.formats._readguard import MAX_COORD, ascii_int
from apygis.formats.dxf._collect import (
    _clean_text,
    _header_from_tags,
    _int_or_none,
    _own_text,
    _point_code,
    _seed_layers,
    _symbol_code,
    _xyz,
)
from apygis.formats.dxf._common import _ENTITIES_END, _ENTITIES_START, FORMAT_NAME, log
from apygis.formats.dxf.templates import _INSERT, _POLYLINE, _SEQEND, _TEXT, _VERTEX, _VERTEX_OWN
from apygis.model.records import MAX_CODE


def _template_re(template: str) -> re.Pattern:
    """A regular expression matching what a writer template formats, fields captured."""
    pat = re.escape(template)
    pat = pat.replace(re.escape("%d %d %d %d %d %d %d"), r"(-?[0-9]+(?: -?[0-9]+){6})")
    pat = pat.replace("%X", "[0-9A-F]+").replace("%d", "(-?[0-9]+)")
    pat = pat.replace("%r", r"([^\n]*)").replace("%s", r"([^\n]*)")
    return re.compile(pat)


_FAST_VERTEX, _FAST_INSERT, _FAST_TEXT = 0, 4, 5
_FAST_RES = [_template_re(t) for t in (_VERTEX_OWN, _VERTEX, _POLYLINE, _SEQEND, _INSERT, _TEXT)]
_FAST_XREC = b"\n100\nAcDbXrecord\n280\n1\n"


def _fast_header(data: bytes, path) -> dict | None:
    k = data.find(_FAST_XREC + b'  1\nformat\n  3\n"' + FORMAT_NAME.encode() + b'"\n')
    if k < 0:
        return None
    start = k + len(_FAST_XREC)
    end = data.find(b"\n  0\n", start)
    lines = data[start:end].decode("utf-8").split("\n")
    if end < 0 or len(lines) % 2:
        return None
    codes = [ascii_int(lines[i].strip()) for i in range(0, len(lines), 2)]  # no '٣' as 3
    if None in codes:
        return None
    tags = [(c, lines[2 * k + 1]) for k, c in enumerate(codes)]
    return _header_from_tags(tags, path)


def _fast_read(data: bytes, path, names, opts: dict, stats: Counter):
    """Header and records of an apygis DXF untouched since it was written, or None.

    The header record holds the size and CRC-32 of the ENTITIES section as
    written; when they match, the section is apygis's own text and is parsed
    by the writer's templates, without ezdxf (100x faster). Anything
    unexpected returns None: the caller reads the file through ezdxf.
    """
    try:
        header = _fast_header(data, path)
    except (ValueError, UnicodeDecodeError):  # FormatError too: ezdxf's path reports it
        return None
    if header is None or header["entities"] is None:
        return None
    size, crc = header["entities"]
    a = data.find(_ENTITIES_START.encode())
    a = a + len(_ENTITIES_START) if a >= 0 else -1
    if a < 0 or data[a + size : a + size + len(_ENTITIES_END)] != _ENTITIES_END.encode():
        return None
    section = data[a : a + size]
    if zlib.crc32(section) != crc:
        return None
    try:
        return header, _fast_entities(section.decode("utf-8"), header, names, opts, stats)
    except (ValueError, OverflowError, UnicodeDecodeError, IndexError) as exc:
        log.debug("%s: fast path failed (%s); reading through ezdxf", path, exc)
        return None


def _fast_entities(text: str, header: dict, names, opts: dict, stats: Counter):
    verts: list[tuple] = []
    inserts: list[tuple] = []
    texts: list[tuple] = []
    keep = {_FAST_VERTEX: verts.append, _FAST_INSERT: inserts.append, _FAST_TEXT: texts.append}
    pos, n = 0, len(text)
    while pos < n:
        kind, m = -1, None
        for k, rx in enumerate(_FAST_RES):
            m = rx.match(text, pos)
            if m is not None:
                kind = k
                break
        if m is None:
            raise ValueError(f"no entity template matches at {pos}")
        if kind in keep:
            keep[kind](m.groups())
        pos = m.end()
    present = [g[0] for g in inserts] + [t[0] for t in texts] + [v[0] for v in verts]
    names.start(list(dict.fromkeys(present)), header)
    collected = _seed_layers(header, names)
    target = names.collector(collected)

    for g in inserts:  # layer, block, x, y, z, 5 + 6 per ATTRIB (NUM, CODE, Z), layer
        c = target(g[0])
        if c is not None:
            pos3 = _xyz(g[2:5], "INSERT")
            code = _symbol_code(g[16], g[1], _point_code(pos3[2], opts))
            c.sym.append((_int_or_none(g[10]), *pos3, code))
    for layer_name, x, y, z, _h, raw, xd in texts:
        c = target(layer_name)
        own = _own_text(xd, raw, "TEXT")
        if c is not None and own is not None:
            c.txt.append((own[0], *_xyz((x, y, z), "TEXT"), _clean_text(own[1], stats)))
    if verts:
        layers, xs, ys, zs, ints = zip(*verts, strict=True)
        del verts
        xyz = np.column_stack(
            [np.array(xs, dtype=float), np.array(ys, dtype=float), np.array(zs, dtype=float)]
        )
        vals = np.array(" ".join(ints).split(), dtype=np.int64).reshape(-1, 7)
        if (
            not (np.abs(xyz) <= MAX_COORD).all()
            or ((vals[:, 1] < 0) | (vals[:, 1] > MAX_CODE)).any()
        ):
            raise ValueError("non-finite coordinates or line codes outside 0-99")
        # XDATA order: num code fwd back side1 side2 row -> row first, as _Collect.own
        vals = vals[:, [6, 0, 1, 2, 3, 4, 5]]
        uniq, inv = np.unique(np.array(layers), return_inverse=True)
        for k, name in enumerate(uniq.tolist()):
            c = target(name)
            if c is not None:
                sel = inv == k
                c.own_arr.append((vals[sel], xyz[sel]))
    return collected
