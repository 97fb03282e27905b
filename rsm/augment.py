"""The loop on a response surface: lack of fit -> supported higher-order or physical term -> refit.

:func:`augment` takes a fit (:class:`rsm.results.RSMResults`), optionally checks it against new
runs (:meth:`~rsm.results.RSMResults.prediction_test`, Chow's predictive F test), then adds to the
model, one at a time, each candidate term of a library (:mod:`rsm.candidates`) that the runs can
estimate, fits it with :class:`rsm.model.ResponseSurfaceModel` and reads everything it judges by
from the results object: the term's partial F and p (its ANOVA row), the BIC, lack of fit and pure
error, PRESS and predicted R2. Nothing is computed here that the results object computes.

Which term, if any, is added is the job of a :class:`SelectionRule` (kept apart from the
libraries): by default the candidate with the smallest p, if its Bonferroni-adjusted p (over the
estimable candidates of that iteration) is below ``alpha`` and it lowers the BIC; among candidates
whose columns the runs cannot tell apart (|correlation| > 0.9999 once the current model is
projected out) a physical term is preferred. The loop repeats up to ``max_add`` times on the
augmented model, and stops when the model reproduces the runs exactly (a term that takes the residual
of exact data to zero counts as F = inf, p = 0). With new runs, the candidates are judged on all runs together (the fitted and
the new ones).

Example
-------
>>> import rsm, rvpaper
>>> res = rsm.fit(rvpaper.table6_runs(), ["EA", "EB", "EC", "ED"], "te_arcmin",
...               levels=rvpaper.DATA_DIR / "paper_table5_levels.csv")
>>> aug = rsm.augment(res)
>>> aug.added, round(aug.before.ssr, 3), round(aug.after.ssr, 3)
(['EB^2:EC'], 0.304, 0.089)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .checks import NotEstimableError, check_numeric_column
from .coding import FactorLevels, Levels
from .candidates import CandidateTerm, DerivedColumn, default_candidates
from .model import ResponseSurfaceModel
from .results import RSMResults

__all__ = ["TermTest", "SelectionRule", "AugmentResult", "augment", "fit_block", "format_augment"]

#: Projected candidate columns with |correlation| above this are "the same column" for these runs.
ALIAS_CORRELATION = 0.9999


@dataclass
class TermTest:
    """The test of one candidate term added alone to the current model.

    Attributes
    ----------
    term, kind, meaning : str
        From the :class:`~rsm.candidates.CandidateTerm`.
    estimable : bool
        False when the runs cannot estimate it (``reason`` says why); the other fields are NaN.
    reason : str
        Why it is not estimable ('' if it is).
    ssr : float
        Residual SS after adding it.
    F, p : float
        Its partial (type-III) F test in the augmented model's ANOVA (1 and ``df_resid`` df).
    p_bonferroni : float
        ``min(1, p * number of estimable candidates)``.
    delta_bic : float
        BIC of the augmented model minus BIC of the current one (negative: supported).
    lack_of_fit_F, lack_of_fit_p : float
        The lack-of-fit test of the augmented model (NaN where undefined).
    r2_pred : float
        Predicted R2 of the augmented model.
    aliases : list of str
        Other estimable candidates whose columns these runs cannot tell apart from this one.
    """

    term: str
    kind: str
    meaning: str
    estimable: bool
    reason: str = ""
    ssr: float = float("nan")
    F: float = float("nan")
    p: float = float("nan")
    p_bonferroni: float = float("nan")
    delta_bic: float = float("nan")
    lack_of_fit_F: float = float("nan")
    lack_of_fit_p: float = float("nan")
    r2_pred: float = float("nan")
    aliases: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return dict(self.__dict__)


@dataclass(frozen=True)
class SelectionRule:
    """Which tested candidate, if any, is added.

    Parameters
    ----------
    alpha : float, default 0.05
        Family-wise level: the chosen term needs a Bonferroni-adjusted p below it.
    require_bic : bool, default True
        The chosen term must also lower the BIC.
    prefer_physical : bool, default True
        Among aliased candidates (same column for these runs) take a physical term.
    max_add : int, default 2
        At most this many terms are added.
    """

    alpha: float = 0.05
    require_bic: bool = True
    prefer_physical: bool = True
    max_add: int = 2

    def __post_init__(self) -> None:
        if not 0 < self.alpha < 1:
            raise ValueError(f"alpha must lie in (0, 1), not {self.alpha}")
        if int(self.max_add) != self.max_add or self.max_add < 1:
            raise ValueError(f"max_add must be an integer >= 1, not {self.max_add}")

    def select(self, tests: Sequence[TermTest]) -> TermTest | None:
        """The term to add from one iteration's tests, or None."""
        est = [t for t in tests if t.estimable and math.isfinite(t.p)]
        if not est:
            return None
        best = min(est, key=lambda t: (t.p, t.kind != "physical"))
        if self.prefer_physical and best.kind != "physical":
            phys = [u for u in est if u.term in best.aliases and u.kind == "physical"]
            if phys:
                best = phys[0]
        if not best.p_bonferroni < self.alpha:
            return None
        if self.require_bic and not best.delta_bic < 0:
            return None
        return best


@dataclass
class AugmentResult:
    """Result of :func:`augment`.

    Attributes
    ----------
    start : RSMResults
        The fit that was given (its own runs only).
    before : RSMResults
        The starting terms fitted to all runs (the fitted and the new ones).
    after : RSMResults
        The augmented model fitted to all runs (``before`` if nothing was added).
    added : list of str
        Display names of the added terms, in order.
    iterations : list of list of TermTest
        The candidate tests of each iteration.
    new_runs : dict or None
        :meth:`RSMResults.prediction_test` of ``start`` on the new runs plus ``lack_of_fit``
        (p < alpha); None without new runs.
    rule : SelectionRule
    verdict : str
        One paragraph: lack of fit before, what was added, residual SS / RMSE / lack of fit after.
    """

    start: RSMResults
    before: RSMResults
    after: RSMResults
    added: list[str]
    iterations: list[list[TermTest]]
    new_runs: dict | None
    rule: SelectionRule
    verdict: str

    def to_dict(self) -> dict:
        """JSON-ready form (documented in :mod:`rsm.cli`)."""
        return {"before": fit_block(self.before), "after": fit_block(self.after), "added": list(self.added),
                "iterations": [[t.to_dict() for t in it] for it in self.iterations],
                "new_runs": self.new_runs, "verdict": self.verdict,
                "rule": {"alpha": self.rule.alpha, "require_bic": self.rule.require_bic,
                         "prefer_physical": self.rule.prefer_physical, "max_add": self.rule.max_add}}


def fit_block(res: RSMResults) -> dict:
    """The statistics of one fit that the loop reports, read from the results object.

    Returns
    -------
    dict
        ``terms, n_runs, ssr, df_resid, rmse, r2, r2_adj, r2_pred, press, bic,
        lack_of_fit {ss, df, F, p}, pure_error {ss, df}, residuals``.
    """
    lof = res.anova.loc["Lack of fit"]
    return {"terms": list(res.term_names), "n_runs": res.nobs, "ssr": res.ssr, "df_resid": res.df_resid,
            "rmse": res.rmse, "r2": res.r2, "r2_adj": res.r2_adj, "r2_pred": res.r2_pred, "press": res.press,
            "bic": res.bic,
            "lack_of_fit": {"ss": res.ss_lack_of_fit, "df": res.df_lack_of_fit, "F": float(lof["F"]),
                            "p": float(lof["p"])},
            "pure_error": {"ss": res.ss_pure_error, "df": res.df_pure_error},
            "residuals": [float(v) for v in res.resid]}


class _Workspace:
    """All runs in coded units with the derived columns, and models built on them."""

    def __init__(self, start: RSMResults, new_data: pd.DataFrame | None, derived: list[DerivedColumn]) -> None:
        m = start.model
        self.factors = list(m.factors)
        self.response = m.response
        frame = pd.DataFrame(m.x_coded, columns=self.factors)
        frame[self.response] = m.y
        if new_data is not None:
            new = pd.DataFrame({f: check_numeric_column(new_data, f, "new-data factor") for f in self.factors})
            if m.units == "actual":
                new[self.factors] = m.levels.actual_to_coded(new.to_numpy(float), self.factors)
            new[self.response] = check_numeric_column(new_data, self.response, "new-data response")
            frame = pd.concat([frame, new], ignore_index=True)
        self.levels = m.levels
        self.derived: dict[str, DerivedColumn] = {}
        if derived:
            actual = pd.DataFrame(self.levels.coded_to_actual(frame[self.factors].to_numpy(float), self.factors),
                                  columns=self.factors)
            for d in derived:
                if d.name in self.derived or d.name in self.factors or d.name == self.response:
                    continue
                frame[d.name] = np.asarray(d.func(actual), dtype=float)
                self.derived[d.name] = d
        self.frame = frame

    def model(self, terms: list[str], extra: list[str]) -> ResponseSurfaceModel:
        """A model on all runs with ``terms`` (rsm syntax) and the derived columns ``extra``."""
        factors = self.factors + [e for e in dict.fromkeys(extra)]
        levels = self.levels
        if levels is not None and extra:
            rows = [levels[f] for f in self.factors]
            rows += [FactorLevels(e, -1.0, 0.0, 1.0, self.derived[e].unit, self.derived[e].meaning)
                     for e in dict.fromkeys(extra)]
            levels = Levels(rows)
        return ResponseSurfaceModel(self.frame, factors, self.response, terms, levels, "coded")


def augment(
    results: RSMResults,
    new_data: pd.DataFrame | None = None,
    candidates: Sequence[CandidateTerm] | None = None,
    rule: SelectionRule | None = None,
) -> AugmentResult:
    """Test the candidate terms the runs can estimate beyond a fit and add those they support.

    Parameters
    ----------
    results : RSMResults
        The starting fit (e.g. the full quadratic of :func:`rsm.fit`).
    new_data : DataFrame or None
        New runs or measured responses (every factor column and the response, in the units of the
        fitted data). The starting fit is tested against them (Chow's predictive F), and the
        candidates are then judged on all runs together.
    candidates : sequence of CandidateTerm or None
        Default :func:`rsm.candidates.default_candidates` (polynomial terms, and the pin clearance
        terms when the factors are the paper's and a levels table is given).
    rule : SelectionRule or None
        Default ``SelectionRule()``.

    Returns
    -------
    AugmentResult

    Raises
    ------
    ValueError
        New runs without a factor or the response column, or with a non-numeric cell (the message
        names the column and the row).
    """
    rule = SelectionRule() if rule is None else rule
    m = results.model
    cands = list(default_candidates(m.factors, m.levels) if candidates is None else candidates)
    if any(c.derived is not None for c in cands) and m.levels is None:
        raise ValueError("physical candidate terms need a levels table (their columns are defined in actual units)")
    new_check = None
    if new_data is not None and len(new_data) > 0:
        try:
            new_check = results.prediction_test(new_data)
        except ValueError as exc:
            raise ValueError(f"new data: {exc}") from None
        new_check["lack_of_fit"] = bool(new_check["p"] < rule.alpha)
    else:
        new_data = None
    ws = _Workspace(results, new_data, [c.derived for c in cands if c.derived is not None])
    terms = list(m.term_names[1:])
    extra: list[str] = []
    before = cur = ws.model(terms, extra).fit(alpha=results.alpha, warn=False)
    added: list[str] = []
    iterations: list[list[TermTest]] = []
    for _ in range(rule.max_add):
        if cur.exact_fit:  # nothing left to explain
            break
        tests, columns = _test_candidates(ws, cur, terms, extra, [c for c in cands if c.name not in added])
        _mark_aliases(cur, tests, columns)
        iterations.append(tests)
        best = rule.select(tests)
        if best is None:
            break
        cand = next(c for c in cands if c.name == best.term)
        terms.append(cand.term)
        if cand.derived is not None:
            extra.append(cand.derived.name)
        added.append(cand.name)
        cur = ws.model(terms, extra).fit(alpha=results.alpha, warn=False)
    verdict = _verdict(results, before, cur, added, new_check)
    return AugmentResult(results, before, cur, added, iterations, new_check, rule, verdict)


def _test_candidates(ws: _Workspace, cur: RSMResults, terms: list[str], extra: list[str],
                     cands: list[CandidateTerm]) -> tuple[list[TermTest], dict[str, np.ndarray]]:
    tests: list[TermTest] = []
    columns: dict[str, np.ndarray] = {}
    for c in cands:
        ex = extra + ([c.derived.name] if c.derived is not None else [])
        try:
            model = ws.model(terms + [c.term], ex)
        except NotEstimableError:
            tests.append(TermTest(c.name, c.kind, c.meaning, False,
                                  "its column is zero or a combination of the model's columns at these runs"))
            continue
        except ValueError as exc:  # too few runs, a constant derived column
            tests.append(TermTest(c.name, c.kind, c.meaning, False, str(exc)))
            continue
        new_names = [t for t in model.term_names if t not in cur.term_names]
        if len(new_names) != 1:  # the candidate is already a term of the model
            tests.append(TermTest(c.name, c.kind, c.meaning, False, "already in the model"))
            continue
        if model.nobs - len(model.term_names) < 2:
            tests.append(TermTest(c.name, c.kind, c.meaning, False, "it would leave fewer than 2 residual df"))
            continue
        res = model.fit(alpha=cur.alpha, warn=False)
        row = res.anova.loc[new_names[0]]
        lof = res.anova.loc["Lack of fit"]
        F, p = float(row["F"]), float(row["p"])
        if res.exact_fit and not cur.exact_fit:
            # the term takes the residual to zero (exact data): the strongest support there is; the ANOVA
            # leaves F undefined (0/0 after the term), the limit of F as the residual vanishes is +inf
            F, p = float("inf"), 0.0
        tests.append(TermTest(c.name, c.kind, c.meaning, True, "", res.ssr, F, p,
                              float("nan"), res.bic - cur.bic, float(lof["F"]), float(lof["p"]), res.r2_pred))
        columns[c.name] = model.exog[:, model.term_names.index(new_names[0])]
    est = [t for t in tests if t.estimable]
    for t in est:
        t.p_bonferroni = min(1.0, t.p * len(est)) if math.isfinite(t.p) else float("nan")
    return tests, columns


def _mark_aliases(cur: RSMResults, tests: list[TermTest], columns: dict[str, np.ndarray]) -> None:
    """Candidates whose columns, with the current model projected out, are the same for these runs."""
    Q, _ = np.linalg.qr(cur.model.exog)
    unit: dict[str, np.ndarray] = {}
    for name, v in columns.items():
        r = v - Q @ (Q.T @ v)
        unit[name] = r / np.linalg.norm(r)
    for t in tests:
        if t.term in unit:
            t.aliases = [u for u in unit if u != t.term and abs(float(unit[t.term] @ unit[u])) > ALIAS_CORRELATION]


def _verdict(start: RSMResults, before: RSMResults, after: RSMResults, added: list[str],
             new_check: dict | None) -> str:
    head = f"The starting model ({len(before.term_names)} terms) shows {_lof_text(before)}"
    if added:
        text = (f"{head}; the runs support adding {', '.join(added)}: residual SS {before.ssr:.4g} -> "
                f"{after.ssr:.4g}, RMSE {before.rmse:.4g} -> {after.rmse:.4g}, R2pred {before.r2_pred:.4f} -> "
                f"{after.r2_pred:.4f}" + (f", {_lof_text(after)}." if math.isfinite(float(after.anova.loc[
                    "Lack of fit", "F"])) else "."))
    else:
        text = f"{head}; no estimable higher-order or physical term is supported (Bonferroni-adjusted F test and BIC)."
    if new_check is not None:
        text += (f" Against {new_check['n']} new runs the starting fit gives predictive F {new_check['F']:.4g} "
                 f"(p {new_check['p']:.3g}), prediction RMSE {new_check['rmse_pred']:.4g}"
                 f"{' (lack of fit)' if new_check['lack_of_fit'] else ''}; terms judged on all "
                 f"{before.nobs} runs.")
    return text


def _lof_text(res: RSMResults) -> str:
    """``lack of fit F .. (p .., a and b df)``, or why the lack-of-fit test is undefined."""
    lof = res.anova.loc["Lack of fit"]
    if math.isfinite(float(lof["F"])):
        return f"lack of fit F {lof['F']:.4g} (p {lof['p']:.3g}, {res.df_lack_of_fit} and {res.df_pure_error} df)"
    if res.pure_error_is_zero:
        why = "pure error is zero: replicated runs agree exactly, as a deterministic simulator gives"
    elif res.df_pure_error == 0:
        why = "no replicated runs"
    else:
        why = "no lack-of-fit df"
    return (f"residual SS {res.ssr:.4g} on {res.df_resid} df, all of it lack of fit: the lack-of-fit F test is "
            f"undefined ({why})") if res.pure_error_is_zero else f"no lack-of-fit test ({why})"


def format_augment(res: AugmentResult, top: int = 8) -> str:
    """Plain-text report of an :class:`AugmentResult`."""
    lines = ["Augmenting the model (lack of fit -> supported higher-order or physical term -> refit)",
             res.verdict, ""]
    for tag, r in (("before", res.before), ("after", res.after)):
        b = fit_block(r)
        lines.append(f"{tag}: {len(r.term_names)} terms, residual SS {b['ssr']:.5g} ({b['df_resid']} df), RMSE "
                     f"{b['rmse']:.4g}, R2 {b['r2']:.4f}, R2adj {b['r2_adj']:.4f}, R2pred {b['r2_pred']:.4f}, BIC "
                     f"{b['bic']:.2f}, lack of fit SS {b['lack_of_fit']['ss']:.4g} ({b['lack_of_fit']['df']} df) "
                     f"F {b['lack_of_fit']['F']:.4g} p {b['lack_of_fit']['p']:.3g}, pure error SS "
                     f"{b['pure_error']['ss']:.4g} ({b['pure_error']['df']} df)")
    for i, tests in enumerate(res.iterations, 1):
        lines += ["", f"iteration {i}: candidate terms (partial F, p, Bonferroni p, dBIC, lack-of-fit p after)"]
        est = sorted([t for t in tests if t.estimable], key=lambda t: t.p)
        for t in est[:top]:
            al = f"  (same column as {', '.join(t.aliases)})" if t.aliases else ""
            lines.append(f"  {t.term:16s} {t.kind:10s} F {t.F:8.3f} p {t.p:.3g} p_bonf {t.p_bonferroni:.3g} "
                         f"dBIC {t.delta_bic:7.2f} LOF p {t.lack_of_fit_p:.3g}{al}")
        if len(est) > top:
            lines.append(f"  ... {len(est) - top} more estimable candidates")
        ne = [t.term for t in tests if not t.estimable]
        if ne:
            lines.append("  not estimable from these runs: " + ", ".join(ne))
    return "\n".join(lines)
