"""Planar helpers of the profile layer: unit vectors, rotations and the chord count of an arc.

Plain numpy; lengths in mm, angles in rad.
"""
from __future__ import annotations

import math

import numpy as np

#: Longest chord of any sampled circle or arc, mm, whatever the sagitta (keeps large radii from
#: producing long skinny cap triangles).
MAX_CHORD_MM = 1.0


def unit(a: np.ndarray | float) -> np.ndarray:
    """Unit vectors (cos a, sin a), shape (..., 2), for angles a in rad."""
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



__all__ = ["MAX_CHORD_MM", "arc_steps", "rotate2d", "unit"]
