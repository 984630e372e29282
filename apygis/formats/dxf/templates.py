"""The DXF writer's templates: symbol blocks from the symbol bitmaps, and the text of
every entity it writes (the fast reader parses by them too)."""

from __future__ import annotations

import numpy as np

from apygis.formats.dxf._common import _GRID, APPID

# =========================================================================== symbols


def block_rects(bitmap) -> np.ndarray:
    """The painted cells of a 15x15 bitmap as few rectangles, in cell units.

    Returns ``(k, 4)`` floats ``x0, y0, x1, y1`` with the grid centred on
    the origin (the centre of cell row 7, column 7), x to the right and y up
    (row 0 is the top). Runs of painted cells in a row make one rectangle;
    identical runs in consecutive rows are merged.

    >>> bm = np.zeros((15, 15), bool)
    >>> bm[7, 5:10] = True
    >>> bm[5:10, 7] = True
    >>> block_rects(bm).tolist()
    [[-0.5, 0.5, 0.5, 2.5], [-2.5, -0.5, 2.5, 0.5], [-0.5, -2.5, 0.5, -0.5]]
    """
    bm = np.asarray(bitmap, dtype=bool)
    runs: list[list[int]] = []  # [row0, row1, col0, col1], col1 exclusive
    open_runs: dict[tuple[int, int], list[int]] = {}
    for r in range(bm.shape[0]):
        row = np.r_[False, bm[r], False].astype(np.int8)
        edges = np.flatnonzero(np.diff(row))
        here = {}
        for c0, c1 in zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True):
            run = open_runs.get((c0, c1))
            if run is not None and run[1] == r - 1:
                run[1] = r
            else:
                run = [r, r, c0, c1]
                runs.append(run)
            here[(c0, c1)] = run
        open_runs = here
    half = _GRID / 2.0
    out = [(c0 - half, half - r1 - 1, c1 - half, half - r0) for r0, r1, c0, c1 in runs]
    return np.array(out, dtype=float).reshape(-1, 4)


def _fallback_bitmap() -> np.ndarray:
    """An open square of 5x5 cells, drawn for a code the library leaves free."""
    bm = np.zeros((_GRID, _GRID), dtype=bool)
    bm[5, 5:10] = bm[9, 5:10] = True
    bm[5:10, 5] = bm[5:10, 9] = True
    return bm


# =========================================================================== entities

_HEAD = "  0\n%s\n  5\n%X\n330\n%X\n100\nAcDbEntity\n  8\n%s\n"
_INSERT = (
    _HEAD
    + "100\nAcDbBlockReference\n 66\n1\n  2\n%s\n 10\n%r\n 20\n%r\n 30\n%r\n"
    + "".join(
        _HEAD.replace("%s", "ATTRIB", 1)
        + "100\nAcDbText\n 10\n%r\n 20\n%r\n 30\n%r\n 40\n%r\n  1\n%s\n"
        + f"100\nAcDbAttribute\n  2\n{tag}\n 70\n1\n"
        for tag in ("NUM", "CODE", "Z")
    )
    + _HEAD.replace("%s", "SEQEND", 1)
).replace("%s", "INSERT", 1)
_TEXT = (
    _HEAD.replace("%s", "TEXT", 1)
    + "100\nAcDbText\n 10\n%r\n 20\n%r\n 30\n%r\n 40\n%r\n  1\n%s\n100\nAcDbText\n"
    + f"1001\n{APPID}\n1000\n%s\n"
)
_POLYLINE = (
    _HEAD.replace("%s", "POLYLINE", 1)
    + "100\nAcDb3dPolyline\n 66\n1\n 10\n0.0\n 20\n0.0\n 30\n0.0\n 70\n%d\n"
)
_VERTEX = (
    _HEAD.replace("%s", "VERTEX", 1)
    + "100\nAcDbVertex\n100\nAcDb3dPolylineVertex\n 10\n%r\n 20\n%r\n 30\n%r\n 70\n32\n"
)
_VERTEX_OWN = _VERTEX + f"1001\n{APPID}\n1000\n%d %d %d %d %d %d %d\n"
_SEQEND = _HEAD.replace("%s", "SEQEND", 1)
