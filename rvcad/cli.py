"""Command line of rvcad: ``rvcad export [CASE.json] --out DIR ...`` (also ``python -m rvcad``).

Exit codes: 0 success, 2 bad input (message on stderr, no traceback), 1 unexpected failure.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import rvcad.validation as validation
from rvcad.errors import load_case
from rvcad.validation import MAX_ANGLE_DEG
from rvcad.export import DEFAULT_TOLERANCE_UM, FORMATS, TOLERANCE_RANGE_UM, ExportedFile, export_case

_EXPORT_EPILOG = """\
files written to DIR:
  <part>.step, <part>.stl  one per part: sun, planet0, planet1, crank0, crank1, flange,
                           disc0, disc1, carrier, housing, pin00..pin39
  assembly.step            every part placed at --theta-in-deg (or --state), one labelled solid per part
  assembly.stl             every part placed at --theta-in-deg (or --state), one mesh
  case.json, manifest.json the exported case and the cache manifest

frames: moving parts (sun, planets, cranks, plates, discs) are written in their own frame:
  the frame that the kinematic placement at an input angle rotates about +z and then moves in
  x, y (z is already the axial position in the assembly, +z from input to output side); the
  assembly files hold them placed. Pins and housing are fixed and in the world frame.

accuracy: every STL vertex lies on the exact outline and every chord deviates from it by at most
  the tolerance (binary STL stores float32: about 0.004 um more at 64 mm); STEP lines and circles
  are exact, the cycloid envelope and involute flanks are cubic B-splines within the tolerance.

checks: a case that cannot give valid solids (pointed teeth, overlapping crank holes, pins that
  overlap the discs beyond the solver's 100 um elastic limit in every pose) is refused before
  anything is written, naming the field; every STEP solid passes OpenCASCADE's BRepCheck or the
  export stops with an error. The summary reports overlaps of the placed parts (pin-disc,
  crank-disc, stage I teeth).

cache: a rerun skips every file whose content (case, tolerance, format, input angle for the
  assembly) is unchanged; --force rewrites. A folder holding another case's (or tolerance's)
  export is refused; --force removes that export's files first. Files are written atomically
  (temp file + rename) with the umask's permissions; temp files of a killed run are removed.

exit codes: 0 done, 2 bad input (message on stderr), 1 unexpected failure.
"""


def _formats(text: str) -> list[str]:
    items = [t.strip().lower() for t in text.split(",") if t.strip()]
    if not items:
        raise argparse.ArgumentTypeError("give at least one format: step, stl or step,stl")
    bad = [t for t in items if t not in FORMATS]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown format {bad[0]!r}; allowed: step, stl (comma separated)")
    return items


def _tolerance(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    lo, hi = TOLERANCE_RANGE_UM
    if not lo <= v <= hi:  # also rejects nan
        raise argparse.ArgumentTypeError(f"{text} um is outside [{lo}, {hi}] um")
    return v


def _angle(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of degrees") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"{text} must be a finite number of degrees")
    if abs(v) > MAX_ANGLE_DEG:
        raise argparse.ArgumentTypeError(f"{text} deg is out of range; allowed: |angle| <= {MAX_ANGLE_DEG:g} deg "
                                         "(float64 keeps sub-arcsecond positions there)")
    return v


def _state(text: str) -> list[float]:
    try:
        vals = [float(t) for t in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma separated list of angles in degrees") from None
    if not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"{text} must hold finite angles in degrees")
    return vals


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``rvcad`` (subcommand ``export``)."""
    p = validation.ArgumentParser(
        prog="rvcad",
        description="Error-perturbed CAD of the RV reducer: exact parts as STEP and STL files.",
        epilog="Run 'rvcad export --help' for the export options. Lengths in mm, angles in degrees, "
               "error values in um or degrees as in the case JSON (see the README).")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    e = sub.add_parser(
        "export", help="write a STEP and an STL file of every part and of the assembly",
        description="Write a STEP and an STL file of every part of the error-perturbed reducer and of the "
                    "assembly placed at one input angle.",
        epilog=_EXPORT_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    e.add_argument("case", nargs="?", metavar="CASE.json",
                   help="case file (design, errors in um or deg, see the README); default: the nominal design "
                        "without errors")
    e.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    e.add_argument("--format", type=_formats, default=list(FORMATS), metavar="FORMATS",
                   help="comma separated file formats: step, stl (default: step,stl)")
    e.add_argument("--tolerance-um", type=_tolerance, default=DEFAULT_TOLERANCE_UM, metavar="UM",
                   help=f"largest deviation of the exported geometry from the exact one, um: STL chord "
                        f"sagitta and STEP B-spline budget (default {DEFAULT_TOLERANCE_UM}; range "
                        f"{TOLERANCE_RANGE_UM[0]}..{TOLERANCE_RANGE_UM[1]})")
    e.add_argument("--theta-in-deg", type=_angle, default=0.0, metavar="DEG",
                   help="input (sun) angle at which the assembly files place the moving parts, degrees "
                        "(default 0; the others follow the ideal kinematics)")
    e.add_argument("--state", type=_state, default=None, metavar="OUT_DEG,CRANK0_DEG,CRANK1_DEG[,...]",
                   help="place the assembly at this output angle and these crank angles (degrees, one per crank) "
                        "instead of the "
                        "ideal kinematics at --theta-in-deg, e.g. the equilibrium printed by "
                        "'python -m rvdyn.pose CASE.json --theta-in-deg DEG'")
    e.add_argument("--parts", default=None, metavar="PATTERNS",
                   help="comma separated shell patterns of the parts to write, e.g. 'disc*,pin0?,assembly' "
                        "(default: all)")
    e.add_argument("--force", action="store_true",
                   help="rewrite files even if the cache shows them up to date; clean a folder that holds the "
                        "export of another case or tolerance (refused without --force)")
    e.add_argument("--json", action="store_true",
                   help="print one JSON object (files, sizes, seconds, design check) instead of the summary")
    e.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    return p


def _export(args: argparse.Namespace) -> int:
    validation.output_dir(args.out)
    case = load_case(args.case)
    state = None
    if args.state is not None:
        if len(args.state) != case.design.n_cranks + 1:
            raise ValueError(f"--state {','.join(f'{v:g}' for v in args.state)} must give the output angle and "
                             f"{case.design.n_cranks} crank angles, degrees")
        state = (math.radians(args.state[0]), tuple(math.radians(v) for v in args.state[1:]))
    parts = [s.strip() for s in args.parts.split(",") if s.strip()] if args.parts else None

    def progress(f: ExportedFile) -> None:
        if not args.quiet and not args.json:
            state = "up to date" if f.skipped else f"{f.seconds:.2f} s"
            print(f"  {f.file:16s} {f.bytes / 1e6:8.2f} MB  {state}", file=sys.stderr, flush=True)

    rep = export_case(case, args.out, formats=args.format, tolerance_um=args.tolerance_um,
                      theta_in_deg=args.theta_in_deg, parts=parts, force=args.force, progress=progress,
                      state=state, pose="ideal" if state is None else "state")
    if args.json:
        print(json.dumps(rep.to_dict(), indent=1))
    else:
        print(rep.summary())
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``rvcad`` and ``python -m rvcad``.

    Parameters
    ----------
    argv : list of str or None
        Arguments without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit code: 0 success, 2 bad input, 1 unexpected failure.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return int(exc.code or 0)
    if args.command is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return _export(args)
    except ValueError as exc:
        print(f"rvcad {args.command}: error: {validation.one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"rvcad {args.command}: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "),
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"rvcad {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
