"""Design parameters of the RV reducer (paper Table 1 plus the stated assumptions).

Units at the API: lengths in mm, angles in degrees. Every assumption that is not in the
paper is a named field here and is listed in the README.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields, replace
from functools import cached_property
from pathlib import Path
from typing import Any

from rvcad.memo import LRUMemo
from rvcad.profile import MAX_MODIFICATION
from rvcad.validation import DesignError, as_int, as_mapping, as_real, read_json_file, reject

#: Profile shift coefficients of the stage I gears (assumption; x1 = -x2 keeps the 30 mm centre
#: distance, and x1 = +0.4 keeps the planet tip off the 12-tooth sun's base circle).
SUN_SHIFT = 0.4
PLANET_SHIFT = -0.4


@dataclass(frozen=True)
class Design:
    """Nominal (error-free) design of the reducer.

    Attributes
    ----------
    z_sun : int
        Sun gear teeth Z1 (paper Table 1: 12).
    z_planet : int
        Planet (involute) gear teeth Z2 (Table 1: 36).
    z_pins : int
        Number of pins Zp (Table 1: 40).
    z_disc : int
        Cycloid disc lobes Zc (Table 1: 39); must equal ``z_pins - 1``.
    pin_circle_diameter_mm : float
        Diameter of the pin distribution circle, mm (Table 1: 128).
    eccentricity_mm : float
        Crank (cam) eccentricity e, mm (Table 1: 1.3).
    pin_radius_mm : float
        Pin radius, mm. Table 1 prints "radius of pin 6 mm"; 40 pins of radius 6 mm overlap on a
        128 mm circle, so the 6 mm is read as the diameter: default 3 mm (assumption).
    module_mm : float
        Stage I module, mm (assumption: 1.25, centre distance 30 mm).
    pressure_angle_deg : float
        Stage I pressure angle, degrees (assumption: 20).
    stage1_backlash_mm : float
        Circumferential backlash of the stage I mesh on the pitch circle, mm (assumption: 0;
        the planet teeth are thinned by this amount).
    crank_angles_deg : tuple of float
        Angular positions of the crankshafts in the carrier frame, degrees (assumption: 0, 180). Two or more
        (:data:`MAX_CRANKS` at most) as the planets, the crank holes and the pillars between them fit: RV reducers
        of the larger frames have three crankshafts, evenly spaced (:func:`even_crank_angles`).
    gear_width_mm, disc_width_mm, disc_gap_mm, plate_width_mm : float
        Axial widths, mm (assumptions of this implementation).
    cam_radius_mm : float
        Radius of each eccentric cam and of the matching disc hole (bearing omitted), mm.
    crank_journal_radius_mm : float
        Radius of the crankshaft journals in the carrier and flange plate, mm.
    disc_center_hole_radius_mm : float
        Radius of the central clearance hole of each cycloid disc, mm.
    housing_outer_radius_mm : float
        Outer radius of the pin housing, mm.
    cam_bearing_rollers, cam_bearing_roller_diameter_mm, cam_bearing_roller_length_mm : int, float, float
        Needle rollers of each cam bearing: count, diameter and effective length, mm (assumption:
        16 x 2.5 mm x 8 mm in the 9 mm cam hole).
    journal_bearing_rollers, journal_bearing_roller_diameter_mm, journal_bearing_roller_length_mm : int, float, float
        Rollers of each crank journal bearing (two per crank): count, diameter, effective length, mm
        (assumption: 12 x 3 mm x 6 mm around the 7 mm journal).
    journal_bearing_contact_angle_deg : float
        Contact angle of the crank journal bearings, degrees: tapered roller bearings as in the RV-E series
        (default 13.13 deg, ISO 281 e = 1.5 tan(alpha) = 0.35 of a small 302-series bearing); 0 = cylindrical.
    journal_bearing_arrangement : str
        ``"face_to_face"`` (X, the default) or ``"back_to_back"`` (O): how the tapered journal bearings of a
        crank face each other, which moves their effective load centres inwards or outwards by
        ``(crank_journal_radius_mm + journal_bearing_roller_diameter_mm) tan(contact angle)`` (rvdyn.bearings).
    carrier_pillars, carrier_pillar_radius_mm : int, float
        Pillars joining the output flange and the carrier end plate (round bars on the crank circle, midway
        between the cranks), mm; their bending and shear twist the carrier (rvdyn.bearings.carrier_torsional_stiffness).
        Not given (None): one pillar between each pair of neighbouring cranks, ``n_cranks`` pillars.
    pin_seat_clearance_mm : float
        Radial clearance of a pin in its housing groove (groove radius = pin radius + this), mm; the conformal
        line contact of the seat is in series with the pin-disc contact (rvdyn.bearings.pin_seat_contact).
    housing_support : str
        How the pin housing is held against ovalising under the pin forces (rvdyn.housing): ``"main_bearings"``
        (default: held round at the main bearings on the plates' rims, the wall between the pin band and the
        bearings a foundation of the band) or ``"free"`` (a free ring: an upper bound).
    profile_equidistant_mm, profile_shift_mm, profile_rotation_deg : float
        Profile modification of both discs: the disc is cut by a wheel of radius ``pin_radius_mm +
        equidistant`` whose centre runs on the circle ``pin_circle_radius + shift``, and the profile is
        turned by ``rotation`` (+z) relative to the crank holes. Positive equidistant and negative shift
        remove material (backlash); 0 by default.
    """

    z_sun: int = 12
    z_planet: int = 36
    z_pins: int = 40
    z_disc: int = 39
    pin_circle_diameter_mm: float = 128.0
    eccentricity_mm: float = 1.3
    pin_radius_mm: float = 3.0
    module_mm: float = 1.25
    pressure_angle_deg: float = 20.0
    stage1_backlash_mm: float = 0.0
    crank_angles_deg: tuple[float, ...] = (0.0, 180.0)
    gear_width_mm: float = 10.0
    disc_width_mm: float = 10.0
    disc_gap_mm: float = 0.5
    plate_width_mm: float = 10.0
    cam_radius_mm: float = 9.0
    crank_journal_radius_mm: float = 7.0
    disc_center_hole_radius_mm: float = 14.0
    housing_outer_radius_mm: float = 80.0
    # ---- bearings and supports of the physical contact law (rvdyn) ---------------------------------
    # Assumptions of this implementation (not in the paper; docs/conventions.md "Assumptions"): the cam bearings
    # are needle bearings between cam and disc hole, the crank journal bearings roller bearings (one in the
    # flange plate, one in the carrier; tapered, below), all rolling elements steel (GCr15).
    cam_bearing_rollers: int = 16
    cam_bearing_roller_diameter_mm: float = 2.5
    cam_bearing_roller_length_mm: float = 8.0
    journal_bearing_rollers: int = 12
    journal_bearing_roller_diameter_mm: float = 3.0
    journal_bearing_roller_length_mm: float = 6.0
    # The crank journal bearings of an RV-E reducer are tapered roller bearings: contact angle alpha (0: a
    # cylindrical roller bearing). 13.13 deg: ISO 281's e = 1.5 tan(alpha) with e = 0.35 of the small 302-series
    # tapered roller bearings (e.g. 30203, 17 mm bore; catalogue Y = 1.7 = 0.4 cot(alpha) agrees).
    journal_bearing_contact_angle_deg: float = 13.13
    # How the two tapered bearings of a crank face each other (JOURNAL_ARRANGEMENTS): the effective load centre
    # of a tapered roller bearing lies where the load line of the outer ring crosses the axis, offset from the
    # roller's mid-plane by (journal radius + roller diameter) tan(alpha) towards the cup's wide end; face to
    # face (X) the load centres move inwards (shorter effective span), back to back (O) outwards. Assumption:
    # face to face, the cups pushed inwards by the plates' outer shoulders (the plates clamped onto the
    # pillars set the preload); the arrangement of the RV-E's crank bearings is not published.
    journal_bearing_arrangement: str = "face_to_face"
    # Carrier: the output flange and the carrier end plate joined by pillars through the discs, on the crank
    # circle midway between the cranks (not in the paper; docs/conventions.md "Assumptions"). The pillar holes of
    # the discs are taken as large as the crank holes (cam_radius_mm), so a pillar is a round bar of radius
    # cam_radius - e - 0.7 mm = 7 mm. Pin seats: each pin lies in a semicircular groove of the housing whose
    # radius is the pin radius plus pin_seat_clearance_mm (a running fit: the pins turn in their grooves).
    # Not given: one pillar between each pair of neighbouring cranks (n_cranks pillars; 2 for the default design).
    carrier_pillars: int | None = None
    carrier_pillar_radius_mm: float = 7.0
    pin_seat_clearance_mm: float = 0.01
    # The housing ring under the pin forces (rvdyn.housing, docs/physics.md section 9): held round at the main
    # bearings, which ride on the plates' rims (the assumption of rvdyn.bearings.journal_seat_compliance too).
    housing_support: str = "main_bearings"
    # Profile modification of the cycloid discs (rvcad.profile.modified_profile_parameters): the
    # grinding wheel's radius rp + equidistant, its centre circle Rp + shift, the profile turned by
    # rotation. Zero by default (the paper's unmodified, zero-backlash profile).
    profile_equidistant_mm: float = 0.0
    profile_shift_mm: float = 0.0
    profile_rotation_deg: float = 0.0
    # ---- end of the bearing block ---------------------------------------------------------------------

    def __post_init__(self) -> None:
        # the pillars follow the cranks unless given: one between each pair of neighbouring cranks
        if self.carrier_pillars is None and isinstance(self.crank_angles_deg, (tuple, list)):
            object.__setattr__(self, "carrier_pillars", len(self.crank_angles_deg))

    # ------------------------------------------------------------------ derived values
    @property
    def ratio(self) -> float:
        """Total ratio ``1 + Z2*Zp / (Z1*(Zp - Zc))`` (paper Eq. A.5; 121 by default)."""
        return 1.0 + self.z_planet * self.z_pins / (self.z_sun * (self.z_pins - self.z_disc))

    @property
    def pin_circle_radius_mm(self) -> float:
        """Radius Rp of the pin distribution circle, mm."""
        return self.pin_circle_diameter_mm / 2.0

    @property
    def center_distance_mm(self) -> float:
        """Stage I centre distance ``m (Z1 + Z2) / 2``, mm; also the crank radius in the carrier."""
        return self.module_mm * (self.z_sun + self.z_planet) / 2.0

    @property
    def sun_pitch_radius_mm(self) -> float:
        """Sun pitch radius ``m Z1 / 2``, mm."""
        return self.module_mm * self.z_sun / 2.0

    @property
    def planet_pitch_radius_mm(self) -> float:
        """Planet pitch radius ``m Z2 / 2``, mm."""
        return self.module_mm * self.z_planet / 2.0

    @property
    def crank_angles_rad(self) -> tuple[float, ...]:
        """Crank positions in the carrier frame, rad."""
        return tuple(math.radians(a) for a in self.crank_angles_deg)

    @property
    def n_cranks(self) -> int:
        """Number of crankshafts (2 by default; 3 on the larger RV frames)."""
        return len(self.crank_angles_deg)

    @property
    def n_discs(self) -> int:
        """Number of cycloid discs (2, eccentrics 180 deg apart)."""
        return 2

    @cached_property
    def _plain(self) -> dict[str, Any]:
        """:func:`dataclasses.asdict` of this (frozen) design, made once: :meth:`to_dict`'s costly part, which the
        calibration loop asks for thousands of times per run (cache keys, worker payloads)."""
        return asdict(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain-dict form (JSON-ready; a new dict on every call)."""
        d = dict(self._plain)
        d["crank_angles_deg"] = list(self.crank_angles_deg)
        return d

    def replace(self, **changes: Any) -> "Design":
        """Copy with fields changed, validated. A design whose pillars follow its cranks (one pillar between each
        pair of neighbouring cranks) keeps following them when only ``crank_angles_deg`` is changed."""
        if ("crank_angles_deg" in changes and "carrier_pillars" not in changes
                and self.carrier_pillars == self.n_cranks):
            changes["carrier_pillars"] = None
        d = replace(self, **changes)
        d.validate()
        return d

    def validate(self) -> "Design":
        """Raise :class:`~rvcad.validation.DesignError` naming the field if the design cannot be built.

        Checks, in this order: the type of every field (integers, finite numbers, 2 to
        :data:`MAX_CRANKS` crank angles), the physical range of every field (:data:`FIELD_RANGES`), then the
        relations between fields: Zc = Zp - 1, pins that do not overlap, the shortening coefficient
        e Zp / Rp < 1, neighbouring planets apart on the crank circle (radius = the stage I centre distance),
        the cam, journal, centre-hole and housing radii, and the pillar holes of the discs between neighbouring
        crank holes.
        What the solids need beyond these relations (tip lands and root gaps of the teeth, crank
        holes apart and inside the disc root and plate rim, pins against the discs with the errors
        applied) is :func:`rvcad.check.check_case`, run before anything is exported. Undercut (pin radius above the smallest
        convex radius of curvature of the pin-centre curve, :attr:`min_convex_radius_mm`) is
        allowed: the CAD trims the loops and the design check reports it (conventions).

        Returns
        -------
        Design
            ``self``, for chaining.
        """
        self._check_types()
        self._check_ranges()
        self._check_relations()
        return self

    def _check_types(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            default = f.default
            where = f"design.{f.name}"
            if f.name == "crank_angles_deg":
                if not isinstance(v, (tuple, list)):
                    reject(where, v, CRANK_LIST, f"is of type {type(v).__name__}", DesignError)
                for i, x in enumerate(v):
                    as_real(x, f"{where}[{i}]", unit="deg", cls=DesignError)
            elif isinstance(default, bool):
                if not isinstance(v, bool):
                    reject(where, v, "true or false", f"is of type {type(v).__name__}", DesignError)
            elif isinstance(default, int) or f.name == "carrier_pillars":
                as_int(v, where, cls=DesignError)
            elif isinstance(default, float):
                as_real(v, where, cls=DesignError)
            elif f.name == "journal_bearing_arrangement":
                if not (isinstance(v, str) and v in JOURNAL_ARRANGEMENTS):
                    reject(where, v, f"one of {list(JOURNAL_ARRANGEMENTS)}",
                           "is not a tapered-bearing arrangement", DesignError)
            elif f.name == "housing_support":
                if not (isinstance(v, str) and v in HOUSING_SUPPORTS):
                    reject(where, v, f"one of {list(HOUSING_SUPPORTS)}", "is not a support of the housing ring",
                           DesignError)

    def _check_ranges(self) -> None:
        for name, (lo, hi, lo_open, why) in FIELD_RANGES.items():
            v = getattr(self, name)
            if type(self.__dataclass_fields__[name].default) is int or name == "carrier_pillars":
                as_int(v, f"design.{name}", lo=int(lo), hi=int(hi), cls=DesignError, why=why)
            elif name == "crank_angles_deg":
                if not 2 <= len(v) <= MAX_CRANKS:
                    reject(f"design.{name}", list(v), f"2 to {MAX_CRANKS} crank angles (crankshafts), e.g. "
                           f"{list(even_crank_angles(3))} for three", f"lists {len(v)}", DesignError)
                for i, x in enumerate(v):
                    as_real(x, f"design.{name}[{i}]", lo=lo, hi=hi, unit="deg", cls=DesignError, why=why)
            else:
                unit = "deg" if name.endswith("_deg") else "mm"
                as_real(v, f"design.{name}", lo=lo, hi=hi, lo_open=lo_open, unit=unit, cls=DesignError, why=why)

    def _check_relations(self) -> None:
        def bad(name: str, value: Any, allowed: str, problem: str) -> None:
            reject(f"design.{name}", value, allowed, problem, DesignError)

        if self.z_disc != self.z_pins - 1:
            bad("z_disc", self.z_disc, f"z_pins - 1 = {self.z_pins - 1}",
                "does not match the pins (the cycloid drive has one lobe fewer than pins)")
        rp = self.pin_circle_radius_mm
        half_pitch = rp * math.sin(math.pi / self.z_pins)
        if self.pin_radius_mm >= half_pitch:
            bad("pin_radius_mm", self.pin_radius_mm, f"< half the pin chord pitch, {half_pitch:.4f} mm",
                f"mm makes the {self.z_pins} pins overlap on the {self.pin_circle_diameter_mm:g} mm circle")
        k1 = self.eccentricity_mm * self.z_pins / rp
        if not k1 < 1.0:
            bad("eccentricity_mm", self.eccentricity_mm, f"< Rp / Zp = {rp / self.z_pins:.4f} mm",
                f"mm gives a shortening coefficient e*Zp/Rp = {k1:.4f} >= 1 (a looped, unusable profile)")
        # the planets on the crank circle: its radius is the stage I centre distance a, so two neighbouring planets
        # (tip radius m (Z2/2 + 1 + x2)) at crank angles beta_i, beta_j stand 2 a sin(|beta_j - beta_i| / 2) apart
        # and must not overlap (the crank holes in the discs and plates are rvcad.check's)
        a = self.center_distance_mm
        need = 2.0 * (self.planet_pitch_radius_mm + self.module_mm * (1.0 + PLANET_SHIFT))
        i, j, gap = closest_cranks(self.crank_angles_deg)
        chord = 2.0 * a * abs(math.sin(math.radians(gap) / 2.0))
        if chord <= need:
            min_deg = 2.0 * math.degrees(math.asin(min(1.0, need / (2.0 * a))))
            given = [int(c) if float(c).is_integer() else c for c in self.crank_angles_deg]
            which = "the two planets" if self.n_cranks == 2 else f"planets {i} and {j}"
            most = (f"and at most {360 - min_deg:.2f} deg" if self.n_cranks == 2
                    else f"at most {int(360.0 // min_deg) if min_deg > 0 else MAX_CRANKS} cranks")
            bad("crank_angles_deg", given, f"cranks at least {min_deg:.2f} deg apart ({most})",
                f"puts {which} {chord:.3f} mm apart on the {a:g} mm crank circle (the stage I centre "
                f"distance): their tip circles ({need:.3f} mm across) overlap")
        if self.cam_radius_mm + self.eccentricity_mm >= a:
            bad("cam_radius_mm", self.cam_radius_mm, f"< crank radius - eccentricity = {a - self.eccentricity_mm:g} mm",
                "mm plus the eccentricity reaches the disc centre")
        if self.crank_journal_radius_mm >= self.cam_radius_mm - self.eccentricity_mm:
            bad("crank_journal_radius_mm", self.crank_journal_radius_mm,
                f"< cam_radius_mm - eccentricity_mm = {self.cam_radius_mm - self.eccentricity_mm:g} mm",
                "mm does not pass through the cam (the crank cannot be assembled)")
        # the input shaft through the discs, taken as large as the unshifted sun tip circle m (Z1 + 2) / 2
        sun_tip = self.sun_pitch_radius_mm + self.module_mm
        if self.disc_center_hole_radius_mm <= sun_tip + self.eccentricity_mm:
            bad("disc_center_hole_radius_mm", self.disc_center_hole_radius_mm,
                f"> sun tip radius + eccentricity = {sun_tip + self.eccentricity_mm:g} mm", "mm touches the sun")
        if self.disc_center_hole_radius_mm >= a - self.cam_radius_mm - self.eccentricity_mm:
            bad("disc_center_hole_radius_mm", self.disc_center_hole_radius_mm,
                f"< crank radius - cam radius - eccentricity = {a - self.cam_radius_mm - self.eccentricity_mm:g} mm",
                "mm leaves no web to the crank holes")
        # the pillars pass through holes of the discs as large as the pillar plus the eccentricity (the disc
        # orbits by e): the hole must leave a web to the centre hole and stay inside the disc root
        ph = self.carrier_pillar_radius_mm + self.eccentricity_mm
        if a - ph <= self.disc_center_hole_radius_mm:
            bad("carrier_pillar_radius_mm", self.carrier_pillar_radius_mm,
                f"< crank radius - eccentricity - centre hole radius = "
                f"{a - self.eccentricity_mm - self.disc_center_hole_radius_mm:g} mm",
                "mm: the pillar holes of the discs (pillar radius + eccentricity) cut into the centre hole")
        if a + ph >= rp - self.pin_radius_mm - self.eccentricity_mm:
            bad("carrier_pillar_radius_mm", self.carrier_pillar_radius_mm,
                f"< Rp - pin radius - 2 e - crank radius = "
                f"{rp - self.pin_radius_mm - 2 * self.eccentricity_mm - a:g} mm",
                "mm: the pillar holes of the discs reach the disc root")
        # a pillar midway between two neighbouring cranks (angular gap g) stands 2 a sin(g / 4) from each crank:
        # its hole in the discs (pillar radius + e) must clear both crank holes (cam radius)
        _, _, gap = closest_cranks(self.crank_angles_deg)
        apart = 2.0 * a * math.sin(math.radians(gap) / 4.0)
        if apart <= self.cam_radius_mm + ph:
            bad("carrier_pillar_radius_mm", self.carrier_pillar_radius_mm,
                f"< {apart - self.cam_radius_mm - self.eccentricity_mm:.4f} mm (a pillar midway between the "
                f"closest cranks, {gap:g} deg apart, stands {apart:.4f} mm from each)",
                f"mm: the pillar holes of the discs (pillar radius + eccentricity) cut into the crank holes "
                f"(cam radius {self.cam_radius_mm:g} mm)")
        if self.housing_outer_radius_mm <= rp + self.pin_radius_mm:
            bad("housing_outer_radius_mm", self.housing_outer_radius_mm,
                f"> Rp + pin radius = {rp + self.pin_radius_mm:g} mm", "mm does not hold the pins")

    @property
    def min_convex_radius_mm(self) -> float:
        """Smallest convex radius of curvature of the pin-centre curve, mm (about 4.6 mm by default).

        A pin radius above it undercuts the disc (the CAD trims the loops; the design check says so).
        Evaluated on 4001 points of the rising half of lobe 0 of ``q(t) = Rp u(t) - e u(Zp t)``.
        """
        rp, e, zp = self.pin_circle_radius_mm, self.eccentricity_mm, self.z_pins
        best = 0.0
        n = 4001
        for i in range(n):
            t = math.pi / (zp - 1) * i / (n - 1)
            dx = -rp * math.sin(t) + e * zp * math.sin(zp * t)
            dy = rp * math.cos(t) - e * zp * math.cos(zp * t)
            ddx = -rp * math.cos(t) + e * zp * zp * math.cos(zp * t)
            ddy = -rp * math.sin(t) + e * zp * zp * math.sin(zp * t)
            k = (dx * ddy - dy * ddx) / math.hypot(dx, dy) ** 3
            best = max(best, k)
        return 1.0 / best if best > 0 else math.inf

    @classmethod
    def from_dict(cls, d: Any) -> "Design":
        """Build and validate from a dict (the ``design`` object of a case JSON).

        ``None`` gives the default design. Unknown keys, wrong types (a crank angle list that is
        not a list of 2 to :data:`MAX_CRANKS` numbers, a tooth count that is not an integer) and values out of range raise
        :class:`~rvcad.validation.DesignError` naming the field.
        """
        if d is None:
            return cls().validate()
        memo_key = _memo_key(d)
        got = design_memo.get(memo_key) if memo_key is not None else None
        if got is not None and type(got) is cls:
            return got
        names = [f.name for f in fields(cls)]
        d = as_mapping(d, "design", f"an object with keys from {names}", DesignError)
        for k in d:
            if k not in names:
                reject("design key", k, f"{sorted(names)}", "is unknown", DesignError)
        kw: dict[str, Any] = {}
        for f in fields(cls):
            if f.name not in d:
                continue
            v = d[f.name]
            where = f"design.{f.name}"
            if f.name == "crank_angles_deg":
                if not isinstance(v, (list, tuple)):
                    reject(where, v, CRANK_LIST, f"is of type {type(v).__name__}, not a list", DesignError)
                kw[f.name] = tuple(as_real(x, f"{where}[{i}]", unit="deg", cls=DesignError) for i, x in enumerate(v))
            elif isinstance(f.default, bool):
                kw[f.name] = v
            elif isinstance(f.default, int) or f.name == "carrier_pillars":
                kw[f.name] = as_int(v, where, cls=DesignError)
            elif isinstance(f.default, float):
                kw[f.name] = as_real(v, where, cls=DesignError)
            else:
                kw[f.name] = v
        design = cls(**kw).validate()
        if memo_key is not None:
            design_memo.put(memo_key, design)
        return design


#: validated designs by the JSON text of the object they were read from (:meth:`Design.from_dict`; a design is
#: frozen, so one instance serves every case that gives the same object), at most this many kept
DESIGN_MEMO_SIZE = 64
design_memo = LRUMemo(DESIGN_MEMO_SIZE)


def _memo_key(d: Any) -> str | None:
    """The memo key of a design object: its JSON text with sorted keys, or None (not a dict of JSON values:
    validated every time, and refused where it is wrong)."""
    if type(d) is not dict:
        return None
    try:
        return json.dumps(d, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError):
        return None


#: Most crankshafts a design may list (the planets, crank holes and pillars must fit between them as well).
MAX_CRANKS = 12
#: What ``design.crank_angles_deg`` allows, in messages.
CRANK_LIST = f"a list of 2 to {MAX_CRANKS} angles in degrees (one per crankshaft)"


def even_crank_angles(n: int) -> tuple[float, ...]:
    """``n`` crank angles evenly spaced from 0, degrees: ``(0, 120, 240)`` for three cranks."""
    return tuple(360.0 * j / n for j in range(n))


def closest_cranks(angles_deg: tuple[float, ...] | list[float]) -> tuple[int, int, float]:
    """The two neighbouring cranks closest together on the carrier and their angular distance, degrees in
    [0, 180]: ``(i, j, gap)`` with i < j the indices in ``angles_deg`` (of the 2 or more given)."""
    best = (0, 1, 360.0)
    n = len(angles_deg)
    for i in range(n):
        for j in range(i + 1, n):
            g = abs(math.remainder(float(angles_deg[j]) - float(angles_deg[i]), 360.0))
            if g < best[2]:
                best = (i, j, g)
    return best


#: Arrangements of the two tapered journal bearings of a crank (``Design.journal_bearing_arrangement``).
JOURNAL_ARRANGEMENTS = ("face_to_face", "back_to_back")
#: Supports of the pin housing against ovalising (``Design.housing_support``; rvdyn.housing).
HOUSING_SUPPORTS = ("main_bearings", "free")

#: Physical range of every Design field: (low, high, low bound open?, reason). Relations between
#: fields are checked in :meth:`Design.validate` after these.
FIELD_RANGES: dict[str, tuple[float, float, bool, str]] = {
    "z_sun": (6, 300, False, "an involute pinion below 6 teeth has no tip land"),
    "z_planet": (6, 300, False, "stage I gears of 6 to 300 teeth"),
    "z_pins": (6, 200, False, "cycloid drives of 6 to 200 pins"),
    "z_disc": (5, 199, False, "z_pins - 1"),
    "pin_circle_diameter_mm": (0.0, 2000.0, True, "a reducer below 2 m"),
    "eccentricity_mm": (0.0, 100.0, True, "below Rp / Zp as well"),
    "pin_radius_mm": (0.0, 100.0, True, "below half the pin pitch as well"),
    "module_mm": (0.05, 50.0, False, "the ISO 54 module range"),
    "pressure_angle_deg": (10.0, 30.0, False, "standard pressure angles 14.5 to 25 deg with margin"),
    "stage1_backlash_mm": (0.0, 50.0, False, "below the planet's tip thickness as well"),
    "crank_angles_deg": (-360.0, 360.0, False, "one turn either way"),
    "gear_width_mm": (0.0, 1000.0, True, "axial widths below 1 m"),
    "disc_width_mm": (0.0, 1000.0, True, "axial widths below 1 m"),
    "disc_gap_mm": (0.0, 1000.0, False, "axial widths below 1 m"),
    "plate_width_mm": (0.0, 1000.0, True, "axial widths below 1 m"),
    "cam_radius_mm": (0.0, 1000.0, True, "inside the disc as well"),
    "crank_journal_radius_mm": (0.0, 1000.0, True, "inside the cam as well"),
    "disc_center_hole_radius_mm": (0.0, 1000.0, True, "between the sun and the crank holes as well"),
    "housing_outer_radius_mm": (0.0, 2000.0, True, "a reducer below 2 m"),
    "cam_bearing_rollers": (3, 200, False, "rolling elements of one bearing"),
    "cam_bearing_roller_diameter_mm": (0.0, 100.0, True, "needle rollers below 100 mm"),
    "cam_bearing_roller_length_mm": (0.0, 1000.0, True, "axial widths below 1 m"),
    "journal_bearing_rollers": (3, 200, False, "rolling elements of one bearing"),
    "journal_bearing_roller_diameter_mm": (0.0, 100.0, True, "rollers below 100 mm"),
    "journal_bearing_roller_length_mm": (0.0, 1000.0, True, "axial widths below 1 m"),
    "journal_bearing_contact_angle_deg": (0.0, 44.9, False, "cylindrical (0) to steep tapered roller bearings"),
    "carrier_pillars": (1, 12, False, "pillars joining the output flange and the carrier end plate"),
    "carrier_pillar_radius_mm": (0.0, 1000.0, True, "inside the disc between its centre hole and root as well"),
    "pin_seat_clearance_mm": (1e-4, 1.0, False, "a groove at least 0.1 um wider than the pin (the conformal "
                              "Hertz seat law needs a finite relative radius) and at most 1 mm"),
    **{k: (-lim, lim, False, "rvcad.profile.MAX_MODIFICATION") for k, lim in MAX_MODIFICATION.items()},
}


def load_design(path: str | Path) -> Design:
    """Read a design JSON file (the ``design`` object of a case: ``Design`` fields).

    Raises
    ------
    DesignError
        Naming the file or the field (a repeated key, a bad value, an unknown key).
    """
    d = read_json_file(path, "design file", DesignError)
    if not isinstance(d, dict):
        reject(f"design file {str(path)!r}", d, "a JSON object of Design fields", "is not an object", DesignError)
    return Design.from_dict(d)
