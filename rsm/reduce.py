"""Model reduction: refitted backward elimination and the paper's no-refit shortcut.

* :func:`backward_elimination` -- repeatedly remove the least significant removable term
  (largest partial-F p-value above ``alpha_out``) and **refit**; with ``hierarchy=True``
  (default) a term is removable only if no retained term contains it (``EB`` stays while
  ``EB:EC`` or ``EB^2`` stays).
* :func:`paper_reduction` -- the paper's Eq. 9: keep the terms of the full fit with
  ``p < alpha`` (and the intercept), keep their *actual-unit* coefficients from the full
  fit (Eq. 8) unchanged and drop the rest, without refitting and without hierarchy (Eq. 9
  keeps ``EB:EC`` while dropping ``EB`` and ``EC``).
* :func:`compare_reductions` -- both on the same data, plus the paper's terms refitted, with
  residual SS / RMSE of each: what the shortcut costs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .checks import check_numeric_column
from .results import RSMResults
from .surface import PolynomialSurface, ValidationResult, validation_metrics
from .terms import INTERCEPT, Monomial, contains

__all__ = [
    "BackwardResult",
    "PaperReduction",
    "ReductionComparison",
    "backward_elimination",
    "paper_reduction",
    "compare_reductions",
    "reduce_model",
]


@dataclass
class BackwardResult:
    """Outcome of :func:`backward_elimination`.

    Attributes
    ----------
    results : RSMResults
        The refitted reduced model.
    removed : list of str
        Terms removed, in order.
    steps : DataFrame
        One row per removal: ``step, term, p`` (p-value when removed), ``n_terms`` left.
    alpha_out : float
    hierarchy : bool
    """

    results: RSMResults
    removed: list[str]
    steps: pd.DataFrame
    alpha_out: float
    hierarchy: bool

    @property
    def terms(self) -> list[str]:
        """Retained terms including the intercept."""
        return self.results.term_names


@dataclass
class PaperReduction:
    """Outcome of :func:`paper_reduction` (not a fit: coefficients are kept from the full fit).

    Attributes
    ----------
    terms : list of str
        Retained terms (``Intercept`` first) in the units the truncation was made in.
    dropped : list of str
        Dropped terms.
    units : str
        ``actual`` if truncated in actual units (levels given), else ``coded``.
    surface : PolynomialSurface
        The truncated polynomial (coded monomials; evaluate with ``predict``).
    coefficients : Series
        Retained coefficients in ``units`` (for the paper: Eq. 9).
    sse, rmse, r2 : float
        Residual SS, ``sqrt(SSE/n)`` and ``1 - SSE/SST`` on the fitted data.
    residuals : ndarray
        Observed - predicted at the runs.
    alpha : float
        Significance level used for the selection.
    """

    terms: list[str]
    dropped: list[str]
    units: str
    surface: PolynomialSurface
    coefficients: pd.Series
    sse: float
    rmse: float
    r2: float
    residuals: np.ndarray = field(repr=False)
    alpha: float = 0.05
    _data_units: str = field(default="coded", repr=False)

    @property
    def coefficients_coded(self) -> pd.Series:
        """The truncated surface in coded units."""
        return self.surface.params

    @property
    def coefficients_actual(self) -> pd.Series | None:
        """The truncated surface in actual units (None without levels)."""
        return self.surface.params_actual

    def predict(self, points: pd.DataFrame | np.ndarray | Mapping[str, Sequence[float]],
                units: str | None = None) -> np.ndarray:
        """Point predictions (no intervals: the shortcut has no error model)."""
        return self.surface.predict(points, self._data_units if units is None else units)

    def validate(self, data: pd.DataFrame, response: str, units: str | None = None) -> ValidationResult:
        """RMSE, max error etc. on held-out runs (``pi_coverage`` is NaN)."""

        obs = check_numeric_column(data, response, "response")
        return validation_metrics(obs, self.predict(data, units))


@dataclass
class ReductionComparison:
    """Outcome of :func:`compare_reductions`.

    Attributes
    ----------
    table : DataFrame
        Rows ``full``, ``paper`` (no refit), ``paper_refit`` (paper's terms, refitted) and
        ``backward`` (refitted, hierarchical by default); columns ``n_terms, terms, sse,
        rmse, r2, max_abs_resid, refitted``.
    full : RSMResults
    paper : PaperReduction
    paper_refit : RSMResults
    backward : BackwardResult
    """

    table: pd.DataFrame
    full: RSMResults
    paper: PaperReduction
    paper_refit: RSMResults
    backward: BackwardResult

    @property
    def shortcut_cost(self) -> float:
        """Residual SS of the paper's no-refit model minus that of the same terms refitted."""
        return float(self.table.loc["paper", "sse"] - self.table.loc["paper_refit", "sse"])


def _removable(monos: list[Monomial], hierarchy: bool) -> list[int]:
    out = []
    for i, m in enumerate(monos):
        if sum(m) == 0:
            continue
        if hierarchy and any(contains(m, other) for other in monos):
            continue
        out.append(i)
    return out


def backward_elimination(
    results: RSMResults, alpha_out: float = 0.05, hierarchy: bool = True
) -> BackwardResult:
    """Backward elimination with refitting after every removal.

    Parameters
    ----------
    results : RSMResults
        The starting (usually full quadratic) fit.
    alpha_out : float, default 0.05
        A term is removed while its partial-F p-value exceeds ``alpha_out``.
    hierarchy : bool, default True
        Only remove terms that no retained term contains.

    Returns
    -------
    BackwardResult
    """
    if not 0 < alpha_out < 1:
        raise ValueError(f"alpha_out must lie in (0, 1), not {alpha_out}")
    current = results
    removed: list[str] = []
    steps = []
    while True:
        monos = list(current.model.monomials)
        cand = _removable(monos, hierarchy)
        if not cand:
            break
        pv = current.pvalues.to_numpy()
        # NaN p-values (exact fit) never trigger removal
        scores = [(pv[i] if np.isfinite(pv[i]) else -1.0, i) for i in cand]
        p_worst, i_worst = max(scores)
        if not p_worst > alpha_out:
            break
        name = current.term_names[i_worst]
        keep = [n for j, n in enumerate(current.term_names) if j != i_worst and n != INTERCEPT]
        removed.append(name)
        steps.append({"step": len(removed), "term": name, "p": float(p_worst),
                      "n_terms": len(keep) + 1})
        if not keep:
            # intercept-only model: stop here rather than fit a model without factors
            removed.pop()
            steps.pop()
            break
        current = current.model.with_terms(keep).fit(alpha=results.alpha, warn=False)
    return BackwardResult(results=current, removed=removed,
                          steps=pd.DataFrame(steps, columns=["step", "term", "p", "n_terms"]),
                          alpha_out=alpha_out, hierarchy=hierarchy)


def paper_reduction(results: RSMResults, alpha: float = 0.05, units: str | None = None) -> PaperReduction:
    """The paper's simplification (Eq. 9): drop insignificant terms without refitting.

    Parameters
    ----------
    results : RSMResults
        The full fit (its coefficients are kept).
    alpha : float, default 0.05
        Terms with partial-F p-value ``< alpha`` are kept; the intercept always is.
    units : {'actual', 'coded'}, optional
        Units in which the polynomial is truncated. Default ``actual`` when the fit has a
        levels table (what the paper did: Eq. 9 keeps Eq. 8's actual-unit coefficients),
        else ``coded``. With a centre of 0 (as in the paper) both give the same surface.

    Returns
    -------
    PaperReduction
    """
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must lie in (0, 1), not {alpha}")
    if units is None:
        units = "actual" if results.levels is not None else "coded"
    pv = results.pvalues
    keep_names = [n for n in results.term_names if n == INTERCEPT or (np.isfinite(pv[n]) and pv[n] < alpha)]
    dropped = [n for n in results.term_names if n not in keep_names]
    model = results.model
    keep_idx = [results.term_names.index(n) for n in keep_names]
    if units == "coded":
        monos = [model.monomials[i] for i in keep_idx]
        coefs = results.params.to_numpy()[keep_idx]
        surface = PolynomialSurface(model.factors, monos, coefs, model.levels)
        kept = pd.Series(coefs, index=keep_names, name="coded")
    elif units == "actual":
        if results.levels is None:
            raise ValueError("units='actual' needs a levels table")
        target, T = results.surface.actual_transform()
        full_act = T @ results.params.to_numpy()
        # the actual-unit polynomial lists the coded monomials first, in the same order
        monos = [target[i] for i in keep_idx]
        coefs = full_act[keep_idx]
        surface = PolynomialSurface.from_actual(model.factors, monos, coefs, model.levels)
        kept = pd.Series(coefs, index=keep_names, name="actual")
    else:
        raise ValueError(f"units must be 'coded' or 'actual', not '{units}'")
    pred = surface.predict_coded(model.x_coded)
    resid = model.y - pred
    sse = float(resid @ resid)
    return PaperReduction(
        terms=keep_names, dropped=dropped, units=units, surface=surface, coefficients=kept,
        sse=sse, rmse=float(np.sqrt(sse / len(resid))), r2=1.0 - sse / results.ss_total,
        residuals=resid, alpha=alpha, _data_units=model.units,
    )


def compare_reductions(
    results: RSMResults,
    alpha: float = 0.05,
    alpha_out: float = 0.05,
    hierarchy: bool = True,
) -> ReductionComparison:
    """Paper-mode shortcut vs refitted reductions on the fitted data.

    Parameters
    ----------
    results : RSMResults
        The full fit.
    alpha : float
        Selection level of :func:`paper_reduction`.
    alpha_out, hierarchy
        Passed to :func:`backward_elimination`.

    Returns
    -------
    ReductionComparison
        ``table.loc['paper', 'sse'] >= table.loc['paper_refit', 'sse']`` always holds
        (least squares is optimal for a given term set); the difference is
        :attr:`ReductionComparison.shortcut_cost`.
    """
    paper = paper_reduction(results, alpha)
    back = backward_elimination(results, alpha_out, hierarchy)
    refit_terms = [t for t in paper.terms if t != INTERCEPT]
    if paper.units == "actual":
        # the refit uses the same monomials as the truncated actual-unit polynomial
        refit_terms = [t for t in paper.surface.names if t != INTERCEPT]
    paper_refit = results.model.with_terms(refit_terms).fit(alpha=results.alpha, warn=False)

    def row(name: str, terms: list[str], resid: np.ndarray, refitted: bool) -> dict:
        sse = float(resid @ resid)
        return {"model": name, "n_terms": len(terms), "terms": " + ".join(terms), "sse": sse,
                "rmse": float(np.sqrt(sse / len(resid))), "r2": 1.0 - sse / results.ss_total,
                "max_abs_resid": float(np.max(np.abs(resid))), "refitted": refitted}

    rows = [
        row("full", results.term_names, results.resid, True),
        row("paper", paper.terms, paper.residuals, False),
        row("paper_refit", paper_refit.term_names, paper_refit.resid, True),
        row("backward", back.results.term_names, back.results.resid, True),
    ]
    table = pd.DataFrame(rows).set_index("model")
    return ReductionComparison(table=table, full=results, paper=paper, paper_refit=paper_refit,
                               backward=back)


def reduce_model(results: RSMResults, method: str = "backward", **kwargs):
    """Dispatch: ``backward`` -> :func:`backward_elimination`, ``paper`` -> :func:`paper_reduction`."""
    if method == "backward":
        return backward_elimination(results, **kwargs)
    if method == "paper":
        return paper_reduction(results, **kwargs)
    raise ValueError(f"reduction method must be 'backward' or 'paper', not '{method}'")
