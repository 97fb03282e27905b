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

from rvcalib.effects import Effect
from rvcalib.forward import ModelEvaluationError
from rvcalib.lsq import chord_fit, fd_jac, projector
from rvcalib.residual import lag1_autocorr
from rvcalib.results import EmpiricalTerm, FittedEffect
from rvcalib.screening import Screening


class Fitting(Screening):
    """The fitting stage of the loop (methods on the loop's model and screening)."""

    #: Start Jacobians of the joint refits taken from the last joint fit: ``"removals"`` (its own state
    #: only: refits of the same effects with members removed), ``"all"`` (any kept column, stale) or ``"off"``.
    jacobian_reuse: str = "removals"
    #: The last joint fit's Jacobian columns per effect, its empirical terms and its solution
    #: (:meth:`_keep_jacobian`); None before the first joint fit.
    _jac_kept: tuple | None = None

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
        sizes = [e.n_params for e in effects]
        scales = np.concatenate([np.full(e.n_params, e.scale) for e in effects]) if effects else np.zeros(0)
        lo = np.concatenate([np.array(e.lower) for e in effects]) / scales if effects else np.zeros(0)
        hi = np.concatenate([np.array(e.upper) for e in effects]) / scales if effects else np.zeros(0)
        P = projector(self._emp_matrix(terms))

        def unpack(xs: np.ndarray) -> list[tuple[Effect, np.ndarray]]:
            out, i = [], 0
            for e, k in zip(effects, sizes):
                out.append((e, xs[i:i + k] * e.scale))
                i += k
            return out

        def fun(xs: np.ndarray) -> np.ndarray:
            pred = self.predict(unpack(xs))
            return P(np.concatenate([y - p for y, p in zip(self.y, pred)]))

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

    def _cached_jacobian(self, effects: list[Effect], p0: list[np.ndarray], terms: list[EmpiricalTerm],
                         P) -> tuple[np.ndarray | None, np.ndarray | None]:
        """A start Jacobian for :meth:`fit_full` from the last joint fit's final Jacobian
        (:meth:`_keep_jacobian`), and the mask of the columns it holds.

        Columns are reused only at that fit's own state: every effect of this fit was in it, at the
        same parameters (``p0`` equal to its solution), and its empirical terms are all among
        ``terms`` (the projector of ``terms`` applied to a column projected with fewer terms is the
        column projected with ``terms``). That is a refit of the same effects with members removed
        (the backward elimination, the term-limit checks): its start Jacobian is the kept one's
        columns; otherwise (new members, moved sizes) every column is differenced as before. With
        ``jacobian_reuse = "all"`` any kept column of an effect is reused wherever it was taken (a
        stale start: faster, but the fits then stop at other points within their tolerance and the
        loop's discrete choices can change; measured in docs/calibration.md)."""
        kept = self._jac_kept
        mode = self.jacobian_reuse
        if kept is None or mode == "off":
            return None, None
        cols, kterms, kparams = kept
        tset = set(terms)
        if not kterms <= tset:
            return None, None
        if mode != "all":
            for e, p in zip(effects, p0):
                q = kparams.get(e.name)
                if q is None or q.shape != np.shape(p) or not np.array_equal(q, np.asarray(p, dtype=float)):
                    return None, None
        blocks, mask = [], []
        for e in effects:
            got = cols.get(e.name)
            if got is not None and got.shape == (self.n, e.n_params):
                blocks.append(P(got) if kterms != tset else got)
                mask += [True] * e.n_params
            else:
                blocks.append(np.zeros((self.n, e.n_params)))
                mask += [False] * e.n_params
        if not any(mask):
            return None, None
        return np.column_stack(blocks), np.array(mask)

    def _keep_jacobian(self, effects: list[Effect], params: list[np.ndarray], terms: list[EmpiricalTerm],
                       J: np.ndarray) -> None:
        """Keep a joint fit's final Jacobian (scaled parameters, residual projected with ``terms``) per
        effect, with the fit's solution, for the start of later fits (:meth:`_cached_jacobian`)."""
        if J is None or J.ndim != 2 or J.shape[0] != self.n:
            return
        cols: dict[str, np.ndarray] = {}
        if self.jacobian_reuse == "all" and self._jac_kept is not None:
            cols.update(self._jac_kept[0])
        i = 0
        for e in effects:
            cols[e.name] = np.array(J[:, i:i + e.n_params])
            i += e.n_params
        self._jac_kept = (cols, frozenset(terms), {e.name: np.array(p, dtype=float) for e, p in zip(effects, params)})

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

    def state_jacobian(self, effects: list[Effect], params: list[np.ndarray], only: list[int] | None = None,
                       backward: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The residual (every reading, empirical terms projected out) of ``effects`` at ``params`` and its
        forward-difference Jacobian in the scaled parameters (step 0.01 of each effect's scale); ``only``: just
        these columns; ``backward``: backward differences (the slope on the negative side of each parameter,
        which differs from the forward one where the TE has a kink, e.g. a one-sided contact at size zero).
        Returns (scaled parameters, residual, Jacobian)."""
        sizes = [e.n_params for e in effects]
        scales = np.concatenate([np.full(e.n_params, e.scale) for e in effects])
        lo = np.concatenate([np.array(e.lower) for e in effects]) / scales
        hi = np.concatenate([np.array(e.upper) for e in effects]) / scales
        P = projector(self._emp_matrix(self.empirical))

        def fun(xs: np.ndarray) -> np.ndarray:
            out, i = [], 0
            for e, k in zip(effects, sizes):
                out.append((e, xs[i:i + k] * e.scale))
                i += k
            return P(np.concatenate([y - p for y, p in zip(self.y, self.predict(out))]))

        x = np.concatenate([np.asarray(p, dtype=float) for p in params]) / scales
        r = fun(x)
        # (backward: the upper bound at the point itself, so every forward step leaves it: fd_jac steps back)
        return x, r, fd_jac(fun, x, lo, np.minimum(hi, x) if backward else hi, h=0.01, f0=r, only=only)

    def intervals(self) -> list[FittedEffect]:
        """The reported effects: each active effect's size with its 95 % confidence interval from the
        Jacobian (forward differences) of the joint fit on all samples and the residual variance,
        widened by ``sqrt((1 + rho) / (1 - rho))`` for a lag-1 residual autocorrelation ``rho > 0``."""
        effects = [a.effect for a in self.active]
        n_emp = sum(t.n_cols for t in self.empirical)
        fitted: list[FittedEffect] = []
        if effects:
            scales = np.concatenate([np.full(e.n_params, e.scale) for e in effects])
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
                declared, total = self._declared_total(e, a.p)
                fitted.append(FittedEffect(
                    e.name, e.key, e.family, e.unit, e.meaning, float(val), float(val - half), float(val + half),
                    angle, se, params, a.iteration, float(a.info.get("explained_fraction", float("nan"))),
                    float(a.info.get("F", float("nan"))), float(a.info.get("p_value", float("nan"))),
                    float(a.info.get("delta_bic", float("nan"))), list(a.info.get("alternatives", [])),
                    declared, total, dict(a.info.get("selection", {"method": "greedy"}))))
            if rho > 0.2:
                self.notes.append(f"the final residual is autocorrelated (lag-1 {rho:.2f}): the confidence intervals "
                                  f"are widened by {infl:.2f}")
        return fitted
