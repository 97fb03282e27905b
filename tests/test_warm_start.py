"""Warm starts of the forward solves (rvdyn.solver x_init, rvdyn.te state, rvdyn.runner StateStore).

A solve started from a nearby case's converged states must reach the same equilibrium as the cold solve
(within the solver tolerance, Tolerances.solver_angle_rad = 1e-9 rad = 2.06e-4 arcsec) and take fewer outer
iterations; a solve started at its own equilibrium stops after one outer iteration.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvcad.tolerances import TOL
from rvdyn.contacts import AnalyticContacts
from rvdyn.runner import Runner, StateStore
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver
from rvdyn.te import input_angles, run_te, run_te_many

TOL_ARCSEC = TOL.solver_angle_rad * ARCSEC_PER_RAD
CONDS = [(10.0, 1), (30.0, -1)]
STEPS = 24
BASE = {"name": "warm", "errors": {"cam_eccentricity": 5.0, "pin_radius": -2.0,
                                   "pin_pitch": [{"value": 0.02, "pin": 12}]}}


def _case(ecc: float, contact: str = "physical", load: float = 20.0, direction: int = 1) -> dict:
    d = copy.deepcopy(BASE)
    d["errors"]["cam_eccentricity"] = ecc
    d["model"] = {"contact": contact}
    d["load_Nm"], d["direction"] = load, direction
    return d


def _batch(d: dict, x_init=None):
    g = ReducerGeometry(Case.from_dict(d))
    s = QuasiStaticSolver(g, AnalyticContacts(g, per_point=True))
    ths = [input_angles(g.ratio, STEPS, 1.0, dd) for _, dd in CONDS]
    return s.solve_many(ths, [dd for _, dd in CONDS], [L for L, _ in CONDS], x_init=x_init)


@pytest.fixture(scope="module", params=["physical", "impact"])
def solved(request):
    """Parent (5 um cam eccentricity), and a 0.5 um perturbation solved cold and warm from the parent."""
    law = request.param
    parent = _batch(_case(5.0, law))
    cold = _batch(_case(5.5, law))
    warm = _batch(_case(5.5, law), x_init=[s.x for s in parent])
    return parent, cold, warm, law


def test_warm_and_cold_reach_the_same_equilibrium(solved):
    _, cold, warm, _ = solved
    for c, w in zip(cold, warm):
        assert np.abs(c.te_rad - w.te_rad).max() * ARCSEC_PER_RAD < TOL_ARCSEC


def test_a_warm_solve_takes_fewer_outer_iterations(solved):
    _, cold, warm, _ = solved
    assert sum(w.iterations for w in warm) < sum(c.iterations for c in cold)


def test_a_solve_started_at_its_equilibrium_stops_after_one_outer_iteration(solved):
    parent, law = solved[0], solved[3]
    again = _batch(_case(5.0, law), x_init=[s.x for s in parent])
    assert [s.iterations for s in again] == [1] * len(CONDS)
    for a, p in zip(again, parent):
        assert np.abs(a.te_rad - p.te_rad).max() * ARCSEC_PER_RAD < TOL_ARCSEC


def test_run_te_returns_its_state_and_takes_it_as_start():
    c = Case.from_dict(_case(5.0, "impact"))
    r0 = run_te(c, steps=STEPS)
    assert r0.state is not None and r0.state.shape[0] == STEPS
    r1 = run_te(c, steps=STEPS, x_init=r0.state)
    assert r1.stats["rms"] == pytest.approx(r0.stats["rms"], abs=TOL_ARCSEC)
    # a start of another shape (another model's coordinates) is not used: the cold solve, bit for bit
    r2 = run_te(c, steps=STEPS, x_init=np.zeros((STEPS, 1)))
    assert np.array_equal(r2.table["te_arcsec"].to_numpy(), r0.table["te_arcsec"].to_numpy())
    many = run_te_many(c, steps=STEPS, loads=[(20.0, 1), (20.0, -1)], x_init=[r0.state, None])
    assert np.abs(many[0].table["te_arcsec"].to_numpy() - r0.table["te_arcsec"].to_numpy()).max() < TOL_ARCSEC


def test_bad_start_states_are_refused_with_the_field_named():
    g = ReducerGeometry(Case.from_dict(_case(5.0, "impact")))
    s = QuasiStaticSolver(g, AnalyticContacts(g, per_point=True))
    th = input_angles(g.ratio, STEPS, 1.0, 1)
    with pytest.raises(ValueError, match=r"x_init\[0\] must be a finite array of shape"):
        s.solve_many([th], [1], [20.0], x_init=[np.zeros((STEPS + 1, s.ndof))])
    with pytest.raises(ValueError, match=r"x_init has 2 entries for 1 solves"):
        s.solve_many([th], [1], [20.0], x_init=[None, None])
    bad = np.zeros((STEPS, s.ndof))
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match=r"x_init must be a finite array"):
        s.solve(th, x_init=bad)


def test_runner_starts_a_neighbour_from_the_newest_state_and_caches_no_state(tmp_path):
    cases = [Case.from_dict(_case(e, "impact", L, d)) for e in (5.0, 5.5) for L, d in CONDS]
    warm = Runner(cache=tmp_path / "c", steps=STEPS, warm_bytes=2 ** 20)
    a = warm(cases[:2], "parent", group=[0, 0])
    b = warm(cases[2:], "child", group=[1, 1])
    assert warm.states.hits == 2 and len(warm.states) == 2
    assert all("state" not in r for r in a + b)
    assert all("state" not in warm.cache.get(r["key"]) for r in a + b)
    cold = Runner(steps=STEPS)(cases[2:], "cold", group=[1, 1])
    for w, c in zip(b, cold):
        assert w["key"] == c["key"]
        assert np.abs(w["te_arcsec"] - c["te_arcsec"]).max() < TOL_ARCSEC
    single = warm(cases[2:3], "single", steps=STEPS + 2)  # another angle set: its own neighbourhood
    assert single[0]["status"] == "ok" and len(warm.states) == 3
    # one batch, no state yet: its first group is solved first, the second starts from its states
    both = Runner(steps=STEPS, warm_bytes=2 ** 20)
    got = both(cases, "both", group=[0, 0, 1, 1])
    assert both.states.hits == 2 and both.computed == 4
    for w, c in zip(got[2:], cold):
        assert np.abs(w["te_arcsec"] - c["te_arcsec"]).max() < TOL_ARCSEC


def test_state_store_keeps_the_newest_state_within_its_budget():
    st = StateStore(3 * 800)
    for i in range(4):
        st.put(f"k{i}", np.full((10, 10), float(i)))
    assert len(st) == 3 and st.get("k0") is None and st.get("k3")[0, 0] == 3.0
    st.put("k1", np.zeros((10, 10)))            # the newest state of a neighbourhood replaces the older
    assert len(st) == 3 and st.bytes == 2400 and st.get("k1")[0, 0] == 0.0
    st.put("big", np.zeros((100, 100)))         # larger than the budget: not kept
    assert st.get("big") is None and st.bytes <= st.max_bytes
    with pytest.raises(ValueError, match="warm_bytes -1 must be an integer >= 0"):
        StateStore(-1)


class _LastFirst:
    """An executor whose results arrive in the reverse order of the tasks (as from workers that finish out of
    order), each solved in this process."""

    name = "last-first"
    workers = 2

    def run(self, fn, payloads):
        got = [fn(p) for p in payloads]
        for i in reversed(range(len(payloads))):
            yield i, got[i]

    def close(self):
        pass


def test_warm_store_takes_a_batch_s_states_in_task_order_whatever_the_arrival_order():
    """Two cases of one neighbourhood (same angles, load and direction; other errors) in one batch: the state
    kept for the next solves is the last task's, whether its result arrives last (in this process) or first
    (workers finishing out of order), so a run with workers does not depend on which finished first."""
    cases = [Case.from_dict(_case(e, "impact", 10.0, 1)) for e in (5.0, 5.5, 6.0)]
    kept = []
    for ex in (None, _LastFirst()):
        r = Runner(executor=ex, steps=STEPS, warm_bytes=2 ** 20)
        r(cases[:1], "parent")
        r(cases[1:], "batch")
        kept.append(r.states.get(r.jobs(cases[2:])[0].neighbour_key()).copy())
    np.testing.assert_array_equal(kept[0], kept[1])
    solo = Runner(steps=STEPS, warm_bytes=2 ** 20)
    solo(cases[:1], "parent")
    solo(cases[2:], "last")
    np.testing.assert_array_equal(kept[0], solo.states.get(solo.jobs(cases[2:])[0].neighbour_key()))
