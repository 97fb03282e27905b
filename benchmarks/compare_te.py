"""Record or compare TE curves of the physical and impact laws (nominal, every Table 4 error at the paper's
value, and the clearance cases), to check that a solver change moves no result beyond the solver tolerance.

Run: ``python benchmarks/compare_te.py record OUT.npz`` before a change, then
``python benchmarks/compare_te.py compare OUT.npz`` after it. Prints per case the max |TE difference|
(arcsec) and the overall max per law and solver; ``--fcl`` adds the fcl provider (slow), ``--steps`` the
step count (default 720).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from results_log import record, slug  # noqa: E402
from rvcad.errors import ERROR_TYPES, Case  # noqa: E402
from rvdyn.contacts import ContactLaw  # noqa: E402
from rvdyn.te import run_te, run_te_many  # noqa: E402


def cases() -> dict[str, dict]:
    out = {"nominal": {}}
    out.update({k: {"errors": {k: et.paper_value}} for k, et in ERROR_TYPES.items()})
    out["clearance 6 um"] = {"model": {"cam_bearing_clearance_um": 6.0}}
    return out


def runs(solvers: list[str], steps: int) -> dict[str, np.ndarray]:
    res: dict[str, np.ndarray] = {}
    for solver in solvers:
        for kind in ("physical", "impact"):
            for name, d in cases().items():
                if solver == "fcl" and kind == "impact" and name != "nominal":
                    continue
                t = time.process_time()
                r = run_te(Case.from_dict(d), solver, steps, law=ContactLaw(kind=kind))
                res[f"{solver}|{kind}|{name}"] = r.table["te_arcsec"].to_numpy()
                print(f"  {solver:8s} {kind:8s} {name:28s} pp {r.stats['pp']:9.4f}  {time.process_time() - t:6.2f} s CPU",
                      flush=True)
        # the physical law with clearance at load 0 (rigid limit), and a batch of loads (run_te_many)
        t = time.process_time()
        r = run_te(Case.from_dict({"model": {"cam_bearing_clearance_um": 6.0}}), solver, steps, load_Nm=0.0,
                   law=ContactLaw(kind="physical"))
        res[f"{solver}|physical|clearance 6 um load 0"] = r.table["te_arcsec"].to_numpy()
        print(f"  {solver:8s} physical clearance 6 um, load 0          {time.process_time() - t:6.2f} s CPU", flush=True)
        if solver == "analytic":
            for name in ("nominal", "pin_pitch", "clearance 6 um"):
                t = time.process_time()
                rs = run_te_many(Case.from_dict(cases()[name]), solver, [360, 37, 37, 37, 37],
                                 loads=[(20.0, 1), (5.01, 1), (5.01, -1), (167.0, 1), (167.0, -1)],
                                 law=ContactLaw(kind="physical"))
                for i, r in enumerate(rs):
                    res[f"{solver}|physical|many {name} {i}"] = r.table["te_arcsec"].to_numpy()
                print(f"  {solver:8s} physical run_te_many {name:16s}    {time.process_time() - t:6.2f} s CPU", flush=True)
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("mode", choices=["record", "compare"])
    ap.add_argument("file")
    ap.add_argument("--fcl", action="store_true")
    ap.add_argument("--steps", type=int, default=720)
    a = ap.parse_args()
    solvers = ["analytic"] + (["fcl"] if a.fcl else [])
    res = runs(solvers, a.steps)
    if a.mode == "record":
        np.savez(a.file, **res)
        return
    ref = np.load(a.file)
    worst: dict[str, float] = {}
    for k, v in res.items():
        if k not in ref:
            continue
        d = float(np.abs(v - ref[k]).max())
        grp = "|".join(k.split("|")[:2]) + (" (rigid limit)" if k.endswith("load 0") else "")
        worst[grp] = max(worst.get(grp, 0.0), d)
        print(f"  {k:60s} max |dTE| {d:.3e} arcsec")
    for g, d in worst.items():
        print(f"max |dTE| {g}: {d:.3e} arcsec")
    record("compare_te", [(slug(f"{a.steps} steps max dte {g}"), d, "arcsec") for g, d in worst.items()])


if __name__ == "__main__":
    main()
