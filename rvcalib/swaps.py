"""The swap move of best-subset selection, ranked on the linearised model.

The loop's estimator proposes a chosen set from its posterior (:mod:`rvcalib.sparse`), and the union of that set
with the current one. Neither proposal can replace one chosen feature by another that the posterior has not put
forward: when a look-alike entered first (a half-turn alias on the other crank or disc, fitted at a size that
absorbs part of the true effect), the posterior at the next linearisation sees the residual the look-alike leaves
and nothing more. The swap neighbourhood of best-subset local search is the move that reaches it (Hazimeh and
Mazumder, "Fast best subset selection: coordinate descent and local combinatorial optimization algorithms",
Operations Research 68 (2020) 1517-1537, doi:10.1287/opre.2019.1919): take one feature ``f`` out of the chosen
set ``A`` and put one candidate ``g`` in its place.

On the linearised model ``z = X c + e`` (the features' scaled, projected columns: a unit coefficient is the
tolerance scale), the criterion's likelihood and prior terms are, to first order at ``sigma^2 = RSS / n``,

    S(T) = min_c |z - X_T c|^2 / sigma^2 + |c|^2,

and the price per parameter is the same before and after a swap of equal size. With ``B = A \\ f`` factorised once
(the QR decomposition of its design augmented by the prior's rows), every candidate's ``S(B + g)`` is a rank-``m``
update (``m`` its columns): ``S(B + g) = S(B) - u^T (G^T G + I)^{-1} u`` with ``u = X_g^T e_B / sigma`` and
``G`` the part of ``X_g / sigma`` outside ``B``'s augmented columns. The ranked swaps are proposals: the loop
tries the best through the reducer model and accepts one only where the criterion itself lowers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular


@dataclass(frozen=True)
class Swap:
    """One swap: feature ``out`` leaves the chosen set, feature ``into`` takes its place.

    Attributes
    ----------
    out, into : int
        Feature indices.
    delta : float
        Linearised change of the penalised chi-square, ``S(A - out + into) - S(A)`` (negative: better).
    """

    out: int
    into: int
    delta: float


def feature_columns(starts: np.ndarray, features) -> np.ndarray:
    """The column indices of the given features, in order."""
    feats = list(features)
    if not feats:
        return np.zeros(0, dtype=int)
    return np.concatenate([np.arange(starts[f], starts[f + 1]) for f in feats]).astype(int)


def features_of(starts: np.ndarray, columns: np.ndarray) -> list[int]:
    """The features that hold the given columns (each once, in increasing order)."""
    return sorted({int(f) for f in np.searchsorted(starts, np.asarray(columns), side="right") - 1})


def penalised_fit(X: np.ndarray, z: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """The penalised least squares of ``z`` on the columns ``X``: min |z - X c|^2 / sigma^2 + |c|^2.

    Returns
    -------
    (Q, e, S, c)
        The orthonormal basis of the augmented design ``[X / sigma; I]``, the augmented residual, its squared norm
        ``S`` and the coefficients.
    """
    n, k = X.shape
    A = np.vstack([X / sigma, np.eye(k)])
    b = np.concatenate([z / sigma, np.zeros(k)])
    if k == 0:
        return np.zeros((n, 0)), b, float(b @ b), np.zeros(0)
    Q, Rr = np.linalg.qr(A)
    qb = Q.T @ b
    e = b - Q @ qb
    return Q, e, float(e @ e), solve_triangular(Rr, qb)


def swap_table(X: np.ndarray, starts: np.ndarray, z: np.ndarray, chosen, allowed: np.ndarray, sigma: float,
               fixed=(), most: int = 3) -> list[Swap]:
    """The best swaps of each chosen feature on the linearised model, all candidates at once.

    Parameters
    ----------
    X : (n, P) the features' scaled, projected columns
    starts : (F + 1,) feature f holds columns ``starts[f]:starts[f + 1]``
    z : (n,) the linearised data (projected), so that ``z - X c`` is the current residual
    chosen : iterable of int, the features of the chosen set ``A``
    allowed : (F,) bool, the features that may enter
    sigma : the noise standard deviation the chi-square is taken at (same unit as ``z``)
    fixed : features that never leave (the always-estimated block)
    most : most swaps kept per chosen feature (the best first)

    Returns
    -------
    list of Swap
        Sorted by ``delta`` (best first).
    """
    chosen = sorted(set(int(f) for f in chosen))
    n = X.shape[0]
    _, _, S_A, _ = penalised_fit(X[:, feature_columns(starts, chosen)], z, sigma)
    cand = [g for g in np.nonzero(allowed)[0] if g not in chosen]
    if not cand:
        return []
    width = np.diff(starts)[cand]
    single = np.array([g for g, w in zip(cand, width) if w == 1], dtype=int)
    multi = [g for g, w in zip(cand, width) if w > 1]
    Gs = X[:, starts[single]] / sigma if single.size else np.zeros((n, 0))
    norm2 = np.sum(Gs ** 2, axis=0)
    out: list[Swap] = []
    for f in chosen:
        if f in fixed:
            continue
        B = [h for h in chosen if h != f]
        Q, e, S_B, _ = penalised_fit(X[:, feature_columns(starts, B)], z, sigma)
        Qn = Q[:n]
        en = e[:n]
        deltas, into = [], []
        if single.size:
            QG = Qn.T @ Gs
            u = Gs.T @ en                                   # e is orthogonal to Q: no correction
            gg = norm2 - np.sum(QG ** 2, axis=0)
            deltas.append(S_B - u ** 2 / (gg + 1.0) - S_A)
            into.append(single)
        for g in multi:
            G = X[:, starts[g]:starts[g + 1]] / sigma
            QG = Qn.T @ G
            u = G.T @ en
            M = G.T @ G - QG.T @ QG + np.eye(G.shape[1])
            deltas.append(np.array([S_B - float(u @ np.linalg.solve(M, u)) - S_A]))
            into.append(np.array([g]))
        d, g_all = np.concatenate(deltas), np.concatenate(into)
        for k in np.argsort(d, kind="stable")[:most]:
            out.append(Swap(int(f), int(g_all[k]), float(d[k])))
    return sorted(out, key=lambda s: s.delta)
