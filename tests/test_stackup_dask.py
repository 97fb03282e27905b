"""The executors give identical numbers: serial, local process pool and a Dask LocalCluster on loopback.

The serial numbers are those of the shared design-stage run (``doe_reference``: this process, one worker).
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from rvstudy import cli
from rvstudy.montecarlo import parse_tolerance
from rvstudy.study import StudyConfig, run_study

from conftest import STUDY_STEPS

STEPS = STUDY_STEPS
pytestmark = pytest.mark.slow  # process pool, Dask cluster, a design run each


def _numbers(res) -> pd.DataFrame:
    return res.design[["run", "mean_abs_arcmin", "pp_arcmin", "status"]].reset_index(drop=True)


def _cfg(tmp_path, **kw) -> StudyConfig:
    base = dict(out=tmp_path, solver="analytic", steps=STEPS, workers=1, stages=("doe",), progress=False,
                figures=False, use_cache=False)
    base.update(kw)
    return StudyConfig(**base)


@pytest.fixture(scope="module")
def serial(doe_reference) -> pd.DataFrame:
    """Design numbers of the serial run, full precision (the parquet table; the CSV keeps 10 digits)."""
    out, summary = doe_reference
    assert summary["executor"].startswith("serial")
    d = pd.read_parquet(out / "tables" / "design_runs.parquet")
    return d[["run", "mean_abs_arcmin", "pp_arcmin", "status"]].reset_index(drop=True)


def _mc_cfg(tmp_path, **kw) -> StudyConfig:
    """A tiny full-solver Monte Carlo under the default (physical) law: every feature of two tolerances (one
    per pin, one per disc hole), 2 draws and a designed sample of 2 (10 draws of 5 solves). The physical law
    stays: its damping floor depends on the batch, so equal numbers also show that every executor solves each
    draw's five cases as the one batch."""
    tols = {k: parse_tolerance(f"{k}=normal:{v}") for k, v in (("pin_radius", 1.5), ("disc_hole_eccentricity", 3.0))}
    return _cfg(tmp_path, stages=("mc",), mc_draws=2, mc_sobol=2, mc_check=0, tolerances=tols, **kw)


@pytest.fixture(scope="module")
def serial_mc(tmp_path_factory):
    return run_study(_mc_cfg(tmp_path_factory.mktemp("serial_mc"))).mc


@pytest.fixture(scope="module")
def cluster_address():
    """One Dask LocalCluster on loopback for the tests of this module (its start-up paid once)."""
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp",
                                  host="127.0.0.1", dashboard_address=":0") as cluster:
        yield cluster.scheduler_address


def test_local_pool_equals_serial(serial, tmp_path):
    res = run_study(_cfg(tmp_path, workers=2))
    assert res.executor.startswith("local process pool, 2")
    pd.testing.assert_frame_equal(_numbers(res), serial)


def test_dask_local_cluster_equals_serial(serial, cluster_address, tmp_path, capsys):
    addr = cluster_address
    assert addr.startswith("tcp://127.0.0.1:")
    # every case solved on the cluster, the results cached here
    res = run_study(_cfg(tmp_path / "api", scheduler=addr, use_cache=True, cache_dir=tmp_path / "cache"))
    assert res.executor.startswith(f"Dask scheduler {addr}")
    assert res.counters["computed"] == 25
    pd.testing.assert_frame_equal(_numbers(res), serial)
    # through the command line, on that cache: the entries the Dask results filled are reused
    out = tmp_path / "cli"
    argv = ["--out", str(out), "--scheduler", addr, "--cache", str(tmp_path / "cache"), "--solver", "analytic",
            "--steps", str(STEPS), "--stages", "doe", "--no-progress", "--no-figures", "--json"]
    assert cli.main(argv) == 0
    s1 = json.loads(capsys.readouterr().out)
    assert s1["executor"].startswith(f"Dask scheduler {addr}")
    assert s1["cases"]["computed"] == 0 and s1["cases"]["reused"] == 25
    d = pd.read_parquet(out / "tables" / "design_runs.parquet")  # full precision (the CSV keeps 10 digits)
    np.testing.assert_array_equal(d["mean_abs_arcmin"].to_numpy(), serial["mean_abs_arcmin"].to_numpy())


def test_monte_carlo_same_numbers_serial_pool_and_dask(serial_mc, cluster_address, tmp_path):
    """The full-solver Monte Carlo gives bit-identical draws and responses on a local pool and a Dask
    LocalCluster as in this process (the draws are seeded; each solve is deterministic)."""
    pool = run_study(_mc_cfg(tmp_path / "pool", workers=2)).mc
    pd.testing.assert_frame_equal(pool["draws"], serial_mc["draws"], check_exact=True)
    dk = run_study(_mc_cfg(tmp_path / "dask", scheduler=cluster_address)).mc
    pd.testing.assert_frame_equal(dk["draws"], serial_mc["draws"], check_exact=True)
    pd.testing.assert_frame_equal(dk["sobol"], serial_mc["sobol"], check_exact=True)
    assert dk["responses"]["te_pp_arcmin"]["mean"] == serial_mc["responses"]["te_pp_arcmin"]["mean"]


def test_monte_carlo_default_law_is_the_physical_one(serial_mc):
    """The Monte Carlo of a default configuration solves its draws with rvdyn's physical law: the first
    draw's TE equals that draw's case solved directly under the physical law (within run_te_many's bound:
    the draw's five solves are one batch) and not under the impact law."""
    from rvcad.params import Design
    from rvdyn.contacts import ContactLaw
    from rvdyn.te import run_te
    from rvstudy.features import features
    from rvstudy.stackup import draw_cases

    cfg = _mc_cfg(None)
    assert cfg.mc_contact == "physical"
    feats = features(cfg.tolerances, Design())
    X = serial_mc["draws"][[f.name for f in feats]]
    case = draw_cases(feats, X.iloc[:1], Design(), "mc", cfg.load_Nm, {}, [])[0]
    pp = {law: float(run_te(case, "analytic", STEPS, law=ContactLaw(kind=law)).stats["pp"]) / 60.0
          for law in ("physical", "impact")}
    got = serial_mc["draws"]["te_pp_arcmin"].iloc[0]
    assert got == pytest.approx(pp["physical"], abs=2e-4 / 60)  # run_te_many's bound, 1e-4 arcsec per step
    assert abs(got - pp["impact"]) > 100 * 2e-4 / 60
