"""The DXF reader through ezdxf: any DXF file, repaired by :func:`ezdxf.recover.read`
where it can be."""

from __future__ import annotations

import io
import math
from collections import Counter
from typing import Any

import numpy as np

from apygis.errors import ApygisError, FormatError
from apygis.formats._readguard import check_str
from apygis.formats.dxf._collect import (
    _clean_text,
    _Collect,
    _flatten_bulges,
    _header_from_tags,
    _int_or_none,
    _own_text,
    _seed_layers,
    _symbol_code,
    _xyz,
)
from apygis.formats.dxf._common import _BINARY_SENTINEL, _CURVE_TYPES, APPID, log
from apygis.model.records import MAX_CODE


def bulge_tolerance(scale: int) -> float:
    """The default chord tolerance of arcs (bulges) of closed polylines, in metres.

    A quarter of the 0.1 mm that is the plotting accuracy at the compilation
    scale 1:``scale``: ``0.1 mm x scale / 4``, i.e. 0.025 m at 1:1000 (the
    scale of a DXF without apygis's header record) and 0.125 m at 1:5000.
    Taken in the drawing's units, like ``sagitta_m``.
    """
    return 0.1e-3 * scale / 4.0


def _load(data: bytes, path):
    """The ezdxf document, recovered and audited; problems are logged."""
    from ezdxf import recover
    from ezdxf.lldxf.const import DXFStructureError

    try:
        if data.startswith(_BINARY_SENTINEL):  # ezdxf's recovery reads ASCII DXF only
            doc, auditor = _load_binary(data)
        else:
            doc, auditor = recover.read(io.BytesIO(data))
    except DXFStructureError as exc:
        raise FormatError(f"not a readable DXF file: {exc}", path=path) from None
    except MemoryError:
        raise
    except Exception as exc:
        # ezdxf's repair can itself fail on odd files (seen: duplicate handles
        # in blocks); load the recovered sections without the audit.
        log.debug("%s: ezdxf recover failed", path, exc_info=True)
        return _load_unaudited(data, path, exc)
    for err in auditor.errors[:20]:
        log.warning("%s: DXF error left unrepaired: %s", path, err.message)
    if auditor.fixes:
        log.info("%s: ezdxf repaired %d problems", path, len(auditor.fixes))
        for fix in auditor.fixes[:20]:
            log.debug("%s: repaired: %s", path, fix.message)
    return doc


def _load_binary(data: bytes):
    from ezdxf.document import Drawing
    from ezdxf.lldxf.tagger import binary_tags_loader

    doc = Drawing.load(binary_tags_loader(data, errors="surrogateescape"))
    return doc, doc.audit()


def _section_tags(section_dict):
    """The tag stream of a recovered section dict (each section's entities, ENDSEC; EOF)."""
    from ezdxf.lldxf.types import DXFTag

    for entities in section_dict.values():
        for entity in entities:  # the first holds (0, SECTION), (2, name)
            yield from entity
        yield DXFTag(0, "ENDSEC")
    yield DXFTag(0, "EOF")


def _load_unaudited(data: bytes, path, first: Exception):
    """The document of ezdxf's recovered sections, loaded without the audit that failed.

    ``recover.read`` is ``Recover.run`` (the structure repairs) and the
    audit; the recovered sections go to :meth:`Drawing.from_tags` as a tag
    stream (no private ``Drawing._load_section_dict``).
    """
    from ezdxf import recover
    from ezdxf.document import Drawing

    try:
        if data.startswith(_BINARY_SENTINEL):
            raise first
        tool = recover.Recover.run(io.BytesIO(data))
        doc = Drawing.from_tags(_section_tags(tool.section_dict))
        doc.modelspace()
    except MemoryError:
        raise
    except Exception as exc:
        raise FormatError(
            f"not a readable DXF file: {type(first).__name__}: {first}", path=path
        ) from exc
    log.warning(
        "%s: ezdxf could not audit this file (%s: %s); read without repairs",
        path,
        type(first).__name__,
        first,
    )
    return doc


def _read_header(doc, path) -> dict | None:
    """The APYGIS header record of an ezdxf document, or None if it has none."""
    try:
        d = doc.rootdict.get(APPID)
    except Exception:  # a damaged objects section
        return None
    if d is None:
        return None
    rec = d.get("HEADER") if hasattr(d, "get") else None
    if rec is None or getattr(rec, "dxftype", lambda: "")() != "XRECORD":
        raise FormatError(f"the {APPID} dictionary has no HEADER record", path=path)
    return _header_from_tags([(t[0], t[1]) for t in rec.tags], path)


# --------------------------------------------------------------------------- through ezdxf


def _own_xdata(e) -> list | None:
    if not e.has_xdata(APPID):
        return None
    return [t[1] for t in e.get_xdata(APPID) if t[0] == 1000]


def _entity(e, c: _Collect, opts: dict, stats: Counter) -> None:
    kind = e.dxftype()
    what = f"{kind} #{e.dxf.get('handle', '?')}"
    if kind == "POINT":
        c.sym.append((None, *_xyz(e.dxf.location, what), opts["symbol_code"]))
    elif kind == "INSERT":
        _insert(e, c, opts, what)
    elif kind in ("TEXT", "MTEXT"):
        _text(e, c, stats, what)
    elif kind == "POLYLINE":
        _polyline(e, c, opts, stats, what)
    elif kind == "LINE":
        pts = [_xyz(e.dxf.start, what), _xyz(e.dxf.end, what)]
        c.lines.append(np.array(pts))
        c.closed.append(False)
    elif kind == "LWPOLYLINE":
        xyb = np.array([tuple(p) for p in e.get_points("xyb")], dtype=float).reshape(-1, 3)
        if e.closed and xyb[:, 2].any():
            line = _bulged_ring(e, xyb, float(e.dxf.get("elevation", 0.0)), opts, what)
        else:
            line = np.array([_xyz(v, what) for v in e.vertices_in_wcs()])
            if xyb[:, 2].any():
                stats["bulges"] += 1
        if len(line):
            c.lines.append(line)
            c.closed.append(bool(e.closed))
    elif kind in _CURVE_TYPES:
        pts = [_xyz(v, what) for v in e.flattening(opts["sagitta_m"])]
        if kind == "SPLINE":
            closed = bool(e.closed)
        elif kind == "ELLIPSE":
            span = (e.dxf.end_param - e.dxf.start_param) % (2 * math.pi)
            closed = math.isclose(span, 0.0, abs_tol=1e-9)
        else:
            closed = kind == "CIRCLE"
        if pts:
            c.lines.append(np.array(pts))
            c.closed.append(closed)
    else:
        stats[f"skip:{kind}"] += 1


def _bulged_ring(e, xyb: np.ndarray, elevation: float, opts: dict, what: str) -> np.ndarray:
    """A closed 2-D polyline with arcs (bulges) as a ring of points in WCS.

    The arcs are flattened to chords within ``opts["bulge_m"]`` of them
    (:func:`_flatten_bulges`), in the polyline's object coordinates at its
    elevation, then converted to WCS (the OCS keeps distances).
    """
    from ezdxf.math import Vec3

    ring = _flatten_bulges(xyb, opts["bulge_m"], closed=True)
    ocs = e.ocs()
    return np.array([_xyz(ocs.to_wcs(Vec3(x, y, elevation)), what) for x, y in ring])


def _insert(e, c: _Collect, opts: dict, what: str) -> None:
    attribs: dict[str, Any] = {}
    for a in e.attribs:
        attribs.setdefault(str(a.dxf.get("tag", "")).upper(), a.dxf.get("text", ""))
    code = _symbol_code(attribs.get("CODE"), e.dxf.get("name", ""), opts["symbol_code"])
    num = _int_or_none(attribs["NUM"]) if "NUM" in attribs else None
    if e.mcount > 1:
        for k, v in enumerate(e.multi_insert()):
            pos = _xyz(v.ocs().to_wcs(v.dxf.insert), what)
            c.sym.append((num if k == 0 else None, *pos, code))
    else:
        c.sym.append((num, *_xyz(e.ocs().to_wcs(e.dxf.insert), what), code))


def _text(e, c: _Collect, stats: Counter, what: str) -> None:
    xd = _own_xdata(e) if e.dxftype() == "TEXT" else None
    if xd is not None:
        if len(xd) != 1:
            raise FormatError(f"{what}: bad {APPID} XDATA {xd!r}")
        own = _own_text(xd[0], str(e.dxf.get("text", "")), what)
        if own is not None:
            check_str(own[1], f"{what}: the text")
            pos = _xyz(e.ocs().to_wcs(e.dxf.insert), what)
            c.txt.append((own[0], *pos, _clean_text(own[1], stats)))
        return
    if e.dxftype() == "TEXT":
        text = e.plain_text()
        pos = _xyz(e.ocs().to_wcs(e.dxf.insert), what)
    else:  # MTEXT: its insertion point is in WCS
        text = " ".join(ln.strip() for ln in e.plain_text(split=True) if ln.strip())
        pos = _xyz(e.dxf.insert, what)
    check_str(text, f"{what}: the text")
    c.txt.append((None, *pos, _clean_text(text, stats)))


def _polyline(e, c: _Collect, opts: dict, stats: Counter, what: str) -> None:
    if e.is_poly_face_mesh or e.is_polygon_mesh:
        stats["skip:POLYLINE mesh"] += 1
        return
    verts = list(e.vertices)
    if e.is_2d_polyline:
        bulges = [float(v.dxf.get("bulge", 0.0)) for v in verts]
        if any(bulges) and all(_own_xdata(v) is None for v in verts):
            if e.is_closed:
                xyb = np.array(
                    [
                        (v.dxf.location[0], v.dxf.location[1], b)
                        for v, b in zip(verts, bulges, strict=True)
                    ],
                    dtype=float,
                ).reshape(-1, 3)
                z = float(e.dxf.get("elevation", (0.0, 0.0, 0.0))[2])
                c.lines.append(_bulged_ring(e, xyb, z, opts, what))
                c.closed.append(True)
                return
            stats["bulges"] += 1
    pts = list(e.points_in_wcs()) if e.is_2d_polyline else [v.dxf.location for v in verts]
    if len(pts) != len(verts):  # pragma: no cover - ezdxf yields one point per vertex
        raise FormatError(f"{what}: vertices and points differ")
    xds = [_own_xdata(v) for v in verts]
    if all(xd is None for xd in xds):
        if pts:
            c.lines.append(np.array([_xyz(p, what) for p in pts]))
            c.closed.append(bool(e.is_closed))
        return
    own = []
    for i, (v, p, xd) in enumerate(zip(verts, pts, xds, strict=True)):
        vwhat = f"VERTEX #{v.dxf.get('handle', '?')} of {what}"
        if xd is None:
            if i in (0, len(verts) - 1):
                continue  # a junction's vertex, drawn so that a branch touches it
            raise FormatError(f"{vwhat}: a vertex without {APPID} XDATA inside an apygis line")
        given = [_int_or_none(s) for s in xd[0].split()] if len(xd) == 1 else []
        ints = [k for k in given if k is not None]
        if len(given) != 7 or len(ints) != 7:
            raise FormatError(f"{vwhat}: bad {APPID} XDATA {xd!r}")
        num, code, fwd, back, s1, s2, row = ints
        if not 0 <= code <= MAX_CODE:
            raise FormatError(f"{vwhat}: line code {code} outside 00-{MAX_CODE}")
        own.append((row, num, code, fwd, back, s1, s2, *_xyz(p, vwhat)))
    nums = {o[1] for o in own}
    if len(nums) < len(own) or nums & c.own_nums:
        # a copy made in CAD, XDATA and all: its numbers are taken, so it is new geometry
        stats["copied lines"] += 1
        c.lines.append(np.array([_xyz(p, what) for p in pts]))
        c.closed.append(bool(e.is_closed))
        return
    c.own_nums |= nums
    c.own += own


def _slow_read(data: bytes, path, names, opts: dict, stats: Counter, progress):
    """Header and records of any DXF, through ezdxf's document model."""
    doc = _load(data, path)
    header = _read_header(doc, path)
    if opts.get("bulge_m") is None:
        scale = header["scale"] if header and header["scale"] else 1000
        opts["bulge_m"] = bulge_tolerance(scale)
    collected = _seed_layers(header, names)
    try:
        entities = list(doc.modelspace())
    except MemoryError:
        raise
    except Exception as exc:
        raise FormatError(f"cannot read the model space: {exc}", path=path) from None
    total = len(entities)
    for i, e in enumerate(entities):
        try:
            ext = names(str(e.dxf.get("layer", "0")))
            if ext is None:
                stats["skip:layer"] += 1
                continue
            _entity(e, collected.setdefault(ext, _Collect()), opts, stats)
        except ApygisError as exc:
            if isinstance(exc, FormatError) and exc.path is None:
                raise FormatError(exc.reason, path=path, record=exc.record) from None
            raise
        except MemoryError:
            raise
        except Exception as exc:
            handle = getattr(getattr(e, "dxf", None), "handle", "?")
            raise FormatError(
                f"{type(exc).__name__}: {exc}", path=path, record=f"{e.dxftype()} #{handle}"
            ) from None
        if progress and (i % 1000 == 999 or i == total - 1):
            progress(i + 1, total)
    return header, collected
