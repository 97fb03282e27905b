"""Shared test fixtures: the paper's tables as the package ships them (no folder outside the clone), the
shared study runs, and the grouping of the tests for two worker processes (``pytest -n 2 --dist loadgroup``,
pytest-xdist; see :func:`pytest_collection_modifyitems`)."""
from __future__ import annotations

import os
from pathlib import Path

# One BLAS thread per process: the suite runs in two xdist worker processes on two cores, and OpenBLAS's
# own threads (two per process by default, spinning between calls) oversubscribe them: rvcalib's pinv
# and lstsq calls then take seconds of wall time each under load. Set before numpy is first imported
# (pytest loads this file before it collects a test, in the controller and in each worker; workers and
# subprocesses inherit it); a user's own setting is kept.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest

import rvpaper

@pytest.fixture(scope="session")
def paper_data() -> Path:
    """Folder of the paper's tables as CSV (package data of :mod:`rvpaper`)."""
    return rvpaper.DATA_DIR


# ---------------------------------------------------------------------------------------------- test groups
#: Session fixtures that solve many cases: every module using one runs on the same worker, so each is made once.
SHARED_SESSION_FIXTURES = ("small_study", "doe_reference")
#: Modules whose tests are handed out one by one (or by their own ``xdist_group`` mark) instead of as a
#: module: their scenarios are independent and long.
SPLIT_MODULES = ("test_calib_loop",)
#: Units handed out first, in this order (groups, modules or test names), longest first: pytest-xdist's
#: loadgroup scheduler hands each worker its next unit while it still has up to two tests pending, so a long
#: unit late in the queue would leave the other worker idle at the end. The order holds only without xdist's
#: reordering of the units by their number of tests (switched off in :func:`pytest_configure`).
HEAVY_FIRST = ("study", "calib_loop", "build123d", "calib_standin", "test_fcl_vs_analytic", "test_stackup_mc",
               "test_calib_cli", "test_calib_holdout", "test_rvcad_parts", "test_rvcad_errors", "test_rvdyn_physics",
               "test_stackup_reducer", "test_rvdyn_stiffness", "test_fcl_contacts", "test_stackup_failures",
               "test_rsm_plots", "test_fuzz_loaders")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "xdist_group(name): tests run on one pytest-xdist worker (--dist loadgroup)")
    # pytest-xdist (3.x) hands out the --dist loadgroup units sorted by their number of tests unless told not to
    # (--no-loadscope-reorder): the many quick parametrised checks went first and the long single-test units of
    # the loop last, both workers then screening the same run conditions at the same time. Keep the order of
    # pytest_collection_modifyitems (HEAVY_FIRST) unless the command line asks for the reordering.
    if hasattr(config.option, "loadscopereorder") and "--loadscope-reorder" not in config.invocation_params.args:
        config.option.loadscopereorder = False


def _unit(it: pytest.Item, study_modules: set[str]) -> tuple[str, str]:
    """(group, name to look up in :data:`HEAVY_FIRST`) of a test: its own ``xdist_group`` mark; else
    ``study`` for the modules using a :data:`SHARED_SESSION_FIXTURES` fixture; else the test itself in
    :data:`SPLIT_MODULES`; else its module."""
    mark = it.get_closest_marker("xdist_group")
    mod = it.path.stem
    if mark is not None:
        name = mark.args[0] if mark.args else mark.kwargs.get("name", "default")
        return str(name), str(name)
    if mod in study_modules:
        return "study", "study"
    if mod in SPLIT_MODULES:
        return "", it.originalname
    return mod, mod


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the marks
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the tests with their group (``xdist_group``, used by ``--dist loadgroup``) and order them:
    :data:`HEAVY_FIRST` first, the rest in collection order, a group's tests together in collection
    order. Without xdist the marks do nothing and only the order changes (no test depends on the order)."""
    study_modules = {it.path.stem for it in items if any(f in it.fixturenames for f in SHARED_SESSION_FIXTURES)}
    first = {g: i for i, g in enumerate(HEAVY_FIRST)}
    seen: dict[str, int] = {}
    keys = {}
    for i, it in enumerate(items):
        group, name = _unit(it, study_modules)
        if group and it.get_closest_marker("xdist_group") is None:
            it.add_marker(pytest.mark.xdist_group(group))
        seen.setdefault(name, i)
        keys[it.nodeid] = (first.get(name, len(first)), seen[name], i)
    items.sort(key=lambda it: keys[it.nodeid])


# ---------------------------------------------------------------------------------------------- shared study runs
#: Steps per output revolution of the study runs in the tests (analytic solver; fast, undersampled).
STUDY_STEPS = 24
#: ``rv-stackup`` options of the design stage alone: 27 runs, 25 unique cases, in this process.
DOE_ARGV = ["--solver", "analytic", "--steps", str(STUDY_STEPS), "--workers", "1", "--stages", "doe",
            "--no-progress", "--no-figures"]
#: Every stage with small counts, figures included. The Monte Carlo on the impact law: the tests of this run
#: check the pipeline (stages, tables, figures, report, summary), which is the same under either law, and the
#: impact law costs about a third of the physical one per draw. The physical law (``rv-stackup``'s default)
#: is tested on the Monte Carlo in tests/test_stackup_dask.py (serial, pool and Dask runs, and one draw
#: solved again directly) and as the command line's default in tests/test_stackup.py.
SMALL_STUDY_ARGV = ["--solver", "analytic", "--steps", str(STUDY_STEPS), "--workers", "1", "--sweep-points", "3",
                    "--validation-cases", "4", "--mc-check", "1", "--mc-draws", "6", "--mc-sobol", "2",
                    "--mc-contact", "impact", "--no-progress"]


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
    """One ``rv-stackup`` run of every stage with small counts and figures (the Monte Carlo on the impact law,
    see :data:`SMALL_STUDY_ARGV`): (output folder, printed summary)."""
    out = tmp_path_factory.mktemp("small_study") / "run"
    return out, _run_stackup(["--out", str(out), *SMALL_STUDY_ARGV])
