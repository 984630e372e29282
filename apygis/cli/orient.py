"""``apygis orient``: orient the map and the photos (the APY ORIENTATION program).

``apygis orient map CONTROL MEASUREMENTS`` fits the tablet-to-ground transform;
``apygis orient photos PHOTOFILE CONTROL MEASUREMENTS`` orients each photo by
the APY parallax conditions. Both print the control points with their
residuals and the RMSE in position, and with ``-o FILE`` put their result
into an orientation file (docs/formats/orientation.md). An existing file is
refused without ``--overwrite``, like every command's output; with it, the
file is read and only the part computed here is replaced, so ``orient map
-o F`` and ``orient photos -o F --overwrite`` build one file together. Points
are rejected with ``--reject`` and the command re-run (the seed: "points can
now be rejected or added, followed by a recalculation").
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import click

from apygis.cli._common import run_guarded
from apygis.cli.view import host_options, serve_until_interrupted, start_view, view_server
from apygis.errors import FileOverwriteError, MeasurementError
from apygis.orient.io import Orientation, load_orientation, save_orientation
from apygis.orient.photo import orient_photo
from apygis.orient.readers import (
    control_for,
    read_control,
    read_map_measurements,
    read_photo_file,
    read_photo_measurements,
)
from apygis.orient.transforms import MODELS, MirroredTransformWarning, fit_map_transform

__all__ = ["orient"]

GON = 200.0 / math.pi

# No click checks on the paths: the readers report a missing file, a
# directory or a symbolic-link loop as a FormatError naming the path (one
# line, exit 1) like any other input error.
_in_file = click.Path(path_type=Path)
_out_file = click.Path(path_type=Path)

NOT_CHECKED = "no redundancy: the result is not checked"


def _reject_ids(values) -> tuple[str, ...]:
    out: list[str] = []
    for v in values:
        out.extend(p for p in v.replace(",", " ").split() if p)
    return tuple(out)


def _save(o: Orientation, output: Path) -> None:
    try:
        save_orientation(o, output)
    except OSError as exc:
        raise click.ClickException(f"cannot write {output}: {exc.strerror or exc}") from exc
    click.echo(f"wrote {output}")


def _existing(path: Path | None, overwrite: bool) -> Orientation:
    """The orientation file to update; a directory or a broken link there is a FormatError.

    An existing file (or anything else at ``path``) is refused without ``--overwrite``.
    """
    if path is not None and os.path.lexists(path):
        if not overwrite:
            raise FileOverwriteError(f"{path} exists; use --overwrite to replace it")
        return load_orientation(path)
    return Orientation()


@click.group("orient")
def orient() -> None:
    """Orient the map (tablet -> ground) and the photos (parallax conditions)."""


@orient.command("map")
@click.argument("control", type=_in_file)
@click.argument("measurements", type=_in_file)
@click.option(
    "--model",
    type=click.Choice(list(MODELS)),
    default="affine",
    show_default=True,
    help="conformal: >= 2 points each measured twice; affine: >= 3; bilinear: 4 or more.",
)
@click.option(
    "--reject",
    "reject",
    multiple=True,
    metavar="ID",
    help="Leave a point out (repeat, or separate ids by commas).",
)
@click.option("--map-id", default=None, help="Map identification to record in the output file.")
@click.option(
    "-o",
    "--output",
    type=_out_file,
    default=None,
    help="Orientation file to write.",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Update an existing output file: replace the part computed here.",
)
@click.option(
    "--view",
    "view_page",
    is_flag=True,
    help="Show the control points and their residual vectors on a local web page "
    "(served until Ctrl-C).",
)
@click.option(
    "--map",
    "map_path",
    type=_in_file,
    default=None,
    help="With --view: the existing map data to show under the control points.",
)
@host_options("view-")
@run_guarded
def orient_map(
    control, measurements, model, reject, map_id, output, overwrite, view_page, map_path,
    view_host, view_port, no_browser,
):  # fmt: skip
    """Orient the map from CONTROL (ID X Y Z) and tablet MEASUREMENTS (ID x_mm y_mm).

    With --view the control points, their residual vectors (exaggerated, the
    factor in the legend) and, with --map, the existing map are shown on a
    local web page until Ctrl-C.
    """
    if map_path is not None and not view_page:
        raise click.UsageError("--map goes with --view")
    server = view_server(view_host, view_port) if view_page else None
    try:
        fit = _orient_map(control, measurements, model, reject, map_id, output, overwrite)
        if server is not None:
            _show_fit(server, fit, control, map_path, map_id, no_browser)
    except BaseException:
        if server is not None:
            server.stop()
        raise
    if server is not None:
        serve_until_interrupted(server)


def _show_fit(server, fit, control, map_path, map_id, no_browser) -> None:
    import apygis
    from apygis.model.map import MapFile
    from apygis.view import control_overlays, map_hub

    m = apygis.read(map_path) if map_path is not None else MapFile(map_id or "orientation")
    ctrl = read_control(control)
    hub = map_hub(m, kind="orientation", source=str(map_path or control))
    rejected = {pid: ctrl[pid][:2] for pid in fit.rejected if pid in ctrl}
    hub.set_overlays(control_overlays(fit.ids, fit.ground, fit.residuals, rejected))
    what = f"the map orientation ({len(fit.ids)} control points"
    what += f", map {m.id})" if map_path is not None else ")"
    start_view(server, hub, what, no_browser)


def _orient_map(control, measurements, model, reject, map_id, output, overwrite):
    existing = _existing(output, overwrite)  # a bad output path fails before any work
    ctrl = read_control(control)
    ids, tablet = read_map_measurements(measurements)
    if not ids:
        raise MeasurementError(f"{measurements}: no measurements")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MirroredTransformWarning)
        fit = fit_map_transform(ids, tablet, ctrl, model, reject=_reject_ids(reject))
    for w in caught:
        if issubclass(w.category, MirroredTransformWarning):
            click.echo(f"warning: {w.message}", err=True)
    scale = fit.transform.mean_scale(fit.tablet_mm.mean(axis=0))
    click.echo(
        f"Map orientation: {model}, {len(fit.ids)} points, "
        f"{int(fit.n_measurements.sum())} measurements"
    )
    click.echo(f"{'ID':>8} {'X':>13} {'Y':>13} {'vX m':>8} {'vY m':>8} {'vXY m':>8} {'n':>3}")
    for pid, G, v, n in zip(fit.ids, fit.ground, fit.residuals, fit.n_measurements, strict=True):
        click.echo(
            f"{pid:>8} {G[0]:13.3f} {G[1]:13.3f} {v[0]:8.3f} {v[1]:8.3f} "
            f"{math.hypot(v[0], v[1]):8.3f} {int(n):3d}"
        )
    if not fit.checked:
        click.echo(
            f"{NOT_CHECKED} ({len(fit.ids)} points, {2 * len(fit.ids)} coordinates for "
            f"{fit.transform.n_parameters} {model} parameters: no RMSE, no sigma0)"
        )
    else:
        click.echo(f"RMSE in position: {fit.rmse:.3f} m ({fit.rmse / scale:.3f} mm on the map)")
    if math.isfinite(fit.sigma0):
        click.echo(f"sigma0 (one coordinate): {fit.sigma0:.3f} m")
    if math.isfinite(fit.pointing_sigma_mm):
        click.echo(
            f"pointing precision (double measurements): {fit.pointing_sigma_mm:.3f} mm "
            f"on the tablet = {fit.pointing_sigma:.3f} m"
        )
    if fit.rejected:
        click.echo(f"rejected: {', '.join(fit.rejected)}")
    if output is not None:
        o = existing
        quality = dict(o.quality)
        quality["map"] = fit.summary()
        o = o.replace(
            map_transform=fit.transform,
            map_id=map_id if map_id is not None else o.map_id,
            quality=quality,
        )
        _save(o, output)
    return fit


@orient.command("photos")
@click.argument("photofile", type=_in_file)
@click.argument("control", type=_in_file)
@click.argument("measurements", type=_in_file)
@click.option(
    "--reject",
    "reject",
    multiple=True,
    metavar="ID",
    help="Leave a control spot out in every photo (repeat, or separate by commas).",
)
@click.option(
    "-o",
    "--output",
    type=_out_file,
    default=None,
    help="Orientation file to write.",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Update an existing output file: replace the part computed here.",
)
@run_guarded
def orient_photos(photofile, control, measurements, reject, output, overwrite):
    """Orient the photos of PHOTOFILE from parallaxes zeroed at control spots.

    MEASUREMENTS has lines 'POINT_ID PHOTO_ID px_mm py_mm'; only the
    parameters not entered with '=' in PHOTOFILE are solved for.
    """
    existing = _existing(output, overwrite)  # a bad output path fails before any work
    entries = read_photo_file(photofile)
    ctrl = read_control(control)
    meas = read_photo_measurements(measurements)
    rejects = _reject_ids(reject)
    all_ids = {i for ids, _ in meas.values() for i in ids}
    unknown = [r for r in rejects if r not in all_ids]
    if unknown:
        raise MeasurementError(f"cannot reject {', '.join(unknown)}: not measured in any photo")
    extra = sorted(set(meas) - {e.photo_id for e in entries})
    if extra:
        raise MeasurementError(
            f"{measurements}: photo(s) {', '.join(extra)} not in the photo file {photofile}"
        )
    results = []
    for e in entries:
        if e.photo_id not in meas:
            raise MeasurementError(f"{measurements}: no measurements for photo {e.photo_id}")
        ids, P = meas[e.photo_id]
        G = control_for(ids, ctrl, e.photo_id)
        keep = [i not in rejects for i in ids]
        approx, fixed = e.approximation(G[keep] if any(keep) else G)
        r = orient_photo(
            G, P, approx, fixed=fixed, ids=ids, reject=[i for i in rejects if i in ids]
        )
        results.append(r)
        _print_photo(r, G, ids)
    if output is not None:
        o = existing
        quality = dict(o.quality)
        quality["photos"] = {r.orientation.photo_id: r.summary() for r in results}
        o = o.replace(photos=tuple(r.orientation for r in results), quality=quality)
        _save(o, output)


def _print_photo(r, G, ids) -> None:
    po = r.orientation
    unused = ("Yo", "sy") if po.interior.scanned else ()
    known = [
        n
        for n in ("Xo", "Yo", "Zo", "omega", "phi", "kappa", "sx", "sy")
        if n not in r.free and n not in unused
    ]
    click.echo(
        f"Photo {po.photo_id}: {len(r.ids)} control spots, solved "
        f"{', '.join(r.free) or 'nothing'}"
        + (f"; known {', '.join(known)}" if known else "")
        + f"; {r.iterations} iterations"
    )
    click.echo(f"{'ID':>8} {'X':>13} {'Y':>13} {'Z':>9} {'vpx um':>8} {'vpy um':>8} {'vp um':>8}")
    index = {pid: k for k, pid in enumerate(ids)}
    for pid, v in zip(r.ids, r.residuals_mm, strict=True):
        X, Y, Z = G[index[pid]]
        click.echo(
            f"{pid:>8} {X:13.3f} {Y:13.3f} {Z:9.3f} {1000 * v[0]:8.1f} {1000 * v[1]:8.1f} "
            f"{1000 * math.hypot(v[0], v[1]):8.1f}"
        )
    if not r.checked:
        click.echo(
            f"{NOT_CHECKED} ({len(r.ids)} spots, {2 * len(r.ids)} parallaxes for "
            f"{len(r.free)} unknowns: no RMSE, no sigmas)"
        )
    else:
        click.echo(
            f"RMSE in position: {1000 * r.rmse_mm:.1f} um in the photo = "
            f"{r.rmse_ground_m:.3f} m on the ground"
        )
    if math.isfinite(r.sigma0_mm):
        click.echo(f"sigma0: {1000 * r.sigma0_mm:.1f} um, redundancy {r.redundancy}")
    std = r.std
    e = po.exterior
    rows = [
        ("Xo", e.Xo, "m", 1.0),
        ("Yo", e.Yo, "m", 1.0),
        ("Zo", e.Zo, "m", 1.0),
        ("omega", e.omega_rad * GON, "gon", GON),
        ("phi", e.phi_rad * GON, "gon", GON),
        ("kappa", (e.kappa_rad * GON) % 400.0, "gon", GON),
        ("sx", po.sx_mm_per_m, "mm/m", 1.0),
        ("sy", po.sy_mm_per_m, "mm/m", 1.0),
    ]
    for name, value, unit, k in rows:
        if po.interior.scanned and name in ("Yo", "sy"):
            click.echo(f"  {name:<6}{'':>16} {unit:<5} (scanned imagery: not used)")
        elif name not in r.free:
            click.echo(f"  {name:<6}{value:16.5f} {unit:<5} (known)")
        elif math.isfinite(std[name]):
            click.echo(f"  {name:<6}{value:16.5f} {unit:<5} +- {std[name] * k:.5f}")
        else:
            click.echo(f"  {name:<6}{value:16.5f} {unit:<5} (solved, no sigma: not checked)")
    if r.rejected:
        click.echo(f"rejected: {', '.join(r.rejected)}")
