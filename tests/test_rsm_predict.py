"""Prediction intervals, validation metrics, canonical analysis and bounded optimum."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rsm
from rvpaper import DATA_DIR as PAPER_DATA

DATA = PAPER_DATA
FACTORS = ["EA", "EB", "EC", "ED"]


@pytest.fixture(scope="module")
def paper_fit() -> rsm.RSMResults:
    return rsm.fit(pd.read_csv(DATA / "paper_table6_bbd_runs.csv"), FACTORS, "te_arcmin",
                   levels=DATA / "paper_table5_levels.csv")


def _truth(x: np.ndarray) -> np.ndarray:
    return (2.0 + 1.5 * x[:, 0] - 0.8 * x[:, 1] + 0.6 * x[:, 0] * x[:, 2]
            + 1.2 * x[:, 0] ** 2 + 0.7 * x[:, 2] ** 2)


def _noisy_bbd_fit(sigma: float, seed: int) -> rsm.RSMResults:
    d = rsm.box_behnken(3, center=5).coded
    x = d[["x1", "x2", "x3"]].to_numpy()
    d["y"] = _truth(x) + np.random.default_rng(seed).normal(scale=sigma, size=len(d))
    return rsm.fit(d, ["x1", "x2", "x3"], "y")


def test_predict_at_runs_equals_fitted_and_intervals_are_nested(paper_fit):
    data = pd.read_csv(DATA / "paper_table6_bbd_runs.csv")
    p = paper_fit.predict(data)
    assert p["mean"].to_numpy() == pytest.approx(paper_fit.fittedvalues)
    assert np.all(p["obs_ci_lower"] < p["mean_ci_lower"]) and np.all(p["mean_ci_lower"] < p["mean"])
    assert np.all(p["mean"] < p["mean_ci_upper"]) and np.all(p["mean_ci_upper"] < p["obs_ci_upper"])
    # se of the mean at run i is sigma * sqrt(leverage_i)
    assert p["mean_se"].to_numpy() == pytest.approx(paper_fit.sigma * np.sqrt(paper_fit.leverage))
    wide = paper_fit.predict(data, alpha=0.01)
    assert np.all(wide["obs_ci_upper"] > p["obs_ci_upper"])


def test_predict_units_and_inputs(paper_fit):
    coded = paper_fit.predict({"EA": [0.5], "EB": [-1], "EC": [0.25], "ED": [0]})
    actual = paper_fit.predict({"EA": [0.03], "EB": [-14], "EC": [1.75], "ED": [0]}, units="actual")
    arr = paper_fit.predict(np.array([[0.5, -1, 0.25, 0]]))
    assert coded["mean"][0] == pytest.approx(actual["mean"][0])
    assert coded["mean"][0] == pytest.approx(arr["mean"][0])
    # actual-unit polynomial (Eq. 8) evaluated by hand gives the same number
    b = paper_fit.params_actual
    x = {"EA": 0.03, "EB": -14.0, "EC": 1.75, "ED": 0.0}
    by_hand = 0.0
    for term, c in b.items():
        v = c
        if term != "Intercept":
            for part in term.split(":"):
                name, _, k = part.partition("^")
                v *= x[name] ** int(k or 1)
        by_hand += v
    assert by_hand == pytest.approx(actual["mean"][0], rel=1e-10)
    with pytest.raises(ValueError, match="factor column 'ED' not found"):
        paper_fit.predict({"EA": [0], "EB": [0], "EC": [0]})


def test_validation_metrics_by_hand():
    v = rsm.validation_metrics(np.array([1.0, 2.0, 4.0]), np.array([1.5, 2.0, 3.0]),
                               lower=np.array([1.2, 1.0, 3.5]), upper=np.array([2.0, 3.0, 4.5]))
    assert v.n == 3
    assert v.rmse == pytest.approx(np.sqrt((0.25 + 0 + 1) / 3))
    assert v.max_abs_error == pytest.approx(1.0)
    assert v.bias == pytest.approx((0.5 + 0 - 1) / 3)
    assert v.mae == pytest.approx(0.5)
    assert v.pi_coverage == pytest.approx(2 / 3)
    assert v.r2 == pytest.approx(1 - 1.25 / np.sum((np.array([1, 2, 4]) - 7 / 3) ** 2))
    assert v.table["inside"].tolist() == [False, True, True]


def test_validation_on_held_out_runs_has_nominal_coverage():
    sigma = 0.1
    res = _noisy_bbd_fit(sigma, seed=3)
    rng = np.random.default_rng(4)
    x = rng.uniform(-1, 1, size=(4000, 3))
    hold = pd.DataFrame(x, columns=["x1", "x2", "x3"])
    hold["y"] = _truth(x) + rng.normal(scale=sigma, size=len(x))
    v = res.validate(hold, alpha=0.05)
    assert v.n == 4000
    assert 0.88 <= v.pi_coverage <= 0.995
    assert v.rmse == pytest.approx(np.sqrt(sigma**2 + 0.05**2), rel=0.3)
    assert v.max_abs_error > v.rmse
    # a confidence interval of the mean is far too narrow for new observations
    p = res.predict(hold)
    inside_ci = np.mean((hold["y"] >= p["mean_ci_lower"]) & (hold["y"] <= p["mean_ci_upper"]))
    assert inside_ci < v.pi_coverage - 0.2


def test_canonical_analysis_of_known_minimum():
    xs = np.array([0.3, -0.2, 0.1])
    A = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, -0.2], [0.0, -0.2, 0.5]])
    d = rsm.central_composite(3, center=4).coded
    x = d[["x1", "x2", "x3"]].to_numpy()
    dx = x - xs
    noise = np.random.default_rng(0).normal(scale=1e-4, size=len(d))
    d["y"] = 5.0 + np.einsum("ij,jk,ik->i", dx, A, dx) + noise
    res = rsm.fit(d, ["x1", "x2", "x3"], "y")
    ca = res.canonical()
    assert ca.nature == "minimum" and ca.inside_design
    assert ca.stationary_point.to_numpy() == pytest.approx(xs, abs=1e-3)
    assert ca.value == pytest.approx(5.0, abs=1e-3)
    assert ca.eigenvalues == pytest.approx(np.linalg.eigvalsh(A), abs=1e-3)
    opt = res.optimum("min")
    assert opt.x_coded.to_numpy() == pytest.approx(ca.stationary_point.to_numpy(), abs=1e-5)
    assert opt.at_bound == []
    assert opt.value == pytest.approx(ca.value, abs=1e-8)


def test_canonical_saddle_and_optimum_on_the_bound():
    d = rsm.box_behnken(3, center=3).coded
    x = d[["x1", "x2", "x3"]].to_numpy()
    d["y"] = 1 + 3 * x[:, 0] + x[:, 0] ** 2 - x[:, 1] ** 2 + 0.5 * x[:, 2] ** 2 \
        + np.random.default_rng(1).normal(scale=1e-3, size=len(d))
    res = rsm.fit(d, ["x1", "x2", "x3"], "y")
    ca = res.canonical()
    assert ca.nature == "saddle"
    assert ca.stationary_point["x1"] == pytest.approx(-1.5, abs=1e-2)
    assert not ca.inside_design
    opt = res.optimum("min")
    # true minimum on the box: x1 = -1, x2 = +-1, x3 = 0 -> y = 1 - 3 + 1 - 1 = -2
    assert opt.x_coded["x1"] == pytest.approx(-1) and abs(opt.x_coded["x2"]) == pytest.approx(1)
    assert opt.x_coded["x3"] == pytest.approx(0, abs=1e-3)
    assert set(opt.at_bound) == {"x1", "x2"}
    assert opt.value == pytest.approx(-2, abs=0.01)
    hi = res.optimum("max")
    assert hi.value == pytest.approx(1 + 3 + 1 + 0.5, abs=0.01)


def test_paper_surface_minimum_inside_the_design_box(paper_fit):
    opt = paper_fit.optimum("min")
    grid = np.array(list(itertools.product(np.linspace(-1, 1, 21), repeat=4)))
    brute = paper_fit.surface.predict_coded(grid).min()
    assert opt.value <= brute + 1e-9
    assert opt.value >= brute - 0.05
    assert all(-1 <= v <= 1 for v in opt.x_coded)
    assert opt.x_actual["EA"] == pytest.approx(0.06 * opt.x_coded["EA"])
    ca = paper_fit.canonical()
    assert ca.nature == "minimum"  # all squares positive in Table 7's model
    assert np.all(ca.eigenvalues > 0)
    assert ca.stationary_point_actual["EB"] == pytest.approx(14 * ca.stationary_point["EB"])
    if ca.inside_design:
        assert opt.value == pytest.approx(ca.value, abs=1e-6)


def test_canonical_rejects_higher_order_and_linear_models():
    d = rsm.central_composite(2, center=3).coded
    d["y"] = np.random.default_rng(2).normal(size=len(d))
    with pytest.raises(ValueError, match=r"degree <= 2.*x1\^3"):
        rsm.fit(d, ["x1", "x2"], "y", terms="quadratic + x1^3").canonical()
    with pytest.raises(ValueError, match="second-order"):
        rsm.fit(d, ["x1", "x2"], "y", terms="linear").canonical()
