import json
from pathlib import Path

import numpy as np
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
