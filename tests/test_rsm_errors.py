"""Bad input gives a ValueError naming the column; zero pure error is detected, not divided by."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rsm
from rvpaper import DATA_DIR as PAPER_DATA

DATA = PAPER_DATA
FACTORS = ["EA", "EB", "EC", "ED"]


@pytest.fixture()
def table6() -> pd.DataFrame:
    return pd.read_csv(DATA / "paper_table6_bbd_runs.csv")


def test_too_few_runs(table6):
    with pytest.raises(ValueError, match=r"too few runs for the model: 14 runs .* 15 coefficients"):
        rsm.fit(table6.iloc[:14], FACTORS, "te_arcmin")
    with pytest.raises(ValueError, match=r"15 runs .* 15 coefficients"):
        rsm.fit(table6.iloc[:15], FACTORS, "te_arcmin")
    rsm.fit(table6.iloc[:14], FACTORS, "te_arcmin", terms="linear")  # 5 coefficients: fine


def test_missing_factor_column(table6):
    with pytest.raises(ValueError, match="factor column 'EB' not found in the data"):
        rsm.fit(table6.drop(columns="EB"), FACTORS, "te_arcmin")
    with pytest.raises(ValueError, match="response column 'te' not found"):
        rsm.fit(table6, FACTORS, "te")


def test_non_numeric_and_missing_cells(table6):
    bad = table6.astype({"EC": object})
    bad.loc[4, "EC"] = "abc"
    with pytest.raises(ValueError, match=r"factor column 'EC' has a non-numeric value 'abc' in data row 5"):
        rsm.fit(bad, FACTORS, "te_arcmin")
    miss = table6.copy()
    miss.loc[2, "te_arcmin"] = np.nan
    with pytest.raises(ValueError, match="response column 'te_arcmin' has a missing value in data row 3"):
        rsm.fit(miss, FACTORS, "te_arcmin")
    inf = table6.astype(float)
    inf.loc[0, "EA"] = np.inf
    with pytest.raises(ValueError, match="factor column 'EA' has a non-numeric value 'inf' in data row 1"):
        rsm.fit(inf, FACTORS, "te_arcmin")


def test_constant_factor_and_response(table6):
    const = table6.copy()
    const["EB"] = 0.0
    with pytest.raises(ValueError, match=r"factor column 'EB' is constant \(value 0\.0\)"):
        rsm.fit(const, FACTORS, "te_arcmin")
    flat = table6.copy()
    flat["te_arcmin"] = 1.0
    with pytest.raises(ValueError, match="response column 'te_arcmin' is constant"):
        rsm.fit(flat, FACTORS, "te_arcmin")


def test_bad_terms_and_levels(table6):
    with pytest.raises(ValueError, match="unknown factor 'EZ'"):
        rsm.fit(table6, FACTORS, "te_arcmin", terms="quadratic + EA:EZ")
    with pytest.raises(ValueError, match="non-integer power"):
        rsm.fit(table6, FACTORS, "te_arcmin", terms="EA^x")
    # a BBD has three levels, so EA^3 equals EA at every run
    with pytest.raises(ValueError, match=r"term 'EA\^3' cannot be estimated"):
        rsm.fit(table6, FACTORS, "te_arcmin", terms="quadratic + EA^3")
    # a 4-factor BBD never has three factors away from 0 at once
    with pytest.raises(ValueError, match="term 'EA:EB:EC' cannot be estimated"):
        rsm.fit(table6, FACTORS, "te_arcmin", terms="quadratic + EA:EB:EC")
    # the typed error carries every inestimable term; dropping them leaves a full-rank model
    with pytest.raises(rsm.NotEstimableError, match=r"term 'EA\^3' cannot be estimated.*also not estimable: "
                       r"EA:EB:EC, EB\^3") as info:
        rsm.fit(table6, FACTORS, "te_arcmin", terms="quadratic + EA^3 + EA:EB:EC + EB^3 + EA^2:EB")
    assert info.value.terms == ["EA^3", "EA:EB:EC", "EB^3"]
    kept = [t for t in rsm.parse_terms("quadratic + EA^2:EB", FACTORS)]
    assert len(rsm.fit(table6, FACTORS, "te_arcmin", terms="quadratic + EA^2:EB").params) == len(kept)
    lv = pd.read_csv(DATA / "paper_table5_levels.csv")
    with pytest.raises(ValueError, match="levels table has no row for factor 'ED'"):
        rsm.fit(table6, FACTORS, "te_arcmin", levels=lv[lv.factor != "ED"])
    lv2 = lv.astype({"center": float})
    lv2.loc[0, "center"] = 0.01
    with pytest.raises(ValueError, match="centre of factor 'EA'"):
        rsm.fit(table6, FACTORS, "te_arcmin", levels=lv2)
    with pytest.raises(ValueError, match="needs a levels table"):
        rsm.fit(table6, FACTORS, "te_arcmin", units="actual")
    with pytest.raises(ValueError, match="factor 'EA' is listed twice"):
        rsm.fit(table6, ["EA", "EA", "EB"], "te_arcmin")


def _simulator(x: np.ndarray) -> np.ndarray:
    """A deterministic, non-polynomial 'simulator'."""
    return np.exp(0.5 * (x[:, 0] + x[:, 1])) + x[:, 0] * x[:, 2] ** 2 + np.sin(1.3 * x[:, 1]) * x[:, 2]


def test_zero_pure_error_is_detected_and_lack_of_fit_skipped():
    d = rsm.box_behnken(3, center=3).coded
    d["y"] = _simulator(d[["x1", "x2", "x3"]].to_numpy())
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no division by zero anywhere
        with pytest.warns(rsm.ZeroPureErrorWarning, match="pure error is zero"):
            res = rsm.fit(d, ["x1", "x2", "x3"], "y")
    assert res.pure_error_is_zero
    assert any("pure error is zero" in n and "deterministic" in n for n in res.notes)
    a = res.anova
    assert a.loc["Pure error", "sum_sq"] == 0.0 and a.loc["Pure error", "df"] == 2
    assert np.isnan(a.loc["Lack of fit", "F"]) and np.isnan(a.loc["Lack of fit", "p"])
    assert a.loc["Lack of fit", "sum_sq"] == pytest.approx(a.loc["Residual", "sum_sq"])
    # the other tests are still there
    assert np.isfinite(a.loc["Model", "F"]) and np.isfinite(a.loc["x1", "p"])
    assert res.to_dict()["pure_error_is_zero"] is True


def test_noisy_replicates_keep_the_lack_of_fit_test():
    d = rsm.box_behnken(3, center=3).coded
    noise = np.random.default_rng(0).normal(scale=0.01, size=len(d))
    d["y"] = _simulator(d[["x1", "x2", "x3"]].to_numpy()) + noise
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = rsm.fit(d, ["x1", "x2", "x3"], "y")
    assert not res.pure_error_is_zero and res.notes == []
    assert np.isfinite(res.anova.loc["Lack of fit", "F"])


def test_no_replicates_and_exact_fit_are_reported():
    d = rsm.box_behnken(3, center=1).coded
    x = d[["x1", "x2", "x3"]].to_numpy()
    d["y"] = _simulator(x)
    res = rsm.fit(d, ["x1", "x2", "x3"], "y")
    assert res.anova.loc["Pure error", "df"] == 0
    assert np.isnan(res.anova.loc["Lack of fit", "F"])
    assert any("no replicated runs" in n for n in res.notes)
    # a response that is exactly quadratic leaves no residual: tests undefined, no crash
    d["y"] = 1 + x[:, 0] + x[:, 1] * x[:, 2] + x[:, 2] ** 2
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        exact = rsm.fit(d, ["x1", "x2", "x3"], "y")
    assert exact.r2 == pytest.approx(1.0)
    assert np.isnan(exact.anova.loc["Model", "F"]) and np.isnan(exact.pvalues["x1"])
    assert any("exactly" in n for n in exact.notes)
