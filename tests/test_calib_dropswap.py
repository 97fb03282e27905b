"""The drop-swap refit before the loop stops (rvcalib.dropswap, issue 10, "#7").

Two parts: the mechanism on a stub loop (which members are dropped, what is screened and refitted, what is
kept), and the check through the full model (impact law, the test session's runner) on the stand-in state of
``test_calib_replacement_refit``: data made by the simulator at 200 readings per output revolution from
0.37 deg (off the loop's grid), its own noise and seed, four runs holding a planet eccentricity, a cam phase, a
cam eccentricity and a compliance at once; the state holds both cranks' planet eccentricities at 14 um and no
cam phase.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcalib.dropswap import DROP_SWAP_MEMBERS, DropSwap
from rvcalib.effects import Effect
from rvcalib.subsets import JOINT_BIC_MARGIN
from rvcalib.lsq import bic
from rvcalib.results import Active, Candidate, PoolMember

NC = 200
N = 1000


def _effect(name: str, family: str = "table4", template: str | None = None, expensive: bool = False) -> Effect:
    return Effect(name, name.split("[")[0], family, "um", name, template=template, expensive=expensive)


def _stub(rss_swapped: dict[str, float]):
    """A loop holding members A (large part), B (small part) and D (middle part), each one parameter; the removal
    costs in the linearised model follow the parts' sizes, so B and then D are the cheapest. Without a member the
    refit leaves 41 arcsec^2; the candidate added in its place leaves ``rss_swapped[candidate]`` (40 if not
    given). The screening at the state without a member offers, best first: the member's own instance twin
    (``B_twin``, its family), an expensive candidate, a measurement effect, a member of the model (A), then
    ``C`` and ``E``. The fit and the ranking are stubs that record their calls."""
    rng = np.random.default_rng(11)
    a, b, d = rng.normal(size=(3, NC))
    eff = {"A": _effect("A"), "B": _effect("B[crank=1]", template="B[crank=0]"), "D": _effect("D"),
           "B_twin": _effect("B[crank=0]"), "X": _effect("X", family="model", expensive=True),
           "M": _effect("M", family="measurement"), "C": _effect("C"), "E": _effect("E")}
    sel = DropSwap.__new__(DropSwap)
    sel.active = [Active(eff["A"], np.array([10.0]), 1), Active(eff["B"], np.array([0.5]), 1),
                  Active(eff["D"], np.array([2.0]), 1)]
    sel.empirical = []
    sel.n = N
    sel.rss_full = 40.0
    said: list[str] = []
    sel.log = said.append
    sel.over_budget = lambda: False
    sel._p_cur = lambda: sum(x.effect.n_params for x in sel.active)
    refreshed = []
    sel.refresh_state = lambda: refreshed.append(True)
    sel._emp_matrix = lambda terms, coarse=False: None
    parts = {"A": 10.0 * a, "B[crank=1]": 0.5 * b, "D": 2.0 * d}
    sel.active_members = lambda Pc=None: [PoolMember(x.effect, (parts[x.effect.name] / float(x.p[0]))[:, None],
                                                     parts[x.effect.name], lambda q: q, x) for x in sel.active]
    noise = 0.2 * rng.normal(size=NC)
    sel.coarse_residual = lambda pairs=None: [noise]
    fits: list[list[str]] = []
    ranked: list[int] = []

    def fit_full(effects, p0, terms):
        names = [e.name for e in effects]
        fits.append(names)
        if len(effects) == len(sel.active) - 1:
            return [np.asarray(p, dtype=float) + 0.1 for p in p0], 41.0, None, None, None
        return ([np.asarray(p, dtype=float) + 0.1 for p in p0], rss_swapped.get(names[-1], 40.0), None, None, None)

    def rank(rc, Ec, r_full=None):
        ranked.append(rc.size)
        return [Candidate(eff[k], f, np.array([0.7]), None, None) for k, f in
                (("B_twin", 0.9), ("X", 0.8), ("M", 0.7), ("A", 0.6), ("C", 0.5), ("E", 0.4))]

    sel.fit_full = fit_full
    sel.subset_rows = lambda per_rev: np.ones(N, dtype=bool)   # every reading: the trials go to fit_full directly
    sel.rank = rank
    return sel, fits, ranked, refreshed, said, eff


def test_the_cheapest_members_are_dropped_and_the_best_other_family_refitted_in_their_place():
    # C in place of B lowers the BIC by 20 units: B goes, C comes at its refitted size, the others refitted
    sel, fits, ranked, refreshed, said, eff = _stub({"C": 40.0 * math.exp(-20.0 / N)})
    b0 = bic(40.0, N, 3)
    got = sel.drop_swap_refit(4)
    assert got == ("B[crank=1]", "C")
    # the DROP_SWAP_MEMBERS cheapest (B, then D) each dropped, then refitted with the first candidate that is not
    # of the dropped member's family (its twin), expensive, a measurement effect or in the model: C in B's place,
    # B's twin in D's place (another family than D's)
    assert DROP_SWAP_MEMBERS == 2
    assert fits == [["A", "D"], ["A", "D", "C"], ["A", "B[crank=1]"], ["A", "B[crank=1]", "B[crank=0]"]]
    assert ranked == [NC, NC]
    assert [x.effect.name for x in sel.active] == ["A", "D", "C"]
    assert [float(x.p[0]) for x in sel.active] == pytest.approx([10.2, 2.2, 0.8])
    info = sel.active[-1].info
    assert info["selection"] == {"method": "drop-swap refit before the stop", "iteration": 4, "replaced": "B[crank=1]"}
    assert info["delta_bic"] == pytest.approx(bic(40.0 * math.exp(-20.0 / N), N, 3) - b0)
    assert refreshed == [True]
    assert any(s.startswith("drop-swap refit: C in place of B[crank=1]: ") for s in said)


def test_a_swap_within_the_margin_leaves_the_state():
    rss = 40.0 * math.exp(-(JOINT_BIC_MARGIN - 0.5) / N)    # 1.5 BIC units better: inside the margin
    sel, fits, _, refreshed, _, _ = _stub({"C": rss})
    before = [(x.effect.name, float(x.p[0])) for x in sel.active]
    assert sel.drop_swap_refit(4) is None
    assert len(fits) == 4 and not refreshed
    assert [(x.effect.name, float(x.p[0])) for x in sel.active] == before


def test_nothing_is_tried_over_the_budget_or_without_members():
    sel, fits, _, _, _, _ = _stub({})
    sel.over_budget = lambda: True
    assert sel.drop_swap_refit(4) is None and fits == []
    sel, fits, _, _, _, _ = _stub({})
    sel.active = []
    assert sel.drop_swap_refit(4) is None and fits == []


@pytest.mark.usefixtures("calib_forward_cache")  # solves shared by the session (impact law)
def test_the_stand_in_planet_eccentricity_is_swapped_for_the_cam_phase(tmp_path):
    from test_calib_replacement_refit import CAM_E, CAM_P, COMPLIANCE, NOISE, P0, P1, stand_in_state

    said: list[str] = []
    cal, rms_before = stand_in_state(tmp_path / "ds")
    assert rms_before > 5 * NOISE
    cal.log = said.append
    got = cal.drop_swap_refit(5)
    assert got is not None and got[0] in (P0, P1) and got[1] == CAM_P, (got, said)
    by = {a.effect.name: a for a in cal.active}
    assert set(by) == {P0 if got[0] == P1 else P1, CAM_P, CAM_E, COMPLIANCE}
    planet = next(a for a in cal.active if a.effect.key == "planet_eccentricity")
    assert float(np.hypot(*planet.p)) == pytest.approx(2.7, abs=0.3), planet.p
    assert float(by[CAM_P].p[0]) == pytest.approx(1.1, abs=0.1)
    assert float(by[CAM_E].p[0]) == pytest.approx(-4.3, abs=0.15)
    assert float(by[COMPLIANCE].p[0]) == pytest.approx(0.2, rel=0.03)
    assert math.sqrt(cal.rss_full / cal.n) < 1.2 * NOISE
    # from there nothing else lowers the BIC
    assert cal.drop_swap_refit(6) is None


def test_at_the_term_limit_the_drop_swap_follows_a_replacement_refit_that_swaps_nothing():
    from rvcalib.identify import Calibrator

    c = Calibrator.__new__(Calibrator)
    c.joint, c.active, c.empirical = True, [Active(_effect("A"), np.array([1.0]), 1)], []
    c._replaced_at, c._dropswap_at, c._instances_at, c._pinscan_at = set(), set(), set(), set()
    c.over_budget = lambda: False
    c.n, c.rss_full = N, 40.0
    said: list[str] = []
    c.log = said.append
    ran: list[str] = []
    swap = {"replacement": None, "dropswap": ("A", "C"), "pinscan": None}
    c._instances_before_stop = lambda it, iterations=None: ran.append("instances") or []
    c.restart_refit = lambda adopt=True: ran.append("restart") or None
    c.replacement_refit = lambda it: ran.append("replacement") or swap["replacement"]
    c.drop_swap_refit = lambda it: ran.append("dropswap") or swap["dropswap"]
    c.pin_scan_refit = lambda it: ran.append("pinscan") or swap["pinscan"]
    its: list[dict] = []
    assert c.replacement_before_stop(5, its) == ("A", "C")
    assert ran == ["instances", "restart", "replacement", "dropswap"]
    assert its == [{"iteration": 5, "decision": "drop-swap refit at the term limit: C in place of A"}]
    assert said[-1].startswith("drop-swap refit at the term limit: C in place of A")
    # once per model state (the stubs left the state as it was)
    ran.clear()
    assert c.replacement_before_stop(6, its) is None and ran == ["instances", "restart"]
    # a replacement that swaps: no drop-swap at that state
    c.active = [Active(_effect("B"), np.array([1.0]), 1)]
    ran.clear()
    swap["replacement"] = ("B", "E")
    assert c.replacement_before_stop(7, its) == ("B", "E")
    assert ran == ["instances", "restart", "replacement"]
    assert its[-1]["decision"] == "replacement refit at the term limit: E in place of B"
    # neither swaps: the pin scan (replacements only at the limit) is the last check
    c.active = [Active(_effect("F"), np.array([1.0]), 1)]
    ran.clear()
    swap.update(replacement=None, dropswap=None, pinscan=("F", "pin_pitch[pin=3]"))
    assert c.replacement_before_stop(8, its) == ("F", "pin_pitch[pin=3]")
    assert ran == ["instances", "restart", "replacement", "dropswap", "pinscan"]
    assert its[-1]["decision"] == "pin scan at the term limit: pin_pitch[pin=3] in place of F"
