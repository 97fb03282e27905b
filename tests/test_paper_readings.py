"""rvstudy.paper_readings: the paper's Table 6 as measurements, one reading of its unstated choices at a time.

A synthetic worker stands in for the solver where the right answer must be known (it returns the paper's
own number for one reading); the solver itself runs on a few cases at few steps to show that the contact
law reaches the worker and the cache key.
"""
from __future__ import annotations

import functools

import numpy as np
import pytest

import rvpaper as paper
from rvdyn.contacts import ContactLaw
from rvdyn.te import run_te
from rvdyn.cache import CaseCache, Job
from rvdyn.runner import make_executor, solve_job
from rvstudy.paper_readings import compare_with_paper, readings_section, run_readings
from rvstudy.screen import make_case
from rvstudy.study import StudyConfig, load_factors, run_study

HALF = {"pin_pitch": 0.06, "pin_circle_diameter": 14.0, "pin_radius": 7.0, "disc_hole_eccentricity": 14.0}
RUNS = [1, 2, 4, 7, 10, 13, 16, 18]  # EA = +-1 runs and one centre run (the paper's replicates differ)


def test_compare_with_paper_closed_forms():
    paper_y = np.array([0.2, 1.0, 2.0, 0.5, 0.1, 2.2])
    ea = np.array([0, 1, -1, 0, 0, 1])
    centre = np.array([True, False, False, False, True, False])
    ours = 0.25 + 0.5 * paper_y  # an exact affine image
    c = compare_with_paper(ours, paper_y, ea, centre)
    assert c["n"] == 6 and c["r"] == pytest.approx(1.0, abs=1e-12)
    assert c["slope"] == pytest.approx(2.0, rel=1e-10) and c["intercept"] == pytest.approx(-0.5, abs=1e-10)
    assert c["rms_affine"] == pytest.approx(0.0, abs=1e-12)
    assert c["rms_raw"] == pytest.approx(np.sqrt(np.mean((ours - paper_y) ** 2)), rel=1e-12)
    assert c["bias"] == pytest.approx(np.mean(ours - paper_y), rel=1e-12)
    # EA^2 contrast: mean at |EA| = 1 minus the centre mean
    assert c["ea2_contrast_paper"] == pytest.approx((1.0 + 2.0 + 2.2) / 3 - 0.15, rel=1e-12)
    assert c["ea2_contrast_ours"] == pytest.approx(0.5 * c["ea2_contrast_paper"], rel=1e-12)
    # a failed solve (NaN) is left out; the Fisher interval contains r
    ours2 = ours + np.array([0.01, -0.02, 0.0, 0.03, np.nan, 0.0])
    c2 = compare_with_paper(ours2, paper_y, ea, centre)
    assert c2["n"] == 5 and c2["r_low"] < c2["r"] < c2["r_high"] < 1.0


def _coded(errors: dict) -> tuple[float, ...]:
    vals = []
    for key in ("pin_pitch", "pin_circle_diameter", "pin_radius", "disc_hole_eccentricity"):
        v = errors.get(key, 0.0)
        vals.append(float(v[0] if isinstance(v, list) else v) / HALF[key])
    return tuple(round(v, 9) for v in vals)


@functools.lru_cache(maxsize=1)
def _table6_by_point() -> dict[tuple[float, ...], float]:
    """The paper's Table 6 mean |TE| (arcmin) by coded point, read once per process (the synthetic
    worker is called once per case; building this dict each time cost ~0.04 CPU-s a call)."""
    t6 = paper.table6_runs()
    # replicated centre runs: the first one's value (run 4) stands for the point
    return {tuple(round(float(v), 9) for v in r[["EA", "EB", "EC", "ED"]]): float(r["te_arcmin"])
            for _, r in t6.iloc[::-1].iterrows()}


def paper_is_alternate(payload: dict) -> dict:
    """mean |TE| = the paper's Table 6 value (arcsec) if EA moves alternate pins, else a constant 6 arcsec."""
    e = payload["case"].get("errors", {})
    table = _table6_by_point()
    pp_ = e.get("pin_pitch")
    alternate = isinstance(pp_, list) and pp_[0] != 0 and pp_[1] == 0
    y = 60.0 * table[_coded(e)] if alternate or pp_ is None else 6.0 + 0.01 * _coded(e)[1]
    stats = {"pp": 2.0 * y, "mean": y, "mean_abs": y, "rms": 1.1 * y, "ratio": 121.0, "seconds": 0.0}
    return {"key": payload["key"], "status": "ok", "stats": stats, "te_arcsec": [], "error": ""}


def test_the_right_reading_is_found(tmp_path):
    fs = load_factors(None, None)
    ex = make_executor(1)
    try:
        rr = run_readings(fs, ex, CaseCache(None), steps=16, laws=("impact",), runs=RUNS, solve_fn=paper_is_alternate)
    finally:
        ex.close()
    assert len(rr.table) == 3 * 1 * 3 and len(rr.runs) == 3 * len(RUNS)
    exact = rr.reading("alternate", "impact", "mean |TE|")
    assert rr.best.equals(exact)  # the smallest raw residual: the paper's own numbers
    assert exact["r"] == pytest.approx(1.0, abs=1e-12) and exact["rms_raw"] == pytest.approx(0.0, abs=1e-12)
    assert exact["ea2_contrast_ours"] == pytest.approx(exact["ea2_contrast_paper"], rel=1e-12)
    # pp = 2 x the paper: correlation 1, but the raw residual shows the factor 2 and the affine slope 1/2
    pp = rr.reading("alternate", "impact", "peak-to-peak")
    assert pp["rms_raw"] > 0.5 and pp["slope"] == pytest.approx(0.5, rel=1e-10)
    assert rr.default["r"] < 0.9 and rr.default["rms_raw"] > 0.1
    # the runs table: every reading's cases, the paper's value beside ours
    sub = rr.runs[(rr.runs.ea_pins == "alternate")]
    np.testing.assert_allclose(sub["mean_abs_arcmin"], sub["paper_te_arcmin"], rtol=1e-12)
    with pytest.raises(ValueError, match="at least 4 Table 6 runs"):
        run_readings(fs, None, CaseCache(None), runs=[1, 2])


def test_study_stage_and_report_section(tmp_path):
    cfg = StudyConfig(out=tmp_path, solver="analytic", steps=16, workers=1, stages=("readings",), progress=False,
                      figures=False, use_cache=False)
    res = run_study(cfg, solve_fn=paper_is_alternate)
    assert res.readings is not None and res.readings.steps == 16
    sec = readings_section(res)
    text = "\n".join(sec.findings)
    assert "Before (our default reading: EA on pin 0, impact law, mean |TE|)" in text
    assert "After (the reading with the smallest raw residual: EA on alternate" in text
    assert "Highest correlation: EA on alternate" in text
    assert set(sec.tables["paper_readings"]["contact"]) == {"impact", "physical"}
    assert len(sec.data["paper_readings_runs"]) == 3 * 2 * 27


def test_contact_law_reaches_worker_and_key():
    case = make_case({"pin_pitch": 0.03, "pin_radius": 3.0}, "law")
    impact, physical = Job(case, "analytic", 16), Job(case, "analytic", 16, law=ContactLaw(kind="physical"))
    assert impact.key() != physical.key()
    assert "kind" not in impact.to_payload()["law"]  # impact keys unchanged by the kind field
    out = solve_job(physical.to_payload())
    ref = run_te(case, "analytic", 16, 1.0, law=ContactLaw(kind="physical"))
    assert out["stats"]["mean_abs"] == pytest.approx(float(ref.stats["mean_abs"]), rel=1e-12)
    imp = run_te(case, "analytic", 16, 1.0, law=ContactLaw())
    assert abs(float(imp.stats["mean_abs"]) - out["stats"]["mean_abs"]) > 1e-3


def test_a_run_of_the_readings_alone_is_a_result():
    """``rv-stackup --stages readings`` writes a report whose section 8c is the result: exit 0, not 'no stage
    gave a result' (a run with nothing solved still is that error)."""
    from types import SimpleNamespace

    import pandas as pd

    from rvstudy.cli import useful

    none = SimpleNamespace(fits={}, mc=None, screen=None, readings=None)
    assert not useful(none)
    done = SimpleNamespace(fits={}, mc=None, screen=None, readings=SimpleNamespace(table=pd.DataFrame({"r": [0.9]})))
    assert useful(done)
    failed = SimpleNamespace(fits={}, mc=None, screen=None,
                             readings=SimpleNamespace(table=pd.DataFrame({"r": [float("nan")]})))
    assert not useful(failed)
