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
