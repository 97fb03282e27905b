"""rvcalib: identifiability groups with sizes, honest intervals and recommended runs (issue 10 item 2).

Small datasets made by the simulator at another step count than the loop's screening grid (200
readings per output revolution from input angle 0.37 deg: every reading off the 280-point grid),
with several effects at once and output encoder noise 0.1 arcsec. The loop's search is not run:
the model state is the one the loop would end in (the effects fitted jointly through the full
nonlinear model from sizes away from the truth), so that each test checks the final-state analysis
(:meth:`rvcalib.groups.Groups.final_state_groups`) and the run recommendation
(:meth:`rvcalib.groups.Groups.recommend_runs`) in seconds.

* One load (20 N m, both directions): a torsional compliance gives a direction-signed offset
  proportional to the load, and so does a pin radius error of all pins (lost motion): from one
  load the data cannot tell them apart, so the compliance must not be named; the group gives both
  sizes and the RMS each leaves. The D-optimal recommendation must pick another load, and adding
  that run to the data (simulated) must split them: the compliance is then named with a narrow
  interval that covers the truth.
* An error the model leaves out (a pin radius of 0.6 um beside a cam eccentricity and a compliance,
  10 and 30 N m): the plain interval of the compliance (white noise, the state's Jacobian) misses
  the truth; the interval profiled over the library's candidates covers it and says which
  candidate widened it.
"""
from __future__ import annotations

import numpy as np
import pytest

from rvcalib.dataset import read_dataset
from rvcalib.effects import Library, build_library
from rvcalib.identify import Calibrator
from rvcalib.results import Active
from rvcalib.simulate import simulate_dataset

pytestmark = pytest.mark.usefixtures("calib_forward_cache")  # solves shared by the session

COMPLIANCE = "torsional_compliance_arcsec_per_Nm"
CAM = "cam_eccentricity[crank=0,disc=0]"
NAMES = (CAM, "pin_radius", COMPLIANCE)
TRUTH = {"errors": {"cam_eccentricity": 4.0}, "model": {COMPLIANCE: 0.2}}
SIM = dict(samples_per_rev=200, start_deg=0.37, seed=5, noise_arcsec=0.1)


def runs(loads, extra=None) -> list[dict]:
    out = [{"run": f"{'fw' if d > 0 else 'bw'}{L:g}", "load_Nm": float(L), "direction": d}
           for L, d in loads]
    if extra is not None:
        out.append({"run": "extra", "load_Nm": float(extra["load_Nm"]), "direction": int(extra["direction"])})
    return out


def final_state(root, run_list, hidden) -> Calibrator:
    """The loop's final state on a simulated dataset: the cam eccentricity and the compliance fitted
    jointly through the full model (from 1 um and 0.1 arcsec/(N m)); the library restricted to them
    and the pin radius of all pins (to keep the test in seconds)."""
    simulate_dataset(root, run_list, hidden, **SIM)
    ds = read_dataset(root)
    lib = Library([e for e in build_library(ds) if e.name in NAMES])
    cal = Calibrator(ds, library=lib)
    cal.screening_signatures()
    eff = [lib.by_name(CAM), lib.by_name(COMPLIANCE)]
    params, *_ = cal.fit_full(eff, [np.array([1.0]), np.array([0.1])], [])
    cal.active = [Active(e, p, 1) for e, p in zip(eff, params)]
    r, cal.emp_coef = cal.full_residual([(a.effect, a.p) for a in cal.active], [])
    cal.rss_full = float(r @ r)
    return cal


@pytest.fixture(scope="module")
def one_load(tmp_path_factory):
    cal = final_state(tmp_path_factory.mktemp("groups") / "one_load", runs([(20, 1), (20, -1)]), TRUTH)
    fitted = cal.intervals()
    kept, groups = cal.final_state_groups(fitted)
    return cal, kept, groups


def test_one_load_leaves_compliance_and_pin_radius_in_a_group_with_sizes(one_load):
    cal, kept, groups = one_load
    names = {f.name for f in kept}
    assert COMPLIANCE not in names, "a compliance from one load must not be named"
    cam = next(f for f in kept if f.name == CAM)
    assert cam.ci_low <= 4.0 <= cam.ci_high and abs(cam.value - 4.0) < 0.1
    g = next(g for g in groups if g["kind"] == "unsplit" and g["found"] == COMPLIANCE)
    sizes = {m["name"]: m for m in g["members"]}
    assert set(sizes) >= {COMPLIANCE, "pin_radius"}, sorted(sizes)
    assert sizes[COMPLIANCE]["value"] == pytest.approx(0.2, rel=0.02) and sizes[COMPLIANCE]["found"]
    # the pin radius needs its own size and sign (a smaller radius: more lost motion), not 0
    pr = sizes["pin_radius"]
    assert pr["unit"] == "um" and pr["value"] < -0.1 and not pr["found"]
    rms_model = np.sqrt(cal.rss_full / cal.n)
    for m in g["members"]:
        assert rms_model <= m["rms_after_arcsec"] + 1e-12
        assert m["rms_after_arcsec"] <= rms_model * 1.02, m  # each fits as well, within the noise


def test_recommended_run_splits_the_group(one_load, tmp_path):
    cal, _, groups = one_load
    recs = cal.recommend_runs(groups)
    rec = next(r for r in recs if COMPLIANCE in r["members"])
    assert rec["run"] is not None and rec["run"]["load_Nm"] != 20.0, rec
    assert rec["log_det_gain"] > np.log(2.0)
    # the run it recommends, made and added: the compliance is split from the pin radius
    cal2 = final_state(tmp_path / "with_extra", runs([(20, 1), (20, -1)], rec["run"]), TRUTH)
    kept, groups2 = cal2.final_state_groups(cal2.intervals())
    comp = next((f for f in kept if f.name == COMPLIANCE), None)
    assert comp is not None, groups2
    assert comp.ci_low <= 0.2 <= comp.ci_high
    assert comp.ci_high - comp.ci_low < 0.02
    assert not any(COMPLIANCE in [m["name"] for m in g["members"]] for g in groups2)


def test_interval_covers_the_truth_when_an_error_is_left_out(tmp_path):
    hidden = {"errors": {"cam_eccentricity": 4.0, "pin_radius": 0.6}, "model": {COMPLIANCE: 0.2}}
    cal = final_state(tmp_path / "left_out", runs([(10, 1), (30, -1)]), hidden)
    fitted = cal.intervals()
    plain = {f.name: (f.ci_low, f.ci_high) for f in fitted}
    lo, hi = plain[COMPLIANCE]
    assert not lo <= 0.2 <= hi, "the plain interval (white noise at the state) misses the truth here"
    kept, _ = cal.final_state_groups(fitted)
    comp = next(f for f in kept if f.name == COMPLIANCE)
    assert comp.ci_low <= 0.2 <= comp.ci_high
    assert comp.ci_low <= lo and comp.ci_high >= hi  # widened, never narrowed
    assert comp.selection["interval_widened_by"] == "pin_radius"


def test_a_member_the_other_fit_holds_near_zero_is_not_named(one_load, monkeypatch):
    """A member of a ``two_fits`` group whose size in the other fit is within its interval's half-width of zero
    (``named`` false, rvcalib.basins) leaves ``effects`` as a member of an ``unsplit`` group does; the other
    effects stay named."""
    cal, _, _ = one_load
    seen = {}

    def basin_groups(by_name, rms_model):
        seen.update(by_name)
        return [{"kind": "two_fits", "found": CAM, "rms_other_fit_arcsec": rms_model,
                 "members": [{"name": CAM, "key": "cam_eccentricity", "value": by_name[CAM].value, "unit": "um",
                              "rms_after_arcsec": rms_model, "found": True, "value_other_fit": 0.0,
                              "named": False}], "note": "stub"}]

    monkeypatch.setattr(cal, "basin_groups", basin_groups)
    kept, groups = cal.final_state_groups(cal.intervals())
    assert CAM in seen
    assert CAM not in {f.name for f in kept}
    assert any(g["kind"] == "two_fits" and g["found"] == CAM for g in groups)
