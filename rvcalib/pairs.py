"""The pair check of the final state: a named effect that one left-out library error, nearly collinear with it
through the full model, could stand beside (:meth:`PairCheck._nonlinear_pairs`, docs/calibration.md "Groups and
honest intervals", item 7), and the refits through rvdyn that decide it. :class:`rvcalib.groups.Groups` builds on it.

The linear analysis of the final state judges a left-out candidate by the part of its screening signature the
model's secant columns do not reproduce; for a candidate the model reproduces to 1e-4 of its signature that part
is the linearisation's own error, not the data. Here the candidate's column is differenced through rvdyn at the
final state, the pairs whose estimates it makes collinear beyond :data:`CORRELATION_LIMIT` are refitted with it
beside and in place of the effect, and the likelihood-ratio test decides whether the effect stays named.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats

from rvcalib.effects import Effect, param_scales
from rvcalib.forward import ModelEvaluationError
from rvcalib.replace import ReplacementRefit
from rvcalib.results import FittedEffect
from rvcalib.subsets import JOINT_BIC_MARGIN

#: Joint-fit correlation above which two effects are reported as one group.
CORRELATION_LIMIT = 0.95
#: The sides of size zero on which each left-out candidate's column is differenced (forward, backward). At zero
#: the TE can have a kink (a uniformly thinner pin opens a play, a thicker one preloads every pin): realistic seed
#: 3's final state (stop 26), the all-pins pin radius beside the pin circle diameter, multiple correlation 0.946
#: forward and 0.998 backward (truth -1.44 um); the stored screening signatures on the grid gave 0.55
#: (docs/calibration.md, "Groups and honest intervals", item 7).
SIDES = (1, -1)
#: 95 % point of chi-square with one degree of freedom: a candidate that takes an effect's place and
#: raises the residual sum of squares by less than this many noise variances fits as well.
CHI2_95 = 3.841
#: An effect whose Wald statistic beside a collinear candidate (the joint fit's local standard error) exceeds
#: this many times the chi-square limit is not refitted with the candidate in its place (the factor of the
#: backward elimination's "overwhelmingly significant", :meth:`rvcalib.selection.Selection._backward`).
OVERWHELMING = 100.0


class PairCheck(ReplacementRefit):
    """The final state's pair check and the model's refits with extra effects (methods on the loop)."""

    def _nonlinear_pairs(self, by_name: dict[str, FittedEffect], unsplit: set[str], rms_model: float) -> list[dict]:
        """Named effects that one left-out library error, nearly collinear with them through the full model,
        could stand beside: groups of kind ``unsplit`` (see docs/calibration.md, "Groups and honest
        intervals", item 7).

        Why: the linear analysis of the final state (items 1-3, 6) judges a left-out candidate by the part of
        its screening signature the model's columns (secants from zero to each member's size) do not
        reproduce. For a candidate that the model reproduces to 1e-4 of its signature, that part is the
        linearisation's own error, not the data: on the realistic draw seed 3 (physical law) the all-pins
        pin radius (truth -1.44 um) was seen as unsupported (0.5 +- 0.5 um, the pin circle diameter's
        interval barely moved), while through rvdyn it correlates 0.98-0.997 with the pin circle diameter
        and, refitted beside it, takes the diameter from +6.5 um [3.2, 12.1] to 2.5 +- 2.5 um (truth -0.77):
        the data fix one combination of the two, not either.

        How: the model's Jacobian at the final state (every reading) is augmented by each left-out family's
        representative (the library's templates whose family has no member in the model; Table 4 and model
        effects, not the expensive ones) at size zero, differenced on both sides of zero (:data:`SIDES`; one
        side for a size that cannot be negative); a named effect whose variance the candidate inflates beyond
        ``1 / (1 - CORRELATION_LIMIT^2)`` (multiple correlation with it, the others refitted, above
        :data:`CORRELATION_LIMIT`, the limit of the ``correlated`` groups) is a pair to check. The model is
        refitted with the candidate through rvdyn (one joint fit per candidate, from its size zero, i.e. the
        final state; a fit that ends no lower than the state leaves the pair at the state, the candidate at
        zero), and the effect's interval is taken there (Jacobian at the refit, the t quantile of
        :meth:`intervals`). When the pair's correlation there exceeds the limit and the effect's interval holds
        zero, the data do not support the effect beside the candidate: the nonlinear form of item 1's rule (a
        candidate that replaces it within the chi-square(1) 95 % limit leaves it insignificant in the model
        holding both). It is then not named; the group gives its size alone and both sizes with their intervals
        in the joint fit. While the effect stays named, its interval covers its size beside the candidate (item
        2's rule: the model plus any one left-out candidate), and the pair is a group: of kind ``left_out`` when
        the data support the candidate beside the model (item 6's level), else of kind ``correlated`` (the runs
        split them only partly) when the interval had to widen."""
        effects = [a.effect for a in self.active]
        params = [np.asarray(a.p, dtype=float) for a in self.active]
        n_emp = sum(t.n_cols for t in self.empirical)
        targets = [i for i, a in enumerate(self.active)
                   if a.effect.family in ("table4", "model") and a.effect.name in by_name
                   and a.effect.name not in unsplit]
        if not targets:
            return []
        try:
            _, r0, J = self.state_jacobian(effects, params)
        except ModelEvaluationError:
            return []
        idx = np.cumsum([0] + [e.n_params for e in effects])
        fam_in = {e.template or e.name for e in effects}
        cands = [e for e in self.lib.templates() if (e.template or e.name) not in fam_in
                 and e.family in ("table4", "model") and not e.expensive]
        # each candidate's columns on both sides of size zero (SIDES): the slopes differ where the TE has a kink
        # (from the state's residual: a candidate at size zero changes no TE)
        cols: list[tuple[Effect, np.ndarray, int]] = []
        for c, side in ((c, side) for c in cands for side in SIDES):
            if self.over_budget():
                break
            if side < 0 and min(c.lower) >= 0:
                continue  # a size that cannot be negative (a compliance, a friction torque): one side only
            try:
                _, _, Jc = self.state_jacobian(effects + [c], params + [np.zeros(c.n_params)],
                                                only=list(range(J.shape[1], J.shape[1] + c.n_params)),
                                                backward=side < 0, f0=r0)
            except ModelEvaluationError:
                continue
            cols.append((c, Jc, side))
        # the state's Jacobian and each candidate's forward column at size zero, kept: the refits beside a
        # candidate start from them (rvcalib.fitting.Fitting._cached_jacobian) instead of differencing again
        fwd = [(c, Jc) for c, Jc, side in cols if side > 0]
        self._keep_jacobian(effects + [c for c, _ in fwd], params + [np.zeros(c.n_params) for c, _ in fwd],
                            self.empirical, np.column_stack([J] + [Jc for _, Jc in fwd]))
        pairs = collinear_partners(J, [list(range(idx[i], idx[i + 1])) for i in targets],
                                   [Jc for _, Jc, _ in cols], CORRELATION_LIMIT)
        # one refit per candidate; each effect checked with its most collinear candidate (either side) of another type
        n_cands = len({c.name for c, _, _ in cols})
        best: dict[int, tuple[float, int]] = {}
        for ti, ci, rho in pairs:
            i = targets[ti]
            if cols[ci][0].key == effects[i].key:
                continue  # instances of one type: items 1, 4 and 5
            if i not in best or rho > best[i][0]:
                best[i] = (rho, ci)
        out: list[dict] = []
        refits: dict[str, tuple | None] = {}
        swept: set[str] = set()                      # supported candidates whose joint fit item 7b has read
        gone: set[str] = set()                       # effects this check has found not named
        tq = float(stats.t.ppf(0.975, max(1, self.n - J.shape[1] - n_emp)))
        s2_noise = self.rss_full / max(1, self.n - J.shape[1] - n_emp)  # noise variance per reading
        for i, (rho, ci) in sorted(best.items(), key=lambda kv: -kv[1][0]):
            if self.over_budget():
                break
            c, Jc, side = cols[ci]
            if effects[i].name in gone:
                continue
            if c.name not in refits:
                refits[c.name] = None
                # from size zero, i.e. the final state (the fit cannot end above it; realistic seed 3, stop 26: the
                # pin radius from zero went to its negative side, -1.51 um; seed 1: a start one difference step on
                # the negative side of a cam phase ended above the state)
                got = self._refit_with([(c, np.zeros(c.n_params))])
                how = "refit failed"
                if got is not None and got[1] <= float(r0 @ r0) * (1.0 + 1e-9):
                    p_new, rss_new = got
                    try:
                        _, r1, J1 = self.state_jacobian(effects + [c], p_new)
                        refits[c.name] = (p_new, float(r1 @ r1), J1)
                        how = f"RMS {rms_model:.4g} -> {math.sqrt(refits[c.name][1] / self.n):.4g}"
                    except ModelEvaluationError:
                        pass
                elif got is not None:
                    # the refit found nothing below the state (on a flat ridge the solver's rounding decides): the
                    # pair beside each other is the state with the candidate at zero, its columns there (this side's)
                    # (realistic seed 3, stop 28: the pin radius beside the pin circle diameter, collinear 0.997,
                    # ended 1e-9 above the state, and the diameter stayed named at +1.40 um [0.62, 2.18], truth -0.77)
                    refits[c.name] = (params + [np.zeros(c.n_params)], float(r0 @ r0), np.column_stack([J, Jc]))
                    how = "no lower residual: the pair taken at the state, the candidate at zero"
                self.log(f"pair check: {c.name} beside the model (collinear with {effects[i].name}, "
                         f"{rho:.3f}, {'negative' if side < 0 else 'positive'} side): {how}")
            if refits[c.name] is None:
                continue
            p_new, rss_new, J1 = refits[c.name]
            scales = param_scales(effects + [c])
            s2 = rss_new / max(1, self.n - J1.shape[1] - n_emp)
            jc = list(range(J1.shape[1] - c.n_params, J1.shape[1]))
            test = split_test(J1, scales, p_new, list(range(idx[i], idx[i + 1])), jc, s2, effects[i].polar,
                              c.polar)
            if test is None:
                continue
            corr, (v_f, se_f), (v_c, se_c) = test
            f = by_name[effects[i].name]
            self.log(f"pair check: {f.name} beside {c.name}: {v_f:.4g} +- {tq * se_f:.3g} {f.unit} and "
                     f"{v_c:.4g} +- {tq * se_c:.3g} {c.unit}, correlation {corr:.3f}")
            drop = (self.rss_full - rss_new) / s2_noise
            supported = drop > float(stats.chi2.isf(0.05 / n_cands, c.n_params))
            # the effect's interval covers its size beside the candidate (item 2's rule: the model plus any one
            # candidate left out, here through rvdyn where the linearisation cannot judge the pair)
            lo, hi = v_f - tq * se_f, v_f + tq * se_f
            widened = lo < f.ci_low or hi > f.ci_high
            if widened:
                f.ci_low, f.ci_high = float(min(f.ci_low, lo)), float(max(f.ci_high, hi))
                f.selection["size_with_left_out"] = {"value": v_f, "ci_low": lo, "ci_high": hi,
                                                     "left_out": [c.name],
                                                     "how": "refitted through rvdyn (pair check)"}
                self.log(f"pair check: {f.name}'s interval covers {v_f:.4g} {f.unit} (beside {c.name}, "
                         + ("supported" if supported else "not supported") + f" by {drop:.1f} noise variances)")
            ce = {"name": c.name, "key": c.key, "value": v_c, "unit": c.unit,
                  "rms_after_arcsec": float(math.sqrt(rss_new / self.n)), "found": False}
            if c.polar:
                ce["angle_deg"] = float(c.magnitude_angle(p_new[-1])[1])
            if supported:
                # reported as a group with both sizes (the model lacks the candidate; the term limit or the
                # stop left it out), replaced by the unsplit group below when the effect is not named
                me = {"name": f.name, "key": f.key, "value": f.value, "unit": f.unit, "rms_after_arcsec": rms_model,
                      "found": True, "value_with_left_out": v_f}
                out.append({"kind": "left_out", "found": f.name, "members": [me, ce],
                            "note": f"the data support {c.name} beside the model ({drop:.1f} noise variances; "
                                    f"refitted through rvdyn, RMS {math.sqrt(rss_new / self.n):.4g} arcsec): with it "
                                    f"at the size listed {f.name} would be {v_f:.4g} {f.unit}; its interval covers "
                                    "both"})
            elif widened:
                # not supported beside the model, but the runs split the two only partly: a group (a run that
                # splits them is recommended), the interval covering the effect's size beside the candidate
                me = {"name": f.name, "key": f.key, "value": f.value, "unit": f.unit, "rms_after_arcsec": rms_model,
                      "found": True, "value_together": v_f, "se_together": se_f}
                out.append({"kind": "correlated", "found": f.name, "correlation": abs(corr),
                            "members": [me, dict(ce, value_together=v_c, se_together=se_c)],
                            "note": f"{c.name}, left out of the model (beside it the residual falls by {drop:.1f} "
                                    f"noise variances: not supported), correlates {corr:.3f} with {f.name} through "
                                    f"rvdyn: beside it {f.name} would be {v_f:.4g} {f.unit}; the runs given split "
                                    "them only partly; its interval covers both"})
            if supported and c.name not in swept:
                # every other named effect beside the supported candidate (item 7b)
                swept.add(c.name)
                beside = self._beside_supported(c, i, targets, (p_new, rss_new, J1), scales, s2, s2_noise, tq,
                                                by_name, unsplit | gone, drop)
                gone.update(g["found"] for g in beside if g["members"][0]["named"] is False)
                out.extend(beside)
            if se_f <= 0 or (v_f / se_f) ** 2 >= OVERWHELMING * CHI2_95:
                continue  # overwhelmingly significant beside it (the backward elimination's rule): no refit
            # the likelihood-ratio test of the effect beside the candidate: the candidate in its place, refitted
            # through rvdyn from the joint sizes (a curved ridge: the local standard error understates it)
            eff_r = [c if k == i else e for k, e in enumerate(effects)]
            p0_r = [p_new[-1] if k == i else p_new[k] for k in range(len(effects))]
            try:
                p_r, rss_r, *_ = self.fit_full(eff_r, p0_r, self.empirical)
            except ModelEvaluationError:
                continue
            miss = (float(rss_r) - min(rss_new, self.rss_full)) / s2_noise
            self.log(f"pair check: {c.name} in place of {f.name}: {float(c.value(p_r[i])):.4g} {c.unit}, RMS "
                     f"{math.sqrt(rss_r / self.n):.4g} ({miss:.1f} noise variances above the pair's; limit {CHI2_95})")
            if miss >= CHI2_95:
                continue
            rms_new = float(math.sqrt(rss_new / self.n))
            me = {"name": f.name, "key": f.key, "value": f.value, "unit": f.unit, "rms_after_arcsec": rms_model,
                  "found": True, "value_together": v_f, "se_together": se_f}
            if f.angle_deg is not None:
                me["angle_deg"] = f.angle_deg
            ce = {"name": c.name, "key": c.key, "value": float(c.value(p_r[i])), "unit": c.unit,
                  "rms_after_arcsec": float(math.sqrt(rss_r / self.n)), "found": False,
                  "value_together": v_c, "se_together": se_c}
            if c.polar:
                ce["angle_deg"] = float(c.magnitude_angle(p_r[i])[1])
            out[:] = [g for g in out if not (g["kind"] in ("left_out", "correlated") and g["found"] == f.name)]
            out.append({"kind": "unsplit", "found": f.name, "members": [me, ce], "correlation_together": corr,
                        "rms_together_arcsec": rms_new,
                        "note": f"the data fix a combination of these two, not either: {c.name} in place of {f.name}"
                                f" (refitted through rvdyn) leaves the residual within the noise of the two together "
                                f"(RMS {rms_new:.4g} arcsec, where they correlate {corr:.3f}; value_together and "
                                f"se_together are their sizes there): {f.name} is therefore not named"})
            gone.add(f.name)
            self.log(f"pair check: {f.name} not named (unsplit from {c.name})")
        return out

    def lookalike_average(self, by_name: dict[str, FittedEffect], unsplit: set[str], rms_model: float) -> list[dict]:
        """The named effects' sizes averaged over the final state and its look-alike fits by their BIC weights, and
        a group for each fit the BIC cannot tell from the state that moves an effect beyond its interval
        (docs/calibration.md, "Groups and honest intervals", item 9).

        Why: the look-alike refit (:meth:`rvcalib.replace.ReplacementRefit.lookalike_refit`) adds a candidate
        beside a member through rvdyn and keeps it only when the F test passes and the BIC falls by more than
        ``JOINT_BIC_MARGIN``. A trial that does not is still a model the data weigh against the state: its weight
        relative to the state is ``exp(-dBIC/2)`` (the BIC's approximation of the posterior odds, Raftery 1995,
        "Bayesian model selection in social research"; Hoeting, Madigan, Raftery and Volinsky 1999, "Bayesian model
        averaging: a tutorial"), and a size that depends on whether the candidate is present is estimated by the
        weighted mean over the models, not by the state's alone. Realistic seed 7 (stop 37) ended at the truth's
        fit (within 10 BIC units) with the all-pins pin circle diameter at 6.30 um (truth 4.47, with an all-pins
        pin radius of -0.82 that the model lacks); the pin radius beside it, refitted through rvdyn, took it to
        4.89 um at dBIC -0.9. The two columns correlate 0.88-0.90 at the state, under the pair check's limit
        (:data:`CORRELATION_LIMIT`).

        How: every trial kept for the final state (:meth:`lookalike_store`; each holds every member) gets the weight
        ``exp(-dBIC/2)``, the state 1. Each named effect's parameters are averaged with these weights (a polar
        effect's two components, so its magnitude and angle come from the mean vector); its value and angle become
        the mean's, its interval covers the mean and, for each fit within the margin (``dBIC < JOINT_BIC_MARGIN``),
        the effect's size there give or take the state's half-width, widened by the ratio of the effect's standard
        errors in that fit and at the state when it is larger (the fit's own interval; seed 7 at stop 38: the pin
        circle diameter beside the pin radius, which correlate 0.88-0.90, and the truth 0.09 um outside the interval
        with the state's half-width); ``selection["model_average"]`` gives the
        state's size and each fit's size and weight. Each fit within the margin that moves a named effect beyond
        its interval is a group (kind ``model_average``): the moved effects at their mean, the state's and the
        fit's sizes, the fit's candidates at their sizes, the RMS of both fits and the weights."""
        recs = self.lookalike_store().get(self._state_key(), [])
        if not recs:
            return []
        weights = [math.exp(-0.5 * max(rec["delta_bic"], -1400.0)) for rec in recs]
        total = 1.0 + sum(weights)
        state = {a.effect.name: (a.effect, np.asarray(a.p, dtype=float)) for a in self.active}
        fits = [{e.name: np.asarray(q, dtype=float) for e, q in zip(rec["effects"], rec["params"])} for rec in recs]
        moved_by: dict[int, list[dict]] = {}
        for name, f in by_name.items():
            if name in unsplit or name not in state:
                continue
            e, p_s = state[name]
            acc = p_s.copy()
            for w, fit in zip(weights, fits):
                acc = acc + w * fit.get(name, p_s)
            p_avg = acc / total
            v_avg = float(e.value(p_avg))
            half = (f.ci_high - f.ci_low) / 2
            lo, hi = min(f.ci_low, v_avg), max(f.ci_high, v_avg)
            per_fit = []
            for k, (w, rec, fit) in enumerate(zip(weights, recs, fits)):
                q = fit.get(name, p_s)
                v = float(e.value(q))
                per_fit.append({"added": list(rec["added"]), "value": v, "weight": w / total,
                                "delta_bic": rec["delta_bic"]})
                if rec["delta_bic"] >= JOINT_BIC_MARGIN:
                    continue
                moved = float(np.linalg.norm(q - p_s))
                if not (f.ci_low <= v <= f.ci_high) or (e.polar and moved > half):
                    d = {"name": f.name, "key": f.key, "value": v_avg, "unit": f.unit, "rms_after_arcsec": rms_model,
                         "found": True, "value_state": f.value, "value_together": v}
                    if e.polar:
                        d["angle_deg"] = float(e.magnitude_angle(p_avg)[1])
                        d["angle_deg_together"] = float(e.magnitude_angle(q)[1])
                    moved_by.setdefault(k, []).append(d)
                # the fit's own interval: the state's half-width scaled by the ratio of the effect's standard errors
                # in the fit and at the state (a candidate beside a correlated member widens the member's)
                se_fit = rec.get("std_err", {}).get(name)
                h = half * max(1.0, se_fit / f.std_err) if se_fit and f.std_err and f.std_err > 0 else half
                lo, hi = min(lo, v - h), max(hi, v + h)
            f.selection["model_average"] = {"value_state": f.value, "weight_state": 1.0 / total, "fits": per_fit}
            f.value, f.ci_low, f.ci_high = v_avg, float(lo), float(hi)
            if f.implied_total is not None:   # a mis-declared error: the total from the mean correction
                f.implied_total = self._declared_total(e, p_avg)[1]
            if e.polar:
                f.angle_deg = float(e.magnitude_angle(p_avg)[1])
        out: list[dict] = []
        for k, mem in sorted(moved_by.items()):
            rec, w = recs[k], weights[k]
            rms_la = math.sqrt(rec["rss"] / self.n)
            cands = []
            for x, q in zip(rec["effects"], rec["params"]):
                if x.name in rec["added"]:
                    d = {"name": x.name, "key": x.key, "value": float(x.value(q)), "unit": x.unit,
                         "rms_after_arcsec": rms_la, "found": False}
                    if x.polar:
                        d["angle_deg"] = float(x.magnitude_angle(q)[1])
                    cands.append(d)
            added = ", ".join(rec["added"])
            out.append({"kind": "model_average", "found": ", ".join(m["name"] for m in mem), "members": mem + cands,
                        "rms_together_arcsec": rms_la, "delta_bic_together": rec["delta_bic"],
                        "weight_state": 1.0 / total, "weight_together": w / total,
                        "note": f"{added} beside the model (refitted through rvdyn, not added: dBIC "
                                f"{rec['delta_bic']:+.1f}, RMS {rms_model:.4g} -> {rms_la:.4g} arcsec) fits as well by "
                                f"the BIC and moves these effects beyond their intervals (value_state: the model's "
                                f"size, value_together: beside {added}); each is named at the mean of the fits "
                                f"weighted by exp(-dBIC/2) (weights {1.0 / total:.2f} and {w / total:.2f}), its "
                                f"interval covering both"})
            self.log(f"model average: {added} beside the model (dBIC {rec['delta_bic']:+.1f}, weight {w / total:.2f}): "
                     + ", ".join(f"{m['name']} {m['value_state']:.4g} or {m['value_together']:.4g} -> {m['value']:.4g}"
                                 for m in mem))
        return out

    def _beside_supported(self, c: Effect, i: int, targets: list[int], joint: tuple, scales: np.ndarray, s2: float,
                          s2_noise: float, tq: float, by_name: dict[str, FittedEffect], unsplit: set[str],
                          drop: float) -> list[dict]:
        """The other named effects in the joint fit beside a candidate the data support (item 7b of
        docs/calibration.md, "Groups and honest intervals").

        ``c`` was refitted beside the model through rvdyn (``joint``: its parameters, residual sum of squares
        and Jacobian, ``c`` last) because it is nearly collinear with effect ``i``, and it lowers the residual by
        ``drop`` noise variances, beyond item 6's family-wise level: the data support it. Every other named
        effect j of ``targets`` gets its interval widened to cover its interval there (``size +- tq se``,
        :func:`split_test`), as item 6 does for the candidates the linear analysis chooses, and a group of kind
        ``left_out`` with both sizes when its size there lies outside its own interval. When the interval there
        holds zero where its own did not, the model with ``c`` and without j is refitted through rvdyn (from the
        joint sizes): within the chi-square(1) 95 % limit of the joint fit's residual, j is not significant
        beside a candidate the data support, so it is not named (``"named": false``, in a ``left_out`` group; it
        stood for the candidate). Realistic seed 5 (stop
        30): disc 1's phase named at 0.0051 deg [0.0023, 0.0098] (truth 0) beside disc 0's, while the planet
        eccentricity, left out and supported by 16.3 noise variances, was checked against the cam phase only.
        """
        p_new, rss_new, J1 = joint
        effects = [a.effect for a in self.active]
        idx = np.cumsum([0] + [e.n_params for e in effects])
        jc = list(range(J1.shape[1] - c.n_params, J1.shape[1]))
        out: list[dict] = []
        for j in targets:
            f = by_name[effects[j].name]
            if j == i or f.name in unsplit:
                continue
            test = split_test(J1, scales, p_new, list(range(idx[j], idx[j + 1])), jc, s2, effects[j].polar,
                              c.polar)
            if test is None:
                continue
            _, (v, se), (v_c, _) = test
            lo, hi = v - tq * se, v + tq * se
            moved = not f.ci_low <= v <= f.ci_high
            stands_in = lo <= 0.0 <= hi and not f.ci_low <= 0.0 <= f.ci_high
            f.ci_low, f.ci_high = float(min(f.ci_low, lo)), float(max(f.ci_high, hi))
            if not (moved or stands_in):
                continue                             # the size stays inside the interval (widened to cover it)
            named = True
            if stands_in:
                eff_r = [e for k, e in enumerate(effects) if k != j] + [c]
                p0_r = [p_new[k] for k in range(len(effects)) if k != j] + [p_new[-1]]
                try:
                    _, rss_r, *_ = self.fit_full(eff_r, p0_r, self.empirical)
                    miss = (float(rss_r) - min(rss_new, self.rss_full)) / s2_noise
                    named = miss >= CHI2_95
                    self.log(f"pair check: {c.name} without {f.name}: RMS {math.sqrt(rss_r / self.n):.4g} ({miss:.1f} "
                             f"noise variances above the joint fit's; limit {CHI2_95})"
                             + ("" if named else f": {f.name} not named"))
                except ModelEvaluationError:
                    pass
            if named and not moved:
                continue
            f.selection["size_with_left_out"] = {"value": v, "ci_low": lo, "ci_high": hi, "left_out": [c.name],
                                                 "how": "refitted through rvdyn beside a supported candidate "
                                                        "(pair check)"}
            self.log(f"pair check: {f.name}'s interval covers {v:.4g} {f.unit} (beside {c.name}, supported by "
                     f"{drop:.1f} noise variances)")
            me = {"name": f.name, "key": f.key, "value": f.value, "unit": f.unit,
                  "rms_after_arcsec": float(math.sqrt(self.rss_full / self.n)), "found": True,
                  "value_with_left_out": v, "se_with_left_out": se, "named": named}
            ce = {"name": c.name, "key": c.key, "value": v_c, "unit": c.unit,
                  "rms_after_arcsec": float(math.sqrt(rss_new / self.n)), "found": False}
            note = (f"the data support {c.name} beside the model ({drop:.1f} noise variances; refitted through rvdyn):"
                    f" with it at the size listed {f.name} would be {v:.4g} +- {tq * se:.3g} {f.unit}")
            note += "; its interval covers both" if named else (
                f", not significant, and the model without it fits within the noise: {f.name} stood for "
                f"{c.name} and is not named")
            out.append({"kind": "left_out", "found": f.name, "members": [me, ce], "note": note})
        return out

    def _refit_with(self, extra: list[tuple[Effect, np.ndarray]]) -> tuple[list[np.ndarray], float] | None:
        """The model with ``extra`` effects added, refitted jointly through the full model at every reading
        (empirical terms kept) from the present sizes and the extra effects' starts: (parameters of the
        model's effects then the extra ones, residual sum of squares), or None when rvdyn cannot evaluate it."""
        effects = [a.effect for a in self.active] + [e for e, _ in extra]
        p0 = [np.asarray(a.p, dtype=float) for a in self.active] + [
            np.clip(np.asarray(p, dtype=float), e.lower, e.upper) for e, p in extra]
        try:
            params, rss, *_ = self.fit_full(effects, p0, self.empirical)
        except ModelEvaluationError:
            return None
        return params, float(rss)


def collinear_partners(J: np.ndarray, targets: list[list[int]], cand_cols: list[np.ndarray],
                       limit: float) -> list[tuple[int, int, float]]:
    """The (target, candidate) pairs in which a candidate's columns, added to a model's Jacobian, inflate a
    target's variance beyond ``1 / (1 - limit^2)``.

    Parameters
    ----------
    J : ndarray
        (n, k) the model's Jacobian (any parameter scaling).
    targets : list of list of int
        The column indices of each target effect in ``J``.
    cand_cols : list of ndarray
        Each candidate's (n, m) columns at the model's state.
    limit : float
        Largest multiple correlation of a target's estimate with a candidate's (the others refitted).

    Returns
    -------
    list of (target index, candidate index, rho)
        ``rho = sqrt(1 - var_without / var_with)`` of the target's parameter the candidate inflates most.
    """
    cov0 = np.diag(np.linalg.pinv(J.T @ J))
    out = []
    for ci, C in enumerate(cand_cols):
        C = np.asarray(C, dtype=float).reshape(J.shape[0], -1)
        if not np.all(np.isfinite(C)) or float(np.sum(C * C)) <= 0:
            continue
        A = np.column_stack([J, C])
        cova = np.diag(np.linalg.pinv(A.T @ A))[:J.shape[1]]
        for ti, cols in enumerate(targets):
            rho2 = max(1.0 - cov0[j] / cova[j] if cova[j] > 0 else 0.0 for j in cols)
            if rho2 > limit ** 2:
                out.append((ti, ci, float(math.sqrt(rho2))))
    return out


def split_test(J: np.ndarray, scales: np.ndarray, params: list[np.ndarray], jf: list[int], jc: list[int],
               s2: float, f_polar: bool, c_polar: bool
               ) -> tuple[float, tuple[float, float], tuple[float, float]] | None:
    """Two effects refitted together: the correlation of their estimates and each one's size and standard
    error (along its magnitude for a two-component effect).

    Parameters
    ----------
    J : ndarray
        (n, k) Jacobian of the joint fit's residual in the scaled parameters (``scales`` per column).
    params : list of ndarray
        The joint fit's parameters (unscaled), effect by effect, in the order of ``J``'s columns.
    jf, jc : list of int
        The columns of the two effects.
    s2 : float
        Residual variance per reading.
    f_polar, c_polar : bool
        Whether each effect has two components (magnitude and angle).

    Returns
    -------
    (correlation, (size f, se f), (size c, se c)) or None when the Jacobian is not finite.
    """
    if not np.all(np.isfinite(J)):
        return None
    cov = s2 * np.linalg.pinv(J.T @ J) * np.outer(scales, scales)
    p = np.concatenate([np.asarray(q, dtype=float) for q in params])

    def along(cols: list[int], polar: bool) -> tuple[np.ndarray, float, float]:
        v = p[cols]
        if polar:
            mag = float(np.hypot(v[0], v[1]))
            g = v / mag if mag > 0 else np.array([1.0, 0.0])
        else:
            mag, g = float(v[0]), np.array([1.0])
        return g, mag, float(math.sqrt(max(g @ cov[np.ix_(cols, cols)] @ g, 0.0)))

    gf, vf, sf = along(jf, f_polar)
    gc, vc, sc = along(jc, c_polar)
    cfc = float(gf @ cov[np.ix_(jf, jc)] @ gc)
    corr = cfc / (sf * sc) if sf > 0 and sc > 0 else 0.0
    return corr, (vf, sf), (vc, sc)
