"""The datasheet of a design: the maker's hysteresis curve, torsional rigidity, lost motion and backlash.

The input is locked and the output torque swept -rated -> +rated -> -rated (rated 167 N m, the RV-20E class of
the paper's reducer), with Coulomb friction at the pins and bearings (``rvdyn.stiffness.hysteresis``; the figures
as a maker defines them, docs/conventions.md). Two designs: the default (zero-backlash profile) and the same
reducer with its discs ground 10 um equidistant (``design.profile_equidistant_mm`` 0.01), which opens a play at
light load. The figure draws both curves and, beside them, the compliance budget at rated torque (which part
winds up how much).

Run: ``python examples/datasheet.py [--small] [--out DIR]``; writes ``DIR/datasheet.png`` (default DIR
``examples-out``) and prints the datasheet figures. ``--small``: 9 torque points per branch instead of 41.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rvcad.errors import Case  # noqa: E402
from rvdyn.stiffness import hysteresis  # noqa: E402

DESIGNS = {"default design": {}, "discs 10 um equidistant": {"profile_equidistant_mm": 0.01}}


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="9 torque points per sweep branch instead of 41")
    ap.add_argument("--out", type=Path, default=Path("examples-out"), help="output folder (default examples-out)")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)

    fig, (ax, bud) = plt.subplots(1, 2, figsize=(13, 4.8), gridspec_kw={"width_ratios": [1.4, 1.0]})
    budgets = {}
    for i, (name, design) in enumerate(DESIGNS.items()):
        res = hysteresis(Case.from_dict({"name": name, "design": design}), points=9 if a.small else 41)
        f = res.figures
        print(f"{name}: torsional rigidity {f['torsional_rigidity_Nm_per_arcmin']:.1f} N m/arcmin, lost motion "
              f"{f['lost_motion_arcmin']:.3f} arcmin, backlash {f['backlash_arcmin']:.3f} arcmin, hysteresis loss "
              f"{f['hysteresis_loss_arcmin']:.3f} arcmin (rated {f['rated_torque_Nm']:g} N m)")
        for branch, style in (("load", "-"), ("unload", "--")):
            c = res.curve[res.curve["branch"] == branch]
            ax.plot(c["torque_Nm"], c["torsion_arcmin"], style, color=f"C{i}",
                    label=f"{name}, {branch}: k {f['torsional_rigidity_Nm_per_arcmin']:.1f} N m/arcmin, "
                          f"lost motion {f['lost_motion_arcmin']:.2f}'" if branch == "load" else None)
        budgets[name] = f["budget"]
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.axvline(0.0, color="0.7", lw=0.5)
    ax.set_xlabel("output torque [N m], input locked")
    ax.set_ylabel("torsion angle [arcmin]")
    ax.set_title("hysteresis curve (solid: loading, dashed: unloading)", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, lw=0.3)

    parts = sorted(budgets["default design"], key=lambda p: -budgets["default design"][p])
    y = np.arange(len(parts))
    for i, (name, b) in enumerate(budgets.items()):
        bud.barh(y + 0.4 * i - 0.2, [b.get(p, 0.0) for p in parts], height=0.4, color=f"C{i}", label=name)
    bud.set_yticks(y, parts, fontsize=8)
    bud.invert_yaxis()
    bud.set_xlabel("wind-up at rated torque [arcsec]")
    bud.set_title("compliance budget", fontsize=10)
    bud.legend(fontsize=8)
    fig.tight_layout()
    path = a.out / "datasheet.png"
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
