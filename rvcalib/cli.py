"""``rv-calibrate DATASET --out DIR [--reducer DESIGN.json] [--json] [--steps N] [--workers N] [--cache DIR]``:
the closed loop on measured data.

Reads the dataset folder (``runs.csv``, ``samples.csv``, optionally ``design.json``: the reducer
measured; ``--reducer`` names it when the folder does not; see :mod:`rvcalib.dataset`), runs
:func:`rvcalib.identify.calibrate`, writes the report (:mod:`rvcalib.report`) into ``--out`` and
prints a human summary, or with ``--json`` one JSON object (``reducer``, ``ratio``, ``rms_before_arcsec``,
``rms_after_arcsec``, ``effects`` = list of ``{name, value, unit, ci_low, ci_high, ...}``,
``unexplained``, per-run figures under ``runs``). Bad input: a message naming the file and column
on stderr, exit status 2.

The model TE is solved by rvdyn's forward runner (:class:`rvdyn.runner.Runner`, see
:mod:`rvcalib.forward`): ``--workers`` local processes (default 2, as ``rv-stackup``) solve each batch of model states (the screening
signatures, the difference columns of a refit's Jacobian; a state's run conditions two and two, each pair in one
process as serially, so a single state spreads over two; every difference column warm-started from the state, as
serially; no result depends on which worker
finishes first: the result is the serial one bit for bit), ``--cache`` keeps
every solve on disk for later runs (the same cache format as ``rv-stackup --cache``).
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from rvcad import validation as v
from rvcad.errors import MAX_LOAD_NM
from rvcalib.causes import datasheet_of
from rvcalib.dataset import read_dataset


def build_parser() -> argparse.ArgumentParser:
    """The argument parser."""
    p = v.ArgumentParser(
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
                        f"the report says so (default: that grid; at most {v.MAX_GRID_STEPS})")
    p.add_argument("--alpha", type=float, default=0.01, help="family-wise significance level (default 0.01)")
    p.add_argument("--max-terms", type=int, default=6, help="largest number of effects + empirical terms (default 6)")
    p.add_argument("--screen-points", type=int, default=None,
                   help="explicit screening grid, points per output revolution; refused unless it resolves the "
                        "orders that matter (default: the smallest grid that does)")
    p.add_argument("--time-budget", type=float, default=None, metavar="SECONDS",
                   help="stop adding terms after this many seconds (the result says so; default: no budget)")
    p.add_argument("--workers", type=int, default=2,
                   help="local worker processes solving the model's batches (default 2, as rv-stackup; 1 = this "
                        "process; the result is the same bit for bit whatever the workers)")
    p.add_argument("--cache", default=None, metavar="DIR",
                   help="case cache folder kept for later runs (default: none; solves are kept in memory for this run)")
    p.add_argument("--rated-Nm", dest="rated_Nm", type=float, default=None, metavar="T",
                   help="rated output torque of the datasheet as calibrated, N m (default 167, the RV-20E class of "
                        "the paper's reducer; give your reducer's)")
    p.add_argument("--verbose", action="store_true", help="progress messages on stderr")
    return p


def _reducer_for_options(args: argparse.Namespace):
    """The reducer the options are checked against: ``--reducer``, else DATASET/design.json, else the
    default design (a bad design file is reported when the dataset is read)."""
    from rvcad.params import Design

    from rvcalib.dataset import load_design

    try:
        return load_design(args.reducer, Path(args.dataset))[0]
    except ValueError:
        return Design()


def check_options(args: argparse.Namespace) -> None:
    """Ranges of the options, before the dataset is read (OptionError naming the option and its bound).

    ``--steps`` and ``--screen-points`` are bounded by :data:`rvcad.validation.MAX_GRID_STEPS` (the
    time budget of the grid solves), ``--max-terms`` by :data:`rvcad.validation.MAX_TERMS`; both grids
    are multiples of the reducer's pin count Zp (``--steps``; pin-wise signatures shift by whole pin
    pitches) and ``--screen-points`` above 2 Zp (sampling theorem). Whether a grid resolves every
    order that matters (the input orders too) is checked once the dataset is read (:func:`rvcalib.orders.screen_grid`: ``--steps``
    that would alias is replaced by the smallest grid that does not, with a note; ``--screen-points``
    that would alias is refused).
    """
    zp = _reducer_for_options(args).z_pins
    if args.steps is not None:
        v.option_int(args.steps, "--steps", zp, v.MAX_GRID_STEPS, why="the time budget of the grid solves")
        if args.steps % zp:
            raise v.OptionError(f"--steps {args.steps} is not a multiple of {zp} (the pin count of the reducer); "
                                f"allowed: a multiple of {zp} in [{zp}, {v.MAX_GRID_STEPS}]", field="--steps",
                                value=args.steps)
    v.option_real(args.alpha, "--alpha", 0.0, 1.0, lo_open=True, hi_open=True)
    v.option_int(args.max_terms, "--max-terms", 1, v.MAX_TERMS, why="effects plus empirical terms the loop may add")
    if args.screen_points is not None:
        v.option_int(args.screen_points, "--screen-points", 2 * zp + 1, v.MAX_GRID_STEPS,
                     why=f"more than 2 points per period of the pin order {zp}")
    if args.time_budget is not None:
        v.option_real(args.time_budget, "--time-budget", 0.0, 86400.0, lo_open=True)
    v.option_int(args.workers, "--workers", 1, v.MAX_WORKERS, why="local processes of about 160 MB each")
    if args.rated_Nm is not None:
        v.option_real(args.rated_Nm, "--rated-Nm", 0.0, MAX_LOAD_NM, lo_open=True, unit="N m")
    if args.cache is not None:
        v.output_dir(args.cache, "--cache")
    v.output_dir(args.out)


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
            bnd = f" (at the {e.at_bound} bound of its range: a one-sided limit)" if e.at_bound else ""
            lines.append(f"  {e.name} = {e.value:.5g} {e.unit}{ang}, 95 % [{e.ci_low:.5g}, {e.ci_high:.5g}]{bnd}{alt}")
            for q in e.equivalents:
                if "default" in q:      # a compliance read as friction (a coefficient, no unit)
                    lines.append(f"    or, as Coulomb friction, {q['parameter']} = {q['value']:.4g} [{q['ci_low']:.4g}, "
                                 f"{q['ci_high']:.4g}] (the model's default {q['default']:g})")
                else:
                    lines.append(f"    the same TE as {q['parameter']} = {q['value']:+.5g} {q['unit']} [{q['ci_low']:.5g}, "
                                 f"{q['ci_high']:.5g}]")
    if res.unexplained:
        lines.append("unexplained (outside the library):")
        for u in res.unexplained:
            ph = f", phase {u.phase_deg:.1f} deg" if u.phase_deg is not None else ""
            lines.append(f"  {u.label}: {abs(u.amplitude_arcsec):.4g} arcsec{ph}")
            lines += [f"    or {q['parameter']} = {q['value']:+.5g} {q['unit']}" for q in u.equivalents]
    for g in res.groups:
        mem = ", ".join(f"{m['name']} {m['value']:.4g} {m['unit']}"
                        + "".join(f" (= {q['parameter']} {q['value']:+.4g} {q['unit']})" for q in m.get("equivalents", []))
                        for m in g["members"][:4])
        lines.append(f"group ({g['kind']}): {mem}")
    for rec in res.recommended_runs:
        if rec.get("run"):
            lines.append(f"recommended run to split {', '.join(rec['members'][:3])}: load {rec['run']['load_Nm']:g} N m, "
                         f"direction {rec['run']['direction']:+d}")
    ds = res.datasheet
    if ds.get("calibrated"):
        m, c = ds["model"], ds["calibrated"]
        ci = ds.get("rigidity_ci")
        lines.append(f"datasheet at {c['rated_torque_Nm']:g} N m rated (rvdyn stiffness): torsional rigidity "
                     f"{m['torsional_rigidity_Nm_per_arcmin']:.4g} (declared) -> {c['torsional_rigidity_Nm_per_arcmin']:.4g}"
                     + (f" [{ci[0]:.4g}, {ci[1]:.4g}]" if ci else "") + " N m/arcmin calibrated; lost motion "
                     f"{m['lost_motion_arcmin']:.3g} -> {c['lost_motion_arcmin']:.3g} arcmin")
    elif ds.get("error"):
        lines.append(f"datasheet: not computed ({ds['error']})")
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
    """Entry point; returns the exit status (0 ok, 2 bad input). ``rv-calibrate import ...``: :mod:`rvcalib.cli_import`."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "import":
        from rvcalib.cli_import import main as import_main

        return import_main(argv[1:])
    args = build_parser().parse_args(argv)
    from rvcalib import forward
    from rvcalib.identify import calibrate
    from rvcalib.report import result_json, write_report

    try:
        check_options(args)
        ds = read_dataset(args.dataset, design=args.reducer)
        steps = args.steps
        log = (lambda s: print(f"rv-calibrate: {s}", file=sys.stderr, flush=True)) if args.verbose else None
        runner = None
        if args.workers > 1 or args.cache is not None:
            from rvdyn.runner import Runner

            # the pool keeps the forward model's contact law (None: each case's own, rvdyn's physical default)
            runner = Runner(executor=args.workers, cache=args.cache, memory_bytes=forward.CACHE_BYTES,
                            law=forward.forward_runner().law, warm_bytes=forward.WARM_BYTES)
        prev = forward.use_runner(runner) if runner is not None else None
        try:
            res = calibrate(ds, steps=steps, alpha=args.alpha, max_terms=args.max_terms, log=log,
                            screen_points=args.screen_points, time_budget_s=args.time_budget)
        finally:
            if runner is not None:
                forward.use_runner(prev)
                runner.close()
        try:
            res.datasheet = datasheet_of(res, forward.forward_runner().law, args.rated_Nm)
        except (ValueError, ArithmeticError) as exc:   # a design the sweep cannot take: said, not fatal
            res.datasheet = {"error": v.one_line(exc)}
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
