"""``rv-calibrate DATASET --out DIR [--json] [--steps N]``: the closed loop on measured data.

Reads the dataset folder (``runs.csv``, ``samples.csv``; see :mod:`rvcalib.dataset`), runs
:func:`rvcalib.identify.calibrate`, writes the report (:mod:`rvcalib.report`) into ``--out`` and
prints a human summary, or with ``--json`` one JSON object (``rms_before_arcsec``,
``rms_after_arcsec``, ``effects`` = list of ``{name, value, unit, ci_low, ci_high, ...}``,
``unexplained``, per-run figures under ``runs``). Bad input: a message naming the file and column
on stderr, exit status 2.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from rvcad import validation as v
from rvcad.params import Design
from rvcalib.dataset import MeasuredDataset, read_dataset


def auto_steps(ds: MeasuredDataset) -> int:
    """Model grid for a dataset (screening and grid fits): its samples per output revolution when
    every run is sampled on the same uniform grid of a multiple of 40 points (then the screening
    sees every sample), else 360. Residuals and final fits solve the model at every reading
    whatever the grid."""
    per = set()
    for r in ds.runs:
        n = r.n / max(r.revolutions, 1e-12)
        per.add(int(round(n)))
    if len(per) == 1:
        n = per.pop()
        if n % 40 == 0 and 40 <= n <= 1440:
            return n
    return 360


def build_parser() -> argparse.ArgumentParser:
    """The argument parser."""
    p = v.ArgumentParser(
        prog="rv-calibrate",
        description="Close the loop on measured TE data: residual -> missing effect -> model update -> "
                    "error before and after.")
    p.add_argument("dataset", metavar="DATASET", help="folder with runs.csv and samples.csv")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for report.md, figures and result.json")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")
    p.add_argument("--steps", type=int, default=None, metavar="N",
                   help="model grid points per output revolution, a multiple of 40 (default: the samples per "
                        "revolution when the runs are sampled on such a grid, else 360)")
    p.add_argument("--alpha", type=float, default=0.01, help="family-wise significance level (default 0.01)")
    p.add_argument("--max-terms", type=int, default=6, help="largest number of effects + empirical terms (default 6)")
    p.add_argument("--screen-points", type=int, default=120,
                   help="largest screening grid, points per output revolution (default 120)")
    p.add_argument("--verbose", action="store_true", help="progress messages on stderr")
    return p


def check_options(args: argparse.Namespace) -> None:
    """Ranges of the options, before the dataset is read (OptionError naming the option and its bound).

    ``--steps`` and ``--screen-points`` are bounded by :data:`rvcad.validation.MAX_GRID_STEPS` (the
    time budget of the grid solves), ``--max-terms`` by :data:`rvcad.validation.MAX_TERMS`; the
    screening grid needs more than two points per period of the pin order Zp (sampling theorem),
    i.e. at least 2 Zp + 1 points per output revolution.
    """
    if args.steps is not None:
        v.option_int(args.steps, "--steps", 40, v.MAX_GRID_STEPS, why="the time budget of the grid solves")
        if args.steps % 40:
            raise v.OptionError(f"--steps {args.steps} is not a multiple of 40; allowed: a multiple of 40 in "
                                f"[40, {v.MAX_GRID_STEPS}]", field="--steps", value=args.steps)
    v.option_real(args.alpha, "--alpha", 0.0, 1.0, lo_open=True, hi_open=True)
    v.option_int(args.max_terms, "--max-terms", 1, v.MAX_TERMS, why="effects plus empirical terms the loop may add")
    zp = Design().z_pins
    v.option_int(args.screen_points, "--screen-points", 2 * zp + 1, v.MAX_GRID_STEPS,
                 why=f"more than 2 points per period of the pin order {zp}")
    v.output_dir(args.out)


def summary(res, paths: dict) -> str:
    """Human summary printed by default."""
    lines = [res.verdict, ""]
    lines.append(f"residual RMS: before {res.rms_before:.4g} arcsec, after {res.rms_after:.4g} arcsec "
                 f"(noise {res.noise_arcsec:.4g} arcsec)")
    if res.effects:
        lines.append("effects:")
        for e in res.effects:
            ang = f" at {e.angle_deg:.1f} deg" if e.angle_deg is not None else ""
            alt = f" (indistinguishable: {', '.join(e.alternatives[:3])})" if e.alternatives else ""
            lines.append(f"  {e.name} = {e.value:.5g} {e.unit}{ang}, 95 % [{e.ci_low:.5g}, {e.ci_high:.5g}]{alt}")
    if res.unexplained:
        lines.append("unexplained (outside the library):")
        for u in res.unexplained:
            ph = f", phase {u.phase_deg:.1f} deg" if u.phase_deg is not None else ""
            lines.append(f"  {u.label}: {abs(u.amplitude_arcsec):.4g} arcsec{ph}")
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
        check_options(args)
        ds = read_dataset(args.dataset)
        steps = args.steps if args.steps is not None else auto_steps(ds)
        log = (lambda s: print(f"rv-calibrate: {s}", file=sys.stderr, flush=True)) if args.verbose else None
        res = calibrate(ds, steps=steps, alpha=args.alpha, max_terms=args.max_terms, log=log,
                        screen_points=args.screen_points)
        paths = write_report(res, args.out)
    except ValueError as exc:
        print(f"rv-calibrate: error: {v.one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"rv-calibrate: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 2
    if args.json:
        print(result_json(res, paths["figures"], paths["report"]))
    else:
        print(summary(res, paths))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
