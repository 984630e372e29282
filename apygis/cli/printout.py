"""``apygis printout``: the APY print-out of a map file, as text or as a PDF."""

from __future__ import annotations

import click

from apygis.cli._common import map_input_options, progress_bar, read_map, run_guarded


@click.command()
@click.argument("path", type=click.Path())
@click.option(
    "-o",
    "--output",
    type=click.Path(),
    help="Write to this file instead of stdout (.pdf: A4 pages in DejaVu Sans Mono).",
)
@map_input_options
@click.option("--library", type=click.Path(), help="Symbol library for the names.")
@click.option("--overwrite", is_flag=True, help="Replace an existing output file.")
@run_guarded
def printout(path, output, library, overwrite, src):
    """Symbol legend, symbols by code, line points with references, and texts.

    With -o NAME.pdf the print-out is a PDF of numbered A4 pages in a
    monospaced font (DejaVu Sans Mono, embedded: any script it covers comes
    out right); any other name gets plain UTF-8 text.
    """
    from pathlib import Path

    from apygis.errors import FileOverwriteError
    from apygis.formats._io import atomic_write_many
    from apygis.model.symbols import load_library
    from apygis.plot.printout import printout_text

    m, _ = read_map(path, src)
    text = printout_text(m, load_library(library))
    if output is None:
        click.echo(text, nl=False)
        return
    if Path(output).exists() and not overwrite:
        raise FileOverwriteError(f"{output} exists; use --overwrite to replace it")
    if Path(output).suffix.lower() == ".pdf":
        from apygis.plot.pdf import text_pages, text_pages_pdf
        from apygis.progress import STEPS, fraction

        with progress_bar(STEPS, f"print-out of {m.id}") as bar:

            def advance(done: int, total: int) -> None:
                bar.update(round(STEPS * fraction(done, total)) - bar.pos)

            data = text_pages_pdf(text, title=f"APY print-out {m.id}", progress=advance)
        atomic_write_many({Path(output): data})
        n = len(text_pages(text))
        click.echo(f"print-out of {m.id} written to {output} ({n} A4 pages)")
        return
    atomic_write_many({Path(output): text.encode("utf-8")})
    click.echo(f"print-out of {m.id} written to {output}")
