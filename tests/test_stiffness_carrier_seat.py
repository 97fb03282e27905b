"""The carrier (pillars) and pin-seat compliances of the physical law against closed forms
(docs/physics.md, section 8; rvdyn.bearings)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvcad.params import Design
from rvcad.validation import DesignError
from rvdyn.bearings import (Supports, carrier_torsional_stiffness, circle_shear_coefficient, guided_beam_stiffness,
                            pillar_length_mm, pin_seat_contact)
from rvdyn.contacts import AnalyticContacts
from rvdyn.materials import MATERIALS, LineContact, e_star
from rvdyn.solver import QuasiStaticSolver


def test_guided_beam_is_timoshenko_bending_plus_shear() -> None:
    """Clamped-guided round bar: 12 E I / L^3 for a slender bar, kappa G A / L for a stubby one, and the
    series sum of both in between; Cowper's kappa of a solid circle is 0.886 at nu = 0.3."""
    E, nu, r = 2.0e5, 0.3, 5.0
    I, A, G = math.pi * r ** 4 / 4, math.pi * r ** 2, E / (2 * (1 + nu))
    assert circle_shear_coefficient(0.3) == pytest.approx(7.8 / 8.8, rel=1e-12)
    slender = 2000.0     # shear part 3 E r^2 / (kappa G L^2) = 5.5e-5 of the bending part
    assert guided_beam_stiffness(E, nu, r, slender) == pytest.approx(12 * E * I / slender ** 3, rel=1e-4)
    stubby = 0.05        # bending part 1.1e-5 of the shear part
    assert guided_beam_stiffness(E, nu, r, stubby) == pytest.approx(7.8 / 8.8 * G * A / stubby, rel=1e-4)
    L = 20.0
    k = 1.0 / (L ** 3 / (12 * E * I) + L / (7.8 / 8.8 * G * A))
    assert guided_beam_stiffness(E, nu, r, L) == pytest.approx(k, rel=1e-12)


def test_carrier_stiffness_of_the_default_design() -> None:
    """Two pillars of radius 7 mm, 21.5 mm free length (two 10 mm discs, 0.5 mm gap, 0.5 mm clearance either
    side), on the 30 mm crank circle, ZG65Mn (E 198 GPa, nu 0.23): k_t = 2 k r^2 = 4.30e8 N mm/rad with rigidly
    clamped roots, 2.72e8 with the roots turning in the plates."""
    d = Design()
    assert pillar_length_mm(d) == pytest.approx(21.5)
    E, nu, r, L = 1.98e5, 0.23, 7.0, 21.5
    I, A, G = math.pi * r ** 4 / 4, math.pi * r ** 2, E / (2 * (1 + nu))
    kappa = 6 * (1 + nu) / (7 + 6 * nu)
    k = 1.0 / (L ** 3 / (12 * E * I) + L / (kappa * G * A))
    # rigidly clamped roots (the earlier model): 4.30e8
    assert carrier_torsional_stiffness(d, root=False) == pytest.approx(2 * k * 30.0 ** 2, rel=1e-12)
    assert carrier_torsional_stiffness(d, root=False) == pytest.approx(4.30e8, rel=2e-3)
    # the default: each root turns in its plate against 4 E r^3/(3 (1 - nu^2)) (a rigid punch rocking on a
    # half-space), adding L^2/(2 k_theta) to the pillar's compliance: 2.72e8
    k_th = 4 * E * r ** 3 / (3 * (1 - nu ** 2))
    k_root = 1.0 / (1.0 / k + L ** 2 / (2 * k_th))
    assert carrier_torsional_stiffness(d) == pytest.approx(2 * k_root * 30.0 ** 2, rel=1e-12)
    assert carrier_torsional_stiffness(d) == pytest.approx(2.725e8, rel=2e-3)
    assert carrier_torsional_stiffness(d.replace(carrier_pillars=3)) == pytest.approx(
        1.5 * carrier_torsional_stiffness(d), rel=1e-12)


def test_pin_seat_is_johnson_conformal_line_contact_in_series() -> None:
    """The seat's approach is Johnson's ``P/pi sum c_i (2 ln(4 R_i/b) - 1)`` with the concave groove (relative
    radius r (r + c)/c), and the series law (A_1 + A_2, weighted C) gives the sum of the two approaches."""
    d = Design()
    seat = pin_seat_contact(d)
    r, c, L = d.pin_radius_mm, d.pin_seat_clearance_mm, d.disc_width_mm
    pin, hs = MATERIALS["pin"], MATERIALS["pin_housing"]
    es = e_star(pin, hs)
    R = r * (r + c) / c
    for F in (50.0, 500.0, 3000.0):
        P = F / L
        b = math.sqrt(4 * P * R / (math.pi * es))
        johnson = P / math.pi * (pin.c * (2 * math.log(4 * r / b) - 1) + hs.c * (2 * math.log(4 * (r + c) / b) - 1))
        assert float(seat.approach(np.array(F))) == pytest.approx(johnson, rel=1e-10)
    disc = LineContact.of(np.array(r), np.array(-20.0), pin, MATERIALS["cycloid_disc"], L)
    both = LineContact(disc.A + seat.A, (disc.A * disc.C + seat.A * seat.C) / (disc.A + seat.A), L)
    F = np.array([10.0, 300.0, 2500.0])
    np.testing.assert_allclose(both.approach(F), disc.approach(F) + seat.approach(F), rtol=1e-12)
    np.testing.assert_allclose(both.force(both.approach(F)), F, rtol=1e-9)   # the solver's exact inversion
    # a closer fit is stiffer (larger conformal radius), a looser one softer
    tight, loose = (pin_seat_contact(d.replace(pin_seat_clearance_mm=v)) for v in (0.002, 0.05))
    assert tight.approach(np.array(500.0)) < seat.approach(np.array(500.0)) < loose.approach(np.array(500.0))


def test_pillar_and_seat_sizes_are_validated() -> None:
    with pytest.raises(DesignError, match="design.carrier_pillar_radius_mm 20.0 mm: the pillar holes"):
        Design(carrier_pillar_radius_mm=20.0).validate()
    with pytest.raises(DesignError, match=r"design.pin_seat_clearance_mm 0.0 is out of range; allowed: a number in "
                                          r"\[0.0001, 1\] mm"):
        Design(pin_seat_clearance_mm=0.0).validate()
    with pytest.raises(DesignError, match=r"design.carrier_pillars 0 is out of range"):
        Design(carrier_pillars=0).validate()


@pytest.fixture(scope="module")
def rated():
    """The nominal case at rated torque (167 N m), physical law, elastic supports, at two input angles; and
    the same with a carrier 6x stiffer (12 pillars: thicker ones would not fit)."""
    th = np.array([0.0, 0.7])
    out = {}
    for n in (2, 12):
        c = Case.from_dict({"design": {"carrier_pillars": n}, "model": {"contact": "physical"}})
        g = ReducerGeometry(c)
        s = QuasiStaticSolver(g, AnalyticContacts(g))
        out[n] = (s, s.solve(th, 1, 167.0))
    return out


def test_carrier_end_plate_is_in_equilibrium(rated) -> None:
    """The carrier inside the equilibrium: the end plate turns by phi = s / a (the state's last coordinate) until
    the pillars' torque k_t phi equals the torque of the journal-B reactions, which statics gives independently
    from the cam forces (lever rule of each simply supported crank); 6x the pillars turn it less; the parts,
    the pillars' among them, add up to the wind-up."""
    share = {}
    for n in (2, 12):
        s, sol = rated[n]
        k_t = carrier_torsional_stiffness(s.geom.design)
        assert s.supports.carrier_k == pytest.approx(k_t, rel=1e-12)
        phi = sol.x[:, -1] / s.geom.design.center_distance_mm
        R = s.supports.journal_forces(sol.cam_force_N)                          # (N, nc, journals, 2)
        ax = s.geom.crank_axes(sol.theta_out)
        T_B = (ax[..., 0] * R[:, :, 1, 1] - ax[..., 1] * R[:, :, 1, 0]).sum(axis=1)
        np.testing.assert_allclose(k_t * phi, T_B, rtol=1e-8)
        share[n] = T_B / 167e3
        assert -sol.te_rad == pytest.approx(sum(sol.parts_rad.values()), rel=1e-4)
    # a stiffer end plate path draws more of the torque to the far journals
    assert np.all(share[12] > share[2])
    (_, two), (_, twelve) = rated[2], rated[12]
    assert np.all(np.abs(twelve.x[:, -1]) < np.abs(two.x[:, -1]))
    assert np.all(twelve.parts_rad["carrier"] < two.parts_rad["carrier"])
    assert np.all(-twelve.te_rad < -two.te_rad)


def test_far_journal_share_is_the_lever_rule() -> None:
    """Equal disc shares: beta = mean axial position of the cam planes between the journals, 1/2 for the
    default layout (cam planes symmetric between the load centres of the tapered bearings, 31.5 - 2 x 2.333 mm
    apart)."""
    sup = Supports.from_design(Design())
    zA, zB = sup.z_journal
    assert zB - zA == pytest.approx(31.5 - 2 * 10.0 * math.tan(math.radians(13.13)), rel=1e-12)
    assert sup.far_journal_share() == pytest.approx(0.5, rel=1e-12)
    wide = Supports.from_design(Design(disc_gap_mm=10.5))
    zA, zB = wide.z_journal
    assert wide.far_journal_share() == pytest.approx(np.mean((np.asarray(wide.z_cams) - zA) / (zB - zA)), rel=1e-12)
