"""The one executor of every job of many tasks: Dask (``dask.distributed``).

A job of many independent tasks (the Monte Carlo study's chunks of trials, a fleet's machines,
the blind suite's recordings) runs on a Dask cluster:

* by default a **local cluster** started for the job: ``workers`` processes on this machine, one
  thread each, each computing on one core (:data:`WORKER_ENV`, set before the worker starts:
  ``OPENBLAS_NUM_THREADS`` / ``OMP_NUM_THREADS`` / ``MKL_NUM_THREADS`` = 1 for BLAS, and
  :data:`THREADS_VAR` = 1 for this package's own threads, the MuJoCo testbed's ``mujoco.rollout``
  (:func:`pipeline.testbed.available_cores`): a worker using every core would leave none to the
  others, and several multi-threaded workers on a few cores thrash);
* or an **existing cluster** (``scheduler="tcp://host:8786"``, the ``--scheduler`` flag), started
  with ``dask scheduler`` and ``dask worker ADDRESS --nthreads 1`` on machines where this package is installed (Dask's
  worker sets the BLAS variables to 1; set :data:`THREADS_VAR` = 1 in the workers' environment too,
  e.g. ``PARALLEL_CALIB_THREADS=1 dask worker ...``, when a node runs one worker per core);
* or, with one worker and no scheduler, **this process**, one task after another (no cluster to
  start: the cheapest for small jobs and the one debuggers and profilers see).

The tasks are plain functions of plain data, seeded by the task (never by the worker or the order
they finish in), so every way of running a job gives the same numbers. Results come back as each
task finishes (:func:`run_tasks`), which is what lets a fleet write each machine's row as it lands.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Iterable, Iterator

__all__ = ["BLAS_ENV", "THREADS_VAR", "WORKER_ENV", "dask_client", "run_tasks", "task_pool", "add_executor_arguments",
           "default_workers"]

#: One BLAS thread.
BLAS_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: The threads this package's own multi-threaded code may run in this process (the testbed's
#: rollout; :func:`pipeline.testbed.available_cores`); unset: every core the process may use.
THREADS_VAR = "PARALLEL_CALIB_THREADS"
#: Set in every local worker before it starts: each worker computes on one core.
WORKER_ENV = {**BLAS_ENV, THREADS_VAR: "1"}


def default_workers() -> int:
    """The local cluster's default size: the cores of this machine."""
    return os.cpu_count() or 1


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None):
    """A ``distributed.Client``: on the cluster at ``scheduler``, or on a local cluster started here.

    Args:
        workers: local cluster size (processes, one thread each, computing on one core); default the
            cores of this machine. Ignored with ``scheduler``.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``), or None.

    The local cluster's logs are quiet; its dashboard (with ``bokeh`` installed) listens on a free
    port of this machine only (``client.dashboard_link``). It is closed, and this process's
    environment restored (Dask's nanny sets the worker variables in the parent before it
    spawns), when the block ends.
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    workers = int(workers or default_workers())
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    saved = dict(os.environ)
    try:
        environ = {f"distributed.nanny.pre-spawn-environ.{k}": v for k, v in WORKER_ENV.items()}
        with dask.config.set(environ):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
        with cluster, Client(cluster) as client:
            yield client
    finally:
        for k in set(os.environ) - set(saved):
            os.environ.pop(k, None)
        os.environ.update(saved)


def run_tasks(fn: Callable, jobs: Iterable, *, workers: int | None = None, scheduler: str | None = None,
              client=None, progress: Callable[[int, int], None] | None = None) -> Iterator[tuple[int, object]]:
    """Run ``fn(job)`` for every job; yield ``(index, result)`` as each task finishes.

    Args:
        fn: a function importable by name in the workers (a module-level function of this package).
        jobs: the tasks' plain-data arguments.
        workers: processes of the local cluster; 1 (and no ``scheduler`` nor ``client``) runs the
            tasks here, in order. Default: the cores of this machine.
        scheduler: address of an existing Dask cluster.
        client: an open ``distributed.Client`` to use (its cluster stays up afterwards).
        progress: ``progress(done, total)`` after each finished task.

    A task that raises stops the job with its exception (the tasks not yet run are cancelled);
    a job that must go on past a bad input catches the error in ``fn`` and returns it as data.
    """
    jobs = list(jobs)
    total = len(jobs)
    if workers is not None and int(workers) < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if client is None and not scheduler and (workers or default_workers()) == 1:
        for i, job in enumerate(jobs):
            result = fn(job)
            if progress:
                progress(i + 1, total)
            yield i, result
        return
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(dask_client(workers, scheduler))
        yield from _as_completed(client, fn, jobs, progress)


def _as_completed(client, fn, jobs, progress):
    from distributed import as_completed

    # pure=False: two equal jobs are two tasks (a job's result is never shared by key).
    futures = client.map(fn, jobs, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    done = 0
    try:
        for future in as_completed(futures):
            result = future.result()
            done += 1
            if progress:
                progress(done, len(jobs))
            yield index[future.key], result
            future.release()
    finally:
        client.cancel([f for f in futures if not f.done()])


@contextlib.contextmanager
def task_pool(workers: int | None = None, scheduler: str | None = None):
    """A ``concurrent.futures.Executor`` (``submit``, ``map`` in order) backed by a Dask client.

    For code written against a process pool: ``with task_pool(2) as pool: pool.map(f, xs)``.
    """
    with dask_client(workers, scheduler) as client:
        executor = client.get_executor(pure=False)
        try:
            yield executor
        finally:
            executor.shutdown(wait=True)


def add_executor_arguments(parser) -> None:
    """``--workers N`` and ``--scheduler ADDRESS`` (the executor of a many-task command)."""
    parser.add_argument("--workers", type=int, default=None,
                        help="processes of the local Dask cluster (default: all cores; 1: run here, "
                             "no cluster)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run on an existing Dask cluster (e.g. tcp://host:8786) instead of a local one")
