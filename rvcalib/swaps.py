"""Sibling and swap refits of the joint selection (rvcalib.joint): the other instances of a family refitted in
place of one that has just entered the model, the swap trials of the checks before the stop (refitted first at a
subset of the readings, and not again at a later state when they lost far), and the members' present parts on the
screening grid that both use. Methods on the loop, as the joint stage."""
from __future__ import annotations

import math

import numpy as np

from rvcalib.effects import Effect
from rvcalib.forward import ModelEvaluationError
from rvcalib.lsq import bic
from rvcalib.results import Active
from rvcalib.selection import Selection
from rvcalib.subsets import JOINT_BIC_MARGIN

#: Siblings refitted in place of an instance that has just entered the model (see
#: :meth:`JointSelection.sibling_refit`).
SIBLING_REFITS = 2
#: A swap (a member out, a candidate in its place) refitted through rvdyn at an earlier state, where it raised
#: the BIC by ``d``, is not refitted again at a later state that has gained ``g`` BIC units since, when
#: ``d > REPEAT_HOPELESS g + JOINT_BIC_MARGIN`` (:meth:`JointSelection.swap_hopeless`): the later state differs
#: by the changes that gained ``g``, and the swap would have to gain more than ten times as much from them. The
#: largest recovery seen on the realistic draws was 4.2 g (seed 7, stop 37: a disc phase in the compliance's
#: place lost 3799 units, then 2092 after the state had gained about 409).
REPEAT_HOPELESS = 10.0
#: A swap trial is refitted first at every k-th reading of each run, k the largest that leaves at least this many
#: readings per output revolution (the pin scan's ``PIN_SCAN_ROWS_PER_REV``: k = 3 on the realistic draws), and
#: through every reading only when its BIC at those readings is not above the state's by more than
#: :data:`SUBSET_HOPELESS` (:meth:`JointSelection.trial_refit`).
SUBSET_ROWS_PER_REV = 110
#: ... BIC units at the subset's readings: a third of the readings scale a BIC change by about a third, so 10 there
#: is about 30 on every reading, far beyond the margin a swap must win by; the state is not refitted at the subset
#: (the trial is), which favours the trial.
SUBSET_HOPELESS = 10.0


class SwapTrials(Selection):
    """Sibling and swap refits (methods on the loop; see the module docstring)."""

    def _grid_cat(self, pairs: list[tuple[Effect, np.ndarray]], sensitivity: bool = False) -> np.ndarray:
        return np.concatenate(self.predict_grid(pairs, sensitivity=sensitivity))

    def _part_of(self, a: Active, base: np.ndarray) -> np.ndarray | None:
        """The present part of member ``a`` on the screening grid: the state's TE (``base``) minus the TE
        of the state without ``a``; None when rvdyn cannot evaluate the state without it (errors that
        compensate each other, e.g. thinner pins on a smaller pin circle: without one of them the parts
        overlap beyond what a contact law holds; realistic seed 5 at stop 29 stopped with a traceback
        here). The caller then takes the member's local derivative at the state times its size."""
        try:
            return base - self._grid_cat([(b.effect, b.p) for b in self.active if b is not a])
        except ModelEvaluationError:
            self.log(f"the state without {a.effect.name} cannot be evaluated by rvdyn: its part is taken "
                     f"as its derivative at the state times its size")
            return None


    def siblings(self, a: Active, rc: np.ndarray, n: int = SIBLING_REFITS,
                 sigma2: float = 0.0, other_families: bool = False) -> list[tuple[Effect, np.ndarray]]:
        """The other instances of an effect's family (one pin's pitch among the pins, a cam error of one
        crank and disc among the others) closest to it on these data, with a start for their refit.

        The target is the residual on the screening grid with the effect's part given back (``rc`` plus
        its contribution at its fitted size). Instances related by the rotational symmetry of the pins
        (:attr:`Effect.shift_deg`) are ranked by how well the effect's own contribution rotated by their
        pin-pitch difference reproduces it (its fitted size, not the typical one: under rvdyn's physical
        law a pin's TE change is far from proportional to its error); other families by their screening
        signatures at the state (:meth:`screen_effect`). For a pin instance, a sibling whose column
        reproduces the effect's own within the noise (``sigma2``, arcsec^2: the chi-square rule of
        :meth:`_alternatives`; twins such as pins 20 apart) is left out: the data cannot prefer it, and the
        groups report it. With ``other_families`` (the instance check before the stop,
        :meth:`rvcalib.replace.ReplacementRefit.instance_refit`) a crank / disc / hole instance's siblings are instead the other families of
        its error type (its own family is its half-turn twin only), one instance each; they are not exact
        twins, and the refit decides between them (a linear screening at the state can see two instances
        of opposite sign as alike while the refit, moving the other members, tells them apart). Returns at most
        ``n`` (effect, start parameters), best first; an effect of no family, an empty list."""
        e = a.effect
        if e.family == "measurement":
            return []
        fam = e.template or e.name
        in_model = {b.effect.name for b in self.active}
        pinwise = any(k == "pin" for k, _ in e.instance)
        other = bool(other_families and e.instance and not pinwise)
        if other:
            # a crank / disc / hole instance: its own family holds only its half-turn twin (the same TE on
            # a symmetric reducer, which the data cannot prefer); its siblings are the other instances of
            # the same error type, one per family (the family's first in the library), of the families
            # with no member in the model (seed 1, physical law: the disc-hole eccentricity of disc 1 hole
            # 0 at -1.47 um stood in for disc 0 hole 0's +1.49 and pulled the carrier-hole eccentricity
            # from 3.0 to 1.7 um; refitted with disc 0 hole 0 in its place the BIC falls by 19)
            fam_in_model = {b.effect.template or b.effect.name for b in self.active}
            heads: dict[str, Effect] = {}
            for x in self.lib:
                fx = x.template or x.name
                if x.key == e.key and x.instance and fx != fam and fx not in fam_in_model and not x.expensive:
                    heads.setdefault(fx, x)
            sibs = list(heads.values())
        else:
            sibs = [x for x in self.lib if (x.template or x.name) == fam and x.name not in in_model
                    and not x.expensive]
        if not sibs:
            return []
        p = np.asarray(a.p, dtype=float)
        contrib = self._part_of(a, self._grid_cat(self._pairs()))
        if contrib is None:
            return []  # no present part to replace (the state without the member cannot be evaluated)
        target = rc + contrib
        tt = float(target @ target)
        if tt <= 0:
            return []
        ranked: list[tuple[float, Effect, np.ndarray]] = []
        if not other and e.n_params == 1 and e.screen == "two_sided" and abs(float(p[0])) > 0 \
                and all(x.n_params == 1 for x in sibs):
            blocks = contrib.reshape(len(self.runs), self.m)
            for x in sibs:
                roll = (x.shift_deg - e.shift_deg) / 360.0 * self.m
                if abs(roll - round(roll)) > 1e-9:
                    continue
                col = np.roll(blocks, int(round(roll)), axis=1).ravel()
                dd = col - contrib
                if float(dd @ dd) * self.n / self.nc < 3.84 * sigma2:
                    continue  # the same on these data (a twin)
                c = float(col @ target) / max(float(col @ col), 1e-300)
                r = target - c * col
                ranked.append((1.0 - float(r @ r) / tt, x, p * c))
        else:
            groups: dict[int, tuple] = {}
            own = self.screen_effect(e, groups, target, None)
            for x in sibs:
                d = self.screen_effect(x, groups, target, None)
                if d is None:
                    continue
                if not other and own is not None and own.fit is not None and d.fit is not None:
                    # (the other crank / disc / hole families are not twins: the refit decides)
                    dd = d.fit - own.fit
                    if float(dd @ dd) * self.n / self.nc < 3.84 * sigma2:
                        continue
                ranked.append((d.explained, x, np.asarray(d.p, dtype=float)))
        ranked.sort(key=lambda t: -t[0])
        return [(x, q) for _, x, q in ranked[:n]]

    def sibling_refit(self, names: set[str], rc: np.ndarray, other_families: bool = False) -> list[tuple[str, str]]:
        """Refit the model with each of an instance's nearest siblings in its place (the instances of
        ``names`` that have just entered) and keep the one that leaves the smallest residual on all
        samples (the same number of parameters: the BIC and the F test rank them alike), when it lowers
        the BIC by more than :data:`JOINT_BIC_MARGIN` (twin instances tie and keep the first).

        Which instance of a family ranks first is decided by linear screening at a state where other
        effects may still be missing; neighbouring instances have close signatures (under rvdyn's
        physical law a pin's lies 0.87 arcsec RMS from its neighbour's, 1.70 under the impact law), so
        the first-ranked can be a neighbour of the truth, and nothing later replaces it (the subset
        search sees one instance per family, and the residual beyond it no longer ranks the truth).
        The instance index is a discrete parameter of the effect: it is chosen here by the same
        nonlinear refit as the sizes, among the :data:`SIBLING_REFITS` siblings ranked by
        :meth:`siblings`, and again from the new instance while a swap lowers the residual (a descent over
        the instance index; instances already tried are not tried again). ``rc``: the residual on the
        screening grid at the state. Returns the (old, new) names swapped, in order."""
        swapped: list[tuple[str, str]] = []
        todo = [b for b in self.active if b.effect.name in names]
        tried: set[str] = set()
        while todo:
            a = todo.pop(0)
            tried.add(a.effect.name)
            if self.over_budget():
                break
            r_now, _ = self.full_residual(self._pairs(), self.empirical)
            # the families tried (a crank / disc / hole instance's twin gives the same TE as the instance)
            tried_fam = {self.lib.by_name(t).template or t for t in tried
                         if not any(k == "pin" for k, _ in self.lib.by_name(t).instance)} if other_families else set()
            sibs = [(x, q) for x, q in self.siblings(a, rc, SIBLING_REFITS + len(tried), self._noise2(r_now),
                                                     other_families)
                    if x.name not in tried and (x.template or x.name) not in tried_fam]
            sibs = sibs[:SIBLING_REFITS]
            if not sibs:
                continue
            best = None
            k_cur = self._p_cur()
            bic_cur = bic(self.rss_full, self.n, k_cur)
            for x, q in sibs:
                if self.over_budget():
                    break
                why = self.swap_hopeless(a.effect.name, x.name, bic_cur)
                if why:
                    self.log(f"sibling refit: {x.name} not refitted in place of {a.effect.name}: {why}")
                    continue
                effects = [x if b is a else b.effect for b in self.active]
                p0 = [np.clip(q, x.lower, x.upper) if b is a else b.p for b in self.active]
                k_new = k_cur - a.effect.n_params + x.n_params
                try:
                    # the checks before the stop (other families: mostly far worse) at the subset first; a new
                    # instance's neighbours (near ties, decided by the fit's end point) on every reading from the start
                    if other_families:
                        got = self.trial_refit(effects, p0, k_new)
                    else:
                        params, rss, *_ = self.fit_full(effects, p0, self.empirical)
                        got = (params, float(rss))
                except ModelEvaluationError:
                    continue
                if isinstance(got, str):
                    self.log(f"sibling refit: {x.name} in place of {a.effect.name}: {got}")
                    continue
                params, rss = got
                b_new = bic(rss, self.n, k_new)
                self.note_swap(a.effect.name, x.name, bic_cur, b_new)
                self.log(f"sibling refit: {x.name} in place of {a.effect.name}: RMS {math.sqrt(rss / self.n):.4g}, "
                         f"dBIC {b_new - bic_cur:.1f}")
                # a swap must be worth the joint choice's margin (twin instances, pins 20 apart, tie)
                worth = self.n * math.log(max(self.rss_full, 1e-300) / max(rss, 1e-300)) > JOINT_BIC_MARGIN
                if worth and (best is None or rss < best[0]):
                    best = (rss, x, params)
            if best is None:
                continue
            rss, x, params = best
            old = a.effect.name
            a.effect = x
            for b, p in zip(self.active, params):
                b.p = p
            a.info = dict(a.info or {}, sibling_refit={"replaced": old, "rss_before": self.rss_full, "rss": rss})
            self.refresh_state()
            swapped.append((old, x.name))
            # the new instance's own siblings next (a descent over the instance index): the first choice
            # can be several pins from the truth (pin 15 for 12 beside a drift stand-in)
            rc = np.concatenate(self.coarse_residual())
            todo.insert(0, a)
        return swapped

    def _swap_memo(self) -> dict:
        if not hasattr(self, "_swaps_tried"):
            self._swaps_tried: dict = {}
        return self._swaps_tried

    def swap_hopeless(self, member: str, candidate: str, bic_now: float) -> str | None:
        """Why the swap of ``member`` for ``candidate`` need not be refitted at the present state (BIC
        ``bic_now``): it lost at an earlier state by more than :data:`REPEAT_HOPELESS` times the BIC gained since
        (plus the margin); None when it must be refitted."""
        got = self._swap_memo().get((member, candidate))
        if got is None:
            return None
        bic_then, lost = got
        gained = max(bic_then - bic_now, 0.0)
        if lost > REPEAT_HOPELESS * gained + JOINT_BIC_MARGIN:
            return (f"it raised the BIC by {lost:.1f} at an earlier state, and the state has gained {gained:.1f} "
                    "since")
        return None

    def note_swap(self, member: str, candidate: str, bic_now: float, bic_swap: float) -> None:
        """Keep a swap refitted at the present state (BIC ``bic_now``; the swap's ``bic_swap``) for
        :meth:`swap_hopeless`."""
        self._swap_memo()[(member, candidate)] = (bic_now, bic_swap - bic_now)

    def trial_refit(self, effects: list[Effect], p0: list[np.ndarray], k: int, terms: list | None = None
                    ) -> tuple[list[np.ndarray], float] | str:
        """A swap trial (the model's ``effects`` from ``p0``, ``k`` parameters with the empirical terms: the state's,
        or ``terms`` when given, e.g. without its constant offset) refitted
        at the subset's readings (:data:`SUBSET_ROWS_PER_REV`), then from there through every reading unless its
        BIC at the subset is above the state's there by more than :data:`SUBSET_HOPELESS`. Returns (params, rss
        on all samples), or the reason it was left at the subset (a message). When the subset gives nothing to
        judge by (the state or the trial not evaluated there, no decrease) the trial is refitted through every
        reading from ``p0``. Raises ModelEvaluationError as :meth:`fit_full` does."""
        terms = self.empirical if terms is None else terms
        rows = self.subset_rows(SUBSET_ROWS_PER_REV)
        m = int(np.count_nonzero(rows))
        if m < self.n:
            rss_state = self._subset_state_rss(rows)
            got = self.fit_rows(effects, p0, terms, rows) if rss_state is not None else None
            if got is not None:
                p_sub, rss_sub = got
                d = bic(rss_sub, m, k) - bic(rss_state, m, self._p_cur())
                if d > SUBSET_HOPELESS:
                    return (f"left at {m} of {self.n} readings: RMS there {math.sqrt(rss_sub / m):.4g} against the "
                            f"state's {math.sqrt(rss_state / m):.4g}, dBIC {d:.1f}")
                p0 = p_sub
        params, rss, *_ = self.fit_full(effects, p0, terms)
        return params, float(rss)

    def _subset_state_rss(self, rows: np.ndarray) -> float | None:
        """The present state's residual sum of squares at ``rows`` (its sizes as they are, the empirical terms
        projected out there), kept per state."""
        key = (self._state_key(), self.rss_full, int(np.count_nonzero(rows)))
        kept = getattr(self, "_subset_state", None)
        if kept is not None and kept[0] == key:
            return kept[1]
        try:
            r, _ = self.full_residual(self._pairs(), self.empirical, rows)
        except ModelEvaluationError:
            return None
        self._subset_state = (key, float(r @ r))
        return self._subset_state[1]
