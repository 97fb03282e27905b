"""The plan of every part: outline, axial extent and frame; the :class:`Part` base class.

Layers of rvcad (the bd_warehouse and cq_gears habit: numpy maths apart, the CAD kernel only
where the solid is built):

1. *profile maths* (numpy): the exact curves (:mod:`rvcad.profile`), the perturbed feature
   positions and kinematics (:mod:`rvcad.geometry`), the curve pieces and their distances
   (:mod:`rvcad.curves`);
2. *plan* (numpy): each part's outline as :class:`rvcad.outline.Loop` objects (lines, circular
   arcs and exact curve pieces) in the part's own frame plus its axial extent (this module and
   the part modules :mod:`rvcad.gears`, :mod:`rvcad.cycloid`, :mod:`rvcad.housing`,
   :mod:`rvcad.plates`; :mod:`rvcad.assembly` places them);
3. *discretisations*: the mesh (:meth:`Part.mesh`, :mod:`rvcad.mesh`, vertex-exact, chords within
   a sagitta; :mod:`rvcad.stl` writes it) and the B-rep solid (:meth:`Part.shape`, :mod:`rvcad.occ`
   with the B-splines of :mod:`rvcad.bspline`; :mod:`rvcad.build` wraps them as build123d parts).

Frames. Every part has its own frame, the frame :meth:`ReducerGeometry.placement` moves: the
placed part is the part rotated about +z by the placement angle and then moved by (x, y). z is
the assembly's axial coordinate already (parts do not move axially), +z from the input side to the
output side. Fixed parts (pins, housing) are in the world frame. Own frames:

* ``sun``: the sun gear centre, tooth 0 on +x; the input-shaft bore sits at ``-sun_offset``.
* ``planet{j}``: the planet gear centre, tooth 0 on +x; the crank bore at the crank axis.
* ``crank{j}``: the crank axis, turning with the crank angle psi; cams at their eccentricities.
* ``disc{k}``: the disc centre in the frame of its crank holes; the cycloid profile is turned
  by the disc phase error (K) relative to the holes.
* ``flange``, ``carrier``: the main axis, turning with the output angle.

Axial layout (:class:`rvcad.layout.AxialLayout`): stage I gears from z = 0, then the flange plate, disc 0,
disc 1 (``design.disc_gap_mm`` apart), the carrier plate; :data:`AXIAL_CLEARANCE_MM` between the
other neighbouring layers. Pins and housing span both discs. Units: mm and degrees at the API.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rvcad.geometry import ReducerGeometry
from rvcad.layout import (AXIAL_CLEARANCE_MM, DEFAULT_TOLERANCE_MM, PLATE_RIM_CLEARANCE_MM,  # noqa: F401
                          SUN_BORE_FRACTION, AxialLayout)
from rvcad.mesh import Mesh, extrude_rings
from rvcad.occ import planar_solid
from rvcad.outline import CurveSeg, Loop


# ============================================================================ parts
class Part:
    """Base of all parts: name, axial extent, own frame, mesh and solid.

    Attributes
    ----------
    name : str
        File stem and assembly label (``disc0``, ``pin07``, ...).
    z0, z1 : float
        Axial extent in the assembly, mm.
    fixed : bool
        Fixed parts (pins, housing) are given in the world frame.
    placement_key : str or None
        Key of :meth:`ReducerGeometry.placement` that moves this part (``None`` if fixed).
    """

    name: str = "part"
    fixed: bool = False
    placement_key: str | None = None

    def __init__(self, geometry: ReducerGeometry, z: tuple[float, float]) -> None:
        self.geometry = geometry
        self.design = geometry.design
        self.z0, self.z1 = float(z[0]), float(z[1])
        self._solids: dict[float, Any] = {}
        self._meshes: dict[float, Mesh] = {}

    @property
    def width(self) -> float:
        """Axial width z1 - z0, mm."""
        return self.z1 - self.z0

    # ------------------------------------------------------------------ plan
    def outline(self) -> tuple[Loop, list[Loop]]:
        """Outer loop (CCW) and holes (CW) of the planar section, own frame, mm (built once)."""
        if not hasattr(self, "_outline"):
            self._outline = self._make_outline()
        return self._outline[0], list(self._outline[1])

    def _make_outline(self) -> tuple[Loop, list[Loop]]:
        raise NotImplementedError

    def exact_volume(self) -> float | None:
        """Closed-form volume of the exact part, mm^3 (``None`` where none exists)."""
        return None

    def info(self) -> dict[str, Any]:
        """Derived values of the part (JSON-ready; units in the keys)."""
        return {"z0_mm": self.z0, "z1_mm": self.z1}

    # ------------------------------------------------------------------ part
    def mesh(self, sagitta_mm: float | None = None) -> Mesh:
        """Watertight triangle mesh in the own frame, float64, mm.

        Parameters
        ----------
        sagitta_mm : float or None
            Largest chord sagitta of every curved outline, mm (default 1e-4 = 0.1 um). Every
            vertex lies on the exact outline.
        """
        s = DEFAULT_TOLERANCE_MM if sagitta_mm is None else float(sagitta_mm)
        if s not in self._meshes:
            outer, holes = self.outline()
            rings = [outer.ring(s)] + [h.ring(s) for h in holes]
            self._meshes[s] = extrude_rings(rings, self.z0, self.z1).check()
        return self._meshes[s]

    def shape(self, tolerance_mm: float | None = None):
        """OpenCASCADE ``TopoDS_Solid`` in the own frame (OCP only; cached per tolerance).

        Parameters
        ----------
        tolerance_mm : float or None
            Budget of the B-spline fits to exact curves, mm (default 1e-4); lines and circles exact.
        """
        t = DEFAULT_TOLERANCE_MM if tolerance_mm is None else float(tolerance_mm)
        if t not in self._solids:
            self._solids[t] = self._build_shape(t)
        return self._solids[t]

    def solid(self, tolerance_mm: float | None = None):
        """build123d ``Solid`` of :meth:`shape` (imports build123d), labelled with the part name."""
        import build123d as bd

        s = bd.Solid(self.shape(tolerance_mm))
        s.label = self.name
        return s

    def _build_shape(self, tol: float):
        outer, holes = self.outline()
        return planar_solid(outer, holes, self.z0, self.z1, tol)

    def outline_deviation(self, sagitta_mm: float | None = None, float32: bool = True) -> float:
        """Largest distance of the mesh outline (vertices and chord midpoints) from the exact curves
        (cycloid envelope, involutes), mm; 0 if the part has no such curve. Circles are sampled
        with an exact sagitta rule and are not measured here.

        Parameters
        ----------
        sagitta_mm : float or None
            Sagitta of the mesh (default 1e-4 mm).
        float32 : bool
            Measure the vertices rounded to float32 as a binary STL stores them.
        """
        s = DEFAULT_TOLERANCE_MM if sagitta_mm is None else float(sagitta_mm)
        worst = 0.0
        outer, holes = self.outline()
        for loop in [outer] + holes:
            segs = loop.segments
            for i, seg in enumerate(segs):
                if not isinstance(seg, CurveSeg):
                    continue
                p = seg.points(s)
                p = np.concatenate([p, segs[(i + 1) % len(segs)].start[None]])
                if float32:
                    p = p.astype(np.float32).astype(np.float64)
                pts = np.concatenate([p, 0.5 * (p[1:] + p[:-1])])
                worst = max(worst, float(np.abs(self._curve_distance(seg, pts)).max()))
        return worst

    def spline_deviation(self, tolerance_mm: float | None = None, per_span: int = 32) -> float:
        """Largest distance of the STEP B-splines (as handed to OpenCASCADE) from the exact curves,
        mm, sampled ``per_span`` times per knot span; 0 if the part has no exact curve.

        Each distinct curve piece is measured once in its own frame: the other lobes and teeth carry
        the same B-splines turned (B-splines are affine invariant; the turn costs float64 rounding).
        """
        t = DEFAULT_TOLERANCE_MM if tolerance_mm is None else float(tolerance_mm)
        worst = 0.0
        outer, holes = self.outline()
        seen: set[int] = set()
        for loop in [outer] + holes:
            for seg in loop.segments:
                if not isinstance(seg, CurveSeg) or id(seg.curve) in seen:
                    continue
                seen.add(id(seg.curve))
                base = CurveSeg(seg.curve)
                for b in seg.curve.bsplines(t):
                    uk = np.unique(b.knots)
                    u = (uk[:-1, None] + np.diff(uk)[:, None] * np.linspace(0, 1, per_span + 1)[None]).ravel()
                    worst = max(worst, float(np.abs(self._curve_distance(base, b(u))).max()))
        return worst

    def _curve_distance(self, seg: CurveSeg, pts: np.ndarray) -> np.ndarray:
        raise NotImplementedError



__all__ = ["AXIAL_CLEARANCE_MM", "DEFAULT_TOLERANCE_MM", "PLATE_RIM_CLEARANCE_MM", "SUN_BORE_FRACTION",
           "AxialLayout", "Part"]
