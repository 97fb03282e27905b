"""Benchmark of ``rv-stackup``: cost of one case per solver, and the whole default study.

Run::

    python benchmarks/bench_stackup.py                       # per-case cost, analytic and fcl, 360 steps
    python benchmarks/bench_stackup.py --steps 360 720 --solver analytic
    python benchmarks/bench_stackup.py --full --solver fcl    # the default study, no cache, wall time

The per-case part solves three representative cases (error free; a BBD edge run EA=+0.06 deg,
ED=-14 um; a validation-like interior point) one after another in this process and prints the seconds
per case. ``--full`` runs ``rv-stackup`` on its defaults (plus ``--solver``/``--steps`` if given) into a
temporary folder with ``--no-cache`` and prints the wall time and the stage breakdown; the budget of
the README's main command is 480 s on a 2-core machine (>= 2,000 full-solver Monte Carlo draws
included); the Monte Carlo's draws per second per worker and the machine's load average are printed. The figures
are recorded in ``benchmarks/results.csv``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a clone without installing

from results_log import record, slug  # noqa: E402
from rvstudy.screen import make_case  # noqa: E402
from rvdyn.te import run_te  # noqa: E402

CASES = {
    "error free": {},
    "BBD run 14 (EA=+0.06 deg, ED=-14 um)": {"pin_pitch": 0.06, "disc_hole_eccentricity": -14.0},
    "interior (EA=0.02, EB=5, EC=-3, ED=6)": {"pin_pitch": 0.02, "pin_circle_diameter": 5.0, "pin_radius": -3.0,
                                              "disc_hole_eccentricity": 6.0},
}


def per_case(solvers: list[str], steps_list: list[int]) -> None:
    figures = []
    for solver in solvers:
        for steps in steps_list:
            times = []
            for name, errs in CASES.items():
                c = make_case(errs, name)
                t = time.perf_counter()
                try:
                    r = run_te(c, solver, steps)
                    msg = f"pp {r.stats['pp']:8.3f} arcsec  mean|TE| {r.stats['mean_abs']:8.3f} arcsec"
                except Exception as exc:  # noqa: BLE001 - report and go on
                    msg = f"failed: {type(exc).__name__}: {str(exc)[:80]}"
                dt = time.perf_counter() - t
                times.append(dt)
                print(f"{solver:8s} {steps:5d} steps  {name:40s} {dt:7.2f} s  {msg}", flush=True)
            print(f"{solver:8s} {steps:5d} steps  mean {sum(times) / len(times):.2f} s per case", flush=True)
            figures.append((slug(f"{solver} {steps} steps mean per case wall"), sum(times) / len(times), "s"))
    record("bench_stackup", figures)


def full(solver: str | None, steps: int | None, workers: int) -> None:
    with tempfile.TemporaryDirectory() as d:
        cmd = [sys.executable, "-m", "rvstudy", "--out", d, "--no-cache", "--no-progress", "--json",
               "--workers", str(workers)]
        if solver:
            cmd += ["--solver", solver]
        if steps:
            cmd += ["--steps", str(steps)]
        import resource

        load0 = os.getloadavg()
        t = time.perf_counter()
        r = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t
        load1 = os.getloadavg()
        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = ru.ru_utime + ru.ru_stime
        if r.returncode != 0:
            print(r.stderr)
            raise SystemExit(r.returncode)
        s = json.loads(r.stdout)
        c = s["cases"]
        print(f"default study ({' '.join(cmd[3:])}): wall {wall:.1f} s (budget 480 s); CPU of all processes "
              f"{cpu:.1f} s (on an otherwise idle 2-core machine the wall time is about max(CPU / 2, serial parts))")
        print("  stages [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in s["timings_s"].items()))
        print(f"  cases: {c['computed']} solved, {c['failed']} failed, solver s/case mean {c['solve_seconds_mean']:.2f}, "
              f"median {c['solve_seconds_median']:.2f}; report + imports {wall - s['timings_s']['total']:.1f} s")
        mc = s.get("monte_carlo", {}).get("timing")
        if mc:
            print(f"  Monte Carlo: {mc['full_solver_draws']} full-solver draws ({mc['independent_draws']} independent + "
                  f"{mc['design_draws']} designed), {mc['solves_per_draw']} solves each, in {mc['wall_s']:.1f} s: "
                  f"{mc['draws_per_s_per_worker']:.3f} draws/s per worker ({mc['workers']} workers)")
        figures = [("default_study_wall", wall, "s"), ("default_study_cpu", cpu, "s"),
                   ("default_study_cases_solved", c["computed"], "count")]
        if mc:
            figures.append(("default_study_mc_draws_per_s_per_worker", mc["draws_per_s_per_worker"], "1/s"))
        record("bench_stackup", figures)
        print(f"  machine load average (1/5/15 min) before {load0[0]:.1f}/{load0[1]:.1f}/{load0[2]:.1f}, after "
              f"{load1[0]:.1f}/{load1[1]:.1f}/{load1[2]:.1f} on {os.cpu_count()} cores (shared machine)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--solver", nargs="+", default=None)
    ap.add_argument("--steps", nargs="+", type=int, default=[360])
    ap.add_argument("--full", action="store_true", help="run the whole default study and time it")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    if a.full:
        full(a.solver[0] if a.solver else None, a.steps[0] if a.steps != [360] else None, a.workers)
    else:
        per_case(a.solver or ["analytic", "fcl"], a.steps)


if __name__ == "__main__":
    main()
