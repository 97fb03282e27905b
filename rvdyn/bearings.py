"""Compliance of the supports the torque passes through: cam and journal bearings, crankshafts.

The stiffness constants and influence coefficients of the supports (docs/physics.md, section 8); the
solver holds them inside the equilibrium (rvdyn.support_eq). The statics helpers here (least-norm cam
forces, lever-rule journal reactions, series wind-up) serve the friction of the stiffness sweep and the
tests.

Formulas and sources:

- Roller-raceway line contact (Palmgren, *Ball and Roller Bearing Engineering*, 1959; Harris,
  *Rolling Bearing Analysis*, eq. 6.43): ``delta = 3.84e-5 Q^0.9 / l^0.8`` (mm, N, mm), i.e.
  ``Q = K_c delta^(10/9)``, ``K_c = (l^0.8 / 3.84e-5)^(10/9)``; a roller between two raceways:
  ``K_n = K_c / 2^(10/9)``.
- Radial bearing, zero clearance (Harris, sec. 7.2; NSK: ``Q_max = 4.08 F_r / Z`` for line contact):
  ``F_r = Z J_r(0.5) K_n delta_r^(10/9)`` with ``J_r(0.5) = 0.2453`` (line contact).
- Crankshaft bending: simply supported beam between the journals, point loads at the cam planes
  (Roark, Table 8.1 case 1e): ``y(x) = Q b x (L^2 - b^2 - x^2) / (6 E I L)`` for ``x <= a``.
- Crankshaft torsion between the planet and the mean cam plane: ``phi = M_t l / (G J_p)``, i.e. a spring
  ``G J_p / (l r_b2^2)`` along the stage I line of action, in series with the mesh (in the equilibrium).
- Carrier: the far (carrier) end plate reaches the output flange through the pillars. A pillar is a
  Timoshenko beam clamped in both plates, its ends displaced parallel (guided):
  ``1/k = L^3/(12 E I) + L/(kappa G A)`` (Timoshenko & Gere, *Mechanics of Materials*; shear coefficient of a
  solid circle ``kappa = 6 (1 + nu)/(7 + 6 nu)``, Cowper 1966); the plate turns by ``phi`` relative to the
  flange against ``k_t = n_p k r_p^2`` (pillars on the circle r_p). The torque that takes this path is the
  share ``beta`` of the output torque carried by the far journals (lever rule of each crank, statically
  determinate, with the discs sharing the torque equally: the mean position of the cam planes between the
  journals), so the output lags by ``beta^2 T / k_t`` (Castigliano), in series after the equilibrium.
- Pin seat: each pin lies in a housing groove of radius ``r_pin + clearance``; a conformal Hertz line contact
  (Johnson 1985, eq. 5.36 with a concave ``R2 = -(r_pin + clearance)``) in series with the pin-disc contact
  over the disc's face width. Both are ``delta = A_i P (C_i - ln P)`` in the same load per length ``P``, so
  the series law is the same form with ``A = A_1 + A_2``, ``C = (A_1 C_1 + A_2 C_2)/A``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rvcad.params import Design
from rvdyn.materials import MATERIALS, LineContact

#: Palmgren's line-contact constant, mm N^-0.9 mm^0.8.
PALMGREN_LINE = 3.84e-5
#: Load-distribution integral J_r(0.5) of a line-contact radial bearing at zero clearance (Harris Table 7.1).
JR_LINE = 0.2453
#: Axial clearance between the layers, mm (rvcad.parts.AXIAL_CLEARANCE_MM; not imported: rvcad.parts
#: pulls in the CAD kernel).
AXIAL_CLEARANCE_MM = 0.5
BEARING_EXP = 10.0 / 9.0


def roller_contact_K(length_mm: float) -> float:
    """K_c (N/mm^(10/9)) of one roller-raceway line contact, Palmgren: Q = K_c delta^(10/9)."""
    return (length_mm ** 0.8 / PALMGREN_LINE) ** BEARING_EXP


def radial_bearing_K(z: int, length_mm: float) -> float:
    """Radial stiffness constant K_b (N/mm^(10/9)) of a roller bearing: F_r = K_b delta_r^(10/9).

    ``K_b = Z J_r(0.5) K_c / 2^(10/9)`` (each roller between two raceways, zero clearance)."""
    return z * JR_LINE * roller_contact_K(length_mm) / 2.0 ** BEARING_EXP


def radial_bearing_K_discrete(z: int, length_mm: float, cage_angle: float = 0.0) -> float:
    """The same constant from the roller sum ``F_r = K_n delta^(10/9) sum cos^(19/9)(psi_j)`` (loaded half)."""
    psi = cage_angle + 2.0 * math.pi * np.arange(z) / z
    c = np.cos(psi)
    kn = roller_contact_K(length_mm) / 2.0 ** BEARING_EXP
    return float(kn * np.sum(np.where(c > 0, c, 0.0) ** (1.0 + BEARING_EXP)))


def circle_shear_coefficient(nu: float) -> float:
    """Timoshenko shear coefficient of a solid circular section, ``6 (1 + nu)/(7 + 6 nu)`` (Cowper 1966)."""
    return 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu)


def guided_beam_stiffness(E: float, nu: float, radius: float, length: float) -> float:
    """Lateral stiffness (N/mm) of a round Timoshenko beam clamped at one end and guided at the other (ends
    displaced parallel, no end rotation): ``1/k = L^3/(12 E I) + L/(kappa G A)``, ``I = pi r^4/4``,
    ``A = pi r^2``, ``G = E/(2 (1 + nu))``. E in MPa, lengths in mm."""
    I = math.pi * radius ** 4 / 4.0
    A = math.pi * radius ** 2
    G = E / (2.0 * (1.0 + nu))
    return 1.0 / (length ** 3 / (12.0 * E * I) + length / (circle_shear_coefficient(nu) * G * A))


def pillar_length_mm(d: Design) -> float:
    """Free length of a pillar between the inner faces of the flange plate and the carrier end plate, mm:
    both discs, the gap between them and the axial clearance on either side."""
    return 2.0 * AXIAL_CLEARANCE_MM + 2.0 * d.disc_width_mm + d.disc_gap_mm


def carrier_torsional_stiffness(d: Design) -> float:
    """Torsional stiffness (N mm/rad) of the carrier end plate relative to the output flange through the
    pillars: ``n_p k r_p^2`` with ``k`` of :func:`guided_beam_stiffness` (material of the carrier, paper
    Table 2) and ``r_p`` the crank circle (the pillars stand midway between the cranks). The plates are
    taken rigid."""
    m = MATERIALS["carrier"]
    k = guided_beam_stiffness(m.E, m.nu, d.carrier_pillar_radius_mm, pillar_length_mm(d))
    return d.carrier_pillars * k * d.center_distance_mm ** 2


def pin_seat_contact(d: Design) -> LineContact:
    """Johnson constants of a pin in its housing groove over one disc's face width: convex pin radius
    ``r_pin`` in a concave groove of radius ``r_pin + pin_seat_clearance_mm`` (GCr15 pin, QT500-7 housing)."""
    r = d.pin_radius_mm
    return LineContact.of(np.array(r), np.array(-(r + d.pin_seat_clearance_mm)), MATERIALS["pin"],
                          MATERIALS["pin_housing"], d.disc_width_mm)


def _check_design(d: Design) -> None:
    for name in ("cam_bearing_rollers", "journal_bearing_rollers"):
        v = getattr(d, name)
        if isinstance(v, bool) or not isinstance(v, int) or v < 3:
            raise ValueError(f"design.{name} {v!r} must be an integer >= 3")
    for name in ("cam_bearing_roller_diameter_mm", "cam_bearing_roller_length_mm",
                 "journal_bearing_roller_diameter_mm", "journal_bearing_roller_length_mm"):
        v = getattr(d, name)
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
            raise ValueError(f"design.{name} {v!r} must be a finite number > 0 (mm)")


@dataclass(frozen=True)
class Supports:
    """Stiffness constants of the supports of one design.

    Attributes
    ----------
    cam_K, journal_K : N/mm^(10/9), radial stiffness constants of one cam / journal bearing
    cam_r, journal_r : mm, pitch radii of the rolling elements (friction lever)
    EI : N mm^2, bending stiffness of the crankshaft (journal radius over the whole span)
    GJ : N mm^2, torsional stiffness of the crankshaft
    z_planet, z_journal, z_cams : mm, axial positions (planet, journal A and B, cam planes of discs 0, 1)
    carrier_k : N mm/rad, torsional stiffness of the carrier end plate against the flange (pillars)
    """

    cam_K: float
    journal_K: float
    cam_r: float
    journal_r: float
    EI: float
    GJ: float
    z_planet: float
    z_journal: tuple[float, float]
    z_cams: tuple[float, float]
    carrier_k: float = math.inf

    @classmethod
    def from_design(cls, d: Design) -> "Supports":
        _check_design(d)
        c = AXIAL_CLEARANCE_MM
        g1 = d.gear_width_mm
        f = (g1 + c, g1 + c + d.plate_width_mm)
        d0 = (f[1] + c, f[1] + c + d.disc_width_mm)
        d1 = (d0[1] + d.disc_gap_mm, d0[1] + d.disc_gap_mm + d.disc_width_mm)
        cr = (d1[1] + c, d1[1] + c + d.plate_width_mm)
        m = MATERIALS["crankshaft"]
        r = d.crank_journal_radius_mm
        EI = m.E * math.pi * r ** 4 / 4.0
        GJ = m.E / (2.0 * (1.0 + m.nu)) * math.pi * r ** 4 / 2.0
        return cls(cam_K=radial_bearing_K(d.cam_bearing_rollers, d.cam_bearing_roller_length_mm),
                   journal_K=radial_bearing_K(d.journal_bearing_rollers, d.journal_bearing_roller_length_mm),
                   cam_r=d.cam_radius_mm - d.cam_bearing_roller_diameter_mm / 2.0,
                   journal_r=d.crank_journal_radius_mm + d.journal_bearing_roller_diameter_mm / 2.0,
                   EI=EI, GJ=GJ, z_planet=g1 / 2.0, z_journal=(sum(f) / 2.0, sum(cr) / 2.0),
                   z_cams=(sum(d0) / 2.0, sum(d1) / 2.0), carrier_k=carrier_torsional_stiffness(d))

    # ------------------------------------------------------------------ statics
    @staticmethod
    def cam_forces(F_disc: np.ndarray, M_disc: np.ndarray, arms: np.ndarray) -> np.ndarray:
        """Cam-bearing forces on each disc (N, nd, nc, 2), N: the least-norm split that balances the pin
        resultant ``F_disc`` (N, nd, 2) and moment ``M_disc`` (N, nd) N mm about the disc centre, with
        the cam centres at ``arms`` (N, nd, nc, 2) mm from it (equal bearings: the minimum-energy split
        of equal linear springs)."""
        N, nd, nc, _ = arms.shape
        A = np.zeros((N, nd, 3, 2 * nc))
        for h in range(nc):
            A[:, :, 0, 2 * h] = 1.0
            A[:, :, 1, 2 * h + 1] = 1.0
            A[:, :, 2, 2 * h] = -arms[:, :, h, 1]
            A[:, :, 2, 2 * h + 1] = arms[:, :, h, 0]
        rhs = -np.concatenate([F_disc, M_disc[..., None]], axis=-1)           # (N, nd, 3)
        AAt = A @ np.swapaxes(A, -1, -2)
        y = np.linalg.solve(AAt, rhs[..., None])
        b = (np.swapaxes(A, -1, -2) @ y)[..., 0]                                # (N, nd, 2 nc)
        return b.reshape(N, nd, nc, 2)

    def journal_forces(self, B: np.ndarray) -> np.ndarray:
        """Journal reactions (N, nc, 2 journals, 2), N, of the cam loads on each crank (lever rule).

        The crank receives ``-B[:, k, j]`` at cam plane k; the planet's mesh force (two orders smaller)
        is left out of the journal and bending loads."""
        Q = -np.swapaxes(B, 1, 2)                                               # (N, nc, nd, 2)
        zA, zB = self.z_journal
        span = zB - zA
        wB = (np.asarray(self.z_cams) - zA) / span                              # (nd,)
        RB = np.einsum("k,njkx->njx", wB, Q)
        RA = Q.sum(axis=2) - RB
        return np.stack([RA, RB], axis=2)

    def bending_deflections(self, B: np.ndarray) -> np.ndarray:
        """Crankshaft deflection at the cam planes (N, nc, nd, 2), mm, under the cam loads."""
        Q = -np.swapaxes(B, 1, 2)
        zA, zB = self.z_journal
        L = zB - zA
        xs = np.asarray(self.z_cams) - zA
        nd = len(xs)
        infl = np.zeros((nd, nd))                                               # deflection at x_i per unit load at a_k
        for i, x in enumerate(xs):
            for k, a in enumerate(xs):
                if x <= a:
                    b = L - a
                    infl[i, k] = b * x * (L * L - b * b - x * x) / (6.0 * self.EI * L)
                else:
                    xx = L - x
                    infl[i, k] = a * xx * (L * L - a * a - xx * xx) / (6.0 * self.EI * L)
        return np.einsum("ik,njkx->njix", infl, Q)

    def far_journal_share(self) -> float:
        """Share ``beta`` of the output torque that the far journals (carrier end plate) take: the lever rule of
        each crank with the torque shared equally by the discs, the mean axial position of the cam planes
        between the journals (1/2 for the default design)."""
        zA, zB = self.z_journal
        return float(np.mean((np.asarray(self.z_cams) - zA) / (zB - zA)))

    def torsion_lever_mm(self) -> float:
        """Length of crankshaft twisted by the planet torque: planet plane to the mean cam plane, mm."""
        return float(np.mean(self.z_cams) - self.z_planet)
