"""Timing of the rsm hot paths (run: ``python benchmarks/bench_rsm.py``).

Prints one line per case: mean wall time over repeats, and records them in ``benchmarks/results.csv``. Not a
test; no thresholds.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a clone without installing

from results_log import record, slug  # noqa: E402
import rsm  # noqa: E402
from rvpaper import DATA_DIR as PAPER_DATA  # noqa: E402

DATA = PAPER_DATA
FIGURES: list[tuple[str, float, str]] = []


def _time(label: str, fn, repeat: int = 5) -> None:
    fn()
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    ms = 1e3 * (time.perf_counter() - t0) / repeat
    print(f"{label:<48} {ms:9.2f} ms")
    FIGURES.append((slug(label.split(" (")[0]), ms, "ms"))


def main() -> None:
    runs = pd.read_csv(DATA / "paper_table6_bbd_runs.csv")
    levels = rsm.Levels.from_csv(DATA / "paper_table5_levels.csv")
    factors = ["EA", "EB", "EC", "ED"]
    res = rsm.fit(runs, factors, "te_arcmin", levels=levels)
    _time("fit full quadratic, Table 6 (27 runs, 15 terms)",
          lambda: rsm.fit(runs, factors, "te_arcmin", levels=levels))
    _time("backward elimination (hierarchical)", lambda: rsm.backward_elimination(res))
    _time("compare_reductions", lambda: rsm.compare_reductions(res))
    new = pd.DataFrame(np.random.default_rng(0).uniform(-1, 1, size=(10_000, 4)), columns=factors)
    _time("predict 10k points with intervals", lambda: res.predict(new))
    _time("bounded minimum (multi-start L-BFGS-B)", lambda: res.optimum("min"))
    d7 = rsm.box_behnken(7, center=6).coded
    d7["y"] = np.random.default_rng(1).normal(size=len(d7))
    names = [f"x{i + 1}" for i in range(7)]
    _time("BBD k=7 design + quadratic fit (62 runs, 36 terms)",
          lambda: rsm.fit(rsm.box_behnken(7, 6).coded.assign(y=d7["y"]), names, "y"))
    record("bench_rsm", FIGURES)


if __name__ == "__main__":
    main()
