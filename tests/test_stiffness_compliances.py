"""Compliances added to the supports (docs/physics.md, section 8): the pillar roots turning in their plates and the
bearing seats (a disc hole / a plate bore deforming under its bearing), against closed forms and independent
solutions."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcad.params import Design
from rvdyn.bearings import (circle_shear_coefficient, guided_beam_stiffness, root_rotational_stiffness)


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
