"""Figures (PNG, matplotlib's Agg canvas; pyplot and the global backend are not touched).

* :func:`plot_surface_pair` / :func:`plot_surfaces` -- response surface and contour for a
  factor pair (all pairs), the other factors at their centre (paper Fig. 12).
* :func:`plot_predicted_vs_observed` -- predicted against observed, fitted runs and
  optionally held-out runs (paper Fig. 13).
* :func:`plot_residuals` -- residuals vs fitted, normal probability plot, residuals vs run
  order, Cook's distance vs leverage.
* :func:`plot_all` -- all of the above into a directory.

Axes are in actual units (with the unit in brackets) when the fit has a levels table,
otherwise in coded units.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy import stats

from .results import RSMResults

__all__ = [
    "plot_surface_pair",
    "plot_surfaces",
    "plot_predicted_vs_observed",
    "plot_residuals",
    "plot_all",
]


def _save(fig: Figure, path: str | Path, dpi: int) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=dpi)
    return path


def _label(results: RSMResults, factor: str) -> str:
    lv = results.levels
    if lv is None:
        return f"{factor} (coded)"
    unit = lv.unit(factor)
    return f"{factor} [{unit}]" if unit else factor


def plot_surface_pair(
    results: RSMResults,
    f1: str,
    f2: str,
    path: str | Path,
    n_grid: int = 41,
    fixed: dict[str, float] | None = None,
    dpi: int = 110,
) -> Path:
    """Surface (3-D) and contour of the fitted response over two factors.

    Parameters
    ----------
    results : RSMResults
    f1, f2 : str
        The two factors (x and y axes).
    path : str or Path
        PNG file to write.
    n_grid : int
        Grid points per axis.
    fixed : dict, optional
        Coded values of the other factors (default 0, the centre).
    dpi : int

    Returns
    -------
    Path
    """
    factors = results.factors
    for f in (f1, f2):
        if f not in factors:
            raise ValueError(f"factor '{f}' is not in the model; factors are {factors}")
    if f1 == f2:
        raise ValueError("the two factors must differ")
    box = dict(zip(factors, results.design_box()))
    i1, i2 = factors.index(f1), factors.index(f2)
    g1 = np.linspace(*box[f1], n_grid)
    g2 = np.linspace(*box[f2], n_grid)
    G1, G2 = np.meshgrid(g1, g2)
    z = np.zeros((G1.size, len(factors)))
    for f, v in (fixed or {}).items():
        z[:, factors.index(f)] = v
    z[:, i1] = G1.ravel()
    z[:, i2] = G2.ravel()
    Y = results.surface.predict_coded(z).reshape(G1.shape)
    lv = results.levels
    if lv is not None:
        A1 = lv.coded_to_actual(G1[..., None], [f1])[..., 0]
        A2 = lv.coded_to_actual(G2[..., None], [f2])[..., 0]
    else:
        A1, A2 = G1, G2
    fig = Figure(figsize=(11, 4.6))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax3.plot_surface(A1, A2, Y, cmap="viridis", linewidth=0, antialiased=True, alpha=0.95)
    ax3.contour(A1, A2, Y, zdir="z", offset=float(Y.min()), cmap="viridis", levels=12)
    ax3.set_xlabel(_label(results, f1))
    ax3.set_ylabel(_label(results, f2))
    ax3.set_zlabel(results.model.response)
    ax3.tick_params(labelsize=7)
    ax = fig.add_subplot(1, 2, 2)
    cs = ax.contourf(A1, A2, Y, levels=15, cmap="viridis")
    ax.contour(A1, A2, Y, levels=15, colors="k", linewidths=0.4)
    fig.colorbar(cs, ax=ax, label=results.model.response)
    ax.set_xlabel(_label(results, f1))
    ax.set_ylabel(_label(results, f2))
    others = [f for f in factors if f not in (f1, f2)]
    where = ", ".join(f"{f}={(fixed or {}).get(f, 0.0):g}" for f in others)
    fig.suptitle(f"{results.model.response}: {f1} x {f2}" + (f" (coded {where})" if where else ""))
    fig.tight_layout()
    return _save(fig, path, dpi)


def plot_surfaces(results: RSMResults, outdir: str | Path, prefix: str = "surface",
                  dpi: int = 110) -> list[Path]:
    """:func:`plot_surface_pair` for every factor pair; files ``<prefix>_<f1>_<f2>.png``."""
    outdir = Path(outdir)
    return [plot_surface_pair(results, a, b, outdir / f"{prefix}_{a}_{b}.png", dpi=dpi)
            for a, b in itertools.combinations(results.factors, 2)]


def plot_predicted_vs_observed(
    results: RSMResults,
    path: str | Path,
    validation: pd.DataFrame | None = None,
    units: str | None = None,
    dpi: int = 110,
) -> Path:
    """Predicted against observed response (paper Fig. 13).

    Parameters
    ----------
    results : RSMResults
    path : str or Path
        PNG file to write.
    validation : DataFrame, optional
        Held-out runs (factor columns and the response) drawn with their prediction
        intervals.
    units : {'coded', 'actual'}, optional
        Units of ``validation``'s factor columns (default the fitted data's).
    dpi : int
    """
    fig = Figure(figsize=(5.6, 5.2))
    ax = fig.add_subplot(1, 1, 1)
    obs, pred = results.model.y, results.fittedvalues
    ax.scatter(obs, pred, s=22, label=f"design runs (n={len(obs)})", zorder=3)
    lo, hi = float(min(obs.min(), pred.min())), float(max(obs.max(), pred.max()))
    if validation is not None:
        vr = results.validate(validation, units=units)
        t = vr.table
        yerr = np.vstack([t["predicted"] - t["obs_ci_lower"], t["obs_ci_upper"] - t["predicted"]])
        ax.errorbar(t["observed"], t["predicted"], yerr=yerr, fmt="s", ms=4, color="C3",
                    ecolor="C3", alpha=0.8, capsize=2,
                    label=f"validation (n={vr.n}, RMSE={vr.rmse:.3g})", zorder=4)
        lo = min(lo, float(t[["observed", "obs_ci_lower"]].min().min()))
        hi = max(hi, float(t[["observed", "obs_ci_upper"]].max().max()))
    pad = 0.05 * (hi - lo)
    ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], "k--", lw=1, label="y = x")
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_ylim(lo - pad, hi + pad)
    ax.set_xlabel(f"observed {results.model.response}")
    ax.set_ylabel(f"predicted {results.model.response}")
    ax.set_title(f"Predicted vs observed (R2 = {results.r2:.4f})")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    return _save(fig, path, dpi)


def plot_residuals(results: RSMResults, path: str | Path, dpi: int = 110) -> Path:
    """Four residual diagnostics in one PNG.

    Panels: internally studentised residuals vs fitted; normal probability plot;
    residuals vs run order; Cook's distance vs leverage (with the ``4/n`` guide).
    """
    inf = results.influence
    r = inf["student_resid"].to_numpy()
    fig = Figure(figsize=(10, 8))
    a1 = fig.add_subplot(2, 2, 1)
    a1.scatter(inf["fitted"], r, s=18)
    a1.axhline(0, color="k", lw=0.8)
    for lim in (-3, 3):
        a1.axhline(lim, color="C3", lw=0.8, ls="--")
    a1.set_xlabel("fitted")
    a1.set_ylabel("studentised residual")
    a1.set_title("Residuals vs fitted")
    a2 = fig.add_subplot(2, 2, 2)
    finite = r[np.isfinite(r)]
    if finite.size:
        (osm, osr), (slope, icept, _) = stats.probplot(finite, dist="norm")
        a2.scatter(osm, osr, s=18)
        a2.plot(osm, slope * np.asarray(osm) + icept, "k--", lw=1)
    a2.set_xlabel("normal quantile")
    a2.set_ylabel("studentised residual")
    a2.set_title("Normal probability")
    a3 = fig.add_subplot(2, 2, 3)
    a3.plot(inf.index, inf["resid"], "o-", ms=4, lw=0.8)
    a3.axhline(0, color="k", lw=0.8)
    a3.set_xlabel("run (data order)")
    a3.set_ylabel("residual")
    a3.set_title("Residuals vs run order")
    a4 = fig.add_subplot(2, 2, 4)
    a4.scatter(inf["leverage"], inf["cooks_d"], s=18)
    a4.axhline(4 / results.nobs, color="C3", lw=0.8, ls="--", label="4/n")
    a4.set_xlabel("leverage")
    a4.set_ylabel("Cook's distance")
    a4.set_title("Influence")
    a4.legend(fontsize=8)
    fig.suptitle(f"Residual diagnostics: {results.model.response}")
    fig.tight_layout()
    return _save(fig, path, dpi)


def plot_all(
    results: RSMResults,
    outdir: str | Path,
    validation: pd.DataFrame | None = None,
    dpi: int = 110,
) -> list[Path]:
    """Every figure into ``outdir``: surfaces, ``predicted_vs_observed.png``, ``residuals.png``."""
    outdir = Path(outdir)
    paths = plot_surfaces(results, outdir, dpi=dpi)
    paths.append(plot_predicted_vs_observed(results, outdir / "predicted_vs_observed.png",
                                            validation, dpi=dpi))
    paths.append(plot_residuals(results, outdir / "residuals.png", dpi=dpi))
    return paths
