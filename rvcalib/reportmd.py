"""The text of ``report.md``, written from the report's JSON object (:func:`rvcalib.report.report_object`), so
the text and the JSON say the same: a group member beyond its physical bounds is ``unbounded`` in both.

Each section is one function of the object; :func:`markdown` joins them. Every formula uses the dataset's ratio.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from rvcalib.datasheet import rated_torque
from rvcalib.result import in_prior_scales

#: Lines of the residual spectrum listed per kind.
MAX_LINES = 12


def num(v: Any, nd: int = 4) -> str:
    """A number for a table: ``-`` for None, text as it is (``unbounded``), else ``nd`` significant digits."""
    if v is None:
        return "-"
    if isinstance(v, str):
        return v
    if isinstance(v, bool):
        return "yes" if v else "no"
    return f"{v:.{nd}g}"


def _table(header: list[str], rows: list[list]) -> list[str]:
    return (["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
            + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows] + [""])


def reducer_line(red: dict) -> str:
    """The reducer: ratio, tooth and pin counts, where the design came from."""
    src = "the default (paper) design" if red["source"] == "default" else red["source"]
    return (f"ratio {red['ratio']:g} (Z1 {red['z_sun']}, Z2 {red['z_planet']}, {red['z_pins']} pins, {red['z_disc']} "
            f"lobes, pin circle {red['pin_circle_diameter_mm']:g} mm); design from {src}")


def te_formula(ratio: float) -> str:
    return f"(output_deg - input_deg / {ratio:g}) * 3600 arcsec"


def _head(obj: dict, dataset) -> list[str]:
    L = [f"# rv-calibrate report: `{dataset.path}`", "", f"**{obj['verdict']}**", "",
         f"- reducer: {reducer_line(obj['reducer'])}",
         f"- measured TE of a reading: {te_formula(obj['ratio'])}, {obj['ratio']:g} the ratio of this reducer",
         f"- {len(dataset.runs)} runs in {len(dataset.tests)} tests, {dataset.n_samples} readings; noise "
         f"{obj['noise_arcsec']:.4g} arcsec (second differences of the records or of the residual, the smaller), the "
         f"estimator's "
         f"{obj['sigma_arcsec']:.4g}",
         f"- the loop ended: {obj['stopped_by']} after {obj['linearisations']} linearisations "
         f"({obj['seconds']:.1f} s)" + ("; **every single effect allowed was used (the cap --max-effects binds)**"
                                        if obj["cap_binds"] else ""),
         "- settings: " + ", ".join(f"{k} {v}" for k, v in obj["settings"].items() if k != "families")
         + f", families {', '.join(obj['settings']['families'])}", ""]
    return L


def _measured(obj: dict) -> list[str]:
    m = obj["measured"]
    L = ["## What the rig shows (measured, before any model)", "",
         "Per test (one homing of the rig): the mean TE per direction over whole revolutions (each test carries its "
         "own rig zero, so only differences within a test compare across tests), backward minus forward (B - F: "
         "the zero cancels), peak-to-peak per direction, the noise.", ""]
    rows = [[t["test"], num(t["load_Nm"]), num(t["speed_rpm"]), t["runs_fw"] or "-", t["runs_bw"] or "-",
             num(t["mean_fw_arcsec"]), num(t["mean_bw_arcsec"]), num(t["bw_minus_fw_arcsec"]), num(t["pp_fw_arcsec"]),
             num(t["pp_bw_arcsec"]), num(t["noise_arcsec"], 3)] for t in m["tests"]]
    L += _table(["test", "load (N m)", "speed (rpm)", "runs +1", "runs -1", "mean +1", "mean -1", "B - F", "p-p +1",
                 "p-p -1", "noise"], rows)
    orders = m.get("main_orders") or []
    if orders:
        L.append("Main orders of the measured TE (amplitude in arcsec, forward / backward):")
        L.append("")
        def amps(t: dict, k: int) -> str:
            return " / ".join(num(t.get(f"order{k}_amp_{d}_arcsec"), 3) for d in ("fw", "bw"))

        rows = [[t["test"], num(t["load_Nm"])] + [amps(t, o["order"]) for o in orders] for t in m["tests"]]
        L += _table(["test", "load (N m)"] + [f"{o['order']} ({o['label']})" for o in orders], rows)
    ch = [c for c in m["load_changes"] if c["quantity"] in ("bw_minus_fw_arcsec", "pp_fw_arcsec", "pp_bw_arcsec")
          or "_amp_" in c["quantity"]]
    if ch:
        L.append("How they change with load (lowest to highest load, arcsec):")
        L.append("")
        L += _table(["quantity", "low load", "high load", "at low", "at high", "change per 1000 N m"],
                    [[c["quantity"], num(c["load_low_Nm"]), num(c["load_high_Nm"]), num(c["low"]), num(c["high"]),
                      num(c["change_per_kNm"])] for c in ch])
    d = m["datasheet"]
    L += ["Measured datasheet (from B - F per load; rated torque: " + m["rated_source"] + "):", "",
          f"- secant torsional rigidity: {num(d['secant_rigidity_Nm_per_arcmin'])} N m/arcmin",
          f"- light-load play: {num(d['light_load_play_arcmin'])} arcmin",
          f"- lost motion: {num(d['lost_motion_arcmin'])} arcmin",
          f"- b/a rigidity: {num(d['torsional_rigidity_b_over_a_Nm_per_arcmin'])} N m/arcmin"]
    L += [f"  - {s}" for s in d["statements"]] + [""]
    return L


def _eq_lines(eqs: list, indent: str = "  ") -> list[str]:
    out = []
    for q in eqs:
        if "default" in q:
            out.append(f"{indent}- or, as Coulomb friction, `{q['parameter']}` = {num(q['value'])} "
                       f"[{num(q['ci_low'])}, {num(q['ci_high'])}] (the model's default {q['default']:g}): "
                       f"{q['meaning']}")
            continue
        implied = (f"; the design value it implies: {num(q['implied_design_value'], 5)} {q['unit']}"
                   if "implied_design_value" in q else "")
        ci = f" [{num(q['ci_low'], 5)}, {num(q['ci_high'], 5)}]" if q["ci_low"] != q["ci_high"] else ""
        out.append(f"{indent}- the same TE as `{q['parameter']}` = {num(q['value'], 5)} {q['unit']}{ci}{implied}: "
                   f"{q['meaning']}")
    return out


def _effects(obj: dict) -> list[str]:
    L = ["## Effects named", ""]
    if not obj["effects"]:
        return L + ["None: no credible set holds a single physical candidate.", ""]
    rows = [[f"`{e['name']}`", e["family"], num(e["value"], 5), e["unit"], num(e["angle_deg"]),
             f"[{num(e['ci95'][0], 5)}, {num(e['ci95'][1], 5)}]", num(e["probability"], 3),
             num(in_prior_scales(e["value"], e.get("prior_scale")), 2)] for e in obj["effects"]]
    L += _table(["effect", "family", "value", "unit", "angle (deg)", "95 % interval", "probability",
                 "prior scales"], rows)
    for e in obj["effects"]:
        L.append(f"- `{e['name']}`: {e['meaning']}")
        L += _eq_lines(obj["equivalents"]["effects"].get(e["name"], []))
    L += ["", "A two-component effect (an eccentricity) is a magnitude at an angle. The 95 % interval is that of the "
          "marginal posterior: the chance that it is no effect at all is in it. Prior scales: the size over the "
          "candidate's prior scale (a third of the paper's Table 4 value for a Table 4 error, the stated class of a "
          "model or measurement effect); a size of many prior scales is more likely a stand-in for an effect the "
          "library lacks than a reducer built within its tolerances.", ""]
    return L


def _groups(obj: dict) -> list[str]:
    L = ["## Groups: what the data cannot split", ""]
    if not obj["groups"]:
        return L + ["None: every credible set that names something holds one candidate.", ""]
    L += ["Each member would explain the same part of the data, with the size given (`unbounded`: beyond its "
          "physical bounds, i.e. the data fix no size for it alone) and its probability of being the one.", ""]
    eqs = obj["equivalents"].get("groups", [])
    for i, g in enumerate(obj["groups"]):
        L.append(f"Group {i + 1} ({g.get('kind', 'physical')}; coverage {num(g.get('coverage'), 3)}, purity "
                 f"{num(g.get('purity'), 3)}):")
        if g.get("reason"):
            L.append(f"Why a group: {g['reason']}.")
        L.append("")
        L += _table(["member", "size", "unit", "angle (deg)", "probability"],
                    [[f"`{m['name']}`", num(m["value"], 5), m["unit"], num(m.get("angle_deg")),
                      num(m["probability"], 3)] for m in g["members"]])
        for j, m in enumerate(g["members"]):
            q = eqs[i][j] if i < len(eqs) and j < len(eqs[i]) else []
            if q:
                L.append(f"- `{m['name']}`:")
                L += _eq_lines(q)
        L.append("")
    return L


def _unexplained(obj: dict) -> list[str]:
    L = ["## Unexplained structure (no physical candidate)", ""]
    if obj["unexplained"]:
        L += _table(["term", "order", "kind", "amplitude (arcsec)", "phase (deg)", "probability"],
                    [[u["label"], u["order"], u["kind"], num(u["amplitude_arcsec"]), num(u["phase_deg"]),
                      num(u["probability"], 3)] for u in obj["unexplained"]])
        L.append("Empirical terms `A cos(k theta_out - phase)` (theta_out the output angle reading; a constant `A` "
                 "for order 0), the same in every run (common), proportional to the load (load, relative to the "
                 "largest load), changing sign with the direction (direction), or both: this part of the signal is the "
                 "data's, and no effect of the library gives it. It is never named as a physical effect.")
    else:
        L.append("None: no credible set of empirical terms only.")
    if obj["diffuse"]:
        L.append("")
        L.append(f"{len(obj['diffuse'])} effect(s) of the fit are diffuse (members that do not explain the same "
                 "signal, or a size whose 95 % interval includes zero) and name nothing.")
    return L + [""]


def _nuisance(obj: dict) -> list[str]:
    L = ["## The tests' constants (the rig's zero: nuisance)", "",
         "A rig zeroes its TE at a homing before each test: each test's constant is estimated and removed, and is "
         "never an effect.", ""]
    L += _table(["test", "constant (arcsec)"], [[n["test"], num(n["constant_arcsec"])] for n in obj["nuisance"]])
    eq = obj["equivalents"]
    if eq.get("constant"):
        L.append(f"A constant common to every test (their mean, {num(eq['common_constant'])} arcsec) is, as far as the "
                 "TE can tell, also:")
        L += _eq_lines(eq["constant"], "")
        L.append("")
    return L


def _datasheet(obj: dict, dataset) -> list[str]:
    L = ["## Datasheet of the reducer: declared and calibrated (`rvdyn stiffness`)", ""]
    d = obj.get("datasheet")
    if d is None:
        rated, why = rated_torque(dataset.design, obj["settings"].get("rated_Nm"))
        return L + [("Not computed: " + why) if rated is None else
                    "Not computed with this report (rv-calibrate computes it: "
                    "rvcalib.datasheet.reducer_datasheet).", ""]
    if not d.get("computed"):
        return L + [f"Not computed: {d['rated_source']}.", ""]
    m, c, ci = d["model"], d["calibrated"], d.get("rigidity_ci")
    L.append(f"Rated torque {d['rated_torque_Nm']:g} N m ({d['rated_source']}); `friction_torque_Nm` is left out of "
             "the sweeps (a torque that resists every motion has no place in a sweep with the input locked).")
    L.append("")
    rows = []
    for k, lab in (("torsional_rigidity_Nm_per_arcmin", "torsional rigidity b/a (N m/arcmin)"),
                   ("lost_motion_arcmin", "lost motion (arcmin)"), ("backlash_arcmin", "backlash (arcmin)"),
                   ("hysteresis_loss_arcmin", "hysteresis loss (arcmin)"), ("preloaded", "preloaded")):
        extra = f" [{num(ci[0])}, {num(ci[1])}]" if ci and k.startswith("torsional") else ""
        rows.append([lab, num(m[k]), num(c[k]) + extra])
    L += _table(["figure", "declared", "calibrated"], rows)
    return L + [f"{d['note']}.", ""]


def _holdout(obj: dict) -> list[str]:
    L = ["## Each load left out of the fit and predicted", ""]
    h = obj.get("holdout")
    if h is None:
        return L + ["Not run (`rv-calibrate --holdout-loads`).", ""]
    L += [h["statement"] + ".", ""]
    if h["rows"]:
        L += _table(["load left out (N m)", "fitted on (N m)", "declared model RMS", "prediction RMS",
                     "reducer alone RMS", "fit on all loads RMS", "noise", "prediction / noise", "named by that fit",
                     "status"],
                    [[num(r["load_Nm"]), ", ".join(num(x) for x in r["fitted_loads_Nm"]),
                      num(r["rms_declared_arcsec"]), num(r["rms_prediction_arcsec"]), num(r.get("rms_reducer_arcsec")),
                      num(r["rms_full_fit_arcsec"]),
                      num(r["noise_arcsec"]), num(r["prediction_over_noise"], 3),
                      ", ".join(f"`{n}`" for n in r["named"]) or "-", r["status"]] for r in h["rows"]])
        L.append("RMS in arcsec, each left-out test's constant removed.")
        L.append("")
    return L


def _spectrum(obj: dict) -> list[str]:
    s = obj["residual_spectrum"]
    L = ["## Lines in the residual after calibration", ""] + [f"- {t}" for t in s["statements"]] + [""]
    if s["order_locked"]:
        L += ["Locked to an order of the reducer (what the model still lacks):", ""]
        L += _table(["order", "what", "largest amplitude (arcsec)", "runs"],
                    [[num(g["order"]), g.get("label") or "-", num(g["amplitude_arcsec"], 3), ", ".join(g["runs"])]
                     for g in s["order_locked"][:MAX_LINES]])
    if s["fixed_frequency"]:
        L += ["At a fixed frequency (the rig's or the environment's; **not claimed for the reducer**):", ""]
        L += _table(["frequency (Hz)", "order", "largest amplitude (arcsec)", "runs"],
                    [[num(g.get("frequency_Hz")), num(g["order"]), num(g["amplitude_arcsec"], 3), ", ".join(g["runs"])]
                     for g in s["fixed_frequency"][:MAX_LINES]])
    if not s["order_locked"] and not s["fixed_frequency"]:
        L += ["No line above the noise floor.", ""]
    return L


def _runs(obj: dict) -> list[str]:
    L = ["## Runs", ""]
    L += _table(["run", "test", "load (N m)", "direction", "readings", "revolutions", "noise", "RMS before",
                 "RMS after"],
                [[r["run"], r["test"], num(r["load_Nm"]), f"{r['direction']:+d}", r["samples"],
                  num(r["revolutions"], 4), num(r["noise_arcsec"], 3), num(r["rms_before_arcsec"]),
                  num(r["rms_after_arcsec"])] for r in obj["runs"]])
    return L + ["Residual RMS in arcsec, each test's constant removed (before: the declared model).", ""]


def _figures(obj: dict) -> list[str]:
    what = {"te_per_run.png": "measured and model TE per run, over one output revolution",
            "residuals.png": "the residual before and after, per run",
            "residual_spectrum.png": "the order spectrum of the residual after, its lines marked",
            "test_means.png": "the mean TE per direction and B - F against load (measured)"}
    L = ["## Figures", ""]
    for f in obj["figures"]:
        name = Path(f).name
        L += [f"{what.get(name, name)}:", "", f"![{name}]({name})", ""]
    return L


def _method(obj: dict) -> list[str]:
    n = obj["ratio"]
    return ["## Method", "",
            f"The measured TE of a reading is {te_formula(n)} ({n:g} the ratio of this reducer). The model TE is "
            "rvdyn's quasi-static equilibrium of each run's case (declared errors, load, direction) solved exactly at "
            f"every reading's input angle, modulo one output revolution ({n:g} x 360 deg of input). Each test's "
            "constant (the rig's zero) is removed from data and model. Every candidate of the library (each Table 4 "
            "error instance, the pin ring's form modes, model options, encoder errors, and empirical terms that are "
            "never named) is estimated at once by a sum of single effects over the linearised model, the sizes of the "
            "effects chosen by a nonlinear fit through rvdyn, re-linearised until the model stops moving. The method, "
            "its reference and what each figure of the result means: docs/calibration.md; the command line and this "
            "report: docs/calibrate.md.", ""]


def markdown(obj: dict, dataset) -> str:
    """The report's Markdown text."""
    L = _head(obj, dataset) + _measured(obj) + _effects(obj) + _groups(obj) + _unexplained(obj) + _nuisance(obj)
    L += _datasheet(obj, dataset) + _holdout(obj) + _spectrum(obj) + _runs(obj) + _figures(obj)
    notes = list(obj.get("notes") or []) + [n for n in dataset.notes if n not in (obj.get("notes") or [])]
    L += ["## Notes", ""] + [f"- {n}" for n in notes or ["none"]] + [""]
    return "\n".join(L + _method(obj))
