"""rvrig.average: a dense dataset averaged down to the readings the reducer model needs, as rv-calibrate fits it."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from rvcad.params import Design
from rvcalib.simulate import simulate_dataset, standard_runs
from rvrig.average import averaged, model_samples_per_rev
from rvrig.dataset import read_dataset


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


def test_sparser_runs_and_zero_keep_every_reading(dense):
    for k in (0, 2000):
        got, notes = averaged(dense, k)
        assert notes == [] and all(a is b for a, b in zip(got.runs, dense.runs))
    with pytest.raises(ValueError, match=r"samples_per_rev -1 must be 0 \(every reading\) or positive"):
        averaged(dense, -1)
