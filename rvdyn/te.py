"""Transmission error of one case over one or more output revolutions.

``run_te(case, solver=...)`` returns a :class:`TEResult`: a table with one row per step
(``input_deg, output_deg, te_arcsec, contacts, peak_force_N``), the statistics of the
conventions (``pp, mean, mean_abs, rms`` in arcsec), the measured ratio and timing.
TE = theta_out - theta_in / ratio, in arcsec, positive when the output leads.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rvcad.atomic import atomic_path
from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvdyn.contacts import AnalyticContacts, ContactLaw
from rvdyn.solver import ARCSEC_PER_RAD, InterferenceError, QuasiStaticSolver

SOLVERS = ("analytic", "fcl")

#: Steps the fcl provider solves together (each chunk starts from the previous chunk's last state):
#: measured 4.0 s CPU per 720-step revolution against 4.9 s for one batch and 4.5 s for chunks of 30.
FCL_CHUNK = 120

#: Light load (N m) at which the backlash is evaluated by default (0: the rigid limit).
LIGHT_LOAD_NM = 0.0


def make_contacts(geom: ReducerGeometry, solver: str):
    """Contact provider by name: ``analytic`` (exact) or ``fcl`` (python-fcl on the exported meshes)."""
    if solver == "analytic":
        return AnalyticContacts(geom)
    if solver == "fcl":
        from rvdyn.fcl_contacts import FclContacts

        return FclContacts(geom)
    raise ValueError(f"solver {solver!r} is unknown; allowed: {list(SOLVERS)}")


def te_stats(te_arcsec: np.ndarray) -> dict[str, float]:
    """Statistics of one TE curve, arcsec: ``pp`` (max - min), ``mean``, ``mean_abs``, ``rms``."""
    te = np.asarray(te_arcsec, dtype=float)
    return {"pp": float(te.max() - te.min()), "mean": float(te.mean()),
            "mean_abs": float(np.abs(te).mean()), "rms": float(np.sqrt(np.mean(te ** 2)))}


@dataclass
class TEResult:
    """TE of one case.

    Attributes
    ----------
    case : Case
    solver : str
    table : pandas.DataFrame
        ``input_deg, output_deg, te_arcsec, contacts, peak_force_N`` (one row per step, in the
        order of motion).
    stats : dict
        ``pp, mean, mean_abs, rms`` (arcsec), ``ratio`` (least-squares slope of input over output
        angle), ``seconds``, ``steps``, ``direction``, ``load_Nm``, ``contact`` (law kind),
        ``peak_pressure_MPa`` (largest Hertzian pin-disc pressure), ``warnings`` (list of str).
    state : (steps, ndof) ndarray or None
        The converged solver states (:attr:`rvdyn.solver.Solution.x`, scaled coordinates), one row per step:
        the start (``x_init``) of a later solve of a nearby case at the same angles (a warm start).
    """

    case: Case
    solver: str
    table: pd.DataFrame
    stats: dict[str, Any] = field(default_factory=dict)
    state: np.ndarray | None = field(default=None, repr=False)

    def to_csv(self, path: str | Path) -> Path:
        """Write the table atomically (temporary file in the same folder, then rename)."""
        return write_table_atomic(self.table, path)


def write_table_atomic(df: pd.DataFrame, path: str | Path) -> Path:
    """Write a CSV so that no half-written file is ever left at ``path``."""
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            df.to_csv(fh, index=False, float_format="%.10g")
    return path


def input_angles(ratio: float, steps: int, revolutions: float, direction: int) -> np.ndarray:
    """Input angles (rad) of the steps: ``steps`` equal steps over ``revolutions`` output turns.

    Direction -1 visits the same angles in reverse order.
    """
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 2:
        raise ValueError(f"steps {steps!r} must be an integer >= 2")
    if not (isinstance(revolutions, (int, float)) and math.isfinite(revolutions) and revolutions > 0):
        raise ValueError(f"revolutions {revolutions!r} must be a finite number > 0")
    th = np.arange(steps) * (2.0 * math.pi * ratio * revolutions / steps)
    return th if direction == 1 else th[::-1].copy()


def run_te(case: Case, solver: str = "analytic", steps: int = 720, revolutions: float = 1.0,
           load_Nm: float | None = None, direction: int | None = None, law: ContactLaw | None = None,
           geom: ReducerGeometry | None = None, theta_in_deg: np.ndarray | None = None,
           x_init: np.ndarray | None = None, max_outer: int | None = None) -> TEResult:
    """Quasi-static TE of a case.

    Parameters
    ----------
    case : Case
    solver : {"analytic", "fcl"}
    steps : int
        Steps over the revolutions (>= 2).
    revolutions : float
        Output revolutions.
    load_Nm : float or None
        Output load torque, N m (default: the case's). 0 gives the rigid single-flank limit.
    direction : {+1, -1} or None
        Default: the case's.
    law : ContactLaw or None
        Contact law (default: the case's ``model.contact``, see :mod:`rvdyn.options`).
    geom : ReducerGeometry or None
        Pre-built geometry of the case (saves rebuilding).
    theta_in_deg : (N,) array or None
        Explicit input angles, deg, in the order of motion (e.g. the readings of a test rig); they
        replace ``steps`` and ``revolutions``. The analytic provider solves every angle on its own,
        so the values do not depend on the order or the spacing.
    x_init : (steps, ndof) array or None
        Start states: :attr:`TEResult.state` of a nearby case (same design, load, direction, law and
        angles) for a warm start; the equilibrium is the same within the solver tolerance. A start of
        another shape (another model's coordinates) is not used: the solve starts as without one.
    max_outer : int or None
        At most this many outer iterations (linearisations) from a warm start (``x_init``): 1 is a sensitivity
        solve, the TE one linearisation away from the nearby equilibrium ``x_init`` (its change from there within
        about 1 % of the converged change; :attr:`rvdyn.solver.QuasiStaticSolver.max_outer`). None: converged.
        Without a usable ``x_init`` the solve converges whatever this says.
    """
    check_max_outer(max_outer)
    if solver not in SOLVERS:
        raise ValueError(f"solver {solver!r} is unknown; allowed: {list(SOLVERS)}")
    load = case.load_Nm if load_Nm is None else float(load_Nm)
    d = case.direction if direction is None else int(direction)
    if d not in (1, -1):
        raise ValueError(f"direction {direction!r} must be +1 or -1")
    g = geom if geom is not None else ReducerGeometry(case)
    th, steps, revolutions = _angles(g, steps, revolutions, d, theta_in_deg)
    t0 = time.perf_counter()
    s = QuasiStaticSolver(g, make_contacts(g, solver), law)
    s.want_parts = False                                 # the TE table needs neither the wind-up parts nor cam forces
    s.max_outer = max_outer
    sol = s.solve(th, direction=d, load_Nm=load, chunk=None if solver == "analytic" else FCL_CHUNK,
                  x_init=_usable_start(x_init, th.size, s.ndof))
    return _te_result(case, solver, s, sol, steps, revolutions, d, load, time.perf_counter() - t0)


def check_max_outer(max_outer) -> None:
    """ValueError naming ``max_outer`` unless it is None or an integer >= 1."""
    if max_outer is not None and (isinstance(max_outer, bool) or not isinstance(max_outer, (int, np.integer))
                                  or max_outer < 1):
        raise ValueError(f"max_outer {max_outer!r} must be None or an integer >= 1 (outer iterations of a warm start)")


def _usable_start(x_init, n: int, ndof: int) -> np.ndarray | None:
    """A start state usable for a solve of n angles and ndof coordinates, else None (start as without one)."""
    if x_init is None:
        return None
    xi = np.asarray(x_init, dtype=float)
    return xi if xi.shape == (n, ndof) and np.all(np.isfinite(xi)) else None


def _angles(g: ReducerGeometry, steps: int, revolutions: float, d: int, theta_in_deg,
            field: str = "theta_in_deg") -> tuple[np.ndarray, int, float]:
    """Input angles (rad) of one solve with their step count and output revolutions: ``steps`` over
    ``revolutions`` in direction ``d``, or the given angles (deg, checked; ``field`` names them in the error)."""
    if theta_in_deg is None:
        return input_angles(g.ratio, steps, revolutions, d), steps, revolutions
    th = np.radians(np.asarray(theta_in_deg, dtype=float))
    if th.ndim != 1 or th.size < 2 or not np.all(np.isfinite(th)):
        raise ValueError(f"{field} must be a 1-D array of at least 2 finite angles (deg); got shape {th.shape}")
    return th, int(th.size), float(abs(th[-1] - th[0]) / (2.0 * math.pi * g.ratio))


def _te_result(case: Case, solver: str, s: QuasiStaticSolver, sol, steps: int, revolutions: float, d: int,
               load: float, secs: float) -> TEResult:
    """The TEResult of one solution (table, statistics, timing)."""
    te = sol.te_rad * ARCSEC_PER_RAD
    table = pd.DataFrame({
        "input_deg": np.degrees(sol.theta_in),
        "output_deg": np.degrees(sol.theta_out),
        "te_arcsec": te,
        "contacts": sol.n_contacts.astype(int),
        "peak_force_N": sol.peak_force_N,
        "peak_pressure_MPa": sol.peak_pressure_MPa,
    })
    slope = np.polyfit(sol.theta_in, sol.theta_out, 1)[0]
    stats: dict[str, Any] = te_stats(te)
    stats.update({"ratio": float(1.0 / slope), "seconds": secs, "steps": int(steps),
                  "revolutions": float(revolutions), "direction": d, "load_Nm": load, "solver": solver,
                  "contact": s.law.kind,
                  "peak_pressure_MPa": float(np.nanmax(sol.peak_pressure_MPa)) if np.any(
                      np.isfinite(sol.peak_pressure_MPa)) else float("nan"),
                  "warnings": list(sol.warnings)})
    return TEResult(case=case, solver=solver, table=table, stats=stats, state=sol.x)


def run_te_many(case: Case, solver: str = "analytic", steps: int | list[int] = 720,
                loads: list[tuple[float, int]] | None = None, revolutions: float = 1.0,
                law: ContactLaw | None = None, geom: ReducerGeometry | None = None,
                errors: str = "raise", theta_in_deg: list | None = None, x_init: list | None = None,
                max_outer: int | None = None) -> list:
    """Quasi-static TE of one case under several (load, direction) pairs, solved as one batch.

    ``run_te_many(case, "analytic", 37, loads=[(5.01, 1), (5.01, -1), (167.0, 1), (167.0, -1)])`` returns
    one :class:`TEResult` per pair, in the order of ``loads``; result i equals
    ``run_te(case, solver, steps_i, revolutions, load_i, direction_i, law)`` within the solver tolerance
    (``Tolerances.solver_angle_rad``, 1e-9 rad = 2e-4 arcsec; measured: up to 1e-5 arcsec with the impact
    law, 4e-5 with the physical law, the solver's noise floor). The analytic provider linearises and
    minimises all the solves' states together (one provider call and one inner solve per outer iteration
    for the batch), stops each foot-point search point by point and grows the trust radius of states far
    from their equilibrium (:meth:`rvdyn.solver.QuasiStaticSolver.solve_many`); the five solves of a Monte
    Carlo draw (``steps=[360, 37, 37, 37, 37]``) take about a third of the time of five ``run_te`` calls.
    The fcl provider solves the pairs one after the other (``run_te``).

    Parameters
    ----------
    case : Case
        The case (geometry, errors, model); its own load and direction are not used.
    solver : {"analytic", "fcl"}
    steps : int or list of int
        Steps over the revolutions (>= 2): one count for all pairs, or one per pair.
    loads : list of (float, int)
        ``(load_Nm, direction)`` pairs: output load torque, N m, finite and > 0 (the rigid limit, load 0,
        is ``run_te``'s), and direction +1 or -1. At least one pair.
    revolutions : float
        Output revolutions (all pairs).
    law : ContactLaw or None
        Contact law (default: the case's ``model.contact``).
    geom : ReducerGeometry or None
        Pre-built geometry of the case.
    errors : {"raise", "return"}
        ``"raise"``: a pair that cannot be solved raises its error (``InterferenceError``, a ValueError, when
        the overlap exceeds what the law holds; RuntimeError when the solver does not converge), as ``run_te``
        does. ``"return"``: that pair's entry is the exception instance and the other pairs are returned.
    theta_in_deg : list of (array or None), or None
        Per pair, explicit input angles (deg, in the order of motion, at least 2) that replace that pair's
        ``steps`` and ``revolutions``, as in ``run_te``; None (or a None entry): the steps.
    x_init : list of (array or None), or None
        Per pair, start states (``run_te``'s ``x_init``: a nearby case's :attr:`TEResult.state` at that pair's
        angles, a warm start) or None.
    max_outer : int or None
        As in ``run_te``: 1 makes the warm-started pairs sensitivity solves; pairs without a start converge.

    Returns
    -------
    list of TEResult (or exception instances with ``errors="return"``)
        ``stats["seconds"]`` is the batch's time divided by the number of pairs.
    """
    if errors not in ("raise", "return"):
        raise ValueError(f"errors {errors!r} must be 'raise' or 'return'")
    check_max_outer(max_outer)
    if solver not in SOLVERS:
        raise ValueError(f"solver {solver!r} is unknown; allowed: {list(SOLVERS)}")
    pairs = _check_pairs(loads)
    counts = list(steps) if isinstance(steps, (list, tuple, np.ndarray)) else [steps] * len(pairs)
    if len(counts) != len(pairs):
        raise ValueError(f"steps has {len(counts)} entries for {len(pairs)} loads; give one count or one per load")
    given = [None] * len(pairs) if theta_in_deg is None else list(theta_in_deg)
    if len(given) != len(pairs):
        raise ValueError(f"theta_in_deg has {len(given)} entries for {len(pairs)} loads")
    g = geom if geom is not None else ReducerGeometry(case)
    ths, revs = [], []
    for i, (n, (_, d), a) in enumerate(zip(counts, pairs, given)):
        th, counts[i], rv = _angles(g, n, revolutions, d, a, field=f"theta_in_deg[{i}]")
        ths.append(th)
        revs.append(float(rv))
    starts = [None] * len(pairs) if x_init is None else list(x_init)
    if len(starts) != len(pairs):
        raise ValueError(f"x_init has {len(starts)} entries for {len(pairs)} loads")
    if solver != "analytic":
        return _run_te_each(case, solver, counts, pairs, revolutions, law, g, errors, given, starts, max_outer)
    return _run_te_batch(case, counts, pairs, ths, revs, law, g, errors, starts, max_outer)


def _check_pairs(loads: list[tuple[float, int]] | None) -> list[tuple[float, int]]:
    """The ``(load_Nm, direction)`` pairs of :func:`run_te_many` as (float N m, int); ValueError naming the first
    bad entry (not a pair, a load not finite and > 0, a direction other than +1 and -1) or an empty list."""
    if loads is None or isinstance(loads, (str, bytes)) or len(loads) == 0:
        raise ValueError(f"loads {loads!r} must be a non-empty list of (load_Nm, direction) pairs")
    pairs: list[tuple[float, int]] = []
    for i, pair in enumerate(loads):
        try:
            L, d = pair
        except (TypeError, ValueError):
            raise ValueError(f"loads[{i}] = {pair!r} must be a (load_Nm, direction) pair") from None
        if isinstance(L, bool) or not isinstance(L, (int, float, np.integer, np.floating)) or not (
                math.isfinite(L) and L > 0):
            raise ValueError(f"loads[{i}] load_Nm {L!r} must be a finite number > 0 (N m; the rigid limit, load 0, "
                             "is run_te's)")
        if isinstance(d, bool) or d not in (1, -1):
            raise ValueError(f"loads[{i}] direction {d!r} must be +1 or -1")
        pairs.append((float(L), int(d)))
    return pairs


def _run_te_batch(case: Case, counts: list[int], pairs: list[tuple[float, int]], ths: list[np.ndarray],
                  revs: list[float], law: ContactLaw | None, g: ReducerGeometry, errors: str, starts: list,
                  max_outer: int | None) -> list:
    """:func:`run_te_many` with the analytic provider, all pairs in one batch (input angles ``ths``, rad, and output
    revolutions ``revs`` per pair): one TEResult per pair (``stats["seconds"]``: the batch's time over the pairs,
    s), or with ``errors="return"`` the error of a pair that cannot be solved in its place."""
    t0 = time.perf_counter()
    s = QuasiStaticSolver(g, AnalyticContacts(g, per_point=True), law)
    s.want_parts = False
    s.max_outer = max_outer
    xs = [_usable_start(xi, th.size, s.ndof) for xi, th in zip(starts, ths)]
    sols = s.solve_many(ths, [d for _, d in pairs], [L for L, _ in pairs], errors=errors,
                        x_init=None if all(xi is None for xi in xs) else xs)
    secs = (time.perf_counter() - t0) / len(pairs)
    return [sol if isinstance(sol, Exception) else _te_result(case, "analytic", s, sol, n, rv, d, L, secs)
            for sol, n, rv, (L, d) in zip(sols, counts, revs, pairs)]


def _run_te_each(case: Case, solver: str, counts: list[int], pairs: list[tuple[float, int]], revolutions: float,
                 law: ContactLaw | None, g: ReducerGeometry, errors: str, given: list, starts: list,
                 max_outer: int | None) -> list:
    """:func:`run_te_many` pair by pair with :func:`run_te` (the fcl provider): one TEResult per pair, or with
    ``errors="return"`` the InterferenceError or RuntimeError of a pair that cannot be solved in its place."""
    out: list = []
    for n, (L, d), a, xi in zip(counts, pairs, given, starts):
        try:
            out.append(run_te(case, solver, n, revolutions, L, d, law, geom=g, theta_in_deg=a, x_init=xi,
                              max_outer=max_outer))
        except (InterferenceError, RuntimeError) as err:
            if errors == "raise":
                raise
            out.append(err)
    return out


def backlash(case: Case, solver: str = "analytic", steps: int = 720, load_Nm: float = LIGHT_LOAD_NM,
             law: ContactLaw | None = None) -> dict[str, float]:
    """Backlash = mean TE(direction -1) - mean TE(direction +1) at the same light load, arcsec.

    The default light load 0 N m is the rigid single-flank limit: the geometric play at zero torque, the
    datasheet's *backlash* (conventions.md). The datasheet's *lost motion* (+-3 % of rated torque on the
    hysteresis curve) is :func:`rvdyn.stiffness.hysteresis`.
    """
    g = ReducerGeometry(case)
    plus = run_te(case, solver, steps, 1.0, load_Nm, 1, law, geom=g)
    minus = run_te(case, solver, steps, 1.0, load_Nm, -1, law, geom=g)
    return {"backlash_arcsec": minus.stats["mean"] - plus.stats["mean"],
            "te_plus_mean_arcsec": plus.stats["mean"], "te_minus_mean_arcsec": minus.stats["mean"],
            "load_Nm": load_Nm}
