"""The pin housing as an elastic ring under the pin forces, and the output wind-up it adds.

docs/physics.md, section 9 ("Housing ring"). The housing between the bottom of the pin grooves and its outer
radius, over both discs' width (the pin band), is a thin ring of mean radius ``R`` and bending stiffness ``E I``
(QT500-7). Its in-plane displacement is expanded in the inextensional ring modes ``n >= 2`` (Castigliano; Timoshenko,
*Strength of Materials* II, sec. on thin rings; Roark's formulas of Table 9.2 are their sums):

    w = A cos(n theta),  v = -A sin(n theta)/n        (radial w outward, tangential v; v' + w = 0)

(and the same with sin / cos). Modes 0 and 1 are the housing's torque and translation, held by its mounting. The
ring's strain energy per mode is ``pi E I (n^2 - 1)^2 A^2/(2 R^3)``; a radial Winkler foundation of modulus ``k_f``
(N/mm per mm of arc) adds ``pi R k_f A^2/2``. Under point forces ``(F_r, F_t)`` at the pins the generalised force of
a mode is ``sum F_r w + F_t v``, so the displacements at the pins are ``d = C F`` with the symmetric compliance

    C = sum_n  phi_n phi_n^T / k_n,   k_n = pi E I (n^2 - 1)^2 / R^3 + pi R k_f.

Supports (``Design.housing_support``):

- ``"main_bearings"`` (default): the housing is held round at the main bearings, which ride on the rims of the
  flange plate and of the carrier end plate (the model's assumption already: the plates' rims are held by the main
  bearings, rvdyn.bearings.journal_seat_compliance). The wall of the housing on either side of the pin band, from
  the band's edge to the plate's mid-plane (``L = axial clearance + plate width / 2``), is a strip of unit width and
  depth ``h`` (the wall thickness) built in at the bearing and guided at the band (the band does not tilt, by
  symmetry): a Timoshenko beam, ``1/k = L^3/(12 E I_s) + L/(kappa G h)``, ``I_s = h^3/12``, Cowper's rectangle
  ``kappa = 10 (1 + nu)/(12 + 11 nu)``; ``k_f = 2 k``. With L/h below 1 the strips are short blocks, shear-dominated;
  the beam formula is an idealisation (stated in docs/physics.md), and the main bearings are taken as holding the
  wall round (their ball sets are far stiffer in the ring modes than the ring).
- ``"free"``: no foundation (``k_f = 0``): an upper bound (``benchmarks/housing_ring_estimate.py``).

The wind-up (unit-load method, incremental): along the torque levels of the stiffness sweep the pin forces on the
housing change by ``dF_j`` over ``dT_j``; the output turns by ``sum_j dF_j^T C dF_j / dT_j`` (``f = dF/dT`` the load
of a unit output torque, ``C dF`` the housing's displacement increment; with loads proportional to T this is
``F^T C F / T``, Castigliano). The pin forces are those of the equilibrium with a rigid housing: the complementary
energy of that statically admissible load path bounds the coupled solution's from above, so the term, added in
series, is an upper bound of the housing's share for the ring model chosen. Each pin force on the housing acts
along the line from the pin's centre to the pitch point of its disc (every normal of the conjugate profile passes
through it: the point ``Zp (c_k - c_H)/(Zp - Zc)`` from the housing's centre ``c_H`` through the disc centre
``c_k``; exact for an unmodified profile without errors, an approximation otherwise).
"""
from __future__ import annotations

import math

import numpy as np

from rvcad.params import HOUSING_SUPPORTS, Design  # HOUSING_SUPPORTS: ("main_bearings", "free")
from rvdyn.materials import MATERIALS
#: Axial clearance between the layers, mm (the same as rvdyn.bearings.AXIAL_CLEARANCE_MM).
AXIAL_CLEARANCE_MM = 0.5


def rectangle_shear_coefficient(nu: float) -> float:
    """Timoshenko shear coefficient of a rectangular section, ``10 (1 + nu)/(12 + 11 nu)`` (Cowper 1966)."""
    return 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)


def ring_mode_stiffness(n: np.ndarray, E: float, I: float, R: float, k_found: float = 0.0) -> np.ndarray:
    """Modal stiffness (N/mm) of the inextensional mode n >= 2 of a thin ring on a radial Winkler foundation:
    ``pi E I (n^2 - 1)^2 / R^3 + pi R k_f``. E in MPa, I in mm^4, R in mm, k_f in N/mm^2."""
    n = np.asarray(n, dtype=float)
    if np.any(n < 2):
        raise ValueError(f"ring modes {n!r} must be >= 2 (modes 0 and 1 are held by the mounting)")
    return math.pi * E * I * (n * n - 1.0) ** 2 / R ** 3 + math.pi * R * k_found


def ring_compliance(angles: np.ndarray, E: float, I: float, R: float, k_found: float = 0.0,
                    n_max: int = 200) -> np.ndarray:
    """Compliance matrix (2 Z, 2 Z), mm/N, of a thin ring at the points ``angles`` (rad): rows and columns
    ``(r_0 .. r_{Z-1}, t_0 .. t_{Z-1})``, the radial (outward) and tangential (+theta) components; modes 2..n_max."""
    th = np.asarray(angles, dtype=float)
    n = np.arange(2, int(n_max) + 1, dtype=float)
    k = ring_mode_stiffness(n, E, I, R, k_found)
    nt = np.outer(th, n)                                                       # (Z, modes)
    c, s = np.cos(nt), np.sin(nt)
    # the cos family: w = cos, v = -sin/n; the sin family: w = sin, v = cos/n
    phi_c = np.concatenate([c, -s / n], axis=0)                                # (2Z, modes)
    phi_s = np.concatenate([s, c / n], axis=0)
    return (phi_c / k) @ phi_c.T + (phi_s / k) @ phi_s.T


def housing_ring_section(d: Design) -> tuple[float, float, float, float]:
    """The pin band as a ring: mean radius R, radial depth h, axial width b and bending stiffness E I (N mm^2):
    from the bottom of the pin grooves (``Rp + r_pin``) to ``housing_outer_radius_mm``, over both discs and
    their gap, QT500-7."""
    r_in = d.pin_circle_radius_mm + d.pin_radius_mm
    h = d.housing_outer_radius_mm - r_in
    if not h > 0:
        raise ValueError(f"design.housing_outer_radius_mm {d.housing_outer_radius_mm!r} must be > Rp + pin radius "
                         f"= {r_in!r} mm (the housing wall around the pin grooves)")
    R = 0.5 * (r_in + d.housing_outer_radius_mm)
    b = 2.0 * d.disc_width_mm + d.disc_gap_mm
    return R, h, b, MATERIALS["pin_housing"].E * b * h ** 3 / 12.0


def housing_wall_length_mm(d: Design) -> float:
    """Axial length (mm) of the housing wall from the pin band's edge to a main bearing's plane (the plate's
    mid-plane): the axial clearance plus half the plate's width."""
    return AXIAL_CLEARANCE_MM + 0.5 * d.plate_width_mm


def housing_foundation_modulus(d: Design) -> float:
    """Radial foundation modulus k_f (N/mm per mm of arc) of the pin band held by the housing wall on both sides:
    ``2 / (L^3/(12 E I_s) + L/(kappa G h))`` with ``I_s = h^3/12`` (unit width), 0 for ``housing_support =
    "free"``."""
    support = d.housing_support
    if support not in HOUSING_SUPPORTS:
        raise ValueError(f"design.housing_support {support!r} must be one of {list(HOUSING_SUPPORTS)}")
    if support == "free":
        return 0.0
    m = MATERIALS["pin_housing"]
    _, h, _, _ = housing_ring_section(d)
    L = housing_wall_length_mm(d)
    G = m.E / (2.0 * (1.0 + m.nu))
    c = L ** 3 / (12.0 * m.E * h ** 3 / 12.0) + L / (rectangle_shear_coefficient(m.nu) * G * h)
    return 2.0 / c


def housing_compliance(d: Design, pin_angles: np.ndarray, n_max: int | None = None) -> np.ndarray:
    """Compliance matrix (2 Zp, 2 Zp), mm/N, of the housing at the pins (radial, tangential; see
    :func:`ring_compliance`) for the design's support. Modes up to ``4 Zp`` by default (beyond, a pin's share is
    below 1e-3 of the sum)."""
    R, _, _, EI = housing_ring_section(d)
    nm = 4 * d.z_pins if n_max is None else int(n_max)
    return ring_compliance(pin_angles, 1.0, EI, R, housing_foundation_modulus(d), nm)


def pitch_points(housing_centre: np.ndarray, disc_centres: np.ndarray, z_pins: int, z_disc: int) -> np.ndarray:
    """The discs' pitch points (mm, the shape of ``disc_centres``): on the line from the housing's centre through each
    disc's centre at ``Zp/(Zp - Zc)`` times their distance. Every contact normal of the conjugate profile passes
    through it, and it is the disc's point at rest relative to the housing (rvdyn.friction)."""
    return housing_centre + z_pins / (z_pins - z_disc) * (disc_centres - housing_centre)


def pin_force_vectors(pins: np.ndarray, housing_centre: np.ndarray, disc_centres: np.ndarray,
                      forces: np.ndarray, z_pins: int, z_disc: int) -> np.ndarray:
    """Forces (Zp, 2), N, of the discs on the housing through the pins (fixed frame): pin i of disc k pushes the
    housing along the line from the pitch point of disc k to the pin's centre with ``forces[k, i]`` (N).

    ``pins`` (Zp, 2) mm; ``disc_centres`` (n_discs, 2) mm; the pitch point of a disc lies on the line from the
    housing's centre through the disc's centre at ``Zp/(Zp - Zc)`` times their distance."""
    out = np.zeros_like(pins, dtype=float)
    for k in range(forces.shape[0]):
        P = pitch_points(housing_centre, disc_centres[k], z_pins, z_disc)
        u = pins - P
        u = u / np.linalg.norm(u, axis=1)[:, None]
        out += forces[k][:, None] * u
    return out


def polar_components(pins: np.ndarray, housing_centre: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Stack ``(F_r, F_t)`` (2 Zp,) of forces F (Zp, 2) at the pins in the housing's polar frame."""
    rel = pins - housing_centre
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    er = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    et = np.stack([-er[:, 1], er[:, 0]], axis=-1)
    return np.concatenate([np.sum(F * er, axis=1), np.sum(F * et, axis=1)])


def incremental_windup(C: np.ndarray, loads: list[np.ndarray], torques_Nmm: np.ndarray) -> np.ndarray:
    """Output wind-up (rad) at each torque level: ``theta_k = sum_{j <= k} dF_j^T C dF_j / dT_j`` with ``dF_j`` the
    change of the stacked polar pin loads (N) between levels j-1 and j and ``dT_j`` that of the torque (N mm); the
    first level is the reference (theta 0). Torques must increase strictly."""
    T = np.asarray(torques_Nmm, dtype=float)
    if T.size != len(loads) or np.any(np.diff(T) <= 0):
        raise ValueError("torque levels must increase strictly and match the loads")
    out = np.zeros(T.size)
    for j in range(1, T.size):
        dF = loads[j] - loads[j - 1]
        out[j] = out[j - 1] + float(dF @ C @ dF) / (T[j] - T[j - 1])
    return out
