"""``rv-calibrate DATASET --out DIR [options]``: calibrate the reducer model on measured TE and report it;
``rv-calibrate import FILES... --out DATASET_DIR ...``: turn TE rig records into a dataset (:mod:`rvrig.cli_import`).

Reads the dataset folder (``runs.csv``, ``samples.csv``, optionally ``design.json``; ``--reducer`` names the design
when the folder does not; :mod:`rvrig.dataset`), shows what the rig measured before any model
(:mod:`rvrig.rigtable`), runs the loop (:func:`rvcalib.loop.calibrate` with one
:class:`rvcalib.settings.CalibrationSettings` made from the options), computes the datasheet of the reducer as
declared and as calibrated (:mod:`rvcalib.datasheet`), optionally predicts each load left out of the fit
(``--holdout-loads``, :mod:`rvcalib.holdout`), writes the report (:mod:`rvcalib.report`) into ``--out`` and prints
a human summary, or with ``--json`` the report's JSON object.

Exit status: 0 done; 2 bad input (an option, the dataset or the design: one line on stderr naming the option or the
file and column, its value and what is allowed); 1 the loop failed on valid input (one line on stderr).
"""
from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

from rvcad import validation as v
from rvcad.errors import MAX_LOAD_NM, Case
from rvcalib.reportmd import num, reducer_line, te_formula
from rvcalib.result import scales_text
from rvcalib.settings import CONTACTS, ESTIMATORS, MAX_LINEARISATIONS, CalibrationSettings

#: Most single effects (the estimator's own bound on ``max_effects``).
MAX_EFFECTS = 1000
#: Highest empirical order (the settings' bound on ``max_order``).
MAX_ORDER = 5000
#: Largest prior weight of the empirical block, in units of one physical type's weight.
MAX_EMPIRICAL_WEIGHT = 1e6


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``rv-calibrate DATASET``."""
    p = v.ArgumentParser(
        prog="rv-calibrate",
        usage="%(prog)s DATASET --out DIR [--reducer DESIGN.json] [--json] [--workers N] [--max-effects L] "
              "[--max-order K] [--empirical-weight W] [--contact physical|impact] [--rated-Nm T] [--samples-per-rev K] "
              "[--holdout-loads] "
              "[--estimator sparse|tolerance-prior] [--max-linearisations N] [--no-half-turn] [--verbose]\n       %(prog)s import FILES... --out DATASET_DIR [--ratio N | --reducer DESIGN.json] "
              "[options of rv-calibrate import --help]",
        description="Calibrate the reducer model on measured TE: what the rig shows, the effects the declared model "
                    "lacks (named with 95 % intervals, or grouped where the data cannot split them), what no "
                    "physical effect explains, the datasheet as calibrated; report.md, result.json and figures in "
                    "--out. Rig records (one CSV per test, output angle and TE sampled in time): first "
                    "'rv-calibrate import FILES... --out DATASET_DIR' (see 'rv-calibrate import --help').",
        epilog="subcommand: rv-calibrate import FILES... --out DATASET_DIR [--ratio N | --reducer DESIGN.json] ... "
               "turns TE rig records into a dataset folder (rv-calibrate import --help). The method: "
               "docs/calibration.md; the command and the report: docs/calibrate.md.")
    p.add_argument("dataset", metavar="DATASET", help="dataset folder with runs.csv and samples.csv")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for report.md, result.json and the figures")
    p.add_argument("--reducer", default=None, metavar="DESIGN.json",
                   help="the reducer measured: a design JSON (the 'design' object of a case JSON, e.g. "
                        "{\"z_sun\": 18, \"z_planet\": 36}); default: DATASET/design.json, else the paper's design")
    p.add_argument("--json", action="store_true", help="print the report's JSON object instead of the summary")
    p.add_argument("--workers", type=int, default=2, metavar="N",
                   help="processes for the model's Jacobian columns (default 2; 1 = this process; the same numbers "
                        "whatever the count)")
    p.add_argument("--max-effects", "--max-terms", dest="max_effects", type=int, default=CalibrationSettings.max_effects,
                   metavar="L", help=f"most single effects of the estimator (--max-terms is the same), a cap the result says when it binds "
                                     f"(default {CalibrationSettings.max_effects})")
    p.add_argument("--max-order", dest="max_order", type=int, default=None, metavar="K",
                   help="highest order of the empirical terms (default: the highest the readings resolve)")
    p.add_argument("--empirical-weight", dest="empirical_weight", type=float,
                   default=CalibrationSettings.empirical_weight, metavar="W",
                   help="prior weight of the empirical block in units of one physical type's (default "
                        f"{CalibrationSettings.empirical_weight:g})")
    p.add_argument("--contact", default=None, metavar="LAW",
                   help="contact law of the model: physical or impact (default: rvdyn's, physical)")
    p.add_argument("--rated-Nm", dest="rated_Nm", type=float, default=None, metavar="T",
                   help="the reducer's rated output torque, N m, for lost motion (+-3 %% of it) and the datasheet; "
                        "default: 167 N m for the default design only (the paper's RV-20E class); any other design "
                        "needs it")
    p.add_argument("--samples-per-rev", dest="samples_per_rev", type=int, default=None, metavar="K",
                   help="readings per output revolution the loop fits: denser runs are averaged down by the import's "
                        "anti-alias low-pass (default: the density flat to the model's orders 2 Zp and N + 1, e.g. "
                        "205 for ratio 81 with 40 pins; 0: every reading); the measured figures use every reading")
    p.add_argument("--holdout-loads", dest="holdout_loads", action="store_true",
                   help="also fit without each load in turn and predict it (one more loop per load)")
    p.add_argument("--estimator", default="sparse", metavar="E",
                   help="sparse (the sum of single effects, default) or tolerance-prior (every candidate a Gaussian "
                        "effect at its tolerance class, no selection); docs/calibration.md")
    p.add_argument("--max-linearisations", dest="max_linearisations", type=int,
                   default=CalibrationSettings.max_linearisations, metavar="N",
                   help="most linearisations of the reducer model (default "
                        f"{CalibrationSettings.max_linearisations}); a tolerance-prior search stopped by it names "
                        "nothing")
    p.add_argument("--no-half-turn", dest="half_turn", action="store_false",
                   help="tolerance-prior: search once, not again from the half-turn image of the crank-indexed "
                        "errors (halves the time; the answer then holds one arrangement only)")
    p.add_argument("--verbose", action="store_true", help="progress on stderr")
    return p


def settings_from(args: argparse.Namespace) -> CalibrationSettings:
    """The options checked (OptionError naming the option, its value and what is allowed) as one settings object."""
    v.option_int(args.workers, "--workers", 1, v.MAX_WORKERS, why="local processes")
    v.option_int(args.max_effects, "--max-effects", 1, MAX_EFFECTS)
    v.option_int(args.max_linearisations, "--max-linearisations", 1, MAX_LINEARISATIONS)
    if args.max_order is not None:
        v.option_int(args.max_order, "--max-order", 1, MAX_ORDER)
    v.option_real(args.empirical_weight, "--empirical-weight", 0.0, MAX_EMPIRICAL_WEIGHT, lo_open=True)
    allowed = [c for c in CONTACTS if c is not None]
    if args.contact is not None and args.contact not in allowed:
        v.reject("--contact", args.contact, " or ".join(allowed), cls=v.OptionError)
    if args.rated_Nm is not None:
        v.option_real(args.rated_Nm, "--rated-Nm", 0.0, MAX_LOAD_NM, lo_open=True, unit="N m")
    if args.samples_per_rev is not None and args.samples_per_rev != 0:
        v.option_int(args.samples_per_rev, "--samples-per-rev", 16, 100000, why="0 for every reading")
    if args.estimator not in ESTIMATORS:
        v.reject("--estimator", args.estimator, " or ".join(ESTIMATORS), cls=v.OptionError)
    v.output_dir(args.out)
    return CalibrationSettings(max_effects=args.max_effects, max_order=args.max_order,
                               empirical_weight=float(args.empirical_weight), workers=args.workers,
                               contact=args.contact, rated_Nm=args.rated_Nm, estimator=args.estimator,
                               max_linearisations=args.max_linearisations,
                               half_turn=args.half_turn, samples_per_rev=args.samples_per_rev).validate()


def _friction(result, dataset, law) -> Any:
    """The friction arms of the declared reducer at the loaded runs' mean load, when a compliance is named (to read
    it as friction too); None otherwise or when rvdyn cannot solve them (the reading is then left out)."""
    from rvcalib.datasheet import COMPLIANCE, reducer_case
    from rvdyn.friction import friction_arms

    loads = [r.load_Nm for r in dataset.runs if r.load_Nm > 0]
    if not loads or not any(e.key == COMPLIANCE for e in result.effects):
        return None
    try:
        return friction_arms(Case.from_dict(reducer_case(dataset.runs[0].case_dict())), sum(loads) / len(loads),
                             law=law)
    except (ValueError, ArithmeticError):
        return None


def run(dataset, settings: CalibrationSettings, out: str, holdout: bool = False, log=None,
        model_for=None) -> dict:
    """Everything the command does after reading its input; returns :func:`rvcalib.report.write_report`'s dict.

    ``model_for(dataset)``: the loop's forward model of a dataset (tests give a stand-in; None: the reducer model).
    The declared model, the datasheet and the predictions of left-out loads are solved by rvdyn whatever it is.
    """
    model_for = model_for or (lambda ds: None)
    from rvcalib.datasheet import reducer_datasheet
    from rvcalib.equivalents import result_equivalents
    from rvcalib.holdout import declared_te, holdout_loads
    from rvcalib.loop import calibrate
    from rvcalib.report import measured_figures, write_report
    from rvdyn.solver import law_from_model
    from rvrig.average import averaged

    law = None if settings.contact is None else law_from_model({"contact": settings.contact})
    measured = measured_figures(dataset, settings.rated_Nm)
    dataset, fit_notes = averaged(dataset, settings.samples_per_rev)
    result = calibrate(dataset, settings, log=log, model=model_for(dataset))
    result.notes[:0] = fit_notes
    try:
        declared = declared_te(dataset, law)
    except ValueError as exc:        # the declared model rvdyn cannot solve: the residual before is left out
        declared = None
        result.notes.append(f"the declared model could not be solved for the figures: {v.one_line(exc)}")
    sheet = reducer_datasheet(result, dataset, settings.rated_Nm, law)
    held = holdout_loads(dataset, settings, log, full=result, declared=declared, law=law,
                         fit=lambda ds, st, lg: calibrate(ds, st, log=lg, model=model_for(ds))) if holdout else None
    eq = result_equivalents(result, dataset.design, _friction(result, dataset, law))
    return write_report(result, dataset, out, measured=measured, datasheet=sheet, holdout=held, declared=declared,
                        equivalents=eq)


def _fmt_member(m: dict) -> str:
    size = m["value"] if isinstance(m["value"], str) else f"{m['value']:.4g} {m['unit']}"
    ang = f" at {m['angle_deg']:.1f} deg" if m.get("angle_deg") is not None and not isinstance(m["value"], str) else ""
    return f"{m['name']} {size}{ang} (p {m['probability']:.2f})"


def _summary_measured(m: dict) -> list[str]:
    lines = ["what the rig shows (measured, before any model; arcsec):"]
    for t in m["tests"]:
        lines.append(f"  test {t['test']} at {num(t['load_Nm'])} N m: mean +1 {num(t['mean_fw_arcsec'])}, -1 "
                     f"{num(t['mean_bw_arcsec'])}, B - F {num(t['bw_minus_fw_arcsec'])}, peak-to-peak "
                     f"{num(t['pp_fw_arcsec'])} / {num(t['pp_bw_arcsec'])}")
    d = m["datasheet"]

    def fig(key: str, unit: str) -> str:
        return "missing" if d[key] is None else f"{d[key]:.4g} {unit}"

    lines.append(f"  measured: secant rigidity {fig('secant_rigidity_Nm_per_arcmin', 'N m/arcmin')}, light-load play "
                 f"{fig('light_load_play_arcmin', 'arcmin')}, lost motion {fig('lost_motion_arcmin', 'arcmin')} "
                 f"(rated torque: {m['rated_source']}; what is missing and why: the report)")
    return lines


def _summary_datasheet(d: dict | None) -> list[str]:
    if d is None:
        return []
    if not d.get("computed"):
        return [f"datasheet as calibrated: not computed: {d['rated_source']}"]
    m, c, ci = d["model"], d["calibrated"], d.get("rigidity_ci")
    return [f"datasheet at {d['rated_torque_Nm']:g} N m rated ({d['rated_source']}): torsional rigidity "
            f"{num(m['torsional_rigidity_Nm_per_arcmin'])} (declared) -> {num(c['torsional_rigidity_Nm_per_arcmin'])}"
            + (f" [{num(ci[0])}, {num(ci[1])}]" if ci else "") + " N m/arcmin calibrated; lost motion "
            f"{num(m['lost_motion_arcmin'])} -> {num(c['lost_motion_arcmin'])} arcmin; backlash "
            f"{num(m['backlash_arcmin'])} -> {num(c['backlash_arcmin'])} arcmin"]


def summary(obj: dict) -> str:
    """The human summary: the report's JSON object (:func:`rvcalib.report.report_object`) in a few lines."""
    lines = [obj["verdict"], f"reducer: {reducer_line(obj['reducer'])}; measured TE = {te_formula(obj['ratio'])}"]
    lines += _summary_measured(obj["measured"])
    eq = obj["equivalents"]
    lines.append("named effects (95 % interval):" if obj["effects"] else "named effects: none")
    for e in obj["effects"]:
        ang = f" at {e['angle_deg']:.1f} deg" if e["angle_deg"] is not None else ""
        lines.append(f"  {e['name']} = {e['value']:.5g} {e['unit']}{ang} [{e['ci95'][0]:.5g}, {e['ci95'][1]:.5g}] "
                     f"(probability {e['probability']:.3f}{scales_text(e['value'], e.get('prior_scale'))})")
        for q in eq["effects"].get(e["name"], []):
            lines.append(f"    or, as Coulomb friction, {q['parameter']} = {q['value']:.4g} (default {q['default']:g})"
                         if "default" in q else f"    the same TE as {q['parameter']} = {q['value']:+.4g} {q['unit']}")
    for i, g in enumerate(obj["groups"]):
        lines.append(f"group {i + 1} ({g.get('kind', 'physical')}; the data cannot split it): "
                     + "; ".join(_fmt_member(m) for m in g["members"][:6])
                     + (f"; and {len(g['members']) - 6} more" if len(g["members"]) > 6 else ""))
    for u in obj["unexplained"]:
        lines.append(f"unexplained: {u['label']}: {num(u['amplitude_arcsec'])} arcsec, phase {num(u['phase_deg'])} "
                     f"deg (A cos(k theta_out - phase); probability {u['probability']:.2f})")
    lines.append("tests' constants (the rig's zero, nuisance): "
                 + ", ".join(f"{n['test']} {n['constant_arcsec']:+.4g}" for n in obj["nuisance"]) + " arcsec")
    lines += _summary_datasheet(obj["datasheet"])
    for r in (obj["holdout"] or {}).get("rows", []):
        lines.append(f"load {r['load_Nm']:g} N m left out: prediction RMS {num(r['rms_prediction_arcsec'])} arcsec, "
                     f"noise {num(r['noise_arcsec'])} ({r['status']})")
    fixed = obj["residual_spectrum"]["fixed_frequency"]
    if fixed:
        lines.append(f"{len(fixed)} fixed-frequency line(s) in the residual, not claimed for the reducer (largest "
                     f"{fixed[0]['amplitude_arcsec']:.3g} arcsec at order {fixed[0]['order']:.4g})")
    if obj["cap_binds"]:
        lines.append(f"every single effect allowed was used (--max-effects {obj['settings']['max_effects']} binds)")
    lines.append(f"report: {obj['report']}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (module docstring).

    ``rv-calibrate import ...`` is :mod:`rvrig.cli_import`'s."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "import":
        from rvrig.cli_import import main as import_main

        return import_main(argv[1:])
    args = build_parser().parse_args(argv)
    from rvrig.dataset import read_dataset

    try:
        settings = settings_from(args)
        ds = read_dataset(args.dataset, design=args.reducer)
    except (ValueError, OSError) as exc:
        return v.refuse("rv-calibrate", exc)
    log = (lambda s: print(f"rv-calibrate: {s}", file=sys.stderr, flush=True)) if args.verbose else None
    try:
        paths = run(ds, settings, args.out, args.holdout_loads, log)
    except OSError as exc:
        print(f"rv-calibrate: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 2
    except (ValueError, ArithmeticError) as exc:
        print(f"rv-calibrate: error: the calibration failed: {v.one_line(exc)}", file=sys.stderr)
        return 1
    print(json.dumps(paths["object"], indent=2) if args.json else summary(paths["object"]))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
