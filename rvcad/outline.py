"""Outlines of planar parts: exact curves, lines, arcs and closed loops (the plan layer).

Every planar part of the reducer is an extrusion of a 2D outline made of lines, circular arcs
and exact curves (the cycloid envelope, involute flanks). A :class:`Loop` gives both discretisations
from one description: vertex-exact polygons with chords within a sagitta (:meth:`Loop.ring`, for
the meshes) and cubic B-splines within a tolerance (:meth:`CurveSeg.bsplines`, for the STEP
solids). numpy only. Units: mm, rad. Outer loops run counter-clockwise seen from +z, holes clockwise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from rvcad.bspline import FIT_TOLERANCE_FRACTION, BSpline2D, fit_bsplines
from rvcad.plane import arc_steps, rotate2d, unit

# ----------------------------------------------------------------------------- exact curves
class ExactCurve:
    """An exact planar curve piece with its own sampler and distance function.

    Parameters
    ----------
    func : callable
        Parameter -> points (..., 2), mm (vectorised).
    t0, t1 : float
        Parameter interval (t0 < t1).
    sampler : callable
        sagitta (mm) -> increasing parameters from t0 to t1 inclusive whose chords deviate by at
        most the sagitta.
    deviation : callable
        (points, parameter guesses) -> distance to the exact curve, mm.
    name : str
        For messages.
    """

    def __init__(self, func: Callable[[np.ndarray], np.ndarray], t0: float, t1: float,
                 sampler: Callable[[float], np.ndarray],
                 deviation: Callable[[np.ndarray, np.ndarray], np.ndarray], name: str = "curve") -> None:
        self.func, self.t0, self.t1 = func, float(t0), float(t1)
        self.sampler, self.deviation, self.name = sampler, deviation, name
        self._samples: dict[float, np.ndarray] = {}
        self._fits: dict[float, tuple[BSpline2D, ...]] = {}

    def samples(self, sagitta: float) -> np.ndarray:
        """Points on the exact curve (vertex-exact), chords within ``sagitta`` mm, (N, 2); cached
        (do not modify the returned array)."""
        s = float(sagitta)
        if s not in self._samples:
            self._samples[s] = self.func(self.sampler(s))
        return self._samples[s]

    def bsplines(self, tol: float) -> tuple[BSpline2D, ...]:
        """Cubic B-splines within ``FIT_TOLERANCE_FRACTION * tol`` of the curve (tol in mm); cached."""
        tol = float(tol)
        if tol not in self._fits:
            t_start = self.sampler(max(tol * 100.0, 1e-3))
            self._fits[tol] = tuple(fit_bsplines(self.func, self.deviation, self.t0, self.t1,
                                                 FIT_TOLERANCE_FRACTION * tol, t_start))
        return self._fits[tol]


# ----------------------------------------------------------------------------- outline segments
@dataclass(frozen=True)
class LineSeg:
    """Straight segment from ``p0`` to ``p1`` (mm)."""

    p0: tuple[float, float]
    p1: tuple[float, float]

    @property
    def start(self) -> np.ndarray:
        return np.asarray(self.p0, dtype=np.float64)

    @property
    def end(self) -> np.ndarray:
        return np.asarray(self.p1, dtype=np.float64)

    def points(self, sagitta: float) -> np.ndarray:
        """The start point only (a line needs no intermediate vertices)."""
        return self.start[None, :]


@dataclass(frozen=True)
class ArcSeg:
    """Circular arc: centre (mm), radius (mm), from angle a0 to a1 (rad; a1 > a0 is CCW).

    A sweep of +-2 pi is a full circle (one closed edge in the B-rep).
    """

    center: tuple[float, float]
    radius: float
    a0: float
    a1: float

    @property
    def full(self) -> bool:
        return abs(abs(self.a1 - self.a0) - 2.0 * math.pi) < 1e-12

    @property
    def ccw(self) -> bool:
        return self.a1 > self.a0

    @property
    def start(self) -> np.ndarray:
        return np.asarray(self.center, dtype=np.float64) + self.radius * unit(self.a0)

    @property
    def end(self) -> np.ndarray:
        return np.asarray(self.center, dtype=np.float64) + self.radius * unit(self.a1)

    def points(self, sagitta: float) -> np.ndarray:
        """Vertices on the circle from the start (included) to the end (excluded), chords within
        ``sagitta`` mm."""
        n = arc_steps(self.radius, self.a1 - self.a0, sagitta)
        a = self.a0 + (self.a1 - self.a0) * np.arange(n) / n
        return np.asarray(self.center, dtype=np.float64) + self.radius * unit(a)


@dataclass(frozen=True)
class CurveSeg:
    """An :class:`ExactCurve` placed in the part: mirror (y -> -y), rotate (rad), translate (mm),
    optionally traversed backwards."""

    curve: ExactCurve
    rotation: float = 0.0
    offset: tuple[float, float] = (0.0, 0.0)
    mirror: bool = False
    reverse: bool = False

    def _tf(self, p: np.ndarray) -> np.ndarray:
        p = np.array(p, dtype=np.float64, copy=True)
        if self.mirror:
            p[..., 1] = -p[..., 1]
        return rotate2d(p, self.rotation) + np.asarray(self.offset, dtype=np.float64)

    def inverse(self, p: np.ndarray) -> np.ndarray:
        """Part-frame points back to the curve's own frame."""
        q = rotate2d(np.asarray(p, dtype=np.float64) - np.asarray(self.offset, dtype=np.float64), -self.rotation)
        if self.mirror:
            q[..., 1] = -q[..., 1]
        return q

    @property
    def start(self) -> np.ndarray:
        t = self.curve.t1 if self.reverse else self.curve.t0
        return self._tf(self.curve.func(np.array([t]))[0])

    @property
    def end(self) -> np.ndarray:
        t = self.curve.t0 if self.reverse else self.curve.t1
        return self._tf(self.curve.func(np.array([t]))[0])

    def points(self, sagitta: float) -> np.ndarray:
        """Vertex-exact samples from the start (included) to the end (excluded)."""
        p = self._tf(self.curve.samples(float(sagitta)))
        if self.reverse:
            p = p[::-1]
        return p[:-1]

    def bsplines(self, tol: float) -> list[BSpline2D]:
        """Placed B-spline pieces in traversal order, each within the fit tolerance."""
        pieces = [b.transformed(self.rotation, self.offset, self.mirror) for b in self.curve.bsplines(float(tol))]
        if self.reverse:
            pieces = [b.reversed() for b in pieces[::-1]]
        return pieces


Segment = LineSeg | ArcSeg | CurveSeg


@dataclass(frozen=True)
class Loop:
    """A closed outline: segments end to end (outer loops CCW, holes CW)."""

    segments: tuple[Segment, ...]

    def __post_init__(self) -> None:
        segs = self.segments
        for a, b in zip(segs, segs[1:] + segs[:1]):
            gap = float(np.linalg.norm(a.end - b.start))
            if gap > 1e-9:
                raise ValueError(f"outline segments do not join: gap {gap:.3e} mm")

    def ring(self, sagitta: float) -> np.ndarray:
        """Closed polygon (N, 2) mm, no repeated end point, vertices on the exact outline."""
        return np.concatenate([s.points(sagitta) for s in self.segments])

    @staticmethod
    def circle(center: Sequence[float], radius: float, hole: bool = False) -> "Loop":
        """Full circle loop (CCW, or CW for a hole)."""
        c = (float(center[0]), float(center[1]))
        return Loop((ArcSeg(c, float(radius), 0.0, -2.0 * math.pi if hole else 2.0 * math.pi),))



__all__ = ["ArcSeg", "CurveSeg", "ExactCurve", "LineSeg", "Loop", "Segment"]
