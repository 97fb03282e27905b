"""Benchmark: how often the loop's 95 % intervals hold the truth, on the linear stand-in of the reducer.

A full realistic draw (:mod:`realistic`) costs the loop an hour of solver time, so coverage over many draws is
measured here on the frozen stand-in of the reducer (``tests/calib_standin.py``: the real model's TE and Jacobian
at the declared state, ``te(theta) = te0 + J theta``). What it keeps of a realistic draw:

* the truth: :func:`realistic.draw` of each seed (the eleven Table 4 errors at random sizes and instances, a
  compliance in [0.1, 0.3] arcsec/(N m)), mapped onto the stand-in's parameters (an eccentricity's components
  ``value (cos a, sin a)``; a one-pin error on the side of its sign);
* the rig: four runs (10 and 30 N m, both directions), each load a test with its own zero ``normal(0, 30)``
  arcsec, TE noise 0.2 arcsec of the draw's own stream.

What it does not keep: the physics beyond the first order (contact sets that change with the errors, the kinks of
the pin-wise errors), and one reading layout for every draw (``--per-rev`` readings per revolution from 0.37 deg
of input angle; the default 333 is the protocol's, above twice the input order 121 of the default design, so
the sun's eccentricity is not aliased onto the low orders). A miss here is therefore a miss of the estimator and
its intervals, not of the linearisation.

Each draw is scored by :func:`score.score` (the protocol's rules); the pooled coverage is the share of named
effects whose interval holds the truth (0 for an effect the truth does not hold).

``--method`` chooses what is scored: ``rv-calibrate``'s ``sparse`` estimator (the default) or its
``tolerance-prior`` one (:mod:`rvcalib.gaussian`), or the ``reference``: the closed-form Gaussian posterior of
:mod:`tolerance_prior` (the tolerance-prior estimator's answer on an exactly linear model, no search).

Run: ``python benchmarks/coverage_linear.py [--set dev|heldout] [--seeds 1 2 ...]
[--method sparse|tolerance-prior|reference] [--per-rev K] [--out FILE.json]``.
Figures are appended to ``benchmarks/results.csv``, named by the seeds unless the run is of the default 1-20.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from calib_standin import frozen_model, rig_data  # noqa: E402
from realistic import COMPLIANCE_KEY, draw  # noqa: E402
from results_log import record  # noqa: E402
from score import pool, score, score_lines  # noqa: E402
from tolerance_prior import calibrate_gaussian  # noqa: E402
from rvcad.errors import ERROR_TYPES  # noqa: E402
from rvcalib import CalibrationSettings, calibrate  # noqa: E402
from rvcalib.simulate import simulate_dataset, standard_runs  # noqa: E402
from rvcalib.readings import nuisance_columns  # noqa: E402
from rvrig.dataset import read_dataset  # noqa: E402

NOISE_ARCSEC = 0.2
#: Seeds of this study (its own: the protocol's dev and held-out seeds are the full-physics draws'): the
#: development set, and the held-out set, fixed before any method was run on it and run only to report.
SEEDS = tuple(range(1, 21))
HELDOUT = tuple(range(201, 213))


def layout(folder: Path, per_rev: int):
    """The readings every draw shares: four runs, ``per_rev`` readings per revolution, no error, no noise."""
    runs = [dict(r, test=f"{r['load_Nm']:g}Nm") for r in standard_runs((10.0, 30.0), (1, -1))]
    simulate_dataset(folder, runs, {}, noise_arcsec=0.0, input_noise_arcsec=0.0, samples_per_rev=per_rev,
                     start_deg=0.37, seed=1)
    return read_dataset(folder)


def truth_vector(fm, dr) -> tuple[np.ndarray, dict]:
    """The stand-in's parameters of a draw and the draw's answer (``expected_effects``, ``noise_te_arcsec``)."""
    theta = np.zeros(fm.n_params)
    pos, at = 0, {}
    for c in fm.candidates:
        at[(c.key, c.instance, c.side)] = (pos, c)
        pos += c.n_params
    expected = []
    for key, item in dr.errors.items():
        et = ERROR_TYPES[key]
        inst = tuple((ik, int(item[ik])) for ik in et.instance_keys if ik in item)
        v = float(item["value"])
        side = (1 if v >= 0 else -1) if "pin" in dict(inst) else 0
        j, c = at[(key, inst, side)]
        if c.n_params == 2:
            a = np.radians(item["angle_deg"])
            theta[j:j + 2] = v * np.cos(a), v * np.sin(a)
        else:
            theta[j] = v
        expected.append({"key": key, "instance": dict(inst), "unit": et.unit, "value": v,
                         "angle_deg": item.get("angle_deg")})
    j, _ = at[(COMPLIANCE_KEY, (), 0)]
    theta[j] = dr.compliance
    expected.append({"key": COMPLIANCE_KEY, "instance": {}, "unit": "arcsec/(N m)", "value": dr.compliance,
                     "angle_deg": None})
    return theta, {"expected_effects": expected, "noise_te_arcsec": NOISE_ARCSEC}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=None, help="draws to run (default: the --set's)")
    p.add_argument("--set", choices=("dev", "heldout"), default="dev", help="the development or the held-out seeds")
    p.add_argument("--per-rev", type=int, default=333, help="readings per revolution of the shared layout")
    p.add_argument("--out", type=Path, default=None, help="JSON of every draw's score")
    p.add_argument("--method", choices=("sparse", "tolerance-prior", "reference"), default="sparse",
                   help="rvcalib.calibrate with the sparse or the tolerance-prior estimator, or the closed-form "
                   "Gaussian posterior of tolerance_prior.py")
    p.add_argument("--cache", type=Path, default=None, help="npz file of the stand-in's TE and Jacobian (reused when "
                   "its shape fits the layout)")
    args = p.parse_args(argv)
    full = list(SEEDS if args.set == "dev" else HELDOUT)
    args.seeds = args.seeds or full
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="coverage-linear-") as tmp:
        ds = layout(Path(tmp) / "ds", args.per_rev)
        fm = frozen_model(ds, cache=args.cache)
    print(f"stand-in: {fm.n_params} solved parameters, {sum(r.n for r in ds.runs)} readings "
          f"({time.perf_counter() - t0:.0f} s)", flush=True)
    scores = []
    for seed in args.seeds:
        theta, answer = truth_vector(fm, draw(seed))
        t1 = time.perf_counter()
        data = rig_data(ds, fm.te(theta), NOISE_ARCSEC, seed)
        if args.method != "reference":
            got = calibrate(data, CalibrationSettings(workers=1, estimator=args.method), model=fm).to_dict()
        else:
            got = calibrate_gaussian(fm, data, nuisance_columns(ds)[0])
        s = score(got, answer)
        scores.append(dict(s, seed=seed))
        print(f"seed {seed}: {'PASS' if s['passed'] else 'FAIL'} RMS {s['rms_ratio']:.2f}x, covered "
              f"{s['covered']}/{s['n_intervals']}, groups {len(s['groups'])} ({time.perf_counter() - t1:.0f} s)",
              flush=True)
        for line in score_lines(s):
            print(f"    {line}")
    pooled = pool(scores)
    print(f"pooled: {pooled['passed']}/{pooled['draws']} pass, coverage {pooled['covered']}/{pooled['n_intervals']}"
          f" = {pooled['coverage'] if pooled['coverage'] is None else round(pooled['coverage'], 3)}")
    if args.out:
        args.out.write_text(json.dumps({"seeds": args.seeds, "per_rev": args.per_rev, "scores": scores,
                                        "pooled": pooled}, indent=1, default=str))
    pre = ("" if args.set == "dev" else "heldout_") if list(args.seeds) == full else \
        "seeds_" + "_".join(map(str, args.seeds)) + "_"
    bench = "coverage_linear" + ("" if args.method == "sparse" else "_" + args.method.replace("-", "_"))
    record(bench, [(pre + "draws", pooled["draws"], "count"), (pre + "passed", pooled["passed"], "count"),
               (pre + "intervals", pooled["n_intervals"], "count"),
               (pre + "covered", pooled["covered"], "count"),
               (pre + "coverage", pooled["coverage"] or 0.0, "fraction"),
               (pre + "seconds", time.perf_counter() - t0, "s")])
    return 0


if __name__ == "__main__":
    sys.exit(main())
