"""Quasi-static meshing equilibrium of the RV reducer for prescribed input angles.

Model (derivation and assumptions in docs/physics.md):

- Coordinates per step: carrier (output) angle ``theta_out`` and the absolute angles ``psi_j`` of the
  n cranks (two by default, three on the larger frames); with a cam-bearing clearance, three more per disc
  (translation and rotation of the disc relative to the least-squares fit of its holes to its cams).
- Disc k's pose follows the cams of all cranks (rigid least-squares fit of its n holes,
  :meth:`rvcad.geometry.ReducerGeometry.disc_poses`): with rigid supports the over-constraint of a disc held by
  n cranks (2n - 3 hole-cam mismatches) is resolved there, with floating discs in the bearings (an equal,
  isotropic spring per hole, whose least-energy pose is that fit); the cranks share the load through the pin
  contacts of both discs and through their own sun-planet meshes.
- Contacts: every pin with both discs (exact signed gap, two-sided by geometry) and the sun with
  each planet on both flanks (the coast flank is open by the stage I backlash, zero by default).
  Each carries ``F = K delta**n``; stored energy ``K delta**(n+1)/(n+1)``.
- Load: the output torque T resists the motion, potential ``direction * T * theta_out``.
- Equilibrium = minimum of the total potential (convex in the linearised gaps). It is found by
  an outer loop that evaluates the contact provider (analytic or fcl) at the current state and
  linearises each gap with its normal, and an inner Levenberg-Marquardt Newton loop on the
  linearised, convex problem. The outer loop repeats until the state moves less than
  ``Tolerances.solver_angle_rad`` (converted to mm at the pin circle).

Internally the unknowns are scaled to mm of motion: ``x0 = Rp * (theta_out - theta_in / i)``,
``x_j = e * (psi_j - psi_ideal)``, disc shifts in mm and disc turns times the crank radius.
"""
from __future__ import annotations

import math
import numpy as np

from rvcad.geometry import ReducerGeometry
from rvcad.tolerances import TOL, Tolerances
from rvdyn.contacts import ContactLaw
from rvdyn.linearise import LinearisationMixin
from rvdyn.options import model_choice, model_value, parse_model
from rvdyn.physical import PhysicsMixin
from rvdyn.results import (ARCSEC_PER_RAD, MAX_ELASTIC_PENETRATION_MM, InterferenceError,  # noqa: F401 (API)
                           ResultsMixin, Solution)
from rvdyn.support_eq import SupportChain, SupportMixin


#: Largest change of a state coordinate (mm) in one outer iteration (trust region of the linearised gaps).
OUTER_TRUST_MM = 0.01

#: Inexact inner solves (the physical law with the supports inside): a state whose step in this outer iteration
#: exceeds LOOSE_MIN_STEP outer tolerances stops its inner Newton iterations once a step moves it less than
#: INNER_LOOSE times that step (inexact Newton, Dembo, Eisenstat & Steihaug, SIAM J. Numer. Anal. 19, 1982): the
#: minimum of a linearisation the outer loop redoes is not worth the last one or two Newton iterations; the
#: outer loop's last iteration (a step below the tolerance) is solved in full, so the equilibrium is the same.
INNER_LOOSE = 1e-2
LOOSE_MIN_STEP = 100.0

#: A solve of at least this many angles with the supports inside starts from a pilot solve at input angle 0
#: (:meth:`QuasiStaticSolver._pilot_start`), with this Levenberg-Marquardt damping (the pilot's state is near each
#: angle's equilibrium, so the first Newton steps need not be damped as from the ideal kinematics, damping 1).
PILOT_MIN_ROWS = 64
PILOT_MU = 1e-3

#: Levenberg-Marquardt damping a warm-started solve (``x_init`` of :meth:`QuasiStaticSolver.solve_many`, a nearby
#: solve's converged states) starts with: as the pilot start's, its rows are near their equilibrium.
WARM_MU = PILOT_MU

#: Stopping on the contraction of the outer iteration (:meth:`QuasiStaticSolver._outer`): the outer loop minimises
#: the potential with the gaps linearised, so its Hessian lacks the contact forces times the gaps' curvature
#: (the geometric stiffness, relative size delta / rho: contact deflection over the profile's radius of curvature,
#: about 1e-2) and it converges linearly: each step about q = |dx_k| / |dx_(k-1)| of the one before (measured
#: 0.4-1 % on the loop's conditions). A state whose step dx_k is uncut and exact (below ``LOOSE_MIN_STEP``
#: tolerances, where the inner solve is not stopped early), with q <= CONTRACTION_MAX, is then within
#: ``q / (1 - q) |dx_k|`` (the geometric series of the remaining steps) of its equilibrium, and stops once that is
#: below the tolerance, without the further iteration whose own step would be below it. Only warm states (solves
#: given ``x_init``, e.g. the runner's warm starts of a closed loop) stop so; a cold solve keeps the plain step
#: test, so its results (and the references of the tests) are unchanged bit for bit.
CONTRACTION_MAX = 0.2

#: Largest trust radius (mm) a batch (:meth:`QuasiStaticSolver.solve_many`) grows to: the largest penetration
#: an elastic solution may have, so one outer step never crosses more than the elastic range.
MAX_TRUST_MM = 0.1


def law_from_model(model: dict, rigid: bool = False) -> ContactLaw:
    """The contact law a case's ``model`` object asks for (default: ``rvdyn.options.DEFAULT_CONTACT``)."""
    m = parse_model(model)
    return ContactLaw(K=model_value(m, "contact_K_N_per_mm_n"), n=model_value(m, "contact_n"), rigid=rigid,
                      kind=model_choice(m, "contact"))


class QuasiStaticSolver(LinearisationMixin, SupportMixin, PhysicsMixin, ResultsMixin):
    """Quasi-static equilibrium for one case geometry with one contact provider.

    Parameters
    ----------
    geom : ReducerGeometry
    contacts : provider with ``disc_distance`` and ``stage1_gaps`` (analytic or fcl)
    law : ContactLaw
    tol : Tolerances
    """

    #: Compute the wind-up parts (:attr:`Solution.parts_rad`, unit-load method) and the cam forces at each
    #: solution; False (:func:`rvdyn.te.run_te`, which reports neither) leaves them out, the TE is the same bit for bit.
    want_parts: bool = True
    #: At most this many outer iterations (linearisations) for a warm-started state (``x_init``); None (default):
    #: to convergence. 1 is a *sensitivity solve*: the state moves by one linearisation from its start, a nearby
    #: equilibrium, and stops there; its TE change from the start is within about 1 % of the converged change
    #: (the outer loop's contraction, docs/physics.md "Sensitivity solves"). Cold states always converge.
    max_outer: int | None = None

    def __init__(self, geom: ReducerGeometry, contacts, law: ContactLaw | None = None,
                 tol: Tolerances = TOL) -> None:
        self.geom = geom
        self.contacts = contacts
        m = parse_model(geom.case.model)
        self.model = m
        self.law = law if law is not None else law_from_model(m)
        self.tol = tol
        d = geom.design
        self.clearance = model_value(m, "cam_bearing_clearance_um") * 1e-3
        self.bearing_k = model_value(m, "cam_bearing_stiffness_N_per_um") * 1e3
        self._spring_k = self.bearing_k
        self.nc, self.nd, self.zp = d.n_cranks, d.n_discs, d.z_pins
        # the physical law with elastic supports: bearings and cranks inside the equilibrium (floating discs
        # and crank coordinates, rvdyn.support_eq); otherwise floating discs only with a cam-bearing clearance
        self.chain_on = self.law.kind == "physical" and model_choice(m, "supports") == "elastic"
        # a cam-bearing clearance, or a finite bearing stiffness, floats the discs (continuous in the clearance:
        # the default stiffness is the rigid limit's penalty, so clearance -> 0 is the fixed-disc model)
        self.float_discs = self.clearance > 0.0 or self.chain_on or self.bearing_k < ContactLaw.RIGID_K
        self.nj = 1 + self.nc + (3 * self.nd if self.float_discs else 0)     # coordinates of the contacts
        self.ndof = self.nj
        self.Rp = d.pin_circle_radius_mm
        self.e = d.eccentricity_mm
        self.a = d.center_distance_mm
        self.friction_Nmm = model_value(m, "friction_torque_Nm") * 1e3
        self.compliance_rad_per_Nmm = model_value(m, "torsional_compliance_arcsec_per_Nm") / ARCSEC_PER_RAD * 1e-3
        self.pressure_limit = model_value(m, "contact_pressure_limit_MPa")
        self._setup_physical(d, m)
        self.chain = None
        if self.chain_on:
            self.chain = SupportChain(self.supports, self.nd, self.nc, self.clearance, self.nj)
            self.ndof = self.nj + self.chain.n_dof
            self._Y = self.chain.y_matrix(self.ndof)

    # ------------------------------------------------------------------ solve
    def _load_Nmm(self, load_Nm: float) -> float:
        if self.law.rigid or load_Nm == 0.0:
            return ContactLaw.RIGID_LOAD_NMM
        return load_Nm * 1e3 + self.friction_Nmm

    def _law(self, load_Nm: float) -> ContactLaw:
        if load_Nm == 0.0 and not self.law.rigid:
            return ContactLaw(self.law.K, self.law.n, rigid=True, kind=self.law.kind)
        return self.law

    def _inner(self, th_in, x0, G, J, b, law: ContactLaw, mu: np.ndarray, max_iter: int = 200,
               floor_k: np.ndarray | None = None, arms: np.ndarray | None | bool = False
               ) -> tuple[np.ndarray, np.ndarray]:
        """Minimise the linearised potential around x0; returns the step (N, ndof) and the linearised potential
        at x0 itself (N,) N mm, which the solve evaluates first and the outer loop's trust region needs too.

        ``b`` is the load vector (ndof,) or one per state (N, ndof). ``mu`` (N,) is the Levenberg-Marquardt
        damping, updated in place so that the next outer iteration starts from where this one ended.
        ``floor_k`` (N,): the law's typical working stiffness per state (default ``law.floor_stiffness()``;
        the physical law's depends on the contacts of its own solve). ``arms``: :meth:`_hole_arms` at
        ``(th_in, x0, law)`` if the caller has them (False: computed here).
        """
        N, M, nj = J.shape                            # nj: the contacts' coordinates, the first of the state
        D = self.ndof
        if arms is False:
            arms = self._hole_arms(th_in, x0, law)
        B = np.broadcast_to(b, (N, D))
        step = np.zeros((N, D))
        # damping floor: about a quarter of the contacts at 1 um of penetration (typical working stiffness)
        fk = np.full(N, law.floor_stiffness()) if floor_k is None else floor_k
        floor = (fk * max(1.0, M / 4.0))[:, None]
        eye = np.eye(D)

        # a law that gives the energy, force and stiffness of one evaluation (the physical law): the line search
        # keeps the force and stiffness of the step it accepts for the next Newton step (the same numbers)
        keep_fk = hasattr(law, "energy_force_stiffness")
        if keep_fk:
            E0, F_all, K_all = energy_sub(self, x0, G, J, B, law, step, arms, fk=True)
        else:
            E0 = energy_sub(self, x0, G, J, B, law, step, arms)
            F_all = K_all = None
        E_start = E0.copy()                           # the linearised potential at x0 itself (returned)
        Jnorm = _row_norm(J)
        bnorm = np.linalg.norm(B, axis=1)
        tol_mm = self.tol.solver_angle_rad * self.Rp * 1e-2
        loose = self.chain is not None
        active = np.ones(N, dtype=bool)
        for it in range(max_iter):
            idx = np.nonzero(active)[0]
            if idx.size == 0:
                break
            if it == 1 and self.chain is not None:
                self.newton_load(B, False)            # the load estimate shaped the first step: exact tangents now
            every = idx.size == N                     # all states still iterating: views, no copies
            sel = slice(None) if every else idx
            s = step[sel]
            Gi, Ji = G[sel], J[sel]
            if keep_fk:
                f, k = (F_all, K_all) if every else (F_all[idx], K_all[idx])
            else:
                delta = -(Gi + _jdot(Ji, s[:, :nj]))
                f, k = law.force_stiffness(delta, idx)
            grad, dstep, sup_scale = self._newton_step(x0, s, idx, sel, Ji, f, k, B, arms, mu, floor, eye)
            best_E, best_s, accepted_full = self._line_search(x0, G, J, Gi, Ji, B, law, arms, s, dstep, idx, sel,
                                                              E0[idx].copy(), F_all, K_all, tol_mm if loose else None)
            moved = np.linalg.norm(best_s - s, axis=1)
            step[idx] = best_s
            E0[idx] = best_E
            mu[idx] = np.where(accepted_full, np.maximum(mu[idx] / 10.0, 1e-12), np.minimum(mu[idx] * 10.0, 1e12))
            # stationarity of the potential relative to the forces in play, plus a settled step
            scale = bnorm[idx] + np.einsum("nm,nm->n", np.abs(f), Jnorm[idx])
            if nj != D:
                scale = scale + sup_scale
            done = (moved < tol_mm) & (np.linalg.norm(grad, axis=1) <= 1e-7 * scale)
            if loose:
                # inexact Newton: a state still far from its equilibrium (step so far > LOOSE_MIN_STEP outer
                # tolerances) stops once its Newton step is below INNER_LOOSE of that step: the outer loop
                # linearises again there, and its last iteration (a step below the tolerance) is solved in full
                tot = np.linalg.norm(best_s, axis=1)
                done |= (tot > LOOSE_MIN_STEP * 100.0 * tol_mm) & (moved < INNER_LOOSE * tot)
            stuck = (moved == 0) & (mu[idx] >= 1e12)
            active[idx[done | stuck]] = False
        return step, E_start

    def _newton_step(self, x0: np.ndarray, s: np.ndarray, idx: np.ndarray, sel: slice | np.ndarray, Ji: np.ndarray,
                     f: np.ndarray, k: np.ndarray, B: np.ndarray, arms: np.ndarray | None, mu: np.ndarray,
                     floor: np.ndarray, eye: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Gradient (n, ndof) N of the linearised potential at the steps ``s`` (mm) of the states ``idx`` (``sel``:
        the same rows or all), their damped Newton step (n, ndof) mm and, supports inside, the supports' force scale
        (n,) N (else None). ``f``, ``k``: contact forces (N) and stiffnesses (N/mm) at ``s``."""
        if Ji.shape[2] == self.ndof:
            grad = -np.matmul(f[:, None, :], Ji)[:, 0] + B[sel]
            H = np.matmul(Ji.transpose(0, 2, 1) * k[:, None, :], Ji)
            if arms is not None:
                _, gb, Hb = self._bearing(x0[idx] + s, arms[idx])
                grad = grad + gb
                H = H + Hb
            diag = np.einsum("ndd->nd", H) + floor[idx]
            A = H + mu[idx, None, None] * diag[:, :, None] * eye[None]
            return grad, -np.linalg.solve(A, grad[:, :, None])[:, :, 0], None
        # supports inside the equilibrium (rvdyn.support_eq)
        return self._chain_newton(x0[idx] + s, arms[idx], -np.matmul(f[:, None, :], Ji)[:, 0],
                                  np.matmul(Ji.transpose(0, 2, 1) * k[:, None, :], Ji), B[sel], mu[idx], floor[idx])

    def _line_search(self, x0: np.ndarray, G: np.ndarray, J: np.ndarray, Gi: np.ndarray, Ji: np.ndarray,
                     B: np.ndarray, law: ContactLaw, arms: np.ndarray | None, s: np.ndarray, dstep: np.ndarray,
                     idx: np.ndarray, sel: slice | np.ndarray, best_E: np.ndarray, F_all: np.ndarray | None,
                     K_all: np.ndarray | None, tiny_mm: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Backtracking on the (convex) linearised potential along the Newton steps ``dstep`` (mm) from the steps ``s``
        of the states ``idx``: the first step length that lowers it below ``best_E`` (N mm, updated). Returns the
        potential (N mm), the step (mm) and whether the full length was taken; the accepted forces (N) and stiffnesses
        (N/mm) go to ``F_all``, ``K_all`` if given. ``tiny_mm``: the inner tolerance (mm) with the supports inside."""
        keep_fk = F_all is not None
        best_s = s.copy()
        accepted_full = np.zeros(idx.size, dtype=bool)
        pending = np.ones(idx.size, dtype=bool)
        # supports inside (loose): a Newton step shorter than the inner tolerance that does not lower the
        # potential at full length (rounding at the minimum) is not shortened further: a shorter one would
        # move the state by less than the tolerance too (the same convergence test, no evaluations)
        tiny = (np.linalg.norm(dstep, axis=1) < tiny_mm) if tiny_mm is not None else None
        for alpha in (1.0, 0.5, 0.25, 0.1, 0.02):
            w = np.nonzero(pending)[0]
            if w.size == 0:
                break
            if w.size == idx.size:
                cand = s + alpha * dstep
                Ec = energy_sub(self, x0[sel], Gi, Ji, B[sel], law, cand, None if arms is None else arms[sel],
                                rows=idx, fk=keep_fk)
            else:
                cand = s[w] + alpha * dstep[w]
                Ec = energy_sub(self, x0[idx[w]], G[idx[w]], J[idx[w]], B[idx[w]], law, cand,
                                None if arms is None else arms[idx[w]], rows=idx[w], fk=keep_fk)
            if keep_fk:
                Ec, fc, kc = Ec
            upd = Ec < best_E[w]
            best_E[w[upd]] = Ec[upd]
            best_s[w[upd]] = cand[upd]
            if keep_fk:
                F_all[idx[w[upd]]] = fc[upd]
                K_all[idx[w[upd]]] = kc[upd]
            if alpha == 1.0:
                accepted_full[w[upd]] = True
                if tiny is not None:
                    pending[w[tiny[w]]] = False
            pending[w[upd]] = False
        return best_E, best_s, accepted_full

    def _check_solve_args(self, theta_in, direction, load_Nm) -> np.ndarray:
        if direction not in (1, -1):
            raise ValueError(f"direction {direction!r} must be +1 or -1")
        if not (math.isfinite(load_Nm) and load_Nm >= 0):
            raise ValueError(f"load_Nm {load_Nm} must be a finite number >= 0")
        th = np.atleast_1d(np.asarray(theta_in, dtype=float))
        if not np.all(np.isfinite(th)):
            raise ValueError("theta_in contains NaN or inf")
        return th

    def solve(self, theta_in: np.ndarray, direction: int = 1, load_Nm: float = 20.0,
              chunk: int | None = None, x_init: np.ndarray | None = None) -> Solution:
        """Equilibrium at each input angle.

        Parameters
        ----------
        theta_in : (N,) rad
            Input (sun) angles.
        direction : int
            +1: input angle increasing; -1: decreasing. The load resists the motion.
        load_Nm : float
            Output load torque, N m (0: the rigid single-flank limit under a vanishing load).
        chunk : int or None
            Steps solved together. ``None``: all at once (analytic provider); 1: step by step, each
            started from the previous solution (fcl provider: fewer distance queries).
        x_init : (N, ndof) or None
            Start states (scaled coordinates, e.g. :attr:`Solution.x` of a nearby solve at these angles: a warm
            start, with the Levenberg-Marquardt damping ``WARM_MU``); default the ideal kinematics, or with the
            supports inside and ``chunk`` None, at least ``PILOT_MIN_ROWS`` angles, the pilot start
            (:meth:`_pilot_start`). The equilibrium is the same within the solver tolerance.
        """
        th = self._check_solve_args(theta_in, direction, load_Nm)
        N = th.size
        law = self._law(load_Nm)
        B = np.zeros((N, self.ndof))
        B[:, 0] = direction * self._load_Nmm(load_Nm) / self.Rp
        dirs = np.full(N, direction)
        x = np.zeros((N, self.ndof)) if x_init is None else self._check_start(x_init, N, "x_init")
        mu0 = 1.0 if x_init is None else WARM_MU
        if x_init is None and chunk is None and self.chain is not None and N >= PILOT_MIN_ROWS:
            x[:], mu0 = self._pilot_start(th, direction, load_Nm, law)
        chunk = N if chunk is None else max(1, int(chunk))
        out = self._outputs(N)
        iters = 0
        prev: np.ndarray | None = None
        for s0 in range(0, N, chunk):
            sl = slice(s0, min(N, s0 + chunk))
            xs = x[sl]
            if x_init is None and prev is not None:
                xs[:] = prev
            used = self._outer(th[sl], xs, dirs[sl], B[sl], law, [(0, sl.stop - s0)], out, s0, [load_Nm], mu0=mu0,
                               contraction=x_init is not None)
            iters = max(iters, used[0])
            prev = xs[-1].copy()
        return self._finish_rows(th, x, direction, load_Nm, law, iters, out, slice(0, N))

    def _check_start(self, x_init, n: int, field: str) -> np.ndarray:
        """A copy of start states (n, ndof) as float64; ValueError naming ``field`` if the shape or a value is wrong."""
        xi = np.array(x_init, dtype=float)
        if xi.shape != (n, self.ndof) or not np.all(np.isfinite(xi)):
            raise ValueError(f"{field} must be a finite array of shape {(n, self.ndof)} (angles, state coordinates); "
                             f"got shape {xi.shape}")
        return xi

    def _pilot_start(self, th_in: np.ndarray, direction: int, load_Nm: float,
                     law: ContactLaw) -> tuple[np.ndarray, float]:
        """Start states (N, ndof) of the rows of a long solve with the supports inside, and the Levenberg-Marquardt
        damping to start them with.

        One outer iteration of the solve at input angle 0 (the same pilot for every set of angles, so each
        angle's result still depends on that angle alone), carried to each row's angles: the output, crank and
        disc-turn coordinates and the carrier end plate's as they are; the disc shifts (fixed frame) turned by the
        row's crank angle against the pilot's (they follow the eccentric), the crank nodes' displacements by its
        output angle (they follow the crank's place on the carrier). Measured on the nominal physical solve: these
        describe every row's equilibrium to 1e-5 mm (disc shifts, 4e-4 mm) and 2e-4 mm (journals, 1.3e-3 mm). The
        rows then start near their equilibrium and take fewer Newton and outer iterations; the equilibrium is
        the same to the solver tolerance."""
        th = np.zeros(1)
        B = np.zeros((1, self.ndof))
        B[:, 0] = direction * self._load_Nmm(load_Nm) / self.Rp
        xp = np.zeros((1, self.ndof))
        G, J = self._linearise(th, xp, direction)
        step_law = self._step_law(law, self._line_last()[0] if law.physical else None)
        self.newton_load(B, True)
        dx, _ = self._inner(th, xp, G, J, B, step_law, np.ones(1))
        if not np.all(np.isfinite(dx)):                  # no usable pilot: the rows start as without one
            return np.zeros((th_in.size, self.ndof)), 1.0
        xp += dx * min(1.0, OUTER_TRUST_MM / max(float(np.abs(dx).max()), 1e-300))
        to_r, psi_r = self.geom.ideal_state(th_in)
        to_p, psi_p = self.geom.ideal_state(th)
        x = np.repeat(xp, th_in.size, axis=0)

        def turn(i: int, a: np.ndarray) -> None:
            c, sn = np.cos(a), np.sin(a)
            vx, vy = xp[0, i], xp[0, i + 1]
            x[:, i] = c * vx - sn * vy
            x[:, i + 1] = sn * vx + c * vy

        for k in range(self.nd):
            turn(1 + self.nc + 3 * k, psi_r[:, 0] - psi_p[0, 0])
        for j in range(self.nc):
            for m in range(2 + self.nd):
                turn(self.nj + j * self.chain.per_crank + 2 * m, to_r - to_p[0])
        return x, PILOT_MU

    def solve_many(self, theta_in: list, directions: list, loads_Nm: list,
                   expand_trust: bool = True, errors: str = "raise", x_init: list | None = None) -> list:
        """Equilibria of several solves of this case in one batch: solve i has the input angles
        ``theta_in[i]`` (rad, in the order of motion), direction ``directions[i]`` and load ``loads_Nm[i]``
        (N m, > 0: the batch shares the contact law, and load 0 is the rigid limit's).

        The states of all solves are linearised and minimised together (one provider call and one inner
        solve per outer iteration for the whole batch); each solve stops on its own convergence test, so
        each result equals :meth:`solve` of that solve alone within the solver tolerance (the foot-point
        searches of a batch share their iteration count, which moves the results by rounding only).

        ``expand_trust``: a state whose outer step was cut to its trust radius and whose potential then fell
        as the linearisation predicted (ratio of actual to predicted decrease > 0.75) gets 4 times the radius
        (up to ``MAX_TRUST_MM``) for its next step, the standard trust-region update (Nocedal & Wright,
        Numerical Optimization, 2nd ed., algorithm 4.1); a reversing step halves it as in :meth:`solve`.
        States far from their equilibrium (the start, the ideal kinematics, is often 0.04 mm away) then take
        two or three outer iterations to get there instead of four or five. The equilibrium is the same to the
        solver tolerance. False: the fixed radius of :meth:`solve` (a batch of one solve is then that solve).

        ``errors``: ``"raise"`` (default) raises the first solve's error (an InterferenceError, or a
        RuntimeError when it does not converge); ``"return"`` puts the error in that solve's place and
        returns the other solutions.

        ``x_init``: per solve, its start states (n_i, ndof) in scaled coordinates (:attr:`Solution.x` of a
        nearby solve at the same angles, e.g. the state a perturbation is taken from) or None (the default
        start, zeros: the ideal kinematics). A warm solve starts its Levenberg-Marquardt damping at
        ``WARM_MU`` (near its equilibrium) and converges to the same equilibrium within the solver tolerance.
        """
        if errors not in ("raise", "return"):
            raise ValueError(f"errors {errors!r} must be 'raise' or 'return'")
        if not (len(theta_in) == len(directions) == len(loads_Nm)) or len(theta_in) == 0:
            raise ValueError(f"theta_in, directions and loads_Nm must be equally long, non-empty lists; got "
                             f"{len(theta_in)}, {len(directions)}, {len(loads_Nm)}")
        ths, bounds = [], []
        for th, d, L in zip(theta_in, directions, loads_Nm):
            t = self._check_solve_args(th, d, L)
            if not L > 0:
                raise ValueError(f"load_Nm {L!r} must be > 0 in a batch (solve load 0, the rigid limit, with solve())")
            bounds.append((sum(len(a) for a in ths), sum(len(a) for a in ths) + t.size))
            ths.append(t)
        th = np.concatenate(ths)
        N = th.size
        B = np.zeros((N, self.ndof))
        dirs = np.empty(N, dtype=int)
        for (a, b), d, L in zip(bounds, directions, loads_Nm):
            B[a:b, 0] = d * self._load_Nmm(L) / self.Rp
            dirs[a:b] = d
        law = self._law(loads_Nm[0])
        x = np.zeros((N, self.ndof))
        mu0 = np.ones(N)
        given = np.zeros(N, dtype=bool)              # the states of solves with start states (warm)
        if x_init is not None:
            if len(x_init) != len(bounds):
                raise ValueError(f"x_init has {len(x_init)} entries for {len(bounds)} solves")
            for i, ((a, b), xi) in enumerate(zip(bounds, x_init)):
                if xi is None:
                    continue
                x[a:b] = self._check_start(xi, b - a, f"x_init[{i}]")
                mu0[a:b] = WARM_MU
                given[a:b] = True
        out = self._outputs(N)
        used = self._outer(th, x, dirs, B, law, bounds, out, 0, list(loads_Nm), expand=expand_trust,
                           collect=errors == "return", mu0=mu0, warm=bool(np.any(mu0 < 1.0)), contraction=given)
        res: list = []
        for (a, b), d, L, it in zip(bounds, directions, loads_Nm, used):
            if isinstance(it, Exception):
                res.append(it)
                continue
            try:
                res.append(self._finish_rows(th[a:b], x[a:b], d, L, law, it, out, slice(a, b)))
            except InterferenceError as err:
                if errors == "raise":
                    raise
                res.append(err)
        return res

    def _outputs(self, N: int) -> dict[str, np.ndarray]:
        """Arrays of the converged linearisation (gaps, normals, Jacobians, Johnson constants, radii)."""
        M = self.nd * self.zp + 2 * self.nc
        return {"G": np.empty((N, M)), "nrm": np.empty((N, self.nd, self.zp, 2)), "J": np.empty((N, M, self.nj)),
                "C": np.empty((N, self.nd * self.zp)), "R": np.empty((N, self.nd * self.zp))}

    def _outer(self, th, x, dirs, B, law, bounds: list[tuple[int, int]], out: dict, offset: int,
               loads: list[float], expand: bool = False, collect: bool = False,
               mu0: float | np.ndarray = 1.0, warm: bool = False, contraction: bool | np.ndarray = False) -> list:
        """Outer iterations of the solves whose rows are ``bounds`` (row ranges of th and x, solved together,
        each to its own convergence test; ``loads`` N m, for the messages); x is updated in place, the converged
        linearisation is written to ``out`` at row ``offset + row``. ``expand``: grow the trust radius of states
        whose cut step the linearisation predicted well (see :meth:`solve_many`). Returns the outer iterations
        each solve used; a solve that does not converge raises its error (:meth:`_unconverged`), or with
        ``collect`` has the error in its place. ``contraction`` (bool or (N,) bool): the states that may stop on
        the outer loop's contraction (``CONTRACTION_MAX``; the warm ones)."""
        N = th.size
        tol_mm = self.tol.solver_angle_rad * self.Rp
        trs = (np.full(N, OUTER_TRUST_MM), np.zeros((N, self.ndof)), np.zeros(N, dtype=bool), np.zeros(N),
               np.zeros(N), np.full(N, np.inf))      # the trust region's state per row (:meth:`_trust_step`)
        mu_all = np.full(N, mu0)
        used = [0] * len(bounds)
        active = list(range(len(bounds)))
        prev_rows = None
        may_settle = np.broadcast_to(np.asarray(contraction, dtype=bool), (N,))   # warm states: the contraction stop
        # one solve with the supports inside: each state leaves the outer loop at its own convergence (the
        # damping floor of the inner loop fixed at the first linearisation's), so a few slow states do not keep
        # the others iterating, and no state's result depends on the others'
        # (a batch of several solves likewise, each state on its own test: measured on the loop's 5 conditions x
        # 280 angles, one state in 1,400 whose contact flips between linearisations needed ten more outer
        # iterations than the rest, and kept its whole solve of 280 states iterating with it)
        # (and with the impact law a warm batch, some of whose solves have start states: a cold batch of the impact
        # law iterates each solve to its slowest state, as it always did, bit for bit)
        per_row = self.chain is not None or (len(bounds) > 1 and warm)
        row_on = np.zeros(N, dtype=bool)
        for a, b in bounds:
            row_on[a:b] = True
        fk0 = None
        fk_rows = np.full(N, np.nan)                 # a batch's floor stiffness of each state, fixed at its first
        solves = (th, x, dirs, law, loads, bounds, collect)     # what the errors of unconverged solves need
        for it in range(self.tol.solver_max_iter):
            if not active:
                break
            rows, n_rows, locs, prev_rows = self._outer_rows(per_row, bounds, active, row_on, prev_rows)
            xs = x[rows]
            G, J = self._linearise(th[rows], xs, dirs[rows] if len(bounds) > 1 else dirs[0])
            C = self._line_last()[0] if law.physical else None
            step_law = self._step_law(law, C)
            floor_k = None
            if per_row and C is not None and len(bounds) == 1:
                fk0 = step_law.floor_stiffness() if fk0 is None else fk0
                floor_k = np.full(n_rows, fk0)
            elif per_row and C is not None:
                if it == 0:
                    for (a, b), lc in zip(bounds, locs):
                        fk_rows[a:b] = self._step_law(law, C[lc]).floor_stiffness()
                floor_k = fk_rows[rows]
            elif C is not None and len(bounds) > 1:
                floor_k = np.empty(n_rows)
                for lc in locs:
                    floor_k[lc] = self._step_law(law, C[lc]).floor_stiffness()
            mu = mu_all[rows]
            self.newton_load(B[rows], it == 0)
            # the cam-bearing model at this linearisation point, shared by the inner solve and the trust region's
            # potentials (a function of the states alone)
            arms = self._hole_arms(th[rows], xs, step_law)
            dx, e_start = self._inner(th[rows], xs, G, J, B[rows], step_law, mu, floor_k=floor_k, arms=arms)
            mu_all[rows] = np.minimum(mu, 1e-2)
            dx, settled = self._trust_step(it, rows, xs, dx, e_start, G, J, B, step_law, arms, trs, may_settle[rows],
                                           expand, tol_mm)
            xs += dx
            x[rows] = xs
            active = self._settle(it, per_row, rows, dx, settled, G, J, locs, active, row_on, used, out, offset,
                                  solves, tol_mm)
        return used

    def _outer_rows(self, per_row: bool, bounds: list[tuple[int, int]], active: list[int], row_on: np.ndarray,
                    prev_rows: np.ndarray | None) -> tuple[slice | np.ndarray, int, list[slice], np.ndarray]:
        """The rows an outer iteration linearises (a slice or indices), their number, each active solve's place
        among them and their indices; a provider with ``keep_rows`` keeps the warm starts of the rows left."""
        N = row_on.size
        if per_row and len(bounds) > 1 and not row_on.all():
            rows = np.nonzero(row_on)[0]
            n_rows = rows.size
        elif per_row and len(bounds) == 1 and not row_on[bounds[0][0]:bounds[0][1]].all():
            rows = np.nonzero(row_on)[0]
            n_rows = rows.size
        elif len(active) == len(bounds) and len(bounds) == 1:
            rows = slice(bounds[0][0], bounds[0][1])
            n_rows = bounds[0][1] - bounds[0][0]
        else:
            rows = np.concatenate([np.arange(*bounds[g]) for g in active])
            n_rows = rows.size
        if prev_rows is not None and n_rows != prev_rows.size and hasattr(self.contacts, "keep_rows"):
            self.contacts.keep_rows(np.isin(prev_rows, rows), self.zp)      # warm starts of the rows left
        locs, pos = [], 0
        for g in active:
            n = bounds[g][1] - bounds[g][0]
            locs.append(slice(pos, pos + n))
            pos += n
        return rows, n_rows, locs, np.arange(N)[rows]

    def _trust_step(self, it: int, rows: slice | np.ndarray, xs: np.ndarray, dx: np.ndarray, e_start: np.ndarray,
                    G: np.ndarray, J: np.ndarray, B: np.ndarray, step_law: ContactLaw, arms: np.ndarray | None,
                    trs: tuple, may_settle: np.ndarray, expand: bool, tol_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """The outer step (n, ndof) mm of the rows at ``xs``: the inner step ``dx`` cut to each state's trust radius,
        and which states stop on the contraction test. ``e_start``: the linearised potential at ``xs``, N mm.
        ``trs``, updated: per row the trust radius (mm), last step (mm), whether it was cut, the linearised
        potential (N mm) at the last state and at the last state plus its step, the last uncut step's size (mm)."""
        trust, last_dx, cut, e_old, e_pred, prev_ch = trs
        # trust region of the linearisation: the gap normals turn by step/rho, rho down to the
        # roots' 0.07 mm, so an outer step moves each state at most `trust` (start
        # OUTER_TRUST_MM); a step that reverses the previous one (a contact flipping between
        # two linearisations) halves that state's trust radius for good
        if it > 0:
            flip = np.einsum("nd,nd->n", dx, last_dx[rows]) < 0
            trust[rows] = np.where(flip, 0.5 * trust[rows], trust[rows])
            if expand:
                # the potential at xs (from the inner solve) plus the load's work over the last step
                e_now = e_start + np.einsum("nd,nd->n", last_dx[rows], B[rows])
                pred = e_old[rows] - e_pred[rows]
                good = cut[rows] & ~flip & (pred > 0) & (e_old[rows] - e_now > 0.75 * pred)
                trust[rows] = np.where(good, np.minimum(4.0 * trust[rows], MAX_TRUST_MM), trust[rows])
        big = np.abs(dx).max(axis=1)
        dx = dx * np.minimum(1.0, trust[rows] / np.maximum(big, 1e-300))[:, None]
        # the contraction test (CONTRACTION_MAX): an uncut, exact step whose predecessor was uncut too
        q = np.maximum(big / np.maximum(prev_ch[rows], 1e-300), CONTRACTION_MAX)
        settled = (may_settle & (big <= trust[rows]) & (big < LOOSE_MIN_STEP * tol_mm)
                   & (q <= CONTRACTION_MAX) & (CONTRACTION_MAX / (1.0 - CONTRACTION_MAX) * big < tol_mm))
        if self.max_outer is not None and it + 1 >= self.max_outer:
            settled = settled | may_settle            # a sensitivity solve's warm states stop here
        prev_ch[rows] = np.where(big <= trust[rows], big, np.inf)
        if expand:
            cut[rows] = big > trust[rows]
            e_old[rows] = e_start                     # the linearised potential at xs, from the inner solve
            e_pred[rows] = energy_sub(self, xs, G, J, B[rows], step_law, dx, arms)
        last_dx[rows] = dx
        return dx, settled

    def _settle(self, it: int, per_row: bool, rows: slice | np.ndarray, dx: np.ndarray, settled: np.ndarray,
                G: np.ndarray, J: np.ndarray, locs: list[slice], active: list[int], row_on: np.ndarray, used: list,
                out: dict, offset: int, solves: tuple, tol_mm: float) -> list[int]:
        """The convergence test after an outer step ``dx`` (mm), state by state (``per_row``, leaving ``row_on``) or
        solve by solve: writes the converged linearisation to ``out``, updates ``used`` and returns the solves still
        iterating; a solve that cannot converge raises its error, or with ``collect`` (in ``solves``) keeps it."""
        th, x, dirs, law, loads, bounds, collect = solves
        N = row_on.size
        still = []
        if per_row:
            ch = np.abs(dx).max(axis=1)
            conv = (ch < tol_mm) | settled | ((it >= self.tol.solver_max_iter // 3) & (ch < 10 * tol_mm))
            if len(bounds) == 1:
                used[0] = it + 1
            if conv.any():
                rr = np.arange(N)[rows][conv]
                o = offset + rr
                out["G"][o] = G[conv] + _jdot(J[conv], dx[conv][:, :self.nj])
                out["nrm"][o] = self._nrm_last[conv]
                out["J"][o] = J[conv]
                out["C"][o], out["R"][o] = self._line_last(np.nonzero(conv)[0])
                row_on[rr] = False
            if len(bounds) > 1:
                for g in active:
                    used[g] = it + 1
                still = [(g, None) for g in active if row_on[bounds[g][0]:bounds[g][1]].any()]
                if still and it + 1 == self.tol.solver_max_iter:
                    big_g = np.zeros(N)
                    big_g[np.arange(N)[rows]] = ch
                    for g, _ in still:
                        a, b = bounds[g]
                        used[g] = self._unconverged(th[a:b], x[a:b], dirs[a], law, loads[g], float(big_g[a:b].max()))
                        if not collect:
                            raise used[g]
                return [g for g, _ in still]
            if row_on.any():
                still.append((0, locs[0]))
                if it + 1 == self.tol.solver_max_iter:
                    a, b = bounds[0]
                    used[0] = self._unconverged(th[a:b], x[a:b], dirs[a], law, loads[0], float(ch.max()))
                    if not collect:
                        raise used[0]
            return [g for g, _ in still]
        for g, lc in zip(active, locs):
            used[g] = it + 1
            change = np.abs(dx[lc]).max()
            ok = bool(np.all((np.abs(dx[lc]).max(axis=1) < tol_mm) | settled[lc]))
            if ok or (it >= self.tol.solver_max_iter // 3 and change < 10 * tol_mm):
                # the step is below the tolerance: the linearised gaps at the new state are exact
                # to O(dx^2 / rho), far below 1e-12 mm
                o = slice(offset + bounds[g][0], offset + bounds[g][1])
                out["G"][o] = G[lc] + _jdot(J[lc], dx[lc][:, :self.nj])
                out["nrm"][o] = self._nrm_last[lc]
                out["J"][o] = J[lc]
                out["C"][o], out["R"][o] = self._line_last(lc)
            else:
                still.append((g, lc))
        if still and it + 1 == self.tol.solver_max_iter:
            for g, lc in still:
                a, b = bounds[g]
                used[g] = self._unconverged(th[a:b], x[a:b], dirs[a], law, loads[g], float(np.abs(dx[lc]).max()))
                if not collect:
                    raise used[g]
        return [g for g, _ in still]


def _row_norm(J: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis; for 3 columns written out (the same sum, in the same order, as
    ``np.linalg.norm(J, axis=-1)``, without its temporaries)."""
    if J.shape[-1] != 3:
        return np.linalg.norm(J, axis=-1)
    a, b, c = J[..., 0], J[..., 1], J[..., 2]
    return np.sqrt(a * a + b * b + c * c)


def _jdot(J: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Batched J @ s: (N, M, D) x (N, D) -> (N, M)."""
    return np.matmul(J, s[:, :, None])[:, :, 0]


def energy_sub(solver: QuasiStaticSolver, x0, G, J, b, law: ContactLaw, s: np.ndarray,
               arms: np.ndarray | None = None, rows=None, fk: bool = False):
    """Linearised potential of the states x0 + s (N,), N mm (``b``: load vector (ndof,) or one per state
    (N, ndof); ``arms``: hole arms at x0, floating discs; ``rows``: the steps of the law's per-step constants).
    ``fk`` (a law with ``energy_force_stiffness``): also the contact forces and stiffnesses (N, M) at x0 + s."""
    delta = -(G + _jdot(J, s[:, :J.shape[-1]]))
    work = s @ b if b.ndim == 1 else np.einsum("nd,nd->n", s, b)
    if fk:
        e, f, k = law.energy_force_stiffness(delta, rows)
    else:
        e = law.energy(delta, rows)
    E = e.sum(axis=1) + work
    if arms is not None:
        E = E + solver._bearing(x0 + s, arms, derivs=False)[0]
    return (E, f, k) if fk else E
