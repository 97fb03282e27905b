"""The linearisation side of the quasi-static solver (a mixin of :class:`rvdyn.solver.QuasiStaticSolver`).

The state maps (scaled coordinates to output, crank and disc poses), the gaps of every contact and their
Jacobians at a set of states (pin gaps from the contact provider with the chain rule through the disc
poses; stage I gaps in closed form; the kinematic derivatives by central differences of all neighbouring
states in one stacked evaluation). State lives on the solver; the cam bearings are in rvdyn.support_eq.
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
            f = x[:, 1 + self.nc:1 + self.nc + 3 * self.nd].reshape(-1, self.nd, 3)
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
        """Pin gaps (N, nd, Zp) mm and Jacobians (N, nd, Zp, nj) mm/mm (written into ``jac`` if given).

        Disc poses are differentiated by central differences (cheap: N x nd values, all neighbours in
        one stacked evaluation, :meth:`_stacked`); the pins follow by the chain rule: p = R(-phi)(P - c),
        dp = -R(-phi) dc + dphi (p_y, -p_x), and the gap's gradient is the outward normal n: dg = n . dp.
        """
        N = x.shape[0]
        nk = 1 + self.nc
        TH, X = self._stacked(th_in, x) if stacked is None else stacked
        cen_all, ang_all = self._poses(TH, X)
        # the poses of the stacked states, for the chain's hole offsets at the same states (rvdyn.support_eq)
        self._stack_poses = (np.array(th_in, dtype=float), np.array(x, dtype=float), TH, X, cen_all, ang_all)
        cen, ang = cen_all[:N], ang_all[:N]
        dcen = np.zeros(cen.shape + (self.nj,))
        dang = np.zeros(ang.shape + (self.nj,))
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
        # -(mx dc_x + my dc_y) + lever dphi, evaluated in place (the same operations in the same order) on the
        # kinematic columns; a floating disc's own columns are -mx, -my and lever / a (its shift and turn move
        # its centre by 1 and its angle by 1 / a), the other disc's 0
        if jac is None:
            jac = np.empty((N, self.nd, self.zp, self.nj))
        jk = jac[..., :nk]
        np.multiply(mx[..., None], dcen[:, :, None, 0, :nk], out=jk)
        jk += my[..., None] * dcen[:, :, None, 1, :nk]
        np.negative(jk, out=jk)
        jk += lever[..., None] * dang[:, :, None, :nk]
        if self.float_discs:
            jac[..., nk:] = 0.0
            for k in range(self.nd):
                b = 1 + self.nc + 3 * k
                np.negative(mx[:, k], out=jac[:, k, :, b])
                np.negative(my[:, k], out=jac[:, k, :, b + 1])
                np.multiply(lever[:, k], 1.0 / self.a, out=jac[:, k, :, b + 2])
        return gaps, jac

    def _line_last(self, rows: slice | np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Johnson constants C and relative radii R (N, nd Zp) of the pin contacts of the last linearisation
        (``rows``: of those rows only, a slice or an index array; row by row, so the same numbers as the rows of
        the whole)."""
        if self._C_last is not None:
            return (self._C_last, self._R_last) if rows is None else (self._C_last[rows], self._R_last[rows])
        Cs, Rs = [], []
        for k, (pts, tk, foot) in enumerate(self._feet_last):
            if rows is not None:
                if isinstance(rows, slice):
                    sub = slice(rows.start * self.zp, rows.stop * self.zp)
                else:
                    sub = (np.asarray(rows)[:, None] * self.zp + np.arange(self.zp)).ravel()
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

    def _linearise(self, th_in: np.ndarray, x: np.ndarray, direction) -> tuple[np.ndarray, np.ndarray]:
        """Gaps (N, M) mm and their Jacobians (N, M, nj) mm/mm at the states x (nj: the coordinates the
        contacts depend on, the first nj of the state; the support coordinates follow them).

        Columns: the 2 x Zp pin gaps, then the stage I flank gaps of each planet, loaded flank
        (``direction``) first, coast flank (``-direction``, open by the stage I backlash) second.
        ``direction`` is +1, -1 or an (N,) array of them (one per state).
        The stage I Jacobians are central differences of the closed-form involute gap (the
        kinematic derivative; the provider only supplies the gap value).
        """
        N = x.shape[0]
        stacked = self._stacked(th_in, x)
        n1 = self.nd * self.zp
        J = np.empty((N, n1 + 2 * self.nc, self.nj))
        gaps, _ = self._pin_gaps(th_in, x, stacked, J[:, :n1].reshape(N, self.nd, self.zp, self.nj))
        g1, J[:, n1:] = self._stage1_linear(th_in, x, direction, stacked)
        return np.concatenate([gaps.reshape(N, -1), g1], axis=1), J

    def _stage1_linear(self, th_in: np.ndarray, x: np.ndarray, direction,
                       stacked=None) -> tuple[np.ndarray, np.ndarray]:
        """The stage I flank gaps (N, 2 nc) mm at the states x and their Jacobians (N, 2 nc, nj), the columns of
        :meth:`_linearise` after the pin gaps (``stacked``: :meth:`_stacked` of these states if already made)."""
        N = x.shape[0]
        nk = 1 + self.nc
        dirs = np.broadcast_to(np.asarray(direction), (N,))
        TH, X = self._stacked(th_in, x) if stacked is None else stacked
        to, ps, _, _ = self._unpack(TH, X)
        analytic = isinstance(self.contacts, AnalyticContacts)
        val, der = {}, {}
        both = self.geom.stage1_gaps_both(TH, to, ps)
        for flank in (1, -1):
            g_all = both[flank]
            # the provider's gap value (the analytic provider's is the closed form just evaluated)
            val[flank] = g_all[:N] if analytic else self.contacts.stage1_gaps(th_in, to[:N], ps[:N], flank)
            j1 = np.zeros((N, self.nc, self.nj))
            j1[..., :nk] = self._central(g_all, N)
            der[flank] = j1
        return self._flanks(val, dirs), self._flanks(der, dirs)

    @staticmethod
    def _flanks(v: dict, dirs: np.ndarray) -> np.ndarray:
        """Per-flank arrays ``{1: (N, nc, ...), -1: ...}`` as the columns of the stage I contacts (N, 2 nc, ...):
        each state's loaded flank (its direction, ``dirs`` (N,)) first, the coast flank second."""
        up = (np.asarray(dirs) == 1).reshape((-1, 1) + (1,) * (v[1].ndim - 2))
        return np.concatenate([np.where(up, v[1], v[-1]), np.where(up, v[-1], v[1])], axis=1)
