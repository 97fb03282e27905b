"""Closed-form checks of the shared core: design, case validation, profile maths, kinematics."""
from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon

from rvcad.errors import Case, load_case
from rvcad.geometry import ReducerGeometry
from rvcad.params import Design
from rvcad.profile import CycloidProfile


def test_ratio_from_tooth_numbers() -> None:
    assert Design().ratio == 121.0
    assert Design(z_sun=12, z_planet=36, z_pins=30, z_disc=29).ratio == 1 + 36 * 30 / 12


def test_table1_pin_radius_6mm_is_refused() -> None:
    with pytest.raises(ValueError, match=r"design.pin_radius_mm 6\.0 mm makes the 40 pins overlap.*half the pin chord pitch"):
        Design(pin_radius_mm=6.0).validate()


def test_bad_design_fields() -> None:
    with pytest.raises(ValueError, match=r"design.z_disc 38 .*allowed: z_pins - 1 = 39"):
        Design(z_disc=38).validate()
    with pytest.raises(ValueError, match="design key 'pin_radius' is unknown"):
        Design.from_dict({"pin_radius": 3})


def test_case_validation_names_the_field() -> None:
    with pytest.raises(ValueError, match="errors key 'pin_pich' is unknown"):
        Case.from_dict({"errors": {"pin_pich": 0.01}})
    with pytest.raises(ValueError, match=r"errors.pin_pitch.pin 40 is out of range; allowed: an integer in \[0, 39\]"):
        Case.from_dict({"errors": {"pin_pitch": {"value": 0.01, "pin": 40}}})
    with pytest.raises(ValueError, match=r"errors.cam_phase key 'hole' is not allowed"):
        Case.from_dict({"errors": {"cam_phase": {"value": 1, "hole": 0}}})
    with pytest.raises(ValueError, match=r"errors.pin_radius 'x' is of type str, not a number"):
        Case.from_dict({"errors": {"pin_radius": "x"}})
    with pytest.raises(ValueError, match=r"errors.pin_radius nan is not finite"):
        Case.from_dict({"errors": {"pin_radius": float("nan")}})
    with pytest.raises(ValueError, match=r"errors.pin_radius \[1, 2, 3\] is a pin-wise list of 3 numbers; allowed: .*a list of 40 numbers"):
        Case.from_dict({"errors": {"pin_radius": [1, 2, 3]}})
    with pytest.raises(ValueError, match=r"direction 0 is not a drive direction; allowed: \+1 or -1"):
        Case.from_dict({"direction": 0})
    with pytest.raises(ValueError, match=r"pins 0 and 1 overlap"):
        Case.from_dict({"errors": {"pin_pitch": {"value": 4.0, "pin": 0}}, "design": {"pin_radius_mm": 4.5}})


def test_case_file_errors(tmp_path) -> None:
    p = tmp_path / "c.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="is not valid JSON"):
        load_case(p)
    with pytest.raises(ValueError, match="does not exist"):
        load_case(tmp_path / "missing.json")


def test_case_example_of_conventions_and_key() -> None:
    d = {"name": "case-07", "design": {"pin_radius_mm": 3.0},
         "errors": {"pin_pitch": 0.06, "pin_circle_diameter": -14, "pin_radius": 7,
                    "disc_hole_eccentricity": {"value": 14, "disc": 0, "hole": 0}},
         "load_Nm": 20, "direction": 1}
    c = Case.from_dict(d)
    g = ReducerGeometry(c)
    assert g.pin_radii == pytest.approx(np.full(40, 3.007))
    r = np.linalg.norm(g.pin_centers, axis=1)
    assert r == pytest.approx(np.full(40, 64 - 0.007), abs=1e-12)
    assert math.degrees(math.atan2(g.pin_centers[0, 1], g.pin_centers[0, 0])) == pytest.approx(0.06)
    assert np.linalg.norm(g.disc_holes[0, 0]) == pytest.approx(30.014)
    assert Case.from_dict(c.to_dict()).key() == c.key()
    assert c.with_errors({}).key() != c.key()


def test_profile_area_closed_form() -> None:
    """Area of the pin-centre curve pi(Rp^2 + Zp e^2); inner parallel curve A - rp L + pi rp^2."""
    p = CycloidProfile(64.0, 1.3, 40, 3.0)
    t = np.linspace(0, 2 * np.pi, 400001)[:-1]
    q, dq = p.q(t), p.dq(t)
    q_area = 0.5 * np.mean(q[:, 0] * dq[:, 1] - q[:, 1] * dq[:, 0]) * 2 * np.pi  # periodic trapezoid: spectral
    assert q_area == pytest.approx(math.pi * (64.0 ** 2 + 40 * 1.3 ** 2), rel=1e-9)
    speed = np.linalg.norm(p.dq(t), axis=1)
    L = speed.mean() * 2 * np.pi
    expect = math.pi * (64.0 ** 2 + 40 * 1.3 ** 2) - 3.0 * L + math.pi * 9.0
    assert Polygon(p.boundary_points()).area == pytest.approx(expect, rel=1e-7)


def test_sampled_boundary_is_exact_and_dense_in_roots() -> None:
    p = CycloidProfile(64.0, 1.3, 40, 3.0)
    t = p.boundary_t()
    b = p.boundary(t)
    # vertices on the envelope: distance to the pin-centre curve is rp
    sd, _, _ = p.signed_distance(b, t)
    assert np.abs(sd + 3.0).max() < 1e-9
    # chord midpoints within 0.1 um of the envelope
    mid = 0.5 * (b + np.roll(b, -1, axis=0))
    sdm, _, _ = p.signed_distance(mid, 0.5 * (t + np.roll(t, -1)))
    sdm[-1] = -3.0
    dev = np.abs(sdm + 3.0)
    assert dev.max() < 1e-4
    assert np.linalg.norm(np.diff(b, axis=0), axis=1).max() < 0.2


def test_undercut_reported_and_trimmed() -> None:
    ok = CycloidProfile(64.0, 1.3, 40, 3.0)
    assert ok.min_convex_radius == pytest.approx(4.61, abs=0.01)
    assert not ok.undercut
    cut = CycloidProfile(64.0, 1.3, 40, 4.8)
    assert cut.undercut
    assert "undercut" in str(cut.design_check()["message"])
    poly = Polygon(cut.boundary_points())
    assert poly.is_valid  # no self-intersecting wire


def test_nominal_kinematics_zero_gaps() -> None:
    g = ReducerGeometry()
    th = np.linspace(0, 2 * np.pi * 121, 2000)
    to, ps = g.ideal_state(th)
    assert to[-1] == pytest.approx(2 * np.pi)
    assert (ps[-1, 0] - ps[0, 0]) / (2 * np.pi) == pytest.approx(-39.0)
    gap = g.pin_gaps(to, ps)[0]
    assert np.abs(gap).max() < 1e-9
    for d in (1, -1):
        assert np.abs(g.stage1_gaps(th, to, ps, d)).max() < 1e-9


def test_pin_radius_error_opens_uniform_clearance() -> None:
    g = ReducerGeometry(Case.from_dict({"errors": {"pin_radius": -5}}))
    to, ps = g.ideal_state(np.linspace(0, 50, 200))
    assert g.pin_gaps(to, ps)[0] == pytest.approx(np.full((200, 2, 40), 0.005), abs=1e-12)


def test_far_points_get_the_nearest_foot() -> None:
    """Beyond the roots' concave radius a second local foot exists; the distance must be the global one."""
    p = CycloidProfile(64.0, 1.3, 40, 3.0)
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 2 * np.pi, 400)
    pts = p.q(t) + rng.uniform(0.05, 0.3, 400)[:, None] * p.normal(t)
    sd, _, _ = p.signed_distance(pts, t + rng.uniform(-0.02, 0.02, 400))
    dense = p.q(np.linspace(0, 2 * np.pi, 400001))
    from scipy.spatial import cKDTree

    brute, _ = cKDTree(dense).query(pts)
    assert np.abs(sd - brute).max() < 2e-5  # dense polyline spacing ~ 1.6 um gives ~1e-5 mm
