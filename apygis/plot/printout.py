"""The APY print-out of a map file, as plain text.

APY's Print & Plot printed "a symbol legend, symbols sorted according to
their attribute code, line points with forward, backward and side point
references, and texts". :func:`printout_text` lays that out per layer, in
fixed columns that line printers and terminals show alike; coordinates in
metres with centimetres, as the native formats store them.
"""

from __future__ import annotations

import numpy as np

from apygis.model.map import MapFile, crs_string
from apygis.model.records import NO_REF

__all__ = ["printout_text"]


def _ref(v: int) -> str:
    return "    -" if v == NO_REF else f"{v:5d}"


def printout_text(m: MapFile, library=None) -> str:
    """The print-out of ``m``; symbol names from ``library`` (a SymbolLibrary) if given.

    >>> m = MapFile("T1", scale=5000)
    >>> _ = m.layer("e").add_symbol(10.0, 20.0, 401.25, code=0)
    >>> print(printout_text(m).splitlines()[0])
    APY PRINT-OUT   map T1   scale 1:5000   CRS none
    """

    def name(code: int) -> str:
        if library is None:
            return ""
        try:
            return library.name(int(code))
        except Exception:  # an unknown code must not stop the print-out
            return "?"

    crs = crs_string(m.crs) if m.crs is not None else "none"
    scale = f"1:{m.scale}" if m.scale else "unknown"
    out = [f"APY PRINT-OUT   map {m.id}   scale {scale}   CRS {crs}"]
    if m.notes:
        out += [f"  {line}" for line in m.notes.split("\n")]
    for ext in sorted(m.layers):
        lay = m.layers[ext]
        sym, lp, tx = lay.symbols, lay.line_points, lay.texts
        out += ["", "=" * 78, f"LAYER {m.id}.{ext}", "=" * 78]
        out += ["", "SYMBOL LEGEND", f"  {'code':>4}  {'name':<24} {'count':>6}"]
        codes, counts = np.unique(sym["code"], return_counts=True)
        if len(codes) == 0:
            out.append("  (no symbols)")
        for c, k in zip(codes.tolist(), counts.tolist(), strict=True):
            out.append(f"    {c:02d}  {name(c):<24} {k:6d}")
        out += [
            "",
            f"SYMBOLS ({len(sym)}, sorted by code)",
            f"  {'num':>5} {'code':>4}  {'name':<24} {'X':>12} {'Y':>12} {'Z':>9}",
        ]
        for r in sym[np.lexsort((sym["num"], sym["code"]))]:
            out.append(
                f"  {r['num']:5d}   {r['code']:02d}  {name(r['code']):<24} "
                f"{r['x']:12.2f} {r['y']:12.2f} {r['z']:9.2f}"
            )
        out += [
            "",
            f"LINE POINTS ({len(lp)})",
            f"  {'num':>5} {'code':>4} {'X':>12} {'Y':>12} {'Z':>9} "
            f"{'fwd':>5} {'back':>5} {'side1':>5} {'side2':>5}",
        ]
        for r in lp[np.argsort(lp["num"], kind="stable")]:
            out.append(
                f"  {r['num']:5d}   {r['code']:02d} {r['x']:12.2f} {r['y']:12.2f} {r['z']:9.2f} "
                f"{_ref(r['fwd'])} {_ref(r['back'])} {_ref(r['side1'])} {_ref(r['side2'])}"
            )
        out += ["", f"TEXTS ({len(tx)})", f"  {'num':>5} {'X':>12} {'Y':>12} {'Z':>9}  text"]
        for r in tx[np.argsort(tx["num"], kind="stable")]:
            out.append(f"  {r['num']:5d} {r['x']:12.2f} {r['y']:12.2f} {r['z']:9.2f}  {r['text']}")
    return "\n".join(out) + "\n"
