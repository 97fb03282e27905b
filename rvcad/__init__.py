"""rvcad: parametric, error-perturbed geometry of an RV reducer (profiles, parts, export).

Lengths in mm and angles in degrees at the API; radians inside. The numpy layer
(:mod:`rvcad.profile`, :mod:`rvcad.geometry`) needs no CAD kernel; build123d is imported only
where solids are built. ``rvcad.reducer(case).parts`` gives every part as a placed, labelled
build123d Solid.
"""
from rvcad.errors import ERROR_TYPES, Case, load_case
from rvcad.geometry import ReducerGeometry
from rvcad.params import Design
from rvcad.profile import CycloidProfile, InvoluteGear
from rvcad.tolerances import TOL, Tolerances

__all__ = ["ERROR_TYPES", "Case", "CycloidProfile", "Design", "DesignError", "InvoluteGear", "Reducer",
           "ReducerGeometry", "TOL", "Tolerances", "check_case", "load_case", "reducer"]

_LAZY = {"Reducer": "rvcad.build", "reducer": "rvcad.build", "DesignError": "rvcad.validation",
         "check_case": "rvcad.check"}


def __getattr__(name: str):  # the part layer (shapely, scipy.optimize) loads on first use only
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'rvcad' has no attribute {name!r}")


def __dir__() -> list[str]:  # tab completion shows the lazy names too
    return sorted(set(globals()) | set(_LAZY))
