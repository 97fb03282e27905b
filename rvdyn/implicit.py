"""Jacobians of the transmission error along directions in case space (the columns of a whole library of
parameters at a state from one factorisation per row), by implicit differentiation of the quasi-static equilibrium
(:mod:`rvdyn.adjoint`; docs/physics.md, "Implicit differentiation of the equilibrium").

A direction ``{"errors": {...}, "model": {...}}`` is split into its geometric part (errors, the geometric model
options) and its solver options; each part's column is a central difference of the adjoint's first-order change
(:meth:`rvdyn.adjoint.TEAdjoint.first_order`) over ``base +- t delta`` at the fixed states: no solve. At an option's
bound the difference is one-sided; a part that changes the state's coordinates (a clearance that floats the discs
of the impact law) falls back to a sensitivity solve; both are flagged.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvdyn.adjoint import TEAdjoint, solver_for
from rvdyn.contacts import ContactLaw
from rvdyn.options import MODEL_OPTIONS, SOLVER_OPTIONS
from rvdyn.results import ARCSEC_PER_RAD
from rvdyn.te import run_te_many

#: Default step of the differences over a direction's geometric part (units of the direction: 0.1 um of 1 um).
REL_STEP = 0.1
#: Step over a direction's solver options (units of the direction): the laws are differentiated at the fixed
#: states, where a cam bearing of the option-spring model is engaged by 0.25 nm only.
OPTION_STEP = 1e-6
_DEFAULTS = {k: o.default for k, o in MODEL_OPTIONS.items()}


@dataclass
class JacobianResult:
    """TE of the base at the readings and its derivatives along the directions.

    Attributes
    ----------
    te_arcsec : list of (n_i,) arrays
        TE of the base per condition, arcsec.
    J : (sum n_i, n_params) array
        ``dTE/dt`` of ``base + t params[j]`` at t = 0, arcsec per unit of the direction; rows: the readings of all
        conditions in order. NaN where a column could not be formed (``flags``).
    states : list of (n_i, ndof) arrays
        The base's converged states (:attr:`rvdyn.te.TEResult.state`).
    flags : list of (str or None)
        Per column: None, or how it was formed otherwise (a one-sided difference at an option's bound, a
        sensitivity solve) or why it is NaN.
    stationarity_arcsec : float
        The largest TE change of a Newton step from the states (the solver's tolerance leaves about 1e-4).
    """

    te_arcsec: list[np.ndarray]
    J: np.ndarray
    states: list[np.ndarray]
    flags: list[str | None] = field(default_factory=list)
    stationarity_arcsec: float = 0.0


def te_jacobian(case: Case | dict, params: list[dict[str, Any]], *, loads: list[tuple[float, int]],
                theta_in_deg: list, states: list | None = None, solver: str = "analytic",
                law: ContactLaw | None = None, rel_step: float = REL_STEP) -> JacobianResult:
    """TE of a case at the readings and its Jacobian along directions in case space (module docstring).

    Parameters
    ----------
    case : Case or dict
        The base (declared and estimated errors, model options).
    params : list of dict
        Directions ``{"errors": {...}, "model": {...}}`` (:meth:`rvcad.errors.Case.plus`: errors add to the base's
        same instance or are appended, model options add to the base's value). Column j is ``dTE/dt`` of
        ``base + t params[j]`` at t = 0, arcsec per unit of the direction.
    loads : list of (float, int)
        ``(load_Nm, direction)`` per condition (load > 0).
    theta_in_deg : list of arrays
        The readings' input angles per condition, deg.
    states : list of arrays or None
        The base's converged states per condition (:attr:`rvdyn.te.TEResult.state` at these angles); solved here
        when None.
    solver : {"analytic"}
        The contact provider (the derivatives difference the analytic provider's exact distances).
    law : ContactLaw or None
        Default: the case's ``model.contact``.
    rel_step : float
        Step of the differences over each direction's geometric part, units of the direction.
    """
    base_case = case if isinstance(case, Case) else Case.from_dict(case)
    if solver != "analytic":
        raise ValueError(f"solver {solver!r} is not allowed; allowed: ['analytic'] (the derivatives difference the "
                         "exact contact distances)")
    if isinstance(rel_step, bool) or not isinstance(rel_step, float | int) or not 0.0 < rel_step <= 1.0:
        raise ValueError(f"rel_step {rel_step!r} must be a number in (0, 1] (units of each direction)")
    for j, d in enumerate(params):
        base_case.plus(d, 0.0, _DEFAULTS, field=f"params[{j}]")        # a bad direction raises, naming it
    if states is None:
        states = [r.state for r in run_te_many(base_case, "analytic", loads=loads, theta_in_deg=theta_in_deg,
                                               law=law)]
    base = TEAdjoint(base_case, law, loads, theta_in_deg, states)
    J = np.empty((base.N, len(params)))
    flags: list[str | None] = []
    for j, d in enumerate(params):
        J[:, j], flag = _column(base, d, float(rel_step), loads, theta_in_deg)
        flags.append(flag)
    te = (base.x[:, 0] / base.s.Rp + base.te_extra(base.s)) * ARCSEC_PER_RAD
    cuts = np.cumsum([0] + [len(x) for x in base.states])
    return JacobianResult([te[a:b] for a, b in zip(cuts[:-1], cuts[1:])], J, base.states, flags,
                          base.stationarity_arcsec)


def _pins_only(a: ReducerGeometry, b: ReducerGeometry) -> bool:
    """Whether two geometries differ at most in their pins (centres, radii)."""
    va, vb = vars(a), vars(b)
    for k, v in va.items():
        if isinstance(v, np.ndarray) and k not in ("pin_centers", "pin_radii") and not np.array_equal(v, vb[k]):
            return False
    return all(np.array_equal(va["_pairing"][d], vb["_pairing"][d]) for d in (1, -1))


def _split(delta: dict[str, Any]) -> list[tuple[dict[str, Any], bool]]:
    """A direction as its geometric part (errors, geometric model options) and its solver-option part,
    ``[(part, is_solver_options)]``; its column is the sum of theirs."""
    model = dict(delta.get("model") or {})
    solver = {k: v for k, v in model.items() if k in SOLVER_OPTIONS}
    geo = {k: v for k, v in delta.items() if k != "model"}
    if len(solver) < len(model):
        geo["model"] = {k: v for k, v in model.items() if k not in SOLVER_OPTIONS}
    parts = [(geo, False)] if geo.get("errors") or geo.get("model") else []
    return parts + ([({"model": solver}, True)] if solver else [])


def _column(base: TEAdjoint, delta: dict[str, Any], h: float, loads, theta_in_deg) -> tuple[np.ndarray, str | None]:
    """One column (N,) arcsec per unit and its flag: the sum over the direction's parts (:func:`_split`) of central
    differences of :meth:`rvdyn.adjoint.TEAdjoint.first_order` (a one-sided one of second order at an option's
    bound; a sensitivity solve where the part changes the state's coordinates)."""
    col, notes = np.zeros(base.N), []
    for part, law in _split(delta):
        step = OPTION_STEP if law else h
        schemes = (("central", ((step, 0.5 / step), (-step, -0.5 / step))),
                   ("forward", ((0.0, -1.5 / step), (step, 2.0 / step), (2.0 * step, -0.5 / step))),
                   ("backward", ((0.0, 1.5 / step), (-step, -2.0 / step), (-2.0 * step, 0.5 / step))))
        why, c = "", None
        for name, pts in schemes:
            try:
                ctx = [(_nearby(base, part, t, law), wt) for t, wt in pts]
            except ValueError as err:                 # the sum leaves the valid cases (InputError included)
                why = why or str(err)
                continue
            nd = [getattr(st, "ndof", base.s.ndof) for st, _ in ctx]
            if any(n != base.s.ndof for n in nd):
                c, note = _sensitivity(base, part, h, loads, theta_in_deg, max(nd))
            else:
                c = sum(wt * base.first_order(st, law) for st, wt in ctx) * ARCSEC_PER_RAD
                note = None if name == "central" else f"one-sided ({name}) difference: {why}"
            break
        if c is None:
            c, note = np.full(base.N, np.nan), f"no valid case at t = +-{step:g} of the direction: {why}"
        col += c
        notes += [note] if note else []
    return col, "; ".join(notes) or None


def _nearby(base: TEAdjoint, part: dict[str, Any], t: float, law: bool):
    """The base's solver at t = 0, else the nearby case's solver, or its geometry when it moves pins only."""
    if t == 0.0:
        return base.s
    case = base.case.plus(part, t, _DEFAULTS)
    g = ReducerGeometry(case)
    if not law and _pins_only(g, base.s.geom):
        return g
    return solver_for(case, base.law_arg, g)


def _sensitivity(base: TEAdjoint, part: dict[str, Any], h: float, loads, theta_in_deg,
                 ndof: int) -> tuple[np.ndarray, str]:
    """A forward difference over ``t = h`` by a sensitivity solve (one linearisation, ``max_outer=1``) from the
    base's states with zero added coordinates, where the part floats the discs (no derivative at the base)."""
    why = f"the direction changes the state's coordinates ({base.s.ndof} -> {ndof})"
    if ndof < base.s.ndof:
        return np.full(base.N, np.nan), why + ": no derivative at this base"
    pad = [np.concatenate([x, np.zeros((len(x), ndof - x.shape[1]))], axis=1) for x in base.states]
    res = run_te_many(base.case.plus(part, h, _DEFAULTS), "analytic", loads=loads, theta_in_deg=theta_in_deg,
                      law=base.law_arg, x_init=pad, max_outer=1)
    te = np.concatenate([r.table["te_arcsec"].to_numpy() for r in res])
    return (te - (base.x[:, 0] / base.s.Rp + base.te_extra(base.s)) * ARCSEC_PER_RAD) / h, (
        f"one-sided sensitivity solve at t = {h:g}: " + why)
