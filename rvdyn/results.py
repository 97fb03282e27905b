"""Results of the quasi-static solver: the :class:`Solution` of a solve, the interference check and the
finishing of a converged state (forces, unit-load budget, pressures; a mixin of
:class:`rvdyn.solver.QuasiStaticSolver`, state lives on the solver). docs/physics.md, sections 5, 8 and 11.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0

#: Penetration (mm) beyond which an elastic solution is refused as an unresolvable interference.
#: 0.1 mm covers the paper's largest pin pitch error (0.06 deg moves a pin 67 um into a zero-backlash
#: disc; the equilibrium needs 50-59 um); a Hertz-type law at that depth is an extrapolation, which the
#: report states. Both contact providers measure any depth (fcl: the outline window is a surface).
MAX_ELASTIC_PENETRATION_MM = 0.1


class InterferenceError(ValueError):
    """The case's interference cannot be resolved at the given stiffness."""


@dataclass
class Solution:
    """Equilibrium states for a set of input angles.

    Attributes
    ----------
    theta_in, theta_out : (N,) rad
    psi : (N, n_cranks) rad
    te_rad : (N,) rad, ``theta_out - theta_in / ratio`` including the torsional wind-up option
    n_contacts : (N,) int, contacts carrying load (penetration > 0)
    peak_force_N : (N,) N, largest contact force (NaN in the rigid limit)
    max_penetration_mm : (N,) mm
    stage1_force_N : (N, n_cranks) N (NaN in the rigid limit)
    iterations : int, outer iterations used (largest over the chunks)
    parts_rad : dict of (N,) rad
        Output wind-up of each part kind at the step (unit-load method, section 8 of docs/physics.md):
        ``pins`` and ``gears`` (contact deflections), and with the physical law and elastic supports
        ``cam_bearings``, ``journal_bearings``, ``crank_bending``, ``crank_torsion`` (the supports inside
        the equilibrium, rvdyn.support_eq), ``pin_seats`` (the pins in their housing grooves, in series with
        the pin-disc contacts inside the equilibrium) and ``carrier`` (the end plate turning against the
        output flange through the pillars, inside the equilibrium), ``torsional_compliance`` (the lumped
        ``model.torsional_compliance_arcsec_per_Nm`` times the torque, when it is set); empty in the rigid limit and
        with the spring model of floating discs (impact law or rigid supports with a cam-bearing clearance),
        and when the solver's ``want_parts`` is False (:func:`rvdyn.te.run_te`: the TE alone).
    crank_parts_rad : dict of (N, n_cranks) rad
        The parts each crank carries, crank by crank (their sum over the cranks is the part of ``parts_rad``):
        ``gears`` (its planet's mesh), and with elastic supports ``crank_torsion``, ``cam_bearings`` (its cams on
        both discs), ``journal_bearings``, ``crank_bending`` and the bearing seats; empty where ``parts_rad``
        is. The pins, the pin seats and the carrier's pillars are common to all cranks.
    peak_pressure_MPa : (N,) MPa, largest Hertzian pin-disc contact pressure (NaN in the rigid limit)
    warnings : list of str
    pin_force_N : (N, n_discs, Zp) N or None, pin contact forces (None in the rigid limit)
    cam_force_N : (N, n_discs, n_cranks, 2) N or None, forces of the cams on the discs (fixed frame; None when
        the solver's ``want_parts`` is False)
    n_pin_contacts : (N,) int, pin-disc contacts (both discs) that touch (penetration > 0)
    """

    theta_in: np.ndarray
    theta_out: np.ndarray
    psi: np.ndarray
    te_rad: np.ndarray
    n_contacts: np.ndarray
    peak_force_N: np.ndarray
    max_penetration_mm: np.ndarray
    stage1_force_N: np.ndarray
    iterations: int = 0
    x: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    parts_rad: dict = field(default_factory=dict)
    crank_parts_rad: dict = field(default_factory=dict)
    peak_pressure_MPa: np.ndarray = field(default_factory=lambda: np.zeros(0))
    warnings: list = field(default_factory=list)
    pin_force_N: np.ndarray | None = field(default=None, repr=False)
    cam_force_N: np.ndarray | None = field(default=None, repr=False)
    n_pin_contacts: np.ndarray | None = field(default=None, repr=False)


class ResultsMixin:
    """Checks and outputs of converged states (state lives on the solver)."""

    def _unconverged(self, th, x, direction, law, load_Nm: float, change: float) -> Exception:
        """The error of a solve that did not converge: the interference that is the usual cause (an
        InterferenceError, see :meth:`_check_penetration`), else a RuntimeError."""
        try:
            self._check_penetration(th, x, direction, law, load_Nm=load_Nm)
        except InterferenceError as err:
            return err
        return RuntimeError(f"quasi-static solver did not converge in {self.tol.solver_max_iter} outer iterations "
                            f"(last change {change:.3e} mm)")

    def _finish_rows(self, th, x, direction, load_Nm, law, iters, out: dict, rows: slice) -> Solution:
        self._R_all = out["R"][rows]
        self._J_all = out["J"][rows]
        return self._finish(th, x, direction, load_Nm, self._step_law(law, out["C"][rows]), iters, out["G"][rows],
                            out["nrm"][rows])

    def _check_penetration(self, th, x, direction, law, G: np.ndarray | None = None,
                           load_Nm: float = 0.0) -> np.ndarray:
        """Gaps at the states x; raise InterferenceError if an overlap exceeds what the law allows.

        The message names the likely cause: in the rigid limit the errors (the elastic law can take a
        preload); with an elastic law and no errors the load; otherwise the errors or the load."""
        if G is None:
            G, _ = self._linearise(th, x, direction)
        pen = np.maximum(-G, 0.0).max(axis=1)
        limit = self.tol.interference_mm if law.rigid else MAX_ELASTIC_PENETRATION_MM
        if np.any(pen > limit):
            i = int(np.argmax(pen))
            head = (f"interference of {pen[i] * 1e3:.3f} um at input angle {math.degrees(th[i]):.3f} deg cannot be "
                    f"resolved at {law.describe()} (allowed {limit * 1e3:g} um): ")
            if law.rigid:
                advice = ("the parts overlap; reduce the errors that close the clearance, or solve with an elastic "
                          "contact law under load (load_Nm > 0, no --rigid) to take it as a preload")
            elif not self.geom.case.errors:
                advice = (f"the load {load_Nm:g} N m presses the contacts deeper than an elastic contact law "
                          "holds; reduce load_Nm")
            else:
                advice = (f"the parts overlap by more than an elastic contact law holds at load {load_Nm:g} N m; "
                          "reduce the errors that close the clearance (or the load)")
            raise InterferenceError(head + advice)
        return G

    def _finish(self, th, x, direction, load_Nm, law, iters, G: np.ndarray, nrm: np.ndarray) -> Solution:
        G = self._check_penetration(th, x, direction, law, G, load_Nm=load_Nm)
        delta = -G
        pen = np.maximum(delta, 0.0).max(axis=1)
        to, ps, _, _ = self._unpack(th, x)
        F = law.force(delta)
        te = to - th / self.geom.ratio
        T = load_Nm * 1e3 + self.friction_Nmm
        n1 = self.nd * self.zp
        parts: dict[str, np.ndarray] = {}
        crank_parts: dict[str, np.ndarray] = {}
        warnings: list[str] = []
        cam_F = None
        want = self.want_parts                          # the wind-up parts and cam forces (not the TE's)
        if want and not law.rigid and self.chain is None and not self.float_discs:
            cam_F = self.disc_cam_forces(th, x, F, nrm)
        if not law.rigid:
            te = te - direction * T * self.compliance_rad_per_Nmm
            if want and (not self.float_discs or self.chain is not None):
                f, dx = self._unit_load_forces(law, delta, direction, th, x)   # dF/dT, N per N mm
                work = f * np.maximum(delta, 0.0)
                parts = {"pins": work[:, :n1].sum(axis=1), "gears": work[:, n1:].sum(axis=1)}
                # each planet's mesh: its loaded and coast flank columns
                gears_j = work[:, n1:n1 + self.nc] + work[:, n1 + self.nc:]
                crank_parts["gears"] = gears_j
                if self.chain is not None:
                    parts["crank_torsion"] = self.torsion_share * parts["gears"]
                    parts["gears"] = parts["gears"] - parts["crank_torsion"]
                    crank_parts["crank_torsion"] = self.torsion_share * gears_j
                    crank_parts["gears"] = gears_j - crank_parts["crank_torsion"]
                    parts["pin_seats"] = self._seat_parts(f[:, :n1], F[:, :n1])
                    parts["pins"] = parts["pins"] - parts["pin_seats"]
                    parts.update(self._chain_parts(th, x, dx, law, crank_parts))
                    cam_F = self.chain_cam_forces(th, x, law)
                    self._raw_last = None
                if self.compliance_rad_per_Nmm > 0.0:   # the lumped compliance (model option) is a part too
                    parts["torsional_compliance"] = np.full(th.size, T * self.compliance_rad_per_Nmm)
        nan = law.rigid
        pressure = np.full(th.size, np.nan)
        if not nan:
            pressure = self._pin_pressure(F[:, :n1], law).max(axis=1)
            worst = float(np.nanmax(pressure)) if pressure.size else 0.0
            if worst > self.pressure_limit:
                warnings.append(
                    f"peak pin-disc contact pressure {worst:.0f} MPa exceeds the stated limit "
                    f"{self.pressure_limit:g} MPa (model.contact_pressure_limit_MPa): the materials would yield; "
                    "the elastic result is an extrapolation")
        return Solution(
            theta_in=th, theta_out=to + (te - (to - th / self.geom.ratio)), psi=ps, te_rad=te,
            n_contacts=(delta > (1e-12 if not law.rigid else 0.0)).sum(axis=1),
            peak_force_N=np.full(th.size, np.nan) if nan else F.max(axis=1),
            max_penetration_mm=pen,
            stage1_force_N=np.full((th.size, self.nc), np.nan) if nan else F[:, n1:n1 + self.nc],
            iterations=iters, x=x, parts_rad=parts, crank_parts_rad=crank_parts, peak_pressure_MPa=pressure,
            warnings=warnings,
            pin_force_N=None if nan else F[:, :n1].reshape(th.size, self.nd, self.zp), cam_force_N=cam_F,
            n_pin_contacts=(delta[:, :n1] > (1e-12 if not law.rigid else 0.0)).sum(axis=1))
