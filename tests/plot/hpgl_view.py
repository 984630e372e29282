"""A small HP-GL interpreter for the tests: parse, check, and render to a picture.

It understands what a plotter would do with the instructions apygis writes
(and refuses anything else, so that a new instruction must be added here
on purpose): ``IN``, ``PA``, ``DT``, ``SP``, ``PU``, ``PD``, ``SI``, ``DI``,
``LB`` of HP-GL/1, and ``WU``, ``NP``, ``CR``, ``PC``, ``PW``, ``LA`` of
HP-GL/2. :func:`interpret` returns the pen strokes and labels in plotter
units; :func:`render` draws them with OpenCV (labels in OpenCV's Hershey
stick font, at the ``SI`` size and ``DI`` direction, as a plotter's stick
font would), so the tests and a person can look at a plot file.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

HPGL1 = {"IN", "PA", "DT", "SP", "PU", "PD", "SI", "DI", "LB"}
HPGL2_ONLY = {"WU", "NP", "CR", "PC", "PW", "LA"}
UNITS_PER_MM = 40


@dataclass
class Label:
    pen: int
    x: int
    y: int
    text: str
    width_cm: float
    height_cm: float
    direction: tuple[float, float]


@dataclass
class Plot:
    instructions: list[tuple[str, str]]
    strokes: list[tuple[int, np.ndarray]] = field(default_factory=list)  # pen, (n, 2) units
    labels: list[Label] = field(default_factory=list)
    widths_mm: dict[int, float] = field(default_factory=dict)
    colours: dict[int, tuple[int, int, int]] = field(default_factory=dict)


def parse(data: bytes) -> list[tuple[str, str]]:
    """(mnemonic, parameters) of every instruction; a label's text as its parameter."""
    text = data.decode("ascii")
    out = []
    i = 0
    term = "\x03"
    while i < len(text):
        if text[i] in " \n\r;":
            i += 1
            continue
        op = text[i : i + 2]
        assert re.fullmatch("[A-Z]{2}", op), f"bad instruction at {i}: {text[i : i + 20]!r}"
        if op == "LB":
            end = text.index(term, i)
            out.append((op, text[i + 2 : end]))
            i = end + 1
        elif op == "DT":
            term = text[i + 2]
            out.append((op, term))
            i += 3
        else:
            end = text.index(";", i)
            out.append((op, text[i + 2 : end]))
            i = end + 1
    return out


def interpret(data: bytes, version: int = 1) -> Plot:
    """Run the instructions as a plotter would; ``version`` 1 refuses HP-GL/2 instructions."""
    instr = parse(data)
    allowed = HPGL1 | (HPGL2_ONLY if version == 2 else set())
    plot = Plot(instr)
    pen, pos = 0, (0, 0)
    si = (0.19, 0.27)  # HP-GL's default character size, cm
    di = (1.0, 0.0)
    for op, args in instr:
        assert op in allowed, f"{op} is not HP-GL/{version}"
        vals = [v for v in args.split(",") if v != ""] if op != "LB" else []
        if op == "SP":
            pen = int(args or 0)
        elif op == "PU":
            if vals:
                nums = [int(v) for v in vals]
                assert len(nums) % 2 == 0
                pos = (nums[-2], nums[-1])
        elif op == "PD":
            nums = [int(v) for v in vals]
            assert nums, args
            assert len(nums) % 2 == 0, args
            pts = [pos, *zip(nums[::2], nums[1::2], strict=True)]
            assert pen > 0, "drawing with no pen selected"
            plot.strokes.append((pen, np.array(pts, dtype=np.int64)))
            pos = pts[-1]
        elif op == "SI":
            w, h = (float(v) for v in vals)
            si = (w, h)
        elif op == "DI":
            run, rise = (float(v) for v in vals)
            n = math.hypot(run, rise)
            di = (run / n, rise / n)
        elif op == "LB":
            assert pen > 0
            assert all(32 <= ord(c) < 127 for c in args), f"non-ASCII label {args!r}"
            plot.labels.append(Label(pen, pos[0], pos[1], args, si[0], si[1], di))
        elif op == "PW":
            w, p = vals
            plot.widths_mm[int(p)] = float(w)
        elif op == "PC":
            p, r, g, b = (int(v) for v in vals)
            plot.colours[p] = (r, g, b)
    return plot


def render(
    plot: Plot, width_mm: float, height_mm: float, dpi: float = 100, pen_widths=None
) -> np.ndarray:
    """The plot drawn on white paper: an (rows, cols, 3) uint8 BGR image, row 0 at the top.

    Strokes are drawn antialiased in their pen's width (``pen_widths`` mm,
    the file's ``PW``, or 0.3 mm) and colour (the file's ``PC``, else black).
    """
    import cv2

    k = dpi / 25.4 / UNITS_PER_MM  # pixels per plotter unit
    rows = math.floor(height_mm / 25.4 * dpi + 1e-6)  # whole pixels, as the pin plot
    cols = math.floor(width_mm / 25.4 * dpi + 1e-6)
    img = np.full((rows, cols, 3), 255, dtype=np.uint8)
    widths = {**(pen_widths or {}), **plot.widths_mm}

    def px(pts) -> np.ndarray:
        pts = np.asarray(pts, dtype=float)
        return np.column_stack([pts[:, 0] * k, rows - pts[:, 1] * k])

    shift = 4
    for pen, pts in plot.strokes:
        colour = plot.colours.get(pen, (0, 0, 0))[::-1]
        thick = max(1, round(widths.get(pen, 0.3) / 25.4 * dpi))
        p = np.rint(px(pts) * (1 << shift)).astype(np.int32)
        cv2.polylines(img, [p], False, colour, thick, cv2.LINE_AA, shift)
    for lab in plot.labels:
        colour = plot.colours.get(lab.pen, (0, 0, 0))[::-1]
        cap_px = lab.height_cm * 10 / 25.4 * dpi
        scale = cap_px / 21.0  # Hershey simplex: cap height 21 units at scale 1
        thick = max(1, round(cap_px / 10))
        (tw, th), base = cv2.getTextSize(lab.text, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
        tile = np.full((th + base + 2 * thick + 2, tw + 2 * thick + 2, 3), 255, np.uint8)
        cv2.putText(
            tile,
            lab.text,
            (thick, th + thick),
            cv2.FONT_HERSHEY_SIMPLEX,
            scale,
            colour,
            thick,
            cv2.LINE_AA,
        )
        x, y = px([(lab.x, lab.y)])[0]
        angle = math.degrees(math.atan2(lab.direction[1], lab.direction[0]))
        # the tile's baseline start (thick, th + thick) goes to (x, y), turned by angle
        m = cv2.getRotationMatrix2D((float(thick), float(th + thick)), angle, 1.0)
        m[0, 2] += x - thick
        m[1, 2] += y - (th + thick)
        warped = cv2.warpAffine(
            tile,
            m,
            (cols, rows),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=(255, 255, 255),
        )
        img = np.minimum(img, warped)
    return img
