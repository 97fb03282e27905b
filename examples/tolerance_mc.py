"""A small tolerance Monte Carlo through the full solver, with the process capability of the TE.

Every Table 4 error is drawn on every feature of the reducer (each of the 40 pins' radius, pitch and radial
position, each cam, crank, disc hole, ...; 144 features) from the default tolerances of ``rv-stackup``: normal with
mean 0 and sigma = the paper's value / 3. Each draw is one case solved by rvdyn over one output revolution
(``rvdyn.run_cases``, in worker processes), and its TE peak-to-peak is set against an upper specification limit of
1 arcmin: mean, sigma, Cpk and the fraction out of spec with its exact (Clopper-Pearson) 95 % interval
(``rvstudy.capability``). ``rv-stackup`` does the same at scale, with the play and rigidity responses and the
contributors of each tolerance.

Run: ``python examples/tolerance_mc.py [--small] [--draws N] [--workers N] [--out DIR]``; writes
``DIR/tolerance_mc.png`` (default DIR ``examples-out``). Default 200 draws at 360 steps on 2 workers;
``--small``: 12 draws at 60 steps in this process.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import rvdyn  # noqa: E402
from rvcad.params import Design  # noqa: E402
from rvstudy.capability import capability  # noqa: E402
from rvstudy.features import draw, features, make_draw_case  # noqa: E402
from rvstudy.study import StudyConfig  # noqa: E402

USL_ARCMIN = 1.0
LOAD_NM = 20.0


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="12 draws at 60 steps, in this process")
    ap.add_argument("--draws", type=int, default=None, help="number of draws (default 200; 12 with --small)")
    ap.add_argument("--workers", type=int, default=None, help="worker processes (default 2; 1 with --small)")
    ap.add_argument("--seed", type=int, default=1, help="random seed of the draws")
    ap.add_argument("--out", type=Path, default=Path("examples-out"), help="output folder (default examples-out)")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    n = a.draws or (12 if a.small else 200)
    steps = 60 if a.small else 360
    workers = a.workers or (1 if a.small else 2)

    tolerances = StudyConfig().tolerances            # rv-stackup's defaults: normal(0, paper value / 3), each
    design = Design()
    feats = features(tolerances, design)
    X = draw(tolerances, feats, n, np.random.default_rng(a.seed))
    cases = [make_draw_case(feats, X.iloc[i], design, f"draw{i}", LOAD_NM) for i in range(n)]
    results = rvdyn.run_cases(cases, steps=steps, executor=workers)
    pp = np.array([r["stats"]["pp"] / 60.0 if r["status"] == "ok" else np.nan for r in results])  # arcmin
    cap = capability(pp, None, USL_ARCMIN)
    lo, hi = cap["out_of_spec_ci"]
    print(f"{n} draws of {len(feats)} features, {steps} steps: TE pp mean {cap['mean']:.3f} arcmin, sigma "
          f"{cap['std']:.3f}, Cpk {cap['cpk']:.2f} against USL {USL_ARCMIN} arcmin; out of spec "
          f"{100 * cap['out_of_spec_fraction']:.1f} % (95 % CI [{100 * lo:.1f}, {100 * hi:.1f}] %); "
          f"{cap['n_failed']} failed solves")

    fig, (hist, curves) = plt.subplots(1, 2, figsize=(13, 4.6))
    hist.hist(pp[np.isfinite(pp)], bins=max(5, n // 8), color="tab:blue", alpha=0.8)
    hist.axvline(USL_ARCMIN, color="tab:red", lw=1.5, label=f"USL {USL_ARCMIN} arcmin")
    hist.set_xlabel("TE peak-to-peak [arcmin]")
    hist.set_ylabel("draws")
    hist.set_title(f"{n} full-solver draws: Cpk {cap['cpk']:.2f}, out of spec {100 * cap['out_of_spec_fraction']:.1f} % "
                   f"[{100 * lo:.1f}, {100 * hi:.1f}] %", fontsize=10)
    hist.legend(fontsize=8)
    order = np.argsort(np.nan_to_num(pp, nan=-1.0))
    for i in (order[0], order[len(order) // 2], order[-1]):
        te = np.asarray(results[i]["te_arcsec"])
        x = np.arange(te.size) * 360.0 / te.size
        curves.plot(x, te, lw=0.8, label=f"{cases[i].name}: pp {pp[i]:.2f} arcmin")
    curves.set_xlabel("output angle [deg]")
    curves.set_ylabel("TE [arcsec]")
    curves.set_title("TE of the smallest, the median and the largest draw", fontsize=10)
    curves.legend(fontsize=8)
    curves.grid(True, lw=0.3)
    fig.tight_layout()
    path = a.out / "tolerance_mc.png"
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
