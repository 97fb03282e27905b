"""Design parameters of the RV reducer (paper Table 1 plus the stated assumptions).

Units at the API: lengths in mm, angles in degrees. Every assumption that is not in the
paper is a named field here and is listed in the README.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any


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
        Angular positions of the crankshafts in the carrier frame, degrees (assumption: 0, 180).
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
    crank_angles_deg: tuple[float, float] = (0.0, 180.0)
    gear_width_mm: float = 10.0
    disc_width_mm: float = 10.0
    disc_gap_mm: float = 0.5
    plate_width_mm: float = 10.0
    cam_radius_mm: float = 9.0
    crank_journal_radius_mm: float = 7.0
    disc_center_hole_radius_mm: float = 14.0
    housing_outer_radius_mm: float = 80.0
    # ---- bearings and supports of the physical contact law (rvdyn, issue 11) -------------------------
    # Assumptions of this implementation (not in the paper; README "Assumptions"): the cam bearings are
    # needle bearings between cam and disc hole, the crank journal bearings are modelled as cylindrical
    # roller bearings (one in the flange plate, one in the carrier), all rolling elements steel (GCr15).
    cam_bearing_rollers: int = 16
    cam_bearing_roller_diameter_mm: float = 2.5
    cam_bearing_roller_length_mm: float = 8.0
    journal_bearing_rollers: int = 12
    journal_bearing_roller_diameter_mm: float = 3.0
    journal_bearing_roller_length_mm: float = 6.0
    # Profile modification of the cycloid discs (rvcad.profile.modified_profile_parameters): the
    # grinding wheel's radius rp + equidistant, its centre circle Rp + shift, the profile turned by
    # rotation. Zero by default (the paper's unmodified, zero-backlash profile).
    profile_equidistant_mm: float = 0.0
    profile_shift_mm: float = 0.0
    profile_rotation_deg: float = 0.0
    # ---- end of the bearing block ---------------------------------------------------------------------

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
        """Number of crankshafts (2)."""
        return len(self.crank_angles_deg)

    @property
    def n_discs(self) -> int:
        """Number of cycloid discs (2, eccentrics 180 deg apart)."""
        return 2

    def to_dict(self) -> dict[str, Any]:
        """Plain-dict form (JSON-ready)."""
        d = asdict(self)
        d["crank_angles_deg"] = list(self.crank_angles_deg)
        return d

    def replace(self, **changes: Any) -> "Design":
        """Copy with fields changed, validated."""
        d = replace(self, **changes)
        d.validate()
        return d

    def validate(self) -> "Design":
        """Raise ``ValueError`` naming the field if the design cannot be built.

        Returns
        -------
        Design
            ``self``, for chaining.
        """
        for name in ("z_sun", "z_planet", "z_pins", "z_disc"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 3:
                raise ValueError(f"design.{name} {v!r} must be an integer >= 3")
        if self.z_disc != self.z_pins - 1:
            raise ValueError(
                f"design.z_disc {self.z_disc} must equal z_pins - 1 = {self.z_pins - 1} "
                "(single-tooth-difference cycloid drive)")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name.endswith("_mm") or f.name.endswith("_deg"):
                vals = v if isinstance(v, tuple) else (v,)
                for x in vals:
                    if not isinstance(x, (int, float)) or isinstance(x, bool) or not math.isfinite(x):
                        raise ValueError(f"design.{f.name} {x!r} must be a finite number")
        positive = ("pin_circle_diameter_mm", "eccentricity_mm", "pin_radius_mm", "module_mm",
                    "gear_width_mm", "disc_width_mm", "plate_width_mm", "cam_radius_mm",
                    "crank_journal_radius_mm", "disc_center_hole_radius_mm", "housing_outer_radius_mm")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"design.{name} {getattr(self, name)} must be > 0")
        if not 10.0 <= self.pressure_angle_deg <= 30.0:
            raise ValueError(f"design.pressure_angle_deg {self.pressure_angle_deg} must be in [10, 30]")
        if self.stage1_backlash_mm < 0:
            raise ValueError(f"design.stage1_backlash_mm {self.stage1_backlash_mm} must be >= 0")
        if self.disc_gap_mm < 0:
            raise ValueError(f"design.disc_gap_mm {self.disc_gap_mm} must be >= 0")
        rp = self.pin_circle_radius_mm
        half_pitch = rp * math.sin(math.pi / self.z_pins)
        if self.pin_radius_mm >= half_pitch:
            raise ValueError(
                f"design.pin_radius_mm {self.pin_radius_mm} mm must be below half the pin chord pitch "
                f"{half_pitch:.4f} mm: {self.z_pins} pins of that radius overlap on the "
                f"{self.pin_circle_diameter_mm} mm circle")
        k1 = self.eccentricity_mm * self.z_pins / rp
        if not 0.0 < k1 < 1.0:
            raise ValueError(
                f"design.eccentricity_mm {self.eccentricity_mm} gives a shortening coefficient e*Zp/Rp = "
                f"{k1:.4f}; it must be in (0, 1), i.e. eccentricity below {rp / self.z_pins:.4f} mm")
        if len(self.crank_angles_deg) != 2:
            raise ValueError(f"design.crank_angles_deg {self.crank_angles_deg} must list exactly 2 cranks")
        a = self.center_distance_mm
        if self.cam_radius_mm + self.eccentricity_mm >= a:
            raise ValueError(
                f"design.cam_radius_mm {self.cam_radius_mm} mm plus eccentricity must stay below the crank "
                f"radius {a} mm")
        if self.crank_journal_radius_mm >= self.cam_radius_mm - self.eccentricity_mm:
            raise ValueError(
                f"design.crank_journal_radius_mm {self.crank_journal_radius_mm} mm must be below "
                f"cam_radius_mm - eccentricity_mm = {self.cam_radius_mm - self.eccentricity_mm} mm "
                "so the crank can be assembled through the cam")
        sun_tip = self.sun_pitch_radius_mm + self.module_mm
        if self.disc_center_hole_radius_mm <= sun_tip + self.eccentricity_mm:
            raise ValueError(
                f"design.disc_center_hole_radius_mm {self.disc_center_hole_radius_mm} mm must exceed the sun "
                f"tip radius plus eccentricity ({sun_tip + self.eccentricity_mm} mm)")
        if self.disc_center_hole_radius_mm >= a - self.cam_radius_mm - self.eccentricity_mm:
            raise ValueError(
                f"design.disc_center_hole_radius_mm {self.disc_center_hole_radius_mm} mm must leave a web "
                f"to the crank holes (below {a - self.cam_radius_mm - self.eccentricity_mm} mm)")
        if self.housing_outer_radius_mm <= rp + self.pin_radius_mm:
            raise ValueError(
                f"design.housing_outer_radius_mm {self.housing_outer_radius_mm} mm must exceed Rp + pin radius "
                f"= {rp + self.pin_radius_mm} mm")
        return self

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> "Design":
        """Build and validate from a dict (the ``design`` object of a case JSON).

        Unknown keys raise ``ValueError`` naming the key.
        """
        d = dict(d or {})
        names = {f.name for f in fields(cls)}
        for k in d:
            if k not in names:
                raise ValueError(f"design key {k!r} is unknown; allowed: {sorted(names)}")
        if "crank_angles_deg" in d:
            d["crank_angles_deg"] = tuple(d["crank_angles_deg"])
        for k, v in d.items():
            if k.startswith("z_") and isinstance(v, float) and v.is_integer():
                d[k] = int(v)
        return cls(**d).validate()
