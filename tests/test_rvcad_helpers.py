"""Measuring helpers shared by the rvcad tests (read exported files back and measure them, mm), and
their own check."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from rvcad.stl import read_stl


def stl_vertices(path: Path) -> np.ndarray:
    """Distinct vertices (V, 3) of a binary STL, float64 of the stored float32, mm."""
    tri, _ = read_stl(path)
    return np.unique(tri.reshape(-1, 3), axis=0)


def stl_chords(path: Path) -> np.ndarray:
    """Outline chords of an extruded part from its STL: the horizontal edges of the side-wall
    triangles, as (K, 2, 3) end points, mm."""
    tri, nrm = read_stl(path)
    wall = tri[np.abs(nrm[:, 2]) < 0.5]
    out = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        same = wall[:, a, 2] == wall[:, b, 2]
        out.append(np.stack([wall[same, a], wall[same, b]], axis=1))
    return np.concatenate(out)


def fit_circle(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares (Kasa) circle through 2D points: centre (2,), radius, mm (exact for points on a circle)."""
    p = np.asarray(p, dtype=np.float64)[:, :2]
    m = p.mean(axis=0)
    q = p - m
    A = np.c_[q, np.ones(len(q))]
    b = -(q ** 2).sum(axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    c = -0.5 * sol[:2]
    r = float(np.sqrt(c @ c - sol[2]))
    return c + m, r


def test_fit_circle_is_exact_for_points_on_a_circle() -> None:
    a = np.linspace(0.0, 2.0 * np.pi, 97)[:-1]
    c0, r0 = np.array([64.0, -0.5]), 3.007
    c, r = fit_circle(c0 + r0 * np.c_[np.cos(a), np.sin(a)])
    assert np.abs(c - c0).max() < 1e-12
    assert abs(r - r0) < 1e-12
