"""Fixed parts of the cycloid stage: the pins and the pin housing (world frame).

Lengths in mm, angles in rad inside.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from rvcad.geometry import ReducerGeometry
from rvcad.outline import ArcSeg, Loop
from rvcad.plan import AxialLayout, Part


# ---------------------------------------------------------------------------- pins and housing
class Pin(Part):
    """Pin i: cylinder at ``geometry.pin_centers[i]`` of radius ``geometry.pin_radii[i]`` (world frame).

    Attributes
    ----------
    center : (2,) float64
        mm (errors H, I, L).
    radius : float
        mm (error J).
    """

    fixed = True

    def __init__(self, geometry: ReducerGeometry, i: int, layout: AxialLayout | None = None) -> None:
        layout = layout or AxialLayout.from_design(geometry.design)
        super().__init__(geometry, layout.pins)
        self.i = i
        self.name = f"pin{i:02d}"
        self.center = np.array(geometry.pin_centers[i], dtype=np.float64)
        self.radius = float(geometry.pin_radii[i])

    def _make_outline(self) -> tuple[Loop, list[Loop]]:
        return Loop.circle(self.center, self.radius), []

    def exact_volume(self) -> float:
        return math.pi * self.radius ** 2 * self.width

    def info(self) -> dict[str, Any]:
        return {**super().info(), "center_mm": self.center.tolist(), "radius_mm": self.radius}


def lens_area(R: float, r: float, d: float) -> float:
    """Area of the intersection of two circles (radii R, r, centre distance d), mm^2."""
    if d >= R + r:
        return 0.0
    if d <= abs(R - r):
        return math.pi * min(R, r) ** 2
    a1 = math.acos((d * d + R * R - r * r) / (2 * d * R))
    a2 = math.acos((d * d + r * r - R * R) / (2 * d * r))
    return R * R * a1 + r * r * a2 - 0.5 * math.sqrt((-d + R + r) * (d + R - r) * (d - R + r) * (d + R + r))


class PinHousing(Part):
    """Pin housing: ring of outer radius ``housing_outer_radius_mm`` (centred on the main axis) whose
    bore of radius Rp (centred on the pin circle centre, error H) carries a semicircular groove at
    every pin (the groove circle is the pin circle: errors H, I, J, L move it). World frame.

    Attributes
    ----------
    outer_radius, bore_radius : float
        mm.
    bore_center : (2,) float64
        mm.
    """

    name = "housing"
    fixed = True

    def __init__(self, geometry: ReducerGeometry, layout: AxialLayout | None = None) -> None:
        layout = layout or AxialLayout.from_design(geometry.design)
        super().__init__(geometry, layout.pins)
        d = self.design
        self.outer_radius = float(d.housing_outer_radius_mm)
        self.bore_radius = float(d.pin_circle_radius_mm)
        self.bore_center = np.array(geometry.errors.pin_circle_offset, dtype=np.float64)
        self.groove_centers = np.array(geometry.pin_centers, dtype=np.float64)
        self.groove_radii = np.array(geometry.pin_radii, dtype=np.float64)

    def _inner_loop(self) -> Loop:
        o, R = self.bore_center, self.bore_radius
        n = len(self.groove_centers)
        lo, hi = [], []  # (angle about o, angle about c_i) of the two crossings of groove i
        for c, r in zip(self.groove_centers, self.groove_radii):
            d = c - o
            dist = float(np.linalg.norm(d))
            if not abs(dist - R) < r:
                raise ValueError(f"a pin groove (radius {r} mm at {dist} mm) does not cut the housing bore")
            a = (dist * dist + R * R - r * r) / (2.0 * dist)
            h = math.sqrt(R * R - a * a)
            ud = d / dist
            perp = np.array([-ud[1], ud[0]])
            p_lo, p_hi = o + a * ud - h * perp, o + a * ud + h * perp
            lo.append((math.atan2(*(p_lo - o)[::-1]), math.atan2(*(p_lo - c)[::-1])))
            hi.append((math.atan2(*(p_hi - o)[::-1]), math.atan2(*(p_hi - c)[::-1])))
        order = np.argsort([math.atan2(*(c - o)[::-1]) for c in self.groove_centers])
        segs: list[ArcSeg] = []
        for m, i in enumerate(order):
            c, r = self.groove_centers[i], float(self.groove_radii[i])
            g0, g1 = lo[i][1], hi[i][1]
            # groove arc: CCW about the pin centre through its outward side
            out = math.atan2(*(c - o)[::-1])
            g0 = out + (np.mod(g0 - out + math.pi, 2 * math.pi) - math.pi)
            g1 = out + (np.mod(g1 - out + math.pi, 2 * math.pi) - math.pi)
            segs.append(ArcSeg((float(c[0]), float(c[1])), r, float(g0), float(g1)))
            nxt = order[(m + 1) % n]
            b0, b1 = hi[i][0], lo[nxt][0]
            b1 = b0 + np.mod(b1 - b0, 2 * math.pi)
            segs.append(ArcSeg((float(o[0]), float(o[1])), R, float(b0), float(b1)))
        # as a hole the inner loop runs clockwise: reverse every arc and the order
        rev = tuple(ArcSeg(s.center, s.radius, s.a1, s.a0) for s in segs[::-1])
        return Loop(rev)

    def _make_outline(self) -> tuple[Loop, list[Loop]]:
        return Loop.circle((0.0, 0.0), self.outer_radius), [self._inner_loop()]

    def exact_area(self) -> float:
        """pi R_out^2 - pi Rp^2 - sum over pins of the groove area outside the bore, mm^2."""
        R = self.bore_radius
        grooves = sum(math.pi * r * r - lens_area(R, float(r), float(np.linalg.norm(c - self.bore_center)))
                      for c, r in zip(self.groove_centers, self.groove_radii))
        return math.pi * (self.outer_radius ** 2 - R ** 2) - grooves

    def exact_volume(self) -> float:
        return self.exact_area() * self.width

    def info(self) -> dict[str, Any]:
        return {**super().info(), "outer_radius_mm": self.outer_radius, "bore_radius_mm": self.bore_radius,
                "bore_center_mm": self.bore_center.tolist()}




__all__ = ["Pin", "PinHousing", "lens_area"]
