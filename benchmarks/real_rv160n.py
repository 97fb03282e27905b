"""Benchmark: rv-calibrate on the real RV-160N test-rig records (issue 46).

Reads ``../shared/data/real-rv160n/`` (two records of a public data set: an RV-160N-class reducer, ratio 81,
1800 rpm input, 0 and 1800 N m, forward and backward, 4 kHz; see its README) when present, else says so and
stops. The records are development data: never copied into the project, never read by the tests.

1. By hand, from the raw files (pandas only): the mean TE per direction, backward minus forward (B - F) per
   load, the secant torsional rigidity ``1800 / ((BF(1800) - BF(0)) / 2)`` N m/arcmin and the light-load play
   ``BF(0)`` arcmin.
2. ``rv-calibrate import`` of both records into a temporary dataset (default readings per revolution), the
   per-test table (:func:`rvrig.rigtable.test_table`), how it changes with load, the measured datasheet
   (``--rated-Nm``, default 1568 N m: the RV-160N class) against the figures by hand, and the figure of the
   mean TE per direction against load.
3. The spectrum of every reading (a second import with ``--samples-per-rev 0``): the main order-locked lines
   and the fixed-frequency lines (the rig line near 490 Hz), :func:`rvrig.spectrum.separate`.
4. The loop on the imported dataset as ``rv-calibrate`` runs it (:func:`rvcalib.cli.run`) with the design
   ``--design`` (default ``examples/designs/rv160n.json``, three cranks; ``--no-loop`` skips it), its summary
   printed as the command prints it and its report written to ``OUT/calibration``: the rig's zero of each test,
   what it names, what stays unexplained, the datasheet as declared and as calibrated, and with ``--holdout`` each
   load left out of the fit and predicted. The loop fits the readings averaged to the density ``rv-calibrate``
   chooses (flat to the model's orders, :mod:`rvrig.average`); ``--loop-samples-per-rev K`` is its
   ``--samples-per-rev``.

The design. ``examples/designs/rv160n.json`` holds the published RV-160N sizes (sun 22, planets 44, 40 pins, 39
lobes, pin circle 223 mm, eccentricity 2.0 mm, module 1.5 mm) with three cranks at 0, 120 and 240 deg; its
assumed sizes are in docs/physics.md section 14. ``benchmarks/data/rv160n_2crank.json`` is the same with two
cranks (``--design`` it to compare): the record's sidebands 39 k +- 3 (orders 75, 153, 237, 315) are no orders of
a two-crank design, so its spectrum reports them at a fixed frequency.

Figures are appended to ``benchmarks/results.csv`` (:mod:`results_log`).

Run: ``python benchmarks/real_rv160n.py [--data DIR] [--design DESIGN.json] [--rated-Nm T] [--out DIR]
[--no-loop] [--holdout] [--loop-samples-per-rev K] [--workers N]``.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from results_log import record  # noqa: E402
from rvcalib.cli import main as rv_calibrate  # noqa: E402
from rvrig.average import fitted_density  # noqa: E402
from rvrig.dataset import read_dataset  # noqa: E402
from rvrig.rigtable import load_changes, measured_datasheet, plot_test_means, test_table  # noqa: E402
from rvrig.spectrum import separate  # noqa: E402

FILES = ("1800.0rpm0.0Nm25.0deg.csv", "1800.0rpm1800.0Nm25.0deg.csv")
LOADS = (0.0, 1800.0)
#: Where ../shared may be, from a clone (/work/main) or a worktree (/work/wt/NAME).
CANDIDATES = (ROOT.parent / "shared" / "data" / "real-rv160n", ROOT.parents[1] / "shared" / "data" / "real-rv160n")
RIG_LINE_HZ = (480.0, 500.0)


def by_hand(folder: Path) -> dict:
    """B - F per load, the secant rigidity and the light-load play from the raw files, arithmetic means."""
    bf = {}
    for name, load in zip(FILES, LOADS):
        df = pd.read_csv(folder / name)
        fw = df["Transmission_Error_Fw"].dropna().mean() * 3600.0
        bw = df["Transmission_Error_Bw"].dropna().mean() * 3600.0
        print(f"  {name}: mean forward {fw:.2f}, backward {bw:.2f}, B - F {bw - fw:.2f} arcsec")
        bf[load] = bw - fw
    k = (LOADS[1] - LOADS[0]) / ((bf[LOADS[1]] - bf[LOADS[0]]) / 2.0 / 60.0)
    play = bf[LOADS[0]] / 60.0
    print(f"  secant rigidity 0 -> 1800 N m: {k:.1f} N m/arcmin; light-load play B - F(0) = {play:.3f} arcmin")
    return {"bf": bf, "rigidity": k, "play": play}


def import_dataset(folder: Path, out: Path, design: Path, per_rev: int | None) -> None:
    argv = ["import", *(str(folder / f) for f in FILES), "--out", str(out), "--reducer", str(design), "--json"]
    if per_rev is not None:
        argv += ["--samples-per-rev", str(per_rev)]
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        status = rv_calibrate(argv)
    if status != 0:
        raise SystemExit(f"rv-calibrate import failed with status {status}")
    res = json.loads(buf.getvalue())
    for f in res["files"]:
        for r in f["runs"]:
            print(f"  {r['run']}: {r['readings']} readings, {len(r['gaps'])} gaps, {r['revolutions']:.4f} rev at "
                  f"{r['speed_rpm_from_readings']:.1f} rpm -> {r['samples']} samples")


def table_section(ds, rated: float, hand: dict, fig: Path) -> tuple[dict, list]:
    pd.set_option("display.width", 200)
    pd.set_option("display.max_columns", 12)
    tab = test_table(ds)
    cols = ["test", "load_Nm", "mean_fw_arcsec", "mean_bw_arcsec", "bw_minus_fw_arcsec", "pp_fw_arcsec",
            "pp_bw_arcsec"]
    print(tab[cols].to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    print("  main orders (amplitude arcsec / phase deg, forward | backward):")
    for o in tab.attrs["main_orders"]:
        k = o["order"]
        cells = " ".join(f"{row[f'order{k}_amp_fw_arcsec']:6.2f}/{row[f'order{k}_phase_fw_deg']:7.1f} | "
                         f"{row[f'order{k}_amp_bw_arcsec']:6.2f}/{row[f'order{k}_phase_bw_deg']:7.1f}   "
                         for _, row in tab.iterrows())
        print(f"    order {k:4d} ({o['label']}): {cells}")
    ch = load_changes(tab)
    print("  change from 0 to 1800 N m (per kN m):")
    for _, r in ch[ch["quantity"].str.contains("amp|bw_minus|pp_")].iterrows():
        print(f"    {r['quantity']}: {r['low']:.2f} -> {r['high']:.2f} ({r['change_per_kNm']:+.2f} per kN m)")
    sheet = measured_datasheet(ds, rated, table=tab)
    print("  measured datasheet:")
    for s in sheet["statements"]:
        print(f"    - {s}")
    dk = sheet["secant_rigidity_Nm_per_arcmin"] / hand["rigidity"] - 1.0
    dp = sheet["light_load_play_arcmin"] / hand["play"] - 1.0
    print(f"  against the figures by hand: rigidity {dk:+.2%}, play {dp:+.2%} (within 5 %: "
          f"{'yes' if abs(dk) < 0.05 and abs(dp) < 0.05 else 'NO'})")
    plot_test_means(ds, fig, table=tab)
    print(f"  figure: {fig}")
    figs = [("bw_minus_fw_0Nm", sheet["bw_minus_fw_arcsec"][0], "arcsec"),
            ("bw_minus_fw_1800Nm", sheet["bw_minus_fw_arcsec"][-1], "arcsec"),
            ("secant_rigidity", sheet["secant_rigidity_Nm_per_arcmin"], "N m/arcmin"),
            ("light_load_play", sheet["light_load_play_arcmin"], "arcmin"),
            ("rigidity_vs_hand", dk, "fraction"), ("play_vs_hand", dp, "fraction")]
    if sheet["lost_motion_arcmin"] is not None:
        figs.append(("lost_motion_interpolated", sheet["lost_motion_arcmin"], "arcmin"))
    return sheet, figs


def spectrum_section(ds) -> list:
    out = separate(ds)
    for s in out["statements"]:
        print(f"  - {s}")
    print("  order-locked (largest 12):")
    for g in out["order_locked"][:12]:
        print(f"    order {g['order']:7.1f} {g['label'] or '':32s} {g['amplitude_arcsec']:6.2f} arcsec "
              f"({len(g['runs'])} runs)")
    print("  fixed-frequency, not claimed for the reducer (largest 10):")
    for g in out["fixed_frequency"][:10]:
        print(f"    {g['frequency_Hz']:8.1f} Hz (order {g['order']:7.1f}) {g['amplitude_arcsec']:6.2f} arcsec "
              f"({len(g['runs'])} runs)")
    rig = [g for g in out["fixed_frequency"] if RIG_LINE_HZ[0] <= (g["frequency_Hz"] or 0) <= RIG_LINE_HZ[1]]
    claimed = [g for g in out["order_locked"] if abs(g["order"] - (rig[0]["order"] if rig else -1)) < 1]
    figs = [("nyquist_order", out["nyquist_order"], "order"),
            ("fixed_frequency_lines", len(out["fixed_frequency"]), "count")]
    if rig:
        top = max(rig, key=lambda g: g["amplitude_arcsec"])
        print(f"  rig line: {top['frequency_Hz']:.1f} Hz, {top['amplitude_arcsec']:.2f} arcsec, claimed for the "
              f"reducer: {'YES' if claimed else 'no'}")
        figs += [("rig_line_frequency", top["frequency_Hz"], "Hz"), ("rig_line_amplitude", top["amplitude_arcsec"],
                                                                     "arcsec")]
    return figs


def loop_section(ds, workers: int, rated_Nm: float, out: Path, estimator: str = "sparse",
                 holdout: bool = False, samples_per_rev: int | None = None) -> list:
    """The loop on the imported dataset as ``rv-calibrate`` runs it (:func:`rvcalib.cli.run`: the loop, the
    datasheet as declared and as calibrated, and with ``holdout`` each load left out of the fit and predicted), its
    summary printed as the command prints it, the report in ``out`` (figures named ``loop_...``,
    ``loop_tolerance_prior_...`` for that estimator)."""
    from rvcalib import CalibrationSettings
    from rvcalib.cli import run, summary

    t0 = time.perf_counter()
    settings = CalibrationSettings(workers=workers, rated_Nm=rated_Nm, estimator=estimator,
                                   samples_per_rev=samples_per_rev)

    def log(s: str) -> None:
        print(f"    [{time.perf_counter() - t0:6.0f} s] {s}", flush=True)

    obj = run(ds, settings, str(out), holdout, log)["object"]
    sec = time.perf_counter() - t0
    print(f"  {sec:.0f} s (loop {obj['seconds']:.0f} s); stopped: {obj['stopped_by']}; report: {obj['report']}")
    print("\n".join("  " + line for line in summary(obj).splitlines()))
    pre = "loop_" if estimator == "sparse" else "loop_" + estimator.replace("-", "_") + "_"
    names = [e["key"] for e in obj["effects"]]
    figs = [(pre + "rms_before", obj["rms_before"], "arcsec"), (pre + "rms_after", obj["rms_after"], "arcsec"),
            (pre + "noise", obj["noise_arcsec"], "arcsec"), (pre + "sigma", obj["sigma_arcsec"], "arcsec"),
            (pre + "effects", len(obj["effects"]), "count"), (pre + "seconds", sec, "s"),
            (pre + "ramp_or_scale_named", float(any(k in ("output_encoder_scale_error", "drift_arcsec_per_rev")
                                                    for k in names)), "bool")]
    sheet = obj["datasheet"] or {}
    if sheet.get("computed"):
        for key, unit in (("torsional_rigidity_Nm_per_arcmin", "N m/arcmin"), ("lost_motion_arcmin", "arcmin"),
                          ("backlash_arcmin", "arcmin")):
            figs += [(f"{pre}declared_{key}", sheet["model"][key], unit),
                     (f"{pre}calibrated_{key}", sheet["calibrated"][key], unit)]
    for r in (obj["holdout"] or {}).get("rows", []):
        if r["rms_prediction_arcsec"] is not None:
            figs.append((f"{pre}holdout_{r['load_Nm']:g}Nm_rms_prediction", r["rms_prediction_arcsec"], "arcsec"))
    return figs


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=None, help="folder of the two records (default: ../shared/...)")
    p.add_argument("--design", type=Path, default=ROOT / "examples" / "designs" / "rv160n.json")
    p.add_argument("--rated-Nm", dest="rated_Nm", type=float, default=1568.0,
                   help="rated output torque, N m (default 1568, the RV-160N class)")
    p.add_argument("--out", type=Path, default=None, help="folder for the figure (default: a temporary folder)")
    p.add_argument("--no-loop", action="store_true", help="skip the loop")
    p.add_argument("--holdout", action="store_true", help="after the loop, predict each load left out of the fit")
    p.add_argument("--loop-samples-per-rev", dest="loop_per_rev", type=int, default=None,
                   help="readings per revolution the loop fits (rv-calibrate --samples-per-rev; default its default)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--estimator", default="sparse", choices=("sparse", "tolerance-prior"),
                   help="the loop's estimator (rv-calibrate --estimator)")
    args = p.parse_args()
    folder = args.data or next((c for c in CANDIDATES if (c / FILES[0]).is_file()), None)
    if folder is None or not all((folder / f).is_file() for f in FILES):
        print(f"real_rv160n: skipped: the records {FILES} are not in {args.data or [str(c) for c in CANDIDATES]}")
        return 0
    out = args.out or Path(tempfile.mkdtemp(prefix="real_rv160n-"))
    print(f"records: {folder}\ndesign: {args.design}\n1. by hand from the raw files")
    hand = by_hand(folder)
    figs = [("hand_bw_minus_fw_0Nm", hand["bf"][0.0], "arcsec"), ("hand_bw_minus_fw_1800Nm", hand["bf"][1800.0], "arcsec"),
            ("hand_secant_rigidity", hand["rigidity"], "N m/arcmin"), ("hand_light_load_play", hand["play"], "arcmin")]
    with tempfile.TemporaryDirectory(prefix="rv160n-ds-") as tmp:
        dense, full = Path(tmp) / "dataset", Path(tmp) / "every-reading"
        print("2. rv-calibrate import (default readings per revolution)")
        import_dataset(folder, dense, args.design, None)
        ds = read_dataset(dense)
        _, f2 = table_section(ds, args.rated_Nm, hand, out / "test_means.png")
        figs += f2
        print("3. spectrum of every reading (rv-calibrate import --samples-per-rev 0)")
        import_dataset(folder, full, args.design, 0)
        figs += spectrum_section(read_dataset(full))
        if not args.no_loop:
            print("4. the loop (rv-calibrate, rvcalib.cli.run) on the imported dataset")
            figs += loop_section(ds, args.workers, args.rated_Nm, out / "calibration", args.estimator,
                                 args.holdout, args.loop_per_rev)
            figs.append(("loop_samples_per_rev", fitted_density(ds.runs[0], args.loop_per_rev), "readings/rev"))
    record("real_rv160n", [(n, float(v), u) for n, v, u in figs])
    return 0


if __name__ == "__main__":
    sys.exit(main())
