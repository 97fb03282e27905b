"""Benchmark: warm starts of the forward solves (rvdyn.solver ``x_init``) on the loop's run conditions.

Solves the 5-run benchmark's five run conditions (10/20/30 N m, both directions as in ``bench_calibrate.py``)
on a 280-point grid as one batch (:meth:`rvdyn.solver.QuasiStaticSolver.solve_many`) for a parent state (cam
eccentricity 5 um, pin radius -2 um, pin 12's pitch 0.02 deg, compliance 0.25 arcsec/(N m)), then three
perturbations of it, as the loop asks for them (a Jacobian column: cam eccentricity +0.5 um; a trial step:
pin 12's pitch +0.005 deg; another candidate: pin radius +2 um), each cold (the default start) and warm
(``x_init``: the parent's converged states). Prints the outer iterations per condition, the CPU seconds
(process time) and the largest TE difference warm - cold (arcsec; the solver tolerance is 1e-9 rad =
2.06e-4 arcsec).

Run: ``python benchmarks/bench_warm_start.py [--law physical|impact] [--steps 280]``. Figures only, recorded in
``benchmarks/results.csv``.
"""
from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results_log import record, slug  # noqa: E402
from rvcad.errors import Case  # noqa: E402
from rvcad.geometry import ReducerGeometry  # noqa: E402
from rvdyn.contacts import AnalyticContacts  # noqa: E402
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver  # noqa: E402
from rvdyn.te import input_angles  # noqa: E402

CONDS = [(10.0, 1), (10.0, -1), (20.0, 1), (30.0, 1), (30.0, -1)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--law", choices=("physical", "impact"), default="physical")
    ap.add_argument("--steps", type=int, default=280)
    args = ap.parse_args()
    base = {"name": "parent", "errors": {"cam_eccentricity": 5.0, "pin_radius": -2.0,
                                         "pin_pitch": [{"value": 0.02, "pin": 12}]},
            "model": {"torsional_compliance_arcsec_per_Nm": 0.25, "contact": args.law}}

    def run(d: dict, x_init=None):
        g = ReducerGeometry(Case.from_dict(d))
        s = QuasiStaticSolver(g, AnalyticContacts(g, per_point=True))
        ths = [input_angles(g.ratio, args.steps, 1.0, dd) for _, dd in CONDS]
        t0 = time.process_time()
        sols = s.solve_many(ths, [dd for _, dd in CONDS], [L for L, _ in CONDS], x_init=x_init)
        return sols, time.process_time() - t0

    def pert(key: str, dv: float) -> dict:
        d = copy.deepcopy(base)
        if key == "pin_pitch":
            d["errors"]["pin_pitch"][0]["value"] += dv
        else:
            d["errors"][key] += dv
        return d

    parent, t_p = run(base)
    print(f"law {args.law}, {len(CONDS)} conditions x {args.steps} angles; parent cold: outer iterations "
          f"{[s.iterations for s in parent]}, {t_p:.2f} s CPU")
    tag = f"{args.law} {args.steps} angles"
    figures = [(slug(f"{tag} parent cold cpu"), t_p, "s")]
    x = [s.x for s in parent]
    for name, short, d in [("Jacobian column: cam_eccentricity +0.5 um", "cam_eccentricity", pert("cam_eccentricity", 0.5)),
                           ("trial step: pin_pitch[12] +0.005 deg", "pin_pitch", pert("pin_pitch", 0.005)),
                           ("another candidate: pin_radius +2 um", "pin_radius", pert("pin_radius", 2.0))]:
        cold, t_c = run(d)
        warm, t_w = run(d, x)
        diff = max(np.abs(a.te_rad - b.te_rad).max() for a, b in zip(cold, warm)) * ARCSEC_PER_RAD
        print(f"{name}: cold {[s.iterations for s in cold]} {t_c:.2f} s; warm {[s.iterations for s in warm]} "
              f"{t_w:.2f} s; max |TE warm - cold| {diff:.2e} arcsec")
        figures += [(slug(f"{tag} {short} cold cpu"), t_c, "s"), (slug(f"{tag} {short} warm cpu"), t_w, "s"),
                    (slug(f"{tag} {short} max te warm - cold"), diff, "arcsec")]
    record("bench_warm_start", figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
