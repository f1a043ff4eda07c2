"""The Dask executor (pipeline.executor): results as tasks finish, errors, the concurrent.futures pool."""

import math
import os

import pytest

from pipeline.executor import THREADS_VAR, WORKER_ENV, run_tasks, task_pool


def worker_threads(_):
    from pipeline.testbed import available_cores

    return {k: os.environ.get(k) for k in WORKER_ENV}, available_cores()


def fails_on_three(x):
    if x == 3:
        raise ValueError("three")
    return x


def test_run_tasks_here_and_on_a_cluster(dask_two_workers):
    seen = []
    here = list(run_tasks(math.sqrt, [1, 4, 9], workers=1, progress=lambda d, t: seen.append((d, t))))
    assert here == [(0, 1.0), (1, 2.0), (2, 3.0)] and seen == [(1, 3), (2, 3), (3, 3)]
    there = sorted(run_tasks(math.sqrt, [1, 4, 9, 16, 25], client=dask_two_workers))
    assert there == [(0, 1.0), (1, 2.0), (2, 3.0), (3, 4.0), (4, 5.0)]
    # By the scheduler's address, as --scheduler does.
    assert sorted(run_tasks(math.sqrt, [4, 9], scheduler=dask_two_workers.scheduler.address)) == [(0, 2.0), (1, 3.0)]
    # Every worker computes on one core: one BLAS thread, one thread of the testbed's rollout.
    for _, (env, cores) in run_tasks(worker_threads, range(4), client=dask_two_workers):
        assert env == WORKER_ENV and cores == 1


def test_available_cores_honours_the_thread_limit(monkeypatch):
    from pipeline.testbed import available_cores

    monkeypatch.delenv(THREADS_VAR, raising=False)
    every = available_cores()
    monkeypatch.setenv(THREADS_VAR, "1")
    assert available_cores() == 1
    monkeypatch.setenv(THREADS_VAR, "64")
    assert available_cores() == every
    for bad in ("0", "two"):
        monkeypatch.setenv(THREADS_VAR, bad)
        with pytest.raises(ValueError, match=THREADS_VAR):
            available_cores()


def test_a_failing_task_stops_the_job(dask_two_workers):
    with pytest.raises(ValueError, match="three"):
        list(run_tasks(fails_on_three, range(6), client=dask_two_workers))
    with pytest.raises(ValueError, match="workers must be >= 1"):
        list(run_tasks(math.sqrt, [1], workers=0))


def test_task_pool_is_a_concurrent_futures_executor():
    """What the modules written against a process pool (pipeline.blind) get."""
    with task_pool(1) as pool:
        assert list(pool.map(math.sqrt, [9, 1, 4])) == [3.0, 1.0, 2.0]
        assert pool.submit(math.factorial, 5).result() == 120
