"""A linear stand-in for the loop's reducer model, for fast tests of what surrounds the loop (the command, the
report, the prediction of left-out loads): TE = declared + J theta, with J the model options' columns from rvdyn at
the declared state (exact for the torsional compliance, which rvdyn adds as a wind-up -d C L)."""
from __future__ import annotations

import numpy as np

from rvcalib import forward
from rvcalib.datasheet import reducer_case
from rvcalib.holdout import declared_te, model_te
from rvcalib.library import build_library
from rvcalib.loop import resolved_order
from rvcalib.readings import ramp_shown
from rvcalib.simulate import simulate_dataset
from rvdyn.runner import Runner

#: Families whose solved candidates are model options only (what the stand-in can give a column).
FAMILIES = ("model", "measurement", "empirical")


class LinearReducer:
    """The loop's forward model (``rvcalib.loop.calibrate(model=...)``) as a fixed linear map."""

    def __init__(self, dataset, settings) -> None:
        lib = build_library(dataset, settings.max_order or resolved_order(dataset), settings.families,
                            ramp_shown(dataset)[0])
        self.candidates = ([c for c in lib if c.solved and c.dense] + [c for c in lib if c.solved and not c.dense])
        assert all(c.family == "model" for c in self.candidates), [c.name for c in self.candidates]
        self.n_params = len(self.candidates)
        self.base_case = reducer_case(dataset.runs[0].case_dict())
        self.base = np.concatenate(declared_te(dataset))
        cols = []
        for c in self.candidates:
            h = c.prior_scale
            te = model_te(dataset, lambda r, c=c, h=h: self._case({c.key: h}, r))
            cols.append((np.concatenate(te) - self.base) / h)
        self.J = np.column_stack(cols)
        self._lower = np.array([c.lower for c in self.candidates])
        self._upper = np.array([c.upper for c in self.candidates])
        self.groups = [self.base_case]
        self.solves = 0

    def _case(self, options: dict, run=None) -> dict:
        case = reducer_case(run.case_dict()) if run is not None else dict(self.base_case)
        case["model"] = {**(case.get("model") or {}), **options}
        return case

    def te(self, theta: np.ndarray) -> np.ndarray:
        self.solves += 1
        return self.base + self.J @ np.clip(theta, self._lower, self._upper)

    def jacobian(self, theta, spread=None, renew=None, pool=None) -> np.ndarray:
        return self.J.copy()

    def case_dict(self, group, theta: np.ndarray) -> dict:
        t = np.clip(theta, self._lower, self._upper)
        return self._case({c.key: float(x) for c, x in zip(self.candidates, t)})

    def column_kinds(self) -> np.ndarray:
        return np.array(["derivative"] * self.n_params)


def simulate_own_law(*args, **kwargs):
    """:func:`rvcalib.simulate.simulate_dataset` with each case's own contact law (rvdyn's default, the physical
    law), the law the loop's reducer model, the stand-in and the predictions solve with; the session's forward
    runner (tests/conftest.py ``calib_forward_cache``) may hold another."""
    prev = forward.use_runner(Runner(solver="analytic", memory_bytes=forward.CACHE_BYTES))
    try:
        return simulate_dataset(*args, **kwargs)
    finally:
        forward.use_runner(prev)
