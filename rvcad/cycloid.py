"""Parts of the cycloid stage that move: the cycloid discs and the crankshafts.

Own frames as described in :mod:`rvcad.plan`. Lengths in mm, angles in rad inside.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from rvcad.curves import cycloid_curves, cycloid_deviation
from rvcad.geometry import ReducerGeometry
from rvcad.mesh import Mesh, stacked_circles
from rvcad.occ import cylinders_union
from rvcad.outline import CurveSeg, Loop
from rvcad.plan import DEFAULT_TOLERANCE_MM, AxialLayout, Part
from rvcad.plane import rotate2d
from rvcad.profile import CycloidProfile


# ---------------------------------------------------------------------------- cycloid disc
class CycloidDisc(Part):
    """Cycloid disc k: exact envelope boundary, crank holes at the perturbed positions, central hole.

    Parameters
    ----------
    geometry : ReducerGeometry
    k : int
        Disc index (0: input side; disc 1 has the cam phase pi).

    Attributes
    ----------
    profile : CycloidProfile
        The exact profile (profile frame).
    profile_rotation : float
        Rotation of the profile relative to the crank holes (disc phase error K), rad.
    profile_rotation_deg : float
        The same, degrees.
    hole_centers : (n_cranks, 2) float64
        Crank hole centres in the disc frame, mm (perturbed by error G).
    hole_radius, center_hole_radius : float
        mm.
    root_radius, tip_radius, min_convex_radius : float
        Profile landmarks, mm.
    undercut : bool
        Whether the envelope's swallowtails were trimmed (pin radius above ~4.61 mm by default).
    design_check : dict
        :meth:`CycloidProfile.design_check` of the profile.
    """

    def __init__(self, geometry: ReducerGeometry, k: int, layout: AxialLayout | None = None) -> None:
        layout = layout or AxialLayout.from_design(geometry.design)
        super().__init__(geometry, layout.disc(k))
        d = self.design
        self.k = k
        self.name = f"disc{k}"
        self.placement_key = f"disc{k}"
        self.profile: CycloidProfile = geometry.profiles[k]
        self.profile_rotation = float(geometry.disc_profile_rotation[k])
        self.profile_rotation_deg = math.degrees(self.profile_rotation)
        self.hole_centers = np.array(geometry.disc_holes[k], dtype=np.float64)
        self.hole_radius = float(d.cam_radius_mm)
        self.center_hole_radius = float(d.disc_center_hole_radius_mm)
        self.root_radius = self.profile.root_radius
        self.tip_radius = self.profile.tip_radius
        self.min_convex_radius = self.profile.min_convex_radius
        self.undercut = self.profile.undercut
        self.design_check = self.profile.design_check()
        self._curves = cycloid_curves(self.profile)

    def _make_outline(self) -> tuple[Loop, list[Loop]]:
        two = 2.0 * math.pi / self.profile.z_lobes
        segs = [CurveSeg(c, rotation=l * two + self.profile_rotation)
                for l in range(self.profile.z_lobes) for c in self._curves]
        holes = [Loop.circle((0.0, 0.0), self.center_hole_radius, hole=True)]
        holes += [Loop.circle(c, self.hole_radius, hole=True) for c in self.hole_centers]
        return Loop(tuple(segs)), holes

    def _curve_distance(self, seg: CurveSeg, pts: np.ndarray) -> np.ndarray:
        q = seg.inverse(pts)
        return cycloid_deviation(self.profile, q, np.arctan2(q[:, 1], q[:, 0]))

    def boundary_distance(self, pts: np.ndarray) -> np.ndarray:
        """Signed distance of own-frame points (K, 2) to the exact envelope, mm (positive outside)."""
        q = rotate2d(np.asarray(pts, dtype=np.float64), -self.profile_rotation)
        return cycloid_deviation(self.profile, q, np.arctan2(q[:, 1], q[:, 0]))

    def pin_curve_length(self) -> float:
        """Length L_q of the pin-centre curve q, mm (periodic trapezoid rule: spectrally exact)."""
        t = np.linspace(0.0, 2.0 * math.pi, 200001)[:-1]
        return float(np.linalg.norm(self.profile.dq(t), axis=1).mean() * 2.0 * math.pi)

    def exact_area(self) -> float | None:
        """Section area pi (Rp^2 + Zp e^2) - rp L_q + pi rp^2 minus the holes, mm^2 (None if undercut:
        the trimmed loops change it)."""
        if self.undercut:
            return None
        p = self.profile
        a = math.pi * (p.pin_circle_radius ** 2 + p.z_pins * p.eccentricity ** 2) \
            - p.pin_radius * self.pin_curve_length() + math.pi * p.pin_radius ** 2
        return a - math.pi * (self.center_hole_radius ** 2 + len(self.hole_centers) * self.hole_radius ** 2)

    def exact_volume(self) -> float | None:
        a = self.exact_area()
        return None if a is None else a * self.width

    def info(self) -> dict[str, Any]:
        return {**super().info(), "root_radius_mm": self.root_radius, "tip_radius_mm": self.tip_radius,
                "min_convex_radius_mm": self.min_convex_radius, "undercut": self.undercut,
                "profile_rotation_deg": self.profile_rotation_deg,
                "hole_centers_mm": self.hole_centers.tolist()}



# ---------------------------------------------------------------------------- crankshaft
class Crankshaft(Part):
    """Crankshaft j: journal cylinder along the whole stack and two eccentric cams 180 deg apart.

    Own frame: the crank axis, turning with the absolute crank angle psi_j. The cam of disc k has
    its centre at ``cam_eccentricity[k] * (cos, sin)(cam_phase[k])`` (errors D and E included).

    Attributes
    ----------
    journal_radius, cam_radius : float
        mm.
    cam_centers : (n_discs, 2) float64
        mm, crank frame.
    cam_eccentricity : (n_discs,) float64
        mm.
    cam_phase : (n_discs,) float64
        rad (disc k's nominal phase is k pi).
    sections : list of (z0, z1, center, radius)
        The stack of circular sections, mm.
    """

    def __init__(self, geometry: ReducerGeometry, j: int, layout: AxialLayout | None = None) -> None:
        layout = layout or AxialLayout.from_design(geometry.design)
        super().__init__(geometry, (layout.gears[0], layout.carrier[1]))
        d = self.design
        self.j = j
        self.name = f"crank{j}"
        self.placement_key = f"crank{j}"
        self.journal_radius = float(d.crank_journal_radius_mm)
        self.cam_radius = float(d.cam_radius_mm)
        self.cam_eccentricity = np.array(geometry.cam_ecc[j], dtype=np.float64)
        self.cam_phase = np.array(geometry.cam_phase[j], dtype=np.float64)
        self.cam_centers = self.cam_eccentricity[:, None] * np.stack(
            [np.cos(self.cam_phase), np.sin(self.cam_phase)], axis=1)
        o = np.zeros(2)
        secs: list[tuple[float, float, np.ndarray, float]] = []
        z = self.z0
        for k in range(d.n_discs):
            a, b = layout.disc(k)
            if a > z:
                secs.append((z, a, o, self.journal_radius))
            secs.append((a, b, self.cam_centers[k], self.cam_radius))
            z = b
        secs.append((z, self.z1, o, self.journal_radius))
        self.sections = secs

    def _make_outline(self) -> tuple[Loop, list[Loop]]:
        raise TypeError("a crankshaft is not a single extrusion; use sections")

    def mesh(self, sagitta_mm: float | None = None) -> Mesh:
        s = DEFAULT_TOLERANCE_MM if sagitta_mm is None else float(sagitta_mm)
        if s not in self._meshes:
            self._meshes[s] = stacked_circles(self.sections, s).check()
        return self._meshes[s]

    def _build_shape(self, tol: float):
        return cylinders_union(self.sections)

    def outline_deviation(self, sagitta_mm: float | None = None, float32: bool = True) -> float:
        return 0.0

    def spline_deviation(self, tolerance_mm: float | None = None, per_span: int = 32) -> float:
        return 0.0

    def exact_volume(self) -> float:
        return float(sum(math.pi * r * r * (b - a) for a, b, _, r in self.sections))

    def info(self) -> dict[str, Any]:
        return {**super().info(), "journal_radius_mm": self.journal_radius, "cam_radius_mm": self.cam_radius,
                "cam_eccentricity_mm": self.cam_eccentricity.tolist(),
                "cam_phase_deg": np.degrees(self.cam_phase).tolist()}




__all__ = ["Crankshaft", "CycloidDisc"]
