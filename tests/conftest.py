"""Shared test fixtures: the paper's tables as the package ships them (no folder outside the clone)."""
from __future__ import annotations

from pathlib import Path

import pytest

import rvpaper


@pytest.fixture(scope="session")
def paper_data() -> Path:
    """Folder of the paper's tables as CSV (package data of :mod:`rvpaper`)."""
    return rvpaper.DATA_DIR


# ---------------------------------------------------------------------------------------------- shared study runs
#: Steps per output revolution of the study runs in the tests (analytic solver; fast, undersampled).
STUDY_STEPS = 24
#: ``rv-stackup`` options of the design stage alone: 27 runs, 25 unique cases, in this process.
DOE_ARGV = ["--solver", "analytic", "--steps", str(STUDY_STEPS), "--workers", "1", "--stages", "doe",
            "--no-progress", "--no-figures"]
#: Every stage with small counts, figures included.
SMALL_STUDY_ARGV = ["--solver", "analytic", "--steps", str(STUDY_STEPS), "--workers", "1", "--sweep-points", "3",
                    "--validation-cases", "4", "--mc-check", "1", "--mc-draws", "6", "--mc-sobol", "2",
                    "--no-progress"]


def _run_stackup(argv: list[str]) -> str:
    import contextlib
    import io

    from rvstudy import cli

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert cli.main(argv) == 0
    return buf.getvalue()


@pytest.fixture(scope="session")
def doe_reference(tmp_path_factory) -> tuple[Path, dict]:
    """One uninterrupted ``rv-stackup`` design-stage run from an empty cache, shared by the study tests:
    (output folder, its JSON summary). Tests that change files work on a copy."""
    import json

    out = tmp_path_factory.mktemp("doe_reference")
    return out, json.loads(_run_stackup(["--out", str(out), *DOE_ARGV, "--json"]))


@pytest.fixture(scope="session")
def small_study(tmp_path_factory) -> tuple[Path, str]:
    """One ``rv-stackup`` run of every stage with small counts and figures: (output folder, printed summary)."""
    out = tmp_path_factory.mktemp("small_study") / "run"
    return out, _run_stackup(["--out", str(out), *SMALL_STUDY_ARGV])
