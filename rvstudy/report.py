"""The study report: one Markdown file with the figures, plus every table as CSV and Parquet.

Every table of ours is computed from the :class:`rvstudy.study.StudyResult` of the run; the paper's
columns come from :mod:`rvpaper`. All files are written atomically (temporary file in the same
folder, then :func:`os.replace`).

Layout of ``OUT``::

    report.md            the report (figures linked relatively)
    summary.json         key numbers (also what ``rv-stackup --json`` prints)
    config.json          the options of the run
    tables/*.csv|parquet every table of the report and the raw per-case tables
    figures/*.png        screen, sweeps, surfaces/contours, validation, Monte Carlo
    cache/               solved cases (content-keyed; reused by the next run)
"""
from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rvcad.atomic import atomic_path
from rvcad.errors import ERROR_TYPES
from rvstudy.screen import plot_screen, plot_sweeps
from rvdyn.te import write_table_atomic
import rvpaper as paper
from rvdyn.cache import write_text_atomic
from rvstudy.augment_section import augment_section
from rvstudy.paper_readings import readings_section
import rvstudy.report_mc as report_mc
from rvstudy.study import RESPONSE_LABEL, RESPONSES, FitBundle, StudyResult
from rvstudy.te_figure import plot_te_figure

PRIMARY = "mean_abs_arcmin"


# ---------------------------------------------------------------------------------------------- writers
def write_table(df: pd.DataFrame, tables: Path, name: str) -> dict[str, str]:
    """Write ``name.csv`` and ``name.parquet`` atomically; returns their paths."""
    csv = write_table_atomic(df, tables / f"{name}.csv")
    pq = tables / f"{name}.parquet"
    clean = df.copy()
    for c in clean.columns:
        if clean[c].dtype == object:
            clean[c] = clean[c].map(lambda v: v if v is None or isinstance(v, str) else str(v))
    with atomic_path(pq) as tmp:
        clean.to_parquet(tmp, index=False)
    return {"csv": str(csv), "parquet": str(pq)}


def _atomic_plot(fn: Callable[[Path], Any], path: Path) -> Path:
    """Call ``fn(tmp_path)`` (a plot function that writes a PNG) and move the file to ``path`` atomically."""
    with atomic_path(path, suffix=path.suffix) as tmp:
        fn(tmp)
    return path


def _fmt(v: Any, digits: int = 4) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(v):
            return "/" if math.isnan(v) else str(v)
        a = abs(v)
        if a != 0 and (a < 10 ** (-digits) or a >= 1e6):
            return f"{v:.{digits - 1}e}"
        return f"{v:.{digits}g}" if a >= 1 else f"{v:.{digits}f}".rstrip("0").rstrip(".") if a else "0"
    return str(v).replace("|", "\\|")


def md_table(df: pd.DataFrame, index: bool = False, digits: int = 4) -> str:
    """A DataFrame as a Markdown table (numbers to ``digits`` significant digits, NaN as ``/``)."""
    d = df.reset_index() if index else df
    cols = [str(c) for c in d.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in d.itertuples(index=False):
        lines.append("| " + " | ".join(_fmt(v, digits) for v in row) + " |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- comparisons
def table6_compare(res: StudyResult) -> pd.DataFrame:
    """Our design runs beside the paper's Table 6 (coded factors, ours mean|TE| and pp, paper value)."""
    d = res.design
    cols = ["run"] + res.factors.names + [f"{f}_actual" for f in res.factors.names]
    out = d[cols].copy()
    out["mean_abs_arcmin"] = d["mean_abs_arcmin"]
    out["pp_arcmin"] = d["pp_arcmin"]
    if "paper_te_arcmin" in d:
        out["paper_te_arcmin"] = d["paper_te_arcmin"]
    out["status"] = d["status"]
    return out


def table7_compare(b: FitBundle, with_paper: bool) -> pd.DataFrame:
    """Our ANOVA beside the paper's Table 7 (``sum_sq, df, F, p`` each; significance at 0.05)."""
    a = b.results.anova.copy()
    out = pd.DataFrame({"source": a.index, "sum_sq": a["sum_sq"].to_numpy(), "df": a["df"].to_numpy(),
                        "F": a["F"].to_numpy(), "p": a["p"].to_numpy()})
    out["significant"] = [bool(p < 0.05) if np.isfinite(p) else None for p in out["p"]]
    if with_paper:
        p7 = paper.table7_anova()
        missing = [s for s in p7.index if s not in set(out["source"])]  # terms our fit could not carry
        if missing:
            extra = pd.DataFrame({"source": missing, "sum_sq": np.nan, "df": np.nan, "F": np.nan, "p": np.nan,
                                  "significant": None})
            out = pd.concat([out.iloc[:-4], extra, out.iloc[-4:]], ignore_index=True)
        out["paper_sum_sq"] = [float(p7.loc[s, "sum_sq"]) if s in p7.index else np.nan for s in out["source"]]
        out["paper_df"] = [int(p7.loc[s, "df"]) if s in p7.index else np.nan for s in out["source"]]
        out["paper_F"] = [float(p7.loc[s, "F"]) if s in p7.index else np.nan for s in out["source"]]
        out["paper_p"] = [paper.p_value(p7.loc[s, "p"]) if s in p7.index else np.nan for s in out["source"]]
        out["paper_significant"] = [bool(p < 0.05) if np.isfinite(p) else None for p in out["paper_p"]]
    return out


def eq8_compare(b: FitBundle, with_paper: bool) -> pd.DataFrame:
    """Our actual-unit coefficients (full quadratic) beside the paper's Eq. 8."""
    ct = b.results.coefficients("actual")
    out = pd.DataFrame({"term": ct.index, "coef": ct["coef"].to_numpy(), "std_err": ct["std_err"].to_numpy(),
                        "coded_coef": b.results.params.reindex(ct.index).to_numpy()})
    if with_paper:
        e8 = paper.eq8_coefficients()
        missing = [t for t in e8.index if t not in set(out["term"])]
        if missing:
            out = pd.concat([out, pd.DataFrame({"term": missing})], ignore_index=True)
        out["paper_coef"] = [float(e8.get(t, np.nan)) for t in out["term"]]
    return out


def eq9_compare(b: FitBundle, with_paper: bool) -> pd.DataFrame:
    """Reduced models: the paper's Eq. 9 terms, our paper-mode (no refit) and backward (refitted) models."""
    comp = b.comparison
    pm = comp.paper.coefficients  # actual units, kept from the full fit
    back = comp.backward.results.coefficients("actual")["coef"]
    terms = list(b.results.term_names)
    if with_paper:
        terms += [t for t in paper.EQ8_TERMS if t not in terms]
    out = pd.DataFrame({"term": terms})
    out["paper_mode_coef"] = [float(pm[t]) if t in pm.index else np.nan for t in terms]
    out["backward_coef"] = [float(back[t]) if t in back.index else np.nan for t in terms]
    out["kept_paper_mode"] = [t in pm.index for t in terms]
    out["kept_backward"] = [t in back.index for t in terms]
    if with_paper:
        e9 = paper.eq9_coefficients()
        out["paper_eq9_coef"] = [float(e9[t]) if t in e9.index else np.nan for t in terms]
        out["kept_paper_eq9"] = [t in e9.index for t in terms]
    return out


def fit_stats_table(res: StudyResult, with_paper: bool) -> pd.DataFrame:
    """R2, R2adj, R2pred, model F/p, lack-of-fit p per response; paper's R2 beside."""
    rows = []
    for resp, b in res.fits.items():
        if b.results is None:
            rows.append({"response": resp, "error": b.error})
            continue
        st = b.results.fit_statistics()
        a = b.results.anova
        rows.append({"response": resp, "runs": b.results.nobs, "r2": st["r2"], "r2_adj": st["r2_adj"],
                     "r2_pred": st["r2_pred"], "model_F": float(a.loc["Model", "F"]),
                     "model_p": float(a.loc["Model", "p"]), "lack_of_fit_p": float(a.loc["Lack of fit", "p"]),
                     "pure_error_sum_sq": float(a.loc["Pure error", "sum_sq"]), "error": ""})
    if with_paper:
        p7 = paper.table7_anova()
        rows.append({"response": "paper te_arcmin", "runs": 27, "r2": paper.R2, "r2_adj": paper.R2_ADJ,
                     "r2_pred": np.nan, "model_F": float(p7.loc["Model", "F"]),
                     "model_p": paper.p_value(p7.loc["Model", "p"]),
                     "lack_of_fit_p": paper.p_value(p7.loc["Lack of fit", "p"]),
                     "pure_error_sum_sq": float(p7.loc["Pure error", "sum_sq"]), "error": ""})
    return pd.DataFrame(rows)


def validation_table(res: StudyResult) -> pd.DataFrame:
    """RMSE, MAE, max error, bias, R2 and PI coverage of each model on the validation cases."""
    rows = []
    for resp, b in res.fits.items():
        for model, v in b.validation.items():
            rows.append({"response": resp, "model": model, **v.to_dict()})
        if b.validation and res.design is not None:
            rng = float(res.design.loc[res.design["status"] == "ok", resp].agg(lambda s: s.max() - s.min()))
            for r in rows:
                if r["response"] == resp:
                    r["rmse_over_design_range"] = r["rmse"] / rng if rng > 0 else np.nan
    return pd.DataFrame(rows)


def _top(anova: pd.DataFrame, kind: str) -> tuple[str, float, float]:
    terms = [t for t in anova.index if t not in ("Model", "Residual", "Lack of fit", "Pure error", "Cor total")]
    if kind == "interaction":
        terms = [t for t in terms if ":" in t]
    sub = anova.loc[terms]
    t = str(sub["sum_sq"].idxmax())
    return t, float(sub.loc[t, "F"]), float(sub.loc[t, "p"])


def _factor_strength_note(res: StudyResult, f: str) -> str:
    """How strongly factor ``f`` acts in our design runs and in the paper's (Table 6): mean response
    of the runs at f = +-1 minus that of the runs at f = 0, arcmin; and what our f is physically."""
    d = res.design
    if d is None or f not in d or "paper_te_arcmin" not in d or f not in res.factors.names:
        return ""
    ok = d["status"] == "ok"
    edge, centre = ok & (d[f].abs() == 1), ok & (d[f] == 0)
    if not edge.any() or not centre.any():
        return ""
    ours = float(d.loc[edge, PRIMARY].mean() - d.loc[centre, PRIMARY].mean())
    theirs = float(d.loc[edge, "paper_te_arcmin"].mean() - d.loc[centre, "paper_te_arcmin"].mean())
    key = res.factors.errors[f]
    et = ERROR_TYPES[key]
    pattern = res.factors.patterns.get(f)
    inst = (f"pattern {pattern}" if pattern else ", ".join(f"{k} {v}" for k, v in et.defaults.items()))
    return (f" Mean response of the runs at {f} = +-1 minus that at {f} = 0: paper {theirs:.3g} arcmin, ours "
            f"{ours:.3g} arcmin. Our {f} is `{res.factors.spec(f)}`: {et.meaning}" + (f" ({inst})" if inst else "")
            + f"; the paper shows its {f} pattern only in a schematic (Fig. 10), not in the text. A pattern "
            "that moves more pins acts more strongly: all 40 pins moved by EA rotate the pin ring and shift the "
            "output by about EA itself, every other pin by about half of it (`--levels` with error "
            "`pin_pitch[all]` or `pin_pitch[alternate]` runs these variants).")


def conclusions(res: StudyResult) -> pd.DataFrame:
    """Each checked claim of the paper: what the paper says, what we find, reproduced or not, why."""
    rows: list[dict[str, str]] = []

    def add(claim: str, ours: str, verdict: str, why: str) -> None:
        rows.append({"claim": claim, "paper": paper.CLAIMS[claim], "ours": ours, "reproduced": verdict, "why": why})

    if res.screen is not None:
        sc = res.screen.stage_check
        pp, ma = sc["pp"], sc["mean_abs"]
        s = res.screen.screen
        plus = s[s["sign"] == 1].set_index("letter")
        dpp = plus["d_pp_arcsec"].abs()
        # errors that move the whole TE curve (a clearance or a preload) but add no ripple
        offset_only = [L for L in plus.index if L != "A" and dpp[L] <= 1e-3 * max(dpp.max(), 1e-30)
                       and abs(plus.loc[L, "d_mean_abs_arcsec"]) > 0.1 * plus["d_mean_abs_arcsec"].abs().max()]
        named = ", ".join(f"{L} ({plus.loc[L, 'error']})" for L in offset_only)
        offset_note = (f" {named} shift the "
                       "whole TE curve by a constant (a uniform clearance or preload at every pin) and add no "
                       "ripple, so they rank last by peak-to-peak while changing the mean|TE| strongly."
                       if offset_only else "")
        v = "yes" if pp["reproduced"] and ma["reproduced"] else ("partly" if pp["reproduced"] or ma["reproduced"]
                                                                  or pp["below_rsm_factors"] else "no")
        add("stage1_below_stage2",
            f"by TE pp: B rank {pp['rank_B']}, C rank {pp['rank_C']} of 11; by mean|TE|: B {ma['rank_B']}, "
            f"C {ma['rank_C']}",
            v, "stage II errors ranked below stage I: by pp " + (", ".join(pp["stage2_below_stage1"]) or "none")
            + "; by mean|TE| " + (", ".join(ma["stage2_below_stage1"]) or "none")
            + ". A stage I error disturbs the crank angle, which reaches the output reduced by the stage II "
              "ratio; a stage II error acts at the pin circle." + offset_note)
        ranks = {L: int(plus.loc[L, "rank_pp"]) for L in ("L", "I", "J", "G") if L in plus.index}
        top4 = all(r <= 4 for r in ranks.values())
        above = [f"{L}={int(plus.loc[L, 'rank_pp'])}" for L in plus.index
                 if L not in ranks and L != "A" and plus.loc[L, "rank_pp"] < max(ranks.values())]
        add("four_factors_obvious", "ranks by TE pp: " + ", ".join(f"{L}={r}" for L, r in ranks.items()),
            "yes" if top4 else "partly",
            "the four RSM factors are the four largest" if top4 else
            "errors outside the paper's four that rank above one of them: " + ", ".join(above) + "." + offset_note)
    b = res.fits.get(PRIMARY)
    if b is not None and b.results is not None:
        a = b.results.anova
        st = b.results.fit_statistics()
        mp = float(a.loc["Model", "p"])
        add("model_significant", f"model p = {mp:.3g}, R2 = {st['r2']:.4f}, R2adj = {st['r2_adj']:.4f}",
            "yes" if mp < 1e-4 and st["r2"] >= 0.95 else ("partly" if mp < 0.05 else "no"),
            "quadratic in the coded factors fitted to our runs" + (
                "" if st["r2"] >= 0.95 else "; our response is not as smooth a quadratic as the paper's"))
        lof = float(a.loc["Lack of fit", "p"])
        pe = float(a.loc["Pure error", "sum_sq"])
        add("lack_of_fit_ns", f"lack-of-fit p = {lof:.3g}, pure error SS = {pe:.3g}",
            "untestable" if not np.isfinite(lof) else ("yes" if lof > 0.05 else "no"),
            "our simulator is deterministic: the replicated centre runs give identical responses, so the pure "
            "error is zero and the lack-of-fit F test is undefined (the paper's centre runs differ, "
            "0.1755 vs 0.1042 arcmin, i.e. its ADAMS runs carried numerical noise)" if not np.isfinite(lof) else
            "pure error from the replicated centre runs")
        t, F, p = _top(a, "any")
        ea_note = _factor_strength_note(res, "EA")
        add("ea2_dominant", f"largest term {t} (F = {F:.4g}, p = {p:.3g})", "yes" if t == "EA^2" else "no",
            "EA^2 carries the most variance" if t == "EA^2" else
            f"{t} carries the most variance in our model." + ea_note)
        t, F, p = _top(a, "interaction")
        add("ebec_top_interaction", f"largest interaction {t} (F = {F:.4g}, p = {p:.3g})",
            "yes" if t == "EB:EC" and p < 0.05 else ("partly" if t == "EB:EC" else "no"),
            "EB and EC both set the pin-to-profile clearance (pin circle diameter/2 + pin radius), so they act "
            "through their sum; a clearance couples them" if t == "EB:EC" else
            f"in our model {t} is the strongest interaction")
        ss = {f: float(a.loc[[x for x in a.index if x == f or x == f"{f}^2"], "sum_sq"].sum())
              for f in res.factors.names}
        best = max(ss, key=ss.get)
        add("ea_main_effect", "main + quadratic sum of squares: " + ", ".join(f"{f}={v:.3g}" for f, v in ss.items()),
            "yes" if best == "EA" else "no", f"{best} has the largest own effect" + ("" if best == "EA" else "." + ea_note))
        kept = set(b.comparison.paper.terms) - {"Intercept"} if b.comparison is not None else set()
        p9 = set(paper.EQ9_TERMS) - {"Intercept"}
        if b.comparison is not None:
            add("eq9_terms", "significant (p < 0.05): " + (", ".join(sorted(kept)) or "none"),
                "yes" if kept == p9 else ("partly" if kept & p9 else "no"),
                "same term set" if kept == p9 else
                f"paper-only: {', '.join(sorted(p9 - kept)) or 'none'}; ours only: {', '.join(sorted(kept - p9)) or 'none'}")
        if b.validation:
            v = b.validation["full"]
            rng = float(res.design.loc[res.design["status"] == "ok", PRIMARY].agg(lambda s: s.max() - s.min()))
            rel = v.rmse / rng if rng > 0 else float("nan")
            add("validation_close", f"{v.n} random cases: RMSE {v.rmse:.4g} arcmin ({100 * rel:.1f} % of the design "
                                    f"range), R2 {v.r2:.3f}, {100 * v.pi_coverage:.0f} % inside the 95 % PI",
                "yes" if rel < 0.1 else ("partly" if rel < 0.25 else "no"),
                "the paper gives no number (a plot only); 'close' is read here as RMSE < 10 % of the response "
                "range of the design runs")
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------------------------- figures
def _fit_figures(res: StudyResult, figs: Path) -> dict[str, str]:
    from itertools import combinations

    from rsm import plots

    out: dict[str, str] = {}
    for resp, b in res.fits.items():
        if b.results is None:
            continue
        for f1, f2 in (combinations(res.factors.names, 2) if resp == PRIMARY else ()):
            p = _atomic_plot(lambda path, f1=f1, f2=f2: plots.plot_surface_pair(b.results, f1, f2, path),
                             figs / f"surface_{resp}_{f1}_{f2}.png")
            out[f"surface_{resp}_{f1}_{f2}"] = str(p)
        val = None
        if res.validation is not None:
            val = res.validation[res.validation["status"] == "ok"]
        p = _atomic_plot(lambda path: plots.plot_predicted_vs_observed(
            b.results, path, validation=val if val is not None and len(val) else None, units="coded"),
            figs / f"predicted_vs_observed_{resp}.png")
        out[f"predicted_vs_observed_{resp}"] = str(p)
        p = _atomic_plot(lambda path: plots.plot_residuals(b.results, path), figs / f"residuals_{resp}.png")
        out[f"residuals_{resp}"] = str(p)
    return out


# ---------------------------------------------------------------------------------------------- report
def summary(res: StudyResult) -> dict[str, Any]:
    """JSON-ready key numbers of the run."""
    def clean(x: Any) -> Any:
        if isinstance(x, dict):
            return {str(k): clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        if isinstance(x, (np.floating, float)):
            return float(x) if math.isfinite(x) else None
        if isinstance(x, (np.integer,)):
            return int(x)
        if isinstance(x, (np.bool_,)):
            return bool(x)
        return x

    s: dict[str, Any] = {"config": res.config.to_dict(), "executor": res.executor, "timings_s": res.timings,
                         "cases": res.counters, "cache": res.cache_counters, "notes": res.notes,
                         "contact_models": res.config.contact_models()}
    if res.screen is not None:
        s["stage_check"] = res.screen.stage_check
    for resp, b in res.fits.items():
        if b.results is None:
            s[resp] = {"error": b.error}
            continue
        st = b.results.fit_statistics()
        s[resp] = {"r2": st["r2"], "r2_adj": st["r2_adj"], "r2_pred": st["r2_pred"],
                   "coefficients_actual": b.results.params_actual.to_dict(),
                   "paper_mode_terms": list(b.comparison.paper.terms) if b.comparison is not None else [],
                   "backward_terms": list(b.comparison.backward.terms) if b.comparison is not None else [],
                   "validation": {k: v.to_dict() for k, v in b.validation.items()}}
    s["reducer"] = {"design": res.reducer.to_dict(), "ratio": res.reducer.ratio,
                    "description": report_mc.reducer_text(res.reducer), "source": res.config.reducer or "paper default"}
    if res.mc:
        s["monte_carlo"] = report_mc.summary_part(res.mc)
    s["files"] = res.files
    return clean(s)


def write_report(res: StudyResult) -> Path:
    """Write tables, figures, ``summary.json``, ``config.json`` and ``report.md`` into ``res.config.out``."""
    out = Path(res.config.out)
    tables, figs = out / "tables", out / "figures"
    tables.mkdir(parents=True, exist_ok=True)
    figs.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}
    cfg = res.config
    fs = res.factors
    with_paper = fs.is_paper and res.design_kind == "bbd" and res.paper_order
    L: list[str] = []
    add = L.append

    def tab(df: pd.DataFrame, name: str) -> None:
        files[f"{name}_csv"] = write_table(df, tables, name)["csv"]

    def fig_link(key: str, caption: str) -> None:
        if key in files:
            add(f"![{caption}]({os.path.relpath(files[key], out)})\n")

    c = res.counters
    laws = cfg.contact_models()
    add("# rv-stackup report\n")
    add("Transmission error (TE) of the RV reducer under manufacturing and assembly errors, after "
        "*Effect of Multifactor Interaction on the Accuracy of RV Reducers* (sections 4.2-5). Every table "
        "of ours below is computed by this run; the paper's numbers sit beside ours where the paper gives them.\n")
    add("## Run\n")
    run_rows = pd.DataFrame([
        {"item": "reducer", "value": report_mc.reducer_text(res.reducer)
                                     + (f" (from {cfg.reducer})" if cfg.reducer else " (the paper's, default)")},
        {"item": "solver / steps per output revolution", "value": f"{cfg.solver} / {cfg.steps}"},
        {"item": "output load [N m] / direction", "value": f"{cfg.load_Nm:g} / +1"},
        {"item": "contact model of the paper-reproduction sections (1-8, 8b: screen, sweeps, design runs and "
                 "their fits, validation, response-surface loop)", "value": laws["design"]},
        {"item": "contact model of the Table 6 readings (section 8c)", "value": laws["readings"]},
        {"item": "contact model of the Monte Carlo (section 9)", "value": laws["monte_carlo"]},
        {"item": "executor", "value": res.executor},
        {"item": "design / factors", "value": f"{res.design_kind or '-'} / " + ", ".join(
            f"{f}={fs.spec(f)}" for f in fs.names)},
        {"item": "unique cases: solved now / reused from cache / failed",
         "value": f"{c.get('computed', 0)} / {c.get('reused', 0)} / {c.get('failed', 0)}"},
        {"item": "solver seconds per case (mean / median, computed cases)",
         "value": f"{_fmt(c.get('solve_seconds_mean'))} / {_fmt(c.get('solve_seconds_median'))}"},
        {"item": "wall time [s]: " + ", ".join(res.timings) + (
            " (with 2+ workers the stages' cases are solved together: a stage's time is the wait for its cases "
            "plus its analysis; mc runs from the first draw to its analysis)" if "mc_wait_and_analysis" in res.timings
            else ""), "value": ", ".join(f"{v:.1f}" for v in res.timings.values())},
        {"item": "seed (validation [seed,1], MC [seed,2], check [seed,3])", "value": str(cfg.seed)},
    ])
    add(md_table(run_rows) + "\n")
    add("**Responses.** `mean_abs_arcmin` is the mean of |TE| over one output revolution in arcmin: this is "
        "our reading of the paper's \"mean value of transmission error\" (the paper does not define it; its "
        "error-free value, 0.10-0.18 arcmin, is of the size of our elastic wind-up under load, so a mean of the "
        "signed TE or of |TE| is plausible, and of these only |TE| grows with any error). `pp_arcmin` is the "
        "peak-to-peak TE (the industry's angular transmission error), used for the yield. "
        "TE = theta_out - theta_in/121, positive when the output leads.\n")
    if res.notes:
        add("**Notes of this run.**\n")
        for n in res.notes:
            add(f"- {n}")
        add("")

    # ---------------------------------------------------------------- screen
    if res.screen is not None and "screen" in cfg.stages:
        s = res.screen.screen
        if cfg.figures:
            files["screen_png"] = str(plot_screen(s, figs / "screen.png"))
        if res.screen.curves and cfg.figures:
            titles = {f"screen-{r.letter}": f"{r.letter} {r.error}" for r in s.itertuples()}
            files["te_curves_png"] = str(plot_te_figure(
                res.screen.curves, figs / "te_curves.png", crank_order=int(res.reducer.z_pins), titles=titles,
                suptitle="Single-factor screen: TE of each case (blue: error at +value, red: at -value)"))
        tab(s, "screen")
        add("## 1. Single-factor screen (paper Table 4, Fig. 9)\n")
        add("Each Table 4 error alone at its paper value (default instance) and at minus it; rank 1 = largest "
            "increase of TE peak-to-peak over case A (`rank_pp`) or largest change of mean|TE| (`rank_mean_abs`). "
            "The paper gives Fig. 9 as curves only (no numbers). "
            f"Contact model: {laws['screen']}.\n")
        cols = ["letter", "error", "stage", "value", "unit", "pp_arcsec", "mean_abs_arcsec", "d_pp_arcsec",
                "d_mean_abs_arcsec", "rank_pp", "rank_mean_abs"]
        add(md_table(s[s["sign"].isin([0, 1])][cols]) + "\n")
        for m, chk in res.screen.stage_check.items():
            add(f"- Stage I errors (B rank {chk['rank_B']}, C rank {chk['rank_C']}) below every stage II error by "
                f"`{m}`: **{'reproduced' if chk['reproduced'] else 'not reproduced'}**"
                + ("" if chk["reproduced"] else f" (stage II errors ranked below them: "
                                                 f"{', '.join(chk['stage2_below_stage1'])})")
                + f"; below the four RSM factors: {'yes' if chk['below_rsm_factors'] else 'no'}.")
        add("")
        fig_link("screen_png", "single-factor screen")
        fig_link("te_curves_png", "TE curves of the single-factor cases")
        sw = res.screen.sweeps
        if len(sw):
            if cfg.figures:
                files["sweeps_png"] = str(plot_sweeps(sw, figs / "sweeps.png"))
            tab(sw, "sweeps")
            add("## 2. Factor sweeps (paper Fig. 11)\n")
            add("Each RSM factor alone over its Table 5 range. The paper chose the level at the TE optimum of "
                "these curves as the centre level (0 for all four). "
                f"Contact model: {laws['sweeps']}.\n")
            add(md_table(sw[["factor", "error", "value", "unit", "mean_abs_arcsec", "pp_arcsec",
                             "te_mean_abs_arcmin", "te_pp_arcmin"]]) + "\n")
            opt = sw.loc[sw.groupby("factor")["te_mean_abs_arcmin"].idxmin(), ["factor", "value", "unit",
                                                                                "te_mean_abs_arcmin"]]
            add("Minimum of mean|TE| along each sweep (the paper's centre levels are all 0):\n")
            add(md_table(opt.rename(columns={"value": "value_at_minimum"})) + "\n")
            fig_link("sweeps_png", "factor sweeps")

    # ---------------------------------------------------------------- design and fits
    if res.design is not None:
        tab(res.design, "design_runs")
        t6 = table6_compare(res)
        tab(t6, "table6_compare")
        add(f"## 3. Design runs (paper Table 6): {res.design_kind.upper()}, {len(res.design)} runs\n")
        add(f"Contact model of these runs (and so of the fits in sections 4-7): {laws['design']}.\n")
        if with_paper:
            add("Generated by `rsm.make_design`; the point set equals the paper's Table 6, so the runs are numbered "
                "as there and the paper's response stands beside ours.\n")
        add(md_table(t6) + "\n")
        if with_paper:
            ok = t6["status"] == "ok"
            r = np.corrcoef(t6.loc[ok, "mean_abs_arcmin"], t6.loc[ok, "paper_te_arcmin"])[0, 1] if ok.sum() > 2 else np.nan
            add(f"Correlation of our mean|TE| with the paper's response over the {int(ok.sum())} solved runs: "
                f"{_fmt(r)}; our range {_fmt(t6.loc[ok, 'mean_abs_arcmin'].min())}..{_fmt(t6.loc[ok, 'mean_abs_arcmin'].max())}"
                f" arcmin, the paper's {_fmt(t6['paper_te_arcmin'].min())}..{_fmt(t6['paper_te_arcmin'].max())} arcmin.\n")
        fst = fit_stats_table(res, with_paper)
        tab(fst, "fit_statistics")
        add("## 4. ANOVA of the full quadratic (paper Table 7)\n")
        add(md_table(fst) + "\n")
        for resp, b in res.fits.items():
            if b.results is None:
                add(f"**{resp}: no fit** ({b.error})\n")
                continue
            t7 = table7_compare(b, with_paper)
            tab(t7, f"table7_compare_{resp}")
            add(f"### {RESPONSE_LABEL[resp]}" + (" beside the paper's Table 7" if with_paper and resp == PRIMARY else "")
                + "\n")
            cols = list(t7.columns) if (with_paper and resp == PRIMARY) else [c for c in t7.columns if not c.startswith("paper")]
            add(md_table(t7[cols]) + "\n")
            for n in b.notes:
                add(f"- {n}")
            add("")
        add("## 5. Coefficients in actual units (paper Eq. 8)\n")
        add("EA in deg, EB/EC/ED in um, response in arcmin.\n")
        for resp, b in res.fits.items():
            if b.results is None:
                continue
            e8 = eq8_compare(b, with_paper and resp == PRIMARY)
            tab(e8, f"eq8_compare_{resp}")
            add(f"### {RESPONSE_LABEL[resp]}\n")
            add(md_table(e8, digits=5) + "\n")
        add("## 6. Reduced models (paper Eq. 9)\n")
        add("*Paper mode* keeps the terms with p < 0.05 and their full-fit coefficients without refitting and "
            "without hierarchy, as the paper's Eq. 9 does; *backward* removes the least significant term and refits, "
            "keeping hierarchy.\n")
        for resp, b in res.fits.items():
            if b.results is None:
                continue
            if b.comparison is None:
                add(f"### {RESPONSE_LABEL[resp]}\n")
                add("No reduced models: " + "; ".join(n for n in b.notes if n.startswith("reduced models")) + "\n")
                continue
            e9 = eq9_compare(b, with_paper and resp == PRIMARY)
            tab(e9, f"eq9_compare_{resp}")
            rt = b.comparison.table.reset_index()
            tab(rt, f"reductions_{resp}")
            add(f"### {RESPONSE_LABEL[resp]}\n")
            add(md_table(e9, digits=5) + "\n")
            add(md_table(rt[["model", "n_terms", "sse", "rmse", "r2", "max_abs_resid", "refitted"]]) + "\n")
            add(f"Cost of the paper's no-refit shortcut (SSE paper mode - SSE same terms refitted): "
                f"{_fmt(b.comparison.shortcut_cost)}.\n")
        if cfg.figures:
            files.update(_fit_figures(res, figs))
        add("## 7. Response surfaces and contours (paper Fig. 12)\n")
        add(f"{RESPONSE_LABEL[PRIMARY]} (the paper's response), other factors at their centre level"
            + ("." if cfg.figures else "; figures were not drawn (--no-figures).") + "\n")
        for resp in res.fits:
            for k in [k for k in files if k.startswith(f"surface_{resp}_")]:
                fig_link(k, k)

    # ---------------------------------------------------------------- validation
    if res.validation is not None:
        tab(res.validation, "validation_cases")
        vt = validation_table(res)
        tab(vt, "validation_metrics")
        add(f"## 8. Validation on {cfg.n_validation} random cases (paper Fig. 13)\n")
        add("Uniform in the coded design box, seed [seed, 1]. The paper shows a plot only (\"extremely close\"), "
            "with no RMSE. PI = 95 % prediction interval of the full quadratic (the paper-mode surface has no "
            "error model, hence no coverage). "
            f"Contact model: {laws['validation']}.\n")
        if len(vt):
            add(md_table(vt) + "\n")
        cols = ["case"] + fs.names + [c for c in res.validation.columns
                                      if c.startswith(("mean_abs_arcmin", "pp_arcmin"))] + ["status"]
        add(md_table(res.validation[cols]) + "\n")
        for resp in res.fits:
            fig_link(f"predicted_vs_observed_{resp}", f"predicted vs observed, {resp}")

    # ---------------------------------------------------------------- 8b/8c: rvstudy.augment_section, rvstudy.paper_readings
    for sec in filter(None, (augment_section(res) if res.design is not None else None, readings_section(res))):
        L.extend([sec.heading, sec.intro])
        for name, df in {**sec.tables, **sec.data}.items():
            tab(df, name)
            if name in sec.tables:
                add(md_table(df) + "\n")
        L.extend(sec.findings)

    # ---------------------------------------------------------------- Monte Carlo
    if res.mc:
        report_mc.section(res, add, tab, fig_link, files, figs, md_table)

    # ---------------------------------------------------------------- conclusions
    cc = conclusions(res)
    if len(cc):
        tab(cc, "conclusions")
        add("## 10. The paper's conclusions: reproduced or not\n")
        add(md_table(cc) + "\n")
    add("## Files\n")
    cache_txt = (f"solved cases in the cache (`{cfg.cache_dir or Path(cfg.out) / 'cache'}`)" if cfg.use_cache
                 else "no case cache (`--no-cache`)")
    add(f"Tables in `tables/` (CSV and Parquet), figures in `figures/`, {cache_txt}, key numbers in "
        "`summary.json`.\n")
    res.files = files
    cfg_path = write_text_atomic(json.dumps(res.config.to_dict(), indent=2, default=str), out / "config.json")
    files["config_json"] = str(cfg_path)
    files["summary_json"] = str(out / "summary.json")
    rep = out / "report.md"
    files["report_md"] = str(rep)
    write_text_atomic(json.dumps(summary(res), indent=2, default=str), out / "summary.json")
    write_text_atomic("\n".join(L) + "\n", rep)
    return rep
