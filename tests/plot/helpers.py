"""Helpers of the plot tests: expected counts by plain loops, label boxes, picture comparison."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import shapely

from apygis.model.polylines import export_lines
from apygis.model.symbols import default_library
from apygis.plot.fonts import text_size
from apygis.plot.primitives import FilledRects, PaperLine, PaperText
from tests.conftest import SAMPLES

PLOTTER_DEF = SAMPLES / "PLOTTER.DEF"
UNITS = 40  # plotter units per mm
MAP_TEXT_ROLES = ("text", "spot-height", "control")


def count_runs(bitmap) -> int:
    """Strokes for a bitmap by the documented rule, counted cell by cell."""
    painted = {(r, c) for r in range(15) for c in range(15) if bitmap[r][c]}
    n = 0
    in_hrun = set()
    for r in range(15):
        for c in range(15):
            starts = (r, c) in painted and (r, c - 1) not in painted
            if starts and (r, c + 1) in painted:
                n += 1
                k = c
                while (r, k) in painted:
                    in_hrun.add((r, k))
                    k += 1
    rest = painted - in_hrun
    n += sum(1 for (r, c) in rest if (r - 1, c) not in rest)
    return n


def expected_counts(m, layers=None):
    """Lines, symbols, spot heights, texts and symbol strokes of a map, by plain loops."""
    lib = default_library()
    exts = sorted(m.layers) if layers is None else layers
    lines = sum(len(export_lines(m.layers[e])) for e in exts)
    sym = [s for e in exts for s in m.layers[e].symbols]
    texts = sum(len(m.layers[e].texts) for e in exts)
    spots = sum(1 for s in sym if s["code"] == 0)
    strokes = sum(count_runs(lib[int(s["code"])].bitmap) for s in sym)
    return {"lines": lines, "symbols": len(sym), "spots": spots, "texts": texts, "strokes": strokes}


def label_box(t: PaperText) -> shapely.Polygon:
    """The box a horizontal text covers (descenders included), from the font's measure."""
    assert t.angle == 0.0
    w, d = text_size(t.text, t.height)
    return shapely.box(t.x, t.y - d, t.x + w, t.y + t.height)


def collisions(d) -> list[str]:
    """What each placed label (texts, spot heights, control numbers) collides with.

    Computed from the drawing's own primitives with shapely: a label box that crosses a
    map line, covers a symbol other than the one it labels, overlaps another label or
    leaves the neat line.
    """
    lines = [
        shapely.LineString(it.points)
        for it in d.items
        if isinstance(it, PaperLine) and it.role in ("line", "control") and len(it.points) >= 2
    ]
    sym_items = [
        k
        for k, it in enumerate(d.items)
        if isinstance(it, FilledRects) and it.role == "symbol" and len(it.rects)
    ]
    symbols = [
        shapely.box(*d.items[k].rects[:, :2].min(axis=0), *d.items[k].rects[:, 2:].max(axis=0))
        for k in sym_items
    ]
    frame = shapely.box(*d.frame)
    labels = [(d.items[i], own) for i, own, _, _ in d.labels]
    boxes = [label_box(t) for t, _ in labels]
    out = []
    for i, ((t, own), b) in enumerate(zip(labels, boxes, strict=True)):
        hits = []
        if any(b.intersects(g) for g in lines):
            hits.append("line")
        if any(b.intersects(g) for k, g in zip(sym_items, symbols, strict=True) if k != own):
            hits.append("symbol")
        if any(b.intersects(o) for j, o in enumerate(boxes) if j != i):
            hits.append("label")
        if not frame.contains(b):
            hits.append("frame")
        if hits:
            out.append(f"{t.text!r}: {', '.join(hits)}")
    return out


def ink(img: np.ndarray, threshold: int = 200) -> np.ndarray:
    """Where an RGB(A) or grey picture has ink (darker than ``threshold``)."""
    a = np.asarray(img)
    if a.ndim == 3:
        a = a[:, :, :3].min(axis=2)
    return a < threshold


def similar(a: np.ndarray, b: np.ndarray, tolerance_px: int = 3) -> float:
    """How much of the ink of ``a`` lies within ``tolerance_px`` of ink in ``b`` and back (0-1)."""
    import cv2

    assert a.shape == b.shape, (a.shape, b.shape)
    k = np.ones((2 * tolerance_px + 1, 2 * tolerance_px + 1), np.uint8)
    da = cv2.dilate(a.astype(np.uint8), k) > 0
    db = cv2.dilate(b.astype(np.uint8), k) > 0
    ab = (a & db).sum() / max(a.sum(), 1)
    ba = (b & da).sum() / max(b.sum(), 1)
    return float(min(ab, ba))


def run_tool(*args: str) -> subprocess.CompletedProcess:
    """Run a Debian program (the test is marked and skipped when it is missing)."""
    assert shutil.which(args[0]), args[0]
    return subprocess.run(list(args), capture_output=True, check=True, timeout=120)


def read_png(path) -> np.ndarray:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None, path
    if img.ndim == 3 and img.shape[2] == 4:  # transparent background: composite on white
        alpha = img[:, :, 3:4].astype(float) / 255.0
        img = (img[:, :, :3] * alpha + 255 * (1 - alpha)).astype(np.uint8)
    return img
