"""Single-factor screen and factor sweeps (rvstudy.screen, ``rv-stackup --stages screen``)."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from rvcad.errors import ERROR_TYPES
from rvstudy import cli
from rvstudy.screen import (
    RSM_FACTORS,
    STAGE,
    TABLE5_HALF_RANGE,
    rank_errors,
    run_screen,
    screen_cases,
    stage_check,
    sweep_cases,
)

from conftest import STUDY_STEPS

STEPS = STUDY_STEPS


def test_screen_cases_are_table4_at_paper_values():
    sc = screen_cases(20.0)
    assert list(sc["letter"]) == ["A"] + [e.letter for e in ERROR_TYPES.values()]
    for r in sc.itertuples():
        if r.letter == "A":
            assert r.case.raw_errors == {}
            continue
        et = ERROR_TYPES[r.error]
        assert r.value == et.paper_value and r.unit == et.unit
        assert r.case.raw_errors == {r.error: et.paper_value}
        assert r.case.load_Nm == 20.0
    both = screen_cases(20.0, both_signs=True)
    assert len(both) == 23 and len({c.key() for c in both["case"]}) == 23
    assert set(both.loc[both["sign"] == -1, "value"]) == {-e.paper_value for e in ERROR_TYPES.values()}
    assert STAGE["B"] == STAGE["C"] == "I" and all(STAGE[L] == "II" for L in "DEFGHIJKL")


def test_sweep_cases_span_table5_and_centre_is_case_a():
    sw = sweep_cases(7)
    assert len(sw) == 28
    a = screen_cases()["case"].iloc[0].key()
    for f, key in RSM_FACTORS.items():
        d = sw[sw["factor"] == f]
        assert list(d["error"].unique()) == [key]
        assert d["value"].min() == -TABLE5_HALF_RANGE[f] and d["value"].max() == TABLE5_HALF_RANGE[f]
        centre = d[d["value"] == 0.0]["case"].iloc[0]
        assert centre.key() == a  # zero errors are dropped, so the centre is the error-free case
    with pytest.raises(ValueError, match="sweep points"):
        sweep_cases(1)


def _fake_runner(values: dict[str, tuple[float, float]]):
    """Runner returning given (pp, mean_abs) per error key; counts calls."""
    calls = []

    def run(cases, desc="x"):
        out = []
        for c in cases:
            calls.append(c.key())
            key = next(iter(c.raw_errors), "none")
            pp, ma = values.get(key, (0.0, 9.0))
            out.append({"stats": {"pp": pp, "mean": -ma, "mean_abs": ma, "rms": ma, "seconds": 0.0},
                        "te_arcsec": np.full(8, -ma), "key": c.key(), "cached": False})
        return out

    run.calls = calls
    return run


def test_ranking_and_stage_check_on_given_numbers():
    vals = {k: (float(i + 1), 9.0 + i) for i, k in enumerate(ERROR_TYPES)}  # B smallest ... L largest
    vals["sun_eccentricity"] = (0.01, 9.0)
    vals["planet_eccentricity"] = (0.02, 9.01)
    r = run_screen(runner=_fake_runner(vals), sweeps=False)
    s = r.screen.set_index("letter")
    assert s.loc["L", "rank_pp"] == 1 and s.loc["B", "rank_pp"] == 11 and s.loc["C", "rank_pp"] == 10
    assert r.stage_check["pp"]["reproduced"] and r.stage_check["pp"]["below_rsm_factors"]
    # make a stage II error smaller than C: no longer reproduced, and it is named
    vals["cam_phase"] = (0.015, 9.0)
    r = run_screen(runner=_fake_runner(vals), sweeps=False)
    assert not r.stage_check["pp"]["reproduced"]
    assert r.stage_check["pp"]["stage2_below_stage1"] == ["D"]


def test_rank_needs_case_a():
    df = pd.DataFrame({"letter": ["B"], "sign": [1], "pp_arcsec": [1.0], "mean_abs_arcsec": [1.0]})
    with pytest.raises(ValueError, match="case A"):
        rank_errors(df)


@pytest.fixture(scope="module")
def screen_run(small_study):
    """The screen stage of the shared small ``rv-stackup`` run (analytic, few steps, 3 sweep points):
    (output folder, its summary.json)."""
    out, _ = small_study
    return out, json.loads((out / "summary.json").read_text())


@pytest.mark.slow
def test_real_screen_small_steps(screen_run):
    """The analytic solver at a few steps: stage I errors change the TE ripple far less than cam and hole errors."""
    out, summary = screen_run
    s = pd.read_csv(out / "tables" / "screen.csv")
    assert np.isfinite(s["pp_arcsec"]).all()
    s = s[s["sign"].isin([0, 1])].set_index("letter")
    assert s.loc["A", "pp_arcsec"] < 1e-3  # error-free: a constant elastic wind-up only
    assert s.loc["A", "mean_abs_arcsec"] > 1.0  # ... of several arcsec at 20 N m
    for stage1 in ("B", "C"):
        for big in ("D", "E", "G"):
            assert s.loc[stage1, "d_pp_arcsec"] < s.loc[big, "d_pp_arcsec"]
    sw = pd.read_csv(out / "tables" / "sweeps.csv")
    assert len(sw) == 12 and set(sw["factor"]) == set(RSM_FACTORS)
    assert set(summary["stage_check"]) == {"pp", "mean_abs"}


@pytest.mark.slow
def test_default_serial_runner_gives_the_study_numbers(screen_run):
    """run_screen on its own (serial, no cache) solves the + rows to the same numbers as rv-stackup."""
    out, _ = screen_run
    study = pd.read_csv(out / "tables" / "screen.csv")
    study = study[study["sign"].isin([0, 1])].set_index("letter")
    alone = run_screen("analytic", STEPS, load_Nm=20.0, progress=False, sweeps=False).screen.set_index("letter")
    assert list(alone.index) == list(study.index)
    for col in ("pp_arcsec", "mean_abs_arcsec", "rank_pp"):
        np.testing.assert_allclose(alone[col], study[col], rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_screen_stage_writes_tables_plots_and_json(screen_run):
    out, summary = screen_run
    assert summary["cases"]["failed"] == 0 and summary["cases"]["computed"] > 0
    assert summary["config"]["sweep_points"] == 3
    for name in ("tables/screen.csv", "tables/sweeps.csv", "figures/screen.png", "figures/sweeps.png",
                 "figures/te_curves.png", "report.md"):
        assert (out / name).stat().st_size > 0, name
    assert not [p for p in out.rglob(".*") if p.is_file()]  # no temporary files left
    tab = pd.read_csv(out / "tables" / "screen.csv")
    assert len(tab) == 23 and tab["rank_pp"].notna().sum() == 11  # A, +-11 errors; ranks of the + rows
    assert tab["letter"].iloc[0] == "A"
    report = (out / "report.md").read_text()
    assert "Single-factor screen" in report and "pin_pitch" in report and "reproduced" in report


@pytest.mark.slow
def test_screen_stage_human_summary_reuses_cache(screen_run, tmp_path, capsys):
    out, _ = screen_run
    assert cli.main(["--out", str(tmp_path), "--cache", str(out / "cache"), "--stages", "screen", "--solver",
                     "analytic", "--steps", str(STEPS), "--sweep-points", "3", "--workers", "1", "--no-progress",
                     "--no-figures"]) == 0
    text = capsys.readouterr().out
    assert "0 solved" in text  # every case of the same screen comes from the cache
    assert "stage I errors B/C rank" in text and "below every stage II error" in text


@pytest.mark.parametrize("argv, needle", [
    (["--steps", "1"], "--steps"),
    (["--sweep-points", "1"], "--sweep-points"),
    (["--load-Nm", "-3"], "--load-Nm"),
])
def test_screen_bad_options_exit_2(tmp_path, capsys, argv, needle):
    rc = cli.main(["--out", str(tmp_path), "--stages", "screen", "--solver", "analytic", *argv])
    assert rc == 2
    assert needle in capsys.readouterr().err
