"""The best-subset arithmetic of the joint selection (rvcalib.joint) and its rules between physical and
empirical subsets: the margins, the batched subset least squares, the information criteria and weights, the
physical-first rule and the order in which subsets are tried. Plain numpy: no model, no rvdyn."""
from __future__ import annotations

from collections.abc import Iterator
import math

import numpy as np

from rvcalib.results import PoolMember, SubsetFit


#: The joint choice replaces the greedy one only when its BIC is lower by more than this (a BIC
#: difference below 2 is "not worth more than a bare mention", Kass and Raftery 1995): ties, e.g.
#: the members of an identifiability group (pin radius / pin circle diameter), keep the greedy choice.
JOINT_BIC_MARGIN = 2.0
#: When the best subset adds an empirical term (a constant, a harmonic) and the best subset without
#: one adds physical effects only, both are refitted through the nonlinear model and the empirical one
#: is taken only when its BIC on all samples is lower by more than this ("very strong" evidence,
#: Kass and Raftery 1995): outside-the-library structure is named last.
EMPIRICAL_BIC_MARGIN = 10.0
#: ... unless the physical subset removes at least this share of the residual sum of squares that the
#: empirical one removes (both refitted on all samples): then the physical subset is taken, and what it
#: leaves of the empirical term's structure is screened again at the new state (an offset made by a
#: disc phase and the pin circle diameter is not absorbed by a constant before they are tried).
PHYSICAL_SHARE = 0.9
#: The physical-first share applies while the empirical subset leaves an RMS above this many times
#: the noise (second differences of the residual), and always to a new harmonic.
EMPIRICAL_LEAVES_NOISE = 2.0
#: Subsets whose BIC differ by less than this are ties (twin instances: float noise of ~1e-10).
BIC_TIE = 1e-4


def pool_basis(pool: list[PoolMember], n: int) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """The pool's columns (n rows) side by side as ``Q R`` (reduced QR: Q (n, P) orthonormal, R (P, P)) and
    each member's column indices in them."""
    widths = [m.cols.shape[1] for m in pool]
    starts = np.cumsum([0] + widths)
    C = np.concatenate([m.cols for m in pool], axis=1) if pool else np.zeros((n, 0))
    Q, R = np.linalg.qr(C, mode="reduced")
    return Q, R, [np.arange(a, a + w) for a, w in zip(starts[:-1], widths)]


def subset_lstsq(R: np.ndarray, qt: np.ndarray, cols: list[np.ndarray | None],
                  rcond_rows: float) -> list[tuple[np.ndarray, float] | None]:
    """Least squares ``min |qt - R[:, c] x|`` for every column set ``c`` of ``cols`` (None: skipped), batched:
    the sets of one width are solved together by one stacked singular value decomposition, with the rank
    cut-off of :func:`numpy.linalg.lstsq` (singular values at most ``rcond`` times the largest count as zero;
    ``rcond = max(rcond_rows, eps * width)``: the caller passes ``eps`` times the rows the columns stand for,
    lstsq's default cut-off on them). Returns ``(x, |qt - R[:, c] x|^2)`` per set (x the minimum-norm
    solution); the same minimiser and rank as lstsq, to rounding."""
    out: list[tuple[np.ndarray, float] | None] = [None] * len(cols)
    by_width: dict[int, list[int]] = {}
    for j, c in enumerate(cols):
        if c is not None:
            by_width.setdefault(c.size, []).append(j)
    eps = np.finfo(float).eps
    for w, js in by_width.items():
        A = R[:, np.stack([cols[j] for j in js])].transpose(1, 0, 2)        # (B, P, w)
        U, sv, Vt = np.linalg.svd(A, full_matrices=False)
        rcond = max(rcond_rows, eps * w)
        keep = sv > rcond * sv[:, :1]
        inv = np.where(keep, 1.0 / np.where(keep, sv, 1.0), 0.0)
        x = np.einsum("bji,bj->bi", Vt, inv * np.einsum("bpj,p->bj", U, qt))
        res = qt[None, :] - np.einsum("bpw,bw->bp", A, x)
        rss = np.einsum("bp,bp->b", res, res)
        for k, j in enumerate(js):
            out[j] = (x[k], float(rss[k]))
    return out


def aic(rss: float, n: int, k: int) -> float:
    """Akaike information criterion of a Gaussian least-squares fit: ``n ln(rss/n) + 2 k``."""
    return n * math.log(max(rss, 1e-300) / n) + 2.0 * k


def physical_first(rss_model: float, rss_phys: float, dbic_phys: float, rss_emp: float, dbic_emp: float) -> bool:
    """Whether a physical subset goes before the subset with a new empirical term (both refitted through
    the nonlinear model on all samples and confirmed): it does when it removes at least
    :data:`PHYSICAL_SHARE` of the residual sum of squares the empirical one removes, or when the empirical
    one is not better by more than :data:`EMPIRICAL_BIC_MARGIN` BIC units.

    Parameters
    ----------
    rss_model : float
        Residual sum of squares of the present model, arcsec^2.
    rss_phys, rss_emp : float
        Of the physical subset and of the subset with the empirical term, arcsec^2.
    dbic_phys, dbic_emp : float
        Their BIC change from the present model.
    """
    gain_p, gain_e = rss_model - rss_phys, rss_model - rss_emp
    return gain_p >= PHYSICAL_SHARE * gain_e or dbic_emp >= dbic_phys - EMPIRICAL_BIC_MARGIN


def physical_goes_first(rss_model: float, rss_phys: float, dbic_phys: float, rss_emp: float, dbic_emp: float,
                        n: int, noise2: float, harmonic: bool) -> bool:
    """The joint step's choice between a physical subset and one with a new empirical term (both confirmed):
    :func:`physical_first` while the empirical subset leaves an RMS above :data:`EMPIRICAL_LEAVES_NOISE` times
    the noise (``noise2``, arcsec^2 per sample, over ``n`` samples; where the noise level decides, the joint step
    passes the least estimate of the present residual's and the refitted subsets',
    :meth:`JointSelection._subset_noise2`) and always when the new term is a harmonic
    (the greedy step's rule too: physical signatures span several orders, so only a constant, e.g. an encoder
    zero offset beside a compliance, may win on the BIC margin alone; seed 1 serial: an order-79 harmonic at
    1.15x the noise took the slot of a physical subset that removed 95 % of its part); otherwise the empirical
    subset must be better by more than :data:`EMPIRICAL_BIC_MARGIN`."""
    if harmonic or rss_emp / n > EMPIRICAL_LEAVES_NOISE ** 2 * noise2:
        return physical_first(rss_model, rss_phys, dbic_phys, rss_emp, dbic_emp)
    return dbic_emp >= dbic_phys - EMPIRICAL_BIC_MARGIN


def model_weights(values: np.ndarray) -> np.ndarray:
    """Akaike / Schwarz model weights ``exp(-(v - min v) / 2)`` normalised to sum 1."""
    v = np.asarray(values, dtype=float)
    w = np.exp(-0.5 * (v - v.min()))
    return w / w.sum()


def tie_order(fits: list[SubsetFit], rank: list[int]) -> Iterator[SubsetFit]:
    """The fits in the order of ``(round(bic / BIC_TIE), sorted library ranks of their members)``, stable (equal keys
    keep their order in ``fits``), made lazily: the BIC classes in ascending order (one stable argsort), each sorted by
    the ranks when it is reached (the caller stops at the first fit it accepts, mostly in the first few classes)."""
    if not fits:
        return
    prim = np.round(np.array([f.bic for f in fits], dtype=float) / BIC_TIE)
    order = np.argsort(prim, kind="stable")
    ps = prim[order]
    starts = np.flatnonzero(np.r_[True, ps[1:] != ps[:-1]])
    ends = np.r_[starts[1:], ps.size]
    for a, b in zip(starts, ends):
        group = [fits[j] for j in order[a:b]]
        if len(group) > 1:
            group.sort(key=lambda f: tuple(sorted(rank[i] for i in f.members)))
        yield from group
