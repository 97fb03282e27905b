"""The nonlinear estimate of the effects the posterior has chosen: their maximum a posteriori values through the
reducer model itself, not its linearisation.

The contacts of a zero-backlash reducer make the TE's response to a pin or a ring kinked and saturating at the
tolerance scale (a pin pushed away lifts off: further motion changes nothing), so the linearised model that
chooses the effects (:mod:`rvcalib.sparse`) does not give their sizes. For the chosen (active) parameters
``theta_A`` the posterior is maximised with the same prior the estimator fitted (each active feature
``N(0, V_l s^2)``, ``V_l`` its effect's prior variance and ``s`` its prior scale) and the same noise variance:

    minimise  |P (y - f(theta) - R b)|^2 / sigma^2 + sum_A (theta_j / (sqrt(V_j) s_j))^2

over ``theta_A`` and the active reading coefficients ``b`` (``P`` removes the tests' constants; the other
parameters stay at their posterior means), by a trust-region Levenberg-Marquardt method
(``scipy.optimize.least_squares``, method ``trf``, within the parameters' physical bounds) whose Jacobian is the
reducer model's columns for the active parameters (:meth:`rvcalib.reducer_model.ReducerModel.jacobian`).
"""
from __future__ import annotations

import numpy as np
from scipy import optimize

from rvcalib.reducer_model import ModelEvaluationError


def refine(model, y: np.ndarray, proj, R: np.ndarray, theta: np.ndarray, b_r: np.ndarray, active_s: np.ndarray,
           active_r: np.ndarray, prior_sd: np.ndarray, sigma: float, spread: np.ndarray | None = None,
           max_nfev: int | None = None, pool=None, log=None, feasible: np.ndarray | None = None,
           alternative: np.ndarray | None = None):
    """The MAP of the active parameters (see the module docstring).

    The active reading coefficients enter linearly: for each state of the solved ones they are the ridge solution
    (variable projection), so the nonlinear search runs over the solved parameters alone.

    Parameters
    ----------
    model : ReducerModel
    y : (n,) measured TE, arcsec
    proj : callable removing the tests' constants
    R : (n, m) reading columns
    theta : (p,) the solved parameters' start (posterior mean)
    b_r : (m,) the reading coefficients' start
    active_s, active_r : int arrays, the active solved parameters and reading coefficients
    prior_sd : (p + m,) prior standard deviation of every parameter (sqrt(V) s)
    sigma : float, the noise standard deviation, arcsec
    spread : (p,) or None, the secants' half-widths (the model's default: the prior scales)
    max_nfev : int or None, most model evaluations (default 10 + 2 per active solved parameter)
    feasible : (p,) or None, a state the model can solve (the current one): where the start ``theta`` cannot be
        solved (its errors overlap parts beyond the contact law), the start moves towards it, halving the way
    alternative : (p,) or None, a second start (the linearised estimate); the search starts from whichever of the
        two has the lower objective

    Returns
    -------
    (theta, b_r, te, cost)
        The refined parameters, the model TE there and the objective (the sum of squares above).
    """
    p = theta.size
    lo, hi = model._lower[active_s], model._upper[active_s]
    sd = prior_sd[active_s]
    Ra = proj(R[:, active_r])
    ra_prior = 1.0 / prior_sd[p + active_r] ** 2
    A = Ra.T @ Ra / sigma ** 2 + np.diag(ra_prior)
    cache: dict = {}
    b = b_r.copy()

    def linear(r: np.ndarray) -> np.ndarray:
        return np.linalg.solve(A, Ra.T @ r / sigma ** 2) if active_r.size else np.zeros(0)

    def state(x):
        th = theta.copy()
        th[active_s] = x
        return th

    def fun(x):
        if np.array_equal(cache.get("x"), x):      # the model's last solve: its states are this x's
            return cache["f"].copy()
        th = state(x)
        try:
            te = model.te(th)
        except ModelEvaluationError:
            return np.full(y.size + x.size + active_r.size, 1e6)
        r = proj(y - te - R @ _zero(b_r, active_r))
        br = linear(r)
        f = np.concatenate([(r - Ra @ br) / sigma, x / sd, br * np.sqrt(ra_prior)])
        cache["x"], cache["te"], cache["br"], cache["f"] = x.copy(), te, br, f
        return f.copy()

    def jac(x):
        if not np.array_equal(cache.get("x"), x):
            fun(x)
        renew = np.zeros(p, dtype=bool)
        renew[active_s] = True
        J = proj(model.jacobian(state(x), spread, renew, pool)[:, active_s])
        if active_r.size:
            J = J - Ra @ np.linalg.solve(A, Ra.T @ J / sigma ** 2)
        return np.vstack([-J / sigma, np.diag(1.0 / sd), np.zeros((active_r.size, active_s.size))])

    if active_s.size == 0:
        te = model.te(theta)
        b[active_r] = linear(proj(y - te - R @ _zero(b_r, active_r)))
        return theta, _zero(b, np.zeros(0, int)) + _only(b, active_r, b_r), te, float("nan")
    x0 = _solvable(fun, theta, active_s, lo, hi, feasible)
    if alternative is not None:
        x1 = _solvable(fun, alternative, active_s, lo, hi, feasible)
        if not np.array_equal(x1, x0) and np.sum(fun(x1) ** 2) < np.sum(fun(x0) ** 2):
            x0 = x1
    if np.any((x0 <= lo) | (x0 >= hi)):
        x0 = _gauss_newton_start(fun, jac, x0, lo, hi, sd)
    nfev = max_nfev or 10 + 2 * active_s.size
    res = optimize.least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale=sd, max_nfev=nfev)
    fun(res.x)                                  # the model's states are those of the estimate (the next Jacobian's)
    b[active_r] = cache["br"]
    if log:
        log(f"  nonlinear estimate of {active_s.size} solved and {active_r.size} reading parameters: "
            f"{res.nfev} evaluations, objective {2 * res.cost:.1f} ({res.message})")
    return state(res.x), b, cache["te"], float(2 * res.cost)


def _solvable(fun, theta: np.ndarray, active_s: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              feasible: np.ndarray | None) -> np.ndarray:
    """The active parameters of ``theta`` within their bounds, moved towards ``feasible`` (halving the way, at most
    six times, then ``feasible`` itself) while the model cannot solve them."""
    x0 = np.clip(theta[active_s], lo, hi)
    if feasible is None:
        return x0
    for _ in range(6):
        if np.all(fun(x0)[:3] < 1e6):
            return x0
        theta = feasible + 0.5 * (theta - feasible)
        x0 = np.clip(theta[active_s], lo, hi)
    return np.clip(feasible[active_s], lo, hi)


def _gauss_newton_start(fun, jac, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """The start of the trust-region search from a start on a bound: the linearised MAP from ``x0`` (one
    Gauss-Newton step), kept strictly inside the bounds (a thousandth of a prior scale from each), where it lowers
    the objective; else ``x0``.

    The trust-region reflective method makes little or no progress from a start on a bound (a clearance or a
    compliance at zero) whose gradient points inwards; the Gauss-Newton step moves it off at once."""
    f0 = fun(x0)
    J = jac(x0)
    try:
        x1 = x0 - np.linalg.lstsq(J, f0, rcond=None)[0]
    except np.linalg.LinAlgError:
        return x0
    pad = 1e-3 * sd
    x1 = np.clip(x1, np.minimum(lo + pad, hi), np.maximum(hi - pad, lo))
    return x1 if np.sum(fun(x1) ** 2) < np.sum(f0 ** 2) else x0


def _zero(b: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """b with the entries ``idx`` set to zero."""
    out = b.copy()
    out[idx] = 0.0
    return out


def _only(b: np.ndarray, idx: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Zeros but for the entries ``idx`` of b."""
    out = np.zeros_like(ref)
    out[idx] = b[idx]
    return out
