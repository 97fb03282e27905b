"""The rig's zero per test: which runs of a dataset share one homing (``MeasuredDataset.tests``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rvrig.dataset import read_dataset
from rvrig.orders import period_deg
from rvcad.params import Design

PERIOD = period_deg(Design())
RATIO = Design().ratio


def dataset(folder: Path, runs: dict) -> Path:
    """A dataset of one-revolution runs with a flat TE: ``runs`` = run id -> runs.csv row (without ``run``)."""
    folder.mkdir(parents=True, exist_ok=True)
    rows, samples = [], []
    for rid, row in runs.items():
        th = row["direction"] * np.arange(120) * PERIOD / 120
        samples.append(pd.DataFrame({"run": rid, "input_deg": th, "output_deg": th / RATIO}))
        rows.append({"run": rid, **row})
    pd.DataFrame(rows).to_csv(folder / "runs.csv", index=False)
    pd.concat(samples).to_csv(folder / "samples.csv", index=False, float_format="%.10f")
    return folder


def test_by_default_the_runs_of_one_load_speed_and_temperature_form_one_test(tmp_path):
    ds = read_dataset(dataset(tmp_path / "ds", {
        "a": {"load_Nm": 0.0, "direction": 1, "speed_rpm": 1800.0, "temperature_C": 25.0},
        "b": {"load_Nm": 0.0, "direction": -1, "speed_rpm": 1800.0, "temperature_C": 25.0},
        "c": {"load_Nm": 50.0, "direction": 1, "speed_rpm": 1800.0, "temperature_C": 25.0},
        "d": {"load_Nm": 50.0, "direction": -1, "speed_rpm": 900.0, "temperature_C": 25.0},
        "e": {"load_Nm": 0.0, "direction": 1, "speed_rpm": 1800.0, "temperature_C": 25.0}}))
    assert ds.tests.ids == ("0Nm_1800rpm_25C", "50Nm_1800rpm_25C", "50Nm_900rpm_25C")
    assert ds.tests.runs("0Nm_1800rpm_25C") == ("a", "b", "e")
    assert [r.test for r in ds.runs] == ["0Nm_1800rpm_25C"] * 2 + ["50Nm_1800rpm_25C", "50Nm_900rpm_25C",
                                                                    "0Nm_1800rpm_25C"]
    assert list(ds.tests.index(["e", "d", "c"])) == [0, 2, 1]
    assert "load, speed, temperature" in ds.tests.source
    # without speed and temperature columns: by load alone
    ds = read_dataset(dataset(tmp_path / "ds2", {"a": {"load_Nm": 0.0, "direction": 1},
                                                  "b": {"load_Nm": 10.0, "direction": -1}}))
    assert ds.tests.ids == ("0Nm", "10Nm")


def test_an_explicit_test_column_groups_the_runs_as_written(tmp_path):
    ds = read_dataset(dataset(tmp_path / "ds", {
        "a": {"load_Nm": 0.0, "direction": 1, "test": "7"},
        "b": {"load_Nm": 0.0, "direction": -1, "test": "8"},
        "c": {"load_Nm": 50.0, "direction": 1, "test": "7"}}))
    assert ds.tests.ids == ("7", "8") and ds.tests.runs("7") == ("a", "c")
    assert ds.tests.source == "column 'test' of runs.csv"
    with pytest.raises(KeyError, match="no test '9'"):
        ds.tests.runs("9")


def test_an_empty_test_cell_is_named(tmp_path):
    folder = dataset(tmp_path / "ds", {"a": {"load_Nm": 0.0, "direction": 1, "test": "h1"},
                                       "b": {"load_Nm": 0.0, "direction": -1, "test": ""}})
    with pytest.raises(ValueError, match=r"runs.csv: column 'test' row 3 \(run b\) is empty"):
        read_dataset(folder)
