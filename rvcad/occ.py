"""OpenCASCADE (OCP) builders of the part solids: the only place the CAD kernel builds geometry.

A planar part is its :class:`~rvcad.outline.Loop` outline turned into a wire (exact lines and
circles, the fitted cubic B-splines of :mod:`rvcad.bspline` for exact curves), a planar face and
a prism; a crankshaft is the fused stack of its cylinders. :func:`check_solid` runs
``BRepCheck_Analyzer`` on a built solid. OCP is imported inside the functions only, so the numpy
layer stays usable without the kernel. Lengths in mm.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rvcad.outline import ArcSeg, LineSeg, Loop


def occ_wire(loop: Loop, tol: float, z: float):
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


def planar_solid(outer: Loop, holes: list[Loop], z0: float, z1: float, tol: float):
    """OCP ``TopoDS_Solid``: the planar face of the loops at z0 extruded to z1."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Vec
    from OCP.TopAbs import TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    mf = BRepBuilderAPI_MakeFace(occ_wire(outer, tol, z0), True)
    for h in holes:
        mf.Add(occ_wire(h, tol, z0))
    if not mf.IsDone():
        raise RuntimeError(f"OpenCASCADE could not build the planar face (error {mf.Error()})")
    prism = BRepPrimAPI_MakePrism(mf.Face(), gp_Vec(0.0, 0.0, float(z1 - z0)))
    ex = TopExp_Explorer(prism.Shape(), TopAbs_SOLID)
    return TopoDS.Solid(ex.Current())


def cylinders_union(sections: list[tuple[float, float, np.ndarray, float]]):
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


class InvalidSolidError(ValueError):
    """A built solid fails OpenCASCADE's ``BRepCheck_Analyzer``; it is not written."""


def check_solid(shape: Any, name: str) -> Any:
    """Raise :class:`InvalidSolidError` unless ``BRepCheck_Analyzer`` finds the shape valid; returns it."""
    from OCP.BRepCheck import BRepCheck_Analyzer

    if not BRepCheck_Analyzer(shape).IsValid():
        raise InvalidSolidError(f"part {name}: the built solid is not valid (OpenCASCADE BRepCheck_Analyzer); "
                                "it is not written")
    return shape


__all__ = ["InvalidSolidError", "check_solid", "cylinders_union", "occ_wire", "planar_solid"]
