"""The block display: a map of the block plan as PNG or PDF.

Drawn with :class:`matplotlib.figure.Figure` and the Agg/PDF canvases directly
(no :mod:`matplotlib.pyplot`, so no global figure state), into memory, then
written atomically (:func:`apygis.fileio.atomic_write`).

What is drawn (ground coordinates, metres, equal aspect; see
:mod:`apygis.aerotri.plan`):

* each footprint as an outline, one colour per strip, cross strips dashed;
  the image number at the footprint's centre (in blocks of more than 300
  images only at the strip ends);
* the projection centres (dots) joined by the strip line, with an arrow in
  the flight direction at the strip's last image and the strip number at its
  first;
* control points as triangles with their names: full control filled dark
  red, planimetric filled blue, height filled green, check points hollow;
* once tie points exist: a line between the two centres of every model
  coloured by its tie point count (red below 6 = fewer than one per von
  Gruber region, orange below 18 = fewer than three per region, green
  otherwise) and labelled with it (with more than 60 models only those
  below 18 points); the gap regions hatched red; the tie points as small
  grey dots;
* a legend, a scale bar, axis labels from the CRS (easting/northing).
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Literal

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.backends.backend_pdf import FigureCanvasPdf
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.patches import Polygon as MplPolygon
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar  # type: ignore[import-untyped]

from apygis.aerotri.plan import BlockPlan
from apygis.errors import FormatError
from apygis.fileio import atomic_write

__all__ = ["block_display", "count_class", "nice_length"]

#: (upper bound exclusive, colour, legend text) of the model line classes.
COUNT_CLASSES = (
    (6, "#d62728", "< 6 tie points"),
    (18, "#ff7f0e", "6-17 tie points"),
    (math.inf, "#2ca02c", ">= 18 tie points"),
)
_CONTROL_STYLE = {
    "full": ("#8b0000", True, "full control"),
    "planimetric": ("#1f4fbf", True, "planimetric control"),
    "height": ("#1a7f1a", True, "height control"),
    "check": ("#000000", False, "check point"),
}


def count_class(n: int) -> int:
    """Index into :data:`COUNT_CLASSES` of a model with ``n`` tie points."""
    return next(k for k, (hi, _, _) in enumerate(COUNT_CLASSES) if n < hi)


def nice_length(span: float) -> float:
    """The largest of 1, 2, 5 times a power of ten not above ``span`` (> 0)."""
    e = 10 ** math.floor(math.log10(span))
    return max(m * e for m in (1, 2, 5) if m * e <= span)


def _axis_labels(crs) -> tuple[str, str]:
    if crs is None:
        return "Easting X [m]", "Northing Y [m]"
    try:
        import pyproj

        axes = pyproj.CRS.from_user_input(crs).axis_info
    except Exception:
        return "Easting X [m]", "Northing Y [m]"
    east = next((a for a in axes if a.direction.lower() == "east"), None)
    north = next((a for a in axes if a.direction.lower() == "north"), None)

    def label(a, default):
        if a is None:
            return default
        unit = a.unit_name or "metre"
        unit = "m" if unit in ("metre", "meter") else unit
        return f"{a.name} {a.abbrev} [{unit}]" if a.abbrev else f"{a.name} [{unit}]"

    return label(east, "Easting X [m]"), label(north, "Northing Y [m]")


def block_display(
    plan: BlockPlan,
    path,
    *,
    control=None,
    points_per_pair: dict[tuple[int, int], int] | None = None,
    gaps: dict[tuple[int, int], list] | None = None,
    tie_points_xy=None,
    title: str | None = None,
    crs=None,
    dpi: int = 150,
) -> Path:
    """Draw the block plan to ``path`` (``.png`` or ``.pdf``) and return the path.

    Parameters
    ----------
    plan : BlockPlan
    path : str or os.PathLike
        The output; its suffix chooses the format.
    control : list of (name, X, Y, kind), optional
        Control points; kind ``full | planimetric | height | check``.
    points_per_pair : dict[(a, b), int], optional
        Tie points per model: draws the model lines.
    gaps : dict[(a, b), list of shapely Polygon], optional
        Gap regions (e.g. the gap regions of :func:`~apygis.aerotri.plan.gap_report`).
    tie_points_xy : array_like (n, 2), optional
        Ground positions of tie points.
    title : str, optional
    crs : optional
        Anything :func:`pyproj.CRS.from_user_input` takes: axis labels.
    dpi : int
        PNG resolution.
    """
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("png", "pdf"):
        raise FormatError(f"block display: the file must end in .png or .pdf, got {path.name!r}")

    # extent and figure size (the block's aspect, at most 12 x 10 inches of axes)
    allxy = [np.asarray(f.exterior.coords)[:, :2] for f in plan.footprints.values()]
    if control:
        allxy.append(np.array([(float(c[1]), float(c[2])) for c in control]))
    pts = np.vstack(allxy)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = np.maximum(hi - lo, 1.0)
    pad = 0.04 * float(span.max())
    lo, hi = lo - pad, hi + pad
    span = hi - lo
    aspect = float(span[1] / span[0])
    w_in = 10.0 if aspect <= 1 else max(4.0, 10.0 / aspect)
    h_in = w_in * aspect
    if h_in > 10.0:
        w_in, h_in = w_in * 10.0 / h_in, 10.0
    # fixed margins (inches): the axes get exactly the block's aspect
    left, right, bottom, top = 1.25, 2.9, 0.75, 0.5
    fw, fh = w_in + left + right, h_in + bottom + top
    fig = Figure(figsize=(fw, fh))
    fig.subplots_adjust(left / fw, bottom / fh, 1 - right / fw, 1 - top / fh)
    (FigureCanvasPdf if fmt == "pdf" else FigureCanvasAgg)(fig)
    ax = fig.add_subplot()
    ax.set_aspect("equal")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    xl, yl = _axis_labels(crs)
    ax.set_xlabel(xl)
    ax.set_ylabel(yl)
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.tick_params(labelsize=8)
    ax.grid(True, color="0.9", linewidth=0.5, zorder=0)
    ax.set_title(
        title
        or f"Block: {len(plan.images)} images, {len(plan.strips)} strips, {len(plan.pairs)} pairs"
    )

    n_img = len(plan.images)
    label_size = float(np.clip(90 / max(n_img, 1) ** 0.5, 5.0, 9.0))
    colours = [
        "#1f77b4", "#9467bd", "#17becf", "#8c564b", "#e377c2",
        "#7f7f7f", "#bcbd22", "#393b79", "#637939", "#843c39",
    ]  # fmt: skip
    handles: list = []
    dense = n_img > 300
    fp_lw = 0.4 if dense else 0.8
    many_strips = len(plan.strips) > 12  # legend: one entry per kind instead of per strip
    seen_kinds: set[str] = set()
    for k, (s, st) in enumerate(sorted(plan.strips.items())):
        col = colours[k % len(colours)]
        ls: Literal["--", "-"] = "--" if st.kind == "cross" else "-"
        polys = [np.asarray(plan.footprints[i].exterior.coords)[:, :2] for i in st.images]
        ax.add_collection(
            PolyCollection(
                polys, facecolors="none", edgecolors=col, linestyles=ls, linewidths=fp_lw, zorder=2
            )
        )
        xy = np.array([(plan.images[i].X, plan.images[i].Y) for i in st.images])
        ax.plot(xy[:, 0], xy[:, 1], color=col, linewidth=1.2, linestyle=ls, zorder=3)
        ax.plot(xy[:, 0], xy[:, 1], "o", color=col, markersize=3, zorder=4)
        # flight direction arrow from the last centre along the heading
        h = math.radians(st.direction_deg)
        foot = plan.footprints[st.images[-1]]
        length = 0.25 * math.sqrt(foot.area)
        x1, y1 = xy[-1]
        ax.annotate(
            "",
            xy=(x1 + length * math.sin(h), y1 + length * math.cos(h)),
            xytext=(x1, y1),
            arrowprops={"arrowstyle": "-|>", "color": col, "lw": 1.5, "mutation_scale": 14},
            zorder=5,
        )
        x0, y0 = xy[0]
        ax.annotate(
            f"S{s}",
            (x0 - length * math.sin(h), y0 - length * math.cos(h)),
            ha="center",
            va="center",
            fontsize=label_size + 1,
            fontweight="bold",
            color=col,
            zorder=6,
        )
        if not many_strips or st.kind not in seen_kinds:
            seen_kinds.add(st.kind)
            text = f"{st.kind} strips" if many_strips else f"strip {s} ({st.kind})"
            handles.append(Line2D([], [], color=col, linestyle=ls, label=text, linewidth=1.2))
    # image numbers: all of them, or in dense blocks those at the strip ends
    if dense:
        labelled = sorted({i for st in plan.strips.values() for i in (st.images[0], st.images[-1])})
    else:
        labelled = sorted(plan.images)
    for i in labelled:
        im = plan.images[i]
        ax.annotate(
            str(i),
            (im.X, im.Y),
            xytext=(3, 3),
            textcoords="offset points",
            fontsize=label_size,
            color="0.15",
            zorder=6,
        )

    if tie_points_xy is not None:
        tp = np.asarray(tie_points_xy, dtype=float).reshape(-1, 2)
        if len(tp):
            ax.plot(tp[:, 0], tp[:, 1], ".", color="0.45", markersize=1.5, zorder=2.5)
            handles.append(
                Line2D([], [], marker=".", color="0.45", linestyle="", label="tie points")
            )

    if gaps:
        first = True
        for regions in gaps.values():
            for r in regions:
                if r is None or r.is_empty:
                    continue
                for g in getattr(r, "geoms", [r]):
                    ax.add_patch(
                        MplPolygon(
                            np.asarray(g.exterior.coords)[:, :2],
                            closed=True,
                            facecolor=(1, 0, 0, 0.06),
                            edgecolor="red",
                            hatch="////",
                            linewidth=0.8,
                            zorder=3.5,
                        )
                    )
                    first = False
        if not first:
            handles.append(
                Patch(facecolor=(1, 0, 0, 0.12), edgecolor="red", hatch="////", label="gap")
            )

    if points_per_pair is not None:
        segs: list[list[list[np.ndarray]]] = [[] for _ in COUNT_CLASSES]
        for (a, b), n in points_per_pair.items():
            if a not in plan.images or b not in plan.images:
                continue
            pa = np.array([plan.images[a].X, plan.images[a].Y])
            pb = np.array([plan.images[b].X, plan.images[b].Y])
            k = count_class(int(n))
            segs[k].append([pa, pb])
            if k < len(COUNT_CLASSES) - 1 or len(points_per_pair) <= 60:
                m = (pa + pb) / 2
                ax.annotate(
                    str(int(n)),
                    tuple(m),
                    ha="center",
                    va="center",
                    fontsize=label_size if k < len(COUNT_CLASSES) - 1 else label_size - 1.5,
                    fontweight="bold" if k < len(COUNT_CLASSES) - 1 else "normal",
                    color=COUNT_CLASSES[k][1],
                    bbox={
                        "boxstyle": "round,pad=0.15",
                        "fc": "white",
                        "ec": COUNT_CLASSES[k][1],
                        "lw": 0.6,
                        "alpha": 0.9,
                    },
                    zorder=7,
                )
        for k, (_, col, text) in enumerate(COUNT_CLASSES):
            if segs[k]:
                ax.add_collection(
                    LineCollection(
                        segs[k],
                        colors=col,
                        linewidths=2.0 if len(points_per_pair) <= 200 else 0.7,
                        alpha=0.75,
                        zorder=4.5 + 0.1 * (len(COUNT_CLASSES) - k),  # problems on top
                    )
                )
                handles.append(Line2D([], [], color=col, linewidth=2.0, label=f"model: {text}"))

    if control:
        for kind, (col, filled, text) in _CONTROL_STYLE.items():
            sel = [c for c in control if str(c[3]) == kind]
            if not sel:
                continue
            xy = np.array([(float(c[1]), float(c[2])) for c in sel])
            ax.plot(
                xy[:, 0],
                xy[:, 1],
                "^",
                markersize=9,
                markerfacecolor=col if filled else "white",
                markeredgecolor=col,
                markeredgewidth=1.5,
                linestyle="",
                zorder=8,
                label=text,
            )
            handles.append(
                Line2D(
                    [], [], marker="^", linestyle="", markersize=8,
                    markerfacecolor=col if filled else "white", markeredgecolor=col,
                    markeredgewidth=1.5, label=text,
                )
            )  # fmt: skip
            for c in sel:
                ax.annotate(
                    str(c[0]),
                    (float(c[1]), float(c[2])),
                    xytext=(6, -8),
                    textcoords="offset points",
                    fontsize=label_size,
                    color=col,
                    fontweight="bold",
                    zorder=9,
                )

    handles.append(
        Line2D([], [], marker="o", color="0.3", linestyle="-", markersize=3, label="centres")
    )
    ax.legend(
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(1.02, 1.0),
        fontsize=8,
        frameon=False,
        borderaxespad=0.0,
    )
    bar = nice_length(float(span[0]) / 5)
    unit = f"{bar / 1000:g} km" if bar >= 1000 else f"{bar:g} m"
    ax.add_artist(
        AnchoredSizeBar(
            ax.transData,
            bar,
            unit,
            "lower right",
            pad=0.5,
            sep=4,
            frameon=True,
            size_vertical=float(span[1]) / 250,
            fontproperties={"size": 8},
        )
    )

    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    return atomic_write(path, buf.getvalue(), parents=True)
