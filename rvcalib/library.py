"""The candidate library as data: every effect the loop may name, with its unit, bounds and prior scale.

Families (the first four are physical and may be *named*; the last is never named):

* ``table4``: every instance of every error of paper Table 4 (``rvcad.errors.ERROR_TYPES``): the sun; each
  crank's planet (two components) and carrier hole; each crank and disc's cam phase and eccentricity; each disc's
  holes and phase; the pin circle's offset (two components) and diameter; every pin's pitch, radius and radial
  position, and all pins' radius together.
* ``form``: the smooth form of the pin ring, one two-component candidate per Fourier mode k = 2 .. Zp/2 of the
  pins' radial and of their pitch deviations (cosine and sine of k times the pin's angle): order k of the ring
  gives order k of the TE. Mode 2 of the radial form is the ring's ovality.
* ``model``: physical effects of the reducer the declared model lacks, passed to rvdyn as model options:
  a lumped torsional compliance, a friction torque, a cam-bearing clearance, the carrier's offset from its axis
  of rotation (the main bearings' runout) less the radial part each crank's carrier-hole eccentricity holds
  (:func:`carrier_offset_axes`), and (when the runs differ in temperature) the pin circle's thermal growth.
* ``measurement``: errors of the encoders: eccentricity of the output and of the input encoder scale (two
  components), the output encoder's scale error and a drift of the reading in time. The last two are ramps;
  they are candidates only where the record shows a ramp (:func:`ramp_shown`).
* ``empirical``: structure without a physical meaning, so that a signal the physics cannot give is reported as
  *unexplained* instead of being forced onto a physical candidate: harmonics of the output angle of every order
  the readings resolve, the same in every run (``common``), proportional to the load (``load``) or changing
  sign with the direction (``direction``), and the direction-signed and load-times-direction constants.

Prior scales are the tolerance class a maker holds: a third of the paper's Table 4 value for each error; for
the form modes the amplitude of mode k when every pin deviates independently with that class
(``sigma sqrt(2 / Zp)``); for the model and measurement effects the sizes stated with each in
:data:`PRIOR_SCALES`. The torsional compliance's and the empirical terms' scales come from the declared model's
own response (:func:`rescale`): the compliance is as large as the model's own compliance at the runs' loads,
an empirical term as large as the typical TE of a tolerance-class effect.

Prior inclusion weights: each physical *type* (an error key, a form kind, a model option, an encoder effect) has
weight one, shared among its instances (the pin-wise types: half to all pins together, half to the single pins);
the empirical block together has ``empirical_weight``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rvcad.errors import ERROR_TYPES
from rvcad.params import Design
from rvdyn.options import MODEL_OPTIONS
from rvrig.average import filtered_model_orders, model_samples_per_rev

ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0
ARCSEC_PER_DEG = 3600.0

#: Assumed radius of the output encoder's scale, mm (a ring scale on the output flange).
OUTPUT_ENCODER_RADIUS_MM = 100.0
#: Assumed radius of the input encoder's scale, mm (a shaft encoder).
INPUT_ENCODER_RADIUS_MM = 25.0

PHYSICAL = ("table4", "form", "model", "measurement")
FAMILIES = PHYSICAL + ("empirical",)

#: Prior scales of the model and measurement effects (unit of each): a friction torque of a few percent of the
#: load is taken relative to the largest load (``friction_torque_Nm`` is multiplied by it); a cam bearing's radial
#: clearance of a few micrometres (rolling bearings of class C2..CN); thermal growth of a steel ring (11.5 um/(m K)
#: over the pin circle); an encoder ring mounted within 10 um; a scale error of 20 ppm (a ring scale's accuracy
#: grade); a drift of 2 arcsec per revolution; the carrier's offset from its axis of rotation in the class of its
#: crank holes' position (a third of Table 4 F).
PRIOR_SCALES = {"friction_torque_Nm": 0.03, "cam_bearing_clearance_um": 3.0, "pin_circle_diameter_um_per_K": 1.5,
                "output_encoder_eccentricity": 10.0, "input_encoder_eccentricity": 10.0,
                "output_encoder_scale_error": 20.0, "drift_arcsec_per_rev": 2.0,
                "carrier_offset": ERROR_TYPES["carrier_hole_eccentricity"].paper_value / 3.0}

#: Model candidates of two components (x, y) and the model options that hold them.
MODEL_VECTORS = {"carrier_offset": ("carrier_offset_x_um", "carrier_offset_y_um")}


def carrier_offset_axes(design: Design) -> tuple[tuple[float, float], ...]:
    """The directions (unit vectors of the carrier frame) of the carrier offset the library holds.

    An offset ``d`` of the carrier's crank-hole pattern moves every crank hole by ``d``. At crank ``i`` (angle
    ``beta_i``, radial unit vector ``u_i``, tangential ``t_i``) its radial part ``d . u_i`` is that crank's
    carrier-hole eccentricity (Table 4 F), already a candidate; only the tangential part ``d . t_i`` is new. The
    library's carrier offset is therefore the offset with its radial parts taken back off the holes, and its
    directions are those whose tangential pattern is not zero: both axes with three or more cranks, only the axis
    across the crank line with two cranks at 0 and 180 deg, where an offset along the line is the two holes moved
    radially apart, exactly.
    """
    b = np.array(design.crank_angles_rad, dtype=float)
    t = np.column_stack([-np.sin(b), np.cos(b)])        # row i: t_i; t @ d is each hole's tangential move
    _, s, vt = np.linalg.svd(t)
    if s.size == 2 and s[1] > 1e-9 * s[0]:
        return ((1.0, 0.0), (0.0, 1.0))
    axis = np.where(np.abs(vt[0]) < 1e-12, 0.0, vt[0])
    axis = axis / np.linalg.norm(axis) * (1.0 if axis[np.argmax(np.abs(axis))] > 0 else -1.0) + 0.0
    return ((float(axis[0]), float(axis[1])),)


def carrier_offset_radial(d: np.ndarray, crank_angles_rad: tuple) -> dict[int, float]:
    """The radial part ``d . u_i`` of a carrier offset ``d`` (um, carrier frame) at each crank's hole, by crank; a
    part below the rounding of ``d`` (a crank on the offset's normal) is left out."""
    out = {}
    for i, b in enumerate(crank_angles_rad):
        radial = float(d[0] * math.cos(b) + d[1] * math.sin(b))
        if abs(radial) > 1e-12 * float(np.hypot(d[0], d[1])):
            out[i] = radial
    return out


def _add_carrier_offset(acc: "CaseDelta", axes: tuple, crank_angles_rad: tuple, p: np.ndarray) -> None:
    """Add the library's carrier offset at parameters ``p`` (:func:`carrier_offset_axes`): the offset options,
    and each crank's carrier hole moved radially back by the offset's radial part there."""
    d = sum(float(pj) * np.asarray(ax, dtype=float) for pj, ax in zip(p, axes))
    kx, ky = MODEL_VECTORS["carrier_offset"]
    acc.model[kx] = acc.model.get(kx, 0.0) + float(d[0])
    acc.model[ky] = acc.model.get(ky, 0.0) + float(d[1])
    for i, radial in carrier_offset_radial(d, crank_angles_rad).items():
        acc.items.append(("carrier_hole_eccentricity", {"value": -radial, "crank": i}))


@dataclass(frozen=True)
class Candidate:
    """One candidate effect.

    Attributes
    ----------
    name : str
        Unique id: ``pin_pitch[pin=7]``, ``cam_phase[crank=1,disc=0]``, ``pin_form_radial[k=3]``,
        ``torsional_compliance_arcsec_per_Nm``, ``output_encoder_eccentricity``, ``order 7 (load)``.
    key : str
        Table 4 error key, model option key, measurement key, or the empirical kind.
    family : str
        One of :data:`FAMILIES`.
    unit : str
    meaning : str
        Physical meaning of a positive value.
    params : tuple of str
        ``("value",)``, or the components ``("x", "y")`` (eccentricities: along 0 and 90 deg of the error's frame;
        form modes and harmonics: cosine and sine).
    prior_scale : float
        Tolerance class (prior standard deviation of each parameter), in ``unit``.
    lower, upper : float
        Physical bounds of each parameter.
    instance : tuple of (str, int)
        Selectors (crank, disc, hole, pin, k).
    type_key : str
        The type that shares one prior weight among its instances.
    share : float
        This candidate's share of its type's weight.
    pattern : tuple of (tuple of float) or None
        Pin-wise effects: per parameter, the value of the error at each pin per unit parameter.
    order : int
        Empirical harmonics: the order (cycles per output revolution); 0 for constants.
    kink : bool
        The TE's response has a kink at the tolerance scale (a contact set that changes with the sign: all the
        pins' radius or circle diameter turn the all-pins contact into a clearance one way and a preload the
        other; a bearing clearance opens from zero): its column is a secant over the parameter's current spread,
        not a derivative (:mod:`rvcalib.reducer_model`).
    side : int
        +1 or -1 for one side of a pin-wise error (the positive or negative values only): the response of a
        zero-backlash ring differs in kind with the sign (a pin pushed out opens a clearance, pushed in it preloads),
        so each side is its own candidate, ``name`` ending in `` (+)`` or `` (-)``; 0 for every other candidate.
    dense : bool
        Always estimated (not chosen): the reducer's global fit and stiffness, which every reducer has and which
        change how every other error shows (all the pins' radius and circle diameter, the torsional compliance).
    axes : tuple of (float, float) or None
        The carrier offset: per parameter, its direction in the carrier frame (:func:`carrier_offset_axes`).
    crank_angles_rad : tuple of float
        The carrier offset: the cranks' angles, rad, whose holes take back the offset's radial part.
    """

    @property
    def effect_name(self) -> str:
        """The name of the effect reported: without the side of a pin-wise error."""
        return self.name[:-4] if self.side else self.name

    name: str
    key: str
    family: str
    unit: str
    meaning: str
    params: tuple[str, ...] = ("value",)
    prior_scale: float = 1.0
    lower: float = -math.inf
    upper: float = math.inf
    instance: tuple[tuple[str, int], ...] = ()
    type_key: str = ""
    share: float = 1.0
    pattern: tuple[tuple[float, ...], ...] | None = None
    order: int = 0
    kink: bool = False
    side: int = 0
    dense: bool = False
    axes: tuple[tuple[float, float], ...] | None = None
    crank_angles_rad: tuple[float, ...] = ()

    @property
    def n_params(self) -> int:
        return len(self.params)

    @property
    def polar(self) -> bool:
        """Two components reported as a magnitude and an angle."""
        return self.n_params == 2

    @property
    def physical(self) -> bool:
        return self.family in PHYSICAL

    @property
    def solved(self) -> bool:
        """Its columns come from rvdyn (the reducer's physics); otherwise they are reading errors, analytic."""
        return self.family in ("table4", "form", "model")

    def deltas(self) -> list[dict]:
        """Per parameter, the change of a case per unit parameter (rvdyn's ``te_jacobian`` directions)."""
        out = []
        for j in range(self.n_params):
            acc = CaseDelta()
            p = np.zeros(self.n_params)
            p[j] = 1.0
            self.add_to(acc, p)
            out.append(acc.to_dict(None))
        return out

    def add_to(self, acc: "CaseDelta", p: np.ndarray) -> None:
        """Add this effect at parameters ``p`` to a case under construction."""
        if self.axes is not None:
            _add_carrier_offset(acc, self.axes, self.crank_angles_rad, p)
            return
        if self.family == "model":                   # one option each; the carrier offset's two: axes above
            acc.model[self.key] = acc.model.get(self.key, 0.0) + float(p[0])
            return
        if self.pattern is not None:
            v = acc.pinwise.setdefault(self.key, np.zeros(len(self.pattern[0])))
            for j, pat in enumerate(self.pattern):
                v += float(p[j]) * np.asarray(pat)
            return
        if self.family != "table4":
            return
        inst = dict(self.instance)
        if self.n_params == 1:
            acc.items.append((self.key, {"value": float(p[0]), **inst}))
        else:
            acc.items.append((self.key, {"value": float(p[0]), "angle_deg": 0.0, **inst}))
            acc.items.append((self.key, {"value": float(p[1]), "angle_deg": 90.0, **inst}))

    def size(self, p: np.ndarray) -> tuple[float, float | None]:
        """The reported size: the value, or the magnitude and the angle (deg) of two components."""
        if not self.polar:
            return float(p[0]), None
        return math.hypot(p[0], p[1]), math.degrees(math.atan2(p[1], p[0]))


@dataclass
class CaseDelta:
    """A case under construction: error instances, pin-wise lists (one per key) and model options."""

    items: list = field(default_factory=list)
    pinwise: dict = field(default_factory=dict)
    model: dict = field(default_factory=dict)

    def to_dict(self, base: dict | None) -> dict:
        """The case dict: ``base`` (a run's declared case, or None) with these additions. Error instances of a
        key are listed as objects; a key with a pin-wise addition becomes one list of a value per pin."""
        base = base or {}
        out = {k: v for k, v in base.items() if k not in ("errors", "model")}
        errors: dict = {}
        for key, v in (base.get("errors") or {}).items():
            if isinstance(v, list) and v and not isinstance(v[0], dict):
                errors[key] = [np.asarray(v, dtype=float)]          # a pin-wise list of a value per pin
            else:
                errors[key] = [o if isinstance(o, dict) else {"value": float(o)}
                               for o in (v if isinstance(v, list) else [v])]
        for key, obj in self.items:
            errors.setdefault(key, []).append(obj)
        for key, vec in self.pinwise.items():
            errors.setdefault(key, []).append(np.asarray(vec, dtype=float))
        for key in list(errors):
            if ERROR_TYPES[key].pinwise and any(isinstance(o, np.ndarray) for o in errors[key]):
                zp = next(o.size for o in errors[key] if isinstance(o, np.ndarray))
                errors[key] = [float(x) for x in sum(_pinwise_vector(key, o, zp) for o in errors[key])]
        model = dict(base.get("model") or {})
        for k, v in self.model.items():
            model[k] = model.get(k, 0.0) + v
        if errors:
            out["errors"] = errors
        if model:
            out["model"] = model
        return out


def _pinwise_vector(key: str, obj, zp: int) -> np.ndarray:
    """A pin-wise error given as a vector of a value per pin, or as an instance object whose pin is its own or
    the error's default instance (all pins, or pin 0 of the pin pitch), as a vector."""
    if isinstance(obj, np.ndarray):
        return obj
    pin = obj.get("pin", ERROR_TYPES[key].defaults.get("pin"))
    v = np.zeros(zp)
    if pin is None:
        v[:] = float(obj["value"])
    else:
        v[int(pin)] = float(obj["value"])
    return v


@dataclass
class Library:
    """The candidates of a dataset, in order, with the notes on what was left out and why."""

    candidates: list
    notes: list = field(default_factory=list)

    def __iter__(self):
        return iter(self.candidates)

    def __len__(self) -> int:
        return len(self.candidates)

    def by_name(self, name: str) -> Candidate:
        """The candidate called ``name`` (ValueError naming it if unknown)."""
        for c in self.candidates:
            if c.name == name:
                return c
        raise ValueError(f"effect {name!r} is not in the candidate library")

    def prior_weights(self, empirical_weight: float) -> np.ndarray:
        """Prior inclusion weight of each candidate (unnormalised)."""
        return np.array([c.share * (empirical_weight if c.family == "empirical" else 1.0) for c in self.candidates])


#: Table 4 errors that move the whole pin ring against the discs: like the ring's fit, they lift some pins off
#: and press others, so the TE's response is kinked at the tolerance scale (a secant, not a derivative).
RING_MOTIONS = frozenset({"pin_circle_offset"})


def _name(key: str, inst: dict) -> str:
    return key + ("[" + ",".join(f"{k}={v}" for k, v in inst.items()) + "]" if inst else "")


def _table4(design: Design, declared: set) -> list:
    """Every instance of every Table 4 error (see the module docstring)."""
    out = []
    ranges = {"crank": design.n_cranks, "disc": design.n_discs, "hole": design.n_cranks, "pin": design.z_pins}
    for key, et in ERROR_TYPES.items():
        b = 200.0 if et.unit == "um" else 1.0
        mis = " (a correction to the declared value)" if key in declared else ""
        meaning = f"Table 4 {et.letter}: {et.meaning}{mis}"
        scale = et.paper_value / 3.0
        comps = ("x", "y") if et.has_angle else ("value",)
        if et.pinwise:
            insts = ([] if key == "pin_pitch" else [{}]) + [{"pin": p} for p in range(design.z_pins)]
        else:
            insts = [{}]
            for ik in et.instance_keys:
                insts = [dict(i, **{ik: v}) for i in insts for v in range(ranges[ik])]
        for inst in insts:
            if et.pinwise and key != "pin_pitch":
                share = 0.5 if not inst else 0.5 / design.z_pins
            else:
                share = 1.0 / len(insts)
            where = " (all pins)" if et.pinwise and not inst else ""
            if not et.pinwise:
                out.append(Candidate(_name(key, inst), key, "table4", et.unit, meaning, comps, scale, -b, b,
                                     tuple(inst.items()), key, share, kink=key in RING_MOTIONS))
                continue
            if not inst:                                  # the ring's fit: always estimated
                out.append(Candidate(key, key, "table4", et.unit, meaning + where, comps, scale, -b, b, (), key, share,
                                     kink=True, dense=True))
                continue
            for side, lo, hi in ((1, 0.0, b), (-1, -b, 0.0)):
                out.append(Candidate(_name(key, inst) + (" (+)" if side > 0 else " (-)"), key, "table4", et.unit,
                                     meaning + where + (" (positive values)" if side > 0 else " (negative values)"),
                                     comps, scale, lo, hi, tuple(inst.items()), key, share / 2.0, kink=True,
                                     side=side))
    return out


def _form(design: Design) -> list:
    """The pin ring's form modes k = 2 .. Zp/2, radial (as pin-circle diameter per pin) and pitch."""
    zp = design.z_pins
    phi = 2.0 * math.pi * np.arange(zp) / zp
    kmax = zp // 2
    out = []
    for kind, key, unit, per in (("radial", "pin_circle_diameter", "um", 2.0), ("pitch", "pin_pitch", "deg", 1.0)):
        sigma = ERROR_TYPES[key].paper_value / 3.0 / per * math.sqrt(2.0 / zp)
        for k in range(2, kmax + 1):
            c, s = np.cos(k * phi), np.sin(k * phi)
            pat = (tuple(per * c), tuple(per * s)) if k < kmax or zp % 2 else (tuple(per * c),)
            comps = ("cos", "sin")[:len(pat)]
            what = ("radial position (outward)" if kind == "radial" else "angular position (+z)")
            meaning = (f"form of the pin ring: each pin's {what} deviates by a cos(k phi) + b sin(k phi), k = {k} "
                       f"(phi the pin's angle){'; the ring is oval' if kind == 'radial' and k == 2 else ''}")
            out.append(Candidate(f"pin_form_{kind}[k={k}]", key, "form", unit, meaning, comps, sigma, -200.0, 200.0,
                                 (("k", k),), f"pin_form_{kind}", 1.0 / (kmax - 1), pat))
    return out


def _model(dataset) -> tuple[list, list]:
    mo = MODEL_OPTIONS
    design = dataset.design
    out, notes = [], []
    loads = [r.load_Nm for r in dataset.runs]
    if max(loads) > 0:
        o = mo["torsional_compliance_arcsec_per_Nm"]
        out.append(Candidate(o.key, o.key, "model", "arcsec/(N m)", o.meaning, prior_scale=0.5, lower=0.0,
                             upper=o.high, type_key=o.key, dense=True))
        o = mo["friction_torque_Nm"]
        out.append(Candidate(o.key, o.key, "model", "N m", o.meaning,
                             prior_scale=PRIOR_SCALES[o.key] * max(loads), lower=0.0, upper=o.high, type_key=o.key))
    else:
        notes.append("torsional compliance and friction torque are not candidates: every run is at load 0")
    o = mo["cam_bearing_clearance_um"]
    out.append(Candidate(o.key, o.key, "model", "um", o.meaning, prior_scale=PRIOR_SCALES[o.key], lower=0.0,
                         upper=o.high, type_key=o.key, kink=True))
    o = mo["carrier_offset_x_um"]
    axes = carrier_offset_axes(design)
    if len(axes) == 2:
        params, where = ("x", "y"), "x along crank angle 0 of the carrier frame, y at 90 deg"
    else:
        ang = math.degrees(math.atan2(axes[0][1], axes[0][0]))
        params, where = ("value",), (f"along {ang:g} deg of the carrier frame (across the crank line; an offset "
                                     "along it is the carrier holes' eccentricities, Table 4 F)")
    out.append(Candidate("carrier_offset", "carrier_offset", "model", "um",
                         "the carrier's crank-hole pattern off the carrier's axis of rotation (the main bearings' "
                         "radial runout), less the radial part at each hole, which is that crank's carrier-hole "
                         f"eccentricity (Table 4 F): the holes moved tangentially; {where}", params,
                         PRIOR_SCALES["carrier_offset"], o.low, o.high, type_key="carrier_offset", kink=True,
                         axes=axes, crank_angles_rad=tuple(design.crank_angles_rad)))
    if dataset.temperatures_vary:
        o = mo["pin_circle_diameter_um_per_K"]
        out.append(Candidate(o.key, o.key, "model", "um/K", o.meaning, prior_scale=PRIOR_SCALES[o.key], lower=o.low,
                             upper=o.high, type_key=o.key))
    else:
        notes.append("thermal growth of the pin circle is not a candidate: the runs share one temperature, where "
                     "it cannot be told from pin_circle_diameter")
    return out, notes


def _measurement(design: Design, ramps: bool) -> tuple[list, list]:
    n = float(design.ratio)
    out = [Candidate("output_encoder_eccentricity", "output_encoder_eccentricity", "measurement", "um",
                     f"eccentricity of the output encoder's scale (assumed radius {OUTPUT_ENCODER_RADIUS_MM:g} mm): "
                     "a reading error (eps/R) sin(theta_out + phi), order 1 of the TE", ("x", "y"),
                     PRIOR_SCALES["output_encoder_eccentricity"], -1000.0, 1000.0, type_key="output_encoder"),
           Candidate("input_encoder_eccentricity", "input_encoder_eccentricity", "measurement", "um",
                     f"eccentricity of the input encoder's scale (assumed radius {INPUT_ENCODER_RADIUS_MM:g} mm): "
                     f"a reading error (eps/R) sin(theta_in + phi), order {n:g} of the TE divided by {n:g}",
                     ("x", "y"), PRIOR_SCALES["input_encoder_eccentricity"], -1000.0, 1000.0,
                     type_key="input_encoder")]
    notes = []
    if ramps:
        out.append(Candidate("output_encoder_scale_error", "output_encoder_scale_error", "measurement", "ppm",
                             "scale error s of the output encoder: it reads theta_out (1 + s), a ramp s theta_out "
                             "in the TE over the record", prior_scale=PRIOR_SCALES["output_encoder_scale_error"],
                             lower=-1e4, upper=1e4, type_key="output_encoder_scale_error"))
        out.append(Candidate("drift_arcsec_per_rev", "drift_arcsec_per_rev", "measurement", "arcsec/rev",
                             "a drift of the TE reading in time at a steady speed: it grows by the value per output "
                             "revolution travelled from the start of each run, in either direction",
                             prior_scale=PRIOR_SCALES["drift_arcsec_per_rev"], lower=-1e4, upper=1e4,
                             type_key="drift_arcsec_per_rev"))
    else:
        notes.append("no ramp, drift or encoder scale error is a candidate: no run's record shows a ramp (where "
                     "it meets itself one revolution on, its TE agrees within the noise)")
    return out, notes


def _empirical(max_order: int, loaded: bool, two_dirs: bool) -> list:
    kinds = ["common"] + (["load"] if loaded else []) + (["direction"] if two_dirs else [])
    items = []
    for k in range(1, max_order + 1):
        for kind in kinds:
            items.append((f"order {k} ({kind})", kind, k, ("cos", "sin")))
    if two_dirs:
        items.append(("constant (direction)", "direction", 0, ("value",)))
        if loaded:
            items.append(("constant (load x direction)", "load_direction", 0, ("value",)))
    share = 1.0 / max(len(items), 1)
    def meaning(kind: str, k: int) -> str:
        what = f"harmonic {k} of the output angle" if k else "a constant"
        how = {"common": "the same in every run", "load": "proportional to the load",
               "direction": "changing sign with the direction",
               "load_direction": "proportional to the load, changing sign with the direction"}[kind]
        return f"structure without a physical candidate: {what}, {how}"

    return [Candidate(name, kind, "empirical", "arcsec", meaning(kind, k), comps, 1.0, -1e6, 1e6, (("k", k),),
                      "empirical", share, None, k) for name, kind, k, comps in items]


def build_library(dataset, max_order: int, families: tuple[str, ...] = FAMILIES, ramps: bool = True) -> Library:
    """The candidate library of a dataset (its design gives the instances, pins and ratio).

    Parameters
    ----------
    dataset : MeasuredDataset
    max_order : int
        Highest harmonic order of the empirical block (the readings' resolved band).
    families : tuple of str
        Families to include.
    ramps : bool
        Whether the records show a ramp (:func:`ramp_shown`): the scale error and drift are candidates only then.
    """
    d = dataset.design
    out, notes = [], []
    declared = set(dataset.declared_keys)
    if "table4" in families:
        out += _table4(d, declared)
    if "form" in families:
        out += _form(d)
    if "model" in families:
        m, n = _model(dataset)
        out += m
        notes += n
    if "measurement" in families:
        m, n = _measurement(d, ramps)
        out += m
        notes += n
    if "empirical" in families:
        loaded = len({r.load_Nm for r in dataset.runs}) > 1
        two = len({r.direction for r in dataset.runs}) > 1
        out += _empirical(max_order, loaded, two)
    names = [c.name for c in out]
    assert len(names) == len(set(names)), "candidate names must be unique"
    return Library(out, notes + _folding_notes(dataset))


def _folding_notes(dataset) -> list[str]:
    """A note where the import's low-pass removed orders the model predicts (they fold back in the model's
    predictions at the readings, where the record holds nothing): :func:`rvrig.average.filtered_model_orders`."""
    path = getattr(dataset, "path", None)
    if path is None or dataset.design is None:
        return []
    orders, end = filtered_model_orders(path, dataset.design)
    if not orders:
        return []
    return [f"the import's low-pass kept the orders below {end:g}; the model's order(s) "
            f"{', '.join(f'{k:g}' for k in orders)} fold back onto lower orders in its predictions at these "
            f"readings, where the record holds nothing: import with --samples-per-rev of at least "
            f"{model_samples_per_rev(dataset.design)} to compare them"]
