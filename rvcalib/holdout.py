"""Does the calibration hold between loads? Each load left out of the fit in turn, fitted on the others, predicted.

For a dataset with two or more loads, :func:`holdout_loads` takes each load L in turn:

1. the runs of the other loads form a dataset of their own (:func:`subset`: the same reducer, notes and tests);
2. the loop (:func:`rvcalib.loop.calibrate`, the same settings) calibrates the reducer on it;
3. the calibrated reducer predicts the runs at L (:func:`predicted_te`): its case (``calibrated_case``: the
   declared errors of the runs fitted plus every effect estimated, at the left-out run's temperature) solved by
   rvdyn at the left-out runs' loads, directions and readings, plus the encoder effects the fit named (their
   reading columns, :mod:`rvcalib.readings`); the prediction adds the unexplained structure the fit reported
   (:func:`unexplained_te`: a term proportional to the load scaled to L), and "the reducer alone" leaves it out;
4. each left-out test's constant (the rig's zero, unknown for a test not fitted) is removed from the residual
   ``measured - predicted``, and its RMS is set against the noise of the left-out runs, beside the declared
   model's RMS there (the same constants removed) and the RMS the fit on every load leaves on the same runs.

A prediction whose RMS is near the noise says the effects found at the other loads explain this one; one far
above it says the left-out load shows something the fits at the other loads did not fix (a load dependence the
model lacks, or an effect the other loads did not show).

:func:`model_te` solves any case per run (the runs that share a case solved together, exactly at their readings'
input angles modulo one output revolution, rvdyn's analytic contacts); :func:`declared_te` is the declared model.
"""
from __future__ import annotations

import json
import math
import time
from typing import Any, Callable

import numpy as np

from rvcad.validation import one_line
from rvrig.dataset import MeasuredDataset, RunRecord
from rvcalib.datasheet import reducer_case
from rvcalib.library import Candidate
from rvcalib.readings import reading_columns
from rvcalib.reducer_model import _solve
from rvrig.testgroups import TestGroups

#: The RMS of a prediction within this factor of the noise counts as at the noise (as the result's status).
AT_NOISE = 1.2


def subset(dataset: MeasuredDataset, run_ids: list[str]) -> MeasuredDataset:
    """The dataset of the runs ``run_ids`` (in the dataset's order): the same reducer, notes and declared columns;
    its tests those of the runs kept (a test keeps its id)."""
    keep = set(run_ids)
    runs = [r for r in dataset.runs if r.run in keep]
    if not runs:
        raise ValueError(f"no run of {sorted(keep)} is in the dataset; runs are {[r.run for r in dataset.runs]}")
    of_run = {r.run: dataset.tests.of_run[r.run] for r in runs}
    ids = tuple(t for t in dataset.tests.ids if t in set(of_run.values()))
    return MeasuredDataset(path=dataset.path, runs=runs, notes=list(dataset.notes),
                           declared_keys=list(dataset.declared_keys), design=dataset.design,
                           design_source=dataset.design_source, tests=TestGroups(of_run, ids, dataset.tests.source))


def model_te(dataset: MeasuredDataset, case_of: Callable[[RunRecord], dict], law: Any = None) -> list[np.ndarray]:
    """TE (arcsec) of the case ``case_of(run)`` at every reading of each run; runs sharing a case solved at once.
    ModelEvaluationError when rvdyn cannot solve a case."""
    period = dataset.period_deg
    groups: dict[str, list[int]] = {}
    cases: dict[str, dict] = {}
    for i, r in enumerate(dataset.runs):
        case = case_of(r)
        key = json.dumps(case, sort_keys=True, default=float)
        groups.setdefault(key, []).append(i)
        cases[key] = case
    out: list[np.ndarray] = [np.zeros(0)] * len(dataset.runs)
    for key, idx in groups.items():
        runs = [dataset.runs[i] for i in idx]
        te, _ = _solve(cases[key], [(float(r.load_Nm), int(r.direction)) for r in runs],
                       [np.mod(r.input_deg, period) for r in runs], law)
        for i, t in zip(idx, te):
            out[i] = np.asarray(t, dtype=float)
    return out


def declared_te(dataset: MeasuredDataset, law: Any = None) -> list[np.ndarray]:
    """The declared model's TE (each run's declared errors, temperature, load and direction) at every reading."""
    return model_te(dataset, lambda r: reducer_case(r.case_dict()), law)


def _declared(run: RunRecord) -> dict:
    """What a run declares of the reducer, temperature aside (which each run keeps)."""
    c = reducer_case(run.case_dict())
    c.pop("model", None)
    return c


def unexplained_te(result, dataset: MeasuredDataset, largest_load_Nm: float) -> list[np.ndarray]:
    """The unexplained structure a fit reported, at the readings of ``dataset`` (arcsec per run): each term
    ``A cos(k theta_out - phase)`` (a constant ``A`` for order 0) times 1 (common), the direction, load / the fit's
    largest load (``largest_load_Nm``), or both (:mod:`rvcalib.readings`). A term without a size is left out."""
    out = [np.zeros(r.n) for r in dataset.runs]
    lmax = largest_load_Nm or 1.0
    for u in result.unexplained:
        a = u["amplitude_arcsec"]
        if not isinstance(a, (int, float)) or not math.isfinite(a):
            continue
        for i, r in enumerate(dataset.runs):
            f = {"common": 1.0, "load": r.load_Nm / lmax, "direction": float(r.direction),
                 "load_direction": r.direction * r.load_Nm / lmax}[u["kind"]]
            shape = (np.cos(u["order"] * r.output_rad - math.radians(u["phase_deg"] or 0.0)) if u["order"]
                     else np.ones(r.n))
            out[i] = out[i] + f * a * shape
    return out


def predicted_te(result, dataset: MeasuredDataset, law: Any = None) -> list[np.ndarray]:
    """The calibrated reducer's TE at every reading of the runs of ``dataset`` (module docstring, step 3): its case
    solved by rvdyn plus the encoder effects named (no unexplained structure)."""
    base = result.calibrated_case

    def case_of(r: RunRecord) -> dict:
        c = json.loads(json.dumps(reducer_case(base), default=float))
        if r.temperature_C is not None:
            c.setdefault("model", {})["temperature_C"] = r.temperature_C
        return c

    te = model_te(dataset, case_of, law)
    offs = np.cumsum([0] + [r.n for r in dataset.runs])
    for e in result.effects:
        if e.family != "measurement":
            continue
        col = reading_columns(Candidate(e.name, e.key, e.family, e.unit, e.meaning), dataset) @ np.asarray(e.components)
        te = [t + col[offs[i]:offs[i + 1]] for i, t in enumerate(te)]
    return te


def rms_without_constants(dataset: MeasuredDataset, residuals: list[np.ndarray]) -> float:
    """RMS (arcsec) of per-run residuals after removing each test's constant (its mean over the test's readings)."""
    by_test: dict[str, list[np.ndarray]] = {}
    for r, x in zip(dataset.runs, residuals):
        by_test.setdefault(r.test, []).append(np.asarray(x, dtype=float))
    sq, n = 0.0, 0
    for parts in by_test.values():
        x = np.concatenate(parts)
        sq += float(np.sum((x - x.mean()) ** 2))
        n += x.size
    return math.sqrt(sq / n)


def _row(dataset, load: float, settings, fit, law, full, declared, log) -> dict:
    """One left-out load: fit on the others, predict it (module docstring)."""
    out_ids = [r.run for r in dataset.runs if r.load_Nm == load]
    train = subset(dataset, [r.run for r in dataset.runs if r.load_Nm != load])
    held = subset(dataset, out_ids)
    idx = [i for i, r in enumerate(dataset.runs) if r.load_Nm == load]
    y = [r.te_arcsec for r in held.runs]
    row: dict = {"load_Nm": float(load), "runs": out_ids, "fitted_loads_Nm": sorted({r.load_Nm for r in train.runs}),
                 "noise_arcsec": held.noise_arcsec(), "rms_declared_arcsec": None, "rms_prediction_arcsec": None,
                 "rms_reducer_arcsec": None,
                 "rms_full_fit_arcsec": None, "prediction_over_noise": None, "named": [], "seconds": None,
                 "status": ""}
    if declared is not None:
        row["rms_declared_arcsec"] = rms_without_constants(held, [a - declared[i] for a, i in zip(y, idx)])
    if full is not None and len(full.residuals) == len(dataset.runs):
        row["rms_full_fit_arcsec"] = rms_without_constants(held, [full.residuals[i] for i in idx])
    if any(_declared(r) != _declared(train.runs[0]) for r in held.runs):
        row["status"] = ("not predicted: its runs declare other errors than the runs fitted, and the calibrated "
                         "case holds the declared errors of the runs fitted")
        return row
    t0 = time.perf_counter()
    try:
        res = fit(train, settings, log)
        pred = predicted_te(res, held, law)
    except (ValueError, ArithmeticError) as exc:        # a model rvdyn cannot solve, a loop that fails: said
        row["status"] = f"not predicted: {one_line(exc)}"
        return row
    row["seconds"] = time.perf_counter() - t0
    row["named"] = [e.name for e in res.effects]
    row["rms_reducer_arcsec"] = rms_without_constants(held, [a - p for a, p in zip(y, pred)])
    extra = unexplained_te(res, held, max(abs(r.load_Nm) for r in train.runs))
    rms = rms_without_constants(held, [a - p - u for a, p, u in zip(y, pred, extra)])
    row["rms_prediction_arcsec"] = rms
    row["prediction_over_noise"] = rms / row["noise_arcsec"] if row["noise_arcsec"] > 0 else None
    at = row["prediction_over_noise"] is not None and row["prediction_over_noise"] <= AT_NOISE
    row["status"] = (f"predicted at the noise (within {AT_NOISE:g} x)" if at else
                     f"predicted above the noise (more than {AT_NOISE:g} x)")
    return row


def holdout_loads(dataset: MeasuredDataset, settings=None, log: Callable[[str], None] | None = None, full=None,
                  declared: list[np.ndarray] | None = None, law: Any = None,
                  fit: Callable | None = None) -> dict:
    """The prediction of each load left out of the fit (module docstring).

    Parameters
    ----------
    dataset : MeasuredDataset
    settings : CalibrationSettings or None
        The settings of every fit (default: the defaults).
    log : callable or None
        Progress lines.
    full : CalibrationResult or None
        The fit on every load, for the RMS it leaves on each load's runs.
    declared : list of ndarray or None
        The declared model's TE per run (:func:`declared_te`), for its RMS on each load's runs.
    law : ContactLaw or None
        Contact law of the predictions (default: ``settings.contact``, else each case's).
    fit : callable or None
        ``fit(dataset, settings, log) -> CalibrationResult`` (default :func:`rvcalib.loop.calibrate`).

    Returns
    -------
    dict
        ``loads_Nm``, ``rows`` (per left-out load: ``load_Nm``, ``runs``, ``fitted_loads_Nm``, ``noise_arcsec``,
        ``rms_declared_arcsec``, ``rms_prediction_arcsec`` (the calibrated reducer and the unexplained structure),
        ``rms_reducer_arcsec`` (the calibrated reducer alone), ``rms_full_fit_arcsec``, ``prediction_over_noise``,
        ``named`` (the effects the fit on the other loads named), ``seconds``, ``status``) and ``statement``.
    """
    from rvcalib.loop import calibrate
    from rvcalib.settings import CalibrationSettings
    from rvdyn.solver import law_from_model

    settings = (settings or CalibrationSettings()).validate()
    if law is None and settings.contact is not None:
        law = law_from_model({"contact": settings.contact})
    fit = fit or (lambda ds, s, lg: calibrate(ds, s, log=lg))
    loads = sorted({float(r.load_Nm) for r in dataset.runs})
    if len(loads) < 2:
        return {"loads_Nm": loads, "rows": [],
                "statement": f"one load ({loads[0]:g} N m): no load can be left out and predicted"}
    rows = []
    for load in loads:
        if log:
            log(f"holdout: fitting without {load:g} N m, predicting it")
        rows.append(_row(dataset, load, settings, fit, law, full, declared, log))
    return {"loads_Nm": loads, "rows": rows,
            "statement": ("each load left out in turn: the loop fitted the runs of the other loads (the same "
                          "settings) and predicts the left-out runs: the calibrated reducer (its case and the encoder "
                          "effects named) plus the unexplained structure of that fit (a load-proportional term scaled "
                          "to the left-out load); 'reducer alone' leaves the unexplained structure out; each left-out "
                          "test's constant (the rig's zero) removed")}
