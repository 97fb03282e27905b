"""Joint selection on realistic reducers (issue 10): the rules that keep the path deterministic and
physical first, and instance sets named once at their combined effect. Linear cores, no rvdyn
solves (each test runs in well under a second)."""
from __future__ import annotations

import numpy as np
import pytest

from rvcalib.effects import Effect
from rvcalib.groups import Groups
from rvcalib.joint import (EMPIRICAL_BIC_MARGIN, EMPIRICAL_LEAVES_NOISE, PHYSICAL_SHARE, JointSelection,
                           physical_first, physical_goes_first)
from rvcalib.results import Active, FittedEffect, PoolMember


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
