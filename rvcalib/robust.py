"""Intervals that hold when the residual is not white: the heteroskedasticity- and autocorrelation-consistent
(HAC) sandwich of the chosen parameters' posterior.

Laplace's approximation (:class:`rvcalib.result.Laplace`) takes the residual as white noise of variance
``sigma^2``. A residual that still holds structure (an effect no candidate gives, a basin the fit has not left) is
correlated along the revolution, and its white-noise interval is too narrow by about the square root of the
residual's correlation length. The sandwich replaces the white-noise information ``X' W`` by the covariance of the
score ``sum_t w_t r_t`` that the residual itself shows (Newey and West, Econometrica 55 (1987) 703-708),
prewhitened by the residual's lag-1 correlation ``rho`` and recoloured (Andrews and Monahan, Econometrica 60 (1992)
953-966: without it the kernel estimate under-covers a strongly correlated residual), the remaining lags weighted by
the Bartlett kernel over the bandwidth of Andrews' AR(1) plug-in (Econometrica 59 (1991) 817-858, eq. 6.4 with
Table I's constant for the Bartlett kernel):

    alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2),   S = 1.1447 (alpha T)^(1/3)   (T readings of a run)

``rho`` of the prewhitening is held within +-0.97, which bounds the recolouring ``1 / (1 - rho)^2`` at about 1100.
Lags never cross from one run to the next. The score covariance is never taken below the white-noise one (its
eigenvalues relative to the white-noise information are floored at 1), so the sandwich only ever widens an interval:
a residual at the noise leaves Laplace's interval as it is.
"""
from __future__ import annotations

import numpy as np
from statsmodels.stats.sandwich_covariance import S_hac_simple, weights_bartlett

#: Andrews (1991), Table I: the Bartlett kernel's constant of the optimal bandwidth.
BARTLETT_C = 1.1447


def lag1_correlation(r: np.ndarray, offsets: np.ndarray) -> float:
    """The residual's lag-1 autocorrelation, pooled over the runs (``offsets``: run i is r[offsets[i]:offsets[i+1]])."""
    num = den = 0.0
    for a, b in zip(offsets[:-1], offsets[1:]):
        x = r[a:b]
        num += float(x[1:] @ x[:-1])
        den += float(x @ x)
    return num / den if den > 0 else 0.0


def bandwidth(rho: float, T: int) -> int:
    """Andrews' (1991) AR(1) plug-in bandwidth of the Bartlett kernel for T readings (whole lags, at most T - 1)."""
    rho = float(np.clip(rho, -0.999, 0.999))
    alpha = 4.0 * rho ** 2 / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    return int(min(T - 1, np.floor(BARTLETT_C * (alpha * T) ** (1.0 / 3.0))))


def score_covariance(W: np.ndarray, r: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """HAC covariance of the score ``sum_t W_t r_t`` (k, k), prewhitened (Andrews and Monahan, Econometrica 60
    (1992) 953-966): the scores of each run less ``rho`` times their predecessor, the Bartlett kernel over Andrews'
    bandwidth of what is left, recoloured by ``1 / (1 - rho)^2``; ``rho`` the residual's lag-1 correlation."""
    rho = float(np.clip(lag1_correlation(r, offsets), -0.97, 0.97))
    pre = np.concatenate([r[a + 1:b] - rho * r[a:b - 1] for a, b in zip(offsets[:-1], offsets[1:]) if b - a >= 2])
    cuts = np.cumsum([0] + [b - a - 1 for a, b in zip(offsets[:-1], offsets[1:]) if b - a >= 2])
    rho_left = lag1_correlation(pre, cuts)
    S = np.zeros((W.shape[1], W.shape[1]))
    for a, b in zip(offsets[:-1], offsets[1:]):
        if b - a < 3:
            continue
        u = W[a:b] * r[a:b, None]
        u = u[1:] - rho * u[:-1]
        S += S_hac_simple(u, nlags=bandwidth(rho_left, b - a - 1), weights_func=weights_bartlett)
    return S / (1.0 - rho) ** 2


def floored(S: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``S`` with its eigenvalues relative to the white-noise information ``G`` floored at 1 (on G's range): the
    score covariance never below what white noise gives."""
    lam, Q = np.linalg.eigh((G + G.T) / 2.0)
    keep = lam > 1e-12 * max(float(lam.max(initial=0.0)), 1e-300)
    if not keep.any():
        return S
    half = Q[:, keep] * np.sqrt(lam[keep])                  # G = half half'
    inv = Q[:, keep] / np.sqrt(lam[keep])
    R = inv.T @ S @ inv
    mu, V = np.linalg.eigh((R + R.T) / 2.0)
    Rf = (V * np.maximum(mu, 1.0)) @ V.T
    return half @ Rf @ half.T + (S - half @ R @ half.T)
