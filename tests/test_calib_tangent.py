"""The tangent of the loop's forward model (:meth:`rvcalib.reducer_model.ReducerModel.tangent_jacobian`): every
column, a single pin's too, the derivative of the TE at the state, against differences of converged solves."""
from __future__ import annotations

import numpy as np
import pytest

from rvcad.tolerances import TOL
from rvrig.dataset import read_dataset
from rvcalib.library import ARCSEC_PER_RAD, build_library
from rvcalib.reducer_model import ReducerModel
from rvcalib.simulate import simulate_dataset


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> ReducerModel:
    """A pin's pitch (its positive side) and another pin's radius (its negative side), each pushed a third of its
    prior scale, and the compliance, on two runs at 20 N m, 12 readings per revolution off the model's grid."""
    out = tmp_path_factory.mktemp("tangent") / "ds"
    runs = [{"run": str(i + 1), "load_Nm": 20.0, "direction": d, "test": "a"} for i, d in enumerate((1, -1))]
    simulate_dataset(out, runs, {}, noise_arcsec=0.0, input_noise_arcsec=0.0, samples_per_rev=12, start_deg=0.37,
                     seed=2)
    ds = read_dataset(out)
    lib = build_library(ds, 4, ("table4", "model"))
    cands = [next(c for c in lib.candidates if c.effect_name == name and c.side == side)
             for name, side in (("pin_pitch[pin=3]", 1), ("pin_radius[pin=5]", -1))]
    return ReducerModel(ds, cands + [lib.by_name("torsional_compliance_arcsec_per_Nm")])


def test_tangent_columns_are_the_derivatives_of_converged_solves(model):
    """Each column within the scatter of the one-sided differences (step a thousandth of the prior scale: the
    solver's tolerance shows in them) plus a thousandth of its largest value, of the central difference; the
    pin's secant over its class (:meth:`ReducerModel.jacobian`) is not its tangent there. The thinner pin lifts off
    under the load: its tangent is zero, and its differences are within the resolution of two solves, each
    converged to the solver's angle tolerance (rvcad.tolerances), over the step."""
    scales = np.array([c.prior_scale for c in model.candidates])
    sides = np.array([c.side for c in model.candidates])
    theta = np.where(sides != 0, sides * scales / 3.0, 0.2)
    model.te(theta)
    assert list(model.column_kinds()) == ["pin", "pin", "derivative"]
    J = model.tangent_jacobian(theta)
    secants = model.jacobian(theta)
    for j in range(model.n_params):
        e = np.zeros(model.n_params)
        e[j] = 1e-3 * scales[j]
        mid, up, down = model.te(theta), model.te(theta + e), model.te(theta - e)
        central, scatter = (up - down) / (2 * e[j]), np.abs((up - mid) - (mid - down)) / e[j]
        gap = np.abs(J[:, j] - central)
        if model.candidates[j].key == "pin_radius":                      # lifted off: no effect at the state
            resolution = TOL.solver_angle_rad * ARCSEC_PER_RAD / e[j]
            assert not J[:, j].any() and np.all(gap <= resolution), gap.max()
        else:
            assert np.all(gap <= scatter + 1e-3 * np.abs(J[:, j]).max()), (model.candidates[j].effect_name, gap.max())
    assert np.abs(secants[:, 0] - J[:, 0]).max() > 0.05 * np.abs(J[:, 0]).max()


def test_secant_width_is_the_default_half_width_of_the_secants(model):
    """With ``secant_width`` w a pin's column, given no spread, is its secant over w prior scales: the column the
    spread w times the prior scale gives, and not the one over one prior scale (the pin's response bends)."""
    w = np.sqrt(3.0)
    wide = ReducerModel(model.dataset, model.candidates, secant_width=w)
    scales = np.array([c.prior_scale for c in model.candidates])
    theta = np.zeros(model.n_params)
    wide.te(theta)
    default = wide.jacobian(theta)
    given = wide.jacobian(theta, spread=w * scales)
    one = wide.jacobian(theta, spread=scales)
    np.testing.assert_allclose(default, given, rtol=0, atol=1e-12 * np.abs(given).max())   # the spread's rounding
    assert np.abs(default[:, 0] - one[:, 0]).max() > 0.01 * np.abs(one[:, 0]).max()
