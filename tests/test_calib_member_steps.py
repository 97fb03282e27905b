"""rvcalib: a member's linearisation column when rvdyn cannot evaluate its forward step.

Realistic seed 8 with the small screening trials (stop 34) stopped with a traceback: the loop's linearisation of
the model at a state (``JointSelection.active_members``) solves each member a step of 0.3 of its scale away, and
that step made an interference of 108.6 um, which rvdyn refuses (ModelEvaluationError). The step now goes the
other way (as at a bound), then a tenth of it either way; where none can be evaluated (seed 8's cam phase at a
state at the edge of what rvdyn accepts: every step, even 0.3 um, made more than 100 um of interference) the
column is zero and the log says so, and the checks through rvdyn decide about the member.
A stub model (no rvdyn): the TE on the grid is 3 times the member's size where it can be evaluated.
"""
from __future__ import annotations

import numpy as np
import pytest

from rvcalib.dataset import read_dataset
from rvcalib.forward import ModelEvaluationError
from rvcalib.identify import Calibrator
from rvcalib.results import Active
from rvcalib.simulate import simulate_dataset

MEMBER = "pin_circle_diameter"


@pytest.fixture(scope="module")
def cal(tmp_path_factory):
    root = tmp_path_factory.mktemp("member_steps") / "d"
    simulate_dataset(root, [{"run": "fw", "load_Nm": 20.0, "direction": 1}], {}, samples_per_rev=120,
                     start_deg=0.37, seed=4, noise_arcsec=0.1)
    return Calibrator(read_dataset(root))


def _stub(cal, refuse):
    """``_grid_cat`` of a stub model: 3 x the member's size at every grid point, refused where ``refuse(size)``."""
    n = sum(1 for _ in cal.runs) * cal.m

    def grid_cat(pairs, sensitivity=False):
        v = sum(float(p[0]) for e, p in pairs if e.name == MEMBER)
        if refuse(v):
            raise ModelEvaluationError(f"interference at {MEMBER} = {v}")
        return np.full(n, 3.0 * v)
    return grid_cat


def test_forward_step_refused_backward_taken(cal, monkeypatch):
    e = cal.lib.by_name(MEMBER)
    cal.active = [Active(e, np.array([0.0]), 1)]  # size zero: the column comes from a step, not the secant
    monkeypatch.setattr(cal, "_grid_cat", _stub(cal, lambda v: v > 0.0))
    (m,) = cal.active_members()
    assert m.cols.shape[1] == 1 and np.allclose(m.cols[:, 0], 3.0)


def test_every_step_refused_gives_a_zero_column_and_says_so(cal, monkeypatch):
    e = cal.lib.by_name(MEMBER)
    cal.active = [Active(e, np.array([0.0]), 1)]
    monkeypatch.setattr(cal, "_grid_cat", _stub(cal, lambda v: v != 0.0))
    said = []
    monkeypatch.setattr(cal, "log", said.append)
    (m,) = cal.active_members()
    assert m.cols.shape[1] == 1 and not np.any(m.cols) and not np.any(m.contribution)
    assert any(s.startswith(f"no step of {MEMBER} at the state can be evaluated") and "interference at" in s
               for s in said), said
