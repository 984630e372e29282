"""``apygis info``: what a map holds."""

from __future__ import annotations

import json

import click

from apygis.cli._common import run_guarded


@click.command()
@click.argument("path", type=click.Path())
@click.option("--driver", help="Read with this driver instead of guessing.")
@click.option("--json", "as_json", is_flag=True, help="One JSON object (keys in the README).")
@run_guarded
def info(path: str, driver: str | None, as_json: bool) -> None:
    """Map ID, scale, CRS and, per layer, counts, APY capacity used, extent and warnings.

    PATH is a map file, or dir/ID for all APY layer files dir/ID.*.
    """
    import apygis
    from apygis.formats import driver_for, get_driver
    from apygis.model.summary import summarize

    drv = get_driver(driver, "r") if driver else driver_for(path, "r")
    m = apygis.read(path, driver=drv.name)
    s = {"path": path, "driver": drv.name, **summarize(m)}
    if as_json:
        click.echo(json.dumps(s, ensure_ascii=False))
        return
    scale = f"1:{s['scale']}" if s["scale"] else "unknown"
    crs = f"{s['crs']} ({s['crs_name']})" if s["crs"] else "none"
    click.echo(f"map {s['id']}  ({path}, {drv.name})")
    click.echo(f"  scale  {scale}")
    click.echo(f"  CRS    {crs}")
    if s["notes"]:
        click.echo("  notes  " + s["notes"].replace("\n", "\n         "))
    if s["extent"]:
        e = s["extent"]
        click.echo(
            f"  extent X {e['xmin']:.2f} .. {e['xmax']:.2f}  Y {e['ymin']:.2f} .. {e['ymax']:.2f}"
            f"  Z {e['zmin']:.2f} .. {e['zmax']:.2f}"
        )
    click.echo("")
    click.echo(
        f"  {'layer':<6}{'symbols':>9}{'line pts':>10}{'lines':>7}{'closed':>8}{'branches':>10}"
        f"{'texts':>7}   APY capacity used (sym / line / text)"
    )
    for ext, lay in s["layers"].items():
        cap = lay["capacity_pct"]
        click.echo(
            f"  {ext:<6}{lay['symbols']:>9}{lay['line_points']:>10}{lay['lines']:>7}"
            f"{lay['closed_lines']:>8}{lay['branches']:>10}{lay['texts']:>7}   "
            f"{cap['symbols']:.1f}% / {cap['line_points']:.1f}% / {cap['texts']:.1f}%"
        )
    t = s["totals"]
    click.echo(
        f"  {'total':<6}{t['symbols']:>9}{t['line_points']:>10}{t['lines']:>7}"
        f"{t['closed_lines']:>8}{'':>10}{t['texts']:>7}"
    )
    issues = [(ext, i) for ext, lay in s["layers"].items() for i in lay["issues"]]
    if issues:
        click.echo("")
        for ext, i in issues:
            click.echo(f"  {i['severity']}: layer {ext}: {i['message']}")
    else:
        click.echo("\n  no validation findings")
    if s["read_warnings"]:
        click.echo("")
        for w in s["read_warnings"]:
            click.echo(f"  read: {w['message']}")
