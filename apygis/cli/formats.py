"""``apygis formats``: the drivers, their modes, extensions and options."""

from __future__ import annotations

import json

import click

from apygis.cli._common import run_guarded


def _option_dict(o) -> dict:
    return {
        "name": o.name.upper(),
        "mode": o.mode,
        "kind": o.kind,
        "choices": list(o.choices),
        "flag": o.flag,
        "help": o.help,
    }


@click.command()
@click.option("--json", "as_json", is_flag=True, help="One JSON object instead of a table.")
@click.option(
    "--options", "with_options", is_flag=True, help="Also list each driver's --co options."
)
@run_guarded
def formats(as_json: bool, with_options: bool) -> None:
    """List the format drivers: name, modes (r read, w write), extensions.

    With --options, the options each reader (r) and writer (w) takes: given
    as --co NAME=VALUE, or by the command-line option named with it.
    """
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
                        "stdout": d.stream,
                        "options": [_option_dict(o) for o in d.options],
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
        if with_options:
            for o in d.options:
                how = o.flag or f"--co {o.name.upper()}=" + (
                    "|".join(o.choices) if o.choices else o.kind.upper()
                )
                click.echo(f"{'':<11}{o.mode}  {how:<34} {o.help}")
