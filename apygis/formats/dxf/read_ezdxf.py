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
    _point_code,
    _seed_layers,
    _symbol_code,
    _xyz,
)
from apygis.formats.dxf._common import _BINARY_SENTINEL, _CURVE_TYPES, APPID, log
from apygis.model.records import MAX_CODE


def chord_tolerance(scale: int) -> float:
    """The default chord tolerance of curves (arcs, bulges, ellipses, splines), in metres.

    A quarter of the 0.1 mm that is the plotting accuracy at the compilation
    scale 1:``scale``: ``0.1 mm x scale / 4``, i.e. 0.025 m at 1:1000 (the
    scale of a DXF without apygis's header record) and 0.125 m at 1:5000.
    Taken in the drawing's units.
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


# entity types skipped, with the reason told to the user
_SURFACES = "surfaces are not supported"
_SKIP_REASON = {
    "MESH": _SURFACES,
    "POLYFACE": _SURFACES,
    "POLYMESH": _SURFACES,
    "3DSOLID": _SURFACES,
    "BODY": _SURFACES,
    "REGION": _SURFACES,
    "SURFACE": _SURFACES,
    "EXTRUDEDSURFACE": _SURFACES,
    "LOFTEDSURFACE": _SURFACES,
    "REVOLVEDSURFACE": _SURFACES,
    "SWEPTSURFACE": _SURFACES,
    "PLANESURFACE": _SURFACES,
    "NURBSURFACE": _SURFACES,
    "IMAGE": "raster images are not map data",
    "WIPEOUT": "masks are not map data",
    "PDFUNDERLAY": "underlays are not map data",
    "DWFUNDERLAY": "underlays are not map data",
    "DGNUNDERLAY": "underlays are not map data",
    "OLE2FRAME": "embedded objects are not map data",
    "OLEFRAME": "embedded objects are not map data",
    "XLINE": "infinite lines have no ends to import",
    "RAY": "infinite lines have no ends to import",
    "VIEWPORT": "viewports are not map data",
    "ACAD_TABLE": "tables are not imported",
    "TOLERANCE": "tolerance frames are not imported",
    "ATTDEF": "attribute definitions outside a block are templates, not texts",
    "ACAD_PROXY_ENTITY": "proxy entities cannot be read without their application",
}
# the parts of a DIMENSION, LEADER, MULTILEADER or MLINE that are imported
_PART_LINES = ("LINE", "LWPOLYLINE", "POLYLINE", *_CURVE_TYPES)
_PART_TEXTS = ("TEXT", "MTEXT")


def skip_reason(kind: str) -> str:
    """Why an entity of type ``kind`` is not imported (for the warning)."""
    return _SKIP_REASON.get(kind, "not imported")


def _own_xdata(e) -> list | None:
    if not e.has_xdata(APPID):
        return None
    return [t[1] for t in e.get_xdata(APPID) if t[0] == 1000]


def _add_line(c: _Collect, pts, closed: bool, code: int) -> None:
    line = np.asarray(pts, dtype=float).reshape(-1, 3)
    if len(line):
        c.lines.append(line)
        c.closed.append(bool(closed))
        c.codes.append(code)


def _entity(e, c: _Collect, opts: dict, stats: Counter) -> None:
    kind = e.dxftype()
    what = f"{kind} #{e.dxf.get('handle', '?')}"
    if kind == "POINT":
        x, y, z = _xyz(e.dxf.location, what)
        c.sym.append((None, x, y, z, _point_code(z, opts)))
    elif kind == "INSERT":
        _insert(e, c, opts, stats, what)
    elif kind in _PART_TEXTS:
        _text(e, c, stats, what)
    elif kind == "POLYLINE":
        _polyline(e, c, opts, stats, what)
    elif kind in ("LINE", "LWPOLYLINE", *_CURVE_TYPES, "HELIX"):
        _plain_line(e, c, opts, what)
    elif kind in ("HATCH", "MPOLYGON"):
        for ring in _hatch_rings(e, opts, what):
            _add_line(c, ring, True, opts["line_code"])
    elif kind in ("SOLID", "TRACE", "3DFACE"):
        pts = [_xyz(v, what) for v in e.wcs_vertices()]
        if len(pts) >= 3:
            _add_line(c, pts, True, opts["line_code"])
        else:
            _add_line(c, pts, False, opts["line_code"])
    elif kind == "LEADER":
        pts = [_xyz(v, what) for v in e.vertices]  # WCS
        _add_line(c, pts, False, opts["line_code"])
    elif kind in ("DIMENSION", "ARC_DIMENSION", "LARGE_RADIAL_DIMENSION", "MULTILEADER", "MLINE"):
        _parts(e, c, opts, stats, what)
    else:
        stats[f"skip:{kind}"] += 1


def _plain_line(e, c: _Collect, opts: dict, what: str) -> None:
    """LINE, LWPOLYLINE, ARC, CIRCLE, ELLIPSE, SPLINE (HELIX): a line in WCS."""
    kind = e.dxftype()
    code = opts["line_code"]
    if kind == "LINE":
        _add_line(c, [_xyz(e.dxf.start, what), _xyz(e.dxf.end, what)], False, code)
    elif kind == "LWPOLYLINE":
        xyb = np.array([tuple(p) for p in e.get_points("xyb")], dtype=float).reshape(-1, 3)
        closed = bool(e.closed)
        if xyb[:, 2].any():
            line = _bulged(e, xyb, float(e.dxf.get("elevation", 0.0)), opts, closed, what)
        else:
            line = np.array([_xyz(v, what) for v in e.vertices_in_wcs()]).reshape(-1, 3)
        _add_line(c, line, closed, code)
    else:
        pts = [_xyz(v, what) for v in e.flattening(opts["chord_m"])]
        if kind in ("SPLINE", "HELIX"):
            closed = bool(e.closed)
        elif kind == "ELLIPSE":
            span = (e.dxf.end_param - e.dxf.start_param) % (2 * math.pi)
            closed = math.isclose(span, 0.0, abs_tol=1e-9)
        else:
            closed = kind == "CIRCLE"
        if closed and len(pts) > 1 and np.allclose(pts[0], pts[-1]):
            pts = pts[:-1]
        _add_line(c, pts, closed, code)


def _bulged(e, xyb: np.ndarray, elevation: float, opts: dict, closed: bool, what: str):
    """A 2-D polyline with arcs (bulges) as points in WCS.

    The arcs are flattened to chords within ``opts["chord_m"]`` of them
    (:func:`_flatten_bulges`), in the polyline's object coordinates at its
    elevation, then converted to WCS (the OCS keeps distances).
    """
    from ezdxf.math import Vec3

    pts = _flatten_bulges(xyb, opts["chord_m"], closed=closed)
    ocs = e.ocs()
    return np.array([_xyz(ocs.to_wcs(Vec3(x, y, elevation)), what) for x, y in pts])


def _hatch_rings(e, opts: dict, what: str) -> list[np.ndarray]:
    """The boundary paths of a HATCH (or MPOLYGON) as rings in WCS.

    Polyline paths with their bulges, edge paths edge by edge (lines, arcs,
    ellipse arcs and splines flattened on the true curves within
    ``chord_m``), in the hatch's object coordinates at its elevation.
    """
    from ezdxf.entities.boundary_paths import EdgePath, PolylinePath
    from ezdxf.math import Vec3

    tol = opts["chord_m"]
    elev = e.dxf.get("elevation", Vec3(0, 0, 0))
    z = float(elev[2]) if not isinstance(elev, (int, float)) else float(elev)
    ocs = e.ocs()
    rings = []
    for path in e.paths:
        if isinstance(path, PolylinePath):
            xyb = np.array([(v[0], v[1], v[2]) for v in path.vertices], dtype=float)
            xy = _flatten_bulges(xyb.reshape(-1, 3), tol, closed=True) if len(xyb) else xyb
        elif isinstance(path, EdgePath):
            xy = _edge_points(path, tol)
        else:  # pragma: no cover - ezdxf has the two kinds
            continue
        if len(xy) > 1 and np.allclose(xy[0], xy[-1]):
            xy = xy[:-1]
        if len(xy) >= 2:
            rings.append(np.array([_xyz(ocs.to_wcs(Vec3(x, y, z)), what) for x, y in xy[:, :2]]))
    return rings


def _edge_points(path, tol: float) -> np.ndarray:
    """The points of an edge path, each edge flattened and turned to follow the one before."""
    out: list[np.ndarray] = []
    for edge in path.edges:
        if hasattr(edge, "construction_tool"):
            pts = np.array([(v[0], v[1]) for v in edge.construction_tool().flattening(tol)])
        else:  # a line edge
            pts = np.array([tuple(edge.start)[:2], tuple(edge.end)[:2]], dtype=float)
        if not len(pts):
            continue
        if out:
            end = out[-1][-1]
            if np.hypot(*(pts[-1] - end)) < np.hypot(*(pts[0] - end)):
                pts = pts[::-1]
            if np.allclose(pts[0], end):
                pts = pts[1:]
        out.append(pts)
    return np.concatenate(out) if out else np.zeros((0, 2))


def _parts(e, c: _Collect, opts: dict, stats: Counter, what: str) -> None:
    """DIMENSION, MULTILEADER, MLINE: their lines as lines, their texts as texts.

    Arrowheads, dimension definition points and other parts are drawing
    detail of the one entity read; all its parts go to the entity's layer.
    """
    try:
        parts = list(e.virtual_entities())
    except Exception as exc:  # a dimension without its block, a broken MLINE style
        log.debug("%s: %s has no parts ezdxf can render: %s", opts.get("path"), what, exc)
        stats[f"skip:{e.dxftype()} (no geometry)"] += 1
        return
    for v in parts:
        kind = v.dxftype()
        if kind in _PART_TEXTS:
            _text(v, c, stats, what)
        elif kind == "POLYLINE":
            _polyline(v, c, opts, stats, what)
        elif kind in _PART_LINES:
            _plain_line(v, c, opts, what)


def _insert(e, c: _Collect, opts: dict, stats: Counter, what: str) -> None:
    """A symbol at the insertion point; the attributes of foreign blocks as texts.

    The block ``APY_SYM_NN`` apygis writes carries its point number, code and
    height in the attributes ``NUM``, ``CODE``, ``Z``: those are the symbol's.
    Every other attribute (``ATTRIB``, invisible ones too: they are data) is a
    text at its own place, on its own layer, as GDAL reads them.
    """
    attribs: dict[str, Any] = {}
    for a in e.attribs:
        attribs.setdefault(str(a.dxf.get("tag", "")).upper(), a.dxf.get("text", ""))
    own = _symbol_code(None, e.dxf.get("name", ""), -1) >= 0
    z_of = _xyz(e.ocs().to_wcs(e.dxf.insert), what)[2]
    code = _symbol_code(attribs.get("CODE"), e.dxf.get("name", ""), _point_code(z_of, opts))
    num = _int_or_none(attribs["NUM"]) if "NUM" in attribs else None
    copies = list(e.multi_insert()) if e.mcount > 1 else [e]
    for k, v in enumerate(copies):
        pos = _xyz(v.ocs().to_wcs(v.dxf.insert), what)
        c.sym.append((num if k == 0 else None, *pos, code))
        if own:
            continue
        for a in v.attribs:  # invisible ones too: data, as GDAL reads them
            text = a.plain_text() if hasattr(a, "plain_text") else str(a.dxf.get("text", ""))
            if not text.strip():
                continue
            target = opts["collector"](str(a.dxf.get("layer", "0")))
            if target is None:
                continue
            awhat = f"ATTRIB {a.dxf.get('tag', '?')} of {what}"
            check_str(text, f"{awhat}: the text")
            target.txt.append(
                (None, *_xyz(a.ocs().to_wcs(a.dxf.insert), awhat), _clean_text(text, stats))
            )


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
    else:  # MTEXT: its insertion point is in WCS; its lines joined by a blank, kept whole
        text = " ".join(e.plain_text(split=True))
        pos = _xyz(e.dxf.insert, what)
    check_str(text, f"{what}: the text")
    c.txt.append((None, *pos, _clean_text(text, stats)))


def _polyline(e, c: _Collect, opts: dict, stats: Counter, what: str) -> None:
    if e.is_poly_face_mesh or e.is_polygon_mesh:
        stats["skip:POLYFACE" if e.is_poly_face_mesh else "skip:POLYMESH"] += 1
        return
    verts = list(e.vertices)
    if e.is_2d_polyline:
        bulges = [float(v.dxf.get("bulge", 0.0)) for v in verts]
        if any(bulges) and all(_own_xdata(v) is None for v in verts):
            xyb = np.array(
                [
                    (v.dxf.location[0], v.dxf.location[1], b)
                    for v, b in zip(verts, bulges, strict=True)
                ],
                dtype=float,
            ).reshape(-1, 3)
            z = float(e.dxf.get("elevation", (0.0, 0.0, 0.0))[2])
            closed = bool(e.is_closed)
            _add_line(c, _bulged(e, xyb, z, opts, closed, what), closed, opts["line_code"])
            return
    pts = list(e.points_in_wcs()) if e.is_2d_polyline else [v.dxf.location for v in verts]
    if len(pts) != len(verts):  # pragma: no cover - ezdxf yields one point per vertex
        raise FormatError(f"{what}: vertices and points differ")
    xds = [_own_xdata(v) for v in verts]
    if all(xd is None for xd in xds):
        _add_line(c, [_xyz(p, what) for p in pts], bool(e.is_closed), opts["line_code"])
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
        _add_line(c, [_xyz(p, what) for p in pts], bool(e.is_closed), opts["line_code"])
        return
    c.own_nums |= nums
    c.own += own


def _layer_of(e) -> str:
    try:
        return str(e.dxf.get("layer", "0"))
    except Exception:  # an entity type without layers (a damaged file): layer 0
        return "0"


def _layer_names_of(doc) -> list[str]:
    try:
        return [str(lay.dxf.name) for lay in doc.layers]
    except Exception:  # a damaged layer table: the entities' layers are still met
        return []


def _slow_read(data: bytes, path, names, opts: dict, stats: Counter, progress):
    """Header and records of any DXF, through ezdxf's document model."""
    doc = _load(data, path)
    header = _read_header(doc, path)
    if opts.get("chord_m") is None:
        scale = header["scale"] if header and header["scale"] else 1000
        opts["chord_m"] = chord_tolerance(scale)
    try:
        entities = list(doc.modelspace())
    except MemoryError:
        raise
    except Exception as exc:
        raise FormatError(f"cannot read the model space: {exc}", path=path) from None
    present = _layer_names_of(doc) + [_layer_of(e) for e in entities]
    names.start(present, header)
    collected = _seed_layers(header, names)
    opts["collector"] = names.collector(collected)
    opts["path"] = path
    total = len(entities)
    for i, e in enumerate(entities):
        try:
            target = opts["collector"](_layer_of(e))
            if target is None:
                stats["skip:layer"] += 1
                continue
            _entity(e, target, opts, stats)
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
    try:
        paper = sum(
            1
            for layout in doc.layouts
            if layout.name.upper() != "MODEL"
            for e in layout
            if e.dxftype() != "VIEWPORT"
        )
    except Exception:  # a damaged layout: what it held is not read either way
        paper = 0
    if paper:
        stats["paper space"] += paper
    return header, collected
