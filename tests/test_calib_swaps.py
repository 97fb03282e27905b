"""The swap move (rvcalib.swaps): every candidate's linearised change from one factorisation equals the direct
penalised refit of the swapped set, for single- and multi-column features; the fixed block never leaves."""
from __future__ import annotations

import numpy as np
import pytest

from rvcalib.swaps import feature_columns, features_of, penalised_fit, swap_table


def _problem(seed: int = 3):
    rng = np.random.default_rng(seed)
    n = 120
    starts = np.array([0, 3, 4, 5, 6, 8, 9, 10, 12])       # a 3-column fixed block, singles, two 2-column features
    X = rng.normal(size=(n, starts[-1]))
    X[:, 9] = 0.9 * X[:, 4] + 0.3 * rng.normal(size=n)     # a partial look-alike of feature 2's column
    c = np.zeros(starts[-1])
    c[[0, 1, 2, 4, 6, 7]] = [1.0, -2.0, 0.5, 3.0, 1.5, -1.0]
    z = X @ c + rng.normal(0.0, 0.4, n)
    return X, starts, z


def _direct(X, starts, z, feats, sigma) -> float:
    return penalised_fit(X[:, feature_columns(starts, feats)], z, sigma)[2]


def test_penalised_fit_is_the_ridge_solution():
    X, starts, z = _problem()
    Q, e, S, c = penalised_fit(X[:, :4], z, 0.5)
    want = np.linalg.solve(X[:, :4].T @ X[:, :4] / 0.25 + np.eye(4), X[:, :4].T @ z / 0.25)
    assert np.allclose(c, want)
    assert S == pytest.approx(np.sum((z - X[:, :4] @ want) ** 2) / 0.25 + np.sum(want ** 2))


@pytest.mark.parametrize("chosen", [(0, 2, 4), (0, 6, 3), (0, 1, 2, 4, 7)])
def test_every_swap_equals_the_direct_refit(chosen):
    X, starts, z = _problem()
    sigma = 0.4
    allowed = np.ones(len(starts) - 1, dtype=bool)
    table = swap_table(X, starts, z, chosen, allowed, sigma, fixed=(0,), most=20)
    S_A = _direct(X, starts, z, chosen, sigma)
    pairs = {(s.out, s.into) for s in table}
    want = {(f, g) for f in chosen if f != 0 for g in range(len(starts) - 1) if g not in chosen}
    assert pairs == want                                   # the fixed block never leaves, chosen ones never enter
    for s in table:
        swapped = [h for h in chosen if h != s.out] + [s.into]
        assert s.delta == pytest.approx(_direct(X, starts, z, swapped, sigma) - S_A, rel=1e-9, abs=1e-7)
    assert [s.delta for s in table] == sorted(s.delta for s in table)


def test_a_look_alike_in_the_set_is_swapped_for_the_truth_first():
    X, starts, z = _problem()
    table = swap_table(X, starts, z, (0, 4, 6), np.ones(8, dtype=bool), 0.4, fixed=(0,), most=2)
    assert (table[0].out, table[0].into) == (6, 2)          # feature 6 (column 9) looks like feature 2 (column 4)
    assert table[0].delta < -100.0


def test_features_of_columns():
    starts = np.array([0, 3, 4, 6])
    assert features_of(starts, np.array([5, 0, 2, 3])) == [0, 1, 2]
    assert list(feature_columns(starts, [2, 0])) == [4, 5, 0, 1, 2]
