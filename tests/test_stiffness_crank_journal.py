"""The stepped Timoshenko crankshaft and the tapered journal bearings of the physical law against closed
forms (docs/physics.md, section 8; rvdyn.bearings)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from rvcad.params import Design
from rvcad.validation import DesignError
from rvdyn.bearings import (Supports, circle_shear_coefficient, crank_sections, journal_load_centre_offset_mm,
                            radial_bearing_K,
                            radial_bearing_K_discrete, stepped_beam_influence)
from rvdyn.materials import MATERIALS


def _roark(L: float, EI: float, x: float, a: float) -> float:
    """Roark Table 8.1 case 1e: deflection at x of a simply supported beam under a unit load at a."""
    if x > a:
        x, a = L - x, L - a
    b = L - a
    return b * x * (L * L - b * b - x * x) / (6.0 * EI * L)


def test_uniform_shear_free_beam_is_roark() -> None:
    """Uniform section and no shear compliance: the unit-load integral is Roark's closed form at every pair of
    points, and symmetric (Maxwell)."""
    L, EI = 31.5, 3.9e8
    xs = np.array([3.0, 10.5, 21.0, 29.0])
    got = stepped_beam_influence(L, ((0.0, L, EI, 1e300),), xs)
    want = np.array([[_roark(L, EI, x, a) for a in xs] for x in xs])
    assert got == pytest.approx(want, rel=1e-12)
    assert got == pytest.approx(got.T, rel=1e-12)


def test_stepped_beam_with_shear_central_load_closed_form() -> None:
    """Symmetric stepped beam (EI1, kGA1 on the outer lengths c, EI2, kGA2 in the middle), unit load at
    mid-span: by the unit-load integral with m = x/2, v = 1/2 on each half,
    ``y = (c^3/EI1 + ((L/2)^3 - c^3)/EI2)/6 + (2c/kGA1 + (L - 2c)/kGA2)/4``; uniform: L^3/(48 EI) + L/(4 kGA)."""
    L, c = 30.0, 6.0
    EI1, EI2, k1, k2 = 4.0e8, 2.5e8, 1.1e7, 0.8e7
    secs = ((0.0, c, EI1, k1), (c, L - c, EI2, k2), (L - c, L, EI1, k1))
    y = stepped_beam_influence(L, secs, [L / 2])[0, 0]
    want = (c ** 3 / EI1 + ((L / 2) ** 3 - c ** 3) / EI2) / 6.0 + (2 * c / k1 + (L - 2 * c) / k2) / 4.0
    assert y == pytest.approx(want, rel=1e-12)
    uni = stepped_beam_influence(L, ((0.0, L, EI1, k1),), [L / 2])[0, 0]
    assert uni == pytest.approx(L ** 3 / (48 * EI1) + L / (4 * k1), rel=1e-12)


def test_default_crank_is_journal_and_eccentric_sections() -> None:
    """Default design: the beam spans the tapered bearings' effective load centres, each o = (7 + 3) tan(13.13 deg)
    = 2.333 mm inside its bearing's mid-plane (face to face): journal radius 7 mm from load centre A (x = 0) to
    the first disc (x = 5.5 - o) and from the second disc (x = 26 - o) to load centre B (x = 31.5 - 2 o); the
    eccentric radius 9 - 2.5 = 6.5 mm over both discs and their gap; 20CrMnMo, Cowper's kappa. The beam of
    Supports uses them."""
    d = Design()
    s = Supports.from_design(d)
    o = 10.0 * math.tan(math.radians(13.13))
    assert o == pytest.approx(2.3326, abs=1e-4)
    L = 31.5 - 2 * o
    m = MATERIALS["crankshaft"]
    G, kap = m.E / (2 * (1 + m.nu)), circle_shear_coefficient(m.nu)
    want = [(0.0, 5.5 - o, 7.0), (5.5 - o, 26.0 - o, 6.5), (26.0 - o, L, 7.0)]
    assert len(s.sections) == 3
    for (x0, x1, EI, kGA), (w0, w1, r) in zip(s.sections, want):
        assert (x0, x1) == pytest.approx((w0, w1), abs=1e-12)
        assert EI == pytest.approx(m.E * math.pi * r ** 4 / 4, rel=1e-12)
        assert kGA == pytest.approx(kap * G * math.pi * r ** 2, rel=1e-12)
    assert s.sections == crank_sections(d, s.z_journal, ((21.0, 31.0), (31.5, 41.5)))
    B = np.zeros((1, 2, 2, 2))
    B[0, 0, 0] = (0.0, -1.0)                                    # disc 0 pushes crank 0 by +1 N in y
    y = s.bending_deflections(B)[0, 0, :, 1]
    xs = np.asarray(s.z_cams) - s.z_journal[0]
    assert y == pytest.approx(stepped_beam_influence(L, s.sections, xs)[:, 0], rel=1e-12)
    # without sections: the uniform Euler beam of the journal section (Roark)
    y0 = replace(s, sections=()).bending_deflections(B)[0, 0, :, 1]
    assert y0 == pytest.approx([_roark(L, s.EI, x, xs[0]) for x in xs], rel=1e-12)
    assert np.all(y > y0)                                       # thinner eccentrics and shear: softer


def test_tapered_bearing_load_centres_set_the_span() -> None:
    """The effective load centre of a tapered bearing lies R_o tan(alpha) from its mid-plane (R_o = journal radius +
    roller diameter = 10 mm): face to face (the default) inwards, back to back outwards, none for a cylindrical
    bearing; the beam spans the load centres (mid-planes 31.5 mm apart)."""
    o = 10.0 * math.tan(math.radians(13.13))
    for arr, sign in (("face_to_face", 1.0), ("back_to_back", -1.0)):
        d = Design(journal_bearing_arrangement=arr)
        assert journal_load_centre_offset_mm(d) == pytest.approx(sign * o, rel=1e-12)
        zA, zB = Supports.from_design(d).z_journal
        assert zB - zA == pytest.approx(31.5 - 2 * sign * o, rel=1e-12)
    cyl = Design(journal_bearing_contact_angle_deg=0.0)
    assert journal_load_centre_offset_mm(cyl) == 0.0
    zA, zB = Supports.from_design(cyl).z_journal
    assert zB - zA == pytest.approx(31.5, rel=1e-12)
    with pytest.raises(DesignError, match=r"design\.journal_bearing_arrangement 'tandem'.*allowed: one of "
                                          r"\['face_to_face', 'back_to_back'\]"):
        Design().replace(journal_bearing_arrangement="tandem")


def test_tapered_journal_bearing_contact_angle() -> None:
    """Harris sec. 7.3, axially held tapered bearing: K_b(alpha) = cos(alpha)^(19/9) K_b(0), and the roller sum
    with the contact angle agrees within 2 % (12 rollers); the default design takes alpha = 13.13 deg
    (ISO 281: e = 1.5 tan(alpha) = 0.35)."""
    for a in (0.0, 13.1, 30.0):
        k = radial_bearing_K(12, 6.0, a)
        assert k == pytest.approx(math.cos(math.radians(a)) ** (19 / 9) * radial_bearing_K(12, 6.0), rel=1e-12)
        for cage in (0.0, math.pi / 12):
            assert radial_bearing_K_discrete(12, 6.0, cage, a) == pytest.approx(k, rel=0.02)
    d = Design()
    assert math.degrees(math.atan(0.35 / 1.5)) == pytest.approx(d.journal_bearing_contact_angle_deg, abs=0.005)
    s = Supports.from_design(d)
    assert s.journal_K == pytest.approx(radial_bearing_K(12, 6.0, 13.13), rel=1e-12)
    assert Supports.from_design(d.replace(journal_bearing_contact_angle_deg=0.0)).journal_K == pytest.approx(
        radial_bearing_K(12, 6.0), rel=1e-12)


def test_bad_contact_angle_and_roller_diameter_are_refused() -> None:
    with pytest.raises(DesignError, match=r"design\.journal_bearing_contact_angle_deg"):
        Design().replace(journal_bearing_contact_angle_deg=50.0)
    with pytest.raises(DesignError, match=r"design\.journal_bearing_contact_angle_deg"):
        Design().replace(journal_bearing_contact_angle_deg=-1.0)
    with pytest.raises(ValueError, match=r"design\.cam_bearing_roller_diameter_mm 9\.5 must be < cam_radius_mm"):
        Supports.from_design(Design(cam_bearing_roller_diameter_mm=9.5))


def test_crank_torsion_over_the_stepped_sections() -> None:
    """Planet plane (z = 5 mm) to the mean cam plane (31.25 mm): 16 mm of journal (radius 7 mm) to the first
    disc, then 10.25 mm of eccentric (6.5 mm): ``sum l_i / (G pi r_i^4 / 2)``; without sections ``l / GJ``."""
    s = Supports.from_design(Design())
    m = MATERIALS["crankshaft"]
    G = m.E / (2 * (1 + m.nu))
    want = 16.0 / (G * math.pi * 7.0 ** 4 / 2) + 10.25 / (G * math.pi * 6.5 ** 4 / 2)
    assert s.torsion_compliance() == pytest.approx(want, rel=1e-12)
    assert replace(s, GJ_sections=()).torsion_compliance() == pytest.approx(26.25 / s.GJ, rel=1e-12)
