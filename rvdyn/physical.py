"""The physical law's side of the quasi-static solver (a mixin of :class:`rvdyn.solver.QuasiStaticSolver`).

Constants of the physical contact law (Johnson line contact at the pins with the local profile
curvature, ISO 6336-1 mesh stiffness, crank torsion in series with the mesh), the unit-load forces
``dF/dT``, the cam-bearing statics, the pin seats' wind-up and the peak Hertz pressure.
Derivations and sources: docs/physics.md, sections 7, 8 and 11.
"""
from __future__ import annotations

import math

import numpy as np

from rvdyn.bearings import Supports, pin_seat_contact
from rvdyn.contacts import ContactLaw, PhysicalLaw
from rvdyn.materials import (MATERIALS, LineContact, e_star, hertz_line_pressure, iso_mesh_stiffness,
                             iso_single_tooth_stiffness, transverse_contact_ratio)


class PhysicsMixin:
    """Methods of the solver that belong to the physical law (state lives on the solver)."""

    def _setup_physical(self, d, m) -> None:
        """Constants of the physical law: pin-disc materials, ISO 6336-1 mesh stiffness, supports."""
        pin, disc = MATERIALS["pin"], MATERIALS["cycloid_disc"]
        self.pin_mats = (pin, disc)
        self.pin_estar = e_star(pin, disc)
        self.face_width = d.disc_width_mm
        g = self.geom
        sun, pl = g.sun, g.planet
        aw = d.center_distance_mm
        alpha_w = math.acos((sun.base_radius + pl.base_radius) / aw)
        self.eps_alpha = transverse_contact_ratio(sun.tip_radius, sun.base_radius, pl.tip_radius, pl.base_radius,
                                                  aw, alpha_w, sun.base_pitch)
        self.c_single = iso_single_tooth_stiffness(d.z_sun, d.z_planet, sun.shift, pl.shift,
                                                   MATERIALS["sun_gear"].E, MATERIALS["planet_gear"].E,
                                                   pressure_angle_deg=d.pressure_angle_deg)
        self.c_gamma = iso_mesh_stiffness(self.c_single, self.eps_alpha)      # N/(mm um)
        self.k_mesh = self.c_gamma * 1e3 * d.gear_width_mm                     # N/mm along the line of action
        self.supports = None
        self.k_stage1 = self.k_mesh
        self.torsion_share = 0.0
        # pin-disc Johnson constant A, and the pin seat (groove) in series with it: same law form, A_1 + A_2
        # and C = (A_1 C_1 + A_2 C_2)/A (rvdyn.bearings; only with elastic supports)
        self.pin_A = 1.0 / (math.pi * self.pin_estar)
        self.seat = None
        if self.chain_on:
            self.seat = pin_seat_contact(d)
            self.pin_A = self.pin_A + self.seat.A
            self.supports = Supports.from_design(d)
            # crank torsion between planet and cams in series with the mesh, seen along the line of action
            k_t = 1.0 / (self.supports.torsion_compliance() * g.planet.base_radius ** 2)
            self.k_stage1 = 1.0 / (1.0 / self.k_mesh + 1.0 / k_t)
            self.torsion_share = self.k_stage1 / k_t                           # share of the stage I deflection
        self._C_last: np.ndarray | None = None
        self._R_last: np.ndarray | None = None
        self._R_all: np.ndarray | None = None
        self._nrm_last: np.ndarray | None = None

    def _line_C(self, k: int, pts: np.ndarray, t0: np.ndarray, r_pin: np.ndarray,
                t: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Johnson constant C and relative radius R (mm) of the pin contacts of disc k from the local
        radius of curvature of the disc boundary at the foot points ``t`` (signed: negative where concave;
        without ``t`` (a provider that gives no foot parameters) the foot points are found from ``t0``)."""
        prof = self.geom.profiles[k]
        if t is None or t.shape != t0.shape:
            t = prof.foot_point(pts, t0)
        kap = prof.curvature(t)
        with np.errstate(divide="ignore"):
            rho = 1.0 / kap - prof.pin_radius                                   # boundary radius, signed
        rho = np.where(np.abs(rho) > self.Rp, np.sign(rho + 1e-300) * self.Rp, rho)   # depth datum <= Rp
        # a concave boundary must be wider than the pin (conformal limit: relative radius <= 1e4 mm)
        rho = np.where((rho < 0) & (-rho < r_pin * (1.0 + 1e-4)), -r_pin * (1.0 + 1e-4), rho)
        R = 1.0 / (1.0 / r_pin + 1.0 / rho)
        disc = LineContact.of(r_pin, rho, *self.pin_mats, self.face_width)
        C = disc.C
        if self.seat is not None:                                               # the pin seat in series
            C = (disc.A * C + self.seat.A * self.seat.C) / self.pin_A
        return C, R


    # ------------------------------------------------------------------ state maps
    def _step_law(self, law: ContactLaw, C: np.ndarray | None):
        """The law of one linearisation: the physical law with the Johnson constants of its pin contacts."""
        if not law.physical:
            return law
        n1 = self.nd * self.zp
        return PhysicalLaw(LineContact(self.pin_A, C, self.face_width), n1, self.k_stage1)

    def _seat_parts(self, f: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Wind-up of the pin seats (N,) rad: ``sum f delta_seat`` over the pin contacts, with the seat's own
        approach ``delta_seat = A_s P (C_s - ln P)`` under each pin force F (N, n_pin) and f = dF/dT."""
        d = np.where(F > 0, self.seat.approach(np.where(F > 0, F, 1.0)), 0.0)
        return (f * d).sum(axis=1)

    def _pin_pressure(self, F: np.ndarray, law) -> np.ndarray:
        """Peak Hertzian pressure p0 = sqrt(P E*/(pi R)) of every pin contact (N, 2 Zp), MPa, with the
        relative radius R at the converged foot points (for either law: the force meets the real geometry)."""
        return hertz_line_pressure(F, self._R_all, self.pin_estar, self.face_width)

    def _unit_load_forces(self, law, delta: np.ndarray, direction: int, th: np.ndarray,
                          x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact forces per unit output torque, dF/dT (N, M) in N/(N mm), and the state's dx/dT (N, ndof)
        in mm/(N mm), at the solution.

        Equilibrium ``J^T F + g_sup = b`` with ``F = F(-(G + J x))`` and ``db/dT = direction e0 / Rp`` gives
        ``(J^T K J + H_sup) dx/dT = -db/dT`` and ``dF/dT = -K J dx/dT`` (K: contact stiffnesses, H_sup: the
        tangent stiffness of the supports inside the equilibrium). With the loads proportional to T this is
        F/T; with a preload (errors) it is the incremental load path the unit-load method needs
        (docs/physics.md, section 8)."""
        J = self._J_all
        nj = J.shape[-1]
        _, k = law.force_stiffness(delta)
        H = np.matmul(J.transpose(0, 2, 1) * k[:, None, :], J) + 1e-12 * np.eye(nj)[None]
        arms = self._hole_arms(th, x, law, exact=True) if self.float_discs else None
        if arms is not None:
            # the supports' exact tangent condensed onto the contacts' coordinates (option springs: their own)
            H += self._condensed(arms)[3] if self.chain is not None else self._bearing(x, arms)[2]
        db = np.zeros(nj)
        db[0] = direction / self.Rp
        dx = -np.linalg.solve(H, np.broadcast_to(db, (J.shape[0], nj))[..., None])[..., 0]
        f = -k * np.einsum("nmi,ni->nm", J, dx)
        if self.chain is not None:
            dx = np.concatenate([dx, self._chain_recover(arms, dx, tangent=True)], axis=1)
        return f, dx

    def disc_cam_forces(self, th, x, F, nrm) -> np.ndarray:
        """Cam-bearing forces on the discs (N, nd, nc, 2) that balance the contact forces F (N, M)."""
        n1 = self.nd * self.zp
        to, ps, _, _ = self._unpack(th, x)
        cen, _ = self._poses(th, x)                                             # (N, nd, 2)
        Fp = F[:, :n1].reshape(-1, self.nd, self.zp)
        fvec = -Fp[..., None] * nrm                                             # force of pin i on disc k
        F_disc = fvec.sum(axis=2)
        r = self.geom.pin_centers[None, None] - cen[:, :, None]
        M_disc = (r[..., 0] * fvec[..., 1] - r[..., 1] * fvec[..., 0]).sum(axis=2)
        cams = np.swapaxes(self.geom.cam_centers(to, ps), 1, 2)                # (N, nd, nc, 2)
        return Supports.cam_forces(F_disc, M_disc, cams - cen[:, :, None])
