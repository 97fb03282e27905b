"""Sensitivity solves (rvdyn ``max_outer=1``): one linearisation from a nearby converged state.

The loop's finite-difference columns are differences of a converged state and a state a small step away.
A solve warm-started at the converged state and stopped after its first outer iteration gives that
difference within about 1 % of itself (the outer loop's contraction factor, docs/physics.md "Sensitivity solves":
0.8 % here under the physical law and 0.25 % under the impact law, whatever the step from 0.005 to 0.5 um;
5e-4 to 7e-3 on realistic seed 1's state), at about 0.55 of a converged warm solve's CPU.
Cold states always converge; the runner keys sensitivity solves apart and keeps no warm state from them.
"""
from __future__ import annotations

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvcad.tolerances import TOL
from rvdyn.contacts import AnalyticContacts
from rvdyn.runner import Runner
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver
from rvdyn.te import input_angles, run_te, run_te_many
from test_warm_start import _case  # the same perturbed case (5 um cam eccentricity, pin radius, pin pitch)

TOL_ARCSEC = TOL.solver_angle_rad * ARCSEC_PER_RAD
CONDS = [(10.0, 1), (30.0, -1)]
STEPS = 24


def _batch(d: dict, x_init=None, max_outer=None):
    g = ReducerGeometry(Case.from_dict(d))
    s = QuasiStaticSolver(g, AnalyticContacts(g, per_point=True))
    s.max_outer = max_outer
    ths = [input_angles(g.ratio, STEPS, 1.0, dd) for _, dd in CONDS]
    return s.solve_many(ths, [dd for _, dd in CONDS], [L for L, _ in CONDS], x_init=x_init)


@pytest.mark.parametrize("law", ["physical", "impact"])
def test_a_sensitivity_solve_gives_the_change_from_its_start_within_1_percent_of_it(law):
    parent = _batch(_case(5.0, law))
    start = [s.x for s in parent]
    exact = _batch(_case(5.05, law), x_init=start)
    sens = _batch(_case(5.05, law), x_init=start, max_outer=1)
    assert [s.iterations for s in sens] == [1] * len(CONDS)
    assert all(s.iterations >= 2 for s in exact)        # the converged solve needs its second linearisation
    d_exact = np.concatenate([e.te_rad - p.te_rad for e, p in zip(exact, parent)])
    d_sens = np.concatenate([s.te_rad - p.te_rad for s, p in zip(sens, parent)])
    assert np.linalg.norm(d_exact) * ARCSEC_PER_RAD > 100 * TOL_ARCSEC   # a change well above the solver tolerance
    assert np.linalg.norm(d_sens - d_exact) <= 1.5e-2 * np.linalg.norm(d_exact)


def test_a_sensitivity_solve_without_a_start_converges():
    c = Case.from_dict(_case(5.0))
    loads = [(10.0, 1), (30.0, -1)]
    conv = run_te_many(c, steps=STEPS, loads=loads)
    cold = run_te_many(c, steps=STEPS, loads=loads, max_outer=1)
    for a, b in zip(conv, cold):
        assert np.array_equal(a.table["te_arcsec"].to_numpy(), b.table["te_arcsec"].to_numpy())
    one = run_te(Case.from_dict(_case(5.0, "impact")), steps=STEPS, max_outer=1)
    assert np.array_equal(one.table["te_arcsec"].to_numpy(),
                          run_te(Case.from_dict(_case(5.0, "impact")), steps=STEPS).table["te_arcsec"].to_numpy())


@pytest.mark.parametrize("bad", [0, -1, True, 1.5, "1"])
def test_max_outer_is_validated_with_the_field_named(bad):
    c = Case.from_dict(_case(5.0, "impact"))
    with pytest.raises(ValueError, match=r"max_outer .* must be None or an integer >= 1"):
        run_te(c, steps=STEPS, max_outer=bad)
    with pytest.raises(ValueError, match=r"max_outer .* must be None or an integer >= 1"):
        run_te_many(c, steps=STEPS, loads=[(10.0, 1), (10.0, -1)], max_outer=bad)
    with pytest.raises(ValueError, match=r"max_outer .* must be None or an integer >= 1"):
        Runner(steps=STEPS)([c], "bad", max_outer=bad)


def test_runner_keys_sensitivity_solves_apart_and_keeps_no_state_of_them():
    cases = [Case.from_dict(_case(e, "physical", L, d)) for e in (5.0, 5.05) for L, d in CONDS]
    run = Runner(steps=STEPS, warm_bytes=2 ** 22, memory_bytes=2 ** 24)
    parent = run(cases[:2], "parent", group=[0, 0])
    kept = [run.states.peek(run.jobs([c])[0].neighbour_key()).copy() for c in cases[:2]]
    sens = run(cases[2:], "sensitivity", group=[1, 1], max_outer=1)
    # the neighbourhoods still hold the parent's converged states
    for c, x in zip(cases[:2], kept):
        assert np.array_equal(run.states.peek(run.jobs([c])[0].neighbour_key()), x)
    exact = run(cases[2:], "converged", group=[1, 1])
    assert run.computed == 6                                    # the converged child is a solve of its own
    for s, e, p in zip(sens, exact, parent):
        assert s["key"] != e["key"]
        d_exact, d_sens = e["te_arcsec"] - p["te_arcsec"], s["te_arcsec"] - p["te_arcsec"]
        assert np.linalg.norm(d_sens - d_exact) <= 1.5e-2 * np.linalg.norm(d_exact)


def test_a_case_taken_from_the_cache_is_its_neighbourhood_s_newest_state_again():
    a, b = (Case.from_dict(_case(e, "impact", 10.0, 1)) for e in (5.0, 5.5))
    run = Runner(steps=STEPS, warm_bytes=2 ** 22, memory_bytes=2 ** 24)
    ra = run([a], "a")
    run([b], "b")
    near = run.jobs([a])[0].neighbour_key()
    x_b = run.states.peek(near).copy()
    assert not np.array_equal(x_b, run.job_states.peek(ra[0]["key"]))
    again = run([a], "a again")
    assert again[0]["cached"] and run.computed == 2
    assert np.array_equal(run.states.peek(near), run.job_states.peek(ra[0]["key"]))


def test_a_case_asked_for_again_without_its_kept_state_leaves_no_start_for_the_sensitivity_solves():
    """The sensitivity solves after a converged case asked for again start from that case's state. When its state
    is no longer kept (the budget holds one state here, and another case of the same run condition was solved
    since), the neighbourhood keeps no state, so the sensitivity solves converge instead of moving one
    linearisation from the other case (which gives their differences against it: far off the column)."""
    a, b, a2 = (Case.from_dict(_case(e, "physical", 10.0, 1)) for e in (5.0, 15.0, 5.05))
    conv = Runner(steps=STEPS)([a2], "a2 converged")[0]["te_arcsec"]
    ref = Runner(steps=STEPS, warm_bytes=2 ** 24, memory_bytes=2 ** 24)
    ra = ref([a], "a")[0]["te_arcsec"]
    one = ref.states.peek(ref.jobs([a])[0].neighbour_key()).nbytes
    run = Runner(steps=STEPS, warm_bytes=one + one // 2, memory_bytes=2 ** 24)   # one state per store
    run([a], "a")
    run([b], "b")
    near = run.jobs([a])[0].neighbour_key()
    assert run.job_states.peek(run.jobs([a])[0].key()) is None                  # a's state pushed out by b's
    assert run([a], "a again")[0]["cached"] and run.states_lost == 1
    assert near not in run.states
    sens = run([a2], "sensitivity", max_outer=1)[0]["te_arcsec"]
    np.testing.assert_allclose(sens, conv, atol=2 * TOL_ARCSEC)
    # (against b's state, one linearisation: the failure this guards against, off by more than the change itself)
    ref([b], "b")
    wrong = ref([a2], "sensitivity from b", max_outer=1)[0]["te_arcsec"]
    assert np.linalg.norm(wrong - conv) > np.linalg.norm(conv - ra)
