"""Physical causes behind what the loop found, where the TE cannot tell them from the effect named, for the
results of :mod:`rvcalib.identify`.

The equivalents themselves (a profile modification for the all-pins radius and circle diameter, a profile rotation
for a constant offset, Coulomb friction for a compliance) are in :mod:`rvcalib.equivalents`; the datasheet of the
reducer as declared and as calibrated in :mod:`rvcalib.datasheet`. This module attaches them to the records of
:mod:`rvcalib.results`.
"""
from __future__ import annotations

from typing import Any

from rvcad.params import Design
from rvcalib.datasheet import calibrated_datasheet, reducer_case
from rvcalib.equivalents import (EQUIVALENTS, Equivalent, compliance_equivalents, effect_equivalents,
                                 offset_equivalents, rotation_per_offset_deg)
from rvdyn.friction import FrictionArms

__all__ = ["EQUIVALENTS", "Equivalent", "attach_equivalents", "calibrated_datasheet", "compliance_equivalents",
           "datasheet_of", "effect_equivalents", "offset_equivalents", "reducer_case", "rotation_per_offset_deg"]


def attach_equivalents(fitted: list, unexplained: list, design: Design, groups: list[dict] | None = None,
                       friction: FrictionArms | None = None) -> None:
    """Fill ``equivalents`` of the found effects (:class:`rvcalib.results.FittedEffect`), of an unexplained
    constant offset common to every run (:class:`rvcalib.results.Unexplained`) and of the identifiability groups'
    members (their ``value``; an effect not named has no interval), in place. ``friction``: the
    :class:`rvdyn.friction.FrictionArms` of the reducer at the runs' load, for a compliance found (None: not read)."""
    for e in fitted:
        e.equivalents = effect_equivalents(e.name, e.value, e.ci_low, e.ci_high, design)
        if e.key == "torsional_compliance_arcsec_per_Nm" and friction is not None:
            e.equivalents += compliance_equivalents(e.value, e.ci_low, e.ci_high, friction)
    for u in unexplained:
        if u.kind == "offset" and u.factor == "common":
            u.equivalents = offset_equivalents(u.amplitude_arcsec, design)
    for g in groups or []:
        for m in g.get("members", []):
            v = m.get("value")
            q = effect_equivalents(m.get("name", ""), v, v, v, design) if isinstance(v, (int, float)) else []
            if q:
                m["equivalents"] = q


def datasheet_of(result, law: Any = None, rated_Nm: float | None = None) -> dict[str, Any]:
    """:func:`calibrated_datasheet` of a :class:`rvcalib.results.CalibrationResult` whose loop found a physical
    effect (a Table 4 error or a model option; empty otherwise: the sweep would repeat the declared reducer's);
    ``rated_Nm`` the sweep's rated torque (default rvdyn's, 167 N m)."""
    if not any(e.family in ("table4", "model") for e in result.effects):
        return {}
    comp = next(((e.value, e.ci_low, e.ci_high) for e in result.effects
                 if e.key == "torsional_compliance_arcsec_per_Nm"), None)
    return calibrated_datasheet(result.declared_case, result.calibrated_case, comp, law, rated_Nm)
