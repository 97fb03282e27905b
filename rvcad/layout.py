"""Sizes and axial layout of the parts (assumptions of this implementation), plain Python.

No numpy, no CAD kernel: the physics layer (``rvdyn``) may read the same numbers.
"""
from __future__ import annotations

from dataclasses import dataclass

from rvcad.params import Design

#: Default tolerance of exported geometry, mm (0.1 um): chord sagitta of the meshes and the
#: B-spline fit budget of the STEP solids.
DEFAULT_TOLERANCE_MM = 1e-4

#: Axial clearance between neighbouring layers other than the two discs (gears | flange plate,
#: flange plate | disc 0, disc 1 | carrier plate), mm (assumption of this implementation).
AXIAL_CLEARANCE_MM = 0.5

#: Radial clearance between the plates' rim and the discs' root circle, mm: the flange and carrier
#: plates have radius ``Rp - e - rp - PLATE_RIM_CLEARANCE_MM`` (assumption; the pillars that join
#: the two plates through the discs are not modelled).
PLATE_RIM_CLEARANCE_MM = 1.0

#: Radius of the sun gear's input-shaft bore as a fraction of the sun's root radius (assumption).
SUN_BORE_FRACTION = 0.5


@dataclass(frozen=True)
class AxialLayout:
    """Axial (z) extents of the layers, mm; +z from the input to the output side.

    Attributes
    ----------
    gears, flange, disc0, disc1, carrier, pins : tuple of float
        (z0, z1) of each layer; ``pins`` (also the housing) spans both discs.
    """

    gears: tuple[float, float]
    flange: tuple[float, float]
    disc0: tuple[float, float]
    disc1: tuple[float, float]
    carrier: tuple[float, float]
    pins: tuple[float, float]

    @classmethod
    def from_design(cls, d: Design) -> "AxialLayout":
        c = AXIAL_CLEARANCE_MM
        g = (0.0, d.gear_width_mm)
        f = (g[1] + c, g[1] + c + d.plate_width_mm)
        d0 = (f[1] + c, f[1] + c + d.disc_width_mm)
        d1 = (d0[1] + d.disc_gap_mm, d0[1] + d.disc_gap_mm + d.disc_width_mm)
        cr = (d1[1] + c, d1[1] + c + d.plate_width_mm)
        return cls(g, f, d0, d1, cr, (d0[0], d1[1]))

    def disc(self, k: int) -> tuple[float, float]:
        return (self.disc0, self.disc1)[k]

    @property
    def length(self) -> float:
        """Overall length from the gear face to the carrier's output face, mm."""
        return self.carrier[1] - self.gears[0]


__all__ = ["AXIAL_CLEARANCE_MM", "DEFAULT_TOLERANCE_MM", "PLATE_RIM_CLEARANCE_MM", "SUN_BORE_FRACTION", "AxialLayout"]
