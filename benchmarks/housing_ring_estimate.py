"""Estimate (not part of the model) of the output wind-up the pin housing would add by deforming as a ring.

docs/physics.md, section 9, "still not modelled": the pins' forces on the housing at rated torque (both discs,
physical law, supports inside the equilibrium) are applied to a free thin ring (the housing between the bottom of
the pin grooves and its outer radius, over both discs' width, QT500-7). Inextensional ring modes n >= 2 (Castigliano:
``w = A cos(n theta)``, ``v = -A sin(n theta)/n``, modal stiffness ``k_n = pi E I (n^2 - 1)^2 / R^3``; n = 0 and 1
are the rigid and the uniform modes, held by the housing's mounting). The unit-load wind-up is ``sum F . d / T``
with d the ring's displacement at the pins under the fixed pin forces. Each pin force is along the line from its pin
to the pitch point (the classical cycloid result: every contact normal passes through the pitch point, which lies on
the line from the housing's centre through the disc's centre at ``Zp e`` from the housing's centre). A free ring is an
upper bound: the real housing is held round by its flanges and by the main bearings on the carrier and the flange.

Run: ``python benchmarks/housing_ring_estimate.py [--load-Nm 167] [--input-deg 0] [--modes 40]``.
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

from rvcad.errors import Case  # noqa: E402
from rvcad.geometry import ReducerGeometry  # noqa: E402
from rvdyn.materials import MATERIALS  # noqa: E402
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver  # noqa: E402
from rvdyn.te import make_contacts  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--load-Nm", type=float, default=167.0)
    ap.add_argument("--input-deg", type=float, default=0.0)
    ap.add_argument("--modes", type=int, default=40, help="highest ring mode n")
    args = ap.parse_args()
    g = ReducerGeometry(Case())
    d = g.design
    s = QuasiStaticSolver(g, make_contacts(g, "analytic"), None)
    th = np.array([math.radians(args.input_deg)])
    sol = s.solve(th, direction=-1, load_Nm=args.load_Nm)
    pf = sol.pin_force_N[0]                                              # (nd, Zp) N
    cen, _ = g.disc_poses(sol.theta_out, sol.psi)                        # (1, nd, 2) disc centres, mm
    pins = g.pin_centers                                                 # (Zp, 2)
    Fh = np.zeros_like(pins)
    torque = []
    for k in range(pf.shape[0]):
        c = cen[0, k]
        P = d.z_pins * c                                                 # pitch point: Zp e along the disc centre
        u = P - pins
        u /= np.linalg.norm(u, axis=1)[:, None]
        F = pf[k][:, None] * u
        T = float(np.sum(pins[:, 0] * F[:, 1] - pins[:, 1] * F[:, 0]))
        torque.append(T)
        Fh += F
    ang = np.arctan2(pins[:, 1], pins[:, 0])
    er = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    et = np.stack([-er[:, 1], er[:, 0]], axis=-1)
    Fr, Ft = np.sum(Fh * er, axis=1), np.sum(Fh * et, axis=1)
    m = MATERIALS["pin_housing"]
    r_in = d.pin_circle_radius_mm + d.pin_radius_mm                      # bottom of the pin grooves
    h = d.housing_outer_radius_mm - r_in
    R = 0.5 * (r_in + d.housing_outer_radius_mm)
    b = 2.0 * d.disc_width_mm + d.disc_gap_mm
    EI = m.E * b * h ** 3 / 12.0
    dr, dt = np.zeros(len(ang)), np.zeros(len(ang))
    for n in range(2, args.modes + 1):
        for w, v in ((np.cos(n * ang), -np.sin(n * ang) / n), (np.sin(n * ang), np.cos(n * ang) / n)):
            A = float(np.sum(Fr * w + Ft * v)) / (math.pi * EI * (n * n - 1) ** 2 / R ** 3)
            dr += A * w
            dt += A * v
    work = float(np.sum(Fr * dr + Ft * dt))
    T_out = args.load_Nm * 1e3
    print(f"pin forces through the pitch point: torques of the discs {torque[0] / 1e3:.1f}, {torque[1] / 1e3:.1f} N m "
          f"(sum {sum(torque) / 1e3:.1f}; load {args.load_Nm:g} N m); net force on the housing "
          f"({Fh.sum(0)[0]:.0f}, {Fh.sum(0)[1]:.0f}) N")
    print(f"ring: mean radius {R:.2f} mm, section {h:.1f} x {b:.1f} mm, E {m.E:.3g} MPa, EI {EI:.4g} N mm^2")
    print(f"free thin ring, modes 2..{args.modes}: wind-up sum F.d/T = {work / T_out * ARCSEC_PER_RAD:.1f} arcsec, "
          f"largest radial displacement {np.abs(dr).max() * 1e3:.1f} um")


if __name__ == "__main__":
    main()
