"""Exact profile maths in plain numpy (no CAD kernel): the cycloid disc and the involute gears.

Conventions: lengths in mm, angles in radians inside this module. A profile is a curve in the
part's own frame; the part classes in :mod:`rvcad.parts` only turn these samples into solids,
and :mod:`rvdyn` measures distances to the same curves (one source of truth).

Cycloid disc
------------
In the frame of disc k (origin at the disc centre, axes turning with the disc) the centre of
every pin, under the ideal motion, runs along the pin-centre ("theoretical") curve

    q(t) = Rp u(t) - e u(Zp t + phi_c),   u(a) = (cos a, sin a),

with phi_c = k pi the cam phase of disc k (derivation in docs/physics.md). Its radius
|q|^2 = Rp^2 + e^2 - 2 Rp e cos(Zc t + phi_c) has Zc = Zp - 1 minima (roots, where a pin sits
deepest) and maxima (lobe tips). The disc boundary is the inner envelope of the pins of radius
rp: b(t) = q(t) - rp n(t), n the outward unit normal. Where rp exceeds the convex radius of
curvature of q near a tip, b(t) forms a swallowtail loop; the true boundary trims it at the
point where b crosses the lobe's symmetry axis (:attr:`CycloidProfile.trim_t`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numba import njit
from scipy.optimize import brentq

from rvcad.tolerances import TOL, Tolerances


#: Distance from the pin-centre curve (mm) beyond which the foot point is also searched globally
#: (the concave radius of curvature of the roots is 0.071 mm by default).
FAR_FOOT_MM = 0.05


def _u(a: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(a), np.sin(a)], axis=-1)


def _up(a: np.ndarray) -> np.ndarray:
    return np.stack([-np.sin(a), np.cos(a)], axis=-1)


@njit(cache=True, inline="always")
def _foot_newton_step(R, e, eZ, eZ2, c1, s1, c2, s2, px, py, max_step):
    """One Newton step (clipped to ``max_step``) of the foot-point condition (q(t) - p) . q'(t) = 0 of the
    pin-centre curve q(t) = R (cos t, sin t) - e (cos(Z t + phi), sin(Z t + phi)), from the trig terms at t
    (``eZ = e Z``, ``eZ2 = e Z^2``); returns the step and |q'(t)|^2 (a concave point, f' <= 0, steps along the
    gradient instead). One point (compiled, inlined in the kernels)."""
    dx = R * c1 - e * c2 - px
    dy = R * s1 - e * s2 - py
    d1x = -R * s1 + eZ * s2
    d1y = R * c1 - eZ * c2
    d2x = -R * c1 + eZ2 * c2
    d2y = -R * s1 + eZ2 * s2
    sp2 = d1x * d1x + d1y * d1y
    f = dx * d1x + dy * d1y
    fp = sp2 + dx * d2x + dy * d2y
    if not fp > 0:
        fp = sp2
    return min(max(f / fp, -max_step), max_step), sp2


@njit(cache=True)
def _foot_points_all_kernel(t0, px, py, R, e, Z, ph, max_step, tol_mm, max_iter):
    """Foot parameters t (K,) of the points (px, py) (K,) from t0 (K,): every point takes the Newton step of
    :func:`_foot_newton_step` (the trig terms evaluated directly) until all have moved their feet by less than
    ``tol_mm`` in one step (at most ``max_iter`` steps), so the feet do not depend on the order of the points
    but on the set (the reproducible default of :meth:`CycloidProfile.foot_point`)."""
    K = t0.shape[0]
    T = t0.copy()
    eZ = e * Z
    eZ2 = e * Z * Z
    for _ in range(max_iter):
        done = True
        for i in range(K):
            a2 = Z * T[i] + ph
            step, sp2 = _foot_newton_step(R, e, eZ, eZ2, math.cos(T[i]), math.sin(T[i]), math.cos(a2),
                                          math.sin(a2), px[i], py[i], max_step)
            T[i] = T[i] - step
            if not abs(step) * math.sqrt(sp2) < tol_mm:
                done = False
        if done:
            break
    return T


@njit(cache=True, inline="always")
def _sin_cos_small_1(x: float) -> tuple[float, float]:
    """sin x and cos x for |x| <= 0.05 by their Taylor series, with as many terms as |x| needs for remainders
    below 1e-19 (to x^9 and x^8 at 0.05; to x^3 and x^2 below 2e-5)."""
    x2 = x * x
    m = abs(x)
    if m < 2e-5:
        return x + x * x2 * (-1.0 / 6.0), 1.0 - 0.5 * x2
    if m < 2e-3:
        return (x + x * x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0)),
                1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0))))
    return (x + x * x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0)))),
            1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0)))))


@njit(cache=True)
def _foot_points_kernel(t0, P, R, e, Z, ph, max_step, tol_mm, max_iter):
    """Foot parameters t (K,) of the points P (K, 2) on ``q(t) = R u(t) - e u(Z t + ph)`` from t0 (K,), each
    point by its own Newton iteration (the step of :func:`_foot_newton_step`, clipped to ``max_step``) until
    it moves the foot by less than ``tol_mm`` (at most ``max_iter`` steps); returns t and cos t, sin t,
    cos(Z t + ph), sin(Z t + ph) at the feet (the trig terms carried by :func:`_sin_cos_small_1` after steps
    of Z |dt| <= 0.05, evaluated directly after larger ones). Each iteration sweeps the points still moving,
    so independent points overlap in the pipeline."""
    K = t0.shape[0]
    T = t0.copy()
    C1 = np.cos(T)
    S1 = np.sin(T)
    C2 = np.cos(Z * T + ph)
    S2 = np.sin(Z * T + ph)
    moving = np.ones(K, dtype=np.bool_)
    eZ = e * Z
    eZ2 = e * Z * Z
    for _ in range(max_iter):
        left = False
        for i in range(K):
            if not moving[i]:
                continue
            c1 = C1[i]
            s1 = S1[i]
            c2 = C2[i]
            s2 = S2[i]
            step, sp2 = _foot_newton_step(R, e, eZ, eZ2, c1, s1, c2, s2, P[i, 0], P[i, 1], max_step)
            t = T[i] - step
            T[i] = t
            zs = Z * step
            if abs(zs) > 0.05:
                C1[i] = math.cos(t)
                S1[i] = math.sin(t)
                a2 = Z * t + ph
                C2[i] = math.cos(a2)
                S2[i] = math.sin(a2)
            else:
                sa, ca = _sin_cos_small_1(step)
                sb, cb = _sin_cos_small_1(zs)
                C1[i] = c1 * ca + s1 * sa
                S1[i] = s1 * ca - c1 * sa
                C2[i] = c2 * cb + s2 * sb
                S2[i] = s2 * cb - c2 * sb
            if abs(step) * math.sqrt(sp2) >= tol_mm:
                left = True
            else:
                moving[i] = False
        if not left:
            break
    return T, C1, S1, C2, S2


@njit(cache=True)
def _curvature_kernel(t, R, e, Z, ph):
    """Signed curvature (1/mm) of ``q(t) = R u(t) - e u(Z t + ph)`` at each t (flat): ``q' = R u'(t) - e Z
    u'(Z t + ph)``, ``q'' = -R u(t) + e Z^2 u(Z t + ph)``, ``kappa = (q'_x q''_y - q'_y q''_x) / |q'|^3``."""
    out = np.empty(t.shape[0])
    eZ = e * Z
    eZ2 = e * Z ** 2
    for i in range(t.shape[0]):
        c1 = math.cos(t[i])
        s1 = math.sin(t[i])
        a2 = Z * t[i] + ph
        c2 = math.cos(a2)
        s2 = math.sin(a2)
        dx = R * -s1 - eZ * -s2
        dy = R * c1 - eZ * c2
        ddx = -R * c1 + eZ2 * c2
        ddy = -R * s1 + eZ2 * s2
        r = math.sqrt(dx * dx + dy * dy)
        out[i] = (dx * ddy - dy * ddx) / (r * r * r)
    return out


def sagitta_samples(t0: float, t1: float, speed, radius, sagitta: float, max_chord: float = 1.0,
                    n_grid: int = 20001) -> np.ndarray:
    """Parameter values on [t0, t1] whose chords have at most the given sagitta.

    Parameters
    ----------
    t0, t1 : float
        Parameter interval.
    speed : callable
        |dC/dt| in mm per unit parameter (vectorised).
    radius : callable
        Local radius of curvature of the curve, mm (vectorised, > 0; ``inf`` for straight).
    sagitta : float
        Largest chord sagitta (deviation of the chord midpoint from the arc), mm.
    max_chord : float
        Longest chord allowed whatever the curvature, mm.
    n_grid : int
        Points of the fine grid on which the chord density is integrated.

    Returns
    -------
    numpy.ndarray
        Increasing parameters including both ends. A chord of length c on an arc of radius R
        has sagitta c^2 / (8 R), so the allowed chord is sqrt(8 R s); the parameters are
        placed at equal steps of the integral of speed / chord, which a 10 % margin rounds up.
    """
    tg = np.linspace(t0, t1, n_grid)
    chord = np.minimum(np.sqrt(8.0 * np.asarray(radius(tg)) * sagitta), max_chord)
    dens = np.asarray(speed(tg)) / chord
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(tg))])
    n = max(1, int(math.ceil(cum[-1] * 1.1)))
    target = np.linspace(0.0, cum[-1], n + 1)
    t = np.interp(target, cum, tg)
    t[0], t[-1] = t0, t1
    return t


@dataclass(frozen=True)
class CycloidProfile:
    """Pin-centre curve and disc boundary of one cycloid disc, in the disc frame.

    Parameters
    ----------
    pin_circle_radius : float
        Rp, mm.
    eccentricity : float
        e, mm.
    z_pins : int
        Zp; the disc has Zc = Zp - 1 lobes.
    pin_radius : float
        Design pin radius rp the disc is cut for, mm.
    cam_phase : float
        phi_c, rad (0 for disc 0, pi for disc 1; equals turning the profile by pi/Zc).

    Attributes
    ----------
    z_lobes : int
        Zc.
    root_radius : float
        Smallest boundary radius Rp - e - rp, mm.
    tip_radius : float
        Largest boundary radius, mm (trimmed tip if undercut).
    min_convex_radius : float
        Smallest convex radius of curvature of the pin-centre curve, mm (undercut if rp above it).
    undercut : bool
        Whether the equidistant self-intersects and is trimmed.
    trim_t : float or None
        For lobe 0, the parameter (in [root_t, tip_t)) where the trimmed boundary meets the lobe axis.
    """

    pin_circle_radius: float
    eccentricity: float
    z_pins: int
    pin_radius: float
    cam_phase: float = 0.0
    tol: Tolerances = field(default=TOL, compare=False, repr=False)

    # -------------------------------------------------------------- curve and derivatives
    @property
    def z_lobes(self) -> int:
        return self.z_pins - 1

    def q(self, t: np.ndarray) -> np.ndarray:
        """Pin-centre curve q(t), shape (..., 2), mm."""
        t = np.asarray(t, dtype=float)
        return self.pin_circle_radius * _u(t) - self.eccentricity * _u(self.z_pins * t + self.cam_phase)

    def dq(self, t: np.ndarray) -> np.ndarray:
        """dq/dt, mm/rad."""
        t = np.asarray(t, dtype=float)
        return (self.pin_circle_radius * _up(t)
                - self.eccentricity * self.z_pins * _up(self.z_pins * t + self.cam_phase))

    def ddq(self, t: np.ndarray) -> np.ndarray:
        """d2q/dt2, mm/rad^2."""
        t = np.asarray(t, dtype=float)
        return (-self.pin_circle_radius * _u(t)
                + self.eccentricity * self.z_pins ** 2 * _u(self.z_pins * t + self.cam_phase))

    def normal(self, t: np.ndarray) -> np.ndarray:
        """Outward unit normal of q (pointing away from the disc material)."""
        d = self.dq(t)
        n = np.stack([d[..., 1], -d[..., 0]], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def curvature(self, t: np.ndarray) -> np.ndarray:
        """Signed curvature of q, 1/mm (positive where the disc is convex):
        ``(q'_x q''_y - q'_y q''_x) / |q'|^3`` (:meth:`dq`, :meth:`ddq`; compiled, :func:`_curvature_kernel`)."""
        t = np.asarray(t, dtype=float)
        return _curvature_kernel(np.ascontiguousarray(t).reshape(-1), float(self.pin_circle_radius),
                                 float(self.eccentricity), float(self.z_pins),
                                 float(self.cam_phase)).reshape(t.shape)

    def boundary(self, t: np.ndarray) -> np.ndarray:
        """Equidistant b(t) = q(t) - rp n(t) (the envelope of the pins), mm."""
        return self.q(t) - self.pin_radius * self.normal(t)

    def boundary_speed(self, t: np.ndarray) -> np.ndarray:
        """|db/dt| = |q'| |1 - rp kappa|, mm/rad."""
        return np.linalg.norm(self.dq(t), axis=-1) * np.abs(1.0 - self.pin_radius * self.curvature(t))

    def boundary_radius_of_curvature(self, t: np.ndarray) -> np.ndarray:
        """Radius of curvature of the boundary |1/kappa - rp|, mm."""
        k = self.curvature(t)
        with np.errstate(divide="ignore"):
            return np.abs(1.0 / k - self.pin_radius)

    # ------------------------------------------------------------------ landmarks
    def root_t(self, lobe: int = 0) -> float:
        """Parameter of root ``lobe`` (a pin sits there at the ideal pose), rad."""
        return (2.0 * math.pi * lobe - self.cam_phase) / self.z_lobes

    def tip_t(self, lobe: int = 0) -> float:
        """Parameter of the lobe tip following root ``lobe``, rad."""
        return self.root_t(lobe) + math.pi / self.z_lobes

    @property
    def root_radius(self) -> float:
        return self.pin_circle_radius - self.eccentricity - self.pin_radius

    @cached_property
    def min_convex_radius(self) -> float:
        t = np.linspace(self.root_t(), self.tip_t(), 40001)
        k = self.curvature(t)
        k = k[k > 0]
        return float(1.0 / k.max()) if k.size else math.inf

    @cached_property
    def trim_t(self) -> tuple[float, float] | None:
        """Trim interval (t1, t2) of the swallowtail on the rising half of lobe 0, or ``None``.

        Where rp exceeds the convex radius of curvature, b(t) turns back between two cusps
        (roots of 1 - rp kappa) and crosses itself: b(t1) = b(t2) with t1 before the first cusp
        and t2 after the second. The true boundary runs root -> t1, then t2 -> tip. Solved by a
        polyline intersection refined with a 2x2 Newton (scipy ``fsolve``) to 1e-13 mm.
        """
        if self.pin_radius < self.min_convex_radius:
            return None
        from scipy.optimize import fsolve

        t0, tt = self.root_t(), self.tip_t()
        tg = np.linspace(t0, tt, 20001)
        f = 1.0 - self.pin_radius * self.curvature(tg)
        idx = np.nonzero(np.sign(f[1:]) != np.sign(f[:-1]))[0]
        if idx.size < 2:
            return None
        ta = float(brentq(lambda x: 1.0 - self.pin_radius * float(self.curvature(np.array(x))), tg[idx[0]], tg[idx[0] + 1]))
        tb = float(brentq(lambda x: 1.0 - self.pin_radius * float(self.curvature(np.array(x))), tg[idx[1]], tg[idx[1] + 1]))
        a_t = np.linspace(t0, ta, 3001)
        c_t = np.linspace(tb, tt, 3001)
        A, C = self.boundary(a_t), self.boundary(c_t)
        # segment intersection A[i]A[i+1] x C[j]C[j+1]
        p0, r = A[:-1, None, :], (A[1:] - A[:-1])[:, None, :]
        q0, s_ = C[None, :-1, :], (C[1:] - C[:-1])[None, :, :]
        den = r[..., 0] * s_[..., 1] - r[..., 1] * s_[..., 0]
        qp = q0 - p0
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (qp[..., 0] * s_[..., 1] - qp[..., 1] * s_[..., 0]) / den
            v = (qp[..., 0] * r[..., 1] - qp[..., 1] * r[..., 0]) / den
        hit = np.argwhere((u >= 0) & (u <= 1) & (v >= 0) & (v <= 1))
        if hit.size == 0:
            raise ValueError(
                f"pin_radius {self.pin_radius} mm undercuts the cycloid so deeply that the trimmed profile "
                "cannot be built (the swallowtails meet at the lobe tips); use a smaller pin radius")
        i, j = hit[-1]
        g0 = np.array([a_t[i] + u[i, j] * (a_t[i + 1] - a_t[i]), c_t[j] + v[i, j] * (c_t[j + 1] - c_t[j])])
        sol = fsolve(lambda x: self.boundary(np.array(x[0])) - self.boundary(np.array(x[1])), g0, xtol=1e-13)
        return float(sol[0]), float(sol[1])

    @property
    def undercut(self) -> bool:
        return self.trim_t is not None

    @property
    def tip_radius(self) -> float:
        return float(np.linalg.norm(self.boundary(np.array(self.tip_t()))))

    def design_check(self) -> dict[str, float | bool | str]:
        """Report of the profile's feasibility (units in the keys)."""
        rep: dict[str, float | bool | str] = {
            "min_convex_radius_mm": self.min_convex_radius,
            "pin_radius_mm": self.pin_radius,
            "undercut": self.undercut,
            "root_radius_mm": self.root_radius,
            "tip_radius_mm": self.tip_radius,
        }
        if self.undercut:
            rep["trim_t_rad"] = str(self.trim_t)
            rep["message"] = (f"pin radius {self.pin_radius} mm exceeds the smallest convex radius of curvature "
                              f"{self.min_convex_radius:.4f} mm of the pin-centre curve: the profile is undercut "
                              "at the lobe tips; the swallowtail loops are trimmed")
        else:
            rep["message"] = "no undercut"
        return rep

    # ------------------------------------------------------------------ sampling
    def half_lobe_t(self, sagitta: float | None = None) -> np.ndarray:
        """Sagitta-controlled parameters from root 0 to the tip (or trim point) of lobe 0."""
        s = self.tol.sagitta_mm if sagitta is None else sagitta
        trim = self.trim_t
        if trim is None:
            return sagitta_samples(self.root_t(), self.tip_t(), self.boundary_speed,
                                   self.boundary_radius_of_curvature, s)
        a = sagitta_samples(self.root_t(), trim[0], self.boundary_speed, self.boundary_radius_of_curvature, s)
        b = sagitta_samples(trim[1], self.tip_t(), self.boundary_speed, self.boundary_radius_of_curvature, s)
        return np.concatenate([a, b[1:]])

    def boundary_t(self, sagitta: float | None = None) -> np.ndarray:
        """Parameters of a closed sampling of the whole boundary (no repeated end point).

        Each lobe is sampled symmetrically about its axis, sagitta-controlled, so no chord
        deviates from the exact envelope by more than ``sagitta`` mm. With an undercut each trim
        point is a corner, sampled once (at t1; b(t2) is the same point).
        """
        h = self.half_lobe_t(sagitta)
        r0 = self.root_t()
        rel = h - r0
        two = 2.0 * math.pi / self.z_lobes
        lobe = np.concatenate([rel[:-1], two - rel[::-1][:-1]])
        return r0 + (np.arange(self.z_lobes)[:, None] * two + lobe[None, :]).ravel()

    def boundary_points(self, sagitta: float | None = None) -> np.ndarray:
        """Boundary polygon (N, 2), mm, counter-clockwise, every vertex on the exact envelope."""
        t = self.boundary_t(sagitta)
        return self.boundary(t)

    # ------------------------------------------------------------------ distances
    def foot_point(self, p: np.ndarray, t0: np.ndarray, per_point: bool = False) -> np.ndarray:
        """Parameter of the closest point of q to each p (vectorised Newton from t0).

        Parameters
        ----------
        p : (K, 2) array, mm
        t0 : (K,) array, rad
            Starting parameters (the ideal-motion parameter of the pin is a good one).
        per_point : bool
            False: every point iterates until all have converged (the reproducible default). True: each
            point stops at its own convergence (fewer evaluations; the feet differ by rounding, ~1e-15 rad).

        Returns
        -------
        (K,) array of rad. Newton on f(t) = (q - p).q' with f' = |q'|^2 + (q - p).q'' (replaced
        by |q'|^2 where not positive), steps clipped to a quarter lobe pitch, until the foot
        point moves less than ``Tolerances.foot_point_mm``.
        """
        p = np.asarray(p, dtype=float)
        if per_point:
            return self._foot_point_per_point(p, t0)
        px, py, t = np.broadcast_arrays(p[..., 0], p[..., 1], np.asarray(t0, dtype=float))
        flat = [np.ascontiguousarray(v, dtype=float).reshape(-1) for v in (t, px, py)]
        out = _foot_points_all_kernel(*flat, float(self.pin_circle_radius), float(self.eccentricity),
                                      float(self.z_pins), float(self.cam_phase), 0.25 * math.pi / self.z_lobes,
                                      float(self.tol.foot_point_mm), int(self.tol.foot_point_max_iter))
        return out.reshape(t.shape)

    def _foot_point_per_point(self, p: np.ndarray, t0: np.ndarray, trig: bool = False):
        """:meth:`foot_point` with each point stopping at its own convergence (the same Newton step).

        Compiled (:func:`_foot_points_kernel`): the trig terms of t and Z t + phi_c are evaluated once; after
        each Newton step of Z |dt| <= 0.05 they follow by the angle-addition formulas with the Taylor series of
        the small angle (remainders below 1e-19), so they agree with direct evaluation to a few rounding errors.
        ``trig``: also return cos t, sin t, cos(Z t + phi_c), sin(Z t + phi_c) at the feet."""
        t = np.ascontiguousarray(t0, dtype=float).reshape(-1)
        P = np.ascontiguousarray(p, dtype=float).reshape(-1, 2)
        T = _foot_points_kernel(t, P, float(self.pin_circle_radius), float(self.eccentricity),
                                float(self.z_pins), float(self.cam_phase), 0.25 * math.pi / self.z_lobes,
                                float(self.tol.foot_point_mm), int(self.tol.foot_point_max_iter))
        shape = np.shape(t0)
        if trig:
            return tuple(v.reshape(shape) for v in T)
        return T[0].reshape(shape)

    def signed_distance(self, p: np.ndarray, t0: np.ndarray,
                        per_point: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance of points to the pin-centre curve q (positive outside the disc).

        Returns
        -------
        sd : (K,) mm
        t : (K,) foot parameters, rad
        n : (K, 2) outward unit normals at the foot points
        """
        p = np.asarray(p, dtype=float)
        # q(t) and the normal from one evaluation of the four trig terms (the same operations in the
        # same order as :meth:`q` and :meth:`normal`, so bit-identical to them, at half the trig cost;
        # the norm and the dot product written out are the same sums as np.linalg.norm and einsum)
        R, e, Z = self.pin_circle_radius, self.eccentricity, self.z_pins
        if per_point:
            t, c1, s1, c2, s2 = self._foot_point_per_point(p, t0, trig=True)
        else:
            t = self.foot_point(p, t0)
            c1, s1 = np.cos(t), np.sin(t)
            a2 = Z * t + self.cam_phase
            c2, s2 = np.cos(a2), np.sin(a2)
        eZ = e * Z
        d1x = R * -s1 - eZ * -s2
        d1y = R * c1 - eZ * c2
        mx = -d1x
        r = np.sqrt(d1y * d1y + mx * mx)
        n = np.empty(np.shape(t) + (2,))
        n[..., 0] = d1y / r
        n[..., 1] = mx / r
        qt = np.empty_like(n)
        qt[..., 0] = R * c1 - e * c2
        qt[..., 1] = R * s1 - e * s2
        sd = (p[..., 0] - qt[..., 0]) * n[..., 0] + (p[..., 1] - qt[..., 1]) * n[..., 1]
        # Newton from t0 finds the nearest foot for points closer than the roots' concave radius
        # of curvature (~0.07 mm on the pin-centre curve); farther out a second local foot can
        # exist: search a lobe pitch either side on a grid and keep the nearer foot.
        # (both sides: a pin with clearance stands outside; a point of an undercut envelope inside
        # can have its Newton foot on the trimmed swallowtail)
        far = np.abs(sd) > FAR_FOOT_MM
        if np.any(far):
            pf = p[far]
            start = self._far_foot_starts(pf, t[far])
            t2 = self.foot_point(pf, start, per_point)
            d_old = np.linalg.norm(pf - qt[far], axis=-1)
            d_new = np.linalg.norm(pf - self.q(t2), axis=-1)
            better = d_new < d_old - 1e-12
            if np.any(better):
                idx = np.nonzero(far)[0][better]
                t[idx] = t2[better]
                n[idx] = self.normal(t[idx])
                sd[idx] = np.einsum("...i,...i->...", p[idx] - self.q(t[idx]), n[idx])
        return sd, t, n

    def _far_foot_starts(self, pf: np.ndarray, tf: np.ndarray) -> np.ndarray:
        """Newton starts (rad) for the points ``pf`` (mm) whose feet ``tf`` (rad) are far: the nearest of 129
        points of q on a grid over a lobe pitch either side of each foot."""
        R, e, Z = self.pin_circle_radius, self.eccentricity, self.z_pins
        grid = np.linspace(-1.0, 1.0, 129) * (2.0 * math.pi / self.z_lobes)
        start = np.empty_like(tf)
        # q on the grid t + g by the angle-addition formulas: the trig of the 129 offsets once, of
        # each foot once, products on the grid (q agrees with :meth:`q` to rounding, ~1e-14 mm, so
        # the nearest grid point, hence the Newton start, is the same but at rounding-level ties, where
        # either start leads to an equally near foot)
        Rcg, Rsg = R * np.cos(grid), R * np.sin(grid)
        ecg, esg = e * np.cos(Z * grid), e * np.sin(Z * grid)
        a2f = Z * tf + self.cam_phase
        cf1, sf1, cf2, sf2 = np.cos(tf), np.sin(tf), np.cos(a2f), np.sin(a2f)
        chunk = 1024  # 1024 x 129 grid points at a time, in place (cache-sized work arrays)
        gx, gy, tmp = (np.empty((min(chunk, len(pf)), grid.size)) for _ in range(3))
        for c0 in range(0, len(pf), chunk):
            sl = slice(c0, c0 + chunk)
            m = len(tf[sl])
            x, y, w = gx[:m], gy[:m], tmp[:m]
            c1g, s1g = cf1[sl, None], sf1[sl, None]
            c2g, s2g = cf2[sl, None], sf2[sl, None]
            # x = R cos(t+g) - e cos(Z(t+g)+phi_c) - px, y likewise (evaluated left to right)
            np.multiply(c1g, Rcg, out=x)
            np.multiply(s1g, Rsg, out=w)
            x -= w
            np.multiply(c2g, ecg, out=w)
            x -= w
            np.multiply(s2g, esg, out=w)
            x += w
            x -= pf[sl, 0, None]
            np.multiply(s1g, Rcg, out=y)
            np.multiply(c1g, Rsg, out=w)
            y += w
            np.multiply(s2g, ecg, out=w)
            y -= w
            np.multiply(c2g, esg, out=w)
            y -= w
            y -= pf[sl, 1, None]
            x *= x
            y *= y
            x += y
            start[sl] = tf[sl] + grid[np.argmin(x, axis=1)]
        return start

    def boundary_distance(self, p: np.ndarray, t0: np.ndarray,
                          per_point: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance of points to the disc boundary (positive outside), mm.

        Exact wherever the foot point lies on the untrimmed part of the envelope (all pin
        contacts of a working disc): distance to the equidistant = distance to q + rp.
        ``per_point``: see :meth:`foot_point`.
        """
        sd, t, n = self.signed_distance(p, t0, per_point)
        return sd + self.pin_radius, t, n


#: Largest profile modification accepted (mm for equidistant and shift, degrees for rotation).
MAX_MODIFICATION = {"profile_equidistant_mm": 0.2, "profile_shift_mm": 0.2, "profile_rotation_deg": 0.5}


def modified_profile_parameters(design) -> tuple[float, float, float]:
    """Generating parameters of the modified disc profile: ``(Rp + shift, rp + equidistant, rotation rad)``.

    Equidistant modification: the disc is cut for a pin (wheel) radius ``rp + d_rp``; shift (offset)
    modification: the wheel centre runs on ``Rp + d_Rp``; rotation modification: the profile is turned by
    ``delta`` relative to the crank holes. The pin-centre curve becomes ``(Rp + d_Rp) u(t) - e u(Zp t)``
    and the boundary its inner equidistant at ``rp + d_rp``. Raises ``ValueError`` naming the field when
    a modification is out of its range (:data:`MAX_MODIFICATION`).
    """
    for name, lim in MAX_MODIFICATION.items():
        v = getattr(design, name, 0.0)
        if not abs(v) <= lim:
            raise ValueError(f"design.{name} {v!r} is out of range; |value| <= {lim}")
    return (design.pin_circle_radius_mm + design.profile_shift_mm, design.pin_radius_mm + design.profile_equidistant_mm,
            math.radians(design.profile_rotation_deg))


def inv(a: np.ndarray | float) -> np.ndarray | float:
    """Involute function tan(a) - a."""
    return np.tan(a) - a


@dataclass(frozen=True)
class InvoluteGear:
    """External involute spur gear, plain numpy.

    Parameters
    ----------
    z : int
        Teeth.
    module : float
        mm.
    pressure_angle : float
        rad.
    shift : float
        Profile shift coefficient x.
    backlash : float
        Circumferential thinning of each tooth on the pitch circle, mm.

    Attributes
    ----------
    pitch_radius, base_radius, tip_radius, root_radius : float
        mm.
    tooth_thickness : float
        On the pitch circle, mm.
    flank_origin : float
        Polar angle (rad, tooth centred on +x) where the upper flank (the one facing +theta,
        an involute unwinding clockwise) leaves the base circle; the lower flank's is its negative.
    """

    z: int
    module: float
    pressure_angle: float
    shift: float = 0.0
    backlash: float = 0.0
    tol: Tolerances = field(default=TOL, compare=False, repr=False)

    @property
    def pitch_radius(self) -> float:
        return self.module * self.z / 2.0

    @property
    def base_radius(self) -> float:
        return self.pitch_radius * math.cos(self.pressure_angle)

    @property
    def tip_radius(self) -> float:
        return self.pitch_radius + self.module * (1.0 + self.shift)

    @property
    def root_radius(self) -> float:
        return self.pitch_radius - self.module * (1.25 - self.shift)

    @property
    def base_pitch(self) -> float:
        return 2.0 * math.pi * self.base_radius / self.z

    @property
    def tooth_thickness(self) -> float:
        return self.module * (math.pi / 2.0 + 2.0 * self.shift * math.tan(self.pressure_angle)) - self.backlash

    @property
    def flank_origin(self) -> float:
        return self.tooth_thickness / (2.0 * self.pitch_radius) + float(inv(self.pressure_angle))

    def flank_polar_angle(self, r: np.ndarray) -> np.ndarray:
        """Polar angle of the upper flank at radius r (>= base radius), rad."""
        a = np.arccos(np.clip(self.base_radius / np.asarray(r, dtype=float), -1.0, 1.0))
        return self.flank_origin - inv(a)

    def tip_half_angle(self) -> float:
        return float(self.flank_polar_angle(self.tip_radius))

    def flank_points(self, r_start: float | None = None, sagitta: float | None = None) -> np.ndarray:
        """Upper flank of tooth 0 from r_start (default the larger of base and root) to the tip.

        Sampled in roll angle with chords of at most ``sagitta`` mm: the involute's radius of
        curvature at roll angle lam is rb*lam and its arc length rb*lam^2/2.
        """
        s = self.tol.involute_sagitta_mm if sagitta is None else sagitta
        rb = self.base_radius
        r0 = max(rb, self.root_radius) if r_start is None else max(rb, r_start)
        lam0 = math.sqrt(max((r0 / rb) ** 2 - 1.0, 0.0))
        lam1 = math.sqrt((self.tip_radius / rb) ** 2 - 1.0)
        lam = sagitta_samples(lam0, lam1, lambda x: rb * np.maximum(x, 1e-12),
                              lambda x: rb * np.maximum(x, 1e-9), s, max_chord=0.25, n_grid=4001)
        return self.involute(lam)

    def involute(self, lam: np.ndarray) -> np.ndarray:
        """Upper-flank point at roll angle lam: rb u(xi - lam) + rb lam u'(xi - lam), mm."""
        lam = np.asarray(lam, dtype=float)
        a = self.flank_origin - lam
        return self.base_radius * (_u(a) + lam[..., None] * _up(a))

    def outline(self, sagitta: float | None = None, root_arc_step: float = 0.05) -> np.ndarray:
        """Closed counter-clockwise outline of the whole gear (N, 2), mm, tooth 0 centred on +x.

        Per tooth: root arc, radial line up to the base circle (where the root is below it),
        lower flank, tip arc, upper flank, radial line, root arc. Involute points are exact.
        """
        up = self.flank_points(sagitta=sagitta)
        rb, rf, ra = self.base_radius, self.root_radius, self.tip_radius
        ang_up = np.arctan2(up[:, 1], up[:, 0])
        low = up[::-1] * np.array([1.0, -1.0])  # mirror: lower flank from tip down... reversed below
        low = low[::-1]  # lower flank from base to tip
        tooth: list[np.ndarray] = []
        a_base = float(ang_up[0])
        if rf < rb:
            tooth.append(np.array([[rf * math.cos(-a_base), rf * math.sin(-a_base)]]))
        tooth.append(low)
        ta = float(ang_up[-1])
        n_tip = max(2, int(math.ceil(2 * ta * ra / root_arc_step)))
        tip = np.linspace(-ta, ta, n_tip + 1)[1:-1]
        tooth.append(ra * _u(tip))
        tooth.append(up[::-1])
        if rf < rb:
            tooth.append(np.array([[rf * math.cos(a_base), rf * math.sin(a_base)]]))
        gap_start = a_base
        gap_end = 2 * math.pi / self.z - a_base
        n_root = max(2, int(math.ceil((gap_end - gap_start) * rf / root_arc_step)))
        root = np.linspace(gap_start, gap_end, n_root + 1)[1:-1]
        if rf >= rb:
            root_pts = rf * _u(root)
        else:
            root_pts = rf * _u(root)
        tooth.append(root_pts)
        one = np.concatenate(tooth)
        out = []
        for k in range(self.z):
            c, s_ = math.cos(2 * math.pi * k / self.z), math.sin(2 * math.pi * k / self.z)
            out.append(one @ np.array([[c, s_], [-s_, c]]))
        return np.concatenate(out)
