"""The hysteresis curve a reducer maker measures, and the datasheet figures read from it.

Measurement (conventions.md, "Lost motion, backlash, rigidity"): the input is locked, the output
torque is swept -rated -> +rated -> -rated and the output torsion angle recorded. Here:

1. The *elastic curve*: the quasi-static equilibrium at the locked input angle for torque levels
   ``+-f T_rated`` (external output torque tau > 0 turns the output +z; the solver's load resists
   the motion, so tau > 0 is direction -1 with load tau) and, at zero torque, the rigid limit in both
   directions (the two ends of the geometric play).
2. *Coulomb friction* (docs/physics.md, section 9): the micro-slip that the elastic deflection
   makes at each contact dissipates ``mu F |ds|``; reflected to the output it is a friction torque
   ``tau_f = mu_pin sum F_i |ds_i/dtheta| + mu_b sum |F_b| r_b |d phi_rel/dtheta|`` (pins: slip =
   arc length of the contact point along the disc boundary; bearings: relative turn of crank and disc
   or carrier at the roller pitch radius). The output then moves only when the torque leaves the band
   ``[tau_el - tau_f, tau_el + tau_f]``: loading branch ``tau = tau_el + tau_f``, unloading
   ``tau = tau_el - tau_f``, sticking in between.
3. Datasheet figures (maker's definitions): ``lost_motion`` = torsion angle between the midpoints of
   the curve's width at +3 % and -3 % of rated torque; ``backlash`` = the geometric play at zero
   torque (rigid limit, TE(-1) - TE(+1)); ``hysteresis_loss`` = the curve's width at zero torque
   (play plus friction); ``torsional_rigidity`` = b/a, read as the secant of the mid-curve between
   3 % and 100 % of rated torque (b = 0.97 T_rated, a = its angle), mean of both sides; ``budget`` =
   each part's output wind-up at rated torque (arcsec, mean of both directions); ``budget_per_crank`` = the
   parts each crank carries (its planet's mesh, torsion, cam and journal bearings, bending, bearing seats),
   crank by crank, in the same unit (their sum over the cranks is the part's ``budget``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvdyn.bearings import Supports
from rvdyn.contacts import ContactLaw
import rvdyn.housing as housing
from rvdyn.results import InterferenceError
from rvdyn.options import model_value
from rvdyn.solver import ARCSEC_PER_RAD, QuasiStaticSolver
from rvdyn.te import make_contacts, write_table_atomic

#: Rated output torque of the default design, N m: the paper's reducer is of the RV-20E class.
DEFAULT_RATED_NM = 167.0
#: Datasheet class of the default design (Nabtesco RV-20E; conventions.md).
DATASHEET = {"model": "RV-20E class", "rated_torque_Nm": 167.0, "torsional_rigidity_Nm_per_arcmin": 49.0,
             "lost_motion_arcmin_max": 1.0}
#: Torque levels of the elastic curve, fractions of rated torque (3 % is a datasheet point).
LEVELS = (0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
LOST_MOTION_FRACTION = 0.03


@dataclass
class StiffnessResult:
    """Hysteresis curve and datasheet figures of one case.

    Attributes
    ----------
    curve : DataFrame
        The sweep: ``torque_Nm``, ``torsion_arcmin``, ``branch`` (``load`` -rated -> +rated,
        ``unload`` +rated -> -rated).
    elastic : DataFrame
        The friction-free equilibrium: ``torque_Nm``, ``torsion_arcmin``, ``friction_torque_Nm``,
        ``pins_in_contact`` (pin-disc contacts of both discs that touch), ``housing_arcmin`` (the housing
        ring's wind-up in series, included in ``torsion_arcmin``; rvdyn.housing).
    figures : dict
        ``torsional_rigidity_Nm_per_arcmin``, ``lost_motion_arcmin``, ``backlash_arcmin``,
        ``hysteresis_loss_arcmin``, ``rated_torque_Nm``, ``budget`` (part -> arcsec at rated torque),
        ``budget_per_crank`` (part -> one arcsec figure per crank, for the parts a crank carries),
        ``preloaded`` (the errors make an interference the parts take as a preload: no play, and the preload's
        normal forces keep the friction band open at zero torque),
        ``pins_in_contact`` (torque fraction of rated -> pin contacts of both discs, positive side)
        and the context (contact law, friction coefficients, datasheet class, notes).
    """

    curve: pd.DataFrame
    elastic: pd.DataFrame
    figures: dict[str, Any] = field(default_factory=dict)

    def plot(self, path: str | Path) -> Path:
        """Write the hysteresis curve as a PNG (matplotlib imported here only)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from rvcad.atomic import atomic_path

        path = Path(path)
        fig, ax = plt.subplots(figsize=(6.4, 4.4))
        for br, st in (("load", "-"), ("unload", "--")):
            c = self.curve[self.curve["branch"] == br]
            ax.plot(c["torque_Nm"], c["torsion_arcmin"], st, label=br)
        f = self.figures
        ax.set_xlabel("output torque (N m), input locked")
        ax.set_ylabel("torsion angle (arcmin)")
        ax.set_title(f"rigidity {f['torsional_rigidity_Nm_per_arcmin']:.1f} N m/arcmin, lost motion "
                     f"{f['lost_motion_arcmin']:.3f} arcmin ({f['contact']} law)", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=120)
        plt.close(fig)
        return path


def _branch_inverse(theta: np.ndarray, tau: np.ndarray, target: float, up: bool) -> float:
    """theta on a non-decreasing curve tau(theta): smallest theta with tau >= target (up) or largest with
    tau <= target (down), linear between the samples."""
    if up:
        i = int(np.searchsorted(tau, target, side="left"))
        if i == 0:
            return float(theta[0])
        if i >= tau.size:
            return float(theta[-1])
    else:
        i = int(np.searchsorted(tau, target, side="right"))
        if i >= tau.size:
            return float(theta[-1])
        if i == 0:
            return float(theta[0])
    t0, t1 = tau[i - 1], tau[i]
    w = 0.0 if t1 == t0 else (target - t0) / (t1 - t0)
    if not up and t1 == t0:
        w = 1.0
    return float(theta[i - 1] + w * (theta[i] - theta[i - 1]))


def _mid_width(curve: pd.DataFrame, tau: float) -> tuple[float, float]:
    """Midpoint and width (arcmin) of the hysteresis curve at torque tau."""
    vals = []
    for br in ("load", "unload"):
        c = curve[curve["branch"] == br].sort_values("torque_Nm", kind="stable")
        vals.append(float(np.interp(tau, c["torque_Nm"].to_numpy(), c["torsion_arcmin"].to_numpy())))
    up, dn = vals
    return 0.5 * (up + dn), dn - up


def hysteresis(case: Case, rated_Nm: float | None = None, theta_in_deg: float = 0.0, solver: str = "analytic",
               law: ContactLaw | None = None, points: int = 41) -> StiffnessResult:
    """The maker's torque sweep of a case and the datasheet figures.

    Parameters
    ----------
    case : Case
    rated_Nm : float or None
        Rated output torque, N m (default 167 N m, the RV-20E class of the default design).
    theta_in_deg : float
        The locked input angle, deg.
    solver : {"analytic", "fcl"}
    law : ContactLaw or None
        Default: the case's ``model.contact``.
    points : int
        Evenly spaced torques of each sweep branch (>= 5); the elastic curve's levels are added.
    """
    rated = DEFAULT_RATED_NM if rated_Nm is None else float(rated_Nm)
    if not (math.isfinite(rated) and rated > 0):
        raise ValueError(f"rated torque {rated_Nm!r} N m must be a finite number > 0")
    if isinstance(points, bool) or not isinstance(points, int) or points < 5:
        raise ValueError(f"points {points!r} must be an integer >= 5")
    if not math.isfinite(theta_in_deg):
        raise ValueError(f"theta_in_deg {theta_in_deg!r} must be finite")
    g = ReducerGeometry(case)
    s = QuasiStaticSolver(g, make_contacts(g, solver), law)
    mu_p = model_value(s.model, "pin_friction_coefficient")
    mu_b = model_value(s.model, "bearing_friction_coefficient")
    th = np.array([math.radians(theta_in_deg)])
    sides, budget_acc, crank_acc, warnings, preloaded = _sweep_levels(s, th, rated)
    # the housing ring in series (rvdyn.housing; elastic supports only, as the other supports): its wind-up
    # along each side's levels, added to the equilibrium's torsion in the sense of the torque
    house = {sign: _housing_windup(s, g, sides[sign]) for sign in (1, -1)}
    if s.supports is not None:
        budget_acc["housing"] = [float(house[sign][-1]) * ARCSEC_PER_RAD for sign in (1, -1)]
    el_theta, el_tau, el_fric, el_pins, el_house = _elastic_points(s, g, sides, house, mu_p, mu_b)
    curve = _sweep_curve(el_theta, el_tau, el_fric, rated, points)
    elastic = pd.DataFrame({"torque_Nm": el_tau / 1e3, "torsion_arcmin": el_theta * ARCSEC_PER_RAD / 60.0,
                            "friction_torque_Nm": el_fric / 1e3, "pins_in_contact": el_pins,
                            "housing_arcmin": el_house * ARCSEC_PER_RAD / 60.0})
    rig, lost_motion, width0 = _curve_figures(curve, rated)
    backlash = _backlash_arcmin(s, sides, preloaded)
    budget = {k: float(np.mean(v)) for k, v in budget_acc.items()}
    figures: dict[str, Any] = {
        "torsional_rigidity_Nm_per_arcmin": float(rig),
        "lost_motion_arcmin": float(lost_motion),
        "backlash_arcmin": float(backlash),
        "hysteresis_loss_arcmin": float(width0),
        "rated_torque_Nm": rated,
        "budget": budget,
        "budget_total_arcsec": float(sum(budget.values())),
        "budget_per_crank": {k: [float(x) for x in np.mean(v, axis=0)] for k, v in crank_acc.items()},
        "pins_in_contact": {f"{f:g}": int(sol.n_pin_contacts[0]) for f, (_, sol) in zip((0.0,) + LEVELS, sides[1])},
        "contact": s.law.kind,
        "supports": "elastic" if s.supports is not None else "rigid",
        "pin_friction_coefficient": mu_p,
        "bearing_friction_coefficient": mu_b,
        "input_angle_deg": float(theta_in_deg),
        "preloaded": preloaded,
        "solver": solver,
        "datasheet_class": DATASHEET,
        "warnings": warnings,
    }
    return StiffnessResult(curve=curve, elastic=elastic, figures=figures)


def _sweep_levels(s: QuasiStaticSolver, th: np.ndarray, rated: float
                  ) -> tuple[dict[int, list], dict[str, list[float]], dict[str, list[np.ndarray]], list[str], bool]:
    """The equilibria of the elastic curve at the locked input angle ``th`` (rad, (1,)): per side (+1, -1) the
    rows ``(torque N m, Solution)`` at zero torque and at each of ``LEVELS`` times ``rated`` (N m); the wind-up
    parts at rated torque (part -> arcsec per side, and per crank), the solves' warnings and whether the case
    is preloaded (:func:`_zero_torque`)."""
    sides = {}
    budget_acc: dict[str, list[float]] = {}
    crank_acc: dict[str, list[np.ndarray]] = {}
    warnings: list[str] = []
    preloaded = False
    for sign in (1, -1):
        rows = []
        for f in (0.0,) + LEVELS:
            torque = f * rated * sign
            if f == 0.0:
                sol, pre = _zero_torque(s, th, -sign)
                preloaded |= pre
                if pre:                              # the elastic point under the vanishing load, at its torque
                    torque = sign * ContactLaw.RIGID_LOAD_NMM / 1e3
            else:
                sol = s.solve(th, direction=-sign, load_Nm=f * rated)
            warnings += [w for w in sol.warnings if w not in warnings]
            rows.append((torque, sol))
            if f == 1.0:
                for k, v in sol.parts_rad.items():
                    budget_acc.setdefault(k, []).append(float(v[0]) * ARCSEC_PER_RAD)
                for k, v in sol.crank_parts_rad.items():
                    crank_acc.setdefault(k, []).append(np.asarray(v[0], dtype=float) * ARCSEC_PER_RAD)
        sides[sign] = rows
    return sides, budget_acc, crank_acc, warnings, preloaded


def _elastic_points(s: QuasiStaticSolver, g: ReducerGeometry, sides: dict, house: dict, mu_p: float,
                    mu_b: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The elastic curve's points of both sides in the order of torsion (then torque): torsion (rad, the housing's
    wind-up ``house`` included), torque and Coulomb friction torque (N mm), pin contacts, housing wind-up (rad)."""
    el_theta, el_tau, el_fric, el_pins, el_house = [], [], [], [], []
    for sign in (-1, 1):
        rows = sides[sign]
        theta = np.array([sol.te_rad[0] for _, sol in rows]) + sign * house[sign]
        tf = _friction_torque(s, g, rows, theta, mu_p, mu_b)
        for i in np.argsort(theta):
            el_theta.append(theta[i])
            el_tau.append(rows[i][0] * 1e3)
            el_fric.append(tf[i])
            el_pins.append(int(rows[i][1].n_pin_contacts[0]))
            el_house.append(sign * house[sign][i])
    el_theta = np.array(el_theta)
    el_tau = np.array(el_tau)
    el_fric = np.array(el_fric)
    el_pins = np.array(el_pins)
    el_house = np.array(el_house)
    o = np.lexsort((el_tau, el_theta))
    return el_theta[o], el_tau[o], el_fric[o], el_pins[o], el_house[o]


def _sweep_curve(el_theta: np.ndarray, el_tau: np.ndarray, el_fric: np.ndarray, rated: float,
                 points: int) -> pd.DataFrame:
    """The hysteresis curve of the torque sweep -rated -> +rated -> -rated (``rated`` N m) from the elastic
    points (torsion rad, torque and friction torque N mm): the output moves only when the torque leaves the
    friction band (module docstring), ``points`` evenly spaced torques per branch plus the elastic levels."""
    U = np.maximum.accumulate(el_tau + el_fric)                                  # loading branch tau(theta)
    D = np.maximum.accumulate(el_tau - el_fric)                                  # unloading branch
    R = rated * 1e3
    # each branch visits the evenly spaced torques and every level of the elastic curve (so the datasheet
    # points +-3 % and +-100 % are samples, not interpolations)
    lv = np.array(LEVELS) * R
    up = np.unique(np.concatenate([np.linspace(-R, R, points), lv, -lv, [0.0]]))
    path = np.concatenate([up, up[::-1]])                # the turning point +rated ends one branch, starts the next
    branch = ["load"] * up.size + ["unload"] * up.size
    theta = _branch_inverse(el_theta, D, -R, up=False)
    out = []
    for tau in path:
        up_t = _branch_inverse(el_theta, U, tau, up=True)
        dn_t = _branch_inverse(el_theta, D, tau, up=False)
        theta = min(max(theta, up_t), dn_t) if up_t <= dn_t else up_t
        out.append(theta)
    # the unloading branch from +rated is the first branch's return; the widths are read on the load branch
    # of the complete cycle (-rated -> +rated after an unloading from +rated)
    return pd.DataFrame({"torque_Nm": path / 1e3, "torsion_arcmin": np.array(out) * ARCSEC_PER_RAD / 60.0,
                         "branch": branch})


def _curve_figures(curve: pd.DataFrame, rated: float) -> tuple[float, float, float]:
    """Torsional rigidity (N m/arcmin: the mid-curve's secant between 3 % and 100 % of ``rated`` N m, mean of
    both sides), lost motion (arcmin, between the mid-curve at +-3 %) and the curve's width at zero torque (arcmin)."""
    lm_plus, _ = _mid_width(curve, LOST_MOTION_FRACTION * rated)
    lm_minus, _ = _mid_width(curve, -LOST_MOTION_FRACTION * rated)
    _, width0 = _mid_width(curve, 0.0)
    m_r_plus, _ = _mid_width(curve, rated)
    m_r_minus, _ = _mid_width(curve, -rated)
    b = (1.0 - LOST_MOTION_FRACTION) * rated
    rig = 0.5 * (b / (m_r_plus - lm_plus) + b / (lm_minus - m_r_minus))
    return rig, lm_plus - lm_minus, width0


def _backlash_arcmin(s: QuasiStaticSolver, sides: dict, preloaded: bool) -> float:
    """The geometric play at zero torque (arcmin): TE(-1) - TE(+1) of the rigid limit's zero-torque rows."""
    zero = sides[1][0][1], sides[-1][0][1]                                     # the f = 0 rows
    # a preloaded case has no play (the rigid limit found an interference): backlash 0; a play within the two
    # solves' convergence (each to solver_angle_rad of output angle) is not resolved: backlash 0, not rounding
    play_rad = zero[0].te_rad[0] - zero[1].te_rad[0]
    resolved = abs(play_rad) > 2.0 * s.tol.solver_angle_rad
    return play_rad * ARCSEC_PER_RAD / 60.0 if resolved and not preloaded else 0.0


def _zero_torque(s: QuasiStaticSolver, th: np.ndarray, direction: int):
    """The curve's zero-torque point in one direction and whether the case is preloaded.

    The rigid limit (the end of the geometric play, under the vanishing load of 1 N mm); a case whose errors
    make an interference the rigid limit cannot resolve has no play: its parts are preloaded, and the point is
    the elastic equilibrium under the same vanishing load, in which the preload's normal forces remain (they
    keep the friction band open at zero torque, docs/physics.md section 9)."""
    try:
        return s.solve(th, direction=direction, load_Nm=0.0), False
    except InterferenceError:
        if s.law.rigid:
            raise
        return s.solve(th, direction=direction, load_Nm=ContactLaw.RIGID_LOAD_NMM / 1e3), True


def _housing_windup(s: QuasiStaticSolver, g: ReducerGeometry, rows) -> np.ndarray:
    """Output wind-up (rad, >= 0) of the housing ring at each level of one side (rows ordered by |torque|), the
    incremental unit-load sum of rvdyn.housing over the pin forces of the equilibrium; zeros without elastic
    supports (the impact law and rigid supports keep a rigid housing)."""
    n = len(rows)
    if s.supports is None:
        return np.zeros(n)
    d = g.design
    hc = np.mean(g.pin_centers, axis=0)                                         # the housing's centre
    rel = g.pin_centers - hc
    C = housing.housing_compliance(d, np.arctan2(rel[:, 1], rel[:, 0]))
    loads, torques = [], []
    for torque, sol in rows:
        if sol.pin_force_N is None:                                             # the rigid limit: no force
            loads.append(np.zeros(2 * d.z_pins))
        else:
            cen, _ = g.disc_poses(sol.theta_out, sol.psi)
            F = housing.pin_force_vectors(g.pin_centers, hc, cen[0], sol.pin_force_N[0], d.z_pins, d.z_disc)
            loads.append(housing.polar_components(g.pin_centers, hc, F))
        torques.append(abs(torque) * 1e3)
    return housing.incremental_windup(C, loads, np.array(torques))


def _friction_torque(s: QuasiStaticSolver, g: ReducerGeometry, rows, theta: np.ndarray, mu_p: float,
                     mu_b: float) -> np.ndarray:
    """Coulomb friction torque reflected to the output (N mm) at each level of one side of the curve.

    Slip rates are differences along the side's own levels (the output deflection is the parameter)."""
    n = len(rows)
    to = np.array([sol.theta_out[0] for _, sol in rows])
    ps = np.array([sol.psi[0] for _, sol in rows])                              # (n, nc)
    p, t0 = g.pins_in_profile_frames(to, ps)
    arc = np.empty((n, s.nd, s.zp))
    for k in range(s.nd):
        prof = g.profiles[k]
        t = prof.foot_point(p[:, k].reshape(-1, 2), t0[:, k].ravel()).reshape(n, s.zp)
        # arc length along the boundary from the ideal foot point (fine: the slips are micrometres)
        arc[:, k] = prof.boundary_speed(t) * (t - t0[:, k])
    _, ang = g.disc_poses(to, ps)                                               # (n, nd)
    dth = np.gradient(theta) if n > 1 else np.ones(1)
    dth = np.where(np.abs(dth) > 0, dth, np.inf)
    slip = np.abs(np.gradient(arc, axis=0) / dth[:, None, None])
    rel_cam = np.abs(np.gradient(ps[:, None, :] - ang[:, :, None], axis=0) / dth[:, None, None])   # (n, nd, nc)
    rel_journal = np.abs(np.gradient(ps - to[:, None], axis=0) / dth[:, None])
    sup = s.supports if s.supports is not None else Supports.from_design(g.design)
    tf = np.zeros(n)
    for i, (_, sol) in enumerate(rows):
        if sol.pin_force_N is None:
            continue
        tf[i] += mu_p * float((sol.pin_force_N[0] * slip[i]).sum())
        if sol.cam_force_N is not None:
            cam, journal = sup.friction_arms(sol.cam_force_N[:1])                # (1, nd, nc), (1, nc)
            tf[i] += mu_b * float((cam[0] * rel_cam[i]).sum() + (journal[0] * rel_journal[i]).sum())
    return tf


def write_curve(res: StiffnessResult, path: str | Path) -> Path:
    """Write the sweep (torque_Nm, torsion_arcmin, branch) atomically."""
    return write_table_atomic(res.curve, path)
