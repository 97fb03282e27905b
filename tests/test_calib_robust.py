"""The HAC sandwich of rvcalib.robust: Andrews' bandwidth in closed form, the floor at the white-noise information,
and the coverage it restores when the residual is correlated along the revolution."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcalib.result import Laplace
from rvcalib.robust import bandwidth, floored, lag1_correlation, score_covariance


def test_andrews_bandwidth_closed_form():
    # rho 0.5, T 100: alpha = 4 * 0.25 / (0.25 * 2.25) = 16 / 9; S = 1.1447 * (1600 / 9)^(1/3) = 6.43
    assert bandwidth(0.5, 100) == 6
    assert bandwidth(0.0, 100) == 0
    assert bandwidth(0.999, 50) == 49                       # never beyond the run


def test_lag1_correlation_does_not_cross_runs():
    r = np.r_[np.ones(5), -np.ones(5)]
    assert lag1_correlation(r, np.array([0, 5, 10])) == pytest.approx(4 / 5)
    assert lag1_correlation(r, np.array([0, 10])) == pytest.approx(7 / 10)


def test_floor_keeps_the_white_noise_information():
    G = np.array([[4.0, 1.0], [1.0, 2.0]])
    assert np.allclose(floored(0.5 * G, G), G)              # smaller: raised to G
    assert np.allclose(floored(3.0 * G, G), 3.0 * G)        # larger: kept


def _coverage(rho: float, sandwich: bool, reps: int = 300) -> float:
    rng = np.random.default_rng(7)
    n, s = 400, 0.2
    t = np.linspace(0, 2 * math.pi, n, endpoint=False)
    X = np.column_stack([np.sin(3 * t), np.cos(5 * t)])
    hits = 0
    for _ in range(reps):
        e = np.empty(n)
        e[0] = rng.normal(0, s)
        for i in range(1, n):
            e[i] = rho * e[i - 1] + math.sqrt(1 - rho ** 2) * rng.normal(0, s)
        y = X @ np.array([1.0, -0.5]) + e
        b = np.linalg.lstsq(X, y, rcond=None)[0]
        r = y - X @ b
        s2 = float(r @ r) / (n - 2)
        lap = Laplace(X, np.array([0, 1]), np.array([1e6, 1e6]), s2, b, np.ones(2),
                      residual=r if sandwich else None, offsets=np.array([0, n]))
        m, C = lap.block(0, 1)
        hits += abs(m[0] - 1.0) <= 1.96 * math.sqrt(C[0, 0])
    return hits / reps


def test_sandwich_restores_coverage_under_correlated_residuals():
    """AR(1) residuals with rho 0.9 (a structure along the revolution): the white-noise interval covers the truth
    far less than 95 %, the sandwich close to it; with white residuals both cover."""
    white, hac = _coverage(0.9, False), _coverage(0.9, True)
    assert white < 0.6 and hac > 0.85, (white, hac)
    assert _coverage(0.0, True) > 0.9


def test_score_covariance_of_white_residual_is_near_the_information():
    rng = np.random.default_rng(1)
    n, s2 = 4000, 0.04
    X = rng.normal(size=(n, 2))
    r = rng.normal(0, math.sqrt(s2), n)
    S = score_covariance(X / s2, r, np.array([0, 2000, 4000]))
    assert np.allclose(S, X.T @ X / s2, rtol=0.1, atol=0.1 * np.abs(X.T @ X / s2).max())
