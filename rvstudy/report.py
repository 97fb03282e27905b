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
from rvstudy.screen import plot_screen, plot_sweeps
from rvdyn.te import write_table_atomic
import rvpaper as paper
from rvdyn.cache import write_text_atomic
from rvstudy.augment_section import augment_section
from rvstudy.paper_readings import readings_section
import rvstudy.report_mc as report_mc
from rvstudy.report_claims import PRIMARY, conclusions
from rvstudy.study import RESPONSE_LABEL, FitBundle, StudyConfig, StudyResult
from rvstudy.te_figure import plot_te_figure


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


class _ReportFiles:
    """The output folder of a report: writes its tables and keeps every file written, by key.

    Parameters
    ----------
    out : Path
        The output folder; ``tables/`` and ``figures/`` are made in it.
    """

    def __init__(self, out: Path) -> None:
        self.out = out
        self.tables, self.figs = out / "tables", out / "figures"
        self.tables.mkdir(parents=True, exist_ok=True)
        self.figs.mkdir(parents=True, exist_ok=True)
        self.files: dict[str, str] = {}

    def tab(self, df: pd.DataFrame, name: str) -> None:
        """Write the table ``name`` (CSV and Parquet) and keep its CSV path as ``<name>_csv``."""
        self.files[f"{name}_csv"] = write_table(df, self.tables, name)["csv"]

    def fig_link(self, key: str, caption: str) -> list[str]:
        """The Markdown line showing the figure kept as ``key`` (path relative to the report); none if the
        figure was not drawn."""
        if key in self.files:
            return [f"![{caption}]({os.path.relpath(self.files[key], self.out)})\n"]
        return []


def _run_table(res: StudyResult) -> pd.DataFrame:
    """The run's settings and counts (``item, value``): reducer, solver, load, contact models, executor,
    design, cases solved and reused, solver and wall times, seed."""
    cfg, fs, c = res.config, res.factors, res.counters
    laws = cfg.contact_models()
    return pd.DataFrame([
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


def _intro_lines(res: StudyResult) -> list[str]:
    """Title, introduction, the run table (:func:`_run_table`), the responses' definition and the run's notes."""
    L = ["# rv-stackup report\n",
         "Transmission error (TE) of the RV reducer under manufacturing and assembly errors, after "
         "*Effect of Multifactor Interaction on the Accuracy of RV Reducers* (sections 4.2-5). Every table "
         "of ours below is computed by this run; the paper's numbers sit beside ours where the paper gives them.\n",
         "## Run\n",
         md_table(_run_table(res)) + "\n",
         "**Responses.** `mean_abs_arcmin` is the mean of |TE| over one output revolution in arcmin: this is "
         "our reading of the paper's \"mean value of transmission error\" (the paper does not define it; its "
         "error-free value, 0.10-0.18 arcmin, is of the size of our elastic wind-up under load, so a mean of the "
         "signed TE or of |TE| is plausible, and of these only |TE| grows with any error). `pp_arcmin` is the "
         "peak-to-peak TE (the industry's angular transmission error), used for the yield. "
         "TE = theta_out - theta_in/121, positive when the output leads.\n"]
    if res.notes:
        L.append("**Notes of this run.**\n")
        L += [f"- {n}" for n in res.notes]
        L.append("")
    return L


def _screen_lines(res: StudyResult, w: _ReportFiles) -> list[str]:
    """Section 1, the single-factor screen (paper Table 4, Fig. 9): its figures and table, the ranking and
    the stage check."""
    cfg, s = res.config, res.screen.screen
    if cfg.figures:
        w.files["screen_png"] = str(plot_screen(s, w.figs / "screen.png"))
    if res.screen.curves and cfg.figures:
        titles = {f"screen-{r.letter}": f"{r.letter} {r.error}" for r in s.itertuples()}
        w.files["te_curves_png"] = str(plot_te_figure(
            res.screen.curves, w.figs / "te_curves.png", crank_order=int(res.reducer.z_pins), titles=titles,
            suptitle="Single-factor screen: TE of each case (blue: error at +value, red: at -value)"))
    w.tab(s, "screen")
    L = ["## 1. Single-factor screen (paper Table 4, Fig. 9)\n",
         "Each Table 4 error alone at its paper value (default instance) and at minus it; rank 1 = largest "
         "increase of TE peak-to-peak over case A (`rank_pp`) or largest change of mean|TE| (`rank_mean_abs`). "
         "The paper gives Fig. 9 as curves only (no numbers). "
         f"Contact model: {cfg.contact_models()['screen']}.\n"]
    cols = ["letter", "error", "stage", "value", "unit", "pp_arcsec", "mean_abs_arcsec", "d_pp_arcsec",
            "d_mean_abs_arcsec", "rank_pp", "rank_mean_abs"]
    L.append(md_table(s[s["sign"].isin([0, 1])][cols]) + "\n")
    for m, chk in res.screen.stage_check.items():
        L.append(f"- Stage I errors (B rank {chk['rank_B']}, C rank {chk['rank_C']}) below every stage II error by "
                 f"`{m}`: **{'reproduced' if chk['reproduced'] else 'not reproduced'}**"
                 + ("" if chk["reproduced"] else f" (stage II errors ranked below them: "
                                                  f"{', '.join(chk['stage2_below_stage1'])})")
                 + f"; below the four RSM factors: {'yes' if chk['below_rsm_factors'] else 'no'}.")
    L.append("")
    return L + w.fig_link("screen_png", "single-factor screen") + w.fig_link(
        "te_curves_png", "TE curves of the single-factor cases")


def _sweeps_lines(res: StudyResult, w: _ReportFiles) -> list[str]:
    """Section 2, the factor sweeps (paper Fig. 11): table, figure and the minimum of mean|TE| per factor."""
    cfg, sw = res.config, res.screen.sweeps
    if cfg.figures:
        w.files["sweeps_png"] = str(plot_sweeps(sw, w.figs / "sweeps.png"))
    w.tab(sw, "sweeps")
    opt = sw.loc[sw.groupby("factor")["te_mean_abs_arcmin"].idxmin(), ["factor", "value", "unit",
                                                                        "te_mean_abs_arcmin"]]
    return ["## 2. Factor sweeps (paper Fig. 11)\n",
            "Each RSM factor alone over its Table 5 range. The paper chose the level at the TE optimum of "
            "these curves as the centre level (0 for all four). "
            f"Contact model: {cfg.contact_models()['sweeps']}.\n",
            md_table(sw[["factor", "error", "value", "unit", "mean_abs_arcsec", "pp_arcsec",
                         "te_mean_abs_arcmin", "te_pp_arcmin"]]) + "\n",
            "Minimum of mean|TE| along each sweep (the paper's centre levels are all 0):\n",
            md_table(opt.rename(columns={"value": "value_at_minimum"})) + "\n"] + w.fig_link("sweeps_png",
                                                                                             "factor sweeps")


def _design_lines(res: StudyResult, w: _ReportFiles, with_paper: bool) -> list[str]:
    """Section 3, the design runs (paper Table 6) beside the paper's response, and how well they agree."""
    w.tab(res.design, "design_runs")
    t6 = table6_compare(res)
    w.tab(t6, "table6_compare")
    L = [f"## 3. Design runs (paper Table 6): {res.design_kind.upper()}, {len(res.design)} runs\n",
         "Contact model of these runs (and so of the fits in sections 4-7): "
         f"{res.config.contact_models()['design']}.\n"]
    if with_paper:
        L.append("Generated by `rsm.make_design`; the point set equals the paper's Table 6, so the runs are numbered "
                 "as there and the paper's response stands beside ours.\n")
    L.append(md_table(t6) + "\n")
    if with_paper:
        ok = t6["status"] == "ok"
        r = np.corrcoef(t6.loc[ok, "mean_abs_arcmin"], t6.loc[ok, "paper_te_arcmin"])[0, 1] if ok.sum() > 2 else np.nan
        L.append(f"Correlation of our mean|TE| with the paper's response over the {int(ok.sum())} solved runs: "
                 f"{_fmt(r)}; our range {_fmt(t6.loc[ok, 'mean_abs_arcmin'].min())}..{_fmt(t6.loc[ok, 'mean_abs_arcmin'].max())}"
                 f" arcmin, the paper's {_fmt(t6['paper_te_arcmin'].min())}..{_fmt(t6['paper_te_arcmin'].max())} arcmin.\n")
    return L


def _anova_lines(res: StudyResult, w: _ReportFiles, with_paper: bool) -> list[str]:
    """Section 4, the fit statistics and the ANOVA of each response's full quadratic (paper Table 7)."""
    fst = fit_stats_table(res, with_paper)
    w.tab(fst, "fit_statistics")
    L = ["## 4. ANOVA of the full quadratic (paper Table 7)\n", md_table(fst) + "\n"]
    for resp, b in res.fits.items():
        if b.results is None:
            L.append(f"**{resp}: no fit** ({b.error})\n")
            continue
        t7 = table7_compare(b, with_paper)
        w.tab(t7, f"table7_compare_{resp}")
        L.append(f"### {RESPONSE_LABEL[resp]}" + (" beside the paper's Table 7" if with_paper and resp == PRIMARY else "")
                 + "\n")
        cols = list(t7.columns) if (with_paper and resp == PRIMARY) else [c for c in t7.columns if not c.startswith("paper")]
        L.append(md_table(t7[cols]) + "\n")
        L += [f"- {n}" for n in b.notes]
        L.append("")
    return L


def _coefficient_lines(res: StudyResult, w: _ReportFiles, with_paper: bool) -> list[str]:
    """Section 5, each fitted response's coefficients in actual units (paper Eq. 8)."""
    L = ["## 5. Coefficients in actual units (paper Eq. 8)\n", "EA in deg, EB/EC/ED in um, response in arcmin.\n"]
    for resp, b in res.fits.items():
        if b.results is None:
            continue
        e8 = eq8_compare(b, with_paper and resp == PRIMARY)
        w.tab(e8, f"eq8_compare_{resp}")
        L += [f"### {RESPONSE_LABEL[resp]}\n", md_table(e8, digits=5) + "\n"]
    return L


def _reduced_model_lines(res: StudyResult, w: _ReportFiles, with_paper: bool) -> list[str]:
    """Section 6, the reduced models of each fitted response (paper Eq. 9) and the cost of the paper's
    no-refit shortcut."""
    L = ["## 6. Reduced models (paper Eq. 9)\n",
         "*Paper mode* keeps the terms with p < 0.05 and their full-fit coefficients without refitting and "
         "without hierarchy, as the paper's Eq. 9 does; *backward* removes the least significant term and refits, "
         "keeping hierarchy.\n"]
    for resp, b in res.fits.items():
        if b.results is None:
            continue
        if b.comparison is None:
            L.append(f"### {RESPONSE_LABEL[resp]}\n")
            L.append("No reduced models: " + "; ".join(n for n in b.notes if n.startswith("reduced models")) + "\n")
            continue
        e9 = eq9_compare(b, with_paper and resp == PRIMARY)
        w.tab(e9, f"eq9_compare_{resp}")
        rt = b.comparison.table.reset_index()
        w.tab(rt, f"reductions_{resp}")
        L += [f"### {RESPONSE_LABEL[resp]}\n", md_table(e9, digits=5) + "\n",
              md_table(rt[["model", "n_terms", "sse", "rmse", "r2", "max_abs_resid", "refitted"]]) + "\n",
              f"Cost of the paper's no-refit shortcut (SSE paper mode - SSE same terms refitted): "
              f"{_fmt(b.comparison.shortcut_cost)}.\n"]
    return L


def _surface_lines(res: StudyResult, w: _ReportFiles) -> list[str]:
    """Section 7, the response surfaces and contours (paper Fig. 12); draws the fits' figures when asked."""
    cfg = res.config
    if cfg.figures:
        w.files.update(_fit_figures(res, w.figs))
    L = ["## 7. Response surfaces and contours (paper Fig. 12)\n",
         f"{RESPONSE_LABEL[PRIMARY]} (the paper's response), other factors at their centre level"
         + ("." if cfg.figures else "; figures were not drawn (--no-figures).") + "\n"]
    for resp in res.fits:
        for k in [k for k in w.files if k.startswith(f"surface_{resp}_")]:
            L += w.fig_link(k, k)
    return L


def _validation_lines(res: StudyResult, w: _ReportFiles) -> list[str]:
    """Section 8, the models on the random validation cases (paper Fig. 13): metrics, cases and figures."""
    cfg, fs = res.config, res.factors
    w.tab(res.validation, "validation_cases")
    vt = validation_table(res)
    w.tab(vt, "validation_metrics")
    L = [f"## 8. Validation on {cfg.n_validation} random cases (paper Fig. 13)\n",
         "Uniform in the coded design box, seed [seed, 1]. The paper shows a plot only (\"extremely close\"), "
         "with no RMSE. PI = 95 % prediction interval of the full quadratic (the paper-mode surface has no "
         "error model, hence no coverage). "
         f"Contact model: {cfg.contact_models()['validation']}.\n"]
    if len(vt):
        L.append(md_table(vt) + "\n")
    cols = ["case"] + fs.names + [c for c in res.validation.columns
                                  if c.startswith(("mean_abs_arcmin", "pp_arcmin"))] + ["status"]
    L.append(md_table(res.validation[cols]) + "\n")
    for resp in res.fits:
        L += w.fig_link(f"predicted_vs_observed_{resp}", f"predicted vs observed, {resp}")
    return L


def _loop_and_readings_lines(res: StudyResult, w: _ReportFiles) -> list[str]:
    """Sections 8b (the response-surface loop, :mod:`rvstudy.augment_section`) and 8c (the Table 6
    readings, :mod:`rvstudy.paper_readings`), each when the run has it."""
    L: list[str] = []
    for sec in filter(None, (augment_section(res) if res.design is not None else None, readings_section(res))):
        L.extend([sec.heading, sec.intro])
        for name, df in {**sec.tables, **sec.data}.items():
            w.tab(df, name)
            if name in sec.tables:
                L.append(md_table(df) + "\n")
        L.extend(sec.findings)
    return L


def _mc_lines(res: StudyResult, w: _ReportFiles) -> list[str]:
    """Section 9, the full-solver Monte Carlo (:func:`rvstudy.report_mc.section`)."""
    L: list[str] = []
    report_mc.section(res, L.append, w.tab, lambda key, caption: L.extend(w.fig_link(key, caption)), w.files,
                      w.figs, md_table)
    return L


def _conclusions_lines(res: StudyResult, w: _ReportFiles) -> list[str]:
    """Section 10, the paper's conclusions reproduced or not (:func:`rvstudy.report_claims.conclusions`);
    none when no claim could be checked."""
    cc = conclusions(res)
    if not len(cc):
        return []
    w.tab(cc, "conclusions")
    return ["## 10. The paper's conclusions: reproduced or not\n", md_table(cc) + "\n"]


def _files_lines(cfg: StudyConfig) -> list[str]:
    """The closing section: where the tables, figures, cached cases and key numbers are."""
    cache_txt = (f"solved cases in the cache (`{cfg.cache_dir or Path(cfg.out) / 'cache'}`)" if cfg.use_cache
                 else "no case cache (`--no-cache`)")
    return ["## Files\n",
            f"Tables in `tables/` (CSV and Parquet), figures in `figures/`, {cache_txt}, key numbers in "
            "`summary.json`.\n"]


def write_report(res: StudyResult) -> Path:
    """Write tables, figures, ``summary.json``, ``config.json`` and ``report.md`` into ``res.config.out``."""
    out = Path(res.config.out)
    w = _ReportFiles(out)
    cfg = res.config
    with_paper = res.factors.is_paper and res.design_kind == "bbd" and res.paper_order
    L = _intro_lines(res)
    if res.screen is not None and "screen" in cfg.stages:
        L += _screen_lines(res, w)
        if len(res.screen.sweeps):
            L += _sweeps_lines(res, w)
    if res.design is not None:
        L += _design_lines(res, w, with_paper)
        L += _anova_lines(res, w, with_paper)
        L += _coefficient_lines(res, w, with_paper)
        L += _reduced_model_lines(res, w, with_paper)
        L += _surface_lines(res, w)
    if res.validation is not None:
        L += _validation_lines(res, w)
    L += _loop_and_readings_lines(res, w)
    if res.mc:
        L += _mc_lines(res, w)
    L += _conclusions_lines(res, w)
    L += _files_lines(cfg)
    files = res.files = w.files
    cfg_path = write_text_atomic(json.dumps(res.config.to_dict(), indent=2, default=str), out / "config.json")
    files["config_json"] = str(cfg_path)
    files["summary_json"] = str(out / "summary.json")
    rep = out / "report.md"
    files["report_md"] = str(rep)
    write_text_atomic(json.dumps(summary(res), indent=2, default=str), out / "summary.json")
    write_text_atomic("\n".join(L) + "\n", rep)
    return rep
