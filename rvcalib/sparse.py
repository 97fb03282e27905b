"""Sparse Bayesian regression over grouped features: the sum of single effects (SuSiE).

The estimator of the loop, written for a linearised model ``y = X b + e`` with ``e ~ N(0, sigma^2 I)``. The
columns of ``X`` are grouped into *features*: a feature is one candidate of the library with one or more
parameters (a scalar error, the two components of an eccentricity, the cosine and sine of a harmonic). The
coefficients are sparse at the feature level: ``b = sum_l b_l``, each *single effect* ``b_l`` non-zero on one
feature only, the feature drawn with prior probabilities ``pi``, its coefficients ``N(0, V_l I)`` (the columns
come scaled by their prior scale, so one prior variance fits features of any unit).

Reference: G. Wang, A. Sarkar, P. Carbonetto and M. Stephens, "A simple new approach to variable selection in
regression, with application to genetic fine mapping", J. R. Statist. Soc. B 82 (2020) 1273-1300 (SuSiE), with
the single-effect regression generalised to blocks of columns (the Bayes factor of a block under a Gaussian prior
is closed form, as for one column). The criterion is the evidence lower bound (ELBO) of the variational
posterior ``q(b_1) ... q(b_L)``; the search is the iterative Bayesian stepwise selection (IBSS: coordinate ascent
on the ELBO, one effect at a time); the prior variance ``V_l`` of each effect (by an expectation-maximisation step
within each update) and the noise variance are fitted by maximising the same ELBO (empirical Bayes). An effect the data do not support ends with ``V_l = 0``: the
number of effects is the data's, ``L`` only caps it.

What the data cannot split is read from the posterior, not decided by a threshold on a difference: the level-
``coverage`` credible set of an effect is the smallest set of features holding that share of its posterior
inclusion probability; a set of one feature names it, a larger set is a group of candidates that explain the same
part of the data (with the size each member would have), and a set whose members do not explain the same signal
(purity: the smallest absolute correlation of the members' fitted signals below ``min_purity``) is diffuse and
names nothing.

Plain numpy; no reducer knowledge.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class SparseSettings:
    """Hyperparameters of :func:`fit_sparse` (validated by :meth:`validate`).

    Attributes
    ----------
    max_effects : int
        L, the most single effects (a cap: unused effects end with prior variance 0).
    coverage : float
        Level of the credible sets (0.95).
    min_purity : float
        Smallest absolute correlation between the fitted signals of a credible set's members for the set to be
        reported (0.5, as SuSiE's default).
    max_iter : int
        Most IBSS sweeps.
    tol : float
        Convergence: an ELBO change below ``tol`` (nats) between sweeps.
    max_prior_variance : float
        Largest prior variance of an effect, in units of the features' prior scales squared (a feature many
        times its tolerance class is not plausible; bounds the empirical-Bayes search).
    """

    max_effects: int = 30
    coverage: float = 0.95
    min_purity: float = 0.5
    max_iter: int = 200
    tol: float = 1e-3
    max_prior_variance: float = 1e4

    def validate(self) -> None:
        """ValueError naming the field, its value and what is allowed."""
        checks = [("max_effects", isinstance(self.max_effects, int) and 1 <= self.max_effects <= 1000,
                   "an integer in 1..1000"),
                  ("coverage", 0.5 <= self.coverage < 1.0, "a number in [0.5, 1)"),
                  ("min_purity", 0.0 <= self.min_purity <= 1.0, "a number in [0, 1]"),
                  ("max_iter", isinstance(self.max_iter, int) and self.max_iter >= 1, "an integer >= 1"),
                  ("tol", self.tol > 0, "a number > 0"),
                  ("max_prior_variance", self.max_prior_variance > 0, "a number > 0")]
        for name, ok, allowed in checks:
            if not ok:
                raise ValueError(f"{name} = {getattr(self, name)!r} is not allowed: {allowed}")


@dataclass
class Features:
    """The design matrix cut into features.

    Attributes
    ----------
    X : (n, P) ndarray
        Columns, scaled (a unit coefficient is the feature's prior scale).
    starts : (F + 1,) int ndarray
        Feature f holds columns ``starts[f]:starts[f + 1]``.
    prior : (F,) ndarray
        Prior inclusion probabilities (sum 1).
    """

    X: np.ndarray
    starts: np.ndarray
    prior: np.ndarray
    _blocks: dict = field(default_factory=dict, repr=False)
    _gram: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self.X = np.asarray(self.X, dtype=float)
        self.starts = np.asarray(self.starts, dtype=int)
        p = np.asarray(self.prior, dtype=float)
        if self.starts[0] != 0 or self.starts[-1] != self.X.shape[1] or np.any(np.diff(self.starts) < 1):
            raise ValueError("starts must run from 0 to the column count in increasing steps")
        if p.shape != (self.n_features,) or np.any(p < 0) or not p.sum() > 0:
            raise ValueError(f"prior must be {self.n_features} non-negative weights, not all zero")
        self.prior = p / p.sum()
        self._eig()

    @property
    def n_features(self) -> int:
        return self.starts.size - 1

    @property
    def dims(self) -> np.ndarray:
        return np.diff(self.starts)

    def _eig(self) -> None:
        """Per feature the eigen-decomposition of its Gram block, grouped by block size (vectorised)."""
        for d in np.unique(self.dims):
            idx = np.nonzero(self.dims == d)[0]
            cols = self.starts[idx][:, None] + np.arange(d)[None, :]
            Xc = self.X[:, cols]                                        # (n, F_d, d)
            A = np.einsum("nfi,nfj->fij", Xc, Xc)
            lam, Q = np.linalg.eigh(A)
            self._blocks[int(d)] = (idx, cols, np.maximum(lam, 0.0), Q)
            self._gram[int(d)] = A


@dataclass
class SingleEffect:
    """The variational posterior of one single effect.

    Attributes
    ----------
    alpha : (F,) posterior inclusion probability of each feature
    mean : (P,) posterior mean of the coefficients given their feature is the one
    cov : dict d -> (F_d, d, d), the posterior covariance given the feature, per block size (the order of
        ``Features._blocks[d]``)
    prior_variance : float, V_l (0: the effect is not supported)
    log_bf : float, log of the effect's Bayes factor against no effect
    """

    alpha: np.ndarray
    mean: np.ndarray
    cov: dict
    prior_variance: float
    log_bf: float

    def coef(self, F: Features) -> np.ndarray:
        """Posterior mean of the coefficients b_l (P,)."""
        return np.repeat(self.alpha, F.dims) * self.mean

    def cov_of(self, F: Features, f: int) -> np.ndarray:
        """The posterior covariance (d, d) of feature f's coefficients given that f is the effect's feature."""
        d = int(F.dims[f])
        idx = F._blocks[d][0]
        return self.cov[d][int(np.searchsorted(idx, f))]

    @classmethod
    def null(cls, F: Features) -> "SingleEffect":
        """No effect: prior variance 0, inclusion probabilities the prior's."""
        cov = {d: np.zeros((idx.size, d, d)) for d, (idx, *_) in F._blocks.items()}
        return cls(F.prior.copy(), np.zeros(F.X.shape[1]), cov, 0.0, 0.0)


def _ser_terms(F: Features, c: np.ndarray, s2: float, V: float):
    """Per block size: log Bayes factors (F_d,) and the posterior in each block's eigenbasis, for prior variance V."""
    out = {}
    for d, (idx, cols, lam, Q) in F._blocks.items():
        ct = np.einsum("fij,fi->fj", Q, c[cols])                    # c in each block's eigenbasis
        if V <= 0:
            lbf = np.zeros(idx.size)
            post = np.zeros_like(ct)
            var = np.zeros_like(lam)
        else:
            den = s2 + V * lam
            lbf = np.sum(-0.5 * np.log1p(V * lam / s2) + 0.5 * ct ** 2 * V / (s2 * den), axis=1)
            var = V * s2 / den                                        # posterior variances in the eigenbasis
            post = var * ct / s2
        out[d] = (idx, cols, Q, lbf, post, var)
    return out


def single_effect(F: Features, r: np.ndarray, s2: float, V: float | None, v_max: float,
                  v_start: float = 0.0, prior: np.ndarray | None = None) -> SingleEffect:
    """Bayesian single-effect regression of ``r`` on the features.

    ``V`` given: the posterior for that prior variance. ``V`` None: empirical Bayes by one expectation-maximisation
    step from ``v_start`` (or from one prior scale squared when the effect was null): the posterior at the start,
    then ``V = E[beta' beta] / d`` under it (the maximiser of the expected log prior; the ELBO does not decrease),
    and no effect (V = 0) where the single-effect model's evidence at that V does not exceed no effect's.
    ``prior``: inclusion probabilities other than the features'."""
    prior = F.prior if prior is None else prior
    c = F.X.T @ r
    if V is not None:
        return _posterior(F, c, s2, float(V), prior)
    e = _posterior(F, c, s2, v_start if v_start > 0 else 1.0, prior)
    second = 0.0
    for d, (idx, cols, _, _) in F._blocks.items():
        m = e.mean[cols]
        second += float(e.alpha[idx] @ ((np.sum(m * m, axis=1) + np.einsum("fii->f", e.cov[d])) / d))
    V = min(max(second, 1e-12), v_max)
    out = _posterior(F, c, s2, V, prior)
    return out if out.log_bf > 0.0 else _posterior(F, c, s2, 0.0, prior)


def _posterior(F: Features, c: np.ndarray, s2: float, V: float, prior: np.ndarray) -> SingleEffect:
    """The single effect's posterior for prior variance V, from ``c = X' r``."""
    mean = np.zeros(F.X.shape[1])
    cov = {}
    lbf = np.zeros(F.n_features)
    for d, (idx, cols, Q, l, post, var) in _ser_terms(F, c, s2, V).items():
        lbf[idx] = l
        mean[cols] = np.einsum("fij,fj->fi", Q, post)
        cov[d] = np.einsum("fij,fj,fkj->fik", Q, var, Q)
    w = np.where(prior > 0, np.log(np.maximum(prior, 1e-300)), -np.inf) + lbf
    m = w.max()
    alpha = np.exp(w - m)
    tot = alpha.sum()
    alpha /= tot
    log_bf = float(m + math.log(tot)) if V > 0 else 0.0
    return SingleEffect(alpha, mean, cov, float(V), log_bf)


def _second_moment(F: Features, e: SingleEffect) -> float:
    """E[b_l' X'X b_l] under q(b_l): sum_f alpha_f (tr(A_f S_f) + m_f' A_f m_f)."""
    tot = 0.0
    for d, (idx, cols, _, _) in F._blocks.items():
        A = F._gram[d]
        m = e.mean[cols]
        tr = np.einsum("fij,fij->f", A, e.cov[d])
        quad = np.einsum("fi,fij,fj->f", m, A, m)
        tot += float(e.alpha[idx] @ (tr + quad))
    return tot


@dataclass
class SparseFit:
    """The result of :func:`fit_sparse`.

    Attributes
    ----------
    effects : list of SingleEffect
    sigma2 : float, the noise variance (units of y squared)
    elbo : float, the evidence lower bound (nats)
    iterations : int
    converged : bool
    coef : (P,) posterior mean of b
    coef_var : (P,) posterior variance of each coefficient (sum over effects)
    """

    effects: list
    sigma2: float
    elbo: float
    iterations: int
    converged: bool
    coef: np.ndarray
    coef_var: np.ndarray

    @property
    def n_supported(self) -> int:
        """Effects with a prior variance above 0 (the data's number of effects)."""
        return sum(1 for e in self.effects if e.prior_variance > 0)


def _elbo(F: Features, y: np.ndarray, effects: list, s2: float) -> tuple[float, float]:
    """ELBO (nats) and the expected residual sum of squares.

    ELBO = E_q log p(y | b) - sum_l KL(q_l || p_l), with each KL from the single-effect identity
    KL_l = E_q log p(r_l | b_l) - log p(r_l) (r_l the residual without effect l, p(r_l) its evidence).
    """
    n = y.size
    fits = [F.X @ e.coef(F) for e in effects]
    res = y - sum(fits)
    second = [_second_moment(F, e) for e in effects]
    erss = float(res @ res) + sum(s - float(f @ f) for s, f in zip(second, fits))
    c0 = -0.5 * n * (LOG_2PI + math.log(s2))
    kl = 0.0
    for e, f, s in zip(effects, fits, second):
        r_l = res + f
        e_ll = c0 - 0.5 / s2 * (r_l @ r_l - 2.0 * r_l @ f + s)
        kl += e_ll - (e.log_bf + c0 - 0.5 / s2 * (r_l @ r_l))
    return c0 - 0.5 * erss / s2 - kl, erss


def fit_sparse(F: Features, y: np.ndarray, settings: SparseSettings = SparseSettings(),
               sigma2: float | None = None, init: list | None = None, fix_sigma2: bool = False,
               fixed: tuple = ()) -> SparseFit:
    """Fit the sum of single effects to ``y`` by IBSS.

    ``fixed`` features are always in the model: each has an effect of its own with inclusion probability one and
    prior variance one (a Gaussian prior of its prior scale: ridge regression within the IBSS), fitted first; they
    are left out of the other effects. The effects of the fit are the fixed ones, then the ``max_effects`` others.

    Parameters
    ----------
    F : Features
    y : (n,) ndarray
    settings : SparseSettings
    sigma2 : float or None
        Start (or, with ``fix_sigma2``, the value) of the noise variance; default the variance of y.
    init : list of SingleEffect or None
        A previous fit's effects (a warm start; the same features).
    fix_sigma2 : bool
        Keep sigma2 as given.
    """
    settings.validate()
    y = np.asarray(y, dtype=float)
    n = y.size
    s2 = max(float(np.var(y)) if sigma2 is None else float(sigma2), 1e-30)
    L = settings.max_effects + len(fixed)
    effects = (list(init) if init else [])[:L]
    effects += [SingleEffect.null(F) for _ in range(L - len(effects))]
    priors: list = []
    for f in fixed:
        one = np.zeros(F.n_features)
        one[f] = 1.0
        priors.append(one)
    rest = F.prior.copy()
    rest[list(fixed)] = 0.0
    priors += [rest / rest.sum()] * settings.max_effects
    fit_total = F.X @ sum(e.coef(F) for e in effects)
    elbo_old = -math.inf
    converged = False
    it = elbo = 0
    for it in range(1, settings.max_iter + 1):
        null_seen = False
        for li, e in enumerate(effects):
            if li >= len(fixed) and e.prior_variance <= 0 and null_seen:
                continue                    # null effects see the same residual: one that stayed null speaks for all
            fit_total -= F.X @ e.coef(F)
            V = 1.0 if li < len(fixed) else None
            new = single_effect(F, y - fit_total, s2, V, settings.max_prior_variance, v_start=e.prior_variance,
                                prior=priors[li])
            effects[li] = new
            fit_total += F.X @ new.coef(F)
            null_seen |= li >= len(fixed) and new.prior_variance <= 0
        elbo, erss = _elbo(F, y, effects, s2)
        if not fix_sigma2:
            s2 = max(erss / n, 1e-30)
            elbo, _ = _elbo(F, y, effects, s2)
        if abs(elbo - elbo_old) < settings.tol:
            converged = True
            break
        elbo_old = elbo
    coef = sum(e.coef(F) for e in effects)
    var = np.zeros(F.X.shape[1])
    for e in effects:
        diag = np.zeros(F.X.shape[1])
        for d, (idx, cols, _, _) in F._blocks.items():
            diag[cols] = np.einsum("fii->fi", e.cov[d])
        a = np.repeat(e.alpha, F.dims)
        var += a * (diag + e.mean ** 2) - (a * e.mean) ** 2
    return SparseFit(effects, s2, float(elbo), it, converged, coef, var)


@dataclass
class CredibleSet:
    """The credible set of one single effect.

    Attributes
    ----------
    effect : int, index of the single effect
    features : list of int, the members (largest inclusion probability first)
    probabilities : list of float, their inclusion probabilities
    coverage : float, their sum
    purity : float, the smallest absolute correlation of the members' fitted signals
    log_bf : float, the effect's log Bayes factor against no effect
    """

    effect: int
    features: list
    probabilities: list
    coverage: float
    purity: float
    log_bf: float

    @property
    def size(self) -> int:
        return len(self.features)

    def pure(self, settings: SparseSettings) -> bool:
        """Its members explain the same signal (purity at least ``settings.min_purity``)."""
        return self.purity >= settings.min_purity


def credible_sets(F: Features, fit: SparseFit, settings: SparseSettings = SparseSettings()) -> list:
    """The credible set of every supported effect (prior variance above 0), with its purity.

    A set is *pure* when ``purity >= settings.min_purity``; effects whose sets hold the same features are
    reported as found more than once by the caller (their coefficients add).
    """
    out = []
    for li, e in enumerate(fit.effects):
        if e.prior_variance <= 0:
            continue
        order = np.argsort(-e.alpha, kind="stable")
        cum = np.cumsum(e.alpha[order])
        k = min(int(np.searchsorted(cum, settings.coverage)) + 1, order.size)
        members = [int(f) for f in order[:k]]
        purity = 1.0
        if len(members) > 1:
            sig = np.column_stack([F.X[:, F.starts[f]:F.starts[f + 1]] @ e.mean[F.starts[f]:F.starts[f + 1]]
                                   for f in members])
            nrm = np.linalg.norm(sig, axis=0)
            if np.all(nrm > 0):
                u = sig / nrm
                purity = float(np.abs(u.T @ u).min())
            else:
                purity = 0.0
        out.append(CredibleSet(li, members, [float(e.alpha[f]) for f in members], float(cum[k - 1]), purity,
                               e.log_bf))
    return out
