"""``apygis convert``: from one format to another."""

from __future__ import annotations

import click

from apygis.cli._common import run_guarded


@click.command()
@click.argument("src", type=click.Path())
@click.argument("dst", type=click.Path())
@click.option("--driver", help="Output driver (default: from DST's extension).")
@click.option("--src-driver", help="Input driver (default: from SRC's content or extension).")
@click.option("--overwrite", is_flag=True, help="Replace existing output files.")
@run_guarded
def convert(src: str, dst: str, driver: str | None, src_driver: str | None, overwrite: bool):
    """Convert the map SRC to DST.

    An APY native map is named dir/ID (all layer files dir/ID.*) or dir/ID.ext
    (one layer). Existing outputs are refused without --overwrite.
    """
    import apygis
    from apygis.errors import FileOverwriteError
    from apygis.formats import driver_for, get_driver

    m = apygis.read(src, driver=src_driver)
    out_drv = get_driver(driver, "w") if driver else driver_for(dst, "w")
    if not overwrite:
        existing = [str(p) for p in out_drv.targets(m, dst) if p.exists()]
        if existing:
            raise FileOverwriteError(f"{', '.join(existing)} exists; use --overwrite to replace it")
    written = apygis.write(m, dst, driver=out_drv.name)
    n = sum(len(lay) for lay in m)
    click.echo(
        f"{src} -> {', '.join(map(str, written))} ({out_drv.name}): "
        f"{len(m.layers)} layers, {n} records"
    )
