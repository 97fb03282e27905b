"""Candidates the data cannot split once the reducer model is nonlinear: the swap test.

The sparse estimator splits the inclusion probability between candidates whose columns are alike, and reports
them as a group (:mod:`rvcalib.sparse`). Through the reducer model that split does not survive the loop: once one
of two alike candidates is in the model (the pins ``p`` and ``p + Zp / 2`` of a two-crank reducer whose cranks are
half a turn apart give the same TE to rounding), the next linearisation takes its column where it is and the
other's where it is not, and the two no longer look alike. Which one entered first is then a coin toss the result
would hide.

So at the end every named single-parameter effect ``f`` is confronted with the candidates ``g`` the data may not
split from it, screened two ways (the screen only limits the cost): columns at the first linearisation (where
neither was in the model) on nearly the same line (|correlation| at least :data:`SCREEN`), and candidates that, at
the last linearisation, take ``f``'s TE with the other chosen parameters refitted and leave less than
:data:`DELTA_CHI2` of it (a partial alias: a look-alike on the other crank or disc that, with the others moved,
gives the same fit). The model is solved with ``f``'s effect moved to ``g`` (the least-squares move of ``f``'s
linearised TE onto ``g`` and the other chosen parameters, on the columns of the screen that admitted ``g``, its sign
included: a crank-indexed error and the same error on the crank half a turn away are first-order look-alikes with
the opposite sign) and the reading coefficients refitted, and where the fit is worse by less than the 95 % quantile
of chi-square with one degree of freedom (``Delta chi^2 < 3.84``, a likelihood ratio the data cannot tell from
chance), ``g`` is a twin and ``f`` is reported as a group with it instead of a name.

Look-alikes can also come as a set: two crank-indexed effects (a pin and a cam of a two-crank reducer) each moved
alone to its look-alike change how the cranks share the load and fit worse, while both moved together give the
same TE (the half-turn image of the pair). So the chosen effects that have look-alikes but no twin alone are moved
together, each to its best single swap (on the first linearisation's columns, where none of them was in the
model), and where that fits as well by the same test, each is reported as a group with its look-alike.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from rvcalib.reducer_model import ModelEvaluationError

#: Columns at least this correlated at the first linearisation are tried as swaps (a screen for the cost).
SCREEN = 0.99
#: Most swaps tried per named effect (the most correlated first).
MOST = 6
#: A swap whose chi-square is worse by less than this is not told apart: chi2(1) at 95 %.
DELTA_CHI2 = float(stats.chi2.ppf(0.95, 1))


def swap_twins(pb, X0: np.ndarray, theta: np.ndarray, sigma: float, active_s: np.ndarray,
               active_r: np.ndarray, tau: np.ndarray | None = None,
               X_last: np.ndarray | None = None) -> dict[int, list[tuple[int, float, float]]]:
    """The twins of each chosen single-parameter feature.

    Parameters
    ----------
    pb : rvcalib.loop.Problem
    X0 : (n, P) the features' scaled, projected columns at the first linearisation
    theta : (p,) the final solved parameters
    sigma : noise standard deviation, arcsec
    active_s, active_r : the chosen solved parameters and reading coefficients
    tau : (p,) the solved parameters' prior scales (the columns' scaling); ones when None
    X_last : (n, P) or None, the columns at the last linearisation (the partial-alias screen); none when None

    Returns
    -------
    dict
        Feature index -> [(twin feature index, Delta chi^2, its size), ...] for the chosen features that have
        twins.
    """
    m, n = pb.model, pb.model.n_params
    tau = np.ones(n) if tau is None else tau
    Ra = pb.proj(pb.R[:, active_r])

    def chi2(th: np.ndarray) -> float:
        try:
            r = pb.proj(pb.y - m.te(th))
        except ModelEvaluationError:
            return float("inf")
        if active_r.size:
            r = r - Ra @ np.linalg.lstsq(Ra, r, rcond=None)[0]
        return float(r @ r) / sigma ** 2

    single = [f for f in range(len(pb.feature_cands))
              if pb.starts[f + 1] - pb.starts[f] == 1 and pb.starts[f] < n and f not in pb.fixed]
    on = set(active_s.tolist())
    chosen = [f for f in single if pb.starts[f] in on]
    if not chosen:
        return {}
    C = X0 / np.maximum(np.linalg.norm(X0, axis=0), 1e-300)
    base = chi2(theta)
    out: dict[int, list[tuple[int, float, float]]] = {}
    alone: dict[int, int] = {}                      # chosen feature -> its best single swap, where none fits
    for f in chosen:
        j = pb.starts[f]
        others = [g for g in single if g != f and pb.starts[g] not in on]
        cols = np.array([pb.starts[g] for g in others], dtype=int)
        r = np.abs(C[:, cols].T @ C[:, j])
        near = {others[k]: X0 for k in np.argsort(-r)[:MOST] if r[k] >= SCREEN}
        if X_last is not None:
            d = _moved_chi2(X_last, j, theta[j] / tau[j], active_s, n + active_r, cols) / sigma ** 2
            for k in np.argsort(d)[:MOST]:
                if d[k] < DELTA_CHI2:
                    near.setdefault(others[k], X_last)
        found, tried = [], []
        for g, X in list(near.items())[:2 * MOST]:
            k = pb.starts[g]
            th = _moved(X, theta, [j], [k], active_s, n + active_r, tau, m._lower, m._upper)
            dchi = chi2(th) - base
            tried.append((dchi, g))
            if dchi < DELTA_CHI2:
                found.append((g, float(dchi), float(th[k])))
        if found:
            out[f] = sorted(found, key=lambda t: t[1])
        elif tried:
            alone[f] = min(tried)[1]
    if len(alone) > 1 and len(set(alone.values())) == len(alone):   # several chosen effects' look-alikes together
        fs = list(alone)
        th = _moved(X0, theta, [pb.starts[f] for f in fs], [pb.starts[alone[f]] for f in fs], active_s,
                    n + active_r, tau, m._lower, m._upper)
        dchi = chi2(th) - base
        if dchi < DELTA_CHI2:
            for f in fs:
                out[f] = [(alone[f], float(dchi), float(th[pb.starts[alone[f]]]))]
    m.te(theta)                                     # the model's states are the estimate's again
    return out


def _moved_chi2(X: np.ndarray, j: int, c: float, active_s: np.ndarray, reading_cols: np.ndarray,
                cols: np.ndarray) -> np.ndarray:
    """For each candidate column: what is left of column ``j``'s TE (coefficient ``c``, scaled units) after the
    least-squares move onto the candidate, the other chosen solved columns and the chosen reading columns."""
    keep = np.concatenate([active_s[active_s != j], reading_cols]).astype(int)
    Q = np.linalg.qr(X[:, keep])[0] if keep.size else np.zeros((X.shape[0], 0))
    t = X[:, j] * c
    t = t - Q @ (Q.T @ t)
    G = X[:, cols]
    G = G - Q @ (Q.T @ G)
    gg = np.maximum(np.sum(G ** 2, axis=0), 1e-300)
    return float(t @ t) - (G.T @ t) ** 2 / gg


def _moved(X: np.ndarray, theta: np.ndarray, js: list, ks: list, active_s: np.ndarray, reading_cols: np.ndarray,
           tau: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The state with the effects of parameters ``js`` moved to ``ks`` (pairwise, together): the least-squares
    move of their linearised TE onto ``ks`` and the other chosen solved parameters (the reading columns take their
    part; the chi-square refits them), within the parameters' bounds."""
    js, ks = np.asarray(js, dtype=int), np.asarray(ks, dtype=int)
    B = np.setdiff1d(active_s, js).astype(int)
    D = X[:, np.concatenate([ks, B, reading_cols]).astype(int)]
    coef = np.linalg.lstsq(D, X[:, js] @ (theta[js] / tau[js]), rcond=None)[0]
    th = theta.copy()
    th[ks] = coef[:ks.size] * tau[ks]
    th[B] = theta[B] + coef[ks.size:ks.size + B.size] * tau[B]
    th[js] = 0.0
    return np.clip(th, lower, upper)
