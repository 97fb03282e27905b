"""Candidates the data cannot split once the reducer model is nonlinear: the swap test.

The sparse estimator splits the inclusion probability between candidates whose columns are alike, and reports
them as a group (:mod:`rvcalib.sparse`). Through the reducer model that split does not survive the loop: once one
of two alike candidates is in the model (the pins ``p`` and ``p + Zp / 2`` of a two-crank reducer whose cranks are
half a turn apart give the same TE to rounding), the next linearisation takes its column where it is and the
other's where it is not, and the two no longer look alike. Which one entered first is then a coin toss the result
would hide.

So at the end every named effect ``f`` (one parameter, or the two components of an eccentricity) is confronted
with the candidates ``g`` of as many parameters the data may not split from it, screened two ways (the screen only
limits the cost): candidates whose columns at the first linearisation (where neither was in the model) hold nearly
all of ``f``'s TE (for one column, |correlation| at least :data:`SCREEN`), and candidates that, at the last
linearisation, take ``f``'s TE with the other chosen parameters refitted and leave less than :data:`DELTA_CHI2` of
it (a partial alias: a look-alike on the other crank or disc that, with the others moved, gives the same fit). The
model is solved with ``f``'s effect moved to ``g`` (the least-squares move of ``f``'s linearised TE onto ``g`` and
the other chosen parameters, on the columns of the screen that admitted ``g``, its sign or direction included: a
crank-indexed error and the same error on the crank half a turn away are first-order look-alikes with the
opposite sign) and the reading coefficients refitted, and where the fit is worse by less than the 95 % quantile
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
               X_last: np.ndarray | None = None) -> dict[int, list[tuple[int, float, tuple]]]:
    """The twins of each chosen feature (one parameter, or the two components of an eccentricity).

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
        Feature index -> [(twin feature index, Delta chi^2, its parameters after the swap), ...] for the chosen
        features that have twins.
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

    feats = {f: list(range(pb.starts[f], pb.starts[f + 1])) for f in range(len(pb.feature_cands))
             if pb.starts[f] < n and f not in pb.fixed}
    on = set(active_s.tolist())
    chosen = [f for f, js in feats.items() if on.intersection(js)]
    if not chosen:
        return {}
    base = chi2(theta)
    out: dict[int, list[tuple[int, float, tuple]]] = {}
    alone: dict[int, int] = {}                      # chosen feature -> its best single swap, where none fits
    for f in chosen:
        js = feats[f]
        others = [g for g, ks in feats.items() if g != f and len(ks) == len(js) and not on.intersection(ks)]
        blocks = [feats[g] for g in others]
        c = theta[js] / tau[js]
        r = _captured(X0, X0[:, js] @ c, blocks)
        near = {others[k]: X0 for k in np.argsort(-r)[:MOST] if r[k] >= SCREEN}
        if X_last is not None:
            d = _moved_chi2(X_last, js, c, active_s, n + active_r, blocks) / sigma ** 2
            for k in np.argsort(d)[:MOST]:
                if d[k] < DELTA_CHI2:
                    near.setdefault(others[k], X_last)
        found, tried = [], []
        for g, X in list(near.items())[:2 * MOST]:
            th = _moved(X, theta, js, feats[g], active_s, n + active_r, tau, m._lower, m._upper)
            dchi = chi2(th) - base
            tried.append((dchi, g))
            if dchi < DELTA_CHI2:
                found.append((g, float(dchi), tuple(float(v) for v in th[feats[g]])))
        if found:
            out[f] = sorted(found, key=lambda t: t[1])
        elif tried:
            alone[f] = min(tried)[1]
    if len(alone) > 1 and len(set(alone.values())) == len(alone):   # several chosen effects' look-alikes together
        fs = list(alone)
        th = _moved(X0, theta, [j for f in fs for j in feats[f]], [k for f in fs for k in feats[alone[f]]],
                    active_s, n + active_r, tau, m._lower, m._upper)
        dchi = chi2(th) - base
        if dchi < DELTA_CHI2:
            for f in fs:
                out[f] = [(alone[f], float(dchi), tuple(float(v) for v in th[feats[alone[f]]]))]
    m.te(theta)                                     # the model's states are the estimate's again
    return out


def _held(G: np.ndarray, t: np.ndarray) -> float:
    """The squared norm of ``t``'s projection onto the span of the columns ``G``."""
    return max(float(t @ (G @ np.linalg.lstsq(G, t, rcond=None)[0])), 0.0)


def _captured(X: np.ndarray, t: np.ndarray, blocks: list) -> np.ndarray:
    """For each block of columns of ``X``: the share of ``t``'s norm its span holds (for one column, the
    |correlation|)."""
    tt = max(float(t @ t), 1e-300)
    return np.array([np.sqrt(_held(X[:, ks], t) / tt) for ks in blocks])


def _moved_chi2(X: np.ndarray, js: list, c: np.ndarray, active_s: np.ndarray, reading_cols: np.ndarray,
                blocks: list) -> np.ndarray:
    """For each candidate block of columns: what is left of the TE of columns ``js`` (coefficients ``c``, scaled
    units) after the least-squares move onto the block, the other chosen solved columns and the chosen reading
    columns."""
    keep = np.concatenate([np.setdiff1d(active_s, js), reading_cols]).astype(int)
    Q = np.linalg.qr(X[:, keep])[0] if keep.size else np.zeros((X.shape[0], 0))
    t = X[:, js] @ c
    t = t - Q @ (Q.T @ t)
    return np.array([float(t @ t) - _held(X[:, ks] - Q @ (Q.T @ X[:, ks]), t) for ks in blocks])


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
