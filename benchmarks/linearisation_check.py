"""Where does the tolerance-prior search's linearisation mispredict the reducer model? Measured through rvdyn on
realistic draws (:mod:`realistic`).

For each draw the script runs the estimator's search (:func:`rvcalib.gaussian.map_estimate`, the product's
settings) from the estimator's own start, then, at the state where it stops, linearises the model three ways:

* ``prior``: the product's columns (:meth:`rvcalib.reducer_model.ReducerModel.jacobian` with its default spread:
  each pin or kinked column a secant over +- the parameter's prior scale);
* ``tangent``: the model's tangent at the state (:meth:`rvcalib.reducer_model.ReducerModel.tangent_jacobian`:
  every column the derivative there, the single pins' too);
* ``tenth``: the same with every secant over +- a tenth of the prior scale (the derivative columns' difference
  step, ``ReducerModel.steps``).

For each it takes the linearised problem's undamped bounded MAP step ``d`` (the ``undamped`` figure of the
search's log) and evaluates the model at ``x + t d_S`` for ``t`` in ``--fractions`` and ``S`` every parameter, or
the parameters of one column kind (``derivative``, ``pin``, ``form``, ``kink``). It prints, in arcsec RMS over the
readings (projected off the tests' constants), the change the linearisation predicts and its misprediction
(the model's TE less the linearised TE), and the criterion (:func:`rvcalib.gaussian.criterion`) both give, at the
noise where the search stopped. Reading it: a misprediction near or above the predicted change says the columns
do not describe the model over that step; the kind whose own step mispredicts most is where the linearisation
fails.

The figures go to ``results.csv`` (benchmark ``linearisation_check``, figures ``seed<N>_<columns>_<kind>_t<t>_...``).
Usage::

    python benchmarks/linearisation_check.py --set dev --seeds 101 --draws DIR [--workers 2]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from realistic import add_search_arguments, generate, seeds_of  # noqa: E402
from results_log import record  # noqa: E402
from rvcalib import CalibrationSettings  # noqa: E402
from rvcalib.gaussian import (criterion, damped_step, map_estimate, measurement_columns, prior_sd,  # noqa: E402
                              search_bounds)
from rvcalib.loop import Problem, global_fit, prior_scales  # noqa: E402
from rvcalib.reducer_model import ModelEvaluationError  # noqa: E402
from rvrig.dataset import read_dataset  # noqa: E402

KINDS = ("all", "derivative", "pin", "form", "kink")


def _rms(pb, v: np.ndarray) -> float:
    return math.sqrt(float(np.mean(pb.proj(v) ** 2)))


def check(seed: int, draws: Path, max_linearisations: int, fractions: list[float], workers: int,
          log) -> list[tuple[str, float, str]]:
    """The figures of one draw (module docstring) as ``(figure, value, unit)``."""
    ds = read_dataset(generate(seed, draws) / "dataset")
    settings = CalibrationSettings(estimator="tolerance-prior", max_linearisations=max_linearisations,
                                   workers=workers).validate()
    pb = Problem(ds, settings)
    m, a_r = pb.model, measurement_columns(pb)
    n_s = m.n_params
    out = []
    with ProcessPoolExecutor(workers) as pool:
        theta, _ = global_fit(pb, np.zeros(n_s), m.te(np.zeros(n_s)), pool, log, a_r)
        J = m.statistical_jacobian(theta, pool)
        sd = prior_sd(pb, *prior_scales(pb.library, m, J, pb.R, pb.readings, ds))
        th, b, _, sigma, stopped = map_estimate(m, pb, theta, a_r, sd, max(float(ds.noise_arcsec()), 1e-3),
                                                settings, pool, log, J)
        te = m.te(th)
        x = np.concatenate([th, b])
        phi = criterion(pb, a_r, sd, x, te, sigma)
        log(f"seed {seed}: the search {stopped}, criterion {phi:.2f} at noise {sigma:.4g} arcsec")
        out += [(f"seed{seed}_end_criterion", phi, "1"), (f"seed{seed}_end_noise", sigma, "arcsec")]
        kinds = m.column_kinds()
        w = 1.0 / sd[np.concatenate([np.arange(n_s), n_s + a_r])]
        lo, hi = search_bounds(m, a_r)
        Rm = pb.proj(pb.R[:, a_r])
        columns = {"prior": lambda: m.jacobian(th, None, None, pool), "tangent": lambda: m.tangent_jacobian(th, pool),
                   "tenth": lambda: m.jacobian(th, m.steps(), None, pool)}
        for label, linearise in columns.items():
            Js = linearise()
            r = pb.proj(pb.y - te) - Rm @ b
            d = np.clip(x + damped_step(np.column_stack([pb.proj(Js), Rm]), r, x, w, sigma, 0.0, lo, hi), lo, hi) - x
            for kind in KINDS:
                sel = np.ones(x.size, dtype=bool) if kind == "all" else np.r_[kinds == kind, np.zeros(a_r.size, bool)]
                if not sel.any():
                    continue
                for t in fractions:
                    xn = x + t * np.where(sel, d, 0.0)
                    lin = te + Js @ (xn - x)[:n_s]
                    try:
                        act = m.te(xn[:n_s])
                    except ModelEvaluationError as exc:
                        log(f"  {label} columns, {kind} step x {t:g}: the model cannot be evaluated there ({exc})")
                        continue
                    pred, mis = _rms(pb, lin - te), _rms(pb, act - lin)
                    c_lin, c_act = criterion(pb, a_r, sd, xn, lin, sigma), criterion(pb, a_r, sd, xn, act, sigma)
                    log(f"  {label} columns, {kind} step x {t:g}: predicted change {pred:.4f}, misprediction "
                        f"{mis:.4f} arcsec RMS; criterion linearised {c_lin:.2f}, model {c_act:.2f}")
                    key = f"seed{seed}_{label}_{kind}_t{t:g}"
                    out += [(key + "_predicted_change", pred, "arcsec"), (key + "_misprediction", mis, "arcsec"),
                            (key + "_criterion_model", c_act, "1")]
            m.te(th)                                # the end's states again, for the next columns
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_search_arguments(ap)
    ap.add_argument("--fractions", type=float, nargs="+", default=[0.1, 0.3, 1.0],
                    help="fractions t of the undamped step (each > 0)")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    if any(not t > 0 for t in a.fractions):
        ap.error(f"--fractions = {a.fractions} is not allowed: numbers > 0")
    t0 = time.perf_counter()

    def log(s: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {s}", flush=True)

    for seed in seeds_of(a.set, a.seeds):
        record("linearisation_check", check(seed, a.draws, a.max_linearisations, a.fractions, a.workers, log))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
