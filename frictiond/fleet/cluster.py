"""Dask as a `concurrent.futures.Executor`, for fleet replays and any other batch job.

Needs the `fleet` extra (`pip install 'frictiond[fleet]'`); dask is imported only when a function
here is called, so importing this module costs nothing.
"""
from __future__ import annotations

import contextlib
import logging
import os
from typing import Any, Iterator


@contextlib.contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[Any]:
    """A `distributed.Client`: on the cluster at `scheduler` (e.g. "tcp://HOST:8786"), or on an
    embedded local cluster of `workers` processes (default: one per core) started here and shut
    down on exit. `workers` is ignored with a scheduler (the cluster has its own)."""
    problem = missing_extra()
    if problem is not None:
        raise ImportError(problem)
    from distributed import Client, LocalCluster

    _quiet_dask()
    if scheduler:
        client = Client(scheduler, timeout="30s")
        try:
            yield client
        finally:
            client.close()
        return
    import dask

    n_workers = workers if workers and workers > 0 else (os.cpu_count() or 1)
    # One single-threaded process per worker: the replay is CPU-bound Python (the GIL would
    # serialise threads); no dashboard (an HTTP port nobody asked for); Dask's own INFO lines
    # about starting workers are noise on a command's stderr. The workers' statistical profiler
    # (a stack sample of the running task every 10 ms, for the dashboard nobody sees) is off: it
    # takes the GIL from CPU-bound tasks (the nannies pass this config on to the workers).
    # Nor do the workers' allocators hand freed memory back to the OS at every 64 KiB (Dask's
    # MALLOC_TRIM_THRESHOLD_, meant for workers holding large arrays): a replay allocates and
    # frees small objects all the time, and the trimming cost its workers 7-9 % more CPU per log
    # than the same replay in a plain process (measured with benchmarks/fleet.py).
    with dask.config.set({"distributed.worker.profile.enabled": False,
                          "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": str(256 << 20)}):
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
    with cluster, Client(cluster) as client:
        yield client


def _quiet_dask() -> None:
    """Dask's loggers at CRITICAL unless frictiond runs with -v: its INFO lines on starting and
    stopping workers, and a benign race at shutdown logged with a traceback, are noise on a
    command's stderr; a task's real failure reaches the caller through its future."""
    if logging.getLogger().getEffectiveLevel() >= logging.WARNING:
        for name in ("distributed", "dask"):
            logging.getLogger(name).setLevel(logging.CRITICAL)


@contextlib.contextmanager
def open_executor(scheduler: str | None = None, workers: int | None = None) -> Iterator[Any]:
    """A `concurrent.futures.Executor` backed by Dask, for the duration of the `with` block.

    Contract, for any batch job (fleet replay, the randomised campaign):
    - `scheduler=None`: an embedded local cluster is started (`workers` single-threaded worker
      processes, default one per core: `processes=True`, one thread each) and shut down when the
      block exits; nothing to install or start beforehand beyond the `fleet` extra.
    - `scheduler="tcp://HOST:8786"`: the existing cluster is used as it is (`workers` ignored);
      its workers must have the same frictiond installed and see the same file paths.
    - `submit(fn, *args)` returns a `concurrent.futures.Future`; `fn` and its arguments must be
      picklable (module-level functions, plain data), as with `ProcessPoolExecutor`. Each call is
      one Dask task (not memoised: the same call twice runs twice); a task whose worker process
      dies is retried by Dask and at last raises (`distributed.KilledWorker`) from `result()`.
    - `map` and `concurrent.futures.wait`/`as_completed` work as with the standard executors.
    - Leaving the block shuts the executor down, cancelling what has not run; tasks still
      running on a remote cluster are released.
    Raises ImportError (naming the `fleet` extra) when dask is not installed, OSError/TimeoutError
    when the scheduler cannot be reached.
    """
    with open_client(scheduler, workers) as client:
        executor = client.get_executor()
        try:
            yield executor
        finally:
            executor.shutdown(wait=False)


def worker_count(client: Any) -> int:
    """Workers the client's scheduler has now."""
    return len(client.scheduler_info().get("workers", {}))


def missing_extra() -> str | None:
    """None when the `fleet` extra is installed, else the one-line message to show."""
    try:
        import distributed  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError as exc:
        return (f"fleet needs the 'fleet' extra ({exc.name or 'dask/pyarrow'} is not installed): "
                "pip install 'frictiond[fleet]'")
    return None
