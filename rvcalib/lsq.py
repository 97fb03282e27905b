"""Least-squares numerics of the loop (no reducer knowledge): projectors, F test and BIC, linear
fits of signature columns, forward-difference Jacobians and the chord (kept-Jacobian Gauss-Newton)
fit used for the nonlinear refits through rvdyn."""
from __future__ import annotations

import math
import time

import numpy as np
from scipy import optimize, stats

from rvcalib.forward import ModelEvaluationError

#: A fit judged by the BIC is converged when its last step changed the BIC by at most this (see
#: :func:`chord_fit`, ``bic_n``): below the loop's smallest BIC margin (2), so no decision turns on it.
BIC_CONVERGED = 1.0


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
            f0: np.ndarray | None = None, central: bool = False, only=None) -> np.ndarray:
    """Forward-difference Jacobian of ``fun`` at ``x`` (step ``h * max(1, |x_j|)``, backward where the
    forward step leaves the bounds or cannot be evaluated; ``central`` differences where both fit).
    ``only``: difference only these column indices (the returned array has just those columns).

    A ``fun`` with a ``many`` attribute (a function of a list of points giving, for each, its residual
    or the :class:`ModelEvaluationError` it raised) has its difference points evaluated in one call
    (one batch of the forward runner, spread over its workers); otherwise they are evaluated one by
    one in the same order. Either way a forward point that cannot be evaluated is replaced by the
    backward one, evaluated after the others."""
    plan = []  # per column: (index, step, [(point, sign)]) with sign +1 forward, -1 backward
    for j in (range(x.size) if only is None else only):
        step = h * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += step
        xm[j] -= step
        if central and x[j] - step >= lo[j] and x[j] + step <= hi[j]:
            plan.append((j, step, [(xp, 1), (xm, -1)]))
        elif x[j] + step <= hi[j]:
            plan.append((j, step, [(xp, 1)]))
        else:
            plan.append((j, step, [(xm, -1)]))
    if f0 is None and any(len(pts) == 1 for _, _, pts in plan):
        f0 = fun(x)
    many = getattr(fun, "many", None) or (lambda points: [_evaluated(fun, q) for q in points])
    got = many([q for _, _, pts in plan for q, _ in pts])
    cols, k = [], 0
    for j, step, pts in plan:
        vals = got[k:k + len(pts)]
        k += len(pts)
        if len(pts) == 2:
            for v in vals:
                if isinstance(v, ModelEvaluationError):
                    raise v
            cols.append((vals[0] - vals[1]) / (2 * step))
            continue
        v, sign = vals[0], pts[0][1]
        if isinstance(v, ModelEvaluationError):
            if sign < 0:
                raise v
            xm = x.copy()
            xm[j] -= step
            v, sign = fun(xm), -1
        cols.append((v - f0) / step if sign > 0 else (f0 - v) / step)
    return np.column_stack(cols)


def _evaluated(fun, x: np.ndarray):
    """``fun(x)``, or the :class:`ModelEvaluationError` it raised."""
    try:
        return fun(x)
    except ModelEvaluationError as exc:
        return exc


def broyden_update(J: np.ndarray, s: np.ndarray, dr: np.ndarray) -> np.ndarray:
    """Broyden's rank-one ("good") update of a residual Jacobian: the smallest change of ``J`` (Frobenius
    norm) that reproduces the change ``dr`` of the residual over the step ``s`` (Dennis and Schnabel,
    Numerical Methods for Unconstrained Optimization, 1983, sec. 8.1). A step of zero length returns J."""
    ss = float(s @ s)
    if ss <= 0.0:
        return J
    return J + np.outer(dr - J @ s, s) / ss


def chord_fit(fun, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, max_iter: int = 8,
              h: float = 0.01, xtol: float = 1e-3, r0: np.ndarray | None = None,
              ref: tuple[np.ndarray, np.ndarray] | None = None, deadline: float | None = None,
              J0: np.ndarray | None = None, known: np.ndarray | None = None, bic_n: int | None = None):
    """Gauss-Newton on a Jacobian kept up to date by Broyden's rank-one updates from every evaluation
    (accepted steps and rejected trial points alike): the start is already the coarse-grid estimate,
    so a few solves suffice and the Jacobian is differenced (forward, step ``h``) only at the start.

    A trial point that does not lower the residual sum of squares updates the Jacobian and the step is
    recomputed from it, at most half as long as the rejected one (five trials per iteration). The fit
    stops when a step moves no parameter by more than ``xtol`` (scaled units) or lowers the sum of
    squares by less than 1e-6 of it, after ``max_iter`` iterations, or (``deadline``, a
    ``time.perf_counter()`` value) when the time is up. With ``bic_n`` (the number of samples of a
    fit whose result the loop judges by the BIC) the fit goes on past ``max_iter`` (at most as many
    iterations again) while its last step still lowered the BIC, ``bic_n * ln(rss_before /
    rss_after)``, by more than BIC_CONVERGED (1) unit: a fit stopped by its iteration cap while still
    moving by more than that is not converged for the decision made on it (realistic seed 1 with 2
    workers: a subset refit from a poor linearised start stopped at 8 iterations, its last step
    91.04 -> 89.31 arcsec^2 = 25 BIC units, and was rejected; docs/calibration.md). When it goes on past
    ``max_iter`` the Jacobian is differenced afresh at that point, once (stop 39): rank-one updates had
    left realistic seed 1's 14-parameter joint refit of iteration 3 still gaining 6 BIC units a step at the
    cap, and two codes' ends of that refit 110 noise variances apart.

    Parameters
    ----------
    r0 : ndarray or None
        ``fun(x0)`` if already known.
    ref : (x, r) or None
        Another point and its residual (e.g. the model without the fitted effect): for one parameter
        the start's Jacobian is the secant through it when it lies at least ``h`` from ``x0``, which
        saves the differencing solve.
    J0, known : ndarray or None
        A start Jacobian (columns of the scaled parameters) whose columns ``known`` (bool mask) are taken
        as they are (e.g. from an earlier fit of the same effects near this state); only the other
        columns are differenced at ``x0``. The Broyden updates of every evaluation then correct it; when
        its first step gives no decrease, the whole Jacobian is differenced there and the fit goes on.

    Returns (x, residual, Jacobian, solves) or None if no decrease could be made."""
    try:
        r = fun(x0) if r0 is None else r0
    except ModelEvaluationError:
        return None
    nfev = int(r0 is None)
    J = None
    if ref is not None and x0.size == 1:
        d = float(x0[0] - ref[0][0])
        if abs(d) >= h * max(1.0, abs(float(x0[0]))):
            J = ((r - ref[1]) / d)[:, None]
    reused = False
    if J is None and J0 is not None and known is not None and np.any(known):
        reused = True
        J = np.array(J0, dtype=float, copy=True)
        todo = np.flatnonzero(~np.asarray(known, dtype=bool))
        if todo.size:
            try:
                J[:, todo] = fd_jac(fun, x0, lo, hi, h=h, f0=r, only=todo)
            except ModelEvaluationError:
                return None
            nfev += int(todo.size)
    if J is None:
        try:
            J = fd_jac(fun, x0, lo, hi, h=h, f0=r)
        except ModelEvaluationError:
            return None
        nfev += x0.size
    n_start = nfev
    x, rss = x0.copy(), float(r @ r)
    it = 0
    while it < (2 * max_iter if bic_n else max_iter):
        it += 1
        if deadline is not None and time.perf_counter() > deadline:
            break
        dx, *_ = np.linalg.lstsq(J, -r, rcond=None)
        accepted = False
        for _ in range(5):
            xn = np.clip(x + dx, lo, hi)
            s = xn - x
            if not np.any(s):
                break
            try:
                rn = fun(xn)
                nfev += 1
            except ModelEvaluationError:
                dx = 0.5 * dx
                continue
            J = broyden_update(J, s, rn - r)
            rssn = float(rn @ rn)
            if rssn <= rss:
                accepted = True
                break
            # rejected: a step from the updated linearisation, at most half as long
            dn, *_ = np.linalg.lstsq(J, -r, rcond=None)
            lim = 0.5 * float(np.linalg.norm(s))
            nd = float(np.linalg.norm(dn))
            dx = dn if nd <= lim else dn * (lim / max(nd, 1e-300))
        if not accepted and reused:
            # the reused start Jacobian gave no decrease: difference it here and go on (once)
            reused = False
            try:  # fun(x) asked for again (the forward runner's cache): its difference points start from x's state
                J = fd_jac(fun, x, lo, hi, h=h)
            except ModelEvaluationError:
                return (x, r, J, nfev) if nfev > n_start else None
            nfev += x.size
            continue
        if not accepted:
            return (x, r, J, nfev) if nfev > n_start else None
        step = float(np.max(np.abs(xn - x)))
        act = rss - rssn
        x, r, rss = xn, rn, rssn
        if step < xtol or act <= 1e-6 * rss:
            break
        if it >= max_iter and (not bic_n or rss <= 0.0 or bic_n * math.log((rss + act) / rss) <= BIC_CONVERGED):
            break
        if it == max_iter and bic_n:
            # at the cap still gaining (once: it passes max_iter once): Gauss-Newton on a Jacobian differenced
            # here, not more rank-one updates
            try:
                J = fd_jac(fun, x, lo, hi, h=h, f0=r)
            except ModelEvaluationError:
                pass
            else:
                nfev += x.size
    return x, r, J, nfev


def profile_limit(fun, x: np.ndarray, J: np.ndarray, i: int, toward: float, drss: float,
                  r0: np.ndarray | None = None, n_bisect: int = 8, rel_floor: float = 1e-4) -> float | None:
    """The end of a parameter's confidence region on the side of ``toward``, by a profile of the residual sum
    of squares, for a parameter whose linearised interval means nothing (one at a bound of its range, where
    the residual does not depend on it: a pin out of contact at any larger size).

    Along the line from ``x[i]`` (a least-squares solution, other parameters as in ``x``) to ``toward``, the
    profile is ``g(v) = |(I - Q Q^T) r(v)|^2``: the residual with ``x[i] = v`` solved through ``fun``, the other
    parameters readjusted linearly (``Q`` an orthonormal basis of the columns of ``J`` other than ``i``). The
    confidence region is ``g(v) <= g(x[i]) + drss`` (``drss = t^2 s^2``: the rise at the end of a linear
    interval of ``t`` standard errors). If ``toward`` is inside, returns None (the region reaches past it);
    else the crossing is bracketed in the distance from ``toward``, between ``rel_floor`` of the whole
    distance (returned if inside) and the whole, and bisected ``n_bisect`` times geometrically (the distances'
    ratio shrinks to ``(1/rel_floor)^(2^-n_bisect)``, 1.037 by default: a limit near ``toward`` is resolved as
    well as one far from it); the innermost point known to lie inside is returned, so the interval errs wide
    (assumes one crossing: flat, then rising; a point ``fun`` cannot evaluate counts as outside). Scaled units
    as ``x``.
    """
    x = np.asarray(x, dtype=float)
    P = projector(np.delete(np.asarray(J, dtype=float), i, axis=1))

    def g(v: float) -> float:
        xv = x.copy()
        xv[i] = v
        try:
            r = np.asarray(fun(xv) if (v != x[i] or r0 is None) else r0, dtype=float)
        except ModelEvaluationError:
            return math.inf
        u = P(r)
        return float(u @ u)

    thr = g(float(x[i])) + float(drss)
    if g(float(toward)) <= thr:
        return None
    d_in = abs(float(x[i]) - float(toward))
    sign = 1.0 if float(x[i]) >= float(toward) else -1.0
    d_out = rel_floor * d_in
    if g(float(toward) + sign * d_out) <= thr:
        return float(toward) + sign * d_out
    for _ in range(n_bisect):
        d = math.sqrt(d_in * d_out)
        if g(float(toward) + sign * d) <= thr:
            d_in = d
        else:
            d_out = d
    return float(toward) + sign * d_in


def bic_backward(r: np.ndarray, J: np.ndarray, x: np.ndarray, member_cols: list[np.ndarray], n: int,
                 max_members: int | None = None, keep: set[int] | frozenset[int] = frozenset()) -> list[int]:
    """Backward elimination by the BIC in the model linearised at a fit's solution.

    Each step removes the member whose removal (its parameters set to zero, every other member refitted by
    linear least squares, ``r(x') ~ r + J (x' - x)``) raises ``n ln(rss)`` least against the ``k ln n`` it saves,
    while that lowers the BIC or more than ``max_members`` members are left.

    Parameters
    ----------
    r : ndarray (n_rows,)
        The residual at the solution.
    J : ndarray (n_rows, p)
        Its Jacobian in the (scaled) parameters ``x``.
    x : ndarray (p,)
    member_cols : list of ndarray of int
        Each member's columns.
    n : int
        The number of samples of the BIC.
    max_members : int or None
        At most this many members are kept (removal goes on past the BIC's optimum down to it).
    keep : set of int
        Members never removed.

    Returns
    -------
    list of int
        The members kept, in their order.
    """
    alive = list(range(len(member_cols)))
    t = r - J @ x   # the residual with every parameter at zero, in the linear model
    rss_cur = float(r @ r)
    while True:
        cols_alive = [member_cols[i] for i in alive]
        best = None
        for i in alive:
            if i in keep:
                continue
            others = np.concatenate([c for j, c in zip(alive, cols_alive) if j != i] or [np.zeros(0, dtype=int)])
            if others.size:
                z, *_ = np.linalg.lstsq(J[:, others], -t, rcond=None)
                rr = t + J[:, others] @ z
            else:
                rr = t
            rss = float(rr @ rr)
            d = n * math.log(max(rss, 1e-300) / max(rss_cur, 1e-300)) - member_cols[i].size * math.log(n)
            if best is None or d < best[0]:
                best = (d, i, rss)
        if best is None:
            return alive
        over = max_members is not None and len(alive) > max_members
        if best[0] >= 0.0 and not over:
            return alive
        alive.remove(best[1])
        rss_cur = best[2]
