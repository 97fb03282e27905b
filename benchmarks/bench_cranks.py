"""Benchmark: one output revolution at 720 steps with three crankshafts against two, one core.

Run: ``python benchmarks/bench_cranks.py [--solver analytic fcl] [--contact impact physical] [--steps 720]
[--repeat 2] [--no-record]``. Times the default design with its two cranks (0, 180 deg) and with three (0, 120,
240 deg), the nominal case and a cam phase of 5 um on crank 1, and the RV-160N-like example
(``examples/designs/rv160n.json``, three cranks); prints seconds per revolution (wall and CPU, best of --repeat)
and the three-crank time over the two-crank one, and appends the figures to ``benchmarks/results.csv``
(``results_log.record``). The goal: three cranks within 1.5 times the two-crank time.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a clone without installing

import numpy as np  # noqa: E402

from rvcad.errors import Case  # noqa: E402
from rvdyn.contacts import ContactLaw  # noqa: E402
from rvdyn.te import run_te  # noqa: E402
from results_log import record  # noqa: E402


def _time(case: Case, solver: str, steps: int, contact: str, repeat: int) -> tuple[float, float]:
    """Best wall and CPU seconds of one revolution of ``case``."""
    best = cpu = np.inf
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        run_te(case, solver, steps, law=ContactLaw(kind=contact))
        best = min(best, time.perf_counter() - t)
        cpu = min(cpu, time.process_time() - c)
    return best, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--solver", nargs="+", default=["analytic"])
    ap.add_argument("--contact", nargs="+", default=["impact", "physical"])
    ap.add_argument("--steps", type=int, default=720)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--no-record", action="store_true", help="print only, do not append to results.csv")
    a = ap.parse_args()
    rv160n = json.loads((ROOT / "examples" / "designs" / "rv160n.json").read_text())["design"]
    cams = {"cam_phase": {"value": 5.0, "crank": 1}}
    cases = {
        ("nominal", 2): Case.from_dict({"name": "two"}),
        ("nominal", 3): Case.from_dict({"name": "three", "design": {"crank_angles_deg": [0, 120, 240]}}),
        ("cam_phase", 2): Case.from_dict({"name": "two-cam", "errors": cams}),
        ("cam_phase", 3): Case.from_dict({"name": "three-cam", "design": {"crank_angles_deg": [0, 120, 240]},
                                          "errors": cams}),
        ("rv160n", 3): Case.from_dict({"name": "rv160n", "design": rv160n}),
    }
    figures = []
    for solver in a.solver:
        for contact in a.contact:
            run_te(cases[("nominal", 3)], solver, 8, law=ContactLaw(kind=contact))        # compile and warm up
            secs = {}
            for (name, n), case in cases.items():
                wall, cpu = _time(case, solver, a.steps, contact, a.repeat)
                secs[(name, n)] = cpu
                print(f"{solver:8s} {contact:8s} {name:10s} {n} cranks  {a.steps} steps: {wall:6.3f} s/rev wall, "
                      f"{cpu:6.3f} s CPU", flush=True)
                figures.append((f"{solver}_{contact}_{name}_{n}_cranks_{a.steps}_steps_cpu_seconds", cpu, "s"))
            for name in ("nominal", "cam_phase"):
                r = secs[(name, 3)] / secs[(name, 2)]
                print(f"{solver:8s} {contact:8s} {name:10s} three cranks / two: {r:.3f} (goal <= 1.5)")
                figures.append((f"{solver}_{contact}_{name}_3_over_2_cranks_cpu_ratio", r, "ratio"))
    if not a.no_record:
        print(f"recorded in {record('bench_cranks', figures)}")


if __name__ == "__main__":
    main()
