"""The bundle adjustment's report as text (the seed's Table 3), CSV and pictures.

:func:`adjust_text` prints a report of :func:`apygis.aerotri.adjust.adjust_block`
(its ``to_dict()``, as stored in the block): the block's figures in the layout
of the seed's Table 3 (images, control points, tie points by multiplicity,
sigma0 in micrometres and pixels, image rms x/y, object rms x/y/z at the check
points), then the exterior orientations with their standard deviations, the
control and check point residuals, and the rejected observations.

:func:`export_points` and :func:`export_exterior` write the adjusted points and
orientations as CSV; :func:`adjust_display` draws the block with the points'
precision ellipses, :func:`residual_display` every image's residual vectors.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np

from apygis.aerotri.block import Block, BlockError
from apygis.fileio import atomic_write

__all__ = [
    "adjust_display",
    "adjust_text",
    "export_exterior",
    "export_points",
    "last_report",
    "residual_display",
]


def last_report(block: Block) -> dict:
    """The report of the block's last adjustment (a dict; refused when there is none)."""
    row = block.conn.execute(
        "SELECT report FROM adjustments WHERE report IS NOT NULL ORDER BY id DESC LIMIT 1"
    ).fetchone()
    if row is None:
        raise BlockError(f"{block.path}: the block is not adjusted yet (run 'apygis at adjust')")
    return json.loads(row[0])


def _f(v, fmt: str) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def adjust_text(r: dict, *, max_rows: int = 40) -> str:
    """The report as text (module docstring); long tables are cut at ``max_rows`` rows."""
    out = io.StringIO()
    w = out.write
    w(f"Bundle block adjustment {r['adjustment']}\n\n")
    ctrl = r["control"]
    rows = [
        ("No. of images", f"{r['images']}"),
        ("No. of cameras", f"{r['cameras']}"),
        (
            "No. of control points",
            f"{ctrl['full']} full, {ctrl['planimetric']} planimetric, {ctrl['height']} height",
        ),
        ("No. of check points", f"{ctrl['check']}"),
    ]
    mult = {int(k): v for k, v in r["multiplicity"].items()}
    for k in sorted(mult, reverse=True):
        if k >= 2:
            rows.append((f"  {k}-fold points", f"{mult[k]}"))
    rows += [
        ("Observations", f"{r['observations']} (rejected {r['rejected']})"),
        ("sigma0", f"{_f(r['sigma0'], '.3f')} (of the a priori precisions)"),
        *(
            (f"  variance factor {k}", _f(v, ".3f"))
            for k, v in sorted(r.get("variance_factors", {}).items())
        ),
        ("sigma0 (um)", _f(r["sigma0_um"], ".2f")),
        ("sigma0 (px)", _f(r["sigma0_px"], ".3f")),
        (
            "Image rms x/y (um)",
            f"{_f(r['image_rms_um'][0], '.2f')} {_f(r['image_rms_um'][1], '.2f')}",
        ),
    ]
    if r.get("object_rms_m"):
        o, p = r["object_rms_m"], r.get("object_rms_predicted_m") or [None] * 3
        rows.append(("Object rms x/y/z (m)", " ".join(_f(v, ".3f") for v in o)))
        rows.append(("  expected (covariance and given)", " ".join(_f(v, ".3f") for v in p)))
    rows += [
        ("Redundancy", f"{r['redundancy']}"),
        ("Iterations / seconds", f"{r['iterations']} / {r['seconds']:.1f}"),
    ]
    if r.get("gps_used"):
        rows.append(("Projection centres", "observed (GPS)"))
    width = max(len(a) for a, _ in rows) + 2
    for a, b in rows:
        w(f"{a:<{width}}{b}\n")
    for note in r.get("notes", []):
        w(f"note: {note}\n")
    if r.get("calibration"):
        w("\nSelf-calibration (value, standard deviation, largest correlation with an "
          "orientation element)\n")  # fmt: skip
        for c in r["calibration"]:
            w(f"  camera {c['camera']} {c['parameter']:>3} {c['value']: .6g} "
              f"+- {_f(c['std'], '.3g')}  "
              f"r_eo {_f(c['max_corr_orientation'], '.2f')}\n")  # fmt: skip
    if r.get("subblocks"):
        w("\nSubblocks\n")
        for s in r["subblocks"]:
            if s.get("error"):
                w(f"  {s['subblock']}: {s['images']} images, not adjusted: {s['error']}\n")
            else:
                w(f"  {s['subblock']}: {s['images']} images, {s['points']} points, sigma0 "
                  f"{_f(s['sigma0'], '.3f')}, {s['rejected']} rejected\n")  # fmt: skip
    w("\nExterior orientation (m, gon = grad; standard deviations in m and mgon)\n")
    w(f"{'image':>8} {'X':>13} {'Y':>13} {'Z':>10} {'omega':>9} {'phi':>9} {'kappa':>9}"
      f" {'sX':>6} {'sY':>6} {'sZ':>6} {'so':>6} {'sp':>6} {'sk':>6}\n")  # fmt: skip
    g = 200.0 / math.pi
    for e in r["exterior"]:
        w(f"{e['image']:>8} {e['X']:13.3f} {e['Y']:13.3f} {e['Z']:10.3f} "
          f"{e['omega_rad'] * g:9.4f} {e['phi_rad'] * g:9.4f} {(e['kappa_rad'] * g) % 400:9.4f} "
          f"{_f(e['sX'], '6.3f')} {_f(e['sY'], '6.3f')} {_f(e['sZ'], '6.3f')} "
          f"{_f(_mgon(e['somega_rad']), '6.2f')} {_f(_mgon(e['sphi_rad']), '6.2f')} "
          f"{_f(_mgon(e['skappa_rad']), '6.2f')}\n")  # fmt: skip
    if r["control_residuals"]:
        w("\nControl points: residuals (adjusted - given, m)\n")
        w(f"{'point':>15} {'kind':>12} {'vX':>8} {'vY':>8} {'vZ':>8} {'rays':>5}\n")
        for c in r["control_residuals"]:
            flag = "  rejected" if c.get("rejected") else ""
            w(f"{c['point']:>15} {c['kind']:>12} {_f(c['vX'], '8.3f')} {_f(c['vY'], '8.3f')} "
              f"{_f(c['vZ'], '8.3f')} {c['rays']:5d}{flag}\n")  # fmt: skip
    if r["check_residuals"]:
        w("\nCheck points: adjusted - given (m), and the standard deviations\n")
        w(f"{'point':>15} {'dX':>8} {'dY':>8} {'dZ':>8} {'sX':>7} {'sY':>7} {'sZ':>7}"
          f" {'rays':>5}\n")  # fmt: skip
        for c in r["check_residuals"]:
            w(f"{c['point']:>15} {c['dX']:8.3f} {c['dY']:8.3f} {c['dZ']:8.3f} "
              f"{_f(c['sX'], '7.3f')} {_f(c['sY'], '7.3f')} {_f(c['sZ'], '7.3f')} "
              f"{c['rays']:5d}\n")  # fmt: skip
    rej = r["rejections"]
    if rej:
        w(f"\nRejected observations: {len(rej)} (threshold of the test: see docs/aerotri.md)\n")
        w(f"{'point':>15} {'image':>8} {'vx px':>8} {'vy px':>8} {'w':>7} {'round':>5}  reason\n")
        for x in rej[:max_rows]:
            if x["image"] is None:
                v = x["residual_m"]
                w(f"{x['point']:>15} {'control':>8} {v[0]:8.3f} {v[1]:8.3f} {x['w']:7.1f} "
                  f"{x['round']:5d}  {x['reason']} (dZ {v[2]:.3f} m)\n")  # fmt: skip
            else:
                v = x["residual_px"]
                w(f"{x['point']:>15} {x['image']:>8} {v[0]:8.2f} {v[1]:8.2f} {x['w']:7.1f} "
                  f"{x['round']:5d}  {x['reason']}\n")  # fmt: skip
        if len(rej) > max_rows:
            w(f"... and {len(rej) - max_rows} more (--json lists them all)\n")
    return out.getvalue()


def _mgon(rad):
    return None if rad is None else rad * 200000.0 / math.pi


def export_points(block: Block, path) -> int:
    """Adjusted points as CSV ``point,kind,X,Y,Z,sX,sY,sZ,rays``; returns the rows."""
    rows = block.conn.execute(
        "SELECT p.name, p.kind, a.X, a.Y, a.Z, a.sX, a.sY, a.sZ, a.rays FROM adjusted_points a "
        "JOIN points p ON p.id = a.point ORDER BY p.kind != 'tie', p.name"
    ).fetchall()
    if not rows:
        raise BlockError(f"{block.path}: no adjusted points (run 'apygis at adjust')")
    buf = io.StringIO()
    wr = csv.writer(buf, lineterminator="\n")
    wr.writerow(["point", "kind", "X", "Y", "Z", "sX", "sY", "sZ", "rays"])
    for name, kind, X, Y, Z, sx, sy, sz, n in rows:
        wr.writerow([name, kind, f"{X:.4f}", f"{Y:.4f}", f"{Z:.4f}", _f(sx, ".4f"),
                     _f(sy, ".4f"), _f(sz, ".4f"), n])  # fmt: skip
    atomic_write(Path(path), buf.getvalue(), parents=True)
    return len(rows)


def export_exterior(block: Block, path) -> int:
    """Exterior orientations as CSV ``image,X,Y,Z,omega_rad,phi_rad,kappa_rad`` and their
    standard deviations; returns the rows."""
    rows = block.conn.execute("SELECT * FROM exterior ORDER BY image").fetchall()
    if not rows:
        raise BlockError(f"{block.path}: no exterior orientations (run 'apygis at adjust')")
    buf = io.StringIO()
    wr = csv.writer(buf, lineterminator="\n")
    wr.writerow(["image", "X", "Y", "Z", "omega_rad", "phi_rad", "kappa_rad", "sX", "sY", "sZ",
                 "somega_rad", "sphi_rad", "skappa_rad"])  # fmt: skip
    for r in rows:
        image, _, *v = r
        wr.writerow([image, *(f"{x:.4f}" for x in v[:3]), *(f"{x:.9f}" for x in v[3:6]),
                     *(_f(x, ".4f") for x in v[6:9]), *(_f(x, ".9f") for x in v[9:])])  # fmt: skip
    atomic_write(Path(path), buf.getvalue(), parents=True)
    return len(rows)


# --- pictures ------------------------------------------------------------------------------


def _save(fig, path: Path, dpi: int) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.backends.backend_pdf import FigureCanvasPdf

    from apygis.errors import FormatError

    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("png", "pdf"):
        raise FormatError(f"{path}: pictures are written as .png or .pdf")
    buf = io.BytesIO()
    canvas = FigureCanvasAgg(fig) if fmt == "png" else FigureCanvasPdf(fig)
    canvas.print_figure(buf, format=fmt, dpi=dpi)
    atomic_write(path, buf.getvalue(), parents=True)
    return path


def _footprints(block: Block, ext: dict[int, tuple], tz: float) -> dict[int, np.ndarray]:
    """Ground outlines of the images (their corners' rays on the plane ``Z = tz``)."""
    from apygis.aerotri.camera import PixelTransform
    from apygis.orient.rotation import rotation_matrix

    cams = block.cameras()
    interior = block.interior()
    out = {}
    for im in block.images():
        if im.image not in ext or im.image not in interior:
            continue
        X, Y, Z, om, ph, ka = ext[im.image]
        T = PixelTransform.from_list(interior[im.image]["transform"])
        cam = cams[im.camera]
        w, h = im.width, im.height
        mm = T.to_mm([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]])
        R = rotation_matrix(om, ph, ka)
        d = (R @ np.c_[mm[:, 0] - cam.x0_mm, mm[:, 1] - cam.y0_mm,
                       np.full(4, -cam.focal_mm)].T).T  # fmt: skip
        t = (tz - Z) / d[:, 2]
        out[im.image] = np.c_[X + t * d[:, 0], Y + t * d[:, 1]]
    return out


def adjust_display(block: Block, path, *, dpi: int = 150) -> Path:
    """The adjusted block: footprints, projection centres, control and check points with
    their error ellipses (1 sigma, magnified; the factor is in the legend), tie points."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Ellipse, Polygon

    from apygis.aerotri.project import terrain_height

    path = Path(path)
    r = last_report(block)
    ext = {e["image"]: (e["X"], e["Y"], e["Z"], e["omega_rad"], e["phi_rad"], e["kappa_rad"])
           for e in r["exterior"]}  # fmt: skip
    try:
        tz = terrain_height(block)
    except BlockError:
        tz = float(np.mean([e[2] for e in ext.values()])) - 1000.0
    fps = _footprints(block, ext, tz)
    pts = block.conn.execute(
        "SELECT p.name, p.kind, a.X, a.Y, a.Z, a.sX, a.sY, a.sZ, a.rXY FROM adjusted_points a "
        "JOIN points p ON p.id = a.point"
    ).fetchall()
    fig = Figure(figsize=(11, 9))
    ax = fig.add_axes((0.12, 0.08, 0.84, 0.84))
    strips = {im.image: im.strip for im in block.images()}
    colours = ["#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf"]
    for n, fp in fps.items():
        col = colours[(strips.get(n) or 0) % len(colours)]
        ax.add_patch(Polygon(fp, closed=True, fill=False, ec=col, lw=0.8, alpha=0.8))
        X, Y = ext[n][0], ext[n][1]
        ax.plot([X], [Y], "o", color=col, ms=3)
        ax.annotate(str(n), (X, Y), fontsize=7, xytext=(3, 3), textcoords="offset points")
    allxy = np.vstack(list(fps.values())) if fps else np.zeros((1, 2))
    span = float(np.ptp(allxy, axis=0).max()) or 1.0
    tie = np.array([(p[2], p[3]) for p in pts if p[1] == "tie"]).reshape(-1, 2)
    if len(tie):
        step = max(1, len(tie) // 20000)
        ax.plot(tie[::step, 0], tie[::step, 1], ".", color="0.6", ms=1, label="tie points")
    named = [p for p in pts if p[1] != "tie"]
    sig = [max(p[5] or 0, p[6] or 0) for p in named]
    mag = _nice(0.03 * span / max(sig)) if named and max(sig) > 0 else 1.0
    styles = {
        "full": ("#8b0000", "^"),
        "planimetric": ("#1f4fbf", "^"),
        "height": ("#1a7f1a", "^"),
        "check": ("#000000", "v"),
        "new": ("#6a3d9a", "s"),
    }
    for name, kind, X, Y, _Z, sx, sy, _sz, rxy in named:
        col, mk = styles.get(kind, ("k", "o"))
        ax.plot([X], [Y], mk, color=col, ms=6, mfc=col if kind != "check" else "none")
        ax.annotate(name, (X, Y), fontsize=7, xytext=(4, -9), textcoords="offset points")
        cov = _xy_cov(sx, sy, rxy)
        if cov is not None:
            ev, V = np.linalg.eigh(cov)
            ang = math.degrees(math.atan2(V[1, 1], V[0, 1]))
            ax.add_patch(Ellipse((X, Y), 2 * mag * math.sqrt(ev[1]), 2 * mag * math.sqrt(ev[0]),
                                 angle=ang, fill=False, ec=col, lw=1.0))  # fmt: skip
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], marker=m, color=c, ls="", mfc=c if k != "check" else "none",
                      label=k if k != "full" else "full control") for k, (c, m) in styles.items()
               if any(p[1] == k for p in named)]  # fmt: skip
    handles.append(Line2D([], [], color="k", lw=1, label=f"error ellipses (1 sigma) x {mag:g}"))
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.set_title(
        f"{block.path.name}: adjustment {r['adjustment']}, sigma0 {r['sigma0_px']:.3f} px, "
        f"{r['images']} images, {r['observations']} observations"
    )
    return _save(fig, path, dpi)


def _nice(x: float) -> float:
    """The largest of 1, 2, 5 times a power of ten not above ``x``."""
    if not x > 0 or not math.isfinite(x):
        return 1.0
    e = math.floor(math.log10(x))
    for m in (5, 2, 1):
        if m * 10**e <= x:
            return float(m * 10**e)
    return float(10**e)


def _xy_cov(sx, sy, rxy) -> np.ndarray | None:
    if sx is None or sy is None:
        return None
    c = (rxy or 0.0) * sx * sy
    return np.array([[sx * sx, c], [c, sy * sy]])


def residual_display(block: Block, path, *, dpi: int = 120, columns: int = 6) -> Path:
    """Every image's residual vectors (pixels, magnified), one panel per image, rejected
    observations in red; under each panel the image's rms."""
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    path = Path(path)
    r = last_report(block)
    rows = block.conn.execute(
        "SELECT r.image, o.x_px, o.y_px, r.vx_px, r.vy_px, r.rejected FROM residuals r "
        "JOIN observations o ON o.point = r.point AND o.image = r.image"
    ).fetchall()
    by: dict[int, list] = {}
    for row in rows:
        by.setdefault(row[0], []).append(row[1:])
    sizes = {im.image: (im.width, im.height) for im in block.images()}
    images = sorted(by)
    n = len(images)
    cols = min(columns, n) or 1
    nrow = -(-n // cols)
    fig = Figure(figsize=(2.6 * cols, 2.8 * nrow + 0.6))
    allv = np.array([np.hypot(v[2], v[3]) for k in images for v in by[k] if not v[4]])
    ref = float(np.percentile(allv, 95)) if len(allv) else 1.0
    size = max(max(sizes.get(k, (1, 1))) for k in images) if images else 1
    mag = _nice(0.04 * size / max(ref, 1e-9))
    for k, img in enumerate(images):
        ax = fig.add_subplot(nrow, cols, k + 1)
        a = np.array(by[img], float)
        w, h = sizes.get(img, (a[:, 0].max(), a[:, 1].max()))
        good = a[:, 4] == 0
        for sel, col in ((good, "#1f77b4"), (~good, "#d62728")):
            if sel.any():
                seg = np.stack([a[sel, :2], a[sel, :2] + mag * a[sel, 2:4]], axis=1)
                ax.add_collection(LineCollection(list(seg), colors=col, lw=0.5))
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        rms = np.sqrt(np.mean(a[good, 2:4] ** 2, axis=0)) if good.any() else (np.nan, np.nan)
        ax.set_title(f"{img}", fontsize=8)
        ax.set_xlabel(f"rms {rms[0]:.3f} / {rms[1]:.3f} px", fontsize=7)
    fig.suptitle(
        f"{block.path.name}: image residuals of adjustment {r['adjustment']}, vectors "
        f"magnified {mag:g} times (red: rejected observations)",
        fontsize=10,
    )
    return _save(fig, path, dpi)
