"""The adjoint of the transmission error at converged states of the quasi-static solver, and the first-order
change of the equilibrium's gradient for a nearby case: the machinery of :func:`rvdyn.implicit.te_jacobian`
(docs/physics.md, "Implicit differentiation of the equilibrium").

At a row's converged state ``x*`` the potential's gradient vanishes, ``F(x*, p) = 0``; along ``p = base + t delta``
``dx*/dt = -H^-1 dF/dt`` with ``H = dF/dx``, and ``TE = x_0 / Rp - direction T c`` (c the lumped compliance, T the
resisting torque with the friction torque). With the adjoint ``lambda = H^-T e_0 / Rp`` (one per row, whatever the
number of directions) ``dTE/dt = -lambda . dF/dt`` plus the derivative of ``-direction T c``.

Every force element is a law of a geometric measure ``y`` (a pin's or a flank's approach, a cam bearing's
deflection) entering ``F`` through rows ``Y`` (``Y^T dE/dy``). Its law is linearised at ``x*`` (forces and
stiffnesses there, and the pins' Johnson constants through their derivative) and only the geometry is differenced:
the differences are then the exact tangent's and smooth, where those of the laws change with the step wherever a
contact opens or closes within it. The pin contacts act through the disc poses ``pi`` (centre, profile angle):
``F_pin = Pi_x^T phi(pi)``; ``dphi/dpi`` from differences over the poses, and a pin's error moving its own two
contacts only, all pins' derivatives (centre x, y, radius) from six evaluations that move every pin at once.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvdyn.contacts import AnalyticContacts, ContactLaw
from rvdyn.results import ARCSEC_PER_RAD
from rvdyn.solver import QuasiStaticSolver

#: Step (mm) of the differences over the disc poses (the angle: this over the pin circle radius) and the pins.
POSE_STEP_MM = 1e-5
#: Step (mm of scaled state) of the differences over the state. The stage I gaps carry the input angle (760 rad
#: over an output revolution), so a rounding of 5e-13 mm: this step keeps the curvature terms within 1e-5.
STATE_STEP_MM = 1e-4
#: Singular values of H below this fraction of its largest are a free body's (a disc that carries nothing): the
#: derivatives leave it where it is. Loaded parts' stiffnesses are above 1e-5 of the largest.
PINV_RCOND = 1e-9
#: States whose Newton step moves the TE by more than this (arcsec) are not the base's converged states.
STATIONARY_ARCSEC = 0.01


def solver_for(case: Case, law: ContactLaw | None, geom: ReducerGeometry | None = None) -> QuasiStaticSolver:
    """The solver of a case as :func:`rvdyn.te.run_te_many` builds it, the supports' Newton model at the exact
    tangent."""
    g = ReducerGeometry(case) if geom is None else geom
    s = QuasiStaticSolver(g, AnalyticContacts(g, per_point=True), law)
    s.newton_load(np.zeros((1, s.ndof)), False)
    return s


def _pose(s: QuasiStaticSolver, th: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Disc poses (N, nd, 3) at the states: centre (mm) and the profile's angle (rad, with its rotation)."""
    cen, ang = s._poses(th, x)
    return np.concatenate([cen, (ang + s.geom.disc_profile_rotation[None])[..., None]], axis=-1)


def _pose_derivs(s: QuasiStaticSolver, th: np.ndarray, x: np.ndarray):
    """Poses (N, nd, 3) at the states, their derivatives over the contacts' coordinates (N, nd, 3, nj) and second
    derivatives over the kinematic ones (N, nd, 3, nk, nk) (the discs' floats enter linearly), by differences."""
    N, D, nk, h = x.shape[0], x.shape[1], 1 + s.nc, STATE_STEP_MM
    E = h * np.eye(D)[:nk]
    pairs = [(i, j) for i in range(nk) for j in range(i, nk)]
    offs = [np.zeros(D)] + [sg * e for e in E for sg in (1, -1)]
    offs += [a * E[i] + b * E[j] for i, j in pairs for a, b in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
    P = _pose(s, np.tile(th, len(offs)), (x[None] + np.asarray(offs)[:, None]).reshape(-1, D))
    P = P.reshape(len(offs), N, s.nd, 3)
    Px = np.zeros((N, s.nd, 3, s.nj))
    for i in range(nk):
        Px[..., i] = (P[1 + 2 * i] - P[2 + 2 * i]) / (2.0 * h)
    if s.float_discs:
        for k in range(s.nd):
            b = 1 + s.nc + 3 * k
            Px[:, k, 0, b] = Px[:, k, 1, b + 1] = 1.0
            Px[:, k, 2, b + 2] = 1.0 / s.a
    Pxx = np.empty((N, s.nd, 3, nk, nk))
    for m, (i, j) in enumerate(pairs):
        pp, pm, mp, mm = P[1 + 2 * nk + 4 * m:5 + 2 * nk + 4 * m]
        Pxx[..., i, j] = Pxx[..., j, i] = (pp - pm - mp + mm) / (4.0 * h * h)
    return P[0], Px, Pxx


def _pin_contacts(s: QuasiStaticSolver, pose: np.ndarray, pins: np.ndarray, radii: np.ndarray,
                  start: np.ndarray) -> tuple[np.ndarray, ...]:
    """The pin contacts at the disc poses (the solver's ``_pin_gaps``): gaps (N, nd, Zp) mm, their derivatives over
    the poses (N, nd, Zp, 3), the foot parameters and, with the physical law, the Johnson constants (else None)."""
    N, nd, zp = pose.shape[0], pose.shape[1], pins.shape[0]
    c, sn = np.cos(pose[..., 2])[..., None], np.sin(pose[..., 2])[..., None]
    rx, ry = pins[None, None, :, 0] - pose[..., 0, None], pins[None, None, :, 1] - pose[..., 1, None]
    p = np.stack([c * rx + sn * ry, -sn * rx + c * ry], axis=-1)
    gap, feet, nrm = np.empty((N, nd, zp)), np.empty((N, nd, zp)), np.empty((N, nd, zp, 2))
    for k in range(nd):
        d, t, n = s.geom.profiles[k].boundary_distance(p[:, k].reshape(-1, 2), start[:, k].ravel(), True)
        gap[:, k], feet[:, k], nrm[:, k] = d.reshape(N, zp) - radii[None], t.reshape(N, zp), n.reshape(N, zp, 2)
    nx, ny = nrm[..., 0], nrm[..., 1]
    dg = np.stack([-(nx * c - ny * sn), -(nx * sn + ny * c), nx * p[..., 1] - ny * p[..., 0]], axis=-1)
    C = None
    if s.law.physical:
        r = np.broadcast_to(radii[None], (N, zp)).ravel()
        C = np.stack([s._line_C(k, p[:, k].reshape(-1, 2), feet[:, k].ravel(), r, feet[:, k].ravel())[0]
                      .reshape(N, zp) for k in range(nd)], axis=1)
    return gap, dg, feet, C


def _measures(s: QuasiStaticSolver, base: "TEAdjoint", X: np.ndarray, reps: int) -> dict[str, np.ndarray]:
    """The stage I approaches ``s1`` (reps N, 2 nc) and the chain's cam-bearing deflections ``cam`` (reps N,
    nd nc, 2; hole minus cam minus the crank's displacement) at ``reps`` stacked copies X of the rows' states."""
    th = np.tile(base.th, reps)
    to, ps, _, _ = s._unpack(th, X)
    out = {"s1": -s._flanks({d: s.geom.stage1_gaps(th, to, ps, d) for d in (1, -1)}, np.tile(base.dirs, reps))}
    if s.chain is not None:
        d = s._hole_offsets(th, X) - np.einsum("kjad,nd->nkja", s._Y, X)
        out["cam"] = d.reshape(X.shape[0], -1, 2)
    return out


def _rest_parts(s: QuasiStaticSolver, base: "TEAdjoint", x: np.ndarray) -> dict[str, Any]:
    """The elements outside the pins at the states x as ``(y, Y)``: the stage I approaches (``s1``: (N, 2 nc) and
    rows (N, 2 nc, ndof)) and the cam bearings (``cam``: (N, nd nc, 2) and (N, nd nc, 2, ndof)); ``own``: the
    gradient of the supports' own energy (journals, bending, carrier); their laws at x (``s1_law``, ``cam_law``:
    dE/dy and d2E/dy2), the load vector (``load``) and the supports' exact tangent (``H_sup``, N, ndof, ndof)."""
    N, D = x.shape
    g1, J1 = s._stage1_linear(base.th, x, base.dirs)
    Y1 = np.zeros((N, g1.shape[1], D))
    Y1[..., :s.nj] = -J1
    out: dict[str, Any] = {"s1": (-g1, Y1), "own": np.zeros((N, D)), "load": np.zeros((N, D))}
    out["load"][:, 0] = base.dirs * (base.L * 1e3 + s.friction_Nmm) / s.Rp
    n1 = s.nd * s.zp
    delta = np.zeros((N, n1 + g1.shape[1]))
    delta[:, n1:] = -g1
    out["s1_law"] = tuple(v[:, n1:] for v in s._step_law(s.law, base.law_C).force_stiffness(delta))
    arms = s._hole_arms(base.th, x, base.law)
    if s.chain is not None:
        _, dcam, Dm, tang = s._chain_unpack(x, arms)
        _, g, _, gc, Hc, _, _ = s.chain.energy(x, dcam, False, True, 0.0, tang)
        out["own"][:, s.chain.base:] = g
        out["cam"] = (dcam.reshape(N, -1, 2), Dm.reshape(N, -1, 2, D))
        out["cam_law"] = (gc.reshape(N, -1, 2), Hc.reshape(N, -1, 2, 2))
        out["H_sup"] = s._bearing(x, arms)[2]
    elif arms is not None:
        out["cam"] = _spring_geometry(s, x, arms)
        out["cam_law"] = _spring_law(s, out["cam"][0])
        R = out["cam"][1]
        out["H_sup"] = np.einsum("nhad,nhab,nhbe->nde", R, out["cam_law"][1], R)
    return out


def _spring_geometry(s: QuasiStaticSolver, x: np.ndarray, arms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The option springs' hole floats (N, nd nc, 2) (disc shift plus turn times the hole's arm) and their rows in
    the gradient (N, nd nc, 2, ndof) (the solver's ``_bearing``: the discs' floats, the arms frozen at x)."""
    N, nd, nc, D = x.shape[0], s.nd, s.nc, x.shape[1]
    blk = x[:, 1 + nc:1 + nc + 3 * nd].reshape(N, nd, 1, 3)
    perp = np.stack([-arms[..., 1], arms[..., 0]], axis=-1)
    R = np.zeros((N, nd, nc, 2, D))
    for k in range(nd):
        b = 1 + nc + 3 * k
        R[:, k, :, 0, b] = R[:, k, :, 1, b + 1] = 1.0
        R[:, k, :, :, b + 2] = perp[:, k]
    return (blk[..., :2] + blk[..., 2:3] * perp).reshape(N, -1, 2), R.reshape(N, -1, 2, D)


def _spring_law(s: QuasiStaticSolver, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Force (N, H, 2) and exact Hessian (N, H, 2, 2) of the springs ``k (|y| - c)_+^2 / 2``."""
    r = np.maximum(np.linalg.norm(y, axis=-1), 1e-300)
    over = np.maximum(r - s.clearance, 0.0)
    u = y / r[..., None]
    uu = u[..., :, None] * u[..., None, :]
    K = s._spring_k * ((over > 0)[..., None, None] * uu + (over / r)[..., None, None] * (np.eye(2) - uu))
    return (s._spring_k * over)[..., None] * u, K


def _rest_gradient(parts: dict[str, Any], frozen: dict[str, Any] | None = None) -> np.ndarray:
    """The gradient (N, ndof) of the elements outside the pins, ``sum Y^T dE/dy`` with the supports' own and the
    load; with ``frozen`` (the parts at the base states) each law linearised there, ``dE/dy* + d2E/dy2* (y - y*)``."""
    ref = parts if frozen is None else frozen
    F = parts["own"] + ref["load"]
    for key in ("s1", "cam"):
        if key not in parts:
            continue
        (y, Y), (g, H) = parts[key], ref[key + "_law"]
        if frozen is not None:
            dy = y - frozen[key][0]
            g = g + (H * dy if key == "s1" else np.einsum("nhab,nhb->nha", H, dy))
        F = F + np.einsum("nm,nmd->nd" if key == "s1" else "nha,nhad->nd", g, Y)
    return F


class TEAdjoint:
    """The base's rows at their converged states: the pin contacts' generalised forces on the disc poses and
    their derivatives, the other elements with their laws, the Hessian H and the adjoint lambda of the TE."""

    def __init__(self, case: Case, law: ContactLaw | None, loads, theta_in_deg, states) -> None:
        self.case, self.law_arg = case, law
        s = self.s = solver_for(case, law)
        if not len(states) == len(theta_in_deg) == len(loads):
            raise ValueError(f"states ({len(states)}), theta_in_deg ({len(theta_in_deg)}) and loads ({len(loads)}) "
                             "must have one entry per condition")
        self.states = []
        for i, (xs, th, (L, d)) in enumerate(zip(states, theta_in_deg, loads)):
            xs = np.asarray(xs, dtype=float)
            if xs.shape != (np.size(th), s.ndof) or not np.all(np.isfinite(xs)):
                raise ValueError(f"states[{i}] must be a finite array of shape {(np.size(th), s.ndof)} (the base's "
                                 f"converged states at theta_in_deg[{i}]); got shape {xs.shape}")
            if not (np.isfinite(L) and L > 0 and d in (1, -1)):
                raise ValueError(f"loads[{i}] = {(L, d)!r} must be (load_Nm > 0, direction +1 or -1)")
            self.states.append(xs)
        self.th = np.radians(np.concatenate([np.asarray(t, dtype=float).ravel() for t in theta_in_deg]))
        self.x = np.concatenate(self.states)
        self.dirs = np.concatenate([np.full(len(x), int(d)) for x, (_, d) in zip(self.states, loads)])
        self.L = np.concatenate([np.full(len(x), float(L)) for x, (L, _) in zip(self.states, loads)])
        self.N = self.th.size
        self._contacts()
        self._adjoint()
        self.dir0 = self.directional(s)

    def te_extra(self, s: QuasiStaticSolver) -> np.ndarray:
        """The lumped torsional compliance's wind-up in the TE, ``-direction T c`` (N,) rad, of a solver."""
        return -self.dirs * (self.L * 1e3 + s.friction_Nmm) * s.compliance_rad_per_Nmm

    def forces(self, law, gap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forces (N) and stiffnesses (N/mm) of the pin contacts (N, nd, Zp) under a law at the gaps."""
        n1 = gap.shape[1] * gap.shape[2]
        delta = np.zeros((self.N, n1 + 2 * self.s.nc))
        delta[:, :n1] = -gap.reshape(self.N, n1)
        f, k = law.force_stiffness(delta)
        return f[:, :n1].reshape(gap.shape), k[:, :n1].reshape(gap.shape)

    def phi(self, res: tuple[np.ndarray, ...]) -> np.ndarray:
        """Generalised force of each pin contact on its disc's pose (N, nd, Zp, 3), ``-f dg/dpi``, for contacts
        ``res`` (:func:`_pin_contacts`), the law linearised at the states in the gap and the Johnson constant,
        ``f = f* - k* (g - g*) + df/dC* (C - C*)``: a contact touching there contributes its stiffness, one open
        does not, and the differences are smooth (the law's own change wherever a contact opens within a step)."""
        gap, dg, _, C = res
        f = self.f0 - self.k0 * (gap - self.gap)
        return -(f if C is None else f + self.fC * (C - self.C))[..., None] * dg

    def _contacts(self) -> None:
        """Poses, the pin contacts, their laws and the derivatives of their forces over the poses and the pins."""
        s, g = self.s, self.s.geom
        self.pose, self.Px, self.Pxx = _pose_derivs(s, self.th, self.x)
        start = g.pin_angles_nominal[None, None] - self.pose[..., 2, None]
        self.gap, self.dg, self.feet, self.C = _pin_contacts(s, self.pose, g.pin_centers, g.pin_radii, start)
        self.law_C = None if self.C is None else self.C.reshape(self.N, -1)
        self.law = s._step_law(s.law, self.law_C)
        self.f0, self.k0 = self.forces(self.law, self.gap)
        if self.C is not None:                                  # df/dC at the approach (smooth where touching)
            law = s._step_law(s.law, self.law_C + 1e-6)
            self.fC = (self.forces(law, self.gap)[0] - self.f0) / 1e-6
        self.phi_c = self.phi((self.gap, self.dg, None, self.C))
        self.Phi = np.empty((self.N, s.nd, 3, 3))
        for c in range(3):
            e = np.zeros(3)
            e[c] = POSE_STEP_MM if c < 2 else POSE_STEP_MM / s.Rp
            fp, fm = (self.phi(_pin_contacts(s, self.pose + sg * e, g.pin_centers, g.pin_radii, self.feet))
                      for sg in (1.0, -1.0))
            self.Phi[..., c] = (fp - fm).sum(axis=2) / (2.0 * e[c])
        self.dphi_pin = np.empty(self.phi_c.shape + (3,))
        for j in range(3):
            dP, dr = np.zeros((s.zp, 2)), np.zeros(s.zp)
            if j < 2:
                dP[:, j] = POSE_STEP_MM
            else:
                dr[:] = POSE_STEP_MM
            fp, fm = (self.phi(_pin_contacts(s, self.pose, g.pin_centers + sg * dP, g.pin_radii + sg * dr, self.feet))
                      for sg in (1.0, -1.0))
            self.dphi_pin[..., j] = (fp - fm) / (2.0 * POSE_STEP_MM)

    def _adjoint(self) -> None:
        """H = dF/dx at the states (the other elements' analytic tangent, with differences of their linearised
        gradient over the coordinates that turn their geometry: the kinematic ones and the discs' turns), the
        adjoint ``lambda = H^+T e_0 / Rp`` (pseudo-inverse: a free body stays where it is), the pose velocity
        ``w = Pi_x lambda``, the pins' weights and the stationarity of the states (one Newton step)."""
        s, nj, nk, D = self.s, self.s.nj, 1 + self.s.nc, self.s.ndof
        self.phi_sum = self.phi_c.sum(axis=2)
        self.rest = r = _rest_parts(s, self, self.x)
        (_, Y1), (_, k1) = r["s1"], r["s1_law"]
        H = np.einsum("nmd,nm,nme->nde", Y1, k1, Y1) + r.get("H_sup", 0.0)
        H[:, :nj, :nj] += np.einsum("nkci,nkcd,nkdj->nij", self.Px, self.Phi, self.Px)
        H[:, :nk, :nk] += np.einsum("nkc,nkcij->nij", self.phi_sum, self.Pxx)
        turns = [1 + s.nc + 3 * k + 2 for k in range(s.nd)] if s.float_discs else []
        for i in list(range(nk)) + turns:
            e = np.zeros(D)
            e[i] = STATE_STEP_MM
            col = (_rest_gradient(_rest_parts(s, self, self.x + e), r)
                   - _rest_gradient(_rest_parts(s, self, self.x - e), r)) / (2.0 * STATE_STEP_MM)
            H[:, :, i] += col - np.einsum("nmd,nm,nm->nd", Y1, k1, Y1[..., i]) - (r["H_sup"][..., i] if turns else 0)
        self.H = H
        Hi = np.linalg.pinv(H, rcond=PINV_RCOND)
        F = _rest_gradient(r)
        F[:, :nj] += np.einsum("nkci,nkc->ni", self.Px, self.phi_sum)
        self.stationarity_arcsec = float(np.abs(np.einsum("nj,nj->n", Hi[:, 0], F)).max()) / s.Rp * ARCSEC_PER_RAD
        if self.stationarity_arcsec > STATIONARY_ARCSEC:
            raise ValueError(f"states are not converged states of the base case: a Newton step moves the TE by "
                             f"{self.stationarity_arcsec:.3g} arcsec (allowed {STATIONARY_ARCSEC:g}); pass the "
                             "base's own TEResult.state, or None to solve here")
        self.lam = Hi[:, 0] / s.Rp
        self.w = np.einsum("nkci,ni->nkc", self.Px, self.lam[:, :nj])
        self.a_pin = np.einsum("nkc,nkicj->nij", self.w, self.dphi_pin)       # (N, Zp, [x, y, radius])

    def directional(self, st: QuasiStaticSolver) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """For the geometry of a nearby case at the states: the poses and the other elements' measures, each with
        its rows times lambda (``Pi_x lambda``, ``Y lambda``), as the solver forms them: differences of step
        ``STATE_STEP_MM`` along lambda's kinematic part, the discs' floats and the supports' coordinates exactly
        (a hole moves by its disc's shift plus turn times ``perp(arm)``, the arm at the kinematic pose)."""
        N, nk, lam = self.N, 1 + st.nc, self.lam
        lk = np.zeros_like(lam)
        lk[:, :nk] = lam[:, :nk]
        eps = STATE_STEP_MM / np.maximum(np.abs(lk).max(axis=1), 1e-300)[:, None]
        X = np.concatenate([self.x, self.x + eps * lk, self.x - eps * lk])
        P = _pose(st, np.tile(self.th, 3), X).reshape(3, N, st.nd, 3)
        out = {"pose": (P[0], (P[1] - P[2]) / (2.0 * eps[..., None]))}
        for key, v in _measures(st, self, X, 3).items():
            v = v.reshape((3, N) + v.shape[1:])
            out[key] = (v[0], (v[1] - v[2]) / (2.0 * eps.reshape((-1,) + (1,) * (v.ndim - 2))))
        if st.float_discs:
            fl = lam[:, 1 + st.nc:1 + st.nc + 3 * st.nd].reshape(N, st.nd, 3)
            out["pose"][1][...] += fl * np.array([1.0, 1.0, 1.0 / st.a])
            arms = st._disc_arms(self.th, self.x)
            moved = (fl[:, :, None, :2] + fl[:, :, None, 2:] * np.stack([-arms[..., 1], arms[..., 0]], -1))
            if st.chain is not None:
                out["cam"] = (out["cam"][0], out["cam"][1] + moved.reshape(N, -1, 2)
                              - np.einsum("kjad,nd->nkja", st._Y, lam).reshape(N, -1, 2))
            else:
                out["cam"] = (_spring_geometry(st, self.x, arms)[0], moved.reshape(N, -1, 2))
        return out

    def first_order(self, st, law: bool) -> np.ndarray:
        """``TE_extra - lambda . (F(x*) - F_base(x*))`` (N,) rad for a nearby case (its solver, or its geometry when
        it moves pins only), to first order in its change from the base: its derivative along a direction is the
        TE's. ``law``: the case differs in the solver's options, else in its geometry, every law linearised."""
        s = self.s
        if st is s:
            return self.te_extra(s)
        if law:
            f = self.forces(st._step_law(st.law, self.law_C), self.gap)[0]
            v = np.einsum("nkc,nkc->n", self.w, ((f - self.f0)[..., None] * self.dg).sum(axis=2))
            parts = _rest_parts(st, self, self.x)
            dc = st.clearance - s.clearance
            if dc and "cam" in parts:       # the clearance shifts the bearings' law along their deflection
                y, (g0, H0) = self.rest["cam"][0], self.rest["cam_law"]
                u = y / np.maximum(np.linalg.norm(y, axis=-1, keepdims=True), 1e-300)
                parts["cam_law"] = (g0 - dc * np.einsum("nhab,nhb->nha", H0, u), H0)
            dF = _rest_gradient(parts) - _rest_gradient(self.rest)
            return v - np.einsum("nd,nd->n", self.lam, dF) + self.te_extra(st)
        g = getattr(st, "geom", st)
        dP, dr = g.pin_centers - s.geom.pin_centers, g.pin_radii - s.geom.pin_radii
        v = -(np.einsum("nij,ij->n", self.a_pin[..., :2], dP) + self.a_pin[..., 2] @ dr)
        if g is st:                                     # pins only
            return v
        d, d0 = self.directional(st), self.dir0
        v -= np.einsum("nkc,nkcd,nkd->n", self.w, self.Phi, d["pose"][0] - d0["pose"][0])
        v -= np.einsum("nkc,nkc->n", self.phi_sum, d["pose"][1] - d0["pose"][1])
        for key in ("s1", "cam"):
            if key in d:
                (y, yl), (y0, yl0), (f0, k0) = d[key], d0[key], self.rest[key + "_law"]
                ky = k0 * (y - y0) if key == "s1" else np.einsum("nhab,nhb->nha", k0, y - y0)
                v -= (yl0 * ky).reshape(self.N, -1).sum(axis=1) + (f0 * (yl - yl0)).reshape(self.N, -1).sum(axis=1)
        return v
