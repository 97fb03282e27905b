"""Parts of an error-perturbed reducer as build123d solids: seen from the output side, exported, and their TE.

The case makes every pin 10 um thinner than drawn (``pin_radius`` -10 um, paper Table 4 error J). ``rvcad.reducer``
builds each part as an OpenCASCADE solid with the error applied, placed at input angle 0 by the ideal kinematics;
the figure draws the top face of each stage II part (the edges build123d gives), a zoom on the pin with the
smallest gap to disc 0 (the 10 um the error opens, on a micrometre scale), and the TE this case and the nominal
reducer give over one output revolution (``rvdyn.solve``): under the resisting load the output lags by the elastic
wind-up, and the clearance adds about 10 um over the largest pin lever (52.4 mm, docs/physics.md section 6), i.e.
about 39 arcsec.

Run: ``python examples/perturbed_parts.py [--small] [--out DIR]``; writes ``DIR/perturbed_parts.png`` and
``DIR/disc0.step``, ``DIR/disc0.stl`` (default DIR ``examples-out``). ``--small``: B-splines within 10 um instead
of 0.1 um (the zoom then shows the fit, not the error), a quarter of the pins drawn, 120 TE steps.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import build123d as bd  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import rvcad  # noqa: E402
import rvdyn  # noqa: E402

CASE = {"name": "pins 10 um thin", "errors": {"pin_radius": -10.0}}


def top_edges(solid, spacing_mm: float) -> list[np.ndarray]:
    """(n, 2) x-y points along every edge of the solid's topmost face, about ``spacing_mm`` apart."""
    face = solid.faces().sort_by(bd.Axis.Z)[-1]
    return [np.array([(p.X, p.Y) for p in e.positions(np.linspace(0.0, 1.0, max(8, int(e.length / spacing_mm))))])
            for e in face.edges()]


def gap_zoom(disc, pin, samples: int = 4000) -> tuple[list[np.ndarray], np.ndarray, float]:
    """The disc's edges near a pin (sampled) and the pin's circle, both relative to the disc point nearest the
    pin centre, in um; and the gap there (um)."""
    c = np.array([pin.center().X, pin.center().Y])
    r_pin = pin.bounding_box().size.X / 2.0
    near = [e for e in disc.faces().sort_by(bd.Axis.Z)[-1].edges()
            if np.hypot(*(np.array([e.center().X, e.center().Y]) - c)) < 6.0]
    t = np.linspace(0.0, 1.0, samples)
    edges = [np.array([(p.X, p.Y) for p in e.positions(t)]) for e in near]
    pts = np.concatenate(edges)
    dist = np.hypot(*(pts - c).T)
    foot = pts[np.argmin(dist)]
    phi = np.linspace(0.0, 2.0 * np.pi, 20000)
    circle = c + r_pin * np.c_[np.cos(phi), np.sin(phi)]
    return [(xy - foot) * 1e3 for xy in edges], (circle - foot) * 1e3, float((dist.min() - r_pin) * 1e3)


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="coarser parts, fewer pins drawn, 120 TE steps")
    ap.add_argument("--out", type=Path, default=Path("examples-out"), help="output folder (default examples-out)")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)

    tol_mm = 1e-2 if a.small else 1e-4  # B-spline budget of the exact curves: 10 um quick, 0.1 um (the default)
    r = rvcad.reducer(CASE, tolerance_mm=tol_mm)
    pins = [n for n in r.names if n.startswith("pin")][:: 4 if a.small else 1]
    disc = r.parts["disc0"]
    bd.export_step(disc, str(a.out / "disc0.step"))
    bd.export_stl(disc, str(a.out / "disc0.stl"), tolerance=0.01)
    print(f"{r!r}; disc0 volume {disc.volume:.1f} mm^3; wrote disc0.step and disc0.stl")

    fig, (ax, zoom, te_ax) = plt.subplots(1, 3, figsize=(15, 5), gridspec_kw={"width_ratios": [1.1, 1.0, 1.4]})
    for name, colour in [("disc0", "tab:blue"), ("crank0", "0.3"), ("crank1", "0.3"), ("housing", "0.6")] + \
            [(p, "tab:red") for p in pins]:
        for xy in top_edges(r.parts[name], 1.0 if a.small else 0.3):
            ax.plot(xy[:, 0], xy[:, 1], color=colour, lw=0.6)
    ax.set_aspect("equal")
    ax.set_title("disc 0 (blue), pins (red), cranks, housing [mm]", fontsize=9)

    gaps = {p: gap_zoom(disc, r.parts[p], 800 if a.small else 4000) for p in pins}
    pin = min(gaps, key=lambda p: gaps[p][2])
    edge, circle, gap = gaps[pin]
    for i, xy in enumerate(edge):
        zoom.plot(xy[:, 0], xy[:, 1], color="tab:blue", lw=1.0, label="disc 0 (its B-spline edges)" if i == 0 else None)
    zoom.plot(circle[:, 0], circle[:, 1], color="tab:red", lw=1.0, label=f"{pin}")
    zoom.set_xlim(-25, 25)
    zoom.set_ylim(-25, 25)
    zoom.set_aspect("equal")
    zoom.legend(fontsize=8, loc="upper left")
    zoom.set_title(f"zoom on {pin}: gap {gap:.2f} um [um] (B-splines within {tol_mm * 1e3:g} um)", fontsize=9)

    steps = 120 if a.small else 720
    res, nominal = rvdyn.solve(CASE, steps=steps), rvdyn.solve({}, steps=steps)
    for r_, colour, label in ((nominal, "0.5", "nominal"), (res, "tab:red", CASE["name"])):
        te_ax.plot(r_.table["output_deg"], r_.table["te_arcsec"], color=colour, lw=0.6,
                   label=f"{label}: mean {r_.stats['mean']:.1f}\", pp {r_.stats['pp']:.2f}\"")
    te_ax.axhline(0.0, color="k", lw=0.5)
    te_ax.set_ylim(1.2 * res.stats["mean"], -0.1 * res.stats["mean"])
    te_ax.set_xlabel("output angle [deg]")
    te_ax.set_ylabel("TE [arcsec]")
    te_ax.legend(fontsize=8, loc="center right")
    te_ax.set_title(f"TE over one output revolution at {res.case.load_Nm:g} N m: the clearance adds to the wind-up",
                    fontsize=9)
    fig.suptitle(f"rvcad + rvdyn: case '{CASE['name']}' ({CASE['errors']})", fontsize=10)
    fig.tight_layout()
    path = a.out / "perturbed_parts.png"
    fig.savefig(path, dpi=90)
    print(f"smallest pin gap to disc 0: {gap:.2f} um at {pin}; TE mean {res.stats['mean']:.4g} arcsec "
          f"(nominal {nominal.stats['mean']:.4g}), pp {res.stats['pp']:.4g} arcsec; wrote {path}")
    return path


if __name__ == "__main__":
    main()
