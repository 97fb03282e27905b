"""Simulator of measured datasets, to test the loop on data whose truth is known.

:func:`simulate_dataset` writes a dataset folder (``runs.csv``, ``samples.csv``) as a test rig
would record it, and the truth into a separate answer file (``answer.json`` outside the dataset
folder by default): the hidden effects never enter the dataset, which only declares what the
runs' ``declared`` errors say.

What the "rig" does, per run:

1. True TE: rvdyn (analytic contacts) solved exactly at every sample's input angle
   (``samples_per_rev`` per output revolution from ``start_deg``), for the declared plus the
   hidden errors and model options (TE is periodic in one output revolution).
2. Encoders: the input reading is ``theta_in + (eps_in / R_in) sin(theta_in + phi_in) + noise``,
   the output reading ``theta_out + (eps_out / R_out) sin(theta_out + phi_out) + noise`` (radii of
   :mod:`rvcalib.library`), Gaussian noise in arcsec of each encoder.
3. Hidden effects outside the library: harmonics of the output angle added to the output reading
   (``amplitude * cos(k theta_out + phase)``, arcsec).
4. A start-up transient ``A exp(-i / tau)`` (arcsec, sample i) added to the output reading of the
   first samples of chosen runs; such runs are recorded ``extra_revolutions`` longer.
5. The rig's zero per test: a rig zeroes its TE at a homing before each test, so every run of one
   test reads the TE plus the same unknown constant (``test_offsets``, arcsec, added to the output
   reading; conventions.md, "Measured-data format"). The dataset does not record which runs share a
   test; the answer file does (``test_offsets``, ``run_tests``).
6. Duplicated samples (a row written twice) at random places.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rvcad.atomic import atomic_path
from rvcad.errors import ERROR_TYPES, Case
from rvdyn.te import run_te
from rvdyn.options import MODEL_OPTIONS

from rvcad.params import Design

from rvcalib.equivalents import EQUIVALENTS
from rvcalib.library import (INPUT_ENCODER_RADIUS_MM, MODEL_VECTORS, OUTPUT_ENCODER_RADIUS_MM, CaseDelta,
                             carrier_offset_axes, carrier_offset_radial)
from rvrig.orders import check_periodic, period_deg

MEASUREMENT_KEYS = ("output_encoder_eccentricity_um", "output_encoder_phase_deg",
                    "input_encoder_eccentricity_um", "input_encoder_phase_deg", "output_encoder_scale_ppm")


def _write_csv_atomic(df: pd.DataFrame, path: Path) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            df.to_csv(fh, index=False, float_format="%.10f")


def expected_effects(hidden: dict[str, Any], design: Design | None = None) -> list[dict[str, Any]]:
    """The effects the loop should find for a ``hidden`` specification (names as in the library), for the reducer
    ``design`` (default the paper's): a carrier offset as the library holds it (:func:`_carrier_offset_effects`).

    Returns
    -------
    list of dict
        ``name, key, value, unit`` (magnitude for two-component effects, with ``angle_deg``); a Table 4
        error also has its ``instance`` (``{}`` for the all-pins instance of a pin-wise error).
    """
    out: list[dict[str, Any]] = []
    for key, spec in (hidden.get("errors") or {}).items():
        et = ERROR_TYPES[key]
        items = spec if isinstance(spec, list) else [spec]
        for item in items:
            if not isinstance(item, dict):
                item = {"value": item}
            inst = {k: item[k] for k in et.instance_keys if k in item}
            if et.pinwise and "pin" not in inst and key == "pin_pitch":
                inst = {"pin": 0}
            if key in ("cam_phase", "cam_eccentricity", "planet_eccentricity", "carrier_hole_eccentricity",
                       "disc_hole_eccentricity", "disc_phase"):
                inst = {k: item.get(k, et.defaults[k]) for k in et.instance_keys}
            name = key + ("[" + ",".join(f"{k}={v}" for k, v in inst.items()) + "]" if inst else "")
            d = {"name": name, "key": key, "value": float(item["value"]), "unit": et.unit}
            d["instance"] = dict(inst)
            if et.has_angle:
                d["angle_deg"] = float(item.get("angle_deg", 0.0))
            out.append(d)
    model = hidden.get("model") or {}
    _carrier_offset_effects(out, model, design or Design())
    vectors = {k for keys in MODEL_VECTORS.values() for k in keys}
    for key, v in model.items():
        if key in ("pin_circle_ovality_angle_deg", "temperature_C", "cam_bearing_stiffness_N_per_um") or \
                key in vectors or isinstance(v, str):     # a choice (the contact law), not an effect
            continue
        d = {"name": key, "key": key, "value": float(v), "unit": MODEL_OPTIONS[key].unit}
        if key == "pin_circle_ovality_um":
            d["angle_deg"] = float(model.get("pin_circle_ovality_angle_deg", 0.0))
        out.append(d)
    for key, v in (hidden.get("design") or {}).items():   # a design the dataset does not declare
        for q in EQUIVALENTS:
            if q.parameter == key:
                out.append({"name": q.effect, "key": q.effect, "value": float(v) / q.factor,
                            "unit": ERROR_TYPES[q.effect].unit, "cause": f"design.{key}", "cause_value": float(v)})
    meas = hidden.get("measurement") or {}
    for which in ("output", "input"):
        eps = float(meas.get(f"{which}_encoder_eccentricity_um", 0.0))
        if eps:
            out.append({"name": f"{which}_encoder_eccentricity", "key": f"{which}_encoder_eccentricity",
                        "value": eps, "unit": "um", "angle_deg": float(meas.get(f"{which}_encoder_phase_deg", 0.0))})
    s = float(meas.get("output_encoder_scale_ppm", 0.0))
    if s:
        out.append({"name": "output_encoder_scale_error", "key": "output_encoder_scale_error", "value": s,
                    "unit": "ppm"})
    return out


def simulate_dataset(out_dir: str | Path, runs: list[dict[str, Any]], hidden: dict[str, Any] | None = None,
                     noise_arcsec: float = 0.15, input_noise_arcsec: float = 2.0, samples_per_rev: int = 240,
                     revolutions: float = 1.0, transient: dict[str, Any] | None = None, duplicates: int = 0,
                     seed: int = 0, answer_path: str | Path | None = None, speed_rpm: float | None = None,
                     start_deg: float = 0.0, design: dict[str, Any] | None = None,
                     write_design: bool = True, test_offsets: dict[str, float] | None = None) -> Path:
    """Write a simulated measured dataset and its answer file.

    Parameters
    ----------
    out_dir : str or Path
        Dataset folder to create (``runs.csv``, ``samples.csv``).
    runs : list of dict
        Each ``{"run", "load_Nm", "direction"}`` plus optional ``"declared": {error key: value}`` (default instance,
        written to runs.csv and used in the truth), ``"temperature_C"`` and ``"test"`` (the id of the test, one homing
        of the rig, the run belongs to; default the run's own id).
    hidden : dict or None
        The truth the dataset does not declare: ``"errors"`` (case JSON errors, any instance), ``"model"`` (rvdyn
        model options), ``"measurement"`` (``output_encoder_eccentricity_um``, ``output_encoder_phase_deg``,
        ``input_encoder_eccentricity_um``, ``input_encoder_phase_deg``, ``output_encoder_scale_ppm``: the output
        reading is ``theta_out (1 + s)``), ``"design"`` (design fields of the reducer as built that the dataset's
        design does not hold, e.g. an undeclared profile modification ``{"profile_equidistant_mm": 0.004}``; expected
        as the library effect that gives the same TE, :mod:`rvcalib.equivalents`) and ``"harmonics"`` (list of
        ``{"order", "amplitude_arcsec", "phase_deg", "per_Nm"}``, outside the library; with ``"per_Nm": true`` the
        amplitude is per N m of the run's load).
    noise_arcsec, input_noise_arcsec : float
        Output and input encoder noise (standard deviations), arcsec; the input's enters the TE divided by the ratio.
    samples_per_rev : int
        Samples per output revolution (any count >= 8; the rig's sampling, not a model grid).
    start_deg : float
        Input angle of the first sample, deg. Any start other than 0 puts the samples off every model grid, as on a
        real rig.
    revolutions : float
        Output revolutions recorded per run (>= 1).
    transient : dict or None
        ``{"runs": [ids] or "all", "amplitude_arcsec", "tau_samples", "extra_revolutions"}``.
    duplicates, seed : int
        Rows written twice (spread at random over the file); the random seed.
    answer_path : str, Path or None
        Where the answer goes (default ``<out_dir>.answer.json`` beside the folder).
    speed_rpm : float or None
        Written to runs.csv if given (informative).
    design : dict or None
        The reducer (the ``design`` object of a case JSON; default the paper's). Every run is solved with it, and its
        ratio converts the encoder angles.
    write_design : bool
        Write the design into the dataset folder as ``design.json`` (only for a non-default design), as a bench that
        knows its reducer would.
    test_offsets : dict or None
        The rig's zero of each test: test id -> constant (arcsec) added to the TE reading of every run of that test
        (tests not listed: 0). Not written to the dataset; the answer file holds it.

    Returns
    -------
    Path
        The answer file.
    """
    hidden = dict(hidden or {})
    meas = _check_hidden(hidden)
    declared_keys = _check_runs(runs, revolutions, samples_per_rev)
    run_tests, offsets = _test_offsets(runs, test_offsets)
    rng = np.random.default_rng(seed)
    out = Path(out_dir)
    des, built = _designs(design, hidden)
    rig = _Rig(float(des.ratio), period_deg(des) / int(samples_per_rev), int(samples_per_rev), float(revolutions),
               float(start_deg), dict(transient or {}), meas, list(hidden.get("harmonics") or []),
               float(noise_arcsec), float(input_noise_arcsec))
    built_dict = built.to_dict() if design or hidden.get("design") else None
    truths = [_truth_case(r, hidden, built_dict) for r in runs]
    samples = [rig.readings(r, t, offsets.get(run_tests[str(r["run"])], 0.0), rng) for r, t in zip(runs, truths)]
    _write_dataset(out, [_run_row(r, declared_keys, speed_rpm) for r in runs], samples, int(duplicates), rng,
                   any("temperature_C" in r for r in runs),
                   des.to_dict() if design and write_design and des != Design() else None)
    answer = {"dataset": str(out), "hidden": hidden, "expected_effects": expected_effects(hidden, des), **rig.answer(),
              "start_deg": float(start_deg), "revolutions": revolutions, "duplicates": int(duplicates), "seed": seed,
              "design": des.to_dict(), "test_offsets": offsets, "run_tests": run_tests}
    ap = Path(answer_path) if answer_path is not None else out.parent / f"{out.name}.answer.json"
    _write_json_atomic(answer, ap)
    return ap


def _carrier_offset_effects(out: list[dict[str, Any]], model: dict[str, Any], design: Design) -> None:
    """Add a hidden carrier offset ``d`` to ``out`` as the library holds it
    (:func:`rvcalib.library.carrier_offset_axes`): its radial part at each crank's hole, ``d . u_i``, added to
    that crank's carrier-hole eccentricity, and the offset along the library's axes (a size and a direction with
    two axes, one value with one)."""
    kx, ky = MODEL_VECTORS["carrier_offset"]
    d = np.array([float(model.get(kx, 0.0)), float(model.get(ky, 0.0))])
    if not d.any():
        return
    key = "carrier_hole_eccentricity"
    for i, radial in carrier_offset_radial(d, design.crank_angles_rad).items():
        hit = [e for e in out if e["key"] == key and e["instance"].get("crank") == i]
        if hit:
            hit[0]["value"] += radial
        else:
            out.append({"name": f"{key}[crank={i}]", "key": key, "value": radial, "unit": ERROR_TYPES[key].unit,
                        "instance": {"crank": i}})
    axes = carrier_offset_axes(design)
    unit = MODEL_OPTIONS[kx].unit
    if len(axes) == 2:
        out.append({"name": "carrier_offset", "key": "carrier_offset", "value": float(np.hypot(*d)), "unit": unit,
                    "angle_deg": math.degrees(math.atan2(d[1], d[0]))})
    else:
        out.append({"name": "carrier_offset", "key": "carrier_offset", "value": float(d @ axes[0]), "unit": unit})


def _check_runs(runs: list[dict[str, Any]], revolutions: float, samples_per_rev: int) -> list[str]:
    """Validate the runs and the sampling; returns the declared error keys of the runs, sorted."""
    if revolutions < 1.0:
        raise ValueError(f"revolutions {revolutions} must be >= 1 (the format needs one output revolution)")
    if not runs:
        raise ValueError("runs must list at least one run")
    if int(samples_per_rev) < 8:
        raise ValueError(f"samples_per_rev {samples_per_rev} must be >= 8")
    declared_keys = sorted({k for r in runs for k in (r.get("declared") or {})})
    for k in declared_keys:
        if k not in ERROR_TYPES:
            raise ValueError(f"runs[].declared key {k!r} is unknown; allowed: {sorted(ERROR_TYPES)}")
    return declared_keys


def _write_dataset(out: Path, rows: list[dict[str, Any]], samples: list[pd.DataFrame], duplicates: int,
                   rng: np.random.Generator, temperatures: bool, design: dict[str, Any] | None) -> None:
    """Write ``runs.csv``, ``samples.csv`` (``duplicates`` rows written twice, at random places) and, where given,
    ``design.json``."""
    out.mkdir(parents=True, exist_ok=True)
    sdf = pd.concat(samples, ignore_index=True)
    if duplicates:
        idx = np.sort(rng.choice(len(sdf), size=duplicates, replace=False))
        sdf = pd.concat([sdf, sdf.iloc[idx]]).sort_index(kind="stable").reset_index(drop=True)
    rdf = pd.DataFrame(rows)
    if temperatures:
        rdf["temperature_C"] = rdf["temperature_C"].fillna(20.0)
    _write_csv_atomic(rdf, out / "runs.csv")
    _write_csv_atomic(sdf, out / "samples.csv")
    if design is not None:
        _write_json_atomic(design, out / "design.json")


def _write_json_atomic(obj: Any, path: Path) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(obj, fh, indent=2)


def _check_hidden(hidden: dict[str, Any]) -> dict[str, Any]:
    """Validate the keys of ``hidden``; returns its measurement effects."""
    for k in hidden:
        if k not in ("errors", "model", "measurement", "harmonics", "design"):
            raise ValueError(f"hidden key {k!r} is unknown; allowed: errors, model, measurement, harmonics, design")
    meas = dict(hidden.get("measurement") or {})
    for k in meas:
        if k not in MEASUREMENT_KEYS:
            raise ValueError(f"hidden.measurement key {k!r} is unknown; allowed: {list(MEASUREMENT_KEYS)}")
    return meas


def _designs(design: dict[str, Any] | None, hidden: dict[str, Any]) -> tuple[Design, Design]:
    """The declared design and the reducer as built (plus ``hidden.design``), which must keep the ratio."""
    des = Design.from_dict(design)
    check_periodic(des)
    built = Design.from_dict(dict(des.to_dict(), **dict(hidden.get("design") or {})))
    if built.ratio != des.ratio:
        raise ValueError(f"hidden.design changes the ratio from {des.ratio:g} to {built.ratio:g}; allowed: fields of "
                         "the reducer as built that keep the declared design's ratio (e.g. a profile modification)")
    return des, built


def _truth_case(r: dict[str, Any], hidden: dict[str, Any], design: dict[str, Any] | None) -> dict[str, Any]:
    """The case the rig's reducer runs in run ``r``: its declared errors plus the hidden errors and model
    options (validated, naming the field)."""
    base: dict[str, Any] = {"errors": dict(r.get("declared") or {}), "load_Nm": float(r.get("load_Nm", 20.0)),
                            "direction": int(r.get("direction", 1))}
    if design is not None:
        base["design"] = design
    if "temperature_C" in r:
        base["model"] = {"temperature_C": float(r["temperature_C"])}
    errs = []
    for key, spec in (hidden.get("errors") or {}).items():
        for item in (spec if isinstance(spec, list) else [spec]):
            errs.append((key, item if isinstance(item, dict) else {"value": item}))
    truth = CaseDelta(items=errs).to_dict({k: v for k, v in base.items() if k != "model"})
    model = {**(base.get("model") or {}), **dict(hidden.get("model") or {})}
    if model:
        truth["model"] = model
    Case.from_dict(truth)
    return truth


def te_exact(case_dict: dict[str, Any], input_deg: np.ndarray) -> np.ndarray:
    """The TE (arcsec) of a case solved exactly at every input angle (deg, any revolution, in the order given),
    each angle on its own (rvdyn's analytic contacts; the case's own contact law and load): the TE repeats every
    output revolution, so angles equal modulo one (to 1e-9 deg) are solved once."""
    case = Case.from_dict(case_dict)
    period = period_deg(case.design)
    red = np.round(np.mod(np.asarray(input_deg, dtype=float), period), 9)
    uniq, inv = np.unique(red, return_inverse=True)
    res = run_te(case, "analytic", theta_in_deg=uniq if case.direction > 0 else uniq[::-1])
    te = res.table["te_arcsec"].to_numpy()
    return (te if case.direction > 0 else te[::-1])[inv]


def _run_row(r: dict[str, Any], declared_keys: list[str], speed_rpm: float | None) -> dict[str, Any]:
    """The run's row of runs.csv."""
    decl = dict(r.get("declared") or {})
    row: dict[str, Any] = {"run": str(r["run"]), "load_Nm": float(r.get("load_Nm", 20.0)),
                           "direction": int(r.get("direction", 1))}
    for key in declared_keys:
        row[key] = float(decl.get(key, 0.0))
    if "temperature_C" in r:
        row["temperature_C"] = float(r["temperature_C"])
    if speed_rpm is not None:
        row["speed_rpm"] = float(speed_rpm)
    return row


@dataclass(frozen=True)
class _Rig:
    """The rig's sampling and reading errors (module docstring, steps 1-5): ratio, sample step (input deg),
    samples per output revolution, revolutions per run, start angle (deg), transient, measurement effects,
    harmonics outside the library, and the encoders' noise (arcsec)."""

    ratio: float
    step: float
    N: int
    revolutions: float
    start_deg: float
    transient: dict[str, Any]
    meas: dict[str, Any]
    harmonics: list[dict[str, Any]]
    noise_arcsec: float
    input_noise_arcsec: float

    def answer(self) -> dict[str, Any]:
        """What the answer file says of the rig: its noise (the TE's, the output's and the input's, arcsec), its
        sampling, its transient, the encoder radii and the ratio."""
        te_noise = math.sqrt(self.noise_arcsec ** 2 + (self.input_noise_arcsec / self.ratio) ** 2)
        return {"noise_te_arcsec": te_noise, "noise_output_arcsec": self.noise_arcsec,
                "noise_input_arcsec": self.input_noise_arcsec, "samples_per_rev": self.N,
                "transient": self.transient or None, "ratio": self.ratio,
                "encoder_radii_mm": {"output": OUTPUT_ENCODER_RADIUS_MM, "input": INPUT_ENCODER_RADIUS_MM}}

    def readings(self, r: dict[str, Any], truth: dict[str, Any], offset_arcsec: float,
                 rng: np.random.Generator) -> pd.DataFrame:
        """Run ``r``'s samples (``run, input_deg, output_deg, time_s``): the true TE of ``truth`` at every
        sample, the reading errors, the test's rig zero and the noise (drawn from ``rng``, output then input)."""
        rid, d, load = str(r["run"]), int(r.get("direction", 1)), float(r.get("load_Nm", 20.0))
        tr = self.transient
        tr_runs = tr.get("runs", "all")
        has_tr = bool(tr) and (tr_runs == "all" or rid in [str(x) for x in tr_runs])
        revs = self.revolutions + (float(tr.get("extra_revolutions", 0.1)) if has_tr else 0.0)
        M = int(math.ceil(revs * self.N - 1e-9))
        k = np.arange(M)
        th_in = self.start_deg + d * k * self.step
        th_out = th_in / self.ratio + te_exact(truth, th_in) / 3600.0  # the TE exact at every sample
        for h in self.harmonics:
            amp = float(h["amplitude_arcsec"]) * (load if h.get("per_Nm") else 1.0)
            te_h = amp * np.cos(int(h["order"]) * np.radians(th_out) + math.radians(float(h.get("phase_deg", 0.0))))
            th_out = th_out + te_h / 3600.0
        if has_tr:
            th_out = th_out + float(tr.get("amplitude_arcsec", 20.0)) * np.exp(
                -k / float(tr.get("tau_samples", 5.0))) / 3600.0
        meas = self.meas
        eo = float(meas.get("output_encoder_eccentricity_um", 0.0))
        po = math.radians(float(meas.get("output_encoder_phase_deg", 0.0)))
        ei = float(meas.get("input_encoder_eccentricity_um", 0.0))
        pi_ = math.radians(float(meas.get("input_encoder_phase_deg", 0.0)))
        out_read = th_out + np.degrees(eo * 1e-3 / OUTPUT_ENCODER_RADIUS_MM * np.sin(np.radians(th_out) + po))
        in_read = th_in + np.degrees(ei * 1e-3 / INPUT_ENCODER_RADIUS_MM * np.sin(np.radians(th_in) + pi_))
        out_read = out_read * (1.0 + 1e-6 * float(meas.get("output_encoder_scale_ppm", 0.0)))
        out_read = out_read + offset_arcsec / 3600.0
        out_read = out_read + rng.normal(0.0, self.noise_arcsec, M) / 3600.0
        in_read = in_read + rng.normal(0.0, self.input_noise_arcsec, M) / 3600.0
        return pd.DataFrame({"run": rid, "input_deg": in_read, "output_deg": out_read, "time_s": k * 0.01})


def _test_offsets(runs: list[dict[str, Any]], test_offsets: dict[str, float] | None
                  ) -> tuple[dict[str, str], dict[str, float]]:
    """Each run's test id and the validated offsets (test id -> arcsec) of ``test_offsets``."""
    run_tests = {str(r["run"]): str(r.get("test", r["run"])) for r in runs}
    offsets: dict[str, float] = {}
    for t, v in (test_offsets or {}).items():
        if str(t) not in run_tests.values():
            raise ValueError(f"test_offsets key {t!r} is no run's test; allowed: {sorted(set(run_tests.values()))}")
        x = float(v)
        if not math.isfinite(x):
            raise ValueError(f"test_offsets[{t!r}] = {v!r} must be a finite number of arcsec")
        offsets[str(t)] = x
    return run_tests, offsets


def standard_runs(loads: tuple[float, ...] = (10.0, 30.0), directions: tuple[int, ...] = (1, -1),
                  declared: dict[str, float] | None = None) -> list[dict[str, Any]]:
    """Runs at every load and direction (ids 1, 2, ...), all with the same declared errors."""
    out = []
    i = 1
    for L in loads:
        for d in directions:
            r: dict[str, Any] = {"run": str(i), "load_Nm": float(L), "direction": int(d)}
            if declared:
                r["declared"] = dict(declared)
            out.append(r)
            i += 1
    return out
