"""rvcalib on a reducer other than the paper's: a ratio-81 RV (Z1 18, Z2 36, 40 pins, 39 lobes).

The dataset is made with other settings than the loop uses: 333 readings per output revolution
from input angle 0.21 deg (off every screening grid), its own noise (output encoder 0.2 arcsec,
input encoder 1.5 arcsec), two runs at 15 N m in both directions. The folder carries the reducer's
``design.json``; the truth (an undeclared pin-circle diameter error of 8 um) stays outside it.
"""
from __future__ import annotations

import json
import shutil

import pytest

from rvcalib.cli import main
from rvcalib.dataset import read_dataset
from rvcalib.simulate import simulate_dataset

pytestmark = pytest.mark.usefixtures("calib_forward_cache")  # solves shared by the session

DESIGN81 = {"z_sun": 18, "z_planet": 36}
RUNS = [{"run": "cw", "load_Nm": 15.0, "direction": 1}, {"run": "ccw", "load_Nm": 15.0, "direction": -1}]


@pytest.fixture(scope="module")
def ratio81(tmp_path_factory):
    root = tmp_path_factory.mktemp("r81")
    ap = simulate_dataset(root / "ds", RUNS, {"errors": {"pin_circle_diameter": 8.0}}, design=DESIGN81,
                          noise_arcsec=0.2, input_noise_arcsec=1.5, samples_per_rev=333, start_deg=0.21, seed=81)
    return root, json.loads(ap.read_text())


def test_ratio81_dataset_names_the_pin_circle_error(ratio81, capsys):
    root, ans = ratio81
    assert (root / "ds" / "design.json").is_file() and ans["ratio"] == pytest.approx(81.0)
    ds = read_dataset(root / "ds")
    assert ds.ratio == pytest.approx(81.0) and ds.design_source.startswith("design.json")
    assert main([str(root / "ds"), "--out", str(root / "out"), "--json", "--workers", "1", "--rated-Nm", "120"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["ratio"] == pytest.approx(81.0) and d["reducer"]["z_sun"] == 18
    assert [e["name"] for e in d["effects"]] == ["pin_circle_diameter"]
    assert d["effects"][0]["value"] == pytest.approx(8.0, rel=0.10)
    # its physical twin on this design: the disc's shift modification, -v/2000 mm (rvcalib.causes)
    (q,) = d["effects"][0]["equivalents"]
    assert q["parameter"] == "design.profile_shift_mm" and q["value"] == pytest.approx(-d["effects"][0]["value"] / 2000)
    # the datasheet of the ratio-81 reducer as declared and as calibrated (the larger pin circle opens a play)
    dsh = d["datasheet"]
    assert dsh["model"]["rated_torque_Nm"] == dsh["calibrated"]["rated_torque_Nm"] == 120.0     # --rated-Nm
    assert dsh["calibrated"]["backlash_arcmin"] > dsh["model"]["backlash_arcmin"] + 0.1
    assert d["calibrated_case"]["design"]["z_sun"] == 18 and d["calibrated_case"]["errors"]["pin_circle_diameter"]
    assert d["unexplained"] == []
    assert d["rms_before_arcsec"] > 5 * d["rms_after_arcsec"]
    assert d["rms_after_arcsec"] == pytest.approx(ans["noise_te_arcsec"], rel=0.2)
    md = (root / "out" / "report.md").read_text()
    assert "ratio 81" in md


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
