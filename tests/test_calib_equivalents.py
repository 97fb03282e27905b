"""rvcalib.equivalents: the physical parameters behind what the loop names (profile modifications, a profile
rotation for a constant), each checked against rvdyn solving the physical parameter itself."""
from __future__ import annotations

import json

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.params import Design
from rvcalib.equivalents import EQUIVALENTS, effect_equivalents, result_equivalents, rotation_per_offset_deg
from rvdyn.te import run_te


def _te(case: dict, load: float, direction: int, steps: int = 120) -> np.ndarray:
    return run_te(Case.from_dict(case), steps=steps, load_Nm=load, direction=direction).table["te_arcsec"].to_numpy()


@pytest.mark.parametrize("parameter,value,tol", [("profile_equidistant_mm", 0.003, 1e-4),
                                                 ("profile_shift_mm", -0.004, 2e-3)])
def test_a_profile_modification_gives_the_te_of_the_library_effect_it_is_reported_as(parameter, value, tol):
    """The disc cut with the modification and the unmodified disc with the all-pins error of
    :data:`rvcalib.equivalents.EQUIVALENTS` solve to the same TE at the rigid limit, light and rated load, both
    directions (<= 2e-5 arcsec for the equidistant, 1.2e-3 for the shift, of effects of 9-13 arcsec); the factor is
    not a fit: half or twice it misses by arcseconds."""
    q = next(q for q in EQUIVALENTS if q.parameter == parameter)
    size = value / q.factor                                      # um of the library effect
    for load in (0.0, 20.0, 167.0):
        for d in (1, -1):
            nominal = _te({}, load, d)
            mod = _te({"design": {parameter: value}}, load, d)
            same = _te({"errors": {q.effect: size}}, load, d)
            assert np.abs(mod - nominal).max() > 5.0                       # a real effect
            assert np.abs(mod - same).max() < tol, (load, d)
            for wrong in (0.5, 2.0):
                assert np.abs(mod - _te({"errors": {q.effect: wrong * size}}, load, d)).max() > 2.0
    # the reported size maps back with its interval (sorted: the factor is negative)
    got = effect_equivalents(q.effect, size, size - 0.5, size + 0.5, Design())
    assert len(got) == 1 and got[0]["parameter"] == f"design.{parameter}"
    assert got[0]["value"] == pytest.approx(value, rel=1e-12)
    assert got[0]["ci_low"] < value < got[0]["ci_high"]
    # a declared modification is the base of the implied design value
    base = Design.from_dict({parameter: 0.01})
    assert effect_equivalents(q.effect, size, size, size, base)[0]["implied_design_value"] == pytest.approx(0.01 + value)
    assert effect_equivalents("pin_radius[pin=3]", size, size, size, Design()) == []     # one pin is no modification


def test_a_group_member_with_a_physical_twin_carries_it():
    """A group the data cannot split (a friction torque and all the pins' radius): the pin radius member carries its
    modification, the friction torque none, an unbounded member none."""
    res = {"effects": [], "nuisance": [], "groups": [{"kind": "physical", "members": [
        {"name": "friction_torque_Nm", "value": 23.9, "unit": "N m"}, {"name": "pin_radius", "value": -4.0, "unit": "um"},
        {"name": "pin_circle_diameter", "value": "unbounded", "unit": "um"}]}]}
    fr, pr, unb = result_equivalents(res, Design())["groups"][0]
    assert fr == [] and unb == []
    (q,) = pr
    assert q["parameter"] == "design.profile_equidistant_mm" and q["value"] == pytest.approx(0.004, rel=1e-12)


@pytest.mark.parametrize("design", [{}, {"z_sun": 18, "z_planet": 36}])
def test_a_constant_offset_reads_as_the_profile_rotation_that_shifts_the_te_by_it(design):
    """``rotation_per_offset_deg`` from the closed form ``-delta Zc/(Zc + 1 + Z1/Z2)``: the rotation it gives for
    an offset of 12 arcsec shifts rvdyn's TE by 12 arcsec at every step (ratio 121 and ratio 81 designs)."""
    des = Design.from_dict(design)
    delta = 12.0 * rotation_per_offset_deg(des)
    for load in (0.0, 20.0):
        shift = _te({"design": dict(design, profile_rotation_deg=delta)}, load, 1) - _te({"design": design}, load, 1)
        assert np.abs(shift - 12.0).max() < 1e-3
