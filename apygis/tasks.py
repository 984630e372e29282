"""Independent tasks run in this process, in local worker processes, or on a Dask cluster.

``Runner(scheduler)`` with ``scheduler``:

* ``"sync"``: one after the other in this process (tests, debugging, tiny blocks);
* ``None`` / ``"processes"``: a local Dask cluster of worker processes, one
  thread each (``workers`` processes; default: the machine's cores);
* ``"tcp://host:port"`` (any Dask scheduler address): the same tasks on that
  cluster; the workers must see the image files under the same paths.

:meth:`Runner.run` yields ``(key, result)`` as tasks finish, in the calling
process, so that the caller commits each result to the block as it arrives:
an interrupted run keeps everything finished so far. A task that raises stops
the run with that error (the remaining tasks are cancelled).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterable, Iterator
from typing import Any

__all__ = ["Runner"]

log = logging.getLogger(__name__)


class Runner:
    """Runs tasks (see the module docstring); a context manager."""

    def __init__(self, scheduler: str | None = None, workers: int | None = None):
        self.scheduler = scheduler or "processes"
        self.workers = workers
        self._client: Any = None
        self._cluster: Any = None

    def __enter__(self) -> Runner:
        if self.scheduler == "sync":
            return self
        from distributed import Client, LocalCluster

        # Dask's own INFO lines (scheduler, nanny, dashboard) are not the user's business
        for name in ("distributed", "dask", "bokeh", "tornado"):
            logging.getLogger(name).setLevel(logging.WARNING)
        if self.scheduler == "processes":
            import dask

            n = self.workers or os.cpu_count() or 1
            # Dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which fixes glibc's
            # mmap threshold at 128 KiB: every larger numpy temporary is then mapped and
            # unmapped afresh, and least-squares matching ran 2.8 times slower. The workers
            # keep one BLAS thread each; Dask also leaves these variables in this process's
            # environment, for every process started later: they are put back.
            environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
            environ.pop("MALLOC_TRIM_THRESHOLD_", None)
            saved = dict(os.environ)
            try:
                with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
                    self._cluster = LocalCluster(
                        n_workers=n,
                        threads_per_worker=1,
                        processes=True,
                        host="127.0.0.1",
                        dashboard_address=None,
                        worker_dashboard_address=None,
                        scheduler_kwargs={"dashboard": False},
                        silence_logs=logging.ERROR,
                    )
            finally:
                for key in set(os.environ) - set(saved):
                    if key.startswith("__DASK") or key == "PYTHONHASHSEED":
                        continue  # Dask's own bookkeeping for its processes
                    del os.environ[key]
                os.environ.update({k: v for k, v in saved.items() if os.environ.get(k) != v})
            self._client = Client(self._cluster)
        else:
            self._client = Client(self.scheduler, timeout="30s")
        log.info("dask: %s", self._client)
        return self

    def __exit__(self, *exc) -> None:
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._client = self._cluster = None

    def run(
        self,
        fn: Callable[..., Any],
        tasks: Iterable[tuple[Any, tuple]],
        return_exceptions: bool = False,
    ) -> Iterator[tuple[Any, Any]]:
        """``fn(*args)`` for each ``(key, args)``; yields ``(key, result)`` as they finish.

        With ``return_exceptions``, a task that raises (or whose worker died)
        yields ``(key, exception)`` and the others go on; otherwise the run
        stops with that error.
        """
        if self._client is None:
            for key, args in tasks:
                try:
                    result = fn(*args)
                except Exception as exc:
                    if not return_exceptions:
                        raise
                    result = exc
                yield key, result
            return
        from distributed import as_completed

        futures = {}
        for key, args in tasks:
            fut = self._client.submit(fn, *args, pure=False)
            futures[fut] = key
        if not futures:
            return
        try:
            for fut in as_completed(list(futures)):
                try:
                    result = fut.result()
                except Exception as exc:
                    if not return_exceptions:
                        raise
                    result = exc
                yield futures[fut], result
        finally:
            pending = [f for f in futures if not f.done()]
            if pending:
                self._client.cancel(pending)
