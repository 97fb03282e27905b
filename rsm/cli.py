"""Command line: ``rsm fit`` and ``rsm design`` (also ``python -m rsm``).

``rsm fit DATA.csv --factors F1 F2 ... --response Y [--levels LEVELS.csv]
[--units coded|actual] [--model quadratic|linear|2fi] [--terms T ...]
[--reduce none|backward|paper] [--alpha A] [--alpha-out A] [--no-hierarchy]
[--validate HOLDOUT.csv] [--plots DIR] [--augment [--new-data NEW.csv] [--max-add N]
[--no-physical]] [--json]``

Prints a human summary; with ``--json`` prints one JSON object instead::

    {"response": ..., "factors": [...], "units": "coded", "n_runs": 27, "terms": [...],
     "anova": {"Model": {"sum_sq": .., "df": .., "mean_sq": .., "F": .., "p": ..}, "EA": {..},
               ..., "Residual": {..}, "Lack of fit": {..}, "Pure error": {..}, "Cor total": {..}},
     "r2": .., "r2_adj": .., "r2_pred": .., "press": .., "adeq_precision": .., "std_dev": ..,
     "mean": .., "cv_percent": .., "rmse": ..,
     "coefficients": {"coded": {"Intercept": .., "EA": ..}, "actual": {...} | null},
     "coefficient_table": {"coded": {term: {coef, std_err, t, p, ci_lower, ci_upper}}, "actual": ...},
     "pure_error_is_zero": false, "notes": [...],
     "reduction": {...} (with --reduce), "comparison": {...} (with --reduce),
     "validation": {...} (with --validate), "plots": [...] (with --plots),
     "augment": {...} (with --augment, below)}

``--augment`` runs :func:`rsm.augment.augment` on the full fit: lack of fit (and, with
``--new-data``, Chow's predictive test of the fit on the new runs) -> the supported higher-order
or physical term -> refit, before and after. Its JSON block::

    "augment": {
      "added": ["EB^2:EC"],                       # display names, in the order added
      "verdict": "...",                           # one paragraph, as printed
      "before": FIT, "after": FIT,                # the starting / augmented model on all runs
      "iterations": [[TEST, ...], ...],           # candidate tests of each iteration
      "new_runs": null | {"n", "F", "df_num", "df_den", "p", "rmse_pred", "bias", "lack_of_fit"},
      "rule": {"alpha", "require_bic", "prefer_physical", "max_add"}}
    FIT  = {"terms", "n_runs", "ssr", "df_resid", "rmse", "r2", "r2_adj", "r2_pred", "press",
            "bic", "lack_of_fit": {"ss", "df", "F", "p"}, "pure_error": {"ss", "df"},
            "residuals": [...]}
    TEST = {"term", "kind" (polynomial|physical), "meaning", "estimable", "reason", "ssr", "F",
            "p", "p_bonferroni", "delta_bic", "lack_of_fit_F", "lack_of_fit_p", "r2_pred",
            "aliases": [...]}

``ssr`` is the residual sum of squares (response units squared), ``rmse = sqrt(ssr / n_runs)``.

NaN (undefined F/p, "/" in the paper) is written as ``null``.

``rsm design {bbd,ccd,ff3} --factors K [--names N ...] [--center N] [--alpha rotatable|face|A]
[--levels LEVELS.csv] [--units coded|actual|both] [--randomize --seed S] [--out FILE.csv] [--json]``

Bad input (missing or non-numeric column, constant factor, too few runs ...) prints
``rsm: error: ...`` to stderr and exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from .csvio import read_csv_strict

if TYPE_CHECKING:
    from .results import RSMResults

__all__ = ["main", "jsonable", "build_parser"]


def jsonable(obj: Any) -> Any:
    """Convert numpy/pandas scalars and containers to JSON types; NaN/inf -> None."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [jsonable(v) for v in obj.tolist()]
    if isinstance(obj, pd.Series):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


#: Largest number of centre runs of a generated design (each is one run of the experiment or solver;
#: the same bound as rvcad.validation.MAX_CENTER_RUNS, kept here so rsm imports nothing of rvcad).
MAX_CENTER_RUNS = 1000


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line on stderr, exit status 2 (like the other command lines)."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _output_path(path: str, opt: str, folder: bool) -> None:
    """Refuse an output path that is the wrong kind of existing thing, before any work (ValueError)."""
    p = Path(path)
    if folder and p.exists() and not p.is_dir():
        raise ValueError(f"{opt} '{p}' is an existing file; allowed: a folder (created if missing)")
    if not folder and p.is_dir():
        raise ValueError(f"{opt} '{p}' is an existing folder; allowed: a file path")
    for parent in p.parents:
        if parent.exists() and not parent.is_dir():
            raise ValueError(f"{opt} '{p}' lies under the file '{parent}'; allowed: a path whose folders are folders")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for documentation tools)."""
    p = _Parser(prog="rsm", description="Response-surface designs and fits.")
    sub = p.add_subparsers(dest="command", required=True)

    f = sub.add_parser("fit", help="fit a response surface to a CSV of runs",
                       description="Least-squares response-surface fit with the paper's ANOVA.")
    f.add_argument("data", help="CSV file, one row per run")
    f.add_argument("--factors", nargs="+", required=True, metavar="F", help="factor columns")
    f.add_argument("--response", required=True, metavar="Y", help="response column")
    f.add_argument("--levels", metavar="LEVELS.csv",
                   help="levels table (factor,low,center,high[,unit]) for actual-unit coefficients")
    f.add_argument("--units", choices=["coded", "actual"], default="coded",
                   help="units of the factor columns in DATA (default coded)")
    f.add_argument("--model", choices=["quadratic", "linear", "2fi"], default="quadratic")
    f.add_argument("--terms", nargs="+", metavar="T",
                   help="explicit terms (overrides --model); presets allowed, e.g. "
                        "--terms quadratic EA^3 EA:EB:EC")
    f.add_argument("--reduce", choices=["none", "backward", "paper"], default="none",
                   help="backward: refitted hierarchical elimination; paper: drop p>=alpha "
                        "terms without refitting (Eq. 9)")
    f.add_argument("--alpha", type=float, default=0.05,
                   help="significance level for intervals and paper-mode selection (0.05)")
    f.add_argument("--alpha-out", type=float, default=0.05, help="backward elimination alpha-out (0.05)")
    f.add_argument("--no-hierarchy", action="store_true", help="backward elimination ignores hierarchy")
    f.add_argument("--validate", metavar="HOLDOUT.csv",
                   help="held-out runs (same columns) for RMSE / max error / PI coverage")
    f.add_argument("--plots", metavar="DIR", help="write PNG figures into DIR")
    f.add_argument("--augment", action="store_true",
                   help="lack of fit -> test higher-order and physical terms -> add the supported ones")
    f.add_argument("--new-data", metavar="NEW.csv",
                   help="with --augment: new runs or measured responses (same columns) to test the fit on "
                        "and to judge the terms on together with DATA")
    f.add_argument("--max-add", type=int, default=2, metavar="N",
                   help="with --augment: add at most N terms (default 2)")
    f.add_argument("--no-physical", action="store_true",
                   help="with --augment: polynomial candidates only (no pin clearance terms)")
    f.add_argument("--json", action="store_true", help="print one JSON object")

    d = sub.add_parser("design", help="generate a design",
                       description="Box-Behnken, central composite or 3^k design.")
    d.add_argument("kind", choices=["bbd", "ccd", "ff3"])
    d.add_argument("--factors", type=int, metavar="K",
                   help="number of factors (default: all factors of --levels)")
    d.add_argument("--names", nargs="+", metavar="NAME", help="factor names (default x1..xK or --levels)")
    d.add_argument("--center", type=int, default=None,
                   help="number of centre runs (default 3 for bbd/ccd, 1 for ff3)")
    d.add_argument("--alpha", default="rotatable",
                   help="ccd axial distance: rotatable, face or a number (default rotatable)")
    d.add_argument("--levels", metavar="LEVELS.csv", help="levels table for actual units")
    d.add_argument("--units", choices=["coded", "actual", "both"], default=None,
                   help="columns written (default: both with --levels, else coded)")
    d.add_argument("--randomize", action="store_true", help="randomise the run order")
    d.add_argument("--seed", type=int, default=None, help="seed of the randomisation")
    d.add_argument("--out", metavar="FILE.csv", help="write the design to FILE.csv")
    d.add_argument("--json", action="store_true", help="print one JSON object")
    return p


def _clean(value: float, scale: float) -> float:
    """Round-off (below 1e-12 of ``scale``) to exactly zero, for printing."""
    return 0.0 if abs(value) <= 1e-12 * scale else value


def _results_block(res) -> dict:
    d = res.to_dict()
    return {k: d[k] for k in ("terms", "anova", "r2", "r2_adj", "r2_pred", "press",
                              "adeq_precision", "std_dev", "rmse", "coefficients", "notes")}


def _fit_inputs(args: argparse.Namespace) -> tuple[pd.DataFrame, pd.DataFrame | None]:
    """Check the ``rsm fit`` options; read the data file and the ``--new-data`` file (``None`` without it)."""
    path = Path(args.data)
    if not path.is_file():
        raise ValueError(f"data file '{path}' does not exist")
    if args.plots:
        _output_path(args.plots, "--plots", folder=True)
    if not args.augment:
        for flag, given in (("--new-data", args.new_data is not None), ("--max-add", args.max_add != 2),
                            ("--no-physical", args.no_physical)):
            if given:
                raise ValueError(f"{flag} needs --augment")
    if args.max_add < 1:
        raise ValueError(f"--max-add must be an integer >= 1, got {args.max_add}")
    new_data = None
    if args.new_data is not None:
        npath = Path(args.new_data)
        new_data = read_csv_strict(npath, "--new-data file")
        if len(new_data) == 0:
            raise ValueError(f"--new-data file '{npath}' has no rows")
    return read_csv_strict(path, "data file"), new_data


def _fit_reduction(res: RSMResults, args: argparse.Namespace, out: dict, text: list[str]) -> RSMResults:
    """Reduce the full fit as ``--reduce`` asks (backward or paper) and compare the reductions.

    Adds the ``reduction`` and ``comparison`` blocks to ``out`` (JSON) and their summary to ``text``;
    returns the fit the validation and the plots use (the refitted model of backward elimination).
    """
    from .reduce import compare_reductions

    final = res
    comp = compare_reductions(res, alpha=args.alpha, alpha_out=args.alpha_out,
                              hierarchy=not args.no_hierarchy)
    if args.reduce == "backward":
        b = comp.backward
        final = b.results
        out["reduction"] = {"method": "backward", "alpha_out": b.alpha_out,
                            "hierarchy": b.hierarchy, "removed": b.removed,
                            "steps": b.steps.to_dict(orient="records"),
                            **_results_block(b.results)}
        text += ["", f"Backward elimination (alpha-out {b.alpha_out}, hierarchy "
                     f"{'kept' if b.hierarchy else 'ignored'}, refitted): removed "
                     f"{', '.join(b.removed) or 'nothing'}", "", b.results.summary()]
    else:
        pr = comp.paper
        out["reduction"] = {
            "method": "paper", "alpha": pr.alpha, "units": pr.units, "terms": pr.terms,
            "dropped": pr.dropped, "refitted": False,
            "coefficients": {"coded": pr.coefficients_coded.to_dict(),
                             "actual": (None if pr.coefficients_actual is None
                                        else pr.coefficients_actual.to_dict())},
            "sse": pr.sse, "rmse": pr.rmse, "r2": pr.r2,
        }
        text += ["", f"Paper-mode simplification (terms with p < {pr.alpha}, coefficients "
                     f"kept from the full fit in {pr.units} units, not refitted):",
                 "  " + " + ".join(f"{v:.6g}*{k}" if k != "Intercept" else f"{v:.6g}"
                                   for k, v in pr.coefficients.items()),
                 f"  dropped: {', '.join(pr.dropped)}"]
    tab = comp.table
    out["comparison"] = {m: {c: tab.loc[m, c] for c in tab.columns} for m in tab.index}
    out["comparison"]["shortcut_cost_sse"] = comp.shortcut_cost
    text += ["", "Reduction comparison on the fitted runs (sse = residual SS, rmse = sqrt(sse/n))",
             tab[["n_terms", "sse", "rmse", "r2", "max_abs_resid", "refitted"]].to_string(
                 float_format=lambda v: f"{v:.6g}"),
             f"cost of not refitting the paper's terms: +{_clean(comp.shortcut_cost, res.ss_total):.6g}"
             " residual SS"]
    return final


def _fit_augment(res: RSMResults, args: argparse.Namespace, new_data: pd.DataFrame | None, out: dict,
                 text: list[str]) -> None:
    """Run ``--augment`` on the full fit; adds the ``augment`` block to ``out`` and its summary to ``text``.

    An error about the new runs names the ``--new-data`` file.
    """
    from .augment import SelectionRule, augment, format_augment
    from .candidates import default_candidates

    try:
        aug = augment(res, new_data=new_data,
                      candidates=default_candidates(res.factors, res.levels, physical=not args.no_physical),
                      rule=SelectionRule(alpha=args.alpha, max_add=args.max_add))
    except ValueError as exc:
        msg = str(exc)
        if msg.startswith("new data: "):
            msg = f"--new-data '{args.new_data}': {msg[len('new data: '):]}"
        raise ValueError(msg) from None
    out["augment"] = aug.to_dict()
    text += ["", format_augment(aug)]


def _cmd_fit(args: argparse.Namespace) -> int:
    from .model import ResponseSurfaceModel

    data, new_data = _fit_inputs(args)
    terms = args.terms if args.terms else args.model
    model = ResponseSurfaceModel(data, args.factors, args.response, terms=terms,
                                 levels=args.levels, units=args.units)
    res = model.fit(alpha=args.alpha, warn=False)
    out = res.to_dict()
    final = res
    text = [res.summary()]
    if args.reduce != "none":
        final = _fit_reduction(res, args, out, text)
    vdata = None
    if args.validate:
        vdata = read_csv_strict(args.validate, "validation file")
        vr = final.validate(vdata, units=args.units)
        out["validation"] = vr.to_dict()
        text += ["", f"Validation on {vr.n} held-out runs: RMSE {vr.rmse:.4g}, max |error| "
                     f"{vr.max_abs_error:.4g}, bias {vr.bias:.4g}, R2 {vr.r2:.4f}, "
                     f"{100 * (1 - vr.alpha):.0f}% PI coverage {vr.pi_coverage:.2%}"]
    if args.plots:
        from .plots import plot_all

        paths = plot_all(final, args.plots, validation=vdata)
        out["plots"] = [str(p) for p in paths]
        text += ["", f"wrote {len(paths)} figures to {args.plots}"]
    if args.augment:
        _fit_augment(res, args, new_data, out, text)
    if args.json:
        print(json.dumps(jsonable(out), allow_nan=False))
    else:
        print("\n".join(text))
    return 0

def _cmd_design(args: argparse.Namespace) -> int:
    from .coding import Levels
    from .design import make_design

    if args.out:
        _output_path(args.out, "--out", folder=False)
    if args.center is not None and not 0 <= args.center <= MAX_CENTER_RUNS:
        raise ValueError(f"--center {args.center} is out of range; allowed: an integer in [0, {MAX_CENTER_RUNS}]")
    levels = Levels.coerce(args.levels)
    k = args.factors
    if k is None:
        if args.names:
            k = len(args.names)
        elif levels is not None:
            k = len(levels)
        else:
            raise ValueError("give --factors K (or --names / --levels)")
    kwargs: dict[str, Any] = {"factors": args.names, "levels": levels,
                              "randomize": args.randomize, "seed": args.seed}
    if args.kind == "ccd":
        try:
            kwargs["alpha"] = float(args.alpha)
        except ValueError:
            kwargs["alpha"] = args.alpha
    design = make_design(args.kind, k, args.center, **kwargs)
    units = args.units or ("both" if levels is not None else "coded")
    frame = design.to_frame(units)
    if args.out:
        design.to_csv(args.out, units)
    if args.json:
        obj = {"kind": design.kind, "factors": design.factors, "n_runs": design.n_runs,
               "alpha": design.alpha, "seed": design.seed, "units": units,
               "out": args.out, "runs": frame.to_dict(orient="records")}
        print(json.dumps(jsonable(obj), allow_nan=False))
    elif args.out:
        print(f"wrote {design.kind} design: {design.n_runs} runs, {k} factors -> {args.out}")
    else:
        print(frame.to_csv(index=False), end="")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``rsm`` console script.

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 on bad input (message on stderr).
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or usage error (2)
        return int(exc.code) if isinstance(exc.code, int) else 2
    try:
        if args.command == "fit":
            return _cmd_fit(args)
        return _cmd_design(args)
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        print(f"rsm: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"rsm: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 2
