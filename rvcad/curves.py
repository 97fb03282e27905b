"""The reducer's exact curves as outline pieces: cycloid envelope and involute flanks.

Distances of points to the exact curves (for the fit checks and the deviation reports) and the
:class:`~rvcad.outline.ExactCurve` pieces of a disc lobe and a gear flank, plus the closed gear
outline. numpy only; lengths in mm, angles in rad.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from rvcad.outline import ArcSeg, CurveSeg, ExactCurve, LineSeg, Loop
from rvcad.plane import MAX_CHORD_MM, rotate2d
from rvcad.profile import CycloidProfile, InvoluteGear, sagitta_samples

#: Points per call of the cycloid foot-point search (its global search holds a 129-point grid per
#: point: 8192 points take about 25 MB).
DISTANCE_CHUNK = 8192


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


def gear_outline(gear: InvoluteGear, center: tuple[float, float] = (0.0, 0.0)) -> Loop:
    """Closed CCW outline of an external involute gear, tooth 0 centred on +x (mm).

    Per tooth: radial line from the root circle up to the base circle (where the root is below
    it), lower flank (exact involute), tip arc, upper flank, radial line, root arc: the same
    outline as :meth:`InvoluteGear.outline`, with exact arcs.
    """
    curve = involute_flank_curve(gear)
    up0 = gear.involute(np.array([curve.t0]))[0]  # upper flank start (base or root circle)
    up1 = gear.involute(np.array([curve.t1]))[0]  # upper flank tip
    a_base = math.atan2(up0[1], up0[0])
    a_tip = math.atan2(up1[1], up1[0])
    rf, rb, ra = gear.root_radius, gear.base_radius, gear.tip_radius
    pitch = 2.0 * math.pi / gear.z
    c = np.asarray(center, dtype=np.float64)
    segs: list[Any] = []
    for k in range(gear.z):
        rot = k * pitch
        lower_start = rotate2d(up0 * np.array([1.0, -1.0]), rot) + c
        if rf < rb:
            root_pt = c + rf * np.array([math.cos(rot - a_base), math.sin(rot - a_base)])
            segs.append(LineSeg(tuple(root_pt), tuple(lower_start)))
        segs.append(CurveSeg(curve, rotation=rot, offset=tuple(c), mirror=True))
        segs.append(ArcSeg(tuple(c), ra, rot - a_tip, rot + a_tip))
        segs.append(CurveSeg(curve, rotation=rot, offset=tuple(c), reverse=True))
        upper_start = rotate2d(up0, rot) + c
        if rf < rb:
            root_pt = c + rf * np.array([math.cos(rot + a_base), math.sin(rot + a_base)])
            segs.append(LineSeg(tuple(upper_start), tuple(root_pt)))
        segs.append(ArcSeg(tuple(c), rf, rot + a_base, rot + pitch - a_base))
    return Loop(tuple(segs))



__all__ = ["DISTANCE_CHUNK", "cycloid_curves", "cycloid_deviation", "gear_outline", "involute_deviation",
           "involute_flank_curve"]
