"""``apygis convert``: from one format to another, one file or many (ogr2ogr / fio style)."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import cast

import click

from apygis.cli._common import (
    map_input_options,
    progress_bar,
    reader_for,
    reader_options,
    run_guarded,
    writer_options,
)


def _outputs(paths: list[str]) -> str:
    """The files written, or a summary of them when there are many."""
    if len(paths) <= 4:
        return ", ".join(paths)
    folders = sorted({str(Path(p).parent) for p in paths})
    return f"{len(paths)} files in {', '.join(folders)} ({Path(paths[0]).name}, ...)"


def _is_folder(dst: str) -> bool:
    """A destination that names a folder: a trailing slash, or an existing directory."""
    return dst.endswith(("/", os.sep)) or Path(dst).is_dir()


@click.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@click.option(
    "-o",
    "--output",
    type=click.Path(),
    help="The output file or folder (else the last PATH); '-' is standard output.",
)
@click.option(
    "-f",
    "--driver",
    "--to",
    "driver",
    metavar="NAME",
    help="Output driver (apygis formats); default: from the output's extension.",
)
@click.option("--to-crs", metavar="CRS", help="Reproject to this CRS (EPSG:XXXX, WKT, PROJ).")
@map_input_options
@click.option("-j", "--jobs", type=click.IntRange(1), default=1, help="Parallel processes.")
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    help="Run a batch on this Dask cluster (tcp://host:8786); default: local processes.",
)
@click.option("--overwrite", is_flag=True, help="Replace existing output files.")
@run_guarded
def convert(paths, output, driver, to_crs, jobs, scheduler, overwrite, src):
    """Convert SRC to DST (a file, or a folder), or many SRC... into the folder DST.

    \b
      apygis convert samples/ZH1091 -o out/sheet.gpkg
      apygis convert samples/ZH1091.apa out/sheet.dxf --to-crs EPSG:4326
      apygis convert --to gpkg -j 2 'samples/*.apa' -o out/batch/
      apygis convert drawing.dxf -o out/ --src-crs EPSG:2056 --layer-map ROADS=r
      apygis convert samples/ZH1091 --to dxf -o - > out/sheet.dxf
      apygis convert densification/MAP -o out/block.patb --to patb

    DST names a file, written with --to/--driver or the driver its extension
    names; a DST ending in '/' (or an existing folder) is a folder that
    receives SRC under its own name, in the format of --to (default: SRC's).
    Several SRC (files and globs) go into the folder DST, each reported with
    its result; a file that fails stops nothing and the exit code is 1. '-'
    writes a format that is one file (dxf, e00, ascii) to standard output.
    An APY native map is named dir/ID (all layer files dir/ID.*). Nothing is
    replaced without --overwrite.
    """
    from apygis.errors import DriverError
    from apygis.formats import get_driver
    from apygis.formats.batch import convert_file, convert_many, expand_sources

    if output is not None:
        srcs, dst = list(paths), output
    elif len(paths) >= 2:
        *srcs, dst = paths
    else:
        raise click.UsageError("give SRC and DST (or SRC... -o DST); see apygis convert -h")
    sources = expand_sources(srcs)
    if not sources:
        raise click.UsageError("no SRC given")
    out_drv = None
    if driver:
        try:
            out_drv = get_driver(driver, "w")
        except DriverError as exc:
            raise DriverError(f"--driver {driver}: {exc}") from None
    if len(sources) > 1 and out_drv is None and dst != "-":
        raise click.UsageError("converting several files into a folder needs --to FORMAT")
    in_drv = reader_for(sources[0], src)
    co = src.get("co") or {}
    common = {
        "src_driver": src.get("src_driver"),
        "overwrite": overwrite,
        "to_crs": to_crs,
    }

    if dst == "-":
        _to_stdout(sources, in_drv, out_drv, src, co, common)
        return
    if len(sources) == 1 and _is_folder(dst):  # into the folder, under SRC's own name
        from apygis.formats.batch import output_name

        if out_drv is None:
            if "w" not in in_drv.modes:
                raise click.UsageError(f"the {in_drv.name} driver cannot write: name one with --to")
            out_drv = in_drv
        Path(dst).mkdir(parents=True, exist_ok=True)
        dst = str(Path(dst) / output_name(sources[0], out_drv.name))
    if len(sources) == 1:
        from apygis.formats import driver_for

        target = out_drv or driver_for(dst, "w")
        common["read_options"] = reader_options(in_drv, src, writer=target)
        common["write_options"] = writer_options(target, co, reader=in_drv)
        with progress_bar(1000, f"converting {sources[0]}") as bar:

            def advance(done, total):
                bar.update(round(1000 * done / max(total, 1)) - bar.pos)

            res = convert_file(sources[0], dst, driver=target.name, progress=advance, **common)
        if not res.ok:
            raise click.ClickException(cast(str, res.error))  # set when not ok
        click.echo(
            f"{res.source} -> {_outputs(res.outputs)}: {res.layers} layers, {res.records} records"
        )
        return

    # a batch: several SRC into the folder DST
    assert out_drv is not None  # checked above: several sources need --to
    common["read_options"] = reader_options(in_drv, src, writer=out_drv)
    common["write_options"] = writer_options(out_drv, co, reader=in_drv)
    failed = []
    with progress_bar(len(sources), f"converting to {out_drv.name}") as bar:

        def report(res):
            if not res.ok:
                failed.append(res)

        def advance_batch(done, total):
            bar.update(done - bar.pos)

        results = convert_many(
            sources,
            dst,
            out_drv.name,
            jobs=jobs,
            scheduler=scheduler,
            progress=advance_batch,
            on_result=report,
            **common,
        )
    for res in results:
        if res.ok:
            click.echo(
                f"{res.source} -> {_outputs(res.outputs)}: "
                f"{res.layers} layers, {res.records} records"
            )
            for w in res.warnings:
                click.echo(f"  warning: {w}", err=True)
        else:
            click.echo(f"FAILED {res.source}: {res.error}", err=True)
    click.echo(f"{len(results) - len(failed)} converted, {len(failed)} failed")
    if failed:
        sys.exit(1)


def _to_stdout(sources, in_drv, out_drv, src, co, common) -> None:
    """The one output file written to standard output (formats that are one file)."""
    import tempfile

    from apygis.errors import DriverError
    from apygis.formats.batch import convert_file

    if len(sources) != 1:
        raise click.UsageError("'-' takes one SRC")
    if out_drv is None:
        raise click.UsageError("'-' (standard output) needs the format: --to dxf, e00 or ascii")
    if not out_drv.stream:
        streams = ", ".join(d.name for d in _drivers() if d.stream)
        raise DriverError(
            f"-: the {out_drv.name} driver does not write one file that can go to standard "
            f"output (those that do: {streams}); name an output file"
        )
    common = {
        **common,
        "overwrite": True,
        "read_options": reader_options(in_drv, src, writer=out_drv),
        "write_options": writer_options(out_drv, co, reader=in_drv),
    }
    with tempfile.TemporaryDirectory(prefix="apygis-stdout-") as tmp:
        name = Path(sources[0].rstrip("/")).stem or "map"
        target = Path(tmp) / f"{name}.{out_drv.extensions[0] if out_drv.extensions else 'out'}"
        res = convert_file(sources[0], str(target), driver=out_drv.name, **common)
        if not res.ok:
            raise click.ClickException(cast(str, res.error).replace(str(target), "-"))
        with open(target, "rb") as fh:
            out = sys.stdout.buffer
            while chunk := fh.read(1 << 20):
                out.write(chunk)
            out.flush()


def _drivers():
    from apygis.formats import drivers

    return drivers().values()
