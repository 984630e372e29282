"""``apygis formats``: the drivers, their modes and extensions."""

from __future__ import annotations

import json

import click

from apygis.cli._common import run_guarded


@click.command()
@click.option("--json", "as_json", is_flag=True, help="One JSON object instead of a table.")
@run_guarded
def formats(as_json: bool) -> None:
    """List the format drivers: name, modes (r read, w write), extensions."""
    from apygis.formats import drivers

    drvs = drivers()
    if as_json:
        click.echo(
            json.dumps(
                {
                    d.name: {
                        "modes": d.modes,
                        "extensions": list(d.extensions),
                        "description": d.description,
                    }
                    for d in drvs.values()
                }
            )
        )
        return
    click.echo(f"{'driver':<10} {'modes':<5} {'extensions':<16} description")
    for d in drvs.values():
        exts = " ".join(f".{e}" for e in d.extensions) or "-"
        click.echo(f"{d.name:<10} {d.modes:<5} {exts:<16} {d.description}")
