"""Fitting: nonlinear refits through the full reducer model (one candidate on its screening grid at
the current state; all effects jointly at every reading, empirical terms projected out) and the
confidence intervals of the reported effects.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import optimize, stats

from rvcad.errors import ERROR_TYPES

from rvcalib.effects import Effect, param_scales
from rvcalib.forward import ModelEvaluationError
from rvcalib.lsq import chord_fit, fd_jac, profile_limit, projector
from rvcalib.residual import lag1_autocorr
from rvcalib.results import EmpiricalTerm, FittedEffect
from rvcalib.screening import Screening


#: Joint fits whose end Jacobians are kept for the start of later refits (:meth:`Fitting._cached_jacobian`):
#: the state's own and the checks made beside it (each 8 bytes x the readings x its columns: about 0.15 MB for
#: a dozen columns at 1,300 readings, twice that for the final-state pair check's; a few MB in all).
JAC_KEPT = 8


def _same_state(kept: np.ndarray | None, p: np.ndarray) -> bool:
    """Whether an effect's start ``p`` leaves a kept fit's model where it was: at the kept solution when the
    effect was in that fit (``kept``), at size zero when it was not."""
    p = np.asarray(p, dtype=float)
    if kept is None:
        return not np.any(p)
    return kept.shape == p.shape and np.array_equal(kept, p)


def _scaled_bounds(effects: list[Effect]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The effects' parameter scales and their bounds in scaled units (empty arrays for no effects)."""
    if not effects:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    scales = param_scales(effects)
    lo = np.concatenate([np.array(e.lower) for e in effects]) / scales
    hi = np.concatenate([np.array(e.upper) for e in effects]) / scales
    return scales, lo, hi


def _bound_side(e: Effect, p: np.ndarray) -> str | None:
    """``"lower"`` or ``"upper"`` when a one-parameter effect's value sits at that bound of its range (to 1e-9
    of its scale), else None."""
    v, tol = float(np.asarray(p, dtype=float)[0]), 1e-9 * e.scale
    if math.isfinite(e.upper[0]) and v >= e.upper[0] - tol:
        return "upper"
    if math.isfinite(e.lower[0]) and v <= e.lower[0] + tol:
        return "lower"
    return None


class Fitting(Screening):
    """The fitting stage of the loop (methods on the loop's model and screening)."""

    #: Start Jacobians of the joint refits taken from a kept joint fit: ``"removals"`` (at that fit's own
    #: state only: refits of the same effects with members removed or new members added at size zero),
    #: ``"all"`` (any kept column, stale) or ``"off"``.
    jacobian_reuse: str = "removals"
    #: Kept joint fits' Jacobian columns per effect, their empirical terms and their solutions
    #: (:meth:`_keep_jacobian`), the most recently kept or used first, at most :data:`JAC_KEPT` of them.
    _jac_kept: tuple = ()

    def refine_coarse(self, e: Effect, p0: np.ndarray, rc_raw: list[np.ndarray],
                      Ec: np.ndarray | None, ms: int | None = None) -> tuple[float, np.ndarray]:
        """Fit one candidate's parameters through the nonlinear model at the current state on its
        screening grid (or an ``ms``-point grid; the other parameters fixed). Returns (explained
        fraction, parameters)."""
        ms = self._ms(e) if ms is None else int(ms)
        sub = self.m // ms
        r_sub = [r[::sub] for r in rc_raw]
        r0, Pg, rss0 = self._group(ms, np.concatenate(rc_raw), Ec)
        if rss0 <= 0:
            return 0.0, p0
        cur = self._pairs()
        if e.family == "measurement":
            A = self.meas_coarse(e, ms)
            A = np.column_stack([Pg(A[:, k]) for k in range(A.shape[1])])
            c, *_ = np.linalg.lstsq(A, r0, rcond=None)
            res = r0 - A @ c
            return 1.0 - float(res @ res) / rss0, c
        base = self.predict_grid(cur, ms)
        scale = e.scale
        lo = np.array(e.lower) / scale
        hi = np.array(e.upper) / scale

        def fun(xs: np.ndarray) -> np.ndarray:
            pr = self.predict_grid(cur + [(e, xs * scale)], ms)
            return Pg(np.concatenate([r - (q - b) for r, q, b in zip(r_sub, pr, base)]))

        x0 = np.clip(np.asarray(p0, dtype=float) / scale, lo, hi)
        if e.n_params == 1 and abs(x0[0]) < 1e-3:
            x0 = np.clip(np.array([0.1]), lo, hi)
        for _ in range(4):
            try:
                f0 = fun(x0)
                break
            except ModelEvaluationError:
                x0 = x0 * 0.5
        else:
            return 0.0, p0
        # without the effect the model is the state's (the residual r0): the secant from there is the
        # start's Jacobian of a one-parameter effect
        got = chord_fit(fun, x0, lo, hi, max_iter=3, h=0.02, xtol=1e-3, r0=f0, ref=(np.zeros_like(x0), r0),
                        deadline=self._deadline())
        if got is None:
            return 0.0, p0
        x, r, _, _ = got
        return 1.0 - float(r @ r) / rss0, x * scale

    def fit_full(self, effects: list[Effect], p0: list[np.ndarray], terms: list[EmpiricalTerm],
                 max_nfev: int = 20) -> tuple[list[np.ndarray], float, np.ndarray, Any, np.ndarray]:
        """Joint nonlinear fit of all effects' parameters on every sample (empirical terms projected out).

        Returns
        -------
        params : list of ndarray
        rss : float
        x : ndarray
            Scaled parameter vector.
        fun : callable
            The residual function of the scaled vector (for the Jacobian).
        jac : ndarray
            Jacobian of ``fun`` at the solution (scaled parameters).
        """
        scales, lo, hi = _scaled_bounds(effects)
        P = projector(self._emp_matrix(terms))
        fun, unpack = self.residual_function(effects, P)
        if not effects:
            r = fun(np.zeros(0))
            return [], float(r @ r), np.zeros(0), fun, np.zeros((r.size, 0))
        x0 = np.clip(np.concatenate([np.asarray(p, dtype=float) for p in p0]) / scales, lo, hi)
        J0, known = self._cached_jacobian(effects, p0, terms, P)
        got = chord_fit(fun, x0, lo, hi, deadline=self._deadline(), J0=J0, known=known, bic_n=self.n)
        if got is not None:
            x, r, J, nfev = got
            self.fit_stats.append({"effects": [e.name for e in effects], "method": "chord", "nfev": nfev,
                                   "reused_columns": int(known.sum()) if known is not None else 0})
            params = [p for _, p in unpack(x)]
            self._keep_jacobian(effects, params, terms, J)
            return params, float(r @ r), x, fun, J
        sol = optimize.least_squares(fun, x0, jac=lambda x: fd_jac(fun, x, lo, hi, h=0.01), bounds=(lo, hi),
                                     method="trf", x_scale=1.0, max_nfev=max_nfev, xtol=1e-5, ftol=1e-7)
        self.fit_stats.append({"effects": [e.name for e in effects], "method": "trf", "nfev": int(sol.nfev),
                               "njev": int(sol.njev or 0), "status": int(sol.status)})
        params = [p for _, p in unpack(sol.x)]
        self._keep_jacobian(effects, params, terms, np.asarray(sol.jac, dtype=float))
        return params, float(2.0 * sol.cost), sol.x, fun, sol.jac

    def fit_rows(self, effects: list[Effect], p0: list[np.ndarray], terms: list[EmpiricalTerm],
                 rows: np.ndarray) -> tuple[list[np.ndarray], float] | None:
        """The joint nonlinear fit of :meth:`fit_full` at some readings only (``rows``, bool per sample; the empirical
        terms projected out there), every column of the start Jacobian differenced (the kept Jacobians of
        :meth:`fit_full` are neither used nor replaced: they hold every reading). Returns (params, rss at those
        readings), or None when no decrease could be made or rvdyn cannot evaluate the start."""
        scales, lo, hi = _scaled_bounds(effects)
        E = self._emp_matrix(terms)
        P = projector(None if E is None else E[rows])
        fun, unpack = self.residual_function(effects, P, rows)
        x0 = np.clip(np.concatenate([np.asarray(p, dtype=float) for p in p0]) / scales, lo, hi)
        got = chord_fit(fun, x0, lo, hi, deadline=self._deadline(), bic_n=int(np.count_nonzero(rows)))
        if got is None:
            return None
        x, r, _, nfev = got
        self.fit_stats.append({"effects": [e.name for e in effects], "method": "chord, readings subset",
                               "nfev": nfev, "rows": int(np.count_nonzero(rows))})
        return [p for _, p in unpack(x)], float(r @ r)

    def residual_function(self, effects: list[Effect], P, rows: np.ndarray | None = None):
        """The residual of the model with ``effects`` at every reading (empirical terms projected out by
        ``P``) as a function of the scaled parameter vector, and the vector's unpacking into (effect,
        parameters). The function carries ``many`` (the residuals of a list of vectors in one batch of the
        forward runner), so that :func:`rvcalib.lsq.fd_jac` solves a Jacobian's difference points as one
        batch, each warm-started from the state: with several workers they spread over them, and the
        numbers are the same whatever the workers (one point at a time, each would start from the one
        before, and a run with workers would differ from the serial run within the solver tolerance)."""
        sizes = [e.n_params for e in effects]

        def unpack(xs: np.ndarray) -> list[tuple[Effect, np.ndarray]]:
            out, i = [], 0
            for e, k in zip(effects, sizes):
                out.append((e, xs[i:i + k] * e.scale))
                i += k
            return out

        if rows is None:
            def residual(pred: list[np.ndarray]) -> np.ndarray:
                return P(np.concatenate([y - p for y, p in zip(self.y, pred)]))

            def solve(states: list, sensitivity: bool) -> list:
                return self.predict_many(states, sensitivity=sensitivity)
        else:
            y_rows = np.concatenate(self.y)[rows]

            def residual(pred: np.ndarray) -> np.ndarray:
                return P(y_rows - pred)

            def solve(states: list, sensitivity: bool) -> list:
                return self.predict_rows(states, rows, sensitivity=sensitivity)

        def fun(xs: np.ndarray) -> np.ndarray:
            if rows is None:
                return residual(self.predict(unpack(xs)))
            got = solve([unpack(xs)], False)[0]
            if isinstance(got, ModelEvaluationError):
                raise got
            return residual(got)

        def many(points: list[np.ndarray]) -> list:
            return [p if isinstance(p, ModelEvaluationError) else residual(p)
                    for p in solve([unpack(x) for x in points], True)]
        fun.many = many  # type: ignore[attr-defined]
        return fun, unpack

    def _cached_jacobian(self, effects: list[Effect], p0: list[np.ndarray], terms: list[EmpiricalTerm],
                         P) -> tuple[np.ndarray | None, np.ndarray | None]:
        """A start Jacobian for :meth:`fit_full` from a kept joint fit's final Jacobian
        (:meth:`_keep_jacobian`, the most recently kept or used that applies), and the mask of the columns it
        holds.

        Columns are reused only at that fit's own state: every effect of this fit that was in it is at
        the same parameters (``p0`` equal to its solution), every other effect starts at size zero (the
        model is then that fit's model: an effect of size zero changes no TE), and its empirical terms
        are all among ``terms`` (the projector of ``terms`` applied to a column projected with fewer terms
        is the column projected with ``terms``). That is a refit of the same effects with members removed
        (the backward elimination, the term-limit checks) or with candidates added from zero beside them
        (the checks before the stop: look-alike and pair refits); the new members' columns are differenced
        at ``x0``. Otherwise (moved sizes, a new member started away from zero) every column is differenced
        as before. Several fits are kept, so that the checks made at one state, each of which keeps its own
        end Jacobian, do not take the state's away from the next check (the entry used moves to the front).
        With ``jacobian_reuse = "all"`` any kept column of an effect is reused wherever it was taken (a stale
        start: faster, but the fits then stop at other points within their tolerance and the loop's discrete
        choices can change; measured in docs/calibration.md)."""
        mode = self.jacobian_reuse
        if not self._jac_kept or mode == "off":
            return None, None
        tset = set(terms)
        for k, (cols, kterms, kparams) in enumerate(self._jac_kept):
            if not kterms <= tset:
                continue
            if mode != "all" and not all(_same_state(kparams.get(e.name), p) for e, p in zip(effects, p0)):
                continue
            blocks, mask = [], []
            for e in effects:
                got = cols.get(e.name) if e.name in kparams or mode == "all" else None
                if got is not None and got.shape == (self.n, e.n_params):
                    blocks.append(P(got) if kterms != tset else got)
                    mask += [True] * e.n_params
                else:
                    blocks.append(np.zeros((self.n, e.n_params)))
                    mask += [False] * e.n_params
            if any(mask):
                # the entry used goes first (the fit about to be kept then comes before it): a state's Jacobian
                # stays kept through any number of checks made beside it
                if k:
                    self._jac_kept = (self._jac_kept[k],) + self._jac_kept[:k] + self._jac_kept[k + 1:]
                return np.column_stack(blocks), np.array(mask)
        return None, None

    def _keep_jacobian(self, effects: list[Effect], params: list[np.ndarray], terms: list[EmpiricalTerm],
                       J: np.ndarray) -> None:
        """Keep a joint fit's final Jacobian (scaled parameters, residual projected with ``terms``) per
        effect, with the fit's solution, for the start of later fits (:meth:`_cached_jacobian`)."""
        if J is None or J.ndim != 2 or J.shape[0] != self.n:
            return
        cols: dict[str, np.ndarray] = {}
        if self.jacobian_reuse == "all" and self._jac_kept:
            cols.update(self._jac_kept[0][0])
        i = 0
        for e in effects:
            cols[e.name] = np.array(J[:, i:i + e.n_params])
            i += e.n_params
        entry = (cols, frozenset(terms), {e.name: np.array(p, dtype=float) for e, p in zip(effects, params)})
        self._jac_kept = (entry,) + tuple(self._jac_kept)[:JAC_KEPT - 1]

    def keep_state_jacobian(self) -> None:
        """Difference the present model's Jacobian at its state and keep it (:meth:`_keep_jacobian`), unless a
        kept fit holds it already: the checks that refit the state with candidates added from zero (the
        look-alike refits, a dozen at a state) then difference only the candidates' columns. The state may
        have no fit of its own to take it from (an empirical term dropped at the term limit, a restart that
        was not kept)."""
        effects = [a.effect for a in self.active]
        if not effects or self.jacobian_reuse == "off":
            return
        params = [np.asarray(a.p, dtype=float) for a in self.active]
        _, known = self._cached_jacobian(effects, params, self.empirical,
                                         projector(self._emp_matrix(self.empirical)))
        if known is not None and bool(np.all(known)):
            return
        try:
            _, _, J = self.state_jacobian(effects, params)
        except ModelEvaluationError:
            return
        self._keep_jacobian(effects, params, self.empirical, J)

    def polish_state(self) -> float:
        """Refit the present model from its sizes with every column of the start Jacobian differenced there
        (no kept start) and keep the result when it lowers the residual; returns the decrease of the residual
        sum of squares (0 when none).

        Why: the state's own fit may have ended on a Broyden-updated Jacobian inside its tolerance but short of
        the minimum along a flat valley, and the reported sizes and intervals are taken there. Realistic seed 3
        (stop 27): the loop ended with the pin circle diameter at +3.49 um and the pin radius at +1.02 (truth
        -0.77 and -1.44), RMS 0.2007; refitted from those sizes with a fresh Jacobian the two went to -0.03 and
        -0.82 um, RMS 0.20046, 3 noise variances lower, and from the truth's sizes to -1.62 and -1.69 um within
        0.1 noise variance of that: one flat valley, whose far end the state's fit had not reached."""
        if not self.active:
            return 0.0
        effects = [a.effect for a in self.active]
        self.refresh_state()
        mode, self.jacobian_reuse = self.jacobian_reuse, "off"
        try:
            params, rss, *_ = self.fit_full(effects, [a.p for a in self.active], self.empirical)
        except ModelEvaluationError:
            return 0.0
        finally:
            self.jacobian_reuse = mode
        gain = self.rss_full - float(rss)
        if gain <= 0.0:
            return 0.0
        for a, p in zip(self.active, params):
            a.p = p
        self.refresh_state()
        return gain

    def polish_once(self, where: str) -> str | None:
        """:meth:`polish_state` once per model state and fit: not again while the state (its effects and
        empirical terms) and its residual are those a polish left. Returns the logged message when the polish
        lowered the residual, else None.

        Why before the checks before the stop: each check refits the state with a candidate added or swapped,
        from the state's sizes, and judges the trial by its BIC against the state's. A state left short of its
        minimum by its Broyden-updated fit gives every trial that shortfall as a gain of its own. Realistic seed
        1 (stop 38's code): the seven look-alike trials at one state all ended 0.10-0.14 arcsec^2 below it (2.5-3.5
        noise variances), whatever the candidate, and the final polish found 0.09 arcsec^2 (2.3) in the state
        alone. Polished first, a trial's dBIC is its candidate's, the trials start at the minimum (their fits
        differ from the state's only along the candidate), and the final state, already polished when nothing
        changed since, is not refitted again."""
        key = (self._state_key(), self.rss_full)
        if getattr(self, "_polished_at", None) == key:
            return None
        gain = self.polish_state()
        self._polished_at = (self._state_key(), self.rss_full)
        if gain <= 0.0:
            return None
        msg = (f"{where} refitted from its sizes with a fresh Jacobian: RMS "
               f"{math.sqrt((self.rss_full + gain) / self.n):.5g} -> {math.sqrt(self.rss_full / self.n):.5g} arcsec")
        self.log(msg)
        return msg

    def _declared_total(self, e: Effect, p: np.ndarray) -> tuple[float | None, float | None]:
        """For a correction to a declared error (the runs declare the default instance of ``e.key``,
        the same value in every run): (declared value, implied total); else (None, None). A
        two-component error's declared part lies along 0 deg of its frame."""
        if e.family != "table4":
            return None, None
        vals = {r.declared.get(e.key) for r in self.runs}
        if len(vals) != 1 or None in vals:
            return None, None
        defaults = {k: v for k, v in ERROR_TYPES[e.key].defaults.items()}
        if any(defaults.get(k, v) != v for k, v in e.instance):
            return None, None
        dv = float(vals.pop())
        if e.polar:
            return dv, float(math.hypot(dv + float(p[0]), float(p[1])))
        return dv, dv + float(p[0])

    def _state_fun(self, effects: list[Effect]):
        """The residual at every reading of the model with ``effects`` and the state's empirical terms projected
        out, as a function of the scaled parameter vector (:meth:`residual_function`)."""
        return self.residual_function(effects, projector(self._emp_matrix(self.empirical)))[0]

    def state_jacobian(self, effects: list[Effect], params: list[np.ndarray], only: list[int] | None = None,
                       backward: bool = False, f0: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The residual (every reading, empirical terms projected out) of ``effects`` at ``params`` and its
        forward-difference Jacobian in the scaled parameters (step 0.01 of each effect's scale); ``only``: just
        these columns; ``backward``: backward differences (the slope on the negative side of each parameter,
        which differs from the forward one where the TE has a kink, e.g. a one-sided contact at size zero);
        ``f0``: the residual at ``params`` if the caller has it (e.g. the state's own, for the state with an
        effect added at size zero, which changes no TE), else it is solved.
        Returns (scaled parameters, residual, Jacobian)."""
        scales, lo, hi = _scaled_bounds(effects)
        fun = self._state_fun(effects)
        x = np.concatenate([np.asarray(p, dtype=float) for p in params]) / scales
        r = fun(x) if f0 is None else np.asarray(f0, dtype=float)
        # (backward: the upper bound at the point itself, so every forward step leaves it: fd_jac steps back)
        return x, r, fd_jac(fun, x, lo, np.minimum(hi, x) if backward else hi, h=0.01, f0=r, only=only)

    def _one_sided_interval(self, effects: list[Effect], x: np.ndarray, r: np.ndarray, J: np.ndarray, j: int,
                            e: Effect, side: str, drss: float) -> tuple[float, float]:
        """The confidence interval of a one-parameter member at a bound of its range (``side``: ``"lower"`` or
        ``"upper"``; ``j`` its index in the scaled vector ``x``): from the bound to the end of the region where
        the profiled residual sum of squares rises by at most ``drss`` (:func:`rvcalib.lsq.profile_limit`, scanned
        toward zero, the error's absence, or toward the other bound when zero is outside the range); the other
        bound when the region reaches past zero. The linearised interval is meaningless there: at the bound the
        residual is flat in the parameter (e.g. a pin out of contact at any larger size), so its standard error
        is huge and centred on a value the fit could not go beyond."""
        lo, hi = float(e.lower[0]), float(e.upper[0])
        far = lo if side == "upper" else hi
        toward = 0.0 if lo < 0.0 < hi else far
        fun = self._state_fun(effects)
        lim = profile_limit(fun, x, J, j, toward / e.scale, drss, r0=r)
        end = far if lim is None else lim * e.scale
        val = float(x[j]) * e.scale
        self.notes.append(
            f"{e.name} ended at the {side} bound of its range ({val:.4g} {e.unit}), where the residual does not "
            f"depend on it: the data bound it on one side only, {'>=' if side == 'upper' else '<='} {end:.4g} "
            f"{e.unit} (95 %, profile of the residual with the other effects readjusted linearly); within that the "
            f"size is not determined")
        return (end, val) if side == "upper" else (val, end)

    def clip_to_ranges(self, fitted: list[FittedEffect]) -> None:
        """Keep every reported interval of a one-parameter effect inside the effect's range: the fits cannot
        leave it, and an interval that does (after the linear widenings of the final-state groups, e.g. a pin's
        one-sided interval at the top of its range widened past it) names sizes the model cannot take."""
        by_name = {e.name: e for e in self.lib}
        for f in fitted:
            e = by_name.get(f.name)
            if e is None or e.polar:
                continue
            f.ci_low, f.ci_high = max(f.ci_low, float(e.lower[0])), min(f.ci_high, float(e.upper[0]))

    def intervals(self) -> list[FittedEffect]:
        """The reported effects: each active effect's size with its 95 % confidence interval from the
        Jacobian (forward differences) of the joint fit on all samples and the residual variance,
        widened by ``sqrt((1 + rho) / (1 - rho))`` for a lag-1 residual autocorrelation ``rho > 0``."""
        effects = [a.effect for a in self.active]
        n_emp = sum(t.n_cols for t in self.empirical)
        fitted: list[FittedEffect] = []
        if effects:
            scales = param_scales(effects)
            x, r, J = self.state_jacobian(effects, [a.p for a in self.active])
            p_tot = x.size + n_emp
            dof = max(1, self.n - p_tot)
            s2 = float(r @ r) / dof
            try:
                cov_s = s2 * np.linalg.pinv(J.T @ J)
            except np.linalg.LinAlgError:
                cov_s = np.full((x.size, x.size), np.nan)
            cov = cov_s * np.outer(scales, scales)
            sd = np.sqrt(np.clip(np.diag(cov_s), 1e-300, None))
            self._corr = cov_s / np.outer(sd, sd)
            self._param_index, j0 = [], 0
            for e in effects:
                self._param_index.append(list(range(j0, j0 + e.n_params)))
                j0 += e.n_params
            rho = max(0.0, lag1_autocorr(r))
            infl = math.sqrt((1 + rho) / (1 - rho)) if rho < 0.99 else 10.0
            tq = float(stats.t.ppf(0.975, dof))
            i = 0
            for a in self.active:
                e, k = a.effect, a.effect.n_params
                C = cov[i:i + k, i:i + k]
                a.cov = C
                i += k
                val = e.value(a.p)
                if e.polar:
                    mag, ang = e.magnitude_angle(a.p)
                    g = a.p / mag if mag > 0 else np.array([1.0, 0.0])
                    se = float(math.sqrt(max(g @ C @ g, 0.0)))
                    params = {"x": float(a.p[0]), "y": float(a.p[1])}
                    angle: float | None = ang
                else:
                    se = float(math.sqrt(max(C[0, 0], 0.0)))
                    params = {"value": float(a.p[0])}
                    angle = None
                half = tq * se * infl
                ci = (float(val - half), float(val + half))
                side = None if e.polar else _bound_side(e, a.p)
                if side is not None:
                    ci = self._one_sided_interval(effects, x, r, J, i - k, e, side, (tq * infl) ** 2 * s2)
                declared, total = self._declared_total(e, a.p)
                fitted.append(FittedEffect(
                    e.name, e.key, e.family, e.unit, e.meaning, float(val), ci[0], ci[1],
                    angle, se, params, a.iteration, float(a.info.get("explained_fraction", float("nan"))),
                    float(a.info.get("F", float("nan"))), float(a.info.get("p_value", float("nan"))),
                    float(a.info.get("delta_bic", float("nan"))), list(a.info.get("alternatives", [])),
                    declared, total, dict(a.info.get("selection", {"method": "greedy"})), side))
            if rho > 0.2:
                self.notes.append(f"the final residual is autocorrelated (lag-1 {rho:.2f}): the confidence intervals "
                                  f"are widened by {infl:.2f}")
        return fitted
