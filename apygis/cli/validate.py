"""``apygis validate``: the validation report; exit code 1 when the map has errors."""

from __future__ import annotations

import json
import sys

import click

from apygis.cli._common import map_input_options, read_map, run_guarded


@click.command()
@click.argument("path", type=click.Path())
@map_input_options
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="One JSON object: path, valid, errors, warnings, layers, issues.",
)
@run_guarded
def validate(path: str, as_json: bool, src: dict) -> None:
    """Check references, numbers and codes of every layer of a map.

    Prints one line per finding, or with --json one object whose ``issues``
    lists each finding (layer, severity, kind, table, num, message). Exit
    code 0: valid (warnings allowed); 1: errors found (or the file cannot be
    read).
    """
    m, _ = read_map(path, src)
    issues = [(ext, issue) for ext in sorted(m.layers) for issue in m.layers[ext].validate()]
    n_err = sum(i.severity == "error" for _, i in issues)
    n_warn = sum(i.severity == "warning" for _, i in issues)
    if as_json:
        report = {
            "path": path,
            "valid": n_err == 0,
            "errors": n_err,
            "warnings": n_warn,
            "layers": len(m.layers),
            "issues": [
                {
                    "layer": ext,
                    "severity": i.severity,
                    "kind": i.kind,
                    "table": i.table,
                    "num": i.num,
                    "message": i.message,
                }
                for ext, i in issues
            ],
        }
        click.echo(json.dumps(report, ensure_ascii=False))
    else:
        for ext, issue in issues:
            click.echo(f"{path}: layer {ext}: {issue.severity}: {issue.message}")
        verdict = "valid" if n_err == 0 else "INVALID"
        click.echo(
            f"{path}: {verdict}: {n_err} errors, {n_warn} warnings in {len(m.layers)} layers"
        )
    if n_err:
        sys.exit(1)
