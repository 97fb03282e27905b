"""The paper's conclusions checked against the run (section 10 of the rv-stackup report).

:func:`conclusions` sets each claim of :data:`rvpaper.CLAIMS` beside what this run finds: the screen's
ranking of the errors (Fig. 9), the ANOVA of the full quadratic fit of the primary response (Table 7),
its reduced model (Eq. 9) and its validation (Fig. 13), with a verdict (``yes``, ``partly``, ``no`` or
``untestable``) and the reason.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

import rvpaper as paper
from rvcad.errors import ERROR_TYPES
from rvstudy.screen import ScreenResult
from rvstudy.study import FitBundle, StudyResult

#: The paper's response, the one whose fit the claims are checked on.
PRIMARY = "mean_abs_arcmin"


def _top(anova: pd.DataFrame, kind: str) -> tuple[str, float, float]:
    """The model term with the largest sum of squares in ``anova`` (``kind`` ``interaction``: among the
    interactions only; otherwise among all terms), with its F and p."""
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


def _claim(claim: str, ours: str, verdict: str, why: str) -> dict[str, str]:
    """One row of the conclusions table: the claim's id, the paper's wording, our finding, verdict, reason."""
    return {"claim": claim, "paper": paper.CLAIMS[claim], "ours": ours, "reproduced": verdict, "why": why}


def _offset_note(plus: pd.DataFrame) -> str:
    """A sentence naming the screen's errors that shift the whole TE curve but add no ripple ("" if none).

    Parameters
    ----------
    plus : DataFrame
        The screen's cases at +value, indexed by letter (``error``, ``d_pp_arcsec``, ``d_mean_abs_arcsec``).
    """
    dpp = plus["d_pp_arcsec"].abs()
    # errors that move the whole TE curve (a clearance or a preload) but add no ripple
    offset_only = [L for L in plus.index if L != "A" and dpp[L] <= 1e-3 * max(dpp.max(), 1e-30)
                   and abs(plus.loc[L, "d_mean_abs_arcsec"]) > 0.1 * plus["d_mean_abs_arcsec"].abs().max()]
    named = ", ".join(f"{L} ({plus.loc[L, 'error']})" for L in offset_only)
    return (f" {named} shift the "
            "whole TE curve by a constant (a uniform clearance or preload at every pin) and add no "
            "ripple, so they rank last by peak-to-peak while changing the mean|TE| strongly."
            if offset_only else "")


def _screen_claims(screen: ScreenResult) -> list[dict[str, str]]:
    """The claims the single-factor screen checks: stage I errors below stage II (``stage1_below_stage2``)
    and the four RSM factors as the strongest errors (``four_factors_obvious``)."""
    sc = screen.stage_check
    pp, ma = sc["pp"], sc["mean_abs"]
    s = screen.screen
    plus = s[s["sign"] == 1].set_index("letter")
    offset_note = _offset_note(plus)
    v = "yes" if pp["reproduced"] and ma["reproduced"] else ("partly" if pp["reproduced"] or ma["reproduced"]
                                                              or pp["below_rsm_factors"] else "no")
    rows = [_claim(
        "stage1_below_stage2",
        f"by TE pp: B rank {pp['rank_B']}, C rank {pp['rank_C']} of 11; by mean|TE|: B {ma['rank_B']}, "
        f"C {ma['rank_C']}",
        v, "stage II errors ranked below stage I: by pp " + (", ".join(pp["stage2_below_stage1"]) or "none")
        + "; by mean|TE| " + (", ".join(ma["stage2_below_stage1"]) or "none")
        + ". A stage I error disturbs the crank angle, which reaches the output reduced by the stage II "
          "ratio; a stage II error acts at the pin circle." + offset_note)]
    ranks = {L: int(plus.loc[L, "rank_pp"]) for L in ("L", "I", "J", "G") if L in plus.index}
    top4 = all(r <= 4 for r in ranks.values())
    above = [f"{L}={int(plus.loc[L, 'rank_pp'])}" for L in plus.index
             if L not in ranks and L != "A" and plus.loc[L, "rank_pp"] < max(ranks.values())]
    rows.append(_claim(
        "four_factors_obvious", "ranks by TE pp: " + ", ".join(f"{L}={r}" for L, r in ranks.items()),
        "yes" if top4 else "partly",
        "the four RSM factors are the four largest" if top4 else
        "errors outside the paper's four that rank above one of them: " + ", ".join(above) + "." + offset_note))
    return rows


def _anova_claims(res: StudyResult, b: FitBundle) -> list[dict[str, str]]:
    """The claims the ANOVA of the primary response's full quadratic checks (Table 7): model significance,
    lack of fit, the strongest term, the strongest interaction and the strongest factor."""
    a = b.results.anova
    st = b.results.fit_statistics()
    mp = float(a.loc["Model", "p"])
    rows = [_claim("model_significant", f"model p = {mp:.3g}, R2 = {st['r2']:.4f}, R2adj = {st['r2_adj']:.4f}",
                   "yes" if mp < 1e-4 and st["r2"] >= 0.95 else ("partly" if mp < 0.05 else "no"),
                   "quadratic in the coded factors fitted to our runs" + (
                       "" if st["r2"] >= 0.95 else "; our response is not as smooth a quadratic as the paper's"))]
    lof = float(a.loc["Lack of fit", "p"])
    pe = float(a.loc["Pure error", "sum_sq"])
    rows.append(_claim(
        "lack_of_fit_ns", f"lack-of-fit p = {lof:.3g}, pure error SS = {pe:.3g}",
        "untestable" if not np.isfinite(lof) else ("yes" if lof > 0.05 else "no"),
        "our simulator is deterministic: the replicated centre runs give identical responses, so the pure "
        "error is zero and the lack-of-fit F test is undefined (the paper's centre runs differ, "
        "0.1755 vs 0.1042 arcmin, i.e. its ADAMS runs carried numerical noise)" if not np.isfinite(lof) else
        "pure error from the replicated centre runs"))
    t, F, p = _top(a, "any")
    ea_note = _factor_strength_note(res, "EA")
    rows.append(_claim("ea2_dominant", f"largest term {t} (F = {F:.4g}, p = {p:.3g})", "yes" if t == "EA^2" else "no",
                       "EA^2 carries the most variance" if t == "EA^2" else
                       f"{t} carries the most variance in our model." + ea_note))
    t, F, p = _top(a, "interaction")
    rows.append(_claim(
        "ebec_top_interaction", f"largest interaction {t} (F = {F:.4g}, p = {p:.3g})",
        "yes" if t == "EB:EC" and p < 0.05 else ("partly" if t == "EB:EC" else "no"),
        "EB and EC both set the pin-to-profile clearance (pin circle diameter/2 + pin radius), so they act "
        "through their sum; a clearance couples them" if t == "EB:EC" else
        f"in our model {t} is the strongest interaction"))
    ss = {f: float(a.loc[[x for x in a.index if x == f or x == f"{f}^2"], "sum_sq"].sum())
          for f in res.factors.names}
    best = max(ss, key=ss.get)
    rows.append(_claim(
        "ea_main_effect", "main + quadratic sum of squares: " + ", ".join(f"{f}={v:.3g}" for f, v in ss.items()),
        "yes" if best == "EA" else "no", f"{best} has the largest own effect" + ("" if best == "EA" else "." + ea_note)))
    return rows


def _reduction_claims(res: StudyResult, b: FitBundle) -> list[dict[str, str]]:
    """The claims of the reduced model (Eq. 9: its significant terms) and of the validation (Fig. 13: the
    model's error on the random cases), each only when the run has it."""
    rows = []
    kept = set(b.comparison.paper.terms) - {"Intercept"} if b.comparison is not None else set()
    p9 = set(paper.EQ9_TERMS) - {"Intercept"}
    if b.comparison is not None:
        rows.append(_claim(
            "eq9_terms", "significant (p < 0.05): " + (", ".join(sorted(kept)) or "none"),
            "yes" if kept == p9 else ("partly" if kept & p9 else "no"),
            "same term set" if kept == p9 else
            f"paper-only: {', '.join(sorted(p9 - kept)) or 'none'}; ours only: {', '.join(sorted(kept - p9)) or 'none'}"))
    if b.validation:
        v = b.validation["full"]
        rng = float(res.design.loc[res.design["status"] == "ok", PRIMARY].agg(lambda s: s.max() - s.min()))
        rel = v.rmse / rng if rng > 0 else float("nan")
        rows.append(_claim(
            "validation_close", f"{v.n} random cases: RMSE {v.rmse:.4g} arcmin ({100 * rel:.1f} % of the design "
                                f"range), R2 {v.r2:.3f}, {100 * v.pi_coverage:.0f} % inside the 95 % PI",
            "yes" if rel < 0.1 else ("partly" if rel < 0.25 else "no"),
            "the paper gives no number (a plot only); 'close' is read here as RMSE < 10 % of the response "
            "range of the design runs"))
    return rows


def conclusions(res: StudyResult) -> pd.DataFrame:
    """Each checked claim of the paper: what the paper says, what we find, reproduced or not, why."""
    rows: list[dict[str, Any]] = []
    if res.screen is not None:
        rows += _screen_claims(res.screen)
    b = res.fits.get(PRIMARY)
    if b is not None and b.results is not None:
        rows += _anova_claims(res, b)
        rows += _reduction_claims(res, b)
    return pd.DataFrame(rows)
