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
(``scipy.optimize.least_squares``, method ``trf``, within the parameters' physical bounds). Its Jacobian is the
reducer model's columns for the active parameters (:meth:`rvcalib.reducer_model.ReducerModel.jacobian`) at the
search's first Jacobian point, then kept by Broyden's rank-one update with the secant to every point the search
evaluates, in the parameters scaled by their prior standard deviations (K. Madsen, H. B. Nielsen, O. Tingleff,
"Methods for non-linear least squares problems", 2nd ed., IMM, DTU, 2004, section 3.4, the secant version of the
Levenberg-Marquardt method). A pin's or a clearance's column is a secant over its spread, two solves per
condition; the update costs none, so a search costs its evaluations and one set of columns.
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
    obj = _Objective(model, y, proj, R, theta, b_r, active_s, active_r, prior_sd, sigma, spread, pool)
    b = b_r.copy()
    if active_s.size == 0:
        te = model.te(theta)
        b[active_r] = obj.linear(proj(y - te - obj.fixed_r))
        return theta, b, te, float("nan")
    lo, hi, sd = model._lower[active_s], model._upper[active_s], obj.sd
    x0 = _solvable(obj, theta, active_s, lo, hi, feasible)
    if alternative is not None:
        x1 = _solvable(obj, alternative, active_s, lo, hi, feasible)
        if not np.array_equal(x1, x0) and np.sum(obj(x1) ** 2) < np.sum(obj(x0) ** 2):
            x0 = x1
    if np.any((x0 <= lo) | (x0 >= hi)):
        x0 = _gauss_newton_start(obj, obj.jac, x0, lo, hi, sd)
    nfev = max_nfev or 10 + 2 * active_s.size
    res = optimize.least_squares(obj, x0, jac=obj.jac, bounds=(lo, hi), method="trf", x_scale=sd, max_nfev=nfev)
    obj(res.x)                                  # the model's states are those of the estimate (the next Jacobian's)
    b[active_r] = obj.last["br"]
    if log:
        log(f"  nonlinear estimate of {active_s.size} solved and {active_r.size} reading parameters: "
            f"{res.nfev} evaluations, objective {2 * res.cost:.1f} ({res.message})")
    return obj.state(res.x), b, obj.last["te"], float(2 * res.cost)


class _Objective:
    """The residuals of the module docstring's sum of squares at the active solved parameters ``x``, the active
    reading coefficients eliminated (their ridge solution for each ``x``: variable projection), and their
    Jacobian. The last evaluation is kept: the model's states are then that ``x``'s, which its Jacobian needs."""

    def __init__(self, model, y, proj, R, theta, b_r, active_s, active_r, prior_sd, sigma, spread, pool) -> None:
        self.model, self.y, self.proj, self.R, self.theta = model, y, proj, R, theta
        self.active_s, self.active_r, self.sigma, self.spread, self.pool = active_s, active_r, sigma, spread, pool
        self.sd = prior_sd[active_s]
        self.Ra = proj(R[:, active_r])
        self.ra_prior = 1.0 / prior_sd[theta.size + active_r] ** 2
        self.A = self.Ra.T @ self.Ra / sigma ** 2 + np.diag(self.ra_prior)
        self.fixed_r = R @ _zero(b_r, active_r)         # the inactive reading coefficients' TE
        self.last: dict = {}
        self.Jm: np.ndarray | None = None                # the model's columns of the active parameters
        self.anchor: tuple | None = None                # (x, model TE) where Jm was last accepted

    def linear(self, r: np.ndarray) -> np.ndarray:
        """The active reading coefficients' ridge solution on the residual ``r``."""
        if not self.active_r.size:
            return np.zeros(0)
        return np.linalg.solve(self.A, self.Ra.T @ r / self.sigma ** 2)

    def state(self, x: np.ndarray) -> np.ndarray:
        th = self.theta.copy()
        th[self.active_s] = x
        return th

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if np.array_equal(self.last.get("x"), x):      # the model's last solve: its states are this x's
            return self.last["f"].copy()
        try:
            te = self.model.te(self.state(x))
        except ModelEvaluationError:
            return np.full(self.y.size + x.size + self.active_r.size, 1e6)
        self._update(x, te)
        r = self.proj(self.y - te - self.fixed_r)
        br = self.linear(r)
        f = np.concatenate([(r - self.Ra @ br) / self.sigma, x / self.sd, br * np.sqrt(self.ra_prior)])
        self.last = {"x": x.copy(), "te": te, "br": br, "f": f}
        return f.copy()

    def _update(self, x: np.ndarray, te: np.ndarray) -> None:
        """Broyden's rank-one update of the model's columns with the secant from the anchor to ``x`` (model TE
        ``te``), in the parameters scaled by ``sd``: the least change of the columns that makes them reproduce
        that secant."""
        if self.Jm is None:
            return
        xa, tea = self.anchor
        dx = x - xa
        du = dx / self.sd
        dd = float(du @ du)
        if dd > 0.0:
            self.Jm += np.outer(te - tea - self.Jm @ dx, du / self.sd) / dd

    def jac(self, x: np.ndarray) -> np.ndarray:
        if not np.array_equal(self.last.get("x"), x):
            self(x)
        if self.Jm is None:
            renew = np.zeros(self.theta.size, dtype=bool)
            renew[self.active_s] = True
            self.Jm = self.model.jacobian(self.state(x), self.spread, renew, self.pool)[:, self.active_s].copy()
        self.anchor = (x.copy(), self.last["te"])
        J = self.proj(self.Jm)
        if self.active_r.size:
            J = J - self.Ra @ np.linalg.solve(self.A, self.Ra.T @ J / self.sigma ** 2)
        return np.vstack([-J / self.sigma, np.diag(1.0 / self.sd), np.zeros((self.active_r.size, self.active_s.size))])


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
