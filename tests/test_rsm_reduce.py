"""Backward elimination (refitted, hierarchical) and the paper's no-refit shortcut."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rsm
from rsm.terms import contains, parse_term
from rvpaper import DATA_DIR as PAPER_DATA

DATA = PAPER_DATA
FACTORS = ["EA", "EB", "EC", "ED"]


@pytest.fixture(scope="module")
def paper_fit() -> rsm.RSMResults:
    return rsm.fit(pd.read_csv(DATA / "paper_table6_bbd_runs.csv"), FACTORS, "te_arcmin",
                   levels=DATA / "paper_table5_levels.csv")


def _hierarchical(terms: list[str], factors: list[str]) -> bool:
    """Every term's parents (one exponent lowered by one) are in the model too."""
    monos = [parse_term(t, factors) for t in terms]
    for m in monos:
        for i, p in enumerate(m):
            if p:
                parent = list(m)
                parent[i] -= 1
                if sum(parent) and tuple(parent) not in monos:
                    return False
    return True


def test_backward_keeps_hierarchy_and_is_refitted(paper_fit):
    b = rsm.backward_elimination(paper_fit, alpha_out=0.05)
    assert b.removed and len(b.steps) == len(b.removed)
    assert _hierarchical(b.terms, FACTORS)
    assert "EB" in b.terms and "EC" in b.terms  # parents of EB:EC survive
    # the result is a genuine refit of the retained terms
    direct = paper_fit.model.with_terms(b.terms[1:]).fit(warn=False)
    assert b.results.params.to_numpy() == pytest.approx(direct.params.to_numpy())
    assert b.results.df_resid == 27 - len(b.terms)
    # stopping rule: every removable retained term is significant at alpha_out
    for t in b.terms[1:]:
        m = parse_term(t, FACTORS)
        protected = any(contains(m, parse_term(o, FACTORS)) for o in b.terms[1:])
        assert protected or b.results.pvalues[t] <= 0.05, t
    # removal order: p-values recorded when removed exceed alpha_out
    assert (b.steps["p"] > 0.05).all()


def test_backward_without_hierarchy_can_drop_parents(paper_fit):
    b = rsm.backward_elimination(paper_fit, alpha_out=0.05, hierarchy=False)
    assert not _hierarchical(b.terms, FACTORS)
    assert all(b.results.pvalues[t] <= 0.05 for t in b.terms[1:])


def test_backward_recovers_a_known_model():
    d = rsm.box_behnken(3, center=3).coded
    x = d[["x1", "x2", "x3"]].to_numpy()
    d["y"] = 1 + 2 * x[:, 0] + 3 * x[:, 0] ** 2 + np.random.default_rng(8).normal(scale=0.05, size=len(d))
    res = rsm.fit(d, ["x1", "x2", "x3"], "y")
    b = rsm.backward_elimination(res, alpha_out=0.01)
    assert {"x1", "x1^2"} <= set(b.terms)
    assert len(b.terms) <= 4
    assert b.results.params["x1^2"] == pytest.approx(3, abs=0.1)


def test_paper_shortcut_costs_on_a_non_orthogonal_design():
    rng = np.random.default_rng(21)
    x = rng.uniform(-1, 1, size=(30, 3))
    d = pd.DataFrame(x, columns=["a", "b", "c"])
    d["y"] = 1 + 2 * x[:, 0] + x[:, 0] * x[:, 1] + 1.5 * x[:, 2] ** 2 + 0.4 * x[:, 1] \
        + rng.normal(scale=0.4, size=30)
    res = rsm.fit(d, ["a", "b", "c"], "y")
    comp = rsm.compare_reductions(res, alpha=0.05)
    t = comp.table
    # without refitting, coefficients of correlated retained terms are not least squares
    assert comp.shortcut_cost > 1e-6
    assert t.loc["paper", "sse"] > t.loc["paper_refit", "sse"]
    assert t.loc["paper", "refitted"] == False  # noqa: E712
    assert comp.paper_refit.term_names == comp.paper.terms
    # paper-mode predictions are the truncated full polynomial
    full = res.params
    manual = sum(full[tn] * res.model.exog[:, res.term_names.index(tn)] for tn in comp.paper.terms)
    assert comp.paper.predict(d) == pytest.approx(manual)
    assert comp.paper.sse == pytest.approx(np.sum((d["y"] - manual) ** 2))


def test_paper_mode_in_actual_units_with_offset_centre():
    # with a non-zero centre, dropping actual-unit terms (the paper's way) differs from
    # dropping coded terms; the actual-unit truncation keeps the retained actual coefficients
    levels = rsm.Levels([rsm.FactorLevels("a", 10, 15, 20, "um"), rsm.FactorLevels("b", -1, 1, 3, "deg")])
    d = rsm.central_composite(2, center=4, levels=levels).coded
    z = d[["a", "b"]].to_numpy()
    d["y"] = 3 + z[:, 0] + 2 * z[:, 0] ** 2 + 0.5 * z[:, 0] * z[:, 1] \
        + np.random.default_rng(2).normal(scale=0.05, size=len(d))
    res = rsm.fit(d, ["a", "b"], "y", levels=levels)
    pa = rsm.paper_reduction(res, units="actual")
    pc = rsm.paper_reduction(res, units="coded")
    full_act = res.params_actual
    assert pa.coefficients.to_dict() == pytest.approx(full_act[pa.terms].to_dict())
    # evaluating the kept actual-unit coefficients by hand reproduces the paper surface
    act = levels.to_actual(d, ["a", "b"])
    by_hand = np.zeros(len(d))
    for term, c in pa.coefficients.items():
        v = np.full(len(d), c)
        if term != "Intercept":
            for part in term.split(":"):
                name, _, k = part.partition("^")
                v = v * act[name].to_numpy() ** int(k or 1)
        by_hand += v
    assert pa.predict(d) == pytest.approx(by_hand)
    assert pc.predict(d) == pytest.approx(
        sum(res.params[t] * res.model.exog[:, res.term_names.index(t)] for t in pc.terms))
    assert set(pa.terms) == set(pc.terms)
    # dropping actual-unit 'b' also removes the -centre*a:b part it carries: much worse fit
    assert "b" in pa.surface.names and "b" not in pc.surface.names
    assert pa.sse > 10 * pc.sse


def test_reduce_model_dispatch_and_errors(paper_fit):
    assert isinstance(rsm.reduce_model(paper_fit, "paper"), rsm.PaperReduction)
    assert isinstance(rsm.reduce_model(paper_fit, "backward"), rsm.BackwardResult)
    with pytest.raises(ValueError, match="backward' or 'paper"):
        rsm.reduce_model(paper_fit, "stepwise")
    with pytest.raises(ValueError, match="alpha_out"):
        rsm.backward_elimination(paper_fit, alpha_out=1.5)
