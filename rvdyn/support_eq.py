"""The supports inside the equilibrium (a mixin of :class:`rvdyn.solver.QuasiStaticSolver`).

Two models of the cam bearings of floating discs (docs/physics.md, sections 3 and 8):

- ``option spring`` (the impact law, or ``supports = "rigid"``, with a cam-bearing clearance): each hole
  sits on a linear spring ``model.cam_bearing_stiffness_N_per_um`` beyond the clearance; the cranks are rigid.
- ``chain`` (the physical law with ``supports = "elastic"``): every disc floats (3 coordinates per disc),
  every crank has 4 + 2 nd more: the displacements of its two journal nodes and its bending deflections at the
  cam planes, and the carrier end plate one, ``s = a phi`` (its turn against the output flange, mm at the
  crank circle a): journal B's bearing deflects by ``u_B - s t_j`` (t_j the crank circle's tangent), the pillars
  store ``k_t phi^2 / 2`` (``bearings.carrier_torsional_stiffness``). Each disc hole is held by a needle bearing (Palmgren line contact, radial
  law ``F = K_c (|d| - c)^(10/9)`` beyond the clearance c, ``bearings.radial_bearing_K``) against its cam;
  the cam moves with the crank: ``y_k = (1 - l_k) u_A + l_k u_B + w_k`` (journal deflections interpolated at
  the cam plane, l_k its axial position between the journals, plus bending). Journals: the same law without
  clearance; bending: ``w^T K_b w / 2`` with ``K_b`` the inverse of the simply-supported beam's influence
  matrix at the cam planes (the stepped Timoshenko crank, ``bearings.Supports.bending_deflections``). All of it is an exact
  potential of the state: the equilibrium shares every preload between contacts and supports.

The hole offsets ``d = hole - cam`` (fixed frame) are linearised at each outer iteration like the contact
gaps (the float columns exactly, the kinematic ones by central differences of the rigid hole fit); the
bearing, journal and bending energies are exact in the inner minimisation.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from rvdyn.bearings import BEARING_EXP, Supports
from rvdyn.contacts import ContactLaw

#: Step (mm of scaled state) of the central differences of the hole offsets.
FD_STEP_MM = 1e-6

#: Penalty (N/mm) of every support in the rigid limit (load 0): 1e3 times the contacts' ``ContactLaw.RIGID_K``,
#: so that the supports (three springs in series per cam) add less to the rigid play than the contacts do
#: (1e-15 rad under the vanishing load).
RIGID_SUPPORT_K = 1.0e3 * ContactLaw.RIGID_K

#: Cam-bearing spring (N/mm) of the option-spring model in the rigid limit, at most: the vanishing load
#: (1 N mm) deflects it by < 1e-7 mm, and the floating solve stays as well conditioned as with the contacts'.
RIGID_LIMIT_SPRING_K = 1.0e6

#: Bearing load (N) whose tangent stiffness, times 1e-9, floors the bearings' exact tangent in the Newton model
#: of the supports (a 10/9 power law has no stiffness at zero deflection; the Levenberg-Marquardt damping of the
#: inner loop takes care of the directions without stiffness); the first Newton step of a solve floors it at the
#: full tangent under the load estimate of :meth:`SupportMixin.newton_load`, and at least this load.
NEWTON_FORCE_N = 0.1


#: Newton iterations at most of the series inversion of a bearing with an elastic seat (:func:`series_deflection`).
SERIES_MAX_ITER = 40


def series_deflection(t: np.ndarray, K: float, p: float, cs: float) -> np.ndarray:
    """The bearing's own deflection x (mm) of a power-law bearing ``F = K x^p`` (p > 1) in series with a linear
    seat of compliance ``cs`` (mm/N) under the total deflection t: the root of ``g(x) = x + cs K x^p - t``.
    g is increasing and convex, so Newton's method started from an upper bound of the root
    (``min(t, (t/(cs K))^(1/p))``, each term alone at most t) decreases monotonically onto it; each entry stops
    when its step is at most 4 ulp of its t (at most ``SERIES_MAX_ITER`` steps; compiled,
    :func:`_series_kernel`)."""
    t = np.asarray(t, dtype=float)
    return _series_kernel(np.ascontiguousarray(t).reshape(-1), float(K), float(p), float(cs),
                          SERIES_MAX_ITER).reshape(t.shape)


@njit(cache=True)
def _series_kernel(t, K, p, cs, max_iter):
    """:func:`series_deflection` of a flat array t, each entry stopping on its own test (the iterations sweep
    the entries still moving, so independent entries overlap in the pipeline)."""
    n = t.shape[0]
    x = np.empty(n)
    moving = np.ones(n, dtype=np.bool_)
    ckp = cs * K * p
    eps4 = 4.0 * np.finfo(np.float64).eps
    for i in range(n):
        x[i] = min(t[i], (t[i] / (cs * K)) ** (1.0 / p))
    for _ in range(max_iter):
        left = False
        for i in range(n):
            if moving[i]:
                xi = x[i]
                xp1 = xi ** (p - 1.0)
                dx = (xi + cs * K * xi * xp1 - t[i]) / (1.0 + ckp * xp1)
                x[i] = max(xi - dx, 0.0)
                if abs(dx) > eps4 * max(t[i], 1e-300):
                    left = True
                else:
                    moving[i] = False
        if not left:
            break
    return x


def radial_law(d: np.ndarray, K: float, p: float, c: float = 0.0, derivs: bool = True, kfloor: float = 0.0,
               cs: float = 0.0):
    """Energy (...), force vector (..., 2) and Hessian (..., 2, 2) of a radial spring ``F = K (|d| - c)^p``
    along ``d`` beyond the clearance c (isotropic: the full Hessian ``F' u u^T + F/|d| (I - u u^T)``).
    ``kfloor`` (N/mm): least stiffness of the Hessian (a Newton model only; the energy and force are exact).
    ``cs`` (mm/N, p > 1): a linear seat in series, ``|d| - c = x + cs F`` with ``F = K x^p``
    (:func:`series_deflection`): energy ``F x/(p + 1) + cs F^2/2``, radial stiffness
    ``1/(x/(p F) + cs) = p K x^(p-1)/(1 + cs p K x^(p-1))``."""
    d0, d1 = d[..., 0], d[..., 1]
    r = np.sqrt(d0 * d0 + d1 * d1)
    t = np.maximum(r - c, 0.0)
    if p == 1.0:
        F = K * t
        kr = np.where(t > 0, K, 0.0) if derivs else None
        E = F * t / (p + 1.0)
    elif cs > 0.0:
        x = series_deflection(t, K, p, cs)
        xp1 = x ** (p - 1.0)
        F = K * x * xp1
        kr = (K * p) * xp1 / (1.0 + (cs * K * p) * xp1) if derivs else None
        E = F * x / (p + 1.0) + 0.5 * cs * F * F
    else:
        # one power: t^(p-1), then F = K t t^(p-1) and the radial stiffness p K t^(p-1) (t = 0: both 0)
        tp1 = t ** (p - 1.0)
        F = K * t * tp1
        kr = (K * p) * tp1 if derivs else None
        E = F * t / (p + 1.0)
    if not derivs:
        return E, None, None
    rs = np.maximum(r, 1e-300)
    u0, u1 = d0 / rs, d1 / rs
    fv = np.stack([F * u0, F * u1], axis=-1)
    kt = F / rs
    if kfloor > 0.0:                                  # not inside the clearance: there the bearing is free
        eng = r >= c
        kr, kt = np.where(eng, np.maximum(kr, kfloor), kr), np.where(eng, np.maximum(kt, kfloor), kt)
    # H = (kr - kt) u u^T + kt I, written per entry (2 x 2)
    dk = kr - kt
    h01 = dk * u0 * u1
    H = np.stack([dk * u0 * u0 + kt, h01, h01, dk * u1 * u1 + kt], axis=-1).reshape(d.shape + (2,))
    return E, fv, H


def _tangent(K: float, p: float, F: float, cs: float) -> float:
    """Radial tangent stiffness (N/mm) of the law ``F = K x^p`` under the load F, with a seat of compliance cs in
    series: ``1/(1/(p K (F/K)^((p-1)/p)) + cs)``."""
    kb = K * p * (F / K) ** ((p - 1.0) / p)
    return kb / (1.0 + cs * kb) if cs > 0.0 else kb


def batch_solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Solve the systems ``A X = B`` for a batch of small symmetric positive definite matrices, A (..., n, n),
    B (..., n, r), by Gaussian elimination without pivoting (stable for SPD matrices, as Cholesky), compiled
    system by system (:func:`_batch_solve_kernel`), where ``np.linalg.solve`` calls LAPACK matrix by matrix
    with its checks and pivoting around each."""
    n, r = A.shape[-1], B.shape[-1]
    X = _batch_solve_kernel(np.ascontiguousarray(A, dtype=float).reshape(-1, n, n),
                            np.ascontiguousarray(B, dtype=float).reshape(-1, n, r))
    return X.reshape(B.shape)


@njit(cache=True)
def _batch_solve_kernel(A, B):
    """:func:`batch_solve` of A (K, n, n) and B (K, n, r) (not modified)."""
    K, n, r = B.shape
    X = np.empty((K, n, r))
    a = np.empty((n, n))
    for s in range(K):
        for i in range(n):
            for j in range(n):
                a[i, j] = A[s, i, j]
            for c in range(r):
                X[s, i, c] = B[s, i, c]
        for k in range(n - 1):
            for i in range(k + 1, n):
                f = a[i, k] / a[k, k]
                for j in range(k + 1, n):
                    a[i, j] -= f * a[k, j]
                for c in range(r):
                    X[s, i, c] -= f * X[s, k, c]
        for k in range(n - 1, -1, -1):
            for c in range(r):
                acc = 0.0
                for j in range(k + 1, n):
                    acc += a[k, j] * X[s, j, c]
                X[s, k, c] = (X[s, k, c] - acc) / a[k, k]
    return X


def _small_matmul(A: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``A @ w`` for a small constant matrix A (n, n) and a batch w (..., n, m), as n^2 scaled adds over the
    whole batch (``np.matmul`` broadcasts A over the batch matrix by matrix: twice the time for n = 2)."""
    n = A.shape[0]
    out = np.empty(w.shape)
    for k in range(n):
        acc = A[k, 0] * w[..., 0, :]
        for l in range(1, n):
            acc = acc + A[k, l] * w[..., l, :]
        out[..., k, :] = acc
    return out


class SupportChain:
    """Constants and coordinate layout of the supports inside the equilibrium.

    Parameters
    ----------
    sup : Supports, stiffness constants of the design
    nd, nc : discs and cranks
    clearance : mm, radial clearance of the cam bearings
    base : index of the first support coordinate in the state vector
    """

    def __init__(self, sup: Supports, nd: int, nc: int, clearance: float, base: int) -> None:
        self.sup, self.nd, self.nc, self.c, self.base = sup, nd, nc, clearance, base
        self.per_crank = 4 + 2 * nd
        # rigid limit: with a clearance the play dominates and the contacts' penalty is rigid enough
        self.rigid_K = ContactLaw.RIGID_K if clearance > 0.0 else RIGID_SUPPORT_K
        # the carrier end plate's turn against the flange, one coordinate s = a phi (mm at the crank circle) after
        # the cranks' when the carrier is elastic: journal B's bearing is deflected by u_B - s t_j (t_j the unit
        # tangent of crank j's circle), the pillars store k_s s^2 / 2 with k_s = k_t / a^2 (docs/physics.md, 8)
        self.k_s = sup.carrier_k / sup.crank_radius ** 2 if np.isfinite(sup.carrier_k) else 0.0
        self.n_carrier = 1 if self.k_s > 0.0 else 0
        self.n_dof = nc * self.per_crank + self.n_carrier
        zA, zB = sup.z_journal
        self.lam = (np.asarray(sup.z_cams, dtype=float) - zA) / (zB - zA)       # (nd,)
        # bending: influence matrix at the cam planes (unit load at each plane), its inverse the stiffness
        infl = np.empty((nd, nd))
        for k in range(nd):
            B = np.zeros((1, nd, 1, 2))
            B[0, k, 0, 0] = -1.0                                                # crank receives +1 N in x at plane k
            infl[:, k] = sup.bending_deflections(B)[0, 0, :, 0]
        self.Kb = np.linalg.inv(infl)                                           # N/mm, (nd, nd)
        # weights of the crank's nodes (journal A, journal B, bending at each cam plane) in its displacement
        # at cam plane k: y_k = sum_r L[r, k] node_r
        self.L = np.vstack([1.0 - self.lam, self.lam, np.eye(nd)])
        self.LL = [np.outer(self.L[:, k], self.L[:, k]) for k in range(nd)]
        self.LLk = np.einsum("rk,sk->rsk", self.L, self.L)                      # (4, 4, nd)

    def idx(self, j: int, what: str, k: int = 0) -> int:
        """State index of crank j's coordinate ``uA``, ``uB`` or ``w`` (cam plane k); x and y follow."""
        b = self.base + j * self.per_crank
        return b + {"uA": 0, "uB": 2, "w": 4 + 2 * k}[what]

    def y_matrix(self, ndof: int) -> np.ndarray:
        """dy/dx (nd, nc, 2, ndof): the crank displacement at each cam plane from the support coordinates."""
        Y = np.zeros((self.nd, self.nc, 2, ndof))
        for k in range(self.nd):
            for j in range(self.nc):
                for a in range(2):
                    Y[k, j, a, self.idx(j, "uA") + a] = 1.0 - self.lam[k]
                    Y[k, j, a, self.idx(j, "uB") + a] = self.lam[k]
                    Y[k, j, a, self.idx(j, "w", k) + a] = 1.0
        return Y

    def journal_deflections(self, x: np.ndarray, tang: np.ndarray | None) -> np.ndarray:
        """Deflections (N, nc, 2 journals, 2) mm of the journal bearings: the crank's node displacements, journal
        B's minus the carrier end plate's displacement ``s t_j`` there (``tang`` (N, nc, 2): the unit tangents of
        the cranks' circle at the linearisation, fixed frame)."""
        N = x.shape[0]
        sl = x[:, self.base:self.base + self.nc * self.per_crank].reshape(N, self.nc, self.per_crank)
        u = sl[:, :, :4].reshape(N, self.nc, 2, 2).copy()
        if self.n_carrier and tang is not None:
            u[:, :, 1] -= x[:, self.base + self.n_dof - 1, None, None] * tang
        return u

    def energy(self, x: np.ndarray, dcam: np.ndarray, rigid: bool, derivs: bool = True, newton: float = 0.0,
               tang: np.ndarray | None = None):
        """Support energy (N,) N mm, its gradient (N, ndof) and Hessian in the support coordinates and the
        bearing deflections ``dcam`` (N, nd, nc, 2) (hole minus cam, mm): the Hessian per crank (N, nc, pc, pc),
        and with an elastic carrier its coupling to the carrier coordinate s, ``H_qs`` (N, nc, pc), and ``H_ss``
        (N,); the cam-bearing part of the gradient and Hessian is returned in ``dcam`` coordinates
        (``g_cam`` (N, nd, nc, 2), ``H_cam`` (N, nd, nc, 2, 2)) for the caller's chain rule. ``tang``: the
        cranks' unit tangents (N, nc, 2) (:meth:`journal_deflections`).

        ``rigid``: the rigid limit, every support a linear penalty ``RIGID_SUPPORT_K``. ``newton`` > 0 (N):
        the Hessian of a Newton model, each bearing's stiffness at least its tangent under that load (a power
        law 10/9 has none at zero deflection); 0: the exact tangent (floored at 1e-9 of the one at 0.1 N)."""
        N = x.shape[0]
        s = self.sup
        if rigid:
            Kc = Kj = ks = self.rigid_K
            p = 1.0
            Kb = self.rigid_K * np.eye(self.nd)
            csc = csj = 0.0
        else:
            Kc, Kj, p, Kb, ks = s.cam_K, s.journal_K, BEARING_EXP, self.Kb, self.k_s
            csc, csj = s.cam_seat_c, s.journal_seat_c
        nq = self.nc * self.per_crank
        sl = x[:, self.base:self.base + nq].reshape(N, self.nc, self.per_crank)
        u = self.journal_deflections(x, tang)                                   # journals A, B
        w = sl[:, :, 4:].reshape(N, self.nc, self.nd, 2)
        scale, F = (1.0, newton) if newton > 0 else (1e-9, NEWTON_FORCE_N)
        Ec, gc, Hc = radial_law(dcam, Kc, p, self.c, derivs, scale * _tangent(Kc, p, F, csc), csc)
        Ej, gj, Hj = radial_law(u, Kj, p, 0.0, derivs, scale * _tangent(Kj, p, F, csj), csj)
        Kw = _small_matmul(Kb, w)                                               # (N, nc, nd, 2)
        E = Ec.sum(axis=(1, 2)) + Ej.sum(axis=(1, 2)) + 0.5 * (w * Kw).sum(axis=(1, 2, 3))
        if self.n_carrier:
            sc = x[:, self.base + nq]
            E = E + 0.5 * ks * sc * sc
        if not derivs:
            return E, None, None, None, None, None, None
        g = np.zeros((N, self.n_dof))
        gv = g[:, :nq].reshape(N, self.nc, self.per_crank)
        gv[:, :, :4] = gj.reshape(N, self.nc, 4)
        gv[:, :, 4:] = Kw.reshape(N, self.nc, 2 * self.nd)
        H = np.zeros((N, self.nc, self.per_crank, self.per_crank))
        for a in range(2):
            H[:, :, 2 * a:2 * a + 2, 2 * a:2 * a + 2] = Hj[:, :, a]
        for k in range(self.nd):
            for l in range(self.nd):
                for a in range(2):
                    H[:, :, 4 + 2 * k + a, 4 + 2 * l + a] = Kb[k, l]
        Hqs = Hss = None
        if self.n_carrier:
            # journal B's deflection u_B - s t_j: d/ds = -t_j
            HBt = np.einsum("njab,njb->nja", Hj[:, :, 1], tang)                 # (N, nc, 2)
            g[:, nq] = ks * sc - np.einsum("nja,nja->n", gj[:, :, 1], tang)
            Hqs = np.zeros((N, self.nc, self.per_crank))
            Hqs[:, :, 2:4] = -HBt
            Hss = ks + np.einsum("nja,nja->n", HBt, tang)
        return E, g, H, gc, Hc, Hqs, Hss

    def parts(self, x: np.ndarray, dx: np.ndarray, dcam: np.ndarray, ddcam: np.ndarray,
              rigid: bool = False, tang: np.ndarray | None = None,
              per_crank: dict | None = None) -> dict[str, np.ndarray]:
        """Unit-load wind-up of the supports (N,) rad: ``sum q . d`` with ``d`` each part's actual
        deflection and ``q`` its force per unit output torque (tangent stiffness times ``dx = dx/dT``,
        ``ddcam`` = d(dcam)/dT). ``per_crank`` (a dict, filled in): the same sums of the parts each crank carries
        (its cam bearings on both discs and their seats, its journal bearings and their seats, its bending),
        crank by crank, (N, nc) rad; the carrier's pillars carry all cranks' far journals together."""
        N = x.shape[0]
        s = self.sup
        csc, csj = (0.0, 0.0) if rigid else (s.cam_seat_c, s.journal_seat_c)
        _, _, _, gc, Hc, _, _ = self.energy(x, dcam, rigid, tang=tang)
        qc = np.einsum("nkjab,nkjb->nkja", Hc, ddcam)
        cam = np.einsum("nkja,nkja->n", qc, dcam)
        # the seat's share of a bearing's deflection is cs F along it, i.e. cs times the force vector
        cam_seat = csc * np.einsum("nkja,nkja->n", qc, gc)
        p = BEARING_EXP
        nq = self.nc * self.per_crank
        sl = x[:, self.base:self.base + nq].reshape(N, self.nc, self.per_crank)
        dsl = dx[:, self.base:self.base + nq].reshape(N, self.nc, self.per_crank)
        u = self.journal_deflections(x, tang)
        du = self.journal_deflections(dx, tang)
        _, fj, Hj = radial_law(u, s.journal_K, p, cs=csj)
        qj = np.einsum("njaxy,njay->njax", Hj, du)
        journal = np.einsum("njax,njax->n", qj, u)
        journal_seat = csj * np.einsum("njax,njax->n", qj, fj)
        w = sl[:, :, 4:].reshape(N, self.nc, self.nd, 2)
        dw = dsl[:, :, 4:].reshape(N, self.nc, self.nd, 2)
        bend = np.einsum("kl,njlx,njkx->n", self.Kb, dw, w)
        out = {"cam_bearings": cam - cam_seat, "journal_bearings": journal - journal_seat, "crank_bending": bend}
        if csc > 0.0:
            out["cam_bearing_seats"] = cam_seat
        if csj > 0.0:
            out["journal_bearing_seats"] = journal_seat
        if self.n_carrier:                                                      # the pillars: k_s s ds/dT
            out["carrier"] = self.k_s * x[:, self.base + nq] * dx[:, self.base + nq]
        if per_crank is not None:
            cam_j = np.einsum("nkja,nkja->nj", qc, dcam)
            cam_seat_j = csc * np.einsum("nkja,nkja->nj", qc, gc)
            journal_j = np.einsum("njax,njax->nj", qj, u)
            journal_seat_j = csj * np.einsum("njax,njax->nj", qj, fj)
            per_crank.update({"cam_bearings": cam_j - cam_seat_j, "journal_bearings": journal_j - journal_seat_j,
                              "crank_bending": np.einsum("kl,njlx,njkx->nj", self.Kb, dw, w)})
            if csc > 0.0:
                per_crank["cam_bearing_seats"] = cam_seat_j
            if csj > 0.0:
                per_crank["journal_bearing_seats"] = journal_seat_j
        return out


class SupportMixin:
    """Cam-bearing models of floating discs (state lives on the solver)."""

    _newton_N = NEWTON_FORCE_N

    def newton_load(self, B: np.ndarray, first: bool) -> None:
        """Set the load (N) of the supports' Newton model: in the first outer iteration the bearing load the
        output torque ``B[:, 0] Rp`` gives at the crank radius a shared by all cams (nc nd), an estimate that
        only shapes the first Newton step of the inner loop (which then calls this with ``first`` False);
        otherwise 0: the exact tangent (floored at 1e-9 of the one under ``NEWTON_FORCE_N``). A Hessian floored
        at a bearing's tangent under 0.1 N throughout would be stiffer than the tangent of a bearing that
        carries less, such as one just beyond its clearance, whose Newton steps would then shrink geometrically
        (measured: factor 0.88 per iteration) and pass the step test of the inner loop before the state is at
        its minimum (the rigid limit with a 6 um clearance short of the closed-form slack by up to 1.3
        arcsec/um); with the exact tangent Newton converges quadratically."""
        if self.chain is None:
            return
        T = float(np.abs(B[:, 0]).max()) * self.Rp if B.size else 0.0
        self._newton_N = max(T / (self.nc * self.nd * self.a), NEWTON_FORCE_N) if first else 0.0

    def _hole_offsets(self, th_in: np.ndarray, x: np.ndarray, poses: tuple | None = None) -> np.ndarray:
        """Hole minus cam centre (N, nd, nc, 2) mm, fixed frame, at the states x (floats included); ``poses``:
        the disc poses ``(cen, ang)`` of those states if already known."""
        to, ps, shift, turn = self._unpack(th_in, x)
        cen, ang = self._poses(th_in, x) if poses is None else poses
        c, sn = np.cos(ang)[:, :, None], np.sin(ang)[:, :, None]
        h = self.geom.disc_holes[None]
        holes = cen[:, :, None] + np.stack([c * h[..., 0] - sn * h[..., 1], sn * h[..., 0] + c * h[..., 1]], axis=-1)
        return holes - np.swapaxes(self.geom.cam_centers(to, ps), 1, 2)

    def _hole_arms(self, th_in: np.ndarray, x: np.ndarray, law: ContactLaw | None = None, exact: bool = False):
        """The cam-bearing model at the states x, row by row (None without floating discs).

        Option spring: the disc holes relative to their disc's centre, turned with the disc, divided by the
        turn lever ``a`` (N, nd, nc, 2). Chain: the bearing deflections linearised in the state
        (:meth:`_chain_raw`); with ``exact`` the supports' exact tangent condensed onto the contacts'
        coordinates (:meth:`_condense`, for the unit-load forces).

        The inner solve takes them at its linearisation point (like the contact gaps); the outer iteration
        re-evaluates them, so the converged state is exact."""
        if not self.float_discs:
            return None
        rigid = law is not None and law.rigid
        self._spring_k = min(self.bearing_k, RIGID_LIMIT_SPRING_K) if rigid else self.bearing_k
        if self.chain is not None:
            if exact:                                     # the finishing of a solution: its three uses share one
                raw = self._chain_raw(th_in, x, law)
                self._raw_last = (th_in, x, raw)
                return self._condense(x, raw, 0.0)
            return self._chain_raw(th_in, x, law)
        return self._disc_arms(th_in, x)

    def _disc_arms(self, th_in: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The disc holes relative to their disc's centre, turned with the disc's kinematic pose (the rigid fit to
        its cams, without its floats), divided by the turn lever ``a`` (N, nd, nc, 2): a hole moves by the disc's
        shift plus its turn times ``perp(arm)`` (the floats' columns of the cam-bearing models)."""
        to, ps, _, _ = self._unpack(th_in, x)
        _, ang = self.geom.disc_poses(to, ps)
        c, sn = np.cos(ang)[:, :, None], np.sin(ang)[:, :, None]        # (N, nd, 1)
        h = self.geom.disc_holes[None]                                    # (1, nd, nc, 2)
        hx, hy = h[..., 0], h[..., 1]
        return np.stack([c * hx - sn * hy, sn * hx + c * hy], axis=-1) / self.a

    _raw_last: tuple | None = None

    def _finish_raw(self, th: np.ndarray, x: np.ndarray, law: ContactLaw) -> np.ndarray:
        """The chain's linearisation at a solution (the one the unit-load forces made, if at the same states)."""
        if self._raw_last is not None and self._raw_last[0] is th and self._raw_last[1] is x:
            return self._raw_last[2]
        return self._chain_raw(th, x, law)

    def _chain_raw(self, th_in: np.ndarray, x: np.ndarray, law: ContactLaw | None) -> np.ndarray:
        """The bearing deflections linearised at x, ``d = c0 + D x`` (hole minus cam minus the crank's
        displacement at the cam plane), packed per row: ``[rigid flag, c0 (nd nc 2), D (nd nc 2 ndof),
        t (nc 2)]`` with t the unit tangents of the cranks' circle at x (the direction in which the carrier end
        plate's turn carries journal B, frozen at the linearisation like the offsets)."""
        N, nd, nc, D = x.shape[0], self.nd, self.nc, self.ndof
        nk = 1 + nc
        to, _, _, _ = self._unpack(th_in, x)
        arms = self._disc_arms(th_in, x)
        Dm = np.zeros((N, nd, nc, 2, D))
        hit = getattr(self, "_stack_poses", None)
        if (hit is not None and hit[1].shape == x.shape and np.array_equal(hit[1], x) and np.array_equal(hit[0], th_in)):
            # the linearisation at these states posed the same neighbours (the states x, then x + h e_i and
            # x - h e_i for each kinematic coordinate, h = FD_STEP_MM): the same numbers without posing them again
            TH, XS, cen_all, ang_all = hit[2:]
            offs = self._hole_offsets(TH, XS, (cen_all, ang_all)).reshape(1 + 2 * nk, N, nd, nc, 2)
            d0, dd = offs[0], offs[1:]
        else:
            d0 = self._hole_offsets(th_in, x)
            X = np.repeat(x[None], 2 * nk, axis=0)
            for i in range(nk):
                X[2 * i, :, i] += FD_STEP_MM
                X[2 * i + 1, :, i] -= FD_STEP_MM
            dd = self._hole_offsets(np.tile(th_in, 2 * nk), X.reshape(-1, D)).reshape(2 * nk, N, nd, nc, 2)
        for i in range(nk):
            Dm[..., i] = (dd[2 * i] - dd[2 * i + 1]) / (2 * FD_STEP_MM)
        perp = np.stack([-arms[..., 1], arms[..., 0]], axis=-1)           # d d / d turn (scaled), (N, nd, nc, 2)
        for k in range(nd):
            b = 1 + nc + 3 * k
            Dm[:, k, :, 0, b] = 1.0
            Dm[:, k, :, 1, b + 1] = 1.0
            Dm[:, k, :, :, b + 2] = perp[:, k]
        Dm -= self._Y[None]
        d0 = d0 - np.einsum("kjad,nd->nkja", self._Y, x)                  # bearing deflection: minus the crank's
        c0 = d0 - np.einsum("nkjad,nd->nkja", Dm, x)
        rigid = np.full((N, 1), 1.0 if (law is not None and law.rigid) else 0.0)
        ax = self.geom.crank_axes(to)                                      # (N, nc, 2)
        tang = np.stack([-ax[..., 1], ax[..., 0]], axis=-1) / np.linalg.norm(ax, axis=-1)[..., None]
        return np.concatenate([rigid, c0.reshape(N, -1), Dm.reshape(N, -1), tang.reshape(N, -1)], axis=1)

    def _condense(self, x: np.ndarray, raw: np.ndarray, newton: float = 0.0) -> np.ndarray:
        """Second-order model of the supports at x with their own coordinates q eliminated (static
        condensation).

        With the gradient ``(g_a, g_q)`` and Hessian blocks of the exact support energy at x (a: the contacts'
        coordinates), ``dq = -H_qq^-1 (g_q + H_qa da)`` and the energy of a step da is
        ``E - g_q H_qq^-1 g_q / 2 + (g_a - H_aq Z_g) da + da^T (H_aa - H_aq Z_a) da / 2`` with
        ``Z_g = H_qq^-1 g_q``, ``Z_a = H_qq^-1 H_qa``. The cranks' blocks of H_qq do not couple; the carrier
        coordinate (which couples them) is eliminated after them, as a scalar. Packed per row:
        ``[x_a (nj), constant, gradient (nj), Hessian (nj nj), Z_g (nq), Z_a (nq nj)]``."""
        N = x.shape[0]
        nj, nc, pc = self.nj, self.nc, self.chain.per_crank
        ns = self.chain.n_carrier
        nq0, no = nc * pc, nj + ns                                          # crank coordinates; outer set [a, s]
        oidx = np.r_[np.arange(nj), [nj + nq0] * ns].astype(int)
        E, g, A = self._chain_energy(x, raw, True, newton)
        Ass = np.empty((N, nc, pc, pc))
        R = np.empty((N, nc, pc, no + 1))
        for j in range(nc):
            b = nj + j * pc
            Ass[:, j] = A[:, b:b + pc, b:b + pc]
            R[:, j, :, :no] = A[:, b:b + pc][:, :, oidx]
            R[:, j, :, no] = g[:, b:b + pc]
        Z = np.linalg.solve(Ass, R).reshape(N, nq0, no + 1)                 # [Z_o | Z_g] of the cranks
        corr = np.matmul(A[:, oidx, nj:nj + nq0], Z)                          # (N, no, no + 1)
        Ho = A[:, oidx][:, :, oidx] - corr[:, :, :no]
        go = g[:, oidx] - corr[:, :, no]
        const = E - 0.5 * np.einsum("nq,nq->n", g[:, nj:nj + nq0], Z[:, :, no])
        Za, Zg = Z[:, :, :nj], Z[:, :, no]
        if ns:                                                                # the carrier's s, then a alone
            hss, hsa, gs = Ho[:, nj, nj], Ho[:, nj, :nj], go[:, nj]
            Zsa, Zsg = hsa / hss[:, None], gs / hss
            Ha = Ho[:, :nj, :nj] - Ho[:, :nj, nj, None] * Zsa[:, None, :]
            ga = go[:, :nj] - Ho[:, :nj, nj] * Zsg[:, None]
            const = const - 0.5 * gs * Zsg
            Zqs = Z[:, :, nj]
            Za = np.concatenate([Za - Zqs[:, :, None] * Zsa[:, None, :], Zsa[:, None, :]], axis=1)
            Zg = np.concatenate([Zg - Zqs * Zsg[:, None], Zsg[:, None]], axis=1)
        else:
            Ha, ga = Ho, go
        return np.concatenate([x[:, :nj], const[:, None], ga, Ha.reshape(N, -1), Zg,
                               Za.reshape(N, -1)], axis=1)

    def _condensed(self, arms: np.ndarray):
        N, nj = arms.shape[0], self.nj
        nq = self.chain.n_dof
        o = np.cumsum([0, nj, 1, nj, nj * nj, nq, nq * nj])
        return (arms[:, o[0]:o[1]], arms[:, o[1]], arms[:, o[2]:o[3]], arms[:, o[3]:o[4]].reshape(N, nj, nj),
                arms[:, o[4]:o[5]], arms[:, o[5]:o[6]].reshape(N, nq, nj))

    def _chain_newton(self, x: np.ndarray, raw: np.ndarray, g_con: np.ndarray, H_con: np.ndarray,
                      b: np.ndarray, mu: np.ndarray, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Gradient (N, ndof) of the potential, the damped Newton step (N, ndof) with the supports inside, and
        the scale of the supports' forces (N,) N.

        ``g_con`` (N, nj), ``H_con`` (N, nj, nj): the contacts' gradient and Hessian in their coordinates; ``b``
        (N, ndof) the load vector; ``mu`` (N,) the Levenberg-Marquardt damping; ``floor`` (N, 1) its floor. The
        Hessian is assembled by blocks (contacts' coordinates a, each crank's support coordinates q) and solved by
        the Schur complement on the outer set ``[a, s]`` (the q blocks of different cranks do not couple; the
        carrier coordinate s couples them and joins a), both solves by :func:`batch_solve`."""
        ch = self.chain
        N, nj, nc, pc = x.shape[0], self.nj, self.nc, ch.per_crank
        ns, nq0 = ch.n_carrier, nc * pc
        no = nj + ns
        rigid, dcam, Dm, tang = self._chain_unpack(x, raw)
        _, gs, Hs, gc, Hc, Hqs, Hss = ch.energy(x, dcam, rigid, True, self._newton_N, tang)
        Da = Dm[..., :nj]                                                     # (N, nd, nc, 2, nj)
        HcDa = Hc[..., :, 0, None] * Da[..., 0, None, :] + Hc[..., :, 1, None] * Da[..., 1, None, :]
        D2 = Da.reshape(N, -1, nj)
        ga = g_con + np.matmul(gc.reshape(N, 1, -1), D2)[:, 0] + b[:, :nj]
        Aaa = H_con + np.matmul(D2.transpose(0, 2, 1), HcDa.reshape(N, -1, nj))
        # each hole's terms times the node weights L[r, k] of its crank's nodes (journals A, B, bending at plane k)
        # (tensordot: one matrix product over the cam planes k)
        Aqa = -np.tensordot(HcDa, ch.L, axes=([1], [1])).transpose(0, 1, 4, 2, 3).reshape(N, nc, pc, nj)
        gq = (gs[:, :nq0].reshape(N, nc, pc)
              - np.tensordot(gc, ch.L, axes=([1], [1])).transpose(0, 1, 3, 2).reshape(N, nc, pc)
              + b[:, nj:nj + nq0].reshape(N, nc, pc))
        Aqq = np.tensordot(Hc, ch.LLk, axes=([1], [2])).transpose(0, 1, 4, 2, 5, 3).reshape(N, nc, pc, pc) + Hs
        parts = [ga, gq.reshape(N, -1)]
        if ns:
            gS = gs[:, nq0] + b[:, nj + nq0]
            parts.append(gS[:, None])
        grad = np.concatenate(parts, axis=1)
        da = np.einsum("nii->ni", Aaa) + floor
        dq = np.einsum("njii->nji", Aqq) + floor[:, :, None]
        ia, iq = np.arange(nj), np.arange(pc)
        Aaa[:, ia, ia] += mu[:, None] * da
        Aqq[:, :, iq, iq] += mu[:, None, None] * dq
        # the outer set o = [a, s]: the contacts' coordinates and the carrier's (which couples the cranks)
        Aoo = np.zeros((N, no, no))
        Aoo[:, :nj, :nj] = Aaa
        rhs = [Aqa]
        go = ga
        if ns:
            Aoo[:, nj, nj] = Hss + mu * (Hss + floor[:, 0])
            rhs.append(Hqs[..., None])
            go = np.concatenate([ga, gS[:, None]], axis=1)
        Z = batch_solve(Aqq, np.concatenate(rhs + [gq[..., None]], axis=-1))    # (N, nc, pc, no + 1)
        Aoq = Aqa.transpose(0, 3, 1, 2).reshape(N, nj, nq0)
        if ns:
            Aoq = np.concatenate([Aoq, Hqs.reshape(N, 1, nq0)], axis=1)
        corr = np.matmul(Aoq, Z.reshape(N, nq0, no + 1))
        zo = batch_solve(Aoo - corr[:, :, :no], (go - corr[:, :, no])[:, :, None])[:, :, 0]
        zq = Z[..., no] - np.matmul(Z[..., :no], zo[:, None, :, None])[..., 0]
        # the forces in play in the supports (for the stationarity test: the gradient relative to them)
        scale = (np.linalg.norm(gc, axis=-1)[..., None] * np.abs(Dm).sum(axis=-1)).sum(axis=(1, 2, 3)) + np.abs(gs).sum(1)
        return grad, -np.concatenate([zo[:, :nj], zq.reshape(N, -1), zo[:, nj:]], axis=1), scale

    def _chain_recover(self, arms: np.ndarray, step: np.ndarray, tangent: bool = False) -> np.ndarray:
        """Step of the support coordinates (N, nq) that goes with the step ``step`` (N, nj) of the contacts'
        coordinates (``tangent``: the derivative only, without the Newton correction ``-Z_g``)."""
        _, _, _, _, Zg, Za = self._condensed(arms)
        dq = -np.matmul(Za, step[:, :, None])[:, :, 0]
        return dq if tangent else dq - Zg

    def _bearing(self, x: np.ndarray, arms: np.ndarray | None,
                 derivs: bool = True) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Energy (N,), gradient (N, ndof) and Hessian (N, ndof, ndof) of the cam-bearing model (the
        derivatives None when ``derivs`` is False)."""
        N = x.shape[0]
        if arms is None:
            return np.zeros(N), np.zeros((N, self.ndof)), np.zeros((N, self.ndof, self.ndof))
        if self.chain is not None:
            return self._chain_energy(x, arms, derivs, self._newton_N)
        nd, nc, kb = self.nd, self.nc, self._spring_k
        blk = x[:, 1 + nc:1 + nc + 3 * nd].reshape(N, nd, 1, 3)                       # disc shift x, y and turn
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

    def _chain_unpack(self, x: np.ndarray, arms: np.ndarray):
        """``(rigid, dcam (N, nd, nc, 2), D (N, nd, nc, 2, ndof), t (N, nc, 2))`` of a packed linearisation."""
        N, nd, nc, D = x.shape[0], self.nd, self.nc, self.ndof
        n8 = nd * nc * 2
        rigid = bool(arms[0, 0] > 0.5) if N else False
        c0 = arms[:, 1:1 + n8].reshape(N, nd, nc, 2)
        Dm = arms[:, 1 + n8:1 + n8 + n8 * D].reshape(N, nd, nc, 2, D)
        tang = arms[:, 1 + n8 + n8 * D:].reshape(N, nc, 2)
        return rigid, c0 + np.matmul(Dm.reshape(N, -1, D), x[:, :, None]).reshape(N, nd, nc, 2), Dm, tang

    def _chain_energy(self, x: np.ndarray, arms: np.ndarray, derivs: bool, newton: float = 0.0):
        rigid, dcam, Dm, tang = self._chain_unpack(x, arms)
        ch = self.chain
        E, g, H, gc, Hc, Hqs, Hss = ch.energy(x, dcam, rigid, derivs, newton, tang)
        if not derivs:
            return E, None, None
        N, D = x.shape[0], self.ndof
        D2 = Dm.reshape(N, -1, D)                                             # (N, nd nc 2, ndof)
        G = np.matmul(gc.reshape(N, 1, -1), D2)[:, 0]
        G[:, ch.base:] += g
        A = np.matmul(Hc, Dm).reshape(N, -1, D)                               # H_cam D, per hole
        Ht = np.matmul(D2.transpose(0, 2, 1), A)
        for j in range(self.nc):
            b = ch.base + j * ch.per_crank
            Ht[:, b:b + ch.per_crank, b:b + ch.per_crank] += H[:, j]
        if ch.n_carrier:
            i = D - 1
            Ht[:, ch.base:i, i] += Hqs.reshape(N, -1)
            Ht[:, i, ch.base:i] += Hqs.reshape(N, -1)
            Ht[:, i, i] += Hss
        return E, G, Ht

    def _chain_parts(self, th: np.ndarray, x: np.ndarray, dx: np.ndarray, law: ContactLaw,
                     per_crank: dict | None = None) -> dict[str, np.ndarray]:
        """Wind-up of the supports at the solution per unit-load state derivative ``dx`` (N, ndof) = dx/dT
        (``per_crank``: filled with each crank's share, :meth:`SupportChain.parts`)."""
        _, dcam, Dm, tang = self._chain_unpack(x, self._finish_raw(th, x, law))
        ddcam = np.einsum("nkjad,nd->nkja", Dm, dx)
        return self.chain.parts(x, dx, dcam, ddcam, law.rigid, tang, per_crank)

    def chain_cam_forces(self, th: np.ndarray, x: np.ndarray, law: ContactLaw) -> np.ndarray:
        """Forces of the cams on the discs (N, nd, nc, 2) N, fixed frame, at the states x."""
        rigid, dcam, _, _ = self._chain_unpack(x, self._finish_raw(th, x, law))
        ch = self.chain
        K, p, cs = (ch.rigid_K, 1.0, 0.0) if rigid else (ch.sup.cam_K, BEARING_EXP, ch.sup.cam_seat_c)
        return -radial_law(dcam, K, p, ch.c, cs=cs)[1]
