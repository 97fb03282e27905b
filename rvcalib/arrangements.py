"""The arrangements of the crank-indexed errors that the data may not split, and one answer over several minima.

**Why.** The instances of one crank-indexed Table 4 error (the carrier hole at crank c, the disc hole over crank
c, the cam at crank c, the planet of crank c) move the discs alike to first order: their columns at the declared
state are nearly parallel or anti-parallel (docs/calibration.md, section 8). An error at crank c and the same error
with its sign reversed at the crank half a turn away give nearly the same TE; rvdyn tells them apart only through
how the load is shared between the cranks. Each arrangement can be a minimum of the tolerance-prior criterion of
its own, and a search from one start ends in one of them.

**What.** The tolerance-prior estimator (:mod:`rvcalib.gaussian`) searches once more, from the half-turn image of
its first end (:func:`half_turn_image`), and :func:`combine` reads one answer from the minima:

* the minima are compared by their criterion at one noise, the larger of their noises of the greatest evidence
  (so a difference is not read finer than the noisier fit allows);
* the minima whose criterion is within the chi-square quantile (one degree of freedom, the coverage level) of the
  least are the data's answer together: the likelihood-ratio region over the arrangement (S. S. Wilks, Ann. Math.
  Statist. 9 (1938) 60-62), as :func:`rvcalib.gaussian.zero_check` reads it over a size;
* an effect named at every such minimum is named, its value the least minimum's and its interval the hull of
  theirs (the interval at one minimum holds only that arrangement's uncertainty); an effect named at some of them
  only, or whose hull holds zero, is not named: it is reported as a group of kind ``arrangement``, each member the
  effect as one minimum names it;
* a minimum above the quantile is dropped: the data prefer the other arrangement;
* where a minimum within the quantile is a search stopped by its cap, nothing is named
  (:func:`rvcalib.gaussian.unconverged_note`).

With an odd number of evenly spaced cranks no crank stands half a turn from another and the estimator searches
once.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy import stats


@dataclass
class Minimum:
    """One end of the tolerance-prior search and what was read there.

    Attributes
    ----------
    label : str
        Where the search started (``start``: the estimator's own; ``half-turn image``).
    theta, b_m : numpy.ndarray
        The solved parameters (physical units) and the measurement coefficients of the reading columns.
    te : numpy.ndarray
        The model TE at ``theta`` (arcsec).
    sigma : float
        The noise of the greatest evidence there (arcsec).
    stopped : str
        ``converged``, ``max_linearisations`` or ``no_columns`` (:func:`rvcalib.gaussian.map_estimate`).
    named, groups, notes : list
        The effects whose 95 % region excludes zero there, the groups and the notes read there.
    extra : dict
        What the caller keeps of this end (the estimator: the reading coefficients ``b_r``, the columns ``X`` and
        the residual ``r``).
    """

    label: str
    theta: np.ndarray
    b_m: np.ndarray
    te: np.ndarray
    sigma: float
    stopped: str
    named: list
    groups: list
    notes: list
    extra: dict = field(default_factory=dict)

    @property
    def converged(self) -> bool:
        return self.stopped == "converged"


@dataclass
class Answer:
    """The answer over the minima: ``best`` (the least criterion), the criteria at the common noise, those kept
    (within the quantile), and the named effects, groups and notes read over the kept ones."""

    best: Minimum
    criteria: list
    kept: list
    named: list
    groups: list
    notes: list


def half_turn_image(candidates: list, theta: np.ndarray, crank_angles_deg) -> np.ndarray | None:
    """``theta`` with every crank-indexed Table 4 error moved half a turn: the value of the instance at crank c (or
    at crank c's hole) given to the same error's instance at the crank 180 deg from it, its sign reversed (a
    crank's hole moved outwards and the opposite crank's moved inwards shift the disc alike). None where no crank
    stands 180 deg from another (an odd number of evenly spaced cranks)."""
    angles = [float(a) % 360.0 for a in crank_angles_deg]
    opposite = {}
    for c, a in enumerate(angles):
        match = [d for d, b in enumerate(angles) if abs((b - a) % 360.0 - 180.0) < 1e-6]
        if match:
            opposite[c] = match[0]
    if len(opposite) < len(angles):
        return None
    where, k = {}, 0                                # the crank-indexed Table 4 candidates' parameters
    for cand in candidates:
        if cand.family == "table4" and any(s in ("crank", "hole") for s, _ in cand.instance):
            where[(cand.key, tuple(cand.instance))] = slice(k, k + cand.n_params)
        k += cand.n_params
    src = np.asarray(theta, dtype=float)
    out = src.copy()
    for (key, instance), at in where.items():
        image = tuple((s, opposite[v] if s in ("crank", "hole") else v) for s, v in instance)
        out[where[(key, image)]] = -src[at]
    return out


def _identity(eff) -> tuple:
    return eff.key, tuple(sorted(eff.instance.items()))


def _excludes_zero(lo: float, hi: float) -> bool:
    return lo > 0.0 or hi < 0.0


def _member(eff, m: Minimum) -> dict:
    return {"name": eff.name, "key": eff.key, "family": eff.family, "instance": dict(eff.instance),
            "unit": eff.unit, "value": float(eff.value), "angle_deg": eff.angle_deg, "ci95": list(eff.ci95),
            "probability": None, "minimum": m.label}


def combine(minima: list, phi: Callable[[Minimum, float], float], level: float) -> Answer:
    """One answer over the search's minima (module docstring); ``phi(minimum, sigma)`` the criterion of a minimum
    at the noise ``sigma`` (arcsec), ``level`` the coverage."""
    sigma = max(m.sigma for m in minima)
    crit = [phi(m, sigma) for m in minima]
    least = int(np.argmin(crit))
    limit = float(stats.chi2.ppf(level, 1))
    kept = [m for m, c in zip(minima, crit) if c - crit[least] < limit]
    best = minima[least]
    notes = [f"the search from the {m.label} ended at criterion {c:.2f} (at the common noise {sigma:.4g} arcsec)"
             + ("" if m.converged else ", stopped by its cap") for m, c in zip(minima, crit)]
    if len(kept) == 1:
        return Answer(best, crit, kept, list(best.named), list(best.groups), notes + list(best.notes))
    ids = [{_identity(e): e for e in m.named} for m in kept]
    named, split = [], {}
    for m, found in zip(kept, ids):
        for ident, eff in found.items():
            at_all = all(ident in other for other in ids)
            lo = min(other[ident].ci95[0] for other in ids) if at_all else 0.0
            hi = max(other[ident].ci95[1] for other in ids) if at_all else 0.0
            if at_all and _excludes_zero(lo, hi):
                if m is best:
                    named.append(replace(eff, ci95=[float(lo), float(hi)]))
            else:
                split.setdefault(eff.key, []).append(_member(eff, m))
    groups = [{"kind": "arrangement", "coverage": level, "purity": None,
               "reason": f"{len(kept)} minima of the criterion within the chi-square quantile {limit:.3g} of the "
                         f"least name it differently: the data do not split the arrangements of the crank-indexed "
                         f"errors", "members": members} for members in split.values()]
    notes.append(f"{len(kept)} minima are within the chi-square quantile {limit:.3g} of the least criterion: an "
                 f"effect is named only where every one of them names it, with the hull of their intervals")
    return Answer(best, crit, kept, named, list(best.groups) + groups, notes + list(best.notes))
