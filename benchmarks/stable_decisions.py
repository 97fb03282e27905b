"""Whether the loop's decisions hold when nothing that matters changes: 1 or 2 workers, and every load moved by one ulp.

The loop (``rvcalib.loop.calibrate``, its default settings but ``workers``) runs three times on one simulated
dataset: with one worker, with two, and with every run's load moved up by one unit in the last place
(``numpy.nextafter``). A *decision* is what the result names: the named effects, the members of each group, the
unexplained structure, why the loop stopped and after how many linearisations. The three runs must make the same
decisions; their named sizes may differ only by solver resolution, printed as the largest difference over the
named effect's 95 % interval's half-width.

The dataset (``rvcalib.simulate.simulate_dataset``, other readings than the loop's: 72 per revolution starting off
the grid, its own noise, a rig zero per test): the physical contact law (the loop's default), 10 and 30 N m both
ways, a pin's pitch, a cam's phase, a planet's eccentricity, a torsional compliance and an output encoder
eccentricity at once.

Run: ``python benchmarks/stable_decisions.py`` (about two minutes on two cores); figures to
``benchmarks/results.csv`` (benchmark ``stable_decisions``).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_log import record  # noqa: E402
from rvcalib.loop import calibrate  # noqa: E402
from rvcalib.settings import CalibrationSettings  # noqa: E402
from rvcalib.simulate import simulate_dataset, standard_runs  # noqa: E402
from rvrig.dataset import read_dataset  # noqa: E402

LOADS_NM = (10.0, 30.0)
HIDDEN = {"errors": {"pin_pitch": {"value": 0.008, "pin": 7},
                     "cam_phase": {"value": 3.0, "crank": 0, "disc": 1},
                     "planet_eccentricity": {"value": 4.0, "angle_deg": 30.0, "crank": 1}},
          "model": {"torsional_compliance_arcsec_per_Nm": 0.2},
          "measurement": {"output_encoder_eccentricity_um": 12.0, "output_encoder_phase_deg": 70.0}}


def make_dataset(folder: Path, seed: int) -> Path:
    """The simulated dataset of the module's docstring in ``folder``."""
    runs = [dict(r, test=f"{r['load_Nm']:g}Nm") for r in standard_runs(LOADS_NM, (1, -1))]
    simulate_dataset(folder, runs, HIDDEN, noise_arcsec=0.2, input_noise_arcsec=1.0, samples_per_rev=72,
                     start_deg=0.41, seed=seed, test_offsets={"10Nm": 25.0, "30Nm": -25.0})
    return folder


def one_ulp_up(dataset):
    """A copy of ``dataset`` with every run's load moved up by one unit in the last place."""
    runs = [dataclasses.replace(r, load_Nm=float(np.nextafter(r.load_Nm, np.inf))) for r in dataset.runs]
    return dataclasses.replace(dataset, runs=runs, tests=dataset.tests)


def decisions(res) -> dict[str, Any]:
    """What a result decides: named effects, groups' members, unexplained structure, the stop and its count."""
    return {"named": sorted(e.name for e in res.effects),
            "groups": sorted(tuple(sorted(m["name"] for m in g["members"])) for g in res.groups),
            "unexplained": sorted(u["label"] for u in res.unexplained),
            "stopped_by": res.stopped_by, "linearisations": res.linearisations}


def largest_shift(a, b) -> float:
    """Largest difference of a named effect's size between two results, over its 95 % half-width in ``a``."""
    other = {e.name: e for e in b.effects}
    out = 0.0
    for e in a.effects:
        if e.name in other:
            half = max(0.5 * (e.ci95[1] - e.ci95[0]), 1e-300)
            out = max(out, abs(e.value - other[e.name].value) / half)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=5, help="the simulated rig's noise seed")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="stable-") as tmp:
        ds = read_dataset(make_dataset(Path(tmp) / "ds", args.seed))
        variants = {"1 worker": (ds, 1), "2 workers": (ds, 2), "loads + 1 ulp": (one_ulp_up(ds), 2)}
        results, secs = {}, {}
        for label, (d, workers) in variants.items():
            t0 = time.perf_counter()
            results[label] = calibrate(d, CalibrationSettings(workers=workers))
            secs[label] = time.perf_counter() - t0
            print(f"{label}: {secs[label]:.0f} s, rms {results[label].rms_after:.4g} arcsec, "
                  f"{decisions(results[label])}", flush=True)
    ref = results["1 worker"]
    figs = []
    for label in ("2 workers", "loads + 1 ulp"):
        same = decisions(results[label]) == decisions(ref)
        shift = largest_shift(ref, results[label])
        print(f"{label} against 1 worker: same decisions {same}; largest size change {shift:.3g} half-widths")
        key = label.replace(" ", "_").replace("+", "plus")
        figs += [(f"{key}_same_decisions", float(same), "bool"), (f"{key}_largest_shift", shift, "half-widths")]
    for label, res in results.items():
        key = label.replace(" ", "_").replace("+", "plus")
        figs += [(f"{key}_seconds", secs[label], "s"), (f"{key}_rms_after", res.rms_after, "arcsec")]
    record("stable_decisions", figs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
