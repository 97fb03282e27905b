"""Linear stand-ins of the loop's reducer model for fast tests.

* :class:`FrozenModel` (:func:`frozen_model`): the real model's TE and Jacobian at the declared state, frozen
  (``te(theta) = te0 + J theta``), for tests of the loop's machinery: a test costs one linearisation of rvdyn.
* :class:`LinearReducer`: TE = declared + J theta over the model options only, J from rvdyn at the declared state
  (exact for the torsional compliance, which rvdyn adds as a wind-up -d C L), for tests of what surrounds the loop
  (the command, the report, the prediction of left-out loads).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from rvcalib.datasheet import reducer_case
from rvcalib.holdout import declared_te, model_te
from rvcalib.library import CaseDelta, build_library
from rvcalib.loop import resolved_order
from rvcalib.readings import nuisance_columns, ramp_shown
from rvcalib.reducer_model import ReducerModel
from rvrig.dataset import noise_estimate


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

    def statistical_jacobian(self, theta, pool=None) -> np.ndarray:
        return self.J            # linear: every secant is the column

    def case_dict(self, group, theta) -> dict:
        return dict(group.base)

    def column_kinds(self) -> np.ndarray:
        return self._kinds


def frozen_model(dataset, families=None, cache=None) -> FrozenModel:
    """The stand-in for ``dataset``: its library's solved candidates (dense first, as the loop orders them), the
    real model's TE and Jacobian at the declared state (pin columns: secants over the prior scale). ``cache``: an
    npz file holding ``te0`` and ``J`` of an earlier call on the same readings (used when the shapes fit; written
    when absent)."""
    from rvcalib.settings import CalibrationSettings

    s = CalibrationSettings() if families is None else CalibrationSettings(families=families)
    lib = build_library(dataset, resolved_order(dataset), s.families, ramp_shown(dataset)[0])
    solved = [c for c in lib if c.solved and c.dense] + [c for c in lib if c.solved and not c.dense]
    m = ReducerModel(dataset, solved)
    n = sum(r.n for r in dataset.runs)
    if cache is not None and cache.is_file():
        got = np.load(cache)
        if got["J"].shape == (n, m.n_params):
            return FrozenModel(m, got["te0"], got["J"])
    theta = np.zeros(m.n_params)
    te0 = m.te(theta)
    out = FrozenModel(m, te0, m.jacobian(theta))
    if cache is not None:
        np.savez(cache, te0=te0, J=out.J)
    return out


def with_te(ds, te: np.ndarray):
    """The dataset with its TE readings replaced by ``te`` (arcsec, the runs' readings end to end; the input
    readings kept)."""
    runs, pos = [], 0
    for r in ds.runs:
        t = te[pos:pos + r.n]
        pos += r.n
        runs.append(dataclasses.replace(r, output_deg=r.input_deg / r.ratio + t / 3600.0,
                                        noise_arcsec=noise_estimate(t)))
    return dataclasses.replace(ds, runs=runs)


def rig_data(ds, te: np.ndarray, noise: float, seed: int):
    """The dataset as a rig would record the TE ``te`` (arcsec): each test's zero ``normal(0, 30)`` arcsec, then
    white noise of ``noise`` arcsec, both from ``numpy.random.default_rng(seed)`` in that order."""
    rng = np.random.default_rng(seed)
    N, _ = nuisance_columns(ds)
    return with_te(ds, te + N @ rng.normal(0.0, 30.0, N.shape[1]) + rng.normal(0.0, noise, N.shape[0]))


#: Families whose solved candidates are model options only (what the stand-in can give a column).
FAMILIES = ("model", "measurement", "empirical")


def _options(cand, p: np.ndarray) -> dict:
    """The model options of a model candidate at parameters ``p``."""
    acc = CaseDelta()
    cand.add_to(acc, p)
    return acc.model


class LinearReducer:
    """The loop's forward model (``rvcalib.loop.calibrate(model=...)``) as a fixed linear map."""

    def __init__(self, dataset, settings) -> None:
        lib = build_library(dataset, settings.max_order or resolved_order(dataset), settings.families,
                            ramp_shown(dataset)[0])
        self.candidates = ([c for c in lib if c.solved and c.dense] + [c for c in lib if c.solved and not c.dense])
        assert all(c.family == "model" for c in self.candidates), [c.name for c in self.candidates]
        self.n_params = sum(c.n_params for c in self.candidates)
        self.base_case = reducer_case(dataset.runs[0].case_dict())
        self.base = np.concatenate(declared_te(dataset))
        cols = []
        for c in self.candidates:
            for j in range(c.n_params):
                opts = _options(c, c.prior_scale * np.eye(c.n_params)[j])
                te = model_te(dataset, lambda r, o=opts: self._case(o, r))
                cols.append((np.concatenate(te) - self.base) / c.prior_scale)
        self.J = np.column_stack(cols)
        self._lower = np.concatenate([[c.lower] * c.n_params for c in self.candidates])
        self._upper = np.concatenate([[c.upper] * c.n_params for c in self.candidates])
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

    def statistical_jacobian(self, theta, pool=None) -> np.ndarray:
        return self.J.copy()     # linear: every secant is the column

    def case_dict(self, group, theta: np.ndarray) -> dict:
        t = np.clip(theta, self._lower, self._upper)
        acc, pos = CaseDelta(), 0
        for c in self.candidates:
            c.add_to(acc, t[pos:pos + c.n_params])
            pos += c.n_params
        return self._case(acc.model)

    def column_kinds(self) -> np.ndarray:
        return np.array(["derivative"] * self.n_params)
