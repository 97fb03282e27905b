"""``rv-stackup``: the paper's whole study plus a Monte Carlo tolerance stack-up, in one command.

``rv-stackup [--out DIR] [--scheduler ADDRESS]`` with no other option runs the default study
(see :mod:`rvstudy.study`) and writes ``DIR/report.md``; a rerun with the same options reuses every
solved case from ``DIR/cache`` and an interrupted run resumes where it stopped. Prints a human
summary (or one JSON object with ``--json``) and, last, where the report is. Bad options print a
message naming the option and exit with status 2.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from rvcad import validation as v
from rvcad.errors import MAX_LOAD_NM
from rvdyn.contacts import ContactLaw
from rvdyn.runner import SchedulerError
from rvdyn.te import SOLVERS
from rvstudy.montecarlo import default_tolerances, load_tolerances, parse_tolerance
from rvstudy.study import DEFAULT_SEED, DEFAULT_STEPS, DESIGNS, STAGES, StudyConfig, run_study

DEFAULT_SOLVER = "fcl"


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of ``rv-stackup``."""
    p = v.ArgumentParser(
        prog="rv-stackup",
        description="Single-factor screen, Box-Behnken response surface, validation and Monte Carlo "
                    "tolerance stack-up of the RV reducer's transmission error (paper sections 4.2-5).",
        epilog="Defaults reproduce the paper's study. Tolerance syntax: KEY=normal:SIGMA[:MEAN] | "
               "uniform:LOW:HIGH | triangular:LOW:MODE:HIGH | fixed:VALUE | none (values in the error's "
               "unit, um or deg).")
    p.add_argument("--out", default="rv-stackup-out", help="output folder (default rv-stackup-out)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask distributed scheduler address (e.g. tcp://127.0.0.1:8786); default: local processes")
    p.add_argument("--scheduler-timeout", type=float, default=20.0, metavar="S",
                   help="seconds to wait for the Dask scheduler (default 20)")
    p.add_argument("--workers", type=int, default=2, help="local worker processes (default 2; 1 = this process)")
    p.add_argument("--solver", choices=SOLVERS, default=DEFAULT_SOLVER,
                   help=f"contact provider (default {DEFAULT_SOLVER})")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS,
                   help=f"steps per output revolution (default {DEFAULT_STEPS})")
    p.add_argument("--load-Nm", dest="load_Nm", type=float, default=20.0, help="output load torque, N m (default 20)")
    p.add_argument("--K", type=float, default=ContactLaw.K, help="contact stiffness, N/mm^n (default 2e5)")
    p.add_argument("--n", type=float, default=ContactLaw.n, help="contact force exponent (default 1.5)")
    p.add_argument("--design", choices=DESIGNS, default="bbd", help="response-surface design (default bbd)")
    p.add_argument("--ccd-alpha", default="rotatable",
                   help="CCD axial distance: rotatable, face or a number in coded units (default rotatable)")
    p.add_argument("--center", type=int, default=None, help="centre runs (default 3)")
    p.add_argument("--levels", default=None, metavar="CSV",
                   help="factors and levels: factor,low,center,high[,unit][,error] (default paper Table 5)")
    p.add_argument("--factors", nargs="+", default=None, metavar="F", help="factors of the levels table to use")
    p.add_argument("--sweep-points", type=int, default=7, help="points per factor sweep (default 7)")
    p.add_argument("--validation-cases", dest="n_validation", type=int, default=15,
                   help="random validation cases (default 15, as the paper)")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"seed of the random draws (default {DEFAULT_SEED})")
    p.add_argument("--mc-samples", type=int, default=20000, help="Monte Carlo draws through the surfaces (default 20000)")
    p.add_argument("--mc-check", type=int, default=100,
                   help="Monte Carlo draws through the full solver with all 11 errors (default 100)")
    p.add_argument("--tolerance", action="append", default=[], metavar="KEY=DIST:PARAMS",
                   help="tolerance of one error type (repeatable); default every type normal(0, paper value/3)")
    p.add_argument("--tolerances", default=None, metavar="FILE",
                   help="tolerance file: CSV error,dist,p1,p2,p3 or JSON {key: 'dist:params'}")
    p.add_argument("--spec-arcmin", type=float, default=1.0, help="TE peak-to-peak spec for the yield (default 1)")
    p.add_argument("--stages", default=",".join(STAGES),
                   help=f"comma list of stages to run (default {','.join(STAGES)})")
    p.add_argument("--cache", default=None, metavar="DIR", help="case cache folder (default OUT/cache)")
    p.add_argument("--no-cache", action="store_true", help="solve every case again and store nothing")
    p.add_argument("--no-figures", action="store_true", help="write tables and the report without PNG figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")
    return p


def check_sizes(args: argparse.Namespace) -> None:
    """Upper bounds of the size options and the output folders (OptionError naming the option and bound).

    The bounds come from the memory and time budget in :mod:`rvcad.validation` (one solve within
    ``MEMORY_BUDGET_BYTES``; at most ``MAX_CASES`` full-solver cases per option); the lower bounds
    stay in :meth:`StudyConfig.validate`.
    """
    v.steps_option(args.steps)
    v.option_real(args.K, "--K", 0.0, v.MAX_CONTACT_K, lo_open=True, unit="N/mm^n", why="stiffer is the rigid limit")
    v.option_real(args.load_Nm, "--load-Nm", 0.0, MAX_LOAD_NM, unit="N m")
    v.option_real(args.spec_arcmin, "--spec-arcmin", 0.0, 60.0, lo_open=True, unit="arcmin",
                  why="a TE peak-to-peak spec; 60 arcmin is a degree")
    v.option_real(args.scheduler_timeout, "--scheduler-timeout", 0.0, 3600.0, lo_open=True, unit="s")
    v.option_int(args.workers, "--workers", 1, v.MAX_WORKERS, why="local processes of about 160 MB each")
    v.option_int(args.sweep_points, "--sweep-points", 2, v.MAX_SWEEP_POINTS, why="each point is one solve per factor")
    v.option_int(args.n_validation, "--validation-cases", 0, v.MAX_CASES, why="each is one full solve")
    v.option_int(args.mc_check, "--mc-check", 0, v.MAX_CASES, why="each is one full solve")
    v.option_int(args.mc_samples, "--mc-samples", 100, v.MAX_MC_SAMPLES, why="about 1 kB per draw")
    if args.center is not None:
        v.option_int(args.center, "--center", 0, v.MAX_CENTER_RUNS, why="each is one full solve")
    v.output_dir(args.out)
    if args.cache:
        v.output_dir(args.cache, "--cache")


def config_from_args(args: argparse.Namespace) -> StudyConfig:
    """StudyConfig from parsed options; ValueError naming the option on bad values."""
    check_sizes(args)
    tols = default_tolerances()
    if args.tolerances:
        tols.update(load_tolerances(args.tolerances))
    for t in args.tolerance:
        tol = parse_tolerance(t)
        tols[tol.error] = tol
    stages = tuple(s.strip() for s in str(args.stages).split(",") if s.strip())
    cfg = StudyConfig(
        out=Path(args.out), solver=args.solver, steps=args.steps, load_Nm=args.load_Nm, workers=args.workers,
        scheduler=args.scheduler, scheduler_timeout_s=args.scheduler_timeout, design=args.design, ccd_alpha=args.ccd_alpha, center=args.center,
        levels=args.levels, factors=args.factors, sweep_points=args.sweep_points, n_validation=args.n_validation,
        seed=args.seed, mc_samples=args.mc_samples, mc_check=args.mc_check, tolerances=tols,
        spec_arcmin=args.spec_arcmin, cache_dir=Path(args.cache) if args.cache else None,
        use_cache=not args.no_cache, stages=stages, K=args.K, n=args.n,
        progress=not args.no_progress and sys.stderr.isatty(), figures=not args.no_figures)
    cfg.validate()
    return cfg


def _human(summary: dict[str, Any], report: Path) -> str:
    c = summary.get("cases", {})
    t = summary.get("timings_s", {})
    lines = [f"rv-stackup: {summary['config']['solver']} solver, {summary['config']['steps']} steps, "
             f"{summary['executor']}",
             f"  cases: {c.get('computed', 0)} solved, {c.get('reused', 0)} reused from the cache, "
             f"{c.get('failed', 0)} failed; wall time {t.get('total', float('nan')):.1f} s"]
    sc = summary.get("stage_check")
    if sc:
        pp = sc["pp"]
        lines.append(f"  screen: stage I errors B/C rank {pp['rank_B']}/{pp['rank_C']} of 11 by TE pp; "
                     f"below every stage II error: {'yes' if pp['reproduced'] else 'no'}")
    for resp in ("mean_abs_arcmin", "pp_arcmin"):
        r = summary.get(resp)
        if not r:
            continue
        if "error" in r:
            lines.append(f"  {resp}: no fit ({r['error']})")
            continue
        v = r.get("validation", {}).get("full", {})
        r2 = r.get("r2")
        lines.append(f"  {resp}: R2 {r2:.4f}, R2adj {r['r2_adj']:.4f}; paper-mode terms "
                     f"{' + '.join(r['paper_mode_terms'][1:])}"
                     + (f"; validation RMSE {v['rmse']:.4g} arcmin, PI coverage {v['pi_coverage']:.2f}"
                        if v else ""))
    mc = summary.get("monte_carlo", {})
    for k, lab in (("yield_surface", "surface"), ("yield_solver", "full solver")):
        if k in mc and mc[k].get("yield") is not None:
            y = mc[k]
            lines.append(f"  yield (pp <= {summary['config']['spec_arcmin']:g} arcmin), {lab}: {100 * y['yield']:.1f} % "
                         f"[{100 * y['lower']:.1f}, {100 * y['upper']:.1f}] (n={y['n']})")
    for n in summary.get("notes", [])[:8]:
        lines.append(f"  note: {n}")
    lines.append(f"report: {report}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``rv-stackup``; returns the exit status (2 for bad options)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        cfg = config_from_args(args)
        res = run_study(cfg)
    except SchedulerError as exc:
        print(f"rv-stackup: error: --scheduler {exc.address!r}: {exc.reason}", file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"rv-stackup: error: {v.one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"rv-stackup: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("rv-stackup: interrupted; finished cases are in the cache, rerun the same command to resume",
              file=sys.stderr)
        return 130
    from rvstudy.report import summary, write_report

    report = write_report(res)
    s = summary(res)
    if args.json:
        print(json.dumps({**s, "report": str(report)}))
    else:
        print(_human(s, report))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
