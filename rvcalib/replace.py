"""The checks before the loop stops (docs/calibration.md, steps 8a and 8b of the iteration): the added-variable
ranking of the library with the members refitted (:meth:`ReplacementRefit.added_variable_ranking`), every crank /
disc / hole instance refitted with the other families of its error type in its place
(:meth:`ReplacementRefit.instance_refit`; with a constant offset in the model, also with the offset dropped:
:meth:`ReplacementRefit.offset_instance_refit`), members refitted through the full model with another family's
candidate in their place at the term limit (:meth:`ReplacementRefit.replacement_refit`) and each member's
look-alike of another error type refitted beside it (:meth:`ReplacementRefit.lookalike_refit`)."""
from __future__ import annotations

import math

import numpy as np

from rvcalib.effects import Effect
from rvcalib.forward import ModelEvaluationError
from rvcalib.joint import JointSelection
from rvcalib.lsq import bic, ftest, projector
from rvcalib.results import Active, Candidate
from rvcalib.selection import joint_linear_fit, linear_removal_costs, member_target
from rvcalib.subsets import JOINT_BIC_MARGIN

#: Members refitted through rvdyn with another family's candidate in their place before the loop stops
#: at the term limit (see :meth:`ReplacementRefit.replacement_refit`): the members whose best replacement
#: (screened with the others refitted) explains most of their part.
REPLACE_REFITS = 4
#: A member whose part (the state's TE minus the TE without it, on the screening grid) has at least this share of
#: its sum of squares in its mean is refitted away together with a constant offset before the stop
#: (:meth:`ReplacementRefit.offset_instance_refit`): a disc phase's part is mostly a constant.
OFFSET_LIKE = 0.5
#: Two look-alikes of a member whose fitted screening signatures correlate beyond this are refitted beside it as
#: a pair when neither alone is kept (:meth:`ReplacementRefit.lookalike_refit`): a variance inflation above 5
#: each, so what they add together lies mostly along their difference, which no linear test at the state sees.
LOOKALIKE_PAIR_CORRELATION = 0.9
#: The closest look-alikes of a member (of distinct error types) among which that pair is sought: seed 1's pin radius
#: and pin circle diameter are the disc phase's second and third (a pin pitch is its first).
LOOKALIKE_PAIR_POOL = 3
#: Members (crank / disc / hole instances the data need, those whose removal costs most in the model linearised
#: at the state) refitted through rvdyn with their half-turn twin in their place before the loop stops
#: (:meth:`ReplacementRefit.twin_refit`): each trial is a refit of the whole model (about 10 s CPU on a realistic
#: draw), made at every state where the loop would stop.
TWIN_REFITS = 2


class ReplacementRefit(JointSelection):
    """The checks before the loop stops (methods on the loop)."""

    def added_variable_ranking(self, rc_cat: np.ndarray, Ec: np.ndarray | None) -> tuple[list[Candidate], dict]:
        """The library ranked by the added-variable (partial) test at the current state: every candidate's
        signature and the coarse residual projected orthogonal to the model's columns (its effects
        linearised at the state, :meth:`active_members`, and its empirical terms), i.e. the F test of
        adding the candidate with every member refitted (Frisch-Waugh-Lovell). Returns the ranking
        when its best candidate passes the loop's F test (Bonferroni level ``self.thr``) and lowers the
        BIC on the screening grid, else an empty list; and a log record.

        Why: the plain screening holds every member at its size, so its fit of a candidate ``x`` to the
        residual ``r`` (which the last refit made orthogonal to the members' columns ``X``) removes
        ``(r.x)^2 / |x|^2``, while adding ``x`` with the members free removes ``(r.x)^2 / |P x|^2``
        (``P`` the projector orthogonal to ``X``). For a candidate that resembles the members (the
        all-pins pin circle diameter beside a compliance, a disc phase and a carrier-hole eccentricity)
        ``|P x| << |x|`` and the plain screening understates it many times: the loop stopped with
        "nothing passes" on realistic draws whose all-pins pin circle diameter (1.9-2.6 um) was never
        named and a member stood in for it (docs/calibration.md)."""
        members = self.active_members()
        blocks = [m.cols for m in members] + ([Ec] if Ec is not None else [])
        X = np.column_stack(blocks)
        ranking = [d for d in self.rank(rc_cat, X, None) if d.cols is not None and not d.effect.expensive]
        if not ranking:
            return [], {}
        r = projector(X)(rc_cat)
        rss0 = float(r @ r)
        p_cur = self._p_cur()
        d = ranking[0]
        k = d.effect.n_params
        rss1 = rss0 * max(1.0 - d.explained, 1e-12)
        F, pv = ftest(rss0, rss1, k, self.nc, p_cur + k)
        dbic = bic(rss1, self.nc, p_cur + k) - bic(rss0, self.nc, p_cur)
        rec = {"best": d.effect.name, "explained_fraction": d.explained, "F": F, "p": pv, "delta_bic": dbic,
               "top": [{"name": c.effect.name, "explained_fraction": c.explained} for c in ranking[:6]]}
        return (ranking if pv < self.thr and dbic < 0 else []), rec

    def instance_refit(self) -> list[tuple[str, str]]:
        """Before the loop stops: every crank / disc / hole instance in the model refitted through the full
        model with an instance of each other family of its error type in its place (:meth:`siblings` with
        ``other_families``; the swap kept when it lowers the BIC on all samples by more than
        :data:`JOINT_BIC_MARGIN`, and the descent goes on from it). Returns the (old, new) names swapped.

        Why: the instance of an error (which crank, disc or hole) is a discrete parameter of the model,
        and a final state is a local optimum only if no instance change lowers the BIC. The sibling refit
        at entry tries a pin's neighbours; a crank / disc / hole instance's own family is its half-turn
        twin only, so nothing re-checked which disc or hole. Measured on realistic draw seed 1 (physical
        law): the model ended with the disc-hole eccentricity of disc 1 hole 0 at -1.47 um for disc 0 hole
        0's +1.49 (not a twin on these data: refitted in its place the BIC falls by 19, the carrier-hole
        eccentricity goes from 1.68 to 3.05 um, truth 3.02). Tried at entry instead (every new instance
        checked against the other families), the swap was made in iteration 2 at 2.2x the noise and the
        path then went to empirical harmonics: the check is made where the state is final."""
        names = {a.effect.name for a in self.active
                 if a.effect.instance and not any(k == "pin" for k, _ in a.effect.instance)}
        if not names or self.over_budget():
            return []
        rc = np.concatenate(self.coarse_residual())
        return self.sibling_refit(names, rc, other_families=True)

    def twin_refit(self, it: int) -> tuple[str, str] | None:
        """Before the loop stops: each of the :data:`TWIN_REFITS` crank / disc / hole members whose removal costs
        most (in the model linearised at the state, on the screening grid; only members whose removal raises the
        BIC there by more than :data:`JOINT_BIC_MARGIN`) refitted through rvdyn with each other instance of its own
        family (its half-turn twin: disc 1's phase for disc 0's, crank 1's planet eccentricity for crank 0's) in
        its place, from the member's own size; the swap that lowers the BIC on all samples most, by more than the
        margin, is made. Returns (old, new) or None.

        Why: a twin gives the instance's TE on the symmetric declared reducer (the library puts it in the
        instance's family and the other checks leave it out: the data cannot prefer it there), but not beside
        the other errors of a realistic reducer, which sit on one crank or disc. Realistic seed 11 (stop 36) ended
        with disc 1's phase at -0.063 deg for disc 0's -0.062, and cam phases of -13 and -16 um on disc 0 (truth
        +4.1 um on crank 0) and planet eccentricities of 11 and 22 um on both cranks (truth 4.5 um on crank 0)
        making up for it, RMS 0.237 arcsec (noise 0.2); no linear test at the state ranked disc 0's phase in its
        place. Refitted through rvdyn with disc 0's phase at the same size in its place (by hand, stop 37) the BIC
        fell by 311 (RMS 0.2106), the swaps of the cam phase for its twins rose by 48-168."""
        if not self.active or self.over_budget():
            return None
        members = self.active_members()
        rc = np.concatenate(self.coarse_residual())
        Ec = self._emp_matrix(self.empirical, coarse=True)
        fit = joint_linear_fit(members, rc, Ec)
        costs = linear_removal_costs(members, rc, Ec, fit)
        rss_grid = float(fit[3] @ fit[3])
        in_model = {a.effect.name for a in self.active}
        order = []
        for cost, i, _, _ in sorted(costs, key=lambda c: -c[0]):
            e = members[i].effect
            if e is None or e.family == "measurement" or not e.instance or any(k == "pin" for k, _ in e.instance):
                continue
            needed = self.nc * math.log((rss_grid + max(cost, 0.0)) / max(rss_grid, 1e-300))
            if needed <= e.n_params * math.log(self.nc) + JOINT_BIC_MARGIN:
                continue
            order.append(i)
        p_cur = self._p_cur()
        bic_cur = bic(self.rss_full, self.n, p_cur)
        found = None
        for i in order[:TWIN_REFITS]:
            a = self.active[i]
            fam = a.effect.template or a.effect.name
            keep = [b for k, b in enumerate(self.active) if k != i]
            for x in self.lib:
                if self.over_budget():
                    break
                if (x.template or x.name) != fam or x.name in in_model or x.expensive:
                    continue
                p0 = [b.p for b in keep] + [np.clip(np.asarray(a.p, dtype=float), x.lower, x.upper)]
                found = self.swap_trial([b.effect for b in keep] + [x], p0, p_cur, bic_cur,
                                        f"twin refit: {x.name} in place of {a.effect.name}", found, i, x)
        if found is None:
            return None
        return self.adopt_swap(found, it, "twin refit before the stop")

    def offset_instance_refit(self, it: int) -> tuple[str, str] | None:
        """Before the loop stops, with a constant offset among the empirical terms: the model refitted through
        the full model without the offset, and with each of the best :data:`REPLACE_REFITS` other instances of
        a crank / disc / hole member's error type in the member's place and the offset dropped; the fit that
        lowers the BIC on all samples most (by more than :data:`JOINT_BIC_MARGIN`; one parameter fewer) is
        kept; so is the model without the offset and without one member whose part is mostly a constant
        (:data:`OFFSET_LIKE`). Returns (old, new) of the change, or None.

        Why: the TE is an output angle, and some errors trade their sign against a constant: a disc's phase at
        -a with an offset gives the TE of the same phase at +a (and disc 0's phase at +a, its twin). The
        instance check (:meth:`instance_refit`) keeps the offset in the model, so a swap there only ties (the
        offset goes to zero, the parameter count stays) and the empirical term keeps the constant; a refit
        from the state without the offset may not cross zero, hence the other instances as well. Measured on
        realistic draw seed 5 (stop 29, physical law): the joint step took a constant offset in iteration 1 (no disc phase in the model yet), later
        the disc phase of disc 1 at -0.0636 deg with the offset at -202 arcsec for disc 0's +0.0545 deg, and
        the loop ended with the offset reported unexplained and two disc-hole eccentricities 5-6 um off. With
        both discs' phases in the model the offset is redundant outright (equal phases of both discs turn the
        output as a whole), and the elimination at the term limit removed a disc phase before it."""
        offs = [t for t in self.empirical if t.kind == "offset" and t.factor == "common"]
        if not offs or not self.active or self.over_budget():
            return None
        members = [(i, a) for i, a in enumerate(self.active)
                   if a.effect.instance and not any(k == "pin" for k, _ in a.effect.instance)]
        rc = np.concatenate(self.coarse_residual())   # data minus the physics: the offset's part is in it
        base = self._grid_cat(self._pairs())
        in_model = {a.effect.name for a in self.active}
        parts = {i: self._part_of(a, base) for i, a in enumerate(self.active) if a.effect.family != "measurement"}
        # the candidates: every other instance of the member's error type (its own family's twins too: with
        # the offset dropped they are not twins), ranked by the part of the member's part plus the residual
        # (the offset's part included) their screening signature explains; the best REPLACE_REFITS refitted,
        # after the model itself without the offset (both discs' phases in the model make a constant too)
        trials: list[tuple[float, int, Effect, np.ndarray]] = []
        for i, a in members:
            part = parts[i]
            if part is None:
                continue
            target = rc + part
            groups: dict[int, tuple] = {}
            for x in self.lib:
                if x.key != a.effect.key or not x.instance or x.name in in_model or x.expensive:
                    continue
                d = self.screen_effect(x, groups, target, None)
                if d is not None and d.explained > 0:
                    trials.append((d.explained, i, x, np.asarray(d.p, dtype=float)))
        trials.sort(key=lambda z: -z[0])
        # and each member whose part is mostly a constant removed with the offset (the share of its part's
        # sum of squares in its mean over the grid at least OFFSET_LIKE): realistic seed 5 held both discs'
        # phases and the offset for disc 0's phase alone
        const = sorted(((float(part.mean() ** 2 / np.mean(part ** 2)), i) for i, part in parts.items()
                        if part is not None and np.any(part)), key=lambda z: -z[0])
        const = [(sh, i) for sh, i in const if sh >= OFFSET_LIKE]
        # each trial: the members (Active kept, or a new effect with its start) and what it does
        plans: list[tuple[list[tuple[Active | Effect, np.ndarray]], str]] = [
            ([(a, a.p) for a in self.active], "the {t} dropped, the members refitted")]
        plans += [([(a, a.p) for k, a in enumerate(self.active) if k != i],
                   f"{self.active[i].effect.name} and the {{t}} removed (a constant makes {sh:.2f} of its part)")
                  for sh, i in const[:REPLACE_REFITS]]
        plans += [([((x, np.clip(q, x.lower, x.upper)) if k == i else (a, a.p)) for k, a in enumerate(self.active)],
                   f"{x.name} in place of {self.active[i].effect.name} and the {{t}} (screened {expl:.3f})")
                  for expl, i, x, q in trials[:REPLACE_REFITS]]
        p_cur = self._p_cur()
        bic_cur = bic(self.rss_full, self.n, p_cur)
        found = None
        for t in offs:
            rest = [u for u in self.empirical if u is not t]
            for members_new, what in plans:
                if self.over_budget():
                    break
                effects = [m.effect if isinstance(m, Active) else m for m, _ in members_new]
                k = sum(e.n_params for e in effects) + sum(u.n_cols for u in rest)
                said = what.format(t=t.label)
                # a swap like any other: not refitted again when it lost far at an earlier state, and fitted at the
                # subset's readings first (realistic seed 5, stop 38's code: the disc phase removed with the offset
                # took 150 s CPU through every reading to end 15,400 BIC units above the state)
                memo = said.split(" (")[0]                     # the change without its screened share
                why = self.swap_hopeless(memo, "offset refit", bic_cur)
                if why:
                    self.log(f"offset refit: {said}: not refitted: {why}")
                    continue
                try:
                    if effects:
                        got = self.trial_refit(effects, [p for _, p in members_new], k, rest)
                    else:
                        got = [], float(np.sum(self.full_residual([], rest)[0] ** 2))
                except ModelEvaluationError:
                    continue
                if isinstance(got, str):
                    self.log(f"offset refit: {said}: {got}")
                    continue
                params, rss = got
                b_new = bic(rss, self.n, k)
                self.note_swap(memo, "offset refit", bic_cur, b_new)
                self.log(f"offset refit: {said}: RMS {math.sqrt(rss / self.n):.4g}, dBIC {b_new - bic_cur:.1f}")
                if b_new < bic_cur - JOINT_BIC_MARGIN and (found is None or b_new < found[0]):
                    found = (b_new, members_new, params, rest, t, said)
        if found is None:
            return None
        b_new, members_new, params, rest, t, what = found
        new_active = []
        for (m, _), p in zip(members_new, params):
            if isinstance(m, Active):
                m.p = p
                new_active.append(m)
            else:
                new_active.append(Active(m, p, it, info={
                    "delta_bic": b_new - bic_cur,
                    "selection": {"method": "offset refit before the stop", "iteration": it, "change": what}}))
        kept, before = {id(a) for a in new_active}, {id(a) for a in self.active}   # by identity (Active holds arrays)
        gone = [a.effect.name for a in self.active if id(a) not in kept]
        came = [a.effect.name for a in new_active if id(a) not in before]
        self.active = new_active
        self.empirical = rest
        self._emp_info.pop(t, None)
        self.refresh_state()
        return (" and ".join(gone + [f"the {t.label}"]),
                ", ".join(came) if came else "the members refitted without " + ("them" if gone else "it"))

    def replacement_refit(self, it: int) -> tuple[str, str] | None:
        """Before the loop stops at the term limit: each member refitted through the full model with the
        best candidate of another family in its place, the swap that lowers the BIC on all samples most
        (by more than :data:`JOINT_BIC_MARGIN`) kept.

        Why: the subset search and the replacement shortlist judge a swap in the model linearised at the
        state, where each member moves only a little. Under rvdyn's physical law a member that stands
        in for another error can sit far from its own truth, and the swap that leaves the stand-in then
        moves a partner far as well: on the realistic draw seed 1 the model held the planet eccentricity
        of both cranks at 14.3 um for a cam phase and a planet eccentricity of 2.74 um; linearly the cam
        phase in place of crank 1's planet eccentricity explains 30 % of its part (the swap looks worse),
        refitted through rvdyn the crank-0 planet eccentricity goes to 2.99 um and the BIC falls by 134.
        The candidates: for each physical member, the library ranked against its part plus the residual
        with every other member and empirical term refitted (as in
        :meth:`rvcalib.selection.Selection.replacement_shortlist`), the best of another family not in the
        model; the :data:`REPLACE_REFITS` members whose best explains most are refitted. Returns
        (old, new) of the swap made, or None."""
        if not self.active or self.over_budget():
            return None
        members = self.active_members()
        Ec = self._emp_matrix(self.empirical, coarse=True)
        rc = np.concatenate(self.coarse_residual())
        blocks, col0, coef, r = joint_linear_fit(members, rc, Ec)
        in_model = {a.effect.name for a in self.active}
        trials = []
        for i, m in enumerate(members):
            if m.effect is None or m.effect.family == "measurement":
                continue
            fam = m.effect.template or m.effect.name
            t, others = member_target(members, blocks, i, r, coef, col0)
            best = next((d for d in self.rank(t, others, None)
                         if d.effect.family != "measurement" and not d.effect.expensive
                         and d.effect.name not in in_model and d.family_key != fam), None)
            if best is not None and best.explained > 0:
                trials.append((best.explained, i, best))
        trials.sort(key=lambda x: -x[0])
        p_cur = self._p_cur()
        bic_cur = bic(self.rss_full, self.n, p_cur)
        found = None
        for expl, i, d in trials[:REPLACE_REFITS]:
            if self.over_budget():
                break
            x = d.effect
            effects = [x if k == i else a.effect for k, a in enumerate(self.active)]
            p0 = [np.clip(np.asarray(d.p, dtype=float), x.lower, x.upper) if k == i else a.p
                  for k, a in enumerate(self.active)]
            found = self.swap_trial(effects, p0, p_cur - self.active[i].effect.n_params + x.n_params, bic_cur,
                                    f"replacement refit: {x.name} in place of {self.active[i].effect.name} "
                                    f"(screened {expl:.3f})", found, i, x)
        if found is None:
            return None
        _, i, x, params, rss = found
        old = self.active[i].effect.name
        for a, p in zip(self.active, params):
            a.p = p
        self.active[i] = Active(x, params[i], it, info={
            "explained_fraction": 1.0 - rss / self.rss_full, "delta_bic": found[0] - bic_cur,
            "selection": {"method": "replacement refit at the term limit", "iteration": it, "replaced": old}})
        r_full = self.refresh_state()
        return old, x.name

    def swap_trial(self, effects: list[Effect], p0: list[np.ndarray], k: int, bic_cur: float, what: str,
                   found: tuple | None, i: int, x: Effect) -> tuple | None:
        """A swap of member ``i`` for ``x`` (the model's ``effects``) refitted through rvdyn from ``p0`` (``k``
        parameters in all, the empirical terms projected out) and logged as ``what`` with its RMS and the BIC's
        change from ``bic_cur``: ``(BIC, i, x, parameters, RSS)`` when it lowers the BIC by more than
        :data:`JOINT_BIC_MARGIN` and below ``found`` (the best swap so far, or None), else ``found``."""
        member = self.active[i].effect.name
        why = self.swap_hopeless(member, x.name, bic_cur)
        if why:
            self.log(f"{what}: not refitted: {why}")
            return found
        try:
            got = self.trial_refit(effects, p0, k)
        except ModelEvaluationError:
            return found
        if isinstance(got, str):
            self.log(f"{what}: {got}")
            return found
        params, rss = got
        b_new = bic(rss, self.n, k)
        self.note_swap(member, x.name, bic_cur, b_new)
        self.log(f"{what}: RMS {math.sqrt(rss / self.n):.4g}, dBIC {b_new - bic_cur:.1f}")
        if b_new < bic_cur - JOINT_BIC_MARGIN and (found is None or b_new < found[0]):
            return b_new, i, x, params, rss
        return found

    def adopt_swap(self, found: tuple, it: int, method: str) -> tuple[str, str]:
        """Make the swap ``found`` (:meth:`swap_trial`'s ``(BIC, member index, candidate, parameters, RSS)``, the
        candidate's parameters last): the member leaves, the others take their refitted sizes, the candidate
        enters last with its selection record (``method``, the iteration ``it``, the member it replaced), and
        the state is refreshed. Returns (member, candidate)."""
        b_new, i, x, params, rss = found
        bic_cur = bic(self.rss_full, self.n, self._p_cur())
        old = self.active[i].effect.name
        keep = [a for k, a in enumerate(self.active) if k != i]
        for a, p in zip(keep, params):
            a.p = p
        keep.append(Active(x, params[-1], it, info={
            "explained_fraction": 1.0 - rss / self.rss_full, "delta_bic": b_new - bic_cur,
            "selection": {"method": method, "iteration": it, "replaced": old}}))
        self.active = keep
        self.refresh_state()
        return old, x.name

    def lookalike_refit(self, it: int) -> tuple[str, str] | None:
        """Before the loop stops below the term limit: the model refitted through rvdyn with each member's
        closest look-alike of another error type *added* (the library ranked against the member's part
        alone: the candidate whose signature at the state best reproduces it); the addition that lowers
        the BIC on all samples most (by more than :data:`JOINT_BIC_MARGIN`) and passes the loop's F test
        there is kept. Returns (member, added) or None.

        Why: a candidate whose signature nearly coincides with a member's (correlation 0.92 between the
        all-pins pin circle diameter and the pin radius at seed 2's final state) has almost nothing left
        once the member's column is projected out, so every linear test at the state (the plain
        screening, the added-variable test, the subset search) gives it nothing; under the physical law
        the two differ at the sizes of a realistic reducer, and the nonlinear refit with both free moves
        them and the members they touch far from the linearisation (seed 2: the pin circle diameter added
        from zero goes to 2.74 um (truth 2.58), the pin radius from -0.39 to +0.48 (0.47), the planet
        eccentricity from 3.9 to 2.9 um; RMS 0.2101 -> 0.2010, F 123 on all samples). Near-collinear
        columns are where the linearisation cannot decide and the full model must, at the cost of one
        refit per member (each member's look-alike, once per model state at which the loop would stop;
        ranked by how much of the member's part they reproduce, the first four did not hold seed 2's pin
        circle diameter).

        When no single look-alike is kept, for each member the two of its :data:`LOOKALIKE_PAIR_POOL` closest
        look-alikes (of distinct other error types) whose fitted signatures correlate most, when beyond
        :data:`LOOKALIKE_PAIR_CORRELATION`, are refitted beside it together
        (both from zero; the F test with both's parameters): one alone can only move along its own signature,
        where the member already is, while together they move along their difference. Seed 1 (physical law):
        the all-pins pin circle diameter (truth 1.94 um) and pin radius (0.61) beside the disc phase, each
        alone staying near zero, together BIC -73.6 and both sizes within tolerance (docs/calibration.md)."""
        if not self.active or self.over_budget():
            return None
        members = self.active_members()
        in_model = {a.effect.name for a in self.active}
        fams_in = {a.effect.template or a.effect.name for a in self.active}
        trials: dict[str, tuple[float, object, str]] = {}
        pair_trials: dict[tuple[str, str], tuple[float, tuple, str]] = {}
        for m in members:
            if m.effect is None or m.effect.family == "measurement":
                continue
            part = m.contribution if m.contribution is not None else m.cols @ np.asarray(m.active.p, dtype=float)
            if float(part @ part) <= 0:
                continue
            ok = [d for d in self.rank(part, None, None)
                  if d.effect.family != "measurement" and not d.effect.expensive and d.cols is not None
                  and d.effect.name not in in_model and d.family_key not in fams_in
                  and d.effect.key != m.effect.key]
            if not ok:
                continue
            best = ok[0]
            if best.explained > trials.get(best.effect.name, (0.0,))[0]:
                trials[best.effect.name] = (best.explained, best.effect, m.effect.name)
            # its closest look-alikes of three error types: the pair of them that nearly coincide (the pair's trial)
            top: list = []
            for d in ok:
                if d.fit is not None and all(d.effect.key != x.effect.key for x in top):
                    top.append(d)
                if len(top) == LOOKALIKE_PAIR_POOL:
                    break
            near = [(abs(_correlation(x.fit, y.fit)), x, y) for i, x in enumerate(top) for y in top[i + 1:]]
            if near:
                rho, x, y = max(near, key=lambda t: t[0])
                # one trial per pair of error types, the first member's (in the model's order) instances: the
                # instance is the instance and sibling refits' choice (seed 1: the pin circle diameter and pin
                # radius of pins 0, 19 and 35 beside three more members, each pair correlating 1.000, none kept)
                key = tuple(sorted((x.effect.key, y.effect.key)))
                if rho >= LOOKALIKE_PAIR_CORRELATION and key not in pair_trials:
                    pair_trials[key] = (rho, (x.effect, y.effect), m.effect.name)
        order = sorted(trials.values(), key=lambda t: -t[0])
        if order or pair_trials:
            self.keep_state_jacobian()  # each trial starts at the state: only its candidates' columns differenced
        p_cur = self._p_cur()
        bic_cur = bic(self.rss_full, self.n, p_cur)
        found = None
        for expl, x, mname in order:
            if self.over_budget():
                break
            got = self._lookalike_trial([x], mname, p_cur, bic_cur, f"reproduces {expl:.3f} of its part")
            if got is not None and (found is None or got[0] < found[0]):
                found = got
        if found is None:
            # neither alone: the near-coincident pairs together (seed 1: the all-pins pin circle diameter and pin
            # radius, 1.94 and 0.61 um, beside the disc phase; each alone stays near zero, together BIC -73.6)
            for rho, xs, mname in pair_trials.values():
                if self.over_budget():
                    break
                got = self._lookalike_trial(list(xs), mname, p_cur, bic_cur, f"signatures correlate {rho:.3f}")
                if got is not None and (found is None or got[0] < found[0]):
                    found = got
        if found is None:
            return None
        b_new, xs, params, rss, mname, F, pv = found
        n_old = len(self.active)
        for a, p in zip(self.active, params[:n_old]):
            a.p = p
        for x, p in zip(xs, params[n_old:]):
            self.active.append(Active(x, p, it, info={
                "explained_fraction": 1.0 - rss / self.rss_full, "F": F, "p_value": pv, "delta_bic": b_new - bic_cur,
                "selection": {"method": "look-alike refit before the stop", "iteration": it, "beside": mname,
                              "together_with": [y.name for y in xs if y is not x]}}))
        r_full = self.refresh_state()
        return mname, " and ".join(x.name for x in xs)

    def lookalike_store(self) -> dict:
        """The look-alike refits made: model state (:meth:`_state_key`) -> list of ``{effects, params, rss,
        delta_bic, added, beside}``, one per trial, kept or not."""
        if not hasattr(self, "_lookalike_fits"):
            self._lookalike_fits: dict = {}
        return self._lookalike_fits

    def _lookalike_trial(self, xs: list, mname: str, p_cur: int, bic_cur: float, why: str):
        """The model refitted through rvdyn with ``xs`` added from zero: (BIC, xs, parameters, RSS, member, F,
        p) when the addition passes the loop's F test on all samples and lowers the BIC by more than
        :data:`JOINT_BIC_MARGIN`, else None."""
        effects = [a.effect for a in self.active] + list(xs)
        p0 = [a.p for a in self.active] + [np.zeros(x.n_params) for x in xs]
        try:
            params, rss, _, _, J = self.fit_full(effects, p0, self.empirical)
        except ModelEvaluationError:
            return None
        kx = sum(x.n_params for x in xs)
        k = p_cur + kx
        b_new = bic(rss, self.n, k)
        F, pv = ftest(self.rss_full, rss, kx, self.n, k)
        self.log(f"look-alike refit: {' and '.join(x.name for x in xs)} added beside {mname} ({why}): "
                 f"RMS {math.sqrt(rss / self.n):.4g}, dBIC {b_new - bic_cur:.1f}, p {pv:.3g}")
        # every trial kept with its state: at the final state the sizes are averaged over them by their BIC weights
        # (rvcalib.pairs.PairCheck.lookalike_average)
        self.lookalike_store().setdefault(self._state_key(), []).append(
            {"effects": effects, "params": params, "rss": float(rss), "delta_bic": float(b_new - bic_cur),
             "added": [x.name for x in xs], "beside": mname, "std_err": _std_errors(effects, J, rss, self.n, k)})
        if pv < self.thr and b_new < bic_cur - JOINT_BIC_MARGIN:
            return b_new, list(xs), params, rss, mname, F, pv
        return None


def _std_errors(effects: list[Effect], J: np.ndarray | None, rss: float, n: int, k: int) -> dict[str, float]:
    """Standard errors (effect units) of the one-parameter effects of a fit from its Jacobian ``J`` at the solution
    (scaled parameters, the empirical terms projected out), ``sigma^2 (J^T J)^-1`` with ``sigma^2 = rss / (n - k)``
    (``k`` parameters with the empirical terms); empty without a Jacobian."""
    if J is None or np.size(J) == 0:
        return {}
    J = np.asarray(J, dtype=float)
    cov = (rss / max(1, n - k)) * np.linalg.pinv(J.T @ J)
    out, i = {}, 0
    for e in effects:
        if e.n_params == 1 and i < cov.shape[0]:
            out[e.name] = float(math.sqrt(max(cov[i, i], 0.0))) * e.scale
        i += e.n_params
    return out


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Cosine of the angle between two signatures (their correlation through the origin, as the screening
    fits them)."""
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    return float(a @ b) / (na * nb) if na > 0 and nb > 0 else 0.0
