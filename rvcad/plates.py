"""The flange and carrier plates (turning with the output): rim, central hole, crank journal holes.

Lengths in mm.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from rvcad.geometry import ReducerGeometry
from rvcad.outline import Loop
from rvcad.plan import PLATE_RIM_CLEARANCE_MM, AxialLayout, Part


# ---------------------------------------------------------------------------- plates
class _Plate(Part):
    """Plate turning with the output: rim, central hole and the crank journal holes at
    ``geometry.carrier_holes`` (error F). Own frame: the main axis, turning with theta_out.

    Attributes
    ----------
    outer_radius, center_hole_radius, hole_radius : float
        mm.
    hole_centers : (n_cranks, 2) float64
        mm, carrier frame.
    """

    placement_key = "carrier"
    layer = "carrier"

    def __init__(self, geometry: ReducerGeometry, layout: AxialLayout | None = None) -> None:
        layout = layout or AxialLayout.from_design(geometry.design)
        super().__init__(geometry, getattr(layout, self.layer))
        d = self.design
        self.outer_radius = float(d.pin_circle_radius_mm - d.eccentricity_mm - d.pin_radius_mm
                                  - PLATE_RIM_CLEARANCE_MM)
        self.center_hole_radius = float(d.disc_center_hole_radius_mm)
        self.hole_centers = np.array(geometry.carrier_holes, dtype=np.float64)
        self.hole_radius = float(d.crank_journal_radius_mm)

    def _make_outline(self) -> tuple[Loop, list[Loop]]:
        holes = [Loop.circle((0.0, 0.0), self.center_hole_radius, hole=True)]
        holes += [Loop.circle(c, self.hole_radius, hole=True) for c in self.hole_centers]
        return Loop.circle((0.0, 0.0), self.outer_radius), holes

    def exact_volume(self) -> float:
        return math.pi * (self.outer_radius ** 2 - self.center_hole_radius ** 2
                          - len(self.hole_centers) * self.hole_radius ** 2) * self.width

    def info(self) -> dict[str, Any]:
        return {**super().info(), "outer_radius_mm": self.outer_radius,
                "hole_centers_mm": self.hole_centers.tolist(), "hole_radius_mm": self.hole_radius}


class PlanetaryCarrier(_Plate):
    """Planetary carrier plate (output side, the output member)."""

    name = "carrier"
    layer = "carrier"


class FlangePlate(_Plate):
    """Flange plate (input side of the discs), turning with the carrier."""

    name = "flange"
    layer = "flange"




__all__ = ["FlangePlate", "PlanetaryCarrier"]
