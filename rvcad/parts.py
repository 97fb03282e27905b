"""The RV reducer as error-perturbed, exact parts: profile -> plan -> part.

Layers (the bd_warehouse habit):

1. *profile*: the exact curves in plain numpy (:mod:`rvcad.profile`: the cycloid envelope, the
   involutes) and the perturbed feature positions (:class:`rvcad.geometry.ReducerGeometry`);
2. *plan*: each part's outline as :class:`rvcad.tessellate.Loop` objects (lines, circular arcs
   and exact curve pieces) in the part's own frame, plus its axial extent; numbers only;
3. *part*: the mesh (:meth:`Part.mesh`, vertex-exact, chords within a sagitta) and the B-rep solid
   (:meth:`Part.solid`, build123d/OCP: exact lines and circles, cubic B-splines fitted to the
   exact curves within a tolerance). The CAD kernel is imported only when a solid is built.

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

Axial layout (:class:`AxialLayout`): stage I gears from z = 0, then the flange plate, disc 0,
disc 1 (``design.disc_gap_mm`` apart), the carrier plate; :data:`AXIAL_CLEARANCE_MM` between the
other neighbouring layers. Pins and housing span both discs. Units: mm and degrees at the API.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterator

import numpy as np

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvcad.params import Design
from rvcad.profile import CycloidProfile, InvoluteGear
from rvcad.tessellate import (ArcSeg, CurveSeg, LineSeg, Loop, Mesh, cycloid_curves, cycloid_deviation,
                              extrude_rings, involute_deviation, involute_flank_curve, rotate2d, stacked_circles)

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



# ============================================================================ plan: axial layout
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


# ============================================================================ OCC helpers (part layer)
def _occ_wire(loop: Loop, tol: float, z: float):
    """TopoDS_Wire of a loop at height z: exact lines and circles, fitted B-splines for exact curves."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeVertex, BRepBuilderAPI_MakeWire
    from OCP.collections import Array1_double, Array1_gp_Pnt, Array1_int
    from OCP.Geom import Geom_BSplineCurve, Geom_Circle
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt
    from OCP.TopoDS import TopoDS

    def pnt(p: np.ndarray) -> gp_Pnt:
        return gp_Pnt(float(p[0]), float(p[1]), float(z))

    def vertex(p: np.ndarray):
        return BRepBuilderAPI_MakeVertex(pnt(p)).Vertex()

    def circle(seg: ArcSeg) -> Geom_Circle:
        return Geom_Circle(gp_Ax2(pnt(np.asarray(seg.center)), gp_Dir(0.0, 0.0, 1.0)), float(seg.radius))

    def edge(maker) -> Any:
        if not maker.IsDone():
            raise RuntimeError(f"OpenCASCADE could not build an edge (error {maker.Error()})")
        return maker.Edge()

    segs = loop.segments
    mw = BRepBuilderAPI_MakeWire()
    if len(segs) == 1 and isinstance(segs[0], ArcSeg) and segs[0].full:
        e = edge(BRepBuilderAPI_MakeEdge(circle(segs[0])))
        mw.Add(e if segs[0].ccw else TopoDS.Edge(e.Reversed()))
        return mw.Wire()
    verts = [vertex(s.start) for s in segs]
    n = len(segs)
    for i, s in enumerate(segs):
        v0, v1 = verts[i], verts[(i + 1) % n]
        if isinstance(s, LineSeg):
            mw.Add(edge(BRepBuilderAPI_MakeEdge(v0, v1)))
        elif isinstance(s, ArcSeg):
            if s.ccw:
                mw.Add(edge(BRepBuilderAPI_MakeEdge(circle(s), v0, v1)))
            else:
                mw.Add(TopoDS.Edge(edge(BRepBuilderAPI_MakeEdge(circle(s), v1, v0)).Reversed()))
        else:
            pieces = s.bsplines(tol)
            va = v0
            for m, b in enumerate(pieces):
                vb = v1 if m == len(pieces) - 1 else vertex(b.end)
                poles = Array1_gp_Pnt(1, len(b.poles))
                for q, p in enumerate(b.poles):
                    poles.SetValue(q + 1, pnt(p))
                uk, mult = np.unique(b.knots, return_counts=True)
                knots, mults = Array1_double(1, len(uk)), Array1_int(1, len(uk))
                for q, (kv, mv) in enumerate(zip(uk, mult)):
                    knots.SetValue(q + 1, float(kv))
                    mults.SetValue(q + 1, int(mv))
                crv = Geom_BSplineCurve(poles, knots, mults, b.degree)
                mw.Add(edge(BRepBuilderAPI_MakeEdge(crv, va, vb)))
                va = vb
    if not mw.IsDone():
        raise RuntimeError(f"OpenCASCADE could not close the outline wire (error {mw.Error()})")
    return mw.Wire()


def _planar_shape(outer: Loop, holes: list[Loop], z0: float, z1: float, tol: float):
    """OCP ``TopoDS_Solid``: the planar face of the loops at z0 extruded to z1."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Vec
    from OCP.TopAbs import TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    mf = BRepBuilderAPI_MakeFace(_occ_wire(outer, tol, z0), True)
    for h in holes:
        mf.Add(_occ_wire(h, tol, z0))
    if not mf.IsDone():
        raise RuntimeError(f"OpenCASCADE could not build the planar face (error {mf.Error()})")
    prism = BRepPrimAPI_MakePrism(mf.Face(), gp_Vec(0.0, 0.0, float(z1 - z0)))
    ex = TopExp_Explorer(prism.Shape(), TopAbs_SOLID)
    return TopoDS.Solid(ex.Current())


def _cylinders_union(sections: list[tuple[float, float, np.ndarray, float]]):
    """OCP ``TopoDS_Solid``: union of stacked z-cylinders (z0, z1, centre, radius), faces merged."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Fuse
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.collections import List_TopoDS_Shape
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt
    from OCP.ShapeUpgrade import ShapeUpgrade_UnifySameDomain
    from OCP.TopAbs import TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    cyl = [BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(float(c[0]), float(c[1]), float(a)), gp_Dir(0.0, 0.0, 1.0)),
                                    float(r), float(b - a)).Shape() for a, b, c, r in sections]
    args, tools = List_TopoDS_Shape(), List_TopoDS_Shape()
    args.Append(cyl[0])
    for s in cyl[1:]:
        tools.Append(s)
    fuse = BRepAlgoAPI_Fuse()
    fuse.SetArguments(args)
    fuse.SetTools(tools)
    fuse.Build()
    if not fuse.IsDone():
        raise RuntimeError("OpenCASCADE could not fuse the crankshaft cylinders")
    unify = ShapeUpgrade_UnifySameDomain(fuse.Shape(), True, True, True)
    unify.Build()
    ex = TopExp_Explorer(unify.Shape(), TopAbs_SOLID)
    solids = []
    while ex.More():
        solids.append(TopoDS.Solid(ex.Current()))
        ex.Next()
    if len(solids) != 1:
        raise RuntimeError(f"crankshaft union gave {len(solids)} solids")
    return solids[0]


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
        return _planar_shape(outer, holes, self.z0, self.z1, tol)

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


# ---------------------------------------------------------------------------- gears
def gear_outline(gear: InvoluteGear, center: tuple[float, float] = (0.0, 0.0)) -> Loop:
    """Closed CCW outline of an external involute gear, tooth 0 centred on +x (mm).

    Per tooth: radial line from the root circle up to the base circle (where the root is below
    it), lower flank (exact involute), tip arc, upper flank, radial line, root arc: the same
    outline as :meth:`InvoluteGear.outline`, with exact arcs.
    """
    curve = involute_flank_curve(gear)
    up0 = gear.involute(np.array([curve.t0]))[0]  # upper flank start (base or root circle)
    up1 = gear.involute(np.array([curve.t1]))[0]  # upper flank tip
    a_base = math.atan2(up0[1], up0[0])
    a_tip = math.atan2(up1[1], up1[0])
    rf, rb, ra = gear.root_radius, gear.base_radius, gear.tip_radius
    pitch = 2.0 * math.pi / gear.z
    c = np.asarray(center, dtype=np.float64)
    segs: list[Any] = []
    for k in range(gear.z):
        rot = k * pitch
        lower_start = rotate2d(up0 * np.array([1.0, -1.0]), rot) + c
        if rf < rb:
            root_pt = c + rf * np.array([math.cos(rot - a_base), math.sin(rot - a_base)])
            segs.append(LineSeg(tuple(root_pt), tuple(lower_start)))
        segs.append(CurveSeg(curve, rotation=rot, offset=tuple(c), mirror=True))
        segs.append(ArcSeg(tuple(c), ra, rot - a_tip, rot + a_tip))
        segs.append(CurveSeg(curve, rotation=rot, offset=tuple(c), reverse=True))
        upper_start = rotate2d(up0, rot) + c
        if rf < rb:
            root_pt = c + rf * np.array([math.cos(rot + a_base), math.sin(rot + a_base)])
            segs.append(LineSeg(tuple(upper_start), tuple(root_pt)))
        segs.append(ArcSeg(tuple(c), rf, rot + a_base, rot + pitch - a_base))
    return Loop(tuple(segs))


class _Gear(Part):
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


class SunGear(_Gear):
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


class PlanetGear(_Gear):
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
        return _cylinders_union(self.sections)

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


def _lens_area(R: float, r: float, d: float) -> float:
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
        grooves = sum(math.pi * r * r - _lens_area(R, float(r), float(np.linalg.norm(c - self.bore_center)))
                      for c, r in zip(self.groove_centers, self.groove_radii))
        return math.pi * (self.outer_radius ** 2 - R ** 2) - grooves

    def exact_volume(self) -> float:
        return self.exact_area() * self.width

    def info(self) -> dict[str, Any]:
        return {**super().info(), "outer_radius_mm": self.outer_radius, "bore_radius_mm": self.bore_radius,
                "bore_center_mm": self.bore_center.tolist()}


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


# ============================================================================ assembly
class Assembly:
    """All parts of one case, placed at one input angle.

    Parameters
    ----------
    case : Case or None
        Validated case (``None``: nominal).
    theta_in_deg : float
        Input (sun) angle, degrees; the other moving parts follow the ideal kinematics
        (:meth:`ReducerGeometry.placement`).

    Attributes
    ----------
    geometry : ReducerGeometry
    layout : AxialLayout
    parts : dict of str -> Part
        In a fixed order: sun, planets, cranks, flange, discs, carrier, housing, pins.
    placements : dict of str -> (x mm, y mm, rotation deg)
        Placement of every part (identity for fixed parts).
    """

    def __init__(self, case: Case | None = None, theta_in_deg: float = 0.0) -> None:
        self.case = case if case is not None else Case.from_dict({"name": "nominal"})
        self.theta_in_deg = float(theta_in_deg)
        if not math.isfinite(self.theta_in_deg):
            raise ValueError(f"theta_in_deg {theta_in_deg!r} must be finite")
        g = ReducerGeometry(self.case)
        self.geometry = g
        self.layout = AxialLayout.from_design(g.design)
        d = g.design
        parts: list[Part] = [SunGear(g, self.layout)]
        parts += [PlanetGear(g, j, self.layout) for j in range(d.n_cranks)]
        parts += [Crankshaft(g, j, self.layout) for j in range(d.n_cranks)]
        parts.append(FlangePlate(g, self.layout))
        parts += [CycloidDisc(g, k, self.layout) for k in range(d.n_discs)]
        parts.append(PlanetaryCarrier(g, self.layout))
        parts.append(PinHousing(g, self.layout))
        parts += [Pin(g, i, self.layout) for i in range(d.z_pins)]
        self.parts: dict[str, Part] = {p.name: p for p in parts}
        pl = g.placement(math.radians(self.theta_in_deg))
        self.placements: dict[str, tuple[float, float, float]] = {
            p.name: ((0.0, 0.0, 0.0) if p.placement_key is None else tuple(map(float, pl[p.placement_key])))
            for p in parts}

    def at(self, theta_in_deg: float) -> "Assembly":
        """The same parts (and their cached meshes and solids) placed at another input angle, degrees."""
        if not math.isfinite(float(theta_in_deg)):
            raise ValueError(f"theta_in_deg {theta_in_deg!r} must be finite")
        other = object.__new__(Assembly)
        other.__dict__.update(self.__dict__)
        other.theta_in_deg = float(theta_in_deg)
        pl = self.geometry.placement(math.radians(other.theta_in_deg))
        other.placements = {
            p.name: ((0.0, 0.0, 0.0) if p.placement_key is None else tuple(map(float, pl[p.placement_key])))
            for p in self.parts.values()}
        return other

    def __iter__(self) -> Iterator[Part]:
        return iter(self.parts.values())

    def __getitem__(self, name: str) -> Part:
        return self.parts[name]

    def placed_mesh(self, name: str, sagitta_mm: float | None = None) -> Mesh:
        """Mesh of one part placed in the world frame at this input angle, mm."""
        x, y, r = self.placements[name]
        return self.parts[name].mesh(sagitta_mm).placed(x, y, r)

    def mesh(self, sagitta_mm: float | None = None) -> Mesh:
        """All parts placed, as one mesh (mm)."""
        return Mesh.concatenate([self.placed_mesh(n, sagitta_mm) for n in self.parts])

    def shapes(self, tolerance_mm: float | None = None) -> list[tuple[str, Any, tuple[float, float, float]]]:
        """(name, own-frame OCP solid, placement (x mm, y mm, rotation deg)) of every part."""
        return [(n, p.shape(tolerance_mm), self.placements[n]) for n, p in self.parts.items()]

    def compound(self, tolerance_mm: float | None = None):
        """build123d ``Compound`` of all placed solids, each labelled with its part name."""
        import build123d as bd

        children = []
        for name, part in self.parts.items():
            x, y, r = self.placements[name]
            s = part.solid(tolerance_mm)
            if (x, y, r) != (0.0, 0.0, 0.0):
                s = s.moved(bd.Location((x, y, 0.0), (0.0, 0.0, r)))
            else:
                s = s.moved(bd.Location())
            s.label = name
            children.append(s)
        return bd.Compound(children=children, label=f"rv-reducer {self.case.name}")

    def design_check(self) -> dict[str, Any]:
        """Feasibility report: undercut per disc, pin spacing, stage I and radial clearances (mm)."""
        g, d = self.geometry, self.design
        discs = [p for p in self.parts.values() if isinstance(p, CycloidDisc)]
        c = g.pin_centers
        nxt = np.roll(np.arange(d.z_pins), -1)
        pin_gap = np.linalg.norm(c[nxt] - c, axis=1) - (g.pin_radii + g.pin_radii[nxt])
        a = d.center_distance_mm
        tip_root = min(a - g.sun.tip_radius - g.planet.root_radius, a - g.planet.tip_radius - g.sun.root_radius)
        housing = self.parts["housing"]
        assert isinstance(housing, PinHousing)
        tip_max = max(p.tip_radius for p in discs) + float(np.max(g.cam_ecc))
        disc_bore = housing.bore_radius - float(np.linalg.norm(housing.bore_center)) - tip_max
        plate = self.parts["carrier"]
        assert isinstance(plate, _Plate)
        plate_root = min(p.root_radius for p in discs) - float(np.max(g.cam_ecc)) - plate.outer_radius
        msgs = [f"disc{p.k}: {p.design_check['message']}" for p in discs]
        ok = bool(pin_gap.min() > 0 and tip_root > 0 and disc_bore > 0)
        if disc_bore <= 0:
            msgs.append(f"disc tips may reach the housing bore (clearance {disc_bore:.4f} mm)")
        if tip_root <= 0:
            msgs.append(f"stage I tip/root interference ({tip_root:.4f} mm)")
        return {
            "ok": ok,
            "undercut": any(p.undercut for p in discs),
            "discs": [{**{k: v for k, v in p.design_check.items()},
                       "profile_rotation_deg": p.profile_rotation_deg} for p in discs],
            "pins": {"count": d.z_pins, "min_gap_mm": float(pin_gap.min()), "overlap": bool(pin_gap.min() <= 0)},
            "stage1": {"sun_tip_radius_mm": g.sun.tip_radius, "planet_tip_radius_mm": g.planet.tip_radius,
                       "tip_root_clearance_mm": float(tip_root)},
            "disc_tip_to_housing_bore_mm": float(disc_bore),
            "disc_root_to_plate_rim_mm": float(plate_root),
            "messages": msgs,
        }

    @property
    def design(self) -> Design:
        return self.geometry.design
