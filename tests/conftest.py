import json
import os
from pathlib import Path

# One BLAS thread: timings measured by the tests (the outlier test's <= 1 s) are those of one core,
# not of threads fighting over a shared machine. Set before numpy loads; an explicit setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pytest

REFERENCE = Path(__file__).resolve().parent / "data" / "hexapod_paper_tables.json"


@pytest.fixture(scope="session")
def reference_tables() -> dict:
    """The team's independent hand transcription of the paper's tables (tests/data)."""
    assert REFERENCE.exists(), f"reference tables not found at {REFERENCE}"
    return json.loads(REFERENCE.read_text())


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="module")
def dask_two_workers():
    """A Dask client on a local cluster of two worker processes (one thread, one BLAS thread
    each), started once a module for the tests that need it (starting and closing one: about 1.7
    s of CPU) and closed at the module's end: an idle cluster takes about 0.14 s of CPU a second
    (heartbeats), which a session's cluster spent for the rest of its xdist worker's run."""
    from pipeline.execution import dask_client

    with dask_client(2) as client:
        yield client


def pytest_configure(config):
    """Under pytest-xdist (``-n``) without a ``--dist`` of the caller's, work stealing
    (``--dist worksteal``) instead of xdist's default ``load``: a worker that runs out of tests
    takes half of another's queue. Set here, not in ``addopts``, so that pytest without xdist (or
    with ``-p no:xdist``) still runs."""
    chosen = [*config.invocation_params.args, *os.environ.get("PYTEST_ADDOPTS", "").split()]
    if getattr(config.option, "dist", "no") == "load" and not any(
            a == "--dist" or a.startswith("--dist=") or a == "-d" for a in chosen):
        config.option.dist = "worksteal"


def pytest_collection_modifyitems(config, items):
    """The modules holding slow tests first, each module's tests kept together and in their order:
    under pytest-xdist (``--dist worksteal``, :func:`pytest_configure`) the long tests start first
    and the short ones fill the other cores' time at the end, instead of one long test running
    alone last."""
    slow_modules = {item.module.__name__ for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.module.__name__ not in slow_modules)
