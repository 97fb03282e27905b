"""Closing the loop with measured data: measured TE -> residual -> the effects the model lacks -> the updated model.

The method is written up in docs/calibration.md; the command line and the report in docs/calibrate.md.

Modules
-------
The measured records themselves (the dataset format, importing a rig's files, the per-test table, the spectrum) are
:mod:`rvrig`; ``read_dataset`` is re-exported here.

:mod:`rvcalib.library`, :mod:`rvcalib.readings`
    The candidates as data (unit, bounds, prior scale) and the analytic columns of the reading errors and the
    empirical block.
:mod:`rvcalib.reducer_model`
    The reducer's TE at every reading for a state of the candidates, and its columns (rvdyn).
:mod:`rvcalib.sparse`
    The estimator: the sum of single effects over grouped features (plain numpy).
:mod:`rvcalib.refine`
    The nonlinear estimate of the chosen effects through the reducer model.
:mod:`rvcalib.loop`, :mod:`rvcalib.settings`, :mod:`rvcalib.result`
    ``calibrate(dataset, settings)``: the iteration, its settings, what it reports.
:mod:`rvcalib.datasheet`, :mod:`rvcalib.equivalents`, :mod:`rvcalib.holdout`
    The datasheet as declared and as calibrated, the physical parameters behind what is named, the prediction of
    loads left out of the fit.
:mod:`rvcalib.report`, :mod:`rvcalib.reportmd`, :mod:`rvcalib.figures`, :mod:`rvcalib.cli`
    report.md, result.json and figures; ``rv-calibrate DATASET --out DIR``.
:mod:`rvcalib.simulate`
    ``simulate_dataset(...)``: measured-like datasets with hidden effects (the answer kept apart).

Example
-------
>>> from rvcalib import read_dataset, calibrate            # doctest: +SKIP
>>> res = calibrate(read_dataset("measured/"))             # doctest: +SKIP
>>> res.rms_before, res.rms_after, [e.line() for e in res.effects]   # doctest: +SKIP
"""
from rvrig.dataset import MeasuredDataset, RunRecord, read_dataset
from rvcalib.loop import calibrate
from rvcalib.result import CalibrationResult
from rvcalib.settings import CalibrationSettings
from rvcalib.simulate import simulate_dataset

__all__ = ["MeasuredDataset", "RunRecord", "read_dataset", "CalibrationResult", "CalibrationSettings", "calibrate",
           "simulate_dataset"]
