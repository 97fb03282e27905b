"""A linear stand-in of the reducer model for tests of the loop's machinery: the real model's TE and Jacobian at
the declared state, frozen (``te(theta) = te0 + J theta``), so a loop test costs one linearisation of rvdyn."""
from __future__ import annotations

import numpy as np

from rvcalib.library import build_library
from rvcalib.loop import resolved_order
from rvcalib.readings import ramp_shown
from rvcalib.reducer_model import ReducerModel


class FrozenModel:
    """The forward-model interface of :func:`rvcalib.loop.calibrate` with a fixed linear response."""

    def __init__(self, model: ReducerModel, te0: np.ndarray, J: np.ndarray) -> None:
        self.candidates = model.candidates
        self.n_params = model.n_params
        self.groups = model.groups
        self._lower, self._upper = model._lower, model._upper
        self._kinds = model.column_kinds()
        self.te0, self.J = te0, J
        self.solves = 0

    def te(self, theta: np.ndarray) -> np.ndarray:
        self.solves += 1
        return self.te0 + self.J @ theta

    def jacobian(self, theta, spread=None, renew=None, pool=None) -> np.ndarray:
        return self.J

    def case_dict(self, group, theta) -> dict:
        return dict(group.base)

    def column_kinds(self) -> np.ndarray:
        return self._kinds


def frozen_model(dataset, families=None) -> FrozenModel:
    """The stand-in for ``dataset``: its library's solved candidates (dense first, as the loop orders them), the
    real model's TE and Jacobian at the declared state (pin columns: secants over the prior scale)."""
    from rvcalib.settings import CalibrationSettings

    s = CalibrationSettings() if families is None else CalibrationSettings(families=families)
    lib = build_library(dataset, resolved_order(dataset), s.families, ramp_shown(dataset)[0])
    solved = [c for c in lib if c.solved and c.dense] + [c for c in lib if c.solved and not c.dense]
    m = ReducerModel(dataset, solved)
    theta = np.zeros(m.n_params)
    te0 = m.te(theta)
    return FrozenModel(m, te0, m.jacobian(theta))
