"""Orders over the whole band: a line locked to the order and a line at a fixed frequency, told apart by
two speeds, and at one speed by the orders the reducer has (ratio 81, 40 pins, 39 lobes, two cranks)."""
from __future__ import annotations

import numpy as np
import pytest

from rig_records import cos_orders, write_dataset
from rvrig.dataset import read_dataset
from rvrig.spectrum import find_lines, order_spectrum, reducer_orders, separate
from rvcad.params import Design

FIXED_HZ = 150.0


def te(seed: int, fixed_hz: float = FIXED_HZ):
    """Order 1 (20 arcsec), order 39 (4 arcsec, locked to the output angle), a 3 arcsec line at a fixed
    frequency, and 0.1 arcsec of white noise."""
    locked = cos_orders({1: (20.0, 10.0), 39: (4.0, 30.0)})
    rng = np.random.default_rng(seed)

    def f(th, t):
        return locked(th, t) + 3.0 * np.cos(2 * np.pi * fixed_hz * t + 1.0) + rng.normal(0.0, 0.1, th.size)
    return f


def runs(speeds: dict[str, float]) -> list[dict]:
    """Forward and backward runs at each speed (seconds per output revolution)."""
    out = []
    for i, (name, sec) in enumerate(speeds.items()):
        for d in (1, -1):
            out.append({"run": f"{name}_{'fw' if d > 0 else 'bw'}", "load_Nm": 0.0, "direction": d,
                        "seconds_per_rev": sec, "te": te(10 * i + (d > 0))})
    return out


def test_the_order_spectrum_gives_amplitude_and_phase_up_to_the_nyquist_order(tmp_path):
    ds = read_dataset(write_dataset(tmp_path / "ds", runs({"a": 1.0})))
    for run in ds.runs:
        s = order_spectrum(run)
        assert s.nyquist_order == 360.0 and s.revolutions == 1 and s.rev_hz == pytest.approx(1.0, rel=2e-3)
        a39, p39 = s.at(39)
        assert a39 == pytest.approx(4.0, abs=0.03) and p39 == pytest.approx(30.0, abs=0.5)
        assert s.at(150)[0] == pytest.approx(3.0, abs=0.03)
        lines = {round(ln["order"]): ln for ln in find_lines(s)}
        assert set(lines) == {1, 39, 150}
        assert lines[150]["frequency_Hz"] == pytest.approx(FIXED_HZ, rel=2e-3)


def test_two_speeds_separate_the_order_locked_line_from_the_fixed_frequency_line(tmp_path):
    ds = read_dataset(write_dataset(tmp_path / "ds", runs({"fast": 1.0, "slow": 1.6})))
    out = separate(ds)
    assert out["method"] == "speeds"
    locked = {round(g["order"]) for g in out["order_locked"]}
    assert locked == {39}
    assert len(out["fixed_frequency"]) == 1
    f = out["fixed_frequency"][0]
    assert f["frequency_Hz"] == pytest.approx(FIXED_HZ, abs=1.0) and len(f["runs"]) == 4
    # order 1 moves by less than the resolution between the speeds: not claimed either way
    assert [round(g["order"]) for g in out["ambiguous"]] == [1] and out["ambiguous"][0]["why"] == "not separable"


def test_one_speed_reports_a_line_at_no_order_of_the_reducer_as_fixed_frequency(tmp_path):
    ds = read_dataset(write_dataset(tmp_path / "ds", runs({"a": 1.0})))
    out = separate(ds)
    assert out["method"] == "design orders"
    assert {round(g["order"]) for g in out["order_locked"]} == {1, 39}
    assert [g["label"] for g in sorted(out["order_locked"], key=lambda g: g["order"])] == ["output x1", "lobe 39"]
    assert [round(g["order"]) for g in out["fixed_frequency"]] == [150]
    assert out["fixed_frequency"][0]["frequency_Hz"] == pytest.approx(FIXED_HZ, rel=2e-3)
    assert "not claimed for the reducer" in out["statements"][0]


def test_the_reducer_orders_come_from_the_design():
    d = Design(z_sun=18, z_planet=36)                     # ratio 81, 40 pins, 39 lobes, two cranks
    orders = reducer_orders(d, 400)
    assert orders[39] == "lobe 39" and orders[40] == "pin 40" and orders[81] == "input 81" and orders[80] == "2 x pin 40"
    assert orders[78] == "2 x lobe 39" and orders[41] == "pin 40 + 1" and orders[37] == "lobe 39 - 2 (crank count)"
    assert orders[2] == "output x2" and 150 not in orders and max(orders) <= 400
    # the sidebands follow the design's crank count (two: +-2 and +-4)
    assert orders[44] == "pin 40 + 4 (2 x crank count)" and 46 not in orders
