"""Report parts of the full-solver Monte Carlo (section 9), its summary and the readable figures.

Figures (drawn on Agg Figures, pyplot untouched): ``mc_histograms.png`` (one panel per response with
its limits), ``mc_shares.png`` (Pareto of the variance-based total indices of the full model, first
order beside, one panel per response). The screen's ``te_curves.png`` is drawn by
:mod:`rvstudy.te_figure`.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rvstudy.capability import MIN_ESS, TIGHTEN
from rvstudy.montecarlo import tolerance_table
from rvstudy.stackup import MC_RESPONSES, PLAY_LOAD_FRACTION


def _lim(v: Any) -> str:
    return "-" if v is None else f"{v:g}"


def _pct(v: Any) -> str:
    return "/" if v is None or not math.isfinite(v) else f"{100 * v:.3g} %"


def _num(v: Any, d: int = 4) -> str:
    return "/" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{d}g}"


def capability_table(mc: dict[str, Any]) -> pd.DataFrame:
    """One row per response: n, mean, sigma, min, max, LSL, USL, Cp, Cpk, out of spec, its CI, yield."""
    rows = []
    for r, c in mc["responses"].items():
        rows.append({"response": r, "n": c["n_solver_draws"], "failed": c["n_failed"], "mean": c["mean"],
                     "std": c["std"], "min": c["min"], "max": c["max"], "LSL": c["lsl"], "USL": c["usl"],
                     "Cp": c["cp"], "Cpk": c["cpk"], "out_of_spec": c["out_of_spec_fraction"],
                     "out_of_spec_ci_lo": c["out_of_spec_ci"][0], "out_of_spec_ci_hi": c["out_of_spec_ci"][1],
                     "yield": c["yield"]})
    return pd.DataFrame(rows)


def summary_part(mc: dict[str, Any]) -> dict[str, Any]:
    """The ``monte_carlo`` object of ``summary.json``."""
    keys = ("n_solver_draws", "n_failed", "mean", "std", "min", "max", "lsl", "usl", "cp", "cpk",
            "out_of_spec_fraction", "out_of_spec_ci", "yield", "yield_ci", "contributors", "allocation")
    s: dict[str, Any] = {r: {k: c.get(k) for k in keys} for r, c in mc.get("responses", {}).items()}
    s["timing"] = mc.get("timing", {})
    s["fcl_check"] = mc.get("check_agreement", {})
    s["surface_comparison"] = mc.get("surface", {})
    s["n_features"] = mc.get("n_features")
    s["contributors_method"] = (f"Saltelli (2010) first order and Jansen (1999) total indices from a designed sample, "
                                f"blocks of {mc.get('sobol_n', 0)} rows")
    return s


def section(res: Any, add: Callable[[str], None], tab: Callable[[pd.DataFrame, str], None],
            fig_link: Callable[[str, str], None], files: dict[str, str], figs: Path, md_table: Callable) -> None:
    """Write section 9 of the report (the full-solver Monte Carlo)."""
    mc, cfg = res.mc, res.config
    tt = tolerance_table(mc["tolerances"])
    tab(tt, "mc_tolerances")
    tab(mc["features"], "mc_features")
    for line in _intro_lines(res):
        add(line)
    add(md_table(tt) + "\n")
    cap = capability_table(mc)
    tab(cap, "mc_capability")
    add("### Stack-up statistics (arcmin)\n")
    add("Cp = (USL - LSL)/(6 sigma) (both limits only), Cpk = the smaller of (USL - mean)/(3 sigma) and "
        "(mean - LSL)/(3 sigma) over the limits given; out-of-spec interval: exact binomial (Clopper-Pearson) 95 %.\n")
    add(md_table(cap) + "\n")
    if cfg.figures:
        files["mc_histograms_png"] = str(_histograms(mc, figs / "mc_histograms.png"))
    fig_link("mc_histograms_png", "Monte Carlo histograms with the specification limits")
    tab(mc["draws"], "mc_draws")
    sob = mc.get("sobol")
    if sob is not None and len(sob):
        tab(sob, "mc_contributors")
        for line in _contributor_lines(mc, sob, md_table):
            add(line)
        if cfg.figures:
            files["mc_shares_png"] = str(_pareto(sob, figs / "mc_shares.png"))
        fig_link("mc_shares_png", "Pareto of the contributors")
    al = mc.get("allocation")
    if al is not None and len(al):
        tab(al, "mc_allocation")
        for line in _allocation_lines(mc, al, md_table):
            add(line)
    chk = mc.get("check")
    if chk is not None and len(chk):
        tab(chk, "mc_fcl_check")
        for line in _check_lines(mc, chk, md_table):
            add(line)
    surf = mc.get("surface", {})
    if surf:
        st = pd.DataFrame([{"response": r, **v} for r, v in surf.items()])
        tab(st, "mc_surface_comparison")
        add("### The quadratic surface on the same draws (comparison only)\n")
        add("The fitted response surface knows only the RSM factors; it is evaluated at each draw's default-instance "
            "value (pin 0's pitch, disc 0 hole 0) or the mean over the pins (all-pins errors). Difference = surface - "
            "full solver, arcmin:\n")
        add(md_table(st) + "\n")
    add(_throughput_text(mc["timing"]))


def _intro_lines(res: Any) -> list[str]:
    """Heading of section 9 and its two introductory paragraphs: how the draws are solved, and the responses.

    Parameters
    ----------
    res : rvstudy.study.StudyResult
        The run (its ``mc``, ``config`` and ``reducer``).

    Returns
    -------
    list of str
        Report lines.
    """
    mc, cfg, t = res.mc, res.config, res.mc["timing"]
    law = "contact model " + cfg.contact_models()["monte_carlo"]
    return [
        "## 9. Monte Carlo tolerance stack-up through the full solver\n",
        f"Reducer: {reducer_text(res.reducer)}. Every draw is a case solved by the quasi-static solver (analytic "
        f"contact provider, {cfg.steps} steps per output revolution, {law}, load "
        f"{cfg.load_Nm:g} N m); {mc['n_features']} toleranced features are drawn per case (each pin's radius, pitch "
        "and radial position, each cam, crank, hole and disc, as the scope of each tolerance says; positional "
        "errors as independent x and y components). "
        f"{t['independent_draws']} independent draws (seed [{cfg.seed}, 2]) give the statistics; "
        f"{t['design_draws']} more solver draws form the designed sample of the contributors. "
        "Failed solves and invalid draws count as out of spec.\n",
        f"Responses: **TE peak-to-peak** (the angular transmission error); **two-direction play at +-3 % of rated "
        f"torque** ({PLAY_LOAD_FRACTION * cfg.rated_Nm:.3g} N m of {cfg.rated_Nm:g} N m rated): at "
        f"{mc['play_positions']} locked input positions over one output revolution, output angle at +3 % minus that "
        "at -3 % (TE of direction -1 minus TE of direction +1 at that load), the largest over the positions: a "
        "*proxy* for lost motion, read on rvdyn.stiffness's elastic (friction-free) curve, not its lost-motion "
        "figure (which adds the curve's friction band and is read at one input angle; rvdyn.stiffness cannot be "
        "run per draw: its rigid zero-torque point refuses preloaded draws); **torsional rigidity** b/a on the same "
        "elastic curve (secant 3 %..100 % of rated torque, both sides averaged), the smallest over the positions; "
        "**mean |TE|**, the paper's response, without a specification.\n",
    ]


def _contributor_lines(mc: dict[str, Any], sob: pd.DataFrame, md_table: Callable) -> list[str]:
    """The contributors subsection: how the variance-based indices are estimated, one table per response.

    Parameters
    ----------
    mc : dict
        The Monte Carlo results (:func:`rvstudy.stackup.run_full_mc`).
    sob : DataFrame
        The indices, one row per response and tolerance.
    md_table : callable
        DataFrame -> Markdown table.

    Returns
    -------
    list of str
        Report lines.
    """
    lines = ["### Contributors (variance-based indices of the full model)\n",
             f"From a designed sample (not estimated from the independent draws): A and B are the first two blocks "
             f"of {mc['sobol_n']} independent draws; for each tolerance a block of A with that tolerance's features "
             "taken from B. First order: Saltelli (2010); total: Jansen (1999); 95 % bootstrap intervals over the "
             "rows. A tolerance's index covers all its features together (e.g. all pin radii). With blocks this "
             "small the intervals are wide: read the ranking, not the digits.\n"]
    for r in MC_RESPONSES:
        s = sob[sob["response"] == r]
        if len(s):
            lines.append(f"**{MC_RESPONSES[r]}**\n")
            lines.append(md_table(s.drop(columns="response")) + "\n")
    return lines


def _allocation_lines(mc: dict[str, Any], al: pd.DataFrame, md_table: Callable) -> list[str]:
    """The tolerance-allocation subsection: the recommendation per response with a limit, then the best
    three tightenings of each response.

    Parameters
    ----------
    mc : dict
        The Monte Carlo results (:func:`rvstudy.stackup.run_full_mc`).
    al : DataFrame
        The allocation table (one row per response, tolerance and factor, with its ``gain``).
    md_table : callable
        DataFrame -> Markdown table.

    Returns
    -------
    list of str
        Report lines.
    """
    lines = ["### Tolerance allocation\n",
             f"Yield if one tolerance's spread is scaled by {', '.join(f'{f:g}' for f in TIGHTEN)}, estimated by "
             "re-weighting the existing independent draws with the likelihood ratio of the tightened over the drawn "
             f"distribution (product over the tolerance's features; no new solves). Rows with an effective sample "
             f"size below {MIN_ESS:g} are marked unreliable (a tolerance with many features, e.g. 40 pins, loses "
             "effective draws fast).\n"]
    for r, c in mc["responses"].items():
        rec = c.get("allocation")
        if c["usl"] is None and c["lsl"] is None:
            continue
        if rec is None:
            lines.append(f"- {r}: no reliable yield gain from tightening one tolerance (yield now {_pct(c['yield'])}).")
        else:
            lines.append(
                f"- {r}: tighten **{rec['tolerance']}** to {rec['factor']:g} x its spread (std "
                f"{rec['std_now']:.4g} -> {rec['std_new']:.4g}): yield {_pct(c['yield'])} -> {_pct(rec['yield'])} "
                f"(effective draws {rec['ess']:.0f})" + (f", reaching the target {_pct(rec['target'])}."
                                                          if rec["reaches_target"] else
                                                          f"; the target {_pct(rec['target'])} is not reached by one "
                                                          "tolerance within these factors."))
    lines.append("")
    best = al.sort_values("gain", ascending=False).groupby("response").head(3)
    lines.append(md_table(best) + "\n")
    return lines


def _check_lines(mc: dict[str, Any], chk: pd.DataFrame, md_table: Callable) -> list[str]:
    """The fcl-check subsection: agreement of the fcl and analytic providers on the check draws, and their table.

    Parameters
    ----------
    mc : dict
        The Monte Carlo results (its ``check_agreement``).
    chk : DataFrame
        The check draws, both providers' responses.
    md_table : callable
        DataFrame -> Markdown table.

    Returns
    -------
    list of str
        Report lines.
    """
    a = mc["check_agreement"]
    return ["### fcl check of the analytic solver\n",
            f"The first {len(chk)} draws solved again with the fcl contact provider (python-fcl distances on the "
            "exported meshes): " + "; ".join(f"{r}: max |fcl - analytic| {_num(v['max_abs_diff'], 3)} arcmin, RMS "
                                            f"{_num(v['rms_diff'], 3)} (n = {v['n']})" for r, v in a.items()) + ".\n",
            md_table(chk) + "\n"]


def _throughput_text(t: dict[str, Any]) -> str:
    """The throughput paragraph of section 9 from the Monte Carlo's ``timing``: draws, solves, wall and
    worker seconds, draws per second per worker, solves computed and taken from the cache."""
    busy = t.get("worker_s")
    return (f"Throughput: {t['full_solver_draws']} full-solver draws ({t['solves_per_draw']} solves each: the TE "
            "revolution, and +-3 % and +-100 % of rated torque at the locked positions; one worker task per draw) in "
            f"{t['wall_s']:.1f} s wall on {t['workers']} worker(s)"
            + (f" (solved beside the other stages' cases; {busy:.1f} worker-seconds on the draws)" if busy else "")
            + f": {t['draws_per_s_per_worker']:.3g} draws per second per worker"
            + (" (draws / worker-seconds on the draws)" if busy else "")
            + f", with {t['analytic_solves_computed']} analytic solves computed now and "
            f"{t['analytic_solves_reused']} taken from the cache"
            + (" (a rerun: the figure is not the solver's speed)" if t['analytic_solves_reused'] else "")
            + ", plus the fcl check.\n")


def reducer_text(d: Any) -> str:
    """``Z1 12 / Z2 36, 40 pins, 39 lobes, ratio 121, ..., 2 cranks at 0/180 deg`` style description of a Design."""
    cranks = "/".join(f"{a:g}" for a in d.crank_angles_deg)
    return (f"Z1 {d.z_sun} / Z2 {d.z_planet}, {d.z_pins} pins, {d.z_disc} lobes, ratio {d.ratio:.6g}, pin circle "
            f"{d.pin_circle_diameter_mm:g} mm, e {d.eccentricity_mm:g} mm, pin radius {d.pin_radius_mm:g} mm, "
            f"{d.n_cranks} cranks at {cranks} deg")


# ---------------------------------------------------------------------------------------------- figures
def _save(fig: Any, path: Path) -> Path:
    from rvstudy.screen import save_figure_atomic

    return save_figure_atomic(fig, path)


def _histograms(mc: dict[str, Any], path: Path) -> Path:
    from matplotlib.figure import Figure

    draws = mc["draws"]
    resp = list(MC_RESPONSES)
    cols = 2
    rows = math.ceil(len(resp) / cols)
    fig = Figure(figsize=(6.5 * cols, 4 * rows))
    for i, r in enumerate(resp):
        ax = fig.add_subplot(rows, cols, i + 1)
        y = draws[r].to_numpy(float)
        y = y[np.isfinite(y)]
        c = mc["responses"][r]
        if y.size:
            ax.hist(y, bins=min(50, max(5, y.size // 10)), color="0.55", edgecolor="white",
                    label=f"full solver (n={y.size})")
        span = float(np.ptp(y)) if y.size > 1 else 0.0
        off = []
        for v, lab, col in ((c["lsl"], "LSL", "tab:blue"), (c["usl"], "USL", "tab:red")):
            if v is None:
                continue
            if y.size and span > 0 and (v < y.min() - 2 * span or v > y.max() + 2 * span):
                # a limit far from every draw would squash the histogram: name it instead of drawing it
                k = (v - c["mean"]) / c["std"] if c["std"] else float("nan")
                off.append(f"{lab} {v:g} off scale ({k:+.1f} sigma from the mean)")
            else:
                ax.axvline(v, color=col, ls="--", lw=1.5, label=f"{lab} {v:g}")
        if off:
            ax.text(0.98, 0.97, "\n".join(off), transform=ax.transAxes, ha="right", va="top", fontsize=7,
                    color="tab:red")
        ax.axvline(c["mean"], color="k", lw=1, label=f"mean {c['mean']:.3g}")
        ax.set_xlabel(MC_RESPONSES[r], fontsize=8)
        ax.set_ylabel("draws")
        cpk = "/" if c["cpk"] is None else f"{c['cpk']:.2f}"
        ax.set_title(f"Cpk {cpk}, out of spec {_pct(c['out_of_spec_fraction'])}", fontsize=9)
        ax.legend(fontsize=7)
    fig.suptitle("Full-solver Monte Carlo: distribution of each response against its limits")
    fig.tight_layout()
    return _save(fig, path)


def _pareto(sob: pd.DataFrame, path: Path) -> Path:
    from matplotlib.figure import Figure

    resp = [r for r in MC_RESPONSES if (sob["response"] == r).any()]
    cols = 2
    rows = math.ceil(len(resp) / cols)
    fig = Figure(figsize=(7 * cols, 4.8 * rows))
    for i, r in enumerate(resp):
        ax = fig.add_subplot(rows, cols, i + 1)
        s = sob[sob["response"] == r].sort_values("total", ascending=False)
        x = np.arange(len(s))
        tot = s["total"].clip(lower=0).to_numpy()
        ax.bar(x - 0.2, tot, 0.4, color="tab:blue", label="total index")
        ax.bar(x + 0.2, s["first_order"].clip(lower=0).to_numpy(), 0.4, color="tab:orange", label="first-order index")
        if "total_lo" in s:
            ax.errorbar(x - 0.2, tot, yerr=[np.clip(tot - s["total_lo"].to_numpy(), 0, None),
                                            np.clip(s["total_hi"].to_numpy() - tot, 0, None)],
                        fmt="none", ecolor="k", lw=0.8, capsize=2)
        ax.set_xticks(x)
        ax.set_xticklabels(s["tolerance"], rotation=60, ha="right", fontsize=7)
        ax.set_ylabel("index (share of variance)")
        ax.set_title(MC_RESPONSES[r], fontsize=9)
        ax2 = ax.twinx()
        cum = np.cumsum(tot) / tot.sum() if tot.sum() > 0 else np.zeros_like(tot)
        ax2.plot(x, cum, "k.-", lw=1, label="cumulative share of the total indices")
        ax2.set_ylim(0, 1.05)
        ax2.set_ylabel("cumulative", fontsize=8)
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="center right")
    fig.suptitle("Contributors: variance-based indices of the full solver model (designed sample, 95 % bootstrap bars)")
    fig.tight_layout()
    return _save(fig, path)
