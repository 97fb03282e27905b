"""Measured figures as data: ``benchmarks/results.csv``, one row per figure a benchmark script measured.

Columns: ``benchmark, figure, value, unit, commit, date, machine``. ``commit`` is the short hash of the checkout
the script ran from (with ``+dirty`` when the tree has uncommitted changes), ``date`` the UTC time of the run
(ISO 8601), ``machine`` the CPU model and core count. Rows are only ever appended; ``benchmarks/report.py`` prints
the newest value of each (benchmark, figure).

Use from a benchmark script::

    from results_log import record            # benchmarks/ is the script's own folder
    record("bench_te", [("analytic_720_steps_seconds", 1.23, "s"), ("fcl_agreement_rms", 0.01, "arcsec")])
"""
from __future__ import annotations

import csv
import datetime as _dt
import os
import platform
import re
import subprocess
from collections.abc import Iterable
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results.csv"
COLUMNS = ("benchmark", "figure", "value", "unit", "commit", "date", "machine")


def _commit(root: Path) -> str:
    """Short hash of the checkout at ``root`` (``+dirty`` with uncommitted changes), or ``unknown``."""
    try:
        h = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                           text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return h + ("+dirty" if dirty else "")


def machine() -> str:
    """CPU model and logical core count, e.g. ``AMD EPYC, 2 cores``."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores"


def slug(text: str) -> str:
    """A figure name from free text: lower case, runs of other characters as one ``_``
    (``"analytic physical nominal 720 steps"`` -> ``analytic_physical_nominal_720_steps``)."""
    out = re.sub(r"[^a-z0-9.+-]+", "_", text.lower()).strip("_")
    if not out:
        raise ValueError(f"figure name {text!r} has no letter or digit")
    return out


def record(benchmark: str, figures: Iterable[tuple[str, float, str]], path: Path | None = None) -> Path:
    """Append ``figures`` (``(figure, value, unit)`` each) of ``benchmark`` to the results table.

    Parameters
    ----------
    benchmark : str
        The script's name without ``.py`` (e.g. ``bench_te``).
    figures : iterable of (str, float, str)
        Figure name, value and unit (``s``, ``arcsec``, ``count``, ...).
    path : Path or None
        The table (default ``benchmarks/results.csv``).

    Returns
    -------
    Path
        The table written.
    """
    path = RESULTS if path is None else Path(path)
    rows = [(str(n), float(v), str(u)) for n, v, u in figures]
    if not benchmark or any(not n for n, _, _ in rows):
        raise ValueError(f"benchmark {benchmark!r} and every figure name must be non-empty")
    stamp = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    commit = _commit(Path(__file__).resolve().parents[1])
    mach = machine()
    new = not path.exists() or path.stat().st_size == 0
    with open(path, "a", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh)
        if new:
            w.writerow(COLUMNS)
        for n, v, u in rows:
            w.writerow((benchmark, n, repr(v), u, commit, stamp, mach))
    return path
