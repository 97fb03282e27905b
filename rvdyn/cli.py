"""Command line of rvdyn: ``rvdyn te`` (TE of one case) and ``rvdyn screen`` (single-factor screen).

Each command prints a human summary by default; ``--json`` prints one JSON object on stdout.
Bad input prints a message naming the field to stderr and exits with status 2.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from rvcad.errors import MAX_LOAD_NM, load_case
from rvcad import validation as v
from rvdyn.contacts import ContactLaw
from rvdyn.te import SOLVERS, lost_motion, run_te


def _finite(x: float) -> Any:
    return x if isinstance(x, (int, str)) or (isinstance(x, float) and math.isfinite(x)) else None


def _law(args: argparse.Namespace) -> ContactLaw:
    return ContactLaw(K=args.K, n=args.n, rigid=args.rigid)


def build_parser() -> argparse.ArgumentParser:
    p = v.ArgumentParser(prog="rvdyn", description="Quasi-static transmission error of an RV reducer.")
    sub = p.add_subparsers(dest="command", required=True)
    te = sub.add_parser("te", help="TE curve of one case (CSV) and its statistics",
                        description="Solve the quasi-static meshing equilibrium at N input angles and write "
                                    "TE.csv with input_deg, output_deg, te_arcsec (TE = theta_out - theta_in/121, "
                                    "arcsec, positive = output leads), contacts and peak_force_N.")
    te.add_argument("case", nargs="?", default=None, help="case JSON (conventions.md); default: nominal, no errors")
    te.add_argument("--solver", choices=SOLVERS, default="analytic",
                    help="fcl: python-fcl distances on the exported meshes; analytic: exact envelope (default)")
    te.add_argument("--steps", type=int, default=720, help="steps over the revolutions (>= 2, default 720)")
    te.add_argument("--revolutions", type=float, default=1.0, help="output revolutions (default 1)")
    te.add_argument("--out", default=None, help="TE.csv to write (atomically); omitted: no file")
    te.add_argument("--load-Nm", dest="load_Nm", type=float, default=None,
                    help="output load torque in N m (default: the case's, 20); 0 = rigid single-flank limit")
    te.add_argument("--direction", type=int, choices=(1, -1), default=None, help="+1 or -1 (default: the case's)")
    te.add_argument("--K", type=float, default=ContactLaw.K, help="contact stiffness, N/mm^n (default 2e5)")
    te.add_argument("--n", type=float, default=ContactLaw.n, help="contact force exponent (default 1.5)")
    te.add_argument("--rigid", action="store_true", help="rigid single-flank limit (K -> infinity)")
    te.add_argument("--lost-motion", action="store_true",
                    help="also compute lost motion = mean TE(-1) - mean TE(+1) at light load (rigid limit)")
    te.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")

    sc = sub.add_parser("screen", help="single-factor screen of the Table 4 errors and RSM factor sweeps",
                        description="Paper Fig. 9 and Fig. 11: every Table 4 error alone at its paper value, "
                                    "and sweeps of EA..ED over the Table 5 range; writes CSV tables and PNG plots.")
    sc.add_argument("--out", required=True, help="output folder")
    sc.add_argument("--solver", choices=SOLVERS, default="analytic")
    sc.add_argument("--steps", type=int, default=720)
    sc.add_argument("--sweep-points", type=int, default=7, help="points per factor sweep (default 7)")
    sc.add_argument("--load-Nm", dest="load_Nm", type=float, default=20.0)
    sc.add_argument("--json", action="store_true")
    return p


def _check_te_options(args: argparse.Namespace) -> None:
    """Bounds of the size options and the output path, before anything is solved (OptionError)."""
    v.steps_option(args.steps)
    v.option_real(args.revolutions, "--revolutions", 0.0, v.MAX_REVOLUTIONS, lo_open=True,
                  why=f"at most {v.MAX_STEPS} steps over them")
    if args.load_Nm is not None:
        v.option_real(args.load_Nm, "--load-Nm", 0.0, MAX_LOAD_NM, unit="N m")
    if not args.rigid:
        v.option_real(args.K, "--K", 0.0, v.MAX_CONTACT_K, lo_open=True, unit="N/mm^n",
                      why="stiffer is the rigid limit, --rigid")
    if args.out:
        v.output_file(args.out)


def _te(args: argparse.Namespace) -> int:
    _check_te_options(args)
    case = load_case(args.case)
    law = _law(args)
    res = run_te(case, args.solver, args.steps, args.revolutions, args.load_Nm, args.direction, law)
    out: dict[str, Any] = {"case": case.name, **{k: _finite(v) for k, v in res.stats.items()}}
    if args.lost_motion:
        lm = lost_motion(case, args.solver, args.steps, law=law)
        out["lost_motion_arcsec"] = lm["lost_motion_arcsec"]
    if args.out:
        out["csv"] = str(res.to_csv(args.out))
    if args.json:
        print(json.dumps(out))
    else:
        print(f"case {case.name}: solver {args.solver}, {args.steps} steps, {args.revolutions:g} rev, "
              f"load {res.stats['load_Nm']:g} N m, direction {res.stats['direction']:+d}")
        print(f"  TE pp {out['pp']:.4f} arcsec  mean {out['mean']:.4f}  mean|.| {out['mean_abs']:.4f}  "
              f"rms {out['rms']:.4f}  ratio {res.stats['ratio']:.7f}  ({res.stats['seconds']:.2f} s)")
        if "lost_motion_arcsec" in out:
            print(f"  lost motion {out['lost_motion_arcsec']:.4f} arcsec")
        if args.out:
            print(f"  wrote {out['csv']}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``rvdyn``; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "te":
            return _te(args)
        v.steps_option(args.steps)
        v.option_int(args.sweep_points, "--sweep-points", 2, v.MAX_SWEEP_POINTS,
                     why="each point is one solve per factor")
        v.option_real(args.load_Nm, "--load-Nm", 0.0, MAX_LOAD_NM, unit="N m")
        v.output_dir(args.out)
        from rvdyn.screen import screen_command

        return screen_command(args)
    except ValueError as exc:
        print(f"rvdyn: error: {v.one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"rvdyn: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
