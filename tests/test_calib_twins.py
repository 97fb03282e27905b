"""The twin refit before the loop stops (rvcalib.replace.ReplacementRefit.twin_refit, issue 10, "#7").

On a stub loop (the fit and the linearised members are stubs that record their calls): which members are
tried (crank / disc / hole instances the data need, the most needed first, at most TWIN_REFITS), which twins
(the other instances of the member's own family), from which start, and what is kept (the BIC margin).
Realistic seed 11 (stop 36), by hand through rvdyn: disc 1's phase at -0.063 deg stood for disc 0's -0.062; with
disc 0's phase at the same size in its place the BIC fell by 311 (docs/calibration.md, step 8b).
"""
from __future__ import annotations

import math

import numpy as np

from rvcalib.effects import Effect
from rvcalib.subsets import JOINT_BIC_MARGIN
from rvcalib.swaps import REPEAT_HOPELESS, SUBSET_HOPELESS
from rvcalib.lsq import bic
from rvcalib.replace import TWIN_REFITS, ReplacementRefit
from rvcalib.results import Active, PoolMember

NC = 200
N = 1000


def _effect(name: str, template: str | None = None, family: str = "table4") -> Effect:
    inst = tuple((k, int(v)) for k, v in (kv.split("=") for kv in name[name.index("[") + 1:-1].split(","))) \
        if "[" in name else ()
    return Effect(name, name.split("[")[0], family, "um", name, template=template, instance=inst)


def _stub(rss_of: dict[str, float]):
    """Members: A[crank=0] (large part), T[disc=1] (middle part, its family's head is T[disc=0]), B (no instance,
    the largest part) and S[crank=0] (a part at the noise: the data do not need it). The library holds each
    member's twins and an instance of another family of S's type. A swap to twin ``x`` leaves ``rss_of[x]``."""
    rng = np.random.default_rng(5)
    a, t, b, s = rng.normal(size=(4, NC))
    lib = {"A[crank=0]": _effect("A[crank=0]"), "A[crank=1]": _effect("A[crank=1]", template="A[crank=0]"),
           "T[disc=0]": _effect("T[disc=0]"), "T[disc=1]": _effect("T[disc=1]", template="T[disc=0]"),
           "B": _effect("B"), "S[crank=0]": _effect("S[crank=0]"),
           "S[crank=1]": _effect("S[crank=1]", template="S[crank=0]"), "S[disc=1]": _effect("S[disc=1]")}
    sel = ReplacementRefit.__new__(ReplacementRefit)
    sel.lib = list(lib.values())
    sel.active = [Active(lib["B"], np.array([20.0]), 1), Active(lib["A[crank=0]"], np.array([8.0]), 1),
                  Active(lib["T[disc=1]"], np.array([-0.06]), 1), Active(lib["S[crank=0]"], np.array([0.01]), 1)]
    parts = {"B": 20.0 * b, "A[crank=0]": 8.0 * a, "T[disc=1]": 3.0 * t, "S[crank=0]": 0.01 * s}
    sel.empirical, sel.n, sel.nc, sel.rss_full = [], N, NC, 40.0
    said: list[str] = []
    sel.log = said.append
    sel.over_budget = lambda: False
    sel._p_cur = lambda: sum(x.effect.n_params for x in sel.active)
    refreshed: list[bool] = []
    sel.refresh_state = lambda: refreshed.append(True)
    sel._emp_matrix = lambda terms, coarse=False: None
    sel.active_members = lambda Pc=None: [PoolMember(x.effect, (parts[x.effect.name] / float(x.p[0]))[:, None],
                                                     parts[x.effect.name], lambda q: q, x) for x in sel.active]
    noise = 0.2 * rng.normal(size=NC)
    sel.coarse_residual = lambda pairs=None: [noise]
    fits: list[tuple[list[str], list[float]]] = []

    def fit_full(effects, p0, terms):
        fits.append(([e.name for e in effects], [float(np.asarray(p)[0]) for p in p0]))
        return [np.asarray(p, dtype=float) * 1.01 for p in p0], rss_of.get(effects[-1].name, 40.0), None, None, None

    sel.fit_full = fit_full
    sel.subset_rows = lambda per_rev: np.ones(N, dtype=bool)   # every reading: the trials go to fit_full directly
    return sel, fits, said, refreshed


def test_the_twin_refit_swaps_a_needed_member_for_its_twin():
    sel, fits, said, refreshed = _stub({"T[disc=0]": 30.0, "A[crank=1]": 45.0})
    got = sel.twin_refit(4)
    # the two most needed instance members (A, then T; B has no instance, S is not needed), each with its own
    # family's twin in its place, from the member's own size; S's twins and the other family are not tried
    assert TWIN_REFITS == 2
    assert [f[0][-1] for f in fits] == ["A[crank=1]", "T[disc=0]"], said
    assert fits[1][1][-1] == -0.06 and fits[0][1][-1] == 8.0
    assert fits[1][0][:-1] == ["B", "A[crank=0]", "S[crank=0]"]
    assert got == ("T[disc=1]", "T[disc=0]") and refreshed == [True]
    a = sel.active[-1]
    assert a.effect.name == "T[disc=0]" and float(a.p[0]) == -0.06 * 1.01
    assert a.info["selection"] == {"method": "twin refit before the stop", "iteration": 4, "replaced": "T[disc=1]"}
    assert a.info["delta_bic"] == bic(30.0, N, 4) - bic(40.0, N, 4)
    assert [x.effect.name for x in sel.active] == ["B", "A[crank=0]", "S[crank=0]", "T[disc=0]"]


def test_a_twin_within_the_margin_is_not_taken():
    # a fall of the BIC smaller than the margin (rss 40 -> 39.95: 1000 ln(40/39.95) = 1.25 units)
    gain = N * math.log(40.0 / 39.95)
    assert 0 < gain < JOINT_BIC_MARGIN
    sel, fits, said, refreshed = _stub({"T[disc=0]": 39.95})
    assert sel.twin_refit(4) is None
    assert len(fits) == 2 and refreshed == []
    assert [x.effect.name for x in sel.active] == ["B", "A[crank=0]", "T[disc=1]", "S[crank=0]"]
    assert any(s.startswith("twin refit: T[disc=0] in place of T[disc=1]") for s in said)


def test_a_member_the_data_do_not_need_is_not_tried():
    """S[crank=0]'s part is at the noise: its removal does not raise the BIC in the linearised model, so its twin
    is not refitted (the 5-run benchmark's spare disc phase costs nothing this way)."""
    sel, fits, said, refreshed = _stub({"S[crank=1]": 1.0})
    sel.active = [a for a in sel.active if a.effect.name in ("B", "S[crank=0]")]
    assert sel.twin_refit(4) is None
    assert fits == [] and refreshed == []


def test_a_swap_that_lost_far_at_an_earlier_state_is_not_refitted_again():
    """The repeat rule (rvcalib.joint.JointSelection.swap_hopeless, REPEAT_HOPELESS): a swap refitted at an earlier
    state is skipped at a later one when it lost by more than REPEAT_HOPELESS times the BIC the state has gained
    since (plus the margin); it is refitted again when the state has gained enough, or when it lost little.
    Realistic seed 2 (stop 38) refitted the same two twin swaps at two consecutive stops, losing 2867 and 2056
    units, then 3271 and 1976 after a change that gained 108."""
    sel, fits, said, refreshed = _stub({"T[disc=0]": 400.0, "A[crank=1]": 41.0})
    assert sel.twin_refit(4) is None and len(fits) == 2
    lost_T = bic(400.0, N, 4) - bic(40.0, N, 4)    # ~2303 units
    lost_A = bic(41.0, N, 4) - bic(40.0, N, 4)     # ~24.7 units
    # a later state that gained 50 BIC units (rss 40 -> 38.07 at the same parameter count)
    sel.rss_full = 40.0 * math.exp(-50.0 / N)
    gained = 50.0
    assert lost_T > REPEAT_HOPELESS * gained + JOINT_BIC_MARGIN > lost_A
    fits.clear()
    assert sel.twin_refit(5) is None
    assert [f[0][-1] for f in fits] == ["A[crank=1]"], said     # T[disc=0] skipped, A[crank=1] refitted
    assert any("twin refit: T[disc=0] in place of T[disc=1]: not refitted: it raised the BIC by 2302.6 at an "
               "earlier state, and the state has gained 50.0 since" in s for s in said), said
    # a state that gained more than a tenth of the loss: refitted again
    sel.rss_full = 40.0 * math.exp(-250.0 / N)
    fits.clear()
    sel.twin_refit(6)
    assert sorted(f[0][-1] for f in fits) == ["A[crank=1]", "T[disc=0]"]
    # the memo holds the last refit of each swap (its loss at that state)
    memo = sel._swap_memo()
    assert memo[("T[disc=1]", "T[disc=0]")][0] == bic(sel.rss_full, N, 4)


def test_a_swap_trial_is_refitted_at_a_third_of_the_readings_first():
    """JointSelection.trial_refit: at a subset of the readings (SUBSET_ROWS_PER_REV), a trial whose BIC there is above
    the state's by more than SUBSET_HOPELESS is left there (no fit on every reading); one within it is refitted on every
    reading from the subset's sizes. The state's RSS at the subset is solved once per state."""
    sel, fits, said, refreshed = _stub({})
    rows = np.zeros(N, dtype=bool)
    rows[::3] = True
    m = int(rows.sum())
    sel.subset_rows = lambda per_rev: rows
    sel.y = [np.zeros(N)]
    sel._pairs = lambda: [(a.effect, a.p) for a in sel.active]
    sel._state_key = lambda: ("state",)
    state_solves: list[int] = []

    def predict_rows(states, keep, sensitivity=False):
        state_solves.append(int(keep.sum()))
        return [np.full(int(keep.sum()), 0.2)]                 # the state leaves 0.2 arcsec at every kept reading
    sel.predict_rows = predict_rows
    rss_state = m * 0.04
    sub_rss: dict[str, float] = {}
    sub_fits: list[list[float]] = []

    def fit_rows(effects, p0, terms, keep):
        assert keep is rows
        sub_fits.append([float(np.asarray(p)[0]) for p in p0])
        return [np.asarray(p, dtype=float) * 2.0 for p in p0], sub_rss[effects[-1].name]
    sel.fit_rows = fit_rows
    effects = [a.effect for a in sel.active]
    p0 = [a.p for a in sel.active]
    k = sel._p_cur()
    # hopeless at the subset: dBIC there = m ln(1.5) ~ 135 > SUBSET_HOPELESS
    sub_rss[effects[-1].name] = 1.5 * rss_state
    got = sel.trial_refit(effects, p0, k)
    assert isinstance(got, str) and got.startswith(f"left at {m} of {N} readings") and f"dBIC {m * math.log(1.5):.1f}" in got
    assert fits == [] and len(sub_fits) == 1
    # within it (dBIC there = m ln(1.01) ~ 3.3): refitted through every reading from the subset's sizes
    sub_rss[effects[-1].name] = 1.01 * rss_state
    assert SUBSET_HOPELESS > m * math.log(1.01) > JOINT_BIC_MARGIN
    params, rss = sel.trial_refit(effects, p0, k)
    assert fits[-1][1] == [2.0 * float(np.asarray(p)[0]) for p in p0]
    assert rss == 40.0 and len(state_solves) == 1            # the state at the subset solved once for both trials
    # a new state: solved again
    sel._state_key = lambda: ("another state",)
    sel.trial_refit(effects, p0, k)
    assert len(state_solves) == 2
