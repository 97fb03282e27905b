"""The closed loop on response surfaces: lack of fit -> higher-order or physical term -> refit.

:func:`rsm_closed_loop` fits a response surface with :mod:`rsm` (the paper's full quadratic by
default), checks it for lack of fit (the ANOVA's pure-error test on replicated runs and, when
``new_data`` is given, the prediction errors at new runs or measured responses against the
fit's residual variance), and then tests every candidate term that the runs can estimate:

* higher-order polynomial terms: ``Xi^2:Xj``, ``Xi^2:Xj^2``, ``Xi:Xj:Xk`` (in a Box-Behnken design
  ``Xi^3`` is aliased with ``Xi`` and three-factor products vanish: such terms are reported as not
  estimable);
* physical terms (for the paper's factors EA..ED): the magnitude of the radial pin clearance
  ``|EB/2 - EC|`` (um; the pin-circle radius error minus the pin-radius error: a V-shaped,
  one-sided contact effect that no polynomial of degree 2 has) and its products with ``EA``.

Each candidate is added alone to the current model and judged by its partial F test (Bonferroni
over the estimable candidates), the BIC and the lack-of-fit test after adding it. The best
supported term is added and the loop repeats (``max_add`` terms at most). Residuals and lack of
fit are reported before and after.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

import rsm
from rsm.coding import Levels


@dataclass
class CandidateTerm:
    """A candidate term: name, kind (``polynomial``/``physical``), meaning and its column."""

    name: str
    kind: str
    meaning: str
    column: Callable[[pd.DataFrame], np.ndarray]


@dataclass
class TermTest:
    """The test of one candidate term against the current model."""

    term: str
    kind: str
    meaning: str
    estimable: bool
    rss: float = float("nan")
    F: float = float("nan")
    p: float = float("nan")
    p_bonferroni: float = float("nan")
    delta_bic: float = float("nan")
    lack_of_fit_F: float = float("nan")
    lack_of_fit_p: float = float("nan")
    aliases: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return dict(self.__dict__)


@dataclass
class FitSummary:
    """Residual and lack-of-fit summary of one model."""

    terms: list[str]
    rss: float
    df_resid: int
    rmse: float
    r2: float
    r2_adj: float
    r2_pred: float
    lack_of_fit_ss: float
    lack_of_fit_df: int
    lack_of_fit_F: float
    lack_of_fit_p: float
    pure_error_ss: float
    pure_error_df: int
    bic: float
    residuals: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))

    def to_dict(self) -> dict:
        """JSON-ready form (residuals as a list)."""
        d = dict(self.__dict__)
        d["residuals"] = [float(v) for v in self.residuals]
        return d


@dataclass
class RSMLoopResult:
    """Result of :func:`rsm_closed_loop`.

    Attributes
    ----------
    before, after : FitSummary
    added : list of str
        Terms added, in order.
    iterations : list of list of TermTest
        The candidate tests of each iteration.
    new_runs : dict or None
        The check against new runs: ``n``, ``F``, ``p``, ``rmse_pred`` (None without new data).
    verdict : str
    """

    before: FitSummary
    after: FitSummary
    added: list[str]
    iterations: list[list[TermTest]]
    new_runs: dict | None
    verdict: str

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {"before": self.before.to_dict(), "after": self.after.to_dict(), "added": self.added,
                "iterations": [[t.to_dict() for t in it] for it in self.iterations], "new_runs": self.new_runs,
                "verdict": self.verdict}


def _pure_error(x: np.ndarray, y: np.ndarray) -> tuple[float, int]:
    keys = np.round(x, 9) + 0.0
    _, inv, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    means = np.bincount(inv, weights=y) / counts
    dev = y - means[inv]
    return float(dev @ dev), int(np.sum(counts - 1))


def _summary(X: np.ndarray, y: np.ndarray, xf: np.ndarray, names: list[str]) -> FitSummary:
    n, p = X.shape
    Q, R = np.linalg.qr(X)
    b = np.linalg.solve(R, Q.T @ y)
    r = y - X @ b
    rss = float(r @ r)
    df = n - p
    sst = float(np.sum((y - y.mean()) ** 2))
    h = np.sum(Q ** 2, axis=1)
    press = float(np.sum((r / np.where(h < 1 - 1e-12, 1 - h, np.nan)) ** 2)) if np.all(h < 1 - 1e-12) else float("nan")
    pe_ss, pe_df = _pure_error(xf, y)
    lof_df = df - pe_df
    lof_ss = max(rss - pe_ss, 0.0)
    if lof_df > 0 and pe_df > 0 and pe_ss > 0:
        Fl = (lof_ss / lof_df) / (pe_ss / pe_df)
        pl = float(stats.f.sf(Fl, lof_df, pe_df))
    else:
        Fl, pl = float("nan"), float("nan")
    return FitSummary(names, rss, df, math.sqrt(rss / n), 1 - rss / sst,
                      1 - (rss / df) / (sst / (n - 1)) if df > 0 else float("nan"),
                      1 - press / sst if math.isfinite(press) else float("nan"),
                      lof_ss, lof_df, float(Fl), pl, pe_ss, pe_df, n * math.log(max(rss, 1e-300) / n) + p * math.log(n), r)


def _actual(df: pd.DataFrame, factors: Sequence[str], levels: Levels | None, units: str) -> pd.DataFrame:
    """The factor columns in actual units (coded data decoded with the levels)."""
    x = df[list(factors)].to_numpy(dtype=float)
    if units == "coded" and levels is not None:
        x = levels.coded_to_actual(x, list(factors))
    return pd.DataFrame(x, columns=list(factors))


def default_candidates(factors: Sequence[str], levels: Levels | None, units: str) -> list[CandidateTerm]:
    """Higher-order polynomial terms of every factor, and the physical terms of the paper's factors."""
    f = list(factors)
    out: list[CandidateTerm] = []
    for i, j in itertools.permutations(range(len(f)), 2):
        out.append(CandidateTerm(f"{f[i]}^2:{f[j]}", "polynomial", "third-order (curvature of one factor changing "
                                 "with another)", lambda d, i=i, j=j: d[f[i]].to_numpy(float) ** 2 * d[f[j]].to_numpy(float)))
    for i, j in itertools.combinations(range(len(f)), 2):
        out.append(CandidateTerm(f"{f[i]}^2:{f[j]}^2", "polynomial", "fourth-order curvature interaction",
                                 lambda d, i=i, j=j: d[f[i]].to_numpy(float) ** 2 * d[f[j]].to_numpy(float) ** 2))
    for c in itertools.combinations(range(len(f)), 3):
        out.append(CandidateTerm(":".join(f[k] for k in c), "polynomial", "three-factor interaction",
                                 lambda d, c=c: np.prod(np.column_stack([d[f[k]].to_numpy(float) for k in c]), axis=1)))
    for i in range(len(f)):
        out.append(CandidateTerm(f"{f[i]}^3", "polynomial", "cubic", lambda d, i=i: d[f[i]].to_numpy(float) ** 3))
    if {"EB", "EC"} <= set(f) and levels is not None:
        def clearance(d: pd.DataFrame) -> np.ndarray:
            a = _actual(d, f, levels, units)
            return np.abs(a["EB"].to_numpy() / 2.0 - a["EC"].to_numpy())
        out.append(CandidateTerm("|EB/2-EC|", "physical", "magnitude of the radial pin clearance (pin-circle radius "
                                 "error minus pin-radius error, um): one-sided contact makes the TE V-shaped in it",
                                 clearance))
        if "EA" in f:
            out.append(CandidateTerm("EA:|EB/2-EC|", "physical", "pin-pitch error acting through the radial clearance",
                                     lambda d: d["EA"].to_numpy(float) * clearance(d)))
            out.append(CandidateTerm("EA^2:|EB/2-EC|", "physical", "pitch-error curvature changed by the clearance",
                                     lambda d: d["EA"].to_numpy(float) ** 2 * clearance(d)))
    return out


def rsm_closed_loop(data: pd.DataFrame, factors: Sequence[str], response: str, levels=None,
                    terms: str | Sequence[str] = "quadratic", units: str = "coded",
                    new_data: pd.DataFrame | None = None, alpha: float = 0.05, max_add: int = 2,
                    candidates: list[CandidateTerm] | None = None) -> RSMLoopResult:
    """Test the terms the data can estimate beyond an RSM fit and add the one they support.

    Parameters
    ----------
    data : DataFrame
        Runs with the factor and response columns.
    factors : sequence of str
    response : str
    levels : Levels, DataFrame, path or None
        Levels table (needed for the physical terms and for actual-unit data).
    terms : str or sequence of str
        Starting model (``rsm`` term syntax; default the full quadratic).
    units : {'coded', 'actual'}
        Units of the factor columns.
    new_data : DataFrame or None
        New runs or measured responses; their prediction errors are tested against the fit, and the
        candidate terms are then judged on all runs together.
    alpha : float
        Family-wise level (Bonferroni over the estimable candidates of an iteration).
    max_add : int
        Largest number of terms added.
    candidates : list of CandidateTerm or None
        Default :func:`default_candidates`.

    Returns
    -------
    RSMLoopResult
    """
    lv = Levels.coerce(levels)
    model = rsm.ResponseSurfaceModel(data, factors, response, terms, lv, units)
    base = model.fit(warn=False)
    new_check = None
    all_data = data
    if new_data is not None and len(new_data):
        for c in list(factors) + [response]:
            if c not in new_data.columns:
                raise ValueError(f"new_data: column '{c}' is missing")
        pred = base.predict(new_data[list(factors)], units=units)
        e = new_data[response].to_numpy(float) - pred["mean"].to_numpy(float)
        # prediction variance of each new run in units of sigma^2: 1 + x'(X'X)^-1 x
        h = pred["mean_se"].to_numpy(float) ** 2 / base.mse_resid
        stat = float(np.sum(e ** 2 / (1 + h)) / len(e) / base.mse_resid)
        p_new = float(stats.f.sf(stat, len(e), base.df_resid))
        new_check = {"n": int(len(e)), "F": stat, "p": p_new, "rmse_pred": float(np.sqrt(np.mean(e ** 2))),
                     "lack_of_fit": bool(p_new < alpha)}
        all_data = pd.concat([data, new_data[list(factors) + [response]]], ignore_index=True)
    xf = all_data[list(factors)].to_numpy(float)
    y = all_data[response].to_numpy(float)
    X = rsm.terms.model_matrix(xf if units == "coded" else lv.actual_to_coded(xf, list(factors)), model.monomials)
    names = list(model.term_names)
    before = _summary(X, y, xf, list(names))
    cands = candidates if candidates is not None else default_candidates(factors, lv, units)
    iterations: list[list[TermTest]] = []
    added: list[str] = []
    cur = before
    for _ in range(max_add):
        tests: list[TermTest] = []
        rank0 = np.linalg.matrix_rank(X / np.maximum(np.linalg.norm(X, axis=0), 1e-300))
        for c in cands:
            if c.name in added:
                continue
            col = c.column(all_data)
            X1 = np.column_stack([X, col])
            nrm = np.maximum(np.linalg.norm(X1, axis=0), 1e-300)
            if np.linalg.norm(col) < 1e-12 or np.linalg.matrix_rank(X1 / nrm) == rank0 or X1.shape[1] >= len(y) - 1:
                tests.append(TermTest(c.name, c.kind, c.meaning, False))
                continue
            s1 = _summary(X1, y, xf, names + [c.name])
            F = (cur.rss - s1.rss) / (s1.rss / s1.df_resid) if s1.rss > 0 else float("inf")
            p = float(stats.f.sf(F, 1, s1.df_resid))
            tests.append(TermTest(c.name, c.kind, c.meaning, True, s1.rss, float(F), p, float("nan"),
                                  s1.bic - cur.bic, s1.lack_of_fit_F, s1.lack_of_fit_p))
        est = [t for t in tests if t.estimable]
        for t in est:
            t.p_bonferroni = min(1.0, t.p * len(est))
        # candidates that the runs cannot tell apart (collinear once the current model is projected out)
        Q, _ = np.linalg.qr(X)
        proj = {}
        for t in est:
            v = next(c for c in cands if c.name == t.term).column(all_data)
            v = v - Q @ (Q.T @ v)
            proj[t.term] = v / np.linalg.norm(v)
        for t in est:
            t.aliases = [u.term for u in est if u.term != t.term and abs(float(proj[t.term] @ proj[u.term])) > 0.9999]
        iterations.append(tests)
        if not est:
            break
        # the smallest p; among terms the runs cannot tell apart (aliases) a physical term is preferred
        best = min(est, key=lambda t: (round(t.p, 12) if t.p > 0 else 0.0, t.kind != "physical"))
        phys_alias = [u for u in est if u.term in best.aliases and u.kind == "physical"]
        if best.kind != "physical" and phys_alias:
            best = phys_alias[0]
        if not (best.p_bonferroni < alpha and best.delta_bic < 0):
            break
        col = next(c for c in cands if c.name == best.term).column(all_data)
        X = np.column_stack([X, col])
        names.append(best.term)
        added.append(best.term)
        cur = _summary(X, y, xf, list(names))
    after = cur
    lof = (f"lack of fit F {before.lack_of_fit_F:.4g} (p {before.lack_of_fit_p:.3g}, {before.lack_of_fit_df} and "
           f"{before.pure_error_df} df)")
    if added:
        verdict = (f"The {terms if isinstance(terms, str) else 'given'} model shows {lof}; the data support adding "
                   f"{', '.join(added)}: residual SS {before.rss:.4g} -> {after.rss:.4g}, RMSE {before.rmse:.4g} -> "
                   f"{after.rmse:.4g}, lack of fit F {after.lack_of_fit_F:.4g} (p {after.lack_of_fit_p:.3g}).")
    else:
        verdict = (f"The {terms if isinstance(terms, str) else 'given'} model shows {lof}; no estimable higher-order "
                   "or physical term is supported (Bonferroni-adjusted F test and BIC).")
    if new_check is not None:
        verdict += (f" Against {new_check['n']} new runs: F {new_check['F']:.4g} (p {new_check['p']:.3g}), prediction "
                    f"RMSE {new_check['rmse_pred']:.4g}.")
    return RSMLoopResult(before, after, added, iterations, new_check, verdict)


def table6_loop(data_dir: str | Path | None = None, **kwargs) -> RSMLoopResult:
    """The loop on the paper's Table 6 (Box-Behnken runs, response in arcmin) with Table 5's levels."""
    from rvpaper import DATA_DIR

    d = Path(data_dir) if data_dir is not None else DATA_DIR
    data = pd.read_csv(d / "paper_table6_bbd_runs.csv")
    return rsm_closed_loop(data, ["EA", "EB", "EC", "ED"], "te_arcmin", levels=d / "paper_table5_levels.csv",
                           **kwargs)


def format_result(res: RSMLoopResult, top: int = 8) -> str:
    """Plain-text report of a loop result."""
    L = [res.verdict, ""]
    for tag, s in (("before", res.before), ("after", res.after)):
        L.append(f"{tag}: terms {len(s.terms)}, residual SS {s.rss:.5g} ({s.df_resid} df), RMSE {s.rmse:.4g}, R2 "
                 f"{s.r2:.4f}, R2adj {s.r2_adj:.4f}, R2pred {s.r2_pred:.4f}, lack of fit SS {s.lack_of_fit_ss:.4g} "
                 f"({s.lack_of_fit_df} df) F {s.lack_of_fit_F:.4g} p {s.lack_of_fit_p:.3g}, pure error SS "
                 f"{s.pure_error_ss:.4g} ({s.pure_error_df} df)")
    for i, tests in enumerate(res.iterations, 1):
        L.append("")
        L.append(f"iteration {i}: candidate terms (partial F, Bonferroni p, dBIC, lack-of-fit p after)")
        est = sorted([t for t in tests if t.estimable], key=lambda t: t.p)
        for t in est[:top]:
            al = f"  (same column as {', '.join(t.aliases)})" if t.aliases else ""
            L.append(f"  {t.term:16s} {t.kind:10s} F {t.F:8.3f} p {t.p:.3g} p_bonf {t.p_bonferroni:.3g} "
                     f"dBIC {t.delta_bic:7.2f} LOF p {t.lack_of_fit_p:.3g}{al}")
        ne = [t.term for t in tests if not t.estimable]
        if ne:
            L.append("  not estimable from these runs: " + ", ".join(ne))
    return "\n".join(L)


if __name__ == "__main__":  # pragma: no cover
    import sys

    from rvpaper import DATA_DIR

    print(format_result(table6_loop(sys.argv[1] if len(sys.argv) > 1 else DATA_DIR)))
