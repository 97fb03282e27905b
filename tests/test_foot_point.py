"""CycloidProfile.signed_distance against the reference implementation it replaced (bit-identical).

The reference below is the pre-optimisation ``signed_distance`` (q and the normal evaluated by the
public methods, the global foot search for points more than FAR_FOOT_MM off the curve), kept here only
as the test oracle. Points: near and far from the pin-centre curve, both sides, all around the disc,
on several designs including the 4.8 mm undercut pin radius and the cam phase pi (disc 1).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcad.profile import FAR_FOOT_MM, CycloidProfile


def reference_signed_distance(prof: CycloidProfile, p: np.ndarray, t0: np.ndarray):
    """The signed distance as implemented before the shared-trig evaluation (the oracle)."""
    p = np.asarray(p, dtype=float)
    t = prof.foot_point(p, t0)
    n = prof.normal(t)
    sd = np.einsum("...i,...i->...", p - prof.q(t), n)
    far = np.abs(sd) > FAR_FOOT_MM
    if np.any(far):
        pf = p[far]
        grid = np.linspace(-1.0, 1.0, 129) * (2.0 * math.pi / prof.z_lobes)
        tf = t[far]
        start = np.empty_like(tf)
        for c0 in range(0, len(pf), 4096):
            sl = slice(c0, c0 + 4096)
            tg = tf[sl, None] + grid[None, :]
            dist2 = ((prof.q(tg) - pf[sl, None, :]) ** 2).sum(axis=-1)
            start[sl] = tg[np.arange(tg.shape[0]), np.argmin(dist2, axis=1)]
        t2 = prof.foot_point(pf, start)
        d_old = np.linalg.norm(pf - prof.q(t[far]), axis=-1)
        d_new = np.linalg.norm(pf - prof.q(t2), axis=-1)
        better = d_new < d_old - 1e-12
        if np.any(better):
            idx = np.nonzero(far)[0][better]
            t[idx] = t2[better]
            n[idx] = prof.normal(t[idx])
            sd[idx] = np.einsum("...i,...i->...", p[idx] - prof.q(t[idx]), n[idx])
    return sd, t, n


DESIGNS = [(64.0, 1.3, 40, 3.0, 0.0), (64.0, 1.3, 40, 3.0, math.pi), (64.0, 1.3, 40, 4.8, 0.0),
           (64.0, 1.3, 40, 4.8, math.pi), (50.0, 1.0, 30, 2.5, 0.0), (80.0, 2.0, 24, 4.0, math.pi)]


def _points(prof: CycloidProfile, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points at offsets from 1e-6 mm to 2 mm (log-uniform), both sides, and perturbed Newton starts."""
    t = rng.uniform(0.0, 2.0 * math.pi, n)
    off = np.exp(rng.uniform(math.log(1e-6), math.log(2.0), n)) * rng.choice([-1.0, 1.0], n)
    p = prof.q(t) + off[:, None] * prof.normal(t) + rng.normal(0.0, 0.01, (n, 2))
    t0 = t + rng.normal(0.0, 0.3 * math.pi / prof.z_lobes, n)
    return p, t0


@pytest.mark.parametrize("design", DESIGNS, ids=[f"R{d[0]}-e{d[1]}-Z{d[2]}-rp{d[3]}-ph{d[4]:.2f}" for d in DESIGNS])
def test_signed_distance_matches_reference(design):
    prof = CycloidProfile(*design)
    rng = np.random.default_rng(hash(design) % 2 ** 32)
    p, t0 = _points(prof, rng, 20000)
    sd, t, n = prof.signed_distance(p, t0)
    sd_ref, t_ref, n_ref = reference_signed_distance(prof, p, t0)
    far = np.abs(sd_ref) > FAR_FOOT_MM
    assert far.sum() > 1000 and (~far).sum() > 1000  # both branches exercised
    assert (sd_ref > 0).sum() > 1000 and (sd_ref < 0).sum() > 1000  # both sides
    np.testing.assert_array_equal(sd, sd_ref)
    np.testing.assert_array_equal(t, t_ref)
    np.testing.assert_array_equal(n, n_ref)


def test_signed_distance_consistent_with_public_curve():
    """The returned sd is the projection of p - q(t) on the public normal at the returned foot."""
    prof = CycloidProfile(64.0, 1.3, 40, 3.0)
    p, t0 = _points(prof, np.random.default_rng(7), 5000)
    sd, t, n = prof.signed_distance(p, t0)
    np.testing.assert_array_equal(n, prof.normal(t))
    np.testing.assert_array_equal(sd, np.einsum("...i,...i->...", p - prof.q(t), prof.normal(t)))
