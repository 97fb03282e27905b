"""The restart of collinear members from zero (rvcalib.basins): sets, acceptance, the two_fits group."""
from __future__ import annotations

import numpy as np
import pytest

from rvcalib.basins import BasinCheck, collinear_sets
from rvcalib.effects import Effect
from rvcalib.results import Active, FittedEffect, PoolMember

NC = 200


def test_collinear_sets_joins_parts_along_one_direction_whatever_their_sign():
    rng = np.random.default_rng(3)
    a, b, c, d = rng.normal(size=(4, NC))
    parts = [a, -0.98 * a + 0.05 * b, c, None, 0.95 * c + 0.1 * d, b, np.zeros(NC)]
    assert collinear_sets(parts) == [[0, 1], [2, 4]]
    # a chain: 0 ~ 1 and 1 ~ 2 join all three even where 0 and 2 correlate less
    e = a + 0.6 * b
    chain = [a, a + 0.3 * b, e]
    c02 = float(a @ e) / np.linalg.norm(a) / np.linalg.norm(e)
    assert c02 < 0.9 and collinear_sets(chain) == [[0, 1, 2]]
    assert collinear_sets([a, b, c]) == []


def _fitted(e: Effect, value: float, half: float) -> FittedEffect:
    return FittedEffect(e.name, e.key, e.family, e.unit, e.meaning, value, value - half, value + half, None,
                        half / 2, {"value": value}, 1, 0.5, 10.0, 1e-6, -10.0)


def _basin_case(delta_noise_var: float):
    """Members A (large part), B (its part along A's direction, opposite sign) and D (independent) at
    sizes 10, -8 and 2; the fit from B at zero (A and D at their sizes) ends at A 2.5, B 0.4, D 2.1 with a
    sum of squares ``delta_noise_var`` noise variances from the state's. The fit is a stub that records its
    starts (the mechanism is tested here; the full model's basins in docs/calibration.md)."""
    rng = np.random.default_rng(7)
    a, b, d = rng.normal(size=(3, NC))
    eff = {k: Effect(f"{k}_test", f"{k}_test", "table4", "um", k) for k in "ABD"}
    sel = BasinCheck.__new__(BasinCheck)
    sel.active = [Active(eff["A"], np.array([10.0]), 1), Active(eff["B"], np.array([-8.0]), 1),
                  Active(eff["D"], np.array([2.0]), 1)]
    sel.empirical = []
    sel.n = 1000
    sel.rss_full = 40.0
    sel.log = lambda msg: None
    sel.over_budget = lambda: False
    sel._p_cur = lambda: len(sel.active)
    sel._state_key = lambda: (tuple(sorted(x.effect.name for x in sel.active)),
                              tuple(float(x.p[0]) for x in sel.active))
    refreshed = []
    sel.refresh_state = lambda: refreshed.append(True)
    parts = {"A_test": 10.0 * a, "B_test": -8.0 * (a + 0.1 * b), "D_test": 2.0 * d}
    sel.active_members = lambda Pc=None: [PoolMember(x.effect, parts[x.effect.name][:, None], parts[x.effect.name],
                                                     lambda q: q, x) for x in sel.active]
    s2 = sel.rss_full / (sel.n - 3)
    starts = []

    def fit_full(effects, p0, terms):
        starts.append({e.name: float(p[0]) for e, p in zip(effects, p0)})
        return [np.array([2.5]), np.array([0.4]), np.array([2.1])], sel.rss_full + delta_noise_var * s2, None, None, None

    sel.fit_full = fit_full
    return sel, starts, refreshed, eff


def test_a_second_fit_within_the_noise_widens_the_intervals_and_makes_a_group():
    sel, starts, refreshed, eff = _basin_case(2.0)
    assert sel.restart_refit() is None
    # one set {A, B}: B (the smaller part) from zero, A and D from their sizes
    assert starts == [{"A_test": 10.0, "B_test": 0.0, "D_test": 2.0}]
    assert not refreshed and [float(x.p[0]) for x in sel.active] == [10.0, -8.0, 2.0]
    # once per state
    assert sel.restart_refit() is None and len(starts) == 1
    by_name = {"A_test": _fitted(eff["A"], 10.0, 0.5), "B_test": _fitted(eff["B"], -8.0, 1.0),
               "D_test": _fitted(eff["D"], 2.0, 0.3)}
    groups = sel.basin_groups(by_name, 0.2)
    assert len(groups) == 1 and groups[0]["kind"] == "two_fits"
    g = groups[0]
    assert [m["name"] for m in g["members"]] == ["A_test", "B_test"]          # D's 2.1 is inside 2 +- 0.3
    assert [m["value_other_fit"] for m in g["members"]] == [2.5, 0.4]
    # B at 0.4 in the other fit is within its interval's half-width (1.0) of zero: not named; A (2.5 > 0.5) is
    assert [m["named"] for m in g["members"]] == [True, False]
    assert "B_test not named as effects" in g["note"]
    assert by_name["A_test"].ci_low == 2.5 and by_name["A_test"].ci_high == 10.5
    assert by_name["B_test"].ci_low == -9.0 and by_name["B_test"].ci_high == 0.4
    assert by_name["D_test"].ci_low == pytest.approx(1.7) and by_name["D_test"].ci_high == pytest.approx(2.3)
    assert "within the noise" in g["note"]


def test_a_second_fit_beyond_the_noise_is_no_group():
    sel, starts, refreshed, eff = _basin_case(6.0)
    assert sel.restart_refit() is None and len(starts) == 1
    by_name = {k: _fitted(eff[k[0]], v, 0.5) for k, v in (("A_test", 10.0), ("B_test", -8.0), ("D_test", 2.0))}
    assert sel.basin_groups(by_name, 0.2) == []
    assert by_name["B_test"].ci_high == -7.5


def test_a_better_second_fit_replaces_the_state():
    sel, starts, refreshed, eff = _basin_case(-50.0)
    msg = sel.restart_refit()
    assert msg is not None and msg.startswith("restarted B_test from zero")
    assert refreshed and [float(x.p[0]) for x in sel.active] == [2.5, 0.4, 2.1]
    # at the final state (adopt False) a better fit is reported, not taken
    sel2, _, refreshed2, eff2 = _basin_case(-50.0)
    assert sel2.restart_refit(adopt=False) is None and not refreshed2
    by_name = {k: _fitted(eff2[k[0]], v, 0.5) for k, v in (("A_test", 10.0), ("B_test", -8.0), ("D_test", 2.0))}
    g = sel2.basin_groups(by_name, 0.2)
    assert len(g) == 1 and "the second fits better" in g[0]["note"]
