"""Numerical tolerances of the whole project, in one documented place.

Every length is in mm and every angle in radians unless the field name says otherwise
(the habit of trimesh ``constants.py``: no scattered literals).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tolerances:
    """Tolerances used by the profile maths, the tessellation and the solvers.

    Attributes
    ----------
    foot_point_mm : float
        Convergence of the foot-point (closest point) Newton iteration on the cycloid
        pin-centre curve, mm. 1e-10 mm is far below float64 noise at 64 mm (about 1e-14 mm)
        and far below the 0.25 um that one arcsec moves a pin.
    foot_point_max_iter : int
        Iteration cap of that Newton solve.
    sagitta_mm : float
        Default chord sagitta of the exact-profile tessellation, mm. 5e-5 mm (0.05 um) keeps
        every chord midpoint within 0.1 um of the exact envelope.
    involute_sagitta_mm : float
        Default chord sagitta for involute flanks, mm (0.5 um budget, half of it used).
    solver_angle_rad : float
        Convergence of the quasi-static equilibrium, rad of output angle (1e-9 rad = 2e-4 arcsec;
        converted to mm at the pin circle, 6.4e-8 mm). Ten times this is accepted after
        ``solver_max_iter // 3`` outer iterations (the noise floor of stiff, preloaded cases).
    solver_max_iter : int
        Iteration cap of the equilibrium Newton solve.
    interference_mm : float
        Overlap that the interference check still calls contact, mm (0.1 um).
    """

    foot_point_mm: float = 1e-10
    foot_point_max_iter: int = 50
    sagitta_mm: float = 5e-5
    involute_sagitta_mm: float = 2.5e-4
    solver_angle_rad: float = 1e-9
    solver_max_iter: int = 150
    interference_mm: float = 1e-4


TOL = Tolerances()
"""The project's default tolerances."""
