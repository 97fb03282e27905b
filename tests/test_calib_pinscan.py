"""The pin scan before the loop stops (rvcalib.pinscan, issue 10, "#7").

Two parts: the ranking in the model linearised at the state (pure linear algebra: an addition, a replacement of a
stand-in, the size kept on its own side of the kink), and the check through the full model (impact law, the test
session's runner): data made by the simulator at 200 readings per output revolution from 0.37 deg (off the
loop's grid), its own noise and seed, two runs holding pin 5's pitch error alone; the state holds pin 4's radius
as its stand-in. The loop's shifted signatures are not used: every pin's instance is solved at the state (here
the library holds pins 0-9 to keep the test short).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcalib.pinscan import PIN_SCAN_STEP, scan_ranking


def _linear_world(seed: int = 3, n: int = 400):
    """A linear model with three members (columns G) and a candidate R that member 1 stands in for: the data hold
    members 0 and 2 and R at 1.5 steps; the state is the members' least-squares fit. The residual's Jacobian is
    -G; a candidate's column is the change of the residual for one step (-g on its positive side; its negative
    side moves the TE only a third as much, a kink at zero)."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(n, 3))
    u = rng.normal(size=n)
    g_r = 0.8 * G[:, 1] + 0.6 * u
    g_a = rng.normal(size=n)
    noise = 0.01 * rng.normal(size=n)
    return G, g_r, g_a, noise


def test_a_stand_in_is_replaced_by_the_candidate_it_stands_in_for():
    G, g_r, g_a, noise = _linear_world()
    y = G[:, 0] * 1.0 + G[:, 2] * 0.5 + 1.5 * g_r + noise
    x, *_ = np.linalg.lstsq(G, y, rcond=None)
    r = y - G @ x
    cols = {("R", 1.0): -g_r, ("R", -1.0): g_r / 3.0, ("A", 1.0): -g_a, ("A", -1.0): g_a / 3.0}
    member_cols = [np.array([0]), np.array([1]), np.array([2])]
    additions, replacements, removals, _ = scan_ranking(r, -G, x, member_cols, cols)
    best = replacements[1][0]
    assert best[1] == "R" and best[2] == pytest.approx(1.5, abs=0.01)
    assert best[0] == pytest.approx(float(noise @ noise), rel=0.05)   # to the noise
    assert best[0] < float(r @ r) / 10                                 # far below the state
    # in place of member 0 or 2 (which the data hold) the best leaves far more
    assert min(replacements[0][0][0], replacements[2][0][0]) > 100 * best[0]
    # without member 1 (the others refitted) R's part is back: far above what R leaves in its place
    assert removals[1] > 100 * best[0] and removals[1] > float(r @ r)
    # as an addition (member 1 refitted beside it, to about zero) R leaves the same: the refits' BIC decides
    assert additions[0][1] == "R" and additions[0][0] == pytest.approx(best[0], rel=0.01)


def test_a_size_stays_on_its_own_side_of_the_kink():
    G, _, g_a, noise = _linear_world(seed=5)
    # candidate A moves the TE by -g_a per step on its positive side and by g_a / 3 per step on its negative side;
    # the data hold it at -3 steps
    t_pos, t_neg = -g_a, g_a / 3.0
    y = G @ np.array([1.0, -0.5, 0.3]) + 3.0 * t_neg + noise
    x, *_ = np.linalg.lstsq(G, y, rcond=None)
    r = y - G @ x
    cols = {("A", 1.0): -t_pos, ("A", -1.0): -t_neg}
    additions, _, _, _ = scan_ranking(r, -G, x, [np.array([0]), np.array([1]), np.array([2])], cols)
    rss, name, steps = additions[0]
    assert name == "A" and steps == pytest.approx(-3.0, abs=0.02)
    assert rss == pytest.approx(float(noise @ noise), rel=0.05)
    # the positive side's column would need a negative size: it is held at 0 and leaves the state as it was
    pos = additions[1]
    assert pos[1] == "A" and pos[2] == 0.0 and pos[0] == pytest.approx(float(r @ r), rel=1e-9)


@pytest.mark.usefixtures("calib_forward_cache")  # solves shared by the session (impact law)
def test_a_neighbour_pin_s_radius_is_replaced_by_the_true_pin_s_pitch(tmp_path):
    from rvcalib.dataset import read_dataset
    from rvcalib.effects import Library, build_library
    from rvcalib.identify import Calibrator
    from rvcalib.results import Active
    from rvcalib.simulate import simulate_dataset

    noise = 0.1
    runs = [{"run": "fw10", "load_Nm": 10.0, "direction": 1}, {"run": "bw10", "load_Nm": 10.0, "direction": -1}]
    truth = {"errors": {"pin_pitch": [{"pin": 5, "value": 0.01}]}}
    simulate_dataset(tmp_path / "ds", runs, truth, samples_per_rev=200, start_deg=0.37, seed=17, noise_arcsec=noise,
                     input_noise_arcsec=0.5)
    ds = read_dataset(tmp_path / "ds")
    # the scan solves every pin instance of the library: here pins 0-9 of two error types (38 trials a run
    # condition; the loop's library has all 40 pins of three)
    lib = Library([e for e in build_library(ds) if e.key in ("pin_pitch", "pin_radius")
                   and dict(e.instance).get("pin") is not None and dict(e.instance)["pin"] < 10])
    cal = Calibrator(ds, library=lib)
    cal.thr, cal.max_terms = 1e-4, 6
    said: list[str] = []
    cal.log = said.append
    stand_in = lib.by_name("pin_radius[pin=4]")
    params, rss, *_ = cal.fit_full([stand_in], [np.array([-2.0])], [])
    cal.active = [Active(stand_in, params[0], 1)]
    cal.refresh_state()
    rms_before = math.sqrt(cal.rss_full / cal.n)
    assert rms_before > 3 * noise, said
    got = cal.pin_scan_refit(5)
    assert got == ("pin_radius[pin=4]", "pin_pitch[pin=5]"), said
    a = cal.active[-1]
    assert [x.effect.name for x in cal.active] == [got[1]]
    assert abs(float(a.p[0])) == pytest.approx(0.01, rel=0.05)
    assert a.info["selection"] == {"method": "pin scan before the stop", "iteration": 5, "replaced": "pin_radius[pin=4]"}
    assert math.sqrt(cal.rss_full / cal.n) < 1.2 * noise
    assert any(s.startswith("pin scan: ") and "instances solved at the state" in s for s in said)
    assert PIN_SCAN_STEP * lib.by_name("pin_pitch[pin=5]").scale == pytest.approx(0.005)


def _pruning_world(seed: int = 8, n: int = 500):
    """Five one-parameter members of a linear model; the data hold members 0 (size 2) and 2 (size 0.6) and noise
    0.05; the state is the least-squares fit of all five (the residual's Jacobian is -G)."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(n, 5))
    y = 2.0 * G[:, 0] + 0.6 * G[:, 2] + 0.05 * rng.normal(size=n)
    x, *_ = np.linalg.lstsq(G, y, rcond=None)
    return y - G @ x, -G, x, [np.array([j]) for j in range(5)], n


def test_the_bic_backward_elimination_keeps_what_the_data_hold():
    from rvcalib.lsq import bic_backward

    r, J, x, cols, n = _pruning_world()
    assert bic_backward(r, J, x, cols, n) == [0, 2]
    # a limit below the BIC's choice removes the smaller of the two next
    assert bic_backward(r, J, x, cols, n, max_members=1) == [0]
    # a member that must stay stays, the others go as before
    assert bic_backward(r, J, x, cols, n, keep={4}) == [0, 2, 4]
    # with a two-parameter member holding columns 1 and 3 (both empty in the data) it goes as one
    cols2 = [np.array([0]), np.array([1, 3]), np.array([2]), np.array([4])]
    assert bic_backward(r, J, x, cols2, n) == [0, 2]


def test_the_swap_with_the_missing_error_types_is_adopted_by_the_bic(monkeypatch):
    """The bookkeeping of the refit with the error types the model lacked, on stubs: member B (index 1) replaced by
    pin P, the families the model then lacks beside them (B's own family from zero, C once; the expensive and
    measurement ones are not added), the elimination keeping A, P and C, the refit lowering the BIC."""
    import rvcalib.pinscan as ps
    from rvcalib.effects import Effect
    from rvcalib.subsets import JOINT_BIC_MARGIN
    from rvcalib.lsq import bic
    from rvcalib.results import Active, Candidate, EmpiricalTerm

    def eff(name, family="table4", template=None, expensive=False):
        return Effect(name, name.split("[")[0], family, "um", name, template=template, expensive=expensive)

    A, B, P, C = eff("A"), eff("B[crank=1]", template="B[crank=0]"), eff("pin_pitch[pin=3]"), eff("C")
    s = ps.PinScan.__new__(ps.PinScan)
    s.active = [Active(A, np.array([1.0]), 1, info={"tag": "A"}), Active(B, np.array([2.0]), 2)]
    harmonic = EmpiricalTerm("harmonic", 79)
    s.empirical, s.n, s.rss_full, s.max_terms = [harmonic], 1000, 40.0, 12
    s.log = lambda msg: None
    s._emp_matrix = lambda terms, coarse=False: None
    s.coarse_residual = lambda pairs=None: [np.zeros(4)]
    refreshed = []
    s.refresh_state = lambda: refreshed.append(True)
    ranking = [eff("B[crank=0]"), eff("X", expensive=True), eff("M", family="measurement"), C, eff("C2")]
    ranking[4] = eff("C[crank=1]", template="C")   # C's own family again: added once
    s.rank = lambda rc, Ec, r_full=None: [Candidate(e, 0.5, np.zeros(1)) for e in ranking]
    fits = []
    rss_end = 40.0 * math.exp((-30.0 + math.log(1000)) / 1000)   # dBIC -30 with one parameter fewer

    terms_seen = []

    def fit_full(effects, p0, terms):
        fits.append([e.name for e in effects])
        terms_seen.append(terms)
        params = [np.asarray(p, dtype=float) + 0.5 for p in p0]
        return params, (39.0 if len(fits) == 1 else rss_end), np.zeros(len(effects)), (lambda z: np.zeros(3)), None

    s.fit_full = fit_full
    monkeypatch.setattr(ps, "bic_backward", lambda r, J, x, cols, n, max_members=None: [0, 1, 3])
    got = s._with_missing_types(1, P, -0.004, 7)
    assert fits[0] == ["A", "pin_pitch[pin=3]", "B[crank=0]", "C"]   # each lacking family once
    assert fits[1] == ["A", "pin_pitch[pin=3]", "C"]
    assert got == ("B[crank=1], " + harmonic.label, "pin_pitch[pin=3], C")
    assert s.empirical == []                                  # the harmonic stood for what the model lacked
    assert all(t == [] for t in terms_seen)                   # fitted without the empirical terms
    assert [a.effect.name for a in s.active] == ["A", "pin_pitch[pin=3]", "C"]
    assert s.active[0].info == {"tag": "A"}                    # a member that stays keeps its record
    assert s.active[1].info["selection"]["with"] == "pin_pitch[pin=3]"
    assert s.active[1].info["delta_bic"] == pytest.approx(bic(rss_end, 1000, 3) - bic(40.0, 1000, 4))
    assert s.active[1].info["delta_bic"] == pytest.approx(-30.0)
    assert s.active[1].info["delta_bic"] < -JOINT_BIC_MARGIN and refreshed == [True]
    # a refit that does not lower the BIC by the margin changes nothing
    s.active = [Active(A, np.array([1.0]), 1), Active(B, np.array([2.0]), 2)]
    s.empirical = [harmonic]
    rss_end = 40.0 * math.exp((-1.0 + math.log(1000)) / 1000)   # dBIC -1: inside the margin
    fits.clear()
    assert s._with_missing_types(1, P, -0.004, 8) is None
    assert [a.effect.name for a in s.active] == ["A", "B[crank=1]"] and s.empirical == [harmonic]
    # no swap (step 5, at the term limit): the members as they are with the families the model lacks (C once;
    # B's twin is B's own family, in the model), the elimination keeping A, B and C
    rss_end = 40.0 * math.exp((-30.0 + math.log(1000)) / 1000)
    fits.clear()
    monkeypatch.setattr(ps, "bic_backward", lambda r, J, x, cols, n, max_members=None: [0, 1, 2])
    got = s._with_missing_types(None, None, 0.0, 9)
    assert fits[0] == ["A", "B[crank=1]", "C"] and fits[1] == ["A", "B[crank=1]", "C"]
    assert got == (harmonic.label, "C")
    assert [a.effect.name for a in s.active] == ["A", "B[crank=1]", "C"] and s.empirical == []
    assert s.active[2].info["selection"]["with"] is None and s.active[2].info["selection"]["iteration"] == 9


def test_no_scan_when_the_state_is_within_the_noise():
    """A state whose residual is white noise at the noise estimate (structured_noise): nothing is solved."""
    import rvcalib.pinscan as ps
    from rvcad.params import Design
    from rvcalib.effects import Effect
    from rvcalib.residual import structured_noise
    from rvcalib.results import Active

    rng = np.random.default_rng(4)
    r = 0.1 * rng.normal(size=600)
    s = ps.PinScan.__new__(ps.PinScan)
    s.active = [Active(Effect("A", "A", "table4", "um", "A"), np.array([1.0]), 1)]
    s.empirical, s.n = [], r.size
    s._pin_candidates = lambda: ["a candidate"]
    s.over_budget = lambda: False
    s._pairs = lambda: []
    s.full_residual = lambda pairs, terms: (r, np.zeros(0))
    s.split = lambda v: [v]
    said: list[str] = []
    s.log = said.append
    import types

    class Solved(Exception):
        pass

    def predict_many(*a, **k):
        raise Solved

    s.predict_many = s.predict_rows = predict_many
    s.keep_state_jacobian = lambda: None
    s._emp_matrix = lambda terms, coarse=False: None
    s._cached_jacobian = lambda *a: (np.zeros((r.size, 1)), np.array([True]))
    run = types.SimpleNamespace(input_deg=np.linspace(0.0, 121.0 * 360.0, r.size, endpoint=False), ratio=121.0,
                                n=r.size, revolutions=1.0)
    s.ds = types.SimpleNamespace(runs=[run], design=Design())
    s.runs = s.ds.runs
    sigma = structured_noise(s.ds, [r])
    assert sigma == pytest.approx(0.1, rel=0.02)
    s.rss_full = 0.98 * r.size * sigma ** 2        # below the noise estimate's variance: nothing is solved
    assert s.pin_scan_refit(3) is None
    assert said and said[-1].startswith("pin scan: not made, the state's residual")
    s.rss_full = 1.02 * r.size * sigma ** 2        # above it: the instances are solved
    s._pin_candidates = lambda: [Effect("pin_pitch[pin=1]", "pin_pitch", "table4", "deg", "p")]
    with pytest.raises(Solved):
        s.pin_scan_refit(3)


@pytest.mark.usefixtures("calib_forward_cache")  # solves shared by the session (impact law)
def test_the_model_at_some_readings_is_the_model_at_all_readings_there(tmp_path):
    """LoopModel.predict_rows (the scan solves every third reading of the realistic draws): solved at the kept
    readings alone, it gives the TE that the solve at every reading gives there, within the solver's tolerance."""
    from rvcalib.dataset import read_dataset
    from rvcalib.identify import Calibrator
    from rvcalib.simulate import simulate_dataset

    runs = [{"run": "fw20", "load_Nm": 20.0, "direction": 1}, {"run": "bw20", "load_Nm": 20.0, "direction": -1}]
    simulate_dataset(tmp_path / "ds", runs, {"errors": {"pin_pitch": [{"pin": 3, "value": 0.01}]}},
                     samples_per_rev=150, start_deg=0.41, seed=5, noise_arcsec=0.1)
    cal = Calibrator(read_dataset(tmp_path / "ds"))
    state = [(cal.lib.by_name("pin_radius[pin=7]"), np.array([2.0]))]
    full = np.concatenate(cal.predict(state))
    keep = np.zeros(cal.n, dtype=bool)
    keep[1::3] = True
    part = cal.predict_rows([state, []], keep)
    assert part[0].shape == (int(keep.sum()),)
    np.testing.assert_allclose(part[0], full[keep], rtol=0, atol=1e-6)
    # another state at the same readings differs (the comparison can fail)
    assert np.max(np.abs(part[1] - full[keep])) > 0.1
    with pytest.raises(ValueError, match=r"keep has shape \(299,\); one flag per sample \(300\)"):
        cal.predict_rows([state], keep[:-1])


@pytest.mark.usefixtures("calib_forward_cache")  # solves shared by the session (impact law)
def test_a_fit_at_a_third_of_the_readings_finds_the_size_of_a_fit_at_every_reading(tmp_path):
    """Fitting.fit_rows (the first refit of a swap trial, JointSelection.trial_refit): the data of a pin's pitch
    error with noise, fitted at every third reading only, give the size the fit at every reading gives, within the
    subset's standard error; the state's sum of squares there is the subset's part of the full one."""
    from rvcalib.dataset import read_dataset
    from rvcalib.identify import Calibrator
    from rvcalib.simulate import simulate_dataset

    runs = [{"run": "fw20", "load_Nm": 20.0, "direction": 1}, {"run": "bw20", "load_Nm": 20.0, "direction": -1}]
    simulate_dataset(tmp_path / "ds", runs, {"errors": {"pin_pitch": [{"pin": 3, "value": 0.01}]}},
                     samples_per_rev=150, start_deg=0.41, seed=5, noise_arcsec=0.1)
    cal = Calibrator(read_dataset(tmp_path / "ds"))
    e = cal.lib.by_name("pin_pitch[pin=3]")
    keep = cal.subset_rows(45)                      # every third of 150 readings a run
    assert keep.sum() == 100 and keep[::3].all()
    p_full, rss_full, *_ = cal.fit_full([e], [np.array([0.006])], [])
    p_sub, rss_sub = cal.fit_rows([e], [np.array([0.006])], [], keep)
    assert abs(float(p_full[0][0]) - 0.01) < 2e-4
    assert abs(float(p_sub[0][0]) - float(p_full[0][0])) < 3e-4
    assert rss_sub < rss_full and rss_sub / keep.sum() == pytest.approx(rss_full / cal.n, rel=0.4)
    # the subset's residual is the data's at those readings: the wrong pin leaves far more there
    assert cal.fit_rows([cal.lib.by_name("pin_pitch[pin=20]")], [np.array([0.006])], [], keep)[1] > 2 * rss_sub
