"""Stack-up statistics of full-solver Monte Carlo draws, as a tolerance-analysis tool reports them.

* :func:`capability` -- n, mean, sigma, min, max, Cp, Cpk against LSL/USL, the fraction out of spec
  with its exact (Clopper-Pearson) 95 % interval, and the yield.
* :func:`sobol_from_design` -- first-order (Saltelli 2010) and total (Jansen 1999) variance-based
  indices of groups of inputs from a designed sample (matrices A, B and A with group g from B), with
  bootstrap intervals over the rows.
* :func:`reweighted_yield` / :func:`allocation` -- the yield if one tolerance were tightened, from the
  existing draws re-weighted by the likelihood ratio of the tightened over the drawn distribution
  (no new solves); the effective sample size of the weights says how far that can be trusted.

Formulas: Cp = (USL - LSL) / (6 sigma) (both limits only); Cpk = min((USL - mean) / (3 sigma),
(mean - LSL) / (3 sigma)) over the limits given (one-sided: Cpu or Cpl); sigma is the sample standard
deviation (ddof 1). Out of spec: value < LSL or value > USL; a failed solve counts as out of spec
and is reported separately.
"""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pandas as pd
from scipy import stats

from rvstudy.montecarlo import Tolerance

#: Confidence level of every interval.
CONFIDENCE = 0.95
#: Tightening factors (new spread / drawn spread) tried by :func:`allocation`.
TIGHTEN = (0.9, 0.8, 0.7, 0.6, 0.5)
#: Effective sample size below which a re-weighted yield is marked unreliable.
MIN_ESS = 100.0


def clopper_pearson(k: int, n: int, conf: float = CONFIDENCE) -> tuple[float, float]:
    """Exact binomial interval of a fraction k/n (Clopper-Pearson)."""
    if n <= 0:
        return float("nan"), float("nan")
    a = 1.0 - conf
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def out_of_spec(y: np.ndarray, lsl: float | None, usl: float | None) -> np.ndarray:
    """Boolean mask of values outside [LSL, USL] (a NaN, i.e. a failed solve, is out of spec)."""
    y = np.asarray(y, float)
    bad = ~np.isfinite(y)
    with np.errstate(invalid="ignore"):
        if lsl is not None:
            bad |= y < lsl
        if usl is not None:
            bad |= y > usl
    return bad


def capability(y: np.ndarray, lsl: float | None, usl: float | None) -> dict[str, float | int | list | None]:
    """Stack-up statistics of one response.

    Parameters
    ----------
    y : (n,) array
        Response of every draw (NaN = failed solve).
    lsl, usl : float or None
        Specification limits (None: no such limit).

    Returns
    -------
    dict
        ``n_solver_draws, n_failed, mean, std, min, max, cp, cpk, lsl, usl, out_of_spec_fraction,
        out_of_spec_ci ([lo, hi], Clopper-Pearson 95 %), yield, yield_ci``.
    """
    y = np.asarray(y, float)
    ok = y[np.isfinite(y)]
    n = int(y.size)
    mean = float(ok.mean()) if ok.size else float("nan")
    sd = float(ok.std(ddof=1)) if ok.size > 1 else float("nan")
    cp = (usl - lsl) / (6 * sd) if lsl is not None and usl is not None and sd > 0 else None
    sides = []
    if usl is not None and sd > 0:
        sides.append((usl - mean) / (3 * sd))
    if lsl is not None and sd > 0:
        sides.append((mean - lsl) / (3 * sd))
    cpk = min(sides) if sides else None
    k = int(out_of_spec(y, lsl, usl).sum()) if (lsl is not None or usl is not None) else 0
    lo, hi = clopper_pearson(k, n)
    return {"n_solver_draws": n, "n_failed": int(n - ok.size), "mean": mean, "std": sd,
            "min": float(ok.min()) if ok.size else float("nan"), "max": float(ok.max()) if ok.size else float("nan"),
            "lsl": lsl, "usl": usl, "cp": cp, "cpk": cpk,
            "out_of_spec_fraction": k / n if n else float("nan"), "out_of_spec_ci": [lo, hi],
            "yield": 1 - k / n if n else float("nan"), "yield_ci": [1 - hi, 1 - lo]}


def sobol_from_design(yA: np.ndarray, yB: np.ndarray, yAB: Mapping[str, np.ndarray], var: float | None = None,
                      n_boot: int = 500, seed: int = 0) -> pd.DataFrame:
    """Group first-order and total indices from a designed sample.

    Parameters
    ----------
    yA, yB : (n,) arrays
        Response at the rows of two independent draw matrices A and B.
    yAB : mapping
        ``{group: (n,) response at A with the group's columns taken from B}``.
    var : float or None
        Variance of the response (default: of A and B together); a larger independent sample gives
        a better denominator.
    n_boot : int
        Bootstrap resamples of the rows for the intervals.
    seed : int
        Seed of the bootstrap.

    Returns
    -------
    DataFrame
        ``tolerance, first_order, total, first_order_lo, first_order_hi, total_lo, total_hi, n``;
        S1 = mean((yB - f0) (yAB - yA)) / V (Saltelli 2010, with yB centred on the sample mean f0 of yA and
        yB: since E[yAB - yA] = 0 the centring leaves the expectation unchanged and removes the variance
        that the response's mean adds to the estimate, e.g. of a rigidity of mean 417 and sigma 175),
        ST = mean((yA - yAB)^2) / (2 V) (Jansen 1999). Rows with a failed solve are left out.
    """
    yA, yB = np.asarray(yA, float), np.asarray(yB, float)
    both = np.r_[yA[np.isfinite(yA)], yB[np.isfinite(yB)]]
    V = float(np.var(both)) if var is None else float(var)
    f0 = float(np.mean(both)) if both.size else 0.0
    rng = np.random.default_rng(seed)
    rows = []
    for g, yab in yAB.items():
        yab = np.asarray(yab, float)
        keep = np.isfinite(yA) & np.isfinite(yB) & np.isfinite(yab)
        a, b, ab = yA[keep], yB[keep] - f0, yab[keep]
        m = a.size

        def est(i: np.ndarray) -> tuple[float, float]:
            return (float(np.mean(b[i] * (ab[i] - a[i])) / V), float(0.5 * np.mean((a[i] - ab[i]) ** 2) / V))

        if m == 0 or not V > 0:
            rows.append({"tolerance": g, "first_order": float("nan"), "total": float("nan"), "n": m})
            continue
        s1, st = est(np.arange(m))
        boot = np.array([est(rng.integers(0, m, m)) for _ in range(n_boot)])
        q = [(1 - CONFIDENCE) / 2 * 100, (1 + CONFIDENCE) / 2 * 100]
        (l1, h1), (lt, ht) = np.percentile(boot[:, 0], q), np.percentile(boot[:, 1], q)
        rows.append({"tolerance": g, "first_order": s1, "total": st, "first_order_lo": float(l1),
                     "first_order_hi": float(h1), "total_lo": float(lt), "total_hi": float(ht), "n": m})
    df = pd.DataFrame(rows)
    return df.sort_values("total", ascending=False, na_position="last").reset_index(drop=True) if len(df) else df


def likelihood_weights(X: pd.DataFrame, columns: list[str], tol: Tolerance, factor: float) -> np.ndarray:
    """Weights that turn draws of ``tol`` into draws of ``tol.tightened(factor)`` (product over the columns)."""
    new = tol.tightened(factor)
    logw = np.zeros(len(X))
    for c in columns:
        x = X[c].to_numpy(float)
        p0, p1 = tol.pdf(x), new.pdf(x)
        with np.errstate(divide="ignore"):
            logw += np.where(p1 > 0, np.log(np.maximum(p1, 1e-300)) - np.log(np.maximum(p0, 1e-300)), -np.inf)
    if not np.isfinite(logw).any():
        return np.zeros(len(X))
    return np.exp(logw - np.max(logw[np.isfinite(logw)]))


def reweighted_yield(passed: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """Weighted yield and the effective sample size (sum w)^2 / sum w^2."""
    s = float(w.sum())
    if not s > 0:
        return float("nan"), 0.0
    return float(np.sum(w * passed) / s), s * s / float(np.sum(w * w))


def allocation(X: pd.DataFrame, groups: Mapping[str, list[str]], tols: Mapping[str, Tolerance],
               y: np.ndarray, lsl: float | None, usl: float | None,
               factors: tuple[float, ...] = TIGHTEN) -> pd.DataFrame:
    """Yield if one tolerance is tightened by each factor, from the existing draws re-weighted.

    Returns
    -------
    DataFrame
        ``tolerance, factor, std_now, std_new, yield, gain, ess, reliable`` (one row per tolerance and
        factor; ``gain`` = yield - yield of the drawn tolerances; ``reliable`` = ess >= MIN_ESS).
    """
    passed = (~out_of_spec(y, lsl, usl)).astype(float)
    y0 = float(passed.mean()) if passed.size else float("nan")
    rows = []
    for g, cols in groups.items():
        t = tols[g]
        if t.dist in ("fixed", "none") or not t.std > 0:
            continue
        for f in factors:
            yw, ess = reweighted_yield(passed, likelihood_weights(X, cols, t, f))
            rows.append({"tolerance": g, "factor": f, "std_now": t.std, "std_new": t.tightened(f).std,
                         "yield": yw, "gain": yw - y0, "ess": ess, "reliable": bool(ess >= MIN_ESS)})
    return pd.DataFrame(rows)


def recommend(alloc: pd.DataFrame, target: float | None = None) -> dict[str, object] | None:
    """The tolerance whose tightening gains the most yield (reliable rows only): the mildest factor that
    reaches ``target`` if one does, else the best gain found. None if nothing gains."""
    if alloc is None or not len(alloc):
        return None
    ok = alloc[alloc["reliable"] & (alloc["gain"] > 0)]
    if not len(ok):
        return None
    if target is not None:
        hit = ok[ok["yield"] >= target]
        if len(hit):
            r = hit.sort_values(["factor", "gain"], ascending=[False, False]).iloc[0]
            return {**r.to_dict(), "reaches_target": True, "target": target}
    r = ok.sort_values(["gain", "factor"], ascending=[False, False]).iloc[0]
    return {**r.to_dict(), "reaches_target": False, "target": target}


def ci_text(lo: float, hi: float) -> str:
    """``[a, b]`` in percent."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "/"
    return f"[{100 * lo:.3g}, {100 * hi:.3g}] %"
