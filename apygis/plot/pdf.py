r"""PDF: the plot of a map, and text print-outs on A4 pages, through matplotlib.

matplotlib's PDF backend writes the files (chosen by measuring: see
``benchmarks/bench_plot.py``; it is already a dependency, embeds TrueType
subsets with a ToUnicode map, so any text DejaVu Sans covers (Latin, Greek,
Cyrillic...) is drawn and extracted right, and it renders the pin plot
from the very same figure). Fonts are embedded as Type 42 (TrueType)
subsets; no creation date is written, so the same drawing gives the same
bytes.

Plot (:func:`drawing_pdf`): one page the size of the paper, the drawing as
:mod:`apygis.plot._mpl` builds it (paths in paper millimetres, texts in
DejaVu Sans).

Text (:func:`text_pages_pdf`): A4 portrait pages of 9 pt DejaVu Sans Mono
(monospaced, so columns stay aligned), a footer with a title and "page i of
n". Lines too long for the page wrap; a form feed starts a new page.

Examples
--------
>>> pdf = text_pages_pdf("hello Łódź\n", title="T")
>>> pdf[:5], pdf.count(b"/Type /Page\n") + pdf.count(b"/Type /Page "), b"/FontFile2" in pdf
(b'%PDF-', 1, True)
"""

from __future__ import annotations

import io
from collections.abc import Sequence

from apygis.plot._mpl import RC, drawing_figure
from apygis.plot.fonts import MONO_FAMILY, PT_PER_MM, quiet_missing_glyphs
from apygis.progress import Progress

__all__ = [
    "A4_PT",
    "PT_PER_MM",
    "TEXT_FONT_SIZE",
    "drawing_pdf",
    "text_page_capacity",
    "text_pages",
    "text_pages_pdf",
]

#: A4 portrait in points.
A4_PT = (210.0 * PT_PER_MM, 297.0 * PT_PER_MM)
#: Font size of text print-outs, points.
TEXT_FONT_SIZE = 9.0

# text page layout (points): margins, leading as a multiple of the font size
_TEXT_LEFT, _TEXT_RIGHT, _TEXT_TOP, _TEXT_BOTTOM = 48.0, 36.0, 48.0, 60.0
_FOOTER_Y = 30.0
_LEADING = 1.2
_MONO_ADVANCE = 1233 / 2048  # every DejaVu Sans Mono glyph advances 1233/2048 em


def _metadata(title: str) -> dict:
    return {
        "Title": title,
        "Creator": "apygis",
        "Producer": "apygis (matplotlib)",
        "CreationDate": None,
    }


def drawing_pdf(d, progress: Progress | None = None) -> bytes:
    """The drawing as a one-page PDF the size of its paper.

    ``progress(done, total)`` follows the rendering (:mod:`apygis.progress`).
    """
    import matplotlib

    title = f"{d.map_id} 1:{d.scale}" if d.map_id else f"plot 1:{d.scale}"
    with matplotlib.rc_context(RC), quiet_missing_glyphs():
        fig = drawing_figure(d, progress)
        buf = io.BytesIO()
        fig.savefig(buf, format="pdf", metadata=_metadata(title))
    return buf.getvalue()


# --------------------------------------------------------------------------- text pages


def text_page_capacity(font_size: float = TEXT_FONT_SIZE) -> tuple[int, int]:
    """Characters per line and lines per A4 page of :func:`text_pages_pdf`.

    >>> text_page_capacity(9.0)
    (94, 68)
    """
    cols = int((A4_PT[0] - _TEXT_LEFT - _TEXT_RIGHT) // (_MONO_ADVANCE * font_size))
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
    text: str,
    title: str = "",
    font_size: float = TEXT_FONT_SIZE,
    progress: Progress | None = None,
) -> bytes:
    """Monospaced text on as many A4 pages as it needs, with page numbers.

    Parameters
    ----------
    text : str
        Lines separated by ``\\n``; ``\\f`` (form feed) starts a new page.
    title : str
        Shown in every page's footer and as the document title.
    font_size : float
        DejaVu Sans Mono size in points; :func:`text_page_capacity` gives the
        lines and columns a page holds at that size.
    progress : Progress, optional
        ``progress(done, total)`` after each page (:mod:`apygis.progress`).
    """
    import matplotlib
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure

    pages = text_pages(text, font_size)
    n = len(pages)
    w_in, h_in = A4_PT[0] / 72.0, A4_PT[1] / 72.0
    buf = io.BytesIO()
    with (
        matplotlib.rc_context(RC),
        quiet_missing_glyphs(),
        PdfPages(buf, metadata=_metadata(title)) as pdf,
    ):
        for i, lines in enumerate(pages, start=1):
            fig = Figure(figsize=(w_in, h_in), dpi=72)
            ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
            ax.set_xlim(0.0, A4_PT[0])
            ax.set_ylim(0.0, A4_PT[1])
            ax.set_axis_off()
            _page_text(ax, lines, font_size)
            foot = f"page {i} of {n}"
            right = A4_PT[0] - _TEXT_RIGHT
            for x, s, ha in ((_TEXT_LEFT, title, "left"), (right, foot, "right")):
                ax.text(
                    x,
                    _FOOTER_Y,
                    s,
                    fontsize=font_size,
                    fontfamily=MONO_FAMILY,
                    ha=ha,
                    va="baseline",
                    parse_math=False,
                )
            pdf.savefig(fig)
            if progress is not None:
                progress(i, n)
    return buf.getvalue()


def _page_text(ax, lines: Sequence[str], font_size: float) -> None:
    """The page's lines, each at its own baseline (so that no line spacing rule intervenes)."""
    top = A4_PT[1] - _TEXT_TOP - font_size
    leading = _LEADING * font_size
    for k, ln in enumerate(lines):
        if ln.strip():
            ax.text(
                _TEXT_LEFT,
                top - k * leading,
                ln,
                fontsize=font_size,
                fontfamily=MONO_FAMILY,
                ha="left",
                va="baseline",
                parse_math=False,
            )
