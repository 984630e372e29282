"""Facts about a map for people and scripts: what ``apygis info`` shows.

:func:`summarize` returns a JSON-ready dict; its keys are documented in the
README (``apygis info --json``) and are part of the stable interface.
"""

from __future__ import annotations

import numpy as np

from apygis.model.map import MapFile, crs_string
from apygis.model.records import APY_CAPACITY
from apygis.model.topology import margin_mask

__all__ = ["summarize"]

_COUNT_KEYS = ("symbols", "line_points", "lines", "closed_lines", "texts")


def _extent(ext):
    if ext is None:
        return None
    return dict(zip(("xmin", "ymin", "zmin", "xmax", "ymax", "zmax"), ext, strict=True))


def summarize(m: MapFile) -> dict:
    """Counts, APY capacity used, extents, validation findings and read warnings of a map.

    ``warnings`` counts the validation warnings and the reader's warnings
    (``MapFile.read_warnings``: entities skipped, records renumbered, ...),
    which ``read_warnings`` lists (``kind``, ``what``, ``count``, ``message``).

    >>> m = MapFile("T1", scale=5000)
    >>> _ = m.layer("r").add_line([(0, 0, 0), (10, 0, 0)], code=3)
    >>> s = summarize(m)
    >>> s["layers"]["r"]["lines"], s["layers"]["r"]["capacity_pct"]["line_points"], s["valid"]
    (1, 0.02, True)
    """
    layers = {}
    totals = dict.fromkeys(_COUNT_KEYS, 0)
    extents = []
    n_err = n_warn = 0
    for ext in sorted(m.layers):
        lay = m.layers[ext]
        counts = lay.counts()
        issues = lay.validate()
        n_err += sum(i.severity == "error" for i in issues)
        n_warn += sum(i.severity == "warning" for i in issues)
        e = lay.extent()
        if e is not None:
            extents.append(e)
        layers[ext] = {
            **counts,
            "branches": len(lay.branches()),
            "margin_points": int(np.count_nonzero(margin_mask(lay.line_points))),
            "capacity_pct": {
                k: round(100.0 * counts[k] / cap, 2) for k, cap in APY_CAPACITY.items()
            },
            "extent": _extent(e),
            "issues": [
                {
                    "severity": i.severity,
                    "kind": i.kind,
                    "table": i.table,
                    "num": i.num,
                    "message": i.message,
                }
                for i in issues
            ],
        }
        for k in _COUNT_KEYS:
            totals[k] += counts[k]
    overall = None
    if extents:
        a = np.array(extents)
        overall = _extent((*a[:, :3].min(axis=0).tolist(), *a[:, 3:].max(axis=0).tolist()))
    read = [w.as_dict() if hasattr(w, "as_dict") else dict(w) for w in m.read_warnings]
    return {
        "id": m.id,
        "scale": m.scale,
        "crs": crs_string(m.crs),
        "crs_name": m.crs.name if m.crs is not None else None,
        "notes": m.notes,
        "layers": layers,
        "totals": totals,
        "extent": overall,
        "valid": n_err == 0,
        "errors": n_err,
        "warnings": n_warn + len(read),
        "read_warnings": read,
    }
