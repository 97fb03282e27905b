"""The chord Gauss-Newton's stop (rvcalib.lsq.chord_fit): a fit judged by the BIC does not stop at its
iteration cap while its last step still moves the BIC by more than BIC_CONVERGED (no rvdyn)."""
from __future__ import annotations

import math

import numpy as np

from rvcalib.lsq import BIC_CONVERGED, chord_fit

N = 200
NOISE = np.random.default_rng(0).normal(0.0, 0.1, N)


def fun(x: np.ndarray) -> np.ndarray:
    # Gauss-Newton on exp from far off moves about one unit per step: slow but steady
    return np.full(N, math.exp(float(x[0])) - 1.0) + NOISE


def counted():
    calls = []

    def f(x):
        calls.append(float(x[0]))
        return fun(x)
    return f, calls


def test_iteration_cap_stops_a_fit_not_judged_by_bic() -> None:
    f, calls = counted()
    x, r, _, nfev = chord_fit(f, np.array([20.0]), np.array([-50.0]), np.array([50.0]), max_iter=8)
    assert x[0] > 5.0            # far from the minimum (x = 0): stopped by the cap
    assert nfev <= 1 + 1 + 8 * 5


def test_fit_judged_by_bic_goes_on_while_it_moves_the_bic() -> None:
    f, calls = counted()
    x8, r8, _, _ = chord_fit(fun, np.array([20.0]), np.array([-50.0]), np.array([50.0]), max_iter=8)
    x, r, _, nfev = chord_fit(f, np.array([20.0]), np.array([-50.0]), np.array([50.0]), max_iter=8, bic_n=N)
    assert float(r @ r) < float(r8 @ r8)
    assert x[0] < x8[0] - 4.0    # up to 8 more steps of about one unit
    # at most as many iterations again
    assert nfev <= 1 + 1 + 16 * 5


def test_converged_fit_is_not_extended() -> None:
    # started at the minimum's neighbourhood the fit stops by its own tolerance, bic_n or not
    a = chord_fit(fun, np.array([0.05]), np.array([-50.0]), np.array([50.0]), max_iter=8)
    b = chord_fit(fun, np.array([0.05]), np.array([-50.0]), np.array([50.0]), max_iter=8, bic_n=N)
    assert a[3] == b[3]
    np.testing.assert_allclose(a[0], b[0])
    rss = float(b[1] @ b[1])
    assert N * math.log(rss / float(NOISE @ NOISE)) < BIC_CONVERGED
