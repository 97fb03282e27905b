"""Speed, size and accuracy of the fcl contact provider (``rvdyn.fcl_contacts.FclContacts``).

Run ``python benchmarks/bench_fcl.py [--steps 720] [--repeat 3] [--json]``. Times are the best of
``--repeat`` runs on one core; the machine may be shared, so compare like with like.

Printed figures
---------------
* build: seconds, triangles of each disc's tooth-space window (and of a whole-disc side wall
  at the same sagitta, for scale), triangles of the loaded-flank meshes, resident memory added.
* disc_distance: microseconds per pin query in solver-sized calls (40 pins of one disc per
  call, one call per disc and state along one output revolution), split into the FCL loop and
  the rest (rotation into the window, sign, smooth normal); and in one large call.
* accuracy against the analytic provider: pin gaps and normals (pins that can touch), and
  stage I gaps (um).
* stage1_gaps: microseconds per (state, crank) pair.
* one revolution: the projected cost of the provider for ``--steps`` steps at 2 and 3
  linearisations per step (the solver's pin and stage I queries).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results_log import record, slug  # noqa: E402
from rvcad.errors import Case  # noqa: E402
from rvcad.geometry import ReducerGeometry  # noqa: E402
from rvdyn.fcl_contacts import FclContacts  # noqa: E402

CASE = {"errors": {"pin_pitch": 0.01, "pin_circle_diameter": -6, "sun_eccentricity": 10,
                   "planet_eccentricity": 10, "cam_eccentricity": 5}}


def _rss_mb() -> float:
    """Resident set size of this process, MB (Linux /proc; 0 elsewhere)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return 0.0


def _best(fn, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.einsum("ij,ij->i", a, b)))


def run(steps: int, repeat: int) -> dict:
    g = ReducerGeometry(Case.from_dict(CASE))
    out: dict = {"case": CASE, "steps": steps, "repeat": repeat}

    rss0 = _rss_mb()
    t = time.perf_counter()
    fc = FclContacts(g)
    out["build_s"] = time.perf_counter() - t
    out["rss_added_MB"] = _rss_mb() - rss0
    out["disc_window_triangles"] = fc.disc_triangles
    out["whole_disc_triangles_same_sagitta"] = [len(p.boundary_t(fc.sagitta_mm)) for p in g.profiles]
    out["gear_flank_triangles"] = fc.gear_triangles
    out["sagitta_um"] = fc.sagitta_mm * 1e3
    out["flank_sagitta_um"] = fc.flank_sagitta_mm * 1e3

    th = np.linspace(0.0, 2 * math.pi * g.ratio, steps + 1)[:-1]
    to, ps = g.ideal_state(th)
    p, t0 = g.pins_in_profile_frames(to, ps)
    nd, zp = p.shape[1], p.shape[2]

    # solver-sized calls, with the FCL loop timed on its own
    probe = fc._probe
    orig = probe.distances
    spent = {"fcl": 0.0}

    def timed(*a):
        t1 = time.perf_counter()
        r = orig(*a)
        spent["fcl"] += time.perf_counter() - t1
        return r

    def solver_sized() -> None:
        for i in range(steps):
            for k in range(nd):
                fc.disc_distance(k, p[i, k], t0[i, k])

    probe.distances = timed
    best, fcl_part = math.inf, 0.0
    for _ in range(repeat):
        spent["fcl"] = 0.0
        t1 = time.perf_counter()
        solver_sized()
        dt = time.perf_counter() - t1
        if dt < best:
            best, fcl_part = dt, spent["fcl"]
    probe.distances = orig
    n_q = steps * nd * zp
    out["disc_us_per_pin_solver_calls"] = best / n_q * 1e6
    out["disc_us_per_pin_fcl_loop"] = fcl_part / n_q * 1e6
    out["disc_us_per_pin_rest"] = (best - fcl_part) / n_q * 1e6
    out["disc_us_per_call_of_%d_pins" % zp] = best / (steps * nd) * 1e6

    big = _best(lambda: [fc.disc_distance(k, p[:, k].reshape(-1, 2), t0[:, k].ravel()) for k in range(nd)], repeat)
    out["disc_us_per_pin_one_big_call"] = big / n_q * 1e6

    # accuracy against the analytic provider
    gap, nrm, _, _ = g.pin_gaps(to, ps)
    errs, angs = [], []
    for k in range(nd):
        d, n = fc.disc_distance(k, p[:, k].reshape(-1, 2), t0[:, k].ravel())
        gf = d.reshape(steps, zp) - g.pin_radii[None]
        near = np.abs(gap[:, k]) < 0.06
        errs.append(np.abs(gf - gap[:, k])[near].max())
        angs.append(_angle(n.reshape(-1, 2)[near.ravel()], nrm[:, k].reshape(-1, 2)[near.ravel()]).max())
    out["pin_gap_max_err_um"] = max(errs) * 1e3
    out["pin_normal_max_err_rad"] = max(angs)

    # stage I
    st = {}
    for d_ in (1, -1):
        st[d_] = _best(lambda: fc.stage1_gaps(th, to, ps, d_), repeat)
    out["stage1_us_per_pair"] = min(st.values()) / (steps * g.design.n_cranks) * 1e6
    e1 = max(np.abs(fc.stage1_gaps(th, to, ps, d_) - g.stage1_gaps(th, to, ps, d_)).max() for d_ in (1, -1))
    out["stage1_max_err_um"] = e1 * 1e3

    per_lin = best / steps + min(st.values()) / steps  # one linearisation: both discs + stage I
    out["revolution_s_at_2_linearisations_per_step"] = 2 * steps * per_lin
    out["revolution_s_at_3_linearisations_per_step"] = 3 * steps * per_lin
    out["load_average_1min"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return out


def _unit(key: str) -> str:
    """Unit of a figure of :func:`run` from its name."""
    if "_us_" in f"_{key}_":
        return "us"
    for end, unit in (("_s", "s"), ("_MB", "MB"), ("_um", "um"), ("_rad", "rad")):
        if key.endswith(end) or (end == "_s" and "_s_at_" in key):
            return unit
    return "count"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=720, help="states along one output revolution (default 720)")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs (default 3)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    a = ap.parse_args(argv)
    r = run(a.steps, a.repeat)
    record("bench_fcl", [(slug(f"{a.steps} states {k}"), float(v), _unit(k)) for k, v in r.items()
                         if isinstance(v, (int, float)) and k not in ("steps", "repeat", "load_average_1min")])
    if a.json:
        print(json.dumps(r))
        return 0
    print(f"fcl contact provider benchmark ({a.steps} states, best of {a.repeat}; "
          f"load average {r['load_average_1min']})")
    print(f"  build: {r['build_s']:.2f} s, +{r['rss_added_MB']:.1f} MB resident")
    print(f"  disc window triangles {r['disc_window_triangles']} (whole disc at the same "
          f"{r['sagitta_um']:.3f} um sagitta: {r['whole_disc_triangles_same_sagitta']})")
    print(f"  gear flank triangles {r['gear_flank_triangles']} (flank sagitta {r['flank_sagitta_um']:.4f} um)")
    print(f"  disc_distance: {r['disc_us_per_pin_solver_calls']:.1f} us/pin in calls of 40 pins "
          f"(FCL loop {r['disc_us_per_pin_fcl_loop']:.1f}, rest {r['disc_us_per_pin_rest']:.1f}); "
          f"{r['disc_us_per_pin_one_big_call']:.1f} us/pin in one big call")
    print(f"  pin gaps vs analytic: max {r['pin_gap_max_err_um']:.4f} um, normals max "
          f"{r['pin_normal_max_err_rad']:.2e} rad")
    print(f"  stage1_gaps: {r['stage1_us_per_pair']:.1f} us per (state, crank); max error "
          f"{r['stage1_max_err_um']:.4f} um")
    print(f"  one revolution, provider only: {r['revolution_s_at_2_linearisations_per_step']:.2f} s "
          f"(2 linearisations/step), {r['revolution_s_at_3_linearisations_per_step']:.2f} s (3/step)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
