"""rvcalib: a member whose size ends at a bound of its range gets a one-sided interval, not a linearised one.

Realistic seed 7 (stop 33, ``benchmarks/bench_calibrate.py --realistic 1 --seed 7``) ended with
``pin_circle_diameter[pin=29]`` at +200 um, the top of its range, reported as 200 um with the interval
[-29613, 30013]: pin 29 is out of contact at any size above a few micrometres, the residual does not depend on
the size there, so the Jacobian's column is zero and the standard error (15197 um) says nothing. The interval
is now the profiled region from the bound down to where the residual starts to rise (>= 3.1 um on that state).

* :func:`rvcalib.lsq.profile_limit` on a hinge (a column that saturates at a known size beside a linear one): the
  limit against the closed form ``c - sqrt(drss / |s_perp|^2)``, errs wide by at most the geometric bisection's
  last ratio; None
  when the region reaches past the scan's end; an unevaluable point counts as outside.
* Through the full model: a pin moved out of contact (pin 5 at +30 um, the simulator at 200 readings per output
  revolution from 0.37 deg, its own noise, beside a compliance), the member fitted from the top of its range: it
  stays there, ``at_bound`` is ``"upper"``, the interval runs from a limit between 0 and the truth to the bound,
  and the note says so; an interval widened past the range (the final-state groups' linear widenings took seed
  7's to 291.8 um) is clipped back to it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvcalib.dataset import read_dataset
from rvcalib.effects import Library, build_library
from rvcalib.forward import ModelEvaluationError
from rvcalib.identify import Calibrator
from rvcalib.lsq import profile_limit
from rvcalib.results import Active
from rvcalib.simulate import simulate_dataset

COMPLIANCE = "torsional_compliance_arcsec_per_Nm"
PIN = "pin_circle_diameter[pin=5]"


def _hinge(c: float = 2.0, n: int = 400, seed: int = 3):
    """A residual function of two scaled parameters: ``y - s min(x0, c) - w x1`` with y made at x0 = 5 (beyond
    the hinge), x1 = 0.7 and noise 0.01; returns (fun, the least-squares solution at x0 = 10, its Jacobian)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n)
    s, w = np.sin(7.0 * t) + 0.3, t
    y = s * min(5.0, c) + 0.7 * w + 0.01 * rng.standard_normal(n)

    def fun(x):
        return y - s * min(float(x[0]), c) - w * float(x[1])

    x1 = float(np.linalg.lstsq(w[:, None], y - s * c, rcond=None)[0][0])
    x = np.array([10.0, x1])
    J = np.column_stack([np.zeros(n), -w])  # flat in x0 beyond the hinge
    return fun, x, J, s, w


def test_profile_limit_matches_the_hinge_closed_form():
    fun, x, J, s, w = _hinge()
    drss = 3.84 * 1e-4
    lim = profile_limit(fun, x, J, 0, 0.0, drss)
    s_perp = s - w * (w @ s) / (w @ w)
    exact = 2.0 - math.sqrt(drss / float(s_perp @ s_perp))
    ratio = 1e4 ** (1.0 / 2 ** 8)  # the geometric bracket's last ratio (distances from 0, floor 1e-4 of 10)
    assert exact <= lim <= exact * ratio, (lim, exact)
    # the linearised interval at the bound would be unbounded: the column is zero there
    assert not np.any(J[:, 0])


def test_profile_limit_none_when_the_region_reaches_the_end_and_errors_count_outside():
    fun, x, J, _, _ = _hinge()
    # a threshold so large that even x0 = 0 is inside: the region reaches past the scan's end
    assert profile_limit(fun, x, J, 0, 0.0, 1e6) is None

    def failing(xv):
        if xv[0] < 3.0:
            raise ModelEvaluationError("cannot evaluate")
        return fun(xv)
    # every point below 3 fails: the limit stays at or above 3 (inside), and the hinge's own rise is not reached
    lim = profile_limit(failing, x, J, 0, 0.0, 1e6)
    assert lim is not None and 3.0 <= lim <= 3.0 * 1e4 ** (1.0 / 2 ** 8)


@pytest.mark.usefixtures("calib_forward_cache")
def test_pin_out_of_contact_gets_a_one_sided_interval(tmp_path):
    root = tmp_path / "pin_out"
    simulate_dataset(root, [{"run": "fw", "load_Nm": 20.0, "direction": 1},
                           {"run": "bw", "load_Nm": 20.0, "direction": -1}],
                     {"errors": {"pin_circle_diameter": {"value": 30.0, "pin": 5}},
                      "model": {COMPLIANCE: 0.2}},
                     samples_per_rev=200, start_deg=0.37, seed=11, noise_arcsec=0.1)
    ds = read_dataset(root)
    lib = Library([e for e in build_library(ds) if e.name in (PIN, COMPLIANCE)])
    cal = Calibrator(ds, library=lib)
    eff = [lib.by_name(PIN), lib.by_name(COMPLIANCE)]
    top = float(eff[0].upper[0])
    params, *_ = cal.fit_full(eff, [np.array([top]), np.array([0.1])], [])
    assert params[0][0] == pytest.approx(top), "flat beyond contact: the fit stays at the bound"
    cal.active = [Active(e, p, 1) for e, p in zip(eff, params)]
    r, cal.emp_coef = cal.full_residual([(a.effect, a.p) for a in cal.active], [])
    cal.rss_full = float(r @ r)
    fitted = {f.name: f for f in cal.intervals()}
    pin = fitted[PIN]
    assert pin.at_bound == "upper" and pin.value == pytest.approx(top)
    assert pin.ci_high == pytest.approx(top)
    assert 0.0 < pin.ci_low < 30.0, pin.ci_low  # the truth (30 um) inside; a pin in contact (0) outside
    assert pin.std_err > 100.0, "the linearised standard error means nothing at the bound"
    assert pin.to_dict()["at_bound"] == "upper"
    assert pin.size_text() == f"{PIN} >= {pin.ci_low:.4g} um (at its upper bound {top:.4g})"
    # the final-state groups may widen intervals linearly; none leaves the effect's range
    pin.ci_high = top + 91.8
    cal.clip_to_ranges([pin])
    assert pin.ci_high == top
    comp = fitted[COMPLIANCE]
    assert comp.at_bound is None and comp.ci_low <= 0.2 <= comp.ci_high
    assert any(n.startswith(f"{PIN} ended at the upper bound") and ">=" in n for n in cal.notes), cal.notes
