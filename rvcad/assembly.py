"""All parts of one case placed at one state: the assembly (meshes, OCP solids, build123d compound).

Lengths in mm, angles in degrees at the API.
"""
from __future__ import annotations

import math
from typing import Any, Iterator, Sequence

import numpy as np

from rvcad.cycloid import Crankshaft, CycloidDisc
from rvcad.errors import Case
from rvcad.gears import PlanetGear, SunGear
from rvcad.geometry import ReducerGeometry
from rvcad.housing import Pin, PinHousing
from rvcad.mesh import Mesh
from rvcad.params import Design
from rvcad.plan import AxialLayout, Part
from rvcad.plates import FlangePlate, PlanetaryCarrier, _Plate


class Assembly:
    """All parts of one case, placed at one input angle.

    Parameters
    ----------
    case : Case or None
        Validated case (``None``: nominal).
    theta_in_deg : float
        Input (sun) angle, degrees; the other moving parts follow the ideal kinematics
        (:meth:`ReducerGeometry.placement`) unless ``state`` is given.
    state : (theta_out rad, (psi_0, ..., psi_(n-1)) rad: one per crank) or None
        Explicit output and crank angles at ``theta_in_deg`` (e.g. the pose solved by ``rvdyn``).
    geometry : ReducerGeometry or None
        Pre-built geometry of the case (saves rebuilding it).

    Attributes
    ----------
    geometry : ReducerGeometry
    layout : AxialLayout
    parts : dict of str -> Part
        In a fixed order: sun, planets, cranks, flange, discs, carrier, housing, pins.
    placements : dict of str -> (x mm, y mm, rotation deg)
        Placement of every part (identity for fixed parts).
    """

    def __init__(self, case: Case | None = None, theta_in_deg: float = 0.0,
                 state: tuple[float, Sequence[float]] | None = None,
                 geometry: ReducerGeometry | None = None) -> None:
        self.case = case if case is not None else Case.from_dict({"name": "nominal"})
        self.theta_in_deg = float(theta_in_deg)
        if not math.isfinite(self.theta_in_deg):
            raise ValueError(f"theta_in_deg {theta_in_deg!r} must be finite")
        g = geometry if geometry is not None else ReducerGeometry(self.case)
        self.geometry = g
        self.layout = AxialLayout.from_design(g.design)
        d = g.design
        parts: list[Part] = [SunGear(g, self.layout)]
        parts += [PlanetGear(g, j, self.layout) for j in range(d.n_cranks)]
        parts += [Crankshaft(g, j, self.layout) for j in range(d.n_cranks)]
        parts.append(FlangePlate(g, self.layout))
        parts += [CycloidDisc(g, k, self.layout) for k in range(d.n_discs)]
        parts.append(PlanetaryCarrier(g, self.layout))
        parts.append(PinHousing(g, self.layout))
        parts += [Pin(g, i, self.layout) for i in range(d.z_pins)]
        self.parts: dict[str, Part] = {p.name: p for p in parts}
        self.state = None if state is None else (float(state[0]), tuple(float(v) for v in state[1]))
        if self.state is not None and (len(self.state[1]) != d.n_cranks
                                       or not all(map(math.isfinite, (self.state[0],) + self.state[1]))):
            raise ValueError(f"state {state!r} must be (theta_out rad, {d.n_cranks} crank angles rad), finite")
        if self.state is None:
            pl = g.placement(math.radians(self.theta_in_deg))
        else:
            pl = g.placement(math.radians(self.theta_in_deg), self.state[0], self.state[1])
        self.placements: dict[str, tuple[float, float, float]] = {
            p.name: ((0.0, 0.0, 0.0) if p.placement_key is None else tuple(map(float, pl[p.placement_key])))
            for p in parts}

    def at(self, theta_in_deg: float) -> "Assembly":
        """The same parts (and their cached meshes and solids) placed at another input angle, degrees."""
        if not math.isfinite(float(theta_in_deg)):
            raise ValueError(f"theta_in_deg {theta_in_deg!r} must be finite")
        other = object.__new__(Assembly)
        other.__dict__.update(self.__dict__)
        other.theta_in_deg = float(theta_in_deg)
        other.state = None
        pl = self.geometry.placement(math.radians(other.theta_in_deg))
        other.placements = {
            p.name: ((0.0, 0.0, 0.0) if p.placement_key is None else tuple(map(float, pl[p.placement_key])))
            for p in self.parts.values()}
        return other

    def __iter__(self) -> Iterator[Part]:
        return iter(self.parts.values())

    def __getitem__(self, name: str) -> Part:
        return self.parts[name]

    def placed_mesh(self, name: str, sagitta_mm: float | None = None) -> Mesh:
        """Mesh of one part placed in the world frame at this input angle, mm."""
        x, y, r = self.placements[name]
        return self.parts[name].mesh(sagitta_mm).placed(x, y, r)

    def mesh(self, sagitta_mm: float | None = None) -> Mesh:
        """All parts placed, as one mesh (mm)."""
        return Mesh.concatenate([self.placed_mesh(n, sagitta_mm) for n in self.parts])

    def shapes(self, tolerance_mm: float | None = None) -> list[tuple[str, Any, tuple[float, float, float]]]:
        """(name, own-frame OCP solid, placement (x mm, y mm, rotation deg)) of every part."""
        return [(n, p.shape(tolerance_mm), self.placements[n]) for n, p in self.parts.items()]

    def compound(self, tolerance_mm: float | None = None):
        """build123d ``Compound`` of all placed solids, each labelled with its part name."""
        import build123d as bd

        children = []
        for name, part in self.parts.items():
            x, y, r = self.placements[name]
            s = part.solid(tolerance_mm)
            if (x, y, r) != (0.0, 0.0, 0.0):
                s = s.moved(bd.Location((x, y, 0.0), (0.0, 0.0, r)))
            else:
                s = s.moved(bd.Location())
            s.label = name
            children.append(s)
        return bd.Compound(children=children, label=f"rv-reducer {self.case.name}")

    def design_check(self) -> dict[str, Any]:
        """Feasibility report: undercut per disc, pin spacing, stage I and radial clearances (mm)."""
        g, d = self.geometry, self.design
        discs = [p for p in self.parts.values() if isinstance(p, CycloidDisc)]
        c = g.pin_centers
        nxt = np.roll(np.arange(d.z_pins), -1)
        pin_gap = np.linalg.norm(c[nxt] - c, axis=1) - (g.pin_radii + g.pin_radii[nxt])
        a = d.center_distance_mm
        tip_root = min(a - g.sun.tip_radius - g.planet.root_radius, a - g.planet.tip_radius - g.sun.root_radius)
        housing = self.parts["housing"]
        assert isinstance(housing, PinHousing)
        tip_max = max(p.tip_radius for p in discs) + float(np.max(g.cam_ecc))
        disc_bore = housing.bore_radius - float(np.linalg.norm(housing.bore_center)) - tip_max
        plate = self.parts["carrier"]
        assert isinstance(plate, _Plate)
        plate_root = min(p.root_radius for p in discs) - float(np.max(g.cam_ecc)) - plate.outer_radius
        msgs = [f"disc{p.k}: {p.design_check['message']}" for p in discs]
        ok = bool(pin_gap.min() > 0 and tip_root > 0 and disc_bore > 0)
        if disc_bore <= 0:
            msgs.append(f"disc tips may reach the housing bore (clearance {disc_bore:.4f} mm)")
        if tip_root <= 0:
            msgs.append(f"stage I tip/root interference ({tip_root:.4f} mm)")
        return {
            "ok": ok,
            "undercut": any(p.undercut for p in discs),
            "discs": [{**{k: v for k, v in p.design_check.items()},
                       "profile_rotation_deg": p.profile_rotation_deg} for p in discs],
            "pins": {"count": d.z_pins, "min_gap_mm": float(pin_gap.min()), "overlap": bool(pin_gap.min() <= 0)},
            "stage1": {"sun_tip_radius_mm": g.sun.tip_radius, "planet_tip_radius_mm": g.planet.tip_radius,
                       "tip_root_clearance_mm": float(tip_root)},
            "disc_tip_to_housing_bore_mm": float(disc_bore),
            "disc_root_to_plate_rim_mm": float(plate_root),
            "messages": msgs,
        }

    @property
    def design(self) -> Design:
        return self.geometry.design


__all__ = ["Assembly"]
