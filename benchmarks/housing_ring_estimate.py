"""The output wind-up of the pin housing as a ring (rvdyn.housing), for both supports and a range of foundations.

docs/physics.md, section 9, "Housing ring": the pins' forces on the housing at rated torque (both discs, physical
law, supports inside the equilibrium; each along the line from its disc's pitch point to the pin) applied to the pin
band as a thin ring (inextensional modes n >= 2, ``k_n = pi E I (n^2 - 1)^2 / R^3 + pi R k_f``). ``k_f`` is the
foundation of the housing wall held round at the main bearings (``Design.housing_support = "main_bearings"``, the
model's default) or 0 (``"free"``, the upper bound).
The sweep over k_f shows what a softer hold (e.g. the main bearings' ball sets in series with the wall) would give.
The unit-load wind-up is ``F^T C F / T`` (loads proportional to T).

Run: ``python benchmarks/housing_ring_estimate.py [--load-Nm 167] [--input-deg 0] [--modes 160]``.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from results_log import record, slug  # noqa: E402
from rvcad.errors import Case  # noqa: E402
from rvcad.geometry import ReducerGeometry  # noqa: E402
import rvdyn.housing as H  # noqa: E402
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver  # noqa: E402
from rvdyn.te import make_contacts  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--load-Nm", type=float, default=167.0)
    ap.add_argument("--input-deg", type=float, default=0.0)
    ap.add_argument("--modes", type=int, default=160, help="highest ring mode n")
    args = ap.parse_args()
    g = ReducerGeometry(Case())
    d = g.design
    s = QuasiStaticSolver(g, make_contacts(g, "analytic"), None)
    sol = s.solve(np.array([math.radians(args.input_deg)]), direction=-1, load_Nm=args.load_Nm)
    cen, _ = g.disc_poses(sol.theta_out, sol.psi)
    hc = np.mean(g.pin_centers, axis=0)
    rel = g.pin_centers - hc
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    Fv = H.pin_force_vectors(g.pin_centers, hc, cen[0], sol.pin_force_N[0], d.z_pins, d.z_disc)
    F = H.polar_components(g.pin_centers, hc, Fv)
    torque = float(np.sum(rel[:, 0] * Fv[:, 1] - rel[:, 1] * Fv[:, 0]))
    R, h, b, EI = H.housing_ring_section(d)
    T = args.load_Nm * 1e3
    print(f"pin forces on the housing: torque {torque / 1e3:.1f} N m (load {args.load_Nm:g} N m), net force "
          f"({Fv.sum(0)[0]:.0f}, {Fv.sum(0)[1]:.0f}) N (taken by the mounting: modes 0 and 1)")
    print(f"ring: mean radius {R:.2f} mm, section {h:.1f} x {b:.1f} mm, EI {EI:.4g} N mm^2; wall to the main bearing "
          f"{H.housing_wall_length_mm(d):.2f} mm")
    kf_wall = H.housing_foundation_modulus(d)
    figures = []
    for label, kf in [("main bearings (default)", kf_wall)] + [(f"k_f {k:g}", k) for k in (5e4, 1.5e4, 5e3, 2e3, 500)] \
            + [("free ring", 0.0)]:
        C = H.ring_compliance(ang, 1.0, EI, R, kf, args.modes)
        d_ = C @ F
        windup = float(F @ d_) / T * ARCSEC_PER_RAD
        print(f"{label:>24}: k_f {kf:9.4g} N/mm^2, wind-up {windup:7.3f} arcsec, largest "
              f"radial displacement {np.abs(d_[:d.z_pins]).max() * 1e3:7.3f} um")
        figures.append((slug(f"{args.load_Nm:g} Nm windup {label.replace('(default)', '')}"), windup, "arcsec"))
    record("housing_ring_estimate", figures)


if __name__ == "__main__":
    main()
