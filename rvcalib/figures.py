"""The figures of a calibration report (PNG, matplotlib's Agg backend, written atomically).

* :func:`plot_te`: per run, over its first output revolution, the measured TE, the declared model's and the
  calibrated model's (thin lines; each test's constant, the rig's zero, taken off so the curves share a level);
* :func:`plot_residuals`: per run, the residual before (declared model) and after (calibrated), over its first
  output revolution;
* :func:`plot_residual_spectrum`: the order spectrum of the residual after (:mod:`rvrig.spectrum`), each run a
  thin line, the lines found marked: locked to an order of the reducer, or at a fixed frequency (the rig's, not
  claimed for the reducer).

At most :data:`MAX_PANELS` runs are drawn; the title says when there are more.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from rvcad.atomic import atomic_path
from rvrig.spectrum import threshold

#: Most runs drawn in a figure of one panel per run.
MAX_PANELS = 12
DPI = 110
#: Lines of the residual spectrum labelled in the figure (the largest), per kind.
MAX_LABELS = 6


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def first_revolution(run) -> tuple[np.ndarray, np.ndarray]:
    """Indices of a run's readings over its first output revolution, sorted by output angle, and that angle
    (deg, 0 to 360: the output reading modulo one revolution)."""
    travelled = np.abs(np.asarray(run.output_deg) - run.output_deg[0])
    idx = np.flatnonzero(travelled < 360.0)
    x = np.mod(np.asarray(run.output_deg)[idx], 360.0)
    o = np.argsort(x, kind="stable")
    return idx[o], x[o]


def _panels(runs: list, title: str):
    """A figure with one panel per run (at most MAX_PANELS; two columns beyond four) and its axes."""
    plt = _plt()
    shown = runs[:MAX_PANELS]
    n = len(shown)
    cols = 1 if n <= 4 else 2
    rows = int(np.ceil(n / cols))
    height = 2.3 * rows + 0.9
    fig, axes = plt.subplots(rows, cols, figsize=(10 if cols == 1 else 13, height), squeeze=False, sharex=True)
    fig.subplots_adjust(left=0.08 if cols == 1 else 0.06, right=0.98, bottom=0.55 / height, top=1.0 - 0.6 / height,
                        hspace=0.45, wspace=0.15)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    if len(runs) > MAX_PANELS:
        title += f" (first {MAX_PANELS} of {len(runs)} runs)"
    fig.suptitle(title, fontsize=11, x=0.02, ha="left")
    for ax in axes[-1]:
        ax.set_xlabel("output angle (deg, first revolution of each run)")
    return fig, list(axes.flat[:n])


def _legend(fig, ax) -> None:
    """The legend of a figure of panels, in its header beside the title."""
    fig.legend(*ax.get_legend_handles_labels(), loc="upper right", ncol=3, fontsize=8, frameon=False)


def _label(run) -> str:
    return f"run {run.run}: {run.load_Nm:g} N m, direction {run.direction:+d}, test {run.test}"


def _save(fig, path: str | Path) -> Path:
    p = Path(path)
    with atomic_path(p, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=DPI)
    _plt().close(fig)
    return p


def plot_te(dataset, measured: list, calibrated: list, declared: list | None, path: str | Path) -> Path:
    """Measured and model TE per run (module docstring); every list holds one array per run (arcsec), ``declared``
    None when the declared model could not be solved."""
    fig, axes = _panels(dataset.runs, "TE per run: measured and model (each test's rig zero taken off)")
    for k, (ax, run) in enumerate(zip(axes, dataset.runs)):
        idx, x = first_revolution(run)
        ax.plot(x, measured[k][idx], color="0.7", lw=2.4, label="measured")
        if declared is not None:
            ax.plot(x, declared[k][idx], color="C1", lw=0.7, ls="--", label="declared model")
        ax.plot(x, calibrated[k][idx], color="C0", lw=0.8, label="calibrated model")
        ax.set_title(_label(run), fontsize=9)
        ax.set_ylabel("TE (arcsec)")
        ax.grid(True, lw=0.3)
    _legend(fig, axes[0])
    return _save(fig, path)


def plot_residuals(dataset, before: list | None, after: list, path: str | Path) -> Path:
    """Residual (measured - model) per run before and after (module docstring)."""
    title = "Residual = measured - model TE (each test's rig zero taken off)"
    fig, axes = _panels(dataset.runs, title + ("" if before is not None else "; the declared model not solved"))
    for k, (ax, run) in enumerate(zip(axes, dataset.runs)):
        idx, x = first_revolution(run)
        if before is not None:
            ax.plot(x, before[k][idx], color="0.6", lw=0.7, label="before (declared model)")
        ax.plot(x, after[k][idx], color="C0", lw=0.7, label="after (calibrated)")
        ax.axhline(0.0, color="k", lw=0.4)
        ax.set_title(_label(run), fontsize=9)
        ax.set_ylabel("arcsec")
        ax.grid(True, lw=0.3)
    _legend(fig, axes[0])
    return _save(fig, path)


def plot_residual_spectrum(spectra: list, lines: dict, ratio: float, path: str | Path) -> Path:
    """The order spectrum of the residual after (module docstring).

    Parameters
    ----------
    spectra : list of OrderSpectrum
        One per run (:func:`rvrig.spectrum.order_spectrum` of the residual).
    lines : dict
        :func:`rvrig.spectrum.separate` of the residual: ``order_locked`` and ``fixed_frequency`` lines.
    ratio : float
        The reducer's ratio (the input order, in the title).
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(11, 4.6))
    fig.subplots_adjust(left=0.07, right=0.8, bottom=0.12, top=0.92)
    floor = np.inf
    for i, s in enumerate(spectra[:MAX_PANELS]):
        a = np.maximum(s.amplitude_arcsec[1:], 1e-6)
        floor = min(floor, float(np.percentile(a, 5)))
        ax.plot(s.orders[1:], a, lw=0.6, alpha=0.8, color=f"C{i % 10}", label=f"run {s.run}")
    if spectra:
        s0 = spectra[0]
        ax.plot(s0.orders[1:], threshold(s0)[1:], color="0.4", lw=0.8, ls=":", label=f"line threshold (run {s0.run})")
    for kind, color, marker, what in (("order_locked", "C2", "o", "line at an order\nof the reducer"),
                                      ("fixed_frequency", "C3", "v", "line at a fixed frequency\n(not claimed for\n"
                                                                     "the reducer)")):
        ls = lines.get(kind, [])
        if not ls:
            continue
        ax.plot([g["order"] for g in ls], [g["amplitude_arcsec"] for g in ls], marker, color=color, ms=6, mfc="none",
                mew=1.2, ls="none", label=what)
        for g in ls[:MAX_LABELS]:
            tag = (g.get("label") or f"order {g['order']:.4g}") if kind == "order_locked" else (
                f"{g['frequency_Hz']:.4g} Hz" if g.get("frequency_Hz") else f"order {g['order']:.4g}")
            ax.annotate(tag, (g["order"], g["amplitude_arcsec"]), textcoords="offset points", xytext=(4, 6),
                        fontsize=7, color=color)
    ax.set_yscale("log")
    if np.isfinite(floor):
        ax.set_ylim(bottom=0.5 * floor)
    ax.set_xlim(left=0)
    ax.set_xlabel(f"order (cycles per output revolution; the input shaft turns at order {ratio:g})")
    ax.set_ylabel("amplitude (arcsec)")
    ax.set_title("Order spectrum of the residual after calibration", fontsize=11)
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return _save(fig, path)
