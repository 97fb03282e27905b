"""``rv-calibrate import FILES... --out DATASET_DIR [--load-Nm L] [--speed-rpm S] [--temperature-C T]
[--ratio N | --reducer DESIGN.json] [--samples-per-rev K] [--sample-rate-Hz F] [--test ID] [--json]``.

Turns a TE rig's files (output angle and TE per direction, sampled in time; :mod:`rvrig.rigimport`,
docs/rig-data.md) into a dataset folder ``rv-calibrate`` reads. Prints what it wrote and which conditions
came from the file names, or with ``--json`` the import record (also written to ``DATASET_DIR/import.json``).
Bad input: one line on stderr naming the file, column or option, exit status 2.
"""
from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

from rvcad import validation as v
from rvrig.rigimport import DEFAULT_SAMPLE_RATE_HZ, import_rig


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``rv-calibrate import``."""
    p = v.ArgumentParser(
        prog="rv-calibrate import",
        description="Turn TE rig records (one CSV file per test: output angle and TE, forward and backward, "
                    "sampled in time) into a dataset folder (runs.csv, samples.csv) for rv-calibrate.")
    p.add_argument("files", nargs="+", metavar="FILE", help="rig CSV files, one test (homing) each")
    p.add_argument("--out", required=True, metavar="DATASET_DIR", help="dataset folder to write (created)")
    red = p.add_mutually_exclusive_group(required=True)
    red.add_argument("--ratio", type=float, default=None, metavar="N",
                     help="the reducer's total ratio (input turns per output turn)")
    red.add_argument("--reducer", default=None, metavar="DESIGN.json",
                     help="the reducer's design JSON (the 'design' object of a case JSON); also written to "
                          "DATASET_DIR/design.json so rv-calibrate finds it")
    p.add_argument("--load-Nm", dest="load_Nm", type=float, default=None, metavar="L",
                   help="output load torque of every file, N m (default: from the file name, e.g. "
                        "1800.0rpm0.0Nm25.0deg.csv)")
    p.add_argument("--speed-rpm", dest="speed_rpm", type=float, default=None, metavar="S",
                   help="input speed of every file, rpm (default: from the file name)")
    p.add_argument("--temperature-C", dest="temperature_C", type=float, default=None, metavar="T",
                   help="oil temperature of every file, degC (default: from the file name)")
    p.add_argument("--samples-per-rev", dest="samples_per_rev", type=int, default=None, metavar="K",
                   help="readings per output revolution written, after an anti-alias low-pass (0: every reading; "
                        "default: the smallest multiple of 360 whose pass band holds 4 (N + 1) and 8 Zp, e.g. "
                        "1080 for ratio 81)")
    p.add_argument("--sample-rate-Hz", dest="sample_rate_Hz", type=float, default=DEFAULT_SAMPLE_RATE_HZ,
                   metavar="F", help=f"the rig's sample rate for files without a time_s column (default "
                                     f"{DEFAULT_SAMPLE_RATE_HZ:g})")
    p.add_argument("--test", default=None, metavar="ID",
                   help="one test id for all the files (measured after one homing); default: one test per file")
    p.add_argument("--json", action="store_true", help="print the import record as JSON")
    return p


def summary(result: dict) -> str:
    """The human summary of an import."""
    lines = []
    for f in result["files"]:
        cond = f"load {f['load_Nm']:g} N m"
        if f["speed_rpm"] is not None:
            cond += f", {f['speed_rpm']:g} rpm"
        if f["temperature_C"] is not None:
            cond += f", {f['temperature_C']:g} degC"
        lines.append(f"{Path(f['file']).name}: test {f['test']}, {cond}")
        for r in f["runs"]:
            lines.append(f"  run {r['run']} (direction {r['direction']:+d}): {r['readings']} readings, "
                         f"{r['revolutions']:.4f} revolutions at {r['speed_rpm_from_readings']:.5g} rpm input, noise "
                         f"{r['noise_arcsec_readings']:.3g} arcsec -> {r['samples']} samples "
                         f"({r['samples_per_rev']:.5g} per revolution), {len(r['gaps'])} gap(s), times from "
                         f"{r['time_from']}")
    for n in result["notes"]:
        lines.append(f"note: {n}")
    out = Path(result["dataset"])
    lines.append(f"wrote {out / 'runs.csv'}, {out / 'samples.csv'}, {out / 'import.json'}"
                 + (f", {out / 'design.json'}" if result["design"] is not None else "")
                 + f" (ratio {result['ratio']:g})")
    if result["design"] is None:
        lines.append(f"next: rv-calibrate {out} --reducer DESIGN.json (a design of ratio {result['ratio']:g})")
    else:
        lines.append(f"next: rv-calibrate {out} --out REPORT_DIR")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``rv-calibrate import``; returns the exit status (0 ok, 2 bad input)."""
    args = build_parser().parse_args(argv)
    try:
        out = v.output_dir(args.out)
        res = import_rig(args.files, out, ratio=args.ratio, design=args.reducer, load_Nm=args.load_Nm,
                         speed_rpm=args.speed_rpm, temperature_C=args.temperature_C,
                         samples_per_rev=args.samples_per_rev, sample_rate_Hz=args.sample_rate_Hz, test=args.test)
    except (ValueError, OSError) as exc:
        return v.refuse("rv-calibrate import", exc)
    print(json.dumps(res, indent=2, default=float) if args.json else summary(res))
    return 0
