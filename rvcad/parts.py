"""Index of the part classes (one import for users and tests).

The parts live in modules of one idea each: :mod:`rvcad.plan` (layout and the :class:`Part`
base), :mod:`rvcad.gears` (sun, planets), :mod:`rvcad.cycloid` (discs, crankshafts),
:mod:`rvcad.housing` (pins, housing), :mod:`rvcad.plates` (flange, carrier) and
:mod:`rvcad.assembly` (all parts placed). build123d objects of the placed parts: :func:`rvcad.reducer`.
"""
from __future__ import annotations

from rvcad.assembly import Assembly
from rvcad.curves import gear_outline
from rvcad.cycloid import Crankshaft, CycloidDisc
from rvcad.gears import PlanetGear, SunGear, GearPart
from rvcad.housing import Pin, PinHousing
from rvcad.plan import (AXIAL_CLEARANCE_MM, DEFAULT_TOLERANCE_MM, PLATE_RIM_CLEARANCE_MM, SUN_BORE_FRACTION,
                        AxialLayout, Part)
from rvcad.plates import FlangePlate, PlanetaryCarrier

__all__ = ["AXIAL_CLEARANCE_MM", "DEFAULT_TOLERANCE_MM", "PLATE_RIM_CLEARANCE_MM", "SUN_BORE_FRACTION", "Assembly",
           "AxialLayout", "Crankshaft", "CycloidDisc", "FlangePlate", "Part", "Pin", "PinHousing", "PlanetGear",
           "PlanetaryCarrier", "SunGear", "GearPart", "gear_outline"]
