"""rvrig.average: a dense dataset averaged down to the readings the reducer model needs, as rv-calibrate fits it."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from rvcad.params import Design
from rvcalib.simulate import simulate_dataset, standard_runs
from rig_records import R81, rig_file
from rvcalib.library import build_library
from rvrig.average import averaged, filtered_model_orders, fitted_density, model_samples_per_rev
from rvrig.dataset import read_dataset
from rvrig.rigimport import import_rig


def _te(output_deg: np.ndarray, high: float = 2.0) -> np.ndarray:
    """A constant, order 3 (inside every flat band here) and order 150 (above it), arcsec."""
    th = np.radians(output_deg)
    return 7.0 + 5.0 * np.cos(3.0 * th + 0.2) + high * np.cos(150.0 * th)


@pytest.fixture(scope="module")
def dense(tmp_path_factory):
    """Two runs at 1440 readings per revolution, off the grid, their TE replaced by :func:`_te`."""
    out = tmp_path_factory.mktemp("avg") / "ds"
    simulate_dataset(out, standard_runs((10.0,), (1, -1)), {}, noise_arcsec=0.0, input_noise_arcsec=0.0,
                     samples_per_rev=1440, start_deg=0.37, seed=1)
    ds = read_dataset(out)
    runs = [dataclasses.replace(r, output_deg=r.input_deg / r.ratio + _te(r.input_deg / r.ratio) / 3600.0)
            for r in ds.runs]
    return dataclasses.replace(ds, runs=runs)


def test_the_density_holds_the_pin_orders_and_the_input_order_in_the_flat_band():
    assert model_samples_per_rev(Design()) == 305                      # ratio 121: 0.8 * 305 / 2 >= 122
    assert model_samples_per_rev(Design.from_dict({"z_sun": 18, "z_planet": 36})) == 205   # ratio 81: >= 82
    assert model_samples_per_rev(SimpleNamespace(z_pins=60, ratio=81.0)) == 300    # 2 Zp = 120 sets it


def test_averaging_keeps_the_band_and_removes_what_is_above_it(dense):
    got, notes = averaged(dense, 205)
    for run, before in zip(got.runs, dense.runs):
        assert run.n / run.revolutions == pytest.approx(205.0, abs=1.0)
        assert run.load_Nm == before.load_Nm and run.direction == before.direction
        # the TE the readings give (output - input / N) is the band's part; order 150 is gone
        np.testing.assert_allclose(run.te_arcsec, _te(run.output_deg, high=0.0), atol=0.02)
    assert len(notes) == 1 and "from 1440 to 205 per output revolution (flat to order 82)" in notes[0]
    # None: the model's density (the default design, ratio 121: 305), what rv-calibrate fits by default
    assert fitted_density(dense.runs[0], None) == 305.0 and fitted_density(dense.runs[0], 205) == 205.0
    assert averaged(dense, None)[1] == averaged(dense, 305)[1] != notes


def test_sparser_runs_and_zero_keep_every_reading(dense):
    for k in (0, 2000):
        got, notes = averaged(dense, k)
        assert notes == [] and all(a is b for a, b in zip(got.runs, dense.runs))
    with pytest.raises(ValueError, match=r"samples_per_rev -1 must be 0 \(every reading\) or positive"):
        averaged(dense, -1)


def test_model_orders_an_import_took_out_are_noted_for_the_loop(tmp_path):
    """Imported at 180 per revolution the pass band ends at order 72: of a ratio-81 reducer's orders 40, 80 and 82
    the last two are out of the record but fold back in the model's point predictions, and the library's notes say
    so; at 360 (pass band to 144) and unfiltered, nothing is noted."""
    f = rig_file(tmp_path / "r.csv", per_rev=720)
    notes = {}
    for k in (180, 360, 0):
        import_rig([f], tmp_path / f"ds{k}", design=R81, load_Nm=0.0, samples_per_rev=k)
        notes[k] = [n for n in build_library(read_dataset(tmp_path / f"ds{k}"), 10).notes if "fold back" in n]
    design = read_dataset(tmp_path / "ds180").design
    assert filtered_model_orders(tmp_path / "ds180", design) == ([80.0, 82.0], pytest.approx(72.0))
    assert len(notes[180]) == 1 and "order(s) 80, 82 fold back" in notes[180][0] and "at least 205" in notes[180][0]
    assert notes[360] == [] and notes[0] == []
    assert filtered_model_orders(tmp_path, design) == ([], None)            # no import.json
