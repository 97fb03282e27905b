"""rvdyn.implicit: TE Jacobians by implicit differentiation against differences of converged solves.

Each column is checked row by row against the forward and backward differences (secants) of warm-started,
converged solves of ``base +- h delta``: where the TE's slope is monotone over ``[-h, h]`` the derivative at the
base lies between the two secants, a contact that opens or closes inside the step included (the secants are then
the slopes on either side of the kink). Each secant carries the solver's tolerance on both its solves,
``2 eps / h`` with ``eps = Tolerances.solver_angle_rad`` (1e-9 rad) in arcsec, the whole allowance. A realistic
base has contacts that open or close within nanometres of it, where the slope over a step is not monotone: a row
passes when its derivative lies between the secants of either step ``STEPS``; the smaller step resolves the
kinks the larger one spans, the larger one keeps the solver's tolerance small against the step. At 1e-9 rad
the secants resolve about 1 % of a column; references solved to 1e-12 rad resolve 1e-4 (a second test), enough
to see the contact forces times the gaps' curvature and the Johnson constants' change with the geometry, each
about 1e-3 of the columns.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvcad.tolerances import TOL, Tolerances
from rvdyn.contacts import AnalyticContacts
from rvdyn.implicit import te_jacobian
from rvdyn.options import MODEL_OPTIONS
from rvdyn.results import ARCSEC_PER_RAD
from rvdyn.solver import QuasiStaticSolver
from rvdyn.te import run_te_many

DEFAULTS = {k: o.default for k, o in MODEL_OPTIONS.items()}
LOADS = [(10.0, 1), (10.0, -1), (30.0, 1), (30.0, -1)]
#: Steps of the reference differences, in units of each direction (0.2 um and 0.04 um for a direction of 1 um).
STEPS = (0.2, 0.04)
#: A realistic base: several errors of 1-5 um (0.001-0.003 deg), the pins 2 um small (a clearance), a lumped
#: compliance, a friction torque and a cam-bearing clearance (so that both are differenced centrally).
BASE_ERRORS = {"sun_eccentricity": 3.0, "planet_eccentricity": {"value": -4.0, "crank": 0, "angle_deg": 30.0},
               "cam_phase": 1.5, "cam_eccentricity": -2.0, "carrier_hole_eccentricity": 2.0,
               "disc_hole_eccentricity": -1.0, "pin_circle_offset": {"value": 3.0, "angle_deg": 60.0},
               "pin_circle_diameter": 2.0, "pin_radius": -2.0, "disc_phase": 0.003, "pin_pitch": 0.002}
BASE_MODEL = {"torsional_compliance_arcsec_per_Nm": 0.2, "friction_torque_Nm": 0.5, "cam_bearing_clearance_um": 2.0}
FOURIER = [math.cos(3 * 2 * math.pi * i / 40) for i in range(40)]
PARAMS = {
    "pin 7 pitch": {"errors": {"pin_pitch": {"value": 0.001, "pin": 7}}},
    "pin 7 radius": {"errors": {"pin_radius": {"value": 1.0, "pin": 7}}},
    "pin 7 radial position": {"errors": {"pin_circle_diameter": {"value": 2.0, "pin": 7}}},
    "pin-wise Fourier form": {"errors": {"pin_circle_diameter": FOURIER}},
    "all pins radius": {"errors": {"pin_radius": 1.0}},
    "pin circle diameter": {"errors": {"pin_circle_diameter": 1.0}},
    "sun eccentricity x": {"errors": {"sun_eccentricity": {"value": 1.0, "angle_deg": 0.0}}},
    "sun eccentricity y": {"errors": {"sun_eccentricity": {"value": 1.0, "angle_deg": 90.0}}},
    "planet 1 eccentricity x": {"errors": {"planet_eccentricity": {"value": 1.0, "crank": 1, "angle_deg": 0.0}}},
    "planet 1 eccentricity y": {"errors": {"planet_eccentricity": {"value": 1.0, "crank": 1, "angle_deg": 90.0}}},
    "cam phase crank 1 disc 1": {"errors": {"cam_phase": {"value": 1.0, "crank": 1, "disc": 1}}},
    "cam eccentricity crank 1 disc 1": {"errors": {"cam_eccentricity": {"value": 1.0, "crank": 1, "disc": 1}}},
    "carrier hole crank 1": {"errors": {"carrier_hole_eccentricity": {"value": 1.0, "crank": 1}}},
    "disc hole disc 1 hole 0": {"errors": {"disc_hole_eccentricity": {"value": 1.0, "disc": 1, "hole": 0}}},
    "disc phase disc 1": {"errors": {"disc_phase": {"value": 0.001, "disc": 1}}},
    "pin circle offset": {"errors": {"pin_circle_offset": {"value": 1.0, "angle_deg": 45.0}}},
    "torsional compliance": {"model": {"torsional_compliance_arcsec_per_Nm": 0.1}},
    "friction torque": {"model": {"friction_torque_Nm": 1.0}},
    "cam-bearing clearance": {"model": {"cam_bearing_clearance_um": 1.0}},
    "pin circle ovality": {"model": {"pin_circle_ovality_um": 1.0}},
}


def _angles(n: int, seed: int) -> list[np.ndarray]:
    """n off-grid readings (deg of input) over one output revolution per condition, in the order of motion."""
    rng = np.random.default_rng(seed)
    th = [np.sort(rng.uniform(0.0, 360.0 * 121, n)) for _ in LOADS]
    return [t if d == 1 else t[::-1].copy() for t, (_, d) in zip(th, LOADS)]


def _te(case: Case, th: list[np.ndarray], states: list[np.ndarray], tol: Tolerances = TOL) -> np.ndarray:
    """TE (arcsec) of converged solves warm-started from the states, to the tolerance ``tol``."""
    if tol is TOL:
        return np.concatenate([r.table["te_arcsec"].to_numpy()
                               for r in run_te_many(case, "analytic", loads=LOADS, theta_in_deg=th, x_init=states)])
    g = ReducerGeometry(case)
    s = QuasiStaticSolver(g, AnalyticContacts(g, per_point=True), tol=tol)
    s.want_parts = False
    sols = s.solve_many([np.radians(t) for t in th], [d for _, d in LOADS], [L for L, _ in LOADS], x_init=states)
    return np.concatenate([x.te_rad for x in sols]) * ARCSEC_PER_RAD


def _outside_secants(case: Case, th: list[np.ndarray], names: list[str], steps: tuple[float, ...],
                     tol: Tolerances = TOL) -> tuple[dict[str, list[int]], dict[str, float]]:
    """Per column of PARAMS named: the rows whose derivative lies outside the forward and backward secants of
    converged solves (each allowed ``2 eps / h``, eps the solver's tolerance) at every step (module docstring),
    and the column's RMS relative difference from the central difference at the last step."""
    jr = te_jacobian(case, [PARAMS[n] for n in names], loads=LOADS, theta_in_deg=th)
    assert all(f is None for f in jr.flags), jr.flags
    te0 = _te(case, th, jr.states, tol)
    eps = tol.solver_angle_rad * ARCSEC_PER_RAD
    assert np.allclose(te0, np.concatenate(jr.te_arcsec), atol=2 * TOL.solver_angle_rad * ARCSEC_PER_RAD)
    bad, rel = {}, {}
    for j, name in enumerate(names):
        col = jr.J[:, j]
        inside = np.zeros(col.size, dtype=bool)
        for h in steps:
            fwd = (_te(case.plus(PARAMS[name], h, DEFAULTS), th, jr.states, tol) - te0) / h
            bwd = (te0 - _te(case.plus(PARAMS[name], -h, DEFAULTS), th, jr.states, tol)) / h
            inside |= (col >= np.minimum(fwd, bwd) - 2 * eps / h) & (col <= np.maximum(fwd, bwd) + 2 * eps / h)
        ctr = 0.5 * (fwd + bwd)
        rel[name] = float(np.sqrt(np.mean((col - ctr) ** 2)) / max(np.sqrt(np.mean(ctr ** 2)), 1e-12))
        bad[name] = np.nonzero(~inside)[0].tolist()
    return {k: v for k, v in bad.items() if v}, rel


@pytest.mark.slow
@pytest.mark.parametrize("contact", ["physical", "impact"])
def test_columns_lie_between_the_secants_of_converged_solves(contact):
    model = {**BASE_MODEL, **({"contact": "impact"} if contact == "impact" else {})}
    case = Case.from_dict({"errors": BASE_ERRORS, "model": model})
    bad, rel = _outside_secants(case, _angles(6, 1), list(PARAMS), STEPS)
    assert not bad, f"rows outside the secants at every step: {bad}; RMS relative differences {rel}"


@pytest.mark.slow
def test_columns_resolve_the_contacts_curvature_against_solves_to_1e_12_rad():
    case = Case.from_dict({"errors": BASE_ERRORS, "model": BASE_MODEL})
    names = ["cam phase crank 1 disc 1", "disc hole disc 1 hole 0", "all pins radius", "pin circle offset"]
    bad, rel = _outside_secants(case, _angles(6, 1), names, (0.04, 0.008, 0.0016), Tolerances(solver_angle_rad=1e-12))
    assert not bad, f"rows outside the secants at every step: {bad}; RMS relative differences {rel}"


@pytest.mark.slow
def test_three_cranks_columns_lie_between_the_secants():
    case = Case.from_dict({"design": {"crank_angles_deg": [0.0, 120.0, 240.0]}, "errors": {
        **BASE_ERRORS, "cam_phase": {"value": 1.5, "crank": 2, "disc": 0}}, "model": BASE_MODEL})
    names = ["cam phase crank 1 disc 1", "carrier hole crank 1", "pin 7 pitch", "cam-bearing clearance"]
    bad, rel = _outside_secants(case, _angles(4, 3), names, STEPS)
    assert not bad, f"rows outside the secants at every step: {bad}; RMS relative differences {rel}"


def _small(model: dict) -> tuple[Case, list, list]:
    case = Case.from_dict({"errors": {"pin_radius": -2.0, "cam_phase": 1.5}, "model": model})
    loads = [(20.0, 1), (20.0, -1)]
    return case, loads, [np.array([10.0, 2000.0, 9000.0]), np.array([30000.0, 20000.0, 700.0])]


def test_an_option_at_its_bound_is_differenced_one_sided_and_a_new_coordinate_by_a_sensitivity_solve():
    # the impact law without a clearance: the discs do not float, a clearance floats them (3 -> 9 coordinates)
    case, loads, th = _small({"contact": "impact", "torsional_compliance_arcsec_per_Nm": 0.5})
    params = [{"model": {"friction_torque_Nm": 1.0}}, {"model": {"cam_bearing_clearance_um": 1.0}},
              {"model": {"torsional_compliance_arcsec_per_Nm": 1.0}}]
    jr = te_jacobian(case, params, loads=loads, theta_in_deg=th)
    assert jr.flags[0].startswith("one-sided (forward) difference") and "friction_torque_Nm" in jr.flags[0]
    assert jr.flags[1].startswith("one-sided sensitivity solve") and "(3 -> 9)" in jr.flags[1]
    assert jr.flags[2] is None and np.all(np.isfinite(jr.J))
    # the lumped compliance's column in closed form: -direction * load (arcsec per arcsec/(N m))
    dirs = np.repeat([d for _, d in loads], 3)
    np.testing.assert_allclose(jr.J[:, 2], -dirs * 20.0, rtol=1e-9)
    # a friction torque adds to the load: the TE's slope over the load (a friction torque of 1 N m is 1 N m more)
    te = [np.concatenate([r.table["te_arcsec"].to_numpy() for r in run_te_many(
        case, "analytic", loads=[(20.0 + s, d) for _, d in loads], theta_in_deg=th, x_init=jr.states)])
          for s in (0.1, -0.1)]
    np.testing.assert_allclose(jr.J[:, 0], (te[0] - te[1]) / 0.2, atol=0.01)


def test_bad_directions_and_arguments_name_the_field():
    case, loads, th = _small({"contact": "impact"})
    cases = [([{"errors": {"pin_pich": 1.0}}], r"params\[0\]\.errors key 'pin_pich' is unknown"),
             ([{}, {"errors": {"pin_pitch": {"value": 1e-3, "pin": 40}}}], r"params\[1\]\.errors\.pin_pitch\.pin 40"),
             ([{"errors": {"cam_phase": {"value": 1.0, "crank": 2}}}], r"params\[0\]\.errors\.cam_phase\.crank 2"),
             ([{"model": {"contact": 1.0}}], r"params\[0\]\.model key 'contact' is a named choice"),
             ([{"model": {"no_such_option": 1.0}}], r"params\[0\]\.model key 'no_such_option' is unknown"),
             ([{"erors": {}}], r"params\[0\] key 'erors' is unknown")]
    for params, match in cases:
        with pytest.raises(ValueError, match=match):
            te_jacobian(case, params, loads=loads, theta_in_deg=th)
    with pytest.raises(ValueError, match=r"solver 'fcl' is not allowed"):
        te_jacobian(case, [], loads=loads, theta_in_deg=th, solver="fcl")
    with pytest.raises(ValueError, match=r"rel_step 0 must be a number in \(0, 1\]"):
        te_jacobian(case, [], loads=loads, theta_in_deg=th, rel_step=0)


def test_states_of_another_case_are_refused():
    case, loads, th = _small({"contact": "impact"})
    jr = te_jacobian(case, [], loads=loads, theta_in_deg=th)
    assert jr.J.shape == (6, 0) and jr.stationarity_arcsec < 1e-3
    with pytest.raises(ValueError, match=r"states\[1\] must be a finite array of shape \(3, 3\)"):
        te_jacobian(case, [], loads=loads, theta_in_deg=th, states=[jr.states[0], jr.states[1][:2]])
    moved = [x + np.array([1e-3, 0.0, 0.0]) for x in jr.states]          # 1 um at the pin circle: 3 arcsec
    with pytest.raises(ValueError, match=r"states are not converged states of the base case"):
        te_jacobian(case, [], loads=loads, theta_in_deg=th, states=moved)
