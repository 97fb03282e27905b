"""Geometric design check: refuse a case whose parts cannot be built or assembled, naming the field.

:func:`check_case` runs before anything is exported (and in :func:`rvcad.reducer`). It checks
what the solids need, in closed form where one exists, and raises :class:`DesignError` (a
``ValueError``) whose message names the case field, its value and what is allowed:

* stage I teeth: each tooth keeps a positive tip land (its two flanks meet above the tip circle)
  and a positive root gap (neighbouring teeth do not overlap at the root circle). Thinning the
  planet teeth by ``design.stage1_backlash_mm`` moves both flanks by b / (2 r) in angle; the tip
  land vanishes at ``b_max = b + 2 r_pitch * (tip half angle)`` (1.0 mm points the default planet);
* crank holes: the holes of the two cranks in a disc (radius ``cam_radius_mm``) and in the plates
  (``crank_journal_radius_mm``) do not overlap (centre distance ``2 a sin(|beta_1 - beta_0| / 2)``,
  ``design.crank_angles_deg`` = [0, 0] puts both holes on one spot) and lie inside the disc root
  circle and the plate rim;
* pins against the discs (:func:`pin_interference`): the smallest largest penetration of the
  pins into a disc that any rigid in-plane motion of the disc reaches (a relaxation of every
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

#: Largest pin-disc penetration a pose may keep, mm: the elastic contact limit of the solver
#: (``rvdyn.solver.MAX_ELASTIC_PENETRATION_MM``, 0.1 mm); a case above it everywhere is refused.
MAX_PENETRATION_MM = 0.1

#: States sampled over one crank revolution for the pin-disc check (each pin meets a whole lobe).
INTERFERENCE_STATES = 12

#: Smallest tip land and root gap of a stage I tooth that still gives a valid solid, mm.
MIN_TOOTH_LAND_MM = 1e-3


class DesignError(ValueError):
    """The case cannot give valid, assemblable solids; the message names the field."""


# ----------------------------------------------------------------------------- stage I teeth
def _tooth_lands(gear) -> tuple[float, float]:
    """(tip land, root gap) of an involute gear, mm: chord widths at the tip and root circles."""
    half_tip = gear.tip_half_angle()
    r0 = max(gear.base_radius, gear.root_radius)
    half_root = float(gear.flank_polar_angle(r0))
    gap = math.pi / gear.z - half_root
    return 2.0 * gear.tip_radius * half_tip, 2.0 * gear.root_radius * gap


def _check_gears(g: ReducerGeometry) -> None:
    d = g.design
    tip, root = _tooth_lands(g.planet)
    if tip < MIN_TOOTH_LAND_MM:
        b_max = d.stage1_backlash_mm + 2.0 * g.planet.pitch_radius * (g.planet.tip_half_angle()
                                                                        - MIN_TOOTH_LAND_MM / (2 * g.planet.tip_radius))
        raise DesignError(
            f"design.stage1_backlash_mm {d.stage1_backlash_mm:g} mm thins the planet teeth to a point (tip land "
            f"{tip * 1e3:.1f} um): the planet is not a valid solid; allowed: below {max(b_max, 0.0):.4f} mm")
    stip, sroot = _tooth_lands(g.sun)
    if stip < MIN_TOOTH_LAND_MM:
        raise DesignError(
            f"design.z_sun {d.z_sun} with module_mm {d.module_mm:g} and pressure_angle_deg "
            f"{d.pressure_angle_deg:g} gives pointed sun teeth (tip land {stip * 1e3:.1f} um); allowed: more "
            "teeth or a smaller pressure angle")
    for name, gap in (("z_sun", sroot), ("z_planet", root)):
        if gap < MIN_TOOTH_LAND_MM:
            raise DesignError(f"design.{name} {getattr(d, name)}: neighbouring teeth overlap at the root circle "
                              f"(gap {gap * 1e3:.1f} um); allowed: a tooth count with a positive root gap")


# ----------------------------------------------------------------------------- crank holes
def _check_holes(g: ReducerGeometry) -> None:
    d = g.design
    beta = np.radians(np.asarray(d.crank_angles_deg, dtype=float))
    a = d.center_distance_mm
    sep = 2.0 * a * abs(math.sin(0.5 * (beta[1] - beta[0])))
    need = 2.0 * d.cam_radius_mm
    if sep <= need:
        min_deg = math.degrees(2.0 * math.asin(min(1.0, need / (2.0 * a))))
        raise DesignError(
            f"design.crank_angles_deg {list(d.crank_angles_deg)} put the two crank holes {sep:.4f} mm apart, less "
            f"than two cam radii ({need:g} mm): the disc is not a valid solid; allowed: cranks at least "
            f"{min_deg:.2f} deg apart (and at most {360 - min_deg:.2f} deg)")
    root = min(p.root_radius for p in g.profiles) - float(np.max(np.abs(g.cam_ecc - d.eccentricity_mm)))
    reach = float(np.max(np.linalg.norm(g.disc_holes, axis=-1))) + d.cam_radius_mm
    if reach >= root:
        raise DesignError(
            f"design.cam_radius_mm {d.cam_radius_mm:g} mm: the crank holes reach {reach:.4f} mm from the disc centre, "
            f"beyond the disc root circle {root:.4f} mm; allowed: below {root - a:.4f} mm at crank radius {a:g} mm")
    rim = d.pin_circle_radius_mm - d.eccentricity_mm - d.pin_radius_mm - PLATE_RIM_CLEARANCE_MM
    reach_p = float(np.max(np.linalg.norm(g.carrier_holes, axis=-1))) + d.crank_journal_radius_mm
    if reach_p >= rim:
        raise DesignError(
            f"design.crank_journal_radius_mm {d.crank_journal_radius_mm:g} mm: the journal holes reach "
            f"{reach_p:.4f} mm, beyond the plate rim {rim:.4f} mm; allowed: below {rim - a:.4f} mm")


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
        vals = ", ".join(f"{f} = {json_short(case.raw_errors.get(f.split('.', 1)[1]))}" for f in fields
                         if f.startswith("errors."))
        raise DesignError(
            f"{' / '.join(fields)}{' (' + vals + ')' if vals else ''}: the pins overlap the discs by at least "
            f"{pen * 1e3:.1f} um in every pose of the disc; allowed: at most {MAX_PENETRATION_MM * 1e3:g} um "
            "(the solver's elastic limit)")
    d = g.design
    sep = 2.0 * d.center_distance_mm * abs(math.sin(0.5 * math.radians(d.crank_angles_deg[1] - d.crank_angles_deg[0])))
    return {"planet_tip_land_mm": _tooth_lands(g.planet)[0], "sun_tip_land_mm": _tooth_lands(g.sun)[0],
            "crank_hole_separation_mm": sep, "pin_penetration_mm": pen}


#: Outcome (margins or the refusal) of the cases checked, by case key: a case is checked once per process.
_MEMO: dict[str, Any] = {}


def json_short(v: Any, n: int = 40) -> str:
    """Short text of a JSON value for messages."""
    import json

    s = json.dumps(v)
    return s if len(s) <= n else s[:n - 3] + "..."


__all__ = ["INTERFERENCE_STATES", "MAX_PENETRATION_MM", "MIN_TOOTH_LAND_MM", "DesignError", "check_case",
           "crank_period_input", "pin_interference"]
