"""One forward runner: many TE solves, cached on disk, in this process, a local pool or a Dask cluster.

Use
---
>>> from rvdyn.runner import run_cases
>>> res = run_cases(cases, solver="analytic", steps=360, cache="cache-dir", executor=2)  # doctest: +SKIP
>>> res[0]["stats"]["pp"], res[0]["te_arcsec"]  # doctest: +SKIP

or keep one :class:`Runner` (its caches, executor and counters) for several batches::

    with Runner(executor=2, cache="cache-dir", solver="fcl", steps=360, memory_bytes=2**26) as run:
        first = run(cases_a, "screen")
        second = run(cases_b, "design", steps=[720] * len(cases_b))        # per-case steps
        third = run(cases_c, "readings", theta_in_deg=[angles_c0, angles_c1])  # at given input angles
        draws = run(cases_d, "draws", steps=[360, 37, 37], group=[0, 0, 0])   # one worker task (solve_group)
        run.prefetch(cases_e, "ahead")   # solved now, read later by run(cases_e, ...) without counting twice

Every call returns one result dict per case, in the order of the cases:

* ``key`` -- the cache key (:meth:`rvdyn.cache.Job.key`); equal jobs are solved once per call;
* ``status`` -- ``ok`` or ``failed`` (an interference the contact law cannot resolve or a solver that
  did not converge: a property of the case, cached as such; missing software raises instead);
* ``stats`` -- ``pp, mean, mean_abs, rms`` of the TE (arcsec, :func:`rvdyn.te.te_stats`), ``ratio``
  and ``seconds`` (solver wall time, s); NaN when failed;
* ``te_arcsec`` -- the TE curve (ndarray, arcsec, one value per step or per given input angle, in the
  order of motion) or None when failed;
* ``error`` -- the message of a failed solve (else empty); ``cached`` -- taken from a cache.

Two caches, both keyed by :meth:`rvdyn.cache.Job.key`: the disk cache (:class:`rvdyn.cache.CaseCache`,
survives the process) and the in-memory one (:class:`MemoryCache`): within its ``memory_bytes`` budget
for callers that ask for the same solves again and again within a process (e.g. a fit's trial values),
and beside it, pinned outside that budget until :meth:`MemoryCache.clear`, the results of :meth:`Runner.prefetch`.

Warm starts (``Runner(warm_bytes=...)``, off by default): the runner keeps the newest converged solver state of each
neighbourhood (:meth:`rvdyn.cache.Job.neighbour_key`: the same design, load, direction, solver, law and angles) in a
:class:`rvdyn.cache.StateStore` and starts the next solve of that neighbourhood from it (``x_init`` of :func:`rvdyn.te.run_te`);
results equal the cold solves' within the solver tolerance. The states never enter the result caches. A converged
case taken from a cache becomes its neighbourhood's newest state again (its state kept by job key, ``job_states``),
so the solves after it start from the case asked for last; when its state is no longer kept (beyond the budget, or
solved by another process) the neighbourhood is left without a state (counted in ``states_lost``), so that the
solves after it converge rather than start from another case. Sensitivity solves (``max_outer=1``, see
:func:`rvdyn.te.run_te`) have keys of their own and leave no state behind.

Executors (:mod:`rvdyn.executors`) run the same worker function, :func:`solve_job`, on JSON-ready job payloads
(:meth:`rvdyn.cache.Job.to_payload`) and yield ``(index, result)`` pairs as they finish. The results
come back to this process, which alone writes the cache; Dask workers therefore need the package
installed but no shared disk.

* :class:`SerialExecutor` -- one case after another in this process.
* :class:`LocalPoolExecutor` -- :class:`concurrent.futures.ProcessPoolExecutor` with the ``spawn``
  start method; its workers end themselves when the process that started them dies.
* :class:`DaskExecutor` -- ``dask.distributed.Client(address)``.

Nothing here holds a design constant: everything about the reducer comes from each case.
"""
from __future__ import annotations

import functools
import hashlib
import math
import sys
import time
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rvcad.errors import Case
from rvdyn.contacts import ContactLaw
from rvdyn.cache import CaseCache, Job, StateStore
from rvdyn.executors import (PARENT_POLL_S, DaskExecutor, Executor, LocalPoolExecutor, SchedulerError, SerialExecutor,
                             SolveFn, make_executor)
from rvdyn.solver import law_from_model
from rvdyn.te import SOLVERS, check_max_outer, run_te

__all__ = ["Runner", "run_cases", "solve_job", "solve_group", "MemoryCache", "StateStore", "ENTRY_OVERHEAD_BYTES",
           # executors (rvdyn.executors), re-exported: the runner is where users meet them
           "Executor", "SerialExecutor", "LocalPoolExecutor", "DaskExecutor", "SchedulerError", "make_executor",
           "PARENT_POLL_S", "SolveFn"]

_STAT_KEYS = ("pp", "mean", "mean_abs", "rms", "ratio", "seconds")


def _failed(key: str, exc: BaseException, secs: float) -> dict[str, Any]:
    stats = {k: float("nan") for k in _STAT_KEYS}
    stats["seconds"] = secs
    return {"key": key, "status": "failed", "stats": stats, "te_arcsec": [], "error": f"{type(exc).__name__}: {exc}"}


def _ok(key: str, r: Any, secs: float | None = None, state: bool = False) -> dict[str, Any]:
    stats = {k: float(r.stats[k]) for k in _STAT_KEYS}
    if secs is not None:
        stats["seconds"] = float(secs)
    out = {"key": key, "status": "ok", "stats": stats,
           "te_arcsec": [float(x) for x in r.table["te_arcsec"].to_numpy()], "error": ""}
    if state and getattr(r, "state", None) is not None:
        out["state"] = np.asarray(r.state, dtype=np.float64)  # the runner's warm starts (never cached)
    return out


_SOLVE_ERRORS = (ValueError, RuntimeError, FloatingPointError, np.linalg.LinAlgError)


def solve_job(payload: dict[str, Any]) -> dict[str, Any]:
    """Solve one job payload (worker side).

    Parameters
    ----------
    payload : dict
        ``case`` (case dict), ``solver``, ``steps``, ``revolutions``, ``law`` ({K, n, rigid}), ``key``
        and optionally ``theta_in_deg`` (list of input angles, deg, replacing steps and revolutions),
        ``x_init`` (start states of the solve, a nearby case's converged states: a warm start), ``max_outer``
        (1: a sensitivity solve from ``x_init``, :func:`rvdyn.te.run_te`) and
        ``want_state`` (True: return the converged states as ``state``).

    Returns
    -------
    dict
        ``key``, ``status`` (``ok`` or ``failed``), ``stats`` (``pp, mean, mean_abs, rms`` in arcsec,
        ``ratio``, ``seconds``), ``te_arcsec`` (list, one value per step; empty when failed) and
        ``error`` (message of a failed solve: an interference the contact law cannot resolve or a
        solver that did not converge; both are properties of the case and are cached as such); with
        ``want_state``, ``state`` (ndarray (steps, ndof), :attr:`rvdyn.te.TEResult.state`).
        Missing software (e.g. the fcl provider) raises instead and is never cached.
    """
    case = Case.from_dict(payload["case"])
    law = ContactLaw(**payload["law"])
    t0 = time.perf_counter()
    th = payload.get("theta_in_deg")
    try:
        r = run_te(case, payload["solver"], int(payload["steps"]), float(payload["revolutions"]), law=law,
                   theta_in_deg=None if th is None else np.asarray(th, dtype=float), x_init=payload.get("x_init"),
                   max_outer=payload.get("max_outer"))
    except _SOLVE_ERRORS as exc:  # ImportError (missing software) is none of these and propagates
        return _failed(payload["key"], exc, time.perf_counter() - t0)
    return _ok(payload["key"], r, state=payload.get("want_state", False))


def solve_group(payload: dict[str, Any], solve_fn: SolveFn | None = None) -> dict[str, Any]:
    """Solve a group of job payloads whose cases differ only in load and direction (worker side).

    The case is read and its geometry built once for the group; the jobs of equal ``revolutions`` (each at
    its steps or its given input angles), all under a load > 0, go to :func:`rvdyn.te.run_te_many` in one
    call (the analytic provider solves their states together; each result equals :func:`rvdyn.te.run_te`'s within the
    solver tolerance; a pair that cannot be solved fails alone with its error, the others stand), the
    others to :func:`rvdyn.te.run_te` one after another on the shared geometry (the geometry does not
    depend on the load or the direction).

    Parameters
    ----------
    payload : dict
        ``key`` (of the group) and ``jobs`` (list of :func:`solve_job` payloads; same solver and law).
    solve_fn : callable or None
        A worker function other than :func:`solve_job` (tests): then each job goes through it alone.

    Returns
    -------
    dict
        ``key`` (the group's), ``results`` (one :func:`solve_job` result per job, in order) and
        ``task_seconds`` (wall time of the task in the worker, s).
    """
    t_task = time.perf_counter()
    out = _solve_group(payload, solve_fn)
    out["task_seconds"] = time.perf_counter() - t_task
    return out


def _solve_group(payload: dict[str, Any], solve_fn: SolveFn | None) -> dict[str, Any]:
    jobs = payload["jobs"]
    if solve_fn is not None and solve_fn is not solve_job:
        return {"key": payload["key"], "results": [solve_fn(p) for p in jobs]}
    import rvdyn.te as te
    from rvcad.geometry import ReducerGeometry

    results: list[dict[str, Any] | None] = [None] * len(jobs)
    try:
        case = Case.from_dict(jobs[0]["case"])
        geom = ReducerGeometry(case)
    except _SOLVE_ERRORS:  # every job of the group shares the case: each fails as it would alone
        return {"key": payload["key"], "results": [solve_job(p) for p in jobs]}
    law = ContactLaw(**jobs[0]["law"])
    runs: dict[float, list[int]] = {}  # jobs that one run_te_many call can take: same revolutions
    for i, p in enumerate(jobs):
        runs.setdefault(float(p["revolutions"]), []).append(i)
    for revs, idx in runs.items():
        loads = [(float(jobs[i]["case"].get("load_Nm", 20.0)), int(jobs[i]["case"].get("direction", 1))) for i in idx]
        steps = [int(jobs[i]["steps"]) for i in idx]
        given = [jobs[i].get("theta_in_deg") for i in idx]
        starts = [jobs[i].get("x_init") for i in idx]
        if len(idx) > 1 and all(load > 0 for load, _ in loads):
            t0 = time.perf_counter()
            try:  # a pair that cannot be solved comes back as its error, the others as results
                rs = te.run_te_many(case, payload["solver"], steps, loads=loads, revolutions=revs, law=law, geom=geom,
                                    errors="return", theta_in_deg=given, x_init=starts,
                                    max_outer=jobs[idx[0]].get("max_outer"))
            except _SOLVE_ERRORS:
                rs = None  # solved job by job below
            if rs is not None:
                secs = (time.perf_counter() - t0) / len(idx)
                for i, r in zip(idx, rs):
                    k = jobs[i]["key"]
                    results[i] = (_failed(k, r, secs) if isinstance(r, BaseException)
                                  else _ok(k, r, state=jobs[i].get("want_state", False)))
                continue
        for i, n, (load, d), th, xi in zip(idx, steps, loads, given, starts):
            t0 = time.perf_counter()
            try:
                r = te.run_te(case, payload["solver"], n, revs, load, d, law, geom=geom,
                              theta_in_deg=None if th is None else np.asarray(th, dtype=float), x_init=xi,
                              max_outer=jobs[i].get("max_outer"))
            except _SOLVE_ERRORS as exc:
                results[i] = _failed(jobs[i]["key"], exc, time.perf_counter() - t0)
                continue
            results[i] = _ok(jobs[i]["key"], r, state=jobs[i].get("want_state", False))
    return {"key": payload["key"], "results": results}


def _payload(job: Job, key: str) -> dict[str, Any]:
    """:meth:`rvdyn.cache.Job.to_payload` with its key already computed (the key is the costly part)."""
    d = {"case": job.case.to_dict(), **job.settings(), "key": key}
    if job.theta_in_deg is not None:
        d["theta_in_deg"] = [float(x) for x in job.theta_in_deg]
    return d


def _solve_task(payload: dict[str, Any], solve_fn: SolveFn = solve_job) -> dict[str, Any]:
    """Worker function of a batch with groups: a group payload (``jobs``) or a single job payload."""
    return solve_group(payload, solve_fn) if "jobs" in payload else solve_fn(payload)


#: Bytes counted per in-memory entry besides its TE array (the result dict, its stats and key; an estimate).
ENTRY_OVERHEAD_BYTES = 1024


class MemoryCache:
    """Results of this process by job key: the least recently used dropped first beyond ``max_bytes``,
    except pinned entries, which stay until :meth:`clear` (:meth:`Runner.prefetch`'s results).

    Entries are result dicts whose ``te_arcsec`` is a read-only float64 array (or None when failed).

    Parameters
    ----------
    max_bytes : int
        Budget of the unpinned entries, bytes: each entry counts its TE array plus
        :data:`ENTRY_OVERHEAD_BYTES` (>= 0; 0 keeps only pinned entries).

    Attributes
    ----------
    hits, misses : int
        Lookups since construction.
    bytes : int
        Bytes held now (pinned entries included).
    pinned_bytes : int
        Bytes of the pinned entries.
    """

    def __init__(self, max_bytes: int) -> None:
        if isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, np.integer)) or max_bytes < 0:
            raise ValueError(f"memory_bytes {max_bytes!r} must be an integer >= 0")
        self.max_bytes = int(max_bytes)
        self._d: OrderedDict[str, tuple[dict[str, Any], int, bool]] = OrderedDict()  # entry, size, pinned
        self.bytes = self.pinned_bytes = self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._d)

    def get(self, key: str) -> dict[str, Any] | None:
        """The stored result of a key (now the most recently used), or None."""
        hit = self._d.get(key)
        if hit is None:
            self.misses += 1
            return None
        self._d.move_to_end(key)
        self.hits += 1
        return hit[0]

    def pinned(self, key: str) -> bool:
        """True if the key's entry is pinned (no lookup is counted)."""
        hit = self._d.get(key)
        return hit is not None and hit[2]

    def put(self, key: str, result: dict[str, Any], pin: bool = False) -> dict[str, Any]:
        """Keep a result (its TE made a read-only array), pinned if ``pin`` (an entry once pinned stays
        pinned); drop the oldest unpinned entries beyond the budget. Returns the entry as kept."""
        te = result.get("te_arcsec")
        if te is not None:
            te = np.array(te, dtype=np.float64)
            te.setflags(write=False)
        entry = {**result, "te_arcsec": te}
        size = ENTRY_OVERHEAD_BYTES + (0 if te is None else te.nbytes)
        old = self._d.pop(key, None)
        if old is not None:
            pin = pin or old[2]
            self.bytes -= old[1]
            self.pinned_bytes -= old[1] if old[2] else 0
        self._d[key] = (entry, size, pin)
        self.bytes += size
        self.pinned_bytes += size if pin else 0
        if self.bytes - self.pinned_bytes > self.max_bytes:
            for k in [k for k, v in self._d.items() if not v[2]]:  # oldest first
                self.bytes -= self._d.pop(k)[1]
                if self.bytes - self.pinned_bytes <= self.max_bytes:
                    break
        return entry

    def clear(self) -> None:
        """Forget every entry (pinned ones too)."""
        self._d.clear()
        self.bytes = self.pinned_bytes = 0


def _check_steps(steps: Any, what: str = "steps") -> int:
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 2:
        raise ValueError(f"{what} {steps!r} must be an integer >= 2")
    return int(steps)


class Runner:
    """Solve cases through an executor, reusing and filling a :class:`rvdyn.cache.CaseCache` and a
    :class:`MemoryCache`.

    ``runner(cases, desc)`` returns one result dict per case, in order (see the module docstring).
    Equal jobs (equal keys) are solved once per call. Every finished solve is written to the cache at
    once, so an interrupted run loses only the solves in flight.

    Parameters
    ----------
    executor : Executor, int, str or None
        An executor; or a number of local worker processes (1 = this process); or a Dask scheduler
        address. Default: this process. An executor made here is closed by :meth:`close` (or at the
        end of a ``with`` block); one passed in is the caller's to close.
    cache : CaseCache, str, Path or None
        The cache or its folder; None: no cache (every case is solved, nothing written).
    solver : {"analytic", "fcl"}
        Contact provider.
    steps : int
        Default steps per ``revolutions`` output turns (>= 2).
    law : ContactLaw or None
        Contact law of every case; None: each case's own (its ``model`` options,
        :func:`rvdyn.solver.law_from_model`, as :func:`rvdyn.te.run_te` does: the physical law unless
        the case's ``model.contact`` says ``impact``).
    revolutions : float
        Output revolutions of a solve.
    progress : bool
        tqdm bars on stderr.
    solve_fn : callable
        Worker function (default :func:`solve_job`; tests swap it).
    memory_bytes : int
        Budget of the in-memory cache, bytes (:class:`MemoryCache`; default 0: it keeps only what
        :meth:`prefetch` pins). Looked up before the disk cache and filled from it and from every solve.
    warm_bytes : int
        Budget of the warm starts, bytes (:class:`StateStore`; default 0: none, every solve starts cold as
        :func:`rvdyn.te.run_te` does). With a budget, every solve returns its converged states, kept per
        neighbourhood (:meth:`rvdyn.cache.Job.neighbour_key`), and a solve whose neighbourhood has a state
        starts from it (``x_init``): a closed loop's solves are small perturbations of solved cases (its
        finite-difference columns, trial steps, candidates at the current state), which then take fewer
        outer and Newton iterations. Each result equals the cold solve's within the solver tolerance
        (``Tolerances.solver_angle_rad``); which state a solve starts from depends on the order of the
        solves, so results are reproducible to that tolerance, not bit for bit. A converged case taken from a cache
        is its neighbourhood's newest state again (:attr:`job_states`, the same budget).

    Attributes
    ----------
    computed, reused, failed : int
        Unique solves done now, taken from a cache (memory or disk), and failed (computed or cached),
        cumulative.
    memory : MemoryCache
        The in-memory cache (its unpinned entries within ``memory_bytes``; the prefetched results pinned).
    solve_seconds : list of float
        Solver wall time of every computed case, s.
    wall_seconds : float
        Wall time spent in calls, s.
    worker_seconds : float
        Wall time the workers spent on this runner's tasks (solves, case reading, geometry), s.
    """

    def __init__(self, executor: Executor | int | str | None = None, cache: CaseCache | str | Path | None = None,
                 solver: str = "analytic", steps: int = 720, law: ContactLaw | None = None,
                 revolutions: float = 1.0, progress: bool = False, solve_fn: SolveFn = solve_job,
                 memory_bytes: int = 0, warm_bytes: int = 0) -> None:
        if solver not in SOLVERS:
            raise ValueError(f"solver {solver!r} is unknown; allowed: {list(SOLVERS)}")
        self.steps = _check_steps(steps)
        if not (isinstance(revolutions, (int, float)) and math.isfinite(revolutions) and revolutions > 0):
            raise ValueError(f"revolutions {revolutions!r} must be a finite number > 0")
        self._own = not hasattr(executor, "run")
        if executor is None:
            executor = SerialExecutor()
        elif isinstance(executor, str):
            executor = DaskExecutor(executor)
        elif not hasattr(executor, "run"):
            executor = make_executor(workers=executor)
        self.executor: Executor = executor
        self.memory = MemoryCache(memory_bytes)
        self.states = StateStore(warm_bytes)
        # the state of each converged solve by its job key (the same arrays as ``states``, within the same budget), so
        # that a case taken from a cache can be made its neighbourhood's newest state again
        self.job_states = StateStore(warm_bytes)
        self.cache = cache if isinstance(cache, CaseCache) else CaseCache(cache)
        self.solver = solver
        self.law = law
        self.revolutions = float(revolutions)
        self.progress = progress
        self.solve_fn = solve_fn
        self.computed = self.reused = self.failed = 0
        self.states_lost = 0       # converged cases asked for again whose warm state was no longer kept
        self.solve_seconds: list[float] = []
        self.wall_seconds = 0.0
        self.worker_seconds = 0.0

    def jobs(self, cases: Sequence[Case], steps: int | Sequence[int] | None = None,
             theta_in_deg: Sequence[Sequence[float] | np.ndarray | None] | None = None,
             max_outer: int | None = None) -> list[Job]:
        """The jobs of a batch (see :meth:`__call__` for the arguments)."""
        check_max_outer(max_outer)
        cases = list(cases)
        n = len(cases)
        if steps is None or isinstance(steps, (int, np.integer)):
            st = [_check_steps(self.steps if steps is None else steps)] * n
        else:
            st = [_check_steps(x, f"steps[{i}]") for i, x in enumerate(steps)]
            if len(st) != n:
                raise ValueError(f"steps has {len(st)} entries for {n} cases")
        th: list[tuple[float, ...] | None] = [None] * n
        if theta_in_deg is not None:
            if len(theta_in_deg) != n:
                raise ValueError(f"theta_in_deg has {len(theta_in_deg)} entries for {n} cases")
            for i, a in enumerate(theta_in_deg):
                if a is None:
                    continue
                arr = np.asarray(a, dtype=np.float64)
                if arr.ndim != 1 or arr.size < 2 or not np.all(np.isfinite(arr)):
                    raise ValueError(f"theta_in_deg[{i}] must be a 1-D array of at least 2 finite angles (deg); "
                                     f"got shape {arr.shape}")
                th[i] = tuple(float(x) for x in arr)
        mo = None if max_outer is None else int(max_outer)
        return [Job(c, self.solver, s, self.revolutions, self.law if self.law is not None else law_from_model(c.model),
                    t, mo) for c, s, t in zip(cases, st, th)]

    def __call__(self, cases: Sequence[Case], desc: str = "cases", *, steps: int | Sequence[int] | None = None,
                 theta_in_deg: Sequence[Sequence[float] | np.ndarray | None] | None = None,
                 group: Sequence[Any] | None = None, keep: bool = False,
                 max_outer: int | None = None) -> list[dict[str, Any]]:
        """Solve a batch of cases.

        Parameters
        ----------
        cases : sequence of Case
        desc : str
            Label of the progress bar.
        steps : int, sequence of int or None
            Steps for every case, or one per case; default the runner's.
        theta_in_deg : sequence of (array or None), or None
            Per case, explicit input angles (deg, order of motion) that replace steps and revolutions,
            or None for that case.
        group : sequence or None
            Per case, a label (any hashable) or None: the uncached cases of one label are solved in one
            worker task (:func:`solve_group`: one case read and geometry built, the jobs of one step
            count batched); they must differ only in load and direction (ValueError otherwise). Each
            case keeps its own cache entry, so grouped and single solves share the cache.
        keep : bool
            Keep the results in memory for later calls (:meth:`prefetch`).
        max_outer : int or None
            1: sensitivity solves (:func:`rvdyn.te.run_te`'s ``max_outer``): each case that has a warm start
            (``warm_bytes``) moves by one linearisation from its neighbourhood's newest converged state; their
            results have keys of their own and their states are not kept as warm starts (the next solves start
            from converged equilibria). None (default): converged solves.

        Returns
        -------
        list of dict
            One result per case (module docstring).
        """
        from tqdm.auto import tqdm

        t0 = time.perf_counter()
        jobs = self.jobs(cases, steps, theta_in_deg, max_outer)
        keys = [j.key() for j in jobs]
        unique: dict[str, Job] = {}
        for k, j in zip(keys, jobs):
            unique.setdefault(k, j)
        results, todo, prefetched = self._lookup(unique)
        self.reused += len(results) - len(prefetched)
        if self.states.max_bytes > 0:
            self._renew_states(unique, results)
        tasks = self._tasks(todo, keys, group, len(jobs))
        payloads = [_payload(unique[t[0]], t[0]) if len(t) == 1 else self._group_payload([unique[k] for k in t], t)
                    for t in tasks]
        near: dict[str, str] = {}
        waves = [list(range(len(tasks)))]
        if self.states.max_bytes > 0:  # warm starts: each job from its neighbourhood's newest state, if any
            for t, p in zip(tasks, payloads):
                for k, q in zip(t, p["jobs"] if "jobs" in p else [p]):
                    near[k] = unique[k].neighbour_key()
                    q["want_state"] = unique[k].max_outer is None  # a sensitivity solve leaves no state behind
            waves = self._waves(tasks, near)
        fn = self.solve_fn if all(len(t) == 1 for t in tasks) else functools.partial(_solve_task,
                                                                                     solve_fn=self.solve_fn)
        bar = tqdm(total=len(unique), initial=len(results), desc=desc, unit="case", file=sys.stderr,
                   disable=not self.progress, dynamic_ncols=True)
        try:
            for wave in waves:
                self._run_wave(fn, wave, tasks, payloads, near, results, bar)
        finally:
            bar.close()
            self.wall_seconds += time.perf_counter() - t0
        return self._deliver(unique, keys, results, prefetched, keep)

    def _deliver(self, unique: dict[str, Job], keys: list[str], results: dict[str, dict[str, Any]],
                 prefetched: set[str], keep: bool) -> list[dict[str, Any]]:
        """The results of a call in the order of its cases, each the caller's own copy (its TE a new array); counts
        the failed ones not prefetched and, with ``keep``, pins the results in memory."""
        self.failed += sum(1 for k in unique if results[k].get("status") == "failed" and k not in prefetched)
        if keep:  # pinned with the cached flag of this call, for later calls (counted now)
            for k in unique:
                if k not in prefetched:
                    self.memory.put(k, results[k], pin=True)
        out = []
        for k in keys:
            r = dict(results[k])
            te = r["te_arcsec"]
            r["te_arcsec"] = None if te is None else np.array(te, dtype=float)  # the caller's own copy
            out.append(r)
        return out

    def _lookup(self, unique: dict[str, Job]) -> tuple[dict[str, dict[str, Any]], list[str], set[str]]:
        """The results of a batch's jobs found in this runner's memory or its disk cache (with ``cached`` True;
        the pinned ones of :meth:`prefetch` as they were kept), the keys to solve, and the prefetched keys."""
        results: dict[str, dict[str, Any]] = {}
        todo: list[str] = []
        prefetched: set[str] = set()
        for k in unique:
            if self.memory.pinned(k):  # solved (or taken from the cache) by this runner's prefetch: counted there
                results[k] = self.memory.get(k)  # type: ignore[assignment]
                prefetched.add(k)
                continue
            hit = self.memory.get(k)
            if hit is None:
                hit = self.cache.get(k)
                if hit is not None:
                    hit = self._keep(k, hit)
            if hit is None:
                todo.append(k)
            else:
                results[k] = {**hit, "cached": True}
        return results, todo, prefetched

    def _renew_states(self, unique: dict[str, Job], results: dict[str, dict[str, Any]]) -> None:
        """Make each converged case taken from a cache its neighbourhood's newest warm-start state again, or
        leave the neighbourhood without a state when the case's own is no longer kept (``states_lost``)."""
        # the solves after such a case start from the case last asked for (e.g. a Jacobian's columns from the state
        # at which they are taken, even when other solves of that run condition came in between). When its state is
        # no longer kept (beyond the budget, or solved by another process) the neighbourhood's newest state is
        # another case's, and sensitivity solves from there would give their differences against that case,
        # not against this one: the neighbourhood is left without a state, so the solves after it converge
        # (a Jacobian differenced from another case's state can come out nearly of rank one)
        for k in unique:
            if k in results and unique[k].max_outer is None:
                st = self.job_states.get(k)
                if st is not None:
                    self.states.put(unique[k].neighbour_key(), st)
                else:
                    self.states.discard(unique[k].neighbour_key())
                    self.states_lost += 1

    def _run_wave(self, fn: SolveFn, wave: list[int], tasks: list[list[str]], payloads: list[dict[str, Any]],
                  near: dict[str, str], results: dict[str, dict[str, Any]], bar: Any) -> None:
        """Solve the tasks ``wave`` (indices of ``tasks`` and ``payloads``) through the executor, from the warm
        starts of their neighbourhoods ``near`` (job key -> neighbourhood key; empty: none): each result is
        checked against its key, cached and put in ``results``; the converged states then become the
        neighbourhoods' newest."""
        if near:
            for i in wave:
                for k, q in zip(tasks[i], payloads[i]["jobs"] if "jobs" in payloads[i] else [payloads[i]]):
                    x0 = self.states.get(near[k])
                    if x0 is not None:
                        q["x_init"] = x0
        # the wave's converged states go to the warm-start store in task order once the wave is done, not
        # as the results arrive: with several workers the next solves' starts (hence their rounding) do not
        # depend on which worker finished first
        arrived: list[tuple[int, str, np.ndarray]] = []
        for j, res in self.executor.run(fn, [payloads[i] for i in wave]):
            i = wave[j]
            got = res["results"] if "results" in res else [res]
            self.worker_seconds += float(res.get("task_seconds", res.get("stats", {}).get("seconds", 0.0)))
            if res.get("key") != payloads[i]["key"] or len(got) != len(tasks[i]):
                raise RuntimeError(f"worker returned the result of {res.get('key')!r} for "
                                   f"{payloads[i]['key']!r}")
            for k, r in zip(tasks[i], got):
                if r.get("key") != k:
                    raise RuntimeError(f"worker returned the result of {r.get('key')!r} for {k!r}")
                state = r.pop("state", None)
                if state is not None and k in near:
                    arrived.append((i, k, state))
                self.cache.put(k, r)
                results[k] = {**self._keep(k, r), "cached": False}
                self.computed += 1
                self.solve_seconds.append(float(r["stats"].get("seconds", math.nan)))
            bar.update(len(got))
        for _, k, state in sorted(arrived, key=lambda a: a[0]):  # stable: a task's jobs in their order
            self.states.put(near[k], state)
            kept = self.states.peek(near[k])
            if kept is not None:
                self.job_states.put(k, kept)

    def _keep(self, key: str, res: dict[str, Any]) -> dict[str, Any]:
        """A result with its TE as an array (None when failed), kept in memory (within its budget)."""
        te = res.get("te_arcsec")
        r = {**res, "te_arcsec": np.asarray(te, dtype=float) if te is not None and len(te) else None}
        return self.memory.put(key, r)

    def prefetch(self, cases: Sequence[Case], desc: str = "cases", **kw: Any) -> None:
        """Solve a batch now and keep its results in memory for later calls of this runner (the same
        arguments as :meth:`__call__`; pinned in :attr:`memory`, outside its budget): a later call takes
        them without solving, reading the cache or counting them again. A study submits every case it will need at once (no worker waits between
        its stages) and then reads them stage by stage."""
        self(cases, desc, keep=True, **kw)

    def _waves(self, tasks: list[list[str]], near: dict[str, str]) -> list[list[int]]:
        """Task indices in the order to run them with warm starts: first, for every neighbourhood with no state
        yet, the first task that has it (the batch's base case, e.g. the state a loop's trials perturb, comes
        first), then the rest, which start from the states the first wave leaves."""
        missing = {near[k] for t in tasks for k in t if near[k] not in self.states}
        if not missing or len(tasks) < 2:
            return [list(range(len(tasks)))]
        first: list[int] = []
        for i, t in enumerate(tasks):
            new = {near[k] for k in t} & missing
            if new:
                first.append(i)
                missing -= new
        rest = [i for i in range(len(tasks)) if i not in set(first)]
        return [first, rest] if rest else [first]

    @staticmethod
    def _tasks(todo: list[str], keys: list[str], group: Sequence[Any] | None, n: int) -> list[list[str]]:
        """The uncached keys as worker tasks: one key each, or the keys of one group label together."""
        if group is None:
            return [[k] for k in todo]
        if len(group) != n:
            raise ValueError(f"group has {len(group)} entries for {n} cases")
        label: dict[str, Any] = {}
        for k, g in zip(keys, group):
            label.setdefault(k, g)
        tasks: list[list[str]] = []
        where: dict[Any, int] = {}
        for k in todo:
            g = label[k]
            if g is None:
                tasks.append([k])
            elif g in where:
                tasks[where[g]].append(k)
            else:
                where[g] = len(tasks)
                tasks.append([k])
        return tasks

    @staticmethod
    def _group_payload(jobs: list[Job], keys: list[str]) -> dict[str, Any]:
        """The payload of a :func:`solve_group` task; ValueError if the cases differ in more than load and
        direction or the jobs in solver or law."""
        a = jobs[0]
        for j in jobs[1:]:
            c = j.case
            if (c.raw_errors != a.case.raw_errors or c.design != a.case.design or c.model != a.case.model
                    or j.solver != a.solver or j.law != a.law or j.max_outer != a.max_outer):
                raise ValueError(f"group of cases {a.case.name!r} and {c.name!r}: the cases of one group must differ "
                                 "only in load and direction (same design, errors, model, solver and law)")
        key = "group-" + hashlib.sha256("".join(keys).encode()).hexdigest()[:32]
        return {"key": key, "solver": a.solver, "jobs": [_payload(j, k) for j, k in zip(jobs, keys)]}

    def counters(self) -> dict[str, Any]:
        """``computed, reused, failed``, mean/median solve seconds of computed cases, wall seconds."""
        s = np.array(self.solve_seconds, dtype=float)
        return {"computed": self.computed, "reused": self.reused, "failed": self.failed,
                "solve_seconds_mean": float(np.nanmean(s)) if s.size else float("nan"),
                "solve_seconds_median": float(np.nanmedian(s)) if s.size else float("nan"),
                "solve_seconds_total": float(np.nansum(s)) if s.size else 0.0,
                "wall_seconds": self.wall_seconds}

    def describe(self) -> str:
        """Where the cases are solved (the executor's description)."""
        return getattr(self.executor, "describe", lambda: self.executor.name)()

    def close(self) -> None:
        """Close the executor if this runner made it."""
        if self._own:
            self.executor.close()

    def __enter__(self) -> Runner:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def run_cases(cases: Sequence[Case], *, solver: str = "analytic", steps: int | Sequence[int] = 720,
              revolutions: float = 1.0, law: ContactLaw | None = None,
              theta_in_deg: Sequence[Sequence[float] | np.ndarray | None] | None = None,
              cache: CaseCache | str | Path | None = None, executor: Executor | int | str | None = None,
              progress: bool = False) -> list[dict[str, Any]]:
    """Solve many cases once: a :class:`Runner` for one batch (arguments as there and in ``__call__``).

    Returns
    -------
    list of dict
        One result per case, in order (module docstring).
    """
    with Runner(executor, cache, solver, steps if isinstance(steps, (int, np.integer)) else 720, law,
                revolutions, progress) as run:
        return run(cases, "cases", steps=None if isinstance(steps, (int, np.integer)) else steps,
                   theta_in_deg=theta_in_deg)
