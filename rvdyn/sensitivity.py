"""How the torsional rigidity moves with the sizes the paper does not give.

The paper prints the tooth counts, the pin circle, the pin size and the eccentricity (Table 1); every other
size of the default design (stage I module, bearings, crankshaft, carrier, widths) is an assumption of this
implementation (docs/conventions.md, "Assumptions"). A user comparing :func:`rvdyn.stiffness.hysteresis` with a
datasheet needs to know which of those sizes the rigidity answers to. For a size ``s`` (a ``design.FIELD`` or
``model.OPTION`` of the case JSON) this module evaluates the rigidity ``k`` of the maker's sweep at
``s (1 - h)`` and ``s (1 + h)`` (integers: ``s - 1`` and ``s + 1``) and reports the elasticity

    ``E = ln(k+ / k-) / ln(s+ / s-)``  (dimensionless; ``d ln k / d ln s`` to O(h^2)),

so a 1 % larger size gives about ``E`` % more rigidity. Nothing is fitted: the rigidity is the sweep's own
figure (docs/physics.md, sections 9 and 13).
"""
from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

import pandas as pd

from rvcad.errors import Case
from rvcad.params import Design
from rvcad.validation import InputError
from rvdyn.contacts import ContactLaw
from rvdyn.results import InterferenceError
from rvdyn.stiffness import hysteresis

#: The default design's sizes that are this implementation's assumptions and act on the torque path
#: (docs/conventions.md, "Assumptions"), and the pin radius (paper Table 1 prints 6 mm, read as the diameter).
ASSUMED_SIZES: tuple[str, ...] = (
    "design.module_mm", "design.pin_radius_mm", "design.disc_width_mm", "design.plate_width_mm",
    "design.disc_gap_mm", "design.gear_width_mm", "design.cam_radius_mm", "design.crank_journal_radius_mm",
    "design.cam_bearing_rollers", "design.cam_bearing_roller_diameter_mm", "design.cam_bearing_roller_length_mm",
    "design.journal_bearing_rollers", "design.journal_bearing_roller_diameter_mm",
    "design.journal_bearing_roller_length_mm", "design.journal_bearing_contact_angle_deg",
    "design.carrier_pillar_radius_mm", "design.pin_seat_clearance_mm",
)

_SECTIONS = ("design", "model")


def _numeric_design_fields() -> tuple[str, ...]:
    d = Design()
    return tuple(f.name for f in fields(Design)
                 if isinstance(getattr(d, f.name), (int, float)) and not isinstance(getattr(d, f.name), bool))


def _split(size: Any) -> tuple[str, str]:
    """``("design" | "model", key)`` of a dotted size name; ValueError naming it otherwise."""
    allowed = f"'design.FIELD' (FIELD one of {list(_numeric_design_fields())}) or 'model.OPTION'"
    if not isinstance(size, str) or size.count(".") != 1:
        raise ValueError(f"size {size!r} is not allowed; allowed: {allowed}")
    section, key = size.split(".")
    if section not in _SECTIONS or not key:
        raise ValueError(f"size {size!r} is not allowed; allowed: {allowed}")
    if section == "design" and key not in _numeric_design_fields():
        raise ValueError(f"size {size!r} is not a numeric Design field; allowed: {allowed}")
    return section, key


def size_value(case: Case, size: str) -> float | int:
    """The case's value of a size (a ``model`` option not set in the case: ValueError, its default is the
    solver's and has no size to scale)."""
    section, key = _split(size)
    if section == "design":
        return getattr(case.design, key)
    if key not in case.model:
        raise ValueError(f"size {size!r} is not set in the case's model object; set it to scale it")
    v = case.model[key]
    if isinstance(v, str):
        raise ValueError(f"size {size!r} = {v!r} is a named option, not a size")
    return v


def with_size(case: Case, size: str, value: float | int) -> Case:
    """A copy of the case with one size changed (validated as every case is: the message names the field)."""
    section, key = _split(size)
    d = case.to_dict()
    d.setdefault(section, {})
    d[section][key] = value
    return Case.from_dict(d)


def rigidity(case: Case, rated_Nm: float | None = None, law: ContactLaw | None = None, solver: str = "analytic",
             theta_in_deg: float = 0.0) -> float:
    """Torsional rigidity b/a (N m/arcmin) of the maker's sweep of a case (:func:`rvdyn.stiffness.hysteresis`,
    same arguments; the figure does not depend on the curve's sampling, so the sweep is sampled at its minimum)."""
    res = hysteresis(case, rated_Nm=rated_Nm, theta_in_deg=theta_in_deg, solver=solver, law=law, points=5)
    return float(res.figures["torsional_rigidity_Nm_per_arcmin"])


def rigidity_at(case: Case, size: str, value: float | int, **sweep: Any) -> tuple[float | None, str]:
    """The rigidity (N m/arcmin) of the case with one size set to ``value``, and ``""``; or None and why, when the
    validation refuses that case or the contact law cannot resolve its interference under the rated torque
    (:class:`rvdyn.results.InterferenceError`). ``sweep``: :func:`rigidity`'s keywords."""
    try:
        return rigidity(with_size(case, size, value), **sweep), ""
    except (InputError, InterferenceError) as exc:
        return None, str(exc)


def rigidity_elasticities(case: Case | None = None, sizes: tuple[str, ...] = ASSUMED_SIZES, rel_step: float = 0.05,
                          rated_Nm: float | None = None, law: ContactLaw | None = None, solver: str = "analytic",
                          theta_in_deg: float = 0.0) -> pd.DataFrame:
    """Elasticity of the torsional rigidity to each size.

    Parameters
    ----------
    case : Case or None
        The reducer (default: the nominal case of the default design).
    sizes : tuple of str
        Dotted names ``design.FIELD`` or ``model.OPTION`` (default :data:`ASSUMED_SIZES`).
    rel_step : float
        Relative step h of a real size, 0 < h <= 0.5 (an integer size steps by 1).
    rated_Nm, law, solver, theta_in_deg
        Of the sweep, as :func:`rvdyn.stiffness.hysteresis` (default: 167 N m, the case's law, analytic, 0 deg).

    Returns
    -------
    DataFrame
        One row per size: ``size``, ``value``, ``low``, ``high`` (the two values evaluated),
        ``rigidity_low``, ``rigidity_high`` (N m/arcmin), ``elasticity`` (``ln(k+/k-)/ln(s+/s-)``, 1) and
        ``note``. Where one step leaves the valid designs (the validation refuses the case, or its interference is more than the law resolves) the difference is
        one-sided, from the size's own value, and the note says why (:func:`rigidity_at`); where both do, the
        elasticity is NaN.
    """
    case = Case.from_dict({}) if case is None else case
    if isinstance(rel_step, bool) or not isinstance(rel_step, (int, float)) or not 0.0 < rel_step <= 0.5:
        raise ValueError(f"rel_step {rel_step!r} is not allowed; allowed: a number in (0, 0.5]")
    sweep = {"rated_Nm": rated_Nm, "law": law, "solver": solver, "theta_in_deg": theta_in_deg}
    base: float | None = None
    rows = []
    for size in sizes:
        v = size_value(case, size)
        if isinstance(v, int):
            lo, hi = v - 1, v + 1
        else:
            lo, hi = v * (1.0 - rel_step), v * (1.0 + rel_step)
        if not v > 0:
            raise ValueError(f"size {size!r} = {v!r}: the elasticity needs a size > 0")
        k_lo, why_lo = rigidity_at(case, size, lo, **sweep) if lo > 0 else (None, f"{size} {lo!r} is not > 0")
        k_hi, why_hi = rigidity_at(case, size, hi, **sweep)
        note = ""
        if k_lo is None or k_hi is None:
            if base is None:
                base = rigidity(case, **sweep)
            if k_lo is None and k_hi is None:
                note = f"both steps invalid: {why_lo}; {why_hi}"
            elif k_lo is None:
                lo, k_lo, note = v, base, f"one-sided (the step down is invalid: {why_lo})"
            else:
                hi, k_hi, note = v, base, f"one-sided (the step up is invalid: {why_hi})"
        e = math.nan if k_lo is None or k_hi is None else math.log(k_hi / k_lo) / math.log(hi / lo)
        rows.append({"size": size, "value": v, "low": lo, "high": hi, "rigidity_low": k_lo, "rigidity_high": k_hi,
                     "elasticity": e, "note": note})
    return pd.DataFrame(rows)
