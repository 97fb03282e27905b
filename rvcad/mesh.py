"""Watertight triangle meshes of extruded outlines and stacked cylinders (vertex-exact).

Caps are triangulated by a linear-time strip where the outline is star-shaped, else by GEOS
constrained Delaunay (shapely); side walls join the rings. Every vertex is an exact-outline vertex.
numpy and shapely only; lengths in mm.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import shapely
from shapely.geometry import Polygon

from rvcad.plane import MAX_CHORD_MM, arc_steps, rotate2d, unit

# ----------------------------------------------------------------------------- triangulation
#: Outer rings with more vertices than this are capped by the strip method of
#: :func:`triangulate` (linear time) when the shape allows it; smaller ones by constrained Delaunay.
STRIP_MIN_VERTICES = 1500


def _cdt(rings: Sequence[np.ndarray]) -> np.ndarray:
    """GEOS constrained Delaunay triangulation of a polygon with holes, indices into concat(rings)."""
    pts = np.concatenate(rings)
    poly = Polygon(rings[0], [r for r in rings[1:]])
    if not poly.is_valid:
        from shapely.validation import explain_validity

        raise ValueError(f"outline polygon is invalid (self-intersecting?): {explain_validity(poly)}")
    tri = shapely.constrained_delaunay_triangles(poly)
    coords = shapely.get_coordinates(tri).reshape(-1, 4, 2)[:, :3, :].reshape(-1, 2)
    key = pts[:, 0] + 1j * pts[:, 1]
    order = np.argsort(key)
    sk = key[order]
    if np.any(sk[1:] == sk[:-1]):
        raise ValueError("outline has repeated vertices")
    q = coords[:, 0] + 1j * coords[:, 1]
    pos = np.clip(np.searchsorted(sk, q), 0, len(sk) - 1)
    if not np.all(sk[pos] == q):  # pragma: no cover - GEOS keeps the input vertices
        raise RuntimeError("triangulation created a vertex that is not on the outline")
    faces = order[pos].reshape(-1, 3).astype(np.int64)
    a, b, c = pts[faces[:, 0]], pts[faces[:, 1]], pts[faces[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    flip = area2 < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


def _angles(p: np.ndarray, c: np.ndarray) -> np.ndarray | None:
    """Unwrapped polar angles of a closed CCW ring about c, or None if not strictly increasing."""
    d = p - c
    a = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    if np.any(np.diff(a) <= 0) or not (a[-1] - a[0] < 2.0 * math.pi):
        return None
    return a


def _strip(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray | None:
    """Triangles between an outer CCW ring a and an inner CCW ring b, both star-shaped about c.

    Indices into concat(a, b); ``None`` if either ring is not angle-monotone about c.
    """
    ta, tb = _angles(a, c), _angles(b, c)
    if ta is None or tb is None:
        return None
    na, nb = len(a), len(b)
    # start b at the vertex at or just before a[0] in angle, then unwrap it from there
    rel = np.mod(tb - ta[0], 2.0 * math.pi)
    j0 = int(np.argmax(rel))
    rr = np.roll(rel, -j0)
    tb = ta[0] + np.concatenate([[rr[0] - 2.0 * math.pi], rr[1:]])
    if np.any(np.diff(tb) <= 0):
        return None
    ib = np.roll(np.arange(nb), -j0) + na
    ta_n = np.append(ta, ta[0] + 2.0 * math.pi)
    tb_n = np.append(tb, tb[0] + 2.0 * math.pi)
    ia = np.append(np.arange(na), 0)
    ibn = np.append(ib, ib[0])
    out = np.empty((na + nb, 3), dtype=np.int64)
    i = j = 0
    for m in range(na + nb):
        if j == nb or (i < na and ta_n[i + 1] <= tb_n[j + 1]):
            out[m] = (ia[i], ia[i + 1], ibn[j])
            i += 1
        else:
            out[m] = (ia[i], ibn[j + 1], ibn[j])
            j += 1
    return out


def _positive(pts: np.ndarray, faces: np.ndarray) -> bool:
    a, b, c = pts[faces[:, 0]], pts[faces[:, 1]], pts[faces[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    return bool(np.all(area2 > 0))


def triangulate(rings: Sequence[np.ndarray], interior: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a polygon with holes; its boundary edges are exactly the ring edges.

    Parameters
    ----------
    rings : sequence of (N_i, 2) arrays
        Outer ring first (CCW), then holes (CW); no repeated end points, all vertices distinct.
    interior : bool
        Whether interior vertices may be added (the inner circle of the strip method).

    Returns
    -------
    faces : (T, 3) int64
        Counter-clockwise triangles indexing ``np.concatenate(rings + [extra])``.
    extra : (E, 2) float64
        Interior vertices added by the strip method (none on the boundary).

    Notes
    -----
    Large outlines that are star-shaped about their centroid (cycloid disc, gears, housing) are
    capped in linear time by a strip between the outline and either the single hole or an inner
    circle that encloses all holes; the rest, and everything else, by the GEOS constrained Delaunay
    triangulation (shapely ``constrained_delaunay_triangles``), which keeps the input vertices.
    The result is checked: every triangle has positive area and T = V + 2 H - 2 + (strip extras).
    """
    rings = [np.ascontiguousarray(r, dtype=np.float64) for r in rings]
    pts = np.concatenate(rings)
    n = len(pts)
    faces: np.ndarray | None = None
    extra = np.zeros((0, 2))
    if len(rings[0]) > STRIP_MIN_VERTICES:
        outer = rings[0]
        c = outer.mean(axis=0)
        if len(rings) == 2:
            f = _strip(outer, rings[1][::-1], c)
            if f is not None:
                nb = len(rings[1])
                inner = f >= len(outer)
                f[inner] = len(outer) + (nb - 1 - (f[inner] - len(outer)))
                faces = f
        if faces is None and interior:
            r_out = float(np.min(np.linalg.norm(outer - c, axis=1)))
            r_in = max([float(np.max(np.linalg.norm(h - c, axis=1))) for h in rings[1:]], default=0.0)
            if r_in < r_out:
                rc = 0.5 * (r_in + r_out) if len(rings) > 1 else 0.5 * r_out
                m = max(arc_steps(rc, 2.0 * math.pi, (r_out - rc) * 0.25), 12)
                m = max(m, int(math.ceil(2.0 * math.pi * rc / MAX_CHORD_MM)))
                circ = c + rc * unit(2.0 * math.pi * np.arange(m) / m)
                f_strip = _strip(outer, circ, c)
                if f_strip is not None:
                    f_strip = np.where(f_strip >= len(outer), f_strip - len(outer) + n, f_strip)
                    inner_rings = [circ] + rings[1:]
                    f_in = _cdt(inner_rings)
                    # map: circ -> n.., holes -> their place in pts
                    offs = np.cumsum([0] + [len(r) for r in inner_rings])
                    remap = np.empty(offs[-1], dtype=np.int64)
                    remap[:m] = n + np.arange(m)
                    remap[m:] = np.arange(len(outer), n)
                    faces = np.concatenate([f_strip, remap[f_in]])
                    extra = circ
    allp = np.concatenate([pts, extra])
    if faces is not None:
        if not _positive(allp, faces):
            faces, extra = None, np.zeros((0, 2))
            allp = pts
    if faces is None:
        faces = _cdt(rings)
    a, b, cc = allp[faces[:, 0]], allp[faces[:, 1]], allp[faces[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (cc[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (cc[:, 0] - a[:, 0])
    flip = area2 < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    expected = n + 2 * (len(rings) - 1) - 2 + 2 * len(extra)
    if len(faces) != expected or np.any(area2 == 0):
        raise RuntimeError(f"cap triangulation is not valid: {len(faces)} triangles for {n} vertices "
                           f"and {len(rings) - 1} holes (expected {expected}), {int(np.sum(area2 == 0))} degenerate")
    return faces, extra


# ----------------------------------------------------------------------------- meshes
@dataclass(frozen=True)
class Mesh:
    """Triangle mesh in float64 (mm), faces counter-clockwise seen from outside.

    Attributes
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def volume(self) -> float:
        """Enclosed volume by the divergence theorem, mm^3 (exact for the polyhedron)."""
        v = self.vertices
        a, b, c = v[self.faces[:, 0]], v[self.faces[:, 1]], v[self.faces[:, 2]]
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)

    @property
    def area(self) -> float:
        """Surface area, mm^2."""
        v = self.vertices
        a, b, c = v[self.faces[:, 0]], v[self.faces[:, 1]], v[self.faces[:, 2]]
        return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())

    def placed(self, x: float = 0.0, y: float = 0.0, rotation_deg: float = 0.0) -> "Mesh":
        """Copy rotated about +z by ``rotation_deg`` degrees, then moved by (x, y) mm (float64)."""
        v = self.vertices.copy()
        v[:, :2] = rotate2d(v[:, :2], math.radians(rotation_deg)) + np.array([x, y], dtype=np.float64)
        return Mesh(v, self.faces)

    def check(self) -> "Mesh":
        """Raise ``RuntimeError`` unless the mesh is closed, edge-manifold, consistently wound
        and encloses a positive volume. Returns ``self``."""
        f = self.faces
        nv = np.int64(len(self.vertices))
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        code = np.sort(e[:, 0] * nv + e[:, 1])
        rev = np.sort(e[:, 1] * nv + e[:, 0])
        if np.any(code[1:] == code[:-1]):
            raise RuntimeError("mesh has a directed edge twice (inconsistent winding or non-manifold)")
        if not np.array_equal(code, rev):
            raise RuntimeError("mesh is not watertight (an edge has no opposite)")
        if not self.volume > 0:
            raise RuntimeError(f"mesh volume {self.volume} mm^3 is not positive (faces inside out)")
        return self

    @staticmethod
    def concatenate(meshes: Sequence["Mesh"]) -> "Mesh":
        """One mesh holding several (vertex indices offset)."""
        vs, fs, off = [], [], 0
        for m in meshes:
            vs.append(m.vertices)
            fs.append(m.faces + off)
            off += len(m.vertices)
        return Mesh(np.concatenate(vs), np.concatenate(fs))

    def to_trimesh(self):  # -> trimesh.Trimesh
        """A ``trimesh.Trimesh`` of the same data (no vertex merging)."""
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def _walls(ring_lo: np.ndarray, ring_hi: np.ndarray) -> np.ndarray:
    """Side wall quads between two index rings (same length), outward for CCW outer rings."""
    a, b = ring_lo, np.roll(ring_lo, -1)
    c, d = np.roll(ring_hi, -1), ring_hi
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _tri(rings: Sequence[np.ndarray]) -> np.ndarray:
    """:func:`triangulate` without interior vertices (faces only)."""
    return triangulate(rings, interior=False)[0]


def extrude_rings(rings: Sequence[np.ndarray], z0: float, z1: float) -> Mesh:
    """Watertight prism of a polygon with holes between z0 < z1 (mm).

    Parameters
    ----------
    rings : sequence of (N_i, 2)
        Outer ring CCW, holes CW (vertex-exact samples of the outline).
    z0, z1 : float
        Bottom and top, mm.
    """
    rings = [np.asarray(r, dtype=np.float64) for r in rings]
    cap, extra = triangulate(rings)
    pts = np.concatenate(rings + [extra])
    n = len(pts)
    v = np.concatenate([np.c_[pts, np.full(n, z0)], np.c_[pts, np.full(n, z1)]])
    faces = [cap[:, ::-1], cap + n]
    off = 0
    for r in rings:
        idx = np.arange(off, off + len(r))
        faces.append(_walls(idx, idx + n))
        off += len(r)
    return Mesh(v, np.concatenate(faces).astype(np.int64))


def _circle_intersections(c1: np.ndarray, r1: float, c2: np.ndarray, r2: float) -> np.ndarray:
    d = c2 - c1
    dist = float(np.linalg.norm(d))
    a = (dist * dist + r1 * r1 - r2 * r2) / (2.0 * dist)
    h = math.sqrt(max(r1 * r1 - a * a, 0.0))
    ud = d / dist
    pm = c1 + a * ud
    perp = np.array([-ud[1], ud[0]])
    return np.array([pm - h * perp, pm + h * perp])


def _forced_angles(secs: list[tuple[float, float, np.ndarray, float]]
                   ) -> tuple[list[list[float]], list[np.ndarray | None]]:
    """Per section, the angles (about its centre, rad) of its circle's crossings with its neighbours; per
    step between two sections, the two crossing points of their circles (mm; ``None`` when nested)."""
    extra: list[list[float]] = [[] for _ in secs]
    crossings: list[np.ndarray | None] = []
    for i in range(len(secs) - 1):
        (_, _, ca, ra), (_, _, cb, rb) = secs[i], secs[i + 1]
        d = float(np.linalg.norm(cb - ca))
        if d + min(ra, rb) < max(ra, rb) - 1e-9:
            crossings.append(None)  # nested
            continue
        if d >= ra + rb or d < 1e-12:
            raise ValueError("stacked circular sections must overlap")
        x = _circle_intersections(ca, ra, cb, rb)
        crossings.append(x)
        extra[i] += [math.atan2(*(p - ca)[::-1]) for p in x]
        extra[i + 1] += [math.atan2(*(p - cb)[::-1]) for p in x]
    return extra, crossings


def _ring_angles(r: float, forced: list[float], sagitta: float) -> np.ndarray:
    """Vertex angles (rad) of a circle of radius ``r`` (mm) within the chord ``sagitta`` (mm), through
    every ``forced`` angle (each arc between two forced angles is divided evenly)."""
    n = arc_steps(r, 2.0 * math.pi, sagitta)
    if not forced:
        return 2.0 * math.pi * np.arange(n) / n
    f = np.sort(np.mod(np.asarray(forced), 2.0 * math.pi))
    out = []
    for k in range(len(f)):
        a0 = f[k]
        a1 = f[(k + 1) % len(f)] + (2.0 * math.pi if k + 1 == len(f) else 0.0)
        m = arc_steps(r, a1 - a0, sagitta)
        out.append(a0 + (a1 - a0) * np.arange(m) / m)
    return np.concatenate(out)


def _annulus_step(pa: np.ndarray, hi_a: np.ndarray, pb: np.ndarray, lo_b: np.ndarray, lower_larger: bool
                  ) -> np.ndarray:
    """Faces of the annular step between nested rings: the top ring ``pa`` (vertex ids ``hi_a``) of the
    lower section and the bottom ring ``pb`` (ids ``lo_b``) of the upper one, facing the open side."""
    if lower_larger:  # face looks up, annulus lower \ upper
        t = _tri([pa, pb[::-1]])
        idx = np.concatenate([hi_a, lo_b[::-1]])
        return idx[t]
    # upper is larger: face looks down, annulus upper \ lower
    t = _tri([pb, pa[::-1]])
    idx = np.concatenate([lo_b, hi_a[::-1]])
    return idx[t][:, ::-1]


def _crescent(pp: np.ndarray, hh: np.ndarray, iia: list[int], outside: np.ndarray, qq: np.ndarray,
              hq: np.ndarray, iiq: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Outline (mm) and vertex ids of the crescent of ring ``pp`` outside ring ``qq``.

    Walks ``pp`` (CCW) over its ``outside`` part from one crossing vertex (``iia``) to the other, then
    ``qq`` back (CW) between its crossing vertices ``iiq``, leaving out the shared crossing points.
    """
    n1, n2 = len(pp), len(qq)
    start = next(k for k in iia if outside[(k + 1) % n1] and (k + 1) % n1 not in iia)
    other = iia[1] if start == iia[0] else iia[0]
    path1 = [start]
    k = start
    while k != other:
        k = (k + 1) % n1
        path1.append(k)
    s2 = iiq[iia.index(other)]
    e2 = iiq[iia.index(start)]
    path2 = []
    k = s2
    while k != e2:
        k = (k - 1) % n2
        path2.append(k)
    path2 = path2[:-1]
    ring = np.concatenate([pp[path1], qq[path2]]) if path2 else pp[path1]
    idx = np.concatenate([hh[path1], hq[path2]]) if path2 else hh[path1]
    return ring, idx


def _crescent_steps(a: tuple[np.ndarray, np.ndarray, np.ndarray, float],
                    b: tuple[np.ndarray, np.ndarray, np.ndarray, float], x: np.ndarray, remap: np.ndarray
                    ) -> list[np.ndarray]:
    """Faces of the step between crossing circles: crescent A \\ B looks up, crescent B \\ A looks down.

    ``a`` is (top ring points, their vertex ids, centre, radius) of the lower section, ``b`` the same
    for the bottom ring of the upper one (mm); ``x`` holds the two crossing points (mm). Each crossing
    point keeps one vertex, the lower ring's: ``remap`` is updated in place to merge the upper one.
    """
    (pa, hi_a, ca, ra_), (pb, lo_b, cb, rb_) = a, b
    ia = [int(np.argmin(np.linalg.norm(pa - q, axis=1))) for q in x]
    ib = [int(np.argmin(np.linalg.norm(pb - q, axis=1))) for q in x]
    for ka, kb in zip(ia, ib):
        remap[lo_b[kb]] = hi_a[ka]
    out_a = np.linalg.norm(pa - cb, axis=1) > rb_ - 1e-12
    out_b = np.linalg.norm(pb - ca, axis=1) > ra_ - 1e-12
    faces = []
    for (pp, hh, iia, outside, qq, hq, iiq, up) in (
            (pa, hi_a, ia, out_a, pb, lo_b, ib, True), (pb, lo_b, ib, out_b, pa, hi_a, ia, False)):
        ring, idx = _crescent(pp, hh, iia, outside, qq, hq, iiq)
        t = _tri([ring])
        faces.append(idx[t] if up else idx[t][:, ::-1])
    return faces


def stacked_circles(sections: Sequence[tuple[float, float, Sequence[float], float]], sagitta: float) -> Mesh:
    """Watertight mesh of a stack of circular cylinders (a crankshaft), vertex-exact on every circle.

    Parameters
    ----------
    sections : sequence of (z0, z1, center (2,), radius)
        Consecutive z intervals (each z1 equals the next z0), mm.
    sagitta : float
        Chord sagitta of the circles, mm.

    Notes
    -----
    Between two sections the step face is the annulus between nested circles, or, where the circles
    cross, the two crescents (their intersection points are inserted into both circles).
    """
    secs = [(float(a), float(b), np.asarray(c, dtype=np.float64), float(r)) for a, b, c, r in sections]
    for s0, s1 in zip(secs, secs[1:]):
        if abs(s0[1] - s1[0]) > 1e-12:
            raise ValueError("stacked sections must be contiguous in z")
    # angles (about each circle's centre) of extra vertices forced by crossing neighbours
    extra, crossings = _forced_angles(secs)
    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    rings_idx: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (lo idx, hi idx, 2D pts)
    off = 0
    for (z0, z1, c, r), forced in zip(secs, extra):
        a = _ring_angles(r, forced, sagitta)
        p = c + r * unit(a)
        n = len(p)
        verts += [np.c_[p, np.full(n, z0)], np.c_[p, np.full(n, z1)]]
        lo, hi = np.arange(off, off + n), np.arange(off + n, off + 2 * n)
        faces.append(_walls(lo, hi))
        rings_idx.append((lo, hi, p))
        off += 2 * n
    # end caps
    lo0, _, p0 = rings_idx[0]
    faces.append(lo0[_tri([p0])][:, ::-1])
    _, hiN, pN = rings_idx[-1]
    faces.append(hiN[_tri([pN])])
    # steps
    remap = np.arange(off, dtype=np.int64)
    for i, x in enumerate(crossings):
        _, hi_a, pa = rings_idx[i]
        lo_b, _, pb = rings_idx[i + 1]
        if x is None:
            faces.append(_annulus_step(pa, hi_a, pb, lo_b, secs[i][3] > secs[i + 1][3]))
        else:
            faces += _crescent_steps((pa, hi_a, secs[i][2], secs[i][3]), (pb, lo_b, secs[i + 1][2], secs[i + 1][3]),
                                     x, remap)
    return Mesh(np.concatenate(verts), remap[np.concatenate(faces).astype(np.int64)])



__all__ = ["STRIP_MIN_VERTICES", "Mesh", "extrude_rings", "stacked_circles", "triangulate"]
