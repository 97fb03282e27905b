"""The closed loop: residual -> missing effect -> model update -> residual again.

The loop is built in stages, one module each: :mod:`rvcalib.model` (the model of the dataset),
:mod:`rvcalib.screening`, :mod:`rvcalib.fitting`, :mod:`rvcalib.selection` (the policy) and
:mod:`rvcalib.results` (typed candidate records and the reported result); this module runs them.

Algorithm (:func:`calibrate`)
-----------------------------
0. The residual of every run against the model built from its declared errors only
   (:mod:`rvcalib.forward`).
1. Screening signatures: for every candidate of :mod:`rvcalib.effects` the change of the model TE
   when the candidate is set to its typical size (both signs where the sign matters; four
   directions for the eccentricities in rotating frames), solved through rvdyn on the screening
   grid for every run condition, at the declared model. The screening grid resolves every order
   that matters for the dataset's reducer (1, Zc, Zp, their doubles, the input orders N - 1, N,
   N + 1 and neighbours) without aliasing and is a multiple of the pin count
   (:func:`rvcalib.orders.screen_grid`; 280 points for the paper's reducer). They are solved once and reused in every iteration; pin
   instances and the direction of the pin-circle offset and ovality are the solved signature
   rotated by whole pin pitches / grid steps (rotational symmetry of the pins; exact for a
   symmetric declared model, a screening approximation otherwise). Measurement effects are
   analytic.
2. Ranking: each candidate's signature (piecewise linear in its parameter: one secant per sign or
   quadrant) is fitted to the current residual at the coarse points; the fraction of the residual
   sum of squares it explains ranks it. The best harmonic-only model (one order of the output
   angle, a constant, or a direction-signed constant, common to all runs) is ranked beside.
3. Validation of the ranking: the ``top_k`` candidates are re-fitted through the full nonlinear
   model at the current state (``scipy.optimize.least_squares`` on the coarse grid, rvdyn
   re-solved at each trial value), because the contact model is strongly nonlinear (one-sided
   contacts: a +10 um and a -10 um error do not give opposite TE).
4. Decision: the best physical candidate is added if it passes both the F test on the residual
   sum of squares (p below ``alpha`` / the number of hypotheses screened: Bonferroni over every
   candidate instance and harmonic order) and the BIC (it must lower it), and if the best
   harmonic-only model is not clearly better (BIC lower by more than 2). If the harmonic-only
   model is better, what is left is reported as *unexplained* (its order and size) and absorbed by
   a labelled empirical harmonic term; it is never named as a physical effect.
5. Estimation: all added parameters are re-fitted jointly through the full nonlinear model
   solved exactly at every reading (``least_squares``; empirical terms are projected out linearly) and
   the F test and BIC are confirmed on all samples.
   With ``joint`` (default) every step that would add a term is first put to the joint selection
   of :mod:`rvcalib.joint` (a best subset of a shortlist re-solved at the current state, with
   swaps), which replaces the greedy choice when it differs and is confirmed.
6. Repeat until nothing passes; then confidence intervals from the Jacobian (forward differences)
   and the residual variance, widened by ``sqrt((1 + rho) / (1 - rho))`` for a lag-1 residual
   autocorrelation ``rho > 0`` (the residual is then not white and the plain interval too narrow).
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np
from threadpoolctl import threadpool_limits

from rvcad.errors import Case
from rvdyn.friction import friction_arms

from rvcalib.causes import attach_equivalents, reducer_case
from rvcalib.dataset import MeasuredDataset
from rvcalib.forward import ModelEvaluationError, cache_stats, forward_runner
from rvcalib.lsq import bic, ftest, projector
from rvcalib.residual import Diagnostics, diagnose, structured_noise
from rvcalib.results import (Active, CalibrationResult, Candidate, EmpiricalTerm, FittedEffect, HarmonicCandidate,
                             Unexplained, Validated)
from rvcalib.groups import Groups

__all__ = ["Calibrator", "calibrate", "CalibrationResult", "FittedEffect", "Unexplained", "EmpiricalTerm",
           "Active", "Candidate", "HarmonicCandidate", "Validated"]

#: A residual trend over a record is reported when its t value exceeds RAMP_T and its size exceeds
#: RAMP_NOISE_FACTOR times the noise (see :func:`rvcalib.residual.ramp_fit`).
RAMP_T = 6.0
RAMP_NOISE_FACTOR = 3.0

#: Margin (BIC units) by which a harmonic-only model must beat the best physical candidate before
#: the residual is called unexplained (a tie goes to the physical effect).
HARMONIC_BIC_MARGIN = 2.0

#: Joint steps at the term limit that may only swap members (each must lower the BIC on all samples).
MAX_SWAP_STEPS = 2


class Calibrator(Groups):
    """The loop on one dataset (see the module docstring and :class:`rvcalib.model.LoopModel` for the
    parameters)."""

    def run(self) -> CalibrationResult:
        """Run the loop and return the result."""
        t_start = self.t_start = time.perf_counter()
        try:
            r0 = [y - p for y, p in zip(self.y, self.predict([]))]
        except ModelEvaluationError as exc:
            raise ValueError(f"the declared errors of the dataset cannot be evaluated by rvdyn: {exc}") from None
        before = diagnose(self.ds, r0)
        self.log(f"declared model: residual RMS {before.rms:.4g} arcsec over {self.n} samples")
        self.screening_signatures()
        iterations: list[dict] = []
        r_full = self.refresh_state()
        n_hyp = len(self.lib) + len(self.harmonic_candidates())
        self.thr = thr = self.alpha / n_hyp
        it = 0
        tried: set[str] = set()
        self.stopped_by = "nothing more passes the F test and the BIC"
        dec = ""
        swap_only = False       # at the term limit: a joint step may only swap members
        swaps_left = MAX_SWAP_STEPS
        self._replaced_at: set = set()   # model states at which the replacement refit was tried
        self._instances_at: set = set()  # model states at which the instance check was made
        self._lookalike_at: set = set()  # model states at which the look-alike refit was made
        self._dropswap_at: set = set()   # model states at which the drop-swap refit was tried
        self._pinscan_at: set = set()    # model states at which every pin's instance was solved (the pin scan)
        self._harmonic_checked_at: set = set()  # states checked before a harmonic entered (greedy step)
        eliminated = False      # the backward elimination ran on the present model (nothing changed since)
        while True:
            swap_only = False
            if len(self.active) + len(self.empirical) >= self.max_terms:
                # at the term limit, first free the terms the joint fit no longer needs (stand-ins that
                # later effects made redundant), then allow swaps; stop only when neither helps. An
                # empirical term that the effects found since made insignificant goes first (the test the
                # loop applies at its end; seed 2: a direction-signed order-40 harmonic at p 0.52 held the
                # slot the sun eccentricity needed)
                if self.empirical and not self.over_budget():
                    emp_before = [t.label for t in self.empirical]
                    self._drop_empirical(iterations)
                    if len(self.empirical) < len(emp_before):
                        r_full = self.refresh_state()
                        gone_e = [lab for lab in emp_before if lab not in {t.label for t in self.empirical}]
                        self.log(f"at the term limit: removed {', '.join(gone_e)} (no longer significant; RMS "
                                 f"{math.sqrt(self.rss_full / self.n):.4g} arcsec)")
                        continue
                if self.active and not eliminated and not self.over_budget():
                    r_lim, _ = self.full_residual(self._pairs(), self.empirical)
                    weak = self.removal_candidates()
                    gone = self._backward([a.effect for a in self.active], np.zeros(0), np.zeros((0, 0)),
                                          float(r_lim @ r_lim), include_last=True, only=weak) if weak else []
                    eliminated = True
                    if gone:
                        r_full = self.refresh_state()
                        iterations.append({"iteration": it + 1, "decision": "at the term limit: removed "
                                           + ", ".join(gone) + " (not needed by the joint fit)"})
                        self.log(f"at the term limit: removed {', '.join(gone)} (RMS "
                                 f"{math.sqrt(self.rss_full / self.n):.4g} arcsec)")
                        continue
                if self.joint and swaps_left > 0:
                    swap_only = True
                    swaps_left -= 1
                else:
                    sw = self.replacement_before_stop(it + 1, iterations)
                    if sw:
                        r_full, self.emp_coef = self.full_residual(self._pairs(), self.empirical)
                        eliminated, swaps_left = False, MAX_SWAP_STEPS
                        continue
                    self.stopped_by = (f"the term limit (max_terms = {self.max_terms}) stopped the search: the "
                                       "residual may hold more that a larger limit would name")
                    break
            if self.over_budget():
                self.stopped_by = self.budget_stop("between iterations")
                break
            it += 1
            t_it = time.perf_counter()
            names_before = {a.effect.name for a in self.active}
            if self.rescreen_every and self.rescreen_due >= self.rescreen_every:
                n_sol = self.solve_signatures([e for e in self.lib.templates() if not e.expensive], self._pairs())
                self.rescreen_due = 0
                self.log(f"screening signatures re-solved at the current state ({n_sol} solves) in "
                         f"{time.perf_counter() - t_it:.1f} s")
            p_cur = self._p_cur()
            # the residual at the readings (the model solved there) taken to the coarse grid: where the
            # readings are off the grid only this smooth remainder is interpolated, not the TE's kinks
            Ec = self._emp_matrix(self.empirical, coarse=True)
            rc_raw = self.coarse_residual()
            rc_cat = np.concatenate(rc_raw)
            Pc = projector(Ec)
            rc = Pc(rc_cat)
            rss0c = float(rc @ rc)
            bic0 = bic(rss0c, self.nc, p_cur)
            self._ensure_expensive(rc, Pc)
            ranking = [d for d in self.rank(rc_cat, Ec, r_full) if d.effect.name not in tried]
            harms = self.harmonic_rank(rc, Pc)
            ranking = self.lookahead(ranking, rc)
            self._last_ranking = ranking
            log: dict[str, Any] = {"iteration": it, "rms_arcsec": math.sqrt(self.rss_full / self.n),
                                   "n_coarse": self.nc, "hypotheses": n_hyp, "threshold_p": thr,
                                   "ranking": [{"name": d.effect.name, "explained_fraction": d.explained,
                                                "pair_explained_fraction": d.pair_explained,
                                                "partner": d.partner,
                                                "estimate": np.asarray(d.p).tolist()} for d in ranking[:10]]}

            def tests(explained: float, k: int, extra: int = 0) -> tuple[float, float, float]:
                rss1 = rss0c * max(1.0 - explained, 1e-12)
                F, pv = ftest(rss0c, rss1, k, self.nc, p_cur + k + extra)
                return F, pv, bic(rss1, self.nc, p_cur + k + extra) - bic0

            refined = self._validate(ranking, rc_raw, Ec, lambda e: tests(e, 1)[0], thr, p_cur)
            log["seconds_validation"] = time.perf_counter() - t_it
            if self.over_budget():  # nothing is changed by this iteration: its choice would not be refitted
                self.stopped_by = self.budget_stop(f"in iteration {it} after the validation")
                log["decision"] = "stop: " + self.stopped_by
                log["seconds"] = time.perf_counter() - t_it
                iterations.append(log)
                break
            log["validated"] = [{"name": d.effect.name, "explained_fraction": d.explained,
                                 "pair_explained_fraction": d.pair, "partner": d.partner,
                                 "estimate": np.asarray(d.p).tolist()} for d in refined]
            best = refined[0] if refined else None
            hbest = harms[0] if harms else None
            Fp, pp, dbp = tests(best.explained, best.effect.n_params) if best else (0.0, 1.0, math.inf)
            Fh, ph, dbh = tests(hbest.explained, hbest.term.n_cols) if hbest else (0.0, 1.0, math.inf)
            sig_p = pp < thr and dbp < 0
            sig_h = ph < thr and dbh < 0
            # encompassing test: does the physical candidate explain what the best harmonic-only model
            # cannot (then it is physical), or only a part of what the harmonic explains?
            phys_adds, harm_adds = True, False
            if best is not None and hbest is not None and best.cols is not None:
                A = np.column_stack([best.cols, hbest.cols])
                cj, *_ = np.linalg.lstsq(A, rc, rcond=None)
                rss_j = float(np.sum((rc - A @ cj) ** 2))
                kp, kh = best.effect.n_params, hbest.term.n_cols
                # every sum of squares here on the screening grid (a measurement effect's explained
                # fraction is measured on all samples, so its screening-grid fit is recomputed)
                cp, *_ = np.linalg.lstsq(best.cols, rc, rcond=None)
                rss_p_lin = float(np.sum((rc - best.cols @ cp) ** 2))
                rss_p = rss_p_lin if best.effect.family == "measurement" else \
                    min(rss_p_lin, rss0c * (1.0 - best.explained))
                dof = max(1, self.nc - p_cur - kp - kh)
                _, p_pa = ftest(hbest.rss, rss_j, kp, self.nc, p_cur + kp + kh)
                _, p_ha = ftest(rss_p, rss_j, kh, self.nc, p_cur + kp + kh)
                phys_adds, harm_adds = p_pa < thr, p_ha < thr
                log["encompassing"] = {"physical_adds_to_harmonic_p": p_pa, "harmonic_adds_to_physical_p": p_ha,
                                       "dof": dof}
            elif best is not None and hbest is not None:
                phys_adds = not (dbh < dbp - HARMONIC_BIC_MARGIN)
                harm_adds = not phys_adds
            log["physical_best"] = None if best is None else {
                "name": best.effect.name, "F": Fp, "p": pp, "delta_bic": dbp,
                "explained_fraction": best.explained}
            log["harmonic_best"] = None if hbest is None else {
                "label": hbest.term.label, "F": Fh, "p": ph, "delta_bic": dbh,
                "explained_fraction": hbest.explained}
            # a constant (or direction-signed constant) that each adds to the other with the physical
            # candidate goes first when it is clearly better by BIC: many library effects (pin circle
            # diameter, pin radius, disc phase, clearances) shift the whole curve, so a constant such as
            # an encoder zero offset is otherwise absorbed by a mixture of them. Harmonics keep the rule
            # above (physical first when it adds), as physical signatures span several orders.
            harm_first = (sig_h and harm_adds and hbest.term.kind != "harmonic"
                          and dbh < dbp - HARMONIC_BIC_MARGIN)
            dec = "stop"
            if sig_p and (phys_adds or not harm_adds) and not harm_first:
                dec = "physical"
            elif sig_h:
                dec = "empirical"
            got = None
            if self.joint and dec in ("physical", "empirical"):
                got = self.joint_step(ranking, best if dec == "physical" else None,
                                      hbest.term if dec == "empirical" else None, rc, rc_cat, Ec, r_full, it, log,
                                      harms)
                if got is not None:
                    log["decision"] = got[1]
                    self.rescreen_due += 1
            elif self.joint and dec == "stop" and self.active and not self.over_budget():
                # before stopping: the added-variable test (members refitted) may find what the plain
                # screening (members held at their sizes) understates; the joint step decides and
                # confirms through the full model as for any other addition (the candidates' columns are
                # their stored signatures: re-solving every template at the state here, 10-14 s, changed
                # nothing on the realistic draws)
                av, av_log = self.added_variable_ranking(rc_cat, Ec)
                log["added_variable"] = av_log
                if av:
                    self.log(f"added-variable test before the stop: {av_log['best']} explains "
                             f"{av_log['explained_fraction']:.3f} with the members refitted (p {av_log['p']:.3g})")
                    got = self.joint_step(av, None, None, rc, rc_cat, Ec, r_full, it, log, harms)
                    if got is not None:
                        log["decision"] = "added-variable test before the stop: " + got[1]
                        self.rescreen_due += 1
                        dec = "physical"
            if got is not None and got[0]:
                eliminated = False
            sw = self.replacement_before_stop(it) if got is None and swap_only else None
            if sw:
                log["decision"] = (f"restart refit at the term limit: {sw[1]}" if sw[0] == "restart" else
                                   f"instance or replacement refit at the term limit: {sw[1]} in place of {sw[0]}")
                eliminated, swaps_left = False, MAX_SWAP_STEPS
                # the model changed: the search goes on from it (an iteration whose screening found nothing,
                # dec "stop", ended the loop here without the checks before the stop at the new state;
                # realistic seed 2: a restart at the term limit, then the final pair check found the pin
                # circle diameter worth 115 noise variances that the look-alike refit would have added)
                dec = "physical"
            elif got is None and swap_only:
                self.stopped_by = (f"the term limit (max_terms = {self.max_terms}) stopped the search (no swap "
                                   "at the limit improves the model): the residual may hold more that a larger "
                                   "limit would name")
                log["decision"] = "stop: " + self.stopped_by
                dec = "stop"
            elif got is None and dec in ("physical", "empirical") and self.over_budget():
                self.stopped_by = self.budget_stop(f"in iteration {it} before the refit")
                log["decision"] = "stop: " + self.stopped_by
                dec = "stop"
            elif got is None and dec == "physical":
                ok, msg = self._add_physical(best, ranking, r_full, it, log, harms)
                self.rescreen_due += int(ok)
                eliminated = eliminated and not ok
                log["decision"] = msg
                if not ok:
                    tried.add(best.effect.name)
                    dec = "retry" if len(tried) < 3 else "stop"
            elif got is None and dec == "empirical":
                phys = self._physical_before_harmonic(it, log, rc, rc_cat, Ec, r_full, harms)
                if phys:
                    log["decision"] = f"before {hbest.term.label}: {phys}"
                    self.log(log["decision"] + f" (RMS {math.sqrt(self.rss_full / self.n):.4g} arcsec)")
                    eliminated = False
                    dec = "physical"
                else:
                    ok, msg = self._add_empirical(hbest.term, it, log)
                    eliminated = eliminated and not ok
                    log["decision"] = msg
                    if not ok:
                        dec = "stop"
            elif got is None:
                change = self._refits_before_stop(it)
                if change:
                    log["decision"] = f"{change[0]} before the stop: {change[1]}"
                    if change[0] in ("look-alike refit", "drop-swap refit"):
                        self.log(log["decision"] + f" (RMS {math.sqrt(self.rss_full / self.n):.4g} arcsec)")
                    eliminated = False
                    dec = "physical"
                else:
                    log["decision"] = "stop: no candidate passes the F test and the BIC"
            r_full = self.refresh_state()
            entered = {a.effect.name for a in self.active} - names_before
            if self.joint and entered and not self.over_budget():
                # the instance of a family (which pin) is chosen by the refit too (rvcalib.swaps.SwapTrials.sibling_refit)
                rc_new = np.concatenate(self.coarse_residual())
                swapped = self.sibling_refit(entered, rc_new)
                if swapped:
                    log["sibling_refit"] = [{"replaced": o, "by": n} for o, n in swapped]
                    log["decision"] = log.get("decision", "") + "; refitted in place of " + ", ".join(
                        f"{o}: {n}" for o, n in swapped)
                    r_full = self.refresh_state()
            log["seconds"] = time.perf_counter() - t_it
            iterations.append(log)
            self.log(f"iteration {it}: {log['decision']} (RMS {math.sqrt(self.rss_full / self.n):.4g} arcsec, "
                     f"{log['seconds']:.1f} s)")
            if dec == "stop":
                break
        if self.active and not eliminated:
            r_full, _ = self.full_residual(self._pairs(), self.empirical)
            removed = self._backward([a.effect for a in self.active], np.zeros(0), np.zeros((0, 0)),
                                     float(r_full @ r_full), include_last=True)
            if removed:
                iterations.append({"iteration": len(iterations) + 1,
                                   "decision": "removed " + ", ".join(removed) + ": not needed by the final joint fit"})
        self._drop_empirical(iterations)
        return self._finish(r0, before, iterations, t_start)

    def _physical_before_harmonic(self, it: int, log: dict, rc, rc_cat, Ec, r_full, harms) -> str | None:
        """The checks the loop makes before it stops, made before a harmonic enters by the greedy step
        (physics first: an empirical term is the last resort), once per model state: the added-variable test
        (members refitted; the joint step decides), then :meth:`_refits_before_stop`. Returns what changed
        the model, or None (then the harmonic is judged as before).

        Measured (realistic seed 1, serial, 2026-11-27 machine): without it the greedy step took an order-80
        harmonic at 1.02x the noise and the planet eccentricity ended at 4.87 um (truth 2.74); with it the
        restart of three members collinear with the cam eccentricity found a fit 11.8 noise variances better
        first, the harmonic no longer passed, and every named effect came within tolerance (planet
        eccentricity 2.65 um; docs/calibration.md, "Stop 25")."""
        if not self.joint or not self.active or self.over_budget():
            return None
        key = self._state_key()
        if key in self._harmonic_checked_at:
            return None
        self._harmonic_checked_at.add(key)
        av, av_log = self.added_variable_ranking(rc_cat, Ec)
        log["added_variable_before_harmonic"] = av_log
        if av:
            got = self.joint_step(av, None, None, rc, rc_cat, Ec, r_full, it, log, harms)
            if got is not None and got[0]:
                return "added-variable test: " + got[1]
        change = self._refits_before_stop(it)
        return f"{change[0]}: {change[1]}" if change else None

    def _refits_before_stop(self, it: int) -> tuple[str, str] | None:
        """The instance check, the restart of collinear members (:mod:`rvcalib.basins`), (below the term
        limit) the look-alike refit, the drop-swap refit (:mod:`rvcalib.dropswap`) and the pin scan
        (:mod:`rvcalib.pinscan`), each once per model state: ``(check, what changed)`` of the first that changed
        the model, or None."""
        if not self.joint:
            return None
        if not self.over_budget():
            self.polish_once("the state before the checks before the stop")
        sw_i = self._instances_before_stop(it)
        if sw_i:
            return "instance refit", ", ".join(f"{n} in place of {o}" for o, n in sw_i)
        rs = self.restart_refit()
        if rs:
            return "restart refit", rs
        key = self._state_key()
        if len(self.active) + len(self.empirical) < self.max_terms and key not in self._lookalike_at:
            self._lookalike_at.add(key)
            la = self.lookalike_refit(it)
            if la:
                return "look-alike refit", f"added {la[1]} beside {la[0]}"
        if key not in self._dropswap_at:
            self._dropswap_at.add(key)
            ds = self.drop_swap_refit(it)
            if ds:
                return "drop-swap refit", f"{ds[1]} in place of {ds[0]}"
        ps = self._pin_scan_once(it)
        if ps:
            return "pin scan", f"{ps[1]} in place of {ps[0]}" if ps[0] else f"added {ps[1]}"
        return None

    def _pin_scan_once(self, it: int) -> tuple[str, str] | None:
        """The pin scan (:mod:`rvcalib.pinscan`) once per model state: ``(member, candidate)`` of a replacement,
        ``("", candidate)`` of an addition, or None."""
        key = self._state_key()
        if key in self._pinscan_at or self.over_budget():
            return None
        self._pinscan_at.add(key)
        return self.pin_scan_refit(it)

    def _instances_before_stop(self, it: int, iterations: list[dict] | None = None) -> list[tuple[str, str]]:
        """The instance check (:meth:`rvcalib.replace.ReplacementRefit.instance_refit`) once per model state
        before the loop stops; the swaps made (old, new)."""
        if not self.joint or self.over_budget():
            return []
        key = self._state_key()
        if key in self._instances_at:
            return []
        self._instances_at.add(key)
        sw = self.instance_refit()
        if not sw:
            got = self.offset_instance_refit(it)
            sw = [got] if got else []
        if not sw:
            got = self.twin_refit(it)
            sw = [got] if got else []
        if sw:  # (each check leaves the state refreshed after a change)
            msg = ", ".join(f"{n} in place of {o}" for o, n in sw)
            self.log(f"instance refit before the stop: {msg} (RMS {math.sqrt(self.rss_full / self.n):.4g} arcsec)")
            if iterations is not None:
                iterations.append({"iteration": it, "decision": f"instance refit before the stop: {msg}"})
        return sw

    def replacement_before_stop(self, it: int, iterations: list[dict] | None = None) -> tuple[str, str] | None:
        """The instance check (:meth:`_instances_before_stop`), then the replacement refit
        (:meth:`rvcalib.replace.ReplacementRefit.replacement_refit`) and when it swaps nothing the drop-swap
        refit (:mod:`rvcalib.dropswap`), then the pin scan (:mod:`rvcalib.pinscan`, replacements only), each once
        per model state before the loop stops at the term limit,
        with the restart of collinear members (:mod:`rvcalib.basins`) after the instance check; the (last)
        swap made (old, new), ``("restart", message)``, or None."""
        sw_i = self._instances_before_stop(it, iterations)
        if sw_i:
            return sw_i[-1]
        rs = self.restart_refit() if self.joint else None
        if rs:
            self.log(f"restart refit at the term limit: {rs}")
            if iterations is not None:
                iterations.append({"iteration": it, "decision": f"restart refit at the term limit: {rs}"})
            return "restart", rs
        if not self.joint or self.over_budget():
            return None
        key = self._state_key()
        if key in self._replaced_at:
            return None
        self._replaced_at.add(key)
        sw, how = self.replacement_refit(it), "replacement refit"
        if not sw and key not in self._dropswap_at:
            self._dropswap_at.add(key)
            sw, how = self.drop_swap_refit(it), "drop-swap refit"
        if not sw:
            sw, how = self._pin_scan_once(it), "pin scan"
        if sw:
            self.log(f"{how} at the term limit: {sw[1]} in place of {sw[0]} (RMS "
                     f"{math.sqrt(self.rss_full / self.n):.4g} arcsec)")
            if iterations is not None:
                iterations.append({"iteration": it, "decision": f"{how} at the term limit: {sw[1]} "
                                                                f"in place of {sw[0]}"})
        return sw

    # ------------------------------------------------------------------ wrap up
    def _friction_arms(self, fitted: list[FittedEffect], declared: dict):
        """rvdyn's Coulomb friction arms of the reducer as declared (``declared``, case JSON) at the loaded runs' mean
        load, when a compliance was found (rvcalib.causes reads it as friction too); None otherwise, or when rvdyn
        cannot solve it."""
        loads = [r.load_Nm for r in self.runs if r.load_Nm > 0]
        if not loads or not any(e.key == "torsional_compliance_arcsec_per_Nm" for e in fitted):
            return None
        try:
            return friction_arms(Case.from_dict(declared), float(np.mean(loads)),
                                 law=forward_runner().law)
        except ValueError as exc:
            self.notes.append(f"the compliance is not read as friction: {exc}")
            return None

    def _finish(self, r0, before: Diagnostics, iterations: list[dict], t_start: float) -> CalibrationResult:
        msg = self.polish_once("final state")
        if msg:
            iterations.append({"iteration": len(iterations) + 1, "decision": msg})
        fitted = self.intervals()
        fitted, final_groups = self.final_state_groups(fitted)
        self.clip_to_ranges(fitted)
        if not self.stopped_by.startswith("nothing"):
            self.notes.append(self.stopped_by)
        pairs = self._pairs()
        r_phys = [y - p for y, p in zip(self.y, self.predict(pairs))]
        r_all_cat, coef = self.full_residual(pairs, self.empirical)
        r_all = self.split(r_all_cat)
        unexplained: list[Unexplained] = []
        j = 0
        emp_iter = self._emp_info
        for t in self.empirical:
            c = coef[j:j + t.n_cols]
            j += t.n_cols
            if t.kind == "harmonic":
                amp = float(math.hypot(c[0], c[1]))
                phase = float(math.degrees(math.atan2(-c[1], c[0])))  # a cos(k th) + b sin = A cos(k th + phase)
            else:
                amp, phase = float(c[0]), None
            itn, frac = emp_iter.get(t, (0, float("nan")))
            unexplained.append(Unexplained(t.label, t.kind, t.order, amp, phase, itn, frac, t.note, t.factor, t.unit,
                                           self._per_run_size(t, r_phys), self._unexplained_candidates(t)))
        after = diagnose(self.ds, r_all)
        after_phys = diagnose(self.ds, r_phys)
        noise = structured_noise(self.ds, r_all)
        if not fitted and not unexplained:
            if after.white:
                status = "fits"
                verdict = (f"The declared model fits: no candidate effect is supported, and the residual "
                           f"({after.rms:.3g} arcsec RMS) is white noise at the noise level ({noise:.3g} arcsec).")
            else:
                status = "unexplained"
                dom = ", ".join(f"order {k} ({v:.3g} arcsec)" for k, v in after.runs[0].dominant)
                verdict = (f"No candidate effect is supported, but the residual ({after.rms:.3g} arcsec RMS) is not "
                           f"white (dominant in run {after.runs[0].run}: {dom}).")
        else:
            names = ", ".join(f.size_text() for f in fitted) or "none"
            status = "explained" if not unexplained and after.white else "unexplained"
            verdict = (f"Found {len(fitted)} effect(s): {names}. Residual RMS {before.rms:.3g} -> {after.rms:.3g} "
                       f"arcsec (noise {noise:.3g} arcsec); {'white' if after.white else 'not white'}.")
            if unexplained:
                verdict += " Unexplained (outside the library): " + ", ".join(
                    f"{u.label} {abs(u.amplitude_arcsec):.3g} arcsec" for u in unexplained) + "."
        ramps = [d for d in after.runs
                 if abs(d.ramp_t) > RAMP_T and abs(d.ramp_arcsec) > RAMP_NOISE_FACTOR * noise]
        if ramps:
            status = "unexplained"
            verdict += (" The residual ramps over the record in run(s) " + ", ".join(
                f"{d.run} ({d.ramp_arcsec:+.3g} arcsec, t {d.ramp_t:.1f})" for d in ramps)
                + ": a drift in time or an encoder scale error, not in the library; the effects found may "
                  "partly compensate it.")
        if not self.stopped_by.startswith("nothing"):
            verdict += " Stopped early: " + self.stopped_by + "."
        groups = final_groups + self.identifiability_groups(fitted, unexplained)
        declared = reducer_case(self._case(0, []))
        attach_equivalents(fitted, unexplained, self.ds.design, groups, self._friction_arms(fitted, declared))
        recommended = self.recommend_runs(groups)
        physical = [(e, p) for e, p in pairs if e.family != "measurement"]
        return CalibrationResult(self.ds, fitted, unexplained, before, after, after_phys, r0, r_all, iterations,
                                 status, verdict, noise, self.steps, time.perf_counter() - t_start,
                                 list(self.ds.notes) + self.notes, dict(cache_stats(), fits=self.fit_stats),
                                 stopped_by=self.stopped_by, groups=groups, recommended_runs=recommended,
                                 declared_case=declared,
                                 calibrated_case=reducer_case(self._case(0, physical)))


def calibrate(dataset: MeasuredDataset, steps: int | None = None, alpha: float = 0.01, max_terms: int = 6,
              top_k: int = 4, log: Callable[[str], None] | None = None,
              screen_points: int | None = None, time_budget_s: float | None = None, joint: bool = True,
              joint_new: int = 6, rescreen_every: int = 0) -> CalibrationResult:
    """Close the loop on a measured dataset (see the module docstring).

    Parameters
    ----------
    dataset : MeasuredDataset
        From :func:`rvcalib.dataset.read_dataset`.
    steps : int or None
        Requested screening grid, points per output revolution (see
        :func:`rvcalib.orders.screen_grid`; a request that would alias the orders that matter, or is
        larger than needed, screens on the smallest grid that resolves them, with a note). The model
        is solved exactly at every reading whatever the grid.
    alpha : float
        Family-wise significance level.
    max_terms : int
        Largest number of effects plus empirical terms.
    top_k : int
        Candidates validated through the nonlinear model per iteration.
    log : callable or None
        Progress messages.
    screen_points : int or None
        An explicit screening grid (refused unless it resolves the orders that matter).
    time_budget_s : float or None
        Stop adding terms after this many seconds (the verdict and ``stopped_by`` say so).
    joint : bool
        Joint selection over a shortlist at the current state (:mod:`rvcalib.joint`); False: greedy
        forward selection only (the loop before issue 10 item 1).
    joint_new : int
        New candidates in the joint shortlist (one per family).
    rescreen_every : int
        Re-solve the whole library's screening signatures at the current state after every this many
        accepted joint changes (0: only the shortlist's families, at every joint step).

    Returns
    -------
    CalibrationResult
    """
    cal = Calibrator(dataset, steps=steps, alpha=alpha, max_terms=max_terms, top_k=top_k, log=log,
                     screen_points=screen_points, time_budget_s=time_budget_s, joint=joint, joint_new=joint_new,
                     rescreen_every=rescreen_every)
    # one BLAS thread: the loop's linear algebra is on matrices of a few hundred to a few thousand rows,
    # where BLAS threads cost more than they give, and on a busy machine they stall (measured under a load
    # of 5 on 2 cores: numpy.linalg.pinv of 372 x 279, the resampling of one run, 6.8 s wall / 2.2 s CPU
    # with the default threads, 0.26 s / 0.04 s with one)
    with threadpool_limits(limits=1, user_api="blas"):
        return cal.run()
