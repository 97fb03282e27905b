"""The compiled (numba) kernels against independent numpy forms of the same quantities.

Each kernel replaced a vectorised numpy form; these tests compare it with a form that does not share its
code: LAPACK's solve, the residual of the equation it solves, LineContact's own inversion, the curvature from
``dq``/``ddq`` and the all-points Newton of ``foot_point``.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcad.profile import CycloidProfile
from rvdyn.contacts import PhysicalLaw
from rvdyn.materials import MATERIALS, LineContact
from rvdyn.support_eq import batch_solve, radial_law, series_deflection


@pytest.mark.parametrize("shape,n,r", [((7,), 8, 11), ((3, 2), 10, 1), ((1,), 2, 3)])
def test_batch_solve_equals_lapack_on_spd_batches(shape, n, r):
    rng = np.random.default_rng(n * r)
    M = rng.normal(size=shape + (n, n))
    A = M @ np.swapaxes(M, -1, -2) + n * np.eye(n)
    B = rng.normal(size=shape + (n, r))
    X = batch_solve(A, B)
    assert X.shape == B.shape
    np.testing.assert_allclose(X, np.linalg.solve(A, B), rtol=1e-11, atol=1e-13)
    A0, B0 = A.copy(), B.copy()
    batch_solve(A, B)
    assert np.array_equal(A, A0) and np.array_equal(B, B0)          # the inputs are not modified


def test_series_deflection_solves_its_equation_entry_by_entry():
    K, p, cs = 1.7e5, 10.0 / 9.0, 3e-7
    t = np.concatenate([[0.0, 1e-12], np.geomspace(1e-9, 0.05, 200)]).reshape(2, -1)
    x = series_deflection(t, K, p, cs)
    assert x.shape == t.shape and np.all(x >= 0.0) and np.all(x <= t)
    resid = x + cs * K * x ** p - t
    assert np.all(np.abs(resid) <= 8 * np.finfo(float).eps * np.maximum(t, 1e-300))
    assert x.ravel()[0] == 0.0
    # an entry's value does not depend on the others in the array (each stops on its own test)
    assert series_deflection(t[:, 57:58], K, p, cs)[1, 0] == x[1, 57]


def test_radial_law_with_a_seat_matches_the_series_closed_forms():
    K, p, cs = 1.7e5, 10.0 / 9.0, 3e-7
    d = np.array([[3e-3, -4e-3], [1e-5, 0.0]])
    E, f, H = radial_law(d, K, p, 0.0, True, 0.0, cs)
    x = series_deflection(np.hypot(d[:, 0], d[:, 1]), K, p, cs)
    F = K * x ** p
    np.testing.assert_allclose(np.hypot(f[:, 0], f[:, 1]), F, rtol=1e-13)
    np.testing.assert_allclose(E, F * x / (p + 1.0) + 0.5 * cs * F * F, rtol=1e-13)
    kr = 1.0 / (x / (p * F) + cs)
    u = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    np.testing.assert_allclose(np.einsum("na,nab,nb->n", u, H, u), kr, rtol=1e-12)


def test_physical_law_equals_line_contact_and_the_mesh_spring():
    rng = np.random.default_rng(3)
    N = 9
    pin, disc = MATERIALS["pin"], MATERIALS["cycloid_disc"]
    rho = np.where(rng.random((N, 6)) < 0.5, rng.uniform(5.0, 60.0, (N, 6)), -rng.uniform(3.5, 40.0, (N, 6)))
    line = LineContact.of(np.full((N, 6), 3.0), rho, pin, disc, 10.0)
    law = PhysicalLaw(line, 6, 2.5e5)
    delta = rng.uniform(-2e-3, 4e-3, (N, 8))                        # 6 pins, 2 mesh columns
    E, F, K = law.energy_force_stiffness(delta)
    pins = delta[:, :6]
    np.testing.assert_allclose(F[:, :6], line.force(pins), rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(K[:, :6], line.stiffness(pins), rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(E[:, :6], line.energy(pins), rtol=1e-12, atol=0.0)
    dm = delta[:, 6:]
    assert np.array_equal(F[:, 6:], 2.5e5 * np.maximum(dm, 0.0))
    assert np.array_equal(K[:, 6:], np.where(dm > 0, 2.5e5, 0.0))
    np.testing.assert_allclose(E[:, 6:], 0.5 * 2.5e5 * np.maximum(dm, 0.0) ** 2, rtol=1e-15)
    # the energy alone and the force and stiffness alone: the same numbers as all three together
    assert np.array_equal(law.energy(delta), E)
    F1, K1 = law.force_stiffness(delta)
    assert np.array_equal(F1, F) and np.array_equal(K1, K)
    # rows: the per-step constants of the rows chosen, the same numbers as the whole
    rows = np.array([7, 2, 4])
    E2, F2, K2 = law.energy_force_stiffness(delta[rows], rows)
    assert np.array_equal(F2, F[rows]) and np.array_equal(K2, K[rows]) and np.array_equal(E2, E[rows])
    assert np.array_equal(law.energy_force_stiffness(delta[2:5], slice(2, 5))[1], F[2:5])
    with pytest.raises(ValueError, match="delta has 3 steps where the law's rows select 9"):
        law.energy_force_stiffness(delta[:3])


def test_curvature_equals_the_derivative_form_and_a_circle():
    prof = CycloidProfile(64.0, 1.3, 40, 3.0, cam_phase=math.pi)
    t = np.random.default_rng(5).uniform(0.0, 2.0 * math.pi, (50, 4))
    d, dd = prof.dq(t), prof.ddq(t)
    ref = (d[..., 0] * dd[..., 1] - d[..., 1] * dd[..., 0]) / np.hypot(d[..., 0], d[..., 1]) ** 3
    k = prof.curvature(t)
    assert k.shape == t.shape
    np.testing.assert_allclose(k, ref, rtol=1e-13)
    assert np.shape(prof.curvature(0.3)) == () and float(prof.curvature(0.3)) == prof.curvature(np.array([0.3]))[0]
    circle = CycloidProfile(64.0, 1e-12, 40, 3.0)
    np.testing.assert_allclose(circle.curvature(t), 1.0 / 64.0, rtol=1e-9)


def test_foot_points_each_stopping_match_the_all_points_newton():
    prof = CycloidProfile(64.0, 1.3, 40, 3.0, cam_phase=math.pi)
    rng = np.random.default_rng(7)
    tt = rng.uniform(0.0, 2.0 * math.pi, 600)
    pts = prof.q(tt) + rng.normal(0.0, 0.003, (600, 2))
    t0 = tt + rng.normal(0.0, 0.002, 600)
    t_all = prof.foot_point(pts, t0)
    t, c1, s1, c2, s2 = prof._foot_point_per_point(pts, t0, trig=True)
    np.testing.assert_allclose(t, t_all, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(np.stack([c1, s1]), np.stack([np.cos(t), np.sin(t)]), atol=1e-14)
    a2 = 40 * t + math.pi
    np.testing.assert_allclose(np.stack([c2, s2]), np.stack([np.cos(a2), np.sin(a2)]), atol=1e-14)
    # the foot: (q(t) - p) . q'(t) = 0
    g = np.einsum("na,na->n", prof.q(t) - pts, prof.dq(t))
    assert np.abs(g).max() < 1e-8
