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
  ``F_r = Z J_r(0.5) K_n delta_r^(10/9)`` with ``J_r(0.5) = 0.2453`` (line contact). A tapered roller bearing of
  contact angle alpha held axially (Harris, sec. 7.3: ``delta_psi = delta_a sin(alpha) + delta_r cos(alpha)
  cos(psi)``, ``delta_a = 0``; the radial component of each roller load is ``Q cos(alpha)``):
  ``F_r = Z J_r(0.5) K_n cos(alpha)^(19/9) delta_r^(10/9)``.
- Crankshaft bending: simply supported beam between the journals, point loads at the cam planes, stepped
  (journal radius on the journals, eccentric radius ``cam_radius - cam roller diameter`` over the discs: the
  needles run on the eccentric) with shear (Timoshenko): influence coefficients by the unit-load (Maxwell-Mohr)
  integral ``d_ik = int m_i m_k / (E I) dx + int v_i v_k / (kappa G A) dx`` (Timoshenko & Gere; Roark sec. 8.10);
  uniform and shear-free it is Roark Table 8.1 case 1e, ``y(x) = Q b x (L^2 - b^2 - x^2) / (6 E I L)``.
- Crankshaft torsion between the planet and the mean cam plane: ``phi = M_t sum l_i / (G J_p,i)`` over the
  stepped sections (journal radius to the first disc, eccentric beyond), i.e. a spring
  ``1 / (sum l_i/(G J_p,i) r_b2^2)`` along the stage I line of action, in series with the mesh (in the
  equilibrium).
- Tapered journal bearings' effective load centres (NSK, *Rolling Bearings*): ``R_o tan(alpha)`` from the roller's
  mid-plane towards the cup's wide end, inwards face to face (the default), outwards back to back; the crank's
  beam spans the load centres.
- Bearing seats (Palmgren assumes rigidly backed rings): the disc hole around a cam bearing and the plate bore
  around a journal bearing as a rigid disc bonded in a plate annulus held at radius b, generalised plane stress,
  ``U/F = [kappa ln(b/a) - (b^2 - a^2)/(kappa (b^2 + a^2))]/(2 pi G (1 + kappa) t)`` (from Muskhelishvili's
  potentials), in series with the bearing (rvdyn.support_eq.radial_law).
- Carrier: the far (carrier) end plate reaches the output flange through the pillars. A pillar is a Timoshenko
  beam built into both plates, its ends displaced parallel (guided): ``1/k = L^3/(12 E I) + L/(kappa G A) +
  L^2/(2 k_theta)`` (Timoshenko & Gere, *Mechanics of Materials*; shear coefficient of a solid circle ``kappa = 6
  (1 + nu)/(7 + 6 nu)``, Cowper 1966), each root turning in its plate as a rigid disc rocking on a half-space,
  ``k_theta = 4 E a^3/(3 (1 - nu^2))`` (Richart, Hall & Woods 1970; Gazetas 1991); the plate turns by ``phi``
  relative to the flange against ``k_t = n_p k r_p^2``
  (pillars on the circle r_p). The turn is a coordinate of the equilibrium (rvdyn.support_eq: it carries
  journal B of every crank along the crank circle), so the torque split between the journals is solved;
  :meth:`Supports.far_journal_share` is the lever-rule statics of equal discs (1/2 by default), for reference.
- Pin seat: each pin lies in a housing groove of radius ``r_pin + clearance``; a conformal Hertz line contact
  (Johnson 1985, eq. 5.36 with a concave ``R2 = -(r_pin + clearance)``) in series with the pin-disc contact
  over the disc's face width. Both are ``delta = A_i P (C_i - ln P)`` in the same load per length ``P``, so
  the series law is the same form with ``A = A_1 + A_2``, ``C = (A_1 C_1 + A_2 C_2)/A``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rvcad.layout import PLATE_RIM_CLEARANCE_MM
from rvcad.params import Design
from rvdyn.materials import MATERIALS, LineContact, Material

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


def radial_bearing_K(z: int, length_mm: float, contact_angle_deg: float = 0.0) -> float:
    """Radial stiffness constant K_b (N/mm^(10/9)) of a roller bearing: F_r = K_b delta_r^(10/9).

    ``K_b = Z J_r(0.5) K_c cos(alpha)^(19/9) / 2^(10/9)`` (each roller between two raceways, zero clearance;
    alpha the contact angle of a tapered roller bearing held axially, 0 for a cylindrical one: a radial shift
    delta_r compresses the roller at psi by ``delta_r cos(alpha) cos(psi)`` and its load acts on the shaft with
    the radial component ``Q cos(alpha)``, Harris sec. 7.3)."""
    ca = math.cos(math.radians(contact_angle_deg))
    return z * JR_LINE * roller_contact_K(length_mm) * ca ** (1.0 + BEARING_EXP) / 2.0 ** BEARING_EXP


def radial_bearing_K_discrete(z: int, length_mm: float, cage_angle: float = 0.0,
                              contact_angle_deg: float = 0.0) -> float:
    """The same constant from the roller sum: roller j at psi_j compressed by ``delta cos(alpha) cos(psi_j)``
    carries ``Q_j = K_n (delta cos(alpha) cos(psi_j))^(10/9)`` whose radial component along delta is
    ``Q_j cos(alpha) cos(psi_j)``: ``F_r = K_n cos(alpha)^(19/9) delta^(10/9) sum cos^(19/9)(psi_j)`` (loaded half)."""
    psi = cage_angle + 2.0 * math.pi * np.arange(z) / z
    c = np.cos(psi)
    ca = math.cos(math.radians(contact_angle_deg))
    kn = roller_contact_K(length_mm) / 2.0 ** BEARING_EXP
    q = kn * (ca * np.where(c > 0, c, 0.0)) ** BEARING_EXP                     # roller loads per unit delta^(10/9)
    return float(np.sum(q * ca * np.where(c > 0, c, 0.0)))


def circle_shear_coefficient(nu: float) -> float:
    """Timoshenko shear coefficient of a solid circular section, ``6 (1 + nu)/(7 + 6 nu)`` (Cowper 1966)."""
    return 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu)


def root_rotational_stiffness(E: float, nu: float, radius: float) -> float:
    """Rotational stiffness (N mm/rad) of the root of a round bar of radius a built into an elastic body, taken as
    a rigid circular punch rocking on an elastic half-space (Sneddon's tilted flat punch; the static rocking
    stiffness of a rigid circular foundation, Richart, Hall & Woods 1970, Gazetas 1991):
    ``k_theta = 8 G a^3 / (3 (1 - nu)) = 4 E a^3 / (3 (1 - nu^2))``. E in MPa, a in mm."""
    return 4.0 * E * radius ** 3 / (3.0 * (1.0 - nu * nu))


def guided_beam_stiffness(E: float, nu: float, radius: float, length: float,
                          root_k: float = math.inf) -> float:
    """Lateral stiffness (N/mm) of a round Timoshenko beam whose ends are built into two bodies that move parallel
    (guided: the bodies do not turn): ``1/k = L^3/(12 E I) + L/(kappa G A) + L^2/(2 k_theta)``, ``I = pi r^4/4``,
    ``A = pi r^2``, ``G = E/(2 (1 + nu))``. ``root_k`` (N mm/rad): the rotational stiffness ``k_theta`` of each
    built-in end (:func:`root_rotational_stiffness`; ``inf``: rigidly clamped). By symmetry both end moments are
    ``F L/2``; each root turns by ``F L/(2 k_theta)`` in the same sense, which moves one end against the other by
    ``F L^2/(2 k_theta)`` (slope-deflection equations). E in MPa, lengths in mm."""
    I = math.pi * radius ** 4 / 4.0
    A = math.pi * radius ** 2
    G = E / (2.0 * (1.0 + nu))
    c = length ** 3 / (12.0 * E * I) + length / (circle_shear_coefficient(nu) * G * A)
    if math.isfinite(root_k):
        c += length ** 2 / (2.0 * root_k)
    return 1.0 / c


def stepped_beam_influence(L: float, sections: tuple, xs) -> np.ndarray:
    """Influence matrix (n, n), mm/N, of a simply supported stepped Timoshenko beam on ``[0, L]``: deflection
    at ``xs[i]`` per unit transverse load at ``xs[k]``, by the unit-load (Maxwell-Mohr) integral

        d_ik = int_0^L m_i m_k / (E I) dx + int_0^L v_i v_k / (kappa G A) dx

    with the bending moment ``m_a(x) = x (L - a)/L`` (x <= a), ``a (L - x)/L`` (x >= a) and the shear force
    ``v_a = (L - a)/L`` (x < a), ``-a/L`` (x > a) of a unit load at a (Timoshenko & Gere, *Mechanics of
    Materials*, unit-load method with shear; Roark sec. 8.10). ``sections``: ``(x0, x1, EI, kGA)`` tuples
    (mm, N mm^2, N) covering ``[0, L]``. Exact: the integrand is piecewise quadratic, integrated by two-point
    Gauss-Legendre on every interval between section ends and load points."""
    xs = np.asarray(xs, dtype=float)
    n = xs.size
    out = np.zeros((n, n))
    g = 0.5 / math.sqrt(3.0)
    for x0, x1, EI, kGA in sections:
        cuts = np.unique(np.concatenate([[x0, x1], xs[(xs > x0) & (xs < x1)]]))
        for a, b in zip(cuts[:-1], cuts[1:]):
            h = b - a
            if h <= 0.0:
                continue
            mid = 0.5 * (a + b)
            for x in (mid - g * h, mid + g * h):
                m = np.where(x <= xs, x * (L - xs) / L, xs * (L - x) / L)               # (n,)
                v = np.where(x < xs, (L - xs) / L, -xs / L)
                out += 0.5 * h * (np.outer(m, m) / EI + np.outer(v, v) / kGA)
    return out


def crank_sections(d: Design, z_journal: tuple[float, float], discs: tuple) -> tuple:
    """Sections ``(x0, x1, EI, kGA)`` of the crankshaft between the journal mid-planes, x from journal A, mm:
    the journal radius on the journals and the axial clearances, the eccentric radius ``cam_radius -
    cam roller diameter`` (the needles run on the eccentric) over both discs and the gap between them; solid
    round sections of the crankshaft's material, Cowper's shear coefficient."""
    m = MATERIALS["crankshaft"]
    G = m.E / (2.0 * (1.0 + m.nu))
    kap = circle_shear_coefficient(m.nu)
    zA, zB = z_journal

    def sec(z0: float, z1: float, r: float) -> tuple[float, float, float, float]:
        return (z0 - zA, z1 - zA, m.E * math.pi * r ** 4 / 4.0, kap * G * math.pi * r ** 2)

    rj, re = d.crank_journal_radius_mm, d.cam_radius_mm - d.cam_bearing_roller_diameter_mm
    e0, e1 = discs[0][0], discs[-1][1]
    return (sec(zA, e0, rj), sec(e0, e1, re), sec(e1, zB, rj))


def annulus_seat_compliance(E: float, nu: float, a: float, b: float, t: float) -> float:
    """Compliance (mm/N) of a bearing seat: a rigid disc of radius a bonded in a plate annulus of outer radius b
    (held fixed) and thickness t, translated in the plane by a force (generalised plane stress):

        U / F = [kappa ln(b/a) - (b^2 - a^2) / (kappa (b^2 + a^2))] / (2 pi G (1 + kappa) t),
        kappa = (3 - nu)/(1 + nu),  G = E / (2 (1 + nu))

    from Muskhelishvili's potentials of a resultant force on a contour (``phi = alpha ln z + lambda z^2``,
    ``psi = -kappa alpha ln z + zeta / z^2``, ``alpha = -F/(2 pi (1 + kappa) t)``; the constant and the
    ``e^{2 i theta}`` parts of the displacement matched at r = a and r = b; docs/physics.md, section 8). E in
    MPa, lengths in mm."""
    if not (0.0 < a < b):
        raise ValueError(f"annulus radii a = {a!r} mm, b = {b!r} mm must satisfy 0 < a < b")
    G = E / (2.0 * (1.0 + nu))
    k = (3.0 - nu) / (1.0 + nu)
    return ((k * math.log(b / a) - (b * b - a * a) / (k * (b * b + a * a)))
            / (2.0 * math.pi * G * (1.0 + k) * t))


def plate_outer_radius_mm(d: Design) -> float:
    """Outer radius of the flange plate and the carrier end plate, mm (rvcad.plates: the pin circle less the
    eccentricity, the pin radius and ``PLATE_RIM_CLEARANCE_MM``)."""
    return d.pin_circle_radius_mm - d.eccentricity_mm - d.pin_radius_mm - PLATE_RIM_CLEARANCE_MM


def cam_seat_compliance(d: Design) -> float:
    """Compliance (mm/N) of a disc hole around its needle bearing (the outer raceway's elastic support):
    :func:`annulus_seat_compliance` with the hole radius ``cam_radius_mm``, the outer radius the distance from
    the hole's centre to the pin circle (where the disc is held, by the pins), the disc's width and material."""
    m = MATERIALS["cycloid_disc"]
    b = d.pin_circle_radius_mm - d.center_distance_mm
    if not b > d.cam_radius_mm:
        raise ValueError(f"design.cam_radius_mm {d.cam_radius_mm!r} must be < pin circle radius - centre distance "
                         f"= {b!r} mm (the disc around the crank hole)")
    return annulus_seat_compliance(m.E, m.nu, d.cam_radius_mm, b, d.disc_width_mm)


def journal_seat_compliance(d: Design) -> float:
    """Compliance (mm/N) of a plate bore around a journal bearing: :func:`annulus_seat_compliance` with the
    radius of the outer raceway (``crank_journal_radius_mm + journal_bearing_roller_diameter_mm``; the cup is
    counted as plate material), the outer radius the distance from the bore's centre to the plate's rim (where
    the main bearing holds it), the plate's width and material (ZG65Mn, both plates)."""
    m = MATERIALS["flange_plate"]
    a = d.crank_journal_radius_mm + d.journal_bearing_roller_diameter_mm
    b = plate_outer_radius_mm(d) - d.center_distance_mm
    if not b > a:
        raise ValueError(f"design.crank_journal_radius_mm + journal_bearing_roller_diameter_mm = {a!r} mm must be < "
                         f"plate rim - centre distance = {b!r} mm (the plate around the journal bearing)")
    return annulus_seat_compliance(m.E, m.nu, a, b, d.plate_width_mm)


def journal_load_centre_offset_mm(d: Design) -> float:
    """Axial offset (mm) of a tapered journal bearing's effective load centre from its mid-plane, inwards (towards
    the discs) positive: the load line of the outer ring (normal to the cup raceway through the roller's
    mid-length, at the outer raceway radius ``R_o = crank_journal_radius_mm + journal_bearing_roller_diameter_mm``)
    crosses the axis ``R_o tan(alpha)`` from the roller's mid-plane, towards the cup's wide end (NSK, *Rolling
    Bearings*, "effective load centre": the intersection of the shaft's axis with the line of the load the outer
    ring applies to the rolling elements; the catalogues' ``a = T/2 + (d + D) e/6`` is the same with the mean
    radius and ``e = 1.5 tan(alpha)``). Face to face (X) the wide ends face each other: +R_o tan(alpha); back to
    back (O): -R_o tan(alpha); 0 for a cylindrical bearing (alpha = 0)."""
    ro = d.crank_journal_radius_mm + d.journal_bearing_roller_diameter_mm
    off = ro * math.tan(math.radians(d.journal_bearing_contact_angle_deg))
    return off if d.journal_bearing_arrangement == "face_to_face" else -off


def pillar_length_mm(d: Design) -> float:
    """Free length of a pillar between the inner faces of the flange plate and the carrier end plate, mm:
    both discs, the gap between them and the axial clearance on either side."""
    return 2.0 * AXIAL_CLEARANCE_MM + 2.0 * d.disc_width_mm + d.disc_gap_mm


def carrier_torsional_stiffness(d: Design, root: bool = True) -> float:
    """Torsional stiffness (N mm/rad) of the carrier end plate relative to the output flange through the
    pillars: ``n_p k r_p^2`` with ``k`` of :func:`guided_beam_stiffness` (material of the carrier, paper
    Table 2) and ``r_p`` the crank circle (the pillars stand midway between the cranks). The plates move as
    rigid bodies; each pillar root turns in its plate against :func:`root_rotational_stiffness` (``root``
    False: rigidly clamped roots, an upper bound of the clamping). Both plates are of the carrier's material (ZG65Mn)."""
    m = MATERIALS["carrier"]
    if MATERIALS["flange_plate"] != Material(MATERIALS["flange_plate"].name, m.E, m.nu):
        raise ValueError("the pillar roots assume the flange plate and the carrier of one material")
    rk = root_rotational_stiffness(m.E, m.nu, d.carrier_pillar_radius_mm) if root else math.inf
    k = guided_beam_stiffness(m.E, m.nu, d.carrier_pillar_radius_mm, pillar_length_mm(d), rk)
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
    if not d.cam_bearing_roller_diameter_mm < d.cam_radius_mm:
        raise ValueError(f"design.cam_bearing_roller_diameter_mm {d.cam_bearing_roller_diameter_mm!r} must be < "
                         f"cam_radius_mm = {d.cam_radius_mm!r} mm (the needles run on the eccentric inside the disc "
                         "hole: the eccentric's radius is cam_radius_mm - roller diameter)")
    a = d.journal_bearing_contact_angle_deg
    if not (isinstance(a, (int, float)) and not isinstance(a, bool) and math.isfinite(a) and 0.0 <= a < 45.0):
        raise ValueError(f"design.journal_bearing_contact_angle_deg {a!r} must be a finite angle in [0, 45) deg")


@dataclass(frozen=True)
class Supports:
    """Stiffness constants of the supports of one design.

    Attributes
    ----------
    cam_K, journal_K : N/mm^(10/9), radial stiffness constants of one cam / journal bearing
    cam_r, journal_r : mm, pitch radii of the rolling elements (friction lever)
    EI : N mm^2, bending stiffness of the crankshaft's journal section (the uniform Euler beam when
        ``sections`` is empty)
    GJ : N mm^2, torsional stiffness of the crankshaft (journal section)
    z_planet, z_journal, z_cams : mm, axial positions (planet, journal A and B, cam planes of discs 0, 1)
    carrier_k : N mm/rad, torsional stiffness of the carrier end plate against the flange (pillars)
    sections : ``(x0, x1, EI, kGA)`` tuples of the stepped Timoshenko crank between the journals
        (:func:`crank_sections`; x from journal A, mm); empty: a uniform Euler beam of ``EI``
    crank_radius : mm, radius of the crank circle (the carrier's turn moves journal B by crank_radius * phi)
    GJ_sections : ``(z0, z1, GJ)`` tuples (axial positions, mm; N mm^2) of the crank from its planet end: the
        journal radius up to the first disc, the eccentric radius beyond (:meth:`torsion_compliance`)
    cam_seat_c, journal_seat_c : mm/N, compliance of the disc hole around a cam bearing and of the plate bore
        around a journal bearing, in series with the bearing (:func:`cam_seat_compliance`,
        :func:`journal_seat_compliance`; 0: rigidly backed rings)
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
    sections: tuple = ()
    crank_radius: float = 1.0
    GJ_sections: tuple = ()
    cam_seat_c: float = 0.0
    journal_seat_c: float = 0.0

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
        re = d.cam_radius_mm - d.cam_bearing_roller_diameter_mm                # the eccentric (needle raceway)
        off = journal_load_centre_offset_mm(d)
        zj = (sum(f) / 2.0 + off, sum(cr) / 2.0 - off)                        # effective load centres
        if not (zj[0] < sum(d0) / 2.0 and sum(d1) / 2.0 < zj[1]):
            raise ValueError(f"design.journal_bearing_arrangement {d.journal_bearing_arrangement!r}: the journal "
                             f"bearings' load centres ({zj[0]:.3f}, {zj[1]:.3f} mm) must lie outside the cam planes")
        return cls(cam_K=radial_bearing_K(d.cam_bearing_rollers, d.cam_bearing_roller_length_mm),
                   journal_K=radial_bearing_K(d.journal_bearing_rollers, d.journal_bearing_roller_length_mm,
                                              d.journal_bearing_contact_angle_deg),
                   cam_r=d.cam_radius_mm - d.cam_bearing_roller_diameter_mm / 2.0,
                   journal_r=d.crank_journal_radius_mm + d.journal_bearing_roller_diameter_mm / 2.0,
                   EI=EI, GJ=GJ, z_planet=g1 / 2.0, z_journal=zj,
                   z_cams=(sum(d0) / 2.0, sum(d1) / 2.0), carrier_k=carrier_torsional_stiffness(d),
                   sections=crank_sections(d, zj, (d0, d1)), crank_radius=d.center_distance_mm,
                   GJ_sections=((0.0, d0[0], GJ), (d0[0], d1[1], GJ * (re / r) ** 4)),
                   cam_seat_c=cam_seat_compliance(d), journal_seat_c=journal_seat_compliance(d))

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

    def friction_arms(self, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Friction moment per unit coefficient (N mm) of each cam bearing (N, nd, nc) and each crank's two journals
        together (N, nc) under the cam forces B (N, nd, nc, 2): ``|F| r`` at the roller pitch radius (SKF's constant
        coefficient; the stiffness sweep and rvdyn.friction multiply them by their relative turn rates)."""
        cam = np.linalg.norm(B, axis=-1) * self.cam_r
        journal = np.linalg.norm(self.journal_forces(B), axis=-1).sum(axis=2) * self.journal_r
        return cam, journal

    def bending_deflections(self, B: np.ndarray) -> np.ndarray:
        """Crankshaft deflection at the cam planes (N, nc, nd, 2), mm, under the cam loads: the stepped
        Timoshenko beam of ``sections`` (:func:`stepped_beam_influence`), or without sections the uniform Euler
        beam (Roark Table 8.1 case 1e)."""
        Q = -np.swapaxes(B, 1, 2)
        zA, zB = self.z_journal
        L = zB - zA
        xs = np.asarray(self.z_cams) - zA
        nd = len(xs)
        if self.sections:                                                       # stepped Timoshenko crank
            return np.einsum("ik,njkx->njix", stepped_beam_influence(L, self.sections, xs), Q)
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

    def torsion_compliance(self) -> float:
        """Torsional compliance (rad per N mm) of the crankshaft between the planet plane and the mean cam plane:
        ``sum l_i / (G J_i)`` over its sections (the planet's bore and the journal at the journal radius up to the
        first disc, the eccentric beyond; ``GJ_sections``), or ``l / GJ`` without sections."""
        z0, z1 = self.z_planet, float(np.mean(self.z_cams))
        if not self.GJ_sections:
            return (z1 - z0) / self.GJ
        c = 0.0
        for a, b, GJ in self.GJ_sections:
            lo, hi = max(a, z0), min(b, z1)
            if hi > lo:
                c += (hi - lo) / GJ
        return c

