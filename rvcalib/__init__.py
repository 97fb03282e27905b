"""Closing the loop with measured data: residual -> missing effect -> model update -> error before and after.

Modules
-------
:mod:`rvcalib.orders`
    Ratio, period, orders that matter and the screening grid, from the reducer's design.
:mod:`rvcalib.dataset`
    ``read_dataset(folder, design=None)`` (the reducer: ``design`` / the folder's design.json / default): runs.csv + samples.csv, validated (clear errors naming file/column/run),
    duplicates and start-up transients dropped and reported.
:mod:`rvcalib.forward`
    rvdyn TE on a uniform grid per run condition, periodic interpolation to the readings, cached.
:mod:`rvcalib.effects`
    The candidate library: Table 4 errors (all instances), rvdyn model options, encoder eccentricities.
:mod:`rvcalib.residual`
    Residual diagnostics: RMS, peak, order spectrum, direction/load dependence, Ljung-Box whiteness.
:mod:`rvcalib.identify`
    ``calibrate(dataset)``: the loop, run in stages: :mod:`rvcalib.model` (run conditions, model TE
    at the readings), :mod:`rvcalib.screening` (signatures, ranking, harmonic competitors),
    :mod:`rvcalib.fitting` (nonlinear refits, confidence intervals), :mod:`rvcalib.selection`
    (the policy: F test + BIC, encompassing test, backward elimination, alternatives),
    :mod:`rvcalib.results` (typed candidate records, the result); :mod:`rvcalib.lsq` the numerics.
:mod:`rvcalib.simulate`
    ``simulate_dataset(...)``: measured-like datasets with hidden effects (answer file kept apart).
:mod:`rvcalib.report`, :mod:`rvcalib.cli`
    Markdown/PNG/JSON report; ``rv-calibrate DATASET --out DIR [--reducer DESIGN.json] [--json] [--steps N]``.

Example
-------
>>> from rvcalib import read_dataset, calibrate            # doctest: +SKIP
>>> res = calibrate(read_dataset("measured/"), )   # doctest: +SKIP
>>> res.rms_before, res.rms_after, [e.name for e in res.effects]   # doctest: +SKIP
"""
from rvcalib.dataset import MeasuredDataset, RunRecord, read_dataset
from rvcalib.identify import CalibrationResult, calibrate
from rvcalib.simulate import simulate_dataset

__all__ = ["MeasuredDataset", "RunRecord", "read_dataset", "CalibrationResult", "calibrate", "simulate_dataset"]
