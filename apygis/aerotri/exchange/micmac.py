"""MicMac's ground control files: the 3-D points (``DicoAppuisFlottant``) and their image
measurements (``SetOfMesureAppuisFlottants``), XML.

The structures are MicMac's (``ParamChantierPhotogram.xml``; ``docs/formats/micmac.md``)::

    <Global><DicoAppuisFlottant>              <SetOfMesureAppuisFlottants>
      <OneAppuisDAF>                            <MesureAppuiFlottant1Im>
        <Pt>2600100.0 1200200.0 512.3</Pt>        <NameIm>img_101.tif</NameIm>
        <NamePt>GCP1</NamePt>                     <OneMesureAF1I>
        <Incertitude>0.02 0.02 0.03</Incertitude>   <NamePt>GCP1</NamePt>
      </OneAppuisDAF>                               <PtIm>3044.5 2622.25</PtIm>
    </DicoAppuisFlottant></Global>              </OneMesureAF1I> ...

(the ``Global`` wrapper is optional on reading). ``Incertitude`` is the standard
deviation of X, Y, Z (metres). ASSUMED (not verified against MicMac, see the doc): a
component that is zero or negative means "not used", so a planimetric point is
written with Z 0 and ``Incertitude`` z -1, a height point with x and y -1, a check
point with -1 -1 -1, and read back the same way; image measurements ``PtIm`` are
column, row with the centre of the top-left pixel at 0, 0 (apygis's convention).

``write_micmac(block, "out/blk")`` writes ``out/blk_3d_gcp.xml`` and ``out/blk_2d_gcp.xml``
(control and check points with coordinates, and their measurements); tie and new
points, observations without pixels, sigmas of check points and exterior
orientations are counted in the :class:`~apygis.aerotri.exchange.WriteReport`.
``read_micmac(*sources)`` reads 3-D and 2-D files (each file's kind from its root
element), or the two files of a base name.

Written with :mod:`xml.etree.ElementTree`; read with expat (the parser under
``xml.etree``) directly, record by record, for the line of every record in messages
and handlers that refuse declarations. Hostile XML: a document type declaration or an
entity (``<!DOCTYPE``, ``<!ENTITY``: the "billion laughs") is refused before parsing;
more than :data:`MAX_ELEMENTS` elements, unexpected structure, or a value that is not
what the element holds is a :class:`~apygis.errors.FormatError` naming the file and the
line.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from apygis.aerotri.exchange import ExchangeBlock, ExImage, ExObservation, ExPoint, WriteReport
from apygis.aerotri.exchange._common import Index, control_xyz_ok, finite_xyz, pixels
from apygis.errors import FormatError, ValueRangeError
from apygis.fileio import atomic_write_many, read_bytes
from apygis.formats._records import check_name, numbers

__all__ = ["MAX_ELEMENTS", "read_micmac", "write_micmac"]

MAX_ELEMENTS = 4_000_000
"""The most XML elements read from one file (a million image measurements)."""
MAX_BYTES = 64 << 20
SUFFIX_3D = "_3d_gcp.xml"
SUFFIX_2D = "_2d_gcp.xml"
_KINDS = {
    (True, True): "full",
    (True, False): "planimetric",
    (False, True): "height",
    (False, False): "check",
}


def _f(v) -> str:
    return repr(float(v))


def _xml(root: ET.Element) -> bytes:
    """The document as UTF-8 with a declaration, indented by two blanks per level."""
    ET.indent(root, space="  ")
    return (
        b'<?xml version="1.0" encoding="UTF-8"?>\n'
        + ET.tostring(root, encoding="utf-8", xml_declaration=False)
        + b"\n"
    )


def write_micmac(
    block: ExchangeBlock, target, *, default_sigma_m: float | None = None
) -> WriteReport:
    """Write the block's control and check points and their image measurements as MicMac's
    3-D and 2-D files ``<target>_3d_gcp.xml`` and ``<target>_2d_gcp.xml`` (atomically).

    ``default_sigma_m``: the ``Incertitude`` of control points without sigmas (else such
    a point is refused: MicMac needs one). Raises
    :class:`~apygis.errors.ValueRangeError` naming the file and record for a name that
    is empty or holds a blank or control character, a control point without sigma.
    """
    base = Path(target)
    for suffix in (SUFFIX_3D, SUFFIX_2D, ".xml"):
        if base.name.endswith(suffix):
            base = base.with_name(base.name[: -len(suffix)])
            break
    f3, f2 = base.with_name(base.name + SUFFIX_3D), base.with_name(base.name + SUFFIX_2D)
    idx = Index(block, base)
    report = WriteReport()
    root3 = ET.Element("Global")
    dico = ET.SubElement(root3, "DicoAppuisFlottant")
    written: set[str] = set()
    defaulted = 0
    for p in block.points:
        xyz = finite_xyz(p)
        rec = f"point {p.name!r}"
        if p.kind not in ("full", "planimetric", "height", "check"):
            if xyz is not None:
                report.skip("adjusted coordinates of tie and new points (not ground control)")
            continue
        if not control_xyz_ok(p, xyz):
            report.skip("control and check points without the coordinates their kind needs")
            continue
        assert xyz is not None  # control_xyz_ok
        check_name(p.name, f3, rec, "point name")
        if p.sigma is not None:
            sig = np.array(p.sigma, dtype=float).reshape(3)  # a copy: the block is not changed
        elif default_sigma_m is not None:
            sig = np.full(3, float(default_sigma_m))
            defaulted += p.kind != "check"
        elif p.kind == "check":
            sig = np.ones(3)
        else:
            raise ValueRangeError(
                "the control point has no sigma, and MicMac's Incertitude needs one: give the "
                "block's points sigmas or pass default_sigma_m=",
                f3,
                rec,
            )
        if p.kind != "check" and not (np.isfinite(sig).all() and (sig > 0).all()):
            raise ValueRangeError(f"sigma {sig.tolist()} is not three positive numbers", f3, rec)
        pt = xyz.copy()
        if p.kind == "planimetric":
            pt[2], sig[2] = 0.0, -1.0
            report.skip("sigmas of coordinates a point does not control", int(p.sigma is not None))
        elif p.kind == "height":
            sig[:2] = -1.0
            report.skip("sigmas of coordinates a point does not control", 2 * (p.sigma is not None))
        elif p.kind == "check":
            report.skip(
                "check point sigmas (a check point's Incertitude is -1 -1 -1)",
                int(p.sigma is not None),
            )
            sig[:] = -1.0
        one = ET.SubElement(dico, "OneAppuisDAF")
        ET.SubElement(one, "Pt").text = " ".join(_f(v) for v in pt)
        ET.SubElement(one, "NamePt").text = p.name
        ET.SubElement(one, "Incertitude").text = " ".join(_f(v) for v in sig)
        written.add(p.name)
    if defaulted:
        report.notes.append(
            f"{defaulted} control points without sigma written with Incertitude {default_sigma_m} m"
        )
    root2 = ET.Element("SetOfMesureAppuisFlottants")
    n_meas = 0
    for image, obs in idx.by_image().items():
        im = idx.images[image]
        rows: list[tuple[str, str]] = []
        for ob in obs:
            if ob.point not in written:
                report.skip("observations of points not in the 3-D file (tie and new points)")
                continue
            px = pixels(ob, im)
            if px is None:
                report.skip("observations without pixel coordinates (and no pixel transform)")
                continue
            if not all(math.isfinite(v) and abs(v) <= 1e7 for v in px):
                raise ValueRangeError(
                    f"pixel coordinates {px} are not finite",
                    f2,
                    f"image {image} point {ob.point!r}",
                )
            rows.append((ob.point, f"{_f(px[0])} {_f(px[1])}"))
            n_meas += 1
            report.skip(
                "observation sigmas (MicMac's 2-D file has none)", int(ob.sigma_px is not None)
            )
        if rows:
            check_name(im.name, f2, f"image {image}", "image name")
            one_im = ET.SubElement(root2, "MesureAppuiFlottant1Im")
            ET.SubElement(one_im, "NameIm").text = im.name
            for name, uv in rows:
                mes = ET.SubElement(one_im, "OneMesureAF1I")
                ET.SubElement(mes, "NamePt").text = name
                ET.SubElement(mes, "PtIm").text = uv
    report.skip(
        "exterior orientations (not part of MicMac's GCP files)",
        sum(im.eo is not None for im in block.images),
    )
    report.files = atomic_write_many({f3: _xml(root3), f2: _xml(root2)}, parents=True)
    report.written = {"points": len(written), "measurements": n_meas}
    report.log("MicMac")
    return report


# ------------------------------------------------------------------ reading


def _parse(path: Path) -> tuple[str, list[tuple[str, dict[str, str], int]]]:
    """The root element and the records of one MicMac XML file: ``("3d", {NamePt, Pt,
    Incertitude}, line)`` and ``("2d", {NameIm, NamePt, PtIm}, line)``, parsed with expat
    (no document type, no entities)."""
    from xml.parsers import expat

    data = read_bytes(path, "MicMac XML file", max_bytes=MAX_BYTES)
    for bad in (b"<!DOCTYPE", b"<!ENTITY"):
        k = data.find(bad)
        if k >= 0:
            line = data.count(b"\n", 0, k) + 1
            raise FormatError(
                f"holds {bad.decode()}: document type declarations and entities are refused "
                "(MicMac's files have none)",
                path,
                f"line {line}",
            )
    parser = expat.ParserCreate()
    stack: list[str] = []
    text: list[str] = []
    record: dict[str, str] = {}
    name_im: list[str | None] = [None]
    out: list[tuple[str, dict[str, str], int]] = []
    root: list[str] = []
    count = [0]
    start_line = [0]

    def refuse(*_args):
        raise FormatError(
            "holds a document type declaration or an entity (refused)",
            path,
            f"line {parser.CurrentLineNumber}",
        )

    def start(tag, _attrs):
        count[0] += 1
        if count[0] > MAX_ELEMENTS:
            raise FormatError(
                f"more than {MAX_ELEMENTS} XML elements", path, f"line {parser.CurrentLineNumber}"
            )
        if not root:
            root.append(tag)
        if tag in ("OneAppuisDAF", "OneMesureAF1I"):
            record.clear()
            start_line[0] = parser.CurrentLineNumber
        stack.append(tag)
        text.clear()

    def chars(data):
        if len(text) < 64:  # values are short; a huge text is cut here and refused as a value
            text.append(data)

    def end(tag):
        stack.pop()
        value = "".join(text).strip()
        text.clear()
        parent = stack[-1] if stack else None
        if tag in ("NamePt", "Pt", "Incertitude", "PtIm") and parent in (
            "OneAppuisDAF",
            "OneMesureAF1I",
        ):
            record[tag] = value
        elif tag == "NameIm" and parent == "MesureAppuiFlottant1Im":
            name_im[0] = value
        elif tag == "OneAppuisDAF":
            out.append(("3d", dict(record), start_line[0]))
        elif tag == "OneMesureAF1I":
            rec = dict(record)
            if name_im[0] is not None:
                rec["NameIm"] = name_im[0]
            out.append(("2d", rec, start_line[0]))
        elif tag == "MesureAppuiFlottant1Im":
            name_im[0] = None

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.StartDoctypeDeclHandler = refuse
    parser.EntityDeclHandler = refuse
    try:
        parser.Parse(data, True)
    except LookupError as exc:  # an encoding declaration Python does not know
        raise FormatError(f"the XML declares an unknown encoding ({exc})", path, "line 1") from None
    except expat.ExpatError as exc:
        raise FormatError(
            f"not well-formed XML ({expat.ErrorString(exc.code)})",
            path,
            f"line {exc.lineno} column {exc.offset + 1}",
        ) from None
    if not root:
        raise FormatError("an empty XML document", path)
    return root[0], out


def read_micmac(source, *more) -> ExchangeBlock:
    """Read MicMac GCP files: each argument a 3-D (``DicoAppuisFlottant``) or 2-D
    (``SetOfMesureAppuisFlottants``) file, or a base name whose ``_3d_gcp.xml`` and
    ``_2d_gcp.xml`` are read.

    Points get their kind from the signs of ``Incertitude`` (see the module docstring)
    and it as sigma (control only); images are numbered 1, 2, ... in order of first
    appearance; observations carry pixels only. A measured point that no 3-D file
    given has is a point of kind "tie" without coordinates.
    """
    paths: list[Path] = []
    for s in (source, *more):
        p = Path(s)
        if p.is_file():
            paths.append(p)
            continue
        pair = [p.with_name(p.name + SUFFIX_3D), p.with_name(p.name + SUFFIX_2D)]
        found = [q for q in pair if q.is_file()]
        if not found:
            raise FormatError(f"no such file (nor {pair[0].name} or {pair[1].name} beside it)", p)
        paths += found
    block = ExchangeBlock()
    points: dict[str, ExPoint] = {}
    images: dict[str, ExImage] = {}
    seen: set[tuple[str, int]] = set()
    for path in paths:
        root, records = _parse(path)
        if root not in ("Global", "DicoAppuisFlottant", "SetOfMesureAppuisFlottants"):
            raise FormatError(
                f"root element <{root[:40]}> is not MicMac's Global, DicoAppuisFlottant or "
                "SetOfMesureAppuisFlottants",
                path,
            )
        kinds = {what for what, _, _ in records}
        if len(kinds) > 1:
            raise FormatError("a file holds both 3-D points and image measurements", path)
        if not records:
            block.skipped[f"MicMac files without points or measurements ({path.name})"] = 1
        for what, rec, line in records:
            where = f"line {line}"
            if what == "3d":
                _point(rec, points, path, where)
            else:
                _measure(rec, points, images, seen, block, path, where)
    block.points = list(points.values())
    block.images = list(images.values())
    return block


def _need(rec: dict, key: str, path, where: str) -> str:
    if key not in rec:
        raise FormatError(f"<{key}> is missing", path, where)
    return rec[key]


def _name(s: str, path, where: str, what: str) -> str:
    if not s or not s.isprintable() or s.split() != [s]:
        raise FormatError(
            f"{what} {s[:40]!r} is empty or holds a blank or control character", path, where
        )
    return s


def _point(rec: dict, points: dict, path, where: str) -> None:
    nm = _name(_need(rec, "NamePt", path, where), path, where, "point name")
    pt = numbers(_need(rec, "Pt", path, where).split(), path, where, "Pt")
    inc = numbers(
        _need(rec, "Incertitude", path, where).split(), path, where, "Incertitude", limit=1e6
    )
    if len(pt) != 3 or len(inc) != 3:
        raise FormatError("<Pt> and <Incertitude> hold three numbers each", path, where)
    if (inc[0] > 0) != (inc[1] > 0):
        raise FormatError(
            f"Incertitude {inc.tolist()}: x and y are used or not used together", path, where
        )
    kind = _KINDS[(bool(inc[0] > 0), bool(inc[2] > 0))]
    if kind == "planimetric":
        pt[2] = math.nan
    old = points.get(nm)
    if old is not None and old.xyz is not None:
        raise FormatError(f"point {nm!r} is given twice", path, where)
    sigma = None if kind == "check" else np.where(inc > 0, inc, math.nan)
    if old is None:
        points[nm] = ExPoint(nm, kind, pt, sigma)
    else:
        old.kind, old.xyz, old.sigma = kind, pt, sigma


def _measure(
    rec: dict, points: dict, images: dict, seen: set, block: ExchangeBlock, path, where: str
) -> None:
    img = _name(_need(rec, "NameIm", path, where), path, where, "image name")
    nm = _name(_need(rec, "NamePt", path, where), path, where, "point name")
    uv = numbers(_need(rec, "PtIm", path, where).split(), path, where, "PtIm", limit=1e7)
    if len(uv) != 2:
        raise FormatError("<PtIm> holds two numbers (column, row)", path, where)
    im = images.get(img)
    if im is None:
        im = images[img] = ExImage(image=len(images) + 1, name=img)
    if (nm, im.image) in seen:
        raise FormatError(f"point {nm!r} is measured twice in image {img!r}", path, where)
    seen.add((nm, im.image))
    points.setdefault(nm, ExPoint(nm, "tie"))
    block.observations.append(ExObservation(nm, im.image, None, None, float(uv[0]), float(uv[1])))
