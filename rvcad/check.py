"""Geometric check of a case: refuse parts that cannot be built or assembled, naming the field.

:meth:`rvcad.params.Design.validate` refuses bad field values and the relations between fields
(pins apart, the two planets apart on the crank circle, radii). :func:`check_case` runs before
anything is exported (and in :func:`rvcad.reducer`) and checks what the solids need, on the
error-perturbed geometry of the case, raising :class:`rvcad.validation.DesignError` (a
``ValueError``) whose message names the field, its value and what is allowed:

* stage I teeth: a tip land and a root gap on both gears. Thinning the planet teeth by
  ``design.stage1_backlash_mm`` turns both flanks by b / (2 r_pitch); the tip land vanishes at
  ``b_max = b + s_tip r_pitch / r_tip`` (0.99 mm with the default gears: 1.0 mm points the planet);
* crank holes: the holes of the cranks in each disc (radius ``cam_radius_mm``, moved by
  ``errors.disc_hole_eccentricity``) do not overlap and stay inside the disc root circle; the
  journal holes of the plates (moved by ``errors.carrier_hole_eccentricity``) stay inside the rim;
* contacts (:func:`pin_interference`): the smallest largest penetration of the pins into the
  discs and of the loaded stage I flanks over the poses the solver can take (its coordinates:
  output and crank angles), at states over one crank revolution. The solver keeps these gaps and
  more, so its equilibrium penetrates at least as much. Above :data:`MAX_PENETRATION_MM` (the
  elastic limit of ``rvdyn``, 100 um) it would refuse the case too: ``errors.pin_radius`` +1000 um
  (1000.0 um), ``errors.pin_circle_diameter`` -1000 um (500.0 um), a pin 150 um too large (149 um;
  rvdyn: 155 um). The message names the error types whose removal brings it below the limit.

Lengths in mm at the API, angles in rad inside.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import linprog

from rvcad.errors import GEOMETRY_OPTIONS, Case, as_case
from rvcad.geometry import ReducerGeometry
from rvcad.params import closest_cranks
from rvcad.plan import PLATE_RIM_CLEARANCE_MM
from rvcad.validation import DesignError, quote, reject

#: Largest pin-disc penetration a pose may keep, mm: the elastic contact limit of the solver
#: (``rvdyn.solver.MAX_ELASTIC_PENETRATION_MM``, 0.1 mm); a case above it everywhere is refused.
MAX_PENETRATION_MM = 0.1

#: States sampled over one crank revolution for the pin-disc check (each pin meets a whole lobe).
INTERFERENCE_STATES = 12

#: Smallest root gap between two stage I teeth that still gives a valid solid, mm.
MIN_TOOTH_LAND_MM = 1e-3


# ----------------------------------------------------------------------------- stage I teeth
def _tooth_lands(gear) -> tuple[float, float]:
    """(tip land, root gap) of an involute gear, mm: chord widths at the tip and root circles."""
    half_tip = gear.tip_half_angle()
    r0 = max(gear.base_radius, gear.root_radius)
    half_root = float(gear.flank_polar_angle(r0))
    gap = math.pi / gear.z - half_root
    return 2.0 * gear.tip_radius * half_tip, 2.0 * gear.root_radius * gap


def _check_gears(g: ReducerGeometry) -> None:
    """Tip lands and root gaps of both stage I gears (the planet thinned by the backlash)."""
    d = g.design
    tip, root = _tooth_lands(g.planet)
    if tip < MIN_TOOTH_LAND_MM:
        # thinning by b turns each flank by b / (2 r_pitch): the land shrinks by b r_tip / r_pitch
        b_max = d.stage1_backlash_mm + (tip - MIN_TOOTH_LAND_MM) * g.planet.pitch_radius / g.planet.tip_radius
        reject("design.stage1_backlash_mm", d.stage1_backlash_mm, f"below {max(b_max, 0.0):.4f} mm",
               f"mm thins the planet teeth to a point (tip land {tip * 1e3:.1f} um): the planet is not a valid solid",
               DesignError)
    stip, sroot = _tooth_lands(g.sun)
    if stip < MIN_TOOTH_LAND_MM:
        reject("design.z_sun", d.z_sun, "more teeth, a smaller module or pressure angle",
               f"with module_mm {d.module_mm:g} and pressure_angle_deg {d.pressure_angle_deg:g} gives pointed sun "
               f"teeth (tip land {stip * 1e3:.1f} um)", DesignError)
    for name, gap in (("z_sun", sroot), ("z_planet", root)):
        if gap < MIN_TOOTH_LAND_MM:
            reject(f"design.{name}", getattr(d, name), "a tooth count with a positive root gap",
                   f"makes neighbouring teeth overlap at the root circle (gap {gap * 1e3:.1f} um)", DesignError)


# ----------------------------------------------------------------------------- crank holes
def hole_separation(holes: np.ndarray) -> tuple[float, int, int]:
    """Smallest centre distance (mm) between the crank holes ``holes`` (n, 2) and the two holes, ``(sep, i, j)``."""
    dist = np.linalg.norm(holes[:, None, :] - holes[None, :, :], axis=-1)
    dist[np.diag_indices(len(holes))] = np.inf
    i, j = np.unravel_index(int(np.argmin(dist)), dist.shape)
    return float(dist[i, j]), int(min(i, j)), int(max(i, j))


def _check_holes(g: ReducerGeometry) -> None:
    """The perturbed crank holes of each disc and plate: apart from each other, inside root and rim."""
    d = g.design
    r_hole, r_journal = d.cam_radius_mm, d.crank_journal_radius_mm
    root = min(p.root_radius for p in g.profiles)
    rim = d.pin_circle_radius_mm - d.eccentricity_mm - d.pin_radius_mm - PLATE_RIM_CLEARANCE_MM
    checks = [(f"disc{k}", g.disc_holes[k], r_hole, root, "errors.disc_hole_eccentricity") for k in range(d.n_discs)]
    checks.append(("flange and carrier", g.carrier_holes, r_journal, rim, "errors.carrier_hole_eccentricity"))
    for part, holes, r, limit, field in checks:
        sep, i, j = hole_separation(holes)
        if sep <= 2.0 * r:
            which = "the crank holes" if len(holes) == 2 else f"crank holes {i} and {j}"
            reject("design.crank_angles_deg", list(d.crank_angles_deg), f"holes more than {2 * r:g} mm apart",
                   f"with the errors puts {which} of {part} {sep:.4f} mm apart (they overlap)", DesignError)
        reach = float(np.max(np.linalg.norm(holes, axis=-1))) + r
        if reach >= limit:
            where = "root circle" if part.startswith("disc") else "rim"
            if d.center_distance_mm + r >= limit:  # the design alone: the hole radius is the field
                name = "design.cam_radius_mm" if part.startswith("disc") else "design.crank_journal_radius_mm"
                reject(name, r, f"below {limit - d.center_distance_mm:.4f} mm", f"mm puts the crank holes of {part} "
                       f"(at the {d.center_distance_mm:g} mm crank radius) through its {where} {limit:.4f} mm",
                       DesignError)
            reject(field, g.case.raw_errors.get(field.split(".", 1)[1]), f"holes inside the {where} ({limit:.4f} mm)",
                   f"moves a crank hole of {part} out to {reach:.4f} mm", DesignError)


# ----------------------------------------------------------------------------- pins against discs
def crank_period_input(g: ReducerGeometry) -> float:
    """Input angle of one crank revolution under the ideal kinematics, rad."""
    _, ps = g.ideal_state(np.array([0.0, 1.0]))
    return 2.0 * math.pi / abs(float(ps[1, 0] - ps[0, 0]))


def pin_interference(g: ReducerGeometry, states: int = INTERFERENCE_STATES, rounds: int = 8) -> np.ndarray:
    """Smallest largest contact penetration (pins in the discs, loaded stage I flanks) over the poses
    the solver can take, mm.

    At each of ``states`` ideal states over one crank revolution the solver's coordinates, the
    output angle and the crank angles (``x = (Rp dtheta_out, e dpsi_0, ..., e dpsi_(n-1))``, mm, as in
    ``rvdyn.solver``), may change; the gaps the solver keeps, the pins of both discs and the loaded
    stage I flanks (the case's direction), linearised by finite differences (``g + J x``), give a
    linear programme ``min t, -(g + J x) <= t`` (scipy ``linprog``) inside a trust region,
    re-linearised ``rounds`` times; a move is kept only if the exact penetration drops, else the
    trust region halves. The solver keeps
    the same gaps and more (supports, bearings), so every pose it reaches penetrates at least this
    much (a lower bound). Where the case's
    model lets the discs float in a cam-bearing clearance, each disc may instead move freely in its
    plane (a weaker bound).

    Returns
    -------
    (states,) float64
        Penetration, mm (<= 0: a pose without pin-disc overlap exists).
    """
    try:
        floating = float(g.case.model.get("cam_bearing_clearance_um", 0.0) or 0.0) > 0.0
    except (TypeError, ValueError):
        floating = True
    if floating:
        return _free_disc_interference(g, states, rounds)
    th = np.linspace(0.0, crank_period_input(g), states, endpoint=False)
    to0, ps0 = g.ideal_state(th)
    d = g.design
    rp, e, nc = d.pin_circle_radius_mm, d.eccentricity_mm, d.n_cranks

    def gaps(x: np.ndarray) -> np.ndarray:
        to, ps = to0 + x[:, 0] / rp, ps0 + x[:, 1:] / e
        pins = g.pin_gaps(to, ps)[0].reshape(states, -1)
        return np.concatenate([pins, g.stage1_gaps(th, to, ps, g.case.direction)], axis=1)

    x = np.zeros((states, 1 + nc))
    G = gaps(x)
    best = (-G).max(axis=1)
    radius = np.maximum(np.abs(best), 1e-3)
    done = np.zeros(states, dtype=bool)
    h = 1e-6  # mm: the gaps are exact to ~1e-10 mm (foot-point tolerance), the slopes to ~1e-4
    for _ in range(rounds):
        J = np.stack([(gaps(x + h * np.eye(1 + nc)[i]) - G) / h for i in range(1 + nc)], axis=-1)
        step = np.zeros_like(x)
        for s in np.nonzero(~done)[0]:
            A = np.c_[-J[s], -np.ones(len(G[s]))]
            res = linprog(np.r_[np.zeros(1 + nc), 1.0], A_ub=A, b_ub=G[s], method="highs",
                          bounds=[(-radius[s], radius[s])] * (1 + nc) + [(None, None)])
            if res.status != 0 or res.x[-1] > best[s] - 1e-9:  # no improvement predicted
                done[s] = True
                continue
            step[s] = res.x[:-1]
        if done.all():
            break
        Gn = gaps(x + step)
        pen = (-Gn).max(axis=1)
        better = (pen < best) & ~done
        x[better], G[better], best[better] = x[better] + step[better], Gn[better], pen[better]
        radius[~better] *= 0.5
    return best


def _free_disc_interference(g: ReducerGeometry, states: int, rounds: int) -> np.ndarray:
    """Per state, the largest over the discs of the smallest largest pin penetration when each disc
    may move freely in its plane (x, y, rotation): the relaxation for discs that float in a cam-bearing
    clearance. Linear programmes in a trust region as in :func:`pin_interference`; (states,) mm."""
    th = np.linspace(0.0, crank_period_input(g), states, endpoint=False)
    to, ps = g.ideal_state(th)
    nd = g.design.n_discs
    rp = g.design.pin_circle_radius_mm
    out = np.zeros((states, nd))
    for s in range(states):
        for k, prof in enumerate(g.profiles):
            shift, turn = np.zeros((1, nd, 2)), np.zeros((1, nd))

            def gaps(shift: np.ndarray, turn: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
                p, t0 = g.pins_in_profile_frames(to[s:s + 1], ps[s:s + 1], shift, turn)
                bd, _, n = prof.boundary_distance(p[0, k], t0[0, k])
                return bd - g.pin_radii, p[0, k] - bd[:, None] * n, n

            gap, f, n = gaps(shift, turn)
            best = float(-gap.min())
            radius = max(abs(best), 1e-3)
            for _ in range(rounds):
                lever = -n[:, 0] * f[:, 1] + n[:, 1] * f[:, 0]
                A = np.c_[n, lever, -np.ones(len(gap))]
                res = linprog([0, 0, 0, 1], A_ub=A, b_ub=gap, method="highs",
                              bounds=[(-radius, radius), (-radius, radius), (-radius / rp, radius / rp), (None, None)])
                if res.status != 0 or res.x[3] > best - 1e-9:  # no improvement predicted
                    break
                dx, dy, dth, _ = res.x
                ang = float(g.disc_poses(to[s:s + 1], ps[s:s + 1])[1][0, k]) + float(turn[0, k]) \
                    + float(g.disc_profile_rotation[k])
                c, si = math.cos(ang), math.sin(ang)
                sh2, tu2 = shift.copy(), turn.copy()
                sh2[0, k] += (c * dx - si * dy, si * dx + c * dy)  # profile frame -> fixed frame
                tu2[0, k] += dth
                gap2, f2, n2 = gaps(sh2, tu2)
                pen = float(-gap2.min())
                if pen < best:
                    best, shift, turn, gap, f, n = pen, sh2, tu2, gap2, f2, n2
                else:
                    radius *= 0.5
            out[s, k] = best
    return out.max(axis=1)


def _blame(case: Case, limit: float) -> list[str]:
    """Error types (``errors.<name>``) and model options that move parts (``model.<name>``,
    :data:`rvcad.errors.GEOMETRY_OPTIONS`) whose removal alone brings the pin interference below ``limit``."""
    base = case.to_dict()
    fields = [f"errors.{k}" for k in case.raw_errors] + \
             [f"model.{k}" for k, v in case.model.items() if k in GEOMETRY_OPTIONS and v != GEOMETRY_OPTIONS[k].default]
    hit = []
    for field in fields:
        part, name = field.split(".", 1)
        try:
            g = ReducerGeometry(Case.from_dict({**base, part: {k: v for k, v in base[part].items() if k != name}}))
        except ValueError:
            continue
        if float(pin_interference(g, states=8, rounds=4).max()) <= limit:
            hit.append(field)
    return hit or fields or ["design.pin_radius_mm"]


def _given(case: Case, field: str) -> Any:
    """The value a case gives to ``errors.<name>`` or ``model.<name>`` (None for a design field)."""
    part, name = field.split(".", 1)
    return case.raw_errors.get(name) if part == "errors" else case.model.get(name) if part == "model" else None


# ----------------------------------------------------------------------------- entry point
def check_case(case: "Case | dict[str, Any] | str | Path | None", geometry: ReducerGeometry | None = None,
               cache: bool = True) -> dict[str, Any]:
    """Refuse a case that cannot give valid, assemblable solids; return the measured margins.

    Parameters
    ----------
    case : Case, dict, str, Path or None
        What :func:`rvcad.reducer` takes: a case, the case JSON object as a dict, the path of a case
        JSON file, or None (the nominal case).
    geometry : ReducerGeometry or None
        Pre-built geometry of the case.
    cache : bool
        Reuse the outcome of an earlier check of a case with the same key in this process.

    Returns
    -------
    dict
        ``planet_tip_land_mm``, ``sun_tip_land_mm``, ``crank_hole_separation_mm`` (nominal, the closest two),
        ``pin_penetration_mm`` (largest over the states of the smallest reachable contact penetration).

    Raises
    ------
    DesignError
        With the field, its value and what is allowed.
    """
    case = as_case(case)
    key = case.key()
    if cache and key in _MEMO:
        if isinstance(_MEMO[key], DesignError):
            e = _MEMO[key]  # a fresh exception with the same field, value and allowed
            raise DesignError(str(e), field=e.field, value=e.value, allowed=e.allowed)
        return dict(_MEMO[key])
    try:
        out = _check(case, geometry)
    except DesignError as exc:
        _MEMO[key] = exc
        raise
    if len(_MEMO) > 64:
        _MEMO.clear()
    _MEMO[key] = out
    return dict(out)


def _check(case: Case, geometry: ReducerGeometry | None) -> dict[str, Any]:
    g = geometry if geometry is not None else ReducerGeometry(case)
    _check_gears(g)
    _check_holes(g)
    pen = float(pin_interference(g).max())
    if pen > MAX_PENETRATION_MM:
        fields = _blame(case, MAX_PENETRATION_MM)
        values = [_given(case, f) for f in fields]
        given = quote(values[0]) if len(fields) == 1 else "(" + ", ".join(map(quote, values)) + ")"
        raise DesignError(
            f"{' + '.join(fields)} {given} makes the parts overlap (pins in the discs, loaded stage I flanks) by at "
            f"least {pen * 1e3:.1f} um in every pose the solver can take; allowed: an overlap of at most "
            f"{MAX_PENETRATION_MM * 1e3:g} um (the solver's elastic contact limit)", field=fields[0], value=values[0],
            allowed=f"an overlap of at most {MAX_PENETRATION_MM * 1e3:g} um")
    d = g.design
    sep = 2.0 * d.center_distance_mm * abs(math.sin(0.5 * math.radians(closest_cranks(d.crank_angles_deg)[2])))
    return {"planet_tip_land_mm": _tooth_lands(g.planet)[0], "sun_tip_land_mm": _tooth_lands(g.sun)[0],
            "crank_hole_separation_mm": sep, "pin_penetration_mm": pen}


#: Outcome (margins or the refusal) of the cases checked, by case key: a case is checked once per process.
_MEMO: dict[str, Any] = {}


__all__ = ["INTERFERENCE_STATES", "MAX_PENETRATION_MM", "MIN_TOOTH_LAND_MM", "DesignError", "check_case",
           "crank_period_input", "pin_interference"]
