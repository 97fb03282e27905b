"""Where the cases are solved: in this process, a local process pool, or a Dask cluster.

Every executor runs the same worker function, :func:`solve_job`, on JSON-ready job payloads
(:meth:`rvstudy.cache.Job.to_payload`) and yields ``(index, result)`` pairs as they finish. The
results come back to this process, which alone writes the cache (:class:`CachedRunner`); Dask
workers therefore need the package installed but no shared disk.

* :class:`SerialExecutor` -- one case after another in this process (``--workers 1``; tests).
* :class:`LocalPoolExecutor` -- :class:`concurrent.futures.ProcessPoolExecutor` with the ``spawn``
  start method (``--workers N``, default 2).
* :class:`DaskExecutor` -- ``dask.distributed.Client(address)`` (``--scheduler ADDRESS``).
"""
from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, Protocol

import numpy as np

from rvcad.errors import Case
from rvdyn.contacts import ContactLaw
from rvdyn.te import SOLVERS, run_te
from rvstudy.cache import CaseCache, Job

SolveFn = Callable[[dict[str, Any]], dict[str, Any]]

_STAT_KEYS = ("pp", "mean", "mean_abs", "rms", "ratio", "seconds")


def solve_job(payload: dict[str, Any]) -> dict[str, Any]:
    """Solve one job payload (worker side).

    Parameters
    ----------
    payload : dict
        ``case`` (case dict), ``solver``, ``steps``, ``revolutions``, ``law`` ({K, n, rigid}), ``key``.

    Returns
    -------
    dict
        ``key``, ``status`` (``ok`` or ``failed``), ``stats`` (``pp, mean, mean_abs, rms`` in arcsec,
        ``ratio``, ``seconds``), ``te_arcsec`` (list, one value per step; empty when failed) and
        ``error`` (message of a failed solve: an interference the contact law cannot resolve or a
        solver that did not converge; both are properties of the case and are cached as such).
        Missing software (e.g. the fcl provider) raises instead and is never cached.
    """
    case = Case.from_dict(payload["case"])
    law = ContactLaw(**payload["law"])
    t0 = time.perf_counter()
    try:
        r = run_te(case, payload["solver"], int(payload["steps"]), float(payload["revolutions"]), law=law)
    except (ValueError, RuntimeError, FloatingPointError, np.linalg.LinAlgError) as exc:
        if isinstance(exc, ImportError):  # pragma: no cover - ImportError is not a ValueError; kept explicit
            raise
        secs = time.perf_counter() - t0
        stats = {k: float("nan") for k in _STAT_KEYS}
        stats["seconds"] = secs
        return {"key": payload["key"], "status": "failed", "stats": stats, "te_arcsec": [],
                "error": f"{type(exc).__name__}: {exc}"}
    stats = {k: float(r.stats[k]) for k in _STAT_KEYS}
    return {"key": payload["key"], "status": "ok", "stats": stats,
            "te_arcsec": [float(x) for x in r.table["te_arcsec"].to_numpy()], "error": ""}


class Executor(Protocol):
    """Runs a function over payloads and yields ``(index, result)`` as results arrive."""

    name: str
    workers: int

    def run(self, fn: SolveFn, payloads: Sequence[dict[str, Any]]) -> Iterator[tuple[int, dict[str, Any]]]:
        ...  # pragma: no cover

    def close(self) -> None:
        ...  # pragma: no cover


class SerialExecutor:
    """Solve in this process, in order."""

    name = "serial"
    workers = 1

    def run(self, fn: SolveFn, payloads: Sequence[dict[str, Any]]) -> Iterator[tuple[int, dict[str, Any]]]:
        for i, p in enumerate(payloads):
            yield i, fn(p)

    def close(self) -> None:
        pass

    def describe(self) -> str:
        return "serial (this process)"


#: Seconds between a pool worker's checks that the process that started it is still alive.
PARENT_POLL_S = 2.0


def _exit_with_parent(parent_pid: int) -> None:
    """Pool-worker initializer: a daemon thread ends the worker once its parent is gone (a parent
    killed with SIGKILL cannot shut its pool down, and idle workers would wait for work forever)."""
    import os
    import threading
    import time

    def watch() -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


class LocalPoolExecutor:
    """A local process pool (``spawn`` start method), created on first use and kept until :meth:`close`.

    Parameters
    ----------
    workers : int
        Worker processes (>= 1).
    """

    name = "local"

    def __init__(self, workers: int = 2) -> None:
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"--workers {workers!r} must be an integer >= 1")
        self.workers = workers
        self._pool: ProcessPoolExecutor | None = None

    def _get(self) -> ProcessPoolExecutor:
        if self._pool is None:
            import multiprocessing as mp
            import os

            # one BLAS thread per worker: N workers on N cores must not oversubscribe (children inherit this)
            for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
                os.environ.setdefault(var, "1")
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=mp.get_context("spawn"),
                                             initializer=_exit_with_parent, initargs=(os.getpid(),))
        return self._pool

    def run(self, fn: SolveFn, payloads: Sequence[dict[str, Any]]) -> Iterator[tuple[int, dict[str, Any]]]:
        if not payloads:
            return
        pool = self._get()
        futs: dict[Future, int] = {pool.submit(fn, p): i for i, p in enumerate(payloads)}
        pending = set(futs)
        try:
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    yield futs[f], f.result()
        finally:
            for f in pending:
                f.cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def describe(self) -> str:
        return f"local process pool, {self.workers} workers"


class DaskExecutor:
    """Send the cases to a Dask distributed scheduler.

    Parameters
    ----------
    address : str
        Scheduler address, e.g. ``tcp://127.0.0.1:8786``.
    timeout_s : float
        Connection timeout, s.

    Raises
    ------
    ValueError
        Naming ``--scheduler`` when the scheduler cannot be reached.
    """

    name = "dask"

    def __init__(self, address: str, timeout_s: float = 20.0) -> None:
        try:
            from dask.distributed import Client
        except ImportError as exc:  # pragma: no cover - a declared dependency
            raise ValueError(f"--scheduler needs dask[distributed] installed ({exc})") from None
        if not isinstance(address, str) or not address.strip():
            raise ValueError("--scheduler ADDRESS must be a non-empty scheduler address like tcp://host:8786")
        self.address = address
        try:
            self.client = Client(address, timeout=f"{timeout_s}s", set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ValueError(f"--scheduler {address!r}: cannot connect to the Dask scheduler ({exc})") from None
        info = self.client.scheduler_info()
        self.workers = max(1, sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()))

    def run(self, fn: SolveFn, payloads: Sequence[dict[str, Any]]) -> Iterator[tuple[int, dict[str, Any]]]:
        if not payloads:
            return
        from dask.distributed import as_completed

        futs = [self.client.submit(fn, p, pure=False, key=f"rvstudy-{p['key']}-{i}-{time.time_ns()}")
                for i, p in enumerate(payloads)]
        index = {f.key: i for i, f in enumerate(futs)}
        try:
            for f in as_completed(futs, loop=self.client.loop):
                yield index[f.key], f.result()
        finally:
            for f in futs:
                if not f.done():
                    f.cancel()

    def close(self) -> None:
        self.client.close()

    def describe(self) -> str:
        return f"Dask scheduler {self.address} ({self.workers} worker threads)"


def make_executor(workers: int = 2, scheduler: str | None = None, timeout_s: float = 20.0) -> Executor:
    """Executor from the CLI options: Dask if ``scheduler`` is given, else serial (1) or a pool (N)."""
    if scheduler:
        return DaskExecutor(scheduler, timeout_s)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"--workers {workers!r} must be an integer >= 1")
    return SerialExecutor() if workers == 1 else LocalPoolExecutor(workers)


class CachedRunner:
    """Solve cases through an executor, reusing and filling a :class:`CaseCache`.

    A runner is what :func:`rvstudy.screen.run_screen` and the study call: ``runner(cases, desc)``
    returns one result dict per case, in order: ``stats`` (arcsec), ``te_arcsec`` (ndarray or None),
    ``key``, ``cached`` (bool), ``status`` and ``error``. Equal cases (equal keys) are solved once.
    Every finished solve is written to the cache at once, so an interrupted run loses only the
    solves in flight.

    Parameters
    ----------
    executor : Executor
    cache : CaseCache
    solver : {"analytic", "fcl"}
    steps : int
        Steps per output revolution (>= 2).
    law : ContactLaw or None
    revolutions : float
    progress : bool
        tqdm bars on stderr.
    solve_fn : callable
        Worker function (default :func:`solve_job`; tests swap it).

    Attributes
    ----------
    computed, reused, failed : int
        Unique solves done now, taken from the cache, and failed (computed or cached), cumulative.
    solve_seconds : list of float
        Solver wall time of every computed case, s.
    """

    def __init__(self, executor: Executor, cache: CaseCache, solver: str, steps: int,
                 law: ContactLaw | None = None, revolutions: float = 1.0, progress: bool = True,
                 solve_fn: SolveFn = solve_job) -> None:
        if solver not in SOLVERS:
            raise ValueError(f"--solver {solver!r} is unknown; allowed: {list(SOLVERS)}")
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 2:
            raise ValueError(f"--steps {steps!r} must be an integer >= 2")
        self.executor = executor
        self.cache = cache
        self.solver = solver
        self.steps = steps
        self.law = law if law is not None else ContactLaw()
        self.revolutions = revolutions
        self.progress = progress
        self.solve_fn = solve_fn
        self.computed = self.reused = self.failed = 0
        self.solve_seconds: list[float] = []
        self.wall_seconds = 0.0

    def __call__(self, cases: Sequence[Case], desc: str = "cases") -> list[dict[str, Any]]:
        from tqdm.auto import tqdm

        t0 = time.perf_counter()
        jobs = [Job(c, self.solver, self.steps, self.revolutions, self.law) for c in cases]
        keys = [j.key() for j in jobs]
        unique: dict[str, Job] = {}
        for k, j in zip(keys, jobs):
            unique.setdefault(k, j)
        results: dict[str, dict[str, Any]] = {}
        todo: list[str] = []
        for k in unique:
            hit = self.cache.get(k)
            if hit is None:
                todo.append(k)
            else:
                results[k] = {**hit, "cached": True}
        self.reused += len(results)
        payloads = [unique[k].to_payload() for k in todo]
        bar = tqdm(total=len(unique), initial=len(results), desc=desc, unit="case", file=sys.stderr,
                   disable=not self.progress, dynamic_ncols=True)
        try:
            for i, res in self.executor.run(self.solve_fn, payloads):
                k = todo[i]
                if res.get("key") != k:
                    raise RuntimeError(f"worker returned the result of {res.get('key')!r} for {k!r}")
                self.cache.put(k, res)
                results[k] = {**res, "cached": False}
                self.computed += 1
                self.solve_seconds.append(float(res["stats"].get("seconds", math.nan)))
                bar.update(1)
        finally:
            bar.close()
            self.wall_seconds += time.perf_counter() - t0
        out = []
        for k in keys:
            r = dict(results[k])
            te = r.get("te_arcsec")
            r["te_arcsec"] = np.asarray(te, dtype=float) if te else None
            out.append(r)
        self.failed += sum(1 for k in unique if results[k].get("status") == "failed")
        return out

    def counters(self) -> dict[str, Any]:
        """``computed, reused, failed``, mean/median solve seconds of computed cases, wall seconds."""
        s = np.array(self.solve_seconds, dtype=float)
        return {"computed": self.computed, "reused": self.reused, "failed": self.failed,
                "solve_seconds_mean": float(np.nanmean(s)) if s.size else float("nan"),
                "solve_seconds_median": float(np.nanmedian(s)) if s.size else float("nan"),
                "solve_seconds_total": float(np.nansum(s)) if s.size else 0.0,
                "wall_seconds": self.wall_seconds}
