"""Coulomb friction of the pins and the crank bearings under rotation, referred to the output.

The TE solver has no friction from the coefficients (``model.pin_friction_coefficient``,
``model.bearing_friction_coefficient``; the stiffness sweep uses them for its micro-slips, docs/physics.md
section 9). This module gives the friction torque they make when the reducer turns, from the equilibrium's
forces and the kinematics, so that a load-proportional effect found in measured TE can be read as friction
(rvcalib.equivalents).

**Kinematics.** A disc rotates with the carrier (its cranks are parallel links: ``omega_disc = omega_out``) and
translates on its eccentric circle; relative to the housing its instantaneous centre of rotation is the pitch
point ``W`` (on the line from the housing's centre through the disc's centre, ``Zp/(Zp - Zc)`` times their
distance: the disc's point at rest, the same point the housing ring's load directions use, rvdyn.housing), so a
material point ``P`` of the disc moves at ``omega_out |P - W|`` at right angles to ``P - W``. Every contact normal
of the conjugate profile passes through ``W``, so that velocity is all tangential: the contact of pin ``i``
slides at ``omega_out (|c_i - W| - r_pin)`` (``c_i`` the pin's centre) on a pin held in its groove; a pin that
rolls on the disc slides in its groove at the same surface speed under the same normal force, so with one
coefficient the loss is the same. The cranks turn against the discs (cam bearings) and against the carrier
(journals) at ``(i - 1) Z1/Z2`` times ``omega_out`` (the planet on the crank meshes the sun: ``(omega_in -
omega_out) Z1/Z2`` with ``omega_in = i omega_out``). Friction power over ``omega_out`` is the torque
(the bearings' as SKF's constant coefficient referred to the roller pitch radius, as the sweep):

    T_f = mu_p sum_i F_i (|c_i - W_k| - r_pin) + mu_b (i - 1) Z1/Z2 (sum |F_cam| r_cam + sum |F_journal| r_journal)

**Arms.** ``T_f = (mu_p kappa_p + mu_b kappa_b) T`` with ``kappa`` the sums above per N mm of output torque
``T``. On the default design (physical law, elastic supports; ``python -m rvdyn.friction``) kappa_p = 1.093,
1.091, 1.087, 1.082 and kappa_b = 22.0 at 5, 20, 80, 167 N m, averaged over a pin pitch (ripple +-3 % and +-4 %):
the friction torque is proportional to the load to 1 %, 11 % of it with the default coefficients. In a TE test
it resists both directions as the load does, so every part winds up under ``T (1 + mu_p kappa_p + mu_b kappa_b)``
(the lumped ``friction_torque_Nm`` option's model): the TE moves like a compliance of ``(mu_p kappa_p + mu_b
kappa_b) w`` arcsec/(N m), ``w`` the reducer's own wind-up per N m at that load. TE data cannot tell the two
apart; the hysteresis sweep (input locked) can: friction opens the loop, a compliance tilts it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvdyn.bearings import Supports
import rvdyn.housing as housing
from rvdyn.contacts import ContactLaw
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver
from rvdyn.te import make_contacts

#: Steps over one pin pitch of output at which the arms are averaged.
ARM_STEPS = 12
#: Relative load step of the wind-up slope ``w`` (central difference at 1 -+ this).
SLOPE_STEP = 0.1


@dataclass(frozen=True)
class FrictionArms:
    """Coulomb friction torque per unit coefficient and per unit output torque, and the wind-up slope.

    Attributes
    ----------
    load_Nm : float
    pins : float
        ``kappa_p``: ``sum F_i (|c_i - W| - r_pin) / T`` (dimensionless).
    bearings : float or None
        ``kappa_b``: ``(i - 1) Z1/Z2 (sum |F_cam| r_cam + sum |F_journal| r_journal) / T``; None in the rigid limit.
    windup_arcsec_per_Nm : float
        ``w``: the output's lag per N m at this load, ``-(TE(1.1 L) - TE(0.9 L)) / (0.2 L)`` over the same steps
        (direction +1).
    """

    load_Nm: float
    pins: float
    bearings: float | None
    windup_arcsec_per_Nm: float

    def compliance_per_coefficient(self, which: str) -> float:
        """The compliance (arcsec/(N m)) that a unit coefficient of ``which`` (``pins`` or ``bearings``) mimics in
        the TE: ``kappa w``."""
        k = self.pins if which == "pins" else self.bearings
        if k is None:
            raise ValueError(f"no {which} friction arm in the rigid limit")
        return k * self.windup_arcsec_per_Nm


def friction_arms(case: Case, load_Nm: float = 20.0, law: ContactLaw | None = None,
                  steps: int = ARM_STEPS) -> FrictionArms:
    """The friction arms and the wind-up slope of a case at a load (module docstring).

    Parameters
    ----------
    case : Case
    load_Nm : float
        Output torque, N m (> 0).
    law : ContactLaw or None
        Default: the case's ``model.contact``.
    steps : int
        Input angles over one pin pitch of output.
    """
    if not (np.isfinite(load_Nm) and load_Nm > 0):
        raise ValueError(f"load_Nm {load_Nm!r} must be a finite number > 0 (the friction of a loaded reducer)")
    g = ReducerGeometry(case)
    s = QuasiStaticSolver(g, make_contacts(g, "analytic"), law)
    s.want_parts = True
    d = g.design
    th = np.radians(np.linspace(0.0, 360.0 * d.ratio / d.z_pins, int(steps), endpoint=False))
    sol = s.solve(th, direction=1, load_Nm=load_Nm)
    hc = np.mean(g.pin_centers, axis=0)
    cen, _ = g.disc_poses(sol.theta_out, sol.psi)                                  # (N, nd, 2)
    W = housing.pitch_points(hc, cen, d.z_pins, d.z_disc)                         # (N, nd, 2)
    dist = np.linalg.norm(g.pin_centers[None, None] - W[:, :, None], axis=-1) - d.pin_radius_mm   # (N, nd, Zp)
    T = load_Nm * 1e3
    pins = float(np.mean((sol.pin_force_N * dist).sum(axis=(1, 2)))) / T
    bearings = None
    if sol.cam_force_N is not None:
        sup = s.supports if s.supports is not None else Supports.from_design(d)
        cam, journal = sup.friction_arms(sol.cam_force_N)                         # (N, nd, nc), (N, nc)
        rel = (d.ratio - 1.0) * d.z_sun / d.z_planet
        bearings = float(rel * np.mean(cam.sum(axis=(1, 2)) + journal.sum(axis=1))) / T
    te = [float(np.mean(s.solve(th, direction=1, load_Nm=f * load_Nm).te_rad)) * ARCSEC_PER_RAD
          for f in (1.0 - SLOPE_STEP, 1.0 + SLOPE_STEP)]
    w = -(te[1] - te[0]) / (2.0 * SLOPE_STEP * load_Nm)
    return FrictionArms(float(load_Nm), pins, bearings, w)


if __name__ == "__main__":  # pragma: no cover - the figures of the module docstring
    for L in (5.0, 20.0, 80.0, 167.0):
        a = friction_arms(Case.from_dict({}), L)
        print(f"load {L:g} N m: kappa_p {a.pins:.4f}, kappa_b {a.bearings:.3f}, w {a.windup_arcsec_per_Nm:.4f} "
              f"arcsec/(N m); default coefficients: T_f/T = {0.05 * a.pins + 0.0025 * a.bearings:.4f}")
