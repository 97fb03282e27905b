"""The candidate effect library: what can explain a residual, each with a physical meaning,
parameters and a unit.

Three families:

* ``table4``: every error of paper Table 4 (``rvcad.errors.ERROR_TYPES``), undeclared or
  mis-declared (the parameter is added to whatever the run declares), with its instances: crank,
  disc and hole of the cam and hole errors, the pin of the pin-wise errors (a single pin's pitch,
  radial position and radius) as well as all pins at once, and the direction of the eccentricity
  and offset errors (two parameters: the components along 0 and 90 deg of its frame).
* ``model``: the physical effects that the paper's model lacks (``rvdyn.options.MODEL_OPTIONS``),
  passed to rvdyn through the case's ``model`` object: torsional compliance (load dependent),
  output friction torque (direction dependent), cam-bearing clearance (direction dependent lost
  motion), thermal growth of the pin circle (only where the runs differ in temperature; at one
  temperature it cannot be told from ``pin_circle_diameter``) and pin-circle ovality.
* ``measurement``: errors of the encoders, implemented here (not physics of the reducer): the
  output encoder's scale error (a ramp in the TE with the reading, ppm), a drift in time (a ramp
  with the angle travelled, arcsec per revolution), and the eccentricities. An
  encoder whose scale is mounted with eccentricity ``eps`` at radius ``R`` reads
  ``theta + (eps / R) sin(theta + phi)``. Assumed radii: output (carrier) encoder
  ``OUTPUT_ENCODER_RADIUS_MM`` = 100 mm, input (sun shaft) encoder ``INPUT_ENCODER_RADIUS_MM`` =
  25 mm. The reported eccentricity scales with the assumed radius (the data fix only eps / R).
  In the TE the output encoder gives order 1, the input encoder order N divided by N (N the
  reducer's ratio, from its design).

Instances, pin counts and orders come from the dataset's design (``MeasuredDataset.design``).

Each effect has a typical size ``scale`` (the finite-difference/secant step of the screening) and
bounds. Two-parameter effects are fitted as Cartesian components and reported as a magnitude and
an angle.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rvcad.errors import ERROR_TYPES
from rvdyn.options import MODEL_OPTIONS
from rvcad.params import Design

from rvcalib.dataset import MeasuredDataset

ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0
ARCSEC_PER_DEG = 3600.0

#: Assumed radius of the output encoder's scale, mm (a ring scale on the output flange).
OUTPUT_ENCODER_RADIUS_MM = 100.0
#: Assumed radius of the input encoder's scale, mm (a small shaft encoder).
INPUT_ENCODER_RADIUS_MM = 25.0

#: Plausibility bounds of the corrections fitted for Table 4 errors.
TABLE4_BOUND = {"um": 200.0, "deg": 1.0}

FAMILIES = ("table4", "model", "measurement")

#: The cam-bearing clearance is screened on a grid of one point per pin (Zp points per output
#: revolution, a subset of the screening grid). With a clearance the discs float (9 degrees of
#: freedom instead of 3) and rvdyn is 10 to 40 times slower. On that grid its order-2Zp ripple (and
#: any order Zp/2Zp content of the residual) aliases onto the mean, so the screening sees mainly its
#: lost motion; it is therefore solved only when the residual has an offset, validated only when it
#: ranks first, and re-validated on the full screening grid before it can win.
CLEARANCE_SCREEN_PER_PIN = True


@dataclass(frozen=True)
class Effect:
    """One candidate effect.

    Attributes
    ----------
    name : str
        Unique id, e.g. ``pin_pitch[pin=7]``, ``cam_eccentricity[crank=1,disc=0]``,
        ``torsional_compliance_arcsec_per_Nm``, ``output_encoder_eccentricity``.
    key : str
        Table 4 error key, model option key or measurement key.
    family : str
        ``table4``, ``model`` or ``measurement``.
    unit : str
        Unit of the parameter(s).
    meaning : str
        Physical meaning of a positive value.
    params : tuple of str
        ``("value",)`` or the components ``("x", "y")`` of a direction-dependent effect.
    scale : float
        Typical size (screening step), in ``unit``.
    lower, upper : tuple of float
        Bounds of each parameter.
    instance : tuple of (str, int)
        Instance selectors (crank, disc, hole, pin).
    screen : str
        How the screening signatures are made: ``two_sided`` (+scale and -scale),
        ``one_sided`` (+scale, parameter >= 0), ``vector4`` (scale along 0, 90, 180, 270 deg),
        ``angle_shift`` (scale at angle 0; other angles by rotating the signature), ``analytic``.
    template : str or None
        The effect whose screening signatures are this effect's: for pin instances the pin-0
        effect shifted by ``shift_deg`` of output angle (rotational symmetry of the pins), for
        crank/disc/hole instances their half-turn twin (see :func:`build_library`). Exact for a
        symmetric declared model, a screening approximation otherwise; the fits always solve the
        effect itself.
    screen_steps : int or None
        Points per output revolution of this effect's screening (a multiple of the pin count; default the
        coarse grid), for effects that are expensive to solve.
    expensive : bool
        rvdyn is much slower with this effect (validated only when it ranks first).
    trial_map : tuple of int or None
        For a twin instance: which of the template's trial signatures is this effect's trial j
        (planet eccentricity of crank 1 along a = crank 0's along a + 180 deg).
    shift_deg : float
        Output-angle shift of the template's signature, deg.
    angle_period_deg : float
        Period of the direction of an ``angle_shift`` effect (360; ovality 180).
    polar_factor : float
        Reported angle = atan2(y, x) / polar_factor (ovality: 2).
    ratio : float
        Total ratio N of the reducer (the input encoder's reading error enters the TE divided by N).
    """

    name: str
    key: str
    family: str
    unit: str
    meaning: str
    params: tuple[str, ...] = ("value",)
    scale: float = 1.0
    lower: tuple[float, ...] = (-math.inf,)
    upper: tuple[float, ...] = (math.inf,)
    instance: tuple[tuple[str, int], ...] = ()
    screen: str = "two_sided"
    template: str | None = None
    shift_deg: float = 0.0
    angle_period_deg: float = 360.0
    polar_factor: float = 1.0
    screen_steps: int | None = None
    expensive: bool = False
    trial_map: tuple[int, ...] | None = None
    ratio: float = 1.0

    @property
    def n_params(self) -> int:
        """Number of parameters (1 or 2)."""
        return len(self.params)

    @property
    def polar(self) -> bool:
        """True for two-component effects reported as magnitude and angle."""
        return self.n_params == 2

    @property
    def letter(self) -> str:
        """Paper Table 4 letter (empty for other families)."""
        return ERROR_TYPES[self.key].letter if self.family == "table4" else ""

    # ------------------------------------------------------------------ application
    def error_items(self, p: np.ndarray) -> list[tuple[str, dict]]:
        """Error instances to add to a case (``table4`` family)."""
        if self.family != "table4":
            return []
        inst = dict(self.instance)
        if self.n_params == 1:
            return [(self.key, {"value": float(p[0]), **inst})]
        return [(self.key, {"value": float(p[0]), "angle_deg": 0.0, **inst}),
                (self.key, {"value": float(p[1]), "angle_deg": 90.0, **inst})]

    def model_options(self, p: np.ndarray) -> dict[str, float]:
        """Model options to set in a case (``model`` family)."""
        if self.family != "model":
            return {}
        if self.key == "pin_circle_ovality_um":
            r, ang = self.magnitude_angle(p)
            return {"pin_circle_ovality_um": r, "pin_circle_ovality_angle_deg": ang}
        return {self.key: float(p[0])}

    def reading_arcsec(self, input_deg: np.ndarray, output_deg: np.ndarray, p: np.ndarray) -> np.ndarray | None:
        """TE reading error (arcsec) of a ``measurement`` effect at the readings."""
        if self.family != "measurement":
            return None
        return self.basis(input_deg, output_deg) @ np.asarray(p, dtype=float)

    def basis(self, input_deg: np.ndarray, output_deg: np.ndarray) -> np.ndarray:
        """Columns (n, 2) of a measurement effect's TE reading error per um of each component (one
        column per ppm for the scale error).

        Output encoder: ``TE += (eps / R_out) sin(theta_out + phi)`` with components
        ``(x, y) = eps (cos phi, sin phi)``; input encoder: ``TE -= (eps / R_in) sin(theta_in + phi) / N``.
        """
        if self.key == "drift_arcsec_per_rev":
            # a drift in time at a steady speed: c per output revolution travelled, whatever the direction
            o = np.asarray(output_deg, dtype=float)
            return (np.abs(o - o[0]) / 360.0)[:, None] if o.size else np.zeros((0, 1))
        if self.key == "output_encoder_scale_error":
            # reading theta_out (1 + s): TE += s * theta_out (the absolute reading), per ppm of s
            return (np.asarray(output_deg, dtype=float) * ARCSEC_PER_DEG * 1e-6)[:, None]
        if self.key == "output_encoder_eccentricity":
            th = np.radians(np.asarray(output_deg, dtype=float))
            k = 1e-3 / OUTPUT_ENCODER_RADIUS_MM * ARCSEC_PER_RAD
        elif self.key == "input_encoder_eccentricity":
            th = np.radians(np.asarray(input_deg, dtype=float))
            k = -1e-3 / INPUT_ENCODER_RADIUS_MM * ARCSEC_PER_RAD / self.ratio
        else:  # pragma: no cover
            raise ValueError(f"effect {self.name!r} has no reading basis")
        return k * np.column_stack([np.sin(th), np.cos(th)])

    # ------------------------------------------------------------------ reporting
    def magnitude_angle(self, p: np.ndarray) -> tuple[float, float]:
        """Magnitude (unit) and angle (deg) of a two-component effect."""
        x, y = float(p[0]), float(p[1])
        return math.hypot(x, y), math.degrees(math.atan2(y, x)) / self.polar_factor

    def value(self, p: np.ndarray) -> float:
        """The reported size: the value, or the magnitude of a two-component effect."""
        return self.magnitude_angle(p)[0] if self.polar else float(p[0])

    def describe(self) -> str:
        """One line: name, unit and meaning."""
        return f"{self.name} [{self.unit}]: {self.meaning}"


def _twin(inst: dict[str, int]) -> dict[str, int]:
    """The half-turn twin of an instance (crank, disc and hole indices i -> 1 - i)."""
    return {k: (1 - v if k in ("crank", "disc", "hole") else v) for k, v in inst.items()}


def _inst_name(key: str, inst: dict[str, int]) -> str:
    if not inst:
        return key
    return key + "[" + ",".join(f"{k}={v}" for k, v in inst.items()) + "]"


@dataclass
class Library:
    """The candidates for a dataset.

    Attributes
    ----------
    effects : list of Effect
    notes : list of str
        Candidates left out and why.
    """

    effects: list[Effect]
    notes: list[str] = field(default_factory=list)

    def __iter__(self):
        return iter(self.effects)

    def __len__(self) -> int:
        return len(self.effects)

    def by_name(self, name: str) -> Effect:
        """The effect called ``name`` (ValueError naming it if unknown)."""
        for e in self.effects:
            if e.name == name:
                return e
        raise ValueError(f"effect {name!r} is not in the candidate library")

    def templates(self) -> list[Effect]:
        """Effects whose signatures are solved (not derived by a shift)."""
        return [e for e in self.effects if e.template is None and e.screen != "analytic"]


def build_library(dataset: MeasuredDataset | None = None, design: Design | None = None,
                  families: tuple[str, ...] = FAMILIES) -> Library:
    """The candidate library for a dataset.

    Parameters
    ----------
    dataset : MeasuredDataset or None
        Decides which load/temperature-dependent effects are identifiable.
    design : Design or None
        Instance ranges, pin count and ratio (default: the dataset's design, else the paper's).
    families : tuple of str
        Families to include.

    Returns
    -------
    Library
    """
    d = design or (dataset.design if dataset is not None else Design())
    out: list[Effect] = []
    notes: list[str] = []
    # half-turn symmetry of the default layout (two cranks 180 deg apart, two discs with eccentrics 180
    # deg apart): an error of crank c / disc k / hole h gives the same TE as of crank 1-c / disc 1-k /
    # hole 1-h (checked against rvdyn to 1e-6 arcsec), so the twin's screening signature is reused
    sym = d.n_cranks == 2 and d.n_discs == 2 and tuple(d.crank_angles_deg) == (0.0, 180.0)
    declared = set(dataset.declared_keys) if dataset is not None else set()
    zp = d.z_pins
    if "table4" in families:
        for key, et in ERROR_TYPES.items():
            b = TABLE4_BOUND[et.unit]
            scale = 0.01 if et.unit == "deg" else (5.0 if key == "pin_radius" else 10.0)
            mis = " (a correction to the declared value)" if key in declared else ""
            meaning = f"Table 4 {et.letter}: {et.meaning}{mis}"
            ranges = {"crank": d.n_cranks, "disc": d.n_discs, "hole": d.n_cranks}
            if et.has_angle:
                insts = [dict()] if not et.instance_keys else [{"crank": c} for c in range(d.n_cranks)]
                for inst in insts:
                    if key == "pin_circle_offset":
                        out.append(Effect(_inst_name(key, inst), key, "table4", et.unit, meaning, ("x", "y"), scale,
                                          (-b, -b), (b, b), tuple(inst.items()), "angle_shift"))
                    else:
                        tw = _twin(inst) if sym else None
                        twin_name = _inst_name(key, tw) if tw is not None and tw != inst and \
                            tw.get("crank", 0) < inst.get("crank", 0) else None
                        # planet of crank 1 at angle a = planet of crank 0 at a + 180 deg
                        out.append(Effect(_inst_name(key, inst), key, "table4", et.unit, meaning, ("x", "y"), scale,
                                          (-b, -b), (b, b), tuple(inst.items()), "vector4", twin_name,
                                          trial_map=(2, 3, 0, 1) if twin_name else None))
                continue
            if et.pinwise:
                if key != "pin_pitch":  # all pins at once (the default instance of I and J)
                    out.append(Effect(key, key, "table4", et.unit, meaning + " (all pins)", ("value",), scale,
                                      (-b,), (b,), (), "two_sided"))
                tname = _inst_name(key, {"pin": 0})
                for p in range(zp):
                    out.append(Effect(_inst_name(key, {"pin": p}), key, "table4", et.unit,
                                      meaning + f" (pin {p} only)", ("value",), scale, (-b,), (b,),
                                      (("pin", p),), "two_sided", None if p == 0 else tname,
                                      360.0 * p / zp))
                continue
            insts = [dict()]
            for ik in et.instance_keys:
                insts = [dict(i, **{ik: v}) for i in insts for v in range(ranges[ik])]
            made: set[str] = set()
            for inst in insts:
                tw = _twin(inst) if sym else None
                tname = _inst_name(key, tw) if tw is not None else None
                out.append(Effect(_inst_name(key, inst), key, "table4", et.unit, meaning, ("value",), scale,
                                  (-b,), (b,), tuple(inst.items()), "two_sided",
                                  tname if tname in made else None))
                made.add(_inst_name(key, inst))
    if "model" in families:
        loaded = dataset is None or any(r.load_Nm > 0 for r in dataset.runs)
        mo = MODEL_OPTIONS
        if loaded:
            o = mo["torsional_compliance_arcsec_per_Nm"]
            out.append(Effect(o.key, o.key, "model", "arcsec/(N m)", o.meaning, ("value",), 0.5,
                              (0.0,), (o.high,), (), "one_sided"))
            o = mo["friction_torque_Nm"]
            out.append(Effect(o.key, o.key, "model", "N m", o.meaning, ("value",), 5.0, (0.0,), (o.high,), (),
                              "one_sided"))
        else:
            notes.append("torsional compliance and friction are not candidates: every run is at load 0 "
                         "(the rigid limit of the model has neither)")
        o = mo["cam_bearing_clearance_um"]
        out.append(Effect(o.key, o.key, "model", "um", o.meaning + " (bearing stiffness at its default "
                          f"{mo['cam_bearing_stiffness_N_per_um'].default:g} N/um)", ("value",), 5.0,
                          (0.0,), (o.high,), (), "one_sided", screen_steps=d.z_pins if CLEARANCE_SCREEN_PER_PIN else None,
                          expensive=True))
        if dataset is not None and dataset.temperatures_vary:
            o = mo["pin_circle_diameter_um_per_K"]
            out.append(Effect(o.key, o.key, "model", "um/K", o.meaning, ("value",), 0.5, (o.low,), (o.high,), (),
                              "two_sided"))
        else:
            notes.append("thermal growth of the pin circle (pin_circle_diameter_um_per_K) is not a candidate: the "
                         "runs share one temperature, where it cannot be told from pin_circle_diameter")
        o = mo["pin_circle_ovality_um"]
        out.append(Effect(o.key, o.key, "model", "um", o.meaning + "; reported with its major-axis angle",
                          ("x", "y"), 10.0, (-200.0, -200.0), (200.0, 200.0), (), "angle_shift",
                          angle_period_deg=180.0, polar_factor=2.0))
    if "measurement" in families:
        out.append(Effect("output_encoder_eccentricity", "output_encoder_eccentricity", "measurement", "um",
                          f"eccentricity of the output encoder scale (assumed radius {OUTPUT_ENCODER_RADIUS_MM:g} mm): "
                          "reading error (eps/R) sin(theta_out + phi), order 1 in the TE; reported with phi",
                          ("x", "y"), 5.0, (-1000.0, -1000.0), (1000.0, 1000.0), (), "analytic"))
        out.append(Effect("input_encoder_eccentricity", "input_encoder_eccentricity", "measurement", "um",
                          f"eccentricity of the input encoder scale (assumed radius {INPUT_ENCODER_RADIUS_MM:g} mm): "
                          f"reading error (eps/R) sin(theta_in + phi), order {d.ratio:g} in the TE divided by "
                          f"{d.ratio:g}; reported with phi", ("x", "y"), 20.0, (-1000.0, -1000.0), (1000.0, 1000.0), (),
                          "analytic", ratio=float(d.ratio)))
        out.append(Effect("output_encoder_scale_error", "output_encoder_scale_error", "measurement", "ppm",
                          "scale (gain) error s of the output encoder: it reads theta_out (1 + s), so the TE ramps by "
                          "s theta_out over the record (a sawtooth per revolution); an input encoder scale error of "
                          "the opposite sign, or a drift in time proportional to the angle travelled in one "
                          "direction, gives the same ramp", ("value",), 10.0, (-1e4,), (1e4,), (), "analytic"))
        out.append(Effect("drift_arcsec_per_rev", "drift_arcsec_per_rev", "measurement", "arcsec/rev",
                          "a drift of the TE reading in time (thermal, electronics) at a steady speed: it grows by the "
                          "value per output revolution travelled from the start of each run, in either direction "
                          "(a scale error changes sign with the direction)", ("value",), 5.0, (-1e4,), (1e4,), (),
                          "analytic"))
    return Library(out, notes)


def param_scales(effects: list[Effect]) -> np.ndarray:
    """Each parameter's scale (its effect's :attr:`Effect.scale`), effect by effect in order: the units of the
    scaled parameter vectors of the fits and Jacobians (empty for no effects)."""
    if not effects:
        return np.zeros(0)
    return np.concatenate([np.full(e.n_params, e.scale, dtype=float) for e in effects])


def trial_points(effect: Effect) -> list[np.ndarray]:
    """Parameter values at which the screening solves the model for an effect's signature."""
    s = effect.scale
    if effect.screen == "two_sided":
        return [np.array([s]), np.array([-s])]
    if effect.screen == "one_sided":
        return [np.array([s])]
    if effect.screen == "vector4":
        return [np.array([s, 0.0]), np.array([0.0, s]), np.array([-s, 0.0]), np.array([0.0, -s])]
    if effect.screen == "angle_shift":
        return [np.array([s, 0.0])]
    return []


def polar_to_xy(magnitude: float, angle_deg: float, polar_factor: float = 1.0) -> np.ndarray:
    """Components of a two-component effect from its magnitude and (reported) angle."""
    a = math.radians(angle_deg * polar_factor)
    return np.array([magnitude * math.cos(a), magnitude * math.sin(a)])
