"""The case JSON of the conventions: Table 4 errors with instance selectors, validated on load.

A case is ``{"name", "design", "errors", "load_Nm", "direction"}``; every key is optional.
Error values are in um or degrees exactly as the paper's Table 4 gives them (see
``ERROR_TYPES``). :func:`load_case` and :meth:`Case.from_dict` validate everything and raise
an :class:`~rvcad.validation.InputError` (a ``ValueError``) naming the offending field, its value
and what is allowed; :class:`ResolvedErrors` turns the case into plain
per-instance arrays in mm and rad that the geometry uses.
"""
from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from rvcad.params import Design
from rvcad.validation import CaseError, DesignError, InputError, as_int, as_mapping, as_real, as_text, read_json_file, reject


@dataclass(frozen=True)
class ErrorType:
    """One Table 4 error type.

    Attributes
    ----------
    key : str
        JSON key.
    letter : str
        Paper Table 4 letter (B..L).
    unit : str
        ``"um"`` or ``"deg"``.
    instance_keys : tuple of str
        Allowed instance selector keys besides ``value`` and ``angle_deg``.
    defaults : dict
        Default instance (``None`` for "all pins").
    has_angle : bool
        Whether ``angle_deg`` is accepted.
    pinwise : bool
        Whether a list of ``Zp`` numbers is accepted.
    meaning : str
        What a positive value means.
    """

    key: str
    letter: str
    unit: str
    instance_keys: tuple[str, ...]
    defaults: dict[str, Any]
    has_angle: bool
    pinwise: bool
    meaning: str
    paper_value: float


ERROR_TYPES: dict[str, ErrorType] = {e.key: e for e in [
    ErrorType("sun_eccentricity", "B", "um", (), {}, True, False,
              "sun gear axis offset from the input axis toward angle_deg (sun frame)", 10.0),
    ErrorType("planet_eccentricity", "C", "um", ("crank",), {"crank": 0}, True, False,
              "planet gear axis offset from its crankshaft axis toward angle_deg (planet frame)", 10.0),
    ErrorType("cam_phase", "D", "um", ("crank", "disc"), {"crank": 0, "disc": 0}, False, False,
              "cam centre moved along its circle of radius e in +psi by this arc length", 10.0),
    ErrorType("cam_eccentricity", "E", "um", ("crank", "disc"), {"crank": 0, "disc": 0}, False, False,
              "cam eccentricity e increased", 10.0),
    ErrorType("carrier_hole_eccentricity", "F", "um", ("crank",), {"crank": 0}, False, False,
              "carrier's crankshaft hole moved radially outward", 10.0),
    ErrorType("disc_hole_eccentricity", "G", "um", ("disc", "hole"), {"disc": 0, "hole": 0}, False, False,
              "crankshaft hole in the cycloid disc moved radially outward", 10.0),
    ErrorType("pin_circle_offset", "H", "um", (), {}, True, False,
              "centre of the pin distribution circle moved toward angle_deg", 10.0),
    ErrorType("pin_circle_diameter", "I", "um", ("pin",), {"pin": None}, False, True,
              "pin distribution circle diameter increased (each pin outward by value/2)", 10.0),
    ErrorType("pin_radius", "J", "um", ("pin",), {"pin": None}, False, True,
              "pin radius increased", 5.0),
    ErrorType("disc_phase", "K", "deg", ("disc",), {"disc": 0}, False, False,
              "cycloid profile turned +z relative to its crank holes", 0.1),
    ErrorType("pin_pitch", "L", "deg", ("pin",), {"pin": 0}, False, True,
              "one pin moved +z along the pin circle from its nominal angle", 0.01),
]}
"""The eleven error types of paper Table 4 (A = none is the empty case)."""

#: Largest magnitude accepted for each unit (a sanity bound, not physics): 1 mm and 5 degrees.
MAX_ABS = {"um": 1000.0, "deg": 5.0}

CASE_KEYS = ("name", "design", "errors", "load_Nm", "direction", "model")


@dataclass(frozen=True)
class ModelOption:
    """A physical effect the base model of the paper lacks, as an option of the case's ``model`` object.

    ``choices`` non-empty: a named option (a string out of ``choices``; ``low``/``high`` unused).
    """

    key: str
    unit: str
    low: float
    high: float
    default: Any
    meaning: str
    choices: tuple[str, ...] = ()


GEOMETRY_OPTIONS: dict[str, ModelOption] = {o.key: o for o in [
    ModelOption("temperature_C", "degC", -40.0, 150.0, 20.0,
                "temperature of the reducer (20 degC = as built)"),
    ModelOption("pin_circle_diameter_um_per_K", "um/K", -20.0, 20.0, 0.0,
                "thermal growth of the pin circle diameter relative to the discs per kelvin above 20 degC "
                "(housing/disc expansion mismatch)"),
    ModelOption("pin_circle_ovality_um", "um", -200.0, 200.0, 0.0,
                "out-of-roundness of the pin circle: pin i moves radially by value*cos(2(phi_i - angle))"),
    ModelOption("pin_circle_ovality_angle_deg", "deg", -360.0, 360.0, 0.0,
                "direction of the major axis of the pin circle ovality"),
    ModelOption("carrier_offset_x_um", "um", -200.0, 200.0, 0.0,
                "the carrier's crank-hole pattern moved off the carrier's axis of rotation (the main bearings' "
                "axis) along the carrier frame's x axis (crank angle 0): the main bearings' radial runout"),
    ModelOption("carrier_offset_y_um", "um", -200.0, 200.0, 0.0,
                "the same along the carrier frame's y axis (crank angle 90 deg)"),
]}
"""The ``model`` options that move parts (used by :class:`ResolvedErrors`). The solver's physics options
(contact law, compliance, friction, bearing clearance) live in ``rvdyn.options``, which validates the
whole ``model`` object (names, ranges) when a case is solved."""


def check_option(o: ModelOption, v: Any) -> Any:
    """Validated value of one model option (number in range or one of its choices)."""
    if o.choices:
        if not isinstance(v, str) or v not in o.choices:
            raise ValueError(f"model.{o.key} {v!r} is not allowed; allowed: {list(o.choices)}")
        return v
    x = _number(v, f"model.{o.key}")
    if not o.low <= x <= o.high:
        raise ValueError(f"model.{o.key} {x} {o.unit} is out of range; allowed [{o.low}, {o.high}]")
    return x


def parse_model(model: dict[str, Any] | None) -> dict[str, Any]:
    """Type-check the ``model`` object of a case: string keys, values finite numbers or names; the
    geometric options (:data:`GEOMETRY_OPTIONS`) also in range. The other names are validated by
    ``rvdyn.options.parse_model``, where the physics lives."""
    out: dict[str, Any] = {}
    for k, v in dict(model or {}).items():
        if not isinstance(k, str):
            raise ValueError(f"model key {k!r} must be a string")
        if k in GEOMETRY_OPTIONS:
            out[k] = check_option(GEOMETRY_OPTIONS[k], v)
        elif isinstance(v, str):
            out[k] = v
        else:
            out[k] = _number(v, f"model.{k}")
    return out


def geometry_option(model: dict[str, Any], key: str) -> float:
    """Value of a geometric model option, or its default."""
    return float(model.get(key, GEOMETRY_OPTIONS[key].default))


def _number(v: Any, where: str) -> float:
    """A finite number (not a bool), as float; :class:`CaseError` naming ``where`` otherwise."""
    return as_real(v, where, cls=CaseError)


def _index(v: Any, where: str, n: int) -> int:
    """An instance index in ``[0, n - 1]``; :class:`CaseError` naming ``where`` otherwise."""
    return as_int(v, where, lo=0, hi=n - 1, cls=CaseError)


@dataclass(frozen=True)
class ErrorInstance:
    """One applied error: type key, value (um or deg), instance selectors and direction angle."""

    key: str
    value: float
    crank: int | None = None
    disc: int | None = None
    hole: int | None = None
    pin: int | None = None
    angle_deg: float = 0.0


#: Largest load magnitude of a case, N m: the dataset reader's bound (``rvrig.dataset.MAX_LOAD_NM``);
#: the largest RV reducers are rated below 10 kN m, so a larger number is a unit slip (N mm).
MAX_LOAD_NM = 20000.0
#: Largest |angle_deg| of an error's direction, degrees (one turn either way).
MAX_ANGLE_DEG = 360.0


def parse_errors(errors: dict[str, Any] | None, design: Design) -> list[ErrorInstance]:
    """Validate the ``errors`` object of a case and expand it into instances.

    Parameters
    ----------
    errors : dict or None
        ``{key: number | object | list}`` as in the conventions (``None``: no errors).
    design : Design
        Gives the index ranges (pins, cranks, discs).

    Returns
    -------
    list of ErrorInstance

    Raises
    ------
    CaseError
        Naming the key for unknown keys, wrong types, empty lists, out-of-range indices or values.
    """
    if errors is None:
        return []
    errors = as_mapping(errors, "errors", f"an object mapping error keys {sorted(ERROR_TYPES)} to values", CaseError)
    n = {"crank": design.n_cranks, "disc": design.n_discs, "hole": design.n_cranks, "pin": design.z_pins}
    out: list[ErrorInstance] = []
    for key, spec in errors.items():
        if key not in ERROR_TYPES:
            reject("errors key", key, f"{sorted(ERROR_TYPES)}", "is unknown", CaseError)
        et = ERROR_TYPES[key]
        lim = MAX_ABS[et.unit]
        forms = ("a number, an object {\"value\": v, ...} or a non-empty list of such objects"
                 + (f", or a list of {design.z_pins} numbers (one per pin)" if et.pinwise else ""))
        if isinstance(spec, list):
            if not spec:
                reject(f"errors.{key}", spec, forms, "is an empty list", CaseError)
            if et.pinwise and all(not isinstance(x, dict) for x in spec):
                if len(spec) != design.z_pins:
                    reject(f"errors.{key}", spec, forms, f"is a pin-wise list of {len(spec)} numbers", CaseError)
                for i, x in enumerate(spec):
                    v = as_real(x, f"errors.{key}[{i}]", lo=-lim, hi=lim, unit=et.unit, cls=CaseError)
                    if v != 0.0:
                        out.append(ErrorInstance(key, v, pin=i))
                continue
            for j, item in enumerate(spec):
                if not isinstance(item, dict):
                    reject(f"errors.{key}[{j}]", item, f"objects {{\"value\": v, ...}} in a list ({forms})",
                           "is not an object", CaseError)
            items = spec
        elif isinstance(spec, dict):
            items = [spec]
        else:
            _number(spec, f"errors.{key}")  # names the type of anything else
            items = [spec]
        for j, item in enumerate(items):
            where = f"errors.{key}" + (f"[{j}]" if isinstance(spec, list) else "")
            sel: dict[str, Any] = dict(et.defaults)
            angle = 0.0
            if isinstance(item, dict):
                allowed = {"value", *et.instance_keys} | ({"angle_deg"} if et.has_angle else set())
                for k in item:
                    if k not in allowed:
                        reject(f"{where} key", k, f"{sorted(allowed)}", "is not allowed", CaseError)
                if "value" not in item:
                    reject(where, item, f"an object with a 'value' ({et.unit}) and keys from {sorted(allowed)}",
                           "has no 'value'", CaseError)
                v = as_real(item["value"], f"{where}.value", lo=-lim, hi=lim, unit=et.unit, cls=CaseError)
                for k in et.instance_keys:
                    if k in item:
                        sel[k] = _index(item[k], f"{where}.{k}", n[k])
                if "angle_deg" in item:
                    angle = as_real(item["angle_deg"], f"{where}.angle_deg", lo=-MAX_ANGLE_DEG, hi=MAX_ANGLE_DEG,
                                    unit="deg", cls=CaseError)
            else:
                v = as_real(item, where, lo=-lim, hi=lim, unit=et.unit, cls=CaseError)
            out.append(ErrorInstance(key, v, crank=sel.get("crank"), disc=sel.get("disc"),
                                     hole=sel.get("hole"), pin=sel.get("pin"), angle_deg=angle))
    return out

@dataclass(frozen=True)
class Case:
    """A validated case: design, error instances, load and direction.

    Attributes
    ----------
    name : str
    design : Design
    errors : tuple of ErrorInstance
    raw_errors : dict
        The ``errors`` object as given (normalised JSON), kept for the cache key and export.
    load_Nm : float
        Output load torque magnitude, N m (default 20); it always resists the motion.
    direction : int
        +1 (input angle increasing) or -1.
    model : dict
        Extra physics options of the rvdyn model (unmodelled-effect parameters, see rvdyn).
    """

    name: str = "case"
    design: Design = field(default_factory=Design)
    errors: tuple[ErrorInstance, ...] = ()
    raw_errors: dict[str, Any] = field(default_factory=dict)
    load_Nm: float = 20.0
    direction: int = 1
    model: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: Any) -> "Case":
        """Validate a case object (``None``: the nominal case).

        Raises
        ------
        InputError
            :class:`~rvcad.validation.CaseError` or :class:`~rvcad.validation.DesignError` naming
            the field, its value and what is allowed.
        """
        d = as_mapping({} if d is None else d, "case", f"a JSON object with keys from {list(CASE_KEYS)}", CaseError)
        for k in d:
            if k not in CASE_KEYS:
                reject("case key", k, f"{list(CASE_KEYS)}", "is unknown", CaseError)
        name = as_text(d.get("name", "case"), "name", max_len=255, cls=CaseError)
        if "design" in d:
            as_mapping(d["design"], "design", "an object of Design fields (omit the key for the default design)",
                       DesignError)
        design = Design.from_dict(d.get("design"))
        raw = as_mapping(d.get("errors", {}), "errors",
                         "an object mapping error keys to values (omit the key or give {} for none)", CaseError)
        errs = parse_errors(raw, design)
        load = as_real(d.get("load_Nm", 20.0), "load_Nm", lo=0.0, hi=MAX_LOAD_NM, unit="N m", cls=CaseError,
                       why="a magnitude: the load always resists the motion")
        direction = d.get("direction", 1)
        if isinstance(direction, bool) or not isinstance(direction, (int, float)) or direction not in (1, -1):
            reject("direction", direction, "+1 or -1", "is not a drive direction", CaseError)
        model = as_mapping(d.get("model", {}), "model",
                           "an object of rvdyn physics options (omit the key or give {} for none)", CaseError)
        try:
            model = parse_model(model)
        except InputError:
            raise
        except ValueError as exc:  # parse_model's own range messages name model.KEY already
            raise CaseError(str(exc), field="model") from None
        case = cls(name=name, design=design, errors=tuple(errs), raw_errors=json.loads(json.dumps(raw)),
                   load_Nm=load, direction=int(direction), model=dict(model))
        ResolvedErrors(case)  # checks that the perturbed parts are valid
        return case

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form that :meth:`from_dict` reads back to an equal case."""
        d: dict[str, Any] = {"name": self.name, "design": self.design.to_dict(), "errors": self.raw_errors,
                             "load_Nm": self.load_Nm, "direction": self.direction}
        if self.model:
            d["model"] = self.model
        return d

    def key(self) -> str:
        """Content hash (sha256 hex, 16 chars) of everything that changes the physics (not the name)."""
        return self._key

    @cached_property
    def _key(self) -> str:
        # made once per (frozen) case: the solve cache asks for it on every job
        d = self.to_dict()
        d.pop("name")
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]

    def with_errors(self, errors: dict[str, Any], name: str | None = None) -> "Case":
        """A copy with another ``errors`` object (validated)."""
        d = self.to_dict()
        d["errors"] = errors
        if name is not None:
            d["name"] = name
        return Case.from_dict(d)

    def plus(self, delta: dict[str, Any], t: float = 1.0, model_defaults: dict[str, Any] | None = None,
             field: str = "delta") -> "Case":
        """This case plus ``t`` times a *direction* in case space (validated).

        ``delta`` is ``{"errors": {...}, "model": {...}}`` (either key optional). Its ``errors`` object has the
        case JSON's forms (a number for the default instance, objects with instance keys and ``angle_deg``,
        lists of them, a pin-wise list of numbers); each of its instances times ``t`` adds to this case's
        instance with the same selectors (key, crank, disc, hole, pin, ``angle_deg``), or is appended as a new
        instance (the geometry sums instances, so both read the same). Its ``model`` options add ``t`` times
        their value to this case's value, or to the default when the case does not set the option
        (``model_defaults`` maps option keys to defaults; the geometric options' defaults are known here, the
        solver's live in ``rvdyn.options.MODEL_OPTIONS``). Raises :class:`CaseError` naming
        ``field.errors.KEY`` or ``field.model.KEY`` for a bad delta, and whatever :meth:`from_dict` raises for
        a sum outside the valid cases."""
        delta = as_mapping(delta, field, 'an object {"errors": {...}, "model": {...}}', CaseError)
        for k in delta:
            if k not in ("errors", "model"):
                reject(f"{field} key", k, "['errors', 'model']", "is unknown", CaseError)
        t = _number(t, "t")
        try:
            extra = parse_errors(delta.get("errors") or {}, self.design)
        except CaseError as exc:
            raise CaseError(f"{field}.{exc}", field=f"{field}.{exc.field or 'errors'}") from None
        merged: dict[tuple, float] = {}
        for scale, insts in ((1.0, self.errors), (t, extra)):
            for inst in insts:
                sel = (inst.key, inst.crank, inst.disc, inst.hole, inst.pin, inst.angle_deg)
                merged[sel] = merged.get(sel, 0.0) + scale * inst.value
        errors: dict[str, list[dict[str, Any]]] = {}
        for (key, crank, disc, hole, pin, angle), v in merged.items():
            item: dict[str, Any] = {"value": v}
            item.update({k: i for k, i in (("crank", crank), ("disc", disc), ("hole", hole), ("pin", pin))
                         if i is not None and k in ERROR_TYPES[key].instance_keys})
            if ERROR_TYPES[key].has_angle:
                item["angle_deg"] = angle
            errors.setdefault(key, []).append(item)
        d = self.to_dict()
        d["errors"] = errors
        d["model"] = self._model_plus(as_mapping(delta.get("model") or {}, f"{field}.model",
                                                 "an object of numeric model options", CaseError),
                                      t, {**{k: o.default for k, o in GEOMETRY_OPTIONS.items()},
                                          **(model_defaults or {})}, f"{field}.model")
        return Case.from_dict(d)

    def _model_plus(self, dm: dict[str, Any], t: float, defaults: dict[str, Any], field: str) -> dict[str, Any]:
        """This case's model options with ``t`` times ``dm`` added (see :meth:`plus`)."""
        model = dict(self.model)
        for k, dv in dm.items():
            base = model.get(k, defaults.get(k))
            if isinstance(base, str) or base is None:
                numeric = sorted(o for o, v in defaults.items() if not isinstance(v, str))
                reject(f"{field} key", k, f"a numeric model option {numeric}",
                       "is a named choice, not a number" if isinstance(base, str) else "is unknown", CaseError)
            model[k] = float(base) + t * _number(dv, f"{field}.{k}")
        return model


def load_case(path: str | Path | None) -> Case:
    """Read a case JSON file (``None``: the nominal case with no errors).

    The JSON is read strictly: a key repeated in one object, ``NaN``/``Infinity`` and a top level
    that is not an object are errors (:class:`~rvcad.validation.CaseError`), as is everything
    :meth:`Case.from_dict` refuses.
    """
    if path is None:
        return Case.from_dict({"name": "nominal"})
    p = Path(path)
    d = read_json_file(p, "case file", CaseError)
    if not isinstance(d, dict):
        reject(f"case file {str(p)!r}: the top level", d,
               f"a JSON object with keys from {list(CASE_KEYS)}", "is not an object", CaseError)
    d.setdefault("name", p.stem)
    return Case.from_dict(d)

def as_case(case: Case | dict[str, Any] | str | Path | None) -> Case:
    """A validated :class:`Case` from a case, a dict (the case JSON object) or a JSON file path.

    Raises :class:`rvcad.validation.CaseError` (a ``ValueError``) for anything else."""
    if case is None:
        return Case.from_dict({"name": "nominal"})
    if isinstance(case, Case):
        return case
    if isinstance(case, Mapping):
        d = dict(case)
        d.setdefault("name", "nominal" if not d else "case")
        return Case.from_dict(json.loads(json.dumps(d)))
    if isinstance(case, (str, Path)):
        return load_case(case)
    reject("case", case, "a rvcad.Case, a dict (the case JSON object) or the path of a case JSON file",
           f"is of type {type(case).__name__}", CaseError)


class ResolvedErrors:
    """Per-instance perturbations in mm and rad, ready for the geometry.

    Attributes (all float64 numpy arrays)
    ------------------------------------
    sun_offset : (2,)
        Sun gear centre offset in the sun frame, mm.
    planet_offset : (n_cranks, 2)
        Planet gear centre offset in the crank (planet) frame, mm.
    cam_phase : (n_cranks, n_discs)
        Cam phase shift, rad (arc length / e).
    cam_ecc : (n_cranks, n_discs)
        Cam eccentricity increase, mm.
    carrier_hole : (n_cranks,)
        Radial outward shift of the carrier's crank holes, mm.
    disc_hole : (n_discs, n_cranks)
        Radial outward shift of hole h in disc k, mm.
    pin_circle_offset : (2,)
        Offset of the pin circle centre in the fixed frame, mm.
    carrier_offset : (2,)
        Offset of the carrier's crank-hole pattern from the carrier's axis of rotation, carrier frame, mm.
    pin_radial : (Zp,)
        Radial outward shift of each pin centre, mm (half the diameter error).
    pin_radius : (Zp,)
        Pin radius increase, mm.
    disc_phase : (n_discs,)
        Profile rotation relative to the crank holes, rad.
    pin_pitch : (Zp,)
        Angular shift of each pin along the pin circle, rad.
    """

    def __init__(self, case: Case) -> None:
        d = case.design
        nc, nd, zp = d.n_cranks, d.n_discs, d.z_pins
        self.sun_offset = np.zeros(2)
        self.planet_offset = np.zeros((nc, 2))
        self.cam_phase = np.zeros((nc, nd))
        self.cam_ecc = np.zeros((nc, nd))
        self.carrier_hole = np.zeros(nc)
        self.disc_hole = np.zeros((nd, nc))
        self.pin_circle_offset = np.zeros(2)
        self.carrier_offset = np.zeros(2)
        self.pin_radial = np.zeros(zp)
        self.pin_radius = np.zeros(zp)
        self.disc_phase = np.zeros(nd)
        self.pin_pitch = np.zeros(zp)
        um = 1e-3
        e = d.eccentricity_mm
        for inst in case.errors:
            v = inst.value
            ang = math.radians(inst.angle_deg)
            u = np.array([math.cos(ang), math.sin(ang)])
            pins = slice(None) if inst.pin is None else inst.pin
            if inst.key == "sun_eccentricity":
                self.sun_offset += v * um * u
            elif inst.key == "planet_eccentricity":
                self.planet_offset[inst.crank] += v * um * u
            elif inst.key == "cam_phase":
                self.cam_phase[inst.crank, inst.disc] += v * um / e
            elif inst.key == "cam_eccentricity":
                self.cam_ecc[inst.crank, inst.disc] += v * um
            elif inst.key == "carrier_hole_eccentricity":
                self.carrier_hole[inst.crank] += v * um
            elif inst.key == "disc_hole_eccentricity":
                self.disc_hole[inst.disc, inst.hole] += v * um
            elif inst.key == "pin_circle_offset":
                self.pin_circle_offset += v * um * u
            elif inst.key == "pin_circle_diameter":
                self.pin_radial[pins] += v * um / 2.0
            elif inst.key == "pin_radius":
                self.pin_radius[pins] += v * um
            elif inst.key == "disc_phase":
                self.disc_phase[inst.disc] += math.radians(v)
            elif inst.key == "pin_pitch":
                self.pin_pitch[pins] += math.radians(v)
            else:  # pragma: no cover - parse_errors rejects unknown keys
                raise ValueError(f"errors key {inst.key!r} is unknown")
        # geometric effects of the case's model options (see GEOMETRY_OPTIONS)
        m = case.model
        dT = geometry_option(m, "temperature_C") - 20.0
        self.pin_radial += geometry_option(m, "pin_circle_diameter_um_per_K") * dT * um / 2.0
        ov = geometry_option(m, "pin_circle_ovality_um")
        if ov:
            phi = 2 * np.pi * np.arange(zp) / zp
            self.pin_radial += ov * um * np.cos(2.0 * (phi - math.radians(geometry_option(m, "pin_circle_ovality_angle_deg"))))
        self.carrier_offset += um * np.array([geometry_option(m, "carrier_offset_x_um"),
                                              geometry_option(m, "carrier_offset_y_um")])
        self._check(case)

    def _check(self, case: Case) -> None:
        d = case.design
        if np.any(d.eccentricity_mm + self.cam_ecc <= 0):
            raise CaseError("errors.cam_eccentricity makes a cam eccentricity <= 0 mm")
        r = d.pin_radius_mm + self.pin_radius
        if np.any(r <= 0):
            i = int(np.argmin(r))
            raise CaseError(f"errors.pin_radius makes pin {i} radius {r[i]:.6f} mm <= 0")
        ang = 2 * np.pi * np.arange(d.z_pins) / d.z_pins + self.pin_pitch
        rad = d.pin_circle_radius_mm + self.pin_radial
        xy = rad[:, None] * np.c_[np.cos(ang), np.sin(ang)] + self.pin_circle_offset
        nxt = np.roll(np.arange(d.z_pins), -1)
        dist = np.linalg.norm(xy[nxt] - xy, axis=1)
        over = dist - (r + r[nxt])
        if np.any(over <= 0):
            i = int(np.argmin(over))
            raise CaseError(
                f"errors.pin_pitch / pin_radius / pin_circle_diameter make pins {i} and {int(nxt[i])} overlap "
                f"(centre distance {dist[i]:.4f} mm < radii sum {r[i] + r[nxt[i]]:.4f} mm)")
