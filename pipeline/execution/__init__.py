"""Execution of many-task jobs on Dask: a local cluster or an existing scheduler, results in
job order, progress on stderr."""

from .executor import (BLAS_ENV, THREADS_VAR, WORKER_ENV, ProgressDisplay, available_cores, dask_client,
                       default_workers, run_tasks, runs_here, worker_count)

__all__ = ["BLAS_ENV", "THREADS_VAR", "WORKER_ENV", "ProgressDisplay", "available_cores", "dask_client",
           "default_workers", "run_tasks", "runs_here", "worker_count"]
