"""``apygis validate``: the validation report; exit code 1 when the map has errors."""

from __future__ import annotations

import sys

import click

from apygis.cli._common import run_guarded


@click.command()
@click.argument("path", type=click.Path())
@click.option("--driver", help="Read with this driver instead of guessing.")
@run_guarded
def validate(path: str, driver: str | None) -> None:
    """Check references, numbers and codes of every layer of a map.

    Prints one line per finding. Exit code 0: valid (warnings allowed);
    1: errors found (or the file cannot be read).
    """
    import apygis

    m = apygis.read(path, driver=driver)
    n_err = n_warn = 0
    for ext in sorted(m.layers):
        for issue in m.layers[ext].validate():
            click.echo(f"{path}: layer {ext}: {issue.severity}: {issue.message}")
            n_err += issue.severity == "error"
            n_warn += issue.severity == "warning"
    verdict = "valid" if n_err == 0 else "INVALID"
    click.echo(f"{path}: {verdict}: {n_err} errors, {n_warn} warnings in {len(m.layers)} layers")
    if n_err:
        sys.exit(1)
