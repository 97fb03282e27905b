"""The calibration benchmark protocol (benchmarks/realistic.py, score.py, bench_loop.py) and the
simulator's rig zero per test: fast, no calibration run."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import bench_loop  # noqa: E402
import realistic  # noqa: E402
import score as sc  # noqa: E402
from rvcad.errors import ERROR_TYPES  # noqa: E402
from rvcad.params import Design  # noqa: E402
from rvrig.dataset import read_dataset  # noqa: E402
from rvcalib.simulate import simulate_dataset  # noqa: E402

RUNS = [{"run": "a", "load_Nm": 10.0, "direction": 1, "test": "T1"},
        {"run": "b", "load_Nm": 10.0, "direction": -1, "test": "T1"},
        {"run": "c", "load_Nm": 30.0, "direction": 1}]


# ---------------------------------------------------------------------------------------------- simulator
def _samples(folder: Path) -> pd.DataFrame:
    return pd.read_csv(folder / "samples.csv")


def test_simulate_adds_each_tests_constant_to_its_runs_only(tmp_path):
    kw = dict(noise_arcsec=0.1, input_noise_arcsec=0.5, samples_per_rev=16, seed=4, start_deg=0.3)
    simulate_dataset(tmp_path / "zero", RUNS, **kw)
    ap = simulate_dataset(tmp_path / "off", RUNS, test_offsets={"T1": 12.5, "c": -3.0}, **kw)
    a, b = _samples(tmp_path / "zero"), _samples(tmp_path / "off")
    assert np.array_equal(a["input_deg"], b["input_deg"])          # same noise draws
    diff = (b["output_deg"] - a["output_deg"]) * 3600.0
    want = b["run"].map({"a": 12.5, "b": 12.5, "c": -3.0})
    assert np.allclose(diff, want, atol=1e-5)                        # the CSV's 1e-10 deg rounding
    ans = json.loads(ap.read_text())
    assert ans["test_offsets"] == {"T1": 12.5, "c": -3.0}
    assert ans["run_tests"] == {"a": "T1", "b": "T1", "c": "c"}
    assert "test" not in pd.read_csv(tmp_path / "off" / "runs.csv").columns   # the dataset does not say
    read_dataset(tmp_path / "off")                                   # and stays a valid dataset


@pytest.mark.parametrize("offsets, match", [({"T9": 1.0}, "test_offsets key 'T9' is no run's test"),
                                            ({"T1": math.nan}, r"test_offsets\['T1'\] = nan must be a finite")])
def test_simulate_refuses_bad_test_offsets(tmp_path, offsets, match):
    with pytest.raises(ValueError, match=match):
        simulate_dataset(tmp_path / "x", RUNS, samples_per_rev=16, test_offsets=offsets)
    assert not (tmp_path / "x").exists()                             # nothing half-written


# ---------------------------------------------------------------------------------------------- generator
def test_seed_sets_are_fixed_and_disjoint():
    assert list(realistic.DEV_SEEDS) == list(range(101, 111))
    assert list(realistic.HELDOUT_SEEDS) == list(range(9001, 9025))
    assert realistic.seeds_of("dev", [103, 101]) == [103, 101]
    with pytest.raises(ValueError, match=r"seeds \[5\] are not in the heldout set"):
        realistic.seeds_of("heldout", [5])
    with pytest.raises(ValueError, match="set 'test' is unknown"):
        realistic.seeds_of("test")


def test_every_draw_holds_eleven_errors_at_instances_in_range():
    d = Design()
    counts = {"crank": d.n_cranks, "disc": d.n_discs, "hole": d.n_cranks, "pin": d.z_pins}
    pins = set()
    for seed in [*realistic.DEV_SEEDS, *realistic.HELDOUT_SEEDS]:
        dr = realistic.draw(seed)
        assert dr == realistic.draw(seed)                            # the seed fixes it
        assert list(dr.errors) == list(ERROR_TYPES)
        for key, item in dr.errors.items():
            et = ERROR_TYPES[key]
            want = set(et.instance_keys) - ({"pin"} if key in ("pin_circle_diameter", "pin_radius") else set())
            assert set(item) - {"value", "angle_deg"} == want
            assert all(0 <= item[k] < counts[k] for k in want)
            assert ("angle_deg" in item) == et.has_angle
            assert 0.0 <= item.get("angle_deg", 0.0) < 360.0
            assert abs(item["value"]) < 6 * et.paper_value / 3
        pins.add(dr.errors["pin_pitch"]["pin"])
        assert 0.1 <= dr.compliance <= 0.3 and 0.0 <= dr.start_deg < 1.0
        assert set(dr.test_offsets) == {"10Nm", "30Nm"}
    assert len(pins) > 10                                            # the pin is drawn, not fixed
    assert realistic.draw(101).errors != realistic.draw(102).errors


def test_generated_answer_holds_what_was_drawn(tmp_path, monkeypatch):
    monkeypatch.setattr(realistic, "SAMPLES_PER_REV", 16)            # the same rules on fewer readings
    folder = realistic.generate(9001, tmp_path)
    ans = json.loads((folder / "answer.json").read_text())
    dr = realistic.draw(9001)
    assert ans["draw"] == json.loads(json.dumps(dr.to_dict()))
    exp = {(e["key"], sc.instance_key(e.get("instance"))): e for e in ans["expected_effects"]}
    for key, item in dr.errors.items():
        e = exp[(key, sc.instance_key({k: v for k, v in item.items() if k not in ("value", "angle_deg")}))]
        assert e["value"] == item["value"] and e.get("angle_deg") == item.get("angle_deg")
    assert exp[("torsional_compliance_arcsec_per_Nm", ())]["value"] == dr.compliance
    assert ans["test_offsets"] == dr.test_offsets
    runs = pd.read_csv(folder / "dataset" / "runs.csv")
    for test in ("10Nm", "30Nm"):                                    # both directions of each load share it
        ids = [r for r, t in ans["run_tests"].items() if t == test]
        sub = runs[runs["run"].astype(str).isin(ids)]
        assert sorted(sub["direction"]) == [-1, 1] and set(sub["load_Nm"]) == {float(test[:-2])}
    assert ans["noise_te_arcsec"] == pytest.approx(math.hypot(0.2, 1.0 / Design().ratio))
    assert ans["samples_per_rev"] == 16 and ans["start_deg"] == dr.start_deg
    stamp = (folder / "answer.json").stat().st_mtime_ns
    assert realistic.generate(9001, tmp_path) == folder and (folder / "answer.json").stat().st_mtime_ns == stamp
    ans["draw"]["generator"] = "another"                            # a draw of other rules is drawn again
    (folder / "answer.json").write_text(json.dumps(ans))
    realistic.generate(9001, tmp_path)
    assert json.loads((folder / "answer.json").read_text())["draw"]["generator"] == realistic.GENERATOR


# ---------------------------------------------------------------------------------------------- scorer
def _answer() -> dict:
    def e(key, inst, unit, value, angle=None):
        d = {"key": key, "name": key, "instance": inst, "unit": unit, "value": value}
        if angle is not None:
            d["angle_deg"] = angle
        return d
    return {"noise_te_arcsec": 0.2, "expected_effects": [
        e("sun_eccentricity", {}, "um", 6.0, 30.0), e("cam_phase", {"crank": 1, "disc": 0}, "um", 4.0),
        e("pin_radius", {}, "um", -2.0), e("pin_pitch", {"pin": 3}, "deg", 0.006),
        e("disc_phase", {"disc": 1}, "deg", 0.03),
        {"key": "torsional_compliance_arcsec_per_Nm", "name": "torsional_compliance_arcsec_per_Nm",
         "unit": "arcsec/(N m)", "value": 0.2}]}


def _eff(name, unit, value, lo=None, hi=None, family="table4", angle=None, components=None, cov=None):
    key, inst = sc.parse_name(name)
    return {"name": name, "key": key, "family": family, "instance": inst, "unit": unit, "value": value,
            "angle_deg": angle, "components": components, "cov": cov,
            "ci95": [value - 1 if lo is None else lo, value + 1 if hi is None else hi]}


def _result(*extra, rms=0.22, comp=0.21):
    c = 6.0 * np.array([math.cos(math.radians(30.0)), math.sin(math.radians(30.0))])
    effects = [_eff("torsional_compliance_arcsec_per_Nm", "arcsec/(N m)", comp, 0.19, 0.22, "model"),
               _eff("cam_phase[crank=1,disc=0]", "um", 4.9),
               _eff("pin_pitch[pin=3]", "deg", 0.0055, 0.005, 0.007),
               _eff("sun_eccentricity", "um", 6.0, angle=30.0, components=list(c), cov=[[1.0, 0.0], [0.0, 1.0]]),
               *extra]
    return {"rms_before": 20.0, "rms_after": rms, "effects": effects,
            "groups": [{"members": [{"name": "planet_eccentricity[crank=0]", "value": 30.0, "probability": 0.5}]}]}


def test_a_result_within_every_rule_passes_and_groups_do_not_count():
    s = sc.score(_result(_eff("disc_phase[disc=0]", "deg", 0.007, 0.0, 0.01)), _answer())
    assert s["passed"], s["reasons"]
    assert [e["verdict"] for e in s["effects"]] == ["ok", "ok", "ok", "ok", "small extra"]
    assert s["covered"] == 5 and s["n_intervals"] == 5 and len(s["groups"]) == 1
    assert any("group" in line for line in sc.score_lines(s))


@pytest.mark.parametrize("result, reason", [
    (_result(rms=0.25), "RMS after 0.25 arcsec > 1.2 x noise"),
    (_result(comp=0.225), "off: torsional_compliance"),                              # 12.5 % off
    (_result(_eff("cam_phase[crank=0,disc=0]", "um", 4.0)), "false name: cam_phase[crank=0,disc=0]"),  # twin
    (_result(_eff("pin_pitch[pin=5]", "deg", 0.008)), "false name: pin_pitch[pin=5]"),  # > 25 % of 0.03 deg
    (_result(_eff("friction_torque_Nm", "N m", 0.01, family="model")), "false name: friction_torque_Nm"),
    (_result(_eff("output_encoder_eccentricity", "um", 0.5, family="measurement", angle=0.0)),
     "false name: output_encoder_eccentricity"),
    (_result(_eff("pin_radius", "um", -3.1)), "off: pin_radius"),                      # 1.1 um > max(1, 0.5)
])
def test_each_way_to_fail(result, reason):
    s = sc.score(result, _answer())
    assert not s["passed"]
    assert any(r.startswith(reason) for r in s["reasons"]), s["reasons"]


def test_tolerances_at_their_edges():
    ans = _answer()
    assert sc.score(_result(_eff("pin_radius", "um", -2.99)), ans)["passed"]         # within 1 um
    assert sc.score(_result(comp=0.219), ans)["passed"]                               # within 10 %
    assert sc.score(_result(_eff("cam_phase[crank=0,disc=0]", "um", -1.49)), ans)["passed"]  # 25 % of 6 um
    assert not sc.score(_result(_eff("cam_phase[crank=0,disc=0]", "um", -1.51)), ans)["passed"]
    r = _result()
    r["effects"] = r["effects"][1:]
    assert sc.score(r, ans)["reasons"] == ["the compliance is not named"]


def test_a_polar_effect_is_judged_by_its_components_and_covered_by_mahalanobis():
    ans = _answer()
    t = 6.0 * np.array([math.cos(math.radians(30.0)), math.sin(math.radians(30.0))])
    flip = _eff("sun_eccentricity", "um", -6.0, angle=210.0)          # the same vector, written the other way
    rec = sc.judge_effect(dict(flip, cov=[[0.01, 0], [0, 0.01]]), sc.truths(ans))
    assert rec["verdict"] == "ok" and rec["distance"] < 1e-12 and rec["covered"]
    turned = _eff("sun_eccentricity", "um", 6.0, angle=60.0)           # right size, 30 deg off: 3.1 um away
    rec = sc.judge_effect(turned, sc.truths(ans))
    assert rec["verdict"] == "off" and rec["distance"] == pytest.approx(12 * math.sin(math.radians(15)))
    for shift, cov, inside in [((1.0, 1.0), [[1, 0], [0, 1]], True),        # d2 = 2
                               ((2.0, 2.0), [[1, 0], [0, 1]], False),       # d2 = 8 > 5.99
                               ((2.0, 2.0), [[4, 0], [0, 4]], True),        # d2 = 2
                               ((0.0, 3.0), [[25, 0], [0, 1]], False),      # long along x, short along y
                               ((0.0, 0.0), None, False)]:                  # no covariance: not covered
        e = _eff("sun_eccentricity", "um", 6.0, components=list(t + shift), cov=cov)
        assert sc.judge_effect(e, sc.truths(ans))["covered"] is inside


def test_coverage_is_counted_per_named_effect_and_pooled():
    ans = _answer()
    miss = _eff("cam_phase[crank=1,disc=0]", "um", 4.9, 4.5, 5.5)                # interval misses 4.0
    extra = _eff("cam_phase[crank=0,disc=0]", "um", 0.5, 0.2, 0.8)               # absent: truth 0, missed
    r = _result(extra)
    r["effects"][1] = miss
    s1 = sc.score(r, ans)
    assert s1["passed"] and (s1["covered"], s1["n_intervals"]) == (3, 5)
    s2 = sc.score(_result(), ans)
    raised = sc.score(None, ans, "RuntimeError: boom")
    assert not raised["passed"] and raised["reasons"] == ["the method raised: RuntimeError: boom"]
    assert sc.pool([s1, s2, raised]) == {"draws": 3, "passed": 2, "covered": 7, "n_intervals": 9,
                                         "coverage": 7 / 9}


def test_parse_name():
    assert sc.parse_name("cam_phase[crank=1,disc=0]") == ("cam_phase", {"crank": 1, "disc": 0})
    assert sc.parse_name("pin_radius") == ("pin_radius", {})
    with pytest.raises(ValueError, match=r"instance part 'crank' is not index=integer"):
        sc.parse_name("cam_phase[crank]")


# ---------------------------------------------------------------------------------------------- adapter
# ---------------------------------------------------------------------------------------------- bench_loop
def test_bench_loop_fails_a_raising_method_and_resumes(tmp_path, monkeypatch, capsys):
    ds = tmp_path / "draws" / "seed101"
    ap = simulate_dataset(ds / "dataset", RUNS, samples_per_rev=16, answer_path=ds / "answer.json",
                          hidden={"model": {"torsional_compliance_arcsec_per_Nm": 0.2}})
    calls, recorded = [], []

    def boom(method, dataset, log=None, workers=1, **settings):
        calls.append((method, settings))
        raise RuntimeError("no convergence")
    monkeypatch.setattr(bench_loop, "generate", lambda seed, root: ds)
    monkeypatch.setattr(bench_loop, "run_method", boom)
    monkeypatch.setattr(bench_loop, "record_summary", lambda *a: recorded.append(a))
    argv = ["--set", "dev", "--seeds", "101", "--out", str(tmp_path / "out")]
    assert bench_loop.main(argv) == 1
    rec = json.loads((tmp_path / "out" / "seed101.json").read_text())
    assert rec["error"] == "RuntimeError: no convergence" and not rec["score"]["passed"]
    assert recorded[-1][:3] == ("new", "dev", [101]) and recorded[-1][3]["raised"] == 1
    out = capsys.readouterr().out
    assert "seed 101: FAIL (raised)" in out and "SUMMARY new dev: 0/1 pass (1 raised)" in out
    bench_loop.main(argv)                                              # reused, not run again
    assert calls == [("new", {})] and len(recorded) == 2
    bench_loop.main(argv + ["--report-only"])                          # printed, not recorded
    assert calls == [("new", {})] and len(recorded) == 2
    assert bench_loop.main(["--set", "dev", "--out", str(tmp_path / "empty"), "--report-only"]) == 1
    assert calls == [("new", {})] and "no draw run yet" in capsys.readouterr().out
    bench_loop.main(argv + ["--fresh"])
    assert calls == [("new", {})] * 2
    bench_loop.main(argv + ["--secant-width", "1"])                     # another method: run, not reused
    assert calls[-1] == ("new", {"secant_width": 1.0})
    assert recorded[-1][0] == "new-secant-width-1"
    assert json.loads((tmp_path / "out" / "seed101.json").read_text())["method"] == "new-secant-width-1"
    assert json.loads(ap.read_text())["test_offsets"] == {}


def test_bench_loop_names_a_subset_by_its_seeds(monkeypatch):
    import results_log
    got = []
    monkeypatch.setattr(results_log, "record", lambda bench, figs: got.append((bench, figs)))
    summ = {"draws": 2, "passed": 1, "raised": 0, "n_intervals": 4, "coverage": 0.5, "median_wall_s": 10.0,
            "median_cpu_s": 9.0}
    bench_loop.record_summary("new", "heldout", [9001, 9002], summ)
    bench_loop.record_summary("new", "dev", None, summ)
    names = [f for _, figs in got for f, *_ in figs]
    assert "new_heldout_seeds_9001_9002_passed" in names and "new_dev_passed" in names
    assert not any("subset" in n for n in names)


# ---------------------------------------------------------------------------------------------- tolerance prior
def test_tolerance_prior_posterior_against_its_closed_forms():
    """One column with a Gaussian prior: the ridge formula; a flat column: least squares; the evidence's noise of
    a flat model: the unbiased residual variance RSS / (n - p)."""
    import tolerance_prior as tp

    rng = np.random.default_rng(3)
    x = rng.normal(size=(50, 1))
    r = 2.0 * x[:, 0] + rng.normal(0.0, 0.5, 50)
    m, C = tp.posterior(x, r, 0.5, np.array([1.5]))
    xx, xr = float(x[:, 0] @ x[:, 0]), float(x[:, 0] @ r)
    assert m[0] == pytest.approx(xr / (xx + 0.25 / 1.5 ** 2), rel=1e-12)
    assert C[0, 0] == pytest.approx(1.0 / (xx / 0.25 + 1.0 / 1.5 ** 2), rel=1e-12)
    X = rng.normal(size=(50, 3))
    m, _ = tp.posterior(X, r, 0.5, np.full(3, np.inf))
    ols = np.linalg.lstsq(X, r, rcond=None)[0]
    assert np.allclose(m, ols, rtol=1e-10)
    rss = float(np.sum((r - X @ ols) ** 2))
    assert tp.noise_evidence(X, r, 50, np.full(3, np.inf), 1.0) == pytest.approx(math.sqrt(rss / 47), rel=1e-8)


def test_tolerance_prior_names_only_what_its_region_excludes_zero():
    import tolerance_prior as tp

    one = SimpleNamespace(n_params=1, effect_name="a", key="a", family="table4", instance=(), unit="um",
                          size=lambda v: (float(v[0]), None))
    two = SimpleNamespace(n_params=2, effect_name="b", key="b", family="table4", instance=(), unit="um",
                          size=lambda v: (float(np.hypot(*v)), float(np.degrees(np.arctan2(v[1], v[0])))))
    cov = np.diag([1.0, 1.0, 1.0])
    got = tp.named_effects([one, two], np.array([2.5, 1.5, 1.5]), cov)     # 2.5 > 1.96; 4.5 < chi2(2) 5.99
    assert [e["name"] for e in got] == ["a"]
    assert got[0]["ci95"] == pytest.approx([2.5 - 1.959964, 2.5 + 1.959964], abs=1e-5)
    got = tp.named_effects([one, two], np.array([1.5, 2.0, 1.8]), cov)     # 1.5 < 1.96; 7.24 > 5.99
    assert [e["name"] for e in got] == ["b"]
