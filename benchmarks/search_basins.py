"""Does the tolerance-prior estimator fail by its criterion or by its search? Measured through rvdyn on realistic
draws (:mod:`realistic`).

For each draw the script runs the estimator's search (:func:`rvcalib.gaussian.map_estimate`) twice on the draw's
dataset, with the product's settings:

* from the estimator's own start (the always-estimated block's fit, :func:`rvcalib.loop.global_fit`), as
  ``rv-calibrate --estimator tolerance-prior`` runs it;
* from the draw's truth (the draw's errors and compliance as the library's parameters, no measurement effect);
* with ``--prior-starts K``, from K more starts: the estimator's own start with every Table 4 parameter drawn from
  its prior (``numpy.random.default_rng(k)``, k = 1..K, clipped to the physical bounds);
* with ``--half-turn``, from the half-turn image of the first search's end
  (:func:`rvcalib.arrangements.half_turn_image`): the instances of one crank-indexed Table 4 error move the discs
  alike to first order (their columns are nearly parallel), so which instance carries an error shows only
  through the load sharing between the cranks, and each arrangement can be a minimum of its own.

It prints the criterion (:func:`rvcalib.gaussian.criterion`, dimensionless) of both ends and of the truth itself,
all at one noise (where the first search ended), and along the straight line from the first end to the truth
(``--line`` points). Reading it:

* the truth's criterion below the first end's: the criterion prefers the truth, so a failure there is the
  search's (it ended in another minimum);
* the second search ending near the truth, with the lower criterion: the truth's own basin is a minimum the search
  holds once in it;
* a maximum along the line above both ends: the two are separate minima, with that barrier between them;
* the half-turn start's end below the first end's: a restart over the crank-indexed errors' arrangements would
  reach a better minimum than the search alone.

The figures go to ``results.csv`` (benchmark ``search_basins``, figures ``seed<N>_...``). Usage::

    python benchmarks/search_basins.py --set dev --seeds 103 --draws DIR [--half-turn]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from coverage_linear import truth_vector  # noqa: E402
from realistic import add_search_arguments, draw, generate, seeds_of  # noqa: E402
from results_log import record  # noqa: E402
from rvcalib import CalibrationSettings  # noqa: E402
from rvcalib.arrangements import half_turn_image  # noqa: E402
from rvcalib.gaussian import criterion, map_estimate, measurement_columns, prior_sd  # noqa: E402
from rvcalib.loop import Problem, global_fit, prior_scales  # noqa: E402
from rvrig.dataset import read_dataset  # noqa: E402


def basins(seed: int, draws: Path, max_linearisations: int, line: int, prior_starts: int, half_turn: bool,
           log) -> list[tuple[str, float, str]]:
    """The figures of one draw (module docstring) as ``(figure, value, unit)``."""
    folder = generate(seed, draws)
    ds = read_dataset(folder / "dataset")
    settings = CalibrationSettings(estimator="tolerance-prior", max_linearisations=max_linearisations).validate()
    pb = Problem(ds, settings)
    m = pb.model
    a_r = measurement_columns(pb)
    theta, te = global_fit(pb, np.zeros(m.n_params), m.te(np.zeros(m.n_params)), None, log, a_r)
    J = m.statistical_jacobian(theta, None)
    scales = prior_scales(pb.library, m, J, pb.R, pb.readings, ds)
    sd = prior_sd(pb, *scales)
    sigma0 = max(float(ds.noise_arcsec()), 1e-3)
    truth, _ = truth_vector(m, draw(seed))
    starts = [("own_start", theta, J), ("truth_start", truth, None)]
    table4 = np.array([c.family == "table4" for c in m.candidates for _ in range(c.n_params)])
    for k in range(1, prior_starts + 1):
        drawn = theta.copy()
        drawn[table4] = np.random.default_rng(k).normal(0.0, sd[:m.n_params][table4])
        starts.append((f"prior_start_{k}", np.clip(drawn, m._lower, m._upper), None))
    ends, out = {}, []
    if half_turn:
        starts.append(("half_turn_start", None, None))
    for name, start, J0 in starts:
        if name == "half_turn_start":
            start = half_turn_image(m.candidates, ends["own_start"][0][:m.n_params], ds.design.crank_angles_deg)
            if start is None:
                log(f"seed {seed}: no crank stands half a turn from another; no half-turn start")
                continue
        t0 = time.perf_counter()
        if J0 is None:
            m.te(start)
        th, b, te_end, sigma, stopped = map_estimate(m, pb, start, a_r, sd, sigma0, settings, None, log, J0)
        ends[name] = (np.concatenate([th, b]), te_end, sigma)
        rms = math.sqrt(float(np.mean(pb.proj(pb.y - te_end - pb.R[:, a_r] @ b) ** 2)))
        log(f"seed {seed}, search from the {name.replace('_', ' ')}: {stopped}, residual RMS {rms:.4g} arcsec, "
            f"noise {sigma:.4g}, {time.perf_counter() - t0:.0f} s")
        out += [(f"seed{seed}_{name}_residual_rms", rms, "arcsec"),
                (f"seed{seed}_{name}_converged", float(stopped == "converged"), "1")]
    x_end, te_end, sigma = ends["own_start"]
    x_true = np.concatenate([truth, np.zeros(a_r.size)])
    crit = {name.replace("start", "end"): criterion(pb, a_r, sd, x, te_x, sigma) for name, (x, te_x, _) in ends.items()}
    along = []
    for t in np.linspace(0.0, 1.0, line):
        x = (1.0 - t) * x_end + t * x_true
        along.append(criterion(pb, a_r, sd, x, m.te(x[:m.n_params]), sigma))
        log(f"seed {seed}, line from the own end to the truth, t = {t:.2f}: criterion {along[-1]:.1f}")
    crit["truth"] = along[-1]
    crit["line_max"] = max(along)
    log(f"seed {seed}, criteria at noise {sigma:.4g} arcsec: " + ", ".join(f"{k} {v:.1f}" for k, v in crit.items()))
    return out + [(f"seed{seed}_criterion_{k}", v, "1") for k, v in crit.items()] + \
        [(f"seed{seed}_criterion_noise", sigma, "arcsec")]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_search_arguments(ap)
    ap.add_argument("--line", type=int, default=6, help="points on the line from the own end to the truth (>= 2)")
    ap.add_argument("--prior-starts", type=int, default=0, help="more starts drawn from the prior (>= 0)")
    ap.add_argument("--half-turn", action="store_true",
                    help="one more start: the half-turn image of the first search's end")
    a = ap.parse_args(argv)
    if a.line < 2:
        ap.error(f"--line = {a.line} is not allowed: an integer >= 2")
    if a.prior_starts < 0:
        ap.error(f"--prior-starts = {a.prior_starts} is not allowed: an integer >= 0")
    t0 = time.perf_counter()

    def log(s: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {s}", flush=True)

    for seed in seeds_of(a.set, a.seeds):
        record("search_basins", basins(seed, a.draws, a.max_linearisations, a.line, a.prior_starts, a.half_turn,
                                       log))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
