"""Cross-check against statsmodels (ols + anova_lm typ=3, influence, predictions)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rsm
from rvpaper import DATA_DIR as PAPER_DATA

DATA = PAPER_DATA


def _statsmodels():
    """statsmodels.api and statsmodels.formula.api, imported when a test runs, not at collection (both
    pytest-xdist workers collect every module; only the one running these tests needs statsmodels)."""
    import statsmodels.api as sm
    import statsmodels.formula.api as smf

    return sm, smf


def _sm_name(term: str) -> str:
    """Our term name -> statsmodels/patsy column name."""
    if term == "Intercept":
        return term
    parts = []
    for p in term.split(":"):
        if "^" in p:
            base, k = p.split("^")
            parts.append(f"I({base} ** {k})")
        else:
            parts.append(p)
    return ":".join(parts)


def _compare(ours: rsm.RSMResults, data: pd.DataFrame, response: str) -> None:
    terms = ours.term_names[1:]
    formula = f"{response} ~ " + " + ".join(_sm_name(t) for t in terms)
    sm, smf = _statsmodels()
    ref = smf.ols(formula, data).fit()
    a3 = sm.stats.anova_lm(ref, typ=3)
    for t in terms:
        n = _sm_name(t)
        assert ours.params[t] == pytest.approx(ref.params[n], rel=1e-8, abs=1e-10), t
        assert ours.bse[t] == pytest.approx(ref.bse[n], rel=1e-8), t
        assert ours.pvalues[t] == pytest.approx(ref.pvalues[n], rel=1e-6, abs=1e-14), t
        assert ours.anova.loc[t, "sum_sq"] == pytest.approx(a3.loc[n, "sum_sq"], rel=1e-8, abs=1e-14), t
        assert ours.anova.loc[t, "F"] == pytest.approx(a3.loc[n, "F"], rel=1e-8, abs=1e-12), t
        assert ours.anova.loc[t, "p"] == pytest.approx(a3.loc[n, "PR(>F)"], rel=1e-6, abs=1e-14), t
    assert ours.params["Intercept"] == pytest.approx(ref.params["Intercept"], rel=1e-8, abs=1e-10)
    assert ours.anova.loc["Residual", "sum_sq"] == pytest.approx(a3.loc["Residual", "sum_sq"], rel=1e-10)
    assert ours.anova.loc["Residual", "df"] == a3.loc["Residual", "df"]
    assert ours.anova.loc["Model", "F"] == pytest.approx(ref.fvalue, rel=1e-8)
    assert ours.anova.loc["Model", "p"] == pytest.approx(ref.f_pvalue, rel=1e-6, abs=1e-300)
    assert ours.r2 == pytest.approx(ref.rsquared, rel=1e-10)
    assert ours.r2_adj == pytest.approx(ref.rsquared_adj, rel=1e-10)
    assert ours.llf == pytest.approx(ref.llf, rel=1e-10)
    assert ours.aic == pytest.approx(ref.aic, rel=1e-10)
    assert ours.bic == pytest.approx(ref.bic, rel=1e-10)
    ci = ref.conf_int(0.05)
    mine_ci = ours.conf_int(0.05)
    for t in ours.term_names:
        n = _sm_name(t)
        assert mine_ci.loc[t, "lower"] == pytest.approx(ci.loc[n, 0], rel=1e-8, abs=1e-10)
        assert mine_ci.loc[t, "upper"] == pytest.approx(ci.loc[n, 1], rel=1e-8, abs=1e-10)
    infl = ref.get_influence()
    assert ours.influence["leverage"].to_numpy() == pytest.approx(infl.hat_matrix_diag, rel=1e-8)
    assert ours.influence["cooks_d"].to_numpy() == pytest.approx(infl.cooks_distance[0], rel=1e-7, abs=1e-14)
    assert ours.influence["student_resid"].to_numpy() == pytest.approx(
        infl.resid_studentized_internal, rel=1e-7, abs=1e-12)
    assert ours.influence["ext_student_resid"].to_numpy() == pytest.approx(
        infl.resid_studentized_external, rel=1e-7, abs=1e-12)
    assert ours.press == pytest.approx(np.sum(infl.resid_press**2), rel=1e-8)


def test_paper_data_matches_statsmodels():
    data = pd.read_csv(DATA / "paper_table6_bbd_runs.csv")
    res = rsm.fit(data, ["EA", "EB", "EC", "ED"], "te_arcmin")
    _compare(res, data, "te_arcmin")


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("terms", ["quadratic", "2fi", "linear"])
def test_random_designs_match_statsmodels(seed, terms):
    rng = np.random.default_rng(seed)
    k = 3 + seed % 2
    n = 30 + 3 * seed
    x = rng.uniform(-1, 1, size=(n, k))
    names = [f"x{i + 1}" for i in range(k)]
    data = pd.DataFrame(x, columns=names)
    data["y"] = rng.normal(size=n) + 2 * x[:, 0] - x[:, 1] ** 2
    res = rsm.fit(data, names, "y", terms=terms)
    _compare(res, data, "y")


@pytest.mark.parametrize("k", [3, 4, 5])
def test_bbd_with_random_response_matches_statsmodels(k):
    d = rsm.box_behnken(k, center=4).coded
    names = [f"x{i + 1}" for i in range(k)]
    d["y"] = np.random.default_rng(10 + k).normal(size=len(d))
    res = rsm.fit(d, names, "y")
    _compare(res, d, "y")


def test_user_cubic_terms_match_statsmodels():
    d = rsm.central_composite(3, center=4).coded
    rng = np.random.default_rng(5)
    names = ["x1", "x2", "x3"]
    d["y"] = rng.normal(size=len(d)) + d["x1"] ** 3
    res = rsm.fit(d, names, "y", terms=["quadratic", "x1^3", "x1:x2:x3"])
    assert res.term_names[-2:] == ["x1^3", "x1:x2:x3"]
    _compare(res, d, "y")


def test_prediction_intervals_match_statsmodels():
    rng = np.random.default_rng(7)
    x = rng.uniform(-1, 1, size=(25, 3))
    data = pd.DataFrame(x, columns=["a", "b", "c"])
    data["y"] = 1 + x[:, 0] + 0.5 * x[:, 1] * x[:, 2] + rng.normal(scale=0.2, size=25)
    res = rsm.fit(data, ["a", "b", "c"], "y")
    new = pd.DataFrame(rng.uniform(-1, 1, size=(6, 3)), columns=["a", "b", "c"])
    ours = res.predict(new, alpha=0.1)
    smf = _statsmodels()[1]
    ref = smf.ols("y ~ a + b + c + a:b + a:c + b:c + I(a ** 2) + I(b ** 2) + I(c ** 2)", data).fit()
    sf = ref.get_prediction(new).summary_frame(alpha=0.1)
    for col in ["mean", "mean_se", "mean_ci_lower", "mean_ci_upper", "obs_ci_lower", "obs_ci_upper"]:
        assert ours[col].to_numpy() == pytest.approx(sf[col].to_numpy(), rel=1e-8), col


def test_r2_pred_and_adequate_precision_from_statsmodels_quantities():
    data = pd.read_csv(DATA / "paper_table6_bbd_runs.csv")
    res = rsm.fit(data, ["EA", "EB", "EC", "ED"], "te_arcmin")
    smf = _statsmodels()[1]
    ref = smf.ols("te_arcmin ~ (EA + EB + EC + ED)**2 + I(EA ** 2) + I(EB ** 2) + I(EC ** 2) + I(ED ** 2)",
                  data).fit()
    press = np.sum(ref.get_influence().resid_press ** 2)
    assert res.r2_pred == pytest.approx(1 - press / ref.centered_tss, rel=1e-10)
    # Design-Expert: range of predictions over the mean prediction standard error at the runs
    se_mean = ref.get_prediction(data).se_mean
    adeq = np.ptp(ref.fittedvalues) / np.sqrt(np.mean(se_mean**2))
    assert res.adeq_precision == pytest.approx(adeq, rel=1e-10)
    assert res.adeq_precision > 4  # the paper's model is adequate by the usual rule
