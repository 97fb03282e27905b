"""The full-solver Monte Carlo of rv-stackup: closed form, features, statistics, allocation, reruns.

Small draw and step counts (the closed forms hold at every step, so few steps suffice).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvcad.params import Design
from rvdyn.solver import ARCSEC_PER_RAD
from rvdyn.te import input_angles

from closed_forms import pin_levers
from rvstudy import cli
from rvstudy.capability import allocation, capability, clopper_pearson, sobol_from_design
from rvstudy.features import case_dict, draw, features
from rvstudy.montecarlo import Tolerance, default_tolerances, load_tolerances, parse_tolerance
from rvstudy.study import StudyConfig, run_study

STEPS = 24


def _lever_max(design: Design, steps: int) -> np.ndarray:
    """Largest closed-form pin lever (i Z1/Z2) e (n_i . u'(psi + k pi - theta_out)) at each step, mm
    (docs/physics.md section 6)."""
    g = ReducerGeometry(Case.from_dict({"design": design.to_dict()}))
    return pin_levers(g, input_angles(g.ratio, steps, 1.0, 1)).max(axis=(1, 2))


@pytest.fixture(scope="module")
def common_pin_radius(tmp_path_factory):
    """Only a common pin-radius change, normal(-10 um, 2 um): a uniform clearance at every pin."""
    cfg = StudyConfig(out=tmp_path_factory.mktemp("cf"), solver="analytic", steps=STEPS, workers=1, stages=("mc",),
                      progress=False, figures=False, use_cache=False, load_Nm=0.0, mc_draws=12, mc_sobol=0,
                      mc_check=0, tolerances={"pin_radius": parse_tolerance("pin_radius[common]=normal:2:-10")},
                      mc_contact="impact")  # the rigid limit of the closed form (load 0); ~1/3 the physical law's cost
    return run_study(cfg)


def test_common_pin_radius_closed_form(common_pin_radius):
    """Rigid limit, direction +1: TE at each step = dr / max lambda_i, so mean|TE| = |dr| mean(1/lambda) and
    pp = |dr| (max - min)(1/lambda): the response distribution is the clearance distribution over the lever."""
    mc = common_pin_radius.mc
    d = mc["draws"]
    assert mc["n_features"] == 1 and list(mc["features"]["feature"]) == ["pin_radius[common]"]
    dr = d["pin_radius[common]"].to_numpy()  # um, one value for all 40 pins
    assert (dr < 0).all()
    inv = 1.0 / _lever_max(Design(), STEPS)  # 1/mm
    to_arcmin = 1e-3 * ARCSEC_PER_RAD / 60.0
    np.testing.assert_allclose(d["te_mean_abs_arcmin"], np.abs(dr) * inv.mean() * to_arcmin, rtol=2e-3)
    np.testing.assert_allclose(d["te_pp_arcmin"], np.abs(dr) * (inv.max() - inv.min()) * to_arcmin, rtol=5e-3,
                               atol=1e-6)
    c = mc["responses"]["te_mean_abs_arcmin"]
    assert c["mean"] == pytest.approx(np.mean(-dr) * inv.mean() * to_arcmin, rel=2e-3)
    assert c["std"] == pytest.approx(np.std(dr, ddof=1) * inv.mean() * to_arcmin, rel=2e-3)
    # and the draws are the stated normal: mean -10 um, sigma 2 um (4-sigma bound on the mean of the draws; the
    # sample sigma within 50 %: a wrong scale such as the variance, 4 um, or a uniform of the same bounds fails)
    assert abs(dr.mean() + 10) < 4 * 2 / math.sqrt(len(dr))
    assert 0.5 < dr.std(ddof=1) / 2 < 1.5
    # the lever of the closed form: about (i Z1/Z2) e = 52.4 mm
    assert 1 / inv.max() == pytest.approx(1.3 * 121 / 3, rel=5e-3)


def test_features_of_every_instance():
    tols = default_tolerances()
    f = features(tols, Design())
    # 40 pins x (radius, pitch, radial) + 2x2 cams x (phase, ecc) + 2 planets x (x, y) + 2 carrier holes
    # + 2x2 disc holes + 2 disc phases + sun (x, y) + pin circle offset (x, y)
    assert len(f) == 120 + 8 + 4 + 2 + 4 + 2 + 2 + 2
    X = draw(tols, f, 3, np.random.default_rng(0))
    d = case_dict(f, X.iloc[0], Design(), "t", 20.0)
    e = d["errors"]
    assert len(e["pin_radius"]) == 40 and len(set(e["pin_radius"])) == 40
    assert {(o["crank"], o["disc"]) for o in e["cam_phase"]} == {(0, 0), (0, 1), (1, 0), (1, 1)}
    assert len(e["planet_eccentricity"]) == 2 and "angle_deg" in e["planet_eccentricity"][0]
    x, y = X.iloc[0]["sun_eccentricity.x"], X.iloc[0]["sun_eccentricity.y"]
    assert e["sun_eccentricity"][0]["value"] == pytest.approx(math.hypot(x, y))
    assert e["sun_eccentricity"][0]["angle_deg"] == pytest.approx(math.degrees(math.atan2(y, x)))
    Case.from_dict(d)  # a valid case
    # scopes: common = one value on every pin; default = the default instance (pin 0 for the pitch)
    f2 = features({"pin_pitch": Tolerance("pin_pitch", "normal", (0.01,), "default"),
                   "pin_radius": Tolerance("pin_radius", "normal", (1.0,), "common")}, Design())
    assert [ft.name for ft in f2] == ["pin_pitch[pin=0]", "pin_radius[common]"]
    d2 = case_dict(f2, np.array([0.005, -2.0]), Design(), "t", 20.0)["errors"]
    assert d2["pin_pitch"] == [0.005] + [0.0] * 39 and d2["pin_radius"] == [-2.0] * 40
    # a 30-pin reducer has 30 pins' features
    d30 = Design(z_pins=30, z_disc=29)
    assert sum(ft.tolerance == "pin_radius" for ft in features(tols, d30)) == 30


def test_truncnormal_scope_and_model_tolerances(tmp_path):
    t = parse_tolerance("pin_radius[common]=truncnormal:2:-3:1:-1")
    assert t.scope == "common" and t.dist == "truncnormal"
    x = t.sample(np.random.default_rng(1), 5000)
    assert x.min() >= -3 and x.max() <= 1
    ref = stats.truncnorm((-3 + 1) / 2, (1 + 1) / 2, loc=-1, scale=2)
    assert x.mean() == pytest.approx(ref.mean(), abs=0.05) and t.std == pytest.approx(ref.std())
    m = parse_tolerance("model.cam_bearing_clearance_um=uniform:0:4")
    assert m.is_model and m.unit == "um"
    (tmp_path / "t.csv").write_text("error,dist,p1,p2,p3,p4,scope\npin_radius,truncnormal,1,-2,2,,default\n")
    assert load_tolerances(tmp_path / "t.csv")["pin_radius"] == Tolerance("pin_radius", "truncnormal", (1, -2, 2),
                                                                        "default")
    with pytest.raises(ValueError, match="scope 'some'"):
        parse_tolerance("pin_radius[some]=normal:1")
    with pytest.raises(ValueError, match="model.bogus"):
        parse_tolerance("model.bogus=normal:1")
    with pytest.raises(ValueError, match="truncnormal needs"):
        parse_tolerance("pin_radius=truncnormal:1:2:1")


def test_capability_numbers():
    y = np.array([0.2, 0.4, 0.6, 0.8, 1.2, np.nan])
    c = capability(y, 0.1, 1.0)
    ok = y[:5]
    m, s = ok.mean(), ok.std(ddof=1)
    assert c["cp"] == pytest.approx(0.9 / (6 * s)) and c["cpk"] == pytest.approx(min(1.0 - m, m - 0.1) / (3 * s))
    assert c["out_of_spec_fraction"] == pytest.approx(2 / 6)  # 1.2 and the failed solve
    ci = stats.binomtest(2, 6).proportion_ci(method="exact")
    assert c["out_of_spec_ci"] == pytest.approx([ci.low, ci.high])
    assert clopper_pearson(0, 100)[1] == pytest.approx(1 - 0.025 ** (1 / 100))
    assert capability(ok, None, 1.0)["cp"] is None


def test_sobol_from_design_and_reweighted_allocation():
    rng = np.random.default_rng(3)
    n = 4000
    A, B = rng.normal(0, 1, (n, 2)), rng.normal(0, 1, (n, 2))
    f = lambda M: M[:, 0] + 2 * M[:, 1] + M[:, 0] * M[:, 1]  # noqa: E731 - V = 1 + 4 + 1; S1 = 1/6, 4/6
    AB = {g: np.where(np.arange(2) == j, B, A) for j, g in enumerate(("a", "b"))}
    s = sobol_from_design(f(A), f(B), {g: f(m) for g, m in AB.items()}, n_boot=50).set_index("tolerance")
    assert s.loc["a", "first_order"] == pytest.approx(1 / 6, abs=0.04)
    assert s.loc["b", "first_order"] == pytest.approx(4 / 6, abs=0.05)
    assert s.loc["a", "total"] == pytest.approx(2 / 6, abs=0.04) and s.loc["b", "total"] == pytest.approx(5 / 6, abs=0.05)
    # a response far from zero (mean 100, sigma 2.4): the centred first-order estimate stays as accurate
    # (uncentred its standard error would be ~100/2.4 times larger: about 1 at n = 400)
    m = 400
    s = sobol_from_design(f(A[:m]) + 100, f(B[:m]) + 100, {g: f(mm[:m]) + 100 for g, mm in AB.items()},
                          n_boot=50).set_index("tolerance")
    assert s.loc["a", "first_order"] == pytest.approx(1 / 6, abs=0.15)
    assert s.loc["b", "first_order"] == pytest.approx(4 / 6, abs=0.15)
    # re-weighting: |x| <= 1 with x ~ N(0, 1): tightening sigma to 0.8 gives P(|z| <= 1.25)
    X = pd.DataFrame({"x": rng.normal(0, 1, 20000)})
    al = allocation(X, {"pin_radius": ["x"]}, {"pin_radius": Tolerance("pin_radius", "normal", (1.0,))},
                    X["x"].abs().to_numpy(), None, 1.0).set_index("factor")
    assert al.loc[0.8, "yield"] == pytest.approx(2 * stats.norm.cdf(1.25) - 1, abs=0.01)
    assert al.loc[0.8, "reliable"]


def test_mc_rerun_is_bit_identical_and_reports(tmp_path, capsys):
    tol = tmp_path / "tol.json"  # two tolerances only (a small designed sample): pin radii and a model effect
    tol.write_text(json.dumps({**{k: "none" for k in default_tolerances()}, "pin_radius": "normal:1.5",
                               "model.torsional_compliance_arcsec_per_Nm": "uniform:0:0.5"}))
    # the rerun check is the law's own (the physical MC runs in small_study); no figures: this test reads the
    # report's text, and the Monte Carlo's figures (drawn from the same tables) are checked in small_study
    argv = ["--solver", "analytic", "--steps", "24", "--workers", "1", "--stages", "mc", "--mc-draws", "6",
            "--mc-sobol", "2", "--mc-check", "0", "--no-progress", "--json", "--tolerances", str(tol),
            "--mc-contact", "impact", "--no-figures"]
    assert cli.main(["--out", str(tmp_path / "a"), *argv]) == 0
    s1 = json.loads(capsys.readouterr().out)
    assert cli.main(["--out", str(tmp_path / "b"), *argv, "--no-cache"]) == 0
    s2 = json.loads(capsys.readouterr().out)
    a = pd.read_parquet(tmp_path / "a" / "tables" / "mc_draws.parquet")
    b = pd.read_parquet(tmp_path / "b" / "tables" / "mc_draws.parquet")
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert s1["monte_carlo"]["te_pp_arcmin"] == s2["monte_carlo"]["te_pp_arcmin"]
    m = s1["monte_carlo"]
    for r in ("te_pp_arcmin", "play_3pct_arcmin", "te_mean_abs_arcmin"):
        assert {"n_solver_draws", "mean", "std", "cp", "cpk", "out_of_spec_fraction", "out_of_spec_ci", "yield",
                "contributors"} <= set(m[r])
        assert m[r]["n_solver_draws"] == 6
    assert {c["tolerance"] for c in m["te_pp_arcmin"]["contributors"]} == {
        "pin_radius", "model.torsional_compliance_arcsec_per_Nm"}
    assert 0.0 < a["model.torsional_compliance_arcsec_per_Nm"].max() <= 0.5
    rep = (tmp_path / "a" / "report.md").read_text()
    assert "Monte Carlo tolerance stack-up through the full solver" in rep and "proxy" in rep


def test_play_and_rigidity_equal_rvdyn_stiffness_at_a_locked_input():
    """The two-direction play at +-3 % rated and the b/a secant of the Monte Carlo's solves are readings of
    rvdyn.stiffness's elastic (friction-free) curve at the same locked input (position 0 = input angle 0);
    its lost-motion figure, read with the curve's friction band, is within 0.1 %. A clearance case, which
    the rigid zero-torque point of rvdyn.stiffness accepts."""
    from rvdyn.runner import Runner
    from rvdyn.stiffness import hysteresis
    from rvstudy.stackup import play_at_positions, play_positions, rigidity_at_positions

    case = Case.from_dict({"errors": {"pin_radius": -5.0}})
    rated = 167.0
    run = Runner(None, None, "analytic", play_positions(Design()))
    res = {}
    for name, frac, d in (("dp_3", 0.03, 1), ("dm_3", 0.03, -1), ("dp_full", 1.0, 1), ("dm_full", 1.0, -1)):
        c = Case.from_dict({**case.to_dict(), "load_Nm": frac * rated, "direction": d})
        res[name] = {**run([c], name)[0], "direction": d}
    play = play_at_positions(res["dp_3"], res["dm_3"])
    rig = rigidity_at_positions(res, rated)
    h = hysteresis(case, rated_Nm=rated, theta_in_deg=0.0)
    # the Monte Carlo's solves are the equilibrium alone: rvdyn.stiffness adds the housing ring in series
    el = h.elastic.set_index("torque_Nm")
    el = el["torsion_arcmin"] - el["housing_arcmin"]
    th = {f: el[min(el.index, key=lambda t: abs(t - f * rated))] for f in (-1.0, -0.03, 0.03, 1.0)}
    assert play[0] == pytest.approx(th[0.03] - th[-0.03], rel=1e-9)  # the same elastic curve
    b = 0.97 * rated
    assert rig[0] == pytest.approx(0.5 * (b / (th[1.0] - th[0.03]) + b / (th[-0.03] - th[-1.0])), rel=1e-9)
    # rvdyn.stiffness reads its datasheet figures off the hysteresis curve, whose friction band (its friction
    # torque, 0.09 N m at 3 % here) moves the mid-width points: the proxy is the friction-free reading
    assert play[0] == pytest.approx(h.figures["lost_motion_arcmin"], rel=1e-3)
    assert play.max() >= play[0] and np.all(play > 0)


def test_grouped_draw_solves_equal_single_solves_and_share_the_cache(tmp_path):
    """The five solves of a draw in one worker task (rvdyn.runner group -> rvdyn.te.run_te_many) equal the
    separate solves within the solver tolerance, keep one cache entry each, and a prefetched batch is
    counted once."""
    import dataclasses

    from rvdyn.runner import Runner

    c = Case.from_dict({"errors": {"pin_radius": [0.5 * ((-1) ** i) for i in range(40)], "pin_pitch": 0.004}})
    cases = [c] + [dataclasses.replace(c, load_Nm=L, direction=d) for L, d in ((5.0, 1), (5.0, -1), (167.0, 1),
                                                                               (167.0, -1))]
    steps = [STEPS, 7, 7, 7, 7]
    single = Runner(None, None, "analytic", STEPS)(cases, "single", steps=steps)
    grouped_runner = Runner(None, tmp_path / "cache", "analytic", STEPS)
    grouped = grouped_runner(cases, "grouped", steps=steps, group=[0] * 5)
    assert grouped_runner.computed == 5 and grouped_runner.worker_seconds > 0
    for a, b in zip(single, grouped):
        assert a["key"] == b["key"] and b["status"] == "ok"
        np.testing.assert_allclose(b["te_arcsec"], a["te_arcsec"], rtol=0, atol=1e-4)  # run_te_many's bound
        assert not np.array_equal(b["te_arcsec"], np.zeros_like(b["te_arcsec"]))
    again = Runner(None, tmp_path / "cache", "analytic", STEPS)
    assert [r["key"] for r in again(cases, "from the cache", steps=steps)] == [r["key"] for r in single]
    assert again.computed == 0 and again.reused == 5
    other = dataclasses.replace(c, raw_errors={"pin_pitch": 0.004})
    with pytest.raises(ValueError, match="must differ only in load and direction"):
        Runner(None, None, "analytic", STEPS)([c, other], "bad group", group=[1, 1])
    pre = Runner(None, None, "analytic", STEPS)
    pre.prefetch(cases[:2], "ahead", steps=steps[:2], group=[0, 0])
    out = pre(cases[:2], "read", steps=steps[:2])
    assert pre.computed == 2 and pre.reused == 0
    # the prefetched batch is the batch solve of those two cases (the physical law's damping floor depends on
    # the batch, so a batch of two equals a batch of five only within run_te_many's bound, checked above)
    direct = Runner(None, None, "analytic", STEPS)(cases[:2], "direct", steps=steps[:2], group=[0, 0])
    np.testing.assert_array_equal(out[1]["te_arcsec"], direct[1]["te_arcsec"])
