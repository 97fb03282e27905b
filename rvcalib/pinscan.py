"""Every pin's instance of the pin-wise errors solved at the model state: which pin, chosen by the full model.

The loop screens a pin-wise error (one pin's pitch, radial position or radius) by shifting its template's
signature, solved at the declared model, by whole pin pitches. Under the physical law at a realistic state that
shift is not the instance's TE: the load a pin carries depends on every other error present, so a pin's pitch
error and a neighbour's radius error change places in the ranking, the wrong instance enters, and the errors of
other types then take sizes far from their own to make up the difference. Realistic seed 9 on the 2026-11-28
machine (stop 36, main 449a259): the loop ended at RMS 0.348 arcsec (noise 0.2) with pin 19's radius at +3.6 um
standing in for pin 0's pitch (-0.0068 deg), the carrier-hole and disc-hole eccentricities missing and a cam
eccentricity on the wrong disc; the truth's effects refitted from the truth leave 0.197 arcsec. Refitting the
loop's end with every error type it lacked added (one instance each, chosen by the screening: pin 32's pitch)
stayed in the loop's basin (0.40 arcsec), from zero too (0.47-0.66), with or without a prior on the sizes; with
pin 0's pitch in place of pin 19's radius the same refit went to 0.209 arcsec with every size near its truth
(carrier hole 3.33 um for 3.81, cam eccentricity 2.32 for 2.19, pin 0's pitch -0.0068 deg). The instance's own
TE solved at the loop's end ranked pin 0's pitch first in place of pin 19's radius (the residual's sum of squares
in the model linearised there 393 -> 225 arcsec^2, the state's own 245; the shifted signature had not offered
it). Seed 10: the loop ended at 0.218 arcsec with pin 38's diameter standing in for pin 0's pitch
(-0.0025 deg); solved at the state, pin 0's pitch ranks first as an addition (65.5 -> 61.5 arcsec^2).
(docs/calibration.md, "Stop 36".)

The check (:meth:`PinScan.pin_scan_refit`, once per model state, the last of the checks before the loop stops;
not made when the state's residual is already within the noise estimate, :func:`rvcalib.residual.structured_noise`:
no refit can then gain beyond chance, and the scan's 119 instances x 2 sides x the run conditions solves would
double the cost of a loop that has found its answer, e.g. the 5-run benchmark's):

1. For every pin and each error type of :data:`PIN_SCAN_KEYS`, the instance not in the model is added to the
   state at +-:data:`PIN_SCAN_STEP` of its scale and the model solved at every k-th reading of each run
   (:data:`PIN_SCAN_ROWS_PER_REV`; one batch of sensitivity solves of the forward runner from the state's converged
   solve at those readings); the change of the residual is the instance's column on each side of zero (the TE has a
   kink there: a pin that moves in takes load, one that moves out sheds it).
2. In the model linearised at the state (the members' Jacobian columns, scaled parameters), each column is
   fitted, with a size >= 0 along its own side, as an addition (every member refitted) and in place of each
   physical member (the member's part back in the residual, the other members refitted)
   (:func:`scan_ranking`; the empirical terms refitted beside). A replacement counts only where it passes the BIC
   against the model without the member (by ``JOINT_BIC_MARGIN``): a member the data do not need is not swapped
   for another. These BIC rules are taken on the scan's readings.
3. The best addition (below the term limit, when it passes the BIC in the linearised model) and the best
   replacement whose linear fit leaves less than the state are refitted through rvdyn from their linear sizes.
   An addition is kept when it passes the loop's F test on all samples and lowers the BIC by more than
   ``JOINT_BIC_MARGIN``, a replacement (one effect for one) when it lowers the BIC by more than the margin; the
   better of the two is made and the search goes on.
4. When neither is kept, the best replacement is refitted with one instance of every error family the model
   then lacks beside it (each the best of its family in the screening at the state, from zero; expensive and
   measurement effects left out; the empirical terms dropped), members are removed by the BIC in the model linearised at that fit (down to
   the term limit, :func:`rvcalib.lsq.bic_backward`) and the rest refitted; kept when the BIC falls by more than
   the margin. Why: a stand-in pin holds the other errors where they make up for it, and with it gone alone they
   cannot move there one at a time (seed 9: pin 0's pitch in pin 19's place alone, the rest refitted, rose by
   158 BIC units; with the families the model lacked beside it, by hand, it fell by 1876).
5. When no pin takes a member's place and the model is at the term limit (where the search swaps one for one), the
   model as it is gets step 4's refit with the families it lacks (no swap). Realistic seed 7 (stop 37) ended at the
   term limit 101 BIC units above the truth's refit, with a second cam eccentricity and phase (disc 1) and a pin
   radius of the wrong sign standing for the disc-hole and carrier-hole eccentricities it lacked; the scan's
   ranking offered no replacement there. By hand, that refit from the loop's end (7 families added, 7 members then
   removed by the BIC) fell by 138 BIC units, to 1.6 units of the truth's refit, the carrier hole at -1.51 um
   (truth -1.52) and the disc hole at -3.51 (-3.31). Below the term limit the loop adds what the data support one
   step at a time, and the 5-run benchmark (three members) does not pay for the dense fit.
"""
from __future__ import annotations

import math

import numpy as np

from rvcalib.dropswap import DropSwap
from rvcalib.effects import param_scales
from rvcalib.forward import ModelEvaluationError
from rvcalib.lsq import bic, bic_backward, ftest, projector
from rvcalib.residual import structured_noise
from rvcalib.results import Active
from rvcalib.subsets import JOINT_BIC_MARGIN
from rvcalib.swaps import SUBSET_ROWS_PER_REV

#: The pin-wise error types whose every pin is solved at the state. A pin's radius and its radial position
#: (``pin_circle_diameter[pin=k]``, twice the radial shift) nearly coincide on the data (a radius smaller by d
#: moves the pin's innermost point as an outward shift by d does, the contact normals differ slightly), but not
#: at a realistic state (seed 10: in place of pin 38's diameter, pin 38's radius leaves 70.4 arcsec^2 in the
#: model linearised there, the state 65.5), so both are solved.
PIN_SCAN_KEYS = ("pin_pitch", "pin_circle_diameter", "pin_radius")
#: The trial step of each instance, in units of its effect's scale (0.005 deg of pitch, 5 um of diameter,
#: 2.5 um of radius): the size of a realistic error (paper Table 4 / 3), where the kink at zero is left behind.
PIN_SCAN_STEP = 0.5
#: The scan solves every k-th reading of each run, k the largest that leaves at least this many readings per output
#: revolution (about three per pin pitch of the 40-pin reducer; every reading of a sparser run):
#: the scan ranks, it does not decide (the refits are solved at every reading), and the instances' columns vary
#: on the scale of a pin pitch. The cost of the scan falls as 1/k (k = 3 on the 5-run benchmark's 360 readings per
#: revolution and on the realistic draws' 333). The swap trials' first refits use the same subset
#: (:data:`rvcalib.swaps.SUBSET_ROWS_PER_REV`).
PIN_SCAN_ROWS_PER_REV = SUBSET_ROWS_PER_REV


def _fit_along(t: np.ndarray, d: np.ndarray, Q: np.ndarray) -> tuple[float, float]:
    """Least squares of ``t + a d`` over ``a >= 0`` with the columns of ``Q`` (orthonormal) projected out:
    (residual sum of squares, a)."""
    tq = t - Q @ (Q.T @ t)
    dq = d - Q @ (Q.T @ d)
    den = float(dq @ dq)
    a = max(0.0, -float(dq @ tq) / den) if den > 0.0 else 0.0
    rr = tq + a * dq
    return float(rr @ rr), a


def scan_ranking(r: np.ndarray, J: np.ndarray, x: np.ndarray, member_cols: list[np.ndarray],
                 cols: dict[tuple[str, float], np.ndarray]) -> tuple[list, dict[int, list], dict[int, float], float]:
    """The candidates' columns ranked in the model linearised at the state.

    Parameters
    ----------
    r : ndarray (n,)
        The residual at the state (arcsec, empirical terms projected out).
    J : ndarray (n, p)
        Its Jacobian in the members' scaled parameters (``r(x') ~ r + J (x' - x)``); columns in no member's
        ``member_cols`` (e.g. the empirical terms' on a subset of the samples) are refitted in every fit.
    x : ndarray (p,)
        The members' scaled parameters (0 for the columns in no member).
    member_cols : list of ndarray of int
        Each member's columns of ``J``.
    cols : dict
        ``(name, sign) -> d``: the change of the residual when the candidate ``name`` is added at ``sign`` times
        the trial step (arcsec, the same rows as ``r``).

    Returns
    -------
    additions : list of (rss, name, steps)
        Each column fitted beside every member (refitted): the residual sum of squares it leaves and the
        candidate's size in trial steps (signed), best first.
    replacements : dict
        Member index -> list of (rss, name, steps): each column fitted in the member's place (the member's part
        ``J_m x_m`` back in the residual, the other members refitted), best first.
    removals : dict
        Member index -> the residual sum of squares without the member (the others refitted).
    rss_state : float
        The residual sum of squares of the linear refit of every member (no candidate): the state's, on
        samples where the state was fitted (there ``J`` is orthogonal to ``r``); the baseline of the additions.
    """
    p = J.shape[1]
    Q = np.linalg.qr(J)[0] if p else np.zeros((r.size, 0))
    r0 = r - Q @ (Q.T @ r)
    additions = []
    for (name, sign), d in cols.items():
        rss, a = _fit_along(r, d, Q)
        additions.append((rss, name, sign * a))
    additions.sort()
    replacements: dict[int, list] = {}
    removals: dict[int, float] = {}
    for i, mc in enumerate(member_cols):
        others = np.setdiff1d(np.arange(p), mc)
        Qo = np.linalg.qr(J[:, others])[0] if others.size else np.zeros((r.size, 0))
        t = r - J[:, mc] @ x[mc]
        tq = t - Qo @ (Qo.T @ t)
        removals[i] = float(tq @ tq)
        got = []
        for (name, sign), d in cols.items():
            rss, a = _fit_along(t, d, Qo)
            got.append((rss, name, sign * a))
        got.sort()
        replacements[i] = got
    return additions, replacements, removals, float(r0 @ r0)


class PinScan(DropSwap):
    """Every pin's instance solved at the state before the loop stops (see the module docstring)."""

    def _pin_candidates(self) -> list:
        """The library's single-pin instances of :data:`PIN_SCAN_KEYS` not in the model."""
        in_model = {a.effect.name for a in self.active}
        return [e for e in self.lib if e.key in PIN_SCAN_KEYS and dict(e.instance).get("pin") is not None
                and e.name not in in_model and not e.expensive]

    def _scan_rows(self) -> np.ndarray:
        """The readings the scan solves (bool per sample): every k-th of each run (:data:`PIN_SCAN_ROWS_PER_REV`)."""
        return self.subset_rows(PIN_SCAN_ROWS_PER_REV)

    def pin_scan_refit(self, it: int) -> tuple[str, str] | None:
        """The pin scan (module docstring): returns ``(member, candidate)`` for a replacement made,
        ``("", candidate)`` for an addition, or None."""
        cands = self._pin_candidates()
        if not self.active or not cands or self.over_budget():
            return None
        r_now, _ = self.full_residual(self._pairs(), self.empirical)
        sigma = structured_noise(self.ds, self.split(r_now))
        if math.isfinite(sigma) and self.rss_full <= self.n * sigma ** 2:
            self.log(f"pin scan: not made, the state's residual ({math.sqrt(self.rss_full / self.n):.4g} arcsec RMS) "
                     f"is within the noise estimate ({sigma:.4g} arcsec)")
            return None
        effects = [a.effect for a in self.active]
        params = [np.asarray(a.p, dtype=float) for a in self.active]
        P = projector(self._emp_matrix(self.empirical))
        self.keep_state_jacobian()
        J, known = self._cached_jacobian(effects, params, self.empirical, P)
        r = r_now   # the state's residual with the empirical terms projected out, solved once above
        try:
            if J is None or known is None or not bool(np.all(known)):
                x, _, J = self.state_jacobian(effects, params, f0=r)
            else:
                scales = param_scales(effects)
                x = np.concatenate(params) / scales
        except ModelEvaluationError:
            return None
        state = list(zip(effects, params))
        keep = self._scan_rows()
        rows = np.flatnonzero(keep)
        # converged at the scan's readings (the start of its sensitivity solves; all readings: the state's own solve)
        base = self.predict_rows([state], keep)[0]
        if isinstance(base, ModelEvaluationError):
            return None
        trials = [(c, s) for c in cands for s in (-1.0, 1.0)]
        preds = self.predict_rows([state + [(c, np.array([s * PIN_SCAN_STEP * c.scale]))] for c, s in trials], keep,
                                  sensitivity=True)
        cols = {}
        for (c, s), pred in zip(trials, preds):
            if isinstance(pred, ModelEvaluationError):
                continue
            cols[(c.name, s)] = base - pred   # the change of the residual at the scan's readings
        if not cols:
            return None
        sizes = np.cumsum([0] + [e.n_params for e in effects])
        member_cols = [np.arange(sizes[i], sizes[i + 1]) for i in range(len(effects))]
        # the empirical terms' columns refitted beside every fit: r and J are projected on all samples, so on a
        # subset they keep a part in the terms' span (the same span as the raw residual's and columns')
        E = self._emp_matrix(self.empirical)
        Jr = J[rows] if E is None else np.column_stack([J[rows], E[rows]])
        xr = np.concatenate([x, np.zeros(Jr.shape[1] - x.size)])
        additions, replacements, removals, rss_state = scan_ranking(r[rows], Jr, xr, member_cols, cols)
        by_name = {c.name: c for c in cands}
        p_cur = self._p_cur()
        bic_cur = bic(self.rss_full, self.n, p_cur)

        def earns_its_place(i: int, rss: float, name: str) -> bool:
            # in the member's place the candidate must pass the BIC against the model without the member (a member
            # the data do not need is not swapped for another: the 5-run benchmark's spare disc phase, removal
            # -7.5 BIC units, went for pin 30's radius at -4.3 before this rule)
            # (on the scan's readings: the BIC of those samples, not scaled up to all of them, where a chance gain
            # on a third of the samples would count three times; the 5-run benchmark's spare disc phase went for
            # pin 19's pitch so, whose refit then gained 0.2 BIC units)
            m = rows.size
            gain = m * math.log(max(removals[i], 1e-300) / max(rss, 1e-300))
            return gain > by_name[name].n_params * math.log(m) + JOINT_BIC_MARGIN

        best_rep = min(((got[0], i) for i, got in replacements.items()
                        if got and effects[i].family != "measurement" and got[0][0] < rss_state
                        and earns_its_place(i, got[0][0], got[0][1])), default=None)
        self.log(f"pin scan: {len(cands)} instances solved at the state at {rows.size} of {self.n} readings "
                 f"(RMS {math.sqrt(self.rss_full / self.n):.5g}, "
                 f"noise estimate {sigma:.5g} arcsec); best addition "
                 f"{additions[0][1]} ({rss_state:.4g} -> {additions[0][0]:.4g} arcsec^2 linearised)"
                 + (f", best replacement {best_rep[0][1]} in place of {effects[best_rep[1]].name} "
                    f"({best_rep[0][0]:.4g})" if best_rep else ", no replacement below the state"))
        found = None
        if best_rep is not None and not self.over_budget():
            (_, name, steps), i = best_rep
            c = by_name[name]
            keep = [a for k, a in enumerate(self.active) if k != i]
            p0 = [a.p for a in keep] + [np.array([steps * PIN_SCAN_STEP * c.scale])]
            k = p_cur - effects[i].n_params + c.n_params
            found = self.swap_trial([a.effect for a in keep] + [c], p0, k, bic_cur,
                                    f"pin scan: {name} in place of {effects[i].name}", None, i, c)
        add = None
        # an addition is refitted when it passes the BIC on the scan's readings in the linearised model (the refit
        # must pass it on all samples: the 5-run benchmark's best addition, 13.14 -> 13.06 arcsec^2 on 606 readings,
        # gained 3.7 units for a penalty of 6.4, and its refit, 2 s, raised the BIC on all samples by 5.4)
        m = rows.size
        add_gain = m * math.log(max(rss_state, 1e-300) / max(additions[0][0], 1e-300))
        if (len(self.active) + len(self.empirical) < self.max_terms
                and add_gain > by_name[additions[0][1]].n_params * math.log(m) + JOINT_BIC_MARGIN
                and not self.over_budget()):
            _, name, steps = additions[0]
            c = by_name[name]
            try:
                got = self.fit_full(effects + [c], params + [np.array([steps * PIN_SCAN_STEP * c.scale])],
                                    self.empirical)
            except ModelEvaluationError:
                got = None
            if got is not None:
                params2, rss2 = got[0], got[1]
                k = p_cur + c.n_params
                b_new = bic(rss2, self.n, k)
                F, pv = ftest(self.rss_full, rss2, c.n_params, self.n, k)
                self.log(f"pin scan: {name} added: RMS {math.sqrt(rss2 / self.n):.4g}, dBIC {b_new - bic_cur:.1f}, "
                         f"p {pv:.3g}")
                if pv < self.thr and b_new < bic_cur - JOINT_BIC_MARGIN:
                    add = (b_new, c, params2, rss2, F, pv)
        if add is not None and (found is None or add[0] < found[0]):
            b_new, c, params2, rss2, F, pv = add
            for a, p in zip(self.active, params2):
                a.p = p
            self.active.append(Active(c, params2[-1], it, info={
                "explained_fraction": 1.0 - rss2 / self.rss_full, "F": F, "p_value": pv, "delta_bic": b_new - bic_cur,
                "selection": {"method": "pin scan before the stop", "iteration": it}}))
            self.refresh_state()
            return "", c.name
        if found is not None:
            return self.adopt_swap(found, it, "pin scan before the stop")
        if self.over_budget():
            return None
        if best_rep is None:
            # no pin in a member's place: at the term limit (where the search swaps one for one) the model itself
            # with the families it lacks beside it (step 5 of the module docstring)
            if len(self.active) + len(self.empirical) < self.max_terms:
                return None
            return self._with_missing_types(None, None, 0.0, it)
        (_, name, steps), i = best_rep
        return self._with_missing_types(i, by_name[name], steps * PIN_SCAN_STEP * by_name[name].scale, it)

    def _with_missing_types(self, i: int | None, c, p_c: float, it: int) -> tuple[str, str] | None:
        """Member ``i`` replaced by the pin instance ``c`` (from its linear size ``p_c``; ``i`` None: no swap, the
        members as they are) with one instance of every
        error family the model lacks beside them (each the best of its family in the screening at the state,
        from zero; expensive and measurement effects left out), refitted through rvdyn without the empirical
        terms (they stand for what the model lacked: the loop judges them again from the new state); then members
        removed by the BIC in the model linearised at that fit (:func:`rvcalib.lsq.bic_backward`, down to the term
        limit) and the rest refitted. Kept when the BIC on all samples (the state's with its empirical terms) falls
        by more than ``JOINT_BIC_MARGIN``; returns (members and empirical terms gone, members come) or None."""
        old = [a for k, a in enumerate(self.active) if k != i]
        effects = [a.effect for a in old] + ([c] if c is not None else [])
        present = {e.template or e.name for e in effects}
        rc = np.concatenate(self.coarse_residual())
        extra, seen = [], set()
        for d in self.rank(rc, None):
            e = d.effect
            if d.family_key in present or d.family_key in seen or e.expensive or e.family == "measurement":
                continue
            seen.add(d.family_key)
            extra.append(e)
        effects += extra
        p0 = [a.p for a in old] + ([np.array([p_c])] if c is not None else []) + [np.zeros(e.n_params) for e in extra]
        bic_cur = bic(self.rss_full, self.n, self._p_cur())
        try:
            params, rss, x, fun, J = self.fit_full(effects, p0, [])
            sizes = np.cumsum([0] + [e.n_params for e in effects])
            alive = bic_backward(fun(x), J, x, [np.arange(sizes[j], sizes[j + 1]) for j in range(len(effects))],
                                 self.n, max_members=self.max_terms)
            kept = [effects[j] for j in alive]
            params2, rss2, *_ = self.fit_full(kept, [params[j] for j in alive], [])
        except ModelEvaluationError:
            return None
        b_new = bic(rss2, self.n, sum(e.n_params for e in kept))
        what = f"{c.name} in place of {self.active[i].effect.name}" if c is not None else "the model at the term limit"
        self.log(f"pin scan: {what} with {len(extra)} error types the "
                 f"model lacked ({math.sqrt(rss / self.n):.4g} arcsec), {len(kept)} members kept by the BIC: RMS "
                 f"{math.sqrt(rss2 / self.n):.4g}, dBIC {b_new - bic_cur:.1f}")
        if b_new >= bic_cur - JOINT_BIC_MARGIN:
            return None
        by_name = {a.effect.name: a for a in self.active}
        gone = [a.effect.name for a in self.active if a.effect not in kept]
        come = [e.name for e in kept if e.name not in by_name]
        new_active = []
        for e, p in zip(kept, params2):
            a = by_name.get(e.name)
            if a is not None:
                a.p = p
                new_active.append(a)
            else:
                new_active.append(Active(e, p, it, info={
                    "explained_fraction": 1.0 - rss2 / self.rss_full, "delta_bic": b_new - bic_cur,
                    "selection": {"method": "pin scan before the stop, refitted with the error types the model lacked",
                                  "iteration": it, "replaced": ", ".join(gone),
                                  "with": c.name if c is not None else None}}))
        gone += [t.label for t in self.empirical]
        self.active, self.empirical = new_active, []
        self.refresh_state()
        return ", ".join(gone), ", ".join(come)
