"""Design generation: run counts, published BBD tables, CCD alpha, 3^k, balance, rotatability."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rsm
from rsm.design import BBD_BLOCKS
from rsm.terms import model_matrix, parse_terms
from rvpaper import DATA_DIR as PAPER_DATA

DATA = PAPER_DATA
BBD_RUNS = {3: 12, 4: 24, 5: 40, 6: 48, 7: 56}


def _fourth_moments(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sum x_i^4 per factor and sum x_i^2 x_j^2 per pair."""
    k = X.shape[1]
    pure = np.sum(X**4, axis=0)
    mixed = np.array([np.sum(X[:, i] ** 2 * X[:, j] ** 2) for i, j in itertools.combinations(range(k), 2)])
    return pure, mixed


@pytest.mark.parametrize("k", [3, 4, 5, 6, 7])
@pytest.mark.parametrize("center", [0, 1, 3, 6])
def test_bbd_run_counts(k, center):
    d = rsm.box_behnken(k, center=center)
    assert d.n_runs == BBD_RUNS[k] + center
    X = d.matrix()
    assert int(np.sum(np.all(X == 0, axis=1))) == center
    assert set(np.unique(X)) <= {-1.0, 0.0, 1.0}
    assert (d.coded["point_type"] == "center").sum() == center


@pytest.mark.parametrize("k", [3, 4, 5, 6, 7])
def test_bbd_balance_orthogonality_and_estimability(k):
    X = rsm.box_behnken(k, center=3).matrix()
    edge = X[~np.all(X == 0, axis=1)]
    nonzero = np.count_nonzero(edge, axis=1)
    assert set(nonzero) == {2 if k <= 5 else 3}
    # every factor at +1 and -1 equally often, and equally often across factors
    plus = np.sum(X == 1, axis=0)
    minus = np.sum(X == -1, axis=0)
    assert np.all(plus == minus) and len(set(plus)) == 1
    # main-effect and two-factor-interaction columns mutually orthogonal
    monos = parse_terms("2fi", [f"x{i}" for i in range(k)])[1:]
    M = model_matrix(X, monos)
    G = M.T @ M
    assert np.allclose(G - np.diag(np.diag(G)), 0.0)
    # the full quadratic is estimable
    Q = model_matrix(X, parse_terms("quadratic", [f"x{i}" for i in range(k)]))
    assert np.linalg.matrix_rank(Q) == Q.shape[1]


def test_bbd_seven_factor_blocks_form_a_balanced_incomplete_block_design():
    pairs = [p for block in BBD_BLOCKS[7] for p in itertools.combinations(block, 2)]
    assert len(pairs) == 21 and len(set(pairs)) == 21  # every pair exactly once
    counts = np.bincount([f for block in BBD_BLOCKS[6] for f in block])[1:]
    assert counts.tolist() == [3] * 6  # six-factor table: each factor in three blocks


@pytest.mark.parametrize("k,rotatable", [(3, False), (4, True), (5, False), (6, False), (7, True)])
def test_bbd_rotatability_matches_the_literature(k, rotatable):
    # Box and Behnken: the 4- and 7-factor designs are rotatable, the others are not
    X = rsm.box_behnken(k, center=0).matrix()
    pure, mixed = _fourth_moments(X)
    # odd moments vanish
    assert np.allclose(X.sum(axis=0), 0) and np.allclose((X**3).sum(axis=0), 0)
    is_rot = np.allclose(pure, 3 * mixed[0]) and np.allclose(mixed, mixed[0]) and len(set(pure)) == 1
    assert is_rot == rotatable


@pytest.mark.parametrize("k", [2, 3, 4, 5, 6])
def test_ccd_rotatable_alpha_and_moments(k):
    d = rsm.central_composite(k, center=5, alpha="rotatable")
    assert d.alpha == pytest.approx((2**k) ** 0.25)
    assert d.n_runs == 2**k + 2 * k + 5
    X = d.matrix()
    ax = X[d.coded["point_type"].to_numpy() == "axial"]
    assert np.allclose(np.max(np.abs(ax), axis=1), d.alpha)
    pure, mixed = _fourth_moments(X)
    assert np.allclose(pure[:, None], 3 * mixed[None, :])  # rotatability condition
    assert np.allclose(X.T @ X, np.diag(np.diag(X.T @ X)))  # orthogonal main effects
    Q = model_matrix(X, parse_terms("quadratic", [f"x{i}" for i in range(k)]))
    assert np.linalg.matrix_rank(Q) == Q.shape[1]


def test_ccd_face_centred_and_given_alpha():
    d = rsm.central_composite(3, center=2, alpha="face")
    assert d.alpha == 1.0
    assert set(np.unique(d.matrix())) == {-1.0, 0.0, 1.0}
    X = d.matrix()
    pure, mixed = _fourth_moments(X)
    assert not np.allclose(pure[:, None], 3 * mixed[None, :])  # face-centred: not rotatable
    assert rsm.central_composite(2, alpha=1.5).alpha == 1.5
    with pytest.raises(ValueError, match="alpha"):
        rsm.central_composite(3, alpha="spherical-ish")


@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_full_factorial_3k(k):
    d = rsm.full_factorial_3(k)
    X = d.matrix()
    assert d.n_runs == 3**k
    assert len({tuple(r) for r in X}) == 3**k
    for j in range(k):
        vals, counts = np.unique(X[:, j], return_counts=True)
        assert vals.tolist() == [-1.0, 0.0, 1.0] and counts.tolist() == [3 ** (k - 1)] * 3
    assert np.allclose(X.T @ X, np.diag(np.diag(X.T @ X)))
    assert rsm.full_factorial_3(k, center=3).n_runs == 3**k + 2


def test_randomised_order_is_seeded_permutation():
    a = rsm.box_behnken(4, center=3, randomize=True, seed=11)
    b = rsm.box_behnken(4, center=3, randomize=True, seed=11)
    c = rsm.box_behnken(4, center=3, randomize=True, seed=12)
    s = rsm.box_behnken(4, center=3)
    pd.testing.assert_frame_equal(a.coded, b.coded)
    assert not a.coded["std_order"].equals(c.coded["std_order"])
    assert a.coded["run"].tolist() == list(range(1, 28))
    assert sorted(a.coded["std_order"]) == list(range(1, 28))
    assert not np.array_equal(a.matrix(), s.matrix())
    back = a.coded.sort_values("std_order")[s.factors].to_numpy()
    assert np.array_equal(back, s.matrix())
    assert a.seed == 11 and s.seed is None


def test_design_actual_units_from_table5():
    lv = rsm.Levels.from_csv(DATA / "paper_table5_levels.csv")
    d = rsm.box_behnken(4, center=3, levels=lv)
    assert d.factors == ["EA", "EB", "EC", "ED"]
    act = d.actual()
    assert sorted(act["EA"].unique()) == pytest.approx([-0.06, 0.0, 0.06])
    assert sorted(act["EC"].unique()) == pytest.approx([-7.0, 0.0, 7.0])
    both = d.to_frame("both")
    assert "EA_actual" in both and both["EA"].abs().max() == 1
    # the paper's Table 6 uses the same run set as our 4-factor BBD with 3 centre points
    t6 = pd.read_csv(DATA / "paper_table6_bbd_runs.csv")[d.factors].to_numpy()
    assert sorted(map(tuple, t6)) == sorted(map(tuple, d.matrix()))
    ccd = rsm.central_composite(4, levels=lv)
    assert ccd.actual()["EA"].max() == pytest.approx(0.06 * 2.0)


def test_design_bad_requests():
    with pytest.raises(ValueError, match="3 to 7 factors"):
        rsm.box_behnken(8)
    with pytest.raises(ValueError, match="centre"):
        rsm.box_behnken(3, center=-1)
    with pytest.raises(ValueError, match="center must be >= 1"):
        rsm.full_factorial_3(2, center=0)
    with pytest.raises(ValueError, match="unknown design"):
        rsm.make_design("plackett", 3)
    lv = rsm.Levels.from_csv(DATA / "paper_table5_levels.csv")
    with pytest.raises(ValueError, match="no row for factor 'EZ'"):
        rsm.box_behnken(3, factors=["EA", "EB", "EZ"], levels=lv)
    with pytest.raises(ValueError, match="lists only 4"):
        rsm.box_behnken(5, levels=lv)
