"""rvcalib.rsm_loop: the closed loop on response surfaces (paper Table 6 and synthetic data)."""
from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

from rvcalib.rsm_loop import format_result, rsm_closed_loop, table6_loop


def test_table6_lack_of_fit_and_supported_term(paper_data):
    res = table6_loop(paper_data)
    b, a = res.before, res.after
    # the paper's Table 7: lack of fit F 17.70, p 0.0546 (10 and 2 df), residual SS 0.3037 on 12 df
    assert b.lack_of_fit_F == pytest.approx(17.70, rel=2e-3)
    assert b.lack_of_fit_p == pytest.approx(0.0546, abs=5e-4)
    assert (b.lack_of_fit_df, b.pure_error_df, b.df_resid) == (10, 2, 12)
    assert b.rss == pytest.approx(0.3037, rel=1e-3) and b.r2 == pytest.approx(0.9779, abs=1e-4)
    # what the data support: EB^2:EC (Bonferroni-adjusted p < 0.01), lack of fit gone
    assert res.added == ["EB^2:EC"]
    t = next(t for t in res.iterations[0] if t.term == "EB^2:EC")
    assert t.p_bonferroni < 0.01 and t.delta_bic < 0
    assert a.rss < b.rss / 3 and a.lack_of_fit_p > 0.1 and a.r2_pred > b.r2_pred
    ne = {t.term for t in res.iterations[0] if not t.estimable}
    assert {"EA^3", "EA:EB:EC"} <= ne  # aliased with EA / zero in a Box-Behnken design
    assert "lack of fit F 17.7" in res.verdict and "EB^2:EC" in res.verdict
    assert "EB^2:EC" in format_result(res)


def test_physical_term_on_full_factorial(paper_data):
    g = np.array(list(itertools.product([-1, 0, 1], repeat=4)), float)
    d = pd.DataFrame(np.vstack([g, np.zeros((3, 4))]), columns=["EA", "EB", "EC", "ED"])
    x = d.to_numpy()
    rng = np.random.default_rng(0)
    d["y"] = 1 + 0.5 * x[:, 0] ** 2 + 0.2 * x[:, 1] + 0.05 * np.abs(x[:, 1] * 7 - x[:, 2] * 7) \
        + rng.normal(0, 0.01, len(d))
    res = rsm_closed_loop(d, ["EA", "EB", "EC", "ED"], "y", levels=paper_data / "paper_table5_levels.csv")
    assert res.before.lack_of_fit_p < 0.01
    assert res.added == ["|EB/2-EC|"]
    assert res.after.lack_of_fit_p > 0.01 and res.after.rmse < res.before.rmse / 5


def test_new_runs_show_lack_of_fit(paper_data):
    data = pd.read_csv(paper_data / "paper_table6_bbd_runs.csv")
    new = data.iloc[:4].copy()
    new["te_arcmin"] = new["te_arcmin"] + 0.8
    res = rsm_closed_loop(data, ["EA", "EB", "EC", "ED"], "te_arcmin",
                          levels=paper_data / "paper_table5_levels.csv", new_data=new, max_add=1)
    assert res.new_runs["n"] == 4 and res.new_runs["lack_of_fit"] and res.new_runs["p"] < 1e-3
    assert "new runs" in res.verdict
    with pytest.raises(ValueError, match="te_arcmin"):
        rsm_closed_loop(data, ["EA", "EB", "EC", "ED"], "te_arcmin", levels=paper_data / "paper_table5_levels.csv",
                        new_data=new.drop(columns=["te_arcmin"]))
