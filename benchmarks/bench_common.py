"""Helpers the calibration benchmarks share: the forward model on worker processes, and CPU seconds."""
from __future__ import annotations

import contextlib
import resource
import time
from collections.abc import Iterator


@contextlib.contextmanager
def forward_workers(workers: int) -> Iterator[None]:
    """The loop's forward model (:mod:`rvcalib.forward`) on ``workers`` local processes for the block (as
    ``rv-calibrate --workers``); one process keeps the in-process runner."""
    if workers <= 1:
        yield
        return
    from rvcalib import forward
    from rvdyn.runner import Runner

    runner = Runner(executor=workers, memory_bytes=forward.CACHE_BYTES, law=forward.forward_runner().law,
                    warm_bytes=forward.WARM_BYTES)
    prev = forward.use_runner(runner)
    try:
        yield
    finally:
        forward.use_runner(prev)
        runner.close()


def cpu_seconds() -> float:
    """CPU seconds of this process and of its finished children (the worker processes, once closed)."""
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime
