"""Synthetic measured datasets for the rig tests: runs of one output revolution of a ratio-81 reducer whose TE is
a function of the output angle and time, written in the dataset format (conventions, "Measured data")."""
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
