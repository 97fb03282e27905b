"""Benchmark of one Monte Carlo draw case of the full solver (analytic contacts, one revolution).

Run: ``python benchmarks/bench_mc_draw.py [--case study|pins] [--steps 360] [--repeat 2] [--contact physical|impact]
[--profile]``. ``--contact``: the contact law of every solve (default physical, rvdyn's and the study's Monte Carlo
default; impact = the paper's law).
``study`` (default): one draw of the default stack-up study (``rvstudy.features``), solved as
``rvstudy.stackup.responses_of`` does: the TE run (360 steps) and the four play/rigidity runs; then the same
draw with the four play runs as one ``rvdyn.te.run_te_many`` batch, and with all five runs as one batch
(largest TE difference to the separate ``run_te`` results printed).
``equidistant``: the ``pins`` errors on a disc cut with a 0.1 mm equidistant modification (every pin far
off the profile, the worst case for the global foot search).
``pins``: pin-wise ``pin_radius``, ``pin_pitch`` and ``pin_circle_diameter`` lists of Zp normal draws
(sigma = paper value / 3, seed 1) and ``disc_phase`` 0.03 deg. Prints seconds per draw case (best of --repeat,
one core), the TE peak-to-peak, and the time spent in ``CycloidProfile.signed_distance``.
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a clone without installing

import numpy as np  # noqa: E402

from results_log import record, slug  # noqa: E402

from rvcad.errors import ERROR_TYPES, Case  # noqa: E402
from rvcad.params import Design  # noqa: E402
from rvdyn.contacts import ContactLaw  # noqa: E402
from rvdyn.te import run_te, run_te_many  # noqa: E402


def draw_errors(seed: int = 1) -> dict:
    """One stack-up-like draw: pin-wise errors at sigma = paper value / 3, disc phase 0.03 deg."""
    zp = Design().z_pins
    rng = np.random.default_rng(seed)
    errs = {k: [float(v) for v in rng.normal(0.0, ERROR_TYPES[k].paper_value / 3.0, zp)]
            for k in ("pin_radius", "pin_pitch", "pin_circle_diameter")}
    errs["disc_phase"] = 0.03
    return errs


def draw_case(seed: int = 1) -> Case:
    return Case.from_dict({"name": "mc-draw", "errors": draw_errors(seed)})


def study_cases(seed: int = 1) -> list[tuple[Case, int]]:
    """One draw of the default stack-up study as ``run_full_mc`` solves it: (case, steps) of the TE run at
    the study load and the four play/rigidity runs (+-3 % and +-100 % rated, play positions)."""
    from rvstudy.features import draw, features, make_draw_case
    from rvstudy.stackup import PLAY_LOAD_FRACTION, play_positions
    from rvstudy.study import StudyConfig
    cfg = StudyConfig()
    design = Design()
    feats = features(cfg.tolerances, design)
    X = draw(cfg.tolerances, feats, 1, np.random.default_rng([seed, 2]))
    out = [(make_draw_case(feats, X.iloc[0], design, "mc-te", cfg.load_Nm), cfg.steps)]
    for frac, d in ((PLAY_LOAD_FRACTION, 1), (PLAY_LOAD_FRACTION, -1), (1.0, 1), (1.0, -1)):
        out.append((make_draw_case(feats, X.iloc[0], design, "mc-play", frac * cfg.rated_Nm, d),
                    play_positions(design)))
    return out


def best_of(fn, repeat: int) -> tuple[list, float, float]:
    """Run ``fn`` ``repeat`` times: its last result, the best wall time and the best CPU time, s."""
    best = cpu = np.inf
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        best = min(best, time.perf_counter() - t)
        cpu = min(cpu, time.process_time() - c)
    return out, best, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=360)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--profile", action="store_true", help="print the top cProfile entries")
    ap.add_argument("--contact", choices=ContactLaw.KINDS, default="physical",
                    help="contact law of every solve (default physical; impact = the paper's law)")
    ap.add_argument("--case", choices=["pins", "study", "equidistant"], default="study",
                    help="pins: pin-wise lists + disc phase; study: one draw of the default stack-up study; "
                         "equidistant: the pins-case errors on a disc with a 0.1 mm equidistant modification "
                         "(every pin stands ~0.1 mm off the profile: the global foot search on every point)")
    a = ap.parse_args()
    if a.case == "pins":
        runs = [(draw_case(), a.steps)]
    elif a.case == "equidistant":
        runs = [(Case.from_dict({"name": "mc-equidistant", "design": {"profile_equidistant_mm": 0.1},
                                 "errors": draw_errors()}), a.steps)]
    else:
        runs = study_cases()

    law = ContactLaw(kind=a.contact)

    def solve_all() -> list:
        return [run_te(c, "analytic", n, law=law) for c, n in runs]

    rs, best, cpu = best_of(solve_all, a.repeat)
    print(f"MC draw ({a.case}, {a.contact} law: {len(runs)} analytic solves, steps {[n for _, n in runs]}): "
          f"{best:.3f} s wall, "
          f"{cpu:.3f} s CPU (best of {a.repeat})")
    tag = f"{a.case} {a.contact} {a.steps} steps"
    figures = [(slug(f"{tag} separate solves cpu"), cpu, "s")]
    for (c, n), r in zip(runs, rs):
        print(f"  {c.name} load {c.load_Nm:g} N m dir {c.direction:+d}: pp {r.stats['pp']:.6f} arcsec  "
              f"mean {r.stats['mean']:.6f} arcsec")
    if a.case == "study":
        pairs = [(c.load_Nm, c.direction) for c, _ in runs]
        batches = {
            "TE run_te + 4 play runs as one run_te_many": lambda: (
                [run_te(runs[0][0], "analytic", runs[0][1], law=law)]
                + run_te_many(runs[1][0], "analytic", runs[1][1], loads=pairs[1:], law=law)),
            "all 5 runs as one run_te_many": lambda: run_te_many(
                runs[0][0], "analytic", [n for _, n in runs], loads=pairs, law=law)}
        for name, fn in batches.items():
            rb, bw, bc = best_of(fn, a.repeat)
            d = max(float(np.abs(x.table["te_arcsec"].to_numpy() - y.table["te_arcsec"].to_numpy()).max())
                    for x, y in zip(rs, rb))
            print(f"MC draw, {name}: {bw:.3f} s wall, {bc:.3f} s CPU (best of {a.repeat}); "
                  f"largest TE difference to the separate runs {d:.2e} arcsec")
            short = "play batch" if name.startswith("TE run_te") else "one batch"
            figures += [(slug(f"{tag} {short} cpu"), bc, "s"), (slug(f"{tag} {short} max te difference"), d, "arcsec")]
    record("bench_mc_draw", figures)
    pr = cProfile.Profile()
    pr.enable()
    solve_all()
    pr.disable()
    st = pstats.Stats(pr)
    for (fn, _line, name), v in st.stats.items():
        if name in ("signed_distance", "foot_point", "solve") and fn.endswith(("profile.py", "solver.py")):
            print(f"  {name}: {v[1]} calls, {v[3]:.3f} s cumulative (under cProfile)")
    if a.profile:
        st.sort_stats("cumulative").print_stats(25)


if __name__ == "__main__":
    main()
