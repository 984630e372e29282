r"""Hand-written PDF 1.4: the plot of a map, and text print-outs on A4 pages.

Both use one small writer (:func:`pdf_document`): numbered indirect objects,
a catalog, a page tree, base-14 Type 1 fonts with ``WinAnsiEncoding`` (no
font is embedded), one content stream per page (Flate-compressed unless
``compress=False``), an info dictionary, and a cross-reference table whose
byte offsets point exactly at each ``N 0 obj``. Output is deterministic: no
dates, no random IDs.

Plot (:func:`drawing_pdf`): one page the size of the paper. The content
stream first scales user space to millimetres
(``2.834646 0 0 2.834646 0 0 cm``, 72 / 25.4 points per mm) and sets round
caps and joins, so paper coordinates are written as they are, y up. A
:class:`~apygis.plot.drawing.PaperLine` is one path ``m l ... S``
(``h S`` when closed), a symbol's :class:`~apygis.plot.drawing.FilledRects`
one ``re`` per rectangle and one ``f``, a
:class:`~apygis.plot.drawing.PaperText` ``BT /F1 size Tf x y Td (...) Tj ET``
in Helvetica with size = cap height / 0.718. Pen colour and width are set
(``RG``, ``rg``, ``w``) only where they change.

Text (:func:`text_pages_pdf`): A4 portrait pages of Courier (monospaced, so
columns stay aligned), a footer with a title and "page i of n". Lines too
long for the page wrap; a form feed starts a new page.

Strings are encoded in Windows-1252 (``WinAnsiEncoding``); a character
outside it becomes ``?``; ``(``, ``)`` and ``\`` are escaped and bytes
outside printable ASCII are written as octal escapes (an uncompressed
content stream is plain ASCII).

Examples
--------
>>> pdf_string("a(b)\\c ü€")
b'(a\\(b\\)\\\\c \\374\\200)'
>>> pdf = text_pages_pdf("hello\n", title="T", compress=False)
>>> pdf[:8], pdf.count(b"/Type /Page "), pdf.rstrip().endswith(b"%%EOF")
(b'%PDF-1.4', 1, True)
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence

from apygis.plot.drawing import CAP_HEIGHT, Drawing, FilledRects, PaperLine, PaperText

__all__ = [
    "A4_PT",
    "PT_PER_MM",
    "TEXT_FONT_SIZE",
    "drawing_pdf",
    "pdf_document",
    "pdf_string",
    "text_page_capacity",
    "text_pages",
    "text_pages_pdf",
]

#: Points (1/72 inch) per millimetre.
PT_PER_MM = 72.0 / 25.4
#: A4 portrait in points.
A4_PT = (210.0 * PT_PER_MM, 297.0 * PT_PER_MM)
#: Font size of text print-outs, points.
TEXT_FONT_SIZE = 9.0

# text page layout (points): margins, leading as a multiple of the font size
_TEXT_LEFT, _TEXT_RIGHT, _TEXT_TOP, _TEXT_BOTTOM = 48.0, 36.0, 48.0, 60.0
_FOOTER_Y = 30.0
_LEADING = 1.2
_COURIER_ADVANCE = 0.6  # every Courier glyph is 600/1000 em wide


def pdf_string(text: str) -> bytes:
    """``text`` as a PDF literal string in WinAnsiEncoding, parentheses included."""
    raw = text.encode("cp1252", errors="replace")
    out = bytearray(b"(")
    for b in raw:
        if b in b"()\\":
            out += b"\\" + bytes([b])
        elif 32 <= b < 127:
            out.append(b)
        else:
            out += f"\\{b:03o}".encode("ascii")
    out += b")"
    return bytes(out)


def _num(v: float) -> str:
    s = f"{v:.3f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def pdf_document(
    pages: Sequence[tuple[bytes, tuple[float, float]]],
    fonts: dict[str, str],
    title: str = "",
    compress: bool = True,
) -> bytes:
    """A complete PDF 1.4 file.

    Parameters
    ----------
    pages : sequence of (bytes, (float, float))
        Each page's content stream and its size (width, height) in points.
    fonts : dict of str to str
        Resource name to base-14 font name (``{"F1": "Helvetica"}``), shared
        by all pages.
    title : str
        The document title (info dictionary).
    compress : bool
        Flate-compress the content streams.

    Returns
    -------
    bytes
    """
    objects: list[bytes] = []

    def add(body: bytes) -> int:
        objects.append(body)
        return len(objects)

    catalog = add(b"")  # filled in below
    page_tree = add(b"")
    font_refs = {}
    for name, base in fonts.items():
        font_refs[name] = add(
            f"<< /Type /Font /Subtype /Type1 /BaseFont /{base} "
            f"/Encoding /WinAnsiEncoding >>".encode("ascii")
        )
    resources = "<< /Font << " + " ".join(f"/{n} {r} 0 R" for n, r in font_refs.items()) + " >> >>"
    kids = []
    for content, (w, h) in pages:
        data = zlib.compress(content, 9) if compress else content
        filt = " /Filter /FlateDecode" if compress else ""
        stream = add(
            f"<< /Length {len(data)}{filt} >>\nstream\n".encode("ascii") + data + b"\nendstream"
        )
        kids.append(
            add(
                f"<< /Type /Page /Parent {page_tree} 0 R /MediaBox [0 0 {_num(w)} {_num(h)}] "
                f"/Resources {resources} /Contents {stream} 0 R >>".encode("ascii")
            )
        )
    objects[catalog - 1] = f"<< /Type /Catalog /Pages {page_tree} 0 R >>".encode("ascii")
    objects[page_tree - 1] = (
        f"<< /Type /Pages /Kids [{' '.join(f'{k} 0 R' for k in kids)}] "
        f"/Count {len(kids)} >>".encode("ascii")
    )
    info = add(b"<< /Title " + pdf_string(title) + b" /Producer (apygis) >>")

    buf = bytearray(b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n")
    offsets = []
    for i, body in enumerate(objects, start=1):
        offsets.append(len(buf))
        buf += f"{i} 0 obj\n".encode("ascii") + body + b"\nendobj\n"
    xref = len(buf)
    buf += f"xref\n0 {len(objects) + 1}\n0000000000 65535 f \n".encode("ascii")
    for off in offsets:
        buf += f"{off:010d} 00000 n \n".encode("ascii")
    buf += (
        f"trailer\n<< /Size {len(objects) + 1} /Root {catalog} 0 R /Info {info} 0 R >>\n"
        f"startxref\n{xref}\n%%EOF\n"
    ).encode("ascii")
    return bytes(buf)


# --------------------------------------------------------------------------- the plot


def _rgb(colour: tuple[int, int, int]) -> str:
    return " ".join(_num(c / 255.0) for c in colour)


def drawing_pdf(d: Drawing, compress: bool = True) -> bytes:
    """The drawing as a one-page PDF the size of its paper."""
    out = [f"q\n{PT_PER_MM:.6f} 0 0 {PT_PER_MM:.6f} 0 0 cm\n1 J 1 j\n"]
    stroke = fill = width = None
    for it in d.items:
        pen = d.pens.get(it.pen)
        colour = _rgb(pen.colour) if pen else "0 0 0"
        if isinstance(it, PaperLine):
            w = _num(pen.width_mm if pen else 0.35)
            if w != width:
                out.append(f"{w} w\n")
                width = w
            if colour != stroke:
                out.append(f"{colour} RG\n")
                stroke = colour
            pts = it.points.tolist()
            path = [f"{_num(pts[0][0])} {_num(pts[0][1])} m"]
            path += [f"{_num(x)} {_num(y)} l" for x, y in pts[1:]]
            if len(pts) == 1:
                path.append(f"{_num(pts[0][0])} {_num(pts[0][1])} l")
            out.append("\n".join(path) + ("\nh S\n" if it.closed else "\nS\n"))
        elif isinstance(it, FilledRects):
            if not len(it.rects):
                continue
            if colour != fill:
                out.append(f"{colour} rg\n")
                fill = colour
            out.append(
                "".join(
                    f"{_num(x0)} {_num(y0)} {_num(x1 - x0)} {_num(y1 - y0)} re\n"
                    for x0, y0, x1, y1 in it.rects.tolist()
                )
                + "f\n"
            )
        elif isinstance(it, PaperText):
            if colour != fill:
                out.append(f"{colour} rg\n")
                fill = colour
            size = _num(it.height / CAP_HEIGHT)
            out.append(
                f"BT /F1 {size} Tf {_num(it.x)} {_num(it.y)} Td "
                + pdf_string(it.text).decode("ascii")
                + " Tj ET\n"
            )
    out.append("Q\n")
    content = "".join(out).encode("ascii")
    page = (d.width_mm * PT_PER_MM, d.height_mm * PT_PER_MM)
    title = f"{d.map_id} 1:{d.scale}" if d.map_id else f"plot 1:{d.scale}"
    return pdf_document([(content, page)], {"F1": "Helvetica"}, title=title, compress=compress)


# --------------------------------------------------------------------------- text pages


def text_page_capacity(font_size: float = TEXT_FONT_SIZE) -> tuple[int, int]:
    """Characters per line and lines per A4 page of :func:`text_pages_pdf`.

    >>> text_page_capacity(9.0)
    (94, 68)
    """
    cols = int((A4_PT[0] - _TEXT_LEFT - _TEXT_RIGHT) // (_COURIER_ADVANCE * font_size))
    rows = int((A4_PT[1] - _TEXT_TOP - _TEXT_BOTTOM) // (_LEADING * font_size)) + 1
    return cols, rows


def text_pages(text: str, font_size: float = TEXT_FONT_SIZE) -> list[list[str]]:
    """The lines of each page :func:`text_pages_pdf` makes of ``text`` (wrapped, paginated).

    >>> [len(p) for p in text_pages("a\\n" * 70 + "\\fb\\n")]
    [68, 2, 1]
    """
    cols, rows = text_page_capacity(font_size)
    pages: list[list[str]] = []
    for section in text.split("\f"):
        lines = section.split("\n")
        if lines and lines[-1] == "" and len(lines) > 1:
            lines.pop()  # the final line terminator
        wrapped = []
        for ln in lines:
            ln = ln.rstrip("\r").expandtabs(8)
            while len(ln) > cols:
                wrapped.append(ln[:cols])
                ln = ln[cols:]
            wrapped.append(ln)
        for k in range(0, max(1, len(wrapped)), rows):
            pages.append(wrapped[k : k + rows])
    return pages


def text_pages_pdf(
    text: str, title: str = "", font_size: float = TEXT_FONT_SIZE, compress: bool = True
) -> bytes:
    """Monospaced text on as many A4 pages as it needs, with page numbers.

    Parameters
    ----------
    text : str
        Lines separated by ``\\n``; ``\\f`` (form feed) starts a new page.
    title : str
        Shown in every page's footer and as the document title.
    font_size : float
        Courier size in points; :func:`text_page_capacity` gives the lines
        and columns a page holds at that size.
    compress : bool
        Flate-compress the content streams.
    """
    pages = text_pages(text, font_size)
    n = len(pages)
    leading = _LEADING * font_size
    top = A4_PT[1] - _TEXT_TOP - font_size
    right = A4_PT[0] - _TEXT_RIGHT
    out = []
    for i, lines in enumerate(pages, start=1):
        c = [f"BT /F1 {_num(font_size)} Tf {_num(leading)} TL {_num(_TEXT_LEFT)} {_num(top)} Td\n"]
        for k, ln in enumerate(lines):
            c.append(("T* " if k else "") + pdf_string(ln).decode("ascii") + " Tj\n")
        c.append("ET\n")
        foot = f"page {i} of {n}"
        fx = right - len(foot) * _COURIER_ADVANCE * font_size
        c.append(
            f"BT /F1 {_num(font_size)} Tf {_num(_TEXT_LEFT)} {_num(_FOOTER_Y)} Td "
            + pdf_string(title).decode("ascii")
            + f" Tj ET\nBT /F1 {_num(font_size)} Tf {_num(fx)} {_num(_FOOTER_Y)} Td "
            + pdf_string(foot).decode("ascii")
            + " Tj ET\n"
        )
        out.append(("".join(c).encode("ascii"), A4_PT))
    return pdf_document(out, {"F1": "Courier"}, title=title, compress=compress)
