"""Edits a GIS user made to a file apygis wrote (docs/formats/ogr.md, "Edited files").

:func:`_line_edits` checks ``L_lines`` / ``L_areas`` against ``L_line_points``
(they win: agreeing lines keep their exact topology, changed and new ones are
imported as foreign lines, deleted ones dropped), :func:`_relink` joins kept
branches whose junction went away, and :class:`_EditReport` collects what was
taken into the one WARNING per map layer.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from apygis.errors import FormatError
from apygis.formats._report import warn
from apygis.formats.ogr._common import _field, _int_column, _null_mask, _rec, _Source, _xyz, log
from apygis.formats.ogr.reader import _Foreign, _foreign_layer
from apygis.formats.ogr.schema import _points_text
from apygis.formats.ogr.wkb import _from_wkb
from apygis.model.map import Layer
from apygis.model.records import LINE_DTYPE, NO_REF, REF_FIELDS, next_numbers


@dataclass
class _EditReport:
    """What a read took from a GIS user's edits of one map layer; logged as one message."""

    parts: dict = field(default_factory=dict)  # OGR layer name (or "") -> phrases

    def add(self, source: str, n: int, noun: str, how: str, detail: str = "") -> None:
        if n:
            words = f"{n} {noun if n == 1 else noun + 's'} {how}"
            self.parts.setdefault(source, []).append(f"{words} ({detail})" if detail else words)

    def message(self) -> str:
        return "; ".join(
            ", ".join(ph) + (f" (from {src})" if src else "") for src, ph in self.parts.items()
        )


# agreement of a line feature's vertices with its line points: float64 noise, no more
_AGREE_RTOL, _AGREE_ATOL = 1e-12, 1e-9


def _parse_points(value, k: int, src: _Source) -> tuple[tuple[int, ...], bool]:
    """The point numbers of a ``points`` value and whether it was cut (``,...``)."""
    if not isinstance(value, str):
        value = str(value)
    s = value.strip()
    cut = s.endswith("...")
    if cut:
        s = s[:-3].rstrip().rstrip(",")
    try:
        nums = tuple(int(v) for v in s.split(","))
    except ValueError:
        raise FormatError(
            f"feature {k + 1}: field points is {value!r}, expected point numbers like "
            "'12,13,14' (or NULL for a new line)",
            src.dataset,
            _rec(src.name),
        ) from None
    return nums, cut


def _line_edits(
    lp: np.ndarray, ext: str, feats: dict, opts: dict, acc: _Foreign, report: _EditReport
) -> tuple[np.ndarray, list]:
    """Take the edits of ``L_lines`` / ``L_areas`` against ``L_line_points``.

    ``feats`` maps ``"lines"`` / ``"areas"`` to ``(wkb, columns, source)``.
    A feature whose ``points`` name a line of ``lp`` and whose code and
    vertices agree with it keeps that line's rows; the rows of lines whose
    feature is gone or differs are dropped; changed and new features go to
    ``acc`` (rebuilt by ``Layer.add_polylines``). Returns the rows kept and the branch
    ends whose junction was dropped: ``(num, "fwd" | "back", junction xyz)``.
    """
    from apygis.model.polylines import export_lines

    ls = export_lines(Layer.from_arrays(ext, line_points=lp))
    lengths = np.diff(ls.offsets)
    texts = _points_text(ls.nums, ls.offsets, None)
    has_feature = {"lines": ~ls.closed & (lengths >= 2), "areas": ls.closed.copy()}
    covered = np.zeros(len(ls), dtype=bool)
    kept = np.zeros(len(ls), dtype=bool)
    claimed = np.zeros(len(ls), dtype=bool)
    replaced = np.zeros(len(ls), dtype=bool)
    line_of = np.repeat(np.arange(len(ls)), lengths)
    schema_opts = {**opts, "code_field": "code", "text_field": None}
    later = []  # (kind, feature, nums): features whose points name no line of lp exactly
    for kind in ("lines", "areas"):
        if kind not in feats:  # no such OGR layer: those lines stay as lp has them
            continue
        wkb, columns, src = feats[kind]
        if wkb is None:
            raise FormatError("the layer has no geometry", src.dataset, _rec(src.name))
        idx = np.flatnonzero(has_feature[kind])
        covered[idx] = True
        by_text = {texts[k]: int(k) for k in idx}
        by_first: dict[int, list[int]] = {}
        geoms = np.asarray(_from_wkb(wkb, src.dataset, src.name), dtype=object)
        pcol = _field(columns, "points")
        if pcol is None:
            warn(
                log,
                f"{src.dataset}: layer {src.name} has no field points: its features are taken "
                "as new lines",
                "edited",
            )
        ccol = _field(columns, "code")
        codes = (
            _int_column(ccol, "code", src, nullable=True)
            if ccol is not None
            else np.full(len(geoms), NO_REF)
        )
        if ccol is not None:
            codes = np.where(_null_mask(ccol), NO_REF, codes)
        take = np.zeros(len(geoms), dtype=bool)
        empty = np.array([g is None or g.is_empty for g in geoms], dtype=bool)
        report.add(src.name, int(empty.sum()), "feature", "without geometry skipped")
        n_changed = n_added = 0
        for i in np.flatnonzero(~empty):
            v = None if pcol is None else pcol[i]
            if v is None or (isinstance(v, str) and not v.strip()):
                take[i] = True
                n_added += 1
                continue
            k = by_text.get(v) if isinstance(v, str) else None
            if k is None:
                nums, cut = _parse_points(v, int(i), src)
                if cut:
                    if not by_first:
                        for j in idx:
                            by_first.setdefault(int(ls.nums[ls.offsets[j]]), []).append(int(j))
                    k = next(
                        (
                            j
                            for j in by_first.get(nums[0], [])
                            if tuple(ls.nums[ls.offsets[j] : ls.offsets[j] + len(nums)]) == nums
                        ),
                        None,
                    )
                else:
                    k = by_text.get(",".join(map(str, nums)))
                if k is None:
                    later.append((kind, src, int(i), nums))
                    take[i] = True
                    continue
            if claimed[k]:  # a copy of a feature: a new line
                take[i] = True
                n_added += 1
                continue
            claimed[k] = True
            a, b = ls.offsets[k], ls.offsets[k + 1]
            if codes[i] == ls.codes[k] and _agrees(geoms[i], ls.coords[a:b], kind == "areas"):
                kept[k] = True
            else:
                take[i] = True
                n_changed += 1
        if take.any():
            sub = np.array(wkb, dtype=object)
            sub[~take] = None
            _foreign_layer(sub, columns, src, acc, schema_opts)
        report.add(src.name, n_changed, kind[:-1], "changed (topology rebuilt)")
        report.add(src.name, n_added, kind[:-1], "added")
    # points that name no line of lp exactly: a change where they name line points of a
    # line that is not kept, else new
    own_nums, own_line = ls.nums[ls.own], line_of[ls.own]
    for kind, src, _i, nums in later:
        hit = np.unique(own_line[np.isin(own_nums, nums)])
        hit = hit[covered[hit] & ~kept[hit]]
        replaced[hit] = True
        word = "changed (topology rebuilt)" if len(hit) else "added"
        report.add(src.name, 1, kind[:-1], word)
    drop_line = covered & ~kept
    gone = covered & ~claimed & ~replaced
    for kind in ("lines", "areas"):
        if kind in feats:
            n = int((gone & has_feature[kind]).sum())
            report.add(feats[kind][2].name, n, kind[:-1], "deleted")
    if not drop_line.any():
        return lp, []

    drop = np.zeros(len(lp), dtype=bool)
    drop[ls.rows[ls.own & drop_line[line_of]]] = True
    out = lp[~drop].copy()
    dropped = np.setdiff1d(lp["num"][drop], out["num"])
    rows = np.flatnonzero(drop)
    where = dict(zip(lp["num"][rows].tolist(), rows.tolist(), strict=True))
    relinks = []
    for ref in REF_FIELDS:
        hit = np.isin(out[ref], dropped)
        if ref in ("fwd", "back"):
            for r in np.flatnonzero(hit):
                j = where[int(out[ref][r])]
                if out["num"][r] in (lp["side1"][j], lp["side2"][j]):  # a branch end
                    relinks.append((int(out["num"][r]), ref, _xyz(lp[j : j + 1])[0]))
        out[ref][hit] = NO_REF
    return out, relinks


def _agrees(geom, coords: np.ndarray, closed: bool) -> bool:
    """Whether a feature's geometry has exactly the vertices ``coords`` (a ring: either way)."""
    import shapely

    tid = shapely.get_type_id(geom)
    if closed:
        if tid != 3 or shapely.get_num_interior_rings(geom) != 0:
            return False
        got = shapely.get_coordinates(shapely.get_exterior_ring(geom), include_z=True)
        if len(got) != len(coords) + 1:
            return False
        ring = np.r_[coords, coords[:1]]
        return _close(got, ring) or _close(got[::-1], ring)
    if tid not in (1, 2):
        return False
    got = shapely.get_coordinates(geom, include_z=True)
    return len(got) == len(coords) and _close(got, coords)


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.isclose(a, b, rtol=_AGREE_RTOL, atol=_AGREE_ATOL).all())


def _relink(lay: Layer, relinks: list, report: _EditReport) -> Layer:
    """Join branch ends whose junction was dropped to a line point where it was.

    A line point at the junction's place (within float64 noise) with a free
    side reference takes the end as its branch (a rebuilt line's vertex);
    where there is none, the end grows a new line point there, so the line
    still reaches it as the GIS user saw it.
    """
    from scipy.spatial import cKDTree

    from apygis.model.topology import lookup

    lp = lay.line_points.copy()
    tree = cKDTree(np.column_stack([lp["x"], lp["y"]]))
    extra: list[np.void] = []
    joined = grown = 0
    for num, ref, xyz in relinks:
        r = int(lookup(lp["num"], np.array([num]))[0])
        reach = 2 * (_AGREE_ATOL + _AGREE_RTOL * float(np.abs(xyz[:2]).max()))
        near = np.array(sorted(tree.query_ball_point(xyz[:2], reach)), dtype=np.int64)
        near = near[near != r]
        here = near[
            np.isclose(lp["x"][near], xyz[0], rtol=_AGREE_RTOL, atol=_AGREE_ATOL)
            & np.isclose(lp["y"][near], xyz[1], rtol=_AGREE_RTOL, atol=_AGREE_ATOL)
        ]
        has_me = here[(lp["side1"][here] == num) | (lp["side2"][here] == num)]
        free = here[(lp["side1"][here] == NO_REF) | (lp["side2"][here] == NO_REF)]
        cands = has_me if len(has_me) else free
        if len(cands):
            t = int(cands[0])
            lp[ref][r] = lp["num"][t]
            if not len(has_me):
                side = "side1" if lp["side1"][t] == NO_REF else "side2"
                lp[side][t] = num
            joined += 1
            continue
        q = int(next_numbers(np.r_[lp["num"], [e["num"] for e in extra]].astype(np.int64), 1)[0])
        row = np.zeros(1, LINE_DTYPE)[0]
        row["num"] = q
        row["x"], row["y"], row["z"] = xyz
        row["code"] = lp["code"][r]
        row["fwd"] = num if ref == "back" else NO_REF
        row["back"] = num if ref == "fwd" else NO_REF
        row["side1"] = row["side2"] = NO_REF
        lp[ref][r] = q
        extra.append(row)
        grown += 1
    if extra:
        lp = np.concatenate([lp, np.array(extra, dtype=LINE_DTYPE)])
    report.add("", joined, "branch end", "joined again to its rebuilt junction")
    report.add("", grown, "branch end", "given a new line point where its junction was")
    return Layer.from_arrays(lay.ext, lay.symbols, lp, lay.texts)
