"""The sparse estimator (rvcalib.sparse) against closed forms and on linear problems whose truth is known."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from rvcalib.result import Laplace, mixture_interval
from rvcalib.sparse import Features, SparseSettings, credible_sets, fit_sparse, single_effect


def _features(X, dims, prior=None):
    starts = np.r_[0, np.cumsum(dims)]
    return Features(X, starts, np.ones(len(dims)) if prior is None else prior)


def test_single_effect_bayes_factor_is_the_marginal_likelihood_ratio():
    """log BF of a block under N(0, V I) equals log N(y; 0, s2 I + V X X') - log N(y; 0, s2 I)."""
    rng = np.random.default_rng(1)
    n = 30
    X = rng.normal(size=(n, 3))
    y = X[:, 1:3] @ np.array([0.7, -0.4]) + 0.3 * rng.normal(size=n)
    F = _features(X, [1, 2], prior=np.array([0.5, 0.5]))
    s2, V = 0.09, 0.8
    e = single_effect(F, y, s2, V, 1e4)
    lbf = []
    for cols in ([0], [1, 2]):
        Xf = X[:, cols]
        cov = s2 * np.eye(n) + V * Xf @ Xf.T
        lbf.append(stats.multivariate_normal(np.zeros(n), cov).logpdf(y)
                   - stats.multivariate_normal(np.zeros(n), s2 * np.eye(n)).logpdf(y))
    lbf = np.array(lbf)
    assert e.log_bf == pytest.approx(math.log(0.5 * np.exp(lbf[0]) + 0.5 * np.exp(lbf[1])), rel=1e-9)
    assert e.alpha == pytest.approx(np.exp(lbf) / np.exp(lbf).sum(), rel=1e-9)
    # the posterior given the 2-column block: (X'X / s2 + I / V)^-1 X'y / s2
    Xf = X[:, 1:3]
    S = np.linalg.inv(Xf.T @ Xf / s2 + np.eye(2) / V)
    assert e.mean[1:3] == pytest.approx(S @ Xf.T @ y / s2, rel=1e-9)
    assert e.cov_of(F, 1) == pytest.approx(S, rel=1e-9)


def test_recovers_effects_and_groups_what_the_data_cannot_split():
    rng = np.random.default_rng(0)
    n = 600
    X = rng.normal(size=(n, 60))
    X[:, 1] = X[:, 0] + 0.02 * rng.normal(size=n)          # two columns the data cannot split
    b = np.zeros(60)
    b[0], b[10], b[30], b[31] = 0.8, -1.0, 0.5, -0.3         # features: 0, 10 and the 2-column block 30:32
    y = X @ b + 0.5 * rng.normal(size=n)
    dims = [1] * 30 + [2] + [1] * 28
    F = _features(X, dims)
    fit = fit_sparse(F, y)
    assert fit.converged
    assert math.sqrt(fit.sigma2) == pytest.approx(0.5, rel=0.1)
    sets = {tuple(sorted(cs.features)) for cs in credible_sets(F, fit) if cs.pure(SparseSettings())}
    assert sets == {(10,), (30,), (0, 1)}


def test_no_effect_in_noise_names_nothing():
    rng = np.random.default_rng(4)
    X = rng.normal(size=(300, 40))
    y = rng.normal(size=300)
    F = _features(X, [1] * 40)
    fit = fit_sparse(F, y)
    assert [cs for cs in credible_sets(F, fit) if cs.pure(SparseSettings())] == []


def test_elbo_does_not_decrease_over_sweeps():
    rng = np.random.default_rng(2)
    X = rng.normal(size=(200, 20))
    y = X[:, 3] - 0.5 * X[:, 7] + 0.4 * rng.normal(size=200)
    F = _features(X, [1] * 20)
    elbos = []
    fit = None
    for _ in range(6):
        fit = fit_sparse(F, y, SparseSettings(max_effects=5, max_iter=1), sigma2=0.16, fix_sigma2=True,
                         init=fit.effects if fit else None)
        elbos.append(fit.elbo)
    assert np.all(np.diff(elbos) >= -1e-8)


def test_intervals_cover_the_truth():
    """Over replicates of a problem whose truth is drawn from the prior, the 95 % intervals of the named
    coefficients cover the truth in about 95 % of cases (binomial: at least 88 % of 200)."""
    rng = np.random.default_rng(7)
    hit = tot = 0
    for _ in range(40):
        X = rng.normal(size=(150, 25))
        b = np.zeros(25)
        idx = rng.choice(25, 3, replace=False)
        b[idx] = rng.normal(0.0, 0.5, 3)
        y = X @ b + rng.normal(size=150)
        F = _features(X, [1] * 25)
        fit = fit_sparse(F, y, SparseSettings(max_effects=8))
        for cs in credible_sets(F, fit):
            if cs.size != 1 or not cs.pure(SparseSettings()):
                continue
            f = cs.features[0]
            e = fit.effects[cs.effect]
            lo, hi = mixture_interval(e.alpha[f], e.mean[f], math.sqrt(e.cov_of(F, f)[0, 0]))
            tot += 1
            hit += lo <= b[f] <= hi
    assert tot >= 60
    assert hit / tot >= 0.88


def test_mixture_interval_closed_forms():
    lo, hi = mixture_interval(1.0, 2.0, 0.5)
    assert (lo, hi) == pytest.approx((2.0 - 1.959964 * 0.5, 2.0 + 1.959964 * 0.5), rel=1e-6)
    lo, hi = mixture_interval(0.9, 3.0, 0.1)            # 10 % at zero: the lower end is 0
    assert lo == 0.0 and hi == pytest.approx(3.0 + 0.1 * stats.norm.ppf(1 - 0.025 / 0.9), rel=1e-6)


@pytest.mark.parametrize("field,value,match", [("max_effects", 0, "max_effects = 0"),
                                               ("coverage", 1.0, "coverage = 1.0"),
                                               ("min_purity", -0.1, "min_purity = -0.1")])
def test_settings_refused(field, value, match):
    with pytest.raises(ValueError, match=match):
        SparseSettings(**{field: value}).validate()


def test_laplace_takes_an_unchosen_look_alike_as_a_random_effect():
    """Chosen column x_a, unchosen x_b = x_a + small, background variance v of b: the chosen coefficient's variance
    is the closed form 1 / (x_a' (s2 I + v x_b x_b')^-1 x_a + 1 / p^2) (Sherman-Morrison), wider than without b."""
    rng = np.random.default_rng(3)
    n, s2, p2, v = 200, 0.04, 4.0, 0.5
    xa = rng.normal(size=n)
    xb = xa + 0.1 * rng.normal(size=n)
    X = np.column_stack([xa, xb])
    prior_sd = np.array([math.sqrt(p2), 1.0])
    tau = np.array([2.0, 1.0])                      # physical = scaled * tau
    lap = Laplace(X, np.array([0]), prior_sd, s2, np.array([0.3, 0.0]), tau, background=np.array([9.0, v]))
    c = xb @ xa
    quad = (xa @ xa - v * c ** 2 / (s2 + v * (xb @ xb))) / s2
    assert lap.block(0, 1)[1][0, 0] == pytest.approx(tau[0] ** 2 / (quad + 1 / p2), rel=1e-9)
    alone = Laplace(X, np.array([0]), prior_sd, s2, np.array([0.3, 0.0]), tau)
    assert alone.block(0, 1)[1][0, 0] == pytest.approx(tau[0] ** 2 / (xa @ xa / s2 + 1 / p2), rel=1e-9)
    assert lap.block(0, 1)[1][0, 0] > 10 * alone.block(0, 1)[1][0, 0]
