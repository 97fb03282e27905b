"""The one module that talks to python-fcl (habit of trimesh ``collision.py``).

Everything else in the project calls these functions, never ``fcl`` directly. Transforms are
passed in float64 (a float32 transform loses about 10 nm at 100 mm).

Note (FCL behaviour): mesh-mesh *distance* returns 0 (or a meaningless value) once two bodies
penetrate; it never gives a penetration depth. Callers that need a signed gap must keep the
queried bodies apart, e.g. by querying a probe shrunk by a known margin and adding it back
(see :mod:`rvdyn.fcl_contacts`).
"""
from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np


def bvh(vertices: np.ndarray, faces: np.ndarray) -> fcl.BVHModel:
    """OBBRSS bounding-volume hierarchy of a triangle mesh (vertices mm, float64)."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    m = fcl.BVHModel()
    m.beginModel(len(v), len(f))
    m.addSubModel(v, f)
    m.endModel()
    return m


def cylinder(radius: float, length: float) -> fcl.Cylinder:
    """FCL cylinder along its local z, centred at its origin (mm)."""
    return fcl.Cylinder(float(radius), float(length))


def transform(rotation_deg: float = 0.0, xy: tuple[float, float] = (0.0, 0.0), z: float = 0.0) -> fcl.Transform:
    """Planar placement: rotation about +z (degrees) and translation (mm), float64."""
    a = np.deg2rad(rotation_deg)
    c, s = np.cos(a), np.sin(a)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=np.float64)
    return fcl.Transform(R, np.array([xy[0], xy[1], z], dtype=np.float64))


def obj(geometry: fcl.CollisionGeometry, tf: fcl.Transform | None = None) -> fcl.CollisionObject:
    """Collision object of a geometry at a placement."""
    return fcl.CollisionObject(geometry, tf if tf is not None else fcl.Transform())


@dataclass(frozen=True)
class Distance:
    """Result of a distance query: distance (mm) and nearest points on each body (world frame, mm)."""

    distance: float
    p1: np.ndarray
    p2: np.ndarray


_REQ = fcl.DistanceRequest(enable_nearest_points=True, enable_signed_distance=True)


def distance(o1: fcl.CollisionObject, o2: fcl.CollisionObject) -> Distance:
    """Minimum distance between two placed objects with nearest points (mm)."""
    res = fcl.DistanceResult()
    d = fcl.distance(o1, o2, _REQ, res)
    return Distance(float(d), np.array(res.nearest_points[0], dtype=float), np.array(res.nearest_points[1], dtype=float))


def collide(o1: fcl.CollisionObject, o2: fcl.CollisionObject, max_contacts: int = 1) -> bool:
    """True when the two placed objects overlap (touching counts as overlap in FCL)."""
    req = fcl.CollisionRequest(num_max_contacts=max_contacts, enable_contact=False)
    return bool(fcl.collide(o1, o2, req, fcl.CollisionResult()))
