"""Realistic draws of a reducer on a test rig, for the calibration benchmark protocol.

A draw is a simulated measured dataset (:func:`rvcalib.simulate.simulate_dataset`) of the paper's
default design whose truth is random but fixed by one seed. Each seed's draw (``numpy.random.default_rng``,
in this order):

1. For each of the eleven Table 4 error types (:data:`rvcad.errors.ERROR_TYPES`, in its order): one
   instance of size ``normal(0, paper_value / 3)`` (the tolerance a maker holds as 3 sigma); then its
   instance: ``pin_pitch`` at a pin uniform over the pins, ``pin_circle_diameter`` and ``pin_radius``
   at all pins (their default instance), the crank, disc and hole indices of the others uniform over
   the design's counts (in the order of the type's ``instance_keys``); then, for the eccentricities and
   the pin circle offset (``has_angle``), a direction ``angle_deg`` uniform in [0, 360).
2. A torsional compliance uniform in [0.1, 0.3] arcsec/(N m)
   (``model.torsional_compliance_arcsec_per_Nm``); the contact law is rvdyn's default (physical).
3. Four runs: 10 and 30 N m, each in both directions. Each load is one test, with its own rig zero:
   a constant ``normal(0, 30)`` arcsec added to the TE reading of both runs of that test.
4. The readings: 333 per output revolution, one revolution per run, from an input angle uniform in
   [0, 1) deg (off every model grid); output-encoder noise 0.2 arcsec and input-encoder noise 1.0
   arcsec (standard deviations), drawn with their own seed (an integer taken from the draw's stream).

The seed sets are fixed here, before any method is run on them: :data:`DEV_SEEDS` is the development
set (a method may be tuned on it), :data:`HELDOUT_SEEDS` is run only to report.

Each draw goes in ``<root>/seed<N>/``: ``dataset/`` (``runs.csv``, ``samples.csv``: what a rig would
record, nothing of the truth) and ``answer.json`` (the simulator's answer: ``hidden``,
``expected_effects`` with each error's key, instance, value and angle, ``noise_te_arcsec``,
``test_offsets``, ``run_tests``; plus ``draw``: the seed, the generator tag and the drawn figures).
A folder whose answer carries the same seed and :data:`GENERATOR` is reused; anything else is drawn again.

Run: ``python benchmarks/realistic.py --set dev|heldout [--seeds N ...] --out DIR`` writes the draws
and prints each one's truth.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rvcad.atomic import atomic_path  # noqa: E402
from rvcad.errors import ERROR_TYPES  # noqa: E402
from rvcad.params import Design  # noqa: E402
from rvcalib import CalibrationSettings  # noqa: E402
from rvcalib.simulate import simulate_dataset  # noqa: E402

#: Development seeds: a method may be tuned on these draws.
DEV_SEEDS = range(101, 111)
#: Held-out seeds: run only to report, never to make a rule.
HELDOUT_SEEDS = range(9001, 9025)
SETS: dict[str, range] = {"dev": DEV_SEEDS, "heldout": HELDOUT_SEEDS}

#: Tag of this generator's rules, recorded in each answer; a cached draw of another tag is drawn again.
GENERATOR = "realistic-v1"
SIZE_SIGMA_OF_PAPER = 1.0 / 3.0           # sigma of each error's size, as a fraction of its Table 4 value
COMPLIANCE_RANGE = (0.1, 0.3)             # arcsec/(N m), uniform
COMPLIANCE_KEY = "torsional_compliance_arcsec_per_Nm"
LOADS_NM = (10.0, 30.0)                   # one test per load
DIRECTIONS = (1, -1)
TEST_OFFSET_SIGMA_ARCSEC = 30.0           # rig zero of each test
SAMPLES_PER_REV = 333
START_DEG_RANGE = (0.0, 1.0)              # input angle of the first reading, deg, uniform
OUTPUT_NOISE_ARCSEC = 0.2
INPUT_NOISE_ARCSEC = 1.0


@dataclass(frozen=True)
class Draw:
    """One seed's truth and rig settings.

    Attributes
    ----------
    seed : int
    errors : dict
        Error key -> case-JSON error object (``value`` in um or deg, instance keys, ``angle_deg``).
    compliance : float
        Torsional compliance, arcsec/(N m).
    test_offsets : dict
        Test id -> rig zero (arcsec) added to the TE reading of the test's runs.
    start_deg : float
        Input angle of the first reading, deg.
    noise_seed : int
        Seed of the encoders' noise.
    """

    seed: int
    errors: dict[str, dict[str, Any]]
    compliance: float
    test_offsets: dict[str, float]
    start_deg: float
    noise_seed: int

    def hidden(self) -> dict[str, Any]:
        """The simulator's ``hidden`` object."""
        return {"errors": {k: dict(v) for k, v in self.errors.items()}, "model": {COMPLIANCE_KEY: self.compliance}}

    def runs(self) -> list[dict[str, Any]]:
        """The four runs (ids 1..4), each with its test id."""
        out, i = [], 1
        for load in LOADS_NM:
            for d in DIRECTIONS:
                out.append({"run": str(i), "load_Nm": load, "direction": d, "test": test_id(load)})
                i += 1
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"generator": GENERATOR, "seed": self.seed, "errors": self.errors, "compliance": self.compliance,
                "test_offsets": self.test_offsets, "start_deg": self.start_deg, "noise_seed": self.noise_seed}


def test_id(load_Nm: float) -> str:
    """The id of the test at a load (``10Nm``)."""
    return f"{load_Nm:g}Nm"


test_id.__test__ = False   # not a pytest test when imported into one


def draw(seed: int, design: Design | None = None) -> Draw:
    """The truth of one seed (module docstring, steps 1-4).

    Parameters
    ----------
    seed : int
        Seed of ``numpy.random.default_rng``.
    design : Design or None
        The reducer (default the paper's); its counts bound the instance indices.
    """
    d = design or Design()
    counts = {"crank": d.n_cranks, "disc": d.n_discs, "hole": d.n_cranks, "pin": d.z_pins}
    rng = np.random.default_rng(int(seed))
    errors: dict[str, dict[str, Any]] = {}
    for key, et in ERROR_TYPES.items():
        item: dict[str, Any] = {"value": float(rng.normal(0.0, et.paper_value * SIZE_SIGMA_OF_PAPER))}
        for ik in et.instance_keys:
            if et.defaults.get(ik, 0) is None:
                continue                                   # all pins: the default instance of I and J
            item[ik] = int(rng.integers(counts[ik]))
        if et.has_angle:
            item["angle_deg"] = float(rng.uniform(0.0, 360.0))
        errors[key] = item
    compliance = float(rng.uniform(*COMPLIANCE_RANGE))
    offsets = {test_id(L): float(rng.normal(0.0, TEST_OFFSET_SIGMA_ARCSEC)) for L in LOADS_NM}
    start = float(rng.uniform(*START_DEG_RANGE))
    noise_seed = int(rng.integers(2 ** 31 - 1))
    return Draw(int(seed), errors, compliance, offsets, start, noise_seed)


def draw_folder(root: str | Path, seed: int) -> Path:
    """The folder of a seed's draw under ``root``."""
    return Path(root) / f"seed{int(seed)}"


def cached(folder: Path, seed: int) -> dict[str, Any] | None:
    """The answer of a complete draw of this seed and generator in ``folder``, else None."""
    ap = folder / "answer.json"
    if not (ap.is_file() and (folder / "dataset" / "runs.csv").is_file()
            and (folder / "dataset" / "samples.csv").is_file()):
        return None
    try:
        ans = json.loads(ap.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    meta = ans.get("draw") or {}
    return ans if meta.get("generator") == GENERATOR and meta.get("seed") == int(seed) else None


def generate(seed: int, root: str | Path) -> Path:
    """Write (or reuse) a seed's draw under ``root``; returns its folder (``dataset/``, ``answer.json``)."""
    folder = draw_folder(root, seed)
    if cached(folder, seed) is not None:
        return folder
    dr = draw(seed)
    ap = simulate_dataset(folder / "dataset", dr.runs(), dr.hidden(), noise_arcsec=OUTPUT_NOISE_ARCSEC,
                          input_noise_arcsec=INPUT_NOISE_ARCSEC, samples_per_rev=SAMPLES_PER_REV,
                          start_deg=dr.start_deg, seed=dr.noise_seed, answer_path=folder / "answer.json",
                          test_offsets=dr.test_offsets)
    ans = json.loads(ap.read_text())
    ans["draw"] = dr.to_dict()          # written last: a folder without it is drawn again
    with atomic_path(ap) as tmp:
        Path(tmp).write_text(json.dumps(ans, indent=2), encoding="utf-8")
    return folder


def add_search_arguments(ap) -> None:
    """The arguments of a benchmark that runs the tolerance-prior search on realistic draws: ``--set``,
    ``--seeds``, ``--draws`` (required) and ``--max-linearisations``."""
    ap.add_argument("--set", default="dev", choices=sorted(SETS))
    ap.add_argument("--seeds", type=int, nargs="*", default=None, help="a subset of the set's seeds")
    ap.add_argument("--draws", type=Path, required=True, help="folder of the generated draws (reused)")
    ap.add_argument("--max-linearisations", type=int, default=CalibrationSettings().max_linearisations)


def seeds_of(set_name: str, seeds: list[int] | None = None) -> list[int]:
    """The seeds of a set (``dev`` or ``heldout``), or the given subset of them.

    Raises
    ------
    ValueError
        For an unknown set, or a seed not in the set.
    """
    if set_name not in SETS:
        raise ValueError(f"set {set_name!r} is unknown; allowed: {sorted(SETS)}")
    allowed = list(SETS[set_name])
    if not seeds:
        return allowed
    bad = [s for s in seeds if s not in allowed]
    if bad:
        raise ValueError(f"seeds {bad} are not in the {set_name} set; allowed: {allowed[0]}..{allowed[-1]}")
    return list(seeds)


def truth_lines(answer: dict[str, Any]) -> list[str]:
    """A human summary of a draw's truth."""
    out = []
    for e in answer["expected_effects"]:
        inst = ",".join(f"{k}={v}" for k, v in (e.get("instance") or {}).items())
        ang = f" at {e['angle_deg']:.1f} deg" if e.get("angle_deg") is not None else ""
        out.append(f"{e['key']}[{inst}] = {e['value']:+.4g} {e['unit']}{ang}")
    out.append("test offsets: " + ", ".join(f"{t} {v:+.2f} arcsec" for t, v in answer["test_offsets"].items()))
    out.append(f"TE noise {answer['noise_te_arcsec']:.4g} arcsec, start {answer['start_deg']:.4f} deg")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", required=True, choices=sorted(SETS), help="seed set")
    ap.add_argument("--seeds", type=int, nargs="*", default=None, help="a subset of the set's seeds")
    ap.add_argument("--out", required=True, help="folder of the draws (reused when already drawn)")
    args = ap.parse_args(argv)
    for s in seeds_of(args.set, args.seeds):
        folder = generate(s, args.out)
        print(f"seed {s}: {folder}")
        for line in truth_lines(json.loads((folder / "answer.json").read_text())):
            print("  " + line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
