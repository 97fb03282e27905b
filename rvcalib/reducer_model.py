"""The forward model of the loop: the reducer's TE at every reading for a state of the physical candidates, and
its Jacobian.

A *state* is a value of every parameter of the candidates rvdyn solves (:attr:`rvcalib.library.Candidate.solved`:
Table 4 instances, pin-ring form modes, model options), added to what each run declares. The runs that declare
the same errors form one case; its conditions (load, direction, readings) are solved together by
:func:`rvdyn.te.run_te_many` (analytic contacts, the case's contact law: rvdyn's default, the physical law, unless
the settings say otherwise), exactly at every reading's input angle (modulo one output revolution: the TE repeats
every revolution). The converged states of the last solve start the next one (a warm start: the same equilibrium
within the solver tolerance). A condition at load 0 N m is rvdyn's rigid single-flank limit (the reducer turned
without load), which only :func:`rvdyn.te.run_te` solves: those conditions are solved one at a time, always to
convergence.

The Jacobian's columns are the TE change per unit parameter at the current state, by the kind of response:

* smooth parameters (the eccentricities, phases and holes of Table 4, the model options without a kink): the
  derivative, from ``jacobian_fn`` (default :func:`implicit_jacobian`, rvdyn's implicit differentiation of the
  equilibrium; :func:`sensitivity_jacobian`, one-sided differences each solved by one linearisation from the
  current state, is the alternative); at the rigid limit, where rvdyn has no implicit derivative, the rows of the
  conditions at load 0 are central differences of converged solves (:func:`rigid_columns`);
* a single pin's pitch, radius or radial position: the TE of a zero-backlash ring responds to one pin with a kink
  (a pin pushed into the loaded flank takes load, one pulled away lifts off), so the column is the central secant
  over the parameter's current spread (statistical linearisation: the best straight line over the values the
  parameter may have), each end a sensitivity solve;
* kinked parameters of every pin or bearing (:attr:`rvcalib.library.Candidate.kink`): the same secant, each end
  solved to convergence;
* the pin ring's form modes: the same combination of the single pins' columns as of their errors (superposition).

Where the state is symmetric under a turn of one pin pitch (no error that is not: no single-pin error, pin
circle offset, sun eccentricity or form mode, declared or estimated), pin k's response at input angle ``a`` is pin
0's at ``a - k N 360 / Zp`` (the carrier, cranks and discs repeat every pin pitch of output; N the ratio): the
single pins' columns are then pin 0's secant solved on a uniform grid of :data:`TEMPLATE_PER_PIN` points per pin
pitch and interpolated (periodic cubic spline) at the shifted readings (:meth:`ReducerModel.pin_templates`; 3 %
from the pin's own secant in the physical law, where the stage I mesh is not quite periodic in a pin pitch).

Columns are split over ``workers`` processes in contiguous blocks (the same numbers whatever the number of
workers).
"""
from __future__ import annotations

import json
import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvdyn.contacts import ContactLaw
from rvdyn.implicit import te_jacobian
from rvdyn.options import parse_model
from rvdyn.solver import InterferenceError
from rvdyn.te import run_te, run_te_many

from rvcalib.library import CaseDelta


#: Grid points per pin pitch of output of the pin templates.
TEMPLATE_PER_PIN = 36

#: A solve's fixed cost in readings' worth: a solve of r readings takes about (SOLVE_ROWS + r) times the time of
#: one reading (measured: 0.19 s for 192 readings, 0.45 s for 1332, physical law, one core).
SOLVE_ROWS = 500

#: Errors that break the symmetry of a turn by one pin pitch (fixed to the housing or the input shaft).
ASYMMETRIC_KEYS = ("sun_eccentricity", "pin_circle_offset", "pin_pitch")


class ModelEvaluationError(ValueError):
    """The reducer model cannot be evaluated at this state (an interference the contact law cannot hold, no
    convergence)."""


def _rigid(load_Nm: float) -> bool:
    """Whether a condition's load (N m) is rvdyn's rigid single-flank limit (load 0)."""
    return float(load_Nm) == 0.0


def _solve(case_dict: dict, loads: list, angles: list, law: ContactLaw | None, x_init: list | None = None,
           max_outer: int | None = None) -> tuple[list, list]:
    """TE per condition and the converged states.

    Parameters
    ----------
    case_dict : dict
        The case (case JSON).
    loads : list of (float, int)
        ``(load_Nm, direction)`` per condition: output load, N m (>= 0), and direction +1 or -1.
    angles : list of arrays
        Input angles per condition, deg, in the order of motion.
    law : ContactLaw or None
        The contact law (None: the case's).
    x_init : list of arrays or None
        Start states per condition (``TEResult.state`` of a nearby case at the same angles).
    max_outer : int or None
        Outer iterations of the warm-started conditions at load > 0 (1: a sensitivity solve; None: converged).

    Returns
    -------
    te : list of arrays
        TE per condition, arcsec.
    states : list of arrays
        The solved states per condition.

    Notes
    -----
    The conditions at load > 0 are solved together (:func:`rvdyn.te.run_te_many`). Load 0 is rvdyn's rigid
    single-flank limit, which only :func:`rvdyn.te.run_te` solves: those conditions are solved one at a time, each
    to convergence from its start whatever ``max_outer`` says (measured on the paper's design: one linearisation
    of the rigid penalty contacts misses up to 20 % of a cam-bearing clearance's TE change, and a converged warm
    solve costs about as much). A condition that cannot be solved raises ModelEvaluationError naming its load and
    direction.
    """
    case = Case.from_dict(case_dict)
    geom = ReducerGeometry(case)
    starts = [None] * len(loads) if x_init is None else list(x_init)
    res: list = [None] * len(loads)
    loaded = [i for i, (L, _) in enumerate(loads) if not _rigid(L)]
    if loaded:
        got = run_te_many(case, "analytic", loads=[loads[i] for i in loaded], law=law, geom=geom, errors="return",
                          theta_in_deg=[angles[i] for i in loaded], max_outer=max_outer,
                          x_init=None if x_init is None else [starts[i] for i in loaded])
        for i, r in zip(loaded, got):
            res[i] = r
    for i, (L, d) in enumerate(loads):
        if _rigid(L):
            try:
                res[i] = run_te(case, "analytic", load_Nm=0.0, direction=d, law=law, geom=geom,
                                theta_in_deg=angles[i], x_init=starts[i])
            except (InterferenceError, RuntimeError) as exc:
                res[i] = exc
    for r, (L, d) in zip(res, loads):
        if isinstance(r, Exception):
            raise ModelEvaluationError(f"the model cannot be solved at load {L:g} N m, direction {d:+d}: {r}")
    return [r.table["te_arcsec"].to_numpy() for r in res], [r.state for r in res]


def _by_load(loads: list, angles: list, states: list, loaded_rows, rigid_rows) -> np.ndarray:
    """Jacobian rows of the conditions at load > 0 from ``loaded_rows(loads, angles, states)`` and of those at load
    0 (the rigid limit) from ``rigid_rows(loads, angles, states)``, each called on its conditions only (``states``
    None: None), stacked back in the conditions' order; rows = the conditions' readings stacked."""
    rows = np.cumsum([0] + [len(a) for a in angles])
    out = None
    for fn, rigid in ((loaded_rows, False), (rigid_rows, True)):
        idx = [i for i, (L, _) in enumerate(loads) if _rigid(L) == rigid]
        if not idx:
            continue
        blk = fn([loads[i] for i in idx], [angles[i] for i in idx],
                 None if states is None else [states[i] for i in idx])
        out = np.zeros((rows[-1], blk.shape[1])) if out is None else out
        cuts = np.cumsum([0] + [len(angles[i]) for i in idx])
        for k, i in enumerate(idx):
            out[rows[i]:rows[i + 1]] = blk[cuts[k]:cuts[k + 1]]
    return out


def rigid_columns(case_dict: dict, deltas: list, loads: list, angles: list, states: list,
                  law: ContactLaw | None, steps: list) -> np.ndarray:
    """Columns d TE / d t of ``case (+) t delta`` at the rigid limit (load 0 N m), where rvdyn has no implicit
    derivative: central differences of converged solves.

    Parameters
    ----------
    case_dict : dict
        The case at the current state (case JSON).
    deltas : list of dict
        Directions in case space (:meth:`rvcalib.library.Candidate.deltas`), per unit of each parameter.
    loads : list of (float, int)
        ``(load_Nm, direction)`` per condition, load 0 N m.
    angles : list of arrays
        Input angles per condition, deg, in the order of motion.
    states : list of arrays
        The current state's solved states per condition (warm starts).
    law : ContactLaw or None
        The contact law (None: the case's).
    steps : list of float
        Half-width of each column's difference, units of its parameter.

    Returns
    -------
    (n, len(deltas)) array
        TE change per unit parameter, arcsec per unit; rows = the conditions' readings stacked.

    Notes
    -----
    Each column is :func:`secant_columns` over ``t = -steps[j] .. +steps[j]``, each end solved to convergence from
    ``states``: an end the rigid limit cannot hold (an interference) is moved towards the current state a quarter at
    a time, and an end outside a model option's range is the current state (a one-sided difference at the
    option's bound).
    """
    lo = [-h if _valid_end(case_dict, d, -h) else 0.0 for d, h in zip(deltas, steps)]
    hi = [h if _valid_end(case_dict, d, h) else 0.0 for d, h in zip(deltas, steps)]
    return secant_columns(case_dict, deltas, lo, hi, loads, angles, states, law, None)


def _valid_end(case_dict: dict, delta: dict, h: float) -> bool:
    """Whether ``case (+) h delta`` has every model option inside its range."""
    acc = CaseDelta()
    _add_scaled(acc, delta, h)
    try:
        parse_model(acc.to_dict(case_dict).get("model"))
    except ValueError:
        return False
    return True


def sensitivity_jacobian(case_dict: dict, deltas: list, loads: list, angles: list, states: list,
                         law: ContactLaw | None, steps: list) -> np.ndarray:
    """Columns d TE / d t of ``case (+) t delta`` by one-sided differences of step ``steps[j]``, each perturbed case
    solved by one linearisation from ``states`` (rvdyn's sensitivity solve, ``max_outer=1``); rows = the
    conditions' readings stacked. The rows of the conditions at load 0 (the rigid limit) are
    :func:`rigid_columns`'."""
    if any(_rigid(L) for L, _ in loads):
        return _by_load(loads, angles, states,
                        lambda *c: sensitivity_jacobian(case_dict, deltas, *c, law, steps),
                        lambda *c: rigid_columns(case_dict, deltas, *c, law, steps))
    base, _ = _solve(case_dict, loads, angles, law, x_init=states, max_outer=1)
    base = np.concatenate(base)
    cols = []
    for delta, h in zip(deltas, steps):
        acc = CaseDelta()
        _add_scaled(acc, delta, h)
        te, _ = _solve(acc.to_dict(case_dict), loads, angles, law, x_init=states, max_outer=1)
        cols.append((np.concatenate(te) - base) / h)
    return np.column_stack(cols) if cols else np.zeros((base.size, 0))


def implicit_jacobian(case_dict: dict, deltas: list, loads: list, angles: list, states: list,
                      law: ContactLaw | None, steps: list) -> np.ndarray:
    """Columns d TE / d t of ``case (+) t delta`` by implicit differentiation of the equilibrium at ``states``
    (:func:`rvdyn.implicit.te_jacobian`: one factorisation per reading, no solve per column); each direction is
    scaled by its step (a tenth of the prior scale) for the geometry's differences and the column scaled back. The
    rows of the conditions at load 0 (the rigid limit, which rvdyn does not differentiate) are
    :func:`rigid_columns`'."""
    if any(_rigid(L) for L, _ in loads):
        return _by_load(loads, angles, states,
                        lambda *c: implicit_jacobian(case_dict, deltas, *c, law, steps),
                        lambda *c: rigid_columns(case_dict, deltas, *c, law, steps))
    scaled = []
    for delta, h in zip(deltas, steps):
        acc = CaseDelta()
        _add_scaled(acc, delta, h)
        scaled.append({k: v for k, v in acc.to_dict(None).items() if k in ("errors", "model")})
    try:
        res = te_jacobian(Case.from_dict(case_dict), scaled, loads=loads, theta_in_deg=angles, states=states,
                          law=law)
    except ValueError as exc:
        if "not converged states" not in str(exc):
            raise
        # a contact within nanometres of switching: the one linearisation from the states is not the equilibrium's
        return sensitivity_jacobian(case_dict, deltas, loads, angles, states, law, steps)
    J = res.J / np.asarray(steps, dtype=float)[None, :]
    bad = [i for i, f in enumerate(res.flags) if f is not None and not np.all(np.isfinite(J[:, i]))]
    if bad:
        raise ModelEvaluationError(f"no derivative column for {[deltas[i] for i in bad]}: "
                                   f"{[res.flags[i] for i in bad]}")
    return J


def _add_scaled(acc: CaseDelta, delta: dict, h: float) -> None:
    """Add ``h`` times a case delta (``Candidate.deltas`` form) to a case under construction."""
    for key, v in (delta.get("errors") or {}).items():
        for obj in (v if isinstance(v, list) and v and isinstance(v[0], dict) else [v]):
            if isinstance(obj, dict):
                acc.items.append((key, {**obj, "value": h * float(obj["value"])}))
            else:
                acc.pinwise[key] = acc.pinwise.get(key, 0.0) + h * np.asarray(obj, dtype=float)
    for k, v in (delta.get("model") or {}).items():
        acc.model[k] = acc.model.get(k, 0.0) + h * float(v)


def secant_columns(case_dict: dict, deltas: list, lo: list, hi: list, loads: list, angles: list, states: list,
                   law: ContactLaw | None, max_outer: int | None) -> np.ndarray:
    """Columns (TE(case (+) hi_j delta_j) - TE(case (+) lo_j delta_j)) / (hi_j - lo_j), each end solved from
    ``states`` (``max_outer`` 1: a sensitivity solve; None: to convergence). An end the model cannot solve (an
    interference beyond the contact law) is moved towards the current state, a quarter at a time. With conditions
    both at load 0 (the rigid limit) and above, each set's rows are solved on their own (:func:`_by_load`), so an
    end only the rigid limit cannot hold does not shorten the secant of the other rows."""
    rigid = [_rigid(L) for L, _ in loads]
    if any(rigid) and not all(rigid):
        def part(*c):
            return secant_columns(case_dict, deltas, lo, hi, *c, law, max_outer)
        return _by_load(loads, angles, states, part, part)
    cols = []
    cache: dict = {}

    def end(delta, h):
        if h == 0.0:                              # the current state itself
            if "base" not in cache:
                cache["base"] = np.concatenate(_solve(case_dict, loads, angles, law, x_init=states,
                                                      max_outer=max_outer)[0])
            return cache["base"], h
        for _ in range(4):
            acc = CaseDelta()
            _add_scaled(acc, delta, h)
            try:
                te, _ = _solve(acc.to_dict(case_dict), loads, angles, law, x_init=states, max_outer=max_outer)
                return np.concatenate(te), h
            except ModelEvaluationError:
                h *= 0.25
        return end(delta, 0.0)

    for delta, a, b in zip(deltas, lo, hi):
        (fa, a), (fb, b) = end(delta, a), end(delta, b)
        if b == a:
            raise ModelEvaluationError(f"no secant can be solved along {delta} from this state")
        cols.append((fb - fa) / (b - a))
    return np.column_stack(cols)


def _task(args) -> np.ndarray:
    kind, fn_or_outer, case_dict, deltas, p1, p2, loads, angles, states, law = args
    if kind == "derivative":
        return fn_or_outer(case_dict, deltas, loads, angles, states, law, p1)
    return secant_columns(case_dict, deltas, p1, p2, loads, angles, states, law, fn_or_outer)


@dataclass
class CaseGroup:
    """The runs that declare the same errors: one case, solved under each run's load and direction."""

    base: dict
    runs: list                     # indices into dataset.runs
    loads: list                    # (load_Nm, direction) per run
    angles: list                   # input angles (deg, modulo one output revolution) per run
    states: list | None = None


@dataclass
class ReducerModel:
    """The reducer's TE at the readings for a state of the solved candidates.

    Parameters
    ----------
    dataset : MeasuredDataset
    candidates : list of Candidate
        The solved candidates, in the order of the state's parameters.
    law : ContactLaw or None
        The contact law (None: each case's, rvdyn's default).
    workers : int
        Processes for the Jacobian's columns (1: this process).
    jacobian_fn : callable or None
        ``fn(case_dict, deltas, loads, angles, states, law, steps) -> (n, m)``; default :func:`implicit_jacobian`.
    secant_width : float
        The secants' default half-width, in prior scales (where :meth:`jacobian` is given no spread).
    """

    dataset: object
    candidates: list
    law: ContactLaw | None = None
    workers: int = 1
    jacobian_fn: object = None
    groups: list = field(default_factory=list)
    solves: int = 0
    secant_width: float = 1.0

    def __post_init__(self) -> None:
        if self.jacobian_fn is None:
            self.jacobian_fn = implicit_jacobian
        period = self.dataset.period_deg
        by_key: dict[str, CaseGroup] = {}
        for i, r in enumerate(self.dataset.runs):
            base = {k: v for k, v in r.case_dict().items() if k not in ("name", "load_Nm", "direction")}
            key = json.dumps(base, sort_keys=True)
            g = by_key.setdefault(key, CaseGroup(base, [], [], []))
            g.runs.append(i)
            g.loads.append((float(r.load_Nm), int(r.direction)))
            g.angles.append(np.mod(r.input_deg, period))
        self.groups = list(by_key.values())
        self.offsets = np.cumsum([0] + [r.n for r in self.dataset.runs])
        self.deltas = [d for c in self.candidates for d in c.deltas()]
        self.n_params = len(self.deltas)
        self._lower = np.array([c.lower for c in self.candidates for _ in range(c.n_params)])
        self._upper = np.array([c.upper for c in self.candidates for _ in range(c.n_params)])
        self._pin_index = {}
        self._owner = [c for c in self.candidates for _ in range(c.n_params)]
        pos = 0
        for c in self.candidates:
            inst = dict(c.instance)
            if c.family == "table4" and "pin" in inst:
                self._pin_index.setdefault((c.key, inst["pin"]), []).append(pos)
            pos += c.n_params
        self._J = None

    def case_dict(self, group: CaseGroup, theta: np.ndarray) -> dict:
        """The case of a group of runs at state ``theta`` (bounded parameters clipped to their bounds)."""
        acc = CaseDelta()
        pos = 0
        for c in self.candidates:
            p = np.clip(theta[pos:pos + c.n_params], c.lower, c.upper)
            c.add_to(acc, p)
            pos += c.n_params
        return acc.to_dict(group.base)

    def _place(self, g: CaseGroup, blocks: list, out: np.ndarray) -> None:
        for i, b in zip(g.runs, blocks):
            out[self.offsets[i]:self.offsets[i + 1]] = b

    def te(self, theta: np.ndarray) -> np.ndarray:
        """Model TE (arcsec) at every reading, stacked over the runs; keeps the converged states."""
        out = np.empty(self.offsets[-1])
        for g in self.groups:
            te, states = _solve(self.case_dict(g, theta), g.loads, g.angles, self.law, x_init=g.states)
            self.solves += 1
            g.states = states
            self._place(g, te, out)
        return out

    def steps(self) -> np.ndarray:
        """Difference steps of the derivative columns: a tenth of each parameter's prior scale."""
        return np.array([0.1 * c.prior_scale for c in self.candidates for _ in range(c.n_params)])

    def column_kinds(self) -> np.ndarray:
        """Per parameter: ``derivative``, ``pin`` (single-pin secant), ``kink`` (converged secant) or ``form``."""
        out = []
        for c in self.candidates:
            kind = ("form" if c.pattern is not None and self._pin_index else
                    "pin" if any(k == "pin" for k, _ in c.instance) else "kink" if c.kink else "derivative")
            out += [kind] * c.n_params
        return np.array(out)

    def jacobian(self, theta: np.ndarray, spread: np.ndarray | None = None, renew: np.ndarray | None = None,
                 pool: ProcessPoolExecutor | None = None) -> np.ndarray:
        """The columns of the linearised model at ``theta`` (n, n_params), at the states of the last :meth:`te`
        (call it first); see the module docstring for the kinds of column.

        ``spread`` (n_params,): each parameter's current spread, the half-width of its secant (default its prior
        scale times :attr:`secant_width`). ``renew`` (n_params,) bool: the columns to solve (default all); the
        others keep their columns of the last call (the form modes are always recombined from the single pins').
        """
        return self._columns(theta, spread, renew, pool, self.column_kinds())

    def tangent_jacobian(self, theta: np.ndarray, pool: ProcessPoolExecutor | None = None) -> np.ndarray:
        """The tangent of the model at ``theta`` (n, n_params), at the states of the last :meth:`te` (call it
        first): every column the derivative there (``jacobian_fn``, rvdyn's implicit differentiation of the
        equilibrium), the single pins' too; the kinked parameters of every pin or bearing keep their converged
        secant and the form modes are recombined from the single pins' columns.

        A single pin's derivative is that of the contacts as they stand at ``theta`` (a pin in contact responds, one
        lifted off does not), so it describes the model for steps that keep the contacts as they are, where the
        secant over the pin's spread (:meth:`jacobian`) describes the whole class. It costs one factorisation of
        each condition's equilibrium for all the pins, where the secants cost two solves per pin."""
        kinds = self.column_kinds()
        return self._columns(theta, None, None, pool, np.where(kinds == "pin", "derivative", kinds))

    def statistical_jacobian(self, theta: np.ndarray, pool: ProcessPoolExecutor | None = None) -> np.ndarray:
        """The columns of the statistical linearisation over the prior at ``theta`` (n, n_params), at the states of
        the last :meth:`te` (call it first): every column a secant over +- the parameter's prior scale times
        :attr:`secant_width` (within its bounds), the derivative columns' too. Where the response over a tolerance
        class is not linear (the run means under load are nearly even in a planet's eccentricity at the perfect
        reducer), the secant is a straight line through the response over that class, where the tangent at one
        state would extrapolate that state's slope (statistical linear regression, A. F. Garcia-Fernandez,
        L. Svensson, M. R. Morelande, S. Sarkka, "Posterior linearization filter: principles and implementation
        using sigma points", IEEE Trans. Signal Process. 63 (2015) 5561-5573, with two points per parameter)."""
        kinds = self.column_kinds()
        return self._columns(theta, None, None, pool, np.where(kinds == "derivative", "kink", kinds))

    def _columns(self, theta: np.ndarray, spread: np.ndarray | None, renew: np.ndarray | None,
                 pool: ProcessPoolExecutor | None, kinds: np.ndarray) -> np.ndarray:
        """:meth:`jacobian` with the columns' kinds given."""
        spread = self.steps() * 10.0 * self.secant_width if spread is None else np.asarray(spread, dtype=float)
        if renew is None or self._J is None:
            renew = np.ones(self.n_params, dtype=bool)
        J = np.zeros((self.offsets[-1], self.n_params)) if self._J is None else self._J.copy()
        todo = [(kind, np.nonzero((kinds == kind) & renew)[0]) for kind in ("derivative", "pin", "kink")]
        lo = np.maximum(theta - spread, self._lower) - theta
        hi = np.minimum(theta + spread, self._upper) - theta
        steps = self.steps()
        for g in self.groups:
            if g.states is None:
                raise ValueError("jacobian() needs the states of te() at the same theta")
            case = self.case_dict(g, theta)
            args, where = [], []
            tmpl = np.zeros(0, dtype=int)
            pins = todo[1][1]
            n_tmpl = len({(self._owner[j].key, self._owner[j].side) for j in pins})
            grid_rows = TEMPLATE_PER_PIN * int(self.dataset.design.z_pins) * len(g.loads)
            rows_g = sum(len(a) for a in g.angles)
            if pins.size and self.symmetric(g, theta) and \
                    (n_tmpl + 1) * (SOLVE_ROWS + grid_rows) < pins.size * (SOLVE_ROWS + rows_g):
                tmpl = pins                         # the templates cost less
            for kind, idx in todo:
                if kind == "pin" and tmpl.size:
                    continue
                for a, b in _blocks(idx.size, max(1, self.workers)):
                    sel = idx[a:b]
                    ds = [self.deltas[j] for j in sel]
                    if kind == "derivative":
                        args.append((kind, self.jacobian_fn, case, ds, list(steps[sel]), None, g.loads, g.angles,
                                     g.states, self.law))
                    else:
                        args.append((kind, 1 if kind == "pin" else None, case, ds, list(lo[sel]), list(hi[sel]),
                                     g.loads, g.angles, g.states, self.law))
                    where.append(sel)
            blocks = list(pool.map(_task, args)) if pool is not None and len(args) > 1 else [_task(a) for a in args]
            self.solves += sum(2 * len(w) for w in where)
            rows = np.cumsum([0] + [len(a) for a in g.angles])
            Jg = np.zeros((rows[-1], self.n_params))
            if tmpl.size:
                Jg[:, tmpl] = self.pin_templates(g, theta, tmpl, lo, hi)
                where.append(tmpl)
                blocks.append(Jg[:, tmpl])
            done = np.concatenate(where) if where else np.zeros(0, dtype=int)
            for sel, blk in zip(where, blocks):
                Jg[:, sel] = blk
            for k, i in enumerate(g.runs):
                J[self.offsets[i]:self.offsets[i + 1], done] = Jg[rows[k]:rows[k + 1]][:, done]
        self._combine_forms(J, kinds)
        self._J = J
        return J

    def symmetric(self, group: CaseGroup, theta: np.ndarray) -> bool:
        """Whether the group's case at ``theta`` repeats under a turn of one pin pitch (see the module docstring)."""
        pos = 0
        for c in self.candidates:
            asym = c.pattern is not None or "pin" in dict(c.instance) or c.key in ("sun_eccentricity",
                                                                                    "pin_circle_offset")
            if asym and np.any(theta[pos:pos + c.n_params] != 0.0):
                return False
            pos += c.n_params
        errors = group.base.get("errors") or {}
        return not any(k in ASYMMETRIC_KEYS for k in errors) and not any(
            isinstance(v, list) or (isinstance(v, dict) and "pin" in v) for v in errors.values())

    def pin_templates(self, group: CaseGroup, theta: np.ndarray, idx: np.ndarray, lo: np.ndarray,
                      hi: np.ndarray) -> np.ndarray:
        """The single-pin secant columns ``idx`` of a symmetric group from pin 0's, solved on a uniform grid and
        shifted (see the module docstring); rows = the group's readings stacked."""
        d = self.dataset.design
        zp, ratio = int(d.z_pins), float(d.ratio)
        period = ratio * 360.0
        M = TEMPLATE_PER_PIN * zp
        grid = np.arange(M) * period / M
        angles = [grid if dd > 0 else grid[::-1] for _, dd in group.loads]
        case = self.case_dict(group, theta)
        base, states = _solve(case, group.loads, angles, self.law)
        self.solves += 1
        out = np.empty((sum(len(a) for a in group.angles), idx.size))
        made: dict = {}
        for col, j in enumerate(idx):
            c = self._owner[j]
            p = dict(c.instance)["pin"]
            key = (c.key, c.side, float(lo[j]), float(hi[j]))
            if key not in made:
                pin0 = self._pin_index[(c.key, 0)][0 if c.side > 0 else -1]
                cols = secant_columns(case, [self.deltas[pin0]], [lo[j]], [hi[j]], group.loads, angles, states,
                                      self.law, 1)[:, 0]
                self.solves += 2
                rows = np.cumsum([0] + [len(a) for a in angles])
                made[key] = [_periodic(a, cols[rows[k]:rows[k + 1]], period) for k, a in enumerate(angles)]
            shift = p * period / zp
            out[:, col] = np.concatenate([sp(np.mod(a - shift, period)) for sp, a in zip(made[key], group.angles)])
        return out

    def _combine_forms(self, J: np.ndarray, kinds: np.ndarray) -> None:
        """The form modes' columns as the combination of the single pins' columns their patterns give (each pin's
        column the mean of its two sides' secants)."""
        pos = 0
        for c in self.candidates:
            if kinds[pos] == "form":
                cols = np.column_stack([J[:, self._pin_index[(c.key, p)]].mean(axis=1)
                                        for p in range(len(c.pattern[0]))])
                for j, pat in enumerate(c.pattern):
                    J[:, pos + j] = cols @ np.asarray(pat)
            pos += c.n_params


def _periodic(angles: np.ndarray, values: np.ndarray, period: float) -> CubicSpline:
    """Periodic cubic spline of values on a uniform grid of angles over one period."""
    o = np.argsort(angles)
    return CubicSpline(np.r_[angles[o], period], np.r_[values[o], values[o][0]], bc_type="periodic")


def _blocks(n: int, parts: int) -> list:
    """Contiguous (start, stop) blocks splitting n items into at most ``parts`` non-empty ones."""
    cuts = np.linspace(0, n, min(parts, max(n, 1)) + 1).astype(int)
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]


def finite(x: float) -> bool:
    return isinstance(x, float) and math.isfinite(x)
