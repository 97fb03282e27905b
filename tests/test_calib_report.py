"""The report of a calibration (rvcalib.report, rvcalib.reportmd, rvcalib.figures), its datasheet refusal and
equivalents, on a CalibrationResult built by hand for a ratio-81 reducer whose readings the test writes itself."""
from __future__ import annotations

import json
import math
import os
import stat

import numpy as np
import pytest

from rig_records import R81, cos_orders, write_dataset
from rvcad.atomic import current_umask
from rvcad.params import Design
from rvcalib.cli import summary
from rvrig.dataset import read_dataset
from rvcalib.datasheet import rated_torque, reducer_datasheet
from rvcalib.equivalents import result_equivalents, rotation_per_offset_deg
from rvcalib.report import bounded_groups, physical_bounds, write_report
from rvcalib.reportmd import markdown
from rvcalib.result import CalibrationResult, NamedEffect, merge_sides
from rvcalib.settings import CalibrationSettings

#: A group size of the kind the data leave free (only the combination of two members is fixed).
HUGE = -3.56e9
#: An order the ratio-81 design does not have (rvrig.spectrum.reducer_orders): a line at it is the rig's.
RIG_ORDER = 17


@pytest.fixture(scope="module")
def ds81(tmp_path_factory):
    periodic = cos_orders({1: (20.0, 30.0), 39: (3.0, 0.0)})
    runs = [{"run": f"{ld:g}{'f' if d > 0 else 'b'}", "load_Nm": ld, "direction": d, "speed_rpm": 1800.0,
             "te": (lambda th, t, ld=ld, d=d: 5.0 - d * 0.2 * ld + periodic(th, t))}
            for ld in (10.0, 30.0) for d in (1, -1)]
    return read_dataset(write_dataset(tmp_path_factory.mktemp("r81") / "ds", runs, per_rev=180))


def hand_result(ds, rated_Nm=None) -> CalibrationResult:
    """Two named effects, a group with a member beyond its bounds and one without a size, an order-3 unexplained
    term, the tests' constants; the residual after holds a line at an order the design does not have."""
    rng = np.random.default_rng(5)
    effects = [NamedEffect("pin_radius", "pin_radius", "table4", {}, "um", 2.0, None, [2.0], [[0.04]], [1.6, 2.4], 1.0,
                           "Table 4: radius of all pins"),
               NamedEffect("output_encoder_eccentricity", "output_encoder_eccentricity", "measurement", {}, "um", 8.0,
                           30.0, [8.0 * math.cos(math.radians(30.0)), 4.0], [[0.01, 0.0], [0.0, 0.01]], [7.8, 8.2], 1.0,
                           "eccentricity of the output encoder's scale", 2.5)]

    def member(name: str, key: str, unit: str, value, p: float) -> dict:
        return {"name": name, "key": key, "family": "table4", "instance": {}, "unit": unit, "value": value,
                "angle_deg": None, "probability": p}

    groups = [{"kind": "physical", "coverage": 0.95, "purity": 0.99,
               "members": [member("pin_circle_diameter", "pin_circle_diameter", "um", HUGE, 0.5),
                           member("pin_radius[pin=3]", "pin_radius", "um", "unbounded", 0.2),
                           member("cam_phase[crank=0,disc=1]", "cam_phase", "um", 3.0, 0.3)]}]
    unexplained = [{"label": "order 3 (common)", "order": 3, "kind": "common", "amplitude_arcsec": 1.5,
                    "phase_deg": -20.0, "probability": 0.99, "members": []}]
    nuisance = [{"test": t, "constant_arcsec": 5.0 + i} for i, t in enumerate(ds.tests.ids)]
    resid = [0.8 * np.cos(RIG_ORDER * r.output_rad) + rng.normal(0.0, 0.1, r.n) for r in ds.runs]
    return CalibrationResult(
        effects=effects, groups=groups, unexplained=unexplained, diffuse=[], nuisance=nuisance, rms_before=12.0,
        rms_after=0.58, noise_arcsec=ds.noise_arcsec(), sigma_arcsec=0.5, stopped_by="converged", cap_binds=False,
        seconds=1.0, linearisations=3, settings=CalibrationSettings(max_order=8, rated_Nm=rated_Nm).to_dict(),
        notes=["a note of the loop"], reducer=ds.reducer(),
        calibrated_case={"design": dict(R81), "model": {"torsional_compliance_arcsec_per_Nm": 0.2}}, residuals=resid)


@pytest.fixture(scope="module")
def written(ds81, tmp_path_factory):
    res = hand_result(ds81)
    out = tmp_path_factory.mktemp("report")
    paths = write_report(res, ds81, out, datasheet=reducer_datasheet(res, ds81))
    return res, out, paths


def test_the_report_follows_the_reducer_ratio(written):
    _, out, paths = written
    text = (out / "report.md").read_text()
    assert "(output_deg - input_deg / 81) * 3600 arcsec" in text
    assert "121" not in text
    assert paths["object"]["ratio"] == 81.0
    assert "order 81" in summary(paths["object"]) or "input_deg / 81" in summary(paths["object"])


def test_a_size_beyond_physical_bounds_is_unbounded_in_text_and_json(written):
    _, out, paths = written
    obj = json.loads((out / "result.json").read_text())
    sizes = {m["name"]: m["value"] for m in obj["groups"][0]["members"]}
    assert sizes == {"pin_circle_diameter": "unbounded", "pin_radius[pin=3]": "unbounded",
                     "cam_phase[crank=0,disc=1]": 3.0}
    text = (out / "report.md").read_text() + summary(obj)
    assert "e+09" not in text and "3.56e9" not in text and "-3.56" not in text
    assert "| `pin_circle_diameter` | unbounded | um |" in text
    assert "pin_circle_diameter unbounded" in summary(obj)
    # no physical equivalent is read off a size the data do not fix
    assert obj["equivalents"]["groups"][0] == [[], [], []]


def test_bounded_groups_against_the_library_bounds(ds81):
    bounds = physical_bounds(ds81)
    assert bounds["pin_circle_diameter"][:2] == (-200.0, 200.0)
    assert bounds["pin_radius[pin=3]"][:2] == (-200.0, 200.0)           # the union of its two sides
    g = [{"members": [{"name": "pin_radius[pin=3]", "value": v} for v in (199.0, -201.0, math.nan)]}]
    assert [m["value"] for m in bounded_groups(g, bounds)[0]["members"]] == [199.0, "unbounded", "unbounded"]


def test_report_sections_and_figures(written, ds81):
    _, out, paths = written
    text = (out / "report.md").read_text()
    for head in ("## What the rig shows", "## Effects named", "## Groups", "## Unexplained structure",
                 "## The tests' constants", "## Datasheet of the reducer", "## Each load left out",
                 "## Lines in the residual", "## Runs", "## Figures", "## Method"):
        assert head in text, head
    assert "docs/calibration.md" in text
    # the measured table: one row per test, B - F = 2 x 0.2 x load exactly (the rig zero cancels)
    tests = {t["test"]: t for t in paths["object"]["measured"]["tests"]}
    assert tests["10Nm_1800rpm"]["bw_minus_fw_arcsec"] == pytest.approx(4.0, abs=1e-6)
    assert tests["30Nm_1800rpm"]["bw_minus_fw_arcsec"] == pytest.approx(12.0, abs=1e-6)
    # the residual's line at an order this design does not have: reported at a fixed frequency, not claimed
    fixed = paths["object"]["residual_spectrum"]["fixed_frequency"]
    assert [round(g["order"]) for g in fixed] == [RIG_ORDER]
    assert fixed[0]["frequency_Hz"] == pytest.approx(RIG_ORDER, rel=1e-2)          # one revolution per second
    assert "not claimed for the reducer" in text
    assert not any(round(g["order"]) == RIG_ORDER for g in paths["object"]["residual_spectrum"]["order_locked"])
    mode = 0o666 & ~current_umask()
    for f in paths["figures"] + [paths["report"], paths["json"]]:
        assert stat.S_IMODE(os.stat(f).st_mode) == mode, f
    for f in paths["figures"]:
        with open(f, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    assert not [p for p in os.listdir(out) if p.startswith(".")]                  # no temporary file left


def test_equivalents_of_the_named_effects_and_the_constant(written, ds81):
    res, out, paths = written
    eq = result_equivalents(res, ds81.design)
    (q,) = eq["effects"]["pin_radius"]
    assert q["parameter"] == "design.profile_equidistant_mm" and q["value"] == pytest.approx(-2e-3)
    assert (q["ci_low"], q["ci_high"]) == pytest.approx((-2.4e-3, -1.6e-3))
    consts = [n["constant_arcsec"] for n in res.nuisance]
    assert eq["common_constant"] == pytest.approx(np.mean(consts))
    assert eq["constant"][0]["value"] == pytest.approx(np.mean(consts) * rotation_per_offset_deg(ds81.design))
    assert "design.profile_rotation_deg" in (out / "report.md").read_text()
    # a member's size maps as an effect's does (a pin circle diameter is a shift modification); a cam phase and a
    # member without a size have none
    shift, pin3, cam = eq["groups"][0]
    assert shift[0]["parameter"] == "design.profile_shift_mm" and shift[0]["value"] == pytest.approx(-0.5e-3 * HUGE)
    assert pin3 == [] and cam == []


def test_datasheet_refused_without_a_rated_torque_for_a_design_not_the_default(written, ds81):
    res, out, paths = written
    sheet = reducer_datasheet(res, ds81)
    assert sheet["computed"] is False and sheet["rated_torque_Nm"] is None
    assert "rated torque is needed" in sheet["rated_source"] and "--rated-Nm" in sheet["rated_source"]
    text = (out / "report.md").read_text()
    assert "Not computed: the rated torque is needed" in text
    assert "datasheet as calibrated: not computed: the rated torque is needed" in summary(paths["object"])
    section = text.split("## Datasheet")[1].split("##")[0]
    assert "torsional rigidity" not in section and "Rated torque 167" not in section


def test_rated_torque_rules():
    assert rated_torque(Design(), None)[0] == 167.0
    assert "default" in rated_torque(Design(), None)[1]
    assert rated_torque(Design.from_dict(R81), None)[0] is None
    assert rated_torque(Design.from_dict(R81), 1568.0) == (1568.0, "given (--rated-Nm)")


def test_without_a_datasheet_the_report_says_why(written, ds81):
    _, _, paths = written
    obj = dict(paths["object"], datasheet=None)
    assert "Not computed: the rated torque is needed" in markdown(obj, ds81)
    obj["settings"] = dict(obj["settings"], rated_Nm=1568.0)
    assert "Not computed with this report" in markdown(obj, ds81)


def test_an_existing_file_is_refused_as_the_report_folder(ds81, tmp_path):
    f = tmp_path / "f"
    f.write_text("x")
    with pytest.raises(ValueError, match="--out .* is an existing file"):
        write_report(hand_result(ds81), ds81, f)


def test_the_two_sides_of_one_pin_are_one_group_member():
    """A credible set holding both sides of pin 8's radius error (the negative side's size beyond its range) and
    another candidate: pin 8 is one member, with the probabilities summed and the size of the side that fits."""
    def member(name: str, value, p: float) -> dict:
        return {"name": name, "key": "pin_radius", "family": "table4", "instance": {"pin": 8}, "unit": "um",
                "value": value, "angle_deg": None, "probability": p}

    got = merge_sides([member("pin_radius[pin=8]", "unbounded", 0.6), member("pin_pitch[pin=9]", 0.002, 0.1),
                       member("pin_radius[pin=8]", 1.889, 0.3)])
    assert [m["name"] for m in got] == ["pin_radius[pin=8]", "pin_pitch[pin=9]"]
    assert got[0]["value"] == 1.889 and got[0]["probability"] == pytest.approx(0.9)
    assert got[0]["sides"] == [{"value": "unbounded", "probability": 0.6}, {"value": 1.889, "probability": 0.3}]
    assert got[1] == member("pin_pitch[pin=9]", 0.002, 0.1)
    both = merge_sides([member("pin_radius[pin=8]", "unbounded", 0.5), member("pin_radius[pin=8]", "unbounded", 0.4)])
    assert len(both) == 1 and both[0]["value"] == "unbounded"


def test_a_named_size_is_given_in_prior_scales(written):
    """8 um over the encoder's prior scale of 2.5 um is 3.2 prior scales, in the summary, the table and the JSON; an
    effect without a prior scale has none."""
    res, out, paths = written
    obj = paths["object"]
    assert [e["prior_scale"] for e in obj["effects"]] == [None, 2.5]
    text = summary(obj)
    assert "output_encoder_eccentricity = 8 um at 30.0 deg [7.8, 8.2] (probability 1.000; 3.2 prior scales)" in text
    assert "pin_radius = 2 um [1.6, 2.4] (probability 1.000)" in text
    assert "| `output_encoder_eccentricity` | measurement | 8 | um | 30 | [7.8, 8.2] | 1 | 3.2 |" in \
        (out / "report.md").read_text()
    assert res.effects[1].line().endswith("(probability 1.000; 3.2 prior scales)")
