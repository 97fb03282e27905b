"""Benchmark protocol of the calibration loop: the loop on a fixed set of realistic draws, scored by one rule.

For each seed of the set (:data:`realistic.DEV_SEEDS` or :data:`realistic.HELDOUT_SEEDS`, or a subset), it
draws the reducer (:mod:`realistic`; cached under ``--draws``, default ``OUT/draws``, so a rerun reuses it),
runs the loop with its DEFAULT options on the dataset alone (the answer is read only to score), times
it (wall and CPU seconds, the worker processes' CPU included), scores it (:mod:`score`: the pass rule and the
interval coverage) and writes ``OUT/seed<N>.json`` (``seed, set, method, workers, wall_s, cpu_s,
load_average, error, result, score``). A draw whose method raises is a fail, with the error printed. A
draw already scored in ``OUT`` by the same method is reused (``--fresh`` runs it again), so an
interrupted run resumes.

The loop is ``rvcalib.loop.calibrate(dataset, CalibrationSettings(workers=W)).to_dict()`` (method ``new``; a record
of another method, from an earlier protocol run, is shown by ``--report-only``). ``--workers 2`` gives the loop's
Jacobian two local processes, as ``rv-calibrate --workers 2``.

It prints one line per draw (verdict, RMS after against the noise, compliance, named effects, coverage,
seconds) with each named effect against its truth and the groups, then the summary: the pass count, the
pooled coverage of the named effects' 95 % intervals and the median wall and CPU seconds, which it
appends to ``benchmarks/results.csv`` (:mod:`results_log`, benchmark ``bench_loop``, figures
``<method>_<set>_passed`` ...; ``<method>_<set>_seeds_<s1>_<s2>..._...`` for a subset of the seeds).

Run: ``python benchmarks/bench_loop.py --set dev|heldout [--method new] [--seeds N ...] [--workers 1|2]
[--secant-width W] [--out DIR] [--draws DIR] [--fresh] [--verbose] [--report-only]`` (``--report-only``: the
table of the draws already run, none run, nothing recorded; ``--secant-width``: the loop with that setting, an
ablation, its method labelled ``new-secant-width-W``).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Callable

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_common import cpu_seconds  # noqa: E402
from rvcad.atomic import atomic_path  # noqa: E402
from realistic import SETS, generate, seeds_of  # noqa: E402
from score import pool, score, score_lines  # noqa: E402

#: ``new``: rv-calibrate with its default (sparse) estimator; ``tolerance-prior``: with the tolerance-prior one.
METHODS = ("new", "tolerance-prior")


def run_method(method: str, dataset: Any, log: Callable[[str], None] | None = None, workers: int = 1,
               **settings: Any) -> dict[str, Any]:
    """One method with its default options (but ``settings``, fields of ``CalibrationSettings``) on a dataset; the
    result in the schema (:mod:`score`)."""
    if method in METHODS:
        from rvcalib.loop import calibrate as calibrate_new
        from rvcalib.settings import CalibrationSettings

        est = "sparse" if method == "new" else method
        return calibrate_new(dataset, settings=CalibrationSettings(workers=workers, estimator=est, **settings),
                             log=log).to_dict()
    raise ValueError(f"method {method!r} is unknown; allowed: {list(METHODS)}")


def run_draw(seed: int, set_name: str, method: str, draws: Path, workers: int,
             verbose: bool = False, settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """Draw (or reuse), run and time one seed; returns the per-draw record (not yet scored). ``settings``: the
    fields of ``CalibrationSettings`` set other than by default; the record's method is then labelled with them."""
    from rvrig.dataset import read_dataset

    folder = generate(seed, draws)
    result, error = None, None
    t0, c0 = time.perf_counter(), cpu_seconds()
    log = (lambda s: print(f"    [{time.perf_counter() - t0:7.1f} s] {s}", flush=True)) if verbose else None
    try:
        result = run_method(method, read_dataset(folder / "dataset"), log, workers, **(settings or {}))
    except Exception as exc:  # a method that raises fails the draw; the protocol goes on
        error = f"{type(exc).__name__}: {exc}"
        traceback.print_exc()
    wall, cpu = time.perf_counter() - t0, cpu_seconds() - c0
    return {"seed": seed, "set": set_name, "method": label(method, settings), "workers": workers, "wall_s": wall,
            "cpu_s": cpu, "load_average": os.getloadavg()[0], "dataset": str(folder / "dataset"), "error": error,
            "result": result}


def label(method: str, settings: dict[str, Any] | None) -> str:
    """The method's label in records: its name, then each setting given as ``-name-value``."""
    return method + "".join(f"-{k.replace('_', '-')}-{v:g}" for k, v in sorted((settings or {}).items()))


def rescore(rec: dict[str, Any]) -> dict[str, Any]:
    """The record with its ``score`` from its result and its draw's answer (the scorer is cheap and
    deterministic, so a reused record is scored by the current rules)."""
    answer = json.loads((Path(rec["dataset"]).parent / "answer.json").read_text())
    return dict(rec, score=score(rec["result"], answer, rec["error"]))


def save(rec: dict[str, Any], path: Path) -> None:
    """Write a per-draw record atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(rec, indent=1, default=str), encoding="utf-8")


def draw_line(rec: dict[str, Any]) -> str:
    """One line of a draw's figures."""
    s = rec["score"]
    verdict = "PASS" if s["passed"] else "FAIL"
    if rec["error"]:
        return f"seed {rec['seed']}: {verdict} (raised) wall {rec['wall_s']:.0f} s"
    verd = [e["verdict"] for e in s["effects"]]
    comp = "/".join("none" if x is None else f"{x:.4g}" for x in (s["compliance"], s["compliance_truth"]))
    return (f"seed {rec['seed']}: {verdict}  RMS {s['rms_after']:.4g}/{s['noise']:.4g} = {s['rms_ratio']:.2f}x  "
            f"compliance {comp}  named {len(verd)} (off {verd.count('off')}, false "
            f"{verd.count('false name')}, small extra {verd.count('small extra')})  covered "
            f"{s['covered']}/{s['n_intervals']}  groups {len(s['groups'])}  wall {rec['wall_s']:.0f} s  "
            f"CPU {rec['cpu_s']:.0f} s  stopped by: {rec['result'].get('stopped_by', '')}")


def summary(recs: list[dict[str, Any]]) -> dict[str, Any]:
    """Pass count, pooled coverage and median seconds over the records."""
    p = pool([r["score"] for r in recs])
    p["median_wall_s"] = statistics.median(r["wall_s"] for r in recs) if recs else None
    p["median_cpu_s"] = statistics.median(r["cpu_s"] for r in recs) if recs else None
    p["raised"] = sum(bool(r["error"]) for r in recs)
    return p


def record_summary(method: str, set_name: str, seeds: list[int] | None, summ: dict[str, Any]) -> None:
    """Append the summary figures to ``benchmarks/results.csv`` (``seeds``: the subset run, None for the set)."""
    from results_log import record

    tag = f"{method}_{set_name}" + ("" if seeds is None else "_seeds_" + "_".join(str(s) for s in seeds))
    figs = [(f"{tag}_draws", summ["draws"], "count"), (f"{tag}_passed", summ["passed"], "count"),
            (f"{tag}_raised", summ["raised"], "count"), (f"{tag}_named", summ["n_intervals"], "count")]
    if summ["coverage"] is not None:
        figs.append((f"{tag}_coverage", summ["coverage"], "fraction"))
    if summ["median_wall_s"] is not None:
        figs += [(f"{tag}_median_wall_seconds", summ["median_wall_s"], "s"),
                 (f"{tag}_median_cpu_seconds", summ["median_cpu_s"], "s")]
    record("bench_loop", figs)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", required=True, choices=sorted(SETS), help="seed set")
    ap.add_argument("--method", default="new", choices=METHODS, help="the loop to run (default new)")
    ap.add_argument("--seeds", type=int, nargs="*", default=None, help="a subset of the set's seeds")
    ap.add_argument("--workers", type=int, default=1, choices=(1, 2), help="forward-model processes")
    ap.add_argument("--out", default=None, help="folder of the per-draw JSON (default ./bench-loop-METHOD-SET)")
    ap.add_argument("--draws", default=None, help="folder of the cached draws (default OUT/draws)")
    ap.add_argument("--fresh", action="store_true", help="run draws already scored in OUT again")
    ap.add_argument("--secant-width", dest="secant_width", type=float, default=None,
                    help="the loop's secant_width (default: its own); the method is then labelled with it")
    ap.add_argument("--verbose", action="store_true", help="print the method's progress")
    ap.add_argument("--report-only", action="store_true",
                    help="print the draws already run in OUT (scored again), run none and record nothing")
    args = ap.parse_args(argv)
    seeds = seeds_of(args.set, args.seeds)
    settings = {} if args.secant_width is None else {"secant_width": args.secant_width}
    method = label(args.method, settings)
    out = Path(args.out or f"bench-loop-{method}-{args.set}")
    draws = (Path(args.draws) if args.draws else out / "draws").resolve()
    out.mkdir(parents=True, exist_ok=True)
    print(f"{method} loop on the {args.set} set, seeds {seeds}, {args.workers} worker process(es); "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; draws in {draws}", flush=True)
    recs = []
    for seed in seeds:
        path = out / f"seed{seed}.json"
        old = json.loads(path.read_text()) if path.is_file() and not args.fresh else None
        if old is not None and old.get("method") == method:
            rec, note = old, "  (run by an earlier call, scored again)"
        elif args.report_only:
            continue
        else:
            rec, note = run_draw(seed, args.set, args.method, draws, args.workers, args.verbose, settings), ""
            save(rec, path)             # the run is kept even if the scoring fails
        rec = rescore(rec)
        save(rec, path)
        recs.append(rec)
        print(draw_line(rec) + note, flush=True)
        for line in (([rec["error"]] if rec["error"] else []) + rec["score"]["reasons"]
                     + score_lines(rec["score"])):
            print("    " + line, flush=True)
    if not recs:
        print("no draw run yet")
        return 1
    summ = summary(recs)
    cov = "none named" if summ["coverage"] is None else f"{summ['coverage']:.1%}"
    print(f"SUMMARY {method} {args.set}: {summ['passed']}/{summ['draws']} pass ({summ['raised']} raised); "
          f"pooled coverage {summ['covered']}/{summ['n_intervals']} = {cov}; median wall "
          f"{summ['median_wall_s']:.0f} s, median CPU {summ['median_cpu_s']:.0f} s ({args.workers} worker(s); "
          f"load average now {os.getloadavg()[0]:.1f})", flush=True)
    if not args.report_only:
        record_summary(method, args.set, None if set(seeds) == set(SETS[args.set]) else sorted(seeds), summ)
    return 0 if summ["passed"] == summ["draws"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
