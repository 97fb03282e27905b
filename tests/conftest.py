"""Shared test fixtures: paths to the shared reference data."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Folder of the paper's tables as CSV (../shared/data)."""
    p = SHARED / "data"
    if not p.is_dir():
        pytest.fail(f"shared data folder {p} is missing")
    return p
