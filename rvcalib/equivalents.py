"""Physical parameters that give exactly (or to first order) the TE of an effect the loop names: the TE cannot
tell the two apart, so the report gives them beside the effect, in the physical parameter's own units.

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

:func:`result_equivalents` collects them for a :class:`rvcalib.result.CalibrationResult`: the named effects
(with their intervals), the group members with a size, and the constant common to the tests' zeros.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

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
                    f"{arms.windup_arcsec_per_Nm:.4g} arcsec/(N m) at {arms.load_Nm:.4g} N m): in the TE a compliance "
                    f"of {per:.4g} arcsec/(N m) per unit coefficient; the model's default is {default:g}; a hysteresis "
                    "test (input locked) tells friction (an open loop) from a compliance (a tilt)")
        q["default"] = default
        out.append(q)
    return out


def _get(obj: Any, name: str) -> Any:
    """An attribute of a result record or the key of its dict form."""
    return obj[name] if isinstance(obj, dict) else getattr(obj, name)


def result_equivalents(result, design: Design, arms: FrictionArms | None = None) -> dict[str, Any]:
    """The physical equivalents of what a calibration reports.

    Parameters
    ----------
    result : CalibrationResult
        (:mod:`rvcalib.result`), or its ``to_dict()``.
    design : Design
        The reducer measured (its declared modification is the base of ``implied_design_value``).
    arms : FrictionArms or None
        The friction arms of the reducer as declared at the loaded runs' mean load, to read a compliance as
        friction (None: not read).

    Returns
    -------
    dict
        ``effects``: effect name -> list of equivalents (each ``parameter``, ``value``, ``ci_low``, ``ci_high``,
        ``unit``, ``meaning``, and ``implied_design_value`` or ``default``); ``groups``: per group, per member, a
        list (empty for a member without a size: ``"unbounded"``); ``common_constant``: the mean of the tests'
        constants (arcsec; None without tests) and ``constant``: its equivalents (a profile rotation).
    """
    effects: dict[str, list] = {}
    for e in _get(result, "effects"):
        name, value, (lo, hi) = _get(e, "name"), float(_get(e, "value")), _get(e, "ci95")
        q = effect_equivalents(name, value, float(lo), float(hi), design)
        if _get(e, "key") == "torsional_compliance_arcsec_per_Nm" and arms is not None:
            q += compliance_equivalents(value, float(lo), float(hi), arms)
        if q:
            effects[name] = q
    groups = []
    for g in _get(result, "groups"):
        groups.append([effect_equivalents(m["name"], float(m["value"]), float(m["value"]), float(m["value"]), design)
                       if isinstance(m.get("value"), (int, float)) and math.isfinite(m["value"]) else []
                       for m in g["members"]])
    consts = [float(n["constant_arcsec"]) for n in _get(result, "nuisance")]
    common = float(np.mean(consts)) if consts else None
    return {"effects": effects, "groups": groups, "common_constant": common,
            "constant": offset_equivalents(common, design) if common is not None else []}
