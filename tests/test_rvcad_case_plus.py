"""rvcad.errors.Case.plus: a case plus t times a direction in case space (errors add to the same instance or are
appended, model options add to the case's value or the default), checked through the resolved geometry."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcad.errors import Case, ResolvedErrors
from rvdyn.options import MODEL_OPTIONS

DEFAULTS = {k: o.default for k, o in MODEL_OPTIONS.items()}


def test_errors_add_to_the_same_instance_and_new_instances_are_appended():
    base = Case.from_dict({"errors": {"pin_pitch": 0.01, "planet_eccentricity": {"value": 3.0, "crank": 1,
                                                                                  "angle_deg": 90.0}},
                           "model": {"torsional_compliance_arcsec_per_Nm": 0.2}})
    delta = {"errors": {"pin_pitch": {"value": 0.004, "pin": 7},
                        "planet_eccentricity": {"value": 1.0, "crank": 1, "angle_deg": 90.0},
                        "pin_circle_diameter": [float(i) for i in range(40)]},
             "model": {"torsional_compliance_arcsec_per_Nm": 1.0, "cam_bearing_clearance_um": 4.0}}
    out = base.plus(delta, 0.5, DEFAULTS)
    assert out.raw_errors["planet_eccentricity"] == [{"value": 3.5, "crank": 1, "angle_deg": 90.0}]
    assert out.raw_errors["pin_pitch"] == [{"value": 0.01, "pin": 0}, {"value": 0.002, "pin": 7}]
    assert out.model == {"torsional_compliance_arcsec_per_Nm": 0.7, "cam_bearing_clearance_um": 2.0}
    er, er0 = ResolvedErrors(out), ResolvedErrors(base)
    np.testing.assert_allclose(er.planet_offset[1], [0.0, 3.5e-3], atol=1e-15)
    np.testing.assert_allclose(er.pin_pitch - er0.pin_pitch, np.radians(0.002) * (np.arange(40) == 7), atol=1e-18)
    np.testing.assert_allclose(er.pin_radial, 0.5 * np.arange(40) * 1e-3 / 2.0, atol=1e-15)
    # t = 0 is the case itself; a direction of the default instance adds to it
    assert ResolvedErrors(base.plus(delta, 0.0, DEFAULTS)).pin_pitch[0] == er0.pin_pitch[0]
    assert math.isclose(ResolvedErrors(base.plus({"errors": {"pin_pitch": 0.01}}, -1.0)).pin_pitch[0], 0.0,
                        abs_tol=1e-18)


@pytest.mark.parametrize("delta, match", [
    ({"errors": {"pin_pich": 1.0}}, r"d\.errors key 'pin_pich' is unknown"),
    ({"errors": {"pin_pitch": {"value": 1e-3, "pin": 40}}}, r"d\.errors\.pin_pitch\.pin 40 is out of range"),
    ({"errors": {"pin_radius": [1.0] * 39}}, r"d\.errors\.pin_radius .* pin-wise list of 39 numbers"),
    ({"model": {"contact": 1.0}}, r"d\.model key 'contact' is a named choice, not a number"),
    ({"model": {"torsional_compliance": 1.0}}, r"d\.model key 'torsional_compliance' is unknown"),
    ({"model": {"friction_torque_Nm": "1"}}, r"d\.model\.friction_torque_Nm '1' is of type str"),
    ({"error": {}}, r"d key 'error' is unknown; allowed: \['errors', 'model'\]"),
    ([1.0], r"d \[1.0\] is of type list, not an object"),
])
def test_a_bad_direction_names_its_field(delta, match):
    with pytest.raises(ValueError, match=match):
        Case.from_dict({}).plus(delta, 1.0, DEFAULTS, field="d")


def test_a_sum_outside_the_valid_cases_is_refused_naming_the_option():
    with pytest.raises(ValueError, match=r"model\.pin_circle_ovality_um 300.0 um is out of range"):
        Case.from_dict({}).plus({"model": {"pin_circle_ovality_um": 100.0}}, 3.0, DEFAULTS)
