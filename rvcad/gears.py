"""Stage I spur gears as parts: the sun and the planets (exact involute flanks).

Own frames as described in :mod:`rvcad.plan`. Lengths in mm, angles in rad inside.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from rvcad.curves import gear_outline, involute_deviation
from rvcad.geometry import ReducerGeometry
from rvcad.outline import CurveSeg, Loop
from rvcad.plan import SUN_BORE_FRACTION, AxialLayout, Part
from rvcad.plane import rotate2d
from rvcad.profile import InvoluteGear


class GearPart(Part):
    """Spur gear with a bore: outline from :func:`gear_outline`, bore circle at ``bore_center``."""

    gear: InvoluteGear
    bore_center: np.ndarray
    bore_radius: float

    def _make_outline(self) -> tuple[Loop, list[Loop]]:
        return gear_outline(self.gear), [Loop.circle(self.bore_center, self.bore_radius, hole=True)]

    def _curve_distance(self, seg: CurveSeg, pts: np.ndarray) -> np.ndarray:
        return involute_deviation(self.gear, seg.inverse(pts))

    def flank_distance(self, pts: np.ndarray) -> np.ndarray:
        """Distance of own-frame points (K, 2) to the nearest flank involute (either side of the
        nearest tooth), mm (absolute). Meaningful for points near a flank (radius >= base)."""
        p = np.asarray(pts, dtype=np.float64)
        pitch = 2.0 * math.pi / self.gear.z
        k = np.round(np.arctan2(p[:, 1], p[:, 0]) / pitch)
        c, s = np.cos(-k * pitch), np.sin(-k * pitch)
        q = np.stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]], axis=1)
        up = np.abs(involute_deviation(self.gear, q))
        low = np.abs(involute_deviation(self.gear, q * np.array([1.0, -1.0])))
        return np.minimum(up, low)

    def exact_area(self) -> float:
        """Section area of the exact outline minus the bore, mm^2 (involute sectors in closed form).

        Area per tooth from the polar integral 1/2 int r^2 dphi over root arc, tip arc and the two
        flanks: for the involute with roll angle lam, r^2 = rb^2 (1 + lam^2) and dphi = -(lam^2 /
        (1 + lam^2)) dlam on the upper flank, so each flank sweeps rb^2 (lam1^3 - lam0^3) / 6.
        """
        g = self.gear
        rb, rf, ra = g.base_radius, g.root_radius, g.tip_radius
        r0 = max(rb, rf)
        lam0 = math.sqrt(max((r0 / rb) ** 2 - 1.0, 0.0))
        lam1 = math.sqrt((ra / rb) ** 2 - 1.0)
        a_base = float(g.flank_polar_angle(r0))
        a_tip = float(g.flank_polar_angle(ra))
        pitch = 2.0 * math.pi / g.z
        flank = rb ** 2 * (lam1 ** 3 - lam0 ** 3) / 6.0
        # sector form 1/2 r^2 dphi over the outline; the radial lines sweep no angle
        tooth = 0.5 * ra ** 2 * (2 * a_tip) + 0.5 * rf ** 2 * (pitch - 2 * a_base) + 2 * flank
        return g.z * tooth - math.pi * self.bore_radius ** 2

    def exact_volume(self) -> float:
        return self.exact_area() * self.width

    def info(self) -> dict[str, Any]:
        g = self.gear
        return {**super().info(), "teeth": g.z, "module_mm": g.module, "pitch_radius_mm": g.pitch_radius,
                "base_radius_mm": g.base_radius, "tip_radius_mm": g.tip_radius, "root_radius_mm": g.root_radius,
                "profile_shift": g.shift, "bore_center_mm": self.bore_center.tolist(),
                "bore_radius_mm": self.bore_radius}


class SunGear(GearPart):
    """Stage I sun gear (input), own frame at the gear centre (turning with the input angle).

    Attributes
    ----------
    gear : InvoluteGear
    bore_center : (2,) float64
        Input axis in the sun frame, mm: ``-sun_offset`` (error B moves the teeth off the shaft).
    bore_radius : float
        Input shaft bore, ``SUN_BORE_FRACTION`` of the root radius, mm.
    eccentricity : (2,) float64
        Gear centre relative to the input axis in the sun frame, mm.
    """

    name = "sun"
    placement_key = "sun"

    def __init__(self, geometry: ReducerGeometry, layout: AxialLayout | None = None) -> None:
        layout = layout or AxialLayout.from_design(geometry.design)
        super().__init__(geometry, layout.gears)
        self.gear = geometry.sun
        self.eccentricity = np.array(geometry.sun_offset, dtype=np.float64)
        self.bore_center = -self.eccentricity
        self.bore_radius = SUN_BORE_FRACTION * self.gear.root_radius


class PlanetGear(GearPart):
    """Stage I planet gear j on crank j, own frame at the gear centre (turning with psi_j plus the
    tooth phase that makes it mesh).

    Attributes
    ----------
    gear : InvoluteGear
    tooth_phase : float
        ``geometry.planet_tooth_phase[j]``, rad.
    eccentricity : (2,) float64
        Gear centre offset from the crank axis in the crank frame, mm (error C).
    bore_center : (2,) float64
        Crank axis in the planet frame: ``-R(-tooth_phase) eccentricity``, mm.
    bore_radius : float
        Crank journal radius, mm.
    """

    def __init__(self, geometry: ReducerGeometry, j: int, layout: AxialLayout | None = None) -> None:
        layout = layout or AxialLayout.from_design(geometry.design)
        super().__init__(geometry, layout.gears)
        self.j = j
        self.name = f"planet{j}"
        self.placement_key = f"planet{j}"
        self.gear = geometry.planet
        self.tooth_phase = float(geometry.planet_tooth_phase[j])
        self.eccentricity = np.array(geometry.planet_offsets[j], dtype=np.float64)
        self.bore_center = -rotate2d(self.eccentricity, -self.tooth_phase)
        self.bore_radius = float(self.design.crank_journal_radius_mm)

    def info(self) -> dict[str, Any]:
        return {**super().info(), "tooth_phase_deg": math.degrees(self.tooth_phase)}




__all__ = ["PlanetGear", "SunGear"]
