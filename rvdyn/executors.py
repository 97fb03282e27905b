"""Executors of the forward runner (:mod:`rvdyn.runner`): the same worker function over JSON-ready job
payloads, in this process, a local process pool or a Dask cluster, yielding ``(index, result)`` pairs
as results arrive.

* :class:`SerialExecutor` -- one payload after another in this process.
* :class:`LocalPoolExecutor` -- :class:`concurrent.futures.ProcessPoolExecutor` with the ``spawn``
  start method; its workers end themselves when the process that started them dies.
* :class:`DaskExecutor` -- ``dask.distributed.Client(address)``.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, Protocol

SolveFn = Callable[[dict[str, Any]], dict[str, Any]]


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
            raise ValueError(f"workers {workers!r} must be an integer >= 1")
        self.workers = workers
        self._pool: ProcessPoolExecutor | None = None
        self._lock = threading.Lock()

    def _get(self) -> ProcessPoolExecutor:
        with self._lock:  # threads of one study share the pool (one pool, made once)
            return self._make()

    def _make(self) -> ProcessPoolExecutor:
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


class SchedulerError(ValueError):
    """A Dask scheduler address that is empty or cannot be reached (``address``, and ``reason``)."""

    def __init__(self, address: Any, reason: str) -> None:
        super().__init__(f"scheduler address {address!r}: {reason}")
        self.address = address
        self.reason = reason


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
    SchedulerError
        A ValueError naming the scheduler address when it is empty or cannot be reached.
    """

    name = "dask"

    def __init__(self, address: str, timeout_s: float = 20.0) -> None:
        try:
            from dask.distributed import Client
        except ImportError as exc:  # pragma: no cover - a declared dependency
            raise ValueError(f"a Dask scheduler needs dask[distributed] installed ({exc})") from None
        if not isinstance(address, str) or not address.strip():
            raise SchedulerError(address, "must be a non-empty address like tcp://host:8786")
        self.address = address
        try:
            self.client = Client(address, timeout=f"{timeout_s}s", set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SchedulerError(address, f"cannot connect to the Dask scheduler ({exc})") from None
        info = self.client.scheduler_info()
        self.workers = max(1, sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()))

    def run(self, fn: SolveFn, payloads: Sequence[dict[str, Any]]) -> Iterator[tuple[int, dict[str, Any]]]:
        if not payloads:
            return
        from dask.distributed import as_completed

        futs = [self.client.submit(fn, p, pure=False, key=f"rvdyn-{p['key']}-{i}-{time.time_ns()}")
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


def make_executor(workers: int = 1, scheduler: str | None = None, timeout_s: float = 20.0) -> Executor:
    """Executor from options: Dask if ``scheduler`` (an address) is given, else serial (1) or a local pool (N)."""
    if scheduler:
        return DaskExecutor(scheduler, timeout_s)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers {workers!r} must be an integer >= 1")
    return SerialExecutor() if workers == 1 else LocalPoolExecutor(workers)
