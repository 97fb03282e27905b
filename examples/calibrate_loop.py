"""The closed loop on a simulated record with an undeclared effect: what the measured TE says the model lacks.

A test-rig record is simulated (``rvcalib.simulate_dataset``): TE runs of the default reducer at two loads in both
directions, with encoder noise, whose truth holds one error the record does not declare, pin 12 moved 0.02 deg
along the pin circle (paper Table 4 error L). The loop (``rvcalib.calibrate``) reads the record as it would read a
measured one (``rvcalib.read_dataset``), compares it with the model of the declared reducer and names what is
missing, with its size. The figure sets the residual RMS before and after the loop against the simulated noise,
and the size of each named effect against the hidden one.

Run: ``python examples/calibrate_loop.py [--small] [--out DIR]``; writes ``DIR/calibrate_loop.png`` and the
simulated record in ``DIR/record`` (default DIR ``examples-out``). ``--small``: two runs at one load, 36 readings
per output revolution.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import rvcalib  # noqa: E402

HIDDEN = {"errors": {"pin_pitch": {"value": 0.02, "pin": 12}}}
TRUTH = {"pin_pitch": 0.02}     # the hidden effect's size by error type, deg
NOISE_ARCSEC = 0.15


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="two runs at 20 N m, 36 readings per revolution")
    ap.add_argument("--out", type=Path, default=Path("examples-out"), help="output folder (default examples-out)")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    loads = (20.0,) if a.small else (10.0, 30.0)
    runs = [{"run": f"r{i}", "load_Nm": load, "direction": d}
            for i, (load, d) in enumerate((load, d) for load in loads for d in (1, -1))]

    record = a.out / "record"          # runs.csv + samples.csv, as a rig's record (the truth is kept apart)
    rvcalib.simulate_dataset(record, runs, hidden=HIDDEN, noise_arcsec=NOISE_ARCSEC,
                             samples_per_rev=36 if a.small else 360, seed=1)
    result = rvcalib.calibrate(rvcalib.read_dataset(record)).to_dict()
    before, after = result["rms_before"], result["rms_after"]
    print(f"{len(runs)} runs; residual RMS {before:.4g} -> {after:.4g} arcsec (simulated noise {NOISE_ARCSEC})")
    for e in result["effects"]:
        print(f"  named: {e['name']} = {e['value']:.4g} {e['unit']}")

    fig, (rms, eff) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [1.0, 1.6]})
    rms.bar(["before", "after"], [before, after], color=["tab:red", "tab:blue"])
    rms.axhline(NOISE_ARCSEC, color="k", ls="--", lw=1.0, label=f"simulated noise {NOISE_ARCSEC} arcsec")
    rms.set_yscale("log")
    rms.set_ylabel("residual RMS [arcsec]")
    rms.set_title("measured TE minus model", fontsize=10)
    rms.legend(fontsize=8)
    names = [e["name"] for e in result["effects"]]
    for i, e in enumerate(result["effects"]):
        truth = next((v for k, v in TRUTH.items() if e["name"].startswith(k)), None)
        ratio = e["value"] / truth if truth else 0.0
        eff.barh(i, ratio, color="tab:blue" if truth else "0.8")
        eff.text(max(ratio, 0.0), i, f"  {e['value']:.4g} {e['unit']}" + ("" if truth else " (not hidden)"),
                 va="center", fontsize=8)
    eff.axvline(1.0, color="k", ls="--", lw=1.0, label="the hidden size")
    eff.set_yticks(range(len(names)), names, fontsize=8)
    eff.set_xlim(0.0, 1.6)
    eff.set_xlabel("named size / hidden size")
    eff.set_title("effects the record does not declare, as the loop names them", fontsize=10)
    eff.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    path = a.out / "calibrate_loop.png"
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
