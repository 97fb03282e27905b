"""The datasheet of the reducer as declared and as calibrated: ``rvdyn.stiffness.hysteresis`` of both cases.

**The datasheet as calibrated.** A lumped ``torsional_compliance_arcsec_per_Nm`` ``C`` found by the loop is the
part of the reducer's wind-up the model lacks: every compliance in series (bearings, crank bending, carrier, ...
docs/physics.md section 9) adds to the same load-proportional TE, so the data fix only their sum and cannot say
which part is softer. What the user can read from it, and from the errors found (a play, a preload), is the
datasheet the calibrated reducer has: :func:`calibrated_datasheet` sweeps the reducer as declared and as
calibrated (``rvdyn.stiffness.hysteresis``). The interval of the rigidity follows from the series law
``1/k = 1/k_C + (C' - C)/60`` (arcmin/(N m)), exact for the b/a secant of a frictionless curve (a series
compliance adds ``C b`` to the span ``a``; tests/test_rvdyn_stiffness.py), an approximation of about 1 % with the
default friction coefficients (0.2 arcsec/(N m) on the default design: 70.23 swept against 70.65 from the series
law).

:func:`reducer_datasheet` decides the rated torque: the user's (``--rated-Nm``, ``settings.rated_Nm``); without
it, rvdyn's default (:data:`rvdyn.stiffness.DEFAULT_RATED_NM`, the RV-20E class of the paper's reducer) for the
default design only, and for any other design no datasheet (lost motion at +-3 % of a rated torque that is not
the reducer's would mean nothing).
"""
from __future__ import annotations

import math
from typing import Any

from rvcad.errors import Case
from rvcad.params import Design
from rvcad.validation import one_line
from rvdyn.solver import law_from_model
from rvdyn.stiffness import DEFAULT_RATED_NM, hysteresis

#: The figures of a sweep the datasheet keeps.
FIGURES = ("torsional_rigidity_Nm_per_arcmin", "lost_motion_arcmin", "backlash_arcmin", "hysteresis_loss_arcmin",
           "rated_torque_Nm", "preloaded")
COMPLIANCE = "torsional_compliance_arcsec_per_Nm"


def reducer_case(case: dict[str, Any]) -> dict[str, Any]:
    """A run's case JSON without what belongs to the run (load, direction, name): the reducer."""
    return {k: v for k, v in case.items() if k not in ("load_Nm", "direction", "name")}


def calibrated_datasheet(declared: dict[str, Any], calibrated: dict[str, Any],
                         compliance: tuple[float, float, float] | None = None, law: Any = None,
                         rated_Nm: float | None = None) -> dict[str, Any]:
    """The datasheet figures of the reducer as declared and as calibrated (``rvdyn.stiffness.hysteresis``).

    Parameters
    ----------
    declared, calibrated : dict
        Case JSON of the reducer (:func:`reducer_case`). ``model.friction_torque_Nm`` is left out of the sweeps:
        the sweep's friction comes from the coefficients, and a torque that resists every motion has no place
        in a sweep with the input locked.
    compliance : (value, ci_low, ci_high) or None
        The lumped compliance found, arcsec/(N m), for the rigidity's interval (series law).
    law : rvdyn.contacts.ContactLaw or None
        The forward model's contact law (None: each case's own).
    rated_Nm : float or None
        Rated torque of the sweep (default: rvdyn's, 167 N m).

    Returns
    -------
    dict
        ``model`` (declared) and ``calibrated`` (each: ``torsional_rigidity_Nm_per_arcmin``,
        ``lost_motion_arcmin``, ``backlash_arcmin``, ``hysteresis_loss_arcmin``, ``rated_torque_Nm``,
        ``preloaded``), ``rigidity_ci`` (from the compliance's interval by the series law; None without a
        compliance) and a ``note``.
    """
    def sweep(case: dict[str, Any]) -> dict[str, Any]:
        c = dict(case)
        c["model"] = {k: v for k, v in (case.get("model") or {}).items() if k != "friction_torque_Nm"}
        f = hysteresis(Case.from_dict(c), rated_Nm=rated_Nm, law=law).figures
        return {k: f[k] for k in FIGURES}

    f0, f1 = sweep(declared), sweep(calibrated)
    ci = None
    if compliance is not None:
        k, (c, lo, hi) = f1["torsional_rigidity_Nm_per_arcmin"], compliance
        ends = [1.0 / (1.0 / k + (max(x, 0.0) - c) / 60.0) for x in (hi, lo)]
        ci = [min(ends), max(ends)] if all(math.isfinite(e) and e > 0 for e in ends) else None
    return {"model": f0, "calibrated": f1, "rigidity_ci": ci,
            "note": "rvdyn stiffness of the reducer as declared and as calibrated (every physical effect found); a "
                    "compliance found is the sum of what every part in series lacks (the TE cannot say which part)"}



def _compliance(result, calibrated: dict[str, Any]) -> tuple[float, float, float] | None:
    """The compliance of the calibrated case and the 95 % interval of the named compliance (None if not named)."""
    named = next((e for e in result.effects if e.key == COMPLIANCE), None)
    if named is None:
        return None
    c = float((calibrated.get("model") or {}).get(COMPLIANCE, named.value))
    return c, float(named.ci95[0]), float(named.ci95[1])


def rated_torque(design: Design, rated_Nm: float | None) -> tuple[float | None, str]:
    """The rated torque of the datasheet and where it comes from (None: the design needs the user's)."""
    if rated_Nm is not None:
        return float(rated_Nm), "given (--rated-Nm)"
    if design == Design():
        return DEFAULT_RATED_NM, (f"rvdyn's default {DEFAULT_RATED_NM:g} N m, the RV-20E class of the paper's "
                                  "reducer (the default design; no --rated-Nm given)")
    return None, (f"the rated torque is needed: this reducer (ratio {design.ratio:g}, {design.z_pins} pins) is not "
                  f"the default design, so rvdyn's {DEFAULT_RATED_NM:g} N m (the paper's RV-20E class) is not its own "
                  "and lost motion at +-3 % of it would mean nothing; give --rated-Nm T (the maker's rated output "
                  "torque, N m)")


def reducer_datasheet(result, dataset, rated_Nm: float | None = None, law: Any = None) -> dict[str, Any]:
    """The datasheet of the reducer as declared and as calibrated (:func:`calibrated_datasheet`).

    Parameters
    ----------
    result : CalibrationResult
        Its ``calibrated_case`` is swept; its named compliance gives the rigidity's interval.
    dataset : MeasuredDataset
        The declared reducer is its first run's case (declared errors, temperature) without load and direction.
    rated_Nm : float or None
        The rated torque, N m (default ``result.settings["rated_Nm"]``; without either see :func:`rated_torque`).
    law : ContactLaw or None
        Contact law of the sweeps (default: the result's ``settings["contact"]``, else each case's).

    Returns
    -------
    dict
        ``computed`` (bool), ``rated_torque_Nm`` (None when not computed), ``rated_source`` (where the rated
        torque comes from, or why the datasheet is missing), and when computed :func:`calibrated_datasheet`'s
        ``model``, ``calibrated``, ``rigidity_ci`` and ``note``.
    """
    if rated_Nm is None:
        rated_Nm = (result.settings or {}).get("rated_Nm")
    rated, source = rated_torque(dataset.design, rated_Nm)
    out: dict[str, Any] = {"computed": False, "rated_torque_Nm": rated, "rated_source": source}
    if rated is None:
        return out
    if not result.calibrated_case:
        out["rated_source"] = "the result holds no calibrated case: no datasheet"
        return out
    contact = (result.settings or {}).get("contact")
    if law is None and contact is not None:
        law = law_from_model({"contact": contact})
    calibrated = reducer_case(result.calibrated_case)
    try:
        sheet = calibrated_datasheet(reducer_case(dataset.runs[0].case_dict()), calibrated,
                                     _compliance(result, calibrated), law, rated)
    except (ValueError, ArithmeticError) as exc:     # a case the sweep cannot take: said, not fatal
        out["rated_source"] = f"{source}; rvdyn stiffness could not sweep the reducer: {one_line(exc)}"
        return out
    return {**out, **sheet, "computed": True}
