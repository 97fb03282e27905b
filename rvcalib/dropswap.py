"""A member dropped through the full model, the library screened at the state it leaves, the best there refitted.

Under the physical law a member can hold a size that stands in for an error the model lacks, where no check at the
state sees it: every linear test (the screening, the added-variable ranking, the replacement shortlist) judges a
swap in the model linearised at the state, and the look-alike and replacement refits only try candidates whose
signatures reproduce a member's part. Realistic seed 1 on the 2026-11-27 machine (stop 32's code, two workers):
the loop ended at RMS 0.2058 arcsec (noise 0.2) with the planet eccentricity of both cranks, 4.53 and 3.50 um
(truth 2.74 on crank 0 and a sun eccentricity of 1.15 um); linearly the sun eccentricity reproduces nothing of
crank 1's part (its removal costs 1.22 arcsec^2 on the grid and no candidate takes its place), and the replacement
refit tried four other swaps, none kept. Through rvdyn (by hand, /tmp script): crank 1's planet eccentricity
removed, the rest refitted, RMS 0.2091 (BIC +28.6); the library screened at that state ranks the sun eccentricity
second (0.6 % of the residual, at 0.24 um); refitted with it from there the sun eccentricity goes to 1.09 um,
crank 0's planet eccentricity to 2.77 um, and the BIC falls by 109 below the loop's end (RMS 0.1975).

The check (:meth:`DropSwap.drop_swap_refit`, once per model state before the loop stops):

1. The :data:`DROP_SWAP_MEMBERS` physical members whose removal costs least in the model linearised at the state
   (the rise of the residual sum of squares on the screening grid with every other member and empirical term
   refitted, as :meth:`rvcalib.selection.Selection.replacement_shortlist` ranks them) are each removed, and the
   others refitted through the full model (:meth:`rvcalib.fitting.Fitting.fit_full`).
2. At the state this leaves, the library is screened against the residual (the stored signatures); the
   :data:`DROP_SWAP_CANDIDATES` best candidates of another family than the member's (its own instances left out:
   the instance refit moves those), not expensive and not in the model, are each added (from their screened
   size) and the model refitted through rvdyn, unless it would leave more than :data:`DROP_SWAP_HOPELESS` times
   the state's residual sum of squares in the model linearised there.
3. The swap that lowers the BIC on all samples most, by more than ``JOINT_BIC_MARGIN``, replaces the state (one
   effect for one: the number of terms stays, so the check runs at the term limit too).
"""
from __future__ import annotations

import math

import numpy as np

from rvcalib.basins import BasinCheck
from rvcalib.forward import ModelEvaluationError
from rvcalib.lsq import bic
from rvcalib.selection import linear_removal_costs

#: Members (those whose removal costs least in the model linearised at the state) each dropped through rvdyn
#: by :meth:`DropSwap.drop_swap_refit`.
DROP_SWAP_MEMBERS = 2
#: Candidates (the best of the library screened at the state without the member, of other families, the
#: expensive ones left out) each refitted in the member's place: seed 1's sun eccentricity ranks first among them
#: (second behind the cam-bearing clearance, an expensive candidate). Each trial is a refit of the whole model
#: (about 8 s CPU on a realistic draw), so the check costs DROP_SWAP_MEMBERS * (1 + DROP_SWAP_CANDIDATES) refits.
DROP_SWAP_CANDIDATES = 1
#: A candidate is not refitted in the dropped member's place when, in the model linearised at the state without
#: the member, it would leave more than this many times the state's residual sum of squares
#: (``rss_without * (1 - explained fraction)``): the refit would have to beat its own linear prediction by more than
#: half of what it leaves. A cost rule: seed 1's swap, which the refit made (RMS 0.2091 -> 0.1975), left 1.03 times
#: the state linearly; the 5-run benchmark's pin radius in the torsional compliance's place left 416 times (a refit
#: of 3 s that reached RMS 3.5 arcsec, 23 times the state's).
DROP_SWAP_HOPELESS = 2.0


class DropSwap(BasinCheck):
    """The drop-and-rescreen refit before the loop stops (see the module docstring)."""

    def _cheapest_members(self) -> list[int]:
        """Indices in ``self.active`` of the :data:`DROP_SWAP_MEMBERS` physical members whose removal costs least
        in the model linearised at the state (screening grid, the others and the empirical terms refitted)."""
        members = self.active_members()
        costs = linear_removal_costs(members, np.concatenate(self.coarse_residual()),
                                     self._emp_matrix(self.empirical, coarse=True))
        return [i for _, i, _, _ in costs if members[i].effect.family != "measurement"][:DROP_SWAP_MEMBERS]

    def drop_swap_refit(self, it: int) -> tuple[str, str] | None:
        """Each of the cheapest members dropped through rvdyn, the library screened at the state that leaves and
        its best candidates refitted in the member's place (module docstring); the swap that lowers the BIC on
        all samples most, by more than ``JOINT_BIC_MARGIN``, is made. Returns (dropped, added) or None."""
        if not self.active or self.over_budget():
            return None
        p_cur = self._p_cur()
        bic_cur = bic(self.rss_full, self.n, p_cur)
        in_model = {a.effect.name for a in self.active}
        Ec = self._emp_matrix(self.empirical, coarse=True)
        found = None
        for i in self._cheapest_members():
            if self.over_budget():
                break
            gone = self.active[i]
            keep = [a for k, a in enumerate(self.active) if k != i]
            try:
                params, rss_d, *_ = self.fit_full([a.effect for a in keep], [a.p for a in keep], self.empirical)
            except ModelEvaluationError:
                continue
            pairs = [(a.effect, p) for a, p in zip(keep, params)]
            rc = np.concatenate(self.coarse_residual(pairs))
            fam = gone.effect.template or gone.effect.name
            ranking = [d for d in self.rank(rc, Ec)
                       if d.effect.family != "measurement" and not d.effect.expensive
                       and d.effect.name not in in_model and d.family_key != fam]
            self.log(f"drop-swap: without {gone.effect.name} RMS {math.sqrt(rss_d / self.n):.4g} (dBIC "
                     f"{bic(rss_d, self.n, p_cur - gone.effect.n_params) - bic_cur:.1f}); screened there: "
                     + ", ".join(f"{d.effect.name} {d.explained:.3f}" for d in ranking[:DROP_SWAP_CANDIDATES]))
            for d in ranking[:DROP_SWAP_CANDIDATES]:
                if self.over_budget():
                    break
                if rss_d * (1.0 - d.explained) > DROP_SWAP_HOPELESS * self.rss_full:
                    self.log(f"drop-swap: {d.effect.name} not refitted in place of {gone.effect.name}: it would leave "
                             f"{rss_d * (1.0 - d.explained) / self.rss_full:.3g} times the state's residual linearly")
                    continue
                x = d.effect
                p0 = list(params) + [np.clip(np.asarray(d.p, dtype=float), x.lower, x.upper)]
                k = p_cur - gone.effect.n_params + x.n_params
                found = self.swap_trial([a.effect for a in keep] + [x], p0, k, bic_cur,
                                        f"drop-swap refit: {x.name} in place of {gone.effect.name}", found, i, x)
        if found is None:
            return None
        return self.adopt_swap(found, it, "drop-swap refit before the stop")
