"""Benchmark: TE Jacobians of a realistic reducer over a whole library of parameters (issue 45, item 3).

Base: all eleven Table 4 errors at their default instances, normal with sigma = paper value / 3 (seed ``--seed``),
a torsional compliance of 0.2 arcsec/(N m), the physical law; four conditions (10 and 30 N m, both directions) of
``--readings`` off-grid readings each over one output revolution.

Library (the default design's, :func:`library`): every Table 4 instance (sun eccentricity and pin circle offset
x and y; planet eccentricity x and y per crank; cam phase and cam eccentricity per crank and disc; carrier hole per
crank; disc hole per disc and hole; disc phase per disc; pin circle diameter and pin radius of all pins; per pin
its pitch, radius and radial position), the pin circle's Fourier forms (radial position orders 2-6 and pitch orders
2-5, cosine and sine) and the model options (torsional compliance, friction torque, cam-bearing clearance, pin
circle ovality at 0 and 45 deg). Units: 1 um, 0.001 deg, 0.1 arcsec/(N m), 1 N m.

Prints and records (results_log): the seconds (wall and this process's CPU, one BLAS thread) of all columns by
:func:`rvdyn.implicit.te_jacobian` at the base's states; of the sensitivity route
(``run_te_many(base + t delta, x_init=states, max_outer=1)`` per column, ``t`` = ``--sens-step`` units, one-sided)
on a sample of ``--sample`` columns (one of each kind, the rest spread over the library), extrapolated to all; the agreement of the two routes
on the sample (RMS over rows of the difference over the RMS of the implicit column) and of each with central
differences of converged solves (warm, the solver's tolerance, ``t = +- --fd-step``; one-sided at an option's bound).

Run: ``python benchmarks/bench_jacobian.py [--readings 333] [--sample 20] [--no-record]``. The machine is shared:
the CPU seconds are the figure to compare; say the load when quoting wall time.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rvcad.errors import ERROR_TYPES, Case  # noqa: E402
from rvdyn.implicit import te_jacobian  # noqa: E402
from rvdyn.options import MODEL_OPTIONS  # noqa: E402
from rvdyn.te import run_te_many  # noqa: E402

LOADS = [(10.0, 1), (10.0, -1), (30.0, 1), (30.0, -1)]
DEFAULTS = {k: o.default for k, o in MODEL_OPTIONS.items()}


def library(zp: int = 40, nc: int = 2, nd: int = 2) -> list[tuple[str, dict]]:
    """The library's directions ``(name, delta)`` (module docstring)."""
    out: list[tuple[str, dict]] = []
    for a in (0.0, 90.0):
        out.append((f"sun_eccentricity@{a:g}", {"errors": {"sun_eccentricity": {"value": 1.0, "angle_deg": a}}}))
        out.append((f"pin_circle_offset@{a:g}", {"errors": {"pin_circle_offset": {"value": 1.0, "angle_deg": a}}}))
        out += [(f"planet_eccentricity[{j}]@{a:g}",
                 {"errors": {"planet_eccentricity": {"value": 1.0, "crank": j, "angle_deg": a}}}) for j in range(nc)]
    for j in range(nc):
        out.append((f"carrier_hole_eccentricity[{j}]", {"errors": {"carrier_hole_eccentricity": {"value": 1.0,
                                                                                                "crank": j}}}))
        for k in range(nd):
            out += [(f"{key}[{j},{k}]", {"errors": {key: {"value": 1.0, "crank": j, "disc": k}}})
                    for key in ("cam_phase", "cam_eccentricity")]
            out.append((f"disc_hole_eccentricity[{k},{j}]", {"errors": {"disc_hole_eccentricity": {
                "value": 1.0, "disc": k, "hole": j}}}))
    out += [(f"disc_phase[{k}]", {"errors": {"disc_phase": {"value": 0.001, "disc": k}}}) for k in range(nd)]
    out += [("pin_circle_diameter", {"errors": {"pin_circle_diameter": 1.0}}),
            ("pin_radius", {"errors": {"pin_radius": 1.0}})]
    for i in range(zp):
        out += [(f"pin_pitch[{i}]", {"errors": {"pin_pitch": {"value": 0.001, "pin": i}}}),
                (f"pin_radius[{i}]", {"errors": {"pin_radius": {"value": 1.0, "pin": i}}}),
                (f"pin_radial[{i}]", {"errors": {"pin_circle_diameter": {"value": 2.0, "pin": i}}})]
    phi = 2.0 * np.pi * np.arange(zp) / zp
    for key, orders, unit in (("pin_circle_diameter", range(2, 7), 2.0), ("pin_pitch", range(2, 6), 0.001)):
        for n in orders:
            for name, f in (("cos", np.cos), ("sin", np.sin)):
                out.append((f"{key} {name} {n}", {"errors": {key: [float(unit * v) for v in f(n * phi)]}}))
    out += [("torsional_compliance", {"model": {"torsional_compliance_arcsec_per_Nm": 0.1}}),
            ("friction_torque", {"model": {"friction_torque_Nm": 1.0}}),
            ("cam_bearing_clearance", {"model": {"cam_bearing_clearance_um": 1.0}}),
            ("pin_circle_ovality@0", {"model": {"pin_circle_ovality_um": 1.0}}),
            ("pin_circle_ovality@45", {"errors": {"pin_circle_diameter": [
                float(2.0 * math.cos(2.0 * (p - math.pi / 4))) for p in phi]}})]
    return out


def sample(lib: list[tuple[str, dict]], n: int) -> list[int]:
    """Indices of n columns: the first of each kind (the name before its instance), then evenly spread."""
    kinds: dict[str, int] = {}
    for i, (name, _) in enumerate(lib):
        kinds.setdefault(name.split("[")[0].split("@")[0].split(" ")[0], i)
    pick = set(list(kinds.values())[:n])
    for i in np.linspace(0, len(lib) - 1, n).round().astype(int):
        if len(pick) < n:
            pick.add(int(i))
    return sorted(pick)


def realistic_case(seed: int) -> Case:
    rng = np.random.default_rng(seed)
    errors = {k: float(rng.normal(0.0, et.paper_value / 3.0)) for k, et in ERROR_TYPES.items()}
    return Case.from_dict({"errors": errors, "model": {"torsional_compliance_arcsec_per_Nm": 0.2}})


def te_of(case: Case, th: list, states: list, max_outer: int | None) -> np.ndarray:
    res = run_te_many(case, "analytic", loads=LOADS, theta_in_deg=th, x_init=states, max_outer=max_outer)
    return np.concatenate([r.table["te_arcsec"].to_numpy() for r in res])


def difference(case: Case, delta: dict, th: list, states: list, te0: np.ndarray, t: float,
               max_outer: int | None, central: bool) -> np.ndarray:
    """(TE(t) - TE(-t)) / 2t, or (TE(t) - TE(0)) / t where the minus side is not a valid case or not asked for."""
    tp = te_of(case.plus(delta, t, DEFAULTS), th, states, max_outer)
    if central:
        try:
            return (tp - te_of(case.plus(delta, -t, DEFAULTS), th, states, max_outer)) / (2.0 * t)
        except ValueError:
            pass
    return (tp - te0) / t


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / max(np.sqrt(np.mean(b ** 2)), 1e-300))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--readings", type=int, default=333)
    ap.add_argument("--sample", type=int, default=20)
    ap.add_argument("--sens-step", type=float, default=0.1)
    ap.add_argument("--fd-step", type=float, default=0.1)
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    case = realistic_case(args.seed)
    rng = np.random.default_rng(args.seed + 1)
    th = [np.sort(rng.uniform(0.0, 360.0 * 121, args.readings)) for _ in LOADS]
    th = [t if d == 1 else t[::-1].copy() for t, (_, d) in zip(th, LOADS)]
    lib = library()
    w0, c0 = time.perf_counter(), time.process_time()
    states = [r.state for r in run_te_many(case, "analytic", loads=LOADS, theta_in_deg=th)]
    solve_wall, solve_cpu = time.perf_counter() - w0, time.process_time() - c0
    w0, c0 = time.perf_counter(), time.process_time()
    jr = te_jacobian(case, [d for _, d in lib], loads=LOADS, theta_in_deg=th, states=states)
    jac_wall, jac_cpu = time.perf_counter() - w0, time.process_time() - c0
    te0 = np.concatenate(jr.te_arcsec)
    flagged = [(n, f) for (n, _), f in zip(lib, jr.flags) if f]
    print(f"base: {case.raw_errors}; {len(LOADS)} conditions x {args.readings} readings; load {os.getloadavg()[0]:.1f}")
    print(f"base solve: {solve_wall:.2f} s wall, {solve_cpu:.2f} s CPU; stationarity {jr.stationarity_arcsec:.1e} arcsec")
    print(f"implicit: {len(lib)} columns in {jac_wall:.2f} s wall, {jac_cpu:.2f} s CPU; flagged: {flagged}")
    pick = sample(lib, args.sample)
    c0 = time.process_time()
    sens = {j: difference(case, lib[j][1], th, states, te0, args.sens_step, 1, False) for j in pick}
    sens_cpu = (time.process_time() - c0) / len(pick)
    conv = {j: difference(case, lib[j][1], th, states, te0, args.fd_step, None, True) for j in pick}
    print(f"sensitivity route: {sens_cpu:.3f} s CPU per column -> {sens_cpu * len(lib):.1f} s for {len(lib)}")
    print(f"{'column':30s} {'rms':>8s} {'sens-imp':>9s} {'imp-conv':>9s} {'sens-conv':>9s}")
    rows = []
    for j in pick:
        col = jr.J[:, j]
        rows.append((rel(sens[j], col), rel(col, conv[j]), rel(sens[j], conv[j])))
        print(f"{lib[j][0]:30s} {np.sqrt(np.mean(col ** 2)):8.3f} {rows[-1][0]:9.1e} {rows[-1][1]:9.1e} "
              f"{rows[-1][2]:9.1e}")
    med = np.median(np.array(rows), axis=0)
    print(f"median over the sample: sensitivity-implicit {med[0]:.1e}, implicit-converged {med[1]:.1e}, "
          f"sensitivity-converged {med[2]:.1e}")
    if not args.no_record:
        from results_log import record

        record("bench_jacobian", [
            ("columns", float(len(lib)), "count"), ("readings", float(te0.size), "count"),
            ("implicit_all_columns_cpu_s", jac_cpu, "s"), ("implicit_all_columns_wall_s", jac_wall, "s"),
            ("sensitivity_route_cpu_s_per_column", sens_cpu, "s"),
            ("sensitivity_route_all_columns_cpu_s", sens_cpu * len(lib), "s"),
            ("base_solve_cpu_s", solve_cpu, "s"),
            ("median_rel_sensitivity_vs_implicit", float(med[0]), "1"),
            ("median_rel_implicit_vs_converged", float(med[1]), "1"),
            ("median_rel_sensitivity_vs_converged", float(med[2]), "1"),
            ("max_rel_implicit_vs_converged", float(np.max(np.array(rows)[:, 1])), "1"),
            ("max_rel_sensitivity_vs_converged", float(np.max(np.array(rows)[:, 2])), "1")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
