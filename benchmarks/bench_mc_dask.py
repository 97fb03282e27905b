"""Benchmark of the full-solver Monte Carlo stage on a Dask LocalCluster with 1 and 2 workers.

Run: ``python benchmarks/bench_mc_dask.py [--draws 40] [--sobol 0] [--workers 1,2] [--steps 360]``.

For each worker count a ``dask.distributed.LocalCluster(n_workers=N, threads_per_worker=1,
processes=True)`` is started on loopback and the ``mc`` stage of ``rv-stackup`` (default tolerances:
every feature of every Table 4 error, analytic solver, 360 steps, the four play/rigidity solves) runs on
it through ``--scheduler`` exactly as ``rv-stackup --scheduler ADDRESS --stages mc`` would, without a
cache (every draw is solved). A warm-up of 2 draws first loads the package into the workers. Printed per
worker count: draws, wall time of the stage, draws per second, draws per second per worker, the workers'
busy time per draw, and the wall time 100,000 draws would take at that rate (extrapolated linearly:
the draws are independent tasks, so the rate holds as long as the scheduler keeps every worker busy;
tasks of ~0.1-1 s are far above Dask's ~1 ms per-task overhead).

The machine is shared: keep ``--draws`` modest (40 draws x 5 solves is about a minute on one worker).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a clone without installing
os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep)
                                                          if p])  # the Dask worker processes too

from results_log import record, slug  # noqa: E402
from rvstudy.study import StudyConfig, run_study  # noqa: E402

TARGET_DRAWS = 100_000


def run_mc(address: str, draws: int, sobol: int, steps: int, out: Path) -> dict:
    """The ``mc`` stage on the cluster at ``address``; returns its timing dict."""
    cfg = StudyConfig(out=out, solver="analytic", steps=steps, scheduler=address, stages=("mc",), mc_draws=draws,
                      mc_sobol=sobol, mc_check=0, use_cache=False, progress=False, figures=False)
    t = time.perf_counter()
    res = run_study(cfg)
    t = time.perf_counter() - t
    return {**res.mc["timing"], "study_wall_s": t, "failed": int((res.mc["draws"]["status"] != "ok").sum())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--draws", type=int, default=40, help="independent draws per run (default 40)")
    ap.add_argument("--sobol", type=int, default=0, help="designed-sample block size (default 0: none)")
    ap.add_argument("--workers", default="1,2", help="comma list of worker counts (default 1,2)")
    ap.add_argument("--steps", type=int, default=360, help="steps per output revolution (default 360)")
    a = ap.parse_args()
    from dask.distributed import LocalCluster

    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-mc-dask-") as tmp:
        for n in [int(x) for x in a.workers.split(",")]:
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                              dashboard_address=None) as cluster:
                run_mc(cluster.scheduler_address, 2, 0, a.steps, Path(tmp) / f"warm{n}")  # import into the workers
                t = run_mc(cluster.scheduler_address, a.draws, a.sobol, a.steps, Path(tmp) / f"run{n}")
            rate = t["full_solver_draws"] / t["wall_s"]
            rows.append((n, t, rate))
            print(f"{n} worker(s): {t['full_solver_draws']} draws ({t['independent_draws']} independent + "
                  f"{t['design_draws']} designed, {t['failed']} failed) in {t['wall_s']:.1f} s wall: "
                  f"{rate:.3f} draws/s, {rate / n:.3f} draws/s per worker; worker busy {t['worker_s']:.1f} s "
                  f"({t['worker_s'] / t['full_solver_draws']:.3f} s per draw, "
                  f"{t['draws_per_s_per_worker']:.3f} draws per worker-second); "
                  f"{TARGET_DRAWS:,} draws at this rate: {TARGET_DRAWS / rate / 3600:.2f} h "
                  f"({TARGET_DRAWS / rate / 60:.0f} min)", flush=True)
    record("bench_mc_dask", [(slug(f"{n} workers {a.steps} steps draws per s"), rate, "1/s") for n, _, rate in rows])
    if len(rows) > 1:
        (n1, _, r1), (n2, _, r2) = rows[0], rows[-1]
        print(f"scaling {n1} -> {n2} workers: draws/s x{r2 / r1:.2f} (ideal x{n2 / n1:.2f}); parallel efficiency "
              f"{(r2 / n2) / (r1 / n1):.2f}")
    print(f"machine: {os.cpu_count()} cores; load average {os.getloadavg()[0]:.2f} (the machine is shared: "
          "a load above the core count slows every worker)")


if __name__ == "__main__":
    main()
