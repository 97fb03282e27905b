"""Helpers the calibration benchmarks share: CPU seconds of a process and its workers."""
from __future__ import annotations

import resource
import time


def cpu_seconds() -> float:
    """CPU seconds of this process and of its finished children (the worker processes, once closed)."""
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime
