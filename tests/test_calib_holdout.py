"""rvcalib.holdout: sub-datasets, the calibrated reducer's prediction through rvdyn, the unexplained terms at other
readings, and the table of loads left out (the whole table with the loop: tests/test_calib_command.py)."""
from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from rvcalib.simulate import simulate_dataset
from rig_records import cos_orders, write_dataset
from rvrig.dataset import read_dataset
from rvcalib.holdout import holdout_loads, predicted_te, rms_without_constants, subset, unexplained_te
from rvcalib.library import build_library
from rvcalib.readings import reading_columns
from rvcalib.result import NamedEffect

RUNS = [{"run": str(i + 1), "load_Nm": ld, "direction": d, "test": f"{ld:g}Nm"}
        for i, (ld, d) in enumerate([(10.0, 1), (10.0, -1), (30.0, 1), (30.0, -1)])]


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    runs = [{"run": f"{ld:g}{'f' if d > 0 else 'b'}", "load_Nm": ld, "direction": d, "test": f"T{ld:g}",
             "te": cos_orders({1: (3.0, 10.0)})} for ld in (0.0, 10.0, 30.0) for d in (1, -1)]
    return read_dataset(write_dataset(tmp_path_factory.mktemp("h") / "ds", runs, per_rev=120))


def test_a_subset_keeps_its_runs_tests_and_reducer(ds):
    sub = subset(ds, ["30f", "10b", "30b"])
    assert [r.run for r in sub.runs] == ["10b", "30f", "30b"]
    assert sub.tests.ids == ("T10", "T30") and sub.tests.of_run == {"10b": "T10", "30f": "T30", "30b": "T30"}
    assert sub.design == ds.design and sub.ratio == 81.0
    with pytest.raises(ValueError, match="no run of \\['x'\\] is in the dataset"):
        subset(ds, ["x"])


def test_rms_without_constants_removes_each_tests_constant(ds):
    """A constant per test plus a sine of amplitude 2 over whole revolutions: the RMS is 2 / sqrt(2)."""
    res = [7.0 * (r.load_Nm + 1) + 2.0 * np.sin(5 * r.output_rad) for r in ds.runs]
    assert rms_without_constants(ds, res) == pytest.approx(math.sqrt(2.0), rel=1e-9)


@pytest.mark.parametrize("kind,order", [("common", 3), ("load", 2), ("direction", 4), ("direction", 0),
                                        ("load_direction", 0)])
def test_unexplained_terms_at_other_readings_match_the_library_columns(ds, kind, order):
    """An unexplained term reported as amplitude and phase is the empirical candidate's column times its
    components (cos, sin) = A (cos phase, sin phase), with the load relative to the fit's largest load."""
    cand = next(c for c in build_library(ds, 6) if c.family == "empirical" and c.key == kind and c.order == order)
    comps = np.array([1.7, -0.6]) if order else np.array([-2.5])
    amp, phase = (math.hypot(*comps), math.degrees(math.atan2(comps[1], comps[0]))) if order else (comps[0], None)
    fit = SimpleNamespace(unexplained=[{"order": order, "kind": kind, "amplitude_arcsec": amp, "phase_deg": phase}])
    got = np.concatenate(unexplained_te(fit, ds, max(r.load_Nm for r in ds.runs)))
    assert got == pytest.approx(reading_columns(cand, ds) @ comps, abs=1e-12)
    fit.unexplained[0]["amplitude_arcsec"] = "unbounded"                 # no size: no term
    assert np.all(np.concatenate(unexplained_te(fit, ds, 30.0)) == 0.0)


def test_one_load_has_nothing_to_leave_out(ds):
    one = subset(ds, ["10f", "10b"])
    h = holdout_loads(one, fit=lambda *a: pytest.fail("no fit with one load"))
    assert h["rows"] == [] and "one load (10 N m)" in h["statement"]


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sim") / "ds"
    ans = simulate_dataset(folder, RUNS, {"model": {"torsional_compliance_arcsec_per_Nm": 0.2},
                                          "measurement": {"output_encoder_eccentricity_um": 8.0,
                                                          "output_encoder_phase_deg": 30.0}},
                           samples_per_rev=60, seed=4, test_offsets={"10Nm": 3.0, "30Nm": -2.0})
    return read_dataset(folder), json.loads(ans.read_text())["noise_te_arcsec"]


def _fit_result(theta_C: float, encoder: bool) -> SimpleNamespace:
    c = [8.0 * math.cos(math.radians(30.0)), 8.0 * math.sin(math.radians(30.0))]
    eff = [NamedEffect("output_encoder_eccentricity", "output_encoder_eccentricity", "measurement", {}, "um", 8.0,
                       30.0, c, [[0.0, 0.0], [0.0, 0.0]], [8.0, 8.0], 1.0, "")] if encoder else []
    return SimpleNamespace(calibrated_case={"model": {"torsional_compliance_arcsec_per_Nm": theta_C}}, effects=eff,
                           unexplained=[])


def test_the_calibrated_reducer_predicts_the_readings_through_rvdyn(sim):
    """The truth's case and encoder, solved by rvdyn at the readings, leave the noise; without the encoder its
    order 1 (8 um at 100 mm: 16.5 arcsec) is left."""
    ds, noise = sim
    def rms(fit) -> float:
        return rms_without_constants(ds, [r.te_arcsec - p for r, p in zip(ds.runs, predicted_te(fit, ds))])

    assert rms(_fit_result(0.2, True)) == pytest.approx(noise, rel=0.2)
    assert rms(_fit_result(0.2, False)) == pytest.approx(16.5 / math.sqrt(2.0), rel=0.05)


def test_the_table_of_loads_left_out(sim):
    """With a fit that returns the truth, every left-out load is predicted at the noise; the fit sees the other
    load's runs only."""
    ds, noise = sim
    seen = []

    def fit(sub, settings, log):
        seen.append(sorted({r.load_Nm for r in sub.runs}))
        return _fit_result(0.2, True)

    h = holdout_loads(ds, fit=fit)
    assert seen == [[30.0], [10.0]]
    assert [r["load_Nm"] for r in h["rows"]] == [10.0, 30.0]
    for r in h["rows"]:
        assert r["rms_prediction_arcsec"] == pytest.approx(noise, rel=0.25)
        assert r["status"].startswith("predicted at the noise")
        assert r["named"] == ["output_encoder_eccentricity"]


def test_runs_that_declare_other_errors_are_not_predicted(tmp_path):
    runs = [dict(r, declared={"sun_eccentricity": 5.0} if r["load_Nm"] == 30.0 else {}) for r in RUNS]
    simulate_dataset(tmp_path / "ds", runs, samples_per_rev=40, seed=1)
    h = holdout_loads(read_dataset(tmp_path / "ds"), fit=lambda *a: pytest.fail("not fitted"))
    assert all(r["status"].startswith("not predicted: its runs declare other errors") for r in h["rows"])
    assert all(r["rms_declared_arcsec"] is None for r in h["rows"])
