"""Synthetic measured datasets for the rig tests: runs of one output revolution of a ratio-81 reducer whose TE is
a function of the output angle and time, written in the dataset format (conventions, "Measured data"), and rig
files in the shared rig layout (output angle and TE per direction, sampled at a fixed rate)."""
from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

#: A ratio-81 design (40 pins, 39 lobes, two cranks: the default's other sizes).
R81 = {"z_sun": 18, "z_planet": 36}
RATIO = 81.0


def write_dataset(folder: Path, runs: list[dict], per_rev: int = 720) -> Path:
    """Write ``runs.csv``, ``samples.csv`` and ``design.json`` (ratio 81).

    Each run is a dict with ``run``, ``load_Nm``, ``direction``, ``te`` (a function of the output angle in
    deg and the time in s giving arcsec), optional ``test``, ``speed_rpm`` and ``seconds_per_rev`` (default 1).
    """
    folder.mkdir(parents=True, exist_ok=True)
    rows, samples = [], []
    for r in runs:
        d = r["direction"]
        th = (np.arange(per_rev) + 0.25) * 360.0 / per_rev
        th = th if d > 0 else 360.0 - th
        t = np.arange(per_rev) * r.get("seconds_per_rev", 1.0) / per_rev
        te: Callable = r["te"]
        out = th
        inp = RATIO * (out - te(th, t) / 3600.0)
        samples.append(pd.DataFrame({"run": r["run"], "input_deg": inp, "output_deg": out, "time_s": t}))
        rows.append({k: r[k] for k in ("run", "load_Nm", "direction", "test", "speed_rpm") if k in r})
    pd.DataFrame(rows).to_csv(folder / "runs.csv", index=False)
    pd.concat(samples, ignore_index=True).to_csv(folder / "samples.csv", index=False, float_format="%.12g")
    (folder / "design.json").write_text(json.dumps(R81))
    return folder


def cos_orders(terms: dict[float, tuple[float, float]]) -> Callable:
    """TE ``sum A cos(k theta + phi)`` (arcsec) from ``{k: (A, phi_deg)}``, theta the output angle."""
    def te(th: np.ndarray, t: np.ndarray) -> np.ndarray:
        r = np.radians(th)
        return sum(a * np.cos(k * r + np.radians(p)) for k, (a, p) in terms.items())
    return te


#: The shared rig layout's header: output angle and TE per direction (the source's spelling).
HEADER = ["Poisition_Output_Reducer_Fw", "Transmission_Error_Fw", "Position_Output_Reducer_Bw", "Transmission_Error_Bw"]
ARCSEC = 1.0 / 3600.0


def te_arcsec(theta_deg: np.ndarray, terms: dict[float, float], const: float = 0.0) -> np.ndarray:
    """``const + sum a cos(k theta)`` (theta the output angle, deg)."""
    th = np.radians(theta_deg)
    return const + sum(a * np.cos(k * th) for k, a in terms.items())


def rig_file(path: Path, per_rev: int = 2000, revs: float = 1.0, terms=None, consts=(-20.0, 15.0),
             drop: tuple[int, ...] = (), wrap: bool = False) -> Path:
    """A rig file: ``per_rev`` readings per output revolution, forward 0 -> 360 and backward 360 -> 0;
    ``drop``: reading indices left out of both directions (gaps); ``wrap``: positions modulo 360."""
    terms = {1: 30.0, 39: 4.0} if terms is None else terms
    n = int(round(per_rev * revs))
    keep = np.setdiff1d(np.arange(n), drop)
    fw = (np.arange(n) + 0.5) * 360.0 / per_rev
    bw = 360.0 * np.ceil(revs) - fw
    cols = []
    for pos, c in ((fw, consts[0]), (bw, consts[1])):
        pos = pos[keep]
        cols += [np.mod(pos, 360.0) if wrap else pos, te_arcsec(pos, terms, c) * ARCSEC]
    pd.DataFrame(dict(zip(HEADER, cols))).to_csv(path, index=False, float_format="%.10f")
    return path
