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
#: module: their scenarios are independent and long, and the solves they share (the screening of the
#: loop's run conditions) come from the forward runner's disk cache (:func:`calib_forward_cache`).
SPLIT_MODULES = ("test_calib_loop", "test_calib_failure_modes")
#: Units handed out first, in this order (groups, modules or test names), longest first: pytest-xdist's
#: loadgroup scheduler hands each worker its next unit while it still has up to two tests pending, so a long
#: unit late in the queue would leave the other worker idle at the end. The order holds only without xdist's
#: reordering of the units by their number of tests (switched off in :func:`pytest_configure`). Measured with
#: it (2026-11-23, whole suite, load ~5 from other jobs): workers at 269 and 255 CPU-s (this process and its
#: reaped children), finishing 17 s apart; without it 251 and 258, the loop's single-pin scenario last. The rest follow in collection order
#: (all below ~5 CPU-s). CPU-s of each unit (this process and its reaped children, per test, with a CPU-time
#: plugin) measured on this 2-core machine under ``-n 2 --dist loadgroup`` at load 3-4 (2026-11-23; shared
#: fixtures counted once): study ~70 (small_study 36, the executor comparison ~15, the stack-up tests 16),
#: rvcad export 33 (group build123d, with rvcad build: one import of build123d, ~6.5 CPU-s), fcl against
#: analytic 20 (26 tests), stack-up Monte Carlo 17 (~11 with 12 closed-form draws), rvcad parts 11, rvcad errors 10, rvdyn physics 9, stack-up
#: on other reducers 8, stiffness 7, fcl contacts 7. The loop's scenarios (measured before, ``-n 0`` one module
#: at a time): the single-pin/off-grid scenario 57 (with the screening of the loop's three run conditions,
#: ~18), calib-declared 55 (13 + 42; the declared model's own screening), screening grid 29, scale error 26 (7
#: with the screening on disk), calib groups 14, two-effect scenario 14, joint 13, the sibling refit under the
#: physical law (test_calib_physical) 23 (alone, its module with its imports; 58 at 200 readings per
#: revolution), ratio-81 12, the zero-offset scenario 8.5. The study runs alone on one worker while the
#: single-pin/off-grid scenario makes the screening of the loop's three run conditions (280 points) as it
#: starts and the declared pair screens its declared model, so every later scenario on either worker reads that
#: screening from disk (:func:`calib_forward_cache`).
HEAVY_FIRST = ("study", "calib-pin-offgrid", "calib-declared", "build123d",
               "test_screening_grid_does_not_alias_whatever_the_steps", "test_fcl_vs_analytic", "test_stackup_mc",
               "test_calib_groups", "test_two_effects_at_once", "test_calib_joint", "test_calib_physical",
               "test_calib_design", "test_rvcad_parts", "test_rvcad_errors", "test_rvdyn_physics",
               "test_scale_error_is_a_ramp_term_and_nothing_else", "test_stackup_reducer", "test_rvdyn_stiffness",
               "test_fcl_contacts", "test_encoder_zero_offset_is_not_disguised_as_physics",
               "test_direction_dependent_effect", "calib-order3", "test_load_dependent_effect",
               "test_a_drift_in_time_is_a_drift_term_not_a_scale_error", "test_stackup_failures",
               "test_rsm_plots", "test_output_encoder_eccentricity_named_in_20_of_20_noise_seeds",
               "test_fuzz_loaders")


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


@pytest.fixture(scope="session")
def calib_forward_cache(tmp_path_factory) -> Path:
    """rvcalib's forward model for the session: rvdyn's runner with the in-memory cache and the warm
    starts of the default one (:data:`rvcalib.forward.WARM_BYTES`: each solve starts from the newest
    state of its neighbourhood, equal to the cold solve within the solver tolerance) and a disk cache
    shared by the pytest-xdist workers (entries are written atomically; a solve one worker made is read
    by the other). Returns the cache folder.

    The runner names its contact law: the paper's impact law (``ContactLaw()``). These tests check the
    loop's identification logic on data whose truth and model are solved on this one runner, so one law
    serves both; the impact law costs about a third of rvdyn's default physical law per revolution.
    ``rv-calibrate --workers/--cache`` keeps the forward runner's law."""
    import os

    from rvcalib import forward
    from rvdyn.contacts import ContactLaw
    from rvdyn.runner import Runner

    base = tmp_path_factory.getbasetemp()
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "rvcalib-forward-cache"
    prev = forward.use_runner(Runner(cache=root, memory_bytes=forward.CACHE_BYTES, warm_bytes=forward.WARM_BYTES,
                                     law=ContactLaw()))
    yield root
    forward.use_runner(prev)


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
