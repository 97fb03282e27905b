"""Geometric check of a case: refuse parts that cannot be built or assembled, naming the field.

:meth:`rvcad.params.Design.validate` already refuses a *design* that cannot be built (pointed teeth
from ``design.stage1_backlash_mm``, cranks too close in ``design.crank_angles_deg``, holes through
the disc root, ...). :func:`check_case` runs before anything is exported (and in
:func:`rvcad.reducer`) and adds what needs the error-perturbed geometry of the case, raising
:class:`rvcad.validation.DesignError` (a ``ValueError``) whose message names the field, its value
and what is allowed:

* stage I teeth: a positive root gap (neighbouring teeth do not overlap at the root circle);
* crank holes: the perturbed holes of the two cranks in each disc (radius ``cam_radius_mm``, moved
  by ``errors.disc_hole_eccentricity``) do not overlap and stay inside the disc root circle; the
  journal holes of the plates (moved by ``errors.carrier_hole_eccentricity``) stay inside the rim;
* pins against the discs (:func:`pin_interference`): the smallest largest penetration of the
  pins into a disc that any small rigid in-plane motion of the disc reaches (a relaxation of every
  pose the solver can take: the cams restrict the disc further), over one crank revolution. Above
  :data:`MAX_PENETRATION_MM` (the elastic limit of ``rvdyn``, 100 um) no pose resolves it:
  ``errors.pin_radius`` +1000 um or ``errors.pin_circle_diameter`` -1000 um. The message names
  the error types whose removal brings it below the limit.

Lengths in mm at the API, angles in rad inside.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.optimize import linprog

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
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
    """Root gaps of both gears (the tip lands are checked by ``Design.validate``)."""
    d = g.design
    for name, gear in (("z_sun", g.sun), ("z_planet", g.planet)):
        gap = _tooth_lands(gear)[1]
        if gap < MIN_TOOTH_LAND_MM:
            reject(f"design.{name}", getattr(d, name), "a tooth count with a positive root gap",
                   f"makes neighbouring teeth overlap at the root circle (gap {gap * 1e3:.1f} um)", DesignError)


# ----------------------------------------------------------------------------- crank holes
def _check_holes(g: ReducerGeometry) -> None:
    """The perturbed crank holes of each disc and plate: apart from each other, inside root and rim."""
    d = g.design
    r_hole, r_journal = d.cam_radius_mm, d.crank_journal_radius_mm
    root = min(p.root_radius for p in g.profiles)
    rim = d.pin_circle_radius_mm - d.eccentricity_mm - d.pin_radius_mm - PLATE_RIM_CLEARANCE_MM
    checks = [(f"disc{k}", g.disc_holes[k], r_hole, root, "errors.disc_hole_eccentricity") for k in range(d.n_discs)]
    checks.append(("flange and carrier", g.carrier_holes, r_journal, rim, "errors.carrier_hole_eccentricity"))
    for part, holes, r, limit, field in checks:
        sep = float(np.linalg.norm(holes[1] - holes[0]))
        if sep <= 2.0 * r:
            reject("design.crank_angles_deg", list(d.crank_angles_deg), f"holes more than {2 * r:g} mm apart",
                   f"with the errors puts the crank holes of {part} {sep:.4f} mm apart (they overlap)", DesignError)
        reach = float(np.max(np.linalg.norm(holes, axis=-1))) + r
        if reach >= limit:
            reject(field, g.case.raw_errors.get(field.split(".", 1)[1]), f"holes inside the {'root circle' if part.startswith('disc') else 'rim'} "
                   f"({limit:.4f} mm)", f"moves a crank hole of {part} out to {reach:.4f} mm", DesignError)


# ----------------------------------------------------------------------------- pins against discs
def crank_period_input(g: ReducerGeometry) -> float:
    """Input angle of one crank revolution under the ideal kinematics, rad."""
    _, ps = g.ideal_state(np.array([0.0, 1.0]))
    return 2.0 * math.pi / abs(float(ps[1, 0] - ps[0, 0]))


def pin_interference(g: ReducerGeometry, states: int = INTERFERENCE_STATES, rounds: int = 8) -> np.ndarray:
    """Smallest largest pin penetration into each disc over small rigid in-plane disc motions, mm.

    At each of ``states`` ideal states over one crank revolution the disc may move by
    (dx, dy, dtheta); the linearised gaps ``g_i - n_i . (d + dtheta perp(f_i))`` (outward normal
    n_i at the foot point f_i, disc profile frame) give a linear programme ``min t, -g_i' <= t``
    (scipy ``linprog``) inside a trust region, re-linearised ``rounds`` times; a move is kept only
    if the exact penetration drops, else the trust region halves. The trust region matters: the
    ideal contact normals all pass through the pitch point, so rolling about it is a first-order
    free motion (the reducer's own kinematics, sampled by the states instead). The disc's real
    motion is further restricted by the cams, so a solver pose penetrates about this much or more.

    Returns
    -------
    (states, n_discs) float64
        Penetration, mm (<= 0: a pose without pin-disc overlap exists).
    """
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
    return out


def _blame(case: Case, limit: float) -> list[str]:
    """Error types (``errors.<name>``) whose removal alone brings the pin interference below ``limit``."""
    names = list(case.raw_errors)
    hit = []
    for name in names:
        rest = {k: v for k, v in case.raw_errors.items() if k != name}
        try:
            g = ReducerGeometry(case.with_errors(rest))
        except ValueError:
            continue
        if float(pin_interference(g, states=8, rounds=4).max()) <= limit:
            hit.append(f"errors.{name}")
    return hit or [f"errors.{n}" for n in names] or ["design.pin_radius_mm"]


# ----------------------------------------------------------------------------- entry point
def check_case(case: Case, geometry: ReducerGeometry | None = None, cache: bool = True) -> dict[str, Any]:
    """Refuse a case that cannot give valid, assemblable solids; return the measured margins.

    Parameters
    ----------
    case : Case
    geometry : ReducerGeometry or None
        Pre-built geometry of the case.
    cache : bool
        Reuse the outcome of an earlier check of a case with the same key in this process.

    Returns
    -------
    dict
        ``planet_tip_land_mm``, ``sun_tip_land_mm``, ``crank_hole_separation_mm``,
        ``pin_penetration_mm`` (largest over the states of the smallest reachable penetration).

    Raises
    ------
    DesignError
        With the field, its value and what is allowed.
    """
    key = case.key()
    if cache and key in _MEMO:
        if isinstance(_MEMO[key], DesignError):
            raise DesignError(str(_MEMO[key]))
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
        values = [case.raw_errors.get(f.split(".", 1)[1]) for f in fields]
        given = quote(values[0]) if len(fields) == 1 else "(" + ", ".join(map(quote, values)) + ")"
        raise DesignError(
            f"{' + '.join(fields)} {given} makes the pins overlap the discs by at least {pen * 1e3:.1f} um in every "
            f"pose of the disc; allowed: a pin-disc overlap of at most {MAX_PENETRATION_MM * 1e3:g} um (the "
            "solver's elastic contact limit)", field=fields[0], value=values[0],
            allowed=f"a pin-disc overlap of at most {MAX_PENETRATION_MM * 1e3:g} um")
    d = g.design
    sep = 2.0 * d.center_distance_mm * abs(math.sin(0.5 * math.radians(d.crank_angles_deg[1] - d.crank_angles_deg[0])))
    return {"planet_tip_land_mm": _tooth_lands(g.planet)[0], "sun_tip_land_mm": _tooth_lands(g.sun)[0],
            "crank_hole_separation_mm": sep, "pin_penetration_mm": pen}


#: Outcome (margins or the refusal) of the cases checked, by case key: a case is checked once per process.
_MEMO: dict[str, Any] = {}


__all__ = ["INTERFERENCE_STATES", "MAX_PENETRATION_MM", "MIN_TOOTH_LAND_MM", "DesignError", "check_case",
           "crank_period_input", "pin_interference"]
