"""Report of a calibration: Markdown, PNG figures and the JSON object, written atomically.

:func:`write_report` writes into ``out_dir``:

* ``report.md``: verdict, effects found (value, unit, 95 % interval, meaning, tests,
  indistinguishable alternatives), what is unexplained, per-run residual statistics before and
  after (RMS, peak, Ljung-Box p, the reducer's key orders: 1, Zc, Zp, their doubles, the input orders and
  neighbours), direction and load
  dependence, the iteration log, the data notes and the method;
* ``residual_before_after.png``: the residual of every run against output angle, before (declared
  model) and after;
* ``order_spectrum.png``: the amplitude of each order per output revolution, before and after;
* ``result.json``: the ``--json`` object.

Every file is first written to a temporary folder inside ``out_dir`` and then moved into place
with ``os.replace``; ``report.md`` goes last, so a complete report.md means a complete report.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from rvcalib.effects import INPUT_ENCODER_RADIUS_MM, OUTPUT_ENCODER_RADIUS_MM
from rvcalib.orders import key_orders, orders_that_matter
from rvcalib.results import CalibrationResult
MAX_PANELS = 12


def _json_default(o: Any) -> Any:
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _clean(o: Any) -> Any:
    """Replace NaN/inf by None (strict JSON)."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.floating):
        return _clean(float(o))
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    return o


def result_json(result: CalibrationResult, figures: list[str] | None = None, report: str | None = None) -> str:
    """The ``--json`` object as a string (NaN written as null)."""
    d = result.to_dict()
    if figures is not None:
        d["figures"] = figures
    if report is not None:
        d["report"] = report
    return json.dumps(_clean(d), indent=2, default=_json_default)


def _fmt(v: float | None, nd: int = 4) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{nd}g}"


def _fig_residuals(result: CalibrationResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = result.dataset.runs[:MAX_PANELS]
    n = len(runs)
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.9 * n + 0.8), sharex=True, squeeze=False)
    for ax, run, rb, ra in zip(axes[:, 0], runs, result.residual_before, result.residual_after):
        x = (run.input_deg - run.input_deg[0]) * run.direction / run.ratio
        ax.plot(x, rb, color="0.6", lw=0.8, label="before (declared model)")
        ax.plot(x, ra, color="C0", lw=0.8, label="after")
        ax.axhline(0.0, color="k", lw=0.4)
        ax.set_ylabel("arcsec")
        ax.set_title(f"run {run.run}: load {run.load_Nm:g} N m, direction {run.direction:+d}", fontsize=9)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("output angle travelled (deg)")
    title = "Residual = measured TE - model TE"
    if len(result.dataset.runs) > MAX_PANELS:
        title += f" (first {MAX_PANELS} of {len(result.dataset.runs)} runs)"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fig_spectrum(result: CalibrationResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sb, sa = result.before.spectrum, result.after.spectrum
    k = np.arange(min(sb.size, sa.size))
    fig, ax = plt.subplots(figsize=(9, 3.6))
    ax.vlines(k - 0.15, 0, np.abs(sb[: k.size]), color="0.6", lw=1.5, label="before (declared model)")
    ax.vlines(k + 0.15, 0, np.abs(sa[: k.size]), color="C0", lw=1.5, label="after")
    marks = orders_that_matter(result.dataset.design)
    for o in marks:
        if o < k.size:
            ax.axvline(o, color="C3", lw=0.5, ls=":")
    ax.set_yscale("log")
    ax.set_ylim(bottom=max(1e-4, 0.3 * float(np.min(np.abs(sa[1:k.size]) + 1e-12))))
    ax.set_xlabel("order (cycles per output revolution); dotted: " + ", ".join(map(str, marks)))
    ax.set_ylabel("amplitude (arcsec)")
    ax.set_title("Order spectrum of the residual (sample-weighted mean over runs; order 0 = |mean|)", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(result: CalibrationResult, figures: list[str]) -> str:
    """The Markdown report."""
    ds = result.dataset
    L: list[str] = []
    L.append(f"# rv-calibrate report: `{ds.path}`")
    L.append("")
    L.append(f"**{result.verdict}**")
    L.append("")
    red = ds.reducer()
    L.append(f"- reducer: ratio {red['ratio']:g} (Z1 {red['z_sun']}, Z2 {red['z_planet']}, {red['z_pins']} pins, "
             f"{red['z_disc']} lobes, pin circle {red['pin_circle_diameter_mm']:g} mm); design from "
             f"{'the default (paper) design' if red['source'] == 'default' else red['source']}")
    L.append(f"- status: `{result.status}`")
    L.append(f"- residual RMS before (declared errors only): {result.rms_before:.4g} arcsec; after: "
             f"{result.rms_after:.4g} arcsec (physical and measurement effects only: {result.after_physical.rms:.4g})")
    L.append(f"- noise estimate (second differences of the final residual): {result.noise_arcsec:.4g} arcsec; "
             f"final residual white (Ljung-Box): {'yes' if result.after.white else 'no'}")
    L.append(f"- {len(ds.runs)} runs, {ds.n_samples} samples, screening grid {result.steps} points per output "
             "revolution (the fits and the residuals solve the model at every reading), "
             f"{result.seconds:.1f} s ({result.solver_stats.get('solves', 0)} rvdyn solves)")
    L.append("")
    L.append("## Effects found")
    L.append("")
    if result.effects:
        L.append("| effect | value | unit | 95 % interval | angle (deg) | explained | F | p | dBIC | "
                 "indistinguishable from |")
        L.append("|---|---|---|---|---|---|---|---|---|---|")
        for e in result.effects:
            alts = ", ".join(f"`{a['name']}` {a['value']:.4g} {a['unit']} (RMS {a['rms_after_arcsec']:.3g})"
                             for a in e.alternatives[:6]) + (" ..." if len(e.alternatives) > 6 else "")
            if e.implied_total is not None:
                alts += f"; declared {e.declared_value:.5g} {e.unit}, implied total {e.implied_total:.5g} {e.unit}"
            bnd = f" (at the {e.at_bound} bound: one-sided)" if e.at_bound else ""
            L.append(f"| `{e.name}` ({e.family}) | {e.value:.5g} | {e.unit} | [{e.ci_low:.5g}, {e.ci_high:.5g}]{bnd} | "
                     f"{_fmt(e.angle_deg)} | {e.explained_fraction:.3f} | {_fmt(e.F)} | {_fmt(e.p_value, 3)} | "
                     f"{_fmt(e.delta_bic)} | {alts or '-'} |")
        L.append("")
        for e in result.effects:
            L.append(f"- `{e.name}`: {e.meaning}")
            for q in e.equivalents:
                implied = (f" (design value implied: {q['implied_design_value']:.5g} {q['unit']})"
                           if "implied_design_value" in q else "")
                L.append(f"  - the same TE as `{q['parameter']}` = {q['value']:+.5g} {q['unit']} [{q['ci_low']:.5g}, "
                         f"{q['ci_high']:.5g}]{implied}: {q['meaning']}; the data cannot tell the two apart")
        L.append("")
        L.append("Values of two-component effects are magnitudes; their direction is the angle. The interval is "
                 "the Jacobian interval of the joint nonlinear fit (t quantile), widened for lag-1 residual "
                 "autocorrelation. \"Indistinguishable\" candidates reproduce the fitted signature within the noise "
                 "(chi-square 95 %): the data cannot tell them apart (e.g. pins 20 apart, or the cam of crank 0 on "
                 "disc 1 and of crank 1 on disc 0: the TE of this two-disc design repeats under a half-turn).")
    else:
        L.append("None: no candidate effect passed the F test (Bonferroni) and the BIC.")
    L.append("")
    L.append("## Unexplained (outside the library)")
    L.append("")
    if result.unexplained:
        L.append("| term | order | amplitude (arcsec) | phase (deg) | explained | what it can be |")
        L.append("|---|---|---|---|---|---|")
        for u in result.unexplained:
            what = (u.note or "-") + "".join(f"; or `{q['parameter']}` = {q['value']:+.5g} {q['unit']} ({q['meaning']})"
                                             for q in u.equivalents)
            L.append(f"| {u.label} | {u.order} | {abs(u.amplitude_arcsec):.4g} | {_fmt(u.phase_deg)} | "
                     f"{u.explained_fraction:.3f} | {what} |")
        L.append("")
        L.append("These are labelled empirical terms (``A cos(k theta_out + phase)``, common to all runs): no physical "
                 "or measurement candidate explained this part of the residual better than a pure harmonic, so it "
                 "is not attributed to a physical effect.")
    else:
        L.append("Nothing was absorbed by empirical terms.")
    if not result.after.white:
        L.append("")
        L.append("The final residual is not white: dominant orders per run: " + "; ".join(
            f"run {r.run}: " + ", ".join(f"{k} ({a:.3g})" for k, a in r.dominant) for r in result.after.runs))
    L.append("")
    dsh = result.datasheet
    if dsh.get("calibrated") or dsh.get("error"):
        L.append("## Datasheet as calibrated")
        L.append("")
        if dsh.get("error"):
            L.append(f"Not computed: {dsh['error']}.")
        else:
            m, c = dsh["model"], dsh["calibrated"]
            ci = dsh.get("rigidity_ci")
            L.append(f"`rvdyn stiffness` of the reducer as declared and as calibrated (`calibrated_case` in the JSON: "
                     f"every physical effect found), rated torque {c['rated_torque_Nm']:g} N m:")
            L.append("")
            L.append("| figure | declared | calibrated |")
            L.append("|---|---|---|")
            for k, lab in (("torsional_rigidity_Nm_per_arcmin", "torsional rigidity (N m/arcmin)"),
                           ("lost_motion_arcmin", "lost motion (arcmin)"), ("backlash_arcmin", "backlash (arcmin)"),
                           ("hysteresis_loss_arcmin", "hysteresis loss (arcmin)")):
                extra = f" [{ci[0]:.4g}, {ci[1]:.4g}]" if ci and k.startswith("torsional") else ""
                L.append(f"| {lab} | {m[k]:.4g} | {c[k]:.4g}{extra} |")
            L.append("")
            L.append(f"{dsh['note']}.")
        L.append("")
    L.append("## Identifiability groups and recommended runs")
    L.append("")
    if result.stopped_by and not result.stopped_by.startswith("nothing"):
        L.append(f"**Stopped early:** {result.stopped_by}.")
        L.append("")
    if not result.groups:
        L.append("No group: every effect found is the only candidate that fits as well.")
    for i, g in enumerate(result.groups):
        mem = "; ".join(f"`{m['name']}` {m['value']:.4g}"
                        + (f" or {m['value_other_fit']:.4g}" if m.get("value_other_fit") is not None else "")
                        + f" {m['unit']}"
                        + (f" (RMS {m['rms_after_arcsec']:.3g})" if m.get("rms_after_arcsec") is not None else "")
                        for m in g["members"])
        L.append(f"- group {i} ({g['kind']}): {mem}. {g.get('note', '')}")
    for rec in result.recommended_runs:
        if rec.get("run"):
            L.append(f"- to split group {rec['group']}: run at {rec['run']['load_Nm']:g} N m, direction "
                     f"{rec['run']['direction']:+d} ({rec['criterion']}; log det gain {rec['log_det_gain']:.3g})")
        else:
            L.append(f"- group {rec['group']}: {rec.get('reason', 'no run recommended')}")
    L.append("")
    L.append("## Figures")
    L.append("")
    for f in figures:
        L.append(f"![{f}]({f})")
        L.append("")
    L.append("## Runs")
    L.append("")
    L.append("| run | load (N m) | dir | samples | dropped | RMS before | RMS after | peak before | peak after | "
             "mean before | mean after | LB p before | LB p after |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for run, b, a in zip(ds.runs, result.before.runs, result.after.runs):
        dr = ", ".join(f"{k} {v}" for k, v in run.dropped.items() if v) or "-"
        L.append(f"| {run.run} | {run.load_Nm:g} | {run.direction:+d} | {run.n} | {dr} | {b.rms:.4g} | {a.rms:.4g} | "
                 f"{b.peak:.4g} | {a.peak:.4g} | {b.mean:.4g} | {a.mean:.4g} | {_fmt(b.ljung_box_p, 3)} | "
                 f"{_fmt(a.ljung_box_p, 3)} |")
    L.append("")
    L.append("Residuals in arcsec. LB p: Ljung-Box p-value (small = not white).")
    L.append("")
    L.append("### Order amplitudes (arcsec; order 0 is the mean)")
    L.append("")
    show = key_orders(ds.design)
    L.append("| run | | " + " | ".join(str(o) for o in show) + " |")
    L.append("|---|---|" + "---|" * len(show))
    for run, b, a in zip(ds.runs, result.before.runs, result.after.runs):
        for tag, d in (("before", b), ("after", a)):
            cells = []
            for o in show:
                v = d.orders.get(o)
                if o > 0 and o >= d.nyquist_order:
                    cells.append("*")
                else:
                    cells.append("-" if v is None or not math.isfinite(v) else f"{v:.3g}")
            L.append(f"| {run.run} | {tag} | " + " | ".join(cells) + " |")
    L.append("")
    L.append("`*`: at or above half the samples per output revolution: not resolved by the sampling (aliased).")
    L.append("")
    L.append("### Direction and load dependence of the run means")
    L.append("")
    for tag, dep in (("before", result.before.dependence), ("after", result.after.dependence)):
        L.append(f"- {tag}: offset {_fmt(dep.get('offset_arcsec'))} arcsec, direction term "
                 f"{_fmt(dep.get('direction_arcsec'))} arcsec, direction x load term "
                 f"{_fmt(dep.get('direction_load_arcsec_per_Nm'))} arcsec/(N m)")
    L.append(f"- {result.before.dependence.get('note', '')}")
    L.append("")
    L.append("## Iterations")
    L.append("")
    for it in result.iterations:
        L.append(f"### Iteration {it['iteration']}: {it.get('decision', '')}")
        L.append("")
        if "ranking" in it:
            L.append("Screening (explained fraction of the coarse residual; with its best partner):")
            L.append("")
            for d in it["ranking"][:6]:
                pe = d.get("pair_explained_fraction")
                pair = f", with `{d['partner']}` {pe:.3f}" if d.get("partner") and pe is not None else ""
                L.append(f"- `{d['name']}` {d['explained_fraction']:.3f}{pair}")
            if it.get("validated"):
                L.append("")
                L.append("Validated through the nonlinear model: " + ", ".join(
                    f"`{d['name']}` {d['explained_fraction']:.3f}" for d in it["validated"]))
            hb = it.get("harmonic_best")
            if hb:
                L.append("")
                L.append(f"Best harmonic-only model: {hb['label']} explains {hb['explained_fraction']:.3f} "
                         f"(p {hb['p']:.3g}).")
            pb = it.get("physical_best")
            if pb:
                L.append(f"Best physical candidate: `{pb['name']}` explains {pb['explained_fraction']:.3f} "
                         f"(F {pb['F']:.4g}, p {pb['p']:.3g}, dBIC {pb['delta_bic']:.4g}); threshold p "
                         f"{it['threshold_p']:.3g} (0.01 / {it['hypotheses']} hypotheses).")
            if it.get("encompassing"):
                enc = it["encompassing"]
                L.append(f"Encompassing test: the physical candidate adds to the harmonic p "
                         f"{enc['physical_adds_to_harmonic_p']:.3g}; the harmonic adds to it p "
                         f"{enc['harmonic_adds_to_physical_p']:.3g}.")
            if it.get("full"):
                f = it["full"]
                L.append(f"On all samples: F {f['F']:.4g}, p {f['p']:.3g}, dBIC {f['delta_bic']:.4g}.")
        L.append("")
    L.append("## Data notes")
    L.append("")
    for n in result.notes or ["none"]:
        L.append(f"- {n}")
    L.append("")
    L.append("## Method")
    L.append("")
    L.append(
        "Measured TE = output_deg - input_deg/121 (arcsec); model TE = rvdyn quasi-static TE (analytic contacts) of "
        "each run's declared errors, load and direction, solved exactly at every measured input angle (modulo one "
        "output revolution; no interpolation). Screening uses a uniform grid of one output revolution. Candidates: every Table 4 error and instance, the rvdyn model "
        "options (torsional compliance, output friction, cam-bearing clearance, thermal growth where the "
        "temperature varies, pin-circle ovality) and encoder eccentricities (assumed scale radii: output "
        f"{OUTPUT_ENCODER_RADIUS_MM:g} mm, input {INPUT_ENCODER_RADIUS_MM:g} mm; the eccentricity scales with the "
        "assumed radius). Each iteration screens every candidate's rvdyn signature against the residual, "
        "validates the leading ones through the nonlinear model, adds the best if it passes the F test "
        "(Bonferroni over all candidates and harmonic orders) and lowers the BIC, and only if it explains "
        "what the best harmonic-only model cannot; otherwise the structure is reported as unexplained. All "
        "parameters are then refitted jointly through rvdyn (scipy least_squares) and effects that became "
        "insignificant are removed.")
    L.append("")
    return "\n".join(L)


def write_report(result: CalibrationResult, out_dir: str | Path) -> dict[str, Any]:
    """Write the report files atomically into ``out_dir``.

    Returns
    -------
    dict
        ``report`` (path of report.md), ``json`` (result.json), ``figures`` (PNG paths).
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out '{out}' exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".rv-calibrate-", dir=out))
    try:
        figs = ["residual_before_after.png", "order_spectrum.png"]
        _fig_residuals(result, tmp / figs[0])
        _fig_spectrum(result, tmp / figs[1])
        (tmp / "result.json").write_text(result_json(result, figs, "report.md"), encoding="utf-8")
        (tmp / "report.md").write_text(markdown(result, figs), encoding="utf-8")
        for name in figs + ["result.json", "report.md"]:
            os.replace(tmp / name, out / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"report": str(out / "report.md"), "json": str(out / "result.json"),
            "figures": [str(out / f) for f in figs]}
