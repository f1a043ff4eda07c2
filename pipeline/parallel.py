"""The old pool's name, kept for the modules not yet moved to :mod:`pipeline.executor`.

``spawn_pool(workers)`` is now :func:`pipeline.executor.task_pool`: a ``concurrent.futures``
executor backed by a Dask client on a local cluster (one BLAS thread a worker). Remove this
module once nothing imports it.
"""

from __future__ import annotations

from pipeline.executor import task_pool as spawn_pool

__all__ = ["spawn_pool"]
