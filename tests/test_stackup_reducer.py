"""``rv-stackup --reducer DESIGN.json``: the study runs on the user's reducer and says so (issue 15).

Two designs besides the paper's: a ratio-81 RV (Z1 18, Z2 36, 40 pins, 39 lobes) and a 30-pin /
29-lobe reducer (ratio 91). Small studies (few steps, few draws)."""
from __future__ import annotations

import json

import pandas as pd
import pytest

from rvcad.params import Design
from rvstudy import cli
from rvdyn.cache import CaseCache

STEPS = 24
SMALL = ["--solver", "analytic", "--steps", str(STEPS), "--workers", "1", "--no-progress", "--no-figures",
         "--sweep-points", "2", "--mc-draws", "4", "--mc-sobol", "0", "--mc-check", "0", "--json"]


@pytest.mark.parametrize("design, ratio, stages", [
    ({"z_sun": 18, "z_planet": 36}, 81.0, "doe,mc"),
    ({"z_pins": 30, "z_disc": 29}, 91.0, "screen,mc"),
])
def test_study_on_a_users_reducer(tmp_path, capsys, design, ratio, stages):
    f = tmp_path / "design.json"
    f.write_text(json.dumps(design))
    out = tmp_path / "run"
    assert cli.main(["--out", str(out), "--reducer", str(f), "--stages", stages, *SMALL]) == 0
    s = json.loads(capsys.readouterr().out)
    d = Design.from_dict(design)
    assert s["reducer"]["ratio"] == pytest.approx(ratio, rel=1e-12)
    assert s["reducer"]["design"]["z_pins"] == d.z_pins and s["reducer"]["source"] == str(f)
    rep = (out / "report.md").read_text()
    assert f"ratio {ratio:g}" in rep and f"{d.z_pins} pins, {d.z_disc} lobes" in rep
    # every solved case is of that reducer: its measured ratio (input over output slope, with the case's
    # errors: a TE of up to a few arcmin over 24 steps moves it by ~1e-5) is the design's
    cache = CaseCache(out / "cache")
    ratios = [cache.get(p.stem)["stats"]["ratio"] for p in cache.entries()]
    assert ratios and all(r == pytest.approx(ratio, rel=1e-4) for r in ratios)
    # the Monte Carlo draws every pin of this reducer
    feats = pd.read_csv(out / "tables" / "mc_features.csv")
    assert (feats["tolerance"] == "pin_radius").sum() == d.z_pins
    if "doe" in stages:  # the paper's side-by-side columns are of the paper's reducer only
        assert "paper_te_arcmin" not in pd.read_csv(out / "tables" / "table6_compare.csv")
    if "screen" in stages:
        assert (out / "tables" / "screen.csv").is_file()


def test_bad_reducer_is_named(tmp_path, capsys):
    f = tmp_path / "design.json"
    f.write_text(json.dumps({"z_sun": "eighteen"}))
    assert cli.main(["--out", str(tmp_path / "o"), "--reducer", str(f), *SMALL]) == 2
    err = capsys.readouterr().err
    assert "--reducer" in err and "z_sun" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_study_on_the_three_crank_rv160n_example(tmp_path, capsys):
    """The RV-160N-like example (examples/designs/rv160n.json, a case file: three cranks, ratio 81): the study
    runs on it, and the Monte Carlo draws every instance of the crank-wise errors on all three cranks (a planet
    offset per crank, a cam per crank and disc, a carrier hole per crank, a disc hole per disc and crank)."""
    from pathlib import Path

    example = Path(__file__).resolve().parents[1] / "examples" / "designs" / "rv160n.json"
    out = tmp_path / "run"
    assert cli.main(["--out", str(out), "--reducer", str(example), "--stages", "doe,mc", *SMALL]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["reducer"]["ratio"] == pytest.approx(81.0, rel=1e-12)
    assert s["reducer"]["design"]["crank_angles_deg"] == [0.0, 120.0, 240.0]
    assert "3 cranks at 0/120/240 deg" in (out / "report.md").read_text()
    feats = pd.read_csv(out / "tables" / "mc_features.csv")
    per = feats["tolerance"].value_counts()
    assert per["planet_eccentricity"] == 3 * 2                              # x and y per crank
    assert per["cam_phase"] == per["cam_eccentricity"] == 3 * 2              # crank x disc
    assert per["carrier_hole_eccentricity"] == 3 and per["disc_hole_eccentricity"] == 2 * 3
    assert {f"cam_phase[crank=2,disc={k}]" for k in (0, 1)} <= set(feats["feature"])
    cache = CaseCache(out / "cache")
    entries = [cache.get(p.stem) for p in cache.entries()]
    assert entries and all(e["stats"]["ratio"] == pytest.approx(81.0, rel=1e-4) for e in entries)
