"""The loop's machinery on a linear stand-in of the reducer (tests/calib_standin.py: the real model's TE and
Jacobian at the declared state, frozen): several effects at once with reading errors and the rig's zero per test,
structure outside the physics, twins the data cannot split, settings. The data are made here with their own noise;
what the physics adds beyond a linear response is the subject of tests/test_calib_loop.py."""
from __future__ import annotations

import copy
import math
import re

import numpy as np
import pytest
from scipy import optimize

from calib_standin import frozen_model, rig_data
from rvrig.dataset import read_dataset
from rvcalib.loop import Problem, propose, prior_scales, LoopState, calibrate, criterion, global_fit
from rvcalib.gaussian import measurement_columns
from rvcalib.refine import refine
from rvcalib.settings import CalibrationSettings
from rvcalib.simulate import simulate_dataset, standard_runs

pytestmark = pytest.mark.xdist_group("calib_standin")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A small dataset's readings (4 runs, 60 per revolution off the grid) and the frozen model there."""
    out = tmp_path_factory.mktemp("standin") / "ds"
    simulate_dataset(out, standard_runs((10.0, 30.0), (1, -1)), {}, noise_arcsec=0.0, input_noise_arcsec=0.0,
                     samples_per_rev=60, start_deg=0.37, seed=1)
    ds = read_dataset(out)
    return ds, frozen_model(ds)


def _truth(fm, values: dict) -> np.ndarray:
    names = [c.name for c in fm.candidates for _ in range(c.n_params)]
    th = np.zeros(fm.n_params)
    for k, v in values.items():
        if isinstance(v, tuple):
            i = names.index(k)
            th[i:i + 2] = v
        else:
            th[names.index(k)] = v
    return th


def _data(ds, fm, truth: dict, extra: np.ndarray | None = None, noise: float = 0.2, seed: int = 0):
    return rig_data(ds, fm.te(_truth(fm, truth)) + (0.0 if extra is None else extra), noise, seed)


def _named(res) -> dict:
    return {e.name: e for e in res.effects}


def _criterion_steps(lines: list[str]) -> list[tuple[float, float]]:
    """The (before, after) criterion of every accepted step the loop logged."""
    found = (re.search(r"criterion ([-\d.e+]+) -> ([-\d.e+]+)", s) for s in lines)
    return [(float(m.group(1)), float(m.group(2))) for m in found if m]


def test_several_effects_at_once_named_with_intervals_that_cover(base):
    ds, fm = base
    truth = {"pin_circle_offset": (-3.0, 1.0), "torsional_compliance_arcsec_per_Nm": 0.2,
             "pin_pitch[pin=7] (+)": 0.004, "carrier_offset": -3.0}
    lines: list[str] = []
    res = calibrate(_data(ds, fm, truth), CalibrationSettings(), model=fm, log=lines.append)
    got = _named(res)
    steps = _criterion_steps(lines)
    assert steps and all(b <= a for a, b in steps), lines         # an accepted state never raises the criterion
    assert all(a == b for (_, b), (a, _) in zip(steps, steps[1:])), steps   # and the next starts from it
    for name, v in truth.items():
        name = name.replace(" (+)", "")
        assert name in got, (name, [e.line() for e in res.effects], res.groups)
        e = got[name]
        want = float(np.hypot(*v)) if isinstance(v, tuple) else v
        assert e.value == pytest.approx(want, rel=0.1), e.line()
        if not isinstance(v, tuple):
            assert e.ci95[0] <= v <= e.ci95[1], e.line()
        assert e.prior_scale == next(c.prior_scale for c in fm.candidates if c.effect_name == name), e.line()
    assert res.rms_after <= 1.2 * 0.2
    assert len(res.nuisance) == 2 and all(abs(c["constant_arcsec"]) < 200 for c in res.nuisance)
    assert res.settings["max_effects"] == 30 and res.stopped_by == "converged"


def test_structure_outside_the_physics_is_unexplained_not_named(base):
    ds, fm = base
    th = np.concatenate([np.radians(r.output_deg) for r in ds.runs])
    load = np.concatenate([np.full(r.n, r.load_Nm) for r in ds.runs])
    extra = 0.05 * load * np.cos(7 * th + 0.4)                # order 7, proportional to the load: 0.5 / 1.5 arcsec
    res = calibrate(_data(ds, fm, {"torsional_compliance_arcsec_per_Nm": 0.2}, extra), CalibrationSettings(),
                    model=fm)
    labels = [u["label"] for u in res.unexplained] + [m["name"] for g in res.groups for m in g["members"]]
    assert "order 7 (load)" in labels, (labels, [e.line() for e in res.effects])
    assert all(e.family in ("model",) or abs(e.value) < 0.5 for e in res.effects), [e.line() for e in res.effects]


def test_twins_the_data_cannot_split_are_a_group_with_sizes(base):
    """The four cams of the default layout (two cranks 180 deg apart, two discs with eccentrics 180 deg apart) give
    the same TE up to the sign (the half-turn symmetry): the data cannot split them, so no cam phase is named; the
    group gives each member's size (3 um, the sign its own) and probability."""
    ds, fm = base
    res = calibrate(_data(ds, fm, {"cam_phase[crank=0,disc=0]": 3.0, "torsional_compliance_arcsec_per_Nm": 0.2}),
                    CalibrationSettings(), model=fm)
    assert not any(e.key == "cam_phase" for e in res.effects), [e.line() for e in res.effects]
    grp = [g for g in res.groups if any(m["key"] == "cam_phase" for m in g["members"])]
    assert len(grp) == 1 and len(grp[0]["members"]) >= 2, res.groups
    assert "cam_phase[crank=0,disc=0]" in {m["name"] for m in grp[0]["members"]}
    for m in grp[0]["members"]:
        assert abs(m["value"]) == pytest.approx(3.0, rel=0.1), m
    assert sum(m["probability"] for m in grp[0]["members"]) >= 0.95


def _state_holding(ds, fm, truth: dict, held: str):
    """The problem on data made with ``truth`` and the state that holds ``held`` (with the compliance and the
    dense block) at its best size."""
    data = _data(ds, fm, truth, seed=3)
    pb = Problem(data, CalibrationSettings(), fm)
    names = [c.name for c in fm.candidates for _ in range(c.n_params)]
    scales = prior_scales(pb.library, fm, fm.J, pb.R, pb.readings, data)
    tau = np.concatenate(scales)
    a_s = np.sort(np.r_[pb.dense_params, names.index("torsional_compliance_arcsec_per_Nm"), names.index(held)])
    none = np.zeros(0, int)
    th, b, te, _ = refine(fm, pb.y, pb.proj, pb.R, np.zeros(fm.n_params), np.zeros(pb.R.shape[1]), a_s, none, tau,
                          0.2)
    cur = LoopState(th, te, b, a_s, none, np.ones(tau.size), criterion(pb, th, te, b, a_s, none, tau))
    return pb, names, scales, cur


def _propose_from(ds, fm, truth: dict, held: str):
    """One proposal step from the state that holds ``held`` at its best size, on data made with ``truth``; the
    estimator's chosen set is that same set."""
    pb, names, scales, cur = _state_holding(ds, fm, truth, held)
    tau = np.concatenate(scales)
    z = pb.proj(pb.y - cur.te + fm.J @ cur.theta)
    lines: list[str] = []
    new = propose(pb, cur, None, pb.features(fm.J, scales, False), cur.a_s, cur.a_r, np.ones(tau.size), 0.2, None,
                  None, tau, z, None, lines.append)
    return names, cur, new, lines


def _bounded(fm, idx: int, bound: float):
    """The stand-in with parameter ``idx`` held within +-``bound`` (its physical bound, as the model reports it)."""
    out = copy.copy(fm)
    out._lower, out._upper = fm._lower.copy(), fm._upper.copy()
    out._lower[idx], out._upper[idx] = -bound, bound
    return out


def test_a_look_alike_in_the_chosen_set_is_swapped_for_the_truth(base):
    """A state holding a partial look-alike of the true effect (a cam eccentricity whose column is 0.99 alike to
    the true carrier-hole eccentricity's), at its best size: the estimator's proposal is that set again, so only
    the swap (rvcalib.swaps) reaches the truth; it lowers the criterion, and the truth is found at its size."""
    ds, fm = base
    truth, alias = "carrier_hole_eccentricity[crank=0]", "cam_eccentricity[crank=0,disc=1]"
    names, cur, new, lines = _propose_from(ds, fm, {truth: 4.0, "torsional_compliance_arcsec_per_Nm": 0.2}, alias)
    assert new is not None and new.phi < cur.phi, lines
    assert any(s.strip().startswith(f"swap {alias} -> {truth}") for s in lines), lines
    assert names.index(truth) in new.a_s and names.index(alias) not in new.a_s
    assert new.theta[names.index(truth)] == pytest.approx(4.0, rel=0.1)


def test_a_twin_the_data_cannot_split_is_not_swapped(base):
    """A state holding an exact half-turn twin of the true cam phase: no swap changes the linearised chi-square by
    more than chi2(1) at 95 %, so none is tried (the pair is the swap test's group, not a move)."""
    ds, fm = base
    truth, twin = "cam_phase[crank=0,disc=0]", "cam_phase[crank=1,disc=0]"
    names, cur, new, lines = _propose_from(ds, fm, {truth: 3.0, "torsional_compliance_arcsec_per_Nm": 0.2}, twin)
    assert not any(s.strip().startswith("swap") for s in lines), lines
    assert new is None or names.index(twin) in new.a_s


def test_a_swap_is_accepted_only_beyond_chi2_1(base):
    """The look-alike state of the test above, with the true effect held by a physical bound: the linearised model
    (which knows no bounds) still ranks the swap to the truth far beyond chi2(1), but the reducer model lets it
    lower the criterion by less. With the bound where the swap's drop is 2 (below chi2(1) at 95 %, 3.84) it is
    not accepted; with the bound where the drop is 8 it is."""
    ds, fm = base
    truth, alias = "carrier_hole_eccentricity[crank=0]", "cam_eccentricity[crank=0,disc=1]"
    data = {truth: 4.0, "torsional_compliance_arcsec_per_Nm": 0.2}
    names = [c.name for c in fm.candidates for _ in range(c.n_params)]
    i_t = names.index(truth)

    def drop(bound: float) -> float:
        """The criterion's drop of the swap at ``bound``, refined as the loop refines it."""
        pb, _, scales, cur = _state_holding(ds, _bounded(fm, i_t, bound), data, alias)
        a_s = np.sort(np.r_[np.setdiff1d(cur.a_s, [names.index(alias)]), i_t])
        th, b, te, _ = refine(pb.model, pb.y, pb.proj, pb.R, np.zeros(fm.n_params), cur.b_r, a_s, cur.a_r,
                              np.concatenate(scales), 0.2)
        return cur.phi - criterion(pb, th, te, b, a_s, cur.a_r, np.concatenate(scales))

    for want, accepted in ((2.0, False), (8.0, True)):
        bound = optimize.brentq(lambda x: drop(x) - want, 0.01, 4.0, xtol=1e-4)
        _, cur, new, lines = _propose_from(ds, _bounded(fm, i_t, bound), data, alias)
        assert any(s.strip().startswith(f"swap {alias} -> {truth}") for s in lines), lines
        swapped = new is not None and i_t in new.a_s and names.index(alias) not in new.a_s
        assert swapped == accepted, (want, bound, lines)
        if accepted:
            assert cur.phi - new.phi == pytest.approx(want, abs=0.5)


@pytest.mark.parametrize("field,value,match", [
    ("max_effects", 0, "max_effects = 0"), ("empirical_weight", -1.0, "empirical_weight = -1.0"),
    ("contact", "soft", "contact = 'soft'"), ("rated_Nm", 0.0, "rated_Nm = 0.0"),
    ("families", ("table4", "magic"), "families"), ("workers", 0, "workers = 0"), ("swaps", -1, "swaps = -1"),
    ("estimator", "ridge", "estimator = 'ridge' is not allowed: one of"),
    ("half_turn", "yes", "half_turn = 'yes' is not allowed: True or False"),
    ("secant_width", 0.0, r"secant_width = 0.0 is not allowed: a number in \[0.1, 10\] prior scales"),
    ("secant_width", True, "secant_width = True")])
def test_settings_refused_naming_the_field(field, value, match):
    with pytest.raises(ValueError, match=match):
        CalibrationSettings(**{field: value}).validate()


# ---------------------------------------------------------------------------------------------- tolerance prior
TOLERANCE_PRIOR = CalibrationSettings(estimator="tolerance-prior")
#: One search: the stand-in is linear, so the search from the half-turn image ends where the first did
#: (test_tolerance_prior_names_several_effects_with_regions_that_cover checks it); half the time.
ONE_SEARCH = CalibrationSettings(estimator="tolerance-prior", half_turn=False)


def _covers(e, v) -> bool:
    """The truth v inside the named effect's 95 % region (an interval, or the chi-square(2) ellipse)."""
    if isinstance(v, tuple):
        d = np.array(e.components) - np.array(v)
        return float(d @ np.linalg.solve(np.array(e.cov), d)) <= 5.991
    return e.ci95[0] <= v <= e.ci95[1]


def test_tolerance_prior_names_several_effects_with_regions_that_cover(base):
    """Four effects at once (a ring offset, the compliance, a pin's pitch, a cam's eccentricity), each test with its
    rig zero, noise 0.2 arcsec, 60 readings a revolution for 343 parameters: every named effect is one the truth
    holds, its 95 % region holding the truth; the ring offset and the compliance, which the data determine, are
    named; the noise of the greatest evidence near the true one; the residual at the noise; no structure outside
    the physics reported."""
    ds, fm = base
    truth = {"pin_circle_offset": (-3.0, 1.0), "torsional_compliance_arcsec_per_Nm": 0.2,
             "pin_pitch[pin=7] (+)": 0.004, "cam_eccentricity[crank=0,disc=0]": (4.0, 0.0)}
    lines: list[str] = []
    res = calibrate(_data(ds, fm, truth, seed=5), TOLERANCE_PRIOR, model=fm, log=lines.append)
    got = _named(res)
    want = {k.replace(" (+)", ""): v for k, v in truth.items()}
    assert {"pin_circle_offset", "torsional_compliance_arcsec_per_Nm"} <= set(got), [e.line() for e in res.effects]
    for name, e in got.items():
        assert name in want and _covers(e, want[name]), e.line()
    assert res.sigma_arcsec == pytest.approx(0.2, rel=0.1)
    assert res.rms_after <= 1.2 * 0.2 and res.unexplained == []
    assert res.settings["estimator"] == "tolerance-prior" and res.linearisations >= 2
    assert res.stopped_by == "converged"
    assert all(b <= a for a, b in _criterion_steps(lines)), lines   # a step never raises it
    # the stand-in is linear: the search from the half-turn image ends at the same minimum, so nothing is split
    assert any(n.startswith("2 minima are within") for n in res.notes), res.notes
    assert not any(g["kind"] == "arrangement" for g in res.groups), res.groups
    # and linear: the criterion along each named effect's posterior path is Laplace's, so no interval moves
    assert not any(n.startswith("the interval of") for n in res.notes), res.notes


def test_tolerance_prior_reports_structure_outside_the_physics_as_unexplained(base):
    ds, fm = base
    th = np.concatenate([np.radians(r.output_deg) for r in ds.runs])
    load = np.concatenate([np.full(r.n, r.load_Nm) for r in ds.runs])
    extra = 0.05 * load * np.cos(7 * th + 0.4)                # order 7, proportional to the load: 0.5 / 1.5 arcsec
    res = calibrate(_data(ds, fm, {"torsional_compliance_arcsec_per_Nm": 0.2}, extra), ONE_SEARCH, model=fm)
    assert "order 7 (load)" in [u["label"] for u in res.unexplained], res.unexplained
    assert res.rms_after <= 1.2 * 0.2


def test_tolerance_prior_names_no_twin_the_data_cannot_split(base):
    """The four cams' phases give the same TE up to the sign: no one of them is named, and the sum their
    posterior gives still explains the data."""
    ds, fm = base
    res = calibrate(_data(ds, fm, {"cam_phase[crank=0,disc=0]": 3.0, "torsional_compliance_arcsec_per_Nm": 0.2}),
                    TOLERANCE_PRIOR, model=fm)
    assert not any(e.key == "cam_phase" for e in res.effects), [e.line() for e in res.effects]
    assert res.rms_after <= 1.2 * 0.2


def test_evidence_noise_is_the_fixed_point_of_its_definition_with_flat_and_finite_priors():
    """At the returned noise s2, C is the inverse of X'X / s2 + diag(1 / sd^2) (a flat prior: 0) and s2 is
    |r|^2 / (dof - g), g = sum(1 - C_jj / sd_j^2): the definition, on correlated columns."""
    from rvcalib.gaussian import evidence_sigma

    rng = np.random.default_rng(5)
    X = rng.normal(size=(120, 12)) * rng.uniform(0.1, 10.0, 12)
    X[:, 4] = X[:, 5] + 1e-3 * X[:, 4]
    r = rng.normal(0.0, 0.7, 120)
    sd = rng.uniform(0.1, 3.0, 12)
    sd[[0, 7]] = np.inf
    sigma, C = evidence_sigma(X, r, sd, 117, 2.0, iterations=500)
    prec = 1.0 / np.square(sd)
    want = np.linalg.inv(X.T @ X / sigma ** 2 + np.diag(prec))
    assert np.allclose(C, want, rtol=1e-8, atol=1e-12 * np.abs(want).max())
    g = float(np.sum(1.0 - prec * np.diag(want)))
    assert sigma ** 2 == pytest.approx(float(r @ r) / (117 - g), rel=1e-9)


def test_evidence_noise_and_block_variance_against_closed_forms():
    """MacKay's fixed point with flat priors is the unbiased RSS / (n - p); the REML variance of a one-direction
    block is ``max(0, (z^2 - s2_hat) / |b|^2)`` with ``s2_hat`` the rest over its m - 1 directions."""
    from rvcalib.gaussian import block_variance, evidence_sigma

    rng = np.random.default_rng(11)
    X = rng.normal(size=(80, 4))
    r = rng.normal(0.0, 0.3, 80)
    beta = np.linalg.lstsq(X, r, rcond=None)[0]
    res = r - X @ beta
    sigma, _ = evidence_sigma(X, res, np.full(4, 1e12), 80, 1.0)
    assert sigma == pytest.approx(np.sqrt(res @ res / 76), rel=1e-6)
    b = rng.normal(size=80)
    for amp in (0.0, 3.0):
        y = rng.normal(0.0, 0.3, 80) + amp * b / np.linalg.norm(b)
        z2 = float((b @ y) ** 2 / (b @ b))
        s2 = (float(y @ y) - z2) / 79
        gamma, sigma2 = block_variance(y, b[:, None], 80)
        want = max(0.0, (z2 - s2) / float(b @ b))
        assert gamma == pytest.approx(want, rel=1e-4, abs=1e-9)
        assert sigma2 == pytest.approx(s2 if want > 0 else float(y @ y) / 80, rel=1e-4)


def test_tolerance_prior_reports_a_pair_it_cannot_split_as_a_group():
    """Of two candidates whose posterior correlation is -0.98 the data fix the combination only: a group with the
    size each would have alone (its mean given the other zero); an independent third one is named."""
    from types import SimpleNamespace

    from rvcalib.gaussian import Posterior, read_named

    def cand(name):
        return SimpleNamespace(effect_name=name, key=name, family="table4", instance=(), unit="um", meaning="",
                               polar=False, lower=-200.0, upper=200.0, size=lambda v: (float(v[0]), None))

    pb = SimpleNamespace(feature_cands=[[cand("a")], [cand("b")], [cand("c")]], fixed=(), starts=np.arange(4),
                         empirical=np.zeros(3, dtype=bool))
    cov = np.array([[1.0, -0.98, 0.0], [-0.98, 1.0, 0.0], [0.0, 0.0, 0.04]]) * 0.01
    mean = np.array([2.0, -1.5, 3.0])
    named, groups = read_named(pb, Posterior(np.arange(3), mean, cov), 0.95)
    assert [e.name for e in named] == ["c"] and named[0].ci95 == pytest.approx([3 - 0.0392, 3 + 0.0392], abs=1e-4)
    assert len(groups) >= 1
    alone = {m["name"]: m["value"] for m in groups[0]["members"]}
    assert alone == pytest.approx({"a": 2.0 - 0.98 * 1.5, "b": -1.5 + 0.98 * 2.0})


def test_tolerance_prior_names_nothing_when_the_linearisations_ran_out(base):
    """A search stopped by its cap, one damped step from the start, is not at the criterion's minimum: where the
    converged search names the ring offset and the compliance, the stopped one names nothing, says why and how to
    go on, and still gives its fit."""
    ds, fm = base
    data = _data(ds, fm, {"pin_circle_offset": (-3.0, 1.0), "torsional_compliance_arcsec_per_Nm": 0.2}, seed=6)
    done = calibrate(data, ONE_SEARCH, model=fm)
    assert done.stopped_by == "converged"
    assert {"pin_circle_offset", "torsional_compliance_arcsec_per_Nm"} <= set(_named(done))
    once = CalibrationSettings(estimator="tolerance-prior", max_linearisations=1, half_turn=False)
    res = calibrate(data, once, model=fm)
    assert res.stopped_by == "max_linearisations" and res.linearisations == 2    # the last one gives the regions
    assert res.effects == [] and res.groups == []
    note = [n for n in res.notes if n.startswith("no effect is named")]
    assert len(note) == 1 and "--max-linearisations" in note[0], res.notes
    assert re.search(r"\(([1-9]\d*) effects and \d+ groups excluded zero\)", note[0]), note[0]
    assert res.rms_after < res.rms_before


def test_the_tolerance_priors_start_estimates_a_ramp_with_the_ring_and_the_compliance(base):
    """A record with an output-encoder scale error of 40 ppm (a ramp of 52 arcsec over a revolution) beside a
    compliance: the tolerance prior's start, the always-estimated block's MAP, estimates the measurement effects
    with the block, so the ring's fit stays within its tolerance class and the compliance is the reducer's. The
    same fit without them (the sparse estimator's start) meets the ramp with the ring's fit: the record does
    test what the measurement columns are there for."""
    ds, fm = base
    ramp = np.concatenate([r.output_deg * 3600.0 * 40e-6 for r in ds.runs])
    data = _data(ds, fm, {"torsional_compliance_arcsec_per_Nm": 0.2}, extra=ramp, seed=8)
    names = [c.name for c in fm.candidates for _ in range(c.n_params)]
    scale = {c.name: c.prior_scale for c in fm.candidates}
    start = {}
    for est in ("tolerance-prior", "sparse"):
        pb = Problem(data, CalibrationSettings(estimator=est), fm)
        assert "output_encoder_scale_error" in [c.name for c in pb.readings]
        reading = measurement_columns(pb) if est == "tolerance-prior" else None
        theta, _ = global_fit(pb, np.zeros(fm.n_params), fm.te(np.zeros(fm.n_params)), None, lambda s: None, reading)
        start[est] = {names[i]: float(theta[i]) for i in pb.dense_params}
    assert start["tolerance-prior"].pop("torsional_compliance_arcsec_per_Nm") == pytest.approx(0.2, rel=0.02)
    assert {k: abs(v) < scale[k] for k, v in start["tolerance-prior"].items()} == \
        {k: True for k in start["tolerance-prior"]}, start
    assert any(abs(v) > scale[k] for k, v in start["sparse"].items()), start


def _exp_search(step_tolerance: float) -> tuple:
    """The search on ``a exp(b t)`` from far from the truth: (theta, sigma, stopped, logged lines, the MAP of the
    same prior-augmented residual at that sigma by ``scipy.optimize.least_squares``, the criterion)."""
    from types import SimpleNamespace

    from rvcalib.gaussian import map_estimate

    t = np.linspace(0.0, 1.0, 60)
    rng = np.random.default_rng(3)
    y = 2.0 * np.exp(1.5 * t) + rng.normal(0.0, 0.05, t.size)

    def te(th):
        return th[0] * np.exp(th[1] * t)

    def jacobian(th, *_):
        e = np.exp(th[1] * t)
        return np.column_stack([e, th[0] * t * e])

    model = SimpleNamespace(n_params=2, _lower=np.full(2, -50.0), _upper=np.full(2, 50.0), te=te, jacobian=jacobian)
    pb = SimpleNamespace(proj=lambda v: v, y=y, R=np.zeros((t.size, 0)), tests=[])
    sd = np.array([10.0, 10.0])
    lines: list[str] = []
    settings = CalibrationSettings(estimator="tolerance-prior", max_linearisations=40, step_tolerance=step_tolerance)
    theta, b, fit, sigma, stopped = map_estimate(model, pb, np.array([0.2, -2.0]), np.zeros(0, dtype=int), sd, 1.0,
                                                 settings, None, lines.append)
    assert b.size == 0

    def crit(th):
        return float(np.sum(((y - te(th)) / sigma) ** 2) + np.sum((th / sd) ** 2))

    want = optimize.least_squares(lambda th: np.concatenate([(y - te(th)) / sigma, th / sd]), [0.2, -2.0],
                                  xtol=1e-12, ftol=1e-12).x
    return theta, sigma, stopped, lines, want, crit


def test_levenberg_marquardt_reaches_the_map_of_a_nonlinear_model():
    """On a model nonlinear in its parameters (``a exp(b t)``, started far from the truth, where a full
    Gauss-Newton step overshoots), the search ends at the MAP of its criterion at the noise it ends with: the point
    ``scipy.optimize.least_squares`` finds on the same prior-augmented residual; each accepted step lowers it."""
    theta, sigma, stopped, lines, want, _ = _exp_search(1e-4)
    assert stopped == "converged"
    assert theta == pytest.approx(want, rel=1e-4)
    assert sigma == pytest.approx(0.05, rel=0.25)
    steps = _criterion_steps(lines)
    assert len(steps) >= 3 and all(b <= a for a, b in steps), lines
    # the undamped step is the linearised criterion's own minimum: no damped step's prediction lies below it, and
    # the first (far from the MAP, where the damping shortens the step) lies above it
    pred = [re.search(r"predicted ([-\d.e+]+), undamped ([-\d.e+]+)", s) for s in lines]
    pred = [(float(m.group(1)), float(m.group(2))) for m in pred if m]
    assert len(pred) == len(steps) and all(u <= p + 1e-9 * abs(p) for p, u in pred), lines
    assert pred[0][1] < pred[0][0], lines


def test_a_short_step_that_still_lowers_the_criterion_is_not_convergence():
    """With a step tolerance so loose that every step is short by it, the search still goes on while a step lowers
    the criterion by a unit or more (what the data tell from no change), and ends within a unit of the MAP."""
    from rvcalib.gaussian import CRITERION_RESOLUTION

    theta, sigma, stopped, lines, want, crit = _exp_search(1e3)
    steps = _criterion_steps(lines)
    assert stopped == "converged" and len(steps) >= 3, lines
    assert _fall_below(steps[-1], CRITERION_RESOLUTION) and not _fall_below(steps[0], CRITERION_RESOLUTION)
    assert crit(theta) - crit(want) < CRITERION_RESOLUTION


def _fall_below(step: tuple, resolution: float) -> bool:
    """Whether a logged step (criterion before, after) lowered the criterion by less than ``resolution``."""
    return step[0] - step[1] < resolution


def test_a_region_that_excludes_zero_only_by_the_tangent_is_refused():
    """``y = a^3 g(t) + b h(t)`` (g, h orthogonal), noise-free at a = b = 1, noise 0.05: at the MAP the tangent
    of the cubic term is three times its secant to zero, so Laplace's ellipse puts zero at ``d^2`` = 9 x 2.5 for a,
    while the criterion with a at zero rises by |g|^2 / sigma^2 = 2.5 only (below chi-square(1) 3.84): a is
    refused, with a note; b, linear, rises by its own ``d^2`` and is kept."""
    from types import SimpleNamespace

    from rvcalib.gaussian import Posterior, rise_function, zero_check

    t = np.linspace(0.0, 1.0, 60, endpoint=False)
    sigma = 0.05
    g = sigma * math.sqrt(2.5 / 30.0) * np.cos(2 * np.pi * t)          # |g|^2 / sigma^2 = 2.5
    h = sigma * np.sin(2 * np.pi * t)                                  # |h|^2 / sigma^2 = 30

    def te(th):
        return th[0] ** 3 * g + th[1] * h

    y = te(np.array([1.0, 1.0]))
    sd = np.array([10.0, 10.0])
    pb = SimpleNamespace(proj=lambda v: v, y=y, R=np.zeros((t.size, 0)), tests=[])
    model = SimpleNamespace(n_params=2, _lower=np.full(2, -50.0), _upper=np.full(2, 50.0), te=te)
    x = optimize.least_squares(lambda th: np.concatenate([(y - te(th)) / sigma, th / sd]), [0.5, 0.5],
                               xtol=1e-14, ftol=1e-14).x
    J = np.column_stack([3 * x[0] ** 2 * g, h])
    C = np.linalg.inv(J.T @ J / sigma ** 2 + np.diag(1 / sd ** 2))
    d2 = x ** 2 / np.diag(C)
    assert d2[0] == pytest.approx(9 * 2.5, rel=0.01) and d2[1] == pytest.approx(30.0, rel=0.01)   # both > 3.84
    notes: list[str] = []
    rise = rise_function(pb, model, np.zeros(0, dtype=int), sd, Posterior(np.arange(2), x, C), te(x), sigma)
    check = zero_check(rise, 0.95, notes.append)
    assert check([0], "a") is False
    rise = float(re.search(r"only ([\d.e+-]+) above", notes[0]).group(1))
    assert notes[0].startswith("a is not named") and rise == pytest.approx(2.5, rel=0.01)
    assert check([1], "b") is True and len(notes) == 1


class _NoColumns:
    """The stand-in whose columns cannot be computed once the estimator's search has begun (a perturbed case rvdyn
    cannot solve): after the start's statistical columns, every call of ``jacobian`` raises."""

    def __init__(self, model) -> None:
        self.model, self.searching = model, False

    def __getattr__(self, name):
        return getattr(self.model, name)

    def statistical_jacobian(self, *a, **k):
        self.searching = True
        return self.model.statistical_jacobian(*a, **k)

    def jacobian(self, *a, **k):
        from rvcalib.reducer_model import ModelEvaluationError

        if self.searching:
            raise ModelEvaluationError("no secant can be solved along the stand-in's columns from this state")
        return self.model.jacobian(*a, **k)


def test_tolerance_prior_names_nothing_where_the_models_columns_fail(base):
    """A search that reaches a state where the model's columns cannot be computed stops there: the result names
    nothing, says why, and keeps the fit it reached, instead of failing the calibration."""
    ds, fm = base
    data = _data(ds, fm, {"pin_circle_offset": (-3.0, 1.0), "torsional_compliance_arcsec_per_Nm": 0.2}, seed=6)
    lines: list[str] = []
    res = calibrate(data, TOLERANCE_PRIOR, model=_NoColumns(fm), log=lines.append)
    assert res.stopped_by == "no_columns"
    assert res.effects == [] and res.groups == []
    note = [n for n in res.notes if n.startswith("no effect is named: the reducer model's columns")]
    assert len(note) == 1, res.notes
    assert any("cannot be computed at this state: no secant can be solved" in s for s in lines), lines
    assert res.rms_after < res.rms_before


def test_refine_takes_the_columns_once_and_reaches_the_map_of_a_nonlinear_model():
    """The nonlinear estimate on ``a exp(b t)`` from far from the truth asks the model for its columns once (the
    search keeps them by Broyden's update) and ends at the MAP that ``scipy.optimize.least_squares`` finds with the
    exact Jacobian on the same prior-augmented residual."""
    from types import SimpleNamespace

    t = np.linspace(0.0, 1.0, 60)
    y = 2.0 * np.exp(1.5 * t) + np.random.default_rng(4).normal(0.0, 0.05, t.size)
    calls = []

    def jacobian(th, spread=None, renew=None, pool=None):
        calls.append(th.copy())
        e = np.exp(th[1] * t)
        return np.column_stack([e, th[0] * t * e])

    model = SimpleNamespace(_lower=np.full(2, -50.0), _upper=np.full(2, 50.0), te=lambda th: th[0] * np.exp(th[1] * t),
                            jacobian=jacobian)
    sd, sigma, none = np.array([10.0, 10.0]), 0.05, np.zeros(0, dtype=int)
    theta, _, te, cost = refine(model, y, lambda v: v, np.zeros((t.size, 0)), np.array([0.5, 0.5]), np.zeros(0),
                                np.arange(2), none, sd, sigma, max_nfev=100)
    assert len(calls) == 1
    want = optimize.least_squares(lambda th: np.concatenate([(y - model.te(th)) / sigma, th / sd]), [0.5, 0.5],
                                  jac=lambda th: np.vstack([-jacobian(th) / sigma, np.diag(1.0 / sd)]),
                                  xtol=1e-12, ftol=1e-12, gtol=1e-12).x
    assert theta == pytest.approx(want, rel=1e-5)
    assert te == pytest.approx(model.te(theta))
    assert cost == pytest.approx(np.sum(((y - te) / sigma) ** 2) + np.sum((theta / sd) ** 2))
