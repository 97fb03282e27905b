"""Compliances added to the supports (docs/physics.md, section 8): the pillar roots turning in their plates and the
bearing seats (a disc hole / a plate bore deforming under its bearing), against closed forms and independent
solutions."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcad.params import Design
from rvdyn.bearings import (Supports, annulus_seat_compliance, cam_seat_compliance, circle_shear_coefficient,
                            guided_beam_stiffness, journal_seat_compliance, root_rotational_stiffness)
from rvdyn.support_eq import radial_law


def _timoshenko_guided(E: float, nu: float, r: float, L: float, k_th: float) -> float:
    """Lateral stiffness of one exact two-node Timoshenko beam element (Przemieniecki 1968, the shear parameter
    ``phi = 12 E I/(kappa G A L^2)``) whose end rotations are held by springs ``k_th`` to bodies that do not turn:
    node 1 fixed in translation, node 2 displaced by 1; the force at node 2 with both rotations free to settle."""
    I, A, G = math.pi * r ** 4 / 4, math.pi * r ** 2, E / (2 * (1 + nu))
    phi = 12 * E * I / (circle_shear_coefficient(nu) * G * A * L ** 2)
    c = E * I / (L ** 3 * (1 + phi))
    K = c * np.array([[12, 6 * L, -12, 6 * L],
                      [6 * L, (4 + phi) * L ** 2, -6 * L, (2 - phi) * L ** 2],
                      [-12, -6 * L, 12, -6 * L],
                      [6 * L, (2 - phi) * L ** 2, -6 * L, (4 + phi) * L ** 2]])
    K[1, 1] += k_th
    K[3, 3] += k_th
    # unknowns: the two rotations (dofs 1, 3); v1 = 0, v2 = 1
    rot = np.linalg.solve(K[np.ix_([1, 3], [1, 3])], -K[[1, 3], 2])
    return float(K[2, 2] + K[2, [1, 3]] @ rot)


def test_root_rotational_stiffness_is_the_rocking_stiffness_of_a_rigid_disc() -> None:
    """``4 E a^3/(3 (1 - nu^2))`` equals the foundation engineers' ``8 G a^3/(3 (1 - nu))`` (Richart, Hall & Woods
    1970; Gazetas 1991) and scales with a^3."""
    E, nu, a = 1.98e5, 0.23, 7.0
    G = E / (2 * (1 + nu))
    assert root_rotational_stiffness(E, nu, a) == pytest.approx(8 * G * a ** 3 / (3 * (1 - nu)), rel=1e-12)
    assert root_rotational_stiffness(E, nu, 2 * a) == pytest.approx(8 * root_rotational_stiffness(E, nu, a),
                                                                     rel=1e-12)


@pytest.mark.parametrize("L", [5.0, 21.5, 80.0])
@pytest.mark.parametrize("k_th", [math.inf, 9.56e7, 1.0e6])
def test_guided_beam_with_elastic_roots_equals_the_timoshenko_element(L: float, k_th: float) -> None:
    """The closed form ``1/k = L^3/(12 E I) + L/(kappa G A) + L^2/(2 k_theta)`` against the exact Timoshenko beam
    element with rotational springs at both ends, solved as a 2 x 2 system (stubby to slender, rigid to soft
    roots)."""
    E, nu, r = 1.98e5, 0.23, 7.0
    k_el = _timoshenko_guided(E, nu, r, L, 1e30 if math.isinf(k_th) else k_th)
    assert guided_beam_stiffness(E, nu, r, L, k_th) == pytest.approx(k_el, rel=1e-9)


def test_elastic_roots_soften_the_default_pillar_by_their_share() -> None:
    """Default pillar (r 7 mm, L 21.5 mm, ZG65Mn): the roots add L^2/(2 k_theta) = 2.42e-6 mm/N to the
    clamped pillar's 4.19e-6 mm/N."""
    d = Design()
    E, nu, r, L = 1.98e5, 0.23, d.carrier_pillar_radius_mm, 21.5
    k_th = root_rotational_stiffness(E, nu, r)
    extra = 1 / guided_beam_stiffness(E, nu, r, L, k_th) - 1 / guided_beam_stiffness(E, nu, r, L)
    assert extra == pytest.approx(L ** 2 / (2 * k_th), rel=1e-12)
    assert extra == pytest.approx(2.42e-6, rel=2e-3)
    assert 1 / guided_beam_stiffness(E, nu, r, L) == pytest.approx(4.19e-6, rel=2e-3)


def _annulus_navier(E: float, nu: float, a: float, b: float, t: float) -> float:
    """The same seat solved numerically: Navier's equations of plane stress for the displacement
    ``u_r = f(r) cos(theta)``, ``u_theta = g(r) sin(theta)`` (the translation mode) as a two-point boundary-value
    problem (scipy ``solve_bvp``) with a unit translation at r = a (``f = 1``, ``g = -1``) and a fixed r = b; the
    compliance is 1 over the resultant of the tractions at r = a."""
    from scipy.integrate import solve_bvp

    mu = E / (2 * (1 + nu))
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    lam = 2 * lam * mu / (lam + 2 * mu)                      # plane stress

    def rhs(r, y):
        f, g, fp, gp = y
        e = fp + (f + g) / r                                  # dilatation / cos
        w = gp + (f + g) / r                                  # twice the rotation / sin
        fpp = mu * w / (r * (lam + 2 * mu)) - (fp + gp) / r + (f + g) / r ** 2
        gpp = (lam + 2 * mu) * e / (mu * r) - (fp + gp) / r + (f + g) / r ** 2
        return np.vstack([fp, gp, fpp, gpp])

    r = np.linspace(a, b, 200)
    y0 = np.zeros((4, r.size))
    y0[0], y0[1] = (b - r) / (b - a), -(b - r) / (b - a)
    sol = solve_bvp(rhs, lambda ya, yb: np.array([ya[0] - 1, ya[1] + 1, yb[0], yb[1]]), r, y0, tol=1e-10,
                    max_nodes=100000)
    assert sol.success
    f, g, fp, gp = sol.sol(a)
    e = fp + (f + g) / a
    force = math.pi * a * t * (lam * e + 2 * mu * fp - mu * (gp - (f + g) / a))
    return -1.0 / force


@pytest.mark.parametrize("E,nu,a,b,t", [(2.07e5, 0.254, 9.0, 34.0, 10.0), (1.98e5, 0.23, 10.0, 28.7, 10.0),
                                        (2.0e5, 0.3, 5.0, 50.0, 1.0), (7.0e4, 0.33, 20.0, 21.0, 3.0)])
def test_annulus_seat_is_the_navier_solution(E: float, nu: float, a: float, b: float, t: float) -> None:
    """The closed form of the seat against Navier's equations solved numerically (thick to thin annuli)."""
    assert annulus_seat_compliance(E, nu, a, b, t) == pytest.approx(_annulus_navier(E, nu, a, b, t), rel=1e-7)


def test_seat_compliances_of_the_default_design() -> None:
    """Disc hole: a = 9 mm, b = 64 - 30 = 34 mm, 10 mm 20CrMnMo: 1.520e-7 mm/N. Plate bore: a = 7 + 3 = 10 mm, b =
    64 - 1.3 - 3 - 1 - 30 = 28.7 mm, 10 mm ZG65Mn: 1.232e-7 mm/N. The supports carry them."""
    d = Design()
    assert cam_seat_compliance(d) == pytest.approx(annulus_seat_compliance(2.07e5, 0.254, 9.0, 34.0, 10.0), rel=1e-12)
    assert cam_seat_compliance(d) == pytest.approx(1.520e-7, rel=1e-3)
    assert journal_seat_compliance(d) == pytest.approx(annulus_seat_compliance(1.98e5, 0.23, 10.0, 28.7, 10.0),
                                                       rel=1e-12)
    assert journal_seat_compliance(d) == pytest.approx(1.232e-7, rel=1e-3)
    s = Supports.from_design(d)
    assert (s.cam_seat_c, s.journal_seat_c) == (cam_seat_compliance(d), journal_seat_compliance(d))


def test_seat_geometry_is_validated() -> None:
    """A journal bearing reaching the plate's rim, or radii out of order, is refused naming the values."""
    d = Design().replace(journal_bearing_roller_diameter_mm=25.0)
    with pytest.raises(ValueError, match=r"journal_bearing_roller_diameter_mm = 32.0 mm must be < plate rim - centre "
                                         r"distance = 28.7"):
        journal_seat_compliance(d)
    with pytest.raises(ValueError, match=r"journal_bearing_roller_diameter_mm = 32.0 mm"):
        Supports.from_design(d)
    with pytest.raises(ValueError, match=r"annulus radii a = 5.0 mm, b = 4.0 mm must satisfy 0 < a < b"):
        annulus_seat_compliance(2e5, 0.3, 5.0, 4.0, 1.0)


@pytest.mark.parametrize("cs", [0.0, 1.5e-7, 1e-5])
def test_series_radial_law_is_an_exact_potential(cs: float) -> None:
    """Bearing law ``F = K x^(10/9)`` with a seat ``cs`` in series: the total deflection is ``x + cs F`` to
    rounding; the force is the energy's gradient and the Hessian the force's (central differences); cs = 0 gives
    the bearing alone."""
    K, p, c = 9.3e5, 10.0 / 9.0, 0.002
    rng = np.random.default_rng(3)
    d = rng.normal(size=(50, 2)) * 0.004
    E, f, H = radial_law(d, K, p, c, cs=cs)
    r = np.linalg.norm(d, axis=-1)
    F = np.linalg.norm(f, axis=-1)
    x = (F / K) ** (1 / p)
    np.testing.assert_allclose(np.where(r > c, x + cs * F, 0.0), np.maximum(r - c, 0.0), rtol=1e-12, atol=1e-17)
    h = 1e-8
    for i in range(2):
        e = np.zeros(2)
        e[i] = h
        Ep, fp, _ = radial_law(d + e, K, p, c, cs=cs)
        Em, fm, _ = radial_law(d - e, K, p, c, cs=cs)
        np.testing.assert_allclose((Ep - Em) / (2 * h), f[:, i], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose((fp - fm) / (2 * h), H[:, :, i], rtol=1e-5, atol=1e-3)
    if cs == 0.0:
        np.testing.assert_allclose(F, K * np.maximum(r - c, 0.0) ** p, rtol=1e-13)
