"""Materials (paper Table 2) and the elastic contact formulas of the physical contact law.

Units: N, mm, MPa (= N/mm^2). Sources (docs/physics.md, section 7):

- Hertzian line contact of two parallel cylinders (Johnson, *Contact Mechanics*, 1985, sec. 4.2 and
  eq. 5.36 / p. 101): half-width ``b = sqrt(4 P R / (pi E*))``, peak pressure
  ``p0 = sqrt(P E* / (pi R))``, approach of the two cylinder axes
  ``delta = P/pi * sum_i (1 - nu_i^2)/E_i (2 ln(4 R_i / b) - 1)`` with ``P`` the load per unit
  length, ``1/R = 1/R1 + 1/R2`` (a concave R negative), ``1/E* = sum (1 - nu_i^2)/E_i``.
- Involute mesh stiffness per ISO 6336-1:2019 method B (sec. 9): single-tooth stiffness
  ``c' = c'_th C_M C_R C_B cos(beta) E/E_st`` with ``1/c'_th = q'`` (eq. 43 coefficients), mesh
  stiffness ``c_gamma_alpha = c' (0.75 eps_alpha + 0.25)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Material:
    """Elastic constants of one part (paper Table 2). ``E`` in MPa (N/mm^2)."""

    name: str
    E: float
    nu: float

    @property
    def c(self) -> float:
        """(1 - nu^2)/E, 1/MPa."""
        return (1.0 - self.nu ** 2) / self.E


#: Paper Table 2 (E converted from N/m^2 to N/mm^2). Rolling elements and races of the bearings are
#: not in the table: bearing steel GCr15 (= the pins' material) is assumed for them.
MATERIALS: dict[str, Material] = {
    "sun_gear": Material("15CrMo", 2.12e5, 0.284),
    "planet_gear": Material("38CrMoAl", 2.11e5, 0.277),
    "crankshaft": Material("20CrMnMo", 2.07e5, 0.254),
    "carrier": Material("ZG65Mn", 1.98e5, 0.230),
    "pin_housing": Material("QT500-7", 1.68e5, 0.240),
    "pin": Material("GCr15", 2.19e5, 0.300),
    "cycloid_disc": Material("20CrMnMo", 2.07e5, 0.254),
    "flange_plate": Material("ZG65Mn", 1.98e5, 0.230),
    "bearing": Material("GCr15", 2.19e5, 0.300),
}

#: Young's modulus of steel used by ISO 6336-1 for c'_th, MPa.
E_STEEL_ISO = 206000.0


def e_star(m1: Material, m2: Material) -> float:
    """Contact modulus E* = 1 / ((1 - nu1^2)/E1 + (1 - nu2^2)/E2), MPa."""
    return 1.0 / (m1.c + m2.c)


@dataclass(frozen=True)
class LineContact:
    """Johnson's line-contact approach ``delta(P) = A P (C - ln P)`` for arrays of contacts.

    With ``b^2 = 4 P R/(pi E*)`` the approach of the cylinder axes is
    ``delta = P/(pi E*) [C - ln P]``, ``C = 2 E* (c1 ln 4R1 + c2 ln 4R2) - ln(4 R/(pi E*)) - 1``
    (P in N/mm, lengths in mm). Inverted exactly: with ``u = C - ln P`` the equation is
    ``u - ln u = ln(A e^C / delta)`` (Newton from ``u0 = rhs + ln rhs``, 3 steps to machine precision).
    Energy ``U = L A P^2 (u - 1/2) / 2``; stiffness ``dF/d delta = L / (A (u - 1))``.

    Attributes
    ----------
    A : mm^2/N, ``1/(pi E*)``
    C : dimensionless (arrays broadcast with the penetrations)
    L : mm, contact length (face width)
    """

    A: float
    C: np.ndarray
    L: float

    @staticmethod
    def of(R1: np.ndarray, R2: np.ndarray, m1: Material, m2: Material, length: float) -> "LineContact":
        """Contact of a convex cylinder R1 with a body of signed radius R2 (negative: concave).

        The ln terms use |R_i| (the depth to which each body is compressed); a concave R2 must exceed R1.
        """
        R1 = np.asarray(R1, dtype=float)
        R2 = np.asarray(R2, dtype=float)
        es = e_star(m1, m2)
        R = 1.0 / (1.0 / R1 + 1.0 / R2)
        C = 2.0 * es * (m1.c * np.log(4.0 * R1) + m2.c * np.log(4.0 * np.abs(R2))) - np.log(4.0 * R / (math.pi * es)) - 1.0
        return LineContact(1.0 / (math.pi * es), C, float(length))

    def approach(self, F: np.ndarray) -> np.ndarray:
        """Approach delta (mm) under the force F (N) (forward formula, for tests)."""
        P = np.asarray(F, dtype=float) / self.L
        return self.A * P * (self.C - np.log(P))

    def _u(self, delta: np.ndarray, C: np.ndarray) -> np.ndarray:
        """u = C - ln P at the penetrations delta (where delta <= 0: 2, a placeholder the callers mask)."""
        delta = np.asarray(delta, dtype=float)
        pos = delta > 0
        Cb = np.broadcast_to(C, delta.shape)
        out = np.full(delta.shape, 2.0)
        if not pos.any():
            return out
        rhs = np.log(self.A) + Cb[pos] - np.log(delta[pos])  # u - ln u = rhs  (u = C - ln P > 1)
        rhs = np.maximum(rhs, 1.0 + 1e-12)             # delta beyond the law's maximum: clamp at u = 1
        u = rhs + np.log(rhs)                          # asymptotic start (relative force error < 1e-2),
        for _ in range(3):                             # then Newton: 3 steps reach machine precision
            u = u - (u - np.log(u) - rhs) / (1.0 - 1.0 / u)
        out[pos] = np.maximum(u, 1.0 + 1e-12)
        return out

    def force(self, delta: np.ndarray, C: np.ndarray | None = None) -> np.ndarray:
        """Force (N) at penetration delta (mm); zero where delta <= 0."""
        C = self.C if C is None else C
        u = self._u(delta, C)
        return np.where(delta > 0, self.L * np.exp(C - u), 0.0)

    def stiffness(self, delta: np.ndarray, C: np.ndarray | None = None) -> np.ndarray:
        """dF/d delta, N/mm."""
        C = self.C if C is None else C
        u = self._u(delta, C)
        return np.where(delta > 0, self.L / (self.A * (u - 1.0)), 0.0)

    def energy(self, delta: np.ndarray, C: np.ndarray | None = None) -> np.ndarray:
        """Stored energy (N mm)."""
        C = self.C if C is None else C
        u = self._u(delta, C)
        P = np.exp(C - u)
        return np.where(delta > 0, 0.5 * self.L * self.A * P * P * (u - 0.5), 0.0)


def hertz_line_pressure(F: np.ndarray, R: np.ndarray, es: float, length: float) -> np.ndarray:
    """Peak Hertzian pressure p0 = sqrt(P E*/(pi R)) of a line contact, MPa (R: relative radius, mm)."""
    P = np.maximum(np.asarray(F, dtype=float), 0.0) / length
    return np.sqrt(P * es / (math.pi * np.asarray(R, dtype=float)))


# ---------------------------------------------------------------------- ISO 6336-1 mesh stiffness
#: ISO 6336-1:2019 eq. (43) coefficients C1..C9 of q' (mm um / N).
ISO_Q_COEFFS = (0.04723, 0.15551, 0.25791, -0.00635, -0.11654, -0.00193, -0.24188, 0.00529, 0.00182)


def iso_single_tooth_stiffness(z1: int, z2: int, x1: float, x2: float, E1: float, E2: float,
                               dedendum_factor: float = 1.25, pressure_angle_deg: float = 20.0) -> float:
    """Single-tooth stiffness c' of a solid spur gear pair, N/(mm um) (ISO 6336-1 method B).

    ``c' = c'_th C_M C_R C_B E/E_st``; ``c'_th = 1/q'``; ``C_M = 0.8`` (solid discs, theoretical to
    measured), ``C_R = 1`` (solid gear blanks), ``C_B = (1 + 0.5 (1.2 - h_fP/m))(1 - 0.02 (20 - alpha))``,
    ``E = 2 E1 E2/(E1 + E2)`` against ``E_st = 206000 MPa``. The load factor for F_t/b < 100 N/mm is not
    applied (stiffness at full load; stated in docs/physics.md).
    """
    c = ISO_Q_COEFFS
    q = (c[0] + c[1] / z1 + c[2] / z2 + c[3] * x1 + c[4] * x1 / z1 + c[5] * x2 + c[6] * x2 / z2
         + c[7] * x1 ** 2 + c[8] * x2 ** 2)
    cb = (1.0 + 0.5 * (1.2 - dedendum_factor)) * (1.0 - 0.02 * (20.0 - pressure_angle_deg))
    e = 2.0 * E1 * E2 / (E1 + E2)
    return 1.0 / q * 0.8 * 1.0 * cb * e / E_STEEL_ISO


def transverse_contact_ratio(ra1: float, rb1: float, ra2: float, rb2: float, a_w: float, alpha_w: float,
                             base_pitch: float) -> float:
    """eps_alpha = (sqrt(ra1^2 - rb1^2) + sqrt(ra2^2 - rb2^2) - a_w sin alpha_w) / p_b (external spur pair)."""
    return (math.sqrt(ra1 ** 2 - rb1 ** 2) + math.sqrt(ra2 ** 2 - rb2 ** 2) - a_w * math.sin(alpha_w)) / base_pitch


def iso_mesh_stiffness(c_single: float, eps_alpha: float) -> float:
    """Mean mesh stiffness per unit face width c_gamma_alpha = c' (0.75 eps_alpha + 0.25), N/(mm um)."""
    return c_single * (0.75 * eps_alpha + 0.25)
