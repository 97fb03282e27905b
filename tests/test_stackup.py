"""rv-stackup: cache reuse, resume after interruption, corrupt entries, report from the run, bad options.

All runs use the analytic solver at a few steps so that the whole file stays quick.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rvdyn.runner as executor_mod
import rvpaper as paper
from rvstudy import cli
from rvdyn.cache import CaseCache, Job
from rvstudy.montecarlo import (
    Tolerance,
    load_tolerances,
    parse_tolerance,
    sobol_indices,
    yield_estimate,
)
from rvstudy.study import StudyConfig, run_study

from conftest import DOE_ARGV, STUDY_STEPS

STEPS = STUDY_STEPS
ROOT = Path(__file__).resolve().parents[1]
# the design stage alone: 27 runs, 25 unique cases
DOE = DOE_ARGV


def _cfg(out: Path, **kw) -> StudyConfig:
    base = dict(out=out, solver="analytic", steps=STEPS, workers=1, stages=("doe",), progress=False, figures=False)
    base.update(kw)
    return StudyConfig(**base)


def _design_numbers(out: Path) -> pd.DataFrame:
    d = pd.read_csv(out / "tables" / "design_runs.csv")
    return d[["run", "mean_abs_arcmin", "pp_arcmin", "status"]]


@pytest.fixture(scope="module")
def reference(doe_reference) -> Path:
    """One uninterrupted design-stage run (the numbers every other run must reproduce); read only."""
    return doe_reference[0]


def _copy(reference: Path, to: Path) -> Path:
    """A copy of the reference run (tables, report and cache) to run again in."""
    shutil.copytree(reference, to)
    return to


# ---------------------------------------------------------------------------------------------- paper data
def test_packaged_paper_tables():
    """The packaged paper tables hold the paper's numbers (``.ci/run`` compares the files byte for byte with
    the project's reference copy where that copy stands beside the clone)."""
    packaged = sorted(p.name for p in paper.DATA_DIR.glob("*.csv"))
    assert len(packaged) == 6
    t5 = pd.read_csv(paper.DATA_DIR / "paper_table5_levels.csv")
    pd.testing.assert_frame_equal(paper.table5_levels().drop(columns="error"), t5)
    assert list(t5["high"]) == [paper.TABLE5_HALF_RANGE[f] for f in t5["factor"]]
    assert len(paper.table6_runs()) == 27
    assert paper.table7_anova().loc["EA^2", "F"] == pytest.approx(446.61)
    assert paper.eq8_coefficients()["EA^2"] == pytest.approx(404.36592)


# ---------------------------------------------------------------------------------------------- cache
@pytest.mark.slow
def test_rerun_reuses_every_case(doe_reference, tmp_path, capsys, monkeypatch):
    reference, first = doe_reference  # a first run from an empty cache solves every case
    assert first["cases"]["computed"] == 25 and first["cases"]["reused"] == 0
    assert any("undersampled" in n for n in first["notes"])  # STEPS is below 2 x 121
    out = _copy(reference, tmp_path / "run")
    calls = []
    real = executor_mod.run_te
    monkeypatch.setattr(executor_mod, "run_te", lambda *a, **k: calls.append(1) or real(*a, **k))
    assert cli.main(["--out", str(out), *DOE, "--json"]) == 0
    second = json.loads(capsys.readouterr().out)
    assert second["cases"]["computed"] == 0 and second["cases"]["reused"] == 25 and calls == []
    pd.testing.assert_frame_equal(_design_numbers(out), _design_numbers(reference))
    # the cache key follows the physics: another load is another case
    assert cli.main(["--out", str(out), *DOE, "--load-Nm", "10", "--json"]) == 0
    third = json.loads(capsys.readouterr().out)
    assert third["cases"]["computed"] == 25


@pytest.mark.slow
def test_interrupted_run_resumes_without_loss(reference, tmp_path):
    out = tmp_path / "run"
    k = 7
    done = []

    def dying(payload):
        if len(done) == k:
            raise KeyboardInterrupt("simulated kill")
        done.append(payload["key"])
        return executor_mod.solve_job(payload)

    with pytest.raises(KeyboardInterrupt):
        run_study(_cfg(out), solve_fn=dying)
    cache = CaseCache(out / "cache")
    entries = cache.entries()
    assert len(entries) == k
    assert all(cache.get(p.stem) is not None for p in entries)  # every entry complete and valid
    res = run_study(_cfg(out))
    assert res.counters["reused"] == k and res.counters["computed"] == 25 - k
    from rvstudy.report import write_report

    write_report(res)
    pd.testing.assert_frame_equal(_design_numbers(out), _design_numbers(reference))


def _start_run(out: Path, argv: list[str], entries: int) -> tuple[subprocess.Popen, CaseCache, list[str], dict]:
    """Start ``rv-stackup --out OUT ARGV`` in a subprocess and return once ``entries`` cases are cached."""
    cmd = [sys.executable, "-m", "rvstudy", "--out", str(out), *argv]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    cache = CaseCache(out / "cache")
    t0 = time.time()
    while len(cache.entries()) < entries and time.time() - t0 < 120 and proc.poll() is None:
        time.sleep(0.05)
    return proc, cache, cmd, env


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (Linux /proc)."""
    out = []
    for st in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = st.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(st.parent.name))
    return out


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc to list child processes")
def test_killed_run_resumes_corrupts_nothing_and_leaves_no_workers(reference, tmp_path):
    """``rv-stackup`` with a process pool, SIGKILLed mid-run: every cache entry is whole, the pool workers
    end themselves (a killed run cannot shut its pool down; the workers watch their parent), and a rerun
    of the same command resumes and gives the uninterrupted run's numbers."""
    from rvdyn.runner import PARENT_POLL_S

    argv = [a if a != "1" else "2" for a in DOE]  # --workers 2: a real process pool
    out = tmp_path / "run"
    proc, cache, _, _ = _start_run(out, argv, 2)
    kids = _children(proc.pid)
    assert kids, "the run should have started its pool"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    t1 = time.time()
    while time.time() - t1 < 5 * PARENT_POLL_S + 10:
        alive = [k for k in kids if Path(f"/proc/{k}").exists()
                 and "Z" not in Path(f"/proc/{k}/stat").read_text().rsplit(")", 1)[1].split()[0]]
        if not alive:
            break
        time.sleep(0.2)
    assert not alive, f"pool workers {alive} outlived the killed run"
    n = len(cache.entries())
    assert 0 < n < 25, "the kill should land mid-run"
    assert all(cache.get(p.stem) is not None for p in cache.entries())
    # the same command again (here in this process): resumes from the entries the killed run left
    res = run_study(_cfg(out, workers=1))
    assert res.counters["reused"] >= n and res.counters["computed"] + res.counters["reused"] == 25
    from rvstudy.report import write_report

    write_report(res)
    pd.testing.assert_frame_equal(_design_numbers(out), _design_numbers(reference))


@pytest.mark.slow
def test_corrupt_and_partial_entries_are_recomputed(reference, tmp_path):
    out = _copy(reference, tmp_path / "run")
    cache = CaseCache(out / "cache")
    entries = cache.entries()
    entries[0].write_text(entries[0].read_text()[:50])  # partial (truncated) file
    doc = json.loads(entries[1].read_text())
    doc["payload"]["stats"]["pp"] = 123.0  # tampered: checksum no longer matches
    entries[1].write_text(json.dumps(doc))
    entries[2].write_text("not json at all")
    res = run_study(_cfg(out))
    assert res.counters["computed"] == 3 and res.cache_counters["rejected"] == 3
    assert all(cache.get(p.stem) is not None for p in cache.entries())
    from rvstudy.report import write_report

    write_report(res)
    pd.testing.assert_frame_equal(_design_numbers(out), _design_numbers(reference))


def test_job_key_covers_solver_steps_and_law():
    from rvcad.errors import Case
    from rvdyn.contacts import ContactLaw

    c = Case.from_dict({"errors": {"pin_pitch": 0.01}})
    k = Job(c, "analytic", 24).key()
    assert Job(Case.from_dict({"name": "other", "errors": {"pin_pitch": 0.01}}), "analytic", 24).key() == k
    assert Job(c, "fcl", 24).key() != k
    assert Job(c, "analytic", 48).key() != k
    assert Job(c, "analytic", 24, law=ContactLaw(K=1e5)).key() != k
    assert Job(c.with_errors({"pin_pitch": 0.02}), "analytic", 24).key() != k
    assert Job(Case.from_dict({"errors": {"pin_pitch": 0.01}, "load_Nm": 10.0}), "analytic", 24).key() != k
    assert Job(Case.from_dict({"errors": {"pin_pitch": 0.01}, "direction": -1}), "analytic", 24).key() != k
    assert Job(c, "analytic", 24, revolutions=2.0).key() != k
    # at given input angles: the angles enter the key, the steps follow them
    th = (0.0, 1.0, 2.0)
    assert Job(c, "analytic", 24, theta_in_deg=th).key() not in {k, Job(c, "analytic", 3).key()}
    assert Job(c, "analytic", 24, theta_in_deg=th).key() == Job(c, "analytic", 99, theta_in_deg=th).key()
    assert Job(c, "analytic", 24, theta_in_deg=(0.0, 1.0, 2.5)).key() != Job(c, "analytic", 24, theta_in_deg=th).key()


# ---------------------------------------------------------------------------------------------- report
@pytest.mark.slow
def test_report_tables_come_from_the_run(reference, tmp_path):
    t6 = pd.read_csv(reference / "tables" / "table6_compare.csv")
    design = pd.read_csv(reference / "tables" / "design_runs.csv")
    np.testing.assert_array_equal(t6["mean_abs_arcmin"], design["mean_abs_arcmin"])
    assert list(t6["paper_te_arcmin"]) == list(paper.table6_runs()["te_arcmin"])
    report = (reference / "report.md").read_text()
    st = pd.read_csv(reference / "tables" / "fit_statistics.csv").set_index("response")
    assert f"{st.loc['mean_abs_arcmin', 'r2']:.4f}" in report
    # change an input (the levels): the tables change with it
    lv = paper.table5_levels().drop(columns="error")
    lv.loc[lv["factor"] == "EC", ["low", "high"]] = [-3.0, 3.0]
    lv.to_csv(tmp_path / "levels.csv", index=False)
    out = tmp_path / "run"
    assert cli.main(["--out", str(out), *DOE, "--levels", str(tmp_path / "levels.csv")]) == 0
    d2 = pd.read_csv(out / "tables" / "design_runs.csv")
    assert set(d2["EC_actual"]) == {-3.0, 0.0, 3.0}
    assert not np.allclose(d2["mean_abs_arcmin"].fillna(-1), design["mean_abs_arcmin"].fillna(-1))
    st2 = pd.read_csv(out / "tables" / "fit_statistics.csv").set_index("response")
    assert f"{st2.loc['mean_abs_arcmin', 'r2']:.4f}" in (out / "report.md").read_text()
    assert st2.loc["mean_abs_arcmin", "r2"] != st.loc["mean_abs_arcmin", "r2"]
    # the levels moved away from the paper's: no paper columns are claimed
    assert "paper_te_arcmin" not in pd.read_csv(out / "tables" / "table6_compare.csv")


@pytest.mark.slow
def test_full_pipeline_small(small_study):
    """Every stage with small counts, figures included; the report sets ours beside the paper's."""
    out, text = small_study
    assert text.strip().splitlines()[-1] == f"report: {out / 'report.md'}"
    rep = (out / "report.md").read_text()
    for section in ("Single-factor screen", "Factor sweeps", "Table 6", "Table 7", "Eq. 8", "Eq. 9",
                    "Fig. 12", "Fig. 13", "Monte Carlo", "reproduced or not"):
        assert section in rep, section
    for name in ("screen", "sweeps", "table6_compare", "table7_compare_mean_abs_arcmin", "eq8_compare_mean_abs_arcmin",
                 "eq9_compare_mean_abs_arcmin", "validation_metrics", "mc_capability", "mc_contributors", "mc_draws",
                 "mc_fcl_check", "mc_surface_comparison", "conclusions"):
        assert (out / "tables" / f"{name}.csv").is_file(), name
        assert (out / "tables" / f"{name}.parquet").is_file(), name
    for link in [line.split("](")[1].rstrip(")") for line in rep.splitlines() if line.startswith("![")]:
        assert (out / link).is_file(), link
    s = json.loads((out / "summary.json").read_text())
    assert s["contact_models"]["monte_carlo"].startswith("impact: F = ")  # --mc-contact reaches the summary
    assert s["monte_carlo"]["te_pp_arcmin"]["n_solver_draws"] == 6
    assert s["monte_carlo"]["fcl_check"]["te_pp_arcmin"]["n"] == 1
    assert text.strip().splitlines()[2].startswith("  full solver, 6 draws: te_pp_arcmin")  # the solver's figures lead
    cc = pd.read_csv(out / "tables" / "conclusions.csv")
    assert set(cc["reproduced"]) <= {"yes", "no", "partly", "untestable"}
    assert "lack_of_fit_ns" in set(cc["claim"])
    assert not [p for p in out.rglob(".*") if p.is_file()]  # no temporary files left


# ---------------------------------------------------------------------------------------------- options
def test_mc_contact_defaults_to_the_physical_law():
    """The Monte Carlo's law is rvdyn's physical law unless ``--mc-contact`` says otherwise (the shared small
    study runs it with ``--mc-contact impact``; tests/test_stackup_dask.py solves the physical default)."""
    from rvstudy.study import PHYSICAL_LAW_TEXT

    cfg = cli.config_from_args(cli.build_parser().parse_args(["--out", "x"]))
    assert cfg.mc_contact == "physical" == StudyConfig().mc_contact
    assert cfg.contact_models()["monte_carlo"] == PHYSICAL_LAW_TEXT + " (--mc-contact)"
    assert cli.config_from_args(cli.build_parser().parse_args(["--out", "x", "--mc-contact", "impact"])
                                ).mc_contact == "impact"


@pytest.mark.parametrize("argv, needle", [
    (["--steps", "1"], "--steps"),
    (["--workers", "0"], "--workers"),
    (["--tolerance", "bogus=normal:1"], "bogus"),
    (["--tolerance", "pin_pitch=normal:-1"], "SIGMA"),
    (["--tolerance", "pin_pitch"], "--tolerance"),
    (["--tolerance", "pin_pitch=gamma:1"], "distribution"),
    (["--levels", "/nonexistent/levels.csv"], "--levels"),
    (["--factors", "EA", "EZ", "EC"], "--factors"),
    (["--stages", "doe,bogus"], "--stages"),
    (["--load-Nm", "-1"], "--load-Nm"),
    (["--spec-arcmin", "0"], "--spec-arcmin"),
    (["--mc-draws", "1"], "--mc-draws"),
    (["--mc-sobol", "-1"], "--mc-sobol"),
    (["--spec", "bogus=:1"], "--spec"),
    (["--spec", "te_pp_arcmin=2:1"], "--spec"),
    (["--spec", "te_pp_arcmin"], "--spec"),
    (["--rated-Nm", "0"], "--rated-Nm"),
    (["--reducer", "/nonexistent/design.json"], "--reducer"),
    (["--design", "plackett"], "--design"),
    (["--solver", "magic"], "--solver"),
    (["--steps", "many"], "--steps"),
    (["--K", "-5"], "K"),
    (["--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "1"], "--scheduler"),
    (["--scheduler-timeout", "0"], "--scheduler-timeout"),
])
def test_bad_options_exit_2_naming_the_option(tmp_path, capsys, argv, needle):
    try:
        rc = cli.main(["--out", str(tmp_path), "--solver", "analytic", "--no-progress", *argv])
    except SystemExit as exc:  # argparse: type and choice errors
        rc = exc.code
    assert rc == 2
    assert needle in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------- Monte Carlo parts
def test_tolerance_parsing_and_files(tmp_path):
    t = parse_tolerance("pin_radius=uniform:-2:2")
    assert t.dist == "uniform" and t.params == (-2.0, 2.0) and abs(t.std - 4 / np.sqrt(12)) < 1e-12
    assert parse_tolerance("disc_phase=none").sample(np.random.default_rng(0), 3).tolist() == [0, 0, 0]
    (tmp_path / "t.csv").write_text("error,dist,p1,p2\npin_pitch,normal,0.002,\ncam_phase,uniform,-1,1\n")
    d = load_tolerances(tmp_path / "t.csv")
    assert d["pin_pitch"] == Tolerance("pin_pitch", "normal", (0.002,))
    (tmp_path / "t.json").write_text(json.dumps({"sun_eccentricity": "triangular:-1:0:1"}))
    assert load_tolerances(tmp_path / "t.json")["sun_eccentricity"].dist == "triangular"


def test_sobol_of_additive_function_and_yield():
    tols = {"a": None}
    from rvstudy.montecarlo import default_tolerances

    tols = default_tolerances()
    keys = ["sun_eccentricity", "cam_phase"]  # both normal sigma 10/3
    f = lambda D: 1.0 * D["sun_eccentricity"].to_numpy() + 2.0 * D["cam_phase"].to_numpy()  # noqa: E731
    s = sobol_indices(f, tols, keys, 20000, np.random.default_rng(1)).set_index("error")
    assert abs(s.loc["sun_eccentricity", "S1"] - 0.2) < 0.03 and abs(s.loc["cam_phase", "S1"] - 0.8) < 0.03
    assert abs(s.loc["cam_phase", "ST"] - 0.8) < 0.03
    y = yield_estimate(np.array([0.5, 0.9, 1.5, 2.0]), 1.0)
    assert y["yield"] == 0.5 and y["lower"] < 0.5 < y["upper"]


# ---------------------------------------------------------------------------------------------- pin patterns
def _levels_with(tmp_path: Path, ea_error: str) -> Path:
    lv = paper.table5_levels()
    lv.loc[lv["factor"] == "EA", "error"] = ea_error
    p = tmp_path / "levels.csv"
    lv.to_csv(p, index=False)
    return p


@pytest.mark.parametrize("pattern, expect", [
    ("all", [0.06] * 40),
    ("alternate", [0.06 if i % 2 == 0 else 0.0 for i in range(40)]),
])
def test_pin_pattern_of_a_factor_reaches_the_case(tmp_path, pattern, expect):
    from rvstudy.screen import make_case
    from rvstudy.study import load_factors
    fs = load_factors(str(_levels_with(tmp_path, f"pin_pitch[{pattern}]")), None)
    assert fs.errors["EA"] == "pin_pitch" and fs.patterns["EA"] == pattern and not fs.is_paper
    assert fs.spec("EA") == f"pin_pitch[{pattern}]"
    case = make_case(fs.case_errors({fs.errors[f]: v for f, v in zip(fs.names, [0.06, 0.0, 0.0, 0.0])}), "t")
    assert case.to_dict()["errors"] == {"pin_pitch": expect}
    # other error types (as in the Monte Carlo check) keep their default instance
    assert fs.case_errors({"pin_pitch": 0.01, "pin_radius": 2.0}) == {
        "pin_pitch": [v / 0.06 * 0.01 for v in expect], "pin_radius": 2.0}


@pytest.mark.parametrize("error, needle", [
    ("pin_pitch[every_third]", "pin pattern 'every_third'"),
    ("disc_hole_eccentricity[all]", "needs a pin-wise error"),
])
def test_bad_pin_pattern_is_named(tmp_path, capsys, error, needle):
    rc = cli.main(["--out", str(tmp_path / "o"), "--solver", "analytic", "--no-progress",
                   "--levels", str(_levels_with(tmp_path, error))])
    assert rc == 2
    assert needle in capsys.readouterr().err
