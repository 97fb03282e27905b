"""Term syntax, user-chosen (higher-order) terms and the coded <-> actual polynomial algebra."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import rsm
from rsm.surface import PolynomialSurface
from rsm.terms import affine_transform_matrix, model_matrix, parse_term, parse_terms, term_name

F = ["EA", "EB", "EC", "ED"]


def test_term_syntax_and_canonical_names():
    assert term_name(parse_term("EB:EA", F), F) == "EA:EB"
    assert term_name(parse_term("EA*EA", F), F) == "EA^2"
    assert term_name(parse_term("EA**3", F), F) == "EA^3"
    assert term_name(parse_term("EC:EA^2:EB", F), F) == "EA^2:EB:EC"
    assert term_name(parse_term("Intercept", F), F) == "Intercept"
    names = [term_name(m, F) for m in parse_terms("quadratic", F)]
    assert names == ["Intercept", "EA", "EB", "EC", "ED", "EA:EB", "EA:EC", "EA:ED", "EB:EC",
                     "EB:ED", "EC:ED", "EA^2", "EB^2", "EC^2", "ED^2"]
    assert len(parse_terms("linear", F)) == 5 and len(parse_terms("2fi", F)) == 11
    mixed = [term_name(m, F) for m in parse_terms(["linear", "EA^2", "EB:EA", "EA:EB:EC"], F)]
    assert mixed == ["Intercept", "EA", "EB", "EC", "ED", "EA^2", "EA:EB", "EA:EB:EC"]
    plus = [term_name(m, F) for m in parse_terms("2fi + EA^3 + EA:EB", F)]
    assert plus[-1] == "EA^3" and plus.count("EA:EB") == 1
    with pytest.raises(ValueError, match="unknown factor 'EQ'"):
        parse_term("EA:EQ", F)
    with pytest.raises(ValueError, match="unknown model preset|unknown factor"):
        parse_terms("cubic", F)
    with pytest.raises(ValueError, match="reserved"):
        rsm.ResponseSurfaceModel(pd.DataFrame({"a:b": [1, 2], "y": [1, 2]}), ["a:b"], "y")


def test_user_cubic_terms_are_fitted_and_improve_a_cubic_truth():
    d = rsm.central_composite(3, center=3).coded
    x = d[["x1", "x2", "x3"]].to_numpy()
    rng = np.random.default_rng(3)
    d["y"] = 1 + x[:, 0] + 0.8 * x[:, 0] ** 3 + 0.6 * x[:, 0] * x[:, 1] * x[:, 2] \
        + rng.normal(scale=0.02, size=len(d))
    quad = rsm.fit(d, ["x1", "x2", "x3"], "y")
    cubic = rsm.fit(d, ["x1", "x2", "x3"], "y", terms=["quadratic", "x1^3", "x1:x2:x3"])
    assert cubic.term_names[-2:] == ["x1^3", "x1:x2:x3"]
    assert cubic.params["x1^3"] == pytest.approx(0.8, abs=0.05)
    assert cubic.params["x1:x2:x3"] == pytest.approx(0.6, abs=0.05)
    assert cubic.anova.loc["x1^3", "p"] < 1e-4
    assert cubic.ssr < 0.1 * quad.ssr
    assert cubic.anova.loc["Model", "df"] == quad.anova.loc["Model", "df"] + 2


def test_affine_transform_is_exact_for_higher_order_polynomials():
    rng = np.random.default_rng(0)
    factors = ["a", "b", "c"]
    monos = parse_terms(["quadratic", "a^3", "a:b:c", "a^2:b"], factors)
    coefs = rng.normal(size=len(monos))
    levels = rsm.Levels([rsm.FactorLevels("a", 1, 3, 5), rsm.FactorLevels("b", -2, 0.5, 3),
                         rsm.FactorLevels("c", 10, 20, 30)])
    surf = PolynomialSurface(factors, monos, coefs, levels)
    z = rng.uniform(-1.5, 1.5, size=(50, 3))
    x = levels.coded_to_actual(z, factors)
    act = surf.params_actual
    act_monos = [parse_term(t, factors) for t in act.index]
    assert np.allclose(model_matrix(x, act_monos) @ act.to_numpy(), surf.predict_coded(z))
    # and back: from actual coefficients to coded
    back = PolynomialSurface.from_actual(factors, act_monos, act.to_numpy(), levels)
    assert np.allclose(back.predict_coded(z), surf.predict_coded(z))
    target, T = affine_transform_matrix(monos, np.zeros(3), np.ones(3))
    assert target == list(monos) and np.allclose(T, np.eye(len(monos)))


def test_actual_coefficients_equal_a_fit_in_actual_units_with_offset_centres():
    levels = rsm.Levels([rsm.FactorLevels("p", 100, 150, 200, "N"), rsm.FactorLevels("q", 2, 4, 6, "mm"),
                         rsm.FactorLevels("r", -3, -1, 1, "deg")])
    d = rsm.box_behnken(3, center=3, levels=levels)
    act = d.actual()
    rng = np.random.default_rng(4)
    act["y"] = (0.01 * act["p"] + 0.3 * act["q"] * act["r"] + 0.2 * act["r"] ** 2
                + rng.normal(scale=0.1, size=len(act)))
    res = rsm.fit(act, ["p", "q", "r"], "y", levels=levels, units="actual")
    import statsmodels.formula.api as smf  # here, not at collection (see test_rsm_statsmodels._statsmodels)

    ref = smf.ols("y ~ p + q + r + p:q + p:r + q:r + I(p ** 2) + I(q ** 2) + I(r ** 2)", act).fit()
    tab = res.coefficients("actual")
    for t in res.term_names:
        n = t if "^" not in t else f"I({t.replace('^', ' ** ')})"
        assert tab.loc[t, "coef"] == pytest.approx(ref.params[n], rel=1e-7, abs=1e-10), t
        assert tab.loc[t, "std_err"] == pytest.approx(ref.bse[n], rel=1e-7), t
    # the quadratic and interaction tests are coding-invariant, the main effects are not
    assert res.anova.loc["q:r", "F"] == pytest.approx(ref.tvalues["q:r"] ** 2, rel=1e-7)
    assert res.pvalues["r^2"] == pytest.approx(ref.pvalues["I(r ** 2)"], rel=1e-6)
    assert res.predict(act.iloc[:4])["mean"].to_numpy() == pytest.approx(ref.predict(act.iloc[:4]).to_numpy())


def test_surface_gradient_matches_finite_differences():
    rng = np.random.default_rng(9)
    factors = ["a", "b", "c"]
    monos = parse_terms(["quadratic", "a^3", "a:b:c", "a^2:b"], factors)
    surf = PolynomialSurface(factors, monos, rng.normal(size=len(monos)))
    for x in rng.uniform(-1, 1, size=(5, 3)):
        value, grad = surf.value_and_gradient(x)
        assert value == pytest.approx(surf.predict_coded(x[None, :])[0])
        h = 1e-6
        f = surf.predict_coded
        fd = [(f((x + h * e)[None, :])[0] - f((x - h * e)[None, :])[0]) / (2 * h) for e in np.eye(3)]
        assert grad == pytest.approx(np.array(fd), rel=1e-6, abs=1e-8)
