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

from rvcad.geometry import ReducerGeometry


@dataclass(frozen=True)
class ContactLaw:
    """ADAMS-style impact force without damping, ``F = K * delta**n`` (paper Eq. 1).

    Parameters
    ----------
    K : float
        Stiffness, N/mm**n (default 2.0e5 N/mm^1.5, conventions).
    n : float
        Force exponent (default 1.5).
    rigid : bool
        Rigid single-flank limit (K -> infinity): solved as a linear penalty with stiffness
        ``RIGID_K`` under a vanishing load, so elastic deflections stay below 1e-9 mm.
    """

    K: float = 2.0e5
    n: float = 1.5
    rigid: bool = False

    RIGID_K = 1.0e9  # N/mm, linear penalty of the rigid limit
    RIGID_LOAD_NMM = 1.0  # N mm, vanishing load that only sets the flank in the rigid limit

    def __post_init__(self) -> None:
        if not (math.isfinite(self.K) and self.K > 0):
            raise ValueError(f"contact stiffness K {self.K} must be a finite number > 0 (N/mm^n)")
        if not (math.isfinite(self.n) and 1.0 <= self.n <= 3.0):
            raise ValueError(f"contact exponent n {self.n} must be in [1, 3]")

    @property
    def k_eff(self) -> float:
        return self.RIGID_K if self.rigid else self.K

    @property
    def n_eff(self) -> float:
        return 1.0 if self.rigid else self.n

    def force(self, delta: np.ndarray) -> np.ndarray:
        """Contact force (N) for penetration delta (mm); zero where delta <= 0."""
        d = np.maximum(delta, 0.0)
        n = self.n_eff
        if n == 1.5:
            return self.k_eff * d * np.sqrt(d)
        return self.k_eff * d ** n

    def stiffness(self, delta: np.ndarray) -> np.ndarray:
        """dF/d(delta), N/mm."""
        d = np.maximum(delta, 0.0)
        n = self.n_eff
        if n == 1.0:
            return np.where(delta > 0, self.k_eff, 0.0)
        if n == 1.5:
            return 1.5 * self.k_eff * np.sqrt(d)
        return n * self.k_eff * d ** (n - 1.0)

    def energy(self, delta: np.ndarray) -> np.ndarray:
        """Stored energy K delta^(n+1)/(n+1), N mm."""
        d = np.maximum(delta, 0.0)
        n = self.n_eff
        if n == 1.5:
            return self.k_eff / 2.5 * d * d * np.sqrt(d)
        if n == 1.0:
            return 0.5 * self.k_eff * d * d
        return self.k_eff * d ** (n + 1.0) / (n + 1.0)


class AnalyticContacts:
    """Exact planar distances to the true envelope and the involutes (the reference solver)."""

    name = "analytic"

    def __init__(self, geom: ReducerGeometry) -> None:
        self.geom = geom
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
        d, t, n = prof.boundary_distance(p, start)
        self._last_t[k] = t
        return d, n

    def stage1_gaps(self, theta_in: np.ndarray, theta_out: np.ndarray, psi: np.ndarray,
                    direction: int) -> np.ndarray:
        """Loaded-flank gap (N, n_cranks), mm (closed-form involute geometry)."""
        return self.geom.stage1_gaps(theta_in, theta_out, psi, direction)
