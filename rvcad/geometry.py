"""The error-perturbed reducer as numbers: part placements and kinematics, plain numpy.

:class:`ReducerGeometry` resolves a :class:`~rvcad.errors.Case` into the perturbed positions
of every feature (pins, holes, cams, gear centres) and places the moving parts for any state
``(theta_in, theta_out, psi_0, ..., psi_(n-1))``. The CAD parts (:mod:`rvcad.parts`) and the contact
analysis (:mod:`rvdyn`) both read their geometry from here: the exported geometry is the
analysed geometry.

Frames (conventions.md): fixed frame, right-handed about +z. The carrier turns by
``theta_out``; crank j sits at ``(a + F_j) u(beta_j)`` in the carrier frame, turns by the
absolute angle ``psi_j`` and carries the cam of disc k at eccentricity ``e + E_jk`` and phase
``psi_j + k pi + D_jk / e``. Disc k hangs on the cams of all n cranks (two by default, three on the
larger frames): its pose is the rigid least-squares fit of its n crank holes to the n cam centres (equal
bearing stiffness; the mismatch of holes and cams, one distance for two cranks, 2n - 3 for n, is taken up in
the bearings). Lengths in mm, angles in rad inside.
"""
from __future__ import annotations

import math

import numpy as np

from rvcad.errors import Case, ResolvedErrors
from rvcad.params import PLANET_SHIFT, SUN_SHIFT, Design  # noqa: F401  (shifts re-exported)
from rvcad.profile import CycloidProfile, InvoluteGear, modified_profile_parameters


def rot(a: np.ndarray) -> np.ndarray:
    """Rotation matrices for angles a (...,) -> (..., 2, 2)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.empty(a.shape + (2, 2))
    R[..., 0, 0] = c
    R[..., 0, 1] = -s
    R[..., 1, 0] = s
    R[..., 1, 1] = c
    return R


def _apply(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...ij,...j->...i", R, v)


def _turn(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v (..., 2) turned by the angles a (broadcast against v[..., 0]): ``_apply(rot(a), v)`` without the
    matrices (the same products and sums, c x - s y and s x + c y, so the same numbers)."""
    c, s = np.cos(a), np.sin(a)
    vx, vy = v[..., 0], v[..., 1]
    out = np.empty(np.broadcast_shapes(np.shape(c), vx.shape) + (2,))
    out[..., 0] = c * vx - s * vy
    out[..., 1] = s * vx + c * vy
    return out


def _u(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    out = np.empty(a.shape + (2,))
    out[..., 0] = np.cos(a)
    out[..., 1] = np.sin(a)
    return out


def procrustes_angle(H: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Rotation (rad) of the rigid least-squares fit of point sets H (..., n, 2) onto C (..., n, 2) (broadcast over
    the leading axes): with both taken about their means, ``atan2(sum h x c, sum h . c)`` (the planar Kabsch fit;
    minimises ``sum |R h + t - c|^2`` over the rotation R and the translation t)."""
    h = H - H.mean(axis=-2, keepdims=True)
    c = C - C.mean(axis=-2, keepdims=True)
    cross = (h[..., 0] * c[..., 1] - h[..., 1] * c[..., 0]).sum(axis=-1)
    dot = (h[..., 0] * c[..., 0] + h[..., 1] * c[..., 1]).sum(axis=-1)
    return np.arctan2(cross, dot)


class ReducerGeometry:
    """Perturbed geometry and kinematics of one case.

    Parameters
    ----------
    case : Case or None
        Case with errors (``None``: nominal design, no errors).

    Attributes
    ----------
    design : Design
    errors : ResolvedErrors
    profiles : list of CycloidProfile
        Disc k's profile in its own frame (cam phase k*pi), cut for the design pin radius.
    disc_profile_rotation : (n_discs,) rad
        Profile turned relative to the crank holes (error K).
    sun, planet : InvoluteGear
    pin_angles_nominal : (Zp,) rad
    pin_centers : (Zp, 2) mm, fixed frame
    pin_radii : (Zp,) mm
    carrier_holes : (n_cranks, 2) mm, carrier frame
    disc_holes : (n_discs, n_cranks, 2) mm, disc frame
    cam_ecc : (n_cranks, n_discs) mm
    cam_phase : (n_cranks, n_discs) rad (includes k*pi)
    sun_offset : (2,) mm, sun frame
    planet_offsets : (n_cranks, 2) mm, planet frame
    planet_tooth_phase : (n_cranks,) rad
        Rotation of planet j's teeth relative to its crank frame so that it meshes at zero state.
    """

    def __init__(self, case: Case | None = None) -> None:
        case = case if case is not None else Case()
        self.case = case
        d: Design = case.design
        self.design = d
        er = ResolvedErrors(case)
        self.errors = er
        zp, nc, nd = d.z_pins, d.n_cranks, d.n_discs
        rp = d.pin_circle_radius_mm
        rp_gen, r_gen, rot_mod = modified_profile_parameters(d)   # profile modification (0 by default)
        self.profiles = [CycloidProfile(rp_gen, d.eccentricity_mm, zp, r_gen, cam_phase=k * math.pi)
                         for k in range(nd)]
        self.disc_profile_rotation = er.disc_phase.copy() + rot_mod
        alpha = math.radians(d.pressure_angle_deg)
        share = d.stage1_backlash_mm
        self.sun = InvoluteGear(d.z_sun, d.module_mm, alpha, SUN_SHIFT, 0.0)
        self.planet = InvoluteGear(d.z_planet, d.module_mm, alpha, PLANET_SHIFT, share)
        self.pin_angles_nominal = 2.0 * np.pi * np.arange(zp) / zp
        ang = self.pin_angles_nominal + er.pin_pitch
        self.pin_centers = (rp + er.pin_radial)[:, None] * _u(ang) + er.pin_circle_offset
        self.pin_radii = d.pin_radius_mm + er.pin_radius
        beta = np.array(d.crank_angles_rad)
        self.crank_angles = beta
        a = d.center_distance_mm
        self.carrier_holes = (a + er.carrier_hole)[:, None] * _u(beta) + er.carrier_offset
        self.disc_holes = (a + er.disc_hole)[:, :, None] * _u(beta)[None, :, :]
        self.cam_ecc = d.eccentricity_mm + er.cam_ecc
        self.cam_phase = np.arange(nd)[None, :] * math.pi + er.cam_phase
        self.sun_offset = er.sun_offset.copy()
        self.planet_offsets = er.planet_offset.copy()
        self.planet_tooth_phase = np.array([self._planet_phase(b) for b in beta])
        # tooth pairing of each flank at assembly: the whole base pitches between the flank pair that
        # is loaded for each direction and the pair the formula measures (0 for +1 by construction)
        self._pairing = {1: np.zeros(nc), -1: np.zeros(nc)}
        z0 = np.zeros(1)
        to0, ps0 = self.ideal_state(z0)
        for d_ in (1, -1):
            g0 = self.stage1_gaps(z0, to0, ps0, d_)[0]
            self._pairing[d_] = self.sun.base_pitch * np.round(g0 / self.sun.base_pitch)

    # ------------------------------------------------------------------ kinematics
    @property
    def ratio(self) -> float:
        return self.design.ratio

    def ideal_state(self, theta_in: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal output and crank angles for input angles (rad).

        Returns
        -------
        theta_out : (N,) rad, ``theta_in / ratio``
        psi : (N, n_cranks) rad, ``-(theta_in - theta_out) Z1/Z2 + theta_out``
        """
        th = np.atleast_1d(np.asarray(theta_in, dtype=float))
        d = self.design
        out = th / self.ratio
        psi = -(th - out) * d.z_sun / d.z_planet + out
        return out, np.repeat(psi[:, None], d.n_cranks, axis=1)

    def crank_axes(self, theta_out: np.ndarray) -> np.ndarray:
        """Crank axis positions in the fixed frame, (N, n_cranks, 2) mm."""
        return _turn(np.atleast_1d(np.asarray(theta_out, dtype=float))[:, None], self.carrier_holes[None])

    def cam_centers(self, theta_out: np.ndarray, psi: np.ndarray) -> np.ndarray:
        """Cam centres (N, n_cranks, n_discs, 2), mm, fixed frame."""
        axes = self.crank_axes(theta_out)
        ph = np.asarray(psi)[:, :, None] + self.cam_phase[None]
        return axes[:, :, None, :] + self.cam_ecc[None, :, :, None] * _u(ph)

    def disc_poses(self, theta_out: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pose of each disc: centre (N, n_discs, 2) mm and rotation (N, n_discs) rad.

        Rigid least-squares fit of the disc's crank holes to its cam centres (equal, isotropic bearings: the pose
        that minimises the sum of the squared hole-cam offsets). Two cranks: the rotation is the angle between the
        hole line and the cam line. Three or more (docs/physics.md, section 3): with the holes ``h_j`` and cams
        ``c_j`` taken about their means, the rotation is ``atan2(sum h_j x c_j, sum h_j . c_j)`` (the planar
        Procrustes / Kabsch fit), the same angle for two. Either way the centre is the mean of the cams minus the
        rotated mean of the holes.
        """
        C = self.cam_centers(theta_out, psi)  # (N, nc, nd, 2)
        C = np.swapaxes(C, 1, 2)  # (N, nd, nc, 2)
        H = self.disc_holes  # (nd, nc, 2)
        if C.shape[2] == 2:
            dc = C[:, :, 1] - C[:, :, 0]
            dh = H[:, 1] - H[:, 0]
            ang = np.arctan2(dc[..., 1], dc[..., 0]) - np.arctan2(dh[..., 1], dh[..., 0])[None]
        else:
            ang = procrustes_angle(H, C)
        theta_out = np.atleast_1d(theta_out)
        ang = theta_out[:, None] + (np.mod(ang - theta_out[:, None] + np.pi, 2 * np.pi) - np.pi)
        mid = (C[:, :, 0] + C[:, :, 1]) / 2.0 if C.shape[2] == 2 else C.mean(axis=2)  # as np.mean forms it
        cen = mid - _turn(ang, H.mean(axis=1)[None])
        return cen, ang

    def pins_in_profile_frames(self, theta_out: np.ndarray, psi: np.ndarray,
                               disc_shift: np.ndarray | None = None,
                               disc_turn: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Pin centres in each disc's profile frame and the ideal-motion curve parameter.

        Parameters
        ----------
        theta_out : (N,) rad
        psi : (N, n_cranks) rad
        disc_shift : (N, n_discs, 2) mm, optional
            Extra translation of each disc relative to its cam fit (bearing clearance float).
        disc_turn : (N, n_discs) rad, optional
            Extra rotation of each disc relative to its cam fit.

        Returns
        -------
        p : (N, n_discs, Zp, 2) mm
        t0 : (N, n_discs, Zp) rad, the parameter of the pin-centre curve the pin sits at under
            the ideal motion (``phi_i - disc rotation - profile rotation``): a start for the
            foot-point search.
        """
        cen, ang = self.disc_poses(theta_out, psi)
        if disc_shift is not None:
            cen = cen + disc_shift
        if disc_turn is not None:
            ang = ang + disc_turn
        full = ang + self.disc_profile_rotation[None]
        Rinv = rot(-full)[:, :, None]  # (N, nd, 1, 2, 2)
        rel = self.pin_centers[None, None] - cen[:, :, None, :]
        p = _apply(Rinv, rel)
        t0 = self.pin_angles_nominal[None, None] - full[:, :, None]
        return p, t0

    def pin_gaps(self, theta_out: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Exact signed gaps of every pin to every disc (analytic envelope distance).

        Returns
        -------
        gap : (N, n_discs, Zp) mm, positive = clearance
        normal : (N, n_discs, Zp, 2) outward normal of the disc at the foot point, profile frame
        p : (N, n_discs, Zp, 2) pin centres in the profile frames, mm
        t : (N, n_discs, Zp) foot parameters, rad
        """
        p, t0 = self.pins_in_profile_frames(theta_out, psi)
        gap = np.empty(p.shape[:-1])
        nrm = np.empty(p.shape)
        tf = np.empty(p.shape[:-1])
        for k, prof in enumerate(self.profiles):
            bd, t, n = prof.boundary_distance(p[:, k].reshape(-1, 2), t0[:, k].ravel())
            gap[:, k] = bd.reshape(p.shape[0], -1) - self.pin_radii[None]
            nrm[:, k] = n.reshape(p.shape[0], -1, 2)
            tf[:, k] = t.reshape(p.shape[0], -1)
        return gap, nrm, p, tf

    # ------------------------------------------------------------------ stage I
    def sun_center(self, theta_in: np.ndarray) -> np.ndarray:
        """Sun gear centre (N, 2), mm: the eccentricity turns with the sun."""
        return _turn(np.atleast_1d(np.asarray(theta_in, dtype=float))[:, None], self.sun_offset[None])[:, 0]

    def planet_centers(self, theta_out: np.ndarray, psi: np.ndarray) -> np.ndarray:
        """Planet gear centres (N, n_cranks, 2), mm: crank axis plus the offset turning with the crank."""
        return self.crank_axes(theta_out) + _turn(np.asarray(psi, dtype=float), self.planet_offsets[None])

    def _line_of_action(self, o1: np.ndarray, o2: np.ndarray, direction: int,
                        gamma_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c = o2 - o1
        ad = np.sqrt(c[..., 0] * c[..., 0] + c[..., 1] * c[..., 1])   # |c| (the sum np.linalg.norm forms)
        raw = np.arctan2(c[..., 1], c[..., 0])
        # unwrap the centre-line angle next to its nominal value (carrier angle + crank position), so
        # that the gap is continuous in every coordinate and no tooth pair is ever skipped
        gam = gamma_ref + np.mod(raw - gamma_ref + np.pi, 2.0 * np.pi) - np.pi
        rb1, rb2 = self.sun.base_radius, self.planet.base_radius
        alpha_w = np.arccos((rb1 + rb2) / ad)
        tau1 = gam - direction * alpha_w
        return ad * np.sin(alpha_w), tau1, tau1 + np.pi

    def stage1_gaps_both(self, theta_in: np.ndarray, theta_out: np.ndarray,
                         psi: np.ndarray) -> dict[int, np.ndarray]:
        """:meth:`stage1_gaps` of both flanks, ``{1: ..., -1: ...}`` (N, n_cranks) mm, from one evaluation of
        the gear centres (the same numbers as two calls)."""
        th_in = np.atleast_1d(theta_in)
        centres = (self.sun_center(th_in)[:, None, :], self.planet_centers(theta_out, psi))
        return {d: self.stage1_gaps(th_in, theta_out, psi, d, centres) for d in (1, -1)}

    def stage1_gaps(self, theta_in: np.ndarray, theta_out: np.ndarray, psi: np.ndarray,
                    direction: int, _centres: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Gap of the loaded flank pair between the sun and each planet, along the line of action.

        Exact for involute flanks (contact inside the active line): with base radii rb1, rb2,
        operating pressure angle alpha_w = arccos((rb1 + rb2)/a_w) and tangency angles tau1 =
        gamma -/+ alpha_w, tau2 = tau1 + pi,

            g(+1) = a_w sin(alpha_w) - rb1 (xi1 + phi1 - tau1) - rb2 (xi2 + phi2 - tau2)
            g(-1) = a_w sin(alpha_w) - rb1 (tau1 + xi1 - phi1) - rb2 (tau2 + xi2 - phi2)

        with gamma unwrapped next to the carrier angle plus the crank position (xi: flank origins,
        phi: gear rotations, unwrapped; derivation in docs/physics.md). Under the ideal motion the
        expression is constant (zero), so no modulo is taken: the tooth pairing set at assembly is
        kept and a state that would skip a tooth shows as the interference it is.

        Returns
        -------
        (N, n_cranks) mm
        """
        th_in = np.atleast_1d(theta_in)
        if _centres is None:
            o1 = self.sun_center(th_in)[:, None, :]
            o2 = self.planet_centers(theta_out, psi)
        else:
            o1, o2 = _centres
        gamma_ref = np.atleast_1d(np.asarray(theta_out, dtype=float))[:, None] + self.crank_angles[None]
        L, tau1, tau2 = self._line_of_action(o1, o2, direction, gamma_ref)
        rb1, rb2 = self.sun.base_radius, self.planet.base_radius
        x1, x2 = self.sun.flank_origin, self.planet.flank_origin
        phi1 = th_in[:, None]
        phi2 = np.asarray(psi) + self.planet_tooth_phase[None]
        if direction == 1:
            g = L - rb1 * (x1 + phi1 - tau1) - rb2 * (x2 + phi2 - tau2)
        else:
            g = L - rb1 * (tau1 + x1 - phi1) - rb2 * (tau2 + x2 - phi2)
        pairing = getattr(self, "_pairing", None)
        return g if pairing is None else g - pairing[direction][None]

    def _planet_phase(self, beta: float) -> float:
        """Planet tooth phase that makes the +1 flank gap zero at the zero state."""
        rb1, rb2 = self.sun.base_radius, self.planet.base_radius
        a = self.design.center_distance_mm
        aw = math.acos((rb1 + rb2) / a)
        L = a * math.sin(aw)
        tau1 = beta - aw
        tau2 = tau1 + math.pi
        return (L - rb1 * (self.sun.flank_origin - tau1)) / rb2 - self.planet.flank_origin + tau2

    # ------------------------------------------------------------------ placement
    def placement(self, theta_in: float, theta_out: float | None = None,
                  psi: tuple[float, ...] | None = None) -> dict[str, tuple[float, float, float]]:
        """Planar placement ``(x mm, y mm, rotation deg)`` of every moving part at one state.

        Default state: the ideal kinematics at ``theta_in`` (rad). Keys: ``sun``, ``carrier``,
        ``crank{j}``, ``planet{j}``, ``disc{k}`` (rotation of the disc's crank-hole frame; the
        profile is turned by ``disc_profile_rotation`` within it); pins and housing are fixed.
        """
        to, ps = self.ideal_state(np.array([theta_in]))
        if theta_out is not None:
            to = np.array([theta_out])
        if psi is not None:
            ps = np.array([psi], dtype=float)
        out: dict[str, tuple[float, float, float]] = {}
        sc = self.sun_center(np.array([theta_in]))[0]
        out["sun"] = (float(sc[0]), float(sc[1]), math.degrees(theta_in))
        out["carrier"] = (0.0, 0.0, math.degrees(float(to[0])))
        axes = self.crank_axes(to)[0]
        pc = self.planet_centers(to, ps)[0]
        for j in range(self.design.n_cranks):
            out[f"crank{j}"] = (float(axes[j, 0]), float(axes[j, 1]), math.degrees(float(ps[0, j])))
            out[f"planet{j}"] = (float(pc[j, 0]), float(pc[j, 1]),
                                 math.degrees(float(ps[0, j] + self.planet_tooth_phase[j])))
        cen, ang = self.disc_poses(to, ps)
        for k in range(self.design.n_discs):
            out[f"disc{k}"] = (float(cen[0, k, 0]), float(cen[0, k, 1]), math.degrees(float(ang[0, k])))
        return out
