"""Benchmark: rv-calibrate on a simulated 5-run dataset of one output revolution each.

The dataset: 360 samples per revolution (the model grid), loads 10/20/30 N m in both directions
(5 runs), declared errors on every run, one undeclared Table 4 error (pin 12's pitch) and a
torsional compliance, output encoder noise 0.15 arcsec, a start-up transient on one run and
duplicated samples. The target is < 2 minutes on the development machine (one process, cold
rvdyn cache). Prints the wall time, the effects found against the truth and the RMS before/after.

``--samples-per-rev N --start-deg A --revolutions R`` put the readings off the model grid, as on a
real rig (the model is then solved at every reading; the cost grows with the number of distinct
readings).

Run: ``python benchmarks/bench_calibrate.py [--out DIR] [--steps 360] [--samples-per-rev N]
[--start-deg A] [--revolutions R]``
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rvcalib.dataset import read_dataset  # noqa: E402
from rvcalib.forward import cache_stats  # noqa: E402
from rvcalib.identify import calibrate  # noqa: E402
from rvcalib.report import write_report  # noqa: E402
from rvcalib.simulate import simulate_dataset  # noqa: E402

TARGET_S = 120.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="folder for the dataset and the report (default: a temp folder)")
    ap.add_argument("--steps", type=int, default=360, help="model grid points per output revolution")
    ap.add_argument("--samples-per-rev", type=int, default=None, help="rig samples per output revolution "
                    "(default: --steps, on the model grid)")
    ap.add_argument("--start-deg", type=float, default=0.0, help="input angle of the first sample, deg")
    ap.add_argument("--revolutions", type=float, default=1.0, help="output revolutions per run")
    args = ap.parse_args()
    root = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench-calibrate-"))
    runs = [{"run": f"r{i + 1}", "load_Nm": L, "direction": d, "declared": {"cam_eccentricity": 5.0, "pin_radius": -2.0}}
            for i, (L, d) in enumerate([(10.0, 1), (10.0, -1), (20.0, 1), (30.0, 1), (30.0, -1)])]
    hidden = {"errors": {"pin_pitch": {"value": 0.02, "pin": 12}},
              "model": {"torsional_compliance_arcsec_per_Nm": 0.25}}
    t0 = time.perf_counter()
    spr = args.samples_per_rev or args.steps
    ans_path = simulate_dataset(root / "dataset", runs, hidden, samples_per_rev=spr, seed=5,
                                start_deg=args.start_deg, revolutions=args.revolutions,
                                transient={"runs": ["r1"], "amplitude_arcsec": 12.0, "tau_samples": 6.0,
                                           "extra_revolutions": 0.15}, duplicates=6)
    t_sim = time.perf_counter() - t0
    t1 = time.perf_counter()
    ds = read_dataset(root / "dataset")
    res = calibrate(ds, steps=args.steps, log=lambda s: print(f"  {s}", flush=True))
    paths = write_report(res, root / "report")
    t_cal = time.perf_counter() - t1
    ans = json.loads(ans_path.read_text())
    print(f"dataset: {len(ds.runs)} runs x {spr} samples/rev x {args.revolutions:g} rev from input "
          f"{args.start_deg:g} deg, model grid {args.steps}, {ds.n_samples} samples (simulated in {t_sim:.1f} s)")
    print(f"calibration + report: {t_cal:.1f} s (target < {TARGET_S:.0f} s); rvdyn solves {cache_stats()['solves']}")
    print(f"residual RMS {res.rms_before:.4g} -> {res.rms_after:.4g} arcsec (simulated noise "
          f"{ans['noise_te_arcsec']:.4g}); status {res.status}")
    for exp in ans["expected_effects"]:
        hit = [e for e in res.effects if e.name == exp["name"] or exp["name"] in e.alternatives]
        got = f"{hit[0].name} = {hit[0].value:.5g} [{hit[0].ci_low:.5g}, {hit[0].ci_high:.5g}]" if hit else "NOT FOUND"
        print(f"  truth {exp['name']} = {exp['value']:g} {exp['unit']}: found {got}")
    extra = [e.name for e in res.effects if not any(e.name == x["name"] or x["name"] in e.alternatives
                                                    for x in ans["expected_effects"])]
    if extra:
        print(f"  also reported: {extra}")
    print(f"report: {paths['report']}")
    print(f"BENCH calibrate_5runs_seconds {t_cal:.1f}")
    return 0 if t_cal < TARGET_S else 1


if __name__ == "__main__":
    raise SystemExit(main())
