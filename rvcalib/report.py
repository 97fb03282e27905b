"""The report of a calibration: ``report.md``, ``result.json`` and the figures, written atomically.

:func:`write_report` writes into ``out_dir`` (each file through :func:`rvcad.atomic.atomic_path`, with the
permissions of a normal new file; ``report.md`` last, so a complete report.md means a complete report):

* ``te_per_run.png``, ``residuals.png``, ``residual_spectrum.png`` (:mod:`rvcalib.figures`) and
  ``test_means.png`` (:func:`rvrig.rigtable.plot_test_means`);
* ``result.json``: the object ``rv-calibrate --json`` prints (:func:`report_object`);
* ``report.md``: the verdict; the reducer and its ratio; what the rig shows before any model (the per-test table,
  how it changes with load, the measured datasheet); the named effects with their 95 % intervals and their
  physical equivalents; the groups the data cannot split, each member's size and probability; the unexplained
  structure; the tests' constants (nuisance); the datasheet of the reducer as declared and as calibrated; the
  prediction of each load left out of the fit; the lines of the residual's spectrum (fixed-frequency lines not
  claimed for the reducer); per-run figures; notes; the method in a few lines (docs/calibration.md is the
  method).

Everything follows the dataset's reducer: its ratio N in every formula (``output_deg - input_deg / N``).
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from rvcad.atomic import atomic_path
from rvrig.dataset import MeasuredDataset
from rvcalib.datasheet import rated_torque
from rvcalib.equivalents import result_equivalents
from rvcalib.figures import plot_residual_spectrum, plot_residuals, plot_te
from rvcalib.library import PHYSICAL, build_library
from rvcalib.reportmd import markdown
from rvrig.rigtable import load_changes, measured_datasheet, plot_test_means, test_table
from rvrig.spectrum import order_spectrum, separate

FIGURES = ("te_per_run.png", "residuals.png", "residual_spectrum.png", "test_means.png")


def clean(o: Any) -> Any:
    """A JSON-ready copy: NaN and infinity as None, numpy scalars and arrays as Python numbers and lists."""
    if isinstance(o, dict):
        return {str(k): clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return clean(o.tolist())
    if isinstance(o, (np.bool_, bool)):
        return bool(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, Path):
        return str(o)
    return o


def verdict(result) -> str:
    """One line: the status, the RMS before and after against the noise."""
    ratio = result.rms_after / result.noise_arcsec if result.noise_arcsec > 0 else math.inf
    return (f"{result.status}: residual RMS {result.rms_before:.4g} -> {result.rms_after:.4g} arcsec against a noise "
            f"of {result.noise_arcsec:.4g} arcsec ({ratio:.3g} x the noise; {result.status!r} means within 1.2 x)")


def measured_figures(dataset: MeasuredDataset, rated_Nm: float | None = None) -> dict:
    """What the rig shows before any model (:mod:`rvrig.rigtable`), JSON-ready.

    Returns
    -------
    dict
        ``tests`` (:func:`rvrig.rigtable.test_table` rows), ``main_orders``, ``load_changes`` (rows),
        ``datasheet`` (:func:`rvrig.rigtable.measured_datasheet` at the rated torque of
        :func:`rvcalib.datasheet.rated_torque`), ``rated_source`` and ``spectrum_statements``.
    """
    table = test_table(dataset)
    rated, source = rated_torque(dataset.design, rated_Nm)
    return clean({"tests": table.to_dict(orient="records"), "main_orders": table.attrs.get("main_orders", []),
                  "load_changes": load_changes(table).to_dict(orient="records"),
                  "datasheet": measured_datasheet(dataset, rated, table=table), "rated_source": source,
                  "spectrum_statements": table.attrs["spectrum"]["statements"]})


def physical_bounds(dataset: MeasuredDataset) -> dict[str, tuple[float, float, bool]]:
    """Per physical effect name: its physical bounds (the union of a pin-wise error's two sides) and whether it
    is reported as a magnitude (two components)."""
    out: dict[str, tuple[float, float, bool]] = {}
    for c in build_library(dataset, 1, PHYSICAL, True):
        lo, hi, _ = out.get(c.effect_name, (c.lower, c.upper, c.polar))
        out[c.effect_name] = (min(lo, c.lower), max(hi, c.upper), c.polar)
    return out


def _within(value: float, bounds: tuple[float, float, bool] | None) -> bool:
    """A finite size inside its candidate's physical bounds (a magnitude of two components bounded by each
    component's largest bound times sqrt 2)."""
    if not math.isfinite(value):
        return False
    if bounds is None:
        return True
    lo, hi, polar = bounds
    if polar:
        return abs(value) <= max(abs(lo), abs(hi)) * math.sqrt(2.0)
    return lo <= value <= hi


def bounded_groups(groups: list, bounds: dict) -> list:
    """The groups with every member size beyond its physical bounds written ``"unbounded"`` (a size the data
    leave free along the group, e.g. of two members only their combination is fixed, is no size)."""
    out = []
    for g in groups:
        members = []
        for m in g["members"]:
            v = m.get("value")
            free = isinstance(v, (int, float)) and not _within(float(v), bounds.get(m.get("name")))
            members.append(dict(m, value="unbounded") if free else dict(m))
        out.append({**g, "members": members})
    return out


def _constants(dataset, values: dict, fallback: dict | None = None) -> np.ndarray:
    """Per run, its test's constant from ``values`` (test -> arcsec)."""
    return np.array([values.get(r.test, (fallback or {}).get(r.test, 0.0)) for r in dataset.runs])


def _test_means(dataset, per_run: list) -> dict:
    """Each test's mean of per-run arrays over its readings."""
    acc: dict[str, list] = {}
    for r, x in zip(dataset.runs, per_run):
        acc.setdefault(r.test, []).append(np.asarray(x, dtype=float))
    return {t: float(np.concatenate(v).mean()) for t, v in acc.items()}


def curves(result, dataset, declared: list | None) -> dict:
    """Per run (arcsec): ``measured`` (the TE less its test's constant after), ``calibrated`` (the calibrated model
    with its reading and empirical terms, the same level), ``declared`` (the declared model at that level, or
    None), ``before`` and ``after`` (residuals, each test's own constant removed)."""
    y = [r.te_arcsec for r in dataset.runs]
    after = [np.asarray(a, dtype=float) for a in result.residuals]
    c_after = _constants(dataset, {n["test"]: n["constant_arcsec"] for n in result.nuisance},
                         _test_means(dataset, [a - b for a, b in zip(y, after)]))
    out = {"measured": [a - c for a, c in zip(y, c_after)], "after": after, "declared": None, "before": None}
    out["calibrated"] = [m - r for m, r in zip(out["measured"], after)]
    if declared is not None:
        c_before = _constants(dataset, _test_means(dataset, [a - d for a, d in zip(y, declared)]))
        out["before"] = [a - d - c for a, d, c in zip(y, declared, c_before)]
        out["declared"] = [d + cb - ca for d, cb, ca in zip(declared, c_before, c_after)]
    return out


def residual_dataset(dataset: MeasuredDataset, residuals: list) -> MeasuredDataset:
    """The dataset whose runs' TE is the given residual (the output readings kept, the input readings moved), for
    the spectrum of the residual."""
    runs = [dataclasses.replace(r, input_deg=r.ratio * (r.output_deg - np.asarray(x) / 3600.0), notes=[])
            for r, x in zip(dataset.runs, residuals)]
    return MeasuredDataset(path=dataset.path, runs=runs, declared_keys=list(dataset.declared_keys),
                           design=dataset.design, design_source=dataset.design_source, tests=dataset.tests)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _run_rows(dataset, cv: dict) -> list:
    """Per run: its conditions, readings, noise and the RMS of the residual before and after (arcsec)."""
    return [{"run": r.run, "test": r.test, "load_Nm": r.load_Nm, "direction": r.direction, "samples": r.n,
             "revolutions": r.revolutions, "noise_arcsec": r.noise_arcsec,
             "rms_before_arcsec": _rms(cv["before"][k]) if cv["before"] is not None else None,
             "rms_after_arcsec": _rms(cv["after"][k])} for k, r in enumerate(dataset.runs)]


def report_object(result, dataset, measured: dict, datasheet: dict | None, holdout: dict | None, spectrum: dict,
                  equivalents: dict, runs: list, paths: dict) -> dict:
    """The ``--json`` object: the result's ``to_dict()`` (its groups' sizes beyond physical bounds written
    ``"unbounded"``) and ``verdict``, ``ratio``, ``report``, ``figures``, ``measured``, ``datasheet``, ``holdout``,
    ``equivalents``, ``residual_spectrum``, ``runs``."""
    d = result.to_dict()
    d["groups"] = bounded_groups(d["groups"], physical_bounds(dataset))
    equivalents = dict(equivalents, groups=[[q if m["value"] != "unbounded" else [] for m, q in zip(g["members"], qs)]
                                            for g, qs in zip(d["groups"], equivalents.get("groups", []))])
    d.update({"verdict": verdict(result), "ratio": dataset.ratio, "report": paths.get("report"),
              "figures": paths.get("figures", []), "measured": measured, "datasheet": datasheet, "holdout": holdout,
              "equivalents": equivalents, "residual_spectrum": spectrum, "runs": runs})
    return clean(d)


def _spectrum(dataset, after: list) -> tuple[list, dict]:
    rd = residual_dataset(dataset, after)
    sep = separate(rd)
    keep = ("method", "nyquist_order", "order_locked", "fixed_frequency", "ambiguous", "statements")
    return [order_spectrum(r) for r in rd.runs], clean({k: sep[k] for k in keep})


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_report(result, dataset: MeasuredDataset, out_dir: str | Path, measured: dict | None = None,
                 datasheet: dict | None = None, holdout: dict | None = None, declared: list | None = None,
                 equivalents: dict | None = None) -> dict:
    """Write report.md, result.json and the figures into ``out_dir`` (module docstring).

    Parameters
    ----------
    result : CalibrationResult
    dataset : MeasuredDataset
        The dataset calibrated (the result's residuals are per run of it).
    measured : dict or None
        :func:`measured_figures` (default: made here, at the settings' rated torque).
    datasheet : dict or None
        :func:`rvcalib.datasheet.reducer_datasheet` (None: the section says it was not computed, or that the
        design needs a rated torque).
    holdout : dict or None
        :func:`rvcalib.holdout.holdout_loads` (None: not run).
    declared : list of ndarray or None
        The declared model's TE per run (:func:`rvcalib.holdout.declared_te`), for the residual before; None
        leaves it out of the figures.
    equivalents : dict or None
        :func:`rvcalib.equivalents.result_equivalents` (default: made here, without the friction reading).

    Returns
    -------
    dict
        ``report`` (report.md), ``json`` (result.json), ``figures`` (PNG paths) and ``object`` (the JSON object).
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {str(out)!r} is an existing file, not a folder; allowed: a folder (created if "
                         "missing)")
    out.mkdir(parents=True, exist_ok=True)
    if measured is None:
        measured = measured_figures(dataset, (result.settings or {}).get("rated_Nm"))
    if equivalents is None:
        equivalents = result_equivalents(result, dataset.design)
    cv = curves(result, dataset, declared)
    spectra, spectrum = _spectrum(dataset, cv["after"])
    figs = [out / f for f in FIGURES]
    plot_te(dataset, cv["measured"], cv["calibrated"], cv["declared"], figs[0])
    plot_residuals(dataset, cv["before"], cv["after"], figs[1])
    plot_residual_spectrum(spectra, spectrum, dataset.ratio, figs[2])
    plot_test_means(dataset, figs[3])
    paths = {"report": str(out / "report.md"), "json": str(out / "result.json"), "figures": [str(f) for f in figs]}
    runs = clean(_run_rows(dataset, cv))
    obj = report_object(result, dataset, measured, datasheet, holdout, spectrum, clean(equivalents), runs, paths)
    _write_text(out / "result.json", json.dumps(obj, indent=2))
    _write_text(out / "report.md", markdown(obj, dataset))
    return {**paths, "object": obj}
