"""rvcalib's dataset reader on a reducer other than the paper's: a ratio-81 RV (Z1 18, Z2 36, 40 pins, 39 lobes)
whose folder carries its ``design.json``, read without it (refused, naming the ratio) and with bad design files.
The loop on such a reducer: tests/test_calib_loop.py and tests/test_calib_cli.py."""
from __future__ import annotations

import json
import shutil

import pytest

from rvcalib.cli import main
from rvrig.dataset import read_dataset
from rvcalib.simulate import simulate_dataset

DESIGN81 = {"z_sun": 18, "z_planet": 36}
RUNS = [{"run": "cw", "load_Nm": 15.0, "direction": 1}, {"run": "ccw", "load_Nm": 15.0, "direction": -1}]


@pytest.fixture(scope="module")
def ratio81(tmp_path_factory):
    root = tmp_path_factory.mktemp("r81")
    ap = simulate_dataset(root / "ds", RUNS, {"errors": {"pin_circle_diameter": 8.0}}, design=DESIGN81,
                          noise_arcsec=0.2, input_noise_arcsec=1.5, samples_per_rev=60, start_deg=0.21, seed=81)
    return root, json.loads(ap.read_text())


def test_ratio81_dataset_without_its_design_is_refused(ratio81, tmp_path, capsys):
    root, _ = ratio81
    bare = tmp_path / "bare"
    bare.mkdir()
    for f in ("runs.csv", "samples.csv"):
        shutil.copy(root / "ds" / f, bare / f)
    with pytest.raises(ValueError, match="ratio does not match the default"):
        read_dataset(bare)
    assert main([str(bare), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "ratio does not match the default" in err and "--reducer" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()
    # naming the reducer on the command line reads it (the design object or a whole case JSON)
    (tmp_path / "case.json").write_text(json.dumps({"design": DESIGN81}))
    assert read_dataset(bare, design=tmp_path / "case.json").ratio == pytest.approx(81.0)


@pytest.mark.parametrize("design, match", [({"z_sun": 14}, "is not an integer"), ({"z_sun": "x"}, "z_sun"),
                                           ([1, 2], "JSON object")])
def test_bad_reducer_files_are_named(tmp_path, design, match):
    f = tmp_path / "design.json"
    f.write_text(json.dumps(design))
    simulate_dataset(tmp_path / "ds", RUNS[:1], {}, samples_per_rev=60, seed=1)
    with pytest.raises(ValueError, match=match):
        read_dataset(tmp_path / "ds", design=f)


def test_a_repeated_key_in_design_json_is_refused(tmp_path):
    simulate_dataset(tmp_path / "ds", RUNS[:1], {}, samples_per_rev=60, seed=1)
    (tmp_path / "ds" / "design.json").write_text('{"z_sun": 18, "z_sun": 12}')
    with pytest.raises(ValueError, match="z_sun.*twice"):
        read_dataset(tmp_path / "ds")
