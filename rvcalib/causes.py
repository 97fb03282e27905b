"""Physical causes behind what the loop found, where the TE cannot tell them from the effect named.

The library names Table 4 errors, model options and measurement errors. Some physical parameters of the
reducer give exactly the TE of one of them, so a dataset can never split the two; screening them as
separate candidates would only let one take the other's place at random. This module reports them beside
the effect found instead, in the physical parameter's own units ("equivalents"), and turns what the loop found
into the datasheet figures of the reducer as calibrated.

**Profile modification of the discs** (``Design.profile_equidistant_mm``, ``profile_shift_mm``,
``profile_rotation_deg``; docs/physics.md section 10: the pin-centre curve is ``(Rp + d_Rp) u(t) - e u(Zp t)``,
the boundary its inner equidistant at ``rp + d_rp``, the profile turned by ``delta``):

* equidistant ``d_rp`` (mm): every pin meets the boundary as a pin thinner by ``d_rp`` does, so it is
  ``pin_radius`` (all pins) of ``-1000 d_rp`` um. Exact for the pin-disc contacts (the pin seats' conformal
  radius is the only other place the pin radius enters): measured TE difference <= 2e-5 arcsec for 3 um at 0,
  20 and 167 N m, both directions (tests/test_calib_causes.py).
* shift ``d_Rp`` (mm): the curve is generated for pins on ``Rp + d_Rp``; pins on ``Rp`` meet it as pins on
  ``Rp - d_Rp`` meet the unmodified disc, to first order in the misfit (the curve's shape depends on
  ``e/Rp``): ``pin_circle_diameter`` (all pins) of ``-2000 d_Rp`` um; measured 1.2e-3 arcsec for an effect of
  9-12 arcsec (-4 um shift against +8 um diameter).
* rotation ``delta`` (deg, both discs): ``disc_phase`` of ``delta`` on every disc (the same turn of the profile
  relative to the crank holes; identical TE), which is a uniform TE shift ``-delta Zc/(Zc + 1 + Z1/Z2)``
  (docs/physics.md section 10): so an unexplained constant offset ``c`` arcsec is, among its causes (an
  encoder zero, a turned pin housing), a rotation of ``-c (Zc + 1 + Z1/Z2)/(3600 Zc)`` deg.

A correction found on top of a declared design value is reported as the design value it implies
(``implied_design_value`` = the design's value plus the equivalent).

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

**A compliance as friction.** Under rotation the Coulomb friction of the pins and the crank bearings is proportional
to the load (``rvdyn.friction``: ``T_f = (mu_p kappa_p + mu_b kappa_b) T``, to 1 % from 5 to 167 N m) and resists
both directions as the load does, so in TE data it is a compliance of ``(mu_p kappa_p + mu_b kappa_b) w``
arcsec/(N m) (``w`` the reducer's wind-up per N m): a compliance ``C`` found is also, as far as the TE can tell, a
pin friction coefficient ``C/(kappa_p w)`` or a bearing friction coefficient ``C/(kappa_b w)`` (each alone) beside
the model's defaults (0.05 and 0.0025). The reading is computed on the reducer as declared at the loaded runs' mean
load; it is a reading, not a TE input (rvdyn's TE has no friction from the coefficients). A hysteresis test
(``rvdyn stiffness``, input locked) splits them: friction opens the loop, a compliance tilts it.

Not here: a friction coefficient as the cause of ``friction_torque_Nm``, a torque that does not grow with the load
(seals, grease churning): Coulomb friction at the pins and bearings grows with it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from rvcad.errors import Case
from rvcad.params import Design
from rvdyn.friction import FrictionArms
from rvdyn.options import MODEL_OPTIONS


@dataclass(frozen=True)
class Equivalent:
    """A design parameter that gives the TE of a library effect (exactly, or to first order: see ``meaning``).

    Attributes
    ----------
    effect : str
        Library effect name (``pin_radius``: all pins).
    parameter : str
        Design field, in the case JSON's ``design`` object.
    unit : str
        Unit of the design field.
    factor : float
        Design value per unit of the effect (``parameter = factor * effect value``).
    meaning : str
        What the design value means, and why it is the same TE.
    """

    effect: str
    parameter: str
    unit: str
    factor: float
    meaning: str


EQUIVALENTS: tuple[Equivalent, ...] = (
    Equivalent("pin_radius", "profile_equidistant_mm", "mm", -1e-3,
               "equidistant modification of the disc profile (cut for a pin thicker by this): every pin meets the "
               "disc as a pin thinner by it, the same TE"),
    Equivalent("pin_circle_diameter", "profile_shift_mm", "mm", -0.5e-3,
               "shift modification of the disc profile (cut for pins on a circle larger in radius by this): the pins "
               "meet it as pins on a circle smaller in radius by it, the same TE to first order"),
)


def rotation_per_offset_deg(design: Design) -> float:
    """Profile rotation of both discs (deg) that shifts the TE by +1 arcsec: ``-(Zc + 1 + Z1/Z2)/(3600 Zc)``
    (a rotation ``delta`` shifts the TE by ``-delta Zc/(Zc + 1 + Z1/Z2)``, docs/physics.md section 10)."""
    return -(design.z_disc + 1.0 + design.z_sun / design.z_planet) / (3600.0 * design.z_disc)


def _mapped(value: float, lo: float, hi: float, factor: float, base: float | None, parameter: str, unit: str,
            meaning: str) -> dict[str, Any]:
    """``parameter = factor * value`` with its interval; ``base`` the declared value it adds to (None: a reading, not a
    design field)."""
    a, b = sorted((factor * lo, factor * hi))
    v = factor * value
    out = {"parameter": parameter, "value": v, "ci_low": a, "ci_high": b, "unit": unit, "meaning": meaning}
    if base is not None:
        out["implied_design_value"] = base + v
    return out


def effect_equivalents(name: str, value: float, ci_low: float, ci_high: float, design: Design) -> list[dict]:
    """The design parameters that give the TE of a found effect (empty when none does).

    Parameters
    ----------
    name : str
        Library effect name.
    value, ci_low, ci_high : float
        Its size and 95 % interval, in the effect's unit.
    design : Design
        The reducer measured (its declared modification is the base of ``implied_design_value``).
    """
    out = []
    for q in EQUIVALENTS:
        if q.effect == name:
            out.append(_mapped(value, ci_low, ci_high, q.factor, float(getattr(design, q.parameter)),
                               f"design.{q.parameter}", q.unit, q.meaning))
    return out


def offset_equivalents(amplitude_arcsec: float, design: Design) -> list[dict]:
    """An unexplained constant offset (arcsec, the same in every run) read as a profile rotation of both
    discs: one of its possible causes, which the TE cannot tell from an encoder zero offset."""
    f = rotation_per_offset_deg(design)
    return [_mapped(amplitude_arcsec, amplitude_arcsec, amplitude_arcsec, f, design.profile_rotation_deg,
                    "design.profile_rotation_deg", "deg",
                    "rotation modification of both discs' profile relative to the crank holes (a uniform TE shift); "
                    "an encoder zero offset or a turned pin housing give the same TE")]


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
    from rvdyn.stiffness import hysteresis

    keys = ("torsional_rigidity_Nm_per_arcmin", "lost_motion_arcmin", "backlash_arcmin", "hysteresis_loss_arcmin",
            "rated_torque_Nm", "preloaded")

    def sweep(case: dict[str, Any]) -> dict[str, Any]:
        c = dict(case)
        c["model"] = {k: v for k, v in (case.get("model") or {}).items() if k != "friction_torque_Nm"}
        f = hysteresis(Case.from_dict(c), rated_Nm=rated_Nm, law=law).figures
        return {k: f[k] for k in keys}

    f0, f1 = sweep(declared), sweep(calibrated)
    ci = None
    if compliance is not None:
        k, (c, lo, hi) = f1["torsional_rigidity_Nm_per_arcmin"], compliance
        ends = [1.0 / (1.0 / k + (max(x, 0.0) - c) / 60.0) for x in (hi, lo)]
        ci = [min(ends), max(ends)] if all(math.isfinite(e) and e > 0 for e in ends) else None
    return {"model": f0, "calibrated": f1, "rigidity_ci": ci,
            "note": "rvdyn stiffness of the reducer as declared and as calibrated (every physical effect found); a "
                    "compliance found is the sum of what every part in series lacks (the TE cannot say which part)"}


def compliance_equivalents(value: float, ci_low: float, ci_high: float, arms: FrictionArms) -> list[dict]:
    """A compliance found (arcsec/(N m)) read as Coulomb friction of the pins or of the crank bearings, each alone
    (``arms``: :class:`rvdyn.friction.FrictionArms` of the reducer at the runs' load; module docstring)."""
    out = []
    for which, key in (("pins", "pin_friction_coefficient"), ("bearings", "bearing_friction_coefficient")):
        default = MODEL_OPTIONS[key].default
        if (which == "bearings" and arms.bearings is None) or arms.windup_arcsec_per_Nm <= 0:
            continue
        per = arms.compliance_per_coefficient(which)
        q = _mapped(value, max(ci_low, 0.0), ci_high, 1.0 / per, None, f"model.{key}", "-",
                    f"Coulomb friction of the {which} (the other's at 0), proportional to the load under rotation "
                    f"(kappa {arms.pins if which == 'pins' else arms.bearings:.4g}, wind-up "
                    f"{arms.windup_arcsec_per_Nm:.4g} arcsec/(N m) at {arms.load_Nm:.4g} N m): in the TE a compliance of "
                    f"{per:.4g} arcsec/(N m) per unit coefficient; the model's default is {default:g}; a hysteresis "
                    "test (input locked) tells friction (an open loop) from a compliance (a tilt)")
        q["default"] = default
        out.append(q)
    return out


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
