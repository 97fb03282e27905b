"""Where a loop run spends its time: rvdyn solves and solver seconds by loop stage, and a cProfile.

Runs the 5-run benchmark dataset of ``bench_calibrate.py`` (default) or one realistic draw
(``--realistic-seed S``) with the data and the model on one contact law (``--law impact|physical``),
wraps the forward model's batch call (:func:`rvcalib.forward.te_at_many`) to attribute every batch to
the loop stage that asked for it (the innermost method of the loop's classes on the call stack), and
prints per stage: batches, cases asked, unique solves (cache misses), solver seconds, and the solver's work
in states linearised and taken through the inner solve (outer iterations x states: a measure that does not
depend on the machine's load, unlike the seconds). With
``--cprofile FILE`` the run is profiled as well and the 25 largest cumulative entries are printed.

Run: ``python benchmarks/profile_calibrate.py [--law impact] [--realistic-seed S --max-terms 12
--time-budget B] [--cprofile out.prof] [--cache DIR] [--data DIR] [--json FILE]``. ``--cache`` keeps every
solve on disk (a rerun on the same code reads the same path back; its CPU seconds then count only the new
solves), ``--data`` writes the dataset to a folder kept for diagnoses. It prints figures only (no asserts).
"""
from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results_log import record, slug  # noqa: E402
from rvcalib import forward  # noqa: E402
from rvcalib.dataset import read_dataset  # noqa: E402
from rvcalib.identify import calibrate  # noqa: E402
from rvcalib.simulate import simulate_dataset, standard_runs  # noqa: E402
from rvdyn.contacts import ContactLaw  # noqa: E402
from rvdyn.runner import Runner  # noqa: E402

#: modules whose methods are loop stages (the innermost on the stack names the stage)
STAGE_MODULES = ("rvcalib/screening.py", "rvcalib/fitting.py", "rvcalib/selection.py", "rvcalib/joint.py",
                 "rvcalib/swaps.py", "rvcalib/groups.py", "rvcalib/identify.py", "rvcalib/replace.py")


def stage_of_stack() -> str:
    """``outer > inner`` names of the two innermost loop-stage frames on the call stack."""
    f = sys._getframe(2)
    names: list[str] = []
    while f is not None and len(names) < 2:
        fn = f.f_code.co_filename.replace("\\", "/")
        if any(fn.endswith(m) for m in STAGE_MODULES):
            nm = f.f_code.co_name
            if not names or names[-1] != nm:
                names.append(nm)
        f = f.f_back
    return " > ".join(reversed(names)) or "(outside the loop)"


def instrument() -> dict:
    """Wrap :func:`rvcalib.forward.te_at_many` (seen by the model through its module) to count by stage."""
    stats: dict = defaultdict(lambda: [0, 0, 0, 0.0])
    orig = forward.te_at_many

    def wrapped(case_dicts, input_deg, solver="analytic", **kw):
        r = forward.forward_runner()
        c0 = r.computed
        t0 = time.process_time()
        out = orig(case_dicts, input_deg, solver, **kw)
        st = stats[stage_of_stack()]
        st[0] += 1
        st[1] += len(case_dicts)
        st[2] += r.computed - c0
        st[3] += time.process_time() - t0
        return out

    forward.te_at_many = wrapped
    import rvcalib.model as model_mod
    model_mod.te_at_many = wrapped
    return stats


def count_rows() -> dict:
    """Wrap the solver's linearisation and inner solve to count the states they take (a work measure that
    does not depend on the machine's load): ``linearised`` rows of the outer iterations, ``inner`` rows."""
    from rvdyn.solver import QuasiStaticSolver
    n = {"linearised": 0, "inner": 0}
    lin, inner = QuasiStaticSolver._linearise, QuasiStaticSolver._inner

    def _linearise(self, th_in, x, direction):
        n["linearised"] += int(np.shape(x)[0])
        return lin(self, th_in, x, direction)

    def _inner(self, th_in, x0, *a, **k):
        n["inner"] += int(np.shape(x0)[0])
        return inner(self, th_in, x0, *a, **k)

    QuasiStaticSolver._linearise, QuasiStaticSolver._inner = _linearise, _inner
    return n


def five_run_dataset(root: Path) -> Path:
    """The dataset of ``bench_calibrate.py``'s default mode (same runs, truth, noise and seed)."""
    runs = [{"run": f"r{i + 1}", "load_Nm": L, "direction": d, "declared": {"cam_eccentricity": 5.0, "pin_radius": -2.0}}
            for i, (L, d) in enumerate([(10.0, 1), (10.0, -1), (20.0, 1), (30.0, 1), (30.0, -1)])]
    hidden = {"errors": {"pin_pitch": {"value": 0.02, "pin": 12}},
              "model": {"torsional_compliance_arcsec_per_Nm": 0.25}}
    simulate_dataset(root / "dataset", runs, hidden, samples_per_rev=360, seed=5,
                     transient={"runs": ["r1"], "amplitude_arcsec": 12.0, "tau_samples": 6.0,
                                "extra_revolutions": 0.15}, duplicates=6)
    return root / "dataset"


def realistic_dataset(root: Path, seed: int) -> tuple[Path, dict]:
    """Draw 0 of ``bench_calibrate.py --realistic 1 --seed S`` and its hidden truth."""
    from bench_calibrate import realistic_hidden
    rng = np.random.default_rng(seed)
    hidden = realistic_hidden(rng)
    simulate_dataset(root / "draw0", standard_runs((10.0, 30.0), (1, -1)), hidden, noise_arcsec=0.2,
                     input_noise_arcsec=1.0, samples_per_rev=333, start_deg=0.37, seed=100)
    return root / "draw0", hidden


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--law", choices=("impact", "physical"), default="impact")
    ap.add_argument("--realistic-seed", type=int, default=None)
    ap.add_argument("--max-terms", type=int, default=6)
    ap.add_argument("--time-budget", type=float, default=None)
    ap.add_argument("--cprofile", default=None, help="write a cProfile here and print its top entries")
    ap.add_argument("--json", default=None, help="write the result JSON here")
    ap.add_argument("--cold", action="store_true", help="no warm starts (every solve from the ideal kinematics)")
    ap.add_argument("--verbose", action="store_true", help="print the loop's progress")
    ap.add_argument("--cache", default=None, metavar="DIR",
                    help="keep every solve in this disk cache (reruns and diagnoses reuse them)")
    ap.add_argument("--data", default=None, metavar="DIR",
                    help="write the dataset here instead of a temporary folder")
    args = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    law = ContactLaw() if args.law == "impact" else None
    # the impact law must be named for truth and model alike; None leaves each case's own (physical)
    forward.use_runner(Runner(solver="analytic", memory_bytes=forward.CACHE_BYTES, law=law, cache=args.cache,
                              warm_bytes=0 if args.cold else forward.WARM_BYTES))
    root = Path(args.data) if args.data else Path(tempfile.mkdtemp(prefix="profile-calibrate-"))
    root.mkdir(parents=True, exist_ok=True)
    hidden = None
    if args.realistic_seed is not None:
        folder, hidden = realistic_dataset(root, args.realistic_seed)
    else:
        folder = five_run_dataset(root)
    forward.clear_cache()
    r = forward.forward_runner()
    sim_solves = r.computed
    stats = instrument()
    rows = count_rows()
    prof = cProfile.Profile() if args.cprofile else None
    t0, c0 = time.perf_counter(), time.process_time()
    if prof:
        prof.enable()
    log = (lambda m: print(f"  [{time.process_time() - c0:6.1f} s CPU] {m}", flush=True)) if args.verbose else None
    res = calibrate(read_dataset(folder), max_terms=args.max_terms, time_budget_s=args.time_budget, log=log)
    if prof:
        prof.disable()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"law {args.law}; dataset {folder}; calibration {wall:.1f} s wall, {cpu:.1f} s CPU; "
          f"rvdyn solves {r.computed - sim_solves}, solver s {sum(r.solve_seconds):.1f} (incl. simulation)")
    print(f"RMS {res.rms_before:.5g} -> {res.rms_after:.5g}; stopped by: {res.stopped_by}")
    print(f"solver work: {rows['linearised']} states linearised, {rows['inner']} states through the inner solve "
          f"(outer iterations x states, the loop only)")
    for e in res.effects:
        print(f"  {e.name} = {e.value:.7g} {e.unit} [{e.ci_low:.6g}, {e.ci_high:.6g}]")
    print(f"  unexplained: {[u.label for u in res.unexplained]}")
    if hidden is not None:
        from bench_calibrate import check_realistic
        noise = json.loads(folder.with_name(folder.name + ".answer.json").read_text())["noise_te_arcsec"]
        c = check_realistic(res, hidden, noise, cpu)
        print(f"  realistic-draw conditions (seconds: CPU): RMS after/noise {res.rms_after / noise:.2f} "
              f"{'ok' if c['rms_ok'] else 'FAIL'}; compliance {c['compliance']} {'ok' if c['compliance_ok'] else 'FAIL'}; "
              f"named {'ok' if c['named_ok'] else 'FAIL'}; CPU < 180 s {'ok' if c['seconds_ok'] else 'FAIL'}")
        for name, v, t, unit, ok in c["named"]:
            print(f"    {name} = {v:+.4g} {unit} vs truth of its type {t:+.4g}: {'ok' if ok else 'FAIL'}")
    print(f"{'stage':70s} {'batches':>7s} {'cases':>6s} {'solves':>6s} {'CPU s':>7s}")
    for k, (b, n, s, t) in sorted(stats.items(), key=lambda kv: -kv[1][3]):
        print(f"{k[:70]:70s} {b:7d} {n:6d} {s:6d} {t:7.1f}")
    tot = np.sum([v for v in stats.values()], axis=0) if stats else [0, 0, 0, 0]
    print(f"{'total forward':70s} {int(tot[0]):7d} {int(tot[1]):6d} {int(tot[2]):6d} {tot[3]:7.1f}")
    tag = f"{args.law} {'realistic' if hidden is not None else '5 runs'}"
    record("profile_calibrate", [(slug(f"{tag} cpu"), cpu, "s"), (slug(f"{tag} states linearised"), rows["linearised"],
                                                                  "count")])
    if args.json:
        Path(args.json).write_text(json.dumps(res.to_dict(), default=str, indent=1))
    if prof:
        prof.dump_stats(args.cprofile)
        pstats.Stats(prof).sort_stats("cumulative").print_stats(25)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
