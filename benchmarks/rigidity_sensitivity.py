"""Which assumed size the default design's rigidity answers to, and what one size alone would need to be to land
the RV-20E class (about 49 N m/arcmin) -- a question about the assumptions, not a calibration: nothing here is
written back to a default.

Usage: ``python benchmarks/rigidity_sensitivity.py [--target 49] [--rel-step 0.05]``. Prints, per size of
:data:`rvdyn.sensitivity.ASSUMED_SIZES`: its value, the elasticity ``d ln k / d ln s`` of the rigidity, and the
value that alone gives the target (a root of ``k(s) = target`` found by bisection between the value and the
nearest valid design in the direction that lowers k; "none" when every valid design of that size stays above
the target, with the last valid value and its rigidity).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from scipy.optimize import brentq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a clone without installing

from results_log import record, slug  # noqa: E402
from rvcad.errors import Case  # noqa: E402
from rvdyn.sensitivity import rigidity, rigidity_at, rigidity_elasticities, size_value, with_size  # noqa: E402


def _edge(case: Case, size: str, ok: float, k_ok: float, bad: float, why: str) -> str:
    """Where the valid designs end between a valid value (rigidity k_ok) and an invalid one (bisection), and why."""
    for _ in range(10):
        mid = 0.5 * (ok + bad)
        k, msg = rigidity_at(case, size, mid)
        if k is None:
            bad, why = mid, msg
        else:
            ok, k_ok = mid, k
    return f"none: valid designs end at {ok:.4g} ({k_ok:.1f}): {why}"


def size_alone(case: Case, k0: float, size: str, elasticity: float, target: float) -> str:
    """The value of one size that gives the target rigidity (the others at their defaults; k0: the case's own
    rigidity), or why none does."""
    v = size_value(case, size)
    down = elasticity > 0                       # the direction of the size that lowers the rigidity
    last_ok, last_k = v, k0
    if isinstance(v, int):
        n = v
        while True:
            n = n - 1 if down else n + 1
            if n < 1 or n > 4 * v:
                return f"none (at {last_ok}: {last_k:.1f})"
            k, why = rigidity_at(case, size, n)
            if k is None:
                return f"none: valid designs end at {last_ok} ({last_k:.1f}): {why}"
            if k <= target:
                return f"between {last_ok} and {n} ({last_k:.1f}, {k:.1f})"
            last_ok, last_k = n, k
    factor = 1.0
    for _ in range(12):
        factor = factor * 0.8 if down else factor * 1.25
        s = v * factor
        k, why = rigidity_at(case, size, s)
        if k is None:
            return _edge(case, size, last_ok, last_k, s, why)
        if k <= target:
            root = brentq(lambda x: math.log(rigidity(with_size(case, size, x)) / target), last_ok, s, xtol=1e-4 * v)
            return f"{root:.4g} ({root / v:.2f}x)"
        last_ok, last_k = s, k
    return f"none within {factor:.2g}x (at {last_ok:.4g}: {last_k:.1f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--target", type=float, default=49.0, help="rigidity to reach, N m/arcmin (RV-20E class: 49)")
    ap.add_argument("--rel-step", type=float, default=0.05, help="relative step of the elasticities")
    a = ap.parse_args()
    case = Case.from_dict({})
    t0 = time.perf_counter()
    k0 = rigidity(case)
    tab = rigidity_elasticities(case, rel_step=a.rel_step)
    t1 = time.perf_counter()
    print(f"default design: rigidity {k0:.2f} N m/arcmin; target {a.target} "
          f"(ln ratio {math.log(a.target / k0):+.3f}); elasticities in {t1 - t0:.1f} s")
    print(f"{'size':44s} {'value':>8s} {'elasticity':>10s}  value alone for the target")
    figures = [("default_rigidity", k0, "N m/arcmin")]
    for r in tab.itertuples():
        alone = size_alone(case, k0, r.size, r.elasticity, a.target) if abs(r.elasticity) > 0.02 else "(|E| <= 0.02)"
        print(f"{r.size:44s} {r.value:8.4g} {r.elasticity:10.3f}  {alone}")
        figures.append((slug(f"elasticity {r.size}"), float(r.elasticity), "1"))
    record("rigidity_sensitivity", figures)
    print(f"total {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
