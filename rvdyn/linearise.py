"""The linearisation side of the quasi-static solver (a mixin of :class:`rvdyn.solver.QuasiStaticSolver`).

The state maps (scaled coordinates to output, crank and disc poses), the gaps of every contact and their
Jacobians at a set of states (pin gaps from the contact provider with the chain rule through the disc
poses; stage I gaps in closed form; the kinematic derivatives by central differences of all neighbouring
states in one stacked evaluation), and the cam-bearing springs of floating discs. State lives on the solver.
"""
from __future__ import annotations

import numpy as np

from rvdyn.contacts import AnalyticContacts

#: Step (mm of scaled state) of the central differences of the kinematic Jacobians.
FD_STEP_MM = 1e-6


class LinearisationMixin:
    """Methods of the solver that evaluate and linearise the contact gaps (state lives on the solver)."""

    def _unpack(self, th_in: np.ndarray, x: np.ndarray):
        to0, ps0 = self.geom.ideal_state(th_in)
        to = to0 + x[:, 0] / self.Rp
        ps = ps0 + x[:, 1:1 + self.nc] / self.e
        shift = turn = None
        if self.float_discs:
            f = x[:, 1 + self.nc:].reshape(-1, self.nd, 3)
            shift = f[:, :, :2]
            turn = f[:, :, 2] / self.a
        return to, ps, shift, turn

    def _poses(self, th_in: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Disc centres (N, nd, 2) mm and rotations (N, nd) rad (without the profile rotation)."""
        to, ps, shift, turn = self._unpack(th_in, x)
        cen, ang = self.geom.disc_poses(to, ps)
        if shift is not None:
            cen = cen + shift
            ang = ang + turn
        return cen, ang

    def _stacked(self, th_in: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The states x and their central-difference neighbours in one array.

        Rows ``[0, N)`` are x; block ``1 + 2 i`` holds x + h e_i and block ``2 + 2 i`` holds x - h e_i for each
        kinematic coordinate i (output and cranks), h = 1e-6 mm. One evaluation of the (row-wise) kinematics on
        the stacked array gives the same numbers as one call per neighbour, without the per-call overhead.
        Returns the input angles (tiled) and the states ((1 + 2 (1 + nc)) N, ndof)."""
        N = x.shape[0]
        nk = 1 + self.nc
        X = np.empty(((1 + 2 * nk) * N, self.ndof))
        X[:N] = x
        for i in range(nk):
            xp = X[(1 + 2 * i) * N:(2 + 2 * i) * N]
            xm = X[(2 + 2 * i) * N:(3 + 2 * i) * N]
            xp[:] = x
            xm[:] = x
            xp[:, i] += FD_STEP_MM
            xm[:, i] -= FD_STEP_MM
        return np.tile(th_in, 1 + 2 * nk), X

    def _central(self, v: np.ndarray, N: int) -> np.ndarray:
        """Central differences of a stacked evaluation v ((1 + 2 nk) N, ...) -> (N, ..., nk)."""
        nk = 1 + self.nc
        parts = [(v[(1 + 2 * i) * N:(2 + 2 * i) * N] - v[(2 + 2 * i) * N:(3 + 2 * i) * N]) / (2 * FD_STEP_MM)
                 for i in range(nk)]
        return np.stack(parts, axis=-1)

    def _pin_gaps(self, th_in: np.ndarray, x: np.ndarray, stacked=None,
                  jac: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Pin gaps (N, nd, Zp) mm and Jacobians (N, nd, Zp, ndof) mm/mm (written into ``jac`` if given).

        Disc poses are differentiated by central differences (cheap: N x nd values, all neighbours in
        one stacked evaluation, :meth:`_stacked`); the pins follow by the chain rule: p = R(-phi)(P - c),
        dp = -R(-phi) dc + dphi (p_y, -p_x), and the gap's gradient is the outward normal n: dg = n . dp.
        """
        N = x.shape[0]
        nk = 1 + self.nc
        TH, X = self._stacked(th_in, x) if stacked is None else stacked
        cen_all, ang_all = self._poses(TH, X)
        cen, ang = cen_all[:N], ang_all[:N]
        dcen = np.zeros(cen.shape + (self.ndof,))
        dang = np.zeros(ang.shape + (self.ndof,))
        dcen[..., :nk] = self._central(cen_all, N)
        dang[..., :nk] = self._central(ang_all, N)
        if self.float_discs:
            for k in range(self.nd):
                b = 1 + self.nc + 3 * k
                dcen[:, k, 0, b] = 1.0
                dcen[:, k, 1, b + 1] = 1.0
                dang[:, k, b + 2] = 1.0 / self.a
        full = ang + self.geom.disc_profile_rotation[None]
        c, s = np.cos(full)[:, :, None], np.sin(full)[:, :, None]
        rx = self.geom.pin_centers[None, None, :, 0] - cen[:, :, None, 0]
        ry = self.geom.pin_centers[None, None, :, 1] - cen[:, :, None, 1]
        px = c * rx + s * ry
        py = -s * rx + c * ry
        t0 = self.geom.pin_angles_nominal[None, None] - full[:, :, None]
        gaps = np.empty((N, self.nd, self.zp))
        nx = np.empty_like(gaps)
        ny = np.empty_like(gaps)
        feet = []
        for k in range(self.nd):
            pts = np.stack([px[:, k].ravel(), py[:, k].ravel()], axis=1)
            tk = t0[:, k].ravel()
            dist, nrm = self.contacts.disc_distance(k, pts, tk)
            gaps[:, k] = dist.reshape(N, self.zp) - self.geom.pin_radii[None]
            nx[:, k] = nrm[:, 0].reshape(N, self.zp)
            ny[:, k] = nrm[:, 1].reshape(N, self.zp)
            foot = getattr(self.contacts, "foot_parameters", lambda _k: None)(k)
            feet.append((pts, tk, None if foot is None else foot.copy()))
        mx = nx * c - ny * s
        my = nx * s + ny * c
        # the Johnson constants and relative radii of the pin contacts, computed when asked for (the
        # physical law at every linearisation; the impact law only for the pressures at the solution)
        self._feet_last = feet
        self._C_last = self._R_last = None
        self._nrm_last = np.stack([mx, my], axis=-1)                            # fixed frame, (N, nd, Zp, 2)
        lever = nx * py - ny * px
        # -(mx dc_x + my dc_y) + lever dphi, evaluated in place (the same operations in the same order)
        if jac is None:
            jac = np.empty((N, self.nd, self.zp, self.ndof))
        np.multiply(mx[..., None], dcen[:, :, None, 0, :], out=jac)
        jac += my[..., None] * dcen[:, :, None, 1, :]
        np.negative(jac, out=jac)
        jac += lever[..., None] * dang[:, :, None, :]
        return gaps, jac

    def _line_last(self, rows: slice | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Johnson constants C and relative radii R (N, nd Zp) of the pin contacts of the last linearisation
        (``rows``: of those rows only; row by row, so the same numbers as the rows of the whole)."""
        if self._C_last is not None:
            return (self._C_last, self._R_last) if rows is None else (self._C_last[rows], self._R_last[rows])
        Cs, Rs = [], []
        for k, (pts, tk, foot) in enumerate(self._feet_last):
            if rows is not None:
                sub = slice(rows.start * self.zp, rows.stop * self.zp)
                pts, tk, foot = pts[sub], tk[sub], None if foot is None else foot[sub]
            r_pin = np.broadcast_to(self.geom.pin_radii[None], (len(tk) // self.zp, self.zp)).ravel()
            Ck, Rk = self._line_C(k, pts, tk, r_pin, foot)
            Cs.append(Ck.reshape(-1, self.zp))
            Rs.append(Rk.reshape(-1, self.zp))
        C = np.stack(Cs, axis=1).reshape(len(Cs[0]), -1)
        R = np.stack(Rs, axis=1).reshape(len(Rs[0]), -1)
        if rows is None:
            self._C_last, self._R_last = C, R
        return C, R

    def _stage1(self, th_in: np.ndarray, x: np.ndarray, direction: int, provider: bool) -> np.ndarray:
        to, ps, _, _ = self._unpack(th_in, x)
        if provider:
            return self.contacts.stage1_gaps(th_in, to, ps, direction)
        return self.geom.stage1_gaps(th_in, to, ps, direction)

    def _linearise(self, th_in: np.ndarray, x: np.ndarray, direction) -> tuple[np.ndarray, np.ndarray]:
        """Gaps (N, M) mm and their Jacobians (N, M, ndof) mm/mm at the states x.

        Columns: the 2 x Zp pin gaps, then the stage I flank gaps of each planet, loaded flank
        (``direction``) first, coast flank (``-direction``, open by the stage I backlash) second.
        ``direction`` is +1, -1 or an (N,) array of them (one per state).
        The stage I Jacobians are central differences of the closed-form involute gap (the
        kinematic derivative; the provider only supplies the gap value).
        """
        N = x.shape[0]
        nk = 1 + self.nc
        dirs = np.broadcast_to(np.asarray(direction), (N,))
        stacked = self._stacked(th_in, x)
        n1 = self.nd * self.zp
        J = np.empty((N, n1 + 2 * self.nc, self.ndof))
        gaps, _ = self._pin_gaps(th_in, x, stacked, J[:, :n1].reshape(N, self.nd, self.zp, self.ndof))
        TH, X = stacked
        to, ps, _, _ = self._unpack(TH, X)
        analytic = isinstance(self.contacts, AnalyticContacts)
        val, der = {}, {}
        both = self.geom.stage1_gaps_both(TH, to, ps)
        for flank in (1, -1):
            g_all = both[flank]
            # the provider's gap value (the analytic provider's is the closed form just evaluated)
            val[flank] = g_all[:N] if analytic else self.contacts.stage1_gaps(th_in, to[:N], ps[:N], flank)
            j1 = np.zeros((N, self.nc, self.ndof))
            j1[..., :nk] = self._central(g_all, N)
            der[flank] = j1
        up = (dirs == 1)[:, None]
        g1 = np.concatenate([np.where(up, val[1], val[-1]), np.where(up, val[-1], val[1])], axis=1)
        j1 = np.concatenate([np.where(up[..., None], der[1], der[-1]), np.where(up[..., None], der[-1], der[1])],
                            axis=1)
        G = np.concatenate([gaps.reshape(N, -1), g1], axis=1)
        J[:, n1:] = j1
        return G, J

    # ------------------------------------------------------------------ bearings
    def _hole_arms(self, th_in: np.ndarray, x: np.ndarray) -> np.ndarray | None:
        """Disc holes relative to their disc's centre, turned with the disc at the states x, divided
        by the turn lever ``a``: (N, nd, nc, 2), or None without floating discs.

        The inner solve takes them at its linearisation point (like the contact gaps): the hole
        direction turns by the disc's rotation, microradians within a step, and the outer iteration
        re-evaluates them, so the converged state is exact."""
        if not self.float_discs:
            return None
        to, ps, _, _ = self._unpack(th_in, x)
        _, ang = self.geom.disc_poses(to, ps)
        c, sn = np.cos(ang)[:, :, None], np.sin(ang)[:, :, None]        # (N, nd, 1)
        h = self.geom.disc_holes[None]                                    # (1, nd, nc, 2)
        hx, hy = h[..., 0], h[..., 1]
        return np.stack([c * hx - sn * hy, sn * hx + c * hy], axis=-1) / self.a

    def _bearing(self, x: np.ndarray, arms: np.ndarray | None,
                 derivs: bool = True) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Energy (N,), gradient (N, ndof) and Gauss-Newton Hessian (N, ndof, ndof) of the cam bearings
        (the derivatives None when ``derivs`` is False).

        Each hole moves by ``s = shift + turn * (z x r) / a`` (disc shift and turn DOFs, r the hole's
        arm of :meth:`_hole_arms`); its bearing is a spring ``bearing_k`` beyond the clearance."""
        N = x.shape[0]
        if arms is None:
            return np.zeros(N), np.zeros((N, self.ndof)), np.zeros((N, self.ndof, self.ndof))
        nd, nc, kb = self.nd, self.nc, self.bearing_k
        blk = x[:, 1 + nc:].reshape(N, nd, 1, 3)                       # disc shift x, y and turn
        perp = np.stack([-arms[..., 1], arms[..., 0]], axis=-1)        # d s / d turn, (N, nd, nc, 2)
        s_ = blk[..., :2] + blk[..., 2:3] * perp
        sn = np.sqrt(s_[..., 0] ** 2 + s_[..., 1] ** 2)
        over = np.maximum(sn - self.clearance, 0.0)
        E = 0.5 * kb * (over ** 2).sum(axis=(1, 2))
        if not derivs:
            return E, None, None
        u = s_ / np.maximum(sn, 1e-300)[..., None]                     # over > 0 only where sn > 0
        Ju = np.concatenate([u, (u * perp).sum(axis=-1, keepdims=True)], axis=-1)   # (N, nd, nc, 3)
        g = np.zeros((N, self.ndof))
        g[:, 1 + nc:] = ((kb * over)[..., None] * Ju).sum(axis=2).reshape(N, 3 * nd)
        Hb = np.einsum("nkh,nkhi,nkhj->nkij", kb * (over > 0), Ju, Ju)
        H = np.zeros((N, self.ndof, self.ndof))
        for k in range(nd):
            base = 1 + nc + 3 * k
            H[:, base:base + 3, base:base + 3] = Hb[:, k]
        return E, g, H
