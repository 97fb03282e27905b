"""The loop's forward model (:class:`rvcalib.reducer_model.ReducerModel`) on a dataset with runs at 0 N m output
load, rvdyn's rigid single-flank limit, beside runs under load: the TE at the readings, the Jacobian's rows at the
rigid limit (central differences of converged solves) and under load (implicit differentiation), stacked in the
runs' order, and the error that names a condition the rigid limit cannot hold."""
from __future__ import annotations

import numpy as np
import pytest

from rvcad.errors import Case
from rvdyn.te import run_te
from rvrig.dataset import read_dataset
from rvcalib.library import build_library
from rvcalib.reducer_model import (ModelEvaluationError, ReducerModel, implicit_jacobian, secant_columns,
                                   sensitivity_jacobian)
from rvcalib.simulate import simulate_dataset

#: The candidates the model solves here: a Table 4 error with a response at the rigid limit, and the torsional
#: compliance, which has none there (no load to wind up).
NAMES = ("cam_phase[crank=0,disc=0]", "torsional_compliance_arcsec_per_Nm")
#: Runs interleaved by load (the rows of the two routes are stacked back in this order).
RUNS = [(20.0, 1), (0.0, 1), (0.0, -1), (20.0, -1)]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Four runs (0 and 20 N m, both directions), 12 readings per revolution off the model's grid."""
    out = tmp_path_factory.mktemp("load0") / "ds"
    runs = [{"run": str(i + 1), "load_Nm": L, "direction": d, "test": f"{L:g}Nm"} for i, (L, d) in enumerate(RUNS)]
    simulate_dataset(out, runs, {}, noise_arcsec=0.0, input_noise_arcsec=0.0, samples_per_rev=12, start_deg=0.37,
                     seed=2)
    return read_dataset(out)


def _model(dataset, names=NAMES, **kw) -> ReducerModel:
    lib = build_library(dataset, 4, ("table4", "model"))
    return ReducerModel(dataset, [lib.by_name(n) for n in names], **kw)


def _rows(dataset, model, rigid: bool) -> np.ndarray:
    """Row indices of the runs at load 0 (``rigid``) or under load."""
    return np.concatenate([np.arange(model.offsets[i], model.offsets[i + 1]) for i, r in enumerate(dataset.runs)
                           if (r.load_Nm == 0.0) == rigid])


def test_te_at_load_0_is_run_te_at_the_rigid_limit(dataset):
    m = _model(dataset)
    theta = np.zeros(m.n_params)
    te = m.te(theta)
    assert te.shape == (sum(r.n for r in dataset.runs),) and np.all(np.isfinite(te))
    (g,) = m.groups
    case = Case.from_dict(m.case_dict(g, theta))
    for k, i in enumerate(g.runs):
        L, d = g.loads[k]
        if L != 0.0:
            continue
        want = run_te(case, "analytic", load_Nm=0, direction=d, theta_in_deg=g.angles[k]).table["te_arcsec"]
        np.testing.assert_allclose(te[m.offsets[i]:m.offsets[i + 1]], want.to_numpy(), rtol=0, atol=1e-6)
    # the loaded runs wind up under their load: their TE is not the rigid limit's
    assert np.abs(te[_rows(dataset, m, False)]).max() > 1.0 > np.abs(te[_rows(dataset, m, True)]).max()


def test_jacobian_rows_at_load_0_match_central_differences_of_te(dataset):
    """Rigid rows of the Table 4 column within 1e-4 of its largest value (measured: 6e-7) of a central difference
    of ``te`` over a
    step other than the column's (a tenth of its difference step: the rigid limit holds no more than about a
    sixteenth of a prior scale of this error on the zero-backlash ring, and the response is linear there);
    loaded rows as the implicit route gives them on the loaded runs alone; the compliance's rigid rows 0."""
    m = _model(dataset)
    theta = np.zeros(m.n_params)
    m.te(theta)
    J = m.jacobian(theta)
    assert J.shape == (m.offsets[-1], m.n_params) and np.all(np.isfinite(J))
    rigid, loaded = _rows(dataset, m, True), _rows(dataset, m, False)
    (g,) = m.groups
    sel = [k for k, (L, _) in enumerate(g.loads) if L != 0.0]
    ref = implicit_jacobian(m.case_dict(g, theta), m.deltas, [g.loads[k] for k in sel], [g.angles[k] for k in sel],
                            [g.states[k] for k in sel], None, list(m.steps()))
    h = 0.1 * m.steps()[0]
    e = np.zeros(m.n_params)
    e[0] = h
    fd = (m.te(theta + e) - m.te(theta - e)) / (2 * h)
    col = J[rigid, 0]
    assert np.abs(col).max() > 1.0                             # arcsec per unit: a response to compare
    np.testing.assert_allclose(col, fd[rigid], rtol=0, atol=1e-4 * np.abs(col).max())
    np.testing.assert_allclose(J[loaded], ref, rtol=1e-9, atol=1e-9)
    assert np.all(J[rigid, 1] == 0.0) and np.abs(J[loaded, 1]).max() > 1.0


def test_the_sensitivity_route_has_the_same_rows_at_load_0(dataset):
    m, s = _model(dataset), _model(dataset, jacobian_fn=sensitivity_jacobian)
    theta = np.zeros(m.n_params)
    m.te(theta)
    s.te(theta)
    Jm, Js = m.jacobian(theta), s.jacobian(theta)
    rigid, loaded = _rows(dataset, m, True), _rows(dataset, m, False)
    np.testing.assert_allclose(Js[rigid], Jm[rigid], rtol=0, atol=1e-9)
    # one-sided sensitivity solves under load: within 1 % of the implicit derivative (measured 0.3 %)
    assert np.all(np.abs(Js[loaded] - Jm[loaded]).max(axis=0) <= 0.01 * np.abs(Jm[loaded]).max(axis=0))


def test_secant_rows_under_load_are_those_of_the_loaded_runs_alone(dataset):
    """A single pin's and the cam-bearing clearance's secants: the rows under load equal the secants solved on the
    loaded runs alone (an end only the rigid limit cannot hold does not shorten them); the rows at load 0 finite."""
    m = _model(dataset, ("pin_pitch[pin=3] (+)", "cam_bearing_clearance_um"))
    theta = np.zeros(m.n_params)
    m.te(theta)
    J = m.jacobian(theta)
    assert list(m.column_kinds()) == ["pin", "kink"] and np.all(np.isfinite(J))
    (g,) = m.groups
    sel = [k for k, (L, _) in enumerate(g.loads) if L != 0.0]
    spread = 10.0 * m.steps()
    lo = np.maximum(-spread, [c.lower for c in m.candidates])         # one parameter each
    hi = np.minimum(spread, [c.upper for c in m.candidates])
    for j, outer in ((0, 1), (1, None)):
        ref = secant_columns(m.case_dict(g, theta), [m.deltas[j]], [lo[j]], [hi[j]], [g.loads[k] for k in sel],
                             [g.angles[k] for k in sel], [g.states[k] for k in sel], None, outer)
        np.testing.assert_allclose(J[_rows(dataset, m, False), j], ref[:, 0], rtol=1e-9, atol=1e-9)
    assert np.abs(J[_rows(dataset, m, True)]).max(axis=0).min() > 0.1        # arcsec per unit


def test_an_interference_at_the_rigid_limit_names_load_0(dataset):
    """A cam phase of its prior scale overlaps the zero-backlash ring beyond what the rigid limit holds."""
    m = _model(dataset)
    theta = np.zeros(m.n_params)
    theta[0] = 10 * m.steps()[0]
    with pytest.raises(ModelEvaluationError, match=r"load 0 N m, direction \+1: interference"):
        m.te(theta)


def test_the_statistical_columns_are_secants_over_the_prior_scale(tmp_path):
    """The statistical linearisation: each column, the derivative ones included, is the secant of converged solves
    at +- the parameter's prior scale; it differs from the tangent where the response over that scale bends. Runs
    under load only: a sun eccentricity of its prior scale interferes at the rigid limit."""
    runs = [{"run": str(i + 1), "load_Nm": 20.0, "direction": d, "test": "20Nm"} for i, d in enumerate((1, -1))]
    simulate_dataset(tmp_path / "ds", runs, {}, noise_arcsec=0.0, input_noise_arcsec=0.0, samples_per_rev=12,
                     start_deg=0.37, seed=2)
    m = _model(read_dataset(tmp_path / "ds"), ("sun_eccentricity", "torsional_compliance_arcsec_per_Nm"))
    theta = np.zeros(m.n_params)
    m.te(theta)
    tangent = m.jacobian(theta)
    assert set(m.column_kinds()) == {"derivative"}
    J = m.statistical_jacobian(theta)
    s = 10.0 * m.steps()
    lo = np.maximum(theta - s, [c.lower for c in m.candidates for _ in range(c.n_params)])
    hi = np.minimum(theta + s, [c.upper for c in m.candidates for _ in range(c.n_params)])
    for j in range(m.n_params):                    # within the bounds (the compliance's: >= 0)
        a, b = theta.copy(), theta.copy()
        a[j], b[j] = lo[j], hi[j]
        want = (m.te(b) - m.te(a)) / (hi[j] - lo[j])
        # the ends are solved from other starting states: converged to about 1e-5 of the column (measured 2e-5)
        np.testing.assert_allclose(J[:, j], want, rtol=0, atol=1e-4 * np.abs(want).max())
    # the compliance's TE is linear in it: its secant is its tangent; the sun's eccentricity bends over its class
    np.testing.assert_allclose(J[:, 2], tangent[:, 2], rtol=1e-9)
    assert np.abs(J[:, 0] - tangent[:, 0]).max() > 0.1 * np.abs(tangent[:, 0]).max()       # measured 0.24
