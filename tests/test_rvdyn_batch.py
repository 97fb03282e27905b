"""Batched solves of one case (``rvdyn.te.run_te_many``, ``QuasiStaticSolver.solve_many``) against the
single solves they replace, and the per-point foot-point search the batch uses."""
from __future__ import annotations

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvcad.tolerances import TOL
from rvdyn.contacts import AnalyticContacts, ContactLaw
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver
from rvdyn.te import input_angles, run_te, run_te_many

#: The solver's own tolerance on the output angle, arcsec: a batch must agree with the single solves to it.
SOLVER_TOL_ARCSEC = TOL.solver_angle_rad * ARCSEC_PER_RAD

ERRORS = {"pin_pitch": 0.01, "cam_phase": 0.01, "pin_radius": -0.002, "sun_eccentricity": 0.005}
LOADS = [(5.0, 1), (5.0, -1), (120.0, 1), (120.0, -1)]
STEPS = 12


@pytest.fixture(scope="module")
def case() -> Case:
    return Case.from_dict({"name": "batch", "errors": ERRORS})


@pytest.fixture(scope="module")
def batch(case: Case) -> list:
    return run_te_many(case, "analytic", STEPS, loads=LOADS)


@pytest.mark.parametrize("i", range(len(LOADS)))
def test_run_te_many_equals_separate_run_te(case: Case, batch: list, i: int) -> None:
    load, d = LOADS[i]
    one = run_te(case, "analytic", STEPS, load_Nm=load, direction=d)
    many = batch[i]
    assert many.stats["load_Nm"] == load and many.stats["direction"] == d
    np.testing.assert_array_equal(many.table["input_deg"], one.table["input_deg"])
    dte = np.abs(many.table["te_arcsec"].to_numpy() - one.table["te_arcsec"].to_numpy()).max()
    assert dte < SOLVER_TOL_ARCSEC
    assert many.stats["pp"] == pytest.approx(one.stats["pp"], abs=2 * SOLVER_TOL_ARCSEC)
    np.testing.assert_array_equal(many.table["contacts"], one.table["contacts"])
    np.testing.assert_allclose(many.table["peak_force_N"], one.table["peak_force_N"], rtol=1e-6)
    assert set(many.stats) == set(one.stats)


def test_run_te_many_mixed_step_counts(case: Case, batch: list) -> None:
    """One count per pair: the TE run and the play runs of a Monte Carlo draw in one batch."""
    res = run_te_many(case, "analytic", [20, STEPS], loads=[(20.0, 1), LOADS[3]])
    assert [len(r.table) for r in res] == [20, STEPS]
    one = run_te(case, "analytic", 20, load_Nm=20.0, direction=1)
    assert np.abs(res[0].table["te_arcsec"].to_numpy() - one.table["te_arcsec"].to_numpy()).max() < SOLVER_TOL_ARCSEC
    assert np.abs(res[1].table["te_arcsec"].to_numpy()
                  - batch[3].table["te_arcsec"].to_numpy()).max() < SOLVER_TOL_ARCSEC


def test_physical_law_batch_equals_separate() -> None:
    """The physical law's damping floor depends on each solve's own contacts; the batch keeps them apart."""
    c = Case.from_dict({"errors": {"pin_pitch": 0.01}, "model": {"contact": "physical"}})
    res = run_te_many(c, "analytic", 8, loads=[(10.0, 1), (150.0, -1)])
    for r, (load, d) in zip(res, [(10.0, 1), (150.0, -1)]):
        one = run_te(c, "analytic", 8, load_Nm=load, direction=d)
        assert np.abs(r.table["te_arcsec"].to_numpy() - one.table["te_arcsec"].to_numpy()).max() < SOLVER_TOL_ARCSEC
        assert r.stats["contact"] == "physical"


def test_solve_many_of_one_solve_is_solve() -> None:
    """A batch of one solve with the fixed trust radius is the single solve, bit for bit (same provider
    setting)."""
    g = ReducerGeometry(Case.from_dict({"errors": {"disc_phase": 0.03}}))
    th = input_angles(g.ratio, 10, 1.0, -1)
    one = QuasiStaticSolver(g, AnalyticContacts(g)).solve(th, -1, 30.0)
    many = QuasiStaticSolver(g, AnalyticContacts(g)).solve_many([th], [-1], [30.0], expand_trust=False)[0]
    np.testing.assert_array_equal(many.te_rad, one.te_rad)
    np.testing.assert_array_equal(many.pin_force_N, one.pin_force_N)
    assert many.iterations == one.iterations


@pytest.mark.parametrize("kw, match", [
    ({"loads": [(0.0, 1)]}, r"loads\[0\] load_Nm 0\.0 must be a finite number > 0"),
    ({"loads": [(5.0, 1), (-3.0, -1)]}, r"loads\[1\] load_Nm -3\.0 must be a finite number > 0"),
    ({"loads": [(5.0, 2)]}, r"loads\[0\] direction 2 must be \+1 or -1"),
    ({"loads": [(float("nan"), 1)]}, r"loads\[0\] load_Nm nan must be"),
    ({"loads": [5.0]}, r"loads\[0\] = 5\.0 must be a \(load_Nm, direction\) pair"),
    ({"loads": []}, r"loads \[\] must be a non-empty list"),
    ({"loads": [(5.0, 1)], "steps": [8, 8]}, r"steps has 2 entries for 1 loads"),
    ({"loads": [(5.0, 1)], "solver": "mesh"}, r"solver 'mesh' is unknown"),
])
def test_run_te_many_refuses_bad_input(kw: dict, match: str) -> None:
    args = {"steps": 4, **kw}
    with pytest.raises(ValueError, match=match):
        run_te_many(Case(), **args)


def test_solve_many_refuses_load_zero() -> None:
    g = ReducerGeometry(Case())
    with pytest.raises(ValueError, match=r"load_Nm 0\.0 must be > 0 in a batch"):
        QuasiStaticSolver(g, AnalyticContacts(g), ContactLaw()).solve_many([np.zeros(2)], [1], [0.0])


def test_per_point_foot_search_agrees_with_the_shared_one() -> None:
    """Each point stopping at its own convergence finds the same feet to rounding."""
    prof = ReducerGeometry(Case()).profiles[1]
    rng = np.random.default_rng(3)
    t = rng.uniform(0.0, 2.0 * np.pi, 4000)
    p = prof.q(t) + rng.normal(0.0, 0.02, (4000, 2))
    t0 = t + rng.uniform(-0.02, 0.02, 4000)
    shared = prof.boundary_distance(p, t0)
    own = prof.boundary_distance(p, t0, per_point=True)
    assert np.abs(own[0] - shared[0]).max() < 1e-12                  # mm
    assert np.abs(own[1] - shared[1]).max() < 1e-10                  # rad


def test_a_failing_pair_raises_or_stands_in_its_place() -> None:
    """A load the elastic law cannot hold (more than 0.1 mm of penetration) fails that pair alone: raised by
    default, as run_te does, or returned in its place with errors="return" while the other pair is solved."""
    from rvdyn.solver import InterferenceError

    loads = [(5.0, 1), (3e4, -1)]
    with pytest.raises(InterferenceError, match=r"the load 30000 N m presses the contacts deeper"):
        run_te_many(Case(), "analytic", 6, loads=loads)
    res = run_te_many(Case(), "analytic", 6, loads=loads, errors="return")
    assert isinstance(res[1], InterferenceError)
    one = run_te(Case(), "analytic", 6, load_Nm=5.0, direction=1)
    assert np.abs(res[0].table["te_arcsec"].to_numpy() - one.table["te_arcsec"].to_numpy()).max() < SOLVER_TOL_ARCSEC
    with pytest.raises(ValueError, match=r"errors 'ignore' must be 'raise' or 'return'"):
        run_te_many(Case(), "analytic", 6, loads=loads, errors="ignore")


def test_run_te_many_at_given_angles_equals_run_te(case: Case) -> None:
    """Given input angles per pair (a test rig's readings, off any step grid; None: the steps) equal run_te at
    those angles to the solver tolerance; the runner batches given-angle jobs of one case the same way."""
    from rvdyn.runner import Runner

    a = np.array([0.37, 11.0, 250.5, 3000.25, 7001.0])
    pairs = [(10.0, 1), (30.0, -1), (20.0, 1)]
    given = [a, a[::-1].copy(), None]
    res = run_te_many(case, "analytic", [STEPS, STEPS, 7], loads=pairs, theta_in_deg=given)
    assert [len(r.table) for r in res] == [5, 5, 7]
    for r, (load, d), th in zip(res, pairs, given):
        one = run_te(case, "analytic", 7, load_Nm=load, direction=d, theta_in_deg=th)
        np.testing.assert_allclose(r.table["input_deg"], one.table["input_deg"], rtol=0, atol=1e-12)
        assert np.abs(r.table["te_arcsec"].to_numpy() - one.table["te_arcsec"].to_numpy()).max() < SOLVER_TOL_ARCSEC
        assert r.stats["revolutions"] == pytest.approx(one.stats["revolutions"])
    cases = [Case.from_dict({**case.to_dict(), "load_Nm": L, "direction": d}) for L, d in pairs[:2]]
    got = Runner(memory_bytes=2 ** 20)(cases, "given angles", theta_in_deg=given[:2], group=[0, 0])
    for g, r in zip(got, res[:2]):
        assert np.abs(g["te_arcsec"] - r.table["te_arcsec"].to_numpy()).max() < SOLVER_TOL_ARCSEC
    with pytest.raises(ValueError, match=r"theta_in_deg has 1 entries for 3 loads"):
        run_te_many(case, "analytic", 4, loads=pairs, theta_in_deg=[a])
    with pytest.raises(ValueError, match=r"theta_in_deg\[0\] must be a 1-D array of at least 2"):
        run_te_many(case, "analytic", 4, loads=pairs[:1], theta_in_deg=[a[:1]])
