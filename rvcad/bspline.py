"""Cubic B-spline fits of exact planar curves within a tolerance (the data of a STEP edge).

:func:`fit_bsplines` interpolates a cubic through exact curve points (chord-length parameter)
and refines until every check point lies within the tolerance of the exact curve; the result,
:class:`BSpline2D`, is what :mod:`rvcad.occ` hands to OpenCASCADE's ``Geom_BSplineCurve``.
numpy and scipy only. Lengths in mm.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.interpolate import make_interp_spline

from rvcad.plane import rotate2d


#: Fraction of the requested tolerance that a fitted B-spline may use, checked at
#: :data:`FIT_CHECK_FRACTIONS` of every knot span (the rest is margin for the points between
#: the checks). A STEP edge sampled back densely stays within the tolerance.
FIT_TOLERANCE_FRACTION = 0.5

#: Positions inside each knot span (fractions of its length) where a B-spline fit is checked.
FIT_CHECK_FRACTIONS = np.array([0.0625, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 0.9375])

#: Most knot spans one STEP edge may have. OpenCASCADE integrates area, volume and inertia of a
#: face bounded by a B-spline edge with a fixed number of Gauss points per edge (not per span);
#: with 60 spans per cycloid lobe its default volume is wrong by 10 %, with <= 8 spans per
#: edge it agrees with the closed form to 1e-6 relative. Long curves are therefore split.
MAX_SPANS_PER_EDGE = 8


# ----------------------------------------------------------------------------- B-splines
@dataclass(frozen=True)
class BSpline2D:
    """A clamped planar B-spline (the data handed to OpenCASCADE's ``Geom_BSplineCurve``).

    Attributes
    ----------
    knots : (n + degree + 1,) float64
        Full knot vector; the parameter is the cumulative chord length of the fitted samples, mm.
    poles : (n, 2) float64
        Control points, mm.
    degree : int
    """

    knots: np.ndarray
    poles: np.ndarray
    degree: int = 3

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """Points at parameters ``u`` (mm of chord length), shape (..., 2)."""
        from scipy.interpolate import BSpline

        return BSpline(self.knots, self.poles, self.degree, extrapolate=False)(np.asarray(u, dtype=np.float64))

    @property
    def spans(self) -> int:
        """Number of non-empty knot spans."""
        return int(np.unique(self.knots).size - 1)

    @property
    def start(self) -> np.ndarray:
        return self.poles[0]

    @property
    def end(self) -> np.ndarray:
        return self.poles[-1]

    def transformed(self, rotation: float = 0.0, offset: Sequence[float] = (0.0, 0.0),
                    mirror: bool = False) -> "BSpline2D":
        """Mirror (y -> -y, optional), then rotate by ``rotation`` rad, then translate (mm).

        B-splines are affine invariant: transforming the poles transforms the curve exactly.
        """
        p = self.poles.copy()
        if mirror:
            p[:, 1] = -p[:, 1]
        p = rotate2d(p, rotation) + np.asarray(offset, dtype=np.float64)
        return BSpline2D(self.knots, p, self.degree)

    def reversed(self) -> "BSpline2D":
        """Same curve traversed the other way (knots mirrored, poles reversed)."""
        k = self.knots
        return BSpline2D((k[0] + k[-1]) - k[::-1], self.poles[::-1].copy(), self.degree)


def _fit_chunk(func: Callable[[np.ndarray], np.ndarray], deviation: Callable[[np.ndarray, np.ndarray], np.ndarray],
               t: np.ndarray, tol: float, max_rounds: int = 40) -> tuple[BSpline2D, np.ndarray]:
    """Interpolate a cubic through func(t) (chord-length parameter) and refine t until every
    check point is within ``tol`` of the exact curve. Returns the spline and the final t."""
    fr = FIT_CHECK_FRACTIONS
    for _ in range(max_rounds):
        P = func(t)
        u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
        if t.size < 4:
            t = np.sort(np.concatenate([t, 0.5 * (t[:-1] + t[1:])]))
            continue
        sp = make_interp_spline(u, P, k=3)
        uc = (u[:-1, None] + np.diff(u)[:, None] * fr[None]).ravel()
        tc = (t[:-1, None] + np.diff(t)[:, None] * fr[None]).ravel()
        err = np.abs(deviation(sp(uc), tc)).reshape(-1, fr.size).max(axis=1)
        bad = err > tol
        if not bad.any():
            return BSpline2D(np.asarray(sp.t, dtype=np.float64), np.asarray(sp.c, dtype=np.float64), 3), t
        t = np.sort(np.concatenate([t, 0.5 * (t[:-1] + t[1:])[bad]]))
    raise RuntimeError(f"B-spline fit did not reach {tol * 1e3:.4g} um in {max_rounds} refinements")


def fit_bsplines(func: Callable[[np.ndarray], np.ndarray], deviation: Callable[[np.ndarray, np.ndarray], np.ndarray],
                 t0: float, t1: float, tol: float, t_start: np.ndarray | None = None,
                 max_spans: int = MAX_SPANS_PER_EDGE) -> list[BSpline2D]:
    """Fit an exact planar curve by a chain of cubic B-splines within ``tol``.

    Parameters
    ----------
    func : callable
        t (rad or any parameter, vectorised) -> points (..., 2), mm.
    deviation : callable
        (points (K, 2), parameter guesses (K,)) -> distance of each point to the exact curve, mm.
    t0, t1 : float
        Parameter interval.
    tol : float
        Largest deviation at the check points, mm (use ``FIT_TOLERANCE_FRACTION`` of the budget).
    t_start : array or None
        Initial parameters (default 9 equal steps).
    max_spans : int
        Knot spans per returned spline at most (see :data:`MAX_SPANS_PER_EDGE`).

    Returns
    -------
    list of BSpline2D
        Consecutive pieces from func(t0) to func(t1); every piece interpolates the exact curve
        at its knots (end points exact up to float64 rounding).
    """
    t = np.linspace(t0, t1, 9) if t_start is None else np.asarray(t_start, dtype=np.float64)
    _, t = _fit_chunk(func, deviation, t, tol)
    out: list[BSpline2D] = []
    n = t.size - 1
    n_chunks = max(1, int(math.ceil(n / max_spans)))
    bounds = np.linspace(0, n, n_chunks + 1).round().astype(int)
    for a, b in zip(bounds[:-1], bounds[1:]):
        tc = t[a:b + 1]
        while True:
            sp, tc2 = _fit_chunk(func, deviation, tc, tol)
            if tc2.size - 1 <= max_spans:
                out.append(sp)
                break
            # refinement made the chunk too long: split it in two and fit each half
            mid = (tc2.size - 1) // 2
            left, right = tc2[:mid + 1], tc2[mid:]
            out.extend(fit_bsplines(func, deviation, float(left[0]), float(left[-1]), tol, left, max_spans))
            out.extend(fit_bsplines(func, deviation, float(right[0]), float(right[-1]), tol, right, max_spans))
            break
    return out



__all__ = ["FIT_CHECK_FRACTIONS", "FIT_TOLERANCE_FRACTION", "MAX_SPANS_PER_EDGE", "BSpline2D", "fit_bsplines"]
