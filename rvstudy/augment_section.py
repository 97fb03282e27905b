"""The response-surface loop on our own design: :func:`rsm.augment` on the study's full quadratic fits,
with the validation runs as new data (a section of the rv-stackup report).

For each response with a fit, the full quadratic of the design runs is tested against the solved
validation runs (Chow's predictive F test, :meth:`rsm.RSMResults.prediction_test`), then the
candidate terms (:mod:`rsm.candidates`: third- and fourth-order polynomial terms, and, when the
factors EB and EC are the pin circle diameter and pin radius errors on their default instances, the
pin clearance ``|EB/2 - EC|`` in um and its products with EA) are judged on the design and the
validation runs together by :class:`rsm.SelectionRule` (Bonferroni-adjusted partial F and BIC).

The solver is deterministic: the replicated centre runs agree exactly, so pure error is zero and the
whole residual is lack of fit; the partial F test then asks whether a term explains a part of that
lack of fit that is large against what remains, which is the question the loop answers here.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pandas as pd

import rsm
from rsm.candidates import default_candidates

__all__ = ["AugmentSection", "augment_fits", "augment_table", "augment_section"]


@dataclass
class AugmentSection:
    """A report section: heading, introduction, tables shown (name -> DataFrame), findings (one line each) and
    tables only written (``data``)."""

    heading: str
    intro: str
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    findings: list[str] = field(default_factory=list)
    data: dict[str, pd.DataFrame] = field(default_factory=dict)   # written as tables, not shown
    results: dict[str, rsm.AugmentResult] = field(default_factory=dict)


def _physical_ok(fs: Any) -> bool:
    """The pin clearance terms mean what they say only for the paper's EB/EC on their default instances."""
    return (fs.errors.get("EB") == "pin_circle_diameter" and fs.errors.get("EC") == "pin_radius"
            and fs.patterns.get("EB") is None and fs.patterns.get("EC") is None)


def augment_fits(res: Any) -> dict[str, rsm.AugmentResult]:
    """Run :func:`rsm.augment` on every fitted response of a :class:`rvstudy.study.StudyResult`.

    Parameters
    ----------
    res : StudyResult
        A study with the ``doe`` stage (and, for the new-data check, the ``validation`` stage).

    Returns
    -------
    dict
        Response name -> :class:`rsm.AugmentResult` (responses without a fit are left out).
    """
    fs = res.factors
    out: dict[str, rsm.AugmentResult] = {}
    val = res.validation
    ok = val[val["status"] == "ok"] if val is not None and len(val) else None
    cands = default_candidates(fs.names, fs.levels, physical=_physical_ok(fs))
    rule = rsm.SelectionRule(alpha=res.config.alpha)
    for resp, b in res.fits.items():
        if b.results is None:
            continue
        new = ok[fs.names + [resp]] if ok is not None and len(ok) else None
        out[resp] = rsm.augment(b.results, new_data=new, candidates=cands, rule=rule)
    return out


def augment_table(augs: dict[str, rsm.AugmentResult]) -> pd.DataFrame:
    """One row per response and model (``before`` = the full quadratic, ``after`` = with the added terms),
    both fitted to the design and validation runs together; response units arcmin (ssr in arcmin^2)."""
    rows = []
    for resp, a in augs.items():
        nr = a.new_runs or {}
        for tag, r in (("before", a.before), ("after", a.after)):
            b = rsm.fit_block(r)
            rows.append({
                "response": resp, "model": tag, "n_terms": len(r.term_names), "n_runs": r.nobs,
                "added": (", ".join(a.added) or "(none)") if tag == "after" else "", "ssr": b["ssr"], "rmse": b["rmse"],
                "r2": b["r2"], "r2_pred": b["r2_pred"], "bic": b["bic"],
                "new_runs": nr.get("n", 0) if tag == "before" else None,
                "new_runs_F": nr.get("F") if tag == "before" else None,
                "new_runs_p": nr.get("p") if tag == "before" else None,
                "new_runs_rmse_pred": nr.get("rmse_pred") if tag == "before" else None,
            })
    return pd.DataFrame(rows)


def candidate_table(augs: dict[str, rsm.AugmentResult], top: int = 5) -> pd.DataFrame:
    """The best ``top`` estimable candidates of each iteration (partial F, p, Bonferroni p, dBIC)."""
    rows = []
    for resp, a in augs.items():
        for i, tests in enumerate(a.iterations, 1):
            est = sorted([t for t in tests if t.estimable], key=lambda t: t.p)[:top]
            for t in est:
                rows.append({"response": resp, "iteration": i, "term": t.term, "kind": t.kind, "F": t.F, "p": t.p,
                             "p_bonferroni": t.p_bonferroni, "delta_bic": t.delta_bic,
                             "added": t.term in a.added[i - 1:i]})
    return pd.DataFrame(rows)


def augment_section(res: Any) -> AugmentSection | None:
    """The report section of the loop on our design (None without a fit)."""
    augs = augment_fits(res)
    if not augs:
        return None
    n_val = next(iter(augs.values())).new_runs
    intro = (
        "`rsm.augment` on the full quadratic of each response (the `rsm fit --augment` loop): the fit is tested "
        "against the solved validation runs (Chow's predictive F test"
        + (f", {n_val['n']} runs" if n_val else "; no validation runs in this run") + "), then every "
        "third- and fourth-order polynomial term the runs can estimate"
        + (" and the pin clearance terms |EB/2-EC| (um), EA:|EB/2-EC|, EA^2:|EB/2-EC|" if _physical_ok(res.factors)
           else "") + " is added alone and judged on the design and validation runs together (Bonferroni-adjusted "
        "partial F at alpha and a lower BIC); the supported term is added and the loop repeats (at most 2). The "
        "solver is deterministic, so pure error is zero and the whole residual is lack of fit. "
        f"Contact model: {res.config.contact_models()['augment']}.\n")
    sec = AugmentSection("## 8b. The response-surface loop on our design (lack of fit -> higher-order or physical "
                         "term)\n", intro, results=augs)
    sec.tables["augment_summary"] = augment_table(augs)
    sec.tables["augment_candidates"] = candidate_table(augs)
    for resp, a in augs.items():
        sec.findings.append(f"- {resp}: {a.verdict}")
    sec.findings.append("")
    return sec
