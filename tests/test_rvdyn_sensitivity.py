"""rvdyn.sensitivity: the elasticity of the torsional rigidity to the sizes the paper does not give."""
from __future__ import annotations

import json
import math

import pytest

from rvcad.errors import Case
from rvcad.validation import DesignError
from rvdyn.cli import main as rvdyn_main
from rvdyn.sensitivity import ASSUMED_SIZES, rigidity, rigidity_at, rigidity_elasticities, size_value, with_size

NO_FRICTION = {"pin_friction_coefficient": 0.0, "bearing_friction_coefficient": 0.0}


def test_the_elasticity_to_a_lumped_compliance_is_the_series_law() -> None:
    """Without friction the b/a secant meets ``1/k = 1/k_0 + C/60`` exactly (docs/physics.md section 9), so the
    two rigidities at C (1 -+ h) and the elasticity have closed forms: ``k(C) = 1/(1/k_0 + C/60)``,
    ``E = ln(k+/k-)/ln((1+h)/(1-h))``; with C = 0.2 arcsec/(N m) and k_0 about 86 N m/arcmin, E is about -0.22."""
    k0 = rigidity(Case.from_dict({"model": NO_FRICTION}))
    case = Case.from_dict({"model": dict(NO_FRICTION, torsional_compliance_arcsec_per_Nm=0.2)})
    h = 0.1
    row = rigidity_elasticities(case, sizes=("model.torsional_compliance_arcsec_per_Nm",), rel_step=h).iloc[0]

    def k(c: float) -> float:
        return 1.0 / (1.0 / k0 + c / 60.0)

    assert (row["low"], row["high"]) == pytest.approx((0.18, 0.22), rel=1e-12)
    assert row["rigidity_low"] == pytest.approx(k(0.18), rel=1e-9)
    assert row["rigidity_high"] == pytest.approx(k(0.22), rel=1e-9)
    closed = math.log(k(0.22) / k(0.18)) / math.log(1.1 / 0.9)
    assert row["elasticity"] == pytest.approx(closed, rel=1e-8)
    assert -0.3 < closed < -0.15


def test_integer_sizes_step_by_one_and_longer_rollers_make_a_stiffer_reducer() -> None:
    """A roller count steps to n - 1 and n + 1. More or longer rollers in either bearing carry the same load with
    less deflection (Palmgren: ``delta ~ Q^0.9 / l^0.8``), so the rigidity rises with each; a thicker disc spreads
    the crank's bearings apart and the bending lowers it."""
    sizes = ("design.journal_bearing_rollers", "design.journal_bearing_roller_length_mm",
             "design.cam_bearing_roller_length_mm", "design.disc_width_mm")
    tab = rigidity_elasticities(sizes=sizes).set_index("size")
    assert (tab.loc["design.journal_bearing_rollers", "low"], tab.loc["design.journal_bearing_rollers", "high"]) \
        == (11, 13)
    assert tab.loc["design.journal_bearing_roller_length_mm", "low"] == pytest.approx(6.0 * 0.95, rel=1e-12)
    for s in sizes[:3]:
        assert tab.loc[s, "rigidity_high"] > tab.loc[s, "rigidity_low"]
        assert 0.05 < tab.loc[s, "elasticity"] < 1.0, s
    assert tab.loc["design.disc_width_mm", "elasticity"] < -0.1


def test_the_assumed_sizes_are_sizes_of_the_default_design() -> None:
    case = Case.from_dict({})
    for s in ASSUMED_SIZES:
        v = size_value(case, s)
        assert isinstance(v, (int, float)) and v > 0, s
    assert size_value(case, "design.module_mm") == 1.25
    assert with_size(case, "design.disc_width_mm", 12.0).design.disc_width_mm == 12.0


@pytest.mark.parametrize("size, match", [
    ("design.nope", r"size 'design.nope' is not a numeric Design field; allowed: 'design.FIELD'"),
    ("design.journal_bearing_arrangement", r"size 'design.journal_bearing_arrangement' is not a numeric"),
    ("disc_width_mm", r"size 'disc_width_mm' is not allowed; allowed: 'design.FIELD'"),
    ("errors.pin_radius", r"size 'errors.pin_radius' is not allowed"),
    (3, r"size 3 is not allowed"),
    ("model.torsional_compliance_arcsec_per_Nm", r"is not set in the case's model object"),
])
def test_a_bad_size_is_refused_naming_it(size, match) -> None:
    with pytest.raises(ValueError, match=match):
        rigidity_elasticities(sizes=(size,))


@pytest.mark.parametrize("step", [0.0, -0.1, 0.6, True, "0.1", float("nan")])
def test_a_bad_step_is_refused_naming_it(step) -> None:
    with pytest.raises(ValueError, match=r"rel_step .* is not allowed; allowed: a number in \(0, 0.5\]"):
        rigidity_elasticities(sizes=("design.disc_width_mm",), rel_step=step)


def test_a_named_option_is_not_a_size() -> None:
    case = Case.from_dict({"model": {"contact": "physical"}})
    with pytest.raises(ValueError, match=r"size 'model.contact' = 'physical' is a named option, not a size"):
        rigidity_elasticities(case, sizes=("model.contact",))


def test_a_step_out_of_the_valid_designs_makes_a_one_sided_difference_and_says_why() -> None:
    """A cam 25 % smaller no longer lets the 7 mm journal pass (the validation refuses it): the elasticity is taken
    from the size's own value up, and the note quotes the validation; a three-roller bearing cannot lose one."""
    row = rigidity_elasticities(sizes=("design.cam_radius_mm",), rel_step=0.25).iloc[0]
    k0 = rigidity(Case.from_dict({}))
    assert row["low"] == 9.0 and row["rigidity_low"] == k0 and row["high"] == pytest.approx(11.25, rel=1e-12)
    assert row["elasticity"] == pytest.approx(math.log(row["rigidity_high"] / k0) / math.log(1.25), rel=1e-12)
    assert row["elasticity"] > 0.3
    assert "one-sided (the step down is invalid: design.crank_journal_radius_mm 7.0 mm does not pass" in row["note"]
    three = Case.from_dict({"design": {"cam_bearing_rollers": 3}})
    row = rigidity_elasticities(three, sizes=("design.cam_bearing_rollers",)).iloc[0]
    assert (row["low"], row["high"]) == (3, 4) and row["elasticity"] > 0
    assert "design.cam_bearing_rollers 2 is out of range" in row["note"]
    k, why = rigidity_at(Case.from_dict({}), "design.crank_journal_radius_mm", 2.5)    # a 5 mm crank at 167 N m
    assert k is None and why.startswith("interference of ") and "cannot be resolved at the physical contact law" in why
    assert rigidity_at(Case.from_dict({}), "design.crank_journal_radius_mm", 7.0) == (k0, "")
    with pytest.raises(DesignError, match=r"does not pass through the cam .*allowed: < cam_radius_mm - eccentricity_mm"):
        with_size(Case.from_dict({}), "design.cam_radius_mm", 6.0)


def test_rvdyn_stiffness_sensitivity_json_passes_the_contact_law_on(capsys) -> None:
    """``rvdyn stiffness --sensitivity --json``: one entry per assumed size. With ``--contact impact`` the paper's
    law holds every support rigid, so the bearings' sizes do not move the rigidity (0 to 1e-9) and the module moves
    it only through the mesh (0.067, against 1.89 under the physical law, whose bearings sit on the crank circle):
    the sweeps use the command's law, not the case's default."""
    assert rvdyn_main(["stiffness", "--contact", "impact", "--sensitivity", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    rows = {r["size"]: r for r in out["sensitivity"]}
    assert list(rows) == list(ASSUMED_SIZES)
    for s in ("design.cam_bearing_rollers", "design.journal_bearing_roller_length_mm",
              "design.carrier_pillar_radius_mm"):
        assert abs(rows[s]["elasticity"]) < 1e-9, s
    assert 0.03 < rows["design.module_mm"]["elasticity"] < 0.5     # the mesh stiffness only (physical law: 1.89)
    assert out["contact"] == "impact"
