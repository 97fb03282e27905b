"""TE of a case over one output revolution, zoomed on a crank period, and its order spectrum.

Three cases under the default (physical) contact law at 20 N m: the nominal reducer, a cam phase error of 10 um on
crank 0 / disc 0 (paper Table 4 error D) and a pin pitch error of 0.01 deg on pin 0 (error L). The figure (one row a
case, shared axes) is the one ``rv-stackup`` draws for its screen: TE minus its mean over one output revolution, the
first crank period (9 deg of output: the crank turns 40 times per output revolution), and the amplitude of each
order (periods per output revolution) on a log axis. The cam phase error repeats every crank turn (order 40 and its
multiples); the one displaced pin breaks the pins' symmetry, so its TE has the lobe order 39 and its multiples on top
of every other order.

Run: ``python examples/te_spectrum.py [--small] [--out DIR]``; writes ``DIR/te_spectrum.png`` (default DIR
``examples-out``) and prints the largest orders of each case. ``--small``: 120 steps instead of 720.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import rvdyn
from rvstudy.te_figure import order_spectrum, plot_te_figure

CASES = {
    "nominal": {},
    "cam_phase 10 um": {"errors": {"cam_phase": 10.0}},
    "pin_pitch 0.01 deg, pin 0": {"errors": {"pin_pitch": {"value": 0.01, "pin": 0}}},
}


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="120 steps per revolution instead of 720")
    ap.add_argument("--out", type=Path, default=Path("examples-out"), help="output folder (default examples-out)")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    steps = 120 if a.small else 720

    curves = {}
    for name, case in CASES.items():
        res = rvdyn.solve(case, steps=steps)
        te = res.table["te_arcsec"].to_numpy()
        curves[name] = te
        orders, amp = order_spectrum(te)
        top = np.argsort(amp)[::-1][:4]
        print(f"{name:28s} pp {res.stats['pp']:8.4f} arcsec, mean {res.stats['mean']:9.4f} arcsec; largest orders: "
              + ", ".join(f"{orders[i]} ({amp[i]:.3g}\")" for i in top))
    path = plot_te_figure(curves, a.out / "te_spectrum.png", crank_order=40,
                          suptitle=f"TE at 20 N m, physical contact law, {steps} steps per output revolution")
    print(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
