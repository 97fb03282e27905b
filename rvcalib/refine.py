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
           active_r: np.ndarray, prior_sd: np.ndarray, sigma: float, spread: np.ndarray | None = None, max_nfev: int = 12, pool=None,
           log=None):
    """The MAP of the active parameters (see the module docstring).

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

    Returns
    -------
    (theta, b_r, te, cost)
        The refined parameters, the model TE there and the objective (the sum of squares above).
    """
    p = theta.size
    lo = np.concatenate([model._lower[active_s], np.full(active_r.size, -np.inf)])
    hi = np.concatenate([model._upper[active_s], np.full(active_r.size, np.inf)])
    sd = np.concatenate([prior_sd[active_s], prior_sd[p + active_r]])
    x0 = np.clip(np.concatenate([theta[active_s], b_r[active_r]]), lo, hi)
    cache: dict = {}

    def unpack(x):
        th, br = theta.copy(), b_r.copy()
        th[active_s] = x[:active_s.size]
        br[active_r] = x[active_s.size:]
        return th, br

    def fun(x):
        th, br = unpack(x)
        try:
            te = model.te(th)
        except ModelEvaluationError:
            return np.full(y.size + x.size, 1e6)
        cache["x"], cache["te"] = x.copy(), te
        return np.concatenate([proj(y - te - R @ br) / sigma, x / sd])

    def jac(x):
        th, _ = unpack(x)
        if not np.array_equal(cache.get("x"), x):
            fun(x)
        renew = np.zeros(p, dtype=bool)
        renew[active_s] = True
        J = model.jacobian(th, spread, renew, pool)
        top = -proj(np.column_stack([J[:, active_s], R[:, active_r]])) / sigma
        return np.vstack([top, np.diag(1.0 / sd)])

    if x0.size == 0:
        return theta, b_r, model.te(theta), float("nan")
    res = optimize.least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale=sd, max_nfev=max_nfev)
    th, br = unpack(res.x)
    te = model.te(th)
    if log:
        log(f"  nonlinear estimate of {active_s.size} solved and {active_r.size} reading parameters: "
            f"{res.nfev} evaluations, objective {2 * res.cost:.1f} ({res.message})")
    return th, br, te, float(2 * res.cost)
