"""STEP files through the OCP XCAF document: named parts, placed assemblies, read-back helpers.

The writer sets a fixed header time stamp so that identical input gives byte-identical files.
OCP is imported inside the functions only. Lengths in mm.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

#: Fixed STEP header time stamp: identical input gives byte-identical STEP files.
STEP_TIMESTAMP = "2000-01-01T00:00:00"


def step_writer(items: Sequence[tuple[str, Any, tuple[float, float, float] | None]],
                 name: str) -> Callable[[Path], None]:
    """Writer of a STEP file (AP214, mm) through the OCP XCAF document, without build123d.

    ``items`` are (label, TopoDS_Shape, placement or None). One item without placement is written
    as a single named part; otherwise an assembly ``name`` whose components are the named parts
    placed by (x mm, y mm, rotation deg about +z).
    """
    def w(p: Path) -> None:
        from OCP.APIHeaderSection import APIHeaderSection_MakeHeader
        from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt, gp_Trsf, gp_Vec
        from OCP.IFSelect import IFSelect_ReturnStatus
        from OCP.Interface import Interface_Static
        from OCP.Message import Message, Message_Gravity
        from OCP.STEPCAFControl import STEPCAFControl_Controller, STEPCAFControl_Writer
        from OCP.STEPControl import STEPControl_Controller, STEPControl_StepModelType
        from OCP.TCollection import TCollection_ExtendedString, TCollection_HAsciiString
        from OCP.TDataStd import TDataStd_Name
        from OCP.TDocStd import TDocStd_Document
        from OCP.TopLoc import TopLoc_Location
        from OCP.XCAFApp import XCAFApp_Application
        from OCP.XCAFDoc import XCAFDoc_DocumentTool
        from OCP.XSControl import XSControl_WorkSession

        doc = TDocStd_Document(TCollection_ExtendedString("XmlOcaf"))
        app = XCAFApp_Application.GetApplication_s()
        app.NewDocument(TCollection_ExtendedString("MDTV-XCAF"), doc)
        app.InitDocument(doc)
        XCAFDoc_DocumentTool.SetLengthUnit_s(doc, 0.001)
        tool = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
        tool.SetAutoNaming_s(False)

        def named(label: Any, text: str) -> Any:
            TDataStd_Name.Set_s(label, TCollection_ExtendedString(text))
            return label

        if len(items) == 1 and items[0][2] is None:
            named(tool.AddShape(items[0][1], False), items[0][0])
        else:
            asm = named(tool.NewShape(), name)
            for label, shape, pl in items:
                part = named(tool.AddShape(shape, False), label)
                x, y, r = pl if pl is not None else (0.0, 0.0, 0.0)
                tr = gp_Trsf()
                tr.SetRotation(gp_Ax1(gp_Pnt(0.0, 0.0, 0.0), gp_Dir(0.0, 0.0, 1.0)), math.radians(r))
                tt = gp_Trsf()
                tt.SetTranslation(gp_Vec(float(x), float(y), 0.0))
                comp = tool.AddComponent(asm, part, TopLoc_Location(tt.Multiplied(tr)))
                named(comp, label)
            tool.UpdateAssemblies()
        for printer in Message.DefaultMessenger_s().Printers():
            printer.SetTraceLevel(Message_Gravity.Message_Fail)
        STEPCAFControl_Controller.Init_s()
        STEPControl_Controller.Init_s()
        writer = STEPCAFControl_Writer(XSControl_WorkSession(), False)
        writer.SetNameMode(True)
        header = APIHeaderSection_MakeHeader(writer.Writer().Model())
        if not header.IsDone():
            header = APIHeaderSection_MakeHeader(0)
            header.Apply(writer.Writer().Model())
        header.SetName(TCollection_HAsciiString(name))
        header.SetTimeStamp(TCollection_HAsciiString(STEP_TIMESTAMP))
        header.SetOriginatingSystem(TCollection_HAsciiString("rvcad"))
        Interface_Static.SetIVal_s("write.surfacecurve.mode", 1)
        Interface_Static.SetIVal_s("write.precision.mode", 0)
        if not writer.Transfer(doc, STEPControl_StepModelType.STEPControl_AsIs):
            raise RuntimeError(f"OpenCASCADE could not transfer {name} to STEP")
        if writer.Write(str(p)) != IFSelect_ReturnStatus.IFSelect_RetDone:
            raise RuntimeError(f"OpenCASCADE could not write {p}")
    return w


def read_step(path: str | Path) -> Any:
    """Read a STEP file back as one OCP ``TopoDS_Shape`` (for checks); raises ``ValueError``."""
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader

    r = STEPControl_Reader()
    if r.ReadFile(str(path)) != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise ValueError(f"{path} is not a readable STEP file")
    r.TransferRoots()
    return r.OneShape()


def edge_samples(shape: Any, per_edge: int = 400, kinds: Sequence[str] | None = None) -> list[tuple[str, np.ndarray]]:
    """Points sampled along every edge of an OCP shape: (curve type, (per_edge, 3) mm).

    The curve type is the OpenCASCADE ``GeomAbs_CurveType`` name without prefix (``Line``,
    ``Circle``, ``BSplineCurve``, ...). Parameters are spaced uniformly over each edge's range;
    edge locations (assembly placements) are applied. ``kinds`` keeps only those curve types.
    """
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    out: list[tuple[str, np.ndarray]] = []
    ex = TopExp_Explorer(shape, TopAbs_EDGE)
    while ex.More():
        a = BRepAdaptor_Curve(TopoDS.Edge(ex.Current()))
        kind = a.GetType().name.replace("GeomAbs_", "")
        if kinds is not None and kind not in kinds:
            ex.Next()
            continue
        u = np.linspace(a.FirstParameter(), a.LastParameter(), per_edge)
        pts = np.empty((per_edge, 3))
        for i, uu in enumerate(u):
            p = a.Value(float(uu))
            pts[i] = (p.X(), p.Y(), p.Z())
        out.append((kind, pts))
        ex.Next()
    return out


def count_faces(shape: Any) -> int:
    """Number of faces of an OCP shape."""
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer

    ex, n = TopExp_Explorer(shape, TopAbs_FACE), 0
    while ex.More():
        n += 1
        ex.Next()
    return n



__all__ = ["STEP_TIMESTAMP", "count_faces", "edge_samples", "read_step", "step_writer"]
