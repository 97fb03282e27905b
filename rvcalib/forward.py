"""The forward model of a measured run: rvdyn TE at the readings, or on a uniform grid.

The model TE is solved by rvdyn's one forward runner (:class:`rvdyn.runner.Runner`: analytic contacts,
each case's own contact law: rvdyn's default, the physical law, unless the case's ``model.contact`` or the
runner's ``law`` says otherwise; the simulated "rig" of :mod:`rvcalib.simulate` solves its truth on the same
runner, so truth and model share one law, and ``rv-calibrate --workers/--cache`` keeps it). TE is periodic
in one output revolution (input N turns, N the ratio of
the case's design; see :mod:`rvcalib.orders`), so angles are taken modulo it. Every design constant
comes from the case (its ``design`` object). :func:`grid_te` solves a uniform grid of ``steps`` input
angles over one output revolution (the screening and the coarse fits of :mod:`rvcalib.identify`);
:func:`te_at` solves exactly at given angles (every reading of a run: interpolating a grid is not
exact, see there); :func:`te_at_many` and :func:`grid_te_many` solve a batch at once (in parallel when
the runner has several workers). The cases of a batch that differ only in load and direction (the run
conditions of one model state) are solved :data:`GROUP_CONDITIONS` at a time as one runner group:
:func:`rvdyn.te.run_te_many` solves them together, each equal to its single solve within the solver tolerance.

Solutions are cached by the runner under the job key (the case's content hash, which holds the
design, the errors, the load and the direction, and the angles), so identical conditions and
repeated trial values are solved once per process: the default runner (:func:`forward_runner`) keeps
them in memory (:data:`CACHE_BYTES`, least recently used first out) and solves in this process.

Warm starts: almost every solve the loop asks for is a small perturbation of a state it solved before (the
finite-difference columns of a Jacobian, the trial steps of a fit, the candidates' signatures at the current
state), so the default runner keeps the newest converged state of each run condition and angle set
(:data:`WARM_BYTES`, ``Runner(warm_bytes=...)``) and starts the next solve of that condition from it. Each
result equals the cold solve's within the solver tolerance (1e-9 rad, 2e-4 arcsec; measured on the 5-run
benchmark's conditions: up to 7e-5 arcsec). With each state of a batch on its own convergence test
(:meth:`rvdyn.solver.QuasiStaticSolver.solve_many`) the 5-run benchmark's loop took 294 -> 178 s CPU under the
physical law and 74 -> 56 s under the impact law, with the same effects, sizes and RMS (docs/calibration.md).
:func:`use_runner` puts another in its place, e.g. ``Runner(executor=2, cache="dir",
memory_bytes=CACHE_BYTES)`` for a local pool and a disk cache shared with later runs.

The measurement effects (encoder eccentricities) and empirical harmonic terms are not physics of
the reducer; they are added to the model TE here as reading errors, see :mod:`rvcalib.effects`.
"""
from __future__ import annotations

import copy
import json
import math
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from rvcad.errors import Case
from rvcad.memo import LRUMemo
from rvdyn.runner import Runner

from rvcalib.orders import period_deg

#: Budget of the default runner's in-memory cache, bytes (least recently used solutions go first).
CACHE_BYTES = 256 * 2 ** 20

#: Budget of the default runner's warm starts, bytes (:class:`rvdyn.cache.StateStore`: the newest converged
#: state of each run condition and angle set, ~80 kB for 360 angles under the physical law, and the state of each
#: converged case, for a case asked for again; least recently used first out). 128 MB (32 until stop 39: on
#: realistic seed 8 a round of the checks before the stop pushed the state of the model state it started from out,
#: and the Jacobian differenced there afterwards started from another state, see rvdyn.runner).
WARM_BYTES = 128 * 2 ** 20

#: Run conditions of one model state solved together in one runner group (one worker task), in their order in the
#: batch: two and two, an odd last one with the two before it (3 conditions: one group; 5: two and three), so that a
#: single state's solve (a chord trial) spreads over two workers. Serially a realistic state's four conditions at
#: 333 readings take about the same CPU in two groups of two as in one of four (0.33-0.34 against 0.34-0.38 s, warm;
#: four single solves 0.36-0.38 s; docs/calibration.md, "Loop speed"). A group of one goes to rvdyn.te.run_te,
#: which has no per-state exit: three conditions as two and one made a loop test under the impact law take 51.5
#: instead of 34.2 s.
GROUP_CONDITIONS = 2

_RUNNER: Runner | None = None


class ModelEvaluationError(ValueError):
    """The reducer model cannot be evaluated at these parameters (interference, no convergence)."""


def forward_runner() -> Runner:
    """The runner of the forward model: the one set by :func:`use_runner`, else (made on first use) a
    serial runner with an in-memory cache of :data:`CACHE_BYTES`, warm starts within :data:`WARM_BYTES` and
    no disk cache."""
    global _RUNNER
    if _RUNNER is None:
        _RUNNER = Runner(solver="analytic", memory_bytes=CACHE_BYTES, warm_bytes=WARM_BYTES)
    return _RUNNER


def use_runner(runner: Runner | None) -> Runner | None:
    """Solve the forward model with ``runner`` from now on (None: back to the default); returns the
    previous one (the caller closes runners it made)."""
    global _RUNNER
    if runner is not None and not isinstance(runner, Runner):
        raise TypeError(f"runner must be an rvdyn.runner.Runner or None, not {type(runner).__name__}")
    prev, _RUNNER = _RUNNER, runner
    return prev


def cache_stats() -> dict[str, float]:
    """Of the forward runner: unique solves (``solves``), results taken from its caches (``hits``),
    solver seconds (``seconds``), bytes held in memory (``bytes``) and the cases asked for again whose warm
    state was no longer kept (``states_lost``, :attr:`rvdyn.runner.Runner.states_lost`)."""
    r = forward_runner()
    return {"solves": r.computed, "hits": r.reused, "seconds": r.counters()["solve_seconds_total"],
            "bytes": r.memory.bytes, "states_lost": r.states_lost}


def clear_cache() -> None:
    """Forget the solutions and the warm-start states held in memory (a disk cache stays)."""
    r = forward_runner()
    r.memory.clear()
    r.states.clear()
    r.job_states.clear()


def grid_angles_deg(steps: int, period: float) -> np.ndarray:
    """Input angles of the uniform grid over one output revolution, deg (``k * period / steps``;
    ``period`` = N * 360 deg, see :func:`rvcalib.orders.period_deg`)."""
    return np.arange(steps) * (float(period) / steps)


#: validated cases by their JSON text (:func:`validated_case`), at most this many kept
CASE_MEMO_SIZE = 4096
case_memo = LRUMemo(CASE_MEMO_SIZE)


def validated_case(case_dict: dict[str, Any]) -> Case:
    """The validated case of a case JSON (a :class:`ModelEvaluationError` when it is refused). The loop asks for
    the same case many times (its period, its batch, the cache's key): a case validated before is taken from a
    memo keyed by its JSON text (least recently used out first; a :class:`~rvcad.errors.Case` is frozen)."""
    key = json.dumps(case_dict, sort_keys=True, default=str)
    got = case_memo.get(key)
    if got is not None:
        return got
    try:
        got = Case.from_dict(case_dict)
    except ValueError as exc:
        raise ModelEvaluationError(str(exc)) from None
    case_memo.put(key, got)
    return got


def case_period_deg(case_dict: dict[str, Any]) -> float:
    """Input angle of one output revolution of a case JSON's design, deg."""
    return period_deg(validated_case(case_dict).design)


def grid_te(case_dict: dict[str, Any], steps: int, solver: str = "analytic") -> np.ndarray:
    """Model TE (arcsec) on the uniform grid of one output revolution, ascending input angle
    (:func:`te_at` at :func:`grid_angles_deg`).

    Parameters
    ----------
    case_dict : dict
        Case JSON (``errors``, ``model``, ``load_Nm``, ``direction``).
    steps : int
        Grid points per output revolution.
    solver : str
        rvdyn contact provider.

    Raises
    ------
    ModelEvaluationError
        If rvdyn refuses the case (interference beyond the contact law) or does not converge.
    """
    return te_at(case_dict, grid_angles_deg(int(steps), case_period_deg(case_dict)), solver)


def grid_te_many(case_dicts: Sequence[dict[str, Any]], steps: int | Sequence[int],
                 solver: str = "analytic", sensitivity: bool = False) -> list[np.ndarray | ModelEvaluationError]:
    """:func:`grid_te` of many cases in one batch of the runner (one ``steps`` or one per case); a case
    rvdyn cannot evaluate gives its :class:`ModelEvaluationError` in its place instead of raising.
    ``sensitivity``: as in :func:`te_at_many`."""
    st = [int(steps)] * len(case_dicts) if isinstance(steps, (int, np.integer)) else [int(s) for s in steps]
    angles: list[np.ndarray | None] = []
    for d, s in zip(case_dicts, st):
        try:
            angles.append(grid_angles_deg(s, case_period_deg(d)))
        except ModelEvaluationError:
            angles.append(None)
    return te_at_many(case_dicts, angles, solver, sensitivity=sensitivity)


def te_at(case_dict: dict[str, Any], input_deg: np.ndarray, solver: str = "analytic") -> np.ndarray:
    """Model TE (arcsec) exactly at given input angles (deg, any revolution), in their order.

    TE is periodic in one output revolution, so each angle is reduced modulo it and equal angles
    (to 1e-9 deg) are solved once. This is the forward model for readings that are not on a
    uniform grid: the TE has kinks where pins pick up or drop load and content up to many times
    the input order N, so interpolating a grid solution is not exact (a single-pin pitch error
    of 0.02 deg interpolated from 1440 points per revolution is off by 0.18 arcsec RMS, 1.3 arcsec
    at the worst sample).

    Raises
    ------
    ModelEvaluationError
        If rvdyn refuses the case (interference beyond the contact law) or does not converge.
    """
    out = te_at_many([case_dict], [input_deg], solver)[0]
    if isinstance(out, ModelEvaluationError):
        raise out
    return out


def te_at_many(case_dicts: Sequence[dict[str, Any]], input_deg: Sequence[np.ndarray | None],
               solver: str = "analytic", sensitivity: bool = False) -> list[np.ndarray | ModelEvaluationError]:
    """:func:`te_at` of many cases (each with its angles) in one batch of the forward runner; a case
    rvdyn cannot evaluate (or whose angles are None) gives a :class:`ModelEvaluationError` in its place.

    ``sensitivity``: sensitivity solves (:meth:`rvdyn.runner.Runner.__call__`'s ``max_outer=1``): each case with a
    warm start moves by one linearisation from its run condition's newest converged state (the case asked for
    last). For the differences the loop takes over small steps from that state (a Jacobian's finite-difference
    columns, the joint step's columns), which they give within about 1 % of themselves at about 0.55 of the CPU;
    not for the screening signatures or the members' parts (steps of a whole scale or size, where contacts open
    or close: 14 % off for 10 um of pin-circle diameter), and never for a residual that a decision compares
    (a fit's evaluations converge). docs/calibration.md, "Loop speed"."""
    if len(input_deg) != len(case_dicts):
        raise ValueError(f"input_deg has {len(input_deg)} entries for {len(case_dicts)} cases")
    runner = forward_runner()
    if solver != runner.solver:
        raise ValueError(f"solver {solver!r}: the forward runner solves with {runner.solver!r}")
    out: list[np.ndarray | ModelEvaluationError | None] = [None] * len(case_dicts)
    todo: list[tuple[int, Case, np.ndarray, np.ndarray, bool]] = []  # index, case, angles solved, inverse, reversed
    for i, (d, a) in enumerate(zip(case_dicts, input_deg)):
        try:
            case = validated_case(d)
        except ModelEvaluationError as exc:
            out[i] = exc
            continue
        if a is None:
            out[i] = ModelEvaluationError(f"case {i} has no angles")
            continue
        period = period_deg(case.design)
        x = np.mod(np.asarray(a, dtype=float), period)
        u, inv = np.unique(np.round(x, 9), return_inverse=True)
        rev = case.direction == -1
        u_run = u[::-1] if rev else u  # in the order of motion
        pts = u_run if u_run.size >= 2 else np.append(u_run, u_run + period / 2)
        todo.append((i, case, pts, inv, rev))
    # the cases that differ only in load and direction are solved together, GROUP_CONDITIONS at a time in their
    # order in the batch (rvdyn.te.run_te_many: one linearisation and inner solve per outer iteration for all of
    # them), whatever the workers: a group is solved by one worker as it is in this process, so a batch's numbers
    # are the serial ones bit for bit (stop 28: a split that depended on the workers changed the rounding, and a
    # realistic draw took another path); a single state's conditions (a chord trial) and the states of a batch (a
    # Jacobian's columns, the screening signatures) spread over the workers
    states = [_group_label(case_dicts[t[0]]) for t in todo]
    count = Counter(states)
    seen: dict[str, int] = {}
    labels = []
    for lab in states:
        k = seen.get(lab, 0)
        seen[lab] = k + 1
        # an odd last condition joins the group before it: a group of one is solved alone (rvdyn.te.run_te), without
        # the batch's per-state exit, and under the impact law that cost a loop test half as much again
        last = max(count[lab] // GROUP_CONDITIONS - 1, 0)
        labels.append(f"{lab}#{min(k // GROUP_CONDITIONS, last)}")
    grouped = len(todo) > 1
    res = runner([t[1] for t in todo], "forward model", theta_in_deg=[t[2] for t in todo],
                 group=labels if grouped else None, max_outer=1 if sensitivity else None)
    for (i, _, _, inv, rev), r in zip(todo, res):
        if r["status"] != "ok":
            out[i] = ModelEvaluationError(f"rvdyn could not evaluate the case: {r['error']}")
            continue
        te = r["te_arcsec"][:int(inv.max()) + 1]  # without the padding angle of a single-angle request
        out[i] = (te[::-1] if rev else te)[inv]
    return out  # type: ignore[return-value]


def _group_label(case_dict: dict[str, Any]) -> str:
    """A case JSON without its load, direction and name (the cases of one label are one batch)."""
    return json.dumps({k: v for k, v in case_dict.items() if k not in ("load_Nm", "direction", "name")},
                      sort_keys=True, default=str)


def merge_case(base: dict[str, Any], errors: list[tuple[str, dict]] | None = None,
               model: dict[str, float] | None = None) -> dict[str, Any]:
    """A copy of a case JSON with additional error instances and model options.

    Parameters
    ----------
    base : dict
        Case JSON; its ``errors`` values may be numbers (default instance), objects or lists.
    errors : list of (key, item)
        Error instances to add, each an object ``{"value": v, <instance keys>, "angle_deg": a}``.
    model : dict
        Model options to set (they replace the base's).
    """
    d = copy.deepcopy(base)
    errs: dict[str, Any] = d.setdefault("errors", {})
    for key, item in errors or []:
        cur = errs.get(key)
        if cur is None:
            errs[key] = [item]
            continue
        if isinstance(cur, list) and cur and not isinstance(cur[0], dict):
            # pin-wise list of numbers: add to the right pin(s)
            cur = list(cur)
            pins = range(len(cur)) if item.get("pin") is None else [item["pin"]]
            for p in pins:
                cur[p] = float(cur[p]) + float(item["value"])
            errs[key] = cur
            continue
        items = cur if isinstance(cur, list) else [cur]
        items = [x if isinstance(x, dict) else {"value": x} for x in items]
        errs[key] = items + [item]
    if model:
        m = d.setdefault("model", {})
        m.update(model)
    return d


def fmt_angle(deg: float) -> float:
    """An angle wrapped to (-180, 180] deg."""
    a = math.fmod(deg + 180.0, 360.0)
    if a <= 0:
        a += 360.0
    return a - 180.0
