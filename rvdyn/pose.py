"""The solved pose of a case at one input angle, for placing the CAD assembly there.

rvcad (geometry, CAD) sits below rvdyn (solver), so ``rvcad export`` cannot solve; it places the
assembly at an explicit state (``--state OUT_DEG,CRANK0_DEG,CRANK1_DEG``). This module gives that
state from the quasi-static equilibrium (analytic contacts, the case's load, direction and model)::

    rvcad export case.json --out DIR --theta-in-deg 30 \\
        --state $(python -m rvdyn.pose case.json --theta-in-deg 30)

or in Python ``rvcad.export.export_case(case, DIR, theta_in_deg=30, state=solved_state(case, 30),
pose="solved")``. The discs are placed on their cams (a disc floating in a cam-bearing clearance,
a model option, is not shown floating).
"""
from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from rvcad.errors import Case, load_case
from rvcad.geometry import ReducerGeometry
from rvdyn.contacts import AnalyticContacts
from rvdyn.solver import QuasiStaticSolver


def solved_state(case: Case, theta_in_deg: float) -> tuple[float, tuple[float, ...]]:
    """Output angle and crank angles (rad) of the equilibrium at one input angle (degrees)."""
    if not math.isfinite(float(theta_in_deg)):
        raise ValueError(f"theta_in_deg {theta_in_deg!r} must be a finite number of degrees")
    g = ReducerGeometry(case)
    sol = QuasiStaticSolver(g, AnalyticContacts(g)).solve(np.radians([float(theta_in_deg)]),
                                                         direction=case.direction, load_Nm=case.load_Nm)
    return float(sol.theta_out[0]), tuple(float(v) for v in sol.psi[0])


def main(argv: list[str] | None = None) -> int:
    """``python -m rvdyn.pose [CASE.json] --theta-in-deg DEG``: print ``OUT_DEG,CRANK0_DEG,CRANK1_DEG``."""
    p = argparse.ArgumentParser(prog="python -m rvdyn.pose", description=__doc__.split("\n\n")[0])
    p.add_argument("case", nargs="?", metavar="CASE.json", help="case file (default: nominal)")
    p.add_argument("--theta-in-deg", type=float, default=0.0, metavar="DEG", help="input angle, degrees")
    args = p.parse_args(argv)
    try:
        to, psi = solved_state(load_case(args.case), args.theta_in_deg)
    except ValueError as exc:
        print(f"rvdyn.pose: error: {exc}", file=sys.stderr)
        return 2
    print(",".join(f"{math.degrees(v):.12g}" for v in (to,) + psi))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
