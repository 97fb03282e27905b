"""Check the carrier inside the equilibrium against an independent fixed-point iteration around the solver.

The solver (physical law, elastic supports) holds the carrier end plate's turn phi as a coordinate
(docs/physics.md, section 8). Here the same physics is solved another way: a solver whose end plate is rigid
(``carrier_k`` infinite), the cams displaced by ``l_k a phi`` along the crank circle (journal B carried by the
end plate, journal A fixed in the flange), and ``phi <- T_B / k_t`` with T_B the torque of the journal-B
reactions (lever rule from the cam forces), repeated until phi settles. Prints the TE of both, the end plate's
turn and the far journals' torque share, and the series bound ``T/4 / k_t`` of the lever rule with equal discs.

Run: ``python benchmarks/carrier_fixed_point.py [--load-Nm 167] [--input-deg 0]``.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

import rvdyn.physical as physical  # noqa: E402
from results_log import record, slug  # noqa: E402
from rvcad.errors import Case  # noqa: E402
from rvcad.geometry import ReducerGeometry  # noqa: E402
from rvdyn.bearings import Supports  # noqa: E402
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver  # noqa: E402
from rvdyn.te import make_contacts  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--load-Nm", type=float, default=167.0)
    ap.add_argument("--input-deg", type=float, default=0.0)
    args = ap.parse_args()
    T = args.load_Nm
    th = np.array([math.radians(args.input_deg)])

    g = ReducerGeometry(Case.from_dict({}))
    s = QuasiStaticSolver(g, make_contacts(g, "analytic"))
    sol = s.solve(th, direction=-1, load_Nm=T)
    sup = s.supports
    phi_eq = sol.x[0, -1] / sup.crank_radius
    print(f"in the equilibrium: TE {sol.te_rad[0] * ARCSEC_PER_RAD:.4f} arcsec, end plate turn "
          f"{phi_eq * ARCSEC_PER_RAD:.3f} arcsec")

    # the same design with a rigid end plate, the carrier's turn imposed from outside
    from_design = Supports.from_design
    physical.Supports.from_design = classmethod(lambda cls, d: replace(from_design(d), carrier_k=math.inf))
    try:
        g2 = ReducerGeometry(Case.from_dict({}))
        s2 = QuasiStaticSolver(g2, make_contacts(g2, "analytic"))
    finally:
        physical.Supports.from_design = from_design
    zA, zB = sup.z_journal
    lam = (np.asarray(sup.z_cams) - zA) / (zB - zA)
    cams = g2.cam_centers
    phi = [0.0]

    def displaced(theta_out, psi):
        ax = g2.crank_axes(np.atleast_1d(np.asarray(theta_out, dtype=float)))
        tang = np.stack([-ax[..., 1], ax[..., 0]], axis=-1)                   # a u'(.)
        return cams(theta_out, psi) + phi[0] * lam[None, None, :, None] * tang[:, :, None, :]

    g2.cam_centers = displaced
    te0 = None
    for it in range(40):
        r = s2.solve(th, direction=-1, load_Nm=T)
        R = sup.journal_forces(r.cam_force_N)
        ax = g2.crank_axes(r.theta_out)
        TB = float((ax[0, :, 0] * R[0, :, 1, 1] - ax[0, :, 1] * R[0, :, 1, 0]).sum())
        if te0 is None:
            te0 = r.te_rad[0]
            print(f"rigid end plate: TE {te0 * ARCSEC_PER_RAD:.4f} arcsec, far journals' share {TB / (T * 1e3):.4f}")
        new = TB / sup.carrier_k
        if abs(new - phi[0]) < 1e-14:
            break
        phi[0] = new
    print(f"fixed point ({it} iterations): TE {r.te_rad[0] * ARCSEC_PER_RAD:.4f} arcsec, end plate turn "
          f"{phi[0] * ARCSEC_PER_RAD:.3f} arcsec, far journals' share {TB / (T * 1e3):.4f}; the carrier adds "
          f"{(r.te_rad[0] - te0) * ARCSEC_PER_RAD:.3f} arcsec (series bound of the lever rule, beta = 1/2: "
          f"{0.25 * T * 1e3 / sup.carrier_k * ARCSEC_PER_RAD:.3f})")
    diff = (r.te_rad[0] - sol.te_rad[0]) * ARCSEC_PER_RAD
    print(f"difference to the equilibrium: {diff:.2e} arcsec")
    tag = f"{T:g} Nm input {args.input_deg:g} deg"
    record("carrier_fixed_point", [
        (slug(f"{tag} te in equilibrium"), sol.te_rad[0] * ARCSEC_PER_RAD, "arcsec"),
        (slug(f"{tag} end plate turn"), phi[0] * ARCSEC_PER_RAD, "arcsec"),
        (slug(f"{tag} far journals share"), TB / (T * 1e3), "1"),
        (slug(f"{tag} carrier adds"), (r.te_rad[0] - te0) * ARCSEC_PER_RAD, "arcsec"),
        (slug(f"{tag} fixed point minus equilibrium"), diff, "arcsec")])


if __name__ == "__main__":
    main()
