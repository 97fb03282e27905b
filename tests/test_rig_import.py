"""rv-calibrate import: rig files (output angle and TE per direction, sampled in time) into a dataset.

Every record here is synthetic, written by the tests in the shared rig layout: TE = known orders of the
output angle plus a constant per direction, sampled at a fixed rate at constant speed.
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from rig_records import ARCSEC, HEADER, R81, rig_file, te_arcsec
from rvcalib.cli import main
from rvrig.dataset import read_dataset
from rvrig.rigfilter import antialias_filter, decimate, default_samples_per_rev
from rvrig.rigimport import import_rig, parse_conditions, read_rig_file


def test_the_shared_layout_becomes_a_dataset_with_conditions_from_the_file_name(tmp_path, capsys):
    f = rig_file(tmp_path / "1800.0rpm0.0Nm25.0deg.csv")
    ds_dir = tmp_path / "ds"
    assert main(["import", str(f), "--out", str(ds_dir), "--ratio", "81", "--samples-per-rev", "360"]) == 0
    out = capsys.readouterr().out
    assert "load_Nm, speed_rpm, temperature_C read from the file name" in out
    runs = pd.read_csv(ds_dir / "runs.csv", dtype={"test": str})
    assert list(runs["run"]) == ["1800.0rpm0.0Nm25.0deg_fw", "1800.0rpm0.0Nm25.0deg_bw"]
    assert list(runs["direction"]) == [1, -1] and list(runs["load_Nm"]) == [0.0, 0.0]
    assert list(runs["speed_rpm"]) == [1800.0, 1800.0] and list(runs["temperature_C"]) == [25.0, 25.0]
    assert list(runs["test"]) == ["1800.0rpm0.0Nm25.0deg"] * 2
    ds = read_dataset(ds_dir, design=R81)
    assert ds.tests.ids == ("1800.0rpm0.0Nm25.0deg",)
    fw, bw = ds.runs
    # the backward run's positions run 360 -> 0, and input = 81 (output - TE) gives back the TE
    assert bw.output_deg[0] > 359.0 and bw.output_deg[-1] < 1.0 and np.all(np.diff(bw.output_deg) < 0)
    for run, c in ((fw, -20.0), (bw, 15.0)):
        assert abs(run.n - 360) <= 1
        np.testing.assert_allclose(run.te_arcsec, te_arcsec(run.output_deg, {1: 30.0, 39: 4.0}, c), atol=0.02)
        # 2000 readings per revolution at 4 kHz: 0.5 s per output revolution
        np.testing.assert_allclose(np.diff(run.time_s), 0.5 / 360, rtol=2e-3)


def test_gaps_are_reported_filled_or_split_and_nothing_is_written_inside(tmp_path):
    # one reading missing at 90 deg (filled before the low-pass), 40 missing after 180 deg (a split)
    f = rig_file(tmp_path / "gappy.csv", per_rev=2000, drop=(500,) + tuple(range(1000, 1040)))
    res = import_rig([f], tmp_path / "ds", ratio=81, load_Nm=100.0, samples_per_rev=180)
    gaps = res["files"][0]["runs"][0]["gaps"]
    assert [(g["kind"], g["missing"]) for g in gaps] == [("filled", 1), ("split", 40)]
    assert abs(gaps[0]["at_output_deg"] - 89.91) < 1e-6 and abs(gaps[1]["at_output_deg"] - 179.91) < 1e-6
    assert any("gap(s) of 41 sample spacings (40 readings missing) at output 179.91 deg" in n
               and "split" in n for n in res["notes"])
    ds = read_dataset(tmp_path / "ds", design=R81)
    fw = ds.runs[0]
    inside = (fw.output_deg > 179.92) & (fw.output_deg < 187.28)
    assert not inside.any()
    # the times count the readings missing: 4 kHz, 2000 readings per revolution
    np.testing.assert_allclose(fw.time_s, (fw.output_deg - fw.output_deg[0]) / 360.0 * 0.5, atol=1e-9)
    # the record's ends are padded with its readings one revolution away, exact for a periodic TE; the gap's
    # edges by the odd reflection, which disturbs the readings within half a filter length of them
    half = 0.5 * res["files"][0]["runs"][0]["filter"]["taps"] * 0.18
    err = np.abs(fw.te_arcsec - te_arcsec(fw.output_deg, {1: 30.0, 39: 4.0}, -20.0))
    far = (fw.output_deg < 179.91 - half) | (fw.output_deg > 187.29 + half)
    assert err[far].max() < 0.005 and err.max() < 0.1


def test_a_record_longer_than_one_revolution_is_used_whole(tmp_path):
    f = rig_file(tmp_path / "long.csv", revs=1.5, wrap=True)
    import_rig([f], tmp_path / "ds", ratio=81, load_Nm=0.0, samples_per_rev=360)
    fw, bw = read_dataset(tmp_path / "ds", design=R81).runs
    assert abs(fw.revolutions - 1.5) < 0.01 and fw.output_deg[-1] > 539.0
    # the file's positions wrap at 360: unwrapped, the backward run goes 359.91 -> -179.91
    assert abs(bw.output_deg[0] - 359.91) < 1e-6 and bw.output_deg[-1] < -179.0 and abs(bw.revolutions - 1.5) < 0.01
    for run, c in ((fw, -20.0), (bw, 15.0)):
        np.testing.assert_allclose(run.te_arcsec, te_arcsec(run.output_deg, {1: 30.0, 39: 4.0}, c), atol=0.02)


def spectrum_amplitude(x: np.ndarray, k: int) -> float:
    """Amplitude of order k of a record of exactly one revolution, evenly sampled."""
    return float(2.0 * abs(np.fft.rfft(x)[k]) / x.size)


def test_averaging_down_does_not_fold_an_order_above_the_new_nyquist_back():
    n, k_new = 4000, 256                  # new Nyquist order 128: order 300 would alias to 300 - 256 = 44
    th = np.arange(n) * 360.0 / n
    from rvrig.rigimport import RigRecord

    te = te_arcsec(th, {5: 1.0, 300: 10.0}) * ARCSEC
    rec = RigRecord(direction=1, output_deg=th, te_deg=te, time_s=np.arange(n) / 4000.0, slot=np.arange(n),
                    time_source="sample rate 4000 Hz")
    arr, info = decimate(rec, k_new)
    assert info["filter"]["stop_band_from_order"] == 128.0
    # the grid spans the record: k_new readings over 360 - 360/n deg; resample onto one exact revolution
    x = np.interp(np.arange(k_new) * 360.0 / k_new, arr["output_deg"], arr["te_deg"]) / ARCSEC
    assert abs(spectrum_amplitude(x, 5) - 1.0) < 2e-3
    assert spectrum_amplitude(x, 44) < 2e-3
    # picking every n / k_new-th reading (no low-pass) folds it back at full size: the check can fail
    naive = te[:: n // 250][:250] / ARCSEC
    assert spectrum_amplitude(naive, 50) > 9.0


def test_the_filter_passes_the_band_flat_and_stops_above_the_new_nyquist():
    from scipy import signal

    taps, info = antialias_filter(10800.0, 1080)
    w, h = signal.freqz(taps, worN=np.array([0.0, 400.0, 432.0, 540.0, 700.0, 2000.0]), fs=10800.0)
    g = np.abs(h) ** 2                        # applied forward and backward
    assert np.all(np.abs(g[:3] - 1.0) < 2e-3)
    assert np.all(g[3:] < 1e-6)
    assert default_samples_per_rev(81, 40) == 1080 and default_samples_per_rev(121) == 1440


def test_file_names_give_conditions_and_options_override_them(tmp_path):
    assert parse_conditions("1800.0rpm1800.0Nm25.0deg.csv") == {"speed_rpm": 1800.0, "load_Nm": 1800.0,
                                                               "temperature_C": 25.0}
    assert parse_conditions("record.csv") == {}
    f = rig_file(tmp_path / "1000.0rpm500.0Nm40.0deg.csv", per_rev=400)
    res = import_rig([f], tmp_path / "ds", ratio=81, load_Nm=250.0, samples_per_rev=0)
    assert res["files"][0]["load_Nm"] == 250.0 and res["files"][0]["conditions_from"]["load_Nm"] == "option"
    assert res["files"][0]["temperature_C"] == 40.0
    # every reading kept with --samples-per-rev 0
    assert res["files"][0]["runs"][0]["samples"] == 400


def test_two_files_one_test_and_one_test_per_file(tmp_path):
    a = rig_file(tmp_path / "a.csv", per_rev=400)
    b = rig_file(tmp_path / "b.csv", per_rev=400, consts=(-60.0, 55.0))
    import_rig([a, b], tmp_path / "one", ratio=81, load_Nm=10.0, samples_per_rev=0, test="homing-1")
    assert read_dataset(tmp_path / "one", design=R81).tests.ids == ("homing-1",)
    import_rig([a, b], tmp_path / "two", ratio=81, load_Nm=10.0, samples_per_rev=0)
    ds = read_dataset(tmp_path / "two", design=R81)
    assert ds.tests.ids == ("a", "b") and ds.tests.runs("b") == ("b_fw", "b_bw")


@pytest.mark.parametrize("header, words", [
    (["Position_Fw", "TE_Fw", "Position_Bw", "TE_Bw"], ["Position_Fw", "Poisition_Output_Reducer_Fw"]),
    (HEADER[:2], ["columns found", "Transmission_Error_Bw"]),
    (HEADER + ["Torque"], ["unknown: ['Torque']"]),
])
def test_an_unknown_header_lists_the_columns_found_and_expected(tmp_path, header, words, capsys):
    f = tmp_path / "x.csv"
    pd.DataFrame({h: np.linspace(0.0, 360.0, 50) for h in header}).to_csv(f, index=False)
    assert main(["import", str(f), "--out", str(tmp_path / "ds"), "--ratio", "81", "--load-Nm", "0"]) == 2
    err = capsys.readouterr().err
    assert "x.csv" in err and all(w in err for w in words), err


def test_bad_inputs_are_named(tmp_path, capsys):
    f = rig_file(tmp_path / "record.csv", per_rev=400)
    with pytest.raises(ValueError, match="--load-Nm"):
        import_rig([f], tmp_path / "ds", ratio=81)
    with pytest.raises(ValueError, match="exactly one of --ratio N and --reducer"):
        import_rig([f], tmp_path / "ds", load_Nm=0.0)
    with pytest.raises(ValueError, match="--samples-per-rev 8"):
        import_rig([f], tmp_path / "ds", ratio=81, load_Nm=0.0, samples_per_rev=8)
    arcsec = tmp_path / "arcsec.csv"
    df = pd.read_csv(f)
    df["Transmission_Error_Fw"] *= 3600.0
    df.to_csv(arcsec, index=False)
    with pytest.raises(ValueError, match=r"arcsec.csv: column 'Transmission_Error_Fw' .* arcsec"):
        import_rig([arcsec], tmp_path / "ds", ratio=81, load_Nm=0.0)
    short = rig_file(tmp_path / "short.csv", per_rev=400, revs=0.5)
    with pytest.raises(ValueError, match=r"short.csv: column 'Poisition_Output_Reducer_Fw' covers 0.5"):
        import_rig([short], tmp_path / "ds", ratio=81, load_Nm=0.0)
    back = tmp_path / "back.csv"
    df = pd.read_csv(f)
    df.loc[100, "Poisition_Output_Reducer_Fw"] = df.loc[98, "Poisition_Output_Reducer_Fw"]
    df.to_csv(back, index=False)
    with pytest.raises(ValueError, match=r"back.csv: column 'Poisition_Output_Reducer_Fw' does not move up .* row 102"):
        import_rig([back], tmp_path / "ds", ratio=81, load_Nm=0.0)
    with pytest.raises(SystemExit) as exc:
        main(["import", str(f), "--out", str(tmp_path / "ds"), "--load-Nm", "0"])
    assert exc.value.code == 2 and "--ratio --reducer is required" in capsys.readouterr().err


def test_a_rerun_overwrites_and_a_failed_import_leaves_the_dataset_whole(tmp_path):
    f = rig_file(tmp_path / "r.csv", per_rev=400)
    ds = tmp_path / "ds"
    import_rig([f], ds, design=R81, load_Nm=0.0, samples_per_rev=0)
    assert json.loads((ds / "design.json").read_text())["z_sun"] == 18
    before = {p.name: p.read_bytes() for p in ds.iterdir()}
    (ds / ".samples.csv.abcdefgh.tmp").write_text("left by a killed run")
    import_rig([f], ds, design=R81, load_Nm=0.0, samples_per_rev=0)
    assert {p.name: p.read_bytes() for p in ds.iterdir()} == before
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="bad.csv"):
        import_rig([f, bad], ds, design=R81, load_Nm=5.0, samples_per_rev=0)
    assert {p.name: p.read_bytes() for p in ds.iterdir()} == before
    # a --ratio import into a folder whose design.json has another ratio is refused, naming both
    with pytest.raises(ValueError, match="ratio 81, not the --ratio 121"):
        import_rig([f], ds, ratio=121, load_Nm=0.0, samples_per_rev=0)


def test_a_time_column_gives_the_times_and_a_time_gap(tmp_path):
    f = rig_file(tmp_path / "t.csv", per_rev=800)
    df = pd.read_csv(f)
    t = np.arange(len(df)) / 1000.0
    t[400:] += 0.005                                   # 5 readings' worth of time missing, positions regular
    df["time_s"] = t
    df.to_csv(f, index=False)
    recs = read_rig_file(f)
    assert recs[1].time_source == "column time_s"
    assert [(g["kind"], g["missing"]) for g in recs[1].gaps] == [("split", 5)]
    np.testing.assert_allclose(recs[-1].time_s, t - t[0])
