"""Contact laws and the analytic contact provider.

A *contact provider* answers two geometric questions for the solver:

- ``disc_distance(k, p, t0)``: signed distance (mm, positive outside the material) from points
  ``p`` (K, 2), given in disc k's profile frame, to disc k's boundary, and the outward unit
  normal there;
- ``stage1_gaps(theta_in, theta_out, psi, direction)``: the loaded-flank gap (mm) between the
  sun and each planet along the line of action.

:class:`AnalyticContacts` answers them exactly (foot point on the pin-centre curve, closed-form
involute gap); :class:`rvdyn.fcl_contacts.FclContacts` answers them with python-fcl distance
queries on the meshes of the exported geometry. The solver is the same for both.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from rvcad.geometry import ReducerGeometry
from rvdyn.materials import LineContact


@dataclass(frozen=True)
class ContactLaw:
    """Contact law of the solver, by kind.

    ``kind = "impact"``: the paper's ADAMS-style impact force without damping, ``F = K * delta**n``
    (paper Eq. 1) at every contact. ``kind = "physical"``: Hertzian line contact at the pins and the
    ISO 6336-1 mesh stiffness at the sun-planet meshes (:class:`PhysicalLaw`, built by the solver
    from the geometry at each linearisation); ``K`` and ``n`` are then unused.

    Parameters
    ----------
    K : float
        Stiffness, N/mm**n (default 2.0e5 N/mm^1.5, the paper's value).
    n : float
        Force exponent (default 1.5).
    rigid : bool
        Rigid single-flank limit (K -> infinity): solved as a linear penalty with stiffness
        ``RIGID_K`` under a vanishing load, so elastic deflections stay below 1e-9 mm.
    kind : {"impact", "physical"}
    """

    K: float = 2.0e5
    n: float = 1.5
    rigid: bool = False
    kind: str = "impact"

    RIGID_K = 1.0e9  # N/mm, linear penalty of the rigid limit
    RIGID_LOAD_NMM = 1.0  # N mm, vanishing load that only sets the flank in the rigid limit
    KINDS = ("impact", "physical")

    def __post_init__(self) -> None:
        if self.kind not in self.KINDS:
            raise ValueError(f"contact law {self.kind!r} is unknown; allowed: {list(self.KINDS)}")
        if not (math.isfinite(self.K) and self.K > 0):
            raise ValueError(f"contact stiffness K {self.K} must be a finite number > 0 (N/mm^n)")
        if not (math.isfinite(self.n) and 1.0 <= self.n <= 3.0):
            raise ValueError(f"contact exponent n {self.n} must be in [1, 3]")

    @property
    def physical(self) -> bool:
        return self.kind == "physical" and not self.rigid

    def describe(self) -> str:
        """Words for messages: which law this is."""
        if self.rigid:
            return "the rigid limit"
        if self.kind == "physical":
            return "the physical contact law (Hertz line contact, ISO 6336 mesh stiffness)"
        return f"the impact law K = {self.K:g} N/mm^{self.n:g}"

    @property
    def k_eff(self) -> float:
        return self.RIGID_K if self.rigid else self.K

    @property
    def n_eff(self) -> float:
        return 1.0 if self.rigid else self.n

    def floor_stiffness(self) -> float:
        """Typical working stiffness (N/mm) for the damping floor of the solver."""
        return float(self.k_eff if self.rigid else self.stiffness(np.array(1e-3)))

    def force(self, delta: np.ndarray, rows=None) -> np.ndarray:
        """Contact force (N) for penetration delta (mm); zero where delta <= 0."""
        d = np.maximum(delta, 0.0)
        n = self.n_eff
        if n == 1.5:
            return self.k_eff * d * np.sqrt(d)
        return self.k_eff * d ** n

    def stiffness(self, delta: np.ndarray, rows=None) -> np.ndarray:
        """dF/d(delta), N/mm."""
        d = np.maximum(delta, 0.0)
        n = self.n_eff
        if n == 1.0:
            return np.where(delta > 0, self.k_eff, 0.0)
        if n == 1.5:
            return 1.5 * self.k_eff * np.sqrt(d)
        return n * self.k_eff * d ** (n - 1.0)

    def force_stiffness(self, delta: np.ndarray, rows=None) -> tuple[np.ndarray, np.ndarray]:
        if self.n_eff == 1.5:                      # force and stiffness from one square root (same numbers)
            d = np.maximum(delta, 0.0)
            r = np.sqrt(d)
            return self.k_eff * d * r, 1.5 * self.k_eff * r
        return self.force(delta), self.stiffness(delta)

    def energy(self, delta: np.ndarray, rows=None) -> np.ndarray:
        """Stored energy K delta^(n+1)/(n+1), N mm."""
        d = np.maximum(delta, 0.0)
        n = self.n_eff
        if n == 1.5:
            return self.k_eff / 2.5 * d * d * np.sqrt(d)
        if n == 1.0:
            return 0.5 * self.k_eff * d * d
        return self.k_eff * d ** (n + 1.0) / (n + 1.0)


class PhysicalLaw:
    """The physical law at one linearisation: Hertz line contact on the first ``n_pin`` columns (one
    Johnson constant ``C`` per step and pin, from the local curvature), a linear mesh spring ``k_mesh``
    (N/mm along the line of action) on the others. ``rows`` selects steps of the chunk.

    The per-step constant ``ln A + C`` of the inversion (:meth:`rvdyn.materials.LineContact._u`) is computed
    once per linearisation, and the inversion is compiled (:func:`_physical_kernel`); the numbers are the
    same operations in the same order as ``LineContact``'s. :meth:`energy_force_stiffness` gives the energy,
    force and stiffness of one inversion (the solver's line search keeps the force and stiffness of the
    accepted step for its next Newton step)."""

    rigid = False
    kind = "physical"

    def __init__(self, line: LineContact, n_pin: int, k_mesh: float) -> None:
        self.line = line
        self.n_pin = n_pin
        self.k_mesh = float(k_mesh)
        C = np.asarray(line.C, dtype=float)
        # per step and pin, once per linearisation: ln A + C and the law's largest line load, N/mm (u = 1)
        self._lnAC = np.ascontiguousarray(np.atleast_2d(np.log(line.A) + C), dtype=float)
        self._Pmax = np.ascontiguousarray(np.atleast_2d(np.exp(C - (1.0 + 1e-12))), dtype=float)

    def describe(self) -> str:
        return "the physical contact law (Hertz line contact, ISO 6336 mesh stiffness)"

    def floor_stiffness(self) -> float:
        C = np.median(self.line.C)
        return float(self.line.stiffness(np.array(1e-4), np.array(C)))

    def force_stiffness(self, delta: np.ndarray, rows=None) -> tuple[np.ndarray, np.ndarray]:
        _, F, K = self.energy_force_stiffness(delta, rows, energy=False)
        return F, K

    def force(self, delta: np.ndarray, rows=None) -> np.ndarray:
        return self.force_stiffness(delta, rows)[0]

    def stiffness(self, delta: np.ndarray, rows=None) -> np.ndarray:
        return self.force_stiffness(delta, rows)[1]

    def energy(self, delta: np.ndarray, rows=None) -> np.ndarray:
        return self.energy_force_stiffness(delta, rows, fk=False)[0]

    def energy_force_stiffness(self, delta: np.ndarray, rows=None, fk: bool = True, energy: bool = True):
        """Energy (N mm), force (N) and stiffness (N/mm) of every contact (None: the energy without ``energy``,
        the force and stiffness without ``fk``); compiled (:func:`_physical_kernel`), the pin contacts'
        inversion on the contacts in touch only."""
        N, n_steps = delta.shape[0], self._lnAC.shape[0]
        r = np.arange(n_steps)[slice(None) if rows is None else rows]
        if r.shape[0] != N:
            raise ValueError(f"delta has {N} steps where the law's rows select {r.shape[0]}")
        E, F, K = _physical_kernel(np.ascontiguousarray(delta, dtype=float), self._lnAC, self._Pmax, r,
                                   self.n_pin, float(self.line.L), float(self.line.A), self.k_mesh, energy, fk)
        return (E if energy else None), (F if fk else None), (K if fk else None)


@njit(cache=True)
def _physical_kernel(delta, lnAC, Pmax, rows, p, L, A, k_mesh, want_e, want_fk):
    """Energy, force and stiffness (N, M) of :class:`PhysicalLaw` at the approaches ``delta`` (N, M) mm; step n
    uses row ``rows[n]`` of the per-step constants ``lnAC = ln A + C`` and ``Pmax`` (., p). Only the outputs asked
    for (``want_e``: the energy; ``want_fk``: force and stiffness) are filled; the others are empty (0, 0).

    Pin contacts in touch (delta > 0): ``u = C - ln P`` solves ``u - ln u = ln(A e^C / delta)`` by Newton from
    ``u0 = rhs + ln rhs`` (3 steps, each written ``u <- u (ln u + rhs - 1) / (u - 1)``), clamped at u = 1 (delta
    beyond the law's maximum); the line load ``P = delta / (A u)`` is Johnson's relation itself (``delta = A P (C -
    ln P)``), at most ``Pmax``; energy ``L A P^2 (u - 1/2) / 2``, force ``L P``, stiffness ``L / (A (u - 1))``. The
    mesh columns (j >= p): a linear spring ``k_mesh`` in compression."""
    N, M = delta.shape
    E = np.zeros((N, M) if want_e else (0, 0))
    F = np.zeros((N, M) if want_fk else (0, 0))
    K = np.zeros((N, M) if want_fk else (0, 0))
    for n in range(N):
        r = rows[n]
        for j in range(p):
            d = delta[n, j]
            if d > 0:
                rhs = max(lnAC[r, j] - math.log(d), 1.0 + 1e-12)
                u = rhs + math.log(rhs)
                r1 = rhs - 1.0
                for _ in range(3):
                    u = u * (math.log(u) + r1) / (u - 1.0)
                u = max(u, 1.0 + 1e-12)
                P = min(d / (A * u), Pmax[r, j])
                if want_e:
                    E[n, j] = 0.5 * L * A * P * P * (u - 0.5)
                if want_fk:
                    F[n, j] = L * P
                    K[n, j] = L / (A * (u - 1.0))
        for j in range(p, M):
            dm = delta[n, j]
            if dm > 0:
                if want_e:
                    E[n, j] = 0.5 * k_mesh * (dm * dm)
                if want_fk:
                    F[n, j] = k_mesh * dm
                    K[n, j] = k_mesh
    return E, F, K


class AnalyticContacts:
    """Exact planar distances to the true envelope and the involutes (the reference solver)."""

    name = "analytic"

    def __init__(self, geom: ReducerGeometry, per_point: bool = False) -> None:
        self.geom = geom
        #: foot-point searches stop point by point (:meth:`rvcad.profile.CycloidProfile.foot_point`): the
        #: batch solver's setting; False keeps the reproducible shared iteration count of the single solves
        self.per_point = per_point
        self._last_t: dict[int, np.ndarray] = {}

    def disc_distance(self, k: int, p: np.ndarray, t0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (mm) of points p (K, 2) in disc k's profile frame to its boundary, and normals.

        The foot-point Newton starts from the previous call's foot parameters where they lie within
        an eighth of a lobe pitch of ``t0`` (the solver's outer iterations revisit the same pins).
        """
        prof = self.geom.profiles[k]
        start = np.asarray(t0, dtype=float)
        last = self._last_t.get(k)
        if last is not None and last.shape == start.shape:
            near = np.abs(last - start) < 0.25 * np.pi / prof.z_lobes
            start = np.where(near, last, start)
        d, t, n = prof.boundary_distance(p, start, self.per_point)
        self._last_t[k] = t
        return d, n

    def keep_rows(self, keep: np.ndarray, per_row: int) -> None:
        """Keep the warm starts of the solver rows ``keep`` only ((R,) bool over the rows of the last call,
        ``per_row`` points each): a batch whose converged solves leave it starts the rest as before."""
        keep = np.asarray(keep, dtype=bool)
        for k, t in list(self._last_t.items()):
            if t.size == keep.size * per_row:
                self._last_t[k] = t.reshape(keep.size, per_row)[keep].ravel()

    def foot_parameters(self, k: int) -> np.ndarray | None:
        """Foot parameters (rad) of disc k's last ``disc_distance`` call, or None."""
        return self._last_t.get(k)

    def stage1_gaps(self, theta_in: np.ndarray, theta_out: np.ndarray, psi: np.ndarray,
                    direction: int) -> np.ndarray:
        """Loaded-flank gap (N, n_cranks), mm (closed-form involute geometry)."""
        return self.geom.stage1_gaps(theta_in, theta_out, psi, direction)
