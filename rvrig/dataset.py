"""Read and validate a measured dataset (conventions, "Measured data").

A dataset is a folder with ``runs.csv`` (one row per run: ``run, load_Nm, direction``, optional
declared Table 4 error columns, ``temperature_C``, ``speed_rpm``, ``test``) and ``samples.csv`` (``run,
input_deg, output_deg``, optional ``time_s``). :func:`read_dataset` returns a
:class:`MeasuredDataset` or raises ``DatasetError`` (a ``ValueError``, :mod:`rvcad.validation`)
with a message that names the file, the column and the run.

What is checked (an error) and what is tolerated (repaired and reported in ``notes``):

* errors: a missing file or column, an unknown column, a missing or non-numeric cell, a repeated
  run id, a run without samples or samples of an undeclared run, a direction other than +1/-1,
  an input angle that does not move monotonically in the declared direction, a record shorter
  than one output revolution (N input turns, N the ratio of the reducer), angles that look like radians (judged by the
  span of the record and the ratio of the input and output spans), declared error columns whose
  magnitudes look like mm (for um columns) or like arcsec/um (for degree columns), temperatures
  that look like kelvin;
* tolerated: noise (nothing is smoothed), duplicated samples (the repeat of an input angle is
  dropped, keeping the first), and a start-up transient: where a record is longer than one output
  revolution, its first part is compared with the same input angles one output revolution later;
  a leading stretch that disagrees by more than the noise allows is dropped and reported.

The reducer measured is the folder's ``design.json`` (the ``design`` object of a case JSON, e.g.
``{"z_sun": 18, "z_planet": 36}`` for a ratio-81 RV) or the design given to :func:`read_dataset`
(``rv-calibrate --reducer``), else the paper's design (ratio 121). Its ratio converts the readings
to TE; a record whose input/output span ratio does not match it is refused, and without a design
the message says that the ratio does not match the default.

Angles are absolute encoder readings, but a rig zeroes its TE at a homing position before each test:
the runs of one test share one unknown constant (the rig's zero, a nuisance). ``MeasuredDataset.tests``
(:mod:`rvrig.testgroups`) says which runs form a test: the optional ``test`` column of ``runs.csv``,
else one test per load, speed and temperature.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from rsm.csvio import read_csv_strict
from rvcad.errors import ERROR_TYPES, Case
from rvcad.params import Design
from rvcad.validation import DatasetError, read_json_file

from rvrig.orders import check_periodic, period_deg
from rvrig.testgroups import TestGroups, group_tests

ARCSEC_PER_DEG = 3600.0

RUN_REQUIRED = ("run", "load_Nm", "direction")
RUN_OPTIONAL = ("temperature_C", "speed_rpm", "test")
SAMPLE_REQUIRED = ("run", "input_deg", "output_deg")
SAMPLE_OPTIONAL = ("time_s",)

#: A declared um error whose every non-zero magnitude lies below this (um) is taken as given in mm.
UM_LOOKS_LIKE_MM = 0.1
#: Largest accepted temperature, degC (above it the column looks like kelvin).
MAX_TEMPERATURE_C = 150.0
#: Largest plausible load, N m (above it the column looks like N mm).
MAX_LOAD_NM = 20000.0


@dataclass
class RunRecord:
    """One measured run after validation and repair.

    Attributes
    ----------
    run : str
        Run id as written in the files.
    load_Nm : float
        Output load torque, N m (it resists the motion).
    direction : int
        +1 (input angle increasing) or -1.
    declared : dict of str to float
        Declared Table 4 errors of the default instance (um or deg as in ``ERROR_TYPES``);
        only non-zero values.
    temperature_C : float or None
        Temperature of the run, degC (None: not given, taken as 20 degC).
    speed_rpm : float or None
        Input speed, rpm (informative only).
    input_deg, output_deg : ndarray
        Encoder readings in degrees, in the order of motion, after dropping duplicates and the
        start-up transient.
    time_s : ndarray or None
        Sample times, s.
    dropped : dict of str to int
        Samples dropped: ``duplicates``, ``transient``.
    noise_arcsec : float
        Noise estimate of the TE record, arcsec (robust scatter of second differences / sqrt(6)).
    notes : list of str
        What was repaired or could not be checked.
    design : Design
        The reducer measured (its ratio converts the readings to TE).
    test : str
        Id of the test (one homing of the rig) the run belongs to (:mod:`rvrig.testgroups`).
    """

    run: str
    load_Nm: float
    direction: int
    declared: dict[str, float]
    temperature_C: float | None
    speed_rpm: float | None
    input_deg: np.ndarray
    output_deg: np.ndarray
    time_s: np.ndarray | None = None
    dropped: dict[str, int] = field(default_factory=dict)
    noise_arcsec: float = float("nan")
    notes: list[str] = field(default_factory=list)
    design: Design = field(default_factory=Design)
    test: str = ""

    @property
    def ratio(self) -> float:
        """Total ratio of the reducer."""
        return float(self.design.ratio)

    @property
    def n(self) -> int:
        """Number of samples kept."""
        return int(self.input_deg.size)

    @property
    def te_arcsec(self) -> np.ndarray:
        """Measured TE ``output_deg - input_deg / N`` in arcsec (N the reducer's ratio)."""
        return (self.output_deg - self.input_deg / self.ratio) * ARCSEC_PER_DEG

    @property
    def output_rad(self) -> np.ndarray:
        """Output angle reading, rad."""
        return np.radians(self.output_deg)

    @property
    def revolutions(self) -> float:
        """Output revolutions covered by the kept samples (span plus one sample step)."""
        return record_revolutions(self.input_deg, period_deg(self.design))

    def case_dict(self) -> dict:
        """The case JSON of this run with the declared errors only (see ``rvcad.errors``); its
        ``design`` is the reducer's (omitted for the default design)."""
        d: dict = {"name": f"run-{self.run}", "errors": {k: v for k, v in self.declared.items()},
                   "load_Nm": self.load_Nm, "direction": self.direction}
        if self.design != Design():
            d["design"] = self.design.to_dict()
        if self.temperature_C is not None:
            d["model"] = {"temperature_C": self.temperature_C}
        return d


@dataclass
class MeasuredDataset:
    """A validated measured dataset.

    Attributes
    ----------
    path : Path
        The dataset folder.
    runs : list of RunRecord
    notes : list of str
        Everything that was repaired or not checked, one sentence each.
    declared_keys : list of str
        Table 4 error columns present in ``runs.csv``.
    design : Design
        The reducer measured.
    design_source : str
        Where the design came from: ``default`` (the paper's reducer), ``design.json`` in the
        dataset folder, or the file given (``--reducer``).
    tests : TestGroups
        The tests (one homing of the rig each): ``tests.of_run`` maps run id -> test id,
        ``tests.ids`` lists the tests; default (None given): one test per load, speed and temperature
        of the runs.
    """

    path: Path
    runs: list[RunRecord]
    notes: list[str] = field(default_factory=list)
    declared_keys: list[str] = field(default_factory=list)
    design: Design = field(default_factory=Design)
    design_source: str = "default"
    tests: TestGroups | None = None

    def __post_init__(self) -> None:
        if self.tests is None:
            self.tests = group_tests(pd.DataFrame({
                "run": [r.run for r in self.runs], "load_Nm": [r.load_Nm for r in self.runs],
                **({"speed_rpm": [r.speed_rpm for r in self.runs]} if all(r.speed_rpm is not None for r in self.runs) else {}),
                **({"temperature_C": [r.temperature_C for r in self.runs]}
                   if all(r.temperature_C is not None for r in self.runs) else {})}))
        for r in self.runs:
            r.test = self.tests.of_run[r.run]

    @property
    def ratio(self) -> float:
        """Total ratio of the reducer."""
        return float(self.design.ratio)

    @property
    def period_deg(self) -> float:
        """Input angle of one output revolution, deg."""
        return period_deg(self.design)

    def reducer(self) -> dict:
        """What the report and the JSON say about the reducer: ratio, tooth and pin counts, source."""
        d = self.design
        return {"ratio": self.ratio, "z_sun": d.z_sun, "z_planet": d.z_planet, "z_pins": d.z_pins,
                "z_disc": d.z_disc, "pin_circle_diameter_mm": d.pin_circle_diameter_mm,
                "source": self.design_source, "default": d == Design(), "design": d.to_dict()}

    @property
    def n_samples(self) -> int:
        """Total samples kept."""
        return int(sum(r.n for r in self.runs))

    @property
    def temperatures_vary(self) -> bool:
        """True if the runs were measured at more than one temperature."""
        t = {round(r.temperature_C if r.temperature_C is not None else 20.0, 6) for r in self.runs}
        return len(t) > 1

    def noise_arcsec(self) -> float:
        """Pooled noise estimate over the runs, arcsec (root mean square of the per-run estimates)."""
        w = np.array([r.n for r in self.runs], dtype=float)
        s = np.array([r.noise_arcsec for r in self.runs])
        return float(np.sqrt(np.sum(w * s ** 2) / np.sum(w)))


def median_step(x: np.ndarray) -> float:
    """The median absolute step between consecutive values of ``x`` (a record's sample step, in x's unit)."""
    return float(np.median(np.abs(np.diff(np.asarray(x, dtype=float)))))


def record_revolutions(input_deg: np.ndarray, period: float) -> float:
    """Output revolutions covered by a record: (span + one median sample step) / ``period`` (the input
    angle of one output revolution, deg)."""
    x = np.asarray(input_deg, dtype=float)
    if x.size < 2:
        return 0.0
    step = median_step(x)
    return (abs(float(x[-1] - x[0])) + step) / period


def load_design(source: "str | Path | dict | Design | None", folder: Path | None = None) -> tuple[Design, str]:
    """The reducer of a dataset: ``source`` (a Design, a design dict, or a design JSON file: the
    ``design`` object of a case JSON, or a whole case JSON holding one), else ``design.json`` in the
    dataset ``folder``, else the default (paper) design. Returns (design, source description).
    Errors name the file and the field."""
    if isinstance(source, Design):
        check_periodic(source)
        return source, "given"
    if isinstance(source, dict):
        d = Design.from_dict(source)
        check_periodic(d)
        return d, "given"
    path = Path(source) if source is not None else (folder / "design.json" if folder is not None else None)
    if path is None or (source is None and not path.is_file()):
        return Design(), "default"
    if not path.is_file():
        raise DatasetError(f"reducer design file '{path}' does not exist")
    raw = read_json_file(path, "reducer design file", DatasetError)  # strict: a repeated key or NaN is an error
    if isinstance(raw, dict) and isinstance(raw.get("design"), dict):
        raw = raw["design"]
    if not isinstance(raw, dict):
        raise DatasetError(f"reducer design file '{path}' must hold a JSON object of design fields "
                         f"(e.g. {{\"z_sun\": 18, \"z_planet\": 36}}), got {type(raw).__name__}")
    try:
        d = Design.from_dict(raw)
        check_periodic(d)
    except (TypeError, ValueError) as exc:
        raise DatasetError(f"{path.name}: {exc}") from None
    return d, str(path) if source is not None else "design.json in the dataset folder"


def _read_csv(path: Path, what: str) -> pd.DataFrame:
    if not path.is_file():
        raise DatasetError(f"{what} file '{path}' does not exist (a dataset folder holds runs.csv and samples.csv)")
    df = read_csv_strict(path, f"{what} file", DatasetError, dtype={"run": str, "test": str}, skipinitialspace=True)
    if len(df) == 0:
        raise DatasetError(f"{what} file '{path}' has a header but no rows")
    dup = [c for c in df.columns if list(df.columns).count(c) > 1]
    if dup:
        raise DatasetError(f"{path.name}: column '{dup[0]}' appears more than once")
    if "run" in df.columns:
        df["run"] = df["run"].fillna("").astype(str).str.strip()  # pandas 3 keeps NaN through astype(str)
    return df


def _numeric(df: pd.DataFrame, col: str, fname: str, runs: pd.Series | None = None) -> np.ndarray:
    raw = df[col]
    vals = pd.to_numeric(raw, errors="coerce")
    bad = vals.isna().to_numpy() | ~np.isfinite(vals.to_numpy(dtype=float, na_value=np.nan))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        where = f" (run {runs.iloc[i]})" if runs is not None else ""
        cell = raw.iloc[i]
        what = "is missing" if pd.isna(cell) else f"is not a finite number: {str(cell)!r}"
        raise DatasetError(f"{fname}: column '{col}' row {i + 2}{where} {what}")
    return vals.to_numpy(dtype=float)


def _check_error_column(key: str, values: np.ndarray, runs: pd.Series) -> None:
    et = ERROR_TYPES[key]
    nz = np.abs(values[values != 0.0])
    if nz.size == 0:
        return
    if et.unit == "um":
        if np.all(nz < UM_LOOKS_LIKE_MM):
            raise DatasetError(
                f"runs.csv: column '{key}' holds values up to {nz.max():g}, which look like mm; the "
                f"column is in um (e.g. 14 for 14 um, not 0.014): multiply it by 1000")
        if np.any(nz > 1000.0):
            i = int(np.argmax(np.abs(values)))
            raise DatasetError(
                f"runs.csv: column '{key}' run {runs.iloc[i]} value {values[i]:g} um exceeds 1 mm; "
                "the column is in um (values in nm? divide by 1000)")
    else:
        if np.any(nz > 5.0):
            i = int(np.argmax(np.abs(values)))
            raise DatasetError(
                f"runs.csv: column '{key}' run {runs.iloc[i]} value {values[i]:g} is too large for "
                "degrees (|value| <= 5); it looks like arcsec, arcmin or um: give the error in degrees")


def _read_runs(path: Path) -> tuple[pd.DataFrame, list[str]]:
    df = _read_csv(path, "runs")
    for c in RUN_REQUIRED:
        if c not in df.columns:
            raise DatasetError(f"runs.csv: required column '{c}' is missing; columns are {list(df.columns)}")
    allowed = set(RUN_REQUIRED) | set(RUN_OPTIONAL) | set(ERROR_TYPES)
    for c in df.columns:
        if c not in allowed:
            raise DatasetError(
                f"runs.csv: column '{c}' is unknown; allowed: {list(RUN_REQUIRED)}, optional "
                f"{list(RUN_OPTIONAL)} and the error keys {sorted(ERROR_TYPES)}")
    runs = df["run"]
    if (runs == "").any() or (runs.str.lower() == "nan").any():
        i = int(np.flatnonzero(((runs == "") | (runs.str.lower() == "nan")).to_numpy())[0])
        raise DatasetError(f"runs.csv: column 'run' row {i + 2} is empty")
    dup = runs[runs.duplicated()]
    if len(dup):
        raise DatasetError(f"runs.csv: run '{dup.iloc[0]}' appears more than once in column 'run'")
    load = _numeric(df, "load_Nm", "runs.csv", runs)
    for i, v in enumerate(load):
        if v < 0:
            raise DatasetError(f"runs.csv: column 'load_Nm' run {runs.iloc[i]} is {v:g}; the load magnitude must be >= 0 "
                             "(it always resists the motion)")
        if v > MAX_LOAD_NM:
            raise DatasetError(f"runs.csv: column 'load_Nm' run {runs.iloc[i]} is {v:g}, which looks like N mm; "
                             "give the load in N m")
    direc = _numeric(df, "direction", "runs.csv", runs)
    for i, v in enumerate(direc):
        if v not in (1.0, -1.0):
            raise DatasetError(f"runs.csv: column 'direction' run {runs.iloc[i]} is {v:g}; it must be +1 or -1")
    out = pd.DataFrame({"run": runs, "load_Nm": load, "direction": direc.astype(int)})
    keys = [c for c in df.columns if c in ERROR_TYPES]
    for k in keys:
        v = _numeric(df, k, "runs.csv", runs)
        _check_error_column(k, v, runs)
        out[k] = v
    if "temperature_C" in df.columns:
        t = _numeric(df, "temperature_C", "runs.csv", runs)
        for i, v in enumerate(t):
            if v > MAX_TEMPERATURE_C:
                raise DatasetError(f"runs.csv: column 'temperature_C' run {runs.iloc[i]} is {v:g}, which looks like "
                                 "kelvin or fahrenheit; give degrees Celsius")
            if v < -40.0:
                raise DatasetError(f"runs.csv: column 'temperature_C' run {runs.iloc[i]} is {v:g} degC, below -40")
        out["temperature_C"] = t
    if "speed_rpm" in df.columns:
        s = _numeric(df, "speed_rpm", "runs.csv", runs)
        if np.any(s < 0):
            i = int(np.argmin(s))
            raise DatasetError(f"runs.csv: column 'speed_rpm' run {runs.iloc[i]} is {s[i]:g}; the speed must be >= 0")
        out["speed_rpm"] = s
    if "test" in df.columns:
        out["test"] = df["test"]
    return out, keys


def noise_estimate(te_arcsec: np.ndarray) -> float:
    """Noise of a sampled record from its second differences, arcsec.

    ``1.4826 * MAD(diff2) / sqrt(6)``: exact for white noise on a smooth signal, an overestimate
    where the signal itself has sample-to-sample structure (sharp pin signatures).
    """
    x = np.asarray(te_arcsec, dtype=float)
    if x.size < 5:
        return float("nan")
    d2 = np.diff(x, 2)
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.4826 * mad / math.sqrt(6.0)


def _check_angle_units(run: str, inp: np.ndarray, out: np.ndarray, ratio: float, default: bool) -> None:
    s_in = abs(float(inp[-1] - inp[0]))
    s_out = abs(float(out[-1] - out[0]))
    rad = 180.0 / math.pi
    if s_out > 0 and s_in > 0:
        r = (s_in / s_out) / ratio
        if abs(r / rad - 1.0) < 0.05:
            raise DatasetError(
                f"samples.csv: run {run}: column 'output_deg' looks like radians (input span / output span = "
                f"{s_in / s_out:.4g}, expected {ratio:g}, off by the factor 180/pi); give degrees")
        if abs(r * rad - 1.0) < 0.05:
            raise DatasetError(
                f"samples.csv: run {run}: column 'input_deg' looks like radians (input span / output span = "
                f"{s_in / s_out:.4g}, expected {ratio:g}, off by the factor pi/180); give degrees")
        if abs(r - 1.0) < 0.05 and s_in < 0.5 * (ratio * 360.0) and s_in > 0.5 * 2 * math.pi * ratio:
            raise DatasetError(
                f"samples.csv: run {run}: columns 'input_deg' and 'output_deg' look like radians (input span "
                f"{s_in:.4g} ~ {s_in / (2 * math.pi * ratio):.3g} output revolutions in radians, but only "
                f"{s_in / (ratio * 360.0):.3g} in degrees); give degrees")
        if abs(r - 1.0) > 0.05:
            raise DatasetError(
                f"samples.csv: run {run}: input span / output span is {s_in / s_out:.5g}, not the ratio "
                f"{ratio:g}{' of the default reducer' if default else ''}: "
                + ("the ratio does not match the default (paper) design; describe the reducer measured with "
                   "--reducer DESIGN.json or a design.json in the dataset folder, or " if default else "")
                + "check the units and that 'input_deg' is the input (sun) angle and 'output_deg' "
                "the output (carrier) angle")


def _drop_transient(run: str, inp: np.ndarray, te: np.ndarray, direction: int, sigma: float,
                    notes: list[str], period: float) -> int:
    """Number of leading samples to drop as start-up transient (0 if none or not checkable)."""
    span = abs(float(inp[-1] - inp[0]))
    step = median_step(inp)
    if span < period + 4 * step:
        notes.append(f"run {run}: the record is not longer than one output revolution, so a start-up "
                     "transient could not be checked against the repeat")
        return 0
    x = (inp - inp[0]) * direction          # increasing
    nover = int(np.searchsorted(x, x[-1] - period, side="right"))
    if nover < 3:
        return 0
    partner = np.interp(x[:nover] + period, x, te)
    d = te[:nover] - partner
    # noise of the repeat difference (the periodic signal cancels; the transient is smooth enough
    # for second differences to ignore it)
    sd = noise_estimate(d) if nover >= 8 else float("nan")
    sigma = sd / math.sqrt(2.0) if np.isfinite(sd) and sd > 0 else sigma
    if not np.isfinite(sigma) or sigma <= 0:
        sigma = float(np.std(d)) / math.sqrt(2.0) or 1e-9
    w = min(7, nover)
    dm = np.convolve(d, np.ones(w) / w, mode="same")
    thr = 5.0 * math.sqrt(2.0) * sigma / math.sqrt(w) + 1e-12
    flag = np.abs(dm) > thr
    if not flag[0] and not flag[: max(1, w // 2 + 1)].any():
        return 0
    # first index from which w consecutive samples are unflagged
    end = nover
    for i in range(nover):
        j = min(i + w, nover)
        if j - i >= 3 and not flag[i:j].any():
            end = i
            break
    if end == 0:
        return 0
    if end >= nover:
        # not a start-up transient: the revolutions differ over the whole overlap (a drift with time,
        # an encoder scale error, a change during the run); dropping would leave less than a revolution
        notes.append(f"run {run}: its output revolutions differ over the whole overlap (by {float(np.mean(d)):.3g} "
                     f"arcsec on average, up to {float(np.max(np.abs(d))):.3g} arcsec; noise {sigma:.3g} arcsec): not a "
                     "start-up transient, so nothing is dropped; a drift, an encoder scale error or a change during "
                     "the run is not in the library and shows as a residual ramp")
        return 0
    cut = min(int(math.ceil(1.5 * end)) + w // 2, len(inp))
    remaining = abs(float(inp[-1] - inp[min(cut, len(inp) - 1)])) + step
    if remaining < period:
        cut = end + w // 2
    peak = float(np.max(np.abs(d[:max(end, 1)])))
    notes.append(f"run {run}: dropped the first {cut} samples as start-up transient: they differ from the "
                 f"same input angles one output revolution later by up to {peak:.3g} arcsec (noise "
                 f"{sigma:.3g} arcsec)")
    return cut


def read_dataset(path: str | Path, design: "str | Path | dict | Design | None" = None) -> MeasuredDataset:
    """Read and validate a measured dataset folder.

    Parameters
    ----------
    path : str or Path
        Folder with ``runs.csv`` and ``samples.csv`` (and optionally ``design.json``, the reducer
        measured: the ``design`` object of a case JSON).
    design : Design, dict, path or None
        The reducer measured (``--reducer``); default: the folder's ``design.json``, else the
        paper's design. Its ratio converts the readings to TE and is checked against them.

    Returns
    -------
    MeasuredDataset

    Raises
    ------
    ValueError
        Naming the file, column and run (see the module docstring for what is checked).
    """
    root = Path(path)
    if not root.is_dir():
        raise DatasetError(f"dataset folder '{root}' does not exist or is not a folder")
    des, des_src = load_design(design, root)
    period = period_deg(des)
    runs_df, keys = _read_runs(root / "runs.csv")
    srun, inp_all, out_all, t_all = _read_samples(root / "samples.csv", set(runs_df["run"]))
    groups = {k: np.flatnonzero((srun == k).to_numpy()) for k in runs_df["run"]}
    records: list[RunRecord] = []
    for _, row in runs_df.iterrows():
        idx = groups[row["run"]]
        if idx.size == 0:
            raise DatasetError(f"samples.csv: run {row['run']} of runs.csv has no samples")
        records.append(_run_record(row, keys, runs_df.columns, inp_all[idx], out_all[idx],
                                   t_all[idx] if t_all is not None else None, des, des_src, period))
    notes = [n for r in records for n in r.notes]
    return MeasuredDataset(path=root, runs=records, notes=notes, declared_keys=keys, design=des, design_source=des_src,
                           tests=group_tests(runs_df))


def _read_samples(path: Path, known: set) -> tuple:
    """samples.csv checked (its columns, empty run ids, runs not in runs.csv): the run column and the input,
    output and (or None) time columns as numbers."""
    sdf = _read_csv(path, "samples")
    for c in SAMPLE_REQUIRED:
        if c not in sdf.columns:
            raise DatasetError(f"samples.csv: required column '{c}' is missing; columns are {list(sdf.columns)}")
    for c in sdf.columns:
        if c not in SAMPLE_REQUIRED + SAMPLE_OPTIONAL:
            raise DatasetError(f"samples.csv: column '{c}' is unknown; allowed: {list(SAMPLE_REQUIRED)} and "
                             f"optional {list(SAMPLE_OPTIONAL)}")
    srun = sdf["run"]
    if (srun == "").any():
        raise DatasetError(f"samples.csv: column 'run' row {int(np.flatnonzero((srun == '').to_numpy())[0]) + 2} is empty")
    inp_all = _numeric(sdf, "input_deg", "samples.csv", srun)
    out_all = _numeric(sdf, "output_deg", "samples.csv", srun)
    t_all = _numeric(sdf, "time_s", "samples.csv", srun) if "time_s" in sdf.columns else None
    extra = sorted(set(srun) - known)
    if extra:
        raise DatasetError(f"samples.csv: run '{extra[0]}' in column 'run' is not in runs.csv")
    return srun, inp_all, out_all, t_all


def _drop_duplicates(rid: str, inp: np.ndarray, out: np.ndarray, tt: np.ndarray | None,
                     rnotes: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, int]:
    """The run's samples without duplicates (the same input angle again: the first kept), and their count."""
    keep = np.ones(inp.size, dtype=bool)
    if inp.size > 1:
        keep[1:] = ~(np.diff(inp) == 0.0)
    _, first = np.unique(inp, return_index=True)
    rep = np.zeros(inp.size, dtype=bool)
    rep[first] = True
    keep &= rep
    ndup = int((~keep).sum())
    if not ndup:
        return inp, out, tt, 0
    rnotes.append(f"run {rid}: dropped {ndup} duplicated samples (repeated input_deg; the first kept)")
    return inp[keep], out[keep], (tt[keep] if tt is not None else None), ndup


def _check_order(rid: str, inp: np.ndarray, tt: np.ndarray | None, direction: int) -> None:
    """At least 8 samples, times increasing, input angles monotonic in the run's direction."""
    if inp.size < 8:
        raise DatasetError(f"samples.csv: run {rid} has only {inp.size} distinct samples; at least one output "
                         "revolution of samples is needed")
    if tt is not None and np.any(np.diff(tt) <= 0):
        i = int(np.flatnonzero(np.diff(tt) <= 0)[0])
        raise DatasetError(f"samples.csv: run {rid}: column 'time_s' is not increasing at sample {i + 2} of the run "
                         f"({tt[i]:g} then {tt[i + 1]:g} s)")
    dx = np.diff(inp) * direction
    if np.all(dx < 0):
        raise DatasetError(f"samples.csv: run {rid}: column 'input_deg' runs {'down' if direction == 1 else 'up'} "
                         f"but runs.csv gives direction {direction:+d}")
    if np.any(dx <= 0):
        i = int(np.flatnonzero(dx <= 0)[0])
        raise DatasetError(f"samples.csv: run {rid}: column 'input_deg' is not monotonic: sample {i + 2} of the run "
                         f"goes from {inp[i]:.6g} to {inp[i + 1]:.6g} deg against direction {direction:+d}")


def _run_record(row, keys: list[str], columns, inp: np.ndarray, out: np.ndarray, tt: np.ndarray | None,
                des: Design, des_src: str, period: float) -> RunRecord:
    """One run of runs.csv with its samples, checked and repaired (duplicates, start-up transient)."""
    rid, direction, ratio = row["run"], int(row["direction"]), float(des.ratio)
    rnotes: list[str] = []
    inp, out, tt, ndup = _drop_duplicates(rid, inp, out, tt, rnotes)
    _check_order(rid, inp, tt, direction)
    _check_angle_units(rid, inp, out, ratio, des_src == "default")
    revs = record_revolutions(inp, period)
    if revs < 1.0 - 0.5 * median_step(inp) / period:  # half a sample step of slack for reading errors
        raise DatasetError(f"samples.csv: run {rid} covers {revs:.4g} output revolutions (input span "
                         f"{abs(inp[-1] - inp[0]):.6g} deg); at least one output revolution ({period:g} deg "
                         "of input) is needed")
    te = (out - inp / ratio) * ARCSEC_PER_DEG
    if abs(float(np.median(te))) > 3600.0:
        raise DatasetError(f"samples.csv: run {rid}: the TE output_deg - input_deg/{ratio:g} is "
                         f"{np.median(te) / 3600:.4g} deg; the encoders do not share their zero or the columns "
                         "are not the input and output angles")
    cut = _drop_transient(rid, inp, te, direction, noise_estimate(te), rnotes, period)
    inp, out, te = inp[cut:], out[cut:], te[cut:]
    tt = tt[cut:] if tt is not None else None
    rec = RunRecord(run=rid, load_Nm=float(row["load_Nm"]), direction=direction,
                    declared={k: float(row[k]) for k in keys if float(row[k]) != 0.0},
                    temperature_C=float(row["temperature_C"]) if "temperature_C" in columns else None,
                    speed_rpm=float(row["speed_rpm"]) if "speed_rpm" in columns else None,
                    input_deg=inp, output_deg=out, time_s=tt, dropped={"duplicates": ndup, "transient": cut},
                    noise_arcsec=noise_estimate(te), notes=rnotes, design=des)
    try:
        Case.from_dict(rec.case_dict())
    except ValueError as exc:
        raise DatasetError(f"runs.csv: run {rid}: {exc}") from None
    return rec
