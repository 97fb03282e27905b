"""The tolerance-prior estimator: every candidate a Gaussian random effect at its tolerance class, no selection.

A real reducer holds every error of the library at some size within its tolerance class (the library's prior
scale: a third of the paper's Table 4 value for a Table 4 error, a stated scale for each model and measurement
option). This estimator takes that as its prior, for all candidates at once:

* each physical candidate outside the always-estimated block ``theta_j ~ N(0, s_j^2)``, ``s_j`` its prior scale
  (the two sides of a pin-wise error are two such candidates, each on its side of zero: a half-normal prior);
* the model options of the always-estimated block (the compliance: a property of the reducer, not an error
  within a class) nearly flat (:data:`FLAT`, a thousand prior scales); its Table 4 errors (the pin-circle
  diameter, the radius of all pins) at their class like every other;
* the tests' constants projected out (nuisance, never an effect).

**Criterion and search.** The maximum a posteriori of all parameters through the reducer model itself,

    minimise  |P (y - f(theta) - R_m b)|^2 / sigma^2 + sum_j (theta_j / s_j)^2 + sum_k (b_k / s_k)^2

(``R_m`` the measurement effects' reading columns), by Levenberg-Marquardt through the reducer model: at each
state the linearised problem's damped MAP within the physical bounds, on the model's columns there
(re-linearisation). The first linearisation, at the start, where the posterior is still the prior, is the
statistical one over the prior (:meth:`rvcalib.reducer_model.ReducerModel.statistical_jacobian`: each column the
secant over +- its prior scale), so a response that bends within its tolerance class is not extrapolated from its
slope at the start. There is one criterion; no candidate is chosen or dropped. The search runs a second time from
the half-turn image of its end, and one answer is read over both ends (:mod:`rvcalib.arrangements`): the
crank-indexed errors' arrangements can be minima of their own.

**Intervals.** Laplace's approximation at the MAP: the covariance ``(X' X / sigma^2 + diag(1 / s^2))^-1`` of all
parameters at once (``X`` the columns at the MAP), so each interval holds what every other candidate, at its
tolerance class, could move it; a named effect's interval is then widened through the model where the criterion
rises more slowly than its curvature at the MAP says (:mod:`rvcalib.regions`). ``sigma`` is the noise of the
greatest evidence (MacKay's fixed point, D. J. C. MacKay, "Bayesian interpolation", Neural Computation 4 (1992)
415-447, eq. 4.10: ``sigma^2 = |r|^2 / (n - k - g)``, ``k`` the tests' constants, ``g = sum_j (1 - C_jj / s_j^2)``
the parameters the data determine).

**What is named.** A candidate whose 95 % posterior region excludes zero (one component: its interval; two
components: the chi-square(2) ellipse), with its MAP value and that interval, and whose exclusion of zero holds
through the model: with the candidate at zero and the others at their posterior given that, the criterion rises
above the MAP's by at least the chi-square quantile (:func:`zero_check`; where the response bends, a tangent at the
MAP can make the ellipse tighter than the data). Only a converged search names anything
(:func:`unconverged_note`). The rest are not told from zero by the data: they are in the fit at their posterior
means, never named. A candidate so named whose posterior correlation with another exceeds 0.95 (the data fix their
combination only) is reported as a group of the two instead, each with the size it would have alone; in the
always-estimated block likewise (:func:`rvcalib.result.read_block`).

**The empirical block** (orders and load or direction terms no candidate gives) joins after the physics, on its
residual: each term Gaussian at ``gamma`` times the typical TE of a tolerance-class Table 4 error, ``gamma`` the
data's (restricted maximum likelihood, :func:`block_variance`: white noise gives 0 and nothing is reported); a term
whose region excludes zero is reported as unexplained structure, never as a physical effect.

Reference: the prior is the tolerance stack-up's (each error within its class); the estimator is the linearised
Bayesian least squares of inverse problems (A. Tarantola, *Inverse Problem Theory*, SIAM 2005, section 3.2),
iterated as Levenberg-Marquardt through the nonlinear model (D. W. Marquardt, J. SIAM 11 (1963) 431-441).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import optimize, stats

from rvcalib.arrangements import Minimum, combine, half_turn_image
from rvcalib.reducer_model import ModelEvaluationError
from rvcalib.regions import widener
from rvcalib.result import CalibrationResult, assemble_common, group_member, named_effect, read_block

#: The always-estimated block's prior standard deviation, in prior scales (nearly flat).
FLAT = 1e3
#: Two candidates whose posterior correlation exceeds this are reported together (as in
#: :func:`rvcalib.result.read_block`): the data fix their combination only.
TIE = 0.95


class _Counted:
    """The forward model, counting its Jacobians (the linearisations) and keeping the last it computed
    (``last``)."""

    def __init__(self, model, J0: np.ndarray | None = None) -> None:
        self.model, self.jacobians, self.last = model, 0, J0

    def __getattr__(self, name):
        return getattr(self.model, name)

    def jacobian(self, *a, **k):
        self.jacobians += 1
        self.last = self.model.jacobian(*a, **k)
        return self.last


def prior_sd(pb, ts: np.ndarray, tr: np.ndarray) -> np.ndarray:
    """Prior standard deviation of every solved parameter and reading coefficient, physical units: the prior
    scale (the tolerance class), :data:`FLAT` times it for a model option of the always-estimated block (the
    compliance: a property of the reducer, not an error within a class)."""
    sd = np.concatenate([ts, tr]).astype(float)
    fam = np.array([c.family for c in pb.model.candidates for _ in range(c.n_params)])
    flat = pb.dense_params[fam[pb.dense_params] == "model"]
    sd[flat] *= FLAT
    return sd


def evidence_sigma(X: np.ndarray, r: np.ndarray, sd: np.ndarray, dof: int, sigma0: float,
                   iterations: int = 50) -> tuple[float, np.ndarray]:
    """MacKay's fixed point for the noise (see the module docstring) and the posterior covariance there.

    The parameters with a flat prior (``sd`` infinite), ``F``, are determined by the data alone: each counts one in
    ``g``, and the others see the columns with ``X_F`` projected out (``Q``; the residual at the MAP is already
    orthogonal to ``X_F``). With ``D = diag(sd_B)`` and the eigendecomposition ``D X_B' Q X_B D = V diag(lam) V'``
    (once), the covariance of ``B`` at a noise variance ``s2`` is ``D V diag(1 / (lam / s2 + 1)) V' D`` and ``g =
    |F| + sum(lam / (lam + s2))``, so each step ``s2 = |r|^2 / (dof - g)`` costs ``q`` operations, not a
    factorisation. The flat block's covariance follows from its least-squares solution given ``B``: ``C_FF = s2
    (X_F' X_F)^+ + A C_BB A'``, ``C_FB = -A C_BB``, ``A = (X_F' X_F)^+ X_F' X_B``.

    Parameters
    ----------
    X : (n, q) the columns at the MAP, projected; r : (n,) the residual there; sd : (q,) prior standard deviations
    (``inf``: flat); dof : readings less the constants; sigma0 : the start, arcsec.
    """
    sd = np.asarray(sd, dtype=float)
    F, B = np.flatnonzero(~np.isfinite(sd)), np.flatnonzero(np.isfinite(sd))
    XF, XB = X[:, F], X[:, B]
    GFi = np.linalg.pinv(XF.T @ XF)
    A = GFi @ (XF.T @ XB)
    Xw = (XB - XF @ A) * sd[B][None, :]                       # Q X_B D
    lam, V = np.linalg.eigh(Xw.T @ Xw)
    lam = np.maximum(lam, 0.0)
    rr, s2 = float(r @ r), sigma0 ** 2
    for _ in range(iterations):
        new = rr / max(dof - F.size - float(np.sum(lam / (lam + s2))), 1.0)
        done = abs(new - s2) <= 1e-10 * s2
        s2 = new
        if done:
            break
    W = V * (sd[B][:, None] / np.sqrt(lam / s2 + 1.0))
    C = np.empty((sd.size, sd.size))
    CBB = W @ W.T
    C[np.ix_(B, B)] = CBB
    C[np.ix_(F, B)] = -A @ CBB
    C[np.ix_(B, F)] = C[np.ix_(F, B)].T
    C[np.ix_(F, F)] = s2 * GFi + A @ CBB @ A.T
    return math.sqrt(s2), C


class Posterior:
    """The Laplace posterior of the parameters ``idx`` (solved first, then readings), physical units; the
    interface of :class:`rvcalib.result.Laplace` (``block``)."""

    def __init__(self, idx: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> None:
        self.pos = {int(j): k for k, j in enumerate(idx)}
        self.mean, self.cov = mean, cov

    def block(self, a: int, b: int):
        if any(j not in self.pos for j in range(a, b)):
            return None
        k = [self.pos[j] for j in range(a, b)]
        return self.mean[k], self.cov[np.ix_(k, k)]


def read_named(pb, post: Posterior, level: float, check=None, widen=None) -> tuple[list, list]:
    """The physical candidates outside the always-estimated block whose posterior region excludes zero (of the
    two sides of one pin-wise error, the side with the larger evidence), and, for such a candidate whose posterior
    correlation with another candidate exceeds :data:`TIE` (only their combination is determined: the sun's
    eccentricity and the input encoder's, say), a group of the two with the size each would have alone (its
    posterior mean were the other zero) instead of a name. ``check(positions, name)``, where given, is asked of
    each candidate whose region excludes zero (its posterior positions) and may refuse it (:func:`zero_check`);
    ``widen(effect, candidate, positions)``, where given, returns each named effect with its interval widened
    through the model (:func:`rvcalib.regions.widener`)."""
    sd = np.sqrt(np.maximum(np.diag(post.cov), 1e-300))
    corr = post.cov / np.outer(sd, sd)
    feats = [f for f in range(len(pb.feature_cands)) if f not in pb.fixed and not pb.empirical[f]
             and post.block(pb.starts[f], pb.starts[f + 1]) is not None]
    pos = {f: [post.pos[j] for j in range(pb.starts[f], pb.starts[f + 1])] for f in feats}
    out: dict = {}
    for f in feats:
        m, S = post.block(pb.starts[f], pb.starts[f + 1])
        d2 = float(m @ np.linalg.solve(S, m))
        if d2 <= stats.chi2.ppf(level, m.size):
            continue
        c = pb.feature_cands[f][0]
        if check is not None and not check(pos[f], c.effect_name):
            continue
        if c.effect_name not in out or out[c.effect_name][0] < d2:
            out[c.effect_name] = (d2, f, named_effect(c, 1.0, m, S, level))
    named, groups = [], []
    for _, f, eff in out.values():
        c = pb.feature_cands[f][0]
        tied = [(float(np.max(np.abs(corr[np.ix_(pos[f], pos[g])]))), g) for g in feats
                if pb.feature_cands[g][0].effect_name != c.effect_name]
        tied = sorted(((r, g) for r, g in tied if r > TIE), reverse=True)
        if not tied:
            named.append(eff if widen is None else widen(eff, c, pos[f]))
            continue
        members = []
        for a, b in [(f, g) for _, g in tied[:1]] + [(g, f) for _, g in tied]:
            ia, ib = pos[a], pos[b]
            alone = post.mean[ia] - post.cov[np.ix_(ia, ib)] @ np.linalg.solve(post.cov[np.ix_(ib, ib)],
                                                                                 post.mean[ib])
            members.append(group_member(pb.feature_cands[a][0], alone, np.ones(alone.size), 1.0))
        groups.append({"kind": "physical", "coverage": level, "purity": max(r for r, _ in tied),
                       "reason": "the data fix their combination only (posterior correlation above 0.95)",
                       "members": members})
    return named, groups


def _profiled(lam: float, z2: np.ndarray, s2: np.ndarray, rest: float, m: int) -> float:
    """-2 times the profile restricted log-likelihood at lambda = gamma / sigma^2 (constants dropped)."""
    d = 1.0 + lam * s2
    return float(np.sum(np.log(d)) + m * np.log((np.sum(z2 / d) + rest) / m))


def block_variance(r: np.ndarray, B: np.ndarray, dof: int) -> tuple[float, float]:
    """Restricted maximum likelihood of ``gamma`` and ``sigma^2`` in ``r ~ N(0, sigma^2 I + gamma B B')``
    (H. D. Patterson and R. Thompson, Biometrika 58 (1971) 545-554), ``r`` and ``B`` projected off what the fit
    holds, ``dof`` the residual's degrees of freedom. With ``B``'s singular values ``s_i``, ``z_i = u_i' r`` and
    ``rest = |r|^2 - sum z_i^2``, ``lambda = gamma / sigma^2`` minimises
    ``sum_i log(1 + lambda s_i^2) + dof log sigma^2(lambda)``, ``sigma^2(lambda) = (sum_i z_i^2 / (1 + lambda
    s_i^2) + rest) / dof``; a residual at white noise gives ``gamma = 0``."""
    U, s, _ = np.linalg.svd(B, full_matrices=False)
    k = int(min(np.sum(s > s[0] * 1e-8), dof - 1)) if s.size and s[0] > 0 else 0
    if k == 0:
        return 0.0, float(r @ r) / dof
    s2 = s[:k] ** 2
    z2 = (U[:, :k].T @ r) ** 2
    rest = max(float(r @ r) - float(z2.sum()), 0.0)
    got = optimize.minimize_scalar(lambda t: _profiled(np.expm1(t), z2, s2, rest, dof),
                                   bounds=(0.0, math.log1p(1e8 / s2[-1])), method="bounded",
                                   options={"xatol": 1e-6})
    lam = float(np.expm1(got.x)) if _profiled(float(np.expm1(got.x)), z2, s2, rest, dof) < _profiled(
        0.0, z2, s2, rest, dof) else 0.0
    sigma2 = float((np.sum(z2 / (1.0 + lam * s2)) + rest) / dof)
    return lam * sigma2, sigma2


def _unexplained(pb, r: np.ndarray, Q: np.ndarray, tr: np.ndarray, level: float) -> tuple[list, np.ndarray]:
    """The empirical block on the physics' residual ``r``: each term ``N(0, gamma tr^2)`` with ``gamma`` the
    data's (:func:`block_variance` on what is orthogonal to the physics' columns, orthonormal ``Q``), its Gaussian
    posterior, the terms whose region excludes zero (unexplained structure) and the coefficients of every reading
    column (0 but the empirical ones)."""
    b = np.zeros(pb.R.shape[1])
    emp = [f for f in range(len(pb.feature_cands)) if pb.empirical[f]]
    if not emp:
        return [], b
    n_s = pb.model.n_params
    cols = np.concatenate([np.arange(pb.starts[f], pb.starts[f + 1]) for f in emp]) - n_s
    E = pb.proj(pb.R[:, cols])
    Eo = E - Q @ (Q.T @ E)
    gamma, s2 = block_variance(r - Q @ (Q.T @ r), Eo * tr[cols], r.size - len(pb.tests) - Q.shape[1])
    if gamma <= 0:
        return [], b
    C = np.linalg.inv(E.T @ E / s2 + np.diag(1.0 / (gamma * tr[cols] ** 2)))
    m = C @ (E.T @ r) / s2
    b[cols] = m
    out, pos = [], 0
    for f in emp:
        c, k = pb.feature_cands[f][0], pb.starts[f + 1] - pb.starts[f]
        mm, S = m[pos:pos + k], C[pos:pos + k, pos:pos + k]
        pos += k
        if float(mm @ np.linalg.solve(S, mm)) > stats.chi2.ppf(level, k):
            size, ang = c.size(mm)
            out.append({"label": c.effect_name, "order": c.order, "kind": c.key, "amplitude_arcsec": float(size),
                        "phase_deg": ang, "probability": 1.0, "members": []})
    return out, b


DAMPING_START = 10.0
"""The first step's Levenberg-Marquardt damping, in units of the prior precision: the first linearisation, taken
far from the MAP, moves a candidate the data determine weakly by about a third of its prior scale at most
(``1 / sqrt(1 + 10)``)."""
DAMPING_UP, DAMPING_DOWN, DAMPING_TRIALS = 10.0, 0.3, 8
"""Marquardt's rule: the damping times 10 after a step that does not lower the criterion (or leaves the model's
domain), times 0.3 after one that does; at most 8 trials per linearisation."""
CRITERION_RESOLUTION = 1.0
"""The least fall of the criterion the data tell from none: one unit (a likelihood ratio of ``exp(1/2)``). A step
that lowers it by more is progress however short the damping makes it, so the search goes on."""


def damped_step(J: np.ndarray, r: np.ndarray, x: np.ndarray, w: np.ndarray, sigma: float, lam: float,
                lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The Levenberg-Marquardt step of the linearised criterion: the bounded least-squares solution of
    ``|r - J d|^2 / sigma^2 + |w (x + d)|^2 + lam |w d|^2`` over ``lo <= x + d <= hi``
    (``scipy.optimize.lsq_linear``, bvls). ``lam = 0`` is the Gauss-Newton step; a large ``lam`` a short step
    along the prior-scaled gradient."""
    A = np.vstack([J / sigma, np.diag(w), math.sqrt(lam) * np.diag(w)])
    rhs = np.concatenate([r / sigma, -x * w, np.zeros(x.size)])
    return optimize.lsq_linear(A, rhs, bounds=(lo - x, hi - x), method="bvls").x


def measurement_columns(pb) -> np.ndarray:
    """The reading columns of the measurement effects (encoder eccentricity and scale): the reading parameters the
    search estimates beside the solved ones (indices into ``pb.R``)."""
    n_s = pb.model.n_params
    meas = np.array([k for f, fc in enumerate(pb.feature_cands) if f not in pb.fixed and not pb.empirical[f]
                     and fc[0].family == "measurement" for k in range(pb.starts[f], pb.starts[f + 1])], dtype=int)
    return meas - n_s


def search_bounds(model, a_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of the search's parameters (the solved ones, then the coefficients of the reading columns
    ``a_r``): the model's physical bounds, the reading coefficients unbounded."""
    return (np.concatenate([model._lower, np.full(a_r.size, -np.inf)]),
            np.concatenate([model._upper, np.full(a_r.size, np.inf)]))


def criterion(pb, a_r: np.ndarray, sd: np.ndarray, x: np.ndarray, te: np.ndarray, sigma: float) -> float:
    """The criterion (module docstring) at ``x`` (the solved parameters, then the coefficients of the reading
    columns ``a_r``), ``te`` the model TE there (arcsec), at the noise ``sigma`` (arcsec); ``sd`` the prior standard
    deviations of :func:`prior_sd`. Dimensionless: the data term in noise units squared plus the prior term."""
    n_s = x.size - a_r.size
    r = pb.proj(pb.y - te) - pb.proj(pb.R[:, a_r]) @ x[n_s:]
    w = 1.0 / sd[np.concatenate([np.arange(n_s), n_s + a_r])]
    return float(r @ r) / sigma ** 2 + float(np.sum((x * w) ** 2))


def map_estimate(model, pb, theta: np.ndarray, a_r: np.ndarray, sd: np.ndarray, sigma: float, settings, pool,
                 log, J0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, str]:
    """The MAP of the criterion (module docstring) by Levenberg-Marquardt through the reducer model: at each state
    the linearised problem's damped bounded MAP (:func:`damped_step`, within the physical bounds), the damping
    raised until the step lowers the criterion and lowered after it does (Marquardt 1963), then the noise of the
    greatest evidence at the new state (:func:`evidence_sigma`, on that linearisation's columns); converged when a
    step moves the model TE by at most ``settings.step_tolerance`` of the noise (RMS) and lowers the criterion by
    less than :data:`CRITERION_RESOLUTION` (a short step of a heavily damped search that still lowers it is not
    convergence), or after ``settings.max_linearisations``.

    Returns (theta, the measurement coefficients ``b`` of the reading columns ``a_r``, the model TE, sigma, and
    what stopped it: ``converged``, ``max_linearisations``, or ``no_columns`` where the model's columns cannot be
    computed at a state the search reached, a perturbed case rvdyn cannot solve); ``J0`` the model's columns at
    ``theta`` where known (the first linearisation's)."""
    n_s = model.n_params
    Rm = pb.proj(pb.R[:, a_r])
    lo, hi = search_bounds(model, a_r)
    w = 1.0 / sd[np.concatenate([np.arange(n_s), n_s + a_r])]
    x = np.concatenate([np.clip(theta, model._lower, model._upper), np.zeros(a_r.size)])
    te = model.te(x[:n_s])

    phi = criterion(pb, a_r, sd, x, te, sigma)
    stopped = "max_linearisations"
    lam = DAMPING_START
    for it in range(1, settings.max_linearisations + 1):
        try:
            Js = model.jacobian(x[:n_s], None, None, pool) if J0 is None or it > 1 else J0
        except ModelEvaluationError as exc:
            log(f"linearisation {it}: the model's columns cannot be computed at this state: {exc}")
            stopped = "no_columns"
            break
        J = np.column_stack([pb.proj(Js), Rm])
        r = pb.proj(pb.y - te) - Rm @ x[n_s:]
        for _ in range(DAMPING_TRIALS):
            step = damped_step(J, r, x, w, sigma, lam, lo, hi)
            new = np.clip(x + step, lo, hi)
            try:
                te_new = model.te(new[:n_s])
            except ModelEvaluationError:
                lam *= DAMPING_UP
                continue
            phi_new = criterion(pb, a_r, sd, new, te_new, sigma)
            if phi_new < phi:
                lam *= DAMPING_DOWN
                break
            lam *= DAMPING_UP
        else:
            model.te(x[:n_s])
            log(f"linearisation {it}: no step lowers the criterion")
            stopped = "converged"
            break
        gn = np.clip(x + damped_step(J, r, x, w, sigma, 0.0, lo, hi), lo, hi)
        undamped = criterion(pb, a_r, sd, gn, te + Js @ (gn - x)[:n_s], sigma)
        moved = float(np.sqrt(np.mean(pb.proj(te_new - te) ** 2)))
        predicted = criterion(pb, a_r, sd, new, te + Js @ (new - x)[:n_s], sigma)     # on the linearised TE
        x, te = new, te_new
        r = pb.proj(pb.y - te) - Rm @ x[n_s:]
        sigma_new = evidence_sigma(J, r, 1.0 / w, r.size - len(pb.tests), sigma)[0]
        log(f"linearisation {it}: criterion {phi:.4f} -> {phi_new:.4f} (its linearisation predicted {predicted:.4f}, "
            f"undamped {undamped:.4f}, damping {lam / DAMPING_DOWN:.3g}), the model TE moved {moved:.3g} arcsec RMS, "
            f"noise of the greatest evidence {sigma_new:.4g} arcsec")
        fall = phi - phi_new
        sigma, phi = sigma_new, criterion(pb, a_r, sd, x, te, sigma_new)
        if moved <= settings.step_tolerance * sigma and fall < CRITERION_RESOLUTION:
            stopped = "converged"
            break
    return x[:n_s], x[n_s:], te, sigma, stopped


def _minimum(pb, settings, model, label: str, theta: np.ndarray, a_r: np.ndarray, sd: np.ndarray, sigma0: float,
             pool, log, J0: np.ndarray | None = None) -> Minimum:
    """The search (:func:`map_estimate`) from ``theta`` and what its end names: its Laplace posterior, the
    always-estimated block's effects and groups (:func:`rvcalib.result.read_block`), the others'
    (:func:`read_named`), each exclusion of zero checked through the model where the search converged."""
    n_s = model.n_params
    theta, b_m, te, sigma1, stopped = map_estimate(model, pb, theta, a_r, sd, sigma0, settings, pool, log, J0)
    b_r = np.zeros(pb.R.shape[1])
    b_r[a_r] = b_m
    if stopped != "no_columns":
        try:
            model.jacobian(theta, None, None, pool)
        except ModelEvaluationError as exc:
            log(f"the model's columns cannot be computed at the search's end: {exc}")
            stopped = "no_columns"
    J = pb.proj(model.last)             # at the end; where they cannot be computed there, the last state's
    X = np.column_stack([J, pb.proj(pb.R[:, a_r])])
    idx = np.concatenate([np.arange(n_s), n_s + a_r])
    r = pb.proj(pb.y - te - pb.R @ b_r)
    sigma, C = evidence_sigma(X, r, sd[idx], r.size - len(pb.tests), sigma1)
    post = Posterior(idx, np.concatenate([theta, b_m]), C)
    log(f"tolerance-prior MAP from the {label}: {stopped}, residual RMS {math.sqrt(float(np.mean(r ** 2))):.4g} "
        f"arcsec, noise of the greatest evidence {sigma:.4g}")
    named, groups, notes = [], [], []
    check = widen = None
    if stopped == "converged":
        rise = rise_function(pb, model, a_r, sd, post, te, sigma)
        check = zero_check(rise, settings.coverage, notes.append, log)
        widen = widener(post, rise, settings.coverage, notes.append, log)
    for f in pb.fixed:
        at = np.array([post.pos[j] for j in range(pb.starts[f], pb.starts[f + 1])])
        n, g = read_block(pb.feature_cands[f], *post.block(pb.starts[f], pb.starts[f + 1]), settings.coverage,
                          None if check is None else lambda span, name, at=at: check(at[span], name),
                          None if widen is None else lambda eff, c, span, at=at: widen(eff, c, at[span]))
        named, groups = named + n, groups + g
    n, g = read_named(pb, post, settings.coverage, check, widen)
    return Minimum(label, theta, b_m, te, sigma, stopped, named + n, groups + g, notes,
                   {"b_r": b_r, "X": X, "r": r})


def estimate(pb, settings, theta: np.ndarray, J0: np.ndarray, scales: tuple, pool, log, t0: float,
             rms_before: float, start) -> CalibrationResult:
    """The tolerance-prior estimate (see the module docstring) from ``theta`` (the always-estimated block's own
    MAP, ``J0`` the model's columns there); ``scales`` the prior scales of the solved and the reading parameters;
    ``start`` the clock. With ``settings.half_turn``, the search again from the half-turn image of its end and
    one answer over both ends (:mod:`rvcalib.arrangements`)."""
    ts, tr = scales
    model = _Counted(pb.model, J0)
    model.jacobians = 1                                 # J0, the first linearisation
    n_s = model.n_params
    sd = prior_sd(pb, ts, tr)
    a_r = measurement_columns(pb)
    sigma0 = max(float(pb.dataset.noise_arcsec()), 1e-3)
    ends = [_minimum(pb, settings, model, "start", theta, a_r, sd, sigma0, pool, log, J0)]
    image = half_turn_image(model.candidates, ends[0].theta, pb.dataset.design.crank_angles_deg) \
        if settings.half_turn else None
    if image is not None:
        ends.append(_minimum(pb, settings, model, "half-turn image", image, a_r, sd, sigma0, pool, log))
    answer = combine(ends, lambda m, s: criterion(pb, a_r, sd, np.concatenate([m.theta, m.b_m]), m.te, s),
                     settings.coverage)
    best = answer.best
    named, groups, notes = answer.named, answer.groups, answer.notes
    stops = {m.stopped for m in answer.kept}
    stopped = "no_columns" if "no_columns" in stops else \
        "converged" if stops == {"converged"} else "max_linearisations"
    if stopped == "converged":
        model.te(best.theta)                            # the MAP's states again, after the other evaluations
    else:
        notes.append(unconverged_note(len(named), len(groups), settings.max_linearisations, stopped))
        named, groups = [], []
    X, r = best.extra["X"], best.extra["r"]
    U, sv, _ = np.linalg.svd(X, full_matrices=False)
    Q = U[:, sv > sv[0] * 1e-10]
    unexplained, b_e = _unexplained(pb, r, Q, sd[n_s:], settings.coverage)
    return assemble_common(pb, best.theta, best.te, best.extra["b_r"] + b_e, named, groups, unexplained, [],
                           best.sigma, settings,
                           {"rms_before": rms_before, "stopped_by": stopped, "cap_binds": False,
                            "seconds": start() - t0, "linearisations": model.jacobians, "notes": notes})


def rise_function(pb, model, a_r: np.ndarray, sd: np.ndarray, post: Posterior, te: np.ndarray, sigma: float):
    """``rise(k, values)``: the criterion, through the model, at the point of the linear posterior ``post`` (at the
    MAP, ``te`` its model TE, ``sigma`` the noise) where the parameters at positions ``k`` take ``values`` and
    every other its posterior mean given that (within its bounds), less the MAP's; None where the model cannot be
    evaluated there. That point's criterion bounds from above the least criterion with those values (the profile),
    so a rise below the chi-square quantile puts the values inside the likelihood-ratio region."""
    n_s = model.n_params
    lo, hi = search_bounds(model, a_r)
    phi = criterion(pb, a_r, sd, post.mean, te, sigma)

    def rise(k: np.ndarray, values: np.ndarray) -> float | None:
        x = post.mean + post.cov[:, k] @ np.linalg.solve(post.cov[np.ix_(k, k)], values - post.mean[k])
        x = np.clip(x, lo, hi)
        x[k] = values
        try:
            return criterion(pb, a_r, sd, x, model.te(x[:n_s]), sigma) - phi
        except ModelEvaluationError:
            return None

    return rise


def zero_check(rise_at, level: float, note, log=None):
    """The check, through the model, of a region that excludes zero: ``check(positions, name)`` for the
    parameters at ``positions`` of the posterior whose :func:`rise_function` is ``rise_at``.

    It evaluates the criterion at the point of the linear posterior where those parameters are zero (every other
    at its posterior mean given that, within its bounds). That point's criterion bounds from above the least
    criterion with them at zero (the profile at zero), so when it exceeds the MAP's by less than the chi-square
    quantile of ``level`` (Wilks' likelihood-ratio region, S. S. Wilks, Ann. Math. Statist. 9 (1938) 60-62),
    zero is inside the region through the model, whatever Laplace's ellipse says: the candidate is refused
    (``False``) and ``note`` told why. A rise at or above the quantile leaves Laplace's verdict (the profile could
    still be lower); so could a point the model cannot evaluate. ``log``, where given, is told every rise.
    Where the model is linear the rise is the ellipse's ``d^2`` itself and nothing changes; where it bends (a
    response even in a parameter, a contact that opens) a tight ellipse can exclude a zero the data do not."""

    def check(positions: list, name: str) -> bool:
        k = np.asarray(positions, dtype=int)
        rise = rise_at(k, np.zeros(k.size))
        if rise is None:
            return True
        limit = float(stats.chi2.ppf(level, k.size))
        if log is not None:
            log(f"{name}: the criterion with it at zero is {rise:.4g} above the MAP's (chi-square quantile "
                f"{limit:.3g})")
        if rise >= limit:
            return True
        note(f"{name} is not named: its {level:.0%} region excludes zero, but through the model the criterion with "
             f"it at zero (the others at their posterior given that) is only {rise:.3g} above the MAP's, below the "
             f"chi-square quantile {limit:.3g}: the data do not tell it from zero")
        return False

    return check


def unconverged_note(n_named: int, n_groups: int, max_linearisations: int, stopped: str = "max_linearisations") \
        -> str:
    """Why a search stopped before its stop rule held names nothing: Laplace's approximation is the posterior's at
    its mode, and a state where the last step still moved the model TE or lowered the criterion beyond the stop
    rule's bounds (:func:`map_estimate`) is not known to be one, so the regions read there (``n_named`` effects,
    ``n_groups`` groups) are not the posterior's and can exclude the truth however tight they are. ``stopped``:
    ``max_linearisations`` (the cap) or ``no_columns`` (the model's columns could not be computed)."""
    if stopped == "no_columns":
        return ("no effect is named: the reducer model's columns could not be computed at a state the search "
                "reached (a perturbed case rvdyn cannot solve), so the search stopped before its stop rule held and "
                "its state is not known to be the criterion's minimum; the fit is the state where it stopped, its "
                "noise and unexplained structure read on the last columns computed")
    return (f"no effect is named: the search stopped after {max_linearisations} linearisations before its stop "
            f"rule held, so its state is not known to be the criterion's minimum and the 95 % regions read there "
            f"({n_named} effects and {n_groups} groups excluded zero) are not the posterior's; the fit is the state "
            f"where it stopped. Raise max_linearisations (rv-calibrate --max-linearisations) to go on")
