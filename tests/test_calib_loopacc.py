"""Joint selection on realistic reducers (issue 10): the rules that keep the path deterministic and
physical first, and instance sets named once at their combined effect. Linear cores, no rvdyn
solves (each test runs in well under a second)."""
from __future__ import annotations

import numpy as np
import pytest

from rvcalib.effects import Effect
from rvcalib.groups import Groups
from rvcalib.joint import JointSelection
from rvcalib.results import Active, FittedEffect, PoolMember
from rvcalib.subsets import (EMPIRICAL_BIC_MARGIN, EMPIRICAL_LEAVES_NOISE, PHYSICAL_SHARE, physical_first,
                             physical_goes_first)


def test_twin_instances_tie_goes_to_library_order():
    """Two twin instances with the same column up to float noise: whichever comes first in the pool,
    the subset of the instance first in the library is chosen (the path does not hang on rounding)."""
    rng = np.random.default_rng(7)
    nc = 200
    a = rng.normal(size=nc)
    rc = 2.0 * a + 0.01 * rng.normal(size=nc)
    e0 = Effect("cam_phase[crank=0,disc=1]", "cam_phase", "table4", "um", "twin 0")
    e1 = Effect("cam_phase[crank=1,disc=0]", "cam_phase", "table4", "um", "twin 1")
    for pool_order in ([e1, e0], [e0, e1]):
        sel = JointSelection.__new__(JointSelection)
        sel.empirical, sel.thr, sel.lib = [], 1e-4, [e0, e1]
        pool = []
        for k, e in enumerate(pool_order):
            col = a * (1.0 + 1e-13 * (k + 1))      # float noise only
            pool.append(PoolMember(e, col[:, None], None, lambda c: np.asarray(c)))
        fits = sel.best_subsets(pool, rc, max_members=1)
        choice = sel.choose_subset(pool, fits, nc, current=())
        assert choice is not None
        assert [pool[i].effect.name for i in choice.members] == ["cam_phase[crank=0,disc=1]"]


def test_an_empirical_subset_is_judged_against_the_least_noise_estimate_of_the_residuals_at_hand():
    """Realistic seed 6 at iteration 1 (stop 41): the declared model's residual (RMS 30 arcsec, orders 39/40/80
    in it) gave a second-difference noise estimate of 3.5-4.2 arcsec where the noise is 0.2, so an empirical
    subset at RMS 3.05 passed for one that explains the data to the noise and won on the BIC margin alone over a
    physical subset that removed 99.9 % as much. The refitted subset's residual, with that structure gone, gives
    an estimate near the noise: the joint step takes the least (JointSelection._subset_noise2), and the physical
    subset goes first."""
    rng = np.random.default_rng(6)
    m, n = 333, 1332
    th = 2.0 * np.pi * np.arange(n) / m
    white = 0.2 * rng.normal(size=n)
    r_full = white + 30.0 * np.sqrt(2.0) * (0.6 * np.sin(39 * th) + 0.6 * np.sin(40 * th + 1.0) + 0.5 * np.sin(80 * th))
    r_sub = white + 3.0 * np.sqrt(2.0) * np.sin(th)                   # smooth leftover structure
    sel = JointSelection.__new__(JointSelection)
    sel.split = lambda v: [v[k * m:(k + 1) * m] for k in range(n // m)]
    sel.full_residual = lambda pairs, terms: (r_sub, np.zeros(0))
    pool = [PoolMember(Effect("cam_phase[crank=0,disc=1]", "cam_phase", "table4", "um", "m"), np.zeros((n, 1)), None,
                       lambda c: np.asarray(c))]
    got = ([np.array([-128.0])], float(r_sub @ r_sub), [0], [], None)
    inflated, least = sel._noise2(r_full), sel._subset_noise2(pool, got)
    assert inflated > 1.0 ** 2 and 0.18 ** 2 < least < 0.22 ** 2
    args = (30.0 ** 2 * n, 3.239 ** 2 * n, -5908.3, 3.051 ** 2 * n, -6067.5, n)
    assert not physical_goes_first(*args, inflated, False)            # the empirical subset won on the margin
    assert physical_goes_first(*args, min(inflated, least), False)      # the physical one, 99.9 % of its gain


def test_the_subsets_are_tried_in_the_order_of_their_bic_class_then_library_ranks():
    """choose_subset walks the fits lazily (rvcalib.joint.tie_order): the same order as a full stable sort by
    (round(bic / BIC_TIE), sorted library ranks of the members), on fits with ties, near-ties across a class
    boundary and empty subsets."""
    import random

    from rvcalib.subsets import BIC_TIE, tie_order
    from rvcalib.results import SubsetFit

    rng = random.Random(1)
    for _ in range(200):
        fits = []
        for _ in range(rng.randint(0, 60)):
            mem = tuple(rng.sample(range(12), rng.randint(0, 4)))
            b = rng.choice([rng.uniform(-50.0, 50.0), 3.0, 3.0 + 1e-8, -7.5e-5, 5e-5, 1.5e-4, -2.5e-4])
            fits.append(SubsetFit(mem, (), len(mem), 1.0, b, 0.0, np.zeros(0)))
        rank = [rng.randint(0, 20) for _ in range(12)]
        full = sorted(fits, key=lambda f: (round(f.bic / BIC_TIE), tuple(sorted(rank[i] for i in f.members))))
        assert [id(f) for f in tie_order(fits, rank)] == [id(f) for f in full]


@pytest.mark.parametrize("rss_p, dbic_p, rss_e, dbic_e, expect", [
    # the physical subset removes 98 % of what the constant's subset removes: physical first
    (26.4, -5252.0, 3.28, -8032.0, True),
    # it removes only half: the empirical subset, better by far more than the margin, is taken
    (700.0, -900.0, 3.28, -8032.0, False),
    # it removes half but the empirical subset is not better by more than the margin: physical
    (700.0, -900.0, 690.0, -900.0 - EMPIRICAL_BIC_MARGIN + 1.0, True),
])
def test_physical_first_rule(rss_p, dbic_p, rss_e, dbic_e, expect):
    rss_model = 1394.0
    assert physical_first(rss_model, rss_p, dbic_p, rss_e, dbic_e) is expect
    gain_share = (rss_model - rss_p) / (rss_model - rss_e)
    assert (gain_share >= PHYSICAL_SHARE) or not expect or dbic_e >= dbic_p - EMPIRICAL_BIC_MARGIN


def test_a_harmonic_near_the_noise_is_held_to_the_share_rule():
    # seed 1 serial (converged refits), iteration 4: the subset with an order-79 harmonic leaves 1.15x the noise
    # and is 71 BIC units better; the physical subset removes 95 % of what it removes
    n, noise2, rss_model = 1332, 0.2 ** 2, 1332 * 0.343 ** 2
    rss_e = n * (1.15 * 0.2) ** 2
    rss_p = rss_model - 0.95 * (rss_model - rss_e)
    dbic_e, dbic_p = -1058.7, -987.8
    assert rss_e / n < EMPIRICAL_LEAVES_NOISE ** 2 * noise2          # near the noise: the margin rule alone ...
    assert not physical_goes_first(rss_model, rss_p, dbic_p, rss_e, dbic_e, n, noise2, harmonic=False)
    assert physical_goes_first(rss_model, rss_p, dbic_p, rss_e, dbic_e, n, noise2, harmonic=True)  # ... not for a harmonic
    # a harmonic that the physical subset explains only half of still wins on its BIC
    rss_half = rss_model - 0.5 * (rss_model - rss_e)
    assert not physical_goes_first(rss_model, rss_half, dbic_p, rss_e, dbic_e, n, noise2, harmonic=True)
    # far from the noise (2.5x) the share rule holds for any empirical term
    rss_big, rss_e2 = n * 1.0 ** 2, n * 0.5 ** 2
    rss_p2 = rss_big - 0.95 * (rss_big - rss_e2)
    assert physical_goes_first(rss_big, rss_p2, dbic_p, rss_e2, dbic_e, n, noise2, harmonic=False)


def _fitted(e: Effect, value: float) -> FittedEffect:
    return FittedEffect(e.name, e.key, e.family, e.unit, e.meaning, value, value - 0.1, value + 0.1, None, 0.05,
                        {"value": value}, 1, 0.5, 10.0, 1e-6, -10.0)


def _instance_case(twin_noise: float):
    """Two instances of one type in the model at 2.0 and 1.0 whose columns are ``s`` and
    ``s + twin_noise * u``; the data hold both at those sizes (for twins: one instance at 3.0)."""
    rng = np.random.default_rng(11)
    nc = 240
    s, u = rng.normal(size=(2, nc))
    c0, c1 = s, s + twin_noise * u
    e0 = Effect("carrier_hole_eccentricity_test[crank=0]", "carrier_hole_eccentricity", "table4", "um", "inst 0")
    e1 = Effect("carrier_hole_eccentricity_test[crank=1]", "carrier_hole_eccentricity", "table4", "um", "inst 1")
    p0, p1 = np.array([2.0]), np.array([1.0])
    truth = 2.0 * c0 + 1.0 * c1
    noise = 0.05 * rng.normal(size=nc)
    g = Groups.__new__(Groups)
    g.active = [Active(e0, p0, 1), Active(e1, p1, 2)]
    members = [PoolMember(e0, c0[:, None], c0 * 2.0, lambda c, p=p0: p + np.asarray(c), g.active[0]),
               PoolMember(e1, c1[:, None], c1 * 1.0, lambda c, p=p1: p + np.asarray(c), g.active[1])]
    blocks = [m.cols for m in members]
    X = np.column_stack(blocks)
    r_state = truth + noise - (c0 * 2.0 + c1 * 1.0)
    coef, *_ = np.linalg.lstsq(X, r_state, rcond=None)
    r_fin = r_state - X @ coef
    rss_grid = float(r_fin @ r_fin)
    g.n, g.rss_full = nc, rss_grid
    g.log = lambda msg: None
    s2 = rss_grid / (nc - 2)
    by_name = {e0.name: _fitted(e0, 2.0), e1.name: _fitted(e1, 1.0)}
    col0 = np.array([0, 1, 2])
    return g.__class__._instance_sets(g, members, blocks, coef, col0, r_fin, rss_grid, 1.0, s2, 1.96, by_name,
                                      set())


def test_twin_instances_are_named_once_at_their_combined_size():
    merged, out = _instance_case(twin_noise=1e-3)
    assert merged == {"carrier_hole_eccentricity_test[crank=0]", "carrier_hole_eccentricity_test[crank=1]"}
    assert len(out) == 1
    grp, comb = out[0]
    assert grp["kind"] == "instances" and len(grp["members"]) == 2
    assert comb.value == pytest.approx(3.0, abs=0.02)          # 2.0 + 1.0: the combined effect
    assert comb.ci_low <= 3.0 <= comb.ci_high
    assert comb.selection["combined_from"] == sorted(merged)


def test_instances_the_data_split_stay_separate():
    merged, out = _instance_case(twin_noise=1.0)
    assert merged == set() and out == []


def _harmonic_gate(av_found: bool, swaps: list, lookalike, dropswap, pinscan=None):
    """A Calibrator stand-in at one model state whose checks before a harmonic return the given results;
    records which checks ran."""
    from rvcalib.identify import Calibrator

    c = Calibrator.__new__(Calibrator)
    e = Effect("disc_phase[disc=0]", "disc_phase", "table4", "deg", "disc 0")
    c.joint, c.active, c.empirical, c.max_terms = True, [Active(e, np.array([0.01]), 1)], [], 12
    c._harmonic_checked_at, c._lookalike_at, c._instances_at, c._dropswap_at = set(), set(), set(), set()
    c._pinscan_at = set()
    c.over_budget = lambda: False
    ran: list[str] = []
    cand = [object()] if av_found else []

    def added_variable_ranking(rc_cat, Ec):
        ran.append("added_variable")
        return cand, {"best": "pin_radius" if av_found else None}

    def joint_step(av, best, hterm, *args):
        ran.append("joint_step")
        assert av is cand and best is None and hterm is None
        return True, "joint: added pin_radius"

    def instances(it, iterations=None):
        ran.append("instances")
        return swaps

    def lookalike_refit(it):
        ran.append("lookalike")
        return lookalike

    c.added_variable_ranking, c.joint_step = added_variable_ranking, joint_step
    def restart_refit(adopt=True):
        ran.append("restart")
        return None

    def drop_swap_refit(it):
        ran.append("dropswap")
        return dropswap

    def pin_scan_refit(it):
        ran.append("pinscan")
        return pinscan

    def polish_once(where):
        ran.append("polish")
        return None

    c._instances_before_stop, c.lookalike_refit, c.restart_refit = instances, lookalike_refit, restart_refit
    c.drop_swap_refit, c.pin_scan_refit, c.polish_once = drop_swap_refit, pin_scan_refit, polish_once
    return c, ran


@pytest.mark.parametrize("av_found, instances, lookalike, dropswap, expect, checks", [
    (True, [], None, None, "added-variable test: joint: added pin_radius", ["added_variable", "joint_step"]),
    (False, [("pin_pitch[pin=0]", "pin_pitch[pin=20]")], None, None, "instance refit: pin_pitch[pin=20] in place of "
     "pin_pitch[pin=0]", ["added_variable", "polish", "instances"]),
    (False, [], ("pin_radius", "pin_circle_diameter"), None, "look-alike refit: added pin_circle_diameter beside "
     "pin_radius", ["added_variable", "polish", "instances", "restart", "lookalike"]),
    (False, [], None, ("planet_eccentricity[crank=1]", "sun_eccentricity"), "drop-swap refit: sun_eccentricity in "
     "place of planet_eccentricity[crank=1]", ["added_variable", "polish", "instances", "restart", "lookalike",
                                               "dropswap"]),
    (False, [], None, None, None, ["added_variable", "polish", "instances", "restart", "lookalike", "dropswap",
                                   "pinscan"]),
])
def test_the_checks_before_the_stop_run_before_a_harmonic_enters(av_found, instances, lookalike, dropswap, expect,
                                                                 checks):
    c, ran = _harmonic_gate(av_found, instances, lookalike, dropswap)
    log: dict = {}
    assert c._physical_before_harmonic(7, log, None, None, None, None, []) == expect
    assert ran == checks and "added_variable_before_harmonic" in log
    # once per model state: at the same state nothing runs again and the harmonic is judged as before
    ran.clear()
    assert c._physical_before_harmonic(8, {}, None, None, None, None, []) is None and ran == []
    # at the term limit the look-alike refit (which adds a term) is not tried; the drop-swap (which does not) is
    c2, ran2 = _harmonic_gate(False, [], ("pin_radius", "pin_circle_diameter"), None)
    c2.max_terms = 1
    assert c2._physical_before_harmonic(7, {}, None, None, None, None, []) is None
    assert ran2 == ["added_variable", "polish", "instances", "restart", "dropswap", "pinscan"]
    # the pin scan is the last check: its replacement or addition is taken when nothing before it changed the model
    for got, said in [(("pin_radius[pin=19]", "pin_pitch[pin=0]"), "pin scan: pin_pitch[pin=0] in place of "
                       "pin_radius[pin=19]"), (("", "pin_pitch[pin=0]"), "pin scan: added pin_pitch[pin=0]")]:
        c3, ran3 = _harmonic_gate(False, [], None, None, pinscan=got)
        assert c3._physical_before_harmonic(7, {}, None, None, None, None, []) == said
        assert ran3 == ["added_variable", "polish", "instances", "restart", "lookalike", "dropswap", "pinscan"]


def _elimination_case(cost: float):
    """Members A, D (clearly needed) and B, E (orthogonal, each of whose removal costs ``cost`` noise
    variances), noise variance 1, a linear model (the refits least squares)."""
    from rvcalib.selection import Selection

    n = 200
    rng = np.random.default_rng(2)
    Q, _ = np.linalg.qr(rng.normal(size=(n, 4)))
    cols = {k: 10.0 * Q[:, i] for i, k in enumerate("ADBE")}
    noise = rng.normal(size=n)
    noise -= Q @ (Q.T @ noise)
    noise *= np.sqrt(n - 4) / np.linalg.norm(noise)
    beta = np.sqrt(cost) / 10.0
    y = 3.0 * cols["A"] + 2.0 * cols["D"] + beta * (cols["B"] + cols["E"]) + noise
    eff = {k: Effect(f"{k}_test", f"{k}_test", "table4", "um", k) for k in "ADBE"}
    sel = Selection.__new__(Selection)
    sel.n, sel.thr, sel.empirical = n, 1e-3, []
    sel.active = [Active(eff[k], np.array([v]), 1) for k, v in (("A", 3.0), ("D", 2.0), ("B", beta), ("E", beta))]
    sel._p_cur = lambda: len(sel.active)

    def residual(pairs):
        return y - sum((cols[e.name[0]] * float(q[0]) for e, q in pairs), np.zeros(n))

    sel.full_residual = lambda pairs, terms: (residual(pairs), np.zeros(0))

    def fit_full(effects, p0, terms):
        A = np.column_stack([cols[e.name[0]] for e in effects])
        q, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ q
        return [np.array([v]) for v in q], float(r @ r), q, None, A

    sel.fit_full = fit_full
    r = residual([(a.effect, a.p) for a in sel.active])
    return sel, float(r @ r)


def test_the_elimination_does_not_drop_a_pair_one_member_at_a_time():
    from scipy import stats

    # each removal alone costs 9.5 noise variances, below F(1) at 1e-3 (10.9); both together 19, above
    # 2 F(2) (14.2): the first goes, the second stays
    assert stats.f.isf(1e-3, 1, 196) > 9.5 and 2 * stats.f.isf(1e-3, 2, 196) < 19.0
    sel, rss = _elimination_case(9.5)
    gone = sel._backward([a.effect for a in sel.active], np.zeros(0), np.zeros((0, 0)), rss, include_last=True)
    assert len(gone) == 1 and gone[0] in ("B_test", "E_test")
    assert [a.effect.name for a in sel.active][:2] == ["A_test", "D_test"] and len(sel.active) == 3
    # removals that cost little together go, both
    sel2, rss2 = _elimination_case(3.0)
    gone2 = sel2._backward([a.effect for a in sel2.active], np.zeros(0), np.zeros((0, 0)), rss2, include_last=True)
    assert sorted(gone2) == ["B_test", "E_test"]
