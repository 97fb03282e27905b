"""rsm.augment: lack of fit -> supported higher-order or physical term -> refit (API and ``rsm fit --augment``).

Moved from ``tests/test_calib_rsm.py`` (the loop lived in ``rvcalib.rsm_loop``); its checks are kept.
"""
from __future__ import annotations

import itertools
import json
import re

import numpy as np
import pandas as pd
import pytest

import rsm
from rsm.candidates import pin_clearance_candidates, polynomial_candidates
from rsm.cli import main
from rsm.terms import parse_term, term_name

FACTORS = ["EA", "EB", "EC", "ED"]


@pytest.fixture(scope="module")
def table6(paper_data):
    return pd.read_csv(paper_data / "paper_table6_bbd_runs.csv")


@pytest.fixture(scope="module")
def levels(paper_data):
    return paper_data / "paper_table5_levels.csv"


@pytest.fixture(scope="module")
def table6_aug(table6, levels):
    return rsm.augment(rsm.fit(table6, FACTORS, "te_arcmin", levels=levels))


def _lof(res: rsm.RSMResults) -> tuple[float, float]:
    return float(res.anova.loc["Lack of fit", "F"]), float(res.anova.loc["Lack of fit", "p"])


def test_table6_lack_of_fit_and_supported_term(table6_aug):
    res = table6_aug
    b, a = res.before, res.after
    # the paper's Table 7: lack of fit F 17.70, p 0.0546 (10 and 2 df), residual SS 0.3037 on 12 df
    F, p = _lof(b)
    assert F == pytest.approx(17.70, rel=2e-3)
    assert p == pytest.approx(0.0546, abs=5e-4)
    assert (b.df_lack_of_fit, b.df_pure_error, b.df_resid) == (10, 2, 12)
    assert b.ssr == pytest.approx(0.3037, rel=1e-3) and b.r2 == pytest.approx(0.9779, abs=1e-4)
    # what the data support: EB^2:EC (Bonferroni-adjusted p < 0.01), residual SS 0.304 -> 0.089, lack of fit gone
    assert res.added == ["EB^2:EC"]
    assert round(b.ssr, 3) == 0.304 and round(a.ssr, 3) == 0.089
    assert "EB^2:EC" in a.term_names and a.df_resid == 11
    t = next(t for t in res.iterations[0] if t.term == "EB^2:EC")
    assert t.p_bonferroni < 0.01 and t.delta_bic < 0
    # the test statistics are the results object's own: the term's ANOVA row and BIC of the refit
    assert t.F == pytest.approx(a.anova.loc["EB^2:EC", "F"], rel=1e-12)
    assert t.delta_bic == pytest.approx(a.bic - b.bic, rel=1e-12)
    assert t.F == pytest.approx((b.ssr - a.ssr) / (a.ssr / a.df_resid), rel=1e-10)
    assert a.ssr < b.ssr / 3 and _lof(a)[1] > 0.1 and a.r2_pred > b.r2_pred
    ne = {t.term for t in res.iterations[0] if not t.estimable}
    assert {"EA^3", "EA:EB:EC"} <= ne  # aliased with EA / zero in a Box-Behnken design
    assert "lack of fit F 17.7" in res.verdict and "EB^2:EC" in res.verdict
    assert "EB^2:EC" in rsm.format_augment(res)
    # the second iteration finds nothing more that survives Bonferroni
    assert len(res.iterations) == 2 and res.new_runs is None


def test_physical_term_on_full_factorial(levels):
    g = np.array(list(itertools.product([-1, 0, 1], repeat=4)), float)
    d = pd.DataFrame(np.vstack([g, np.zeros((3, 4))]), columns=FACTORS)
    x = d.to_numpy()
    rng = np.random.default_rng(0)
    d["y"] = 1 + 0.5 * x[:, 0] ** 2 + 0.2 * x[:, 1] + 0.05 * np.abs(x[:, 1] * 7 - x[:, 2] * 7) \
        + rng.normal(0, 0.01, len(d))
    res = rsm.augment(rsm.fit(d, FACTORS, "y", levels=levels))
    assert _lof(res.before)[1] < 0.01
    assert res.added == ["|EB/2-EC|"]
    assert _lof(res.after)[1] > 0.01 and res.after.rmse < res.before.rmse / 5
    # the derived column enters as its own factor (identity coding), coefficient in its unit: 0.05 per um
    assert res.after.params["pin_clearance"] == pytest.approx(0.05, rel=0.05)
    # polynomial candidates only: the physical term cannot be chosen
    poly = rsm.augment(rsm.fit(d, FACTORS, "y", levels=levels), candidates=polynomial_candidates(FACTORS))
    assert "|EB/2-EC|" not in poly.added


def test_new_runs_show_lack_of_fit(table6, levels):
    new = table6.iloc[:4].copy()
    new["te_arcmin"] = new["te_arcmin"] + 0.8
    fit = rsm.fit(table6, FACTORS, "te_arcmin", levels=levels)
    res = rsm.augment(fit, new_data=new, rule=rsm.SelectionRule(max_add=1))
    assert res.new_runs["n"] == 4 and res.new_runs["lack_of_fit"] and res.new_runs["p"] < 1e-3
    assert res.before.nobs == 31 and "new runs" in res.verdict
    with pytest.raises(ValueError, match="new data: response column 'te_arcmin' not found"):
        rsm.augment(fit, new_data=new.drop(columns=["te_arcmin"]))
    with pytest.raises(ValueError, match="new data: factor column 'EC' has a non-numeric value 'x' in data row 2"):
        rsm.augment(fit, new_data=new.astype({"EC": object}).assign(EC=[0, "x", 0, 0]))


def test_exact_data_term_that_zeroes_the_residual_is_added(table6):
    """Exact data (a simulator without noise): the term that takes the residual to zero gets F = inf, p = 0."""
    d = table6[FACTORS].astype(float).copy()
    d["y"] = 1 + d.EA ** 2 + 0.3 * d.EB - 0.5 * d.EB ** 2 * d.EC
    with pytest.warns(rsm.ZeroPureErrorWarning):
        fit = rsm.fit(d, FACTORS, "y")
    res = rsm.augment(fit, candidates=polynomial_candidates(FACTORS))
    assert res.added == ["EB^2:EC"] and res.after.exact_fit
    t = next(t for t in res.iterations[0] if t.term == "EB^2:EC")
    assert t.F == float("inf") and t.p == 0.0
    assert len(res.iterations) == 1  # nothing is left to explain: the loop stops
    assert "undefined (pure error is zero" in res.verdict


def test_prediction_test_is_chow(table6, levels):
    """Chow's predictive F equals the pooled-refit form ((SS_all - SS_1)/m) / (SS_1/df_1)."""
    fit = rsm.fit(table6.iloc[:23], FACTORS, "te_arcmin", levels=levels)
    pooled = rsm.fit(table6, FACTORS, "te_arcmin", levels=levels)
    t = fit.prediction_test(table6.iloc[23:])
    F = ((pooled.ssr - fit.ssr) / 4) / (fit.ssr / fit.df_resid)
    assert t["n"] == 4 and t["df_den"] == fit.df_resid == 8
    assert t["F"] == pytest.approx(F, rel=1e-9)


def test_candidate_libraries_and_rule(levels):
    names = [c.name for c in polynomial_candidates(FACTORS)]
    # display names are rsm's canonical names, so they match the ANOVA rows
    assert all(term_name(parse_term(n, FACTORS), FACTORS) == n for n in names)
    assert len(names) == 12 + 6 + 4 + 4 and len(set(names)) == len(names)
    assert [c.name for c in pin_clearance_candidates(FACTORS, rsm.Levels.coerce(levels))] == \
        ["|EB/2-EC|", "EA:|EB/2-EC|", "EA^2:|EB/2-EC|"]
    assert pin_clearance_candidates(FACTORS, None) == []
    assert pin_clearance_candidates(["EA", "EB"], rsm.Levels.coerce(levels)) == []
    with pytest.raises(ValueError, match="max_add must be an integer >= 1, not 0"):
        rsm.SelectionRule(max_add=0)
    with pytest.raises(ValueError, match="kind must be one of"):
        rsm.CandidateTerm("x", "magic", "", "EA^3")


def test_cli_augment_json(capsys, paper_data):
    runs, lv = str(paper_data / "paper_table6_bbd_runs.csv"), str(paper_data / "paper_table5_levels.csv")
    assert main(["fit", runs, "--factors", *FACTORS, "--response", "te_arcmin", "--levels", lv,
                 "--augment", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)["augment"]
    assert set(d) == {"before", "after", "added", "iterations", "new_runs", "verdict", "rule"}
    assert d["added"] == ["EB^2:EC"] and d["new_runs"] is None
    assert round(d["before"]["ssr"], 3) == 0.304 and round(d["after"]["ssr"], 3) == 0.089
    assert set(d["before"]) == {"terms", "n_runs", "ssr", "df_resid", "rmse", "r2", "r2_adj", "r2_pred", "press",
                                "bic", "lack_of_fit", "pure_error", "residuals"}
    assert d["before"]["lack_of_fit"]["df"] == 10 and d["after"]["lack_of_fit"]["p"] > 0.1
    t = next(t for t in d["iterations"][0] if t["term"] == "EA^3")
    assert t["estimable"] is False and t["F"] is None


def test_cli_augment_human(tmp_path, paper_data, capsys):
    """The human summary of ``rsm fit --augment --new-data`` (in this process: ``python -m rsm`` itself is
    run in tests/test_rsm_cli.py)."""
    runs, lv = str(paper_data / "paper_table6_bbd_runs.csv"), str(paper_data / "paper_table5_levels.csv")
    new = pd.read_csv(runs).iloc[:4]
    new.to_csv(tmp_path / "new.csv", index=False)
    code = main(["fit", runs, "--factors", *FACTORS, "--response", "te_arcmin", "--levels", lv, "--augment",
                 "--new-data", str(tmp_path / "new.csv")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "the runs support adding EB^2:EC" in out and "Against 4 new runs" in out


def test_cli_augment_errors(tmp_path, capsys, paper_data):
    runs, lv = str(paper_data / "paper_table6_bbd_runs.csv"), str(paper_data / "paper_table5_levels.csv")
    base = ["fit", runs, "--factors", *FACTORS, "--response", "te_arcmin", "--levels", lv]
    new = pd.read_csv(runs).iloc[:4]
    new.to_csv(tmp_path / "new.csv", index=False)
    new.drop(columns=["te_arcmin"]).to_csv(tmp_path / "bad.csv", index=False)
    for extra, msg in [
        (["--new-data", str(tmp_path / "new.csv")], "--new-data needs --augment"),
        (["--augment", "--max-add", "0"], "--max-add must be an integer >= 1, got 0"),
        (["--augment", "--new-data", str(tmp_path / "nope.csv")], "--new-data file .*nope.csv' does not exist"),
        (["--augment", "--new-data", str(tmp_path / "bad.csv")],
         "--new-data '.*bad.csv': response column 'te_arcmin' not found"),
    ]:
        assert main(base + extra) == 2
        cap = capsys.readouterr()
        lines = cap.err.strip().splitlines()
        assert cap.out == "" and len(lines) == 1 and lines[0].startswith("rsm: error: ")
        assert re.search(msg, lines[0]), lines[0]
