"""Benchmark of the TE solvers: one output revolution at 720 steps, two discs, one core.

Run: ``python benchmarks/bench_te.py [--solver analytic fcl] [--contact impact physical] [--steps 720] [--load0]``.
Prints seconds per revolution (wall and CPU, best of --repeat), peak resident memory, and with ``--compare``
for fcl the agreement with the analytic solver (RMS and max TE difference, arcsec) on the nominal case and on
each Table 4 error at its paper value. ``--load0`` adds the 6 um cam-bearing clearance at load 0 (the rigid
limit; analytic solver only: the slowest case).
"""
from __future__ import annotations

import argparse
import os
import resource
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a clone without installing

from results_log import record, slug  # noqa: E402
from rvcad.errors import ERROR_TYPES, Case  # noqa: E402
from rvdyn.contacts import ContactLaw  # noqa: E402
from rvdyn.te import run_te  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--solver", nargs="+", default=["analytic", "fcl"])
    ap.add_argument("--steps", type=int, default=720)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--compare", action="store_true", help="fcl vs analytic on every Table 4 error")
    ap.add_argument("--contact", nargs="+", default=["impact", "physical"],
                    help="contact laws to time (physical: bearings and crankshafts on)")
    ap.add_argument("--load0", action="store_true", help="add the 6 um clearance at load 0 (analytic only)")
    a = ap.parse_args()
    cases = {"nominal": Case.from_dict({"name": "nominal"}),
             "pin_pitch 0.01 deg": Case.from_dict({"errors": {"pin_pitch": 0.01}}),
             "cam clearance 6 um": Case.from_dict({"model": {"cam_bearing_clearance_um": 6.0}})}
    if a.load0:
        cases["clearance 6 um, load 0"] = Case.from_dict({"model": {"cam_bearing_clearance_um": 6.0}, "load_Nm": 0.0})
    figures = []
    for solver in a.solver:
        for contact in a.contact:
            for name, case in cases.items():
                if solver != "analytic" and name.endswith("load 0"):
                    continue
                best = cpu = np.inf
                for _ in range(a.repeat):
                    t, c = time.perf_counter(), time.process_time()
                    r = run_te(case, solver, a.steps, law=ContactLaw(kind=contact))
                    best = min(best, time.perf_counter() - t)
                    cpu = min(cpu, time.process_time() - c)
                print(f"{solver:8s} {contact:8s} {name:20s} {a.steps} steps: {best:6.3f} s/rev wall, {cpu:6.3f} s CPU  "
                      f"pp {r.stats['pp']:8.4f} arcsec  mean {r.stats['mean']:9.4f} arcsec")
                figures.append((slug(f"{solver} {contact} {name} {a.steps} steps cpu"), cpu, "s"))
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS {rss:.0f} MB")
    figures.append(("peak_rss", rss, "MB"))
    if a.compare and "fcl" in a.solver:
        print(f"fcl vs analytic ({a.contact[-1]} law), TE difference (arcsec):")
        all_cases = {"nominal": {}} | {k: {k: et.paper_value} for k, et in ERROR_TYPES.items()}
        for name, errs in all_cases.items():
            c = Case.from_dict({"errors": errs})
            ra = run_te(c, "analytic", a.steps, law=ContactLaw(kind=a.contact[-1]))
            rf = run_te(c, "fcl", a.steps, law=ContactLaw(kind=a.contact[-1]))
            d = rf.table["te_arcsec"].to_numpy() - ra.table["te_arcsec"].to_numpy()
            print(f"  {name:28s} rms {np.sqrt(np.mean(d ** 2)):.4f}  max {np.abs(d).max():.4f}  "
                  f"(analytic pp {ra.stats['pp']:.3f}, fcl {rf.stats['seconds']:.2f} s)")
            figures.append((slug(f"fcl vs analytic {a.contact[-1]} {name} rms"), float(np.sqrt(np.mean(d ** 2))),
                            "arcsec"))
    record("bench_te", figures)


if __name__ == "__main__":
    main()
