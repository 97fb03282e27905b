"""Physics checks of the quasi-static solver against closed forms (derivations in docs/physics.md)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvdyn.cli import main as rvdyn_main
from rvdyn.contacts import AnalyticContacts, ContactLaw
from rvdyn.solver import ARCSEC_PER_RAD, InterferenceError, QuasiStaticSolver
from rvdyn.te import lost_motion, run_te

STEPS = 144


def test_ideal_parts_zero_te_and_ratio() -> None:
    nominal = Case.from_dict({})
    for law, load in ((ContactLaw(), 0.0), (ContactLaw(rigid=True), 20.0)):
        r = run_te(nominal, "analytic", STEPS, load_Nm=load, law=law)
        assert np.abs(r.table["te_arcsec"]).max() < 0.01
        assert r.stats["ratio"] == pytest.approx(121.0, rel=1e-6)


def test_ideal_parts_under_load_wind_up_scales_with_contact_law() -> None:
    """Zero backlash: the loaded contacts do not change with load, so every deflection scales as
    load**(1/n) and so does the wind-up (constant over the revolution up to mesh ripple)."""
    nominal = Case.from_dict({})
    r1 = run_te(nominal, "analytic", STEPS, load_Nm=20.0)
    r2 = run_te(nominal, "analytic", STEPS, load_Nm=40.0)
    te1, te2 = r1.table["te_arcsec"].to_numpy(), r2.table["te_arcsec"].to_numpy()
    assert te1.max() < -1.0  # output lags under load, direction +1
    assert r1.stats["pp"] < 0.02 * abs(r1.stats["mean"])  # only mesh ripple on top of the wind-up
    assert te2.mean() / te1.mean() == pytest.approx(2.0 ** (1 / 1.5), rel=2e-3)
    r3 = run_te(nominal, "analytic", STEPS, load_Nm=20.0, law=ContactLaw(n=1.0, K=2e5))
    r4 = run_te(nominal, "analytic", STEPS, load_Nm=40.0, law=ContactLaw(n=1.0, K=2e5))
    assert r4.stats["mean"] / r3.stats["mean"] == pytest.approx(2.0, rel=2e-3)
    minus = run_te(nominal, "analytic", STEPS, load_Nm=20.0, direction=-1)
    assert minus.stats["mean"] == pytest.approx(-r1.stats["mean"], rel=1e-3)


def _lever_arms(geom: ReducerGeometry, theta_in: np.ndarray) -> np.ndarray:
    """Closed-form lever lam_i = (i Z1/Z2) e (n_i . u'(psi + k pi)) of every pin at the ideal pose, mm.

    With the input held and stage I rigid, turning the output by dtheta turns the crank by
    (1 + Z1/Z2) dtheta; subtracting the conjugate motion (dpsi = -Zc dtheta, no gap change)
    leaves a pure crank turn of (i Z1/Z2) dtheta, which moves each disc by e u'(psi + k pi) per
    radian, so the gap of pin i changes by -lam_i dtheta.
    """
    d = geom.design
    to, ps = geom.ideal_state(theta_in)
    _, nrm, _, _ = geom.pin_gaps(to, ps)  # normals in the profile frames (= fixed frame rotated by theta_out)
    lam = np.empty(nrm.shape[:-1])
    for k in range(d.n_discs):
        phi = ps[:, 0] + k * math.pi + to  # direction of u' expressed in the disc frame: psi + k pi + pi/2 - theta
        up = np.stack([-np.sin(phi - to - to), np.cos(phi - to - to)], -1)  # u'(psi + k pi - theta_out)
        lam[:, k] = d.ratio * d.z_sun / d.z_planet * d.eccentricity_mm * np.einsum("nzi,ni->nz", nrm[:, k], up)
    return lam


def test_pin_radius_reduction_clearance_to_angle_and_lost_motion() -> None:
    dr_um = 5.0
    case = Case.from_dict({"errors": {"pin_radius": -dr_um}})
    g = ReducerGeometry(case)
    r = run_te(case, "analytic", STEPS, load_Nm=0.0, geom=g)
    th = np.radians(r.table["input_deg"].to_numpy())
    lam_max = _lever_arms(g, th).max(axis=(1, 2))
    expect = -dr_um * 1e-3 / lam_max * ARCSEC_PER_RAD
    assert r.table["te_arcsec"].to_numpy() == pytest.approx(expect, rel=2e-3)
    # the largest lever is close to e * i * Z1/Z2 = 52.43 mm (the pin whose normal lines up with u')
    assert lam_max.min() == pytest.approx(1.3 * 121 / 3, rel=5e-3)
    lm = lost_motion(case, "analytic", STEPS)
    assert lm["lost_motion_arcsec"] == pytest.approx(-2 * expect.mean(), rel=2e-3)


def test_stage1_error_reduced_by_stage2_ratio() -> None:
    """A planet eccentricity eps turns crank 0 by about eps/rb2 (rad) along the line of action; at the
    output it appears divided by about i Z1/Z2 = 40.3 (and shared with the error-free crank).

    Elastic law at the default load: with zero backlash in both stages the rigid limit of a stage I
    error is over-constrained."""
    eps_um = 10.0
    case = Case.from_dict({"errors": {"planet_eccentricity": eps_um}})
    g = ReducerGeometry(case)
    r = run_te(case, "analytic", 360, geom=g)
    crank_pp_rad = 2 * eps_um * 1e-3 / g.planet.base_radius
    ratio2 = g.ratio * g.design.z_sun / g.design.z_planet
    out_pp_rad = r.stats["pp"] / ARCSEC_PER_RAD
    assert crank_pp_rad / ratio2 / 4 < out_pp_rad < crank_pp_rad / ratio2 * 1.5
    stage2 = run_te(Case.from_dict({"errors": {"disc_hole_eccentricity": eps_um}}), "analytic", 360)
    assert stage2.stats["pp"] > 3 * r.stats["pp"]


@pytest.mark.parametrize("delta_deg", [0.06, -0.06])
def test_pin_ring_rotation_shifts_te_by_120_over_121_of_it(delta_deg: float) -> None:
    """Every pin moved by delta along the pin circle (pin_pitch on all 40 pins) is the pin ring
    rotated by delta: the same as rotating everything but the sun by delta, so the output moves by
    delta and the input sun, relative to the rest, by -delta: TE shifts by delta * (1 - 1/121),
    uniformly (the curve keeps its shape)."""
    nominal = run_te(Case.from_dict({"load_Nm": 20.0}), steps=120)
    rotated = run_te(Case.from_dict({"load_Nm": 20.0, "errors": {"pin_pitch": [delta_deg] * 40}}), steps=120)
    shift = rotated.table["te_arcsec"].to_numpy() - nominal.table["te_arcsec"].to_numpy()
    expected = delta_deg * 3600.0 * 120.0 / 121.0
    assert np.max(np.abs(shift - expected)) < 0.01, (shift.min(), shift.max(), expected)


def test_cam_bearing_clearance_lost_motion_is_geometric_slack() -> None:
    """At the rigid limit a cam-bearing clearance c is pure geometric slack: the lost motion is
    symmetric (TE +-LM/2 in the two directions), proportional to c, zero without a clearance."""
    lm = {c: lost_motion(Case.from_dict({"model": {"cam_bearing_clearance_um": c}} if c else {}), steps=60)
          for c in (0.0, 2.0, 4.0)}
    assert abs(lm[0.0]["lost_motion_arcsec"]) < 1e-6
    for c in (2.0, 4.0):
        assert lm[c]["te_plus_mean_arcsec"] == pytest.approx(-lm[c]["te_minus_mean_arcsec"], rel=1e-6)
    assert lm[4.0]["lost_motion_arcsec"] == pytest.approx(2.0 * lm[2.0]["lost_motion_arcsec"], rel=1e-4)


def test_cam_bearing_clearance_slack_between_its_closed_form_bounds() -> None:
    """Output slack per side at fixed input (docs/physics.md, section 5): turning the output by d
    moves cam h by ``a d t_h + e (1 + Z1/Z2) d t_chi`` (t: unit tangents of the hole arm and of the
    eccentric); the disc may slide along its meshing family (centre e dx t_chi, turn -dx/Zc). The
    bearing offset of hole h is then ``a (d + dx/Zc) t_h + e (k d - dx) t_chi``, k = 4/3, with t_h of
    opposite sign for the two holes. With the tangents aligned the best dx = k d needs
    ``a (1 + k/Zc) d <= c``: slack c / 31.03 mm = 6.648 arcsec/um, the least; orthogonal, the
    sum of squares gives c (A^2 + Zc^2 e^2)^0.5 / ((Zc + k) a e): 7.725 arcsec/um, the most."""
    from rvcad.params import Design

    dsg = Design()
    a = dsg.module_mm * (dsg.z_sun + dsg.z_planet) / 2.0       # crank circle = stage I centre distance, 30 mm
    e, zc, k = dsg.eccentricity_mm, dsg.z_disc, 1.0 + dsg.z_sun / dsg.z_planet
    lo = 1e-3 / (a * (1 + k / zc)) * ARCSEC_PER_RAD
    hi = 1e-3 * math.sqrt(a ** 2 + zc ** 2 * e ** 2) / ((zc + k) * a * e) * ARCSEC_PER_RAD
    c = 2.0
    for d in (1, -1):
        r = run_te(Case.from_dict({"model": {"cam_bearing_clearance_um": c}, "load_Nm": 0.0, "direction": d}),
                   steps=240)
        per_um = -d * r.table["te_arcsec"].to_numpy() / c
        assert per_um.min() >= lo * (1 - 1e-4) and per_um.max() <= hi
        assert per_um.min() == pytest.approx(lo, rel=1e-4)  # the aligned configuration occurs


def test_unresolvable_interference_is_refused() -> None:
    case = Case.from_dict({"errors": {"pin_circle_diameter": -14}})
    g = ReducerGeometry(case)
    s = QuasiStaticSolver(g, AnalyticContacts(g), ContactLaw(rigid=True))
    with pytest.raises(InterferenceError, match=r"interference of 7\.0\d* um .* cannot be resolved at the rigid limit"):
        s.solve(np.linspace(0, 1, 4), 1, 20.0)
    # the elastic law resolves it with a preload
    r = run_te(case, "analytic", 36)
    assert np.isfinite(r.stats["pp"])


def test_bad_input_clear_errors_and_no_partial_csv(tmp_path, capsys) -> None:
    out = tmp_path / "te.csv"
    assert rvdyn_main(["te", "--steps", "1", "--out", str(out)]) == 2
    assert "--steps 1 is out of range; allowed: an integer in [2, " in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"errors": {"pin_radius": "NaN"}}))
    assert rvdyn_main(["te", str(bad), "--out", str(out)]) == 2
    assert "errors.pin_radius 'NaN' is of type str, not a number" in capsys.readouterr().err
    rigid = tmp_path / "rigid.json"
    rigid.write_text(json.dumps({"errors": {"pin_circle_diameter": -14}}))
    assert rvdyn_main(["te", str(rigid), "--rigid", "--steps", "4", "--out", str(out)]) == 2
    assert "cannot be resolved" in capsys.readouterr().err
    assert not out.exists() and not list(tmp_path.glob(".te.csv*"))
    with pytest.raises(ValueError, match="contact exponent n 5.0 must be in"):
        ContactLaw(n=5.0)


def test_cli_te_json_and_csv(tmp_path, capsys) -> None:
    case = tmp_path / "c.json"
    case.write_text(json.dumps({"name": "pitch", "errors": {"pin_pitch": 0.01}}))
    out = tmp_path / "te.csv"
    assert rvdyn_main(["te", str(case), "--solver", "analytic", "--steps", "48", "--out", str(out), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert set(["pp", "mean", "mean_abs", "rms", "ratio"]) <= set(js)
    import pandas as pd

    df = pd.read_csv(out)
    assert list(df.columns[:3]) == ["input_deg", "output_deg", "te_arcsec"]
    assert len(df) == 48
    assert js["pp"] == pytest.approx(df["te_arcsec"].max() - df["te_arcsec"].min(), abs=1e-6)
