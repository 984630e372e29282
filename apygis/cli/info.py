"""``apygis info``: what a map holds, or which maps a folder holds."""

from __future__ import annotations

import json
from pathlib import Path

import click

from apygis.cli._common import map_input_options, read_map, run_guarded


@click.command()
@click.argument("path", type=click.Path())
@map_input_options
@click.option("--json", "as_json", is_flag=True, help="One JSON object (keys in the README).")
@run_guarded
def info(path: str, as_json: bool, src: dict) -> None:
    """Map ID, scale, CRS and, per layer, counts, APY capacity used, extent and warnings.

    PATH is a map file, dir/ID for all APY layer files dir/ID.*, or a folder:
    the maps in it are listed (each readable file or APY map, with its
    driver and counts; files that are no map are named with the reason).
    """
    p = Path(path)
    if p.is_dir() and not _is_map_folder(p, src):
        _folder(p, as_json, src)
        return
    from apygis.model.summary import summarize

    m, drv = read_map(path, src)
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


def _is_map_folder(p: Path, src: dict) -> bool:
    """A folder that is one map itself: a set of files apygis wrote (Shapefile, GeoJSON,
    FlatGeobuf) with one prefix, or any folder when --src-driver names a driver."""
    from apygis.formats import drivers

    if src.get("src_driver"):
        return True
    for d in drivers().values():
        if d.members is None or d.name in ("apy", "generate"):
            continue
        try:
            if d.members(str(p)) is not None:
                return True
        except (OSError, ValueError):
            continue
    return False


def _candidates(p: Path) -> list[Path]:
    """The maps a folder may hold: each file, APY layer files grouped as dir/ID."""
    from apygis.formats.apy import probe as apy_probe

    out: list[Path] = []
    seen: set[Path] = set()
    for f in sorted(p.iterdir()):
        if f.name.startswith(".") or not f.is_file():
            continue
        if apy_probe(f) and "." in f.name:
            base = f.with_name(f.name.rsplit(".", 1)[0])
            if base not in seen:
                seen.add(base)
                out.append(base)
            continue
        out.append(f)
    return out


def _folder(p: Path, as_json: bool, src: dict) -> None:
    """The maps in folder ``p``, each with its driver and counts; the other files named."""
    from apygis.errors import ApygisError
    from apygis.model.summary import summarize

    maps, others = [], []
    for f in _candidates(p):
        try:
            m, drv = read_map(str(f), src)
        except (ApygisError, OSError) as exc:
            others.append({"path": str(f), "reason": str(exc)})
            continue
        s = summarize(m)
        maps.append(
            {
                "path": str(f),
                "driver": drv.name,
                "id": s["id"],
                "crs": s["crs"],
                "layers": list(s["layers"]),
                "totals": s["totals"],
                "valid": s["valid"],
                "warnings": s["warnings"],
            }
        )
    if as_json:
        click.echo(json.dumps({"path": str(p), "maps": maps, "not_maps": others}))
        return
    click.echo(f"{p}: {len(maps)} maps, {len(others)} other files")
    for d in maps:
        t = d["totals"]
        click.echo(
            f"  {d['path']}  ({d['driver']})  map {d['id']}, layers {','.join(d['layers']) or '-'}"
            f": {t['symbols']} symbols, {t['line_points']} line points, {t['texts']} texts"
        )
    for o in others:
        click.echo(f"  not a map: {o['reason']}")
