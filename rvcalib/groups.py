"""Identifiability groups and the extra runs that would split them.

A group is a set of candidates that the given runs cannot tell apart. At the final state
(:meth:`Groups.final_state_groups`, see docs/calibration.md "Groups and honest intervals"): each
effect in the model with the library candidates that take its place within the noise (chi-square(1)
95 %) when every other effect and empirical term is refitted, each at its own size and sign with the
RMS it would leave. Twins of the same error type (kind ``instances``) leave the effect named with an
interval that covers every member's size; a member of another error type (kind ``unsplit``) means
the effect is not named (it leaves ``effects``; the group gives every member's size). Beside them:
effects whose joint-fit estimates are correlated beyond :data:`CORRELATION_LIMIT`, and an
unexplained empirical term with the library effects that could produce it. Several instances of one
error type in the model that one instance reproduces within the noise are named once, at the size of
their combined effect (:meth:`Groups._instance_sets`; kind ``instances`` with ``combined``).

Honest intervals: the interval of each named effect is the union of its plain interval and its
intervals in the linearised model augmented by any one library candidate left out, at the size the
data give that candidate (Frisch-Waugh), so that an error left out (too small for the F test, or in
a group) cannot leave a tight interval that misses the truth.

Recommended runs (D-optimal design): for the members of a group, their sensitivities (the change
of the model TE when each is set to its fitted size, on the screening grid) are solved at candidate
run conditions not yet measured (load 0, the largest load and twice it, in both directions). The
information matrix of the members from the given runs is ``G0 = S0^T S0`` (S0 the members'
signatures at the given conditions, each at its size, on a grid of ``REC_POINTS_PER_PIN`` points
per pin); a condition c adds ``S_c^T S_c``. The run that
maximises ``log det(G0 + S_c^T S_c) - log det(G0 + eps I)`` is recommended. When no condition raises
the determinant by more than :data:`MIN_LOG_DET_GAIN`, the group is a symmetry of the TE that no
load or direction splits, and the recommendation says so.
"""
from __future__ import annotations

import json
import math
import time

import numpy as np
from scipy import stats

from rvcalib.effects import Effect
from rvcalib.forward import ModelEvaluationError, grid_te, merge_case
from rvcalib.results import FittedEffect, Unexplained
from rvcalib.pinscan import PinScan
from rvcalib.pairs import CHI2_95, CORRELATION_LIMIT
from rvcalib.selection import joint_linear_fit, member_target

#: Smallest log-determinant gain for which a run is said to split a group (a factor 2 in det).
MIN_LOG_DET_GAIN = math.log(2.0)
#: Largest number of members per group whose sensitivities are solved for the recommendation.
MAX_MEMBERS = 4
#: The sensitivities of the recommendation are solved on a grid of this many points per pin (per
#: output revolution: this times Zp); the criterion compares conditions, so a coarse grid serves.
REC_POINTS_PER_PIN = 2
#: At the final state the signatures of the candidates within this many times the chi-square limit of
#: replacing an effect (judged with their stored signatures, solved at earlier states) and of the
#: effects' own families are solved again before the groups are decided.
RESOLVE_FACTOR = 25.0


class Groups(PinScan):
    """Identifiability groups and recommended runs (methods on the loop)."""

    def identifiability_groups(self, fitted: list[FittedEffect], unexplained: list[Unexplained]) -> list[dict]:
        """Groups of candidates the data cannot tell apart (see the module docstring); widens the
        interval of a found effect whose group holds members of its unit at other sizes."""
        groups: list[dict] = []
        corr = getattr(self, "_corr", None)
        if corr is not None:
            names = [a.effect.name for a in self.active]
            idx = getattr(self, "_param_index", [])
            for i in range(len(names)):
                for j in range(i + 1, len(names)):
                    c = max(abs(float(corr[p, q])) for p in idx[i] for q in idx[j])
                    fi = next((f for f in fitted if f.name == names[i]), None)
                    fj = next((f for f in fitted if f.name == names[j]), None)
                    if c > CORRELATION_LIMIT and fi is not None and fj is not None:
                        groups.append({"kind": "correlated", "found": names[i], "correlation": c,
                                       "members": [{"name": f.name, "value": f.value, "unit": f.unit,
                                                    "ci_low": f.ci_low, "ci_high": f.ci_high, "found": True}
                                                   for f in (fi, fj)],
                                       "note": "their joint-fit estimates are correlated: the runs given split "
                                               "them only partly; their intervals include that uncertainty"})
        for u in unexplained:
            if not u.candidates:
                continue
            members = [{"name": u.label, "value": u.amplitude_arcsec, "unit": u.unit, "found": True}]
            members += [dict(c, found=False) for c in u.candidates]
            groups.append({"kind": "unexplained", "found": u.label, "members": members,
                           "note": "library effects that could produce this structure, with the size they would "
                                   "need; the loop did not name them because they do not explain it as well"})
        return groups

    # ------------------------------------------------------------------ the final state
    def final_state_groups(self, fitted: list[FittedEffect], resolve: bool = True) -> tuple[list[FittedEffect], list[dict]]:
        """Identifiability at the final state (see the module docstring): the groups of each effect in
        the model, the effects the data cannot tell from another error type (moved from ``fitted``
        to a group of kind ``unsplit``), and honest intervals (profiled over every library candidate
        not in the model). Returns (the effects still named, the groups)."""
        if not self.active:
            return fitted, []
        t0 = time.perf_counter()
        pairs = self._pairs()
        # the final state's own residual (the final backward elimination changes the model after the last fit
        # that set it: seed 3 kept the 11-effect RSS for the 10 effects left, RMS 0.2024 for 0.2037)
        r_state, self.emp_coef = self.full_residual(pairs, self.empirical)
        self.rss_full = float(r_state @ r_state)
        rc_raw = self.coarse_residual()
        rc_cat = np.concatenate(rc_raw)
        Ec = self._emp_matrix(self.empirical, coarse=True)
        members = self.active_members()
        # the final residual on the grid r_fin: linear at the state
        blocks, col0, coef, r_fin = joint_linear_fit(members, rc_cat, Ec)
        X = np.column_stack(blocks)
        w = self.n / self.nc                      # samples per screening-grid point
        k_tot = X.shape[1]
        s2 = self.rss_full / max(1, self.n - k_tot)  # noise variance per sample, arcsec^2
        if s2 <= 0:
            return fitted, []
        rss_grid = float(r_fin @ r_fin)
        Q, R = np.linalg.qr(X)
        Rinv = np.linalg.pinv(R)
        covX = (s2 / w) * (Rinv @ Rinv.T)         # covariance of the linearised coefficients
        tq = float(stats.t.ppf(0.975, max(1, self.n - k_tot)))
        by_name = {f.name: f for f in fitted}
        named_active = {a.effect.name for a in self.active}
        groups: list[dict] = []
        unsplit: set[str] = set()
        alt_names: dict[str, set[str]] = {}
        rms_model = math.sqrt(self.rss_full / self.n)

        def screened(cache: dict, t: np.ndarray, others: np.ndarray | None):
            """The library candidates not in the model (cheap ones) screened against ``t`` with ``others``
            refitted: (effect, its screening record) for each that has signature columns."""
            for e in self.lib:
                if e.name in named_active or e.expensive:
                    continue
                d = self.screen_effect(e, cache, t, others)
                if d is not None and d.cols is not None:
                    yield e, d

        def replacements(t: np.ndarray, others: np.ndarray | None, limit: float) -> list[tuple[dict, Effect]]:
            """Library candidates (not in the model) that fitted to ``t`` with ``others`` refitted leave a
            residual sum of squares within ``limit`` noise variances of the model's."""
            cache_t: dict[int, tuple] = {}
            out = []
            for e, d in screened(cache_t, t, others):
                rss_c = cache_t[self._ms(e)][2] * (1.0 - d.explained)
                miss = max(0.0, rss_c - rss_grid) * w
                if miss / s2 < limit:
                    p = np.asarray(d.p, dtype=float)
                    ent = {"name": e.name, "key": e.key, "value": float(e.value(p)), "unit": e.unit,
                           "rms_after_arcsec": float(math.sqrt((self.rss_full + miss) / self.n)), "found": False}
                    if e.polar:
                        ent["angle_deg"] = float(e.magnitude_angle(p)[1])
                    out.append((ent, e))
            return out

        def target(i: int) -> tuple[np.ndarray, np.ndarray | None]:
            """An effect's contribution plus the final residual, and the other members' columns."""
            return member_target(members, blocks, i, r_fin, coef, col0)

        if resolve:
            # the signatures of the candidates near an alternative (stored ones: solved at earlier states)
            # and of the effects' own families are solved again at the final state
            temps = {}
            for i, a in enumerate(self.active):
                near = [e for _, e in replacements(*target(i), RESOLVE_FACTOR * CHI2_95)] + [a.effect]
                for e in near:
                    if e.screen != "analytic" and not e.expensive:
                        tt = self.lib.by_name(e.template or e.name)
                        temps[tt.name] = tt
            if temps:
                self.solve_signatures(list(temps.values()), pairs)
        # 1. alternatives: candidates that take an effect's place within the noise, the others refitted
        for i, (a, m) in enumerate(zip(self.active, members)):
            f = by_name.get(a.effect.name)
            if f is None:
                continue
            t, others = target(i)
            r0 = self._group(self.m, t, others)[2]  # the residual without it, the others refitted
            if (r0 - rss_grid) * w / s2 < CHI2_95:
                continue  # not supported by the data: anything "replaces" it (the final elimination decides)
            alts = [ent for ent, _ in replacements(t, others, CHI2_95)]
            if not alts:
                continue
            alts.sort(key=lambda x: x["rms_after_arcsec"])
            alt_names[a.effect.name] = {x["name"] for x in alts}
            me = {"name": f.name, "key": f.key, "value": f.value, "unit": f.unit, "rms_after_arcsec": rms_model,
                  "found": True}
            if f.angle_deg is not None:
                me["angle_deg"] = f.angle_deg
            other_types = sorted({x["key"] for x in alts if x["key"] != f.key})
            if other_types:
                unsplit.add(f.name)
                groups.append({"kind": "unsplit", "found": f.name, "members": [me] + alts,
                               "note": "the data cannot tell these apart (each, at its size, leaves the residual "
                                       "within the noise of the model's); the model holds the first, which is "
                                       "therefore not named as an effect"})
                continue
            # the size of the error type each twin gives (a twin may need the opposite sign in its own
            # instance's frame: its magnitude, with the sign of the named instance)
            same = [math.copysign(abs(x["value"]), f.value) for x in alts if x["unit"] == f.unit]
            lo, hi = min([f.ci_low] + same), max([f.ci_high] + same)
            if lo < f.ci_low or hi > f.ci_high:
                f.ci_low, f.ci_high = float(lo), float(hi)
            groups.append({"kind": "instances", "found": f.name, "members": [me] + alts,
                           "note": "instances of the same error that the data cannot tell apart: the size is "
                                   "identified, the instance is not; the interval covers every member's size"})
        # 1b. a set of instances of one error type in the model (planet eccentricity of crank 0 and of crank
        #     1) that another error type takes the place of together (a cam phase): the same rule for the set
        for key, idx, t, rest in self._set_targets(members, blocks, coef, col0, r_fin, by_name, unsplit):
            others = np.column_stack(rest) if rest else None
            r0 = self._group(self.m, t, others)[2]
            if (r0 - rss_grid) * w / s2 < CHI2_95:
                continue
            alts = [ent for ent, _ in replacements(t, others, CHI2_95) if ent["key"] != key]
            if not alts:
                continue
            alts.sort(key=lambda x: x["rms_after_arcsec"])
            mem = []
            for i in idx:
                f = by_name[self.active[i].effect.name]
                d = {"name": f.name, "key": f.key, "value": f.value, "unit": f.unit, "rms_after_arcsec": rms_model,
                     "found": True}
                if f.angle_deg is not None:
                    d["angle_deg"] = f.angle_deg
                mem.append(d)
                unsplit.add(f.name)
                alt_names.setdefault(f.name, set()).update(x["name"] for x in alts)
            groups.append({"kind": "unsplit", "found": ", ".join(x["name"] for x in mem), "members": mem + alts,
                           "note": f"{len(idx)} instances of {key} in the model that another error, each at the size "
                                   "listed, replaces together within the noise (the others refitted): the data "
                                   "cannot tell them apart; the model holds the first ones, which are therefore "
                                   "not named as effects"})
            self.log(f"instances of {key} in the model ({', '.join(x['name'] for x in mem)}) unsplit from "
                     + ", ".join(f"{x['name']} {x['value']:.4g} {x['unit']}" for x in alts[:3]))
        # 1c. a pair the data cannot split that the linear analysis cannot see: a left-out candidate nearly
        #     collinear with a named effect in the model's own Jacobian at the final state, refitted beside it
        #     through rvdyn; the effect is not named when it is no longer significant beside the candidate
        if resolve and not self.over_budget():
            for g in self._nonlinear_pairs(by_name, unsplit, rms_model):
                groups.append(g)
                if g["kind"] == "unsplit":
                    unsplit.add(g["found"])
                unsplit.update(m["name"] for m in g["members"] if m.get("named") is False)
                alt_names.setdefault(g["found"], set()).update(m["name"] for m in g["members"][1:])
        # 2. honest intervals: each named effect's interval in the model plus any one candidate left out
        #    (profiled over the size the data give that candidate), the union over candidates
        res_groups: dict[int, tuple] = {}
        widen: dict[str, tuple[float, str]] = {}
        for e, d in screened(res_groups, r_fin, None):
            S = d.cols
            G = Rinv @ (Q.T @ S)
            U = S - X @ G
            uu = U.T @ U
            if not np.all(np.isfinite(uu)) or float(np.trace(uu)) <= 1e-12 * float(np.sum(S * S)):
                continue
            uu_inv = np.linalg.pinv(uu)
            beta = uu_inv @ (U.T @ r_fin)
            cov_b = (s2 / w) * uu_inv
            shift = G @ beta
            extra = np.einsum("ij,jk,ik->i", G, cov_b, G)
            for i, a in enumerate(self.active):
                f = by_name.get(a.effect.name)
                if f is None or e.name in alt_names.get(f.name, ()):
                    continue
                j = col0[i]
                half = tq * math.sqrt(max(covX[j, j] + extra[j], 0.0))
                lo, hi = f.value - shift[j] - half, f.value - shift[j] + half
                if lo < f.ci_low or hi > f.ci_high:
                    gain = max(f.ci_low - lo, hi - f.ci_high)
                    f.ci_low, f.ci_high = float(min(f.ci_low, lo)), float(max(f.ci_high, hi))
                    if gain > widen.get(f.name, (0.0, ""))[0]:
                        widen[f.name] = (gain, e.name)
        for name, (_, cand) in widen.items():
            by_name[name].selection["interval_widened_by"] = cand
        # 2b. ... and over the left-out candidates together: the ones the data support beyond the model,
        #     chosen one after another at the final state (linear), with every effect refitted beside them
        excluded = set().union(*alt_names.values()) if alt_names else set()
        cands = [(e, d.cols, d.to_p) for e, d in screened({}, r_fin, None) if e.name not in excluded]
        prof = left_out_profile(X, r_fin, cands, s2 / w, self.max_terms)
        if prof is not None:
            chosen, b_aug, cov_aug, rss_aug, picked = prof
            rms_aug = math.sqrt(max(self.rss_full - (rss_grid - rss_aug) * w, 0.0) / self.n)
            v_lin = {f.name: f.value + float(b_aug[col0[i]]) for i, a in enumerate(self.active)
                     if (f := by_name.get(a.effect.name)) is not None}
            how = "linear"
            # the sizes with them through the full model (one joint fit from the linear estimates; the
            # linearisation at a state that stands in for several errors can be far from the truth)
            refit = self._refit_with(picked) if resolve and not self.over_budget() else None
            if refit is not None:
                params_nl, rss_nl = refit
                if rss_nl < self.rss_full:
                    how = "refitted through rvdyn"
                    rms_aug = math.sqrt(rss_nl / self.n)
                    v_lin = {a.effect.name: float(a.effect.value(q)) for a, q in zip(self.active, params_nl)}
                    for c, (e, q) in zip(chosen, zip([e for e, _ in picked], params_nl[len(self.active):])):
                        c["value"] = float(e.value(q))
                        if e.polar:
                            c["angle_deg"] = float(e.magnitude_angle(q)[1])
            for i, a in enumerate(self.active):
                f = by_name.get(a.effect.name)
                if f is None or f.name in unsplit:
                    continue
                j = col0[i]
                half = tq * math.sqrt(max(cov_aug[j, j], 0.0))
                v_aug = v_lin[f.name]
                lo, hi = v_aug - half, v_aug + half
                f.ci_low, f.ci_high = float(min(f.ci_low, lo)), float(max(f.ci_high, hi))
                if abs(v_aug - f.value) <= tq * math.sqrt(max(covX[j, j], 0.0)):
                    continue  # its size does not depend on them beyond its own interval
                f.selection["size_with_left_out"] = {"value": v_aug, "ci_low": lo, "ci_high": hi,
                                                     "left_out": [c["name"] for c in chosen], "how": how}
                me = {"name": f.name, "key": f.key, "value": f.value, "unit": f.unit, "rms_after_arcsec": rms_model,
                      "found": True, "value_with_left_out": v_aug}
                groups.append({"kind": "left_out", "found": f.name,
                               "members": [me] + [dict(c, rms_after_arcsec=rms_aug, found=False) for c in chosen],
                               "note": "the found effect's size depends on library effects the model leaves out "
                                       "(the data support each beyond the model, with everything refitted; "
                                       f"together they leave RMS {rms_aug:.3g} arcsec, {how}): with them at the "
                                       f"sizes listed it would be {v_aug:.4g} {f.unit}; its interval covers both"})
            self.log(f"left-out candidates at the final state: {', '.join(c['name'] for c in chosen)} (RMS "
                     f"{rms_model:.4g} -> {rms_aug:.4g} arcsec, {how})")
        # 2c. a second fit of the same effects from another start (rvcalib.basins): intervals cover both
        if resolve and not self.over_budget():
            self.restart_refit(adopt=False, members=members)
        for g in self.basin_groups(by_name, rms_model):
            groups.append(g)
            unsplit.update(m["name"] for m in g["members"] if m.get("named") is False)
        # 3. instance sets: several instances of one error type in the model that one instance replaces
        #    within the noise are one identified error (its combined effect), not several
        merged, combined = self._instance_sets(members, blocks, coef, col0, r_fin, rss_grid, w, s2, tq,
                                               by_name, unsplit)
        groups += [g for g, _ in combined]
        # 4. the sizes averaged over the state and its look-alike fits by their BIC weights (a size that depends on
        #    whether a candidate is present), with a group for each fit as good by the BIC that moves one
        groups += self.lookalike_average(by_name, unsplit | merged, rms_model)
        kept = [f for f in fitted if f.name not in unsplit and f.name not in merged] + [f for _, f in combined]
        self.log(f"identifiability at the final state: {len(groups)} group(s), {len(unsplit)} effect(s) not named, "
                 f"{time.perf_counter() - t0:.1f} s")
        return kept, groups

    def _set_targets(self, members, blocks, coef, col0, r_fin, by_name, unsplit):
        """The sets of two or more instances of one Table 4 error type in the model (named, not in an unsplit
        group), each as (key, member indices, the final coarse residual with the set's parts added back, the
        other members' and empirical terms' column blocks)."""
        sets: dict[str, list[int]] = {}
        for i, a in enumerate(self.active):
            if a.effect.family == "table4" and a.effect.name in by_name and a.effect.name not in unsplit:
                sets.setdefault(a.effect.key, []).append(i)
        for key, idx in sorted(sets.items()):
            if len(idx) < 2:
                continue
            t = r_fin.copy()
            for i in idx:
                m, a = members[i], self.active[i]
                t += m.cols @ coef[col0[i]:col0[i + 1]] + (m.contribution if m.contribution is not None
                                                           else m.cols @ np.asarray(a.p, dtype=float))
            yield key, idx, t, [blocks[j] for j in range(len(blocks)) if j not in idx]

    def _instance_sets(self, members, blocks, coef, col0, r_fin, rss_grid, w, s2, tq, by_name, unsplit
                       ) -> tuple[set[str], list[tuple[dict, FittedEffect]]]:
        """Effects in the model that are instances of one Table 4 error type (carrier hole eccentricity
        of crank 0 and of crank 1, ...): the set's combined contribution (linearised at the final state,
        every other effect and empirical term refitted) is fitted by each member instance alone; when
        the best leaves the residual sum of squares within chi-square(df) 95 % noise variances of the
        set's (df: the parameters the set has more), the data see one error of that type. It is named
        once, at the equivalent size of that instance (the combined effect), and the set is reported
        as a group of kind ``instances`` with every member's own size. Returns (names of the merged
        members, [(group, the named combined effect)])."""
        merged: set[str] = set()
        out: list[tuple[dict, FittedEffect]] = []
        for key, idx, t, rest in self._set_targets(members, blocks, coef, col0, r_fin, by_name, unsplit):
            k_set = sum(blocks[i].shape[1] for i in idx)
            best = None
            for i in idx:
                A = np.column_stack([blocks[i]] + rest)
                c, *_ = np.linalg.lstsq(A, t, rcond=None)
                rr = t - A @ c
                rss_i = float(rr @ rr)
                if best is None or rss_i < best[1]:
                    best = (i, rss_i, c, A)
            i, rss_i, c, A = best
            k_i = blocks[i].shape[1]
            miss = max(0.0, rss_i - rss_grid) * w
            limit = float(stats.chi2.ppf(0.95, max(1, k_set - k_i)))
            names = [self.active[j].effect.name for j in idx]
            if miss / s2 >= limit:
                self.log(f"instances of {key} in the model ({', '.join(names)}): the data split them "
                         f"({miss / s2:.1f} noise variances for one instance, limit {limit:.2f})")
                continue
            m, a = members[i], self.active[i]
            e = a.effect
            p_now = np.asarray(a.p, dtype=float)
            # the member's columns are the TE change per unit of to_p's coefficients: the total is B c
            B = np.column_stack([m.to_p(np.eye(k_i)[k]) - p_now for k in range(k_i)])
            p_eq = B @ c[:k_i]
            cov_c = (s2 / w) * np.linalg.pinv(A.T @ A)[:k_i, :k_i]
            Cp = B @ cov_c @ B.T
            if e.polar:
                mag, ang = e.magnitude_angle(p_eq)
                g = p_eq / mag if mag > 0 else np.array([1.0, 0.0])
                se = float(math.sqrt(max(g @ Cp @ g, 0.0)))
                params = {"x": float(p_eq[0]), "y": float(p_eq[1])}
                angle: float | None = float(ang)
            else:
                se = float(math.sqrt(max(Cp[0, 0], 0.0)))
                params = {"value": float(p_eq[0])}
                angle = None
            val = float(e.value(p_eq))
            f0 = by_name[e.name]
            sel = dict(f0.selection, combined_from=names)
            comb = FittedEffect(e.name, e.key, e.family, e.unit, e.meaning, val, val - tq * se, val + tq * se, angle,
                                se, params, f0.iteration, f0.explained_fraction, f0.F, f0.p_value, f0.delta_bic,
                                list(f0.alternatives), None, None, sel)
            mem = []
            for j in idx:
                fj = by_name[self.active[j].effect.name]
                d = {"name": fj.name, "key": fj.key, "value": fj.value, "unit": fj.unit, "found": True}
                if fj.angle_deg is not None:
                    d["angle_deg"] = fj.angle_deg
                mem.append(d)
            grp = {"kind": "instances", "found": e.name, "combined": {"name": e.name, "value": val, "unit": e.unit,
                                                                      "angle_deg": angle,
                                                                      "rms_after_arcsec": float(math.sqrt(
                                                                          (self.rss_full + miss) / self.n))},
                   "members": mem,
                   "note": f"{len(idx)} instances of {key} in the model that one instance ({e.name}) reproduces "
                           "within the noise: the data see one error of this type, named once at the size of "
                           "their combined effect; the members' own sizes are not identified"}
            merged.update(names)
            out.append((grp, comb))
            self.log(f"instances of {key} in the model ({', '.join(names)}) named once: {e.name} = {val:.4g} "
                     f"{e.unit} (combined effect; {miss / s2:.2f} noise variances, limit {limit:.2f})")
        return merged, out

    # ------------------------------------------------------------------ experiment design
    def _member_signature(self, name: str, value: float, cond: dict, base: np.ndarray) -> np.ndarray | None:
        """TE change (screening grid) at run condition ``cond`` when member ``name`` takes the
        parameters of its fitted size; None if it is not a library effect that can be solved cheaply."""
        try:
            e = self.lib.by_name(name)
        except ValueError:
            if name.startswith("unexplained constant offset") and "load" not in name:
                return np.full(self._rec_m, float(value))
            return None
        if e.expensive:
            return None
        if e.family == "measurement":
            # a reading error: the same at every load and direction
            x = np.arange(self._rec_m) * (self.period / self._rec_m)
            B = e.basis(x, x / self.ratio)
            p = np.full(B.shape[1], value / math.sqrt(B.shape[1]))
            return B @ p
        p = np.array([value] + [0.0] * (e.n_params - 1), dtype=float)
        try:
            return grid_te(self._case_with(cond, [(e, p)]), self._rec_m) - base
        except ModelEvaluationError:
            return None

    def _case_with(self, cond: dict, active) -> dict:
        errs: list = []
        model: dict = {}
        for e, p in active:
            errs.extend(e.error_items(p))
            model.update(e.model_options(p))
        return merge_case(cond, errs, model)

    def recommend_runs(self, groups: list[dict], loads: list[float] | None = None) -> list[dict]:
        """The extra run (load, direction) that best splits each group (see the module docstring)."""
        if not groups:
            return []
        self._rec_m = REC_POINTS_PER_PIN * int(self.design.z_pins)
        template = dict(self.cond_base[0])
        have = {(float(r.load_Nm), int(r.direction)) for r in self.runs}
        lmax = max([r.load_Nm for r in self.runs] + [10.0])
        if loads is None:
            loads = sorted({0.0, float(lmax), float(2 * lmax)})
        conds = [(L, d) for L in loads for d in (1, -1) if (L, d) not in have]
        out = []
        base_cache: dict[tuple, np.ndarray | None] = {}

        def base_te(cond: dict) -> np.ndarray | None:
            """The model TE of a run condition on the recommendation grid, once per condition (None when
            rvdyn cannot evaluate it)."""
            key = (json_key(cond),)
            if key not in base_cache:
                try:
                    base_cache[key] = grid_te(cond, self._rec_m)
                except ModelEvaluationError:
                    base_cache[key] = None
            return base_cache[key]
        for gi, g in enumerate(groups):
            if g["kind"] == "left_out":
                continue  # not a group the runs fail to split: the model lacks its members (a larger model names them)
            members = [m for m in g["members"] if isinstance(m.get("value"), (int, float)) and m["value"] != 0][:MAX_MEMBERS]
            if len(members) < 2:
                continue
            # information from the runs given: members' signatures at the given conditions
            S0 = []
            ok = True
            for m in members:
                cols = []
                for c in self.cond_base:
                    b = base_te(c)
                    s = None if b is None else self._member_signature(m["name"], m["value"], c, b)
                    if s is None:
                        ok = False
                        break
                    cols.append(s)
                if not ok:
                    break
                S0.append(np.concatenate(cols))
            if not ok:
                out.append({"group": gi, "members": [m["name"] for m in members], "run": None,
                            "reason": "a member's sensitivity cannot be solved cheaply (e.g. a cam-bearing "
                                      "clearance or an empirical term); no run recommended"})
                continue
            S0 = np.column_stack(S0)
            G0 = S0.T @ S0
            eps = 1e-9 * max(float(np.trace(G0)), 1e-12)
            ld0 = float(np.linalg.slogdet(G0 + eps * np.eye(G0.shape[0]))[1])
            best = None
            for L, d in conds:
                cond = dict(template, load_Nm=L, direction=d)
                b = base_te(cond)
                if b is None:
                    continue
                cols = [self._member_signature(m["name"], m["value"], cond, b) for m in members]
                if any(c is None for c in cols):
                    continue
                Sc = np.column_stack(cols)
                ld = float(np.linalg.slogdet(G0 + Sc.T @ Sc + eps * np.eye(G0.shape[0]))[1])
                if best is None or ld > best[0]:
                    best = (ld, L, d)
            rec = {"group": gi, "members": [m["name"] for m in members],
                   "criterion": "D-optimal: largest log det of the members' information matrix"}
            if best is not None and best[0] - ld0 > MIN_LOG_DET_GAIN:
                rec.update(run={"load_Nm": best[1], "direction": best[2]}, log_det_gain=best[0] - ld0)
            else:
                rec.update(run=None, log_det_gain=None if best is None else best[0] - ld0,
                           reason="no load or direction considered splits them (a symmetry of the TE): a "
                                  "measurement other than the TE is needed (e.g. the parts' geometry)")
            out.append(rec)
        return out


def left_out_profile(X: np.ndarray, r: np.ndarray, cands: list[tuple[Effect, np.ndarray, object]], s2: float,
                     max_add: int, alpha: float = 0.05) -> tuple[list[dict], np.ndarray, np.ndarray, float, list] | None:
    """The library candidates the data support beyond a model, chosen one after another (forward
    selection in the model linearised at its state), and the model's coefficients with them.

    Each step adds the candidate whose columns, with the model's and the ones chosen before refitted
    (Frisch-Waugh), lower the residual sum of squares most, while that drop exceeds the chi-square
    quantile of a family-wise 5 % level over the candidates (Bonferroni: ``0.05 / len(cands)``; degrees
    of freedom its columns) in noise variances: a candidate the data support beyond the model, not one of
    the few that pass a 95 % rule by chance among a library of ~150. At most ``max_add`` are chosen.

    Parameters
    ----------
    X : ndarray
        (n, k) the model's columns (effects linearised at the state, empirical terms), screening grid.
    r : ndarray
        The model's residual on the same grid (orthogonal to ``X``), arcsec.
    cands : list of (Effect, ndarray, callable)
        Each candidate's signature columns at the state and its map coefficients -> parameters.
    s2 : float
        Noise variance per grid point, arcsec^2.
    max_add : int
        Most candidates chosen.
    alpha : float
        Family-wise level over the candidates (each is tested at ``alpha / len(cands)``).

    Returns
    -------
    (chosen, b, cov, rss, effects) or None
        ``chosen``: each ``{name, key, value, unit[, angle_deg]}`` at its size in the augmented model;
        ``b``: the coefficients of ``X``'s columns in the augmented model (the change of the model's
        parameters, per column); ``cov``: their covariance (``s2 (A^T A)^-1`` restricted to ``X``);
        ``rss``: the augmented model's residual sum of squares on the grid; ``effects``: (Effect,
        parameters) of the chosen, for a refit. None when no candidate is
        supported (or ``s2`` is not positive).
    """
    if s2 <= 0 or not cands or max_add < 1:
        return None
    k0 = X.shape[1]
    n_cand = len(cands)
    A = X
    rr = r.copy()
    picked: list[int] = []
    for _ in range(max_add):
        Q, _ = np.linalg.qr(A)
        best = None
        for ci, (e, S, _) in enumerate(cands):
            if ci in picked or S is None:
                continue
            U = S - Q @ (Q.T @ S)
            uu = U.T @ U
            if not np.all(np.isfinite(uu)) or float(np.trace(uu)) <= 1e-10 * float(np.sum(S * S)):
                continue
            g = U.T @ rr
            drop = float(g @ np.linalg.lstsq(uu, g, rcond=None)[0])
            if drop / s2 > stats.chi2.isf(alpha / n_cand, S.shape[1]) and (best is None or drop > best[0]):
                best = (drop, ci)
        if best is None:
            break
        picked.append(best[1])
        A = np.column_stack([A, cands[best[1]][1]])
        c, *_ = np.linalg.lstsq(A, r, rcond=None)
        rr = r - A @ c
    if not picked:
        return None
    coef, *_ = np.linalg.lstsq(A, r, rcond=None)
    cov = s2 * np.linalg.pinv(A.T @ A)
    chosen, effs, j = [], [], k0
    for ci in picked:
        e, S, to_p = cands[ci]
        p = np.asarray(to_p(coef[j:j + S.shape[1]]), dtype=float)
        j += S.shape[1]
        ent = {"name": e.name, "key": e.key, "value": float(e.value(p)), "unit": e.unit}
        if e.polar:
            ent["angle_deg"] = float(e.magnitude_angle(p)[1])
        chosen.append(ent)
        effs.append((e, p))
    res = r - A @ coef
    return chosen, coef[:k0], cov[:k0, :k0], float(res @ res), effs


def json_key(case: dict) -> str:
    """A stable key of a case dict."""
    return json.dumps(case, sort_keys=True)
