"""A measured dataset averaged down to the readings the reducer model needs (what ``rv-calibrate`` fits).

A rig record imported at its default density (:func:`rvrig.rigfilter.default_samples_per_rev`: 1080 readings per
output revolution for ratio 81) holds the orders a reducer shows up to the fourth harmonic of its input order.
The reducer model's TE holds fewer: the pin orders ``Zp`` and ``2 Zp`` (docs/physics.md, section 3; ``3 Zp`` is
below a rig's noise) and the input order ``N + 1`` (the sun, the planets, the input encoder). A model evaluation
costs in proportion to the readings, so the loop fits the records averaged down by the import's own anti-alias
low-pass to the density whose flat band holds those orders (:func:`model_samples_per_rev`): the model's point
predictions then fold no order the record holds back onto another. The measured figures (means, peak-to-peak,
spectrum) are read from every reading. A folder imported at a lower density has lost some of those orders for
good: :func:`filtered_model_orders` says which.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from rvcad.params import Design
from rvrig.dataset import MeasuredDataset, RunRecord, median_step, noise_estimate
from rvrig.rigfilter import PASS_FRACTION, decimate
from rvrig.rigimport import RigRecord


def model_orders(design: Design) -> list[float]:
    """The orders of the output angle the reducer model's TE holds: ``Zp``, ``2 Zp`` and ``N + 1``."""
    return [float(design.z_pins), 2.0 * design.z_pins, float(design.ratio) + 1.0]


def model_samples_per_rev(design: Design) -> int:
    """Readings per output revolution whose averaging filter is flat up to the model's orders: the smallest
    ``K`` with ``PASS_FRACTION K / 2 >= max(2 Zp, N + 1)`` (205 for ratio 81 with 40 pins, 305 for ratio 121)."""
    return int(math.ceil(2.0 * max(model_orders(design)) / PASS_FRACTION - 1e-9))


def filtered_model_orders(folder: str | Path, design: Design) -> tuple[list[float], float | None]:
    """The model's orders (:func:`model_orders`) that the import's low-pass took out of a dataset folder's
    records (above the pass band's end of some run, ``import.json``), and that end (order); ``([], None)`` for a
    folder not written by :func:`rvrig.rigimport.import_rig` or not averaged down."""
    path = Path(folder) / "import.json"
    if not path.is_file():
        return [], None
    runs = [r for f in json.loads(path.read_text(encoding="utf-8")).get("files", []) for r in f.get("runs", [])]
    ends = [float(r["filter"]["pass_band_to_order"]) for r in runs if r.get("filter")]
    if not ends:
        return [], None
    end = min(ends)
    return [k for k in model_orders(design) if k > end], end


def _record(run: RunRecord) -> RigRecord:
    """One run as a rig record of its TE (deg) on its output angle, its slots counted in median steps."""
    out = np.asarray(run.output_deg, dtype=float)
    direction = 1 if out[-1] >= out[0] else -1
    step = median_step(out)
    slot = np.rint(np.abs(out - out[0]) / step).astype(int)
    time = run.time_s if run.time_s is not None else slot * 1.0
    return RigRecord(direction, out, run.te_arcsec / 3600.0, np.asarray(time, dtype=float), slot, "the readings")


def fitted_density(run: RunRecord, samples_per_rev: int | None) -> float:
    """Readings per output revolution of ``run`` that the loop fits: ``samples_per_rev`` (None: the model's,
    :func:`model_samples_per_rev`) where the run is denser, else every reading (also for 0)."""
    k = model_samples_per_rev(run.design) if samples_per_rev is None else samples_per_rev
    if k < 0:
        raise ValueError(f"samples_per_rev {samples_per_rev} must be 0 (every reading) or positive")
    density = run.n / max(run.revolutions, 1e-9)
    return density if k == 0 or density <= k else float(k)


def averaged(dataset: MeasuredDataset, samples_per_rev: int | None) -> tuple[MeasuredDataset, list[str]]:
    """The dataset with every run denser than ``samples_per_rev`` readings per output revolution (None: the
    model's, :func:`model_samples_per_rev`) averaged down (:func:`rvrig.rigfilter.decimate`: zero-phase low-pass,
    then an even grid of output angle; the input readings follow from the TE, ``input = N (output - TE)``); sparser
    runs and ``samples_per_rev`` 0 keep every reading (:func:`fitted_density`).

    Returns
    -------
    (MeasuredDataset, list of str)
        The dataset and one note per density averaged (what the loop fits and why).
    """
    runs, notes = [], {}
    for r in dataset.runs:
        density, k = r.n / max(r.revolutions, 1e-9), fitted_density(r, samples_per_rev)
        if k == density:
            runs.append(r)
            continue
        arr, info = decimate(_record(r), int(k))
        te = arr["te_deg"]
        runs.append(dataclasses.replace(
            r, output_deg=arr["output_deg"], input_deg=r.ratio * (arr["output_deg"] - te),
            time_s=arr["time_s"] if r.time_s is not None else None, noise_arcsec=noise_estimate(te * 3600.0)))
        band = info["filter"]["pass_band_to_order"]
        notes[round(density)] = (f"the loop fits the readings averaged from {density:.0f} to "
                                 f"{info['samples_per_rev']:.0f} per output revolution (flat to order {band:g}); "
                                 "the measured figures use every reading")
    return dataclasses.replace(dataset, runs=runs), list(notes.values())
