"""``apygis plot``: draw a map for a pen plotter (HP-GL), as SVG or as PDF."""

from __future__ import annotations

import click

from apygis.cli._common import progress_bar, run_guarded

__all__ = ["FORMATS", "plot"]

#: Output extension to format name.
FORMATS = {".hpgl": "hpgl", ".hpg": "hpgl", ".plt": "hpgl", ".svg": "svg", ".pdf": "pdf"}


def _layers(ctx, param, value):
    if value is None:
        return None
    parts = [p.strip().lower() for p in value.split(",") if p.strip()]
    if not parts:
        raise click.BadParameter(f"expected layer extensions such as c,h,r, not {value!r}")
    return parts


@click.command()
@click.argument("path", type=click.Path())
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(),
    help="Output file: .hpgl/.plt (HP-GL), .svg or .pdf.",
)
@click.option("--plotter", type=click.Path(), help="PLOTTER.DEF with paper, scale, pens, ...")
@click.option("--layers", callback=_layers, help="Layers to plot, e.g. c,h,r (default: all).")
@click.option("--library", type=click.Path(), help="Symbol library (default: the user's).")
@click.option("--driver", help="Read the map with this driver instead of guessing.")
@click.option("--overwrite", is_flag=True, help="Replace an existing output file.")
@run_guarded
def plot(path, output, plotter, layers, library, driver, overwrite):
    """Plot the map PATH to OUTPUT, in the format its extension names.

    \b
      apygis plot samples/ZH1091 -o ZH1091.pdf
      apygis plot samples/ZH1091 -o ZH1091.plt --plotter samples/PLOTTER.DEF --layers h,r

    Paper, scale, origin, margins, pens, symbol size and text height come from
    --plotter (docs/plotter-def.md); without it the map is plotted at its
    compilation scale on the smallest A sheet that holds it.
    """
    from pathlib import Path

    import apygis
    from apygis.errors import DriverError, FileOverwriteError
    from apygis.formats._io import atomic_write_many
    from apygis.model.symbols import load_library
    from apygis.plot.drawing import build_drawing
    from apygis.plot.plotdef import PlotterDef, read_plotdef
    from apygis.progress import STEPS, fraction

    out = Path(output)
    fmt = FORMATS.get(out.suffix.lower())
    if fmt is None:
        raise DriverError(
            f"cannot tell the plot format of {output}: use the extension "
            f"{', '.join(sorted(FORMATS))}"
        )
    if out.exists() and not overwrite:
        raise FileOverwriteError(f"{output} exists; use --overwrite to replace it")
    pdef = read_plotdef(plotter) if plotter else PlotterDef.default()
    m = apygis.read(path, driver=driver)
    if layers is not None:
        missing = [e for e in layers if e not in m.layers]
        if missing:
            raise click.BadParameter(
                f"map {m.id} has no layer {', '.join(missing)} "
                f"(its layers: {' '.join(sorted(m.layers)) or 'none'})",
                param_hint="--layers",
            )
    lib = load_library(library)
    with progress_bar(STEPS, f"plotting {m.id}") as bar:

        def advance(done: int, total: int) -> None:
            bar.update(round(STEPS * fraction(done, total)) - bar.pos)

        d = build_drawing(m, pdef, lib, layers, progress=advance)
    if fmt == "hpgl":
        from apygis.plot.hpgl import drawing_hpgl as render
    elif fmt == "svg":
        from apygis.plot.svg import drawing_svg as render
    else:
        from apygis.plot.pdf import drawing_pdf as render
    atomic_write_many({out: render(d)})
    click.echo(f"wrote {output} ({fmt.upper()}): {d.summary()}")
