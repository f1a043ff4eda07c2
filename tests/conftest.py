import json
from pathlib import Path

import numpy as np
import pytest

REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference" / "hexapod_paper_tables.json"


@pytest.fixture(scope="session")
def reference_tables() -> dict:
    """The team's independent hand transcription of the paper's tables (shared/reference)."""
    assert REFERENCE.exists(), f"reference tables not found at {REFERENCE} (shared/ must sit beside the repo)"
    return json.loads(REFERENCE.read_text())


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
