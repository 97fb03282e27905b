"""The ``fcl`` contact provider: python-fcl distance queries on meshes of the exported geometry.

The analytic provider (:class:`rvdyn.contacts.AnalyticContacts`) is the exact reference; this
one answers the same two questions on triangle meshes built from the very samples that the
exported STL uses, so it checks the exported geometry end to end. Every call into FCL goes
through :mod:`rvdyn.collision` (the only module that imports ``fcl``).

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
* Normal. The outward normal is that of the exported outline with a smooth normal field: the
  exact profile normals and curvatures at the sample parameters (the vertices), interpolated
  along each chord by a cubic Hermite in the normal angle (:func:`smooth_foot`); the foot is
  where that normal points at the query point. A chord's own normal would be off by up to half
  the angle the chord subtends (about 6e-3 rad in the roots at the default sagitta, and a
  pin centre sits near the roots' centre of curvature, which amplifies any normal-field error
  some 40 times); the smooth field agrees with the exact normal to about 1.2e-5 rad (worst at
  the flank inflections), which the solver's Jacobian needs.
* Accuracy. The distance is the distance to the exported polygon (to 1e-12 mm): within the
  sagitta of the exact envelope (0.042 um at the default 0.05 um, the chord count being
  rounded up by 10 %). It is the global nearest distance; the analytic foot-point Newton from
  ``t0`` can stop at a local foot for points more than the roots' concave radius of curvature
  (3.071 mm by default) from the boundary, i.e. pins with more than about 70 um clearance.

Stage I (``stage1_gaps``)
-------------------------
Meshes of the loaded flanks only (the upper flanks ``InvoluteGear.flank_points`` of every tooth
for direction +1, their mirror images for -1), as fin strips, placed at the sun and planet
poses. The gap is measured along the line of action (the common tangent of the base circles,
which is the common normal of two involutes): the planet mesh is moved away from the sun by a
known margin along that line, FCL gives the mesh-mesh distance, and the margin is subtracted.
For two smooth flanks, a translation along their common normal keeps the same closest pair, so
the subtraction is exact; on the polygons it is exact to ``margin * angle**2 / 2``, ``angle``
being half the angle a chord subtends (below 0.001 um at the first margin). The margin starts
at 0.05 mm and grows when the moved meshes still touch, so interference of any realistic depth
is measured, not clipped at 0. The flanks are sampled at a quarter of the disc sagitta by
default: the chords of two convex flanks both lie inside the involutes and their sagittas add
to the gap (0.02 um here; the gears' export sagitta of 0.25 um would give up to 0.4 um).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rvcad.geometry import ReducerGeometry
from rvcad.profile import CycloidProfile, InvoluteGear
import rvdyn.collision as collision

#: Height of the fin strips above the profile plane, mm (any positive value gives the same
#: distances; the point queries sit at z = 0).
FIN_HEIGHT_MM = 1.0

#: Default flank sagitta = disc sagitta / this. Two convex flanks each sampled with chords
#: inside the involute add up to twice the chord sagitta to the gap; a quarter of the disc
#: sagitta keeps that below 0.025 um at the default (the 2.5e-4 mm export sagitta of the gears
#: would give up to 0.4 um).
FLANK_SAGITTA_DIVISOR = 4.0

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


@dataclass
class DiscWindow:
    """Mesh of one tooth-space window of a disc outline with its vertex normals and curvatures.

    Attributes
    ----------
    t : (n,) rad
        Sample parameters of the window vertices (exported samples of lobes -1 and 0 and the
        root of lobe 1).
    b : (n, 2) mm
        Window vertices, on the exact envelope.
    chords : (n - 1, 11) float64
        Per chord ``j`` (from ``b[j]`` to ``b[j + 1]``): start vertex (x, y), chord vector
        ``e`` (x, y), exact outward normal ``n0`` at the start (x, y), outward unit normal of
        the chord itself (x, y), and the cubic ``H(f) = f (s0 + f (a2 + f a3))`` of the normal
        angle along the chord (turn from ``n0``, rad) as ``s0, a2, a3``.
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
    chords: np.ndarray
    root_t: float
    pitch: float
    obj: object
    n_triangles: int

    @classmethod
    def build(cls, prof: CycloidProfile, sagitta: float) -> "DiscWindow":
        """Window of ``prof``'s exported outline sampled at ``sagitta`` (mm).

        The normal angle along chord ``j`` at fraction ``f`` is the cubic Hermite interpolant of
        the exact normals at its ends (a turn ``delta`` from start to end) with end slopes
        ``kappa (e . T)``: the exact boundary curvature at the end times the chord's projection
        on the end tangent, i.e. how fast the normal of the curve point whose normal line
        crosses the chord turns as the crossing runs along the chord. At a trimmed undercut
        corner (b(t1) = b(t2)) a chord takes the normal and curvature of the piece it lies on.
        """
        t_all = prof.boundary_t(sagitta)
        zc = prof.z_lobes
        n_per = len(t_all) // zc
        if n_per * zc != len(t_all):
            raise ValueError("boundary sampling is not identical for every lobe; the tooth-space window needs it")
        two_pi = 2.0 * math.pi
        t = np.concatenate([t_all[-n_per:] - two_pi, t_all[:n_per], t_all[n_per:n_per + 1]])
        b = prof.boundary(t)
        ts, te = t[:-1].copy(), t[1:].copy()
        trim = prof.trim_t
        pitch = two_pi / zc
        if trim is not None:
            t1, t2 = trim
            tip2 = 2.0 * prof.tip_t()
            eps = 1e-12
            for lobe in (-1, 0):
                sh = lobe * pitch
                ts[np.abs(ts - (t1 + sh)) < eps] = t2 + sh
                te[np.abs(te - (tip2 - t1 + sh)) < eps] = tip2 - t2 + sh

        def kappa(x: np.ndarray) -> np.ndarray:
            kq = prof.curvature(x)
            return kq / (1.0 - prof.pin_radius * kq)

        n0, n1 = prof.normal(ts), prof.normal(te)
        e = b[1:] - b[:-1]
        facet = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.linalg.norm(e, axis=1, keepdims=True)
        delta = np.arctan2(n0[:, 0] * n1[:, 1] - n0[:, 1] * n1[:, 0], np.einsum("ij,ij->i", n0, n1))
        # tangent in the direction of increasing t = normal turned by +90 deg
        s0 = kappa(ts) * (e[:, 1] * n0[:, 0] - e[:, 0] * n0[:, 1])
        s1 = kappa(te) * (e[:, 1] * n1[:, 0] - e[:, 0] * n1[:, 1])
        a2 = 3.0 * delta - 2.0 * s0 - s1
        a3 = s0 + s1 - 2.0 * delta
        chords = np.column_stack([b[:-1], e, n0, facet, s0, a2, a3])
        v, f = fin_mesh([b])
        obj = collision.obj(collision.bvh(v, f))
        return cls(t, b, np.ascontiguousarray(chords), prof.root_t(), pitch, obj, len(f))


def smooth_foot(w: DiscWindow, px: np.ndarray, py: np.ndarray, seg: np.ndarray,
                f0: np.ndarray | None = None, max_iter: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foot of points on the window outline under its smooth (Hermite) normal field.

    On chord ``j`` at fraction ``f`` the normal is ``n0`` turned by ``H(f)`` (see
    :meth:`DiscWindow.build`); the foot is where that normal points at the point:
    ``g(f) = cross(p - b_j - f e_j, N(f)) = 0``. Newton steps in ``f`` from ``f0`` on the
    nearest chord; a step that leaves [0, 1] moves to the neighbouring chord, carrying the
    overshoot over. ``g`` is almost linear in ``f`` (slope about ``|e| (1 - d kappa)``, curvature
    of order ``d H''``), so Newton converges quadratically; measured on the default discs the
    error left after a step of ``s`` mm is about ``1.2 s**2`` mm. The iteration stops once
    every step is below 5e-4 mm (foot within about 3e-7 mm, normal within about 1e-7 rad),
    usually after two steps from the nearest point of the polygon.

    Parameters
    ----------
    w : DiscWindow
    px, py : (K,) mm, points in the window frame
    seg : (K,) int, start chords (the nearest chord)
    f0 : (K,) start fractions on those chords (default 0.5)
    max_iter : int
        Newton steps at most (chord moves included).

    Returns
    -------
    nx, ny : (K,) unit normal at the foot
    chord : (K,) int, chord of the foot
    """
    C = w.chords
    last = len(C) - 1
    j = np.asarray(seg, dtype=np.int64)
    f = np.full(len(j), 0.5) if f0 is None else np.clip(f0, 0.0, 1.0)
    tol = 1e-9  # fraction of a chord a foot may lie beyond its end before moving on
    stop = 5e-4 / np.sqrt(C[j, 2] ** 2 + C[j, 3] ** 2)  # steps below 5e-4 mm end the iteration
    for _ in range(max_iter):
        S = C[j]
        ex, ey, n0x, n0y, s0, a2, a3 = S[:, 2], S[:, 3], S[:, 4], S[:, 5], S[:, 8], S[:, 9], S[:, 10]
        H = f * (s0 + f * (a2 + f * a3))
        dH = s0 + f * (2.0 * a2 + 3.0 * f * a3)
        ch, sh = np.cos(H), np.sin(H)
        nx = ch * n0x - sh * n0y
        ny = sh * n0x + ch * n0y
        rx = px - S[:, 0] - f * ex
        ry = py - S[:, 1] - f * ey
        df = (rx * ny - ry * nx) / (nx * ey - ny * ex + dH * (rx * nx + ry * ny))
        fn = f - df
        lo = (fn < -tol) & (j > 0)
        hi = (fn > 1.0 + tol) & (j < last)
        moved = lo | hi
        # on a move, carry the overshoot onto the neighbour (chords of similar length)
        f = np.minimum(np.maximum(fn + lo - hi, 0.0), 1.0)
        if not moved.any():
            if bool(np.all(np.abs(df) < stop)):
                break
        else:
            j = j - lo + hi
    S = C[j]
    H = f * (S[:, 8] + f * (S[:, 9] + f * S[:, 10]))
    ch, sh = np.cos(H), np.sin(H)
    return ch * S[:, 4] - sh * S[:, 5], sh * S[:, 4] + ch * S[:, 5], j


class FclContacts:
    """Contact provider on the exported meshes, answered by python-fcl distance queries.

    Parameters
    ----------
    geom : ReducerGeometry
        The case geometry (profiles, gears, placements).
    sagitta_mm : float
        Chord sagitta of the disc outline, mm (default 0.05 um, the project's
        ``Tolerances.sagitta_mm``): the disc mesh uses the samples of
        ``CycloidProfile.boundary_points(sagitta_mm)``.
    flank_sagitta_mm : float or None
        Chord sagitta of the involute flank samples ``InvoluteGear.flank_points(sagitta=...)``,
        mm; default ``sagitta_mm / 4``.

    Attributes
    ----------
    name : str
        ``"fcl"``.
    windows : list of DiscWindow
        One tooth-space window per disc.
    stage1_margin_mm : float
        First margin along the line of action for the stage I query, mm.
    gear_triangles : dict
        Triangles of the sun's and the planet's loaded-flank meshes (per direction; the mesh
        of direction -1 is built on its first query).
    """

    name = "fcl"

    def __init__(self, geom: ReducerGeometry, sagitta_mm: float = 5e-5,
                 flank_sagitta_mm: float | None = None) -> None:
        if flank_sagitta_mm is None:
            flank_sagitta_mm = sagitta_mm / FLANK_SAGITTA_DIVISOR
        for name, v in (("sagitta_mm", sagitta_mm), ("flank_sagitta_mm", flank_sagitta_mm)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} {v!r} must be a finite number > 0 (mm)")
        self.geom = geom
        self.sagitta_mm = float(sagitta_mm)
        self.flank_sagitta_mm = float(flank_sagitta_mm)
        self.windows = [DiscWindow.build(prof, self.sagitta_mm) for prof in geom.profiles]
        self._probe = collision.PointProbe()
        self.stage1_margin_mm = STAGE1_MARGIN_MM
        self._gear_objs: dict[int, tuple[object, object]] = {}
        self.gear_triangles: dict[str, int] = {}
        self._gear_meshes(1)

    # ------------------------------------------------------------------ meshes
    def _gear_meshes(self, direction: int) -> tuple[object, object]:
        """Sun and planet loaded-flank objects of one drive direction (built on first use)."""
        objs = self._gear_objs.get(direction)
        if objs is None:
            sun_v, sun_f = fin_mesh(self._loaded_flanks(self.geom.sun, direction))
            pl_v, pl_f = fin_mesh(self._loaded_flanks(self.geom.planet, direction))
            objs = (collision.obj(collision.bvh(sun_v, sun_f)), collision.obj(collision.bvh(pl_v, pl_f)))
            self._gear_objs[direction] = objs
            self.gear_triangles = {"sun": len(sun_f), "planet": len(pl_f)}
        return objs

    def _loaded_flanks(self, gear: InvoluteGear, direction: int) -> list[np.ndarray]:
        """Loaded flank of every tooth in the gear frame (tooth 0 centred on +x), mm.

        Direction +1 loads the upper flanks (facing +theta) of both gears, -1 the lower flanks.
        """
        up = gear.flank_points(sagitta=self.flank_sagitta_mm)
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
        K = len(p)
        if len(t0) != K:
            raise ValueError(f"p has {K} points but t0 has {len(t0)} parameters")
        if K == 0:
            return np.empty(0), np.empty((0, 2))
        turn = np.rint((t0 - w.root_t) / w.pitch) * w.pitch  # the window is turned by this
        c, s = np.cos(turn), np.sin(turn)
        pts = np.zeros((K, 3))
        qx = c * p[:, 0] + s * p[:, 1]
        qy = c * p[:, 1] - s * p[:, 0]
        pts[:, 0] = qx
        pts[:, 1] = qy
        dist, tri, near = self._probe.distances(w.obj, pts)
        nseg = len(w.chords)
        bad = (tri <= 0) | (tri >= nseg - 1)
        if bad.any():
            i = int(np.nonzero(bad)[0][0])
            raise ValueError(
                f"disc {k}: point {p[i].tolist()} (t0 = {t0[i]:.6f} rad) lies nearest to the end of the "
                "tooth-space window; t0 must name the tooth space the point sits in")
        S = w.chords[tri]
        side = (qx - near[:, 0]) * S[:, 6] + (qy - near[:, 1]) * S[:, 7]
        sd = np.where(side < 0.0, -dist, dist)
        f0 = ((near[:, 0] - S[:, 0]) * S[:, 2] + (near[:, 1] - S[:, 1]) * S[:, 3]) / (S[:, 2] ** 2 + S[:, 3] ** 2)
        nx, ny, _ = smooth_foot(w, qx, qy, tri, f0)
        n = np.empty((K, 2))
        n[:, 0] = c * nx - s * ny
        n[:, 1] = s * nx + c * ny
        return sd, n

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
        sun, planet = self._gear_meshes(direction)
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
