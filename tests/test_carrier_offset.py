"""The carrier's offset from its axis of rotation (model options ``carrier_offset_x_um``/``_y_um``: the main
bearings' radial runout relative to the crank holes): where it moves the parts, what it does to the TE, and its
candidate in the calibration library."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from rvcad.check import check_case
from rvcad.errors import Case, CaseError
from rvcad.validation import DesignError
from rvcad.geometry import ReducerGeometry
from rvcad.tolerances import TOL
from rvcad.params import Design
from rvcalib.library import Candidate, CaseDelta, PRIOR_SCALES, build_library
from rvcalib.simulate import expected_effects
from rvdyn.solver import ARCSEC_PER_RAD
from rvdyn.te import run_te

#: Two solves, each converged to the solver's angle tolerance, agree within this, arcsec.
RESOLUTION = 2.0 * TOL.solver_angle_rad * ARCSEC_PER_RAD
IMPACT = {"contact": "impact"}


def _te(d: dict, theta_in_deg=None, steps: int = 45) -> np.ndarray:
    # one angle, solved with a second 0.001 deg on (a solve takes two or more angles)
    kw = {"theta_in_deg": [theta_in_deg, theta_in_deg + 1e-3]} if theta_in_deg is not None else {"steps": steps}
    return run_te(Case.from_dict(d), **kw).table["te_arcsec"].to_numpy()


def test_the_offset_moves_every_crank_hole_by_the_same_vector_in_the_carrier_frame():
    nominal = ReducerGeometry(Case.from_dict({}))
    moved = ReducerGeometry(Case.from_dict({"model": {"carrier_offset_x_um": 4.0, "carrier_offset_y_um": -3.0}}))
    assert np.allclose(moved.carrier_holes - nominal.carrier_holes, [[4e-3, -3e-3]] * 2, rtol=0, atol=1e-13)  # mm, rounding at 30 mm
    assert np.array_equal(moved.pin_centers, nominal.pin_centers)


def test_along_the_crank_line_it_is_the_two_carrier_holes_moved_radially_apart():
    """Cranks at 0 and 180 deg: an offset of c along x is crank 0's hole out by c and crank 1's in by c."""
    offset = {"model": {**IMPACT, "carrier_offset_x_um": 6.0}, "load_Nm": 20.0}
    holes = {"model": IMPACT, "load_Nm": 20.0,
             "errors": {"carrier_hole_eccentricity": [{"value": 6.0, "crank": 0}, {"value": -6.0, "crank": 1}]}}
    te, nominal = _te(offset), _te({"model": IMPACT, "load_Nm": 20.0})
    assert np.sqrt(np.mean((te - nominal) ** 2)) > 1.0                  # the offset shows
    assert np.abs(te - _te(holes)).max() < RESOLUTION


@pytest.mark.parametrize("theta_in_deg", [0.0, 1234.5])
def test_the_whole_reducer_moved_together_keeps_its_te(theta_in_deg):
    """The pin ring (fixed frame), the carrier's holes (carrier frame) and the sun (sun frame) moved by the same
    vector in the fixed frame at one input angle: the reducer is translated, so its TE there is the nominal's."""
    c, ang = 8.0, 35.0                                  # um, deg in the fixed frame
    nominal = _te({"model": IMPACT, "load_Nm": 20.0}, theta_in_deg)
    theta_out = math.radians(theta_in_deg) / ReducerGeometry(Case.from_dict({})).ratio - nominal[0] / ARCSEC_PER_RAD
    a_carrier = math.radians(ang) - theta_out
    case = {"model": {**IMPACT, "carrier_offset_x_um": c * math.cos(a_carrier),
                      "carrier_offset_y_um": c * math.sin(a_carrier)}, "load_Nm": 20.0,
            "errors": {"pin_circle_offset": {"value": c, "angle_deg": ang},
                       "sun_eccentricity": {"value": c, "angle_deg": (ang - theta_in_deg) % 360.0}}}
    ring = _te({"model": IMPACT, "load_Nm": 20.0, "errors": {"pin_circle_offset": case["errors"]["pin_circle_offset"]}},
               theta_in_deg)
    carrier = _te({"model": case["model"], "load_Nm": 20.0}, theta_in_deg)
    assert min(abs(ring[0] - nominal[0]), abs(carrier[0] - nominal[0])) > 1.0     # the ring or carrier alone shows
    assert _te(case, theta_in_deg)[0] == pytest.approx(nominal[0], abs=RESOLUTION)


def test_it_gives_a_constant_and_the_pin_orders_only():
    """Turning with the carrier, the offset is fixed relative to the cranks: it changes how the cranks share the
    load (a constant) and the mesh with the fixed ring (the orders of the pins), no low order. Under the impact law
    the response of the two-crank reducer is even in the offset (the offset reversed is the reducer turned half a
    turn)."""
    steps = 160
    plus, minus = (_te({"model": {**IMPACT, "carrier_offset_y_um": c}, "load_Nm": 20.0}, steps=steps)
                   for c in (10.0, -10.0))
    assert np.abs(plus - minus).max() < RESOLUTION
    d = plus - _te({"model": IMPACT, "load_Nm": 20.0}, steps=steps)
    amp = np.abs(np.fft.rfft(d)) / steps * 2.0
    zp = ReducerGeometry(Case.from_dict({})).design.z_pins
    assert abs(d.mean()) > 1.0
    assert max(amp[1:zp // 2]) < 0.01 * abs(d.mean())


def test_under_the_physical_law_its_pin_order_turns_with_the_offset():
    """Three cranks, elastic supports: the discs float, and the offset moves them against the ring at first
    order: the TE's order Zp changes sign with the offset and turns by 90 deg with it, up to the second-order part
    (the constant, even in the offset, a few percent of it at 3 um)."""
    steps, design = 96, {"crank_angles_deg": [0.0, 120.0, 240.0]}
    zp = ReducerGeometry(Case.from_dict({"design": design})).design.z_pins

    def order_zp(model: dict) -> complex:
        d = _te({"design": design, "model": model, "load_Nm": 20.0}, steps=steps) - \
            _te({"design": design, "load_Nm": 20.0}, steps=steps)
        return complex(np.fft.rfft(d)[zp]) / steps * 2.0

    x, minus_x, y = (order_zp(m) for m in ({"carrier_offset_x_um": 3.0}, {"carrier_offset_x_um": -3.0},
                                          {"carrier_offset_y_um": 3.0}))
    assert abs(x) > 1.0                                                 # arcsec for 3 um
    assert abs(minus_x + x) < 0.05 * abs(x)
    assert abs(y - 1j * x) < 0.05 * abs(x)


def test_a_bad_offset_names_the_option_and_its_range():
    with pytest.raises((ValueError, CaseError), match=r"model.carrier_offset_y_um 250.0 um is out of range; "
                                                       r"allowed \[-200.0, 200.0\]"):
        ReducerGeometry(Case.from_dict({"model": {"carrier_offset_y_um": 250.0}}))


def _library_offset(design: Design) -> Candidate:
    dataset = SimpleNamespace(design=design, runs=[SimpleNamespace(load_Nm=10.0, direction=1)], declared_keys=(),
                              temperatures_vary=False)
    return build_library(dataset, max_order=1, families=("model",)).by_name("carrier_offset")


def _holes_moved(design: Design, delta: dict) -> np.ndarray:
    """The crank holes' moves (um, carrier frame) of a case delta on the design."""
    base = {"design": design.to_dict()}
    return (ReducerGeometry(Case.from_dict({**delta, **base})).carrier_holes
            - ReducerGeometry(Case.from_dict(base)).carrier_holes) * 1e3


@pytest.mark.parametrize("angles, n_params", [((0.0, 180.0), 1), ((0.0, 120.0, 240.0), 2)])
def test_the_library_candidate_moves_the_holes_tangentially_only(angles, n_params):
    """The offset's radial part at each hole is that crank's carrier-hole eccentricity (Table 4 F), a candidate
    already: the library's offset holds only the tangential moves, and with two cranks only the axis across them."""
    design = Design(crank_angles_deg=angles)
    cand = _library_offset(design)
    assert cand.n_params == n_params
    b = np.radians(angles)
    for j in range(n_params):
        mv = _holes_moved(design, cand.deltas()[j])
        radial = mv[:, 0] * np.cos(b) + mv[:, 1] * np.sin(b)
        assert np.abs(radial).max() < 1e-9                          # um: rounding at 30 mm
        assert np.abs(mv[:, 1] * np.cos(b) - mv[:, 0] * np.sin(b)).max() > 0.5    # a unit offset moves them


@pytest.mark.parametrize("angles", [(0.0, 180.0), (0.0, 120.0, 240.0)])
def test_a_hidden_offset_is_expected_as_the_library_holds_it(angles):
    """The simulator's answer for a hidden offset, put back through the library's candidates, moves the holes as
    the offset does."""
    design = Design(crank_angles_deg=angles)
    hidden = {"model": {"carrier_offset_x_um": 4.0, "carrier_offset_y_um": -3.0},
              "errors": {"carrier_hole_eccentricity": {"value": 1.5, "crank": 1}}}
    expected = {e["name"]: e for e in expected_effects(hidden, design)}
    acc = CaseDelta()
    for e in expected.values():
        if e["key"] == "carrier_hole_eccentricity":
            acc.items.append((e["key"], {"value": e["value"], **e["instance"]}))
    cand = _library_offset(design)
    e = expected["carrier_offset"]
    a = math.radians(e.get("angle_deg", 0.0))
    cand.add_to(acc, np.array([e["value"] * math.cos(a), e["value"] * math.sin(a)]) if cand.polar
                else np.array([e["value"]]))
    assert np.allclose(_holes_moved(design, acc.to_dict(None)), _holes_moved(design, hidden), rtol=0, atol=1e-9)
    if len(angles) == 2:
        assert expected["carrier_offset"]["value"] == pytest.approx(-3.0)
        assert expected["carrier_hole_eccentricity[crank=0]"]["value"] == pytest.approx(4.0)
        assert expected["carrier_hole_eccentricity[crank=1]"]["value"] == pytest.approx(1.5 - 4.0)


def test_the_library_candidate_writes_both_options_and_reports_a_size_and_direction():
    cand = _library_offset(Design(crank_angles_deg=(0.0, 120.0, 240.0)))
    acc = CaseDelta()
    cand.add_to(acc, np.array([1.5, -2.5]))
    assert acc.to_dict({"model": {"carrier_offset_x_um": 1.0}})["model"] == {"carrier_offset_x_um": 2.5,
                                                                              "carrier_offset_y_um": -2.5}
    assert cand.size(np.array([3.0, 4.0])) == pytest.approx((5.0, math.degrees(math.atan2(4.0, 3.0))))
    assert cand.prior_scale == PRIOR_SCALES["carrier_offset"]


@pytest.mark.parametrize("model", [{"carrier_offset_y_um": 150.0}, {"pin_circle_ovality_um": 150.0}])
def test_a_part_moving_option_that_makes_the_parts_overlap_is_named(model):
    """The design check blames the model option (not a design field) when removing it removes the overlap."""
    (key, value), = model.items()
    with pytest.raises(DesignError, match=rf"^model.{key} {value} makes the parts overlap"):
        check_case({"model": model, "errors": {"pin_pitch": {"value": 0.001, "pin": 3}}}, cache=False)
