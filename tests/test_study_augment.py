"""rvstudy.augment_section: the response-surface loop on our own design, validation runs as new data.

The study runs with a synthetic worker (a known polynomial of the case's errors in place of the solver)
so that the term the loop must find is known: the design's quadratic misses a planted EB^2:EC term.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rsm
from rvstudy.augment_section import augment_section
from rvstudy.report import write_report
from rvstudy.study import StudyConfig, run_study

HALF = {"pin_pitch": 0.06, "pin_circle_diameter": 14.0, "pin_radius": 7.0, "disc_hole_eccentricity": 14.0}


def planted_solve(payload: dict) -> dict:
    """Responses in arcsec: a quadratic in the coded factors plus 40 arcsec x EB^2 x EC (a cubic term) and a
    small smooth remainder that no candidate term carries (so the residual after the loop is not zero)."""
    e = payload["case"].get("errors", {})
    z = {k: float(e.get(k, 0.0)) / h for k, h in HALF.items()}
    a, b, c, d = z["pin_pitch"], z["pin_circle_diameter"], z["pin_radius"], z["disc_hole_eccentricity"]
    y = 30.0 + 60.0 * a * a + 10.0 * b + 5.0 * c * d + 8.0 * d * d + 40.0 * b * b * c + 0.3 * np.sin(3 * a + 2 * b + c)
    stats = {"pp": 2.0 * y + 3.0 * a, "mean": y, "mean_abs": y, "rms": y, "ratio": 121.0, "seconds": 0.0}
    return {"key": payload["key"], "status": "ok", "stats": stats, "te_arcsec": [], "error": ""}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("aug")
    cfg = StudyConfig(out=out, solver="analytic", steps=24, workers=1, stages=("doe", "validation"),
                      n_validation=8, progress=False, figures=False, use_cache=False)
    return run_study(cfg, solve_fn=planted_solve)


def test_section_finds_the_planted_term_on_design_and_validation_runs(study):
    sec = augment_section(study)
    a = sec.results["mean_abs_arcmin"]
    assert a.added[0] == "EB^2:EC"
    # after the planted term only the small remainder is left
    assert a.after.ssr < 1e-3 * a.before.ssr
    assert a.after.params["EB^2:EC"] == pytest.approx(40.0 / 60.0, rel=0.01)  # arcsec -> arcmin
    # the validation runs are the new data: the numbers are rsm's own on the same runs
    val = study.validation[study.validation["status"] == "ok"]
    fit = study.fits["mean_abs_arcmin"].results
    t = fit.prediction_test(val)
    assert a.new_runs["n"] == 8 == t["n"] and a.new_runs["F"] == pytest.approx(t["F"], rel=1e-12)
    both = pd.concat([study.design[study.factors.names + ["mean_abs_arcmin"]],
                      val[study.factors.names + ["mean_abs_arcmin"]]], ignore_index=True)
    ref = rsm.ResponseSurfaceModel(both, study.factors.names, "mean_abs_arcmin", levels=study.factors.levels).fit(warn=False)
    assert a.before.ssr == pytest.approx(ref.ssr, rel=1e-10) and a.before.nobs == 27 + 8
    tab = sec.tables["augment_summary"]
    row = tab[(tab.response == "mean_abs_arcmin") & (tab.model == "after")].iloc[0]
    assert row["added"].startswith("EB^2:EC") and row["n_runs"] == 35
    assert set(sec.tables["augment_candidates"]["response"]) == {"mean_abs_arcmin", "pp_arcmin"}


def test_report_carries_the_section(study):
    rep = write_report(study).read_text()
    assert "The response-surface loop on our design" in rep
    assert "the runs support adding EB^2:EC" in rep
    tables = Path(study.config.out) / "tables"
    assert (tables / "augment_summary.csv").is_file() and (tables / "augment_candidates.csv").is_file()
