"""Least-squares numerics of the loop (no reducer knowledge): projectors, F test and BIC, linear
fits of signature columns, forward-difference Jacobians and the chord (kept-Jacobian Gauss-Newton)
fit used for the nonlinear refits through rvdyn."""
from __future__ import annotations

import math

import numpy as np
from scipy import optimize, stats

from rvcalib.forward import ModelEvaluationError


def projector(E: np.ndarray | None):
    """Projector onto the orthogonal complement of the columns of E (a function)."""
    if E is None or E.shape[1] == 0:
        return lambda v: v
    Q, _ = np.linalg.qr(E)

    def P(v: np.ndarray) -> np.ndarray:
        return v - Q @ (Q.T @ v)
    return P


def bic(rss: float, n: int, k: int) -> float:
    """Bayesian information criterion of a Gaussian least-squares fit: ``n ln(rss/n) + k ln n``."""
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def ftest(rss0: float, rss1: float, k: int, n: int, p1: int) -> tuple[float, float]:
    """F statistic and p value of ``k`` added parameters (``rss0`` -> ``rss1``, ``p1`` parameters in all, ``n`` points)."""
    df2 = n - p1
    if rss1 <= 0 or df2 <= 0 or rss0 <= rss1:
        return 0.0, 1.0
    F = ((rss0 - rss1) / k) / (rss1 / df2)
    return float(F), float(stats.f.sf(F, k, df2))


def fit_option(r: np.ndarray, A: np.ndarray, nonneg: bool) -> tuple[float, np.ndarray]:
    """Residual sum of squares and coefficients of ``r ~ A c`` (``c >= 0`` if ``nonneg``)."""
    if A.shape[1] == 1:
        aa = float(A[:, 0] @ A[:, 0])
        if aa <= 0:
            return float(r @ r), np.zeros(1)
        c = float(A[:, 0] @ r) / aa
        if nonneg and c < 0:
            c = 0.0
        res = r - c * A[:, 0]
        return float(res @ res), np.array([c])
    if nonneg:
        c, rn = optimize.nnls(A, r)
        return float(rn ** 2), c
    c, *_ = np.linalg.lstsq(A, r, rcond=None)
    res = r - A @ c
    return float(res @ res), c


def fd_jac(fun, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, h: float = 0.02,
            f0: np.ndarray | None = None, central: bool = False) -> np.ndarray:
    f0 = fun(x) if (f0 is None and not central) else f0
    cols = []
    for j in range(x.size):
        step = h * max(1.0, abs(x[j]))
        xp = x.copy()
        xm = x.copy()
        if central and x[j] - step >= lo[j] and x[j] + step <= hi[j]:
            xp[j] += step
            xm[j] -= step
            cols.append((fun(xp) - fun(xm)) / (2 * step))
            continue
        if f0 is None:
            f0 = fun(x)
        if x[j] + step <= hi[j]:
            xp[j] += step
            try:
                cols.append((fun(xp) - f0) / step)
                continue
            except ModelEvaluationError:
                pass
        xm[j] -= step
        cols.append((f0 - fun(xm)) / step)
    return np.column_stack(cols)


def chord_fit(fun, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, max_iter: int = 8,
               h: float = 0.01, xtol: float = 1e-3):
    """Gauss-Newton with a Jacobian kept while it predicts the decrease well (chord method):
    the start is already the coarse-grid estimate, so a few full-grid solves suffice.
    Returns (x, residual, Jacobian, solves) or None if no decrease could be made."""
    try:
        r = fun(x0)
        J = fd_jac(fun, x0, lo, hi, h=h, f0=r)
    except ModelEvaluationError:
        return None
    nfev = 1 + x0.size
    x, rss = x0.copy(), float(r @ r)
    for _ in range(max_iter):
        dx, *_ = np.linalg.lstsq(J, -r, rcond=None)
        pred = rss - float(np.sum((r + J @ dx) ** 2))
        alpha, accepted = 1.0, False
        for _ in range(5):
            xn = np.clip(x + alpha * dx, lo, hi)
            try:
                rn = fun(xn)
                nfev += 1
            except ModelEvaluationError:
                alpha *= 0.5
                continue
            rssn = float(rn @ rn)
            if rssn <= rss:
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            return (x, r, J, nfev) if nfev > 1 + x0.size else None
        step = float(np.max(np.abs(xn - x)))
        act = rss - rssn
        x, r, rss = xn, rn, rssn
        if step < xtol or act <= 1e-6 * rss:
            break
        if act < 0.5 * alpha * pred:  # the linearisation is off: take a new Jacobian here
            try:
                J = fd_jac(fun, x, lo, hi, h=h, f0=r)
            except ModelEvaluationError:
                break
            nfev += x.size
    return x, r, J, nfev
