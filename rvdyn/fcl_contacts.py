"""The ``fcl`` contact provider: python-fcl distance queries on meshes of the exported geometry.

The analytic provider (:class:`rvdyn.contacts.AnalyticContacts`) is the exact reference; this
one answers the same two questions on triangle meshes built from the very samples that the
exported STL uses, so it checks the exported geometry end to end. Every call into FCL goes
through :mod:`rvcad.collision` (the only module that imports ``fcl``).

Disc boundary (``disc_distance``)
---------------------------------
* Mesh. The exported disc outline is ``CycloidProfile.boundary_points(sagitta)``: every vertex
  lies on the exact envelope and no chord deviates from it by more than the sagitta. The disc
  profile is exactly ``Zc``-fold symmetric in its own frame and the sampling is identical for
  every lobe, so one window of the outline, two lobe pitches long and centred on root 0
  (``t`` in ``[root_t(0) - 2 pi/Zc, root_t(0) + 2 pi/Zc]``), serves every tooth space: a query
  point is turned by ``-m 2 pi / Zc`` into the window, ``m`` being the tooth space that the
  start parameter ``t0`` names. The window is a side-wall strip with one triangle per chord
  (a "fin"): the chord itself at z = 0 and its apex above the chord midpoint, so the strip's
  section at z = 0 is the exported outline exactly and each chord costs one triangle.
* Query. A sphere of radius 0 at the point (z = 0): FCL's closed-form sphere-triangle distance
  is then the exact point-to-outline distance (no margin, no GJK tolerance). The strip is a
  surface, not a solid, so the distance stays positive inside the material and never collapses
  to 0: the sign comes from the side of the nearest chord on which the point lies (nearest point
  and triangle index both reported by FCL).
* Normal. The outward normal is that of the exported outline with its vertex normals (the exact
  profile normals at the sample parameters), interpolated along each chord: the foot on the
  outline where the interpolated normal points at the query point. A chord's own normal would be
  off by up to half the angle the chord subtends (about 6e-3 rad in the roots at the default
  sagitta); the interpolated one agrees with the exact normal to about 1e-6 rad, which the
  solver's Jacobian needs.
* Accuracy. The distance is the distance to the exported polygon: within the sagitta of the
  exact envelope (0.04 um at the default 0.05 um, the chord count being rounded up by 10 %).

Stage I (``stage1_gaps``)
-------------------------
Meshes of the loaded flanks only (the upper flanks ``InvoluteGear.flank_points`` of every tooth
for direction +1, their mirror images for -1), as fin strips, placed at the sun and planet
poses. The gap is measured along the line of action (the common tangent of the base circles,
which is the common normal of two involutes): the planet mesh is moved away from the sun by a
known margin along that line, FCL gives the mesh-mesh distance, and the margin is subtracted.
For two smooth flanks, a translation along their common normal keeps the same closest pair, so
the subtraction is exact; on the polygons it is exact to ``margin * angle**2 / 2`` (well below
1e-5 um). The margin starts at 0.05 mm and grows when the moved meshes still touch, so
interference of any realistic depth is measured, not clipped at 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rvcad import collision
from rvcad.geometry import ReducerGeometry
from rvcad.profile import CycloidProfile, InvoluteGear

#: Height of the fin strips above the profile plane, mm (any positive value gives the same
#: distances; the point queries sit at z = 0).
FIN_HEIGHT_MM = 1.0

#: First margin by which the planet mesh is moved away along the line of action, mm.
STAGE1_MARGIN_MM = 0.05

#: Distance below which two moved flank meshes count as still touching, mm.
_TOUCH_MM = 1e-9


def fin_mesh(chains: list[np.ndarray], height: float = FIN_HEIGHT_MM) -> tuple[np.ndarray, np.ndarray]:
    """Side-wall strip of open polylines, one triangle per chord.

    Parameters
    ----------
    chains : list of (n_i, 2) arrays, mm
        Polylines in the plane z = 0.
    height : float
        Apex height of each triangle, mm.

    Returns
    -------
    vertices : (V, 3) float64, mm
    faces : (F, 3) int64
        Triangle ``j`` of chain ``c`` (counted over all chains in order) has the chord from
        vertex ``j`` to ``j + 1`` of that chain as its edge at z = 0 and its apex above the
        chord midpoint, so its section at z = 0 is exactly the chord.
    """
    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    off = 0
    for c in chains:
        c = np.asarray(c, dtype=np.float64)
        n = len(c)
        base = np.column_stack([c, np.zeros(n)])
        apex = np.column_stack([0.5 * (c[1:] + c[:-1]), np.full(n - 1, float(height))])
        i = np.arange(n - 1)
        faces.append(np.column_stack([off + i, off + i + 1, off + n + i]))
        verts.extend([base, apex])
        off += 2 * n - 1
    return np.concatenate(verts), np.concatenate(faces).astype(np.int64)


def _rot2(points: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Turn 2-D points (K, 2) by angles (K,) (rad) about the origin."""
    c, s = np.cos(angle), np.sin(angle)
    x, y = points[:, 0], points[:, 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=1)


def _cross(ax: np.ndarray, ay: np.ndarray, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
    return ax * by - ay * bx


@dataclass
class DiscWindow:
    """Mesh of one tooth-space window of a disc outline with its vertex normals.

    Attributes
    ----------
    t : (n,) rad
        Sample parameters of the window vertices (exported samples of lobes -1 and 0 and the
        root of lobe 1).
    b : (n, 2) mm
        Window vertices, on the exact envelope.
    n_start, n_end : (n - 1, 2)
        Exact outward normals at the two ends of each chord (at a trimmed undercut corner, the
        normal of the piece the chord lies on).
    facet : (n - 1, 2)
        Outward unit normal of each chord.
    root_t : float
        Parameter of root 0, rad (window centre).
    pitch : float
        Lobe pitch 2 pi / Zc, rad.
    obj : fcl.CollisionObject
        BVH of the fin strip at the identity placement.
    n_triangles : int
    """

    t: np.ndarray
    b: np.ndarray
    n_start: np.ndarray
    n_end: np.ndarray
    facet: np.ndarray
    root_t: float
    pitch: float
    obj: object
    n_triangles: int

    @classmethod
    def build(cls, prof: CycloidProfile, sagitta: float) -> "DiscWindow":
        """Window of ``prof``'s exported outline sampled at ``sagitta`` (mm)."""
        t_all = prof.boundary_t(sagitta)
        zc = prof.z_lobes
        n_per = len(t_all) // zc
        if n_per * zc != len(t_all):
            raise ValueError("boundary sampling is not identical for every lobe; the tooth-space window needs it")
        two_pi = 2.0 * math.pi
        t = np.concatenate([t_all[-n_per:] - two_pi, t_all[:n_per], t_all[n_per:n_per + 1]])
        b = prof.boundary(t)
        n_start = prof.normal(t[:-1])
        n_end = prof.normal(t[1:])
        trim = prof.trim_t
        pitch = two_pi / zc
        if trim is not None:
            # Chords that jump over a trimmed swallowtail: b(t1) = b(t2), and the chord lies on the
            # piece beyond the loop, so its corner normal is that piece's normal.
            t1, t2 = trim
            tip2 = 2.0 * prof.tip_t()
            eps = 1e-12
            for lobe in (-1, 0):
                sh = lobe * pitch
                j = np.nonzero(np.abs(t[:-1] - (t1 + sh)) < eps)[0]
                n_start[j] = prof.normal(np.full(len(j), t2 + sh))
                j = np.nonzero(np.abs(t[1:] - (tip2 - t1 + sh)) < eps)[0]
                n_end[j] = prof.normal(np.full(len(j), tip2 - t2 + sh))
        e = b[1:] - b[:-1]
        facet = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.linalg.norm(e, axis=1, keepdims=True)
        v, f = fin_mesh([b])
        obj = collision.obj(collision.bvh(v, f))
        return cls(t, b, n_start, n_end, facet, prof.root_t(), pitch, obj, len(f))


def smooth_foot(b: np.ndarray, n_start: np.ndarray, n_end: np.ndarray, p: np.ndarray,
                seg: np.ndarray, max_steps: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Foot of points on a polyline with normals interpolated along each chord.

    Finds, starting from chord ``seg``, the chord ``j`` and fraction ``f`` in [0, 1] where the
    interpolated normal ``(1 - f) n_start[j] + f n_end[j]`` points at ``p`` (the smooth-surface
    foot of the polygon), walking to the neighbouring chord while ``f`` falls outside [0, 1].

    Parameters
    ----------
    b : (n, 2) mm, polyline vertices
    n_start, n_end : (n - 1, 2), unit normals at the chord ends
    p : (K, 2) mm
    seg : (K,) int, start chords (the nearest chord)
    max_steps : int
        Chords walked at most.

    Returns
    -------
    normal : (K, 2) unit normals at the feet
    foot : (K, 2) mm, foot points on the polyline
    """
    nseg = len(b) - 1
    j = np.asarray(seg, dtype=np.int64).copy()
    f = np.zeros(len(j))
    for it in range(max_steps + 1):
        b0 = b[j]
        ex, ey = (b[j + 1] - b0).T
        wx, wy = (p - b0).T
        nx0, ny0 = n_start[j].T
        dnx, dny = (n_end[j] - n_start[j]).T
        # cross(w - f e, n0 + f dn) = 0  ->  A f^2 + B f + C = 0
        A = -_cross(ex, ey, dnx, dny)
        B = _cross(wx, wy, dnx, dny) - _cross(ex, ey, nx0, ny0)
        C = _cross(wx, wy, nx0, ny0)
        disc = np.maximum(B * B - 4.0 * A * C, 0.0)
        q = -0.5 * (B + np.copysign(np.sqrt(disc), B))
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.where(q != 0.0, C / q, 0.5)
        step = np.where(f < 0.0, -1, np.where(f > 1.0, 1, 0))
        step = np.where((j + step < 0) | (j + step >= nseg), 0, step)
        if not step.any() or it == max_steps:
            break
        j = j + step
    f = np.clip(f, 0.0, 1.0)
    n = (1.0 - f)[:, None] * n_start[j] + f[:, None] * n_end[j]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    foot = b[j] + f[:, None] * (b[j + 1] - b[j])
    return n, foot


class FclContacts:
    """Contact provider on the exported meshes, answered by python-fcl distance queries.

    Parameters
    ----------
    geom : ReducerGeometry
        The case geometry (profiles, gears, placements).
    sagitta_mm : float
        Chord sagitta of the disc outline and of the involute flank samples, mm (default
        0.05 um, the project's ``Tolerances.sagitta_mm``). The disc mesh uses the samples of
        ``CycloidProfile.boundary_points(sagitta_mm)``, the flank meshes
        ``InvoluteGear.flank_points(sagitta=sagitta_mm)``.

    Attributes
    ----------
    name : str
        ``"fcl"``.
    windows : list of DiscWindow
        One tooth-space window per disc.
    stage1_margin_mm : float
        First margin along the line of action for the stage I query, mm.
    """

    name = "fcl"

    def __init__(self, geom: ReducerGeometry, sagitta_mm: float = 5e-5) -> None:
        if not (math.isfinite(sagitta_mm) and sagitta_mm > 0):
            raise ValueError(f"sagitta_mm {sagitta_mm} must be a finite number > 0 (mm)")
        self.geom = geom
        self.sagitta_mm = float(sagitta_mm)
        self.windows = [DiscWindow.build(prof, self.sagitta_mm) for prof in geom.profiles]
        self._probe = collision.PointProbe()
        self.stage1_margin_mm = STAGE1_MARGIN_MM
        self._gear_objs: dict[int, tuple[object, object]] = {}
        self.gear_triangles: dict[str, int] = {}
        for d in (1, -1):
            sun_v, sun_f = fin_mesh(self._loaded_flanks(geom.sun, d))
            pl_v, pl_f = fin_mesh(self._loaded_flanks(geom.planet, d))
            self._gear_objs[d] = (collision.obj(collision.bvh(sun_v, sun_f)),
                                  collision.obj(collision.bvh(pl_v, pl_f)))
            self.gear_triangles = {"sun": len(sun_f), "planet": len(pl_f)}

    # ------------------------------------------------------------------ meshes
    def _loaded_flanks(self, gear: InvoluteGear, direction: int) -> list[np.ndarray]:
        """Loaded flank of every tooth in the gear frame (tooth 0 centred on +x), mm.

        Direction +1 loads the upper flanks (facing +theta) of both gears, -1 the lower flanks.
        """
        up = gear.flank_points(sagitta=self.sagitta_mm)
        fl = up if direction == 1 else up * np.array([1.0, -1.0])
        out = []
        for i in range(gear.z):
            a = 2.0 * math.pi * i / gear.z
            c, s = math.cos(a), math.sin(a)
            out.append(fl @ np.array([[c, s], [-s, c]]))
        return out

    @property
    def disc_triangles(self) -> list[int]:
        """Triangles of each disc's window mesh."""
        return [w.n_triangles for w in self.windows]

    # ------------------------------------------------------------------ discs
    def disc_distance(self, k: int, p: np.ndarray, t0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance from points to disc k's exported boundary and the outward normal.

        Parameters
        ----------
        k : int
            Disc index.
        p : (K, 2) array, mm
            Points in disc k's profile frame.
        t0 : (K,) array, rad
            Pin-centre-curve parameter near which each point sits (from
            ``ReducerGeometry.pins_in_profile_frames``); it picks the tooth space. It may be off
            by up to a quarter of a lobe pitch.

        Returns
        -------
        distance : (K,) mm
            Positive outside the disc material, negative inside (any depth the window holds,
            i.e. far beyond the 50 um the solver needs).
        normal : (K, 2)
            Outward unit normal of the boundary at the foot point, profile frame.

        Raises
        ------
        ValueError
            If a point's nearest boundary point falls at the end of the window (``t0`` off by
            about half a lobe pitch or more).
        """
        w = self.windows[k]
        p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        t0 = np.asarray(t0, dtype=np.float64).ravel()
        if len(t0) != len(p):
            raise ValueError(f"p has {len(p)} points but t0 has {len(t0)} parameters")
        if len(p) == 0:
            return np.empty(0), np.empty((0, 2))
        turn = -np.rint((t0 - w.root_t) / w.pitch) * w.pitch
        q = _rot2(p, turn)
        pts = np.zeros((len(q), 3))
        pts[:, :2] = q
        dist, tri, near = self._probe.distances(w.obj, pts)
        nseg = len(w.b) - 1
        if np.any((tri <= 0) | (tri >= nseg - 1)):
            bad = int(np.nonzero((tri <= 0) | (tri >= nseg - 1))[0][0])
            raise ValueError(
                f"disc {k}: point {p[bad].tolist()} (t0 = {t0[bad]:.6f} rad) lies nearest to the end of the "
                "tooth-space window; t0 must name the tooth space the point sits in")
        side = np.einsum("ij,ij->i", q - near[:, :2], w.facet[tri])
        sd = np.where(side < 0.0, -dist, dist)
        n_loc, _ = smooth_foot(w.b, w.n_start, w.n_end, q, tri)
        return sd, _rot2(n_loc, -turn)

    # ------------------------------------------------------------------ stage I
    def line_of_action(self, o1: np.ndarray, o2: np.ndarray, direction: int) -> np.ndarray:
        """Unit direction of the loaded line of action from the sun's flank to the planet's.

        The internal common tangent of the base circles, from its tangency point on the sun base
        circle ``o1 + rb1 u(tau1)`` to the one on the planet base circle ``o2 - rb2 u(tau1)``,
        ``tau1 = gamma - direction * alpha_w`` (``gamma`` the direction of o2 - o1,
        ``cos alpha_w = (rb1 + rb2) / |o2 - o1|``).

        Parameters
        ----------
        o1 : (..., 2) mm, sun centres
        o2 : (..., 2) mm, planet centres
        direction : int, +1 or -1

        Returns
        -------
        (..., 2) unit vectors
        """
        c = o2 - o1
        ad = np.linalg.norm(c, axis=-1)
        gam = np.arctan2(c[..., 1], c[..., 0])
        rb1, rb2 = self.geom.sun.base_radius, self.geom.planet.base_radius
        tau1 = gam - direction * np.arccos((rb1 + rb2) / ad)
        u = np.stack([np.cos(tau1), np.sin(tau1)], axis=-1)
        t1 = o1 + rb1 * u
        t2 = o2 - rb2 * u
        d = t2 - t1
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def stage1_gaps(self, theta_in: np.ndarray, theta_out: np.ndarray, psi: np.ndarray,
                    direction: int) -> np.ndarray:
        """Loaded-flank gap between the sun and each planet, along the line of action.

        Parameters
        ----------
        theta_in : (N,) rad
        theta_out : (N,) rad
        psi : (N, n_cranks) rad
        direction : int
            +1 (input angle increasing) or -1.

        Returns
        -------
        (N, n_cranks) mm
            Positive = clearance, negative = interference; the sign and meaning of
            ``ReducerGeometry.stage1_gaps``.
        """
        if direction not in (1, -1):
            raise ValueError(f"direction {direction!r} must be +1 or -1")
        g = self.geom
        th = np.atleast_1d(np.asarray(theta_in, dtype=np.float64))
        to = np.atleast_1d(np.asarray(theta_out, dtype=np.float64))
        ps = np.asarray(psi, dtype=np.float64).reshape(len(th), -1)
        o1 = g.sun_center(th)
        o2 = g.planet_centers(to, ps)
        n = self.line_of_action(o1[:, None, :], o2, direction)
        rot2 = np.degrees(ps + g.planet_tooth_phase[None])
        sun, planet = self._gear_objs[direction]
        out = np.empty(o2.shape[:2])
        for i in range(len(th)):
            sun.setTransform(collision.transform(math.degrees(th[i]), (o1[i, 0], o1[i, 1])))
            for j in range(o2.shape[1]):
                margin = self.stage1_margin_mm
                while True:
                    c = o2[i, j] + margin * n[i, j]
                    planet.setTransform(collision.transform(float(rot2[i, j]), (c[0], c[1])))
                    d = collision.distance(sun, planet).distance
                    if d > _TOUCH_MM:
                        out[i, j] = d - margin
                        break
                    margin *= 4.0
                    if margin > 0.5 * g.sun.base_pitch:
                        raise ValueError(
                            f"stage I meshes of crank {j} still interfere with the planet moved "
                            f"{margin / 4.0:.3f} mm along the line of action (theta_in = {th[i]:.6f} rad)")
        return out
