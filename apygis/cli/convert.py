"""``apygis convert``: from one format to another, one file or many."""

from __future__ import annotations

import sys
from typing import cast

import click

from apygis.cli._common import progress_bar, run_guarded


def _outputs(paths: list[str]) -> str:
    """The files written, or a summary of them when there are many."""
    if len(paths) <= 4:
        return ", ".join(paths)
    from pathlib import Path

    folders = sorted({str(Path(p).parent) for p in paths})
    return f"{len(paths)} files in {', '.join(folders)} ({Path(paths[0]).name}, ...)"


def _layer_map(ctx, param, value):
    if value is None:
        return None
    out = {}
    for part in value.split(","):
        name, sep, ext = part.partition("=")
        if not sep or not name.strip() or not ext.strip():
            raise click.BadParameter(f"expected NAME=EXT[,NAME=EXT...], not {value!r}")
        out[name.strip()] = ext.strip()
    return out


@click.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@click.option(
    "--to",
    "to_format",
    help="Output driver; DST is then a folder (batch mode), unless one SRC goes to a DST "
    "with that driver's extension.",
)
@click.option("--driver", help="Output driver for a single DST (default: from its extension).")
@click.option("--src-driver", help="Input driver (default: from content or extension).")
@click.option("--to-crs", help="Reproject to this CRS (EPSG:XXXX, WKT, PROJ string).")
@click.option("--layer-map", callback=_layer_map, help="Input layer to map layer: ROADS=r,WATER=h.")
@click.option(
    "--snap",
    type=float,
    help="Tolerance in metres on the ground for rebuilding line topology on import "
    "(converted to feet or degrees for a source in such a CRS).",
)
@click.option("-j", "--jobs", type=click.IntRange(1), default=1, help="Parallel processes.")
@click.option("--overwrite", is_flag=True, help="Replace existing output files.")
@run_guarded
def convert(paths, to_format, driver, src_driver, to_crs, layer_map, snap, jobs, overwrite):
    """Convert SRC to DST, or many SRC... into the folder DST with --to FORMAT.

    \b
      apygis convert samples/ZH1091 out/sheet.apa
      apygis convert --to gpkg -j 2 'in/*.dxf' in/ZH1091 out/
      apygis convert densification/MAP out/block.patb --to patb

    An APY native map is named dir/ID (all layer files dir/ID.*) or dir/ID.ext
    (one layer). Nothing is overwritten without --overwrite, and only regular
    files are (a symlink is written through). A format that cannot hold the
    coordinates (centimetre formats in degrees) refuses. In batch mode a
    file that fails is reported and the others go on; the exit code is 1 if
    any failed.
    """
    from pathlib import Path

    from apygis.formats.batch import convert_file, convert_many, expand_sources

    if len(paths) < 2:
        raise click.UsageError("give SRC and DST (or SRC... DST with --to FORMAT)")
    *srcs, dst = paths
    read_options = {}
    if layer_map:
        read_options["layer_map"] = layer_map
    if snap is not None:
        read_options["tolerance_m"] = snap
    common = {
        "src_driver": src_driver,
        "overwrite": overwrite,
        "to_crs": to_crs,
        "read_options": read_options,
    }
    sources = expand_sources(srcs)
    # one source with --to and a DST that carries that driver's extension (and is no
    # folder) is one file: `convert MAP out/x.patb --to patb`
    if to_format is not None and len(sources) == 1 and not Path(dst).is_dir():
        from apygis.formats import get_driver

        if Path(dst).suffix[1:].lower() in get_driver(to_format, "w").extensions:
            driver, to_format = to_format, None
    # one source into an existing folder is a batch of one, unless --driver names
    # the writer (shp, geojson, fgb and apy write into folders themselves)
    batch = to_format is not None or len(sources) > 1 or (Path(dst).is_dir() and not driver)
    if not batch:
        with progress_bar(1000, f"converting {sources[0]}") as bar:

            def advance(done, total):
                bar.update(round(1000 * done / max(total, 1)) - bar.pos)

            res = convert_file(sources[0], dst, driver=driver, progress=advance, **common)
        if not res.ok:
            raise click.ClickException(cast(str, res.error))  # set when not ok
        click.echo(
            f"{res.source} -> {_outputs(res.outputs)}: {res.layers} layers, {res.records} records"
        )
        return
    if to_format is None:
        raise click.UsageError("converting several files needs --to FORMAT")
    failed = []
    with progress_bar(len(sources), f"converting to {to_format}") as bar:

        def report(res):
            if not res.ok:
                failed.append(res)

        def advance_batch(done, total):
            bar.update(done - bar.pos)

        results = convert_many(
            sources, dst, to_format, jobs=jobs, progress=advance_batch, on_result=report, **common
        )
    for res in results:
        if res.ok:
            click.echo(
                f"{res.source} -> {_outputs(res.outputs)}: "
                f"{res.layers} layers, {res.records} records"
            )
        else:
            click.echo(f"FAILED {res.source}: {res.error}", err=True)
    click.echo(f"{len(results) - len(failed)} converted, {len(failed)} failed")
    if failed:
        sys.exit(1)
