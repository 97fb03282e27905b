"""Shared test fixtures: the paper's tables as the package ships them (no folder outside the clone)."""
from __future__ import annotations

from pathlib import Path

import pytest

import rvpaper


@pytest.fixture(scope="session")
def paper_data() -> Path:
    """Folder of the paper's tables as CSV (package data of :mod:`rvpaper`)."""
    return rvpaper.DATA_DIR
