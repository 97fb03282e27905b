"""Shared test fixtures: the paper's tables as the package ships them (no folder outside the clone), the
shared study runs, and the grouping of the tests for two worker processes (``pytest -n 2 --dist loadgroup``,
pytest-xdist; see :func:`pytest_collection_modifyitems`)."""
from __future__ import annotations

from pathlib import Path

import pytest

import rvpaper

# ---------------------------------------------------------------------------------------------- test groups
#: Session fixtures that solve many cases: every module using one runs on the same worker, so each is made once.
SHARED_SESSION_FIXTURES = ("small_study", "doe_reference")
#: Modules that solve the same screening (the loop's run conditions on the paper's reducer) share a worker,
#: so rvcalib's forward runner solves it once (its in-memory cache).
SHARED_MODULES = (("test_calib_loop", "test_calib_failure_modes"),)
#: Groups handed out first, the longest first (longest-first keeps both workers busy to the end); the rest
#: follow in collection order. Names are modules or the merged groups (``study``, ``calib``).
HEAVY_FIRST = ("calib", "study", "test_stackup_mc", "test_rvcad_export", "test_stackup_reducer", "test_calib_design",
               "test_paper_readings", "test_stackup_failures")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "xdist_group(name): tests run on one pytest-xdist worker (--dist loadgroup)")


def _group_names(items: list[pytest.Item]) -> dict[str, str]:
    """Module name -> group: the module itself, ``calib`` for :data:`SHARED_MODULES`, ``study`` for the
    modules using a :data:`SHARED_SESSION_FIXTURES` fixture."""
    group = {}
    for it in items:
        mod = it.path.stem
        if any(f in it.fixturenames for f in SHARED_SESSION_FIXTURES):
            group[mod] = "study"
        else:
            group.setdefault(mod, mod)
    for i, mods in enumerate(SHARED_MODULES):
        for m in mods:
            if group.get(m) == m:
                group[m] = "calib" if i == 0 else f"shared{i}"
    return group


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the marks
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test with its group (``xdist_group``, used by ``--dist loadgroup``) and order the tests
    by group, :data:`HEAVY_FIRST` first; within a group the collection order is kept. Without xdist the
    marks do nothing and only the order changes (no test depends on another's order)."""
    group = _group_names(items)
    first = {g: i for i, g in enumerate(HEAVY_FIRST)}
    seen: dict[str, int] = {}
    for it in items:
        g = group[it.path.stem]
        seen.setdefault(g, len(seen))
        it.add_marker(pytest.mark.xdist_group(g))
    items.sort(key=lambda it: (first.get(group[it.path.stem], len(first)), seen[group[it.path.stem]]))


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
