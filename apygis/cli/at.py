"""``apygis at``: automatic aerotriangulation of a photo block (PHODIS AT)."""

from __future__ import annotations

import json
from pathlib import Path

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


@at.command("export")
@click.argument("block", type=_block)
@click.option(
    "-o",
    "--output",
    "--tiepoints",
    "tiepoints",
    type=_picture,
    required=True,
    metavar="FILE.csv",
    help="Tie point observations: point,image,x_px,y_px,x_mm,y_mm,sigma_px.",
)
@run_guarded
def at_export(block, tiepoints):
    """Export the tie point observations of BLOCK."""
    from apygis.aerotri.report import export_tiepoints

    with _open(block) as b:
        n = export_tiepoints(b, tiepoints)
    click.echo(f"{tiepoints}: {n} observations")


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
        f"--images {folder}/images.csv --control {folder}/control.csv"
    )
