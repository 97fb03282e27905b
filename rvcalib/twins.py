"""Candidates the data cannot split once the reducer model is nonlinear: the swap test.

The sparse estimator splits the inclusion probability between candidates whose columns are alike, and reports
them as a group (:mod:`rvcalib.sparse`). Through the reducer model that split does not survive the loop: once one
of two alike candidates is in the model (the pins ``p`` and ``p + Zp / 2`` of a two-crank reducer whose cranks are
half a turn apart give the same TE to rounding), the next linearisation takes its column where it is and the
other's where it is not, and the two no longer look alike. Which one entered first is then a coin toss the result
would hide.

So at the end every named single-parameter effect ``f`` is confronted with each candidate ``g`` whose column at the
first linearisation (where neither was in the model) is nearly the same line (|correlation| at least
:data:`SCREEN`, a screen that only limits the cost): the model is solved with ``f``'s effect moved to ``g`` (at the
size whose first-linearisation TE is ``f``'s beyond what the reading coefficients take, its sign included: a
half-turn twin acts with the opposite sign) and the reading coefficients refitted, and where the fit is worse by
less than the 95 % quantile of chi-square with one degree of freedom (``Delta chi^2 < 3.84``, a likelihood ratio
the data cannot tell from chance), ``g`` is a twin and ``f`` is reported as a group with it instead of a name.
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
               active_r: np.ndarray, tau: np.ndarray | None = None) -> dict[int, list[tuple[int, float, float]]]:
    """The twins of each chosen single-parameter feature.

    Parameters
    ----------
    pb : rvcalib.loop._Problem
    X0 : (n, P) the features' scaled, projected columns at the first linearisation
    theta : (p,) the final solved parameters
    sigma : noise standard deviation, arcsec
    active_s, active_r : the chosen solved parameters and reading coefficients

    Returns
    -------
    dict
        Feature index -> [(twin feature index, Delta chi^2), ...] for the chosen features that have twins.
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
    Q = np.linalg.qr(Ra)[0] if active_r.size else np.zeros((Ra.shape[0], 0))

    def keep(x: np.ndarray) -> np.ndarray:
        """What the refitted reading coefficients cannot absorb of a column."""
        return x - Q @ (Q.T @ x)

    C = X0 / np.maximum(np.linalg.norm(X0, axis=0), 1e-300)
    base = chi2(theta)
    out: dict[int, list[tuple[int, float]]] = {}
    for f in chosen:
        j = pb.starts[f]
        others = [g for g in single if g != f and pb.starts[g] not in on]
        r = np.array([abs(C[:, j] @ C[:, pb.starts[g]]) for g in others])
        near = [others[k] for k in np.argsort(-r)[:MOST] if r[k] >= SCREEN]
        found = []
        for g in near:
            k = pb.starts[g]
            th = theta.copy()               # g at the size whose first-linearisation TE is f's (sign included)
            xk, xj = keep(X0[:, k]), keep(X0[:, j])
            size = (xk @ xj) / max(xk @ xk, 1e-300) * theta[j] / tau[j] * tau[k]
            th[k] = np.clip(size, m._lower[k], m._upper[k])
            th[j] = 0.0
            d = chi2(th) - base
            if d < DELTA_CHI2:
                found.append((g, float(d), float(th[k])))
        if found:
            out[f] = found
    m.te(theta)                                     # the model's states are the estimate's again
    return out
