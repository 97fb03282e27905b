"""``rv-calibrate DATASET --out DIR [--reducer DESIGN.json] [--json] [--steps N]``: the closed loop on
measured data.

Reads the dataset folder (``runs.csv``, ``samples.csv``, optionally ``design.json``: the reducer
measured; ``--reducer`` names it when the folder does not; see :mod:`rvcalib.dataset`), runs
:func:`rvcalib.identify.calibrate`, writes the report (:mod:`rvcalib.report`) into ``--out`` and
prints a human summary, or with ``--json`` one JSON object (``reducer``, ``ratio``, ``rms_before_arcsec``,
``rms_after_arcsec``, ``effects`` = list of ``{name, value, unit, ci_low, ci_high, ...}``,
``unexplained``, per-run figures under ``runs``). Bad input: a message naming the file and column
on stderr, exit status 2.
"""
from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence

from rvcalib.dataset import read_dataset
from rvcalib.orders import STEPS_MAX


def build_parser() -> argparse.ArgumentParser:
    """The argument parser."""
    p = argparse.ArgumentParser(
        prog="rv-calibrate",
        description="Close the loop on measured TE data: residual -> missing effect -> model update -> "
                    "error before and after.")
    p.add_argument("dataset", metavar="DATASET", help="folder with runs.csv and samples.csv")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for report.md, figures and result.json")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")
    p.add_argument("--reducer", default=None, metavar="DESIGN.json",
                   help="the reducer measured: a design JSON (the 'design' object of a case JSON, e.g. "
                        "{\"z_sun\": 18, \"z_planet\": 36}); default: DATASET/design.json, else the paper's design")
    p.add_argument("--steps", type=int, default=None, metavar="N",
                   help="requested screening grid, points per output revolution; used when it resolves the "
                        "reducer's orders that matter without aliasing (a multiple of the pin count, above twice "
                        "the highest input order) and is at most 720, else the smallest grid that does is used and "
                        f"the report says so (default: that grid; at most {STEPS_MAX})")
    p.add_argument("--alpha", type=float, default=0.01, help="family-wise significance level (default 0.01)")
    p.add_argument("--max-terms", type=int, default=6, help="largest number of effects + empirical terms (default 6)")
    p.add_argument("--screen-points", type=int, default=None,
                   help="explicit screening grid, points per output revolution; refused unless it resolves the "
                        "orders that matter (default: the smallest grid that does)")
    p.add_argument("--time-budget", type=float, default=None, metavar="SECONDS",
                   help="stop adding terms after this many seconds (the result says so; default: no budget)")
    p.add_argument("--verbose", action="store_true", help="progress messages on stderr")
    return p


def summary(res, paths: dict) -> str:
    """Human summary printed by default."""
    red = res.dataset.reducer()
    lines = [res.verdict, "",
             f"reducer: ratio {red['ratio']:g} (Z1 {red['z_sun']}, Z2 {red['z_planet']}, {red['z_pins']} pins), "
             f"design from {'the default (paper) design' if red['source'] == 'default' else red['source']}"]
    lines.append(f"residual RMS: before {res.rms_before:.4g} arcsec, after {res.rms_after:.4g} arcsec "
                 f"(noise {res.noise_arcsec:.4g} arcsec)")
    if res.effects:
        lines.append("effects:")
        for e in res.effects:
            ang = f" at {e.angle_deg:.1f} deg" if e.angle_deg is not None else ""
            alt = (" (indistinguishable: " + ", ".join(f"{a['name']} {a['value']:.4g} {a['unit']}" for a in e.alternatives[:3])
                   + ")") if e.alternatives else ""
            if e.implied_total is not None:
                alt += f"; declared {e.declared_value:.5g}, implied total {e.implied_total:.5g} {e.unit}"
            lines.append(f"  {e.name} = {e.value:.5g} {e.unit}{ang}, 95 % [{e.ci_low:.5g}, {e.ci_high:.5g}]{alt}")
    if res.unexplained:
        lines.append("unexplained (outside the library):")
        for u in res.unexplained:
            ph = f", phase {u.phase_deg:.1f} deg" if u.phase_deg is not None else ""
            lines.append(f"  {u.label}: {abs(u.amplitude_arcsec):.4g} arcsec{ph}")
    for g in res.groups:
        mem = ", ".join(f"{m['name']} {m['value']:.4g} {m['unit']}" for m in g["members"][:4])
        lines.append(f"group ({g['kind']}): {mem}")
    for rec in res.recommended_runs:
        if rec.get("run"):
            lines.append(f"recommended run to split {', '.join(rec['members'][:3])}: load {rec['run']['load_Nm']:g} N m, "
                         f"direction {rec['run']['direction']:+d}")
    if res.stopped_by and not res.stopped_by.startswith("nothing"):
        lines.append(f"stopped: {res.stopped_by}")
    lines.append("runs (RMS before -> after, arcsec):")
    for run, b, a in zip(res.dataset.runs, res.before.runs, res.after.runs):
        lines.append(f"  {run.run}: load {run.load_Nm:g} N m, dir {run.direction:+d}: {b.rms:.4g} -> {a.rms:.4g}")
    for n in res.dataset.notes:
        lines.append(f"note: {n}")
    lines.append(f"report: {paths['report']}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (0 ok, 2 bad input)."""
    args = build_parser().parse_args(argv)
    from rvcalib.identify import calibrate
    from rvcalib.report import result_json, write_report

    try:
        for opt, v in (("--steps", args.steps), ("--screen-points", args.screen_points)):
            if v is not None and not 1 <= v <= STEPS_MAX:
                raise ValueError(f"{opt} {v} must lie in [1, {STEPS_MAX}] points per output revolution")
        if not (0 < args.alpha < 1 and math.isfinite(args.alpha)):
            raise ValueError(f"--alpha {args.alpha} must lie in (0, 1)")
        if args.time_budget is not None and not (math.isfinite(args.time_budget) and 0 < args.time_budget <= 86400):
            raise ValueError(f"--time-budget {args.time_budget} must lie in (0, 86400] seconds")
        if not 1 <= args.max_terms <= 50:
            raise ValueError(f"--max-terms {args.max_terms} must lie in [1, 50]")
        ds = read_dataset(args.dataset, design=args.reducer)
        steps = args.steps
        log = (lambda s: print(f"rv-calibrate: {s}", file=sys.stderr, flush=True)) if args.verbose else None
        res = calibrate(ds, steps=steps, alpha=args.alpha, max_terms=args.max_terms, log=log,
                        screen_points=args.screen_points, time_budget_s=args.time_budget)
        paths = write_report(res, args.out)
    except ValueError as exc:
        print(f"rv-calibrate: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(result_json(res, paths["figures"], paths["report"]))
    else:
        print(summary(res, paths))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
