"""Identifiability groups and the extra runs that would split them.

A group is a set of candidates that the given runs cannot tell apart: a found effect and its
alternatives (candidates whose signature reproduces its fitted signature within the noise, each at
its own size and sign), effects whose joint-fit estimates are correlated beyond
:data:`CORRELATION_LIMIT`, and an unexplained empirical term with the library effects that could
produce it. Every member is reported with its size and the RMS it would leave.

An effect whose group holds members of its own unit at other sizes does not get a tight interval:
its interval is widened to cover those sizes (the data do not say which member is right).

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

import numpy as np

from rvcalib.forward import ModelEvaluationError, grid_te, merge_case
from rvcalib.results import FittedEffect, Unexplained
from rvcalib.selection import Selection

#: Joint-fit correlation above which two effects are reported as one group.
CORRELATION_LIMIT = 0.95
#: Smallest log-determinant gain for which a run is said to split a group (a factor 2 in det).
MIN_LOG_DET_GAIN = math.log(2.0)
#: Largest number of members per group whose sensitivities are solved for the recommendation.
MAX_MEMBERS = 4
#: The sensitivities of the recommendation are solved on a grid of this many points per pin (per
#: output revolution: this times Zp); the criterion compares conditions, so a coarse grid serves.
REC_POINTS_PER_PIN = 2


class Groups(Selection):
    """Identifiability groups and recommended runs (methods on the loop)."""

    def identifiability_groups(self, fitted: list[FittedEffect], unexplained: list[Unexplained]) -> list[dict]:
        """Groups of candidates the data cannot tell apart (see the module docstring); widens the
        interval of a found effect whose group holds members of its unit at other sizes."""
        groups: list[dict] = []
        for f in fitted:
            if not f.alternatives:
                continue
            me = {"name": f.name, "value": f.value, "unit": f.unit,
                  "rms_after_arcsec": math.sqrt(self.rss_full / self.n), "found": True}
            members = [me] + [dict(a, found=False) for a in f.alternatives]
            same = [a["value"] for a in f.alternatives if a["unit"] == f.unit]
            if same:
                lo, hi = min([f.ci_low] + same), max([f.ci_high] + same)
                if lo < f.ci_low or hi > f.ci_high:
                    f.ci_low, f.ci_high = float(lo), float(hi)
            groups.append({"kind": "alternatives", "found": f.name, "members": members,
                           "note": "these fit the data equally well (within the noise); the interval of the found "
                                   "effect covers the sizes its alternatives of the same unit need"})
        corr = getattr(self, "_corr", None)
        if corr is not None:
            names = [a.effect.name for a in self.active]
            idx = getattr(self, "_param_index", [])
            for i in range(len(names)):
                for j in range(i + 1, len(names)):
                    c = max(abs(float(corr[p, q])) for p in idx[i] for q in idx[j])
                    if c > CORRELATION_LIMIT:
                        fi = next(f for f in fitted if f.name == names[i])
                        fj = next(f for f in fitted if f.name == names[j])
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


def json_key(case: dict) -> str:
    """A stable key of a case dict."""
    return json.dumps(case, sort_keys=True)
