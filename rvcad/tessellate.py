"""Exact-profile discretisation under our control: outlines, B-spline fits, meshes, binary STL.

Every planar part of the reducer is an extrusion of a 2D outline made of lines, circular arcs and
exact curves (the cycloid envelope, involute flanks). This module turns such outlines into

* polygons whose vertices lie on the exact curve and whose chords deviate from it by at most a
  given sagitta (for STL and collision meshes), and
* cubic B-splines fitted to the exact curve within a given tolerance (for the STEP B-rep),

without a CAD kernel: numpy, scipy and shapely only. The CAD kernel (OCP, build123d) is touched in
:mod:`rvcad.parts` when a solid is built from the same outline objects, so the STEP and the STL
come from one description.

Units: lengths in mm, angles in rad (this module is internal; the part API speaks degrees).
Outer loops run counter-clockwise seen from +z, holes clockwise.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Callable, Sequence

import numpy as np
import shapely
from scipy.interpolate import make_interp_spline
from shapely.geometry import Polygon

from rvcad.profile import CycloidProfile, InvoluteGear

#: Fraction of the requested tolerance that a fitted B-spline may use, checked at
#: :data:`FIT_CHECK_FRACTIONS` of every knot span (the rest is margin for the points between
#: the checks). A STEP edge sampled back densely stays within the tolerance.
FIT_TOLERANCE_FRACTION = 0.5

#: Positions inside each knot span (fractions of its length) where a B-spline fit is checked.
FIT_CHECK_FRACTIONS = np.array([0.0625, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 0.9375])

#: Most knot spans one STEP edge may have. OpenCASCADE integrates area, volume and inertia of a
#: face bounded by a B-spline edge with a fixed number of Gauss points per edge (not per span);
#: with 60 spans per cycloid lobe its default volume was wrong by 10 %, with <= 8 spans per
#: edge it agrees with the closed form to 1e-6 relative. Long curves are therefore split.
MAX_SPANS_PER_EDGE = 8

#: Points per call of the cycloid foot-point search (its global search holds a 129-point grid per
#: point: 8192 points take about 25 MB).
DISTANCE_CHUNK = 8192

#: Longest chord of any sampled circle or arc, mm, whatever the sagitta (keeps large radii from
#: producing long skinny cap triangles).
MAX_CHORD_MM = 1.0


# ----------------------------------------------------------------------------- small helpers
def _u(a: np.ndarray | float) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    return np.stack([np.cos(a), np.sin(a)], axis=-1)


def rotate2d(p: np.ndarray, angle: float) -> np.ndarray:
    """Rotate 2D points (..., 2) by ``angle`` rad about the origin (float64)."""
    c, s = math.cos(angle), math.sin(angle)
    p = np.asarray(p, dtype=np.float64)
    return np.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1]], axis=-1)


def arc_steps(radius: float, sweep: float, sagitta: float) -> int:
    """Number of equal chords on an arc so that none deviates by more than ``sagitta``.

    Parameters
    ----------
    radius : float
        Arc radius, mm.
    sweep : float
        Absolute swept angle, rad.
    sagitta : float
        Largest chord sagitta, mm.

    Returns
    -------
    int
        At least 1 (at least 3 for a full circle). A chord spanning angle d deviates by
        ``r (1 - cos(d/2))`` from the arc; chords are also kept below :data:`MAX_CHORD_MM`.
    """
    if sagitta <= 0:
        raise ValueError(f"sagitta {sagitta} mm must be > 0")
    x = min(1.0, sagitta / radius)
    d = 2.0 * math.acos(1.0 - x)
    d = min(d, 2.0 * math.asin(min(1.0, MAX_CHORD_MM / (2.0 * radius))))
    n = max(1, int(math.ceil(abs(sweep) / d - 1e-12)))
    if abs(abs(sweep) - 2.0 * math.pi) < 1e-12:
        n = max(n, 3)
    return n


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
        return np.asarray(self.center, dtype=np.float64) + self.radius * _u(self.a0)

    @property
    def end(self) -> np.ndarray:
        return np.asarray(self.center, dtype=np.float64) + self.radius * _u(self.a1)

    def points(self, sagitta: float) -> np.ndarray:
        """Vertices on the circle from the start (included) to the end (excluded), chords within
        ``sagitta`` mm."""
        n = arc_steps(self.radius, self.a1 - self.a0, sagitta)
        a = self.a0 + (self.a1 - self.a0) * np.arange(n) / n
        return np.asarray(self.center, dtype=np.float64) + self.radius * _u(a)


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


# ----------------------------------------------------------------------------- exact distances
def involute_deviation(gear: InvoluteGear, p: np.ndarray) -> np.ndarray:
    """Signed distance of points to the upper flank involute of tooth 0, mm (positive outside the tooth).

    Every normal of an involute is tangent to its base circle, so the foot point of p lies on the
    tangent from p to the base circle: with s = sqrt(|p|^2 - rb^2) and the tangency angle
    a = arg(p) - atan(s/rb), the roll angle is lam = xi - a and the distance is s - rb lam.
    Exact for points near the flank (|p| >= rb).
    """
    p = np.asarray(p, dtype=np.float64)
    rb = gear.base_radius
    r2 = np.einsum("...i,...i->...", p, p)
    s = np.sqrt(np.maximum(r2 - rb * rb, 0.0))
    a = np.arctan2(p[..., 1], p[..., 0]) - np.arctan2(s, rb)
    lam = gear.flank_origin - a
    lam_guess = s / rb
    lam = lam_guess + (np.mod(lam - lam_guess + math.pi, 2.0 * math.pi) - math.pi)
    return s - rb * lam


def involute_flank_curve(gear: InvoluteGear) -> ExactCurve:
    """Upper flank of tooth 0 from the start radius (max of base and root) to the tip, as an
    :class:`ExactCurve` in the roll angle (rad)."""
    from rvcad.profile import sagitta_samples

    rb = gear.base_radius
    r0 = max(rb, gear.root_radius)
    lam0 = math.sqrt(max((r0 / rb) ** 2 - 1.0, 0.0))
    lam1 = math.sqrt((gear.tip_radius / rb) ** 2 - 1.0)

    def sampler(s: float) -> np.ndarray:
        return sagitta_samples(lam0, lam1, lambda x: rb * np.maximum(x, 1e-12),
                               lambda x: rb * np.maximum(x, 1e-9), s, max_chord=min(0.25, MAX_CHORD_MM),
                               n_grid=4001)

    def deviation(p: np.ndarray, t: np.ndarray) -> np.ndarray:
        return np.abs(involute_deviation(gear, p))

    return ExactCurve(gear.involute, lam0, lam1, sampler, deviation, name=f"involute z={gear.z}")


def cycloid_deviation(profile: CycloidProfile, p: np.ndarray, t_guess: np.ndarray) -> np.ndarray:
    """Signed distance of points to the exact disc boundary (envelope), mm, positive outside.

    Distance to the pin-centre curve q plus the pin radius (exact on the untrimmed envelope; the
    foot point search of :meth:`CycloidProfile.signed_distance` is global within a lobe pitch).
    """
    p = np.asarray(p, dtype=np.float64)
    t = np.asarray(t_guess, dtype=np.float64)
    out = np.empty(len(p))
    for a in range(0, len(p), DISTANCE_CHUNK):  # bounded memory: the foot search holds a grid per point
        out[a:a + DISTANCE_CHUNK] = profile.boundary_distance(p[a:a + DISTANCE_CHUNK], t[a:a + DISTANCE_CHUNK])[0]
    return out


def cycloid_curves(profile: CycloidProfile) -> list[ExactCurve]:
    """The smooth pieces of lobe 0 of a disc boundary, in traversal order (profile frame).

    Without undercut: one piece from the tip before root 0 to the tip after it. With undercut
    (loops trimmed): the root piece between the two trim corners around root 0, then the tip
    piece between the trim corners around tip 0. Rotating the pieces by k 2 pi / Zc gives lobe k.
    Samples match :meth:`CycloidProfile.boundary_t` (same half-lobe sampling, mirrored).
    """
    zc = profile.z_lobes
    r0 = profile.root_t()
    tip = profile.tip_t()
    trim = profile.trim_t

    def dev(p: np.ndarray, t: np.ndarray) -> np.ndarray:
        return np.abs(cycloid_deviation(profile, p, t))

    if trim is None:
        def root_sampler(s: float) -> np.ndarray:
            rel = profile.half_lobe_t(s) - r0
            return r0 + np.concatenate([-rel[::-1], rel[1:]])

        return [ExactCurve(profile.boundary, r0 - math.pi / zc, r0 + math.pi / zc, root_sampler, dev,
                           name="cycloid lobe")]
    t1, t2 = trim

    def split(s: float) -> tuple[np.ndarray, np.ndarray]:
        h = profile.half_lobe_t(s)
        ia = int(np.searchsorted(h, t1, side="right"))
        a = h[:ia]
        a[-1] = t1
        b = np.concatenate([[t2], h[ia:]])
        return a, b

    def root_sampler_u(s: float) -> np.ndarray:
        rel = split(s)[0] - r0
        return r0 + np.concatenate([-rel[::-1], rel[1:]])

    def tip_sampler_u(s: float) -> np.ndarray:
        rel = split(s)[1] - tip
        return tip + np.concatenate([rel, -rel[::-1][1:]])

    return [ExactCurve(profile.boundary, 2.0 * r0 - t1, t1, root_sampler_u, dev, name="cycloid root"),
            ExactCurve(profile.boundary, t2, 2.0 * tip - t2, tip_sampler_u, dev, name="cycloid tip")]


# ----------------------------------------------------------------------------- triangulation
#: Outer rings with more vertices than this are capped by the strip method of
#: :func:`triangulate` (linear time) when the shape allows it; smaller ones by constrained Delaunay.
STRIP_MIN_VERTICES = 1500


def _cdt(rings: Sequence[np.ndarray]) -> np.ndarray:
    """GEOS constrained Delaunay triangulation of a polygon with holes, indices into concat(rings)."""
    pts = np.concatenate(rings)
    poly = Polygon(rings[0], [r for r in rings[1:]])
    if not poly.is_valid:
        from shapely.validation import explain_validity

        raise ValueError(f"outline polygon is invalid (self-intersecting?): {explain_validity(poly)}")
    tri = shapely.constrained_delaunay_triangles(poly)
    coords = shapely.get_coordinates(tri).reshape(-1, 4, 2)[:, :3, :].reshape(-1, 2)
    key = pts[:, 0] + 1j * pts[:, 1]
    order = np.argsort(key)
    sk = key[order]
    if np.any(sk[1:] == sk[:-1]):
        raise ValueError("outline has repeated vertices")
    q = coords[:, 0] + 1j * coords[:, 1]
    pos = np.clip(np.searchsorted(sk, q), 0, len(sk) - 1)
    if not np.all(sk[pos] == q):  # pragma: no cover - GEOS keeps the input vertices
        raise RuntimeError("triangulation created a vertex that is not on the outline")
    faces = order[pos].reshape(-1, 3).astype(np.int64)
    a, b, c = pts[faces[:, 0]], pts[faces[:, 1]], pts[faces[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    flip = area2 < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


def _angles(p: np.ndarray, c: np.ndarray) -> np.ndarray | None:
    """Unwrapped polar angles of a closed CCW ring about c, or None if not strictly increasing."""
    d = p - c
    a = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    if np.any(np.diff(a) <= 0) or not (a[-1] - a[0] < 2.0 * math.pi):
        return None
    return a


def _strip(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray | None:
    """Triangles between an outer CCW ring a and an inner CCW ring b, both star-shaped about c.

    Indices into concat(a, b); ``None`` if either ring is not angle-monotone about c.
    """
    ta, tb = _angles(a, c), _angles(b, c)
    if ta is None or tb is None:
        return None
    na, nb = len(a), len(b)
    # start b at the vertex at or just before a[0] in angle, then unwrap it from there
    rel = np.mod(tb - ta[0], 2.0 * math.pi)
    j0 = int(np.argmax(rel))
    rr = np.roll(rel, -j0)
    tb = ta[0] + np.concatenate([[rr[0] - 2.0 * math.pi], rr[1:]])
    if np.any(np.diff(tb) <= 0):
        return None
    ib = np.roll(np.arange(nb), -j0) + na
    ta_n = np.append(ta, ta[0] + 2.0 * math.pi)
    tb_n = np.append(tb, tb[0] + 2.0 * math.pi)
    ia = np.append(np.arange(na), 0)
    ibn = np.append(ib, ib[0])
    out = np.empty((na + nb, 3), dtype=np.int64)
    i = j = 0
    for m in range(na + nb):
        if j == nb or (i < na and ta_n[i + 1] <= tb_n[j + 1]):
            out[m] = (ia[i], ia[i + 1], ibn[j])
            i += 1
        else:
            out[m] = (ia[i], ibn[j + 1], ibn[j])
            j += 1
    return out


def _positive(pts: np.ndarray, faces: np.ndarray) -> bool:
    a, b, c = pts[faces[:, 0]], pts[faces[:, 1]], pts[faces[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    return bool(np.all(area2 > 0))


def triangulate(rings: Sequence[np.ndarray], interior: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a polygon with holes; its boundary edges are exactly the ring edges.

    Parameters
    ----------
    rings : sequence of (N_i, 2) arrays
        Outer ring first (CCW), then holes (CW); no repeated end points, all vertices distinct.
    interior : bool
        Whether interior vertices may be added (the inner circle of the strip method).

    Returns
    -------
    faces : (T, 3) int64
        Counter-clockwise triangles indexing ``np.concatenate(rings + [extra])``.
    extra : (E, 2) float64
        Interior vertices added by the strip method (none on the boundary).

    Notes
    -----
    Large outlines that are star-shaped about their centroid (cycloid disc, gears, housing) are
    capped in linear time by a strip between the outline and either the single hole or an inner
    circle that encloses all holes; the rest, and everything else, by the GEOS constrained Delaunay
    triangulation (shapely ``constrained_delaunay_triangles``), which keeps the input vertices.
    The result is checked: every triangle has positive area and T = V + 2 H - 2 + (strip extras).
    """
    rings = [np.ascontiguousarray(r, dtype=np.float64) for r in rings]
    pts = np.concatenate(rings)
    n = len(pts)
    faces: np.ndarray | None = None
    extra = np.zeros((0, 2))
    if len(rings[0]) > STRIP_MIN_VERTICES:
        outer = rings[0]
        c = outer.mean(axis=0)
        if len(rings) == 2:
            f = _strip(outer, rings[1][::-1], c)
            if f is not None:
                nb = len(rings[1])
                inner = f >= len(outer)
                f[inner] = len(outer) + (nb - 1 - (f[inner] - len(outer)))
                faces = f
        if faces is None and interior:
            r_out = float(np.min(np.linalg.norm(outer - c, axis=1)))
            r_in = max([float(np.max(np.linalg.norm(h - c, axis=1))) for h in rings[1:]], default=0.0)
            if r_in < r_out:
                rc = 0.5 * (r_in + r_out) if len(rings) > 1 else 0.5 * r_out
                m = max(arc_steps(rc, 2.0 * math.pi, (r_out - rc) * 0.25), 12)
                m = max(m, int(math.ceil(2.0 * math.pi * rc / MAX_CHORD_MM)))
                circ = c + rc * _u(2.0 * math.pi * np.arange(m) / m)
                f_strip = _strip(outer, circ, c)
                if f_strip is not None:
                    f_strip = np.where(f_strip >= len(outer), f_strip - len(outer) + n, f_strip)
                    inner_rings = [circ] + rings[1:]
                    f_in = _cdt(inner_rings)
                    # map: circ -> n.., holes -> their place in pts
                    offs = np.cumsum([0] + [len(r) for r in inner_rings])
                    remap = np.empty(offs[-1], dtype=np.int64)
                    remap[:m] = n + np.arange(m)
                    remap[m:] = np.arange(len(outer), n)
                    faces = np.concatenate([f_strip, remap[f_in]])
                    extra = circ
    allp = np.concatenate([pts, extra])
    if faces is not None:
        if not _positive(allp, faces):
            faces, extra = None, np.zeros((0, 2))
            allp = pts
    if faces is None:
        faces = _cdt(rings)
    a, b, cc = allp[faces[:, 0]], allp[faces[:, 1]], allp[faces[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (cc[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (cc[:, 0] - a[:, 0])
    flip = area2 < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    expected = n + 2 * (len(rings) - 1) - 2 + 2 * len(extra)
    if len(faces) != expected or np.any(area2 == 0):
        raise RuntimeError(f"cap triangulation is not valid: {len(faces)} triangles for {n} vertices "
                           f"and {len(rings) - 1} holes (expected {expected}), {int(np.sum(area2 == 0))} degenerate")
    return faces, extra


# ----------------------------------------------------------------------------- meshes
@dataclass(frozen=True)
class Mesh:
    """Triangle mesh in float64 (mm), faces counter-clockwise seen from outside.

    Attributes
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def volume(self) -> float:
        """Enclosed volume by the divergence theorem, mm^3 (exact for the polyhedron)."""
        v = self.vertices
        a, b, c = v[self.faces[:, 0]], v[self.faces[:, 1]], v[self.faces[:, 2]]
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)

    @property
    def area(self) -> float:
        """Surface area, mm^2."""
        v = self.vertices
        a, b, c = v[self.faces[:, 0]], v[self.faces[:, 1]], v[self.faces[:, 2]]
        return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())

    def placed(self, x: float = 0.0, y: float = 0.0, rotation_deg: float = 0.0) -> "Mesh":
        """Copy rotated about +z by ``rotation_deg`` degrees, then moved by (x, y) mm (float64)."""
        v = self.vertices.copy()
        v[:, :2] = rotate2d(v[:, :2], math.radians(rotation_deg)) + np.array([x, y], dtype=np.float64)
        return Mesh(v, self.faces)

    def check(self) -> "Mesh":
        """Raise ``RuntimeError`` unless the mesh is closed, edge-manifold, consistently wound
        and encloses a positive volume. Returns ``self``."""
        f = self.faces
        nv = np.int64(len(self.vertices))
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        code = np.sort(e[:, 0] * nv + e[:, 1])
        rev = np.sort(e[:, 1] * nv + e[:, 0])
        if np.any(code[1:] == code[:-1]):
            raise RuntimeError("mesh has a directed edge twice (inconsistent winding or non-manifold)")
        if not np.array_equal(code, rev):
            raise RuntimeError("mesh is not watertight (an edge has no opposite)")
        if not self.volume > 0:
            raise RuntimeError(f"mesh volume {self.volume} mm^3 is not positive (faces inside out)")
        return self

    @staticmethod
    def concatenate(meshes: Sequence["Mesh"]) -> "Mesh":
        """One mesh holding several (vertex indices offset)."""
        vs, fs, off = [], [], 0
        for m in meshes:
            vs.append(m.vertices)
            fs.append(m.faces + off)
            off += len(m.vertices)
        return Mesh(np.concatenate(vs), np.concatenate(fs))

    def to_trimesh(self):  # -> trimesh.Trimesh
        """A ``trimesh.Trimesh`` of the same data (no vertex merging)."""
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def _walls(ring_lo: np.ndarray, ring_hi: np.ndarray) -> np.ndarray:
    """Side wall quads between two index rings (same length), outward for CCW outer rings."""
    a, b = ring_lo, np.roll(ring_lo, -1)
    c, d = np.roll(ring_hi, -1), ring_hi
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _tri(rings: Sequence[np.ndarray]) -> np.ndarray:
    """:func:`triangulate` without interior vertices (faces only)."""
    return triangulate(rings, interior=False)[0]


def extrude_rings(rings: Sequence[np.ndarray], z0: float, z1: float) -> Mesh:
    """Watertight prism of a polygon with holes between z0 < z1 (mm).

    Parameters
    ----------
    rings : sequence of (N_i, 2)
        Outer ring CCW, holes CW (vertex-exact samples of the outline).
    z0, z1 : float
        Bottom and top, mm.
    """
    rings = [np.asarray(r, dtype=np.float64) for r in rings]
    cap, extra = triangulate(rings)
    pts = np.concatenate(rings + [extra])
    n = len(pts)
    v = np.concatenate([np.c_[pts, np.full(n, z0)], np.c_[pts, np.full(n, z1)]])
    faces = [cap[:, ::-1], cap + n]
    off = 0
    for r in rings:
        idx = np.arange(off, off + len(r))
        faces.append(_walls(idx, idx + n))
        off += len(r)
    return Mesh(v, np.concatenate(faces).astype(np.int64))


def _circle_intersections(c1: np.ndarray, r1: float, c2: np.ndarray, r2: float) -> np.ndarray:
    d = c2 - c1
    dist = float(np.linalg.norm(d))
    a = (dist * dist + r1 * r1 - r2 * r2) / (2.0 * dist)
    h = math.sqrt(max(r1 * r1 - a * a, 0.0))
    ud = d / dist
    pm = c1 + a * ud
    perp = np.array([-ud[1], ud[0]])
    return np.array([pm - h * perp, pm + h * perp])


def stacked_circles(sections: Sequence[tuple[float, float, Sequence[float], float]], sagitta: float) -> Mesh:
    """Watertight mesh of a stack of circular cylinders (a crankshaft), vertex-exact on every circle.

    Parameters
    ----------
    sections : sequence of (z0, z1, center (2,), radius)
        Consecutive z intervals (each z1 equals the next z0), mm.
    sagitta : float
        Chord sagitta of the circles, mm.

    Notes
    -----
    Between two sections the step face is the annulus between nested circles, or, where the circles
    cross, the two crescents (their intersection points are inserted into both circles).
    """
    secs = [(float(a), float(b), np.asarray(c, dtype=np.float64), float(r)) for a, b, c, r in sections]
    for s0, s1 in zip(secs, secs[1:]):
        if abs(s0[1] - s1[0]) > 1e-12:
            raise ValueError("stacked sections must be contiguous in z")
    # angles (about each circle's centre) of extra vertices forced by crossing neighbours
    extra: list[list[float]] = [[] for _ in secs]
    crossings: list[np.ndarray | None] = []
    for i in range(len(secs) - 1):
        (_, _, ca, ra), (_, _, cb, rb) = secs[i], secs[i + 1]
        d = float(np.linalg.norm(cb - ca))
        if d + min(ra, rb) < max(ra, rb) - 1e-9:
            crossings.append(None)  # nested
            continue
        if d >= ra + rb or d < 1e-12:
            raise ValueError("stacked circular sections must overlap")
        x = _circle_intersections(ca, ra, cb, rb)
        crossings.append(x)
        extra[i] += [math.atan2(*(p - ca)[::-1]) for p in x]
        extra[i + 1] += [math.atan2(*(p - cb)[::-1]) for p in x]

    def ring_angles(r: float, forced: list[float]) -> np.ndarray:
        n = arc_steps(r, 2.0 * math.pi, sagitta)
        if not forced:
            return 2.0 * math.pi * np.arange(n) / n
        f = np.sort(np.mod(np.asarray(forced), 2.0 * math.pi))
        out = []
        for k in range(len(f)):
            a0 = f[k]
            a1 = f[(k + 1) % len(f)] + (2.0 * math.pi if k + 1 == len(f) else 0.0)
            m = arc_steps(r, a1 - a0, sagitta)
            out.append(a0 + (a1 - a0) * np.arange(m) / m)
        return np.concatenate(out)

    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    rings_idx: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (lo idx, hi idx, 2D pts)
    off = 0
    for (z0, z1, c, r), forced in zip(secs, extra):
        a = ring_angles(r, forced)
        p = c + r * _u(a)
        n = len(p)
        verts += [np.c_[p, np.full(n, z0)], np.c_[p, np.full(n, z1)]]
        lo, hi = np.arange(off, off + n), np.arange(off + n, off + 2 * n)
        faces.append(_walls(lo, hi))
        rings_idx.append((lo, hi, p))
        off += 2 * n
    # end caps
    lo0, _, p0 = rings_idx[0]
    faces.append(lo0[_tri([p0])][:, ::-1])
    _, hiN, pN = rings_idx[-1]
    faces.append(hiN[_tri([pN])])
    # steps
    remap = np.arange(off, dtype=np.int64)
    for i, x in enumerate(crossings):
        _, hi_a, pa = rings_idx[i]
        lo_b, _, pb = rings_idx[i + 1]
        if x is None:
            ra, rb = secs[i][3], secs[i + 1][3]
            if ra > rb:  # lower is larger: face looks up, annulus lower \ upper
                t = _tri([pa, pb[::-1]])
                idx = np.concatenate([hi_a, lo_b[::-1]])
                faces.append(idx[t])
            else:  # upper is larger: face looks down, annulus upper \ lower
                t = _tri([pb, pa[::-1]])
                idx = np.concatenate([lo_b, hi_a[::-1]])
                faces.append(idx[t][:, ::-1])
            continue
        # crossing circles: crescent A \ B looks up, crescent B \ A looks down
        ca, cb = secs[i][2], secs[i + 1][2]
        ra_, rb_ = secs[i][3], secs[i + 1][3]
        ia = [int(np.argmin(np.linalg.norm(pa - q, axis=1))) for q in x]
        ib = [int(np.argmin(np.linalg.norm(pb - q, axis=1))) for q in x]
        for ka, kb in zip(ia, ib):  # one vertex per crossing point: the lower ring's
            remap[lo_b[kb]] = hi_a[ka]
        out_a = np.linalg.norm(pa - cb, axis=1) > rb_ - 1e-12
        out_b = np.linalg.norm(pb - ca, axis=1) > ra_ - 1e-12
        for (pp, hh, iia, outside, qq, hq, iiq, up) in (
                (pa, hi_a, ia, out_a, pb, lo_b, ib, True), (pb, lo_b, ib, out_b, pa, hi_a, ia, False)):
            # walk pp (CCW) over its outside part from one crossing to the other, then walk qq back (CW)
            n1, n2 = len(pp), len(qq)
            start = next(k for k in iia if outside[(k + 1) % n1] and (k + 1) % n1 not in iia)
            other = iia[1] if start == iia[0] else iia[0]
            path1 = [start]
            k = start
            while k != other:
                k = (k + 1) % n1
                path1.append(k)
            s2 = iiq[iia.index(other)]
            e2 = iiq[iia.index(start)]
            path2 = []
            k = s2
            while k != e2:
                k = (k - 1) % n2
                path2.append(k)
            path2 = path2[:-1]
            ring = np.concatenate([pp[path1], qq[path2]]) if path2 else pp[path1]
            idx = np.concatenate([hh[path1], hq[path2]]) if path2 else hh[path1]
            t = _tri([ring])
            faces.append(idx[t] if up else idx[t][:, ::-1])
    return Mesh(np.concatenate(verts), remap[np.concatenate(faces).astype(np.int64)])


# ----------------------------------------------------------------------------- STL
_STL_DTYPE = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])


def stl_bytes(mesh: Mesh, header: str = "") -> bytes:
    """Binary STL of the mesh (float32 as the format requires; normals from the float64 mesh)."""
    v = mesh.vertices
    tri = v[mesh.faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.divide(nrm, ln, out=np.zeros_like(nrm), where=ln > 0)
    rec = np.zeros(len(tri), dtype=_STL_DTYPE)
    rec["normal"] = nrm
    rec["v"] = tri
    head = header.encode("ascii", "replace")[:80].ljust(80, b" ")
    return head + struct.pack("<I", len(tri)) + rec.tobytes()


def write_stl(target: str | Path | BinaryIO, mesh: Mesh, header: str = "") -> int:
    """Write a binary STL; returns the number of bytes. ``target`` is a path or a binary file."""
    data = stl_bytes(mesh, header)
    if isinstance(target, (str, Path)):
        Path(target).write_bytes(data)
    else:
        target.write(data)
    return len(data)


def read_stl(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a binary STL: triangles (T, 3, 3) float64 and normals (T, 3), mm (for checks)."""
    data = Path(path).read_bytes()
    n = struct.unpack("<I", data[80:84])[0]
    rec = np.frombuffer(data, dtype=_STL_DTYPE, count=n, offset=84)
    return rec["v"].astype(np.float64), rec["normal"].astype(np.float64)
