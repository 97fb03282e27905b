"""Laplace's intervals widened through the model where the criterion is flatter than its tangent.

Laplace's interval of a named effect is read from the curvature of the criterion at the MAP. Where the reducer's
response bends within the interval (a contact that opens or closes, a response even in a parameter), the criterion
can rise more slowly away from the MAP than its tangent says, and the interval then excludes values the data do
not. Along the path of the linear posterior (the effect at a value, every other parameter at its posterior mean
given that, within its bounds) the criterion through the model bounds the profile from above
(:func:`rvcalib.gaussian.rise_function`), so every value where it rises by less than the chi-square quantile (one
degree of freedom: the interval of one quantity) is inside the likelihood-ratio region (S. S. Wilks, Ann. Math.
Statist. 9 (1938) 60-62). :func:`widen` moves each end of the interval out to the farthest such value it finds:
it probes Laplace's end, then doubles the distance from the MAP (at most :data:`DOUBLINGS` times) while the rise
stays below the quantile, then bisects (:data:`BISECTIONS` times) between the last value inside and the first
outside. It never narrows an interval: where the model is linear the rise at Laplace's end is the quantile itself
and nothing moves; a value the model cannot evaluate counts as outside.

A polar effect (a size at an angle) moves along its own direction: its two components scaled together, its size
not below zero.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np
from scipy import stats

#: Most doublings of the distance from the MAP beyond Laplace's end.
DOUBLINGS = 4
#: Bisections between the last value inside the region and the first outside.
BISECTIONS = 6


def _end(inside_of: Callable[[float], bool], centre: float, end: float, floor: float | None) -> tuple[float, int]:
    """The farthest value on the side of ``end`` (Laplace's) found inside the region (module docstring), and the
    evaluations spent; ``floor`` a bound the value may not pass (a size's zero)."""
    if end == centre:
        return end, 0
    direction, width = np.sign(end - centre), abs(end - centre)
    n = 1
    if not inside_of(end):
        return end, n
    inside, outside = end, None
    for j in range(1, DOUBLINGS + 1):
        v = centre + direction * width * 2.0 ** j
        if floor is not None and direction * (v - floor) > 0:
            v = floor
        n += 1
        if not inside_of(v):
            outside = v
            break
        inside = v
        if v == floor:
            return inside, n
    if outside is None:
        return inside, n
    for _ in range(BISECTIONS):
        mid = 0.5 * (inside + outside)
        n += 1
        if inside_of(mid):
            inside = mid
        else:
            outside = mid
    return inside, n


def widen(eff, cand, k: np.ndarray, mean_k: np.ndarray, rise, level: float) -> tuple:
    """``eff`` (a :class:`rvcalib.result.NamedEffect` of candidate ``cand``, its parameters at positions ``k``
    with posterior mean ``mean_k``) with its interval widened through the model (module docstring), and the model
    evaluations spent. ``rise(k, values)`` is :func:`rvcalib.gaussian.rise_function`'s."""
    limit = float(stats.chi2.ppf(level, 1))
    if cand.polar:
        size = float(np.hypot(*mean_k))
        if size == 0.0:
            return eff, 0

        def values(q):
            return mean_k * (q / size)
        centre, floor_lo, floor_hi = size, 0.0, None
    else:
        def values(q):
            return np.array([q])
        centre, floor_lo, floor_hi = float(mean_k[0]), cand.lower, cand.upper

    def inside_of(q: float) -> bool:
        r = rise(k, values(q))
        return r is not None and r < limit

    lo, n_lo = _end(inside_of, centre, float(eff.ci95[0]), floor_lo)
    hi, n_hi = _end(inside_of, centre, float(eff.ci95[1]), floor_hi)
    ci = [min(lo, float(eff.ci95[0])), max(hi, float(eff.ci95[1]))]
    return replace(eff, ci95=ci), n_lo + n_hi


def widener(post, rise, level: float, note, log=None):
    """``widen_one(eff, cand, positions)``: the named effect ``eff`` of candidate ``cand`` (its parameters at
    ``positions`` of the posterior ``post``) with its interval widened through the model (:func:`widen`);
    ``note`` is told of each interval that moved, ``log``, where given, of the evaluations each spent."""
    def widen_one(eff, cand, positions):
        k = np.asarray(positions, dtype=int)
        new, n = widen(eff, cand, k, post.mean[k], rise, level)
        if log is not None:
            log(f"{eff.name}: its interval through the model in {n} model evaluations")
        if new.ci95 != list(eff.ci95):
            note(f"the interval of {eff.name} is widened through the model from [{eff.ci95[0]:.4g}, "
                 f"{eff.ci95[1]:.4g}] to [{new.ci95[0]:.4g}, {new.ci95[1]:.4g}] {eff.unit}: along its posterior "
                 f"path the criterion rises more slowly than Laplace's curvature says")
        return new

    return widen_one
