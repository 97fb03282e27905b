"""Physics options of the solver: the case's ``model`` object, validated where the physics lives.

A case's ``model`` object holds the effects the paper's base model lacks and the choice of contact
law. The options that move parts (temperature, thermal growth and ovality of the pin circle) are
geometry and live in :data:`rvcad.errors.GEOMETRY_OPTIONS`; the solver's options are here.
:func:`parse_model` validates the whole object (unknown names, ranges, choices) and is called by
the solver, so every command that solves a case reports a bad option naming the key.

Contact laws (docs/physics.md, section 7):

- ``"physical"`` (the default, conventions.md): pin-disc Hertzian line contact with the local profile
  curvature, involute mesh stiffness per ISO 6336-1 with the contact ratio, and (``supports = "elastic"``) the compliance of
  the cam and crank journal bearings, the crankshafts, the pin seats and the carrier (materials of paper
  Table 2).
- ``"impact"``: the paper's ADAMS impact force ``F = K delta**n`` (Eq. 1 without damping) at every
  contact, ``K = contact_K_N_per_mm_n`` (2e5 N/mm^1.5), ``n = contact_n`` (1.5); supports rigid. A named
  option for reproducing the paper (``rvdyn te --contact impact``, ``{"model": {"contact": "impact"}}``).
"""
from __future__ import annotations

from typing import Any

from rvcad.errors import GEOMETRY_OPTIONS, ModelOption, check_option

CONTACT_LAWS = ("impact", "physical")

#: Default contact law of the quasi-static analysis (conventions.md): physical; the paper's impact law is the
#: named option ``"impact"``.
DEFAULT_CONTACT = "physical"

SOLVER_OPTIONS: dict[str, ModelOption] = {o.key: o for o in [
    ModelOption("contact", "", 0.0, 0.0, DEFAULT_CONTACT,
                "contact law: 'physical' (default: Hertz line contact at the pins, ISO 6336-1 mesh stiffness, bearing "
                "and crankshaft compliance) or 'impact' (paper Eq. 1, F = K delta^n at every contact, to reproduce "
                "the paper)",
                choices=CONTACT_LAWS),
    ModelOption("contact_K_N_per_mm_n", "N/mm^n", 1e-3, 1e12, 2.0e5,
                "stiffness K of the impact law F = K delta^n (contact 'impact' only)"),
    ModelOption("contact_n", "", 1.0, 3.0, 1.5, "force exponent n of the impact law (contact 'impact' only)"),
    ModelOption("supports", "", 0.0, 0.0, "elastic",
                "bearings, crankshafts, pin seats and carrier with contact 'physical': 'elastic' (cam and journal "
                "bearings, crankshaft bending and the pins' seats in their housing grooves inside the equilibrium, "
                "crank torsion in series with the mesh, the carrier's pillars inside it) or 'rigid'",
                choices=("elastic", "rigid")),
    ModelOption("pin_friction_coefficient", "", 0.0, 1.0, 0.05,
                "Coulomb friction coefficient at the pin-disc contacts, used by the stiffness sweep (assumption "
                "0.05: grease-lubricated hardened steel in boundary lubrication)"),
    ModelOption("bearing_friction_coefficient", "", 0.0, 1.0, 0.0025,
                "Coulomb friction coefficient of the cam and journal bearings referred to the roller pitch "
                "radius, used by the stiffness sweep (assumption 0.0025: SKF's constant coefficient of needle "
                "roller bearings)"),
    ModelOption("contact_pressure_limit_MPa", "MPa", 100.0, 20000.0, 4000.0,
                "largest Hertzian contact pressure the materials bear (ISO 76 static limit of roller bearing "
                "steel, 4000 MPa); a solution above it carries a warning"),
    ModelOption("torsional_compliance_arcsec_per_Nm", "arcsec/(N m)", 0.0, 100.0, 0.0,
                "torsional compliance of the carrier and crank bearings: the output lags by this times the "
                "resisting torque (load dependent)"),
    ModelOption("friction_torque_Nm", "N m", 0.0, 1000.0, 0.0,
                "friction torque at the output that always resists the motion (direction-dependent hysteresis)"),
    ModelOption("cam_bearing_clearance_um", "um", 0.0, 200.0, 0.0,
                "radial clearance of every cam (crank) bearing between crank and disc (backlash)"),
    ModelOption("cam_bearing_stiffness_N_per_um", "N/um", 1.0, 1.0e6, 1.0e6,
                "radial stiffness of a cam bearing once its clearance is taken up, with rigid supports (contact "
                "'impact', or supports 'rigid'); the default 1e6 N/um is the rigid limit's penalty (a rigid bearing: "
                "the clearance is pure play, and clearance -> 0 is the model without it); a smaller value floats the "
                "discs on linear springs at every clearance, zero included. With contact 'physical' and supports "
                "'elastic' the needle-bearing law applies instead"),
]}

MODEL_OPTIONS: dict[str, ModelOption] = {**SOLVER_OPTIONS, **GEOMETRY_OPTIONS}
"""Every option of ``case["model"]`` (solver and geometric), units in the keys."""


def parse_model(model: dict[str, Any] | None) -> dict[str, Any]:
    """Validate the ``model`` object of a case: known keys, numbers inside their range, names among
    their choices. Raises ``ValueError`` naming the key."""
    out: dict[str, Any] = {}
    for k, v in dict(model or {}).items():
        if k not in MODEL_OPTIONS:
            raise ValueError(f"model key {k!r} is unknown; allowed: {sorted(MODEL_OPTIONS)}")
        out[k] = check_option(MODEL_OPTIONS[k], v)
    return out


def model_value(model: dict[str, Any], key: str) -> float:
    """Value of a numeric model option, or its default."""
    return float(model.get(key, MODEL_OPTIONS[key].default))


def model_choice(model: dict[str, Any], key: str) -> str:
    """Value of a named model option, or its default."""
    return str(model.get(key, MODEL_OPTIONS[key].default))
