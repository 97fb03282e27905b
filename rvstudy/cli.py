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
import math
import sys
from pathlib import Path
from typing import Any

from rvcad import validation as v
from rvcad.errors import MAX_LOAD_NM
from rvdyn.contacts import ContactLaw
from rvdyn.runner import SchedulerError
from rvdyn.te import SOLVERS
from rvstudy.montecarlo import default_tolerances, load_tolerances, parse_tolerance
from rvstudy.study import (
    DEFAULT_MC_CHECK,
    DEFAULT_MC_CONTACT,
    DEFAULT_MC_DRAWS,
    DEFAULT_MC_SOBOL,
    DEFAULT_SEED,
    DEFAULT_STEPS,
    DESIGNS,
    STAGES,
    StudyConfig,
    run_study,
)

DEFAULT_SOLVER = "analytic"


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of ``rv-stackup``."""
    p = v.ArgumentParser(
        prog="rv-stackup",
        description="Single-factor screen, Box-Behnken response surface, validation and Monte Carlo "
                    "tolerance stack-up of the RV reducer's transmission error (paper sections 4.2-5).",
        epilog="Defaults reproduce the paper's study. Tolerance syntax: KEY[SCOPE]=normal:SIGMA[:MEAN] | "
               "uniform:LOW:HIGH | truncnormal:SIGMA:LOW:HIGH[:MEAN] | triangular:LOW:MODE:HIGH | fixed:VALUE | "
               "none (values in the error's unit, um or deg); SCOPE each (every feature, default), common or "
               "default; KEY may be model.OPTION (an rvdyn model effect).")
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
    p.add_argument("--K", type=float, default=ContactLaw.K,
                   help="stiffness of the paper's impact law used by the paper-reproduction sections (and the "
                        "Monte Carlo with --mc-contact impact), N/mm^n (default 2e5)")
    p.add_argument("--n", type=float, default=ContactLaw.n, help="force exponent of that impact law (default 1.5)")
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
    p.add_argument("--mc-draws", "--mc-samples", dest="mc_draws", type=int, default=DEFAULT_MC_DRAWS,
                   help=f"Monte Carlo draws, each solved by the full (analytic) solver (default {DEFAULT_MC_DRAWS})")
    p.add_argument("--mc-sobol", type=int, default=DEFAULT_MC_SOBOL,
                   help=f"block size of the designed sample for the contributors: mc_sobol more solver draws per "
                        f"tolerance (default {DEFAULT_MC_SOBOL}; 0 = no contributors)")
    p.add_argument("--mc-check", type=int, default=DEFAULT_MC_CHECK,
                   help=f"Monte Carlo draws solved again with fcl to check the analytic solver (default {DEFAULT_MC_CHECK})")
    p.add_argument("--tolerance", action="append", default=[], metavar="KEY[SCOPE]=DIST:PARAMS",
                   help="tolerance of one error type or model.OPTION (repeatable); SCOPE each (default: every "
                        "feature independently), common or default; default every error type normal(0, paper "
                        "value/3) on every feature")
    p.add_argument("--tolerances", default=None, metavar="FILE",
                   help="tolerance file: CSV error,dist,p1,p2,p3[,p4][,scope] or JSON {key: 'dist:params'}")
    p.add_argument("--spec-arcmin", type=float, default=1.0, help="USL of TE peak-to-peak, arcmin (default 1)")
    p.add_argument("--play-spec-arcmin", type=float, default=1.0,
                   help="USL of the two-direction play at +-3 %% rated torque, arcmin (default 1)")
    p.add_argument("--spec", action="append", default=[], metavar="RESPONSE=LSL:USL",
                   help="specification limits of a Monte Carlo response (empty = none), e.g. te_mean_abs_arcmin=:0.5")
    p.add_argument("--rated-Nm", dest="rated_Nm", type=float, default=167.0,
                   help="rated output torque, N m (default 167, the RV-20E class); the play is read at 3 %% of it")
    p.add_argument("--rigidity-lsl", type=float, default=49.0,
                   help="LSL of the torsional rigidity, N m/arcmin (default 49, the RV-20E datasheet figure)")
    p.add_argument("--mc-contact", choices=ContactLaw.KINDS, default=DEFAULT_MC_CONTACT,
                   help=f"contact law of the Monte Carlo solves: physical (Hertz, ISO 6336, elastic supports; default "
                        f"{DEFAULT_MC_CONTACT}, about 3.5x the cost of a draw) or impact (paper Eq. 1, --K/--n, "
                        "as every paper-reproduction section uses)")
    p.add_argument("--yield-target", type=float, default=0.9973,
                   help="yield the tolerance allocation aims at (default 0.9973)")
    p.add_argument("--reducer", default=None, metavar="DESIGN.json",
                   help="the reducer: a design JSON (rvcad.Design fields, e.g. {\"z_sun\": 18, \"z_planet\": 36}); "
                        "default the paper's")
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
    v.option_int(args.mc_draws, "--mc-draws", 0, v.MAX_MC_DRAWS, why="each draw is one full solve and ~2 kB")
    v.option_int(args.mc_sobol, "--mc-sobol", 0, v.MAX_CASES, why="each block adds one full solve per tolerance")
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
    limits = {}
    for text in args.spec:
        limits.update(parse_spec_limits(text))
    cfg = StudyConfig(
        out=Path(args.out), solver=args.solver, steps=args.steps, load_Nm=args.load_Nm, workers=args.workers,
        scheduler=args.scheduler, scheduler_timeout_s=args.scheduler_timeout, design=args.design, ccd_alpha=args.ccd_alpha, center=args.center,
        levels=args.levels, factors=args.factors, sweep_points=args.sweep_points, n_validation=args.n_validation,
        seed=args.seed, mc_draws=args.mc_draws, mc_sobol=args.mc_sobol, mc_check=args.mc_check, tolerances=tols,
        spec_arcmin=args.spec_arcmin, play_spec_arcmin=args.play_spec_arcmin, spec_limits=limits,
        rated_Nm=args.rated_Nm, rigidity_lsl=args.rigidity_lsl, mc_contact=args.mc_contact, yield_target=args.yield_target, reducer=args.reducer, cache_dir=Path(args.cache) if args.cache else None,
        use_cache=not args.no_cache, stages=stages, K=args.K, n=args.n,
        progress=not args.no_progress and sys.stderr.isatty(), figures=not args.no_figures)
    cfg.validate()
    return cfg


def parse_spec_limits(text: str) -> dict[str, tuple[float | None, float | None]]:
    """``RESPONSE=LSL:USL`` (either may be empty) -> ``{response: (lsl, usl)}``; ValueError names ``--spec``."""
    if "=" not in text or ":" not in text.split("=", 1)[1]:
        raise ValueError(f"--spec {text!r} must look like RESPONSE=LSL:USL, e.g. te_pp_arcmin=:1.0")
    key, lim = text.split("=", 1)
    lo_s, hi_s = lim.split(":", 1)
    try:
        lo = float(lo_s) if lo_s.strip() else None
        hi = float(hi_s) if hi_s.strip() else None
    except ValueError:
        raise ValueError(f"--spec {text!r}: LSL and USL must be numbers or empty") from None
    for limit in (lo, hi):
        if limit is not None and not math.isfinite(limit):
            raise ValueError(f"--spec {text!r}: limits must be finite")
    return {key.strip(): (lo, hi)}


def headline_from_summary(mc: dict[str, Any]) -> list[str]:
    """Summary lines of the full-solver Monte Carlo from the ``monte_carlo`` object of the summary."""
    from rvstudy.report_mc import _lim, _num, _pct
    from rvstudy.capability import ci_text

    out = []
    for r, c in mc.items():
        if not isinstance(c, dict) or "n_solver_draws" not in c or (c["usl"] is None and c["lsl"] is None):
            continue
        lo, hi = c["out_of_spec_ci"]
        out.append(f"  full solver, {c['n_solver_draws']} draws: {r} mean {_num(c['mean'])} sigma {_num(c['std'])}; "
                   f"spec {_lim(c['lsl'])}..{_lim(c['usl'])}: Cpk {_num(c['cpk'], 3)}, out of spec "
                   f"{_pct(c['out_of_spec_fraction'])} (95 % CI {ci_text(lo if lo is not None else float('nan'), hi if hi is not None else float('nan'))})")
    t = mc.get("timing") or {}
    if t:
        out.append(f"  Monte Carlo: {t['full_solver_draws']} full-solver draws ({t.get('independent_draws', '?')} "
                   f"independent + {t.get('design_draws', '?')} designed) in {t['wall_s']:.0f} s wall, "
                   f"{t['draws_per_s_per_worker']:.3g} draws/s per worker ({t['workers']} workers)")
    return out


def _human(summary: dict[str, Any], report: Path) -> str:
    c = summary.get("cases", {})
    t = summary.get("timings_s", {})
    red = summary.get("reducer", {})
    lines = [f"rv-stackup: {summary['config']['solver']} solver, {summary['config']['steps']} steps, "
             f"{summary['executor']}" + (f"; reducer {red['description']}" if red else ""),
             f"  cases: {c.get('computed', 0)} solved, {c.get('reused', 0)} reused from the cache, "
             f"{c.get('failed', 0)} failed; wall time {t.get('total', float('nan')):.1f} s"
             + (f", {t['command']:.1f} s with the report" if "command" in t else "")]
    if summary.get("monte_carlo"):  # the full-solver figures lead
        lines += headline_from_summary(summary["monte_carlo"])
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
    for n in summary.get("notes", [])[:8]:
        lines.append(f"  note: {n}")
    lines.append(f"report: {report}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``rv-stackup``; returns the exit status (2 for bad options)."""
    import time

    t_main = time.perf_counter()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        cfg = config_from_args(args)
        res = run_study(cfg)
    except SchedulerError as exc:
        print(f"rv-stackup: error: --scheduler {exc.address!r}: {exc.reason}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as exc:
        return v.refuse("rv-stackup", exc)
    except KeyboardInterrupt:
        print("rv-stackup: interrupted; finished cases are in the cache, rerun the same command to resume",
              file=sys.stderr)
        return 130
    from rvstudy.report import summary, write_report

    t_rep = time.perf_counter()
    report = write_report(res)
    s = summary(res)
    s["timings_s"]["report"] = time.perf_counter() - t_rep
    s["timings_s"]["command"] = time.perf_counter() - t_main  # from the parsed options to the written report
    if args.json:
        print(json.dumps({**s, "report": str(report)}))
    else:
        print(_human(s, report))
    if not useful(res):
        print(f"rv-stackup: error: no stage gave a result ({res.counters.get('failed', 0)} cases failed, no fit); "
              f"the report says what failed: {report}", file=sys.stderr)
        return 1
    return 0


def useful(res: Any) -> bool:
    """Whether the run produced anything to read: a screen, a fitted surface, Monte Carlo statistics or the
    Table 6 readings."""
    fitted = any(b.results is not None for b in res.fits.values())
    rr = getattr(res, "readings", None)
    readings_ok = rr is not None and bool(rr.table["r"].notna().any())
    mc_ok = bool(res.mc) and any(c.get("n_failed", 0) < c.get("n_solver_draws", 0)
                                 for c in res.mc.get("responses", {}).values())
    screen_ok = res.screen is not None and bool(res.screen.screen["pp_arcsec"].notna().any())
    return fitted or mc_ok or screen_ok or readings_ok


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
