"""A second fit from another start: members whose parts the data see along one direction, restarted.

Under the physical law the joint fit can settle in a basin where several members that the runs see
along nearly one direction (an offset-like TE: a disc phase, the pin circle diameter, the pin radius)
take large sizes of opposite effect, each with a tight linearised interval. Realistic seed 3 on the
2026-11-27 machine: pin circle diameter -17.3 um [-21.2, -13.5] and pin radius -14.0 um [-16.8, -12.2]
(truth -0.77 and -1.44) beside a second disc phase, RMS 0.2036 arcsec; the same effects refitted with
those two started from zero (by hand) end at 4.09 / 1.41 um and a disc phase of 0.001 deg, RMS 0.2039
arcsec: 3.2 noise variances apart, so a linearised interval describes one basin only. In the loop the
restart acted earlier (at a state 0.2017 arcsec, the second disc phase, the diameter and the radius from
zero: 14.1 noise variances better) and the pair did not come back (docs/calibration.md, "Stop 25").

The check (:meth:`BasinCheck.restart_refit`, once per model state, before the loop stops and at the
final state):

1. The members' present parts (the state's TE minus the TE without the member, on the screening grid,
   :meth:`rvcalib.joint.JointSelection.active_members`) whose directions correlate at
   ``|cos| >= LOOKALIKE_PAIR_CORRELATION`` (0.9, the look-alike pairs' limit) are joined into sets
   (connected components).
2. Each set of two or more is refitted with every member but the largest started from zero, the other
   effects and empirical terms from their sizes (:meth:`rvcalib.fitting.Fitting.fit_full`, every reading).
3. A fit lower by more than ``JOINT_BIC_MARGIN`` BIC units (the same parameters: ``n ln(rss/rss_new)``)
   replaces the state (the search goes on from it). A fit within the chi-square(1) 95 % limit (3.841
   noise variances) of the state is kept as the state's other fit: at the final state every effect
   whose size differs between the two fits beyond its interval is reported in a group of kind
   ``two_fits`` with both sizes, and its interval covers both (:meth:`BasinCheck.basin_groups`). A member
   whose size in the other fit lies within its interval's half-width of zero is not named as an effect
   (``"named": false`` in the group; it leaves ``effects`` as a member of an ``unsplit`` group does): a fit
   that explains the data within the noise without it says the runs do not establish it (realistic seed 3
   on the 2026-11-27 machine, stop 30: pin circle diameter -2.33 or 0.018 um beside pin radius -2.05 or
   -0.89 um, truth -0.77 and -1.44).
"""
from __future__ import annotations

import math

import numpy as np

from rvcalib.forward import ModelEvaluationError
from rvcalib.pairs import CHI2_95, PairCheck
from rvcalib.replace import LOOKALIKE_PAIR_CORRELATION
from rvcalib.results import FittedEffect
from rvcalib.subsets import JOINT_BIC_MARGIN


def collinear_sets(parts: list[np.ndarray | None], limit: float = LOOKALIKE_PAIR_CORRELATION) -> list[list[int]]:
    """Connected components (two or more members) of the graph whose edges join parts with ``|cos| >= limit``.

    Parameters
    ----------
    parts : list of (ndarray or None)
        Each member's present part of the model TE (arcsec, any common grid); None or zero: no edges.
    limit : float
        Smallest absolute cosine of an edge.

    Returns
    -------
    list of list of int
        Member indices of each set, in index order; sets in the order of their first member.
    """
    n = len(parts)
    root = list(range(n))

    def find(i: int) -> int:
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
        return i
    norms = [0.0 if p is None else float(np.linalg.norm(p)) for p in parts]
    for i in range(n):
        for j in range(i + 1, n):
            if norms[i] <= 0 or norms[j] <= 0:
                continue
            c = float(parts[i] @ parts[j]) / (norms[i] * norms[j])
            if abs(c) >= limit:
                root[find(j)] = find(i)
    sets: dict[int, list[int]] = {}
    for i in range(n):
        sets.setdefault(find(i), []).append(i)
    return [s for s in sorted(sets.values()) if len(s) >= 2]


class BasinCheck(PairCheck):
    """The restart of collinear members (see the module docstring); state on the calibrator."""

    def _basin_store(self) -> dict:
        if not hasattr(self, "_basins"):
            self._basins: dict = {}
        return self._basins

    def restart_refit(self, adopt: bool = True, members: list | None = None) -> str | None:
        """Step 1-3 of the module docstring at the present state (once per state); returns the message when a
        restarted fit replaced the state, else None (an other fit within the noise is kept for the groups).
        ``adopt`` False (the final state, whose intervals are being reported): a better fit is kept as the
        other fit too, not taken. ``members``: :meth:`active_members` at this state if the caller has them
        (the final state's analysis does)."""
        store = self._basin_store()
        key = self._state_key()
        if key in store or not self.active or self.over_budget():
            return None
        store[key] = []
        members = [m for m in (self.active_members() if members is None else members)
                   if m.effect is not None and m.active is not None]
        sets = collinear_sets([m.contribution for m in members])
        n = self.n
        k = self._p_cur()
        s2 = self.rss_full / max(1, n - k)
        for idx in sets:
            norms = [float(np.linalg.norm(members[i].contribution)) for i in idx]
            anchor = idx[int(np.argmax(norms))]
            zero = {members[i].effect.name for i in idx if i != anchor}
            effects = [a.effect for a in self.active]
            p0 = [np.zeros_like(np.asarray(a.p, dtype=float)) if a.effect.name in zero else np.asarray(a.p, dtype=float)
                  for a in self.active]
            try:
                params, rss_new, *_ = self.fit_full(effects, p0, self.empirical)
            except ModelEvaluationError:
                continue
            rss_new = float(rss_new)
            gain = n * math.log(self.rss_full / max(rss_new, 1e-300))
            names = ", ".join(sorted(zero))
            self.log(f"restart of {names} from zero (beside {members[anchor].effect.name}): RMS "
                     f"{math.sqrt(self.rss_full / n):.4g} -> {math.sqrt(rss_new / n):.4g} arcsec "
                     f"({(rss_new - self.rss_full) / s2:+.1f} noise variances)")
            if gain > JOINT_BIC_MARGIN and adopt:
                for a, p in zip(self.active, params):
                    a.p = np.asarray(p, dtype=float)
                self.refresh_state()
                return f"restarted {names} from zero: RMS {math.sqrt(rss_new / n):.4g} arcsec (dBIC {-gain:.1f})"
            if gain > JOINT_BIC_MARGIN or (rss_new - self.rss_full) / s2 < CHI2_95:
                store[key].append({"restarted": sorted(zero), "anchor": members[anchor].effect.name,
                                   "params": {a.effect.name: np.asarray(p, dtype=float) for a, p in zip(self.active, params)},
                                   "rss": rss_new})
        return None

    def basin_groups(self, by_name: dict[str, FittedEffect], rms_model: float) -> list[dict]:
        """Groups of kind ``two_fits`` for the other fits kept at the present state (step 3), each effect's
        interval widened to cover its size in the other fit."""
        groups = []
        for other in self._basin_store().get(self._state_key(), []):
            rms_other = math.sqrt(other["rss"] / self.n)
            mem = []
            for a in self.active:
                f = by_name.get(a.effect.name)
                q = other["params"].get(a.effect.name)
                if f is None or q is None:
                    continue
                v2 = float(a.effect.value(q))
                moved = float(np.linalg.norm(np.asarray(q, dtype=float) - np.asarray(a.p, dtype=float)))
                half = (f.ci_high - f.ci_low) / 2
                if (f.ci_low <= v2 <= f.ci_high) and not (a.effect.polar and moved > half):
                    continue  # (a polar effect: also when its vector moved beyond its interval's half-width)
                # the other fit holds it within its interval's half-width of zero: the data do not need it
                named = abs(v2) > half
                f.ci_low, f.ci_high = float(min(f.ci_low, v2)), float(max(f.ci_high, v2))
                f.selection["other_fit"] = {"value": v2, "rms_arcsec": rms_other, "restarted": other["restarted"]}
                d = {"name": f.name, "key": f.key, "value": f.value, "unit": f.unit, "rms_after_arcsec": rms_model,
                     "found": True, "value_other_fit": v2, "named": named}
                if f.angle_deg is not None:
                    d["angle_deg"] = f.angle_deg
                    d["angle_deg_other_fit"] = float(a.effect.magnitude_angle(q)[1])
                mem.append(d)
            if len(mem) < 1:
                continue
            better = other["rss"] < self.rss_full
            dropped = [m["name"] for m in mem if not m["named"]]
            groups.append({"kind": "two_fits", "found": ", ".join(m["name"] for m in mem), "members": mem,
                           "rms_other_fit_arcsec": rms_other,
                           "note": f"the same effects fit the data at two sets of sizes (RMS {rms_model:.4g} and "
                                   f"{rms_other:.4g} arcsec; the second with {', '.join(other['restarted'])} "
                                   "started from zero): " + ("the second fits better (found at the final state, "
                                   "not taken)" if better else "within the noise, the runs given do not decide "
                                   "between them") + "; each interval covers both sizes"
                                   + (f"; {', '.join(dropped)} not named as effects (the other fit holds "
                                      + ("it" if len(dropped) == 1 else "each") + " within its interval's "
                                      "half-width of zero)" if dropped else "")})
            self.log("two fits: " + ", ".join(
                f"{m['name']} {m['value']:.4g} or {m['value_other_fit']:.4g} {m['unit']}" for m in mem))
        return groups
