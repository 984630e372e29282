"""``apygis plot``: a map sheet for a pen plotter (HP-GL), as SVG, PDF, or a raster pin plot."""

from __future__ import annotations

import click

from apygis.cli._common import map_input_options, progress_bar, read_map, run_guarded

__all__ = ["FORMATS", "plot"]

#: Output extension to format name.
FORMATS = {
    ".hpgl": "hpgl",
    ".hpg": "hpgl",
    ".hgl": "hpgl",
    ".plt": "hpgl",
    ".svg": "svg",
    ".pdf": "pdf",
    ".png": "png",
    ".tif": "tiff",
    ".tiff": "tiff",
}


def _layers(ctx, param, value):
    if value is None:
        return None
    parts = [p.strip().lower() for p in value.split(",") if p.strip()]
    if not parts:
        raise click.BadParameter(f"expected layer extensions such as c,h,r, not {value!r}")
    return parts


def _bbox(ctx, param, value):
    if value is None:
        return None
    import math

    parts = [p for p in value.replace(",", " ").split() if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) != 4 or not all(math.isfinite(v) for v in vals):
        raise click.BadParameter(
            f"expected four numbers X0,Y0,X1,Y1 (ground, the map's CRS units), not {value!r}"
        )
    x0, y0, x1, y1 = vals
    if not (x1 > x0 and y1 > y0):
        raise click.BadParameter(
            f"expected the lower-left corner then the upper-right (X1 > X0, Y1 > Y0), not {value!r}"
        )
    return (x0, y0, x1, y1)


def _paper(ctx, param, value):
    if value is None:
        return None
    from apygis.plot.plotdef import parse_paper

    try:
        return parse_paper(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None


def _sources(path: str, layers) -> list[str]:
    """The file names the map was read from, for the title block."""
    from pathlib import Path

    p = Path(path)
    if p.is_file():
        return [p.name]
    if p.is_dir():
        return [p.name + "/"]
    names = sorted(f.name for f in p.parent.glob(p.name + ".*") if f.suffix[1:].lower() in layers)
    return names or [p.name]


@click.command()
@click.argument("path", type=click.Path())
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(),
    help="Output file: .hpgl/.plt (HP-GL), .svg, .pdf, .png or .tif (pin plot).",
)
@click.option("--plotter", type=click.Path(), help="PLOTTER.DEF with paper, scale, pens, ...")
@click.option(
    "--scale",
    type=click.IntRange(min=1),
    help="Plot scale denominator (default: PLOTTER.DEF's, else the map's compilation scale).",
)
@click.option(
    "--paper",
    callback=_paper,
    help="A0-A4 [portrait|landscape], auto, or WxH in mm (default: the smallest that fits).",
)
@click.option(
    "--bbox",
    callback=_bbox,
    help="Map window X0,Y0,X1,Y1 in the map's CRS units (default: the data, padded).",
)
@click.option(
    "--layers",
    "plot_layers",
    callback=_layers,
    help="Map layers to plot, e.g. c,h,r (default: all).",
)
@click.option(
    "--grid",
    type=click.Choice(["crosses", "lines", "off"]),
    help="Coordinate grid (default: crosses; lines for --control).",
)
@click.option(
    "--grid-interval",
    type=click.FloatRange(min=0, min_open=True),
    help="Grid interval in the CRS's units (default: a round one, at least 35 mm on paper).",
)
@click.option(
    "--control",
    is_flag=True,
    help="Control-point and grid plot: the control layer's points with numbers and heights.",
)
@click.option(
    "--control-file",
    type=click.Path(),
    help="Also draw the points of an orientation control file (ID X Y Z); implies --control.",
)
@click.option(
    "--dpi",
    type=click.FloatRange(min=10, max=2400),
    default=300,
    show_default=True,
    help="Resolution of a .png/.tif pin plot.",
)
@click.option(
    "--hpgl",
    "hpgl_version",
    type=click.Choice(["1", "2"]),
    default="1",
    show_default=True,
    help="HP-GL dialect of a .hpgl/.plt output: 1 (HP-GL) or 2 (HP-GL/2, pen widths and colours).",
)
@click.option("--library", type=click.Path(), help="Symbol library (default: the user's).")
@map_input_options
@click.option("--overwrite", is_flag=True, help="Replace an existing output file.")
@run_guarded
def plot(
    path,
    output,
    plotter,
    scale,
    paper,
    bbox,
    plot_layers,
    grid,
    grid_interval,
    control,
    control_file,
    dpi,
    hpgl_version,
    library,
    overwrite,
    src,
):
    """Plot the map PATH to OUTPUT, in the format its extension names.

    \b
      apygis plot samples/ZH1091 -o ZH1091.pdf
      apygis plot samples/ZH1091 -o ZH1091.plt --plotter samples/PLOTTER.DEF --layers h,r
      apygis plot samples/ZH1091 -o ZH1091.png --dpi 200
      apygis plot samples/ZH1091 -o control.pdf --control

    The sheet: the map inside a neat line with a labelled coordinate grid,
    and beside it the map's heading, north arrow, scale bar, the legend of
    the symbols and line codes drawn, and a title block (scale, CRS, date,
    source files). Texts and spot heights are placed off lines, symbols and
    each other where they can be; those that cannot are counted.

    Paper, scale, window, margins, pens and sizes come from --plotter
    (docs/plotter-def.md); --scale, --paper, --bbox, --grid and
    --grid-interval override it; what neither gives comes from the map (its
    compilation scale, its data's extent).
    """
    import dataclasses
    from pathlib import Path

    from apygis.errors import DriverError, FileOverwriteError
    from apygis.formats._io import atomic_write_many
    from apygis.model.symbols import load_library
    from apygis.plot.drawing import ControlPoint, build_drawing
    from apygis.plot.plotdef import PlotterDef, read_plotdef
    from apygis.progress import STEPS, fraction, phase

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
    changes: dict = {}
    if scale is not None:
        changes["scale"] = scale
    if paper is not None:
        changes["paper"] = paper
    if bbox is not None:
        changes["window"] = bbox
        changes["origin"] = None
    if grid_interval is not None:
        changes["grid_interval"] = grid_interval
    if changes:
        pdef = dataclasses.replace(pdef, **changes)
    points = []
    if control_file:
        from apygis.orient.readers import read_control

        control = True
        points = [
            ControlPoint(pid, x, y, z) for pid, (x, y, z) in read_control(control_file).items()
        ]
    m, _ = read_map(path, src)
    if plot_layers is not None:
        missing = [e for e in plot_layers if e not in m.layers]
        if missing:
            raise click.BadParameter(
                f"map {m.id} has no layer {', '.join(missing)} "
                f"(its layers: {' '.join(sorted(m.layers)) or 'none'})",
                param_hint="--layers",
            )
    lib = load_library(library)
    sources = _sources(path, m.layers)
    if control_file:
        sources.append(Path(control_file).name)
    with progress_bar(STEPS, f"plotting {m.id}") as bar:

        def advance(done: int, total: int) -> None:
            bar.update(round(STEPS * fraction(done, total)) - bar.pos)

        d = build_drawing(
            m,
            pdef,
            lib,
            plot_layers,
            control=control,
            control_points=points,
            grid=grid,
            sources=sources,
            progress=phase(advance, 0, 2),
        )
        render_progress = phase(advance, 1, 2)
        report: dict = {}
        if fmt == "hpgl":
            from apygis.plot.hpgl import drawing_hpgl

            data = drawing_hpgl(d, version=int(hpgl_version), report=report)
            if render_progress is not None:
                render_progress(1, 1)
        elif fmt == "svg":
            from apygis.plot.svg import drawing_svg

            data = drawing_svg(d)
            if render_progress is not None:
                render_progress(1, 1)
        elif fmt == "pdf":
            from apygis.plot.pdf import drawing_pdf

            data = drawing_pdf(d, progress=render_progress)
        elif fmt == "png":
            from apygis.plot.raster import drawing_png

            data = drawing_png(d, dpi=dpi, progress=render_progress)
        else:
            from apygis.plot.raster import drawing_tiff

            data = drawing_tiff(d, dpi=dpi, progress=render_progress)
    atomic_write_many({out: data})
    what = {"hpgl": f"HP-GL/{hpgl_version}" if hpgl_version == "2" else "HP-GL"}.get(
        fmt, fmt.upper()
    )
    if fmt in ("png", "tiff"):
        what += f", {dpi:g} dpi"
    line = f"wrote {output} ({what}): {d.summary()}"
    if d.unplaced:
        line += " (-v lists them)"
    if report.get("outlined"):
        k = report["outlined"]
        line += (
            f"; {k} label{'s' if k != 1 else ''} drawn as outlines "
            "(characters outside the plotter's ASCII set)"
        )
    click.echo(line)
