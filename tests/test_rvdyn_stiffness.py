"""rvdyn stiffness: the maker's hysteresis curve and datasheet figures (definitions in conventions.md)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from rvcad.errors import Case
from rvdyn.cli import main as rvdyn_main
from rvdyn.contacts import ContactLaw
from rvdyn.solver import ARCSEC_PER_RAD
from rvdyn.stiffness import DEFAULT_RATED_NM, hysteresis

KEYS = {"torsional_rigidity_Nm_per_arcmin", "lost_motion_arcmin", "backlash_arcmin", "hysteresis_loss_arcmin",
        "rated_torque_Nm", "budget"}


@pytest.fixture(scope="module")
def sweeps():
    law = ContactLaw(kind="physical")
    no_fric = {"pin_friction_coefficient": 0.0, "bearing_friction_coefficient": 0.0}
    return {
        "default": hysteresis(Case.from_dict({}), law=law, points=21),
        "frictionless": hysteresis(Case.from_dict({"model": no_fric}), law=law, points=21),
        "double": hysteresis(Case.from_dict({"model": {"pin_friction_coefficient": 0.1,
                                                       "bearing_friction_coefficient": 0.005}}), law=law, points=21),
        "clearance": hysteresis(Case.from_dict({"errors": {"pin_radius": -5.0}, "model": no_fric}), law=law,
                                points=21),
        "compliance": hysteresis(Case.from_dict({"model": dict(no_fric, torsional_compliance_arcsec_per_Nm=0.25)}),
                                 law=law, points=21),
    }


def test_figures_and_budget_are_the_curve(sweeps) -> None:
    f = sweeps["default"].figures
    assert KEYS <= set(f) and f["rated_torque_Nm"] == DEFAULT_RATED_NM
    assert {"pins", "pin_seats", "gears", "cam_bearings", "journal_bearings", "crank_bending", "crank_torsion",
            "carrier", "cam_bearing_seats", "journal_bearing_seats", "housing"} == set(f["budget"])
    el = sweeps["default"].elastic
    at_rated = el.loc[np.isclose(el["torque_Nm"], DEFAULT_RATED_NM), "torsion_arcmin"].to_numpy()[0] * 60
    # the parts add up to the wind-up (virtual work on the linearised gaps: to 1e-4)
    assert f["budget_total_arcsec"] == pytest.approx(at_rated, rel=1e-4)
    # rigidity b/a from the mid-curve: the frictionless secant between 3 % and 100 % of rated torque
    g = sweeps["frictionless"]
    e = g.elastic
    th = {t: e.loc[np.isclose(e["torque_Nm"], t), "torsion_arcmin"].to_numpy()[0]
          for t in (0.03 * 167, 167.0, -0.03 * 167, -167.0)}
    b = 0.97 * 167
    expect = 0.5 * (b / (th[167.0] - th[0.03 * 167]) + b / (th[-0.03 * 167] - th[-167.0]))
    assert g.figures["torsional_rigidity_Nm_per_arcmin"] == pytest.approx(expect, rel=1e-9)


def test_a_lumped_compliance_is_a_budget_part_and_adds_in_series_to_the_secant(sweeps) -> None:
    """``model.torsional_compliance_arcsec_per_Nm`` C: its wind-up C T_rated is a part of the budget (the parts
    still add up to the wind-up), and without friction the b/a secant meets the series law
    ``1/k = 1/k_0 + C/60`` exactly (C adds C b to the span a); rvcalib.datasheet reads a compliance found so."""
    c, f0 = sweeps["compliance"].figures, sweeps["frictionless"].figures
    assert c["budget"]["torsional_compliance"] == pytest.approx(0.25 * DEFAULT_RATED_NM, rel=1e-12)
    assert "torsional_compliance" not in f0["budget"]
    el = sweeps["compliance"].elastic
    at_rated = el.loc[np.isclose(el["torque_Nm"], DEFAULT_RATED_NM), "torsion_arcmin"].to_numpy()[0] * 60
    assert c["budget_total_arcsec"] == pytest.approx(at_rated, rel=1e-4)
    k0 = f0["torsional_rigidity_Nm_per_arcmin"]
    assert c["torsional_rigidity_Nm_per_arcmin"] == pytest.approx(1.0 / (1.0 / k0 + 0.25 / 60.0), rel=1e-9)


def test_no_friction_no_loop_and_lost_motion_is_the_3_percent_span(sweeps) -> None:
    g = sweeps["frictionless"]
    c = g.curve
    up = c[c["branch"] == "load"].sort_values("torque_Nm")
    dn = c[c["branch"] == "unload"].sort_values("torque_Nm")
    assert np.abs(up["torsion_arcmin"].to_numpy() - dn["torsion_arcmin"].to_numpy()).max() < 1e-9
    f = g.figures
    # no clearance: the two rigid limits agree within the solver's convergence, so the play is exactly zero
    assert f["backlash_arcmin"] == 0.0 and abs(f["hysteresis_loss_arcmin"]) < 1e-8
    e = g.elastic
    th3 = np.interp([-0.03 * 167, 0.03 * 167], e["torque_Nm"], e["torsion_arcmin"])
    assert f["lost_motion_arcmin"] == pytest.approx(th3[1] - th3[0], rel=1e-6)


def test_friction_opens_the_loop_in_proportion(sweeps) -> None:
    """Coulomb friction proportional to the contact loads: the loop's width at half rated torque grows
    with the coefficients (doubling both about doubles it); with no preload it closes at zero torque."""
    def width(res, tau):
        c = res.curve
        vals = [np.interp(tau, *c[c["branch"] == br].sort_values("torque_Nm")[["torque_Nm", "torsion_arcmin"]]
                          .to_numpy().T) for br in ("load", "unload")]
        return vals[1] - vals[0]
    w1, w2 = width(sweeps["default"], 83.5), width(sweeps["double"], 83.5)
    assert w1 > 1e-3
    assert w2 / w1 == pytest.approx(2.0, rel=0.1)
    assert abs(sweeps["default"].figures["hysteresis_loss_arcmin"]) < 1e-6
    assert sweeps["default"].figures["lost_motion_arcmin"] > sweeps["frictionless"].figures["lost_motion_arcmin"]


def test_pin_clearance_is_backlash(sweeps) -> None:
    """A uniform pin radius reduction dr opens a play of 2 dr / lambda_max (docs/physics.md section 6,
    lever lambda_max ~ e i Z1/Z2 = 52.4 mm): backlash = hysteresis loss at zero torque; lost motion
    includes it."""
    f = sweeps["clearance"].figures
    expect_arcmin = 2 * 5e-3 / (1.3 * 121 / 3) * ARCSEC_PER_RAD / 60
    assert f["backlash_arcmin"] == pytest.approx(expect_arcmin, rel=5e-3)
    assert f["hysteresis_loss_arcmin"] == pytest.approx(f["backlash_arcmin"], rel=1e-6)
    assert f["lost_motion_arcmin"] > f["backlash_arcmin"]


def test_cli_stiffness_json_csv_and_bad_input(tmp_path, capsys) -> None:
    out = tmp_path / "curve.csv"
    assert rvdyn_main(["stiffness", "--contact", "impact", "--points", "9", "--out", str(out), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert KEYS <= set(js) and js["contact"] == "impact" and set(js["budget"]) == {"pins", "gears"}
    import pandas as pd

    df = pd.read_csv(out)
    assert list(df.columns) == ["torque_Nm", "torsion_arcmin", "branch"] and len(df) > 17
    assert rvdyn_main(["stiffness", "--rated-Nm", "0", "--out", str(tmp_path / "x.csv")]) == 2
    assert "--rated-Nm 0.0 is out of range" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()


# ---------------------------------------------------------------------------------------------- profile modification
@pytest.fixture(scope="module")
def modified():
    law = ContactLaw(kind="physical")
    no_fric = {"pin_friction_coefficient": 0.0, "bearing_friction_coefficient": 0.0}
    return hysteresis(Case.from_dict({"design": {"profile_equidistant_mm": 0.01}, "model": no_fric}), law=law,
                      points=11)


def test_equidistant_modification_backlash_and_pins_in_contact(modified) -> None:
    """An equidistant modification d_rp = 10 um opens the same play as a pin 10 um thinner:
    2 d_rp / lambda_max (lambda_max = e i Z1/Z2 = 52.43 mm): 1.31 arcmin; few pins touch at light
    load and more engage as the torque grows (never fewer)."""
    f = modified.figures
    assert f["backlash_arcmin"] == pytest.approx(2 * 0.01 / (1.3 * 121 / 3) * ARCSEC_PER_RAD / 60, rel=5e-3)
    n = np.array(list(f["pins_in_contact"].values()))
    assert n[0] <= 4 and n[-1] >= 3 * n[0] and np.all(np.diff(n) >= 0)
    assert f["lost_motion_arcmin"] > f["backlash_arcmin"]


def test_rotation_modification_shifts_te_closed_form() -> None:
    """Both profiles turned by delta relative to their crank holes: the mesh holds when the output turns by
    -delta Zc / (Zc + 1 + Z1/Z2) = -delta 117/121 (a uniform TE shift)."""
    from rvdyn.te import run_te

    a = run_te(Case.from_dict({}), steps=12).table["te_arcsec"].to_numpy()
    b = run_te(Case.from_dict({"design": {"profile_rotation_deg": 0.01}}), steps=12).table["te_arcsec"].to_numpy()
    assert np.abs(b - a - (-0.01 * 3600 * 39 / (39 + 4 / 3))).max() < 1e-3


def test_modification_is_in_the_shared_profile_and_checked() -> None:
    """The modification lives in the shared profile maths (rvcad.profile), so the geometry and the
    exported discs (rvcad.parts takes geometry.profiles) carry it; out-of-range values name the field."""
    from rvcad.geometry import ReducerGeometry

    g = ReducerGeometry(Case.from_dict({"design": {"profile_equidistant_mm": 0.02, "profile_shift_mm": -0.01}}))
    assert g.profiles[0].pin_radius == pytest.approx(3.02) and g.profiles[1].pin_circle_radius == pytest.approx(63.99)
    with pytest.raises(ValueError, match=r"design.profile_shift_mm 0.5 is out of range; allowed: a number in \[-0.2, 0.2\] mm"):
        ReducerGeometry(Case.from_dict({"design": {"profile_shift_mm": 0.5}}))


def test_cli_stiffness_plot_png(tmp_path, capsys) -> None:
    png = tmp_path / "curve.png"
    assert rvdyn_main(["stiffness", "--contact", "impact", "--points", "5", "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "torsional rigidity" in out and "lost motion" in out and "compliance budget" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
