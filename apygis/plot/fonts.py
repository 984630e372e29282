"""The plot's one font: DejaVu Sans, measured, checked for coverage and outlined.

Every output draws texts in DejaVu Sans (DejaVu Sans Mono for the text
print-out): the PDF and the raster pin plot through matplotlib, which ships
the font and embeds a subset of it in the PDF; the SVG names it (with
fallbacks) and sets each text's length; HP-GL draws labels in the plotter's
own stick font, scaled to the same length, or as outlines of the same
glyphs where the plotter's character set cannot hold them
(:mod:`~apygis.plot.hpgl`). So the layout, which places labels by their
size, measures them here once, and every output agrees with it.

Units: texts are sized by their **cap height** in millimetres (the height
of a capital H); the font size (the em) is ``cap height / CAP_HEIGHT``.
Widths are the ink extent of the text (first to last painted pixel, as
matplotlib lays text out), descents the depth below the baseline.

Examples
--------
>>> round(text_size("Zürich", 2.5)[0], 2)
10.94
>>> missing_glyphs("Łódź Ελλάδα Plzeň"), missing_glyphs("中")
('', '中')
"""

from __future__ import annotations

import contextlib
import functools
import warnings

import numpy as np

__all__ = [
    "CAP_HEIGHT",
    "FONT_FAMILY",
    "MONO_FAMILY",
    "PT_PER_MM",
    "font_path",
    "missing_glyphs",
    "quiet_missing_glyphs",
    "text_advance",
    "text_outlines",
    "text_size",
]

#: The font of every plot text.
FONT_FAMILY = "DejaVu Sans"
#: The monospaced font of the text print-out.
MONO_FAMILY = "DejaVu Sans Mono"
#: Cap height of DejaVu Sans as a fraction of its em (1493 / 2048 font units).
CAP_HEIGHT = 1493 / 2048
#: Points (1/72 inch) per millimetre.
PT_PER_MM = 72.0 / 25.4

_EM_PX = 1000  # the size texts are measured at, in pixels per em (no hinting)


@contextlib.contextmanager
def quiet_missing_glyphs():
    """Silence matplotlib's per-glyph warnings: the plot counts and reports such texts itself."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"Glyph \d+ .*missing from", category=UserWarning)
        yield


@functools.lru_cache(maxsize=2)
def font_path(mono: bool = False) -> str:
    """The TrueType file of :data:`FONT_FAMILY` (or :data:`MONO_FAMILY`), as matplotlib ships it."""
    from matplotlib import font_manager

    family = MONO_FAMILY if mono else FONT_FAMILY
    return str(font_manager.findfont(font_manager.FontProperties(family=family)))


@functools.lru_cache(maxsize=2)
def _font(mono: bool = False):
    from matplotlib.ft2font import FT2Font

    return FT2Font(font_path(mono))


@functools.lru_cache(maxsize=65536)
def _unit_size(text: str) -> tuple[float, float]:
    """Ink width and descent of ``text`` at an em of 1."""
    from matplotlib.ft2font import LoadFlags

    font = _font()
    font.set_size(_EM_PX, 72)
    with quiet_missing_glyphs():
        font.set_text(text, 0.0, flags=LoadFlags.NO_HINTING)
    w, _ = font.get_width_height()
    d = font.get_descent()
    return w / 64.0 / _EM_PX, d / 64.0 / _EM_PX


def text_size(text: str, cap_height_mm: float) -> tuple[float, float]:
    """``(width, descent)`` in mm of ``text`` set at cap height ``cap_height_mm``.

    >>> w, d = text_size("Hy", 2.5)
    >>> round(w, 3), round(d, 3)
    (4.608, 0.713)
    """
    if not text:
        return 0.0, 0.0
    w, d = _unit_size(text)
    em = cap_height_mm / CAP_HEIGHT
    return w * em, d * em


@functools.lru_cache(maxsize=4096)
def _glyph_advance(idx: int) -> float:
    """The advance of glyph ``idx`` at an em of 1."""
    from matplotlib.ft2font import LoadFlags

    font = _font()
    font.set_size(_EM_PX, 72)
    with quiet_missing_glyphs():
        glyph = font.load_glyph(idx, flags=LoadFlags.NO_HINTING)
    return glyph.linearHoriAdvance / 65536.0 / _EM_PX


@functools.lru_cache(maxsize=65536)
def _unit_advance(text: str) -> float:
    from matplotlib.ft2font import Kerning

    font = _font()
    font.set_size(_EM_PX, 72)
    total = 0.0
    prev = None
    for ch in text:
        idx = font.get_char_index(ord(ch))
        if prev is not None:
            total += font.get_kerning(prev, idx, Kerning.UNFITTED) / 64.0
        total += _glyph_advance(idx) * _EM_PX  # a missing character advances as the box
        prev = idx
    return total / _EM_PX


def text_advance(text: str, cap_height_mm: float) -> float:
    """The advance width of ``text`` in mm (glyph advances and kerning: SVG's ``textLength``).

    >>> round(text_advance("AV", 2.5) - text_advance("A", 2.5) - text_advance("V", 2.5), 3)
    -0.219
    """
    return _unit_advance(text) * cap_height_mm / CAP_HEIGHT if text else 0.0


@functools.lru_cache(maxsize=4096)
def missing_glyphs(text: str) -> str:
    """The characters of ``text`` DejaVu Sans cannot draw (each once, in order).

    Blanks are never missing. A text with missing glyphs would show empty
    boxes; the plot counts such texts and says so.
    """
    font = _font()
    out = []
    for ch in text:
        if ch.isspace() or ch in out:
            continue
        if font.get_char_index(ord(ch)) == 0:
            out.append(ch)
    return "".join(out)


_OUTLINE_EM = 30.0  # glyphs are outlined at this em (units) and scaled: fine flattening


@functools.lru_cache(maxsize=2048)
def _glyph_rings(ch: str) -> tuple[np.ndarray, ...]:
    """The closed outlines of one character at an em of 1, its origin at (0, 0)."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    if ch.isspace():
        return ()
    with quiet_missing_glyphs():
        path = TextPath((0.0, 0.0), ch, size=_OUTLINE_EM, prop=FontProperties(family=FONT_FAMILY))
    if not len(np.asarray(path.vertices)):
        return ()
    rings = []
    for poly in path.to_polygons(closed_only=True):
        ring = np.asarray(poly, dtype=float)
        if len(ring) >= 3:
            rings.append(ring / _OUTLINE_EM)
    return tuple(rings)


@functools.lru_cache(maxsize=65536)
def _pen_positions(text: str) -> tuple[float, ...]:
    """Where each character of ``text`` starts, at an em of 1 (advances and kerning)."""
    from matplotlib.ft2font import Kerning

    font = _font()
    font.set_size(_EM_PX, 72)
    out = []
    x = 0.0
    prev = None
    for ch in text:
        idx = font.get_char_index(ord(ch))
        if prev is not None:
            x += font.get_kerning(prev, idx, Kerning.UNFITTED) / 64.0 / _EM_PX
        out.append(x)
        x += _glyph_advance(idx)
        prev = idx
    return tuple(out)


def text_outlines(
    text: str, x: float, y: float, cap_height_mm: float, angle_deg: float = 0.0
) -> list[np.ndarray]:
    """The glyph outlines of ``text`` as closed polylines (n, 2) in mm.

    The baseline starts at ``(x, y)`` and runs at ``angle_deg``
    counter-clockwise from the x axis; each character is its DejaVu Sans
    outline (curves flattened to under 0.01 mm at the usual label sizes)
    at its advance and kerning. Used where a pen plotter's character set
    cannot hold a text, and for the white halo of a label.

    >>> rings = text_outlines("O", 0.0, 0.0, 2.5)
    >>> len(rings), bool(np.allclose(rings[0][0], rings[0][-1]))
    (2, True)
    """
    em = cap_height_mm / CAP_HEIGHT
    a = np.radians(angle_deg)
    rot = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]) * em
    out = []
    for ch, x0 in zip(text, _pen_positions(text), strict=True):
        for ring in _glyph_rings(ch):
            out.append(np.add(ring, (x0, 0.0)) @ rot + (x, y))
    return out
