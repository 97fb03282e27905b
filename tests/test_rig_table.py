"""The per-test table and the measured datasheet against a closed form.

The reducer: a clearance b (arcsec) plus a linear compliance C (arcsec per N m of the mid-curve) and a
periodic TE whose order 78 grows with load; each test carries its own rig zero c_t. A rotating test at load
T in direction d then reads ``c_t - d (b/2 + C T) + p(theta)``, so B - F = b + 2 C T, the secant and b/a
rigidity are 60 / C N m/arcmin, the light-load play is b, and the lost motion is b + 2 C (0.03 T_rated).
"""
from __future__ import annotations

import numpy as np
import pytest

from rig_records import cos_orders, write_dataset
from rvrig.dataset import read_dataset
from rvrig.rigtable import load_changes, measured_datasheet, plot_test_means, test_table

B, C = 40.0, 0.1                       # arcsec, arcsec per N m
RIGIDITY = 60.0 / C                    # N m/arcmin


def te_of(load: float, direction: int, zero: float):
    periodic = cos_orders({1: (20.0, 30.0), 39: (3.0, -60.0), 78: (1.0 + 0.002 * load, 45.0)})
    return lambda th, t: zero - direction * (0.5 * B + C * load) + periodic(th, t)


def dataset(tmp_path, loads, zeros=None):
    zeros = zeros or {ld: 7.0 * i - 11.0 for i, ld in enumerate(loads)}
    runs = [{"run": f"T{ld:g}_{'fw' if d > 0 else 'bw'}", "load_Nm": ld, "direction": d, "speed_rpm": 1800.0,
             "te": te_of(ld, d, zeros[ld])} for ld in loads for d in (1, -1)]
    return read_dataset(write_dataset(tmp_path / "ds", runs))


def test_the_table_gives_the_means_differences_and_orders_of_each_test(tmp_path):
    loads = [0.0, 100.0, 400.0, 1000.0]
    ds = dataset(tmp_path, loads)
    tab = test_table(ds, n_orders=3)
    assert list(tab["load_Nm"]) == loads and list(tab["test"]) == ["0Nm_1800rpm", "100Nm_1800rpm", "400Nm_1800rpm",
                                                                   "1000Nm_1800rpm"]
    zero = np.array([7.0 * i - 11.0 for i in range(4)])
    L = np.array(loads)
    np.testing.assert_allclose(tab["mean_fw_arcsec"], zero - 0.5 * B - C * L, atol=1e-6)
    np.testing.assert_allclose(tab["mean_bw_arcsec"], zero + 0.5 * B + C * L, atol=1e-6)
    np.testing.assert_allclose(tab["bw_minus_fw_arcsec"], B + 2.0 * C * L, atol=1e-6)
    assert [o["order"] for o in tab.attrs["main_orders"]] == [1, 39, 78]
    assert tab.attrs["main_orders"][1]["label"] == "lobe 39"
    for tag in ("fw", "bw"):
        np.testing.assert_allclose(tab[f"order78_amp_{tag}_arcsec"], 1.0 + 0.002 * L, atol=1e-6)
        np.testing.assert_allclose(tab[f"order78_phase_{tag}_deg"], 45.0, atol=1e-5)
        np.testing.assert_allclose(tab[f"order39_phase_{tag}_deg"], -60.0, atol=1e-5)
        np.testing.assert_allclose(tab[f"order1_amp_{tag}_arcsec"], 20.0, atol=1e-6)
    ch = load_changes(tab).set_index("quantity")
    assert ch.loc["order78_amp_fw_arcsec", "change_per_kNm"] == pytest.approx(2.0, abs=1e-6)
    assert ch.loc["bw_minus_fw_arcsec", "change"] == pytest.approx(2.0 * C * 1000.0, abs=1e-6)
    assert ch.loc["mean_fw_arcsec", "note"] == "includes the tests' rig zeros"
    png = plot_test_means(ds, tmp_path / "means.png", table=tab)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_datasheet_against_the_closed_form(tmp_path):
    ds = dataset(tmp_path, [0.0, 100.0, 400.0, 1000.0])
    sheet = measured_datasheet(ds, rated_Nm=800.0)
    assert sheet["secant_rigidity_Nm_per_arcmin"] == pytest.approx(RIGIDITY, rel=1e-6)
    assert all(s["rigidity_Nm_per_arcmin"] == pytest.approx(RIGIDITY, rel=1e-6) for s in sheet["secants"])
    assert sheet["light_load_play_arcmin"] == pytest.approx(B / 60.0, rel=1e-6)
    assert sheet["lost_motion_arcmin"] == pytest.approx((B + 2.0 * C * 24.0) / 60.0, rel=1e-6)
    assert sheet["lost_motion_from"] == "B - F at 24 N m, interpolated linearly between 0 and 100 N m"
    assert sheet["torsional_rigidity_b_over_a_Nm_per_arcmin"] == pytest.approx(RIGIDITY, rel=1e-6)
    assert sheet["speed_rpm"] == 1800.0 and sheet["rated_torque_Nm"] == 800.0


def test_the_datasheet_says_what_the_loads_do_not_allow(tmp_path):
    # two loads: the rigidity is their secant, not b/a
    sheet = measured_datasheet(dataset(tmp_path / "a", [0.0, 1000.0]), rated_Nm=800.0)
    assert sheet["secant_rigidity_Nm_per_arcmin"] == pytest.approx(RIGIDITY, rel=1e-6)
    assert sheet["torsional_rigidity_b_over_a_Nm_per_arcmin"] is None
    assert any("lie on one linear piece" in s and "a secant, not b/a" in s for s in sheet["statements"])
    assert any("interpolated linearly between 0 and 1000 N m" in s for s in sheet["statements"])
    # no rated torque: never a default one
    sheet = measured_datasheet(dataset(tmp_path / "b", [0.0, 1000.0]), rated_Nm=None)
    assert sheet["lost_motion_arcmin"] is None and sheet["rated_torque_Nm"] is None
    assert any(s.startswith("rated torque not given (--rated-Nm)") for s in sheet["statements"])
    # no load near 3 % of rated nor zero: lost motion and play are missing, not extrapolated
    sheet = measured_datasheet(dataset(tmp_path / "c", [100.0, 400.0, 1000.0]), rated_Nm=800.0)
    assert sheet["lost_motion_arcmin"] is None and sheet["light_load_play_arcmin"] is None
    assert any("lost motion missing: B - F at 24 N m (3 % of 800 N m) is outside the loads measured" in s
               for s in sheet["statements"])
    assert any("light-load play missing: no test at zero load (lowest 100 N m)" in s for s in sheet["statements"])
    # one load: no rigidity
    sheet = measured_datasheet(dataset(tmp_path / "d", [0.0]), rated_Nm=800.0)
    assert sheet["secant_rigidity_Nm_per_arcmin"] is None
    assert any("no rigidity (it needs two loads)" in s for s in sheet["statements"])
    with pytest.raises(ValueError, match="no test at speed_rpm 900"):
        measured_datasheet(dataset(tmp_path / "e", [0.0, 10.0]), rated_Nm=800.0, speed_rpm=900.0)


def test_runs_of_one_direction_give_no_difference(tmp_path):
    runs = [{"run": "a", "load_Nm": 0.0, "direction": 1, "te": te_of(0.0, 1, 0.0)},
            {"run": "b", "load_Nm": 50.0, "direction": -1, "te": te_of(50.0, -1, 0.0)}]
    ds = read_dataset(write_dataset(tmp_path / "ds", runs))
    tab = test_table(ds)
    assert np.isnan(tab["bw_minus_fw_arcsec"]).all()
    sheet = measured_datasheet(ds, rated_Nm=100.0, table=tab)
    assert sheet["loads_Nm"] == [] and "no test has both directions at one load" in sheet["statements"][-1]
