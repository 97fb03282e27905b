"""rvcad: parametric, error-perturbed geometry of an RV reducer (profiles, parts, export).

Lengths in mm and angles in degrees at the API; radians inside. The numpy layer
(:mod:`rvcad.profile`, :mod:`rvcad.geometry`) needs no CAD kernel; build123d is imported only
where solids are built.
"""
from rvcad.errors import ERROR_TYPES, Case, load_case
from rvcad.geometry import ReducerGeometry
from rvcad.params import Design
from rvcad.profile import CycloidProfile, InvoluteGear
from rvcad.tolerances import TOL, Tolerances

__all__ = ["ERROR_TYPES", "Case", "CycloidProfile", "Design", "InvoluteGear", "ReducerGeometry", "TOL",
           "Tolerances", "load_case"]
