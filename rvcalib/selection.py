"""Selection policy of the loop: which screened candidates are refitted through the nonlinear model,
when a physical candidate is added (joint refit, F test and BIC on all samples), when an empirical
term absorbs what no candidate explains, backward elimination, and the alternatives that fit as well.
"""
from __future__ import annotations

import math
import time

import numpy as np
from scipy import stats

from rvcalib.dataset import noise_estimate
from rvcalib.effects import Effect
from rvcalib.fitting import Fitting
from rvcalib.forward import ModelEvaluationError
from rvcalib.lsq import bic, ftest, projector
from rvcalib.results import Active, Candidate, EmpiricalTerm, HarmonicCandidate, PoolMember, Validated

#: The effects in the model whose place is screened for (the weakest by their linearised removal
#: cost, the others refitted): as many as one joint step may drop.
REPLACE_MEMBERS = 2


class Selection(Fitting):
    """The selection stage of the loop (methods on the loop's model, screening and fitting)."""

    def _validate(self, ranking: list[Candidate], rc_raw, Ec, F_of, thr: float, p_cur: int) -> list[Validated]:
        """Re-fit the leading candidates through the nonlinear model (one per family; candidates
        with the signature of one already validated are skipped)."""
        refined: list[Validated] = []
        if not ranking:
            return refined
        F_crit = float(stats.f.isf(thr, 1, max(1, self.nc - p_cur - 1)))
        best_expl = max(d.explained for d in ranking)
        if F_of(best_expl) < 0.5 * F_crit:
            return refined
        seen: set[str] = set()
        fits: list[np.ndarray] = []
        for d in ranking:
            fam = d.effect.template or d.effect.name
            if fam in seen:
                continue
            if len(refined) >= self.top_k or (refined and self.over_budget()):
                break
            if d.explained < 0.5 * best_expl and (d.pair_explained or 0.0) < best_expl:
                continue
            if d.effect.expensive and d is not ranking[0]:
                continue  # expensive to solve: validated only when it ranks first
            f = d.fit
            u = None
            if f is not None and np.linalg.norm(f) > 0:
                u = f / np.linalg.norm(f)
                if any(abs(float(u @ v)) > 0.9999 for v in fits):
                    continue  # the same signature as a candidate already validated (mirror instances)
            if u is not None:
                fits.append(u)
            seen.add(fam)
            if d.effect.family == "measurement":
                expl, p = d.explained, d.p
            else:
                expl, p = self.refine_coarse(d.effect, d.p, rc_raw, Ec)
            refined.append(Validated(d.effect, expl, p, d.explained,
                                     max(d.explained if d.pair_explained is None else d.pair_explained, expl),
                                     d.partner, d.cols, d.fit, d))
        # the validated candidate of the best pair is preferred (ties within 1e-3 by its own fit)
        refined.sort(key=lambda d: (-round(d.pair, 3), -d.explained))
        if refined and refined[0].effect.expensive and self._ms(refined[0].effect) < self.m:
            # judged on a sparse subset so far: re-validate on the full coarse grid like the others
            d = refined[0]
            d.explained, d.p = self.refine_coarse(d.effect, d.p, rc_raw, Ec, ms=self.m)
            d.pair = d.explained
            refined.sort(key=lambda d: (-round(d.pair, 3), -d.explained))
        return refined

    def replacement_shortlist(self, members: list[PoolMember], rc: np.ndarray, Ec: np.ndarray | None,
                              n_each: int, seen: set[str]) -> list[Candidate]:
        """Library candidates that could take the place of the weakest effects in the model.

        The plain screening ranks each candidate against the residual alone, with every effect in the
        model held at its size. A candidate whose signature overlaps the model's (an all-pins pin
        circle diameter partly looks like a compliance, a disc phase and a carrier-hole eccentricity)
        then ranks low, while a stand-in collinear with a member (a carrier-hole eccentricity of the
        other crank beside the first) ranks high although the refit gives most of its part back to the
        members; the joint step's subset search refits the members, but only among the shortlist.
        Here the screening is partial (Frisch-Waugh), as the subset search is: for each of the
        :data:`REPLACE_MEMBERS` members whose removal costs least (``members``: the model linearised
        at the state, :meth:`rvcalib.joint.JointSelection.active_members`; the removal cost is the rise
        of the residual sum of squares on the screening grid with every other member and empirical
        term refitted), the library is ranked against that member's part plus the residual, every
        candidate's signature and that target projected orthogonal to the other members' columns and
        ``Ec``; the ``n_each`` best, one per family not in ``seen`` (updated), are returned. Measured
        on draw 1 of the realistic benchmark (impact law, final state): for the carrier-hole
        eccentricity of crank 1 the plain ranking puts itself first (71 %) and the all-pins pin circle
        diameter and pin radius at ranks 39 and 30; the partial ranking puts them first and fourth,
        and the swap they make lowers the BIC on all samples by ~120 (docs/calibration.md)."""
        if not any(m.effect is not None for m in members) or n_each <= 0:
            return []
        cand = linear_removal_costs(members, rc, Ec)
        out: list[Candidate] = []
        for cost, i, t, others in cand[:REPLACE_MEMBERS]:
            ranking = [d for d in self.rank(t, others, None) if d.effect.family != "measurement"]
            got = self.shortlist(ranking, n_each, seen)
            out += got
            self.log(f"in place of {members[i].effect.name} (linear removal cost {cost:.3g} arcsec^2 on the grid): "
                     + ", ".join(f"{d.effect.name} {d.explained:.3f}" for d in got))
        return out

    def _add_physical(self, best: Validated, ranking: list[Candidate], r_full: np.ndarray, it: int,
                      log: dict, harms: list[HarmonicCandidate] | None = None) -> tuple[bool, str]:
        """Joint nonlinear fit with the new effect, confirmation on all samples, backward elimination."""
        e = best.effect
        thr = self.thr
        p_cur = self._p_cur()
        effects = [a.effect for a in self.active] + [e]
        p0 = [a.p for a in self.active] + [np.asarray(best.p, dtype=float)]
        t_fit = time.perf_counter()
        try:
            params, rss1, x, _, jac = self.fit_full(effects, p0, self.empirical)
        except ModelEvaluationError as exc:
            log["full_fit_error"] = str(exc)
            return False, f"{e.name} could not be fitted ({exc})"
        log["seconds_full_fit"] = time.perf_counter() - t_fit
        pt = p_cur + e.n_params
        F, pv = ftest(self.rss_full, rss1, e.n_params, self.n, pt)
        dbic = bic(rss1, self.n, pt) - bic(self.rss_full, self.n, p_cur)
        log["full"] = {"F": F, "p": pv, "delta_bic": dbic, "rss": rss1}
        if not (pv < thr and dbic < 0):
            return False, f"{e.name} did not pass on all samples (p {pv:.3g}, dBIC {dbic:.3g})"
        sigma2 = self._noise2(r_full)
        alts = self._alternatives(best, ranking, sigma2, rss1, harms)
        info = {"explained_fraction": 1.0 - rss1 / self.rss_full, "F": F, "p_value": pv, "delta_bic": dbic,
                "alternatives": alts}
        for a, p in zip(self.active, params[:-1]):
            a.p = p
        self.active.append(Active(e, params[-1], it, info=info))
        msg = f"added {e.name}"
        removed = self._backward(effects, x, jac, rss1)
        if removed:
            msg += "; removed " + ", ".join(removed) + " (no longer significant)"
            log["removed"] = removed
        return True, msg

    def _backward(self, effects: list[Effect], x: np.ndarray, jac: np.ndarray, rss: float,
                  include_last: bool = False, only: set[str] | None = None) -> list[str]:
        """Drop effects that the joint fit no longer needs.

        For each effect (the newest only if ``include_last``): the residual with its parameters set to
        zero and the others kept is an upper bound of the residual without it; if even that increase
        is not significant it is removed; if the increase is significant but not overwhelmingly so
        (F below 100 times the critical value) or the estimate is small (|p| < 0.1 typical size), the
        others are refitted without it and the F test decides. ``only``: consider only these names
        (default all). Returns the removed names.

        Each removal after the first is also tested together with the ones made before it, against the
        model the elimination started from (the F test on all their parameters): one at a time, a sequence
        of removals each just below the critical F can drop a pair that entered together because only
        together they pass (realistic seed 3, stop 25: a carrier-hole and a disc-hole eccentricity added as
        a look-alike pair at RMS 0.2015 arcsec, removed one after the other at the term limit, 0.2036 = 28
        noise variances for two parameters; docs/calibration.md).
        """
        removed: list[str] = []
        rss_start, p_start, k_gone = rss, self._p_cur(), 0
        changed = True
        while changed and self.active:
            changed = False
            p_tot = self._p_cur()
            dof = max(1, self.n - p_tot)
            F_crit = float(stats.f.isf(self.thr, 1, dof))
            pool = self.active if include_last else self.active[:-1]
            if only is not None:
                pool = [a for a in pool if a.effect.name in only]
            for a in sorted(pool, key=lambda a: float(np.linalg.norm(a.p)) / a.effect.scale):
                k = a.effect.n_params
                others = [(b.effect, b.p) for b in self.active if b is not a]
                try:
                    r0, _ = self.full_residual(others, self.empirical)
                    rss_fixed = float(r0 @ r0)
                except ModelEvaluationError:
                    rss_fixed = math.inf
                F_fixed, p_fixed = ftest(rss_fixed, rss, k, self.n, p_tot)
                small = float(np.linalg.norm(a.p)) < 0.1 * a.effect.scale
                if p_fixed <= self.thr and F_fixed >= 100 * F_crit and not small:
                    continue
                keep = [b for b in self.active if b is not a]
                if p_fixed > self.thr:
                    params, rss_w = [b.p for b in keep], rss_fixed
                    if keep:
                        try:
                            params, rss_w, _, _, _ = self.fit_full([b.effect for b in keep], [b.p for b in keep],
                                                                   self.empirical)
                        except ModelEvaluationError:
                            params, rss_w = [b.p for b in keep], rss_fixed
                else:
                    try:
                        params, rss_w, _, _, _ = self.fit_full([b.effect for b in keep], [b.p for b in keep],
                                                               self.empirical) if keep else ([], rss_fixed, None, None, None)
                    except ModelEvaluationError:
                        continue
                    _, pv = ftest(rss_w, rss, k, self.n, p_tot)
                    if pv <= self.thr:
                        continue
                if k_gone and ftest(rss_w, rss_start, k_gone + k, self.n, p_start)[1] <= self.thr:
                    continue  # with the removals before it, no longer insignificant
                for b, p in zip(keep, params):
                    b.p = p
                self.active = keep
                rss = rss_w
                k_gone += k
                removed.append(a.effect.name)
                changed = True
                break
        return removed

    def _add_empirical(self, t: EmpiricalTerm, it: int, log: dict) -> tuple[bool, str]:
        """Absorb an unexplained harmonic (refitting the physical parameters with it)."""
        thr = self.thr
        p_cur = self._p_cur()
        terms = self.empirical + [t]
        effects = [a.effect for a in self.active]
        if effects:
            params, rss1, _, _, _ = self.fit_full(effects, [a.p for a in self.active], terms)
        else:
            params, rss1 = [], float(np.sum(self.full_residual([], terms)[0] ** 2))
        pt = p_cur + t.n_cols
        F, pv = ftest(self.rss_full, rss1, t.n_cols, self.n, pt)
        dbic = bic(rss1, self.n, pt) - bic(self.rss_full, self.n, p_cur)
        log["full"] = {"F": F, "p": pv, "delta_bic": dbic, "rss": rss1}
        if not (pv < thr and dbic < 0):
            return False, "stop: the harmonic term did not pass on all samples"
        for a, p in zip(self.active, params):
            a.p = p
        self.empirical.append(t)
        self._emp_info[t] = (it, 1.0 - rss1 / self.rss_full)
        return True, (f"absorbed {t.label}: no physical candidate explains it better than the harmonic-only "
                      "model (outside the library)")

    def _drop_empirical(self, iterations: list[dict]) -> None:
        """Drop empirical terms that later physical effects made insignificant (linear F test)."""
        changed = True
        while changed and self.empirical:
            changed = False
            r, _ = self.full_residual(self._pairs(), self.empirical)
            rss = float(r @ r)
            for t in list(self.empirical):
                rest = [u for u in self.empirical if u != t]
                r2, _ = self.full_residual(self._pairs(), rest)
                _, pv = ftest(float(r2 @ r2), rss, t.n_cols, self.n, self._p_cur())
                if pv > self.thr:
                    self.empirical = rest
                    self._emp_info.pop(t, None)
                    iterations.append({"iteration": len(iterations) + 1, "decision":
                                       f"removed {t.label}: no longer significant (p {pv:.3g})"})
                    changed = True
                    break

    def _noise2(self, r_full: np.ndarray) -> float:
        """Noise variance estimate (second differences of the current residual, pooled), arcsec^2."""
        parts = self.split(r_full)
        v = [noise_estimate(p) ** 2 * p.size for p in parts if p.size >= 5]
        return float(sum(v) / max(1, sum(p.size for p in parts)))

    def _alternatives(self, best: Validated, ranking: list[Candidate], sigma2: float, rss_after: float,
                      harms: list[HarmonicCandidate] | None = None) -> list[dict]:
        """Candidates (library effects and empirical terms) whose signature reproduces the winner's
        fitted signature within the noise: ``|fit_w - S_c b|^2 * n / n_coarse / sigma^2 < 3.84``
        (chi-square, 95 %). Such candidates cannot be told apart by these data (e.g. pins 20 apart,
        cam errors of crank 0 disc 1 and crank 1 disc 0, a constant offset on a single run).

        Each comes with the size it needs (``value`` in its ``unit``, signed for one-parameter effects;
        the magnitude and ``angle_deg`` for two-component ones; the coefficient for an empirical term)
        and ``rms_after_arcsec``, the RMS it would leave in the winner's place (the winner's RMS plus
        the part of its signature the alternative misses, scaled from the screening grid to all samples).
        """
        fw = best.fit
        if fw is None or sigma2 <= 0:
            return []
        out: list[dict] = []
        we = best.effect
        scale_n = self.n / self.nc

        def entry(name: str, value: float, unit: str, miss: float, angle: float | None = None) -> dict:
            d = {"name": name, "value": float(value), "unit": unit,
                 "rms_after_arcsec": float(np.sqrt(max(rss_after + miss, 0.0) / self.n))}
            if angle is not None:
                d["angle_deg"] = float(angle)
            return d

        for d in ranking:
            if d.effect.name == we.name or d.cols is None:
                continue
            if d.effect.family == "measurement" and we.family == "measurement":
                # judged on all samples
                P = projector(self._emp_matrix(self.empirical))
                Aw = np.vstack([we.basis(r.input_deg, r.output_deg) for r in self.runs])
                Ac = np.vstack([d.effect.basis(r.input_deg, r.output_deg) for r in self.runs])
                Aw = np.column_stack([P(Aw[:, k]) for k in range(Aw.shape[1])])
                Ac = np.column_stack([P(Ac[:, k]) for k in range(Ac.shape[1])])
                fwf = Aw @ np.asarray(best.p, dtype=float)
                b, *_ = np.linalg.lstsq(Ac, fwf, rcond=None)
                delta = fwf - Ac @ b
                miss = float(delta @ delta)
                if miss / sigma2 < 3.84:
                    p = np.asarray(b, dtype=float)
                    ang = d.effect.magnitude_angle(p)[1] if d.effect.polar else None
                    out.append(entry(d.effect.name, d.effect.value(p), d.effect.unit, miss, ang))
                continue
            A = d.cols
            b, *_ = np.linalg.lstsq(A, fw, rcond=None)
            delta = fw - A @ b
            miss = float(delta @ delta) * scale_n
            if miss / sigma2 < 3.84:
                p = d.to_p(b) if d.to_p is not None else np.asarray(d.p, dtype=float)
                ang = d.effect.magnitude_angle(p)[1] if d.effect.polar else None
                out.append(entry(d.effect.name, d.effect.value(p), d.effect.unit, miss, ang))
        for h in harms or []:
            b, *_ = np.linalg.lstsq(h.cols, fw, rcond=None)
            delta = fw - h.cols @ b
            miss = float(delta @ delta) * scale_n
            if miss / sigma2 < 3.84:
                val = float(np.hypot(*b)) if b.size == 2 else float(b[0])
                out.append(entry(h.term.label, val, h.term.unit, miss))
        out.sort(key=lambda x: x["rms_after_arcsec"])
        return out

    def _per_run_size(self, t: EmpiricalTerm, r_phys: list[np.ndarray]) -> list[dict]:
        """The size of an empirical term's order in each run's residual after the physical effects
        (its load and direction dependence): amplitude and phase of the order, or the mean."""
        base = EmpiricalTerm(t.kind, t.order)
        out = []
        for run, r in zip(self.runs, r_phys):
            th = np.radians(run.input_deg / self.ratio)
            A = base.columns(th, run.direction, run.load_Nm)
            c, *_ = np.linalg.lstsq(A, r, rcond=None)
            d = {"run": run.run, "load_Nm": run.load_Nm, "direction": run.direction}
            if t.kind == "harmonic":
                d["amplitude_arcsec"] = float(np.hypot(c[0], c[1]))
                d["phase_deg"] = float(np.degrees(np.arctan2(-c[1], c[0])))
            else:
                d["amplitude_arcsec"] = float(c[0] * (run.direction if t.kind == "direction_offset" else 1))
            out.append(d)
        return out

    def _unexplained_candidates(self, t: EmpiricalTerm, top: int = 3) -> list[dict]:
        """Library effects that could produce an empirical term's structure: each candidate's signature
        fitted to the term's fitted contribution on the screening grid; the ``top`` best that
        reproduce at least half of it, with the size they would need and the RMS they would leave
        in the term's place."""
        ranking = getattr(self, "_last_ranking", None) or []
        if t not in self.empirical:
            return []
        i = self.empirical.index(t)
        j = sum(u.n_cols for u in self.empirical[:i])
        th = np.radians(self.coarse_out_deg)
        E = np.vstack([t.columns(th, r.direction, r.load_Nm) for r in self.runs])
        f = E @ self.emp_coef[j:j + t.n_cols] if self.emp_coef.size >= j + t.n_cols else None
        if f is None or float(f @ f) <= 0:
            return []
        ff = float(f @ f)
        res = []
        for d in ranking:
            if d.cols is None:
                continue
            b, *_ = np.linalg.lstsq(d.cols, f, rcond=None)
            delta = f - d.cols @ b
            frac = 1.0 - float(delta @ delta) / ff
            if frac < 0.5:
                continue
            p = d.to_p(b) if d.to_p is not None else np.asarray(d.p, dtype=float)
            e = {"name": d.effect.name, "value": float(d.effect.value(p)), "unit": d.effect.unit,
                 "rms_after_arcsec": float(np.sqrt(max(self.rss_full + float(delta @ delta) * self.n / self.nc, 0.0)
                                                   / self.n)), "reproduced_fraction": frac}
            if d.effect.polar:
                e["angle_deg"] = float(d.effect.magnitude_angle(p)[1])
            res.append(e)
        res.sort(key=lambda x: x["rms_after_arcsec"])
        return res[:top]


def member_target(members: list[PoolMember], blocks: list[np.ndarray], i: int, r: np.ndarray, coef: np.ndarray,
                  col0: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Member ``i`` of a joint linear fit taken out again: its present contribution plus its fitted change plus the
    fit's residual ``r`` (what the others must explain without it), and the other blocks' columns (None when it is
    alone). ``blocks`` are the members' columns (then any empirical terms'), ``coef`` the joint fit's coefficients,
    ``col0`` each block's first column."""
    m = members[i]
    part = m.contribution if m.contribution is not None else m.cols @ np.asarray(m.active.p, dtype=float)
    t = r + m.cols @ coef[col0[i]:col0[i + 1]] + part
    others = np.column_stack([blocks[j] for j in range(len(blocks)) if j != i]) if len(blocks) > 1 else None
    return t, others


def joint_linear_fit(members: list[PoolMember], rc: np.ndarray, Ec: np.ndarray | None
                     ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """The joint linear fit of every member (``members``: the model linearised at the state) and empirical term
    (``Ec``) to the residual ``rc`` on the screening grid: ``(blocks, col0, coef, r)``, the blocks' columns (the
    members', then the terms'), each block's first column, the coefficients and the fit's residual (the arguments of
    :func:`member_target`)."""
    blocks = [m.cols for m in members] + ([Ec] if Ec is not None else [])
    X = np.column_stack(blocks)
    col0 = np.cumsum([0] + [b.shape[1] for b in blocks])
    coef, *_ = np.linalg.lstsq(X, rc, rcond=None)
    return blocks, col0, coef, rc - X @ coef


def linear_removal_costs(members: list[PoolMember], rc: np.ndarray, Ec: np.ndarray | None,
                         fit: tuple | None = None) -> list[tuple[float, int, np.ndarray, np.ndarray | None]]:
    """For each physical member (``members``: the model linearised at the state), the rise of the residual sum of
    squares on the screening grid when it is removed and every other member and empirical term (``Ec``) refitted
    linearly, lowest first: ``(cost, index, target, others)`` with ``target`` the member's part plus the residual
    of the joint fit and ``others`` the other members' and terms' columns (None when it is alone). ``fit``: the
    joint fit, :func:`joint_linear_fit` of the same arguments, when the caller has it."""
    blocks, col0, coef, r = fit if fit is not None else joint_linear_fit(members, rc, Ec)
    rss = float(r @ r)
    cand = []
    for i, m in enumerate(members):
        if m.effect is None:
            continue
        t, others = member_target(members, blocks, i, r, coef, col0)
        if others is None:
            cost = float(t @ t) - rss
        else:
            c, *_ = np.linalg.lstsq(others, t, rcond=None)
            u = t - others @ c
            cost = float(u @ u) - rss
        cand.append((cost, i, t, others))
    cand.sort(key=lambda x: x[0])
    return cand
