"""Turn a TE rig's records into a measured dataset (conventions, "Measured data"; docs/rig-data.md).

A common rig layout writes one CSV file per test (one homing of the rig), sampled in time, with the
output angle and the TE of a forward and a backward run side by side::

    Poisition_Output_Reducer_Fw, Transmission_Error_Fw, Position_Output_Reducer_Bw, Transmission_Error_Bw

(angles in deg; the rig's own spelling ``Poisition`` is accepted beside ``Position``; TE = theta_out -
theta_in / N in deg; an optional ``time_s`` column, else the times follow from the sample rate). The
forward positions run 0 -> 360, the backward ones 360 -> 0 (unwrapped when a record is longer than one
revolution: it is used whole). :func:`import_rig` writes ``runs.csv`` (two runs per file, directions +1
and -1, one test per file) and ``samples.csv`` with ``input_deg = N (output_deg - te_deg)``.

Gaps. A step between two readings of more than 1.5 sample spacings (in time where the file has times,
else in position, as a rig sampling at a fixed rate at constant speed moves one spacing per reading)
is a gap: the readings missing are counted and reported. Gaps of up to :data:`rvrig.rigfilter.FILL_SPACINGS`
spacings are filled by linear interpolation before the low-pass only (no filled reading is written); a
longer gap splits the record into segments, each filtered on its own, and no reading is written inside it.
Without a time column, the times after a gap are shifted by the readings missing.

Averaging down (:mod:`rvrig.rigfilter`): a record denser than ``samples_per_rev`` readings per output
revolution is low-passed and evaluated on an even grid of output angle, no order above the new Nyquist
order folding back.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from rsm.csvio import read_csv_strict
from rvcad.atomic import atomic_path, remove_stale_temps
from rvcad.params import Design
from rvcad.validation import DatasetError, OptionError
from rvrig.dataset import load_design, median_step, noise_estimate
from rvrig.rigfilter import FILL_SPACINGS, decimate, default_samples_per_rev

#: Accepted names of the four columns, per direction: (output angle names, TE name).
LAYOUT = {+1: (("Poisition_Output_Reducer_Fw", "Position_Output_Reducer_Fw"), "Transmission_Error_Fw"),
          -1: (("Position_Output_Reducer_Bw", "Poisition_Output_Reducer_Bw"), "Transmission_Error_Bw")}
#: Optional time column (s from the start of each run), shared by both directions.
TIME_COLUMN = "time_s"
#: Sample rate of the rig layout, Hz (the shared records: 4 kHz).
DEFAULT_SAMPLE_RATE_HZ = 4000.0
#: A step of more than this many sample spacings is a gap.
GAP_THRESHOLD = 1.5
#: Largest plausible |TE|, deg (above it the TE column looks like arcsec or arcmin).
MAX_TE_DEG = 5.0
#: Conditions in a file name, e.g. ``1800.0rpm0.0Nm25.0deg.csv``.
NAME_PATTERN = re.compile(r"(?P<speed_rpm>\d+(?:\.\d*)?)rpm(?P<load_Nm>\d+(?:\.\d*)?)Nm"
                          r"(?P<temperature_C>-?\d+(?:\.\d*)?)deg", re.IGNORECASE)
#: Files the importer writes into the dataset folder (runs.csv last: a folder without it is incomplete).
WRITTEN = ("samples.csv", "design.json", "import.json", "runs.csv")


@dataclass
class RigRecord:
    """One direction of one rig file, as read (readings in motion order).

    Attributes
    ----------
    direction : int
        +1 (forward) or -1 (backward).
    output_deg : ndarray
        Output angle, deg, unwrapped.
    te_deg : ndarray
        TE, deg.
    time_s : ndarray
        Times from the run's first reading, s.
    slot : ndarray of int
        Sample slot of each reading (0, 1, 2, ...; a gap skips slots).
    time_source : str
        ``"column time_s"`` or ``"sample rate ... Hz"``.
    gaps : list of dict
        ``at_output_deg``, ``spacings`` (the step in sample spacings), ``missing`` (readings),
        ``kind`` (``"filled"``, ``"split"`` or ``"position jump"``: a step in position without one in time).
    """

    direction: int
    output_deg: np.ndarray
    te_deg: np.ndarray
    time_s: np.ndarray
    slot: np.ndarray
    time_source: str
    gaps: list[dict] = field(default_factory=list)

    @property
    def step_deg(self) -> float:
        """Median output angle between readings, deg."""
        return median_step(self.output_deg)

    @property
    def revolutions(self) -> float:
        """Output revolutions covered: (span + one step) / 360."""
        return (abs(float(self.output_deg[-1] - self.output_deg[0])) + self.step_deg) / 360.0

    def input_speed_rpm(self, ratio: float) -> float:
        """Input speed from the readings, rpm: output angle travelled over the time taken, times the ratio."""
        dt = float(self.time_s[-1] - self.time_s[0])
        return abs(float(self.output_deg[-1] - self.output_deg[0])) / 360.0 / dt * 60.0 * ratio if dt > 0 else math.nan


def parse_conditions(name: str) -> dict[str, float]:
    """Speed (rpm), load (N m) and temperature (degC) from a file name like ``1800.0rpm0.0Nm25.0deg.csv``;
    an empty dict when the name does not have that form."""
    m = NAME_PATTERN.search(Path(name).name)
    return {k: float(v) for k, v in m.groupdict().items()} if m else {}


def _columns(df: pd.DataFrame, path: Path) -> dict[int, tuple[str, str]]:
    """The (position, TE) column of each direction, or an error listing what was found and expected."""
    found = list(df.columns)
    out = {}
    for d, (pos_names, te) in LAYOUT.items():
        pos = next((p for p in pos_names if p in found), None)
        if pos is not None and te in found:
            out[d] = (pos, te)
    extra = [c for c in found if c != TIME_COLUMN and not any(c in (*p, t) for p, t in LAYOUT.values())]
    if len(out) < 2 or extra:
        expected = [LAYOUT[1][0][0], LAYOUT[1][1], LAYOUT[-1][0][0], LAYOUT[-1][1]]
        raise DatasetError(
            f"{path.name}: the header does not have the rig layout: columns found {found}; expected {expected} "
            f"(output angle and TE in deg per direction; '{LAYOUT[1][0][1]}' is accepted for the first) and "
            f"optionally '{TIME_COLUMN}'" + (f"; unknown: {extra}" if extra else ""))
    return out


def _numeric(df: pd.DataFrame, col: str, path: Path) -> np.ndarray:
    vals = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
    bad = np.flatnonzero(np.isnan(vals) & df[col].notna().to_numpy())
    if bad.size:
        i = int(bad[0])
        raise DatasetError(f"{path.name}: column '{col}' row {i + 2} is not a number: {str(df[col].iloc[i])!r}")
    if np.isinf(vals).any():
        i = int(np.flatnonzero(np.isinf(vals))[0])
        raise DatasetError(f"{path.name}: column '{col}' row {i + 2} is not finite: {vals[i]}")
    return vals


def read_rig_file(path: str | Path, sample_rate_Hz: float = DEFAULT_SAMPLE_RATE_HZ) -> dict[int, RigRecord]:
    """Read one rig file: its forward (+1) and backward (-1) records.

    Parameters
    ----------
    path : str or Path
        A CSV file of the rig layout (module docstring).
    sample_rate_Hz : float
        Sample rate, Hz; used for the times when the file has no ``time_s`` column.

    Returns
    -------
    dict of int to RigRecord

    Raises
    ------
    DatasetError
        An unknown header (listing the columns found and expected), a non-numeric cell, a position that
        does not move in the run's direction, a TE that is not in degrees, a record shorter than one
        output revolution; each names the file and the column.
    """
    p = Path(path)
    if not p.is_file():
        raise DatasetError(f"rig file '{p}' does not exist")
    df = read_csv_strict(p, "rig file", DatasetError, skipinitialspace=True)
    cols = _columns(df, p)
    t_all = _numeric(df, TIME_COLUMN, p) if TIME_COLUMN in df.columns else None
    return {d: _direction_record(df, p, d, pos, te, t_all, sample_rate_Hz) for d, (pos, te) in cols.items()}


def _direction_record(df: pd.DataFrame, p: Path, d: int, pos_col: str, te_col: str, t_all: np.ndarray | None,
                      fs: float) -> RigRecord:
    pos, te = _numeric(df, pos_col, p), _numeric(df, te_col, p)
    rows = np.flatnonzero(np.isfinite(pos) & np.isfinite(te))
    if rows.size < 8:
        raise DatasetError(f"{p.name}: columns '{pos_col}', '{te_col}' hold {rows.size} complete rows; a record of "
                           "at least one output revolution is needed")
    pos, te = np.unwrap(pos[rows], period=360.0), te[rows]
    if np.max(np.abs(te)) > MAX_TE_DEG:
        raise DatasetError(f"{p.name}: column '{te_col}' reaches {np.max(np.abs(te)):g}, which is not a TE in deg "
                           f"(|TE| <= {MAX_TE_DEG:g} deg); it looks like arcsec or arcmin: give degrees")
    step = np.diff(pos) * d
    if np.any(step <= 0):
        i = int(np.flatnonzero(step <= 0)[0])
        raise DatasetError(f"{p.name}: column '{pos_col}' does not move {'up' if d > 0 else 'down'} (the "
                           f"{'forward' if d > 0 else 'backward'} run) at row {rows[i + 1] + 2}: {pos[i]:.7g} then "
                           f"{pos[i + 1]:.7g} deg")
    if t_all is not None:
        t = t_all[rows]
        if np.isnan(t).any():
            raise DatasetError(f"{p.name}: column '{TIME_COLUMN}' row {rows[np.flatnonzero(np.isnan(t))[0]] + 2} is empty")
        if np.any(np.diff(t) <= 0):
            i = int(np.flatnonzero(np.diff(t) <= 0)[0])
            raise DatasetError(f"{p.name}: column '{TIME_COLUMN}' is not increasing at row {rows[i + 1] + 2}")
        source = f"column {TIME_COLUMN}"
    else:
        t = rows / fs
        source = f"sample rate {fs:g} Hz"
    slot, gaps = _slots(pos, t, step, from_column=t_all is not None)
    if t_all is None:
        t = slot / fs
    rec = RigRecord(direction=d, output_deg=pos, te_deg=te, time_s=t - t[0], slot=slot, time_source=source, gaps=gaps)
    if rec.revolutions < 1.0 - 0.5 * rec.step_deg / 360.0:
        raise DatasetError(f"{p.name}: column '{pos_col}' covers {rec.revolutions:.4g} output revolutions "
                           f"({pos[0]:.6g} to {pos[-1]:.6g} deg); at least one output revolution is needed")
    return rec


def _slots(pos: np.ndarray, t: np.ndarray, step: np.ndarray, from_column: bool) -> tuple[np.ndarray, list[dict]]:
    """Sample slot of each reading and the gaps: a step of k > 1.5 spacings skips round(k) - 1 slots."""
    k_pos = step / np.median(step)
    dt = np.diff(t)
    k_t = dt / np.median(dt)
    k = k_t if from_column else np.maximum(k_t, k_pos)
    n = np.where(k > GAP_THRESHOLD, np.rint(k), 1.0).astype(int)
    slot = np.concatenate([[0], np.cumsum(n)])
    gaps = []
    for i in np.flatnonzero((n > 1) | ((k_pos > GAP_THRESHOLD) & (n == 1))):
        kind = ("position jump" if n[i] == 1 else "filled" if n[i] <= FILL_SPACINGS else "split")
        gaps.append({"at_output_deg": float(pos[i]), "spacings": float(max(k[i], k_pos[i])),
                     "missing": int(n[i] - 1), "kind": kind})
    return slot, gaps


@dataclass
class FileConditions:
    """Conditions of one file and where each came from (``option`` or ``file name``)."""

    load_Nm: float
    speed_rpm: float | None
    temperature_C: float | None
    source: dict[str, str]


def file_conditions(path: Path, load_Nm: float | None, speed_rpm: float | None,
                    temperature_C: float | None) -> FileConditions:
    """The options given, else what the file name says; the load is required."""
    parsed = parse_conditions(path.name)
    vals, src = {}, {}
    for key, given in (("load_Nm", load_Nm), ("speed_rpm", speed_rpm), ("temperature_C", temperature_C)):
        if given is not None:
            vals[key], src[key] = float(given), "option"
        elif key in parsed:
            vals[key], src[key] = parsed[key], "file name"
        else:
            vals[key] = None
    if vals["load_Nm"] is None:
        raise OptionError(f"{path.name}: the load is not known: give --load-Nm, or name the file like "
                          "'1800.0rpm0.0Nm25.0deg.csv' (input speed rpm, output load N m, oil temperature degC)",
                          field="--load-Nm", value=None, allowed="a load in N m")
    return FileConditions(vals["load_Nm"], vals["speed_rpm"], vals["temperature_C"], src)


def _reducer(ratio: float | None, design: "str | Path | dict | Design | None") -> tuple[float, Design | None]:
    if (ratio is None) == (design is None):
        raise OptionError("give exactly one of --ratio N and --reducer DESIGN.json (the reducer's ratio converts "
                          "output angle and TE to the input angle)", field="--ratio", value=ratio,
                          allowed="one of --ratio, --reducer")
    if design is not None:
        des = load_design(design)[0]
        return float(des.ratio), des
    if not (isinstance(ratio, (int, float)) and math.isfinite(ratio) and ratio > 1.0):
        raise OptionError(f"--ratio {ratio!r} must be a number > 1", field="--ratio", value=ratio, allowed="> 1")
    return float(ratio), None


def _check_existing_design(out: Path, ratio: float) -> None:
    """A design.json already in the dataset folder must have the ratio the readings are converted with."""
    if (out / "design.json").is_file():
        des = load_design(None, out)[0]
        if abs(des.ratio - ratio) > 1e-9:
            raise OptionError(f"{out / 'design.json'} has ratio {des.ratio:g}, not the --ratio {ratio:g} given: "
                              "remove it or import with --reducer", field="--ratio", value=ratio,
                              allowed=f"{des.ratio:g} (the folder's design.json)")


def import_rig(files: "list[str | Path]", out: str | Path, *, ratio: float | None = None,
               design: "str | Path | dict | Design | None" = None, load_Nm: float | None = None,
               speed_rpm: float | None = None, temperature_C: float | None = None,
               samples_per_rev: int | None = None, sample_rate_Hz: float = DEFAULT_SAMPLE_RATE_HZ,
               test: str | None = None) -> dict:
    """Import rig files into a dataset folder (``runs.csv``, ``samples.csv``, ``import.json`` and, with a
    design, ``design.json``), written atomically; a rerun overwrites them.

    Parameters
    ----------
    files : list of path
        Rig files (module docstring), one test each.
    out : path
        The dataset folder (created).
    ratio, design
        Exactly one: the reducer's ratio N, or its design (a Design, a design dict or JSON file),
        which is also written to ``design.json``.
    load_Nm, speed_rpm, temperature_C : float or None
        Conditions of every file; each one not given is read from the file name (``1800.0rpm0.0Nm25.0deg``).
    samples_per_rev : int or None
        Readings per output revolution kept (0: every reading; default :func:`default_samples_per_rev`).
    sample_rate_Hz : float
        The rig's sample rate, for files without a ``time_s`` column.
    test : str or None
        One test id for all the files (runs measured after one homing); default: one test per file
        (its name without the extension).

    Returns
    -------
    dict
        ``dataset`` (folder), ``ratio``, ``samples_per_rev``, ``files`` (per file: ``file``, ``test``,
        conditions, ``conditions_from``, ``runs``: per run ``run``, ``direction``, ``readings``,
        ``revolutions``, ``speed_rpm_from_readings``, ``noise_arcsec_readings`` (the noise of the readings as read,
        :func:`rvrig.dataset.noise_estimate`: at the rig's density the TE is smooth from one reading to
        the next; after averaging down the same estimate also takes in the orders near the new band's end),
        ``samples``, ``samples_per_rev``, ``gaps``, ``time_from``, ``filter``), ``notes``.
    """
    if not files:
        raise OptionError("no rig file given", field="FILES", value=[], allowed="one or more CSV files")
    n_ratio, des = _reducer(ratio, design)
    fs = float(sample_rate_Hz)
    if not (math.isfinite(fs) and fs > 0):
        raise OptionError(f"--sample-rate-Hz {sample_rate_Hz!r} must be > 0", field="--sample-rate-Hz",
                          value=sample_rate_Hz, allowed="> 0")
    k = default_samples_per_rev(n_ratio, des.z_pins if des else None) if samples_per_rev is None else int(samples_per_rev)
    if k < 0 or (0 < k < 16):
        raise OptionError(f"--samples-per-rev {samples_per_rev} must be 0 (every reading) or at least 16",
                          field="--samples-per-rev", value=samples_per_rev, allowed="0 or >= 16")
    paths = [Path(f) for f in files]
    stems = [p.stem for p in paths]
    if len(set(stems)) < len(stems):
        raise OptionError(f"two files have the same name {sorted({s for s in stems if stems.count(s) > 1})}; the run "
                          "ids are made from the file names", field="FILES", value=stems, allowed="distinct names")
    runs, samples, summary = [], [], []
    for p in paths:
        cond = file_conditions(p, load_Nm, speed_rpm, temperature_C)
        recs = read_rig_file(p, fs)
        tid = test if test is not None else p.stem
        per = []
        for d, rec in recs.items():
            rid = f"{p.stem}_{'fw' if d > 0 else 'bw'}"
            arr, info = decimate(rec, k)
            samples.append(pd.DataFrame({"run": rid, "input_deg": n_ratio * (arr["output_deg"] - arr["te_deg"]),
                                         "output_deg": arr["output_deg"], "time_s": arr["time_s"]}))
            runs.append({"run": rid, "test": tid, "load_Nm": cond.load_Nm, "direction": d,
                         "speed_rpm": cond.speed_rpm, "temperature_C": cond.temperature_C})
            per.append({"run": rid, "direction": d, "readings": int(rec.output_deg.size),
                        "revolutions": rec.revolutions, "speed_rpm_from_readings": rec.input_speed_rpm(n_ratio),
                        "noise_arcsec_readings": noise_estimate(rec.te_deg * 3600.0),
                        "samples": int(arr["output_deg"].size),
                        "samples_per_rev": info["samples_per_rev"], "gaps": rec.gaps, "time_from": rec.time_source,
                        "filter": info["filter"], "dropped_segments": info["dropped_segments"]})
        summary.append({"file": str(p), "test": tid, "load_Nm": cond.load_Nm, "speed_rpm": cond.speed_rpm,
                        "temperature_C": cond.temperature_C, "conditions_from": cond.source, "runs": per})
    runs_df = _runs_table(runs)
    result = {"dataset": str(out), "ratio": n_ratio, "samples_per_rev": k, "sample_rate_Hz": fs,
              "design": des.to_dict() if des is not None else None, "files": summary, "notes": _notes(summary, k)}
    _write(Path(out), runs_df, pd.concat(samples, ignore_index=True), des, n_ratio, result)
    return result


def _runs_table(runs: list[dict]) -> pd.DataFrame:
    """runs.csv: a condition column only when every file has it (a partly known condition is refused)."""
    df = pd.DataFrame(runs)
    for col, opt in (("speed_rpm", "--speed-rpm"), ("temperature_C", "--temperature-C")):
        known = df[col].notna()
        if known.all():
            continue
        if known.any():
            missing = df.loc[~known, "run"].iloc[0]
            raise OptionError(f"{col} is known for some files but not for run {missing}: give {opt} or name every "
                              "file like '1800.0rpm0.0Nm25.0deg.csv'", field=opt, value=None, allowed="a value")
        df = df.drop(columns=[col])
    return df


def _notes(summary: list[dict], k: int) -> list[str]:
    """What the import did that a user should know, one sentence each."""
    notes = []
    for f in summary:
        parsed = sorted(key for key, src in f["conditions_from"].items() if src == "file name")
        if parsed:
            notes.append(f"{Path(f['file']).name}: {', '.join(parsed)} read from the file name")
        for r in f["runs"]:
            notes.extend(_gap_notes(r["run"], r["gaps"], r["time_from"]))
            for s in r["dropped_segments"]:
                notes.append(f"run {r['run']}: the segment of {s['readings']} readings from output "
                             f"{s['from_output_deg']:.6g} deg is shorter than the anti-alias filter: not written")
            given, seen = f["speed_rpm"], r["speed_rpm_from_readings"]
            if given is not None and math.isfinite(seen) and abs(seen / given - 1.0) > 0.01:
                notes.append(f"run {r['run']}: the readings give an input speed of {seen:.5g} rpm, not the {given:g} "
                             f"rpm declared: check --sample-rate-Hz ({r['time_from']}) and --ratio")
            if r["filter"] is None and k > 0:
                notes.append(f"run {r['run']}: {r['samples_per_rev']:.6g} readings per revolution, not more than the "
                             f"{k} asked: every reading kept")
    return notes


_GAP_WHAT = {"filled": "filled by interpolation before the low-pass only (no reading written there)",
             "split": "the record is split there (no reading written in the gaps)",
             "position jump": "jumps in position without a gap in time (kept as measured)"}


def _gap_notes(run: str, gaps: list[dict], time_from: str) -> list[str]:
    """One sentence per kind of gap of a run: how many, how large, where (the list is in import.json)."""
    notes = []
    for kind, what in _GAP_WHAT.items():
        g = [x for x in gaps if x["kind"] == kind]
        if not g:
            continue
        at = [x["at_output_deg"] for x in g]
        sp = [x["spacings"] for x in g]
        size = f"{min(sp):.3g}" if max(sp) - min(sp) < 0.5 else f"{min(sp):.3g} to {max(sp):.3g}"
        where = f"at output {at[0]:.6g} deg" if len(g) == 1 else (
            f"between output {min(at):.6g} and {max(at):.6g} deg (every {(max(at) - min(at)) / (len(g) - 1):.3g} deg "
            "on average)")
        timing = "; the times count the readings missing" if kind != "position jump" and "rate" in time_from else ""
        notes.append(f"run {run}: {len(g)} gap(s) of {size} sample spacings ({sum(x['missing'] for x in g)} readings "
                     f"missing) {where}: {what}{timing}")
    return notes


def _write(out: Path, runs: pd.DataFrame, samples: pd.DataFrame, design: Design | None, ratio: float,
           result: dict) -> None:
    """Write the dataset atomically, runs.csv last (a folder without it is incomplete, and a rerun redoes it)."""
    if out.exists() and not out.is_dir():
        raise OptionError(f"--out '{out}' exists and is not a folder", field="--out", value=str(out), allowed="a folder")
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(out, WRITTEN)
    if design is None:
        _check_existing_design(out, ratio)
    (out / "runs.csv").unlink(missing_ok=True)
    with atomic_path(out / "samples.csv") as tmp:
        samples.to_csv(tmp, index=False, float_format="%.12g")
    if design is not None:
        with atomic_path(out / "design.json") as tmp:
            tmp.write_text(json.dumps(design.to_dict(), indent=2) + "\n", encoding="utf-8")
    with atomic_path(out / "import.json") as tmp:
        tmp.write_text(json.dumps(result, indent=2, default=float) + "\n", encoding="utf-8")
    with atomic_path(out / "runs.csv") as tmp:
        runs.to_csv(tmp, index=False, float_format="%.12g")
