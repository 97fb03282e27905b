"""Closed forms shared by several test files (derivations in docs/physics.md)."""
from __future__ import annotations

import math

import numpy as np

from rvcad.geometry import ReducerGeometry


def pin_levers(geom: ReducerGeometry, theta_in: np.ndarray) -> np.ndarray:
    """Closed-form lever lam_i = (i Z1/Z2) e (n_i . u'(psi + k pi - theta_out)) of every pin at the ideal
    pose, mm, shape (steps, discs, pins).

    With the input held and stage I rigid, turning the output by dtheta turns the crank by
    (1 + Z1/Z2) dtheta; subtracting the conjugate motion (dpsi = -Zc dtheta, no gap change) leaves a
    pure crank turn of (i Z1/Z2) dtheta, which moves each disc by e u'(psi + k pi) per radian, so the
    gap of pin i changes by -lam_i dtheta. A common clearance dr is taken up at the largest lever:
    TE = -dr / max(lam). Since |n . u'| <= 1, max(lam) <= e i Z1/Z2.
    """
    d = geom.design
    to, ps = geom.ideal_state(theta_in)
    _, nrm, _, _ = geom.pin_gaps(to, ps)  # normals in the profile frames (= fixed frame rotated by theta_out)
    lam = np.empty(nrm.shape[:-1])
    for k in range(d.n_discs):
        a = ps[:, 0] + k * math.pi - to  # u' expressed in the disc frame
        up = np.stack([-np.sin(a), np.cos(a)], -1)
        lam[:, k] = d.ratio * d.z_sun / d.z_planet * d.eccentricity_mm * np.einsum("nzi,ni->nz", nrm[:, k], up)
    return lam
