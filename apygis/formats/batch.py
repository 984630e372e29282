"""Convert many map files: one process per job, a result per file, no file lost.

>>> from apygis.formats.batch import output_name
>>> output_name("in/sheet.apa", "apy"), output_name("in/ZH1091", "ascii")
('sheet', 'ZH1091.apa')
>>> output_name("in/ZH1091.c", "ascii"), output_name("in/ZH1091.c", "apy")
('ZH1091.c.apa', 'ZH1091.c')
"""

from __future__ import annotations

import glob
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from apygis.errors import ApygisError, FileOverwriteError
from apygis.progress import STEPS, Progress, phase

__all__ = ["Result", "convert_file", "convert_many", "expand_sources", "output_name"]

log = logging.getLogger(__name__)


@dataclass
class Result:
    """What happened to one source: the files written, or why it failed.

    ``warnings`` are the reader's messages about the source (entities
    skipped, records renumbered: :mod:`apygis.formats._report`).
    """

    source: str
    outputs: list[str] = field(default_factory=list)
    records: int = 0
    layers: int = 0
    error: str | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.error is None


def expand_sources(patterns: Iterable[str]) -> list[str]:
    """Files and globs, expanded and de-duplicated in the order given.

    A pattern with ``*``, ``?`` or ``[`` that matches nothing is kept as it
    is, so that its conversion fails with "no such file" rather than being
    silently skipped.
    """
    out: list[str] = []
    for pat in patterns:
        hits = sorted(glob.glob(pat)) if glob.has_magic(pat) else [pat]
        for h in hits or [pat]:
            if h not in out:
                out.append(h)
    return out


def output_name(source: str, to_driver: str) -> str:
    """The output file name for ``source`` converted by ``to_driver``.

    A source extension that names a known format is replaced by the output
    driver's first extension; any other (an APY layer extension such as
    ``.c``) is kept, so that the layers of one map do not collide.
    """
    from apygis.formats import drivers, get_driver

    p = Path(source.rstrip("/\\") or source)
    known = {e for d in drivers().values() for e in d.extensions}
    base = p.stem if p.suffix[1:].lower() in known else p.name
    exts = get_driver(to_driver).extensions
    return f"{base}.{exts[0]}" if exts else base


def convert_file(
    src: str,
    dst: str,
    *,
    src_driver: str | None = None,
    driver: str | None = None,
    overwrite: bool = False,
    to_crs=None,
    read_options: dict | None = None,
    write_options: dict | None = None,
    progress: Progress | None = None,
) -> Result:
    """Convert one file; errors a user can cause come back in ``Result.error``.

    ``read_options`` and ``write_options`` go to the reader and the writer;
    one they do not take is an error (``Result.error``), never dropped.
    ``progress(done, total)`` (:mod:`apygis.progress`) with ``total``
    :data:`~apygis.progress.STEPS`: reading is the first half, writing the
    second (as far as the drivers report progress); the last call, on
    success, is ``(STEPS, STEPS)``.
    """
    import apygis
    from apygis.formats import driver_for, get_driver

    def step(index):
        cb = phase(progress, index, 2)
        return {} if cb is None else {"progress": cb}

    writing = False
    try:
        in_drv = get_driver(src_driver, "r") if src_driver else driver_for(src, "r")
        m = apygis.read(src, driver=in_drv.name, **(read_options or {}), **step(0))
        notes = [w.message for w in m.read_warnings]
        if to_crs is not None:
            from apygis.errors import CRSError
            from apygis.model.reproject import reproject

            if m.crs is None:
                raise CRSError(
                    f"{src}: the map has no CRS, so it cannot be reprojected to {to_crs} "
                    "(assign its CRS with --src-crs)"
                )

            m = reproject(m, to_crs)
        out_drv = get_driver(driver, "w") if driver else driver_for(dst, "w")
        out_drv.check_options("w", write_options or {})
        if not overwrite:
            existing = [str(p) for p in out_drv.targets(m, dst) if p.exists()]
            if existing:
                what = (
                    existing[0]
                    if len(existing) == 1
                    else (
                        f"{existing[0]} and {len(existing) - 1} more files"
                        if len(existing) > 3
                        else ", ".join(existing)
                    )
                )
                verb = "exists" if len(existing) == 1 else "exist"
                raise FileOverwriteError(f"{what} {verb}; use --overwrite")
        writing = True
        written = apygis.write(m, dst, driver=out_drv.name, **(write_options or {}), **step(1))
        if progress is not None:
            progress(STEPS, STEPS)
        return Result(
            src,
            [str(p) for p in written],
            sum(len(lay) for lay in m),
            len(m.layers),
            warnings=notes,
        )
    except ApygisError as exc:
        return Result(src, error=str(exc))
    except OSError as exc:  # name the file the error is about: the target once writing
        from apygis.formats._io import write_failed

        if writing:
            return Result(src, error=str(write_failed(dst, exc)))
        reason = (exc.strerror or str(exc)).lower()
        return Result(src, error=f"{exc.filename or src}: cannot read: {reason}")


def _convert_task(src: str, dst: str, kwargs: dict) -> Result:
    """One conversion as a task of :class:`apygis.tasks.Runner` (a worker process or node).

    The worker logs nothing itself: what the reader reported comes back in
    ``Result.warnings``, which the caller reports with the file.
    """
    logging.getLogger("apygis").setLevel(logging.ERROR)
    return convert_file(src, dst, **kwargs)


def convert_many(
    sources: Iterable[str],
    outdir,
    to_driver: str,
    *,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: Progress | None = None,
    on_result: Callable[[Result], None] | None = None,
    **kwargs,
) -> list[Result]:
    """Convert every source into ``outdir`` with ``to_driver``; one failure stops nothing.

    Parameters
    ----------
    sources : iterable of str
        Files (or APY ``dir/ID`` names); see :func:`expand_sources` for globs.
    outdir : path
        The output folder, created if missing.
    to_driver : str
        Output driver name.
    jobs : int
        Local worker processes (1: convert in this process).
    scheduler : str, optional
        A Dask scheduler address (``tcp://host:8786``): the conversions run on
        that cluster, through :class:`apygis.tasks.Runner` as the
        aerotriangulation's tasks do; its workers must see the files under the
        same paths. ``jobs`` is then ignored.
    progress : Progress, optional
        ``progress(done, total)`` as each source is finished, ``total`` the
        number of sources (:mod:`apygis.progress`).
    on_result : callable, optional
        Called with each :class:`Result` as it completes (before ``progress``).
    **kwargs
        Passed to :func:`convert_file` (``overwrite``, ``src_driver``,
        ``to_crs``, ``read_options``, ``write_options``).

    Returns
    -------
    list of Result, in the order of ``sources``. Two sources that would give
    the same output name are not both written (the second fails, naming the
    first), and an existing output is not replaced without ``overwrite``.
    """
    from apygis.formats import get_driver
    from apygis.tasks import Runner

    get_driver(to_driver, "w")  # fail early on a bad name
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    sources = list(sources)
    targets: dict[str, str] = {}
    results: dict[int, Result] = {}
    plan = []

    def done(i, res):
        results[i] = res
        if on_result:
            on_result(res)
        if progress:
            progress(len(results), len(sources))

    for i, src in enumerate(sources):
        name = output_name(src, to_driver)
        if name in targets:
            done(i, Result(src, error=f"output {name} would collide with {targets[name]}"))
            continue
        targets[name] = src
        plan.append((i, src, str(outdir / name)))

    kw = {**kwargs, "driver": to_driver}
    if scheduler is None and (jobs <= 1 or len(plan) <= 1):
        for i, src, dst in plan:
            done(i, convert_file(src, dst, **kw))
        return [results[i] for i in range(len(sources))]
    runner = Runner(scheduler or "processes", workers=None if scheduler else jobs)
    with runner:
        tasks = [(i, (src, dst, kw)) for i, src, dst in plan]
        for i, res in runner.run(_convert_task, tasks, return_exceptions=True):
            if isinstance(res, BaseException):  # a worker died: report, go on with the others
                res = Result(sources[i], error=f"{type(res).__name__}: {res}")
            done(i, res)
    return [results[i] for i in range(len(sources))]
