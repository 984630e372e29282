"""``apygis at``: automatic aerotriangulation of a photo block (PHODIS AT)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from apygis.cli._common import progress_bar, run_guarded

_block_new = click.Path(dir_okay=False, path_type=Path)
_block = click.Path(dir_okay=False, path_type=Path)
_in_file = click.Path(exists=True, dir_okay=False, path_type=Path)
_picture = click.Path(dir_okay=False, path_type=Path)


def _open(path: Path):
    from apygis.aerotri.block import Block

    return Block.open(path)


def _bar(label: str):
    return progress_bar(1000, label)


def _advance(bar):
    def cb(done: int, total: int) -> None:
        bar.update(round(1000 * done / max(total, 1)) - bar.pos)

    return cb


def _check_picture(path: Path | None) -> None:
    if path is not None and path.suffix.lower() not in (".png", ".pdf"):
        raise click.BadParameter(f"{path}: the block display is written as .png or .pdf")


@click.group("at")
def at() -> None:
    """Automatic aerotriangulation: block preparation, interior orientation, tie points."""


@at.command("init")
@click.argument("block", type=_block_new)
@click.option(
    "--camera",
    required=True,
    metavar="CAMERA",
    help="Camera protocol (TOML), or 'exif' for a digital camera described by the images' EXIF.",
)
@click.option(
    "--images",
    required=True,
    type=click.Path(exists=True, path_type=Path),
    help="Image list (CSV: image,strip,file,X,Y,Z,heading_deg), or a folder of images "
    "with EXIF GPS.",
)
@click.option("--control", type=_in_file, default=None, help="Control points (CSV).")
@click.option("--crs", default=None, help="Block CRS (default: the UTM zone of EXIF positions).")
@click.option("--terrain-height", type=float, default=None, help="Mean terrain height, metres.")
@click.option(
    "--tie-names",
    default="1000000:1",
    show_default=True,
    metavar="START[:INTERVAL]",
    help="Automatic tie point names: the first number and the step (never reissued).",
)
@click.option("--overwrite", is_flag=True, help="Replace an existing block.")
@run_guarded
def at_init(block, camera, images, control, crs, terrain_height, tie_names, overwrite):
    """Create BLOCK (an SQLite file) from a camera, an image list and control points."""
    from apygis.aerotri.project import init_block

    if camera != "exif" and not Path(camera).is_file():
        raise click.BadParameter(
            f"{camera}: no such camera file (or 'exif')", param_hint="--camera"
        )
    start, _, step = tie_names.partition(":")
    if not start.isdigit() or not (step or "1").isdigit() or int(step or "1") < 1:
        raise click.BadParameter(
            f"{tie_names!r}: expected START[:INTERVAL], whole numbers", param_hint="--tie-names"
        )
    with _bar(f"reading {images}") as bar:
        r = init_block(
            block,
            camera=camera,
            images=images,
            control=control,
            crs=crs,
            overwrite=overwrite,
            terrain_z=terrain_height,
            tie_names=(int(start), int(step or "1")),
            progress=_advance(bar),
        )
    click.echo(
        f"{r.block}: {r.images} images in {r.strips} strips, camera {r.camera}, "
        f"{r.control} control points, CRS {r.crs or '(none)'}"
    )
    for note in r.notes:
        click.echo(f"note: {note}")


@at.command("plan")
@click.argument("block", type=_block)
@click.option("--terrain-height", type=float, default=None, help="Mean terrain height, metres.")
@click.option(
    "--min-overlap",
    type=click.FloatRange(0.01, 0.95),
    default=0.1,
    show_default=True,
    help="Least overlap of a pair to match (fraction of the smaller footprint).",
)
@click.option(
    "--subblock-strips",
    type=click.IntRange(2, 1000),
    default=None,
    help="Subblocks of this many strips, overlapping by one strip.",
)
@click.option(
    "--display", type=_picture, default=None, help="Block display picture (.png or .pdf)."
)
@click.option("--json", "as_json", is_flag=True, help="Print the plan as JSON.")
@run_guarded
def at_plan(block, terrain_height, min_overlap, subblock_strips, display, as_json):
    """Footprints, overlaps, strips, pairs to match and subblocks of BLOCK."""
    from apygis.aerotri.plan import plan_text
    from apygis.aerotri.project import plan
    from apygis.aerotri.report import block_display_for, points_per_model

    _check_picture(display)
    with _open(block) as b:
        p = plan(
            b, terrain_z=terrain_height, min_overlap=min_overlap, subblock_strips=subblock_strips
        )
        counts = points_per_model(b)
        if display is not None:
            block_display_for(b, p, display)
    if as_json:
        click.echo(json.dumps(_plan_json(p), indent=1))
    else:
        click.echo(plan_text(p, points_per_pair=counts or None), nl=False)
    if display is not None:
        click.echo(f"block display: {display}", err=as_json)


def _plan_json(p) -> dict:
    return {
        "images": len(p.images),
        "main_direction_deg": p.main_direction_deg,
        "strips": {
            str(s.number): {"images": s.images, "direction_deg": s.direction_deg, "kind": s.kind}
            for s in p.strips.values()
        },
        "pairs": [
            {"a": q.a, "b": q.b, "kind": q.kind, "overlap": round(q.overlap, 4)} for q in p.pairs
        ],
        "subblocks": p.subblocks,
        "forward_overlap": {str(k): v for k, v in p.overlaps.forward.items()},
        "side_overlap": {f"{a}-{b}": v for (a, b), v in p.overlaps.side.items()},
        "connected": p.connected,
    }


@at.command("match")
@click.argument("block", type=_block)
@click.option(
    "--scheduler",
    default=None,
    metavar="ADDRESS",
    help="Dask scheduler address (tcp://host:port); 'sync' runs in this process. "
    "Default: local worker processes.",
)
@click.option(
    "--workers",
    type=click.IntRange(1, 1024),
    default=None,
    help="Local worker processes (default: the machine's cores).",
)
@click.option(
    "--points-per-image",
    type=click.IntRange(100, 100000),
    default=5000,
    show_default=True,
    help="Förstner points per image for block formation.",
)
@click.option(
    "--corr-min",
    type=click.FloatRange(0.3, 0.99),
    default=0.8,
    show_default=True,
    help="Least correlation of a least-squares match.",
)
@click.option("--terrain-height", type=float, default=None, help="Mean terrain height, metres.")
@click.option(
    "--interior-model",
    type=click.Choice(["affine", "similarity", "projective"]),
    default="affine",
    show_default=True,
    help="Pixel -> photo transform fitted to the fiducials of scanned film.",
)
@click.option(
    "--subblock",
    type=click.IntRange(1, 100000),
    default=None,
    help="Prepare and match only this subblock ('at plan --subblock-strips N'); the "
    "tie points join all subblocks matched so far through their common strips.",
)
@click.option(
    "--display", type=_picture, default=None, help="Block display picture (.png or .pdf)."
)
@run_guarded
def at_match(block, scheduler, workers, points_per_image, corr_min, terrain_height,
             interior_model, subblock, display):  # fmt: skip
    """Fully automatic tie points: block formation, then least-squares point tracking.

    Results are committed to BLOCK as tasks finish: run again after an
    interruption to continue where it stopped.
    """
    from apygis.aerotri.match import MatchOptions, match_block
    from apygis.aerotri.project import block_plan
    from apygis.aerotri.report import block_display_for

    _check_picture(display)
    opt = MatchOptions(
        points_per_image=points_per_image,
        corr_min=corr_min,
        scheduler=scheduler,
        workers=workers,
        interior_model=interior_model,
        subblock=subblock,
    )
    with _open(block) as b:
        with _bar(f"matching {block}") as bar:
            r = match_block(b, opt, progress=_advance(bar), terrain_z=terrain_height)
        if display is not None:
            block_display_for(b, block_plan(b, terrain_z=terrain_height), display)
    click.echo(
        f"{block}: {r.points} tie points, {r.observations} observations in {r.images} images "
        f"(block formation at pyramid level {r.level})"
    )
    click.echo("multiplicity: " + ", ".join(f"{k}-fold {v}" for k, v in r.multiplicity.items()))
    if r.epipolar_rms_px is not None:
        click.echo(
            f"relative orientations: measurements {r.epipolar_rms_px:.3f} px RMS from their "
            "epipolar lines (median over the image pairs)"
        )
    for a, b_, why in r.pairs_failed:
        click.echo(f"pair {a}-{b_} not matched: {why}")
    skipped = {k: v for k, v in r.rejected.items() if v}
    if skipped:
        click.echo("rejected: " + ", ".join(f"{k} {v}" for k, v in skipped.items()))
    for note in r.notes:
        click.echo(f"note: {note}")
    if r.flagged_interior:
        click.echo(f"interior orientation flagged: images {r.flagged_interior}")
    if r.gaps:
        click.echo(f"gaps: {len(r.gaps)} models with von Gruber regions below 3 points "
                   "('apygis at info' lists them)")  # fmt: skip
    if display is not None:
        click.echo(f"block display: {display}")


def _sigmas(value: str | None):
    if value is None:
        return None
    parts = value.split(",")
    try:
        xy, z = (float(parts[0]), float(parts[1])) if len(parts) == 2 else (None, None)
    except ValueError:
        xy = z = None
    if xy is None or z is None or not (xy > 0 and z > 0):
        raise click.BadParameter(
            f"{value!r}: expected XY,Z (metres, positive)", param_hint="--gps-sigma"
        )
    return (xy, z)


@at.command("adjust")
@click.argument("block", type=_block)
@click.option(
    "--calibrate",
    default="",
    metavar="auto|NAMES",
    help="Self-calibration: 'auto' (the parameters the block determines) or a comma list of "
    "c,x0,y0,k1,k2,k3,p1,p2,b1,b2. Default: the camera is fixed.",
)
@click.option(
    "--gps-sigma",
    default=None,
    metavar="XY,Z",
    help="Use the approximate projection centres as observations with these sigmas (m). "
    "Default: only when the control gives no datum, with sigmas by their source.",
)
@click.option("--no-gps", is_flag=True, help="Never use the projection centres as observations.")
@click.option(
    "--threshold",
    type=click.FloatRange(2.5, 20.0),
    default=4.0,
    show_default=True,
    help="Data snooping: an observation whose test exceeds this (normal deviate) is rejected.",
)
@click.option("--no-robust", is_flag=True, help="One least-squares adjustment, no rejections.")
@click.option(
    "--restart", is_flag=True, help="Start from the block plan, not from the last adjustment."
)
@click.option(
    "--subblocks",
    is_flag=True,
    help="Adjust the plan's subblocks as separate tasks first, then join them.",
)
@click.option("--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler (--subblocks).")
@click.option("--workers", type=click.IntRange(1, 1024), default=None, help="Local processes.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("--report", type=_picture, default=None, metavar="FILE.txt", help="Write the "
              "report (text) to FILE.txt.")  # fmt: skip
@click.option("--display", type=_picture, default=None, help="The adjusted block with error "
              "ellipses (.png or .pdf).")  # fmt: skip
@click.option("--residuals", type=_picture, default=None, help="Every image's residual vectors "
              "(.png or .pdf).")  # fmt: skip
@run_guarded
def at_adjust(block, calibrate, gps_sigma, no_gps, threshold, no_robust, restart, subblocks,
              scheduler, workers, as_json, report, display, residuals):  # fmt: skip
    """Bundle block adjustment of BLOCK: tie, control and check points, robust.

    Prints the seed's Table 3 (images, control, points by multiplicity, sigma0 in um
    and px, image and object rms) with every image's exterior orientation and the
    rejected observations. Results are stored in BLOCK ('at export').
    """
    from apygis.aerotri.adjust import AdjustOptions, adjust_block
    from apygis.aerotri.adjust_report import adjust_display, adjust_text, residual_display
    from apygis.fileio import atomic_write

    for pic in (display, residuals):
        _check_picture(pic)
    cal: tuple[str, ...] | str = ()
    if calibrate == "auto":
        cal = "auto"
    elif calibrate:
        cal = tuple(x.strip() for x in calibrate.split(",") if x.strip())
    gps = None if no_gps else (_sigmas(gps_sigma) or "auto")
    opt = AdjustOptions(
        robust=not no_robust, threshold=threshold, calibrate=cal, gps=gps, restart=restart,
        subblocks=subblocks, scheduler=scheduler, workers=workers,
    )  # fmt: skip
    with _open(block) as b:
        with _bar(f"adjusting {block}") as bar:
            r = adjust_block(b, opt, progress=_advance(bar))
        d = r.to_dict()
        text = adjust_text(d)
        if report is not None:
            atomic_write(report, adjust_text(d, max_rows=10**9), parents=True)
        if display is not None:
            adjust_display(b, display)
        if residuals is not None:
            residual_display(b, residuals)
    click.echo(json.dumps(d, indent=1) if as_json else text, nl=as_json)
    for path, what in ((report, "report"), (display, "block display"), (residuals, "residuals")):
        if path is not None:
            click.echo(f"{what}: {path}", err=as_json)


@at.command("gcp")
@click.argument("block", type=_block)
@click.option(
    "--measure",
    "measure_file",
    type=_in_file,
    default=None,
    metavar="FILE.csv",
    help="Measurements: point,image,x_px,y_px,mode[,sigma_px] (mode precise, approx or manual).",
)
@click.option(
    "--odm",
    "odm_file",
    type=_in_file,
    default=None,
    metavar="FILE",
    help="Control points and their measurements from OpenDroneMap's gcp_list.txt.",
)
@click.option(
    "--micmac",
    "micmac_files",
    multiple=True,
    type=_in_file,
    metavar="FILE",
    help="Control points and measurements from MicMac's 3-D and 2-D GCP files.",
)
@click.option("--point", default=None, help="One measurement from the command line: the point.")
@click.option("--image", type=int, default=None, help="... its image number.")
@click.option("--xy", default=None, metavar="X,Y", help="... its pixel position (col,row).")
@click.option(
    "--mode",
    type=click.Choice(["precise", "approx", "manual"]),
    default="precise",
    show_default=True,
    help="... how it was digitised.",
)
@click.option(
    "--auto",
    "automatic",
    is_flag=True,
    help="Predict every point digitised precisely in one image in all the others and measure "
    "it there by least-squares matching.",
)
@click.option("--guide", "guidance", is_flag=True, help="List the control points not measured "
              "yet with their predicted image positions.")  # fmt: skip
@click.option(
    "--thumbnails",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="With --guide: a PNG of the image around each predicted position, into this folder.",
)
@click.option(
    "--corr-min",
    type=click.FloatRange(0.3, 0.99),
    default=0.8,
    show_default=True,
    help="Least correlation of a least-squares match.",
)
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@run_guarded
def at_gcp(block, measure_file, odm_file, micmac_files, point, image, xy, mode, automatic,
           guidance, thumbnails, corr_min, as_json):  # fmt: skip
    """Measure control and new points in the images of BLOCK (manual, semi-automatic or
    automatic), or list the control points still to measure (--guide)."""
    from apygis.aerotri.gcp import Measurement, guide, measure, read_measurements

    if odm_file is not None or micmac_files:
        from apygis.aerotri.exchange.convert import import_control

        if odm_file is not None:
            from apygis.aerotri.exchange.odm import read_odm

            xb = read_odm(odm_file)
        else:
            from apygis.aerotri.exchange.micmac import read_micmac

            xb = read_micmac(*micmac_files)
        with _open(block) as b:
            imp = import_control(b, xb)
        click.echo(f"{imp['points_added']} control points added, {imp['measurements']} "
                   "measurements stored")  # fmt: skip
        for what, n in imp["skipped"].items():
            click.echo(f"left out: {n} {what}")
        if not (measure_file or point or automatic or guidance):
            return

    ms = read_measurements(measure_file) if measure_file is not None else []
    if point is not None or image is not None or xy is not None:
        if point is None or image is None or xy is None:
            raise click.UsageError("--point, --image and --xy go together")
        try:
            x, y = (float(v) for v in xy.split(","))
        except ValueError:
            raise click.BadParameter(f"{xy!r}: expected X,Y (pixels)", param_hint="--xy") from None
        ms.append(Measurement(point, image, x, y, mode))
    if guidance:
        with _open(block) as b:
            g = guide(b, thumbnails=thumbnails)
        if as_json:
            click.echo(json.dumps(g, indent=1))
            return
        if not g:
            click.echo("every control point with coordinates is measured")
        for p in g:
            click.echo(f"{p['point']} ({p['kind']}), predicted by the {p['prediction']}:")
            for e in p["images"]:
                t = f"  {e['thumbnail']}" if "thumbnail" in e else ""
                click.echo(f"  image {e['image']:>6}  x {e['x_px']:9.1f}  y {e['y_px']:9.1f}  "
                           f"+- {e['uncertainty_px']:.0f} px{t}")  # fmt: skip
        return
    if not ms and not automatic:
        raise click.UsageError("nothing to do: give --measure FILE, --point/--image/--xy, "
                               "--auto or --guide")  # fmt: skip
    if automatic and not ms:
        ms = _precise_measurements(block)
    with _open(block) as b, _bar(f"measuring {len(ms)} measurements") as bar:
        r = measure(b, ms, automatic=automatic, corr_min=corr_min, progress=_advance(bar))
    if as_json:
        click.echo(json.dumps({"stored": [dict(zip(("point", "image", "x_px", "y_px",
                               "sigma_px", "source", "corr"), s, strict=True))
                               for s in r.stored], "failed": [dict(zip(("point", "image",
                               "reason"), f, strict=True)) for f in r.failed],
                               "new_points": r.new_points}, indent=1))  # fmt: skip
        return
    for name, img, x, y, s, src, c in r.stored:
        extra = f"  corr {c:.3f}" if c is not None else ""
        click.echo(f"{name:>12} {img:>6}  x {x:10.2f}  y {y:10.2f}  sigma {s:.3f} px  {src}"
                   f"{extra}")  # fmt: skip
    for name, img, why in r.failed:
        click.echo(f"{name:>12} {img:>6}  not measured: {why}")
    if r.new_points:
        click.echo(f"new points: {', '.join(r.new_points)}")
    click.echo(f"{len(r.stored)} measurements stored, {len(r.failed)} failed")


def _precise_measurements(block: Path):
    """The stored precise (manual) measurements of control and new points: --auto alone
    measures them in the other images."""
    from apygis.aerotri.gcp import Measurement

    with _open(block) as b:
        rows = b.conn.execute(
            "SELECT p.name, o.image, o.x_px, o.y_px, o.sigma_px FROM observations o JOIN points "
            "p ON p.id = o.point WHERE o.source = 'manual' ORDER BY p.name, o.sigma_px"
        ).fetchall()
    seen: dict[str, object] = {}
    for name, img, x, y, s in rows:
        seen.setdefault(name, Measurement(name, img, x, y, "precise", s))
    if not seen:
        raise click.UsageError(
            f"{block}: no point is digitised precisely yet (--measure or --point/--xy first)"
        )
    return list(seen.values())


@at.command("sketch")
@click.argument("block", type=_block)
@click.option("-o", "--output", type=_picture, required=True, metavar="FILE.pdf",
              help="The point sketches (PDF).")  # fmt: skip
@click.option("--points", default="", metavar="NAMES", help="Comma list of point names "
              "(default: every measured control and new point).")  # fmt: skip
@run_guarded
def at_sketch(block, output, points):
    """Point sketches of BLOCK: one page per control or new point, with an overview and a
    full-resolution detail of the image, the coordinates and the measurements."""
    from apygis.aerotri.sketch import sketch_points

    names = [x.strip() for x in points.split(",") if x.strip()]
    with _open(block) as b, _bar(f"sketching {output}") as bar:
        n = sketch_points(b, output, names=names, progress=_advance(bar))
    click.echo(f"{output}: {n} point sketches")


@at.command("export")
@click.argument("block", type=_block)
@click.option(
    "-o",
    "--output",
    "--tiepoints",
    "tiepoints",
    type=_picture,
    default=None,
    metavar="FILE.csv",
    help="Tie point observations: point,image,x_px,y_px,x_mm,y_mm,sigma_px.",
)
@click.option(
    "--points",
    type=_picture,
    default=None,
    metavar="FILE.csv",
    help="Adjusted points: point,kind,X,Y,Z,sX,sY,sZ,rays.",
)
@click.option(
    "--exterior",
    type=_picture,
    default=None,
    metavar="FILE.csv",
    help="Exterior orientations with their standard deviations.",
)
@click.option(
    "--models",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    metavar="FOLDER",
    help="One orientation file per stereo model (model-A-B.json) for 'apygis session'.",
)
@click.option(
    "--instrument",
    type=_in_file,
    default=None,
    help="With --models: an orientation file of the plotter whose map orientation and "
    "stage motors the model files take.",
)
@click.option("--patb", type=_picture, default=None, metavar="BASE",
              help="PAT-B files BASE.im (image coordinates), BASE.con, BASE.ori.")  # fmt: skip
@click.option("--bluh", type=_picture, default=None, metavar="BASE",
              help="BLUH files BASE.pho (photo coordinates) and BASE.ctl (control).")  # fmt: skip
@click.option("--colmap", type=click.Path(file_okay=False, path_type=Path), default=None,
              metavar="FOLDER", help="COLMAP text model (cameras, images, points3D).")  # fmt: skip
@click.option("--odm", type=_picture, default=None, metavar="FILE",
              help="OpenDroneMap gcp_list.txt (control measurements).")  # fmt: skip
@click.option("--micmac", type=_picture, default=None, metavar="BASE",
              help="MicMac BASE_3d_gcp.xml and BASE_2d_gcp.xml.")  # fmt: skip
@click.option("--with-rejected", is_flag=True, help="Exchange formats: also the observations "
              "the last adjustment rejected.")  # fmt: skip
@click.option("--renumber", is_flag=True, help="BLUH: give points whose names are not numbers "
              "numbers from 900000001 on, listed in BASE.names.csv.")  # fmt: skip
@click.option("--overwrite", is_flag=True, help="Replace existing model files.")
@run_guarded
def at_export(block, tiepoints, points, exterior, models, instrument, patb, bluh, colmap, odm,
              micmac, with_rejected, renumber, overwrite):  # fmt: skip
    """Export the observations, adjusted points, orientations, stereo models of BLOCK, or the
    block in an exchange format."""
    from apygis.aerotri.adjust_report import export_exterior, export_points
    from apygis.aerotri.report import export_tiepoints

    exchange = {"patb": patb, "bluh": bluh, "colmap": colmap, "odm": odm, "micmac": micmac}
    if all(x is None for x in (tiepoints, points, exterior, models, *exchange.values())):
        raise click.UsageError(
            "nothing to export: give --tiepoints, --points, --exterior, --models or an "
            "exchange format (--patb, --bluh, --colmap, --odm, --micmac)"
        )
    if instrument is not None and models is None:
        raise click.UsageError("--instrument goes with --models")
    with _open(block) as b:
        if models is not None:
            from apygis.aerotri.models import write_models

            paths = write_models(b, models, instrument=instrument, overwrite=overwrite)
            click.echo(f"{models}: {len(paths)} stereo models")
        if tiepoints is not None:
            click.echo(f"{tiepoints}: {export_tiepoints(b, tiepoints)} observations")
        if points is not None:
            click.echo(f"{points}: {export_points(b, points)} points")
        if exterior is not None:
            click.echo(f"{exterior}: {export_exterior(b, exterior)} images")
        if any(v is not None for v in exchange.values()):
            _export_exchange(b, exchange, with_rejected, renumber)


def _renumbered(xb, base: Path):
    """A copy of ``xb`` whose points with names that are not BLUH numbers are numbered from
    900000001 on; the mapping goes to ``BASE.names.csv``."""
    import copy

    from apygis.fileio import atomic_write

    def ok(n: str) -> bool:
        return n.isdigit() and not n.startswith("0") and 0 < int(n) <= 2147483647

    taken = {int(p.name) for p in xb.points if ok(p.name)}
    mapping, nxt = {}, 900000001
    for p in xb.points:
        if not ok(p.name):
            while nxt in taken:
                nxt += 1
            mapping[p.name] = str(nxt)
            taken.add(nxt)
    if not mapping:
        return xb
    out = copy.deepcopy(xb)
    for p in out.points:
        p.name = mapping.get(p.name, p.name)
    for o in out.observations:
        o.point = mapping.get(o.point, o.point)
    names = base.with_name(base.name + ".names.csv")
    atomic_write(names, "name,number\n" + "".join(f"{k},{v}\n" for k, v in mapping.items()),
                 parents=True)  # fmt: skip
    click.echo(f"bluh: {len(mapping)} points renumbered, listed in {names}")
    return out


def _export_exchange(b, targets: dict, with_rejected: bool, renumber: bool = False) -> None:
    from apygis.aerotri.exchange import bluh, colmap, micmac, odm, patb
    from apygis.aerotri.exchange.convert import block_to_exchange

    xb = block_to_exchange(b, rejected=with_rejected)
    for what, n in xb.skipped.items():
        click.echo(f"left out: {n} {what}")
    writers: dict[str, Any] = {
        "patb": patb.write_patb, "bluh": bluh.write_bluh, "colmap": colmap.write_colmap,
        "odm": odm.write_odm, "micmac": micmac.write_micmac,
    }  # fmt: skip
    for fmt, target in targets.items():
        if target is None:
            continue
        block = _renumbered(xb, Path(target)) if fmt == "bluh" and renumber else xb
        rep = writers[fmt](block, target)
        written = ", ".join(f"{n} {w}" for w, n in rep.written.items())
        click.echo(f"{fmt}: {', '.join(str(f) for f in rep.files)}" +
                   (f" ({written})" if written else ""))  # fmt: skip
        for what, n in rep.skipped.items():
            click.echo(f"{fmt}: left out {n} {what}")
        for note in rep.notes:
            click.echo(f"{fmt}: note: {note}")


@at.command("import")
@click.argument("block", type=_block_new)
@click.option("--colmap", type=click.Path(exists=True, file_okay=False, path_type=Path),
              required=True, metavar="FOLDER", help="A COLMAP text model.")  # fmt: skip
@click.option("--images", type=click.Path(exists=True, file_okay=False, path_type=Path),
              required=True, help="The folder of the model's images.")  # fmt: skip
@click.option("--pixel-um", type=click.FloatRange(0.1, 1000.0), required=True,
              help="The cameras' pixel pitch in micrometres (COLMAP has none).")  # fmt: skip
@click.option("--crs", default="", help="The block CRS.")
@click.option("--frame", type=click.Choice(["local", "crs"]), default="local", show_default=True,
              help="The model's frame: its own (placed on the control by 'at adjust') or the "
              "block CRS (a georeferenced model).")  # fmt: skip
@click.option("--undistort", is_flag=True, help="Accept OPENCV cameras (their distortion "
              "applied to the observations).")  # fmt: skip
@click.option("--overwrite", is_flag=True, help="Replace an existing block.")
@run_guarded
def at_import(block, colmap, images, pixel_um, crs, frame, undistort, overwrite):
    """Create BLOCK from a COLMAP model: cameras, images, tie points and observations, and the
    model's poses as the adjustment's starting values."""
    from apygis.aerotri.exchange.colmap import read_colmap
    from apygis.aerotri.exchange.convert import import_block

    xb = read_colmap(colmap, pixel_um=pixel_um,
                     distortion="undistort" if undistort else "refuse")  # fmt: skip
    xb.crs = crs or xb.crs
    r = import_block(xb, block, images_folder=images, frame=frame, overwrite=overwrite)
    click.echo(f"{block}: {r['images']} images ({r['oriented']} oriented), {r['points']} points, "
               f"{r['observations']} observations")  # fmt: skip
    for what, n in xb.skipped.items():
        click.echo(f"left out: {n} {what}")


@at.command("info")
@click.argument("block", type=_block)
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@run_guarded
def at_info(block, as_json):
    """Images, interior orientations, tie points by multiplicity, observations per image, gaps."""
    from apygis.aerotri.report import block_info, info_text

    with _open(block) as b:
        info = block_info(b)
    click.echo(json.dumps(info, indent=1) if as_json else info_text(info), nl=as_json)


def _rotated(values) -> dict[int, int]:
    out = {}
    for v in values:
        image, _, code = v.partition(":")
        if not image.isdigit() or not code.isdigit() or int(code) > 7:
            raise click.BadParameter(
                f"{v!r}: expected IMAGE:CODE, CODE 0..7", param_hint="--rotated"
            )
        out[int(image)] = int(code)
    return out


@at.command("synth")
@click.argument("folder", type=click.Path(file_okay=False, path_type=Path))
@click.option("--strips", type=click.IntRange(1, 50), default=3, show_default=True)
@click.option("--images-per-strip", type=click.IntRange(2, 100), default=6, show_default=True)
@click.option("--forward-overlap", type=click.FloatRange(0.0, 0.9), default=0.6, show_default=True)
@click.option("--side-overlap", type=click.FloatRange(0.0, 0.9), default=0.3, show_default=True)
@click.option("--cross-strips", type=click.IntRange(0, 10), default=0, show_default=True)
@click.option(
    "--size",
    "size_px",
    type=click.IntRange(64, 30000),
    default=3000,
    show_default=True,
    help="Film: scan side in pixels (240 mm); digital: the sensor's long side.",
)
@click.option("--camera", type=click.Choice(["film", "digital"]), default="film", show_default=True)
@click.option(
    "--rotated",
    multiple=True,
    metavar="IMAGE:CODE",
    help="Scan image IMAGE rotated/mirrored: CODE k (0-3) turns by k x 90 degrees, "
    "k + 4 also mirrors.",
)
@click.option(
    "--noise-dn",
    type=click.FloatRange(0.0, 50.0),
    default=2.0,
    show_default=True,
    help="Grain noise, standard deviation in grey values.",
)
@click.option("--no-lake", is_flag=True, help="No textureless water body.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--overwrite", is_flag=True, help="Write into a folder that is not empty.")
@run_guarded
def at_synth(folder, strips, images_per_strip, forward_overlap, side_overlap, cross_strips,
             size_px, camera, rotated, noise_dn, no_lake, seed, overwrite):  # fmt: skip
    """Render a synthetic block with its truth into FOLDER.

    Writes the images, camera.toml, images.csv, control.csv (inputs of
    'apygis at init'), dem.tif and truth.json (exterior and interior
    orientations, scan transforms, control, DEM).
    """
    from apygis.aerotri.synth import SynthSpec, synth_block

    if folder.exists() and any(folder.iterdir()) and not overwrite:
        raise click.ClickException(
            f"{folder}: the folder is not empty (--overwrite writes into it)"
        )
    spec = SynthSpec(
        strips=strips,
        images_per_strip=images_per_strip,
        forward_overlap=forward_overlap,
        side_overlap=side_overlap,
        cross_strips=cross_strips,
        size_px=size_px,
        camera=camera,
        rotated_scans=_rotated(rotated),
        noise_dn=noise_dn,
        lake=not no_lake,
        seed=seed,
    )
    with _bar(f"rendering {folder}") as bar:
        truth = synth_block(folder, spec, progress=_advance(bar))
    n = strips * images_per_strip + cross_strips * images_per_strip
    click.echo(f"{folder}: {n} {camera} images of {size_px} px, truth in {truth}")
    click.echo(
        f"next: apygis at init {folder}.block --camera {folder}/camera.toml "
        f"--images {folder}/images.csv --control {folder}/control.csv --crs {spec.crs}"
    )
