"""rvdyn.friction: the Coulomb friction of the pins and crank bearings under rotation, from the kinematics and the
equilibrium's forces (docs in the module)."""
from __future__ import annotations

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvcalib.equivalents import compliance_equivalents
from rvdyn.friction import FrictionArms, friction_arms
from rvdyn.solver import QuasiStaticSolver
from rvdyn.te import make_contacts


def _turn(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


@pytest.mark.parametrize("design", [{}, {"z_sun": 18, "z_planet": 36}, {"crank_angles_deg": [0, 120, 240]}])
def test_a_disc_turns_about_its_pitch_point_and_the_cranks_against_it_at_i_minus_1_times_z1_over_z2(design):
    """The kinematic facts the friction arms rest on, from the solver's poses by finite differences (rigid limit,
    two input angles 1e-5 rad apart): a material point P of a disc moves at |P - W| per unit output rotation at right
    angles to P - W, W the pitch point (Zp/(Zp - Zc) times the disc centre's offset from the housing's centre),
    and the cranks turn against the discs and against the carrier at (i - 1) Z1/Z2 (40 on the ratio-121 design, 20
    on the ratio-81 one)."""
    g = ReducerGeometry(Case.from_dict({"design": design}))
    d = g.design
    s = QuasiStaticSolver(g, make_contacts(g, "analytic"))
    th = np.array([0.3, 0.3 + 1e-5, 1.7, 1.7 + 1e-5])
    sol = s.solve(th, direction=1, load_Nm=0.0)
    cen, ang = g.disc_poses(sol.theta_out, sol.psi)
    hc = np.mean(g.pin_centers, axis=0)
    rng = np.random.default_rng(3)
    for a, b in ((0, 1), (2, 3)):
        dto = sol.theta_out[b] - sol.theta_out[a]
        for k in range(d.n_discs):
            W = hc + d.z_pins / (d.z_pins - d.z_disc) * (cen[a, k] - hc)
            P = cen[a, k] + rng.uniform(-60, 60, size=(8, 2))                  # material points of the disc
            moved = cen[b, k] + _turn(ang[b, k] - ang[a, k], P - cen[a, k])
            v = (moved - P) / dto
            r = P - W
            assert np.allclose(np.linalg.norm(v, axis=1), np.linalg.norm(r, axis=1), rtol=2e-4)
            assert np.abs(np.sum(v * r, axis=1)).max() < 2e-4 * np.linalg.norm(r, axis=1).max() ** 2
            assert (ang[b, k] - ang[a, k]) / dto == pytest.approx(1.0, rel=1e-6)       # the disc turns with the carrier
        rel = (d.ratio - 1.0) * d.z_sun / d.z_planet
        dpsi = (sol.psi[b] - sol.psi[a]) / dto
        assert np.allclose(np.abs(dpsi - 1.0), rel, rtol=1e-6)                     # crank against carrier and disc


@pytest.mark.parametrize("design", [{}, {"crank_angles_deg": [0, 120, 240]}])
def test_the_friction_torque_grows_with_the_load_as_the_load_does(design):
    """kappa (friction torque per unit coefficient and per N mm of output torque) is the same at 5 and 167 N m
    within 2 % (pins) and 0.5 % (bearings): in a TE test, Coulomb friction acts as a compliance would; with two
    cranks or three (the bearings' sum then runs over three cranks' cams and journals)."""
    case = Case.from_dict({"design": design})
    lo, hi = friction_arms(case, 5.0), friction_arms(case, 167.0)
    assert lo.pins > 0 and lo.bearings > 0 and lo.windup_arcsec_per_Nm > 0
    assert hi.pins == pytest.approx(lo.pins, rel=0.02) and hi.bearings == pytest.approx(lo.bearings, rel=0.005)
    with pytest.raises(ValueError, match="load_Nm 0.0 must be a finite number > 0"):
        friction_arms(Case.from_dict({}), 0.0)


def test_a_compliance_reads_as_the_friction_coefficient_that_mimics_it():
    arms = FrictionArms(20.0, pins=1.0, bearings=20.0, windup_arcsec_per_Nm=0.7)
    p, b = compliance_equivalents(0.07, 0.056, 0.084, arms)
    assert p["parameter"] == "model.pin_friction_coefficient" and p["value"] == pytest.approx(0.1)
    assert (p["ci_low"], p["ci_high"]) == (pytest.approx(0.08), pytest.approx(0.12))
    assert b["parameter"] == "model.bearing_friction_coefficient" and b["value"] == pytest.approx(0.005)
    rigid = FrictionArms(20.0, pins=1.0, bearings=None, windup_arcsec_per_Nm=0.7)
    assert [q["parameter"] for q in compliance_equivalents(0.07, 0.05, 0.09, rigid)] == ["model.pin_friction_coefficient"]
