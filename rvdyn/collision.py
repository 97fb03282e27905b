"""The one module that talks to python-fcl (habit of trimesh ``collision.py``).

Everything else in the project (the ``fcl`` contact provider :mod:`rvdyn.fcl_contacts`, the CAD
tests) calls these functions, never ``fcl`` directly. Transforms are
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


# ------------------------------------------------------------------ point probes
# Added for rvdyn.fcl_contacts: many point-to-mesh distance queries with the Python overhead
# kept to one reused probe object, request and result (python-fcl 0.7's ``fcl.distance`` only
# overwrites a result whose ``min_distance`` is larger, so the result is reset before each query).

def sphere(radius: float) -> fcl.Sphere:
    """FCL sphere centred at its origin (mm). Radius 0 is a point probe."""
    return fcl.Sphere(float(radius))


class PointProbe:
    """Exact point-to-triangle-mesh distances through FCL's sphere-mesh distance.

    The probe is a sphere of radius 0, so FCL's closed-form sphere-triangle distance is the
    point-triangle distance (float64, no GJK iteration, no tolerance).

    Notes
    -----
    python-fcl 0.7 reports the nearest point on the mesh in the mesh's own frame and the index
    of the nearest triangle in ``DistanceResult.b1`` when the mesh is the first object; keep the
    mesh object at the identity placement and move the query points instead, then both
    conventions (mesh frame, world frame) give the same numbers.
    """

    def __init__(self) -> None:
        self._obj = fcl.CollisionObject(fcl.Sphere(0.0), fcl.Transform())
        self._req = fcl.DistanceRequest(enable_nearest_points=True, enable_signed_distance=False,
                                        gjk_solver_type=fcl.GJKSolverType.GST_INDEP)
        self._res = fcl.DistanceResult()

    def distances(self, mesh: fcl.CollisionObject,
                  points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unsigned distances from points to a mesh placed at the identity.

        Parameters
        ----------
        mesh : fcl.CollisionObject
            BVH mesh object at the identity placement.
        points : (K, 3) array, mm

        Returns
        -------
        distance : (K,) mm (>= 0; 0 where a point lies on the mesh)
        triangle : (K,) int, index of the nearest triangle
        nearest : (K, 3) mm, nearest point on the mesh
        """
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        n = len(pts)
        dist = np.empty(n)
        tri = np.empty(n, dtype=np.int64)
        near = np.empty((n, 3))
        o, req, res, fd = self._obj, self._req, self._res, fcl.distance
        big = float(np.finfo(np.float64).max)
        for i in range(n):
            o.setTranslation(pts[i])
            res.min_distance = big
            dist[i] = fd(mesh, o, req, res)
            tri[i] = res.b1
            near[i] = res.nearest_points[0]
        return dist, tri, near
