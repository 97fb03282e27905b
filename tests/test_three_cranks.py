"""Reducers with three crankshafts (and any crank count the geometry allows): design, geometry and the solver
against closed forms (docs/physics.md, sections 3 and 6, "n cranks")."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from rvcad.errors import Case, load_case
from rvcad.geometry import ReducerGeometry, procrustes_angle
from rvcad.params import Design, DesignError, even_crank_angles
from rvdyn.contacts import AnalyticContacts, ContactLaw
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver
from rvdyn.te import run_te

from closed_forms import crank_turn_equivalent, disc_offset_gaps, first_contact_te, free_crank_te, pin_levers

RV160N = Path(__file__).resolve().parents[1] / "examples" / "designs" / "rv160n.json"
THREE = {"crank_angles_deg": [0, 120, 240]}


def rv160n() -> dict:
    """The design object of the RV-160N-like example (examples/designs/rv160n.json)."""
    return json.loads(RV160N.read_text())["design"]


# ------------------------------------------------------------------------------------------------ the design
def test_three_cranks_are_a_valid_design_and_the_pillars_follow() -> None:
    d = Design.from_dict(THREE)
    assert d.n_cranks == 3 and d.carrier_pillars == 3 and d.crank_angles_deg == even_crank_angles(3)
    assert Design().carrier_pillars == 2 and Design().to_dict()["carrier_pillars"] == 2
    # replacing the cranks of a design whose pillars follow them: the pillars follow; given pillars are kept
    assert Design().replace(crank_angles_deg=(0.0, 120.0, 240.0)).carrier_pillars == 3
    assert Design.from_dict({**THREE, "carrier_pillars": 2}).carrier_pillars == 2
    assert Design.from_dict({**THREE, "carrier_pillars": 6}).replace(crank_angles_deg=(0.0, 180.0)).carrier_pillars == 6
    # the round trip of the plain dict
    assert Design.from_dict(d.to_dict()) == d


def test_rv160n_example_is_a_valid_case_of_ratio_81() -> None:
    case = load_case(RV160N)
    d = case.design
    assert (d.z_sun, d.z_planet, d.z_pins, d.z_disc, d.n_cranks) == (22, 44, 40, 39, 3)
    assert (d.pin_circle_diameter_mm, d.eccentricity_mm, d.module_mm) == (223.0, 2.0, 1.5)
    assert d.ratio == 81.0 and d.carrier_pillars == 3


def test_crank_layouts_the_geometry_refuses_name_the_field() -> None:
    # four cranks at 90 deg: neighbouring planets (tip circles 46.5 mm across) stand 42.4 mm apart
    with pytest.raises(DesignError, match=r"design.crank_angles_deg \[0, 90, 180, 270\] puts planets 0 and 1 "
                                          r"42.426 mm apart .*at most 3 cranks"):
        Design.from_dict({"crank_angles_deg": [0, 90, 180, 270]})
    # the RV-160N-like stage I (a = 49.5 mm, tip circles 67.8 mm across) takes four cranks: 70.0 mm apart
    assert Design.from_dict({**rv160n(), "crank_angles_deg": [0, 90, 180, 270]}).n_cranks == 4


def test_error_selectors_cover_every_crank_and_hole() -> None:
    case = Case.from_dict({"design": THREE, "errors": {
        "cam_phase": {"value": 1, "crank": 2, "disc": 1}, "planet_eccentricity": {"value": 2, "crank": 2},
        "carrier_hole_eccentricity": {"value": 3, "crank": 1}, "disc_hole_eccentricity": {"value": 4, "hole": 2}}})
    g = ReducerGeometry(case)
    assert g.errors.cam_phase[2, 1] == pytest.approx(1e-3 / 1.3)
    assert g.errors.planet_offset[2, 0] == pytest.approx(2e-3)
    assert g.carrier_holes[1] == pytest.approx((30.003 * np.array([math.cos(2 * math.pi / 3), math.sin(2 * math.pi / 3)])))
    assert np.linalg.norm(g.disc_holes[0, 2]) == pytest.approx(30.004)
    with pytest.raises(ValueError, match=r"errors.cam_phase.crank 3 is out of range; allowed: an integer in \[0, 2\]"):
        Case.from_dict({"design": THREE, "errors": {"cam_phase": {"value": 1, "crank": 3}}})
    with pytest.raises(ValueError, match=r"errors.disc_hole_eccentricity.hole 2 is out of range; allowed: an integer "
                                         r"in \[0, 1\]"):
        Case.from_dict({"errors": {"disc_hole_eccentricity": {"value": 1, "hole": 2}}})


# ------------------------------------------------------------------------------------------------ geometry
def test_procrustes_fit_is_the_two_hole_fit_and_least_squares() -> None:
    """The fit of n holes: for two it is the angle between the hole line and the cam line (the two-crank
    formula); for three it minimises the sum of squared offsets (no turn nearby does better)."""
    rng = np.random.default_rng(3)
    H2, C2 = rng.normal(size=(5, 2, 2)), rng.normal(size=(5, 2, 2))
    dh, dc = H2[:, 1] - H2[:, 0], C2[:, 1] - C2[:, 0]
    two = np.arctan2(dc[:, 1], dc[:, 0]) - np.arctan2(dh[:, 1], dh[:, 0])
    assert np.angle(np.exp(1j * (procrustes_angle(H2, C2) - two))) == pytest.approx(np.zeros(5), abs=1e-12)
    H3, C3 = rng.normal(size=(3, 2)), rng.normal(size=(3, 2))

    def cost(a: float) -> float:
        R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        h, c = H3 - H3.mean(0), C3 - C3.mean(0)
        return float(((h @ R.T - c) ** 2).sum())

    best = float(procrustes_angle(H3, C3))
    assert all(cost(best) < cost(best + da) for da in (-1e-3, 1e-3))


@pytest.mark.parametrize("design", [THREE, "rv160n"])
def test_nominal_three_crank_kinematics_zero_gaps(design) -> None:
    g = ReducerGeometry(Case.from_dict({"design": rv160n() if design == "rv160n" else design}))
    i = g.design.ratio
    th = np.linspace(0, 2 * np.pi * i, 1500)
    to, ps = g.ideal_state(th)
    assert np.abs(g.pin_gaps(to, ps)[0]).max() < 1e-9
    for d in (1, -1):
        assert np.abs(g.stage1_gaps(th, to, ps, d)).max() < 1e-9
    # the disc follows the ideal motion: rotation theta_out, centre e u(psi + k pi)
    cen, ang = g.disc_poses(to, ps)
    assert ang == pytest.approx(np.repeat(to[:, None], 2, axis=1), abs=1e-12)
    e = g.design.eccentricity_mm
    assert cen[:, 0] == pytest.approx(e * np.c_[np.cos(ps[:, 0]), np.sin(ps[:, 0])], abs=1e-12)


# ------------------------------------------------------------------------------------------------ solver
@pytest.mark.parametrize("design", [THREE, "rv160n"])
def test_ideal_three_crank_parts_zero_te_and_exact_ratio(design) -> None:
    """Ideal parts: |TE| < 0.01 arcsec at every step and the ratio exact, in the rigid limit (the rigid law
    under load, each law's limit under a vanishing load) and the elastic one (the wind-up under load is a
    constant: no TE ripple beyond the mesh's)."""
    dsg = rv160n() if design == "rv160n" else design
    case = Case.from_dict({"design": dsg})
    i = case.design.ratio
    for law, load in ((ContactLaw(), 0.0), (ContactLaw(rigid=True), 20.0), (None, 0.0)):
        r = run_te(case, "analytic", 120, load_Nm=load, law=law)
        assert np.abs(r.table["te_arcsec"]).max() < 0.01
        assert r.stats["ratio"] == pytest.approx(i, rel=1e-6)
    for law in (ContactLaw(), None):
        r = run_te(case, "analytic", 120, load_Nm=20.0, law=law)
        assert r.stats["ratio"] == pytest.approx(i, rel=1e-6)
        assert r.stats["pp"] < 0.01 and r.stats["mean"] < -0.5   # wind-up, flat to 0.01 arcsec


@pytest.mark.parametrize("design", [THREE, "rv160n"])
def test_pin_clearance_to_angle_with_three_cranks(design) -> None:
    """Clearance to angle (docs/physics.md, section 6) does not depend on the crank count: a pin radius reduced
    by dr lets the output turn -dr / max lam_i, lam_i = (i Z1/Z2) e (n_i . u'); max lam ~ e i Z1/Z2 (52.43 mm
    by default, 81 mm for the RV-160N-like design)."""
    dr_um = 5.0
    dsg = rv160n() if design == "rv160n" else design
    case = Case.from_dict({"design": dsg, "errors": {"pin_radius": -dr_um}})
    g = ReducerGeometry(case)
    r = run_te(case, "analytic", 144, load_Nm=0.0, geom=g)
    th = np.radians(r.table["input_deg"].to_numpy())
    lam_max = pin_levers(g, th).max(axis=(1, 2))
    assert r.table["te_arcsec"].to_numpy() == pytest.approx(-dr_um * 1e-3 / lam_max * ARCSEC_PER_RAD, rel=2e-3)
    d = g.design
    assert lam_max.min() == pytest.approx(d.eccentricity_mm * d.ratio * d.z_sun / d.z_planet, rel=5e-3)


def _rigid_te(cranks: list[float], errors: dict, direction: int, steps: int = 72):
    """TE (arcsec) at the rigid limit of the paper's model (impact law, discs fixed at the least-squares fit of
    their holes to their cams) with a pin clearance of 5 um, and the geometry of the clearance alone."""
    base = {"design": {"crank_angles_deg": cranks}, "direction": direction, "model": {"contact": "impact"}}
    case = Case.from_dict({**base, "errors": {"pin_radius": -5.0, **errors}})
    g = ReducerGeometry(Case.from_dict({**base, "errors": {"pin_radius": -5.0}}))
    r = run_te(case, "analytic", steps, load_Nm=0.0)
    return r.table["te_arcsec"].to_numpy(), np.radians(r.table["input_deg"].to_numpy()), g


@pytest.mark.parametrize("cranks", [[0.0, 180.0], [0.0, 120.0, 240.0]])
@pytest.mark.parametrize("direction", [1, -1])
def test_cam_phase_on_one_crank_closed_form(cranks: list[float], direction: int) -> None:
    """A cam phase v (arc length) on crank 1, disc 0, at the rigid limit with a 5 um pin clearance: the least-
    squares fit moves disc 0 as crank 1 turned by v/e would, i.e. as the output turned by ``c_0 v/e`` with
    ``c_0 = (1 + (Zc e/a) cos(chi - beta_1 - theta_out)) / (n i Z1/Z2)`` (1/n of the cam's move, the turn
    across the hole arm over n a^2); disc 1 keeps its pose. The output stops at the first disc to close."""
    v = 2.0
    te, th, g = _rigid_te(cranks, {"cam_phase": {"value": v, "crank": 1, "disc": 0}}, direction)
    lam = pin_levers(g, th)
    delta = crank_turn_equivalent(g, th, 1) * v * 1e-3 / g.design.eccentricity_mm
    delta[:, 1] = 0.0
    expect = first_contact_te(lam, lam * delta[:, :, None], 5e-3, direction) * ARCSEC_PER_RAD
    clearance_only = first_contact_te(lam, np.zeros_like(lam), 5e-3, direction) * ARCSEC_PER_RAD
    assert np.abs(expect - clearance_only).max() > 1.0                     # the error's own effect, arcsec
    assert te == pytest.approx(expect, rel=2e-3)


@pytest.mark.parametrize("cranks", [[0.0, 180.0], [0.0, 120.0, 240.0]])
@pytest.mark.parametrize("direction", [1, -1])
def test_carrier_hole_offset_closed_form(cranks: list[float], direction: int) -> None:
    """A carrier hole of crank 1 moved outward by f (rigid limit, 5 um pin clearance): both discs' cams on crank 1
    move by ``f u(beta_1 + theta_out)``, so the fit shifts each disc by ``f u/n`` without a turn (the move is
    along the hole arm); and the planet of crank 1 moves off the sun by f, which opens both of its flanks by
    ``f sin(alpha_w)`` (docs/physics.md, section 4): crank 1 turns within ``+-f sin(alpha_w)/rb2`` to where the
    load takes the output furthest."""
    f = 2.0
    te, th, g = _rigid_te(cranks, {"carrier_hole_eccentricity": {"value": f, "crank": 1}}, direction)
    d = g.design
    lam = pin_levers(g, th)
    to, _ = g.ideal_state(th)
    beta = g.crank_angles[1]
    shift = np.repeat((f * 1e-3 / d.n_cranks * np.c_[np.cos(beta + to), np.sin(beta + to)])[:, None], 2, axis=1)
    dg = disc_offset_gaps(g, th, shift, np.zeros((len(th), 2)))
    X = np.stack([first_contact_te(lam[:, k:k + 1], dg[:, k:k + 1], 5e-3, direction) for k in range(2)], axis=1)
    rb2 = g.planet.base_radius
    play = f * 1e-3 * math.sqrt(1.0 - ((g.sun.base_radius + rb2) / d.center_distance_mm) ** 2) / rb2
    expect = free_crank_te(X, crank_turn_equivalent(g, th, 1), (-play, play), direction) * ARCSEC_PER_RAD
    clearance_only = first_contact_te(lam, np.zeros_like(lam), 5e-3, direction) * ARCSEC_PER_RAD
    assert np.abs(expect - clearance_only).max() > 1.0
    assert te == pytest.approx(expect, rel=2e-3)


@pytest.mark.parametrize("design", [THREE, "rv160n"])
@pytest.mark.parametrize("model", [{"contact": "impact"}, {"contact": "physical", "supports": "rigid"}])
def test_ideal_parts_share_the_load_equally_among_the_cranks(design, model: dict) -> None:
    """Ideal parts on rigid supports: the two discs are mirror images (the turn of crank j moves disc 0 and disc
    1 by the same output turn in their translation and by opposite ones in their turn), so every crank feels
    ``e u'(psi) . (F_0 - F_1)/n`` and the sun-planet meshes carry equal forces, whatever n, within 1e-6."""
    dsg = rv160n() if design == "rv160n" else design
    g = ReducerGeometry(Case.from_dict({"design": dsg, "model": model}))
    s = QuasiStaticSolver(g, AnalyticContacts(g))
    th = np.linspace(0.0, 2.0 * np.pi * g.design.z_planet / g.design.z_sun, 7)
    for load in (20.0, 500.0):
        F = s.solve(th, 1, load).stage1_force_N
        assert F.shape == (7, 3)
        assert np.abs(F / F.mean(axis=1, keepdims=True) - 1.0).max() < 1e-6
        # statics: the planets together take the sun's torque T / i at its base radius (up to the change of the
        # stored elastic energy with the angle: virtual work T_in d theta_in = T d theta_out + dU)
        assert F.sum(axis=1) == pytest.approx(load * 1e3 / g.design.ratio / g.sun.base_radius, rel=1e-3)
