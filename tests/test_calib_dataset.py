"""rvcalib: reading and validating measured datasets; forward-model helpers (fast, no rvdyn loop)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rvcalib.cli import main
from rvcad.params import Design
from rvrig.dataset import noise_estimate, read_dataset
from rvrig.orders import base_orders, period_deg

RATIO = Design().ratio
PERIOD_DEG = period_deg(Design())


def write(folder: Path, runs: pd.DataFrame, samples: pd.DataFrame) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    runs.to_csv(folder / "runs.csv", index=False)
    samples.to_csv(folder / "samples.csv", index=False, float_format="%.10f")
    return folder


def record(run: str, direction: int = 1, n: int = 120, revs: float = 1.0, te_arcsec=None, seed: int = 0,
           noise: float = 0.1) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    m = int(round(n * revs))
    th = direction * np.arange(m) * PERIOD_DEG / n
    te = np.zeros(m) if te_arcsec is None else np.asarray(te_arcsec(np.arange(m)), dtype=float)
    out = th / RATIO + (te + rng.normal(0, noise, m)) / 3600.0
    return pd.DataFrame({"run": run, "input_deg": th, "output_deg": out})


def good(tmp_path: Path, **runs_cols) -> tuple[pd.DataFrame, pd.DataFrame]:
    runs = pd.DataFrame({"run": ["a", "b"], "load_Nm": [10.0, 20.0], "direction": [1, -1], **runs_cols})
    samples = pd.concat([record("a", 1), record("b", -1, seed=1)], ignore_index=True)
    return runs, samples


def test_reads_a_valid_dataset(tmp_path):
    runs, samples = good(tmp_path, pin_circle_diameter=[14.0, 0.0])
    ds = read_dataset(write(tmp_path / "ds", runs, samples))
    assert [r.run for r in ds.runs] == ["a", "b"]
    assert ds.runs[0].declared == {"pin_circle_diameter": 14.0}
    assert ds.runs[1].declared == {}
    assert ds.runs[1].direction == -1
    assert abs(ds.runs[0].revolutions - 1.0) < 1e-9
    assert abs(float(np.std(ds.runs[0].te_arcsec)) - 0.1) < 0.03
    assert abs(ds.runs[0].noise_arcsec - 0.1) < 0.03


@pytest.mark.parametrize("drop, file, word", [
    ("load_Nm", "runs", "load_Nm"), ("direction", "runs", "direction"), ("output_deg", "samples", "output_deg"),
])
def test_missing_columns_are_named(tmp_path, drop, file, word):
    runs, samples = good(tmp_path)
    if file == "runs":
        runs = runs.drop(columns=[drop])
    else:
        samples = samples.drop(columns=[drop])
    with pytest.raises(ValueError, match=word):
        read_dataset(write(tmp_path / "ds", runs, samples))


def test_unknown_column_and_bad_cells_are_named(tmp_path):
    runs, samples = good(tmp_path)
    runs["pin_pich"] = 0.0
    with pytest.raises(ValueError, match="pin_pich"):
        read_dataset(write(tmp_path / "a", runs, samples))
    runs, samples = good(tmp_path)
    samples.loc[5, "output_deg"] = np.nan
    with pytest.raises(ValueError, match=r"output_deg.*row 7.*run a"):
        read_dataset(write(tmp_path / "b", runs, samples))
    runs, samples = good(tmp_path)
    runs.loc[1, "direction"] = 0
    with pytest.raises(ValueError, match="direction.*run b"):
        read_dataset(write(tmp_path / "c", runs, samples))
    runs, samples = good(tmp_path)
    samples = samples[samples.run == "a"]
    with pytest.raises(ValueError, match="run b.*no samples"):
        read_dataset(write(tmp_path / "d", runs, samples))
    with pytest.raises(ValueError, match="does not exist"):
        read_dataset(tmp_path / "nowhere")


def test_non_monotonic_and_wrong_direction(tmp_path):
    runs, samples = good(tmp_path)
    i = samples.index[samples.run == "a"][10]
    samples.loc[[i, i + 1], "input_deg"] = samples.loc[[i + 1, i], "input_deg"].to_numpy()
    with pytest.raises(ValueError, match="run a.*not monotonic"):
        read_dataset(write(tmp_path / "a", runs, samples))
    runs, samples = good(tmp_path)
    runs.loc[0, "direction"] = -1
    with pytest.raises(ValueError, match="run a.*direction -1"):
        read_dataset(write(tmp_path / "b", runs, samples))


def test_short_record(tmp_path):
    runs, _ = good(tmp_path)
    samples = pd.concat([record("a", 1, revs=0.6), record("b", -1)], ignore_index=True)
    with pytest.raises(ValueError, match=r"run a covers 0\.6 output revolutions"):
        read_dataset(write(tmp_path / "ds", runs, samples))


def test_radians_are_detected(tmp_path):
    runs, samples = good(tmp_path)
    s = samples.copy()
    s["input_deg"] = np.radians(s["input_deg"])
    s["output_deg"] = np.radians(s["output_deg"])
    with pytest.raises(ValueError, match="look like radians"):
        read_dataset(write(tmp_path / "a", runs, s))
    s = samples.copy()
    s["output_deg"] = np.radians(s["output_deg"])
    with pytest.raises(ValueError, match="'output_deg' looks like radians"):
        read_dataset(write(tmp_path / "b", runs, s))
    s = samples.copy()
    s["input_deg"] = np.radians(s["input_deg"])
    with pytest.raises(ValueError, match="'input_deg' looks like radians"):
        read_dataset(write(tmp_path / "c", runs, s))


@pytest.mark.parametrize("column, values, message", [
    ("pin_circle_diameter", [0.014, 0.0], "pin_circle_diameter.*look like mm"),
    ("pin_pitch", [36.0, 0.0], "pin_pitch.*arcsec"),
    ("temperature_C", [293.0, 293.0], "temperature_C.*kelvin"),
    ("cam_eccentricity", [2000.0, 0.0], "cam_eccentricity.*run a"),
])
def test_error_units_by_magnitude(tmp_path, column, values, message):
    runs, samples = good(tmp_path, **{column: values})
    with pytest.raises(ValueError, match=message):
        read_dataset(write(tmp_path / "a", runs, samples))


def test_duplicates_and_transient_are_dropped_and_reported(tmp_path):
    runs = pd.DataFrame({"run": ["a"], "load_Nm": [10.0], "direction": [1]})
    n = 120
    te = lambda k: 2.0 * np.sin(2 * np.pi * 40 * k / n) + 20.0 * np.exp(-k / 4.0)  # noqa: E731
    s = record("a", 1, n=n, revs=1.2, te_arcsec=te)
    s = pd.concat([s.iloc[:50], s.iloc[[49, 49]], s.iloc[50:]], ignore_index=True)
    ds = read_dataset(write(tmp_path / "ds", runs, s))
    r = ds.runs[0]
    assert r.dropped["duplicates"] == 2
    assert 10 <= r.dropped["transient"] <= 24
    assert any("start-up transient" in x for x in ds.notes)
    assert any("duplicated" in x for x in ds.notes)
    assert r.revolutions >= 1.0
    resid = r.te_arcsec - 2.0 * np.sin(2 * np.pi * 40 * np.round(r.input_deg / (PERIOD_DEG / n)) / n)
    assert np.abs(resid).max() < 1.0


def test_cli_bad_input_exit_2(tmp_path, capsys):
    runs, samples = good(tmp_path)
    runs = runs.drop(columns=["load_Nm"])
    d = write(tmp_path / "ds", runs, samples)
    assert main([str(d), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "runs.csv" in err and "load_Nm" in err
    assert main([str(tmp_path / "missing"), "--out", str(tmp_path / "out")]) == 2
    capsys.readouterr()
    ok = write(tmp_path / "ok", *good(tmp_path))
    for opt, bad in (("--max-effects", "0"), ("--workers", "0"), ("--rated-Nm", "0"), ("--rated-Nm", "nan")):
        assert main([str(ok), "--out", str(tmp_path / "out"), opt, bad]) == 2
        err = capsys.readouterr().err.strip()
        assert opt.lstrip("-").replace("-", "_") in err.replace("-", "_") and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_noise_estimate():
    rng = np.random.default_rng(3)
    x = np.sin(np.linspace(0, 6, 2000)) + rng.normal(0, 0.2, 2000)
    assert abs(noise_estimate(x) - 0.2) < 0.02


@pytest.mark.parametrize("design, ratio", [({}, 121), ({"z_sun": 18, "z_planet": 36}, 81),
                                           ({"z_pins": 30, "z_disc": 29}, 91)])
def test_ratio_and_base_orders_come_from_the_design(design, ratio):
    d = Design.from_dict(design)
    assert round(d.ratio, 9) == ratio and period_deg(d) == pytest.approx(ratio * 360.0)
    assert base_orders(d) == {"output": 1, "lobe": d.z_disc, "pin": d.z_pins, "sun": ratio - 1, "input": ratio,
                              "stage I mesh": d.z_sun * (ratio - 1)}
