"""Results of a response-surface fit: coefficients, ANOVA, fit statistics, diagnostics,
prediction with intervals, validation, canonical analysis and bounded optimum.

ANOVA layout (as the paper's Table 7 / Design-Expert)
-----------------------------------------------------
Index ``Model``, each term (``EA``, ``EA:EB``, ``EA^2`` ...), ``Residual``, ``Lack of fit``,
``Pure error``, ``Cor total``; columns ``sum_sq, df, mean_sq, F, p``.

* Term rows hold *partial* (type-III) sums of squares: the increase of the residual sum of
  squares when that term alone is removed, ``b_j^2 / [(X'X)^-1]_jj``; ``F = SS / MS_res``
  with ``(1, df_res)`` degrees of freedom.
* ``Model`` is ``SS_total - SS_res`` with ``p - 1`` df, tested against ``MS_res``.
* ``Pure error`` pools the scatter of runs at identical factor settings; ``Lack of fit`` is
  ``SS_res - SS_pe`` with ``F = MS_lof / MS_pe``.
* ``F`` and ``p`` are NaN where the paper prints "/" and wherever a test is undefined: no
  replicated runs, zero lack-of-fit df, zero pure error (deterministic simulator: see
  ``notes``), zero residual.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from .checks import check_numeric_column
from .surface import (
    CanonicalAnalysis,
    Optimum,
    PolynomialSurface,
    ValidationResult,
    points_to_coded,
    validation_metrics,
)

__all__ = ["RSMResults", "PURE_ERROR_ZERO_RTOL", "ANOVA_COLUMNS"]

#: Pure-error SS at or below this fraction of the total SS counts as zero.
PURE_ERROR_ZERO_RTOL = 1e-12
#: Residual SS at or below this fraction of the total SS counts as an exact fit.
RESIDUAL_ZERO_RTOL = 1e-20
ANOVA_COLUMNS = ["sum_sq", "df", "mean_sq", "F", "p"]


def _f_sf(F: float, d1: float, d2: float) -> float:
    if not (np.isfinite(F) and d1 > 0 and d2 > 0):
        return float("nan")
    return float(stats.f.sf(F, d1, d2))


class RSMResults:
    """Results of :meth:`rsm.model.ResponseSurfaceModel.fit`.

    Attributes
    ----------
    model : ResponseSurfaceModel
        The model that was fitted.
    params, bse, tvalues, pvalues : Series
        Coded-unit coefficients, standard errors, t statistics and two-sided p-values.
    anova : DataFrame
        The ANOVA table (see module docstring).
    r2, r2_adj, r2_pred : float
        R^2, adjusted R^2 and predicted R^2 (``1 - PRESS/SS_total``).
    press : float
        Prediction error sum of squares (leave-one-out, from the leverages).
    adeq_precision : float
        Adequate precision, ``(max yhat - min yhat) / sqrt(p * MS_res / n)`` (signal to
        noise; > 4 is customarily adequate).
    sigma : float
        Residual standard deviation ``sqrt(MS_res)`` (response units).
    rmse : float
        ``sqrt(SS_res / n)`` (response units).
    fittedvalues, resid : ndarray
        Fitted values and residuals (observed - fitted) at the runs.
    influence : DataFrame
        Per run: ``observed, fitted, resid, leverage, student_resid`` (internally
        studentised), ``ext_student_resid``, ``cooks_d``, ``dffits``.
    notes : list of str
        Statements about undefined tests (e.g. zero pure error at repeated centre runs).
    pure_error_is_zero : bool
        True if replicated runs exist and their pure-error SS is zero.
    alpha : float
        Default significance level for intervals.
    llf, aic, bic : float
        Gaussian log-likelihood (at the ML variance ``SS_res / n``), AIC ``-2 llf + 2p`` and
        BIC ``-2 llf + p ln n``, with p the number of coefficients (statsmodels' OLS convention).
    ss_lack_of_fit, df_lack_of_fit, ss_pure_error, df_pure_error : float, int
        The lack-of-fit split of the residual (also in ``anova``).
    """

    def __init__(
        self,
        model: Any,  # rsm.model.ResponseSurfaceModel (not imported: model imports this module)
        beta: np.ndarray,
        xtx_inv: np.ndarray,
        leverage: np.ndarray,
        alpha: float = 0.05,
    ) -> None:
        if not 0 < alpha < 1:
            raise ValueError(f"alpha must lie in (0, 1), not {alpha}")
        self.model = model
        self.alpha = float(alpha)
        self.notes: list[str] = []
        self.surface = PolynomialSurface(model.factors, model.monomials, beta, model.levels)
        X, y = model.exog, model.y
        n, p = X.shape
        self.nobs, self.n_params = n, p
        self.df_resid = n - p
        self.df_model = p - 1
        self._xtx_inv = xtx_inv
        self.fittedvalues = X @ beta
        self.resid = y - self.fittedvalues
        self.ssr = float(self.resid @ self.resid)
        self.ss_total = float(np.sum((y - y.mean()) ** 2))
        self.exact_fit = self.ssr <= RESIDUAL_ZERO_RTOL * self.ss_total
        self.mse_resid = self.ssr / self.df_resid
        self.sigma = math.sqrt(self.mse_resid)
        self.rmse = math.sqrt(self.ssr / n)
        if self.exact_fit:
            self.notes.append(
                "the model reproduces the data exactly (zero residual): F tests, p-values "
                "and intervals are undefined and reported as NaN"
            )
        names = model.term_names
        self.params = pd.Series(beta, index=names, name="coef")
        cov = self.mse_resid * xtx_inv
        self._cov = cov
        self.bse = pd.Series(np.sqrt(np.diag(cov)), index=names, name="std_err")
        with np.errstate(divide="ignore", invalid="ignore"):
            t = beta / self.bse.to_numpy()
        if self.exact_fit:
            t = np.full_like(beta, np.nan)
        self.tvalues = pd.Series(t, index=names, name="t")
        self.pvalues = pd.Series(2 * stats.t.sf(np.abs(t), self.df_resid), index=names, name="p")

        self._pure_error()
        self.anova = self._anova_table()
        self.r2 = 1.0 - self.ssr / self.ss_total
        self.r2_adj = 1.0 - (self.ssr / self.df_resid) / (self.ss_total / (n - 1))
        self.leverage = np.asarray(leverage, dtype=float)
        if np.any(self.leverage >= 1 - 1e-10):
            self.press = float("nan")
            runs = [int(i) + 1 for i in np.flatnonzero(self.leverage >= 1 - 1e-10)]
            self.notes.append(
                f"runs {runs} have leverage 1 (the model passes through them): PRESS and "
                "predicted R2 are undefined"
            )
        else:
            self.press = float(np.sum((self.resid / (1 - self.leverage)) ** 2))
        self.r2_pred = 1.0 - self.press / self.ss_total
        spread = float(np.ptp(self.fittedvalues))
        avg_var = p * self.mse_resid / n
        self.adeq_precision = spread / math.sqrt(avg_var) if avg_var > 0 else float("nan")
        self.influence = self._influence()
        # Gaussian log-likelihood at the ML variance SS_res/n, as statsmodels' OLS.llf
        if self.ssr > 0:
            self.llf = -0.5 * n * (math.log(2 * math.pi) + math.log(self.ssr / n) + 1.0)
        else:
            self.llf = float("inf")
        #: Akaike and Bayesian information criteria, ``-2 llf + 2p`` and ``-2 llf + p ln n``
        #: (p counts the intercept; statsmodels' OLS convention). Only differences between models
        #: fitted to the same runs mean anything.
        self.aic = -2.0 * self.llf + 2.0 * p
        self.bic = -2.0 * self.llf + p * math.log(n)

    # ------------------------------------------------------------------ ANOVA parts
    def _pure_error(self) -> None:
        m = self.model
        keys = np.round(m.x_coded, 9) + 0.0
        uniq, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.ravel()
        self.n_distinct_points = int(len(uniq))
        self.df_pure_error = int(np.sum(counts - 1))
        means = np.bincount(inverse, weights=m.y) / counts
        dev = m.y - means[inverse]
        self.ss_pure_error = float(dev @ dev) if self.df_pure_error > 0 else 0.0
        self.df_lack_of_fit = self.df_resid - self.df_pure_error
        self.ss_lack_of_fit = max(self.ssr - self.ss_pure_error, 0.0)
        self.pure_error_is_zero = bool(
            self.df_pure_error > 0 and self.ss_pure_error <= PURE_ERROR_ZERO_RTOL * self.ss_total
        )
        self.pure_error_note: str | None = None
        if self.df_pure_error == 0:
            self.pure_error_note = (
                "no replicated runs: pure error has 0 df and the lack-of-fit test is not available"
            )
        elif self.pure_error_is_zero:
            reps = [[float(v) for v in u] for u, c in zip(uniq, counts) if c > 1]
            self.pure_error_note = (
                f"pure error is zero: the {self.df_pure_error + len(reps)} replicated runs "
                f"(at {len(reps)} repeated setting(s), e.g. coded {reps[0]}) have identical "
                "responses (pure-error SS <= 1e-12 of the total SS), as a deterministic "
                "simulator gives; the lack-of-fit F test is skipped (F and p are NaN). "
                "Judge the fit by R2_pred, residuals and validation runs"
            )
        elif self.df_lack_of_fit == 0:
            self.pure_error_note = (
                "lack of fit has 0 df (one coefficient per distinct design point): the "
                "lack-of-fit test is not available"
            )
        if self.pure_error_note:
            self.notes.append(self.pure_error_note)

    def _anova_table(self) -> pd.DataFrame:
        ms_res = self.mse_resid
        undefined = self.exact_fit
        rows: dict[str, list[float]] = {}

        def f_test(ss: float, df: int, denom: float, df_den: int) -> tuple[float, float]:
            if undefined or df <= 0 or df_den <= 0 or not denom > 0:
                return float("nan"), float("nan")
            F = (ss / df) / denom
            return F, _f_sf(F, df, df_den)

        ss_model = self.ss_total - self.ssr
        F, pv = f_test(ss_model, self.df_model, ms_res, self.df_resid)
        rows["Model"] = [ss_model, self.df_model,
                         ss_model / self.df_model if self.df_model else float("nan"), F, pv]
        beta = self.params.to_numpy()
        for j, name in enumerate(self.model.term_names):
            if j == 0:
                continue  # Intercept
            ss = float(beta[j] ** 2 / self._xtx_inv[j, j])
            F, pv = f_test(ss, 1, ms_res, self.df_resid)
            rows[name] = [ss, 1, ss, F, pv]
        rows["Residual"] = [self.ssr, self.df_resid, ms_res, float("nan"), float("nan")]
        ms_pe = self.ss_pure_error / self.df_pure_error if self.df_pure_error else float("nan")
        ms_lof = (self.ss_lack_of_fit / self.df_lack_of_fit if self.df_lack_of_fit > 0
                  else float("nan"))
        if self.pure_error_is_zero or self.df_pure_error == 0 or self.df_lack_of_fit <= 0:
            F, pv = float("nan"), float("nan")
        else:
            F, pv = f_test(self.ss_lack_of_fit, self.df_lack_of_fit, ms_pe, self.df_pure_error)
        rows["Lack of fit"] = [self.ss_lack_of_fit, self.df_lack_of_fit, ms_lof, F, pv]
        rows["Pure error"] = [self.ss_pure_error, self.df_pure_error, ms_pe, float("nan"), float("nan")]
        rows["Cor total"] = [self.ss_total, self.nobs - 1, float("nan"), float("nan"), float("nan")]
        table = pd.DataFrame.from_dict(rows, orient="index", columns=ANOVA_COLUMNS)
        table["df"] = table["df"].astype(int)
        table.index.name = "source"
        return table

    def _influence(self) -> pd.DataFrame:
        h = self.leverage
        n, p = self.nobs, self.n_params
        s2 = self.mse_resid
        with np.errstate(divide="ignore", invalid="ignore"):
            r = self.resid / np.sqrt(s2 * (1 - h))
            dfe = self.df_resid - 1
            ext = r * np.sqrt(dfe / np.maximum(self.df_resid - r**2, 0.0)) if dfe > 0 else np.full(n, np.nan)
            cooks = r**2 * h / (p * (1 - h))
            dffits = ext * np.sqrt(h / (1 - h))
        return pd.DataFrame({
            "observed": self.model.y, "fitted": self.fittedvalues, "resid": self.resid,
            "leverage": h, "student_resid": r, "ext_student_resid": ext,
            "cooks_d": cooks, "dffits": dffits,
        }, index=pd.RangeIndex(1, n + 1, name="run"))

    # ------------------------------------------------------------------ coefficients
    @property
    def factors(self) -> list[str]:
        """Factor names."""
        return self.model.factors

    @property
    def term_names(self) -> list[str]:
        """Term names including ``Intercept``."""
        return self.model.term_names

    @property
    def levels(self):
        """The levels table (or None)."""
        return self.model.levels

    def cov_params(self, units: str = "coded") -> pd.DataFrame:
        """Covariance matrix of the coefficients in ``coded`` or ``actual`` units."""
        if units == "coded":
            return pd.DataFrame(self._cov, index=self.term_names, columns=self.term_names)
        if units == "actual":
            target, T = self._actual_T()
            names = self._actual_names(target)
            return pd.DataFrame(T @ self._cov @ T.T, index=names, columns=names)
        raise ValueError(f"units must be 'coded' or 'actual', not '{units}'")

    def _actual_T(self):
        return self.surface.actual_transform()

    def _actual_names(self, target) -> list[str]:
        from .terms import term_name

        return [term_name(m, self.factors) for m in target]

    @property
    def params_actual(self) -> pd.Series | None:
        """Coefficients in actual units (None without a levels table); see Eq. 8."""
        return self.surface.params_actual

    def conf_int(self, alpha: float | None = None, units: str = "coded") -> pd.DataFrame:
        """Confidence intervals of the coefficients.

        Parameters
        ----------
        alpha : float, optional
            ``1 - alpha`` intervals (default ``self.alpha``).
        units : {'coded', 'actual'}

        Returns
        -------
        DataFrame with columns ``lower, upper``.
        """
        tab = self.coefficients(units=units, alpha=alpha)
        return tab[["ci_lower", "ci_upper"]].rename(columns={"ci_lower": "lower", "ci_upper": "upper"})

    def coefficients(self, units: str = "coded", alpha: float | None = None) -> pd.DataFrame:
        """Coefficient table: ``coef, std_err, t, p, ci_lower, ci_upper``.

        Parameters
        ----------
        units : {'coded', 'actual'}
            Actual-unit rows are the exact re-expansion of the coded polynomial; their
            standard errors come from the transformed covariance ``T C T'``.
        alpha : float, optional
            Interval level (default ``self.alpha``).
        """
        alpha = self.alpha if alpha is None else alpha
        if units == "coded":
            coef = self.params.to_numpy()
            se = self.bse.to_numpy()
            names = self.term_names
        elif units == "actual":
            if self.levels is None:
                raise ValueError("actual-unit coefficients need a levels table")
            target, T = self._actual_T()
            coef = T @ self.params.to_numpy()
            se = np.sqrt(np.diag(T @ self._cov @ T.T))
            names = self._actual_names(target)
        else:
            raise ValueError(f"units must be 'coded' or 'actual', not '{units}'")
        q = stats.t.ppf(1 - alpha / 2, self.df_resid)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = coef / se
        if self.exact_fit:
            t = np.full_like(coef, np.nan)
        return pd.DataFrame({
            "coef": coef, "std_err": se, "t": t, "p": 2 * stats.t.sf(np.abs(t), self.df_resid),
            "ci_lower": coef - q * se, "ci_upper": coef + q * se,
        }, index=pd.Index(names, name="term"))

    # ------------------------------------------------------------------ prediction
    def predict(
        self,
        points: pd.DataFrame | np.ndarray | Mapping[str, Sequence[float]],
        units: str | None = None,
        alpha: float | None = None,
    ) -> pd.DataFrame:
        """Predictions with confidence and prediction intervals.

        Parameters
        ----------
        points : DataFrame, mapping or array (n, k)
            New factor settings (every factor column; extra columns ignored).
        units : {'coded', 'actual'}, optional
            Units of ``points``; default the units of the fitted data.
        alpha : float, optional
            ``1 - alpha`` intervals (default ``self.alpha``).

        Returns
        -------
        DataFrame
            ``mean`` (predicted response), ``mean_se``, ``mean_ci_lower/upper``
            (confidence interval of the mean response) and ``obs_ci_lower/upper``
            (prediction interval of a new observation), as statsmodels names them.
        """
        units = self.model.units if units is None else units
        alpha = self.alpha if alpha is None else alpha
        z = points_to_coded(points, self.factors, self.levels, units)
        from .terms import model_matrix

        Xn = model_matrix(z, self.model.monomials)
        mean = Xn @ self.params.to_numpy()
        var_mean = np.einsum("ij,jk,ik->i", Xn, self._cov, Xn)
        se = np.sqrt(np.maximum(var_mean, 0.0))
        q = stats.t.ppf(1 - alpha / 2, self.df_resid)
        se_obs = np.sqrt(var_mean + self.mse_resid)
        return pd.DataFrame({
            "mean": mean, "mean_se": se,
            "mean_ci_lower": mean - q * se, "mean_ci_upper": mean + q * se,
            "obs_ci_lower": mean - q * se_obs, "obs_ci_upper": mean + q * se_obs,
        })

    def prediction_test(
        self,
        data: pd.DataFrame,
        response: str | None = None,
        units: str | None = None,
    ) -> dict[str, float]:
        """Do new runs agree with this fit? Chow's predictive test.

        With ``e = y_new - X_new b`` the prediction errors of ``m`` new runs and
        ``V = I + X_new (X'X)^-1 X_new'`` their covariance in units of ``sigma^2``,
        ``F = e' V^-1 e / (m s^2)`` follows ``F(m, df_resid)`` when the new runs come from the
        fitted model (G. C. Chow, Econometrica 28 (1960) 591-605, the predictive form). A small
        ``p`` says the new runs show a lack of fit that the fitted runs could not.

        Parameters
        ----------
        data : DataFrame
            New runs with every factor column and the response column.
        response : str, optional
            Response column (default the model's response).
        units : {'coded', 'actual'}, optional
            Units of the factor columns (default the fitted data's units).

        Returns
        -------
        dict
            ``n`` (new runs), ``F``, ``df_num`` (= n), ``df_den`` (= df_resid), ``p``,
            ``rmse_pred`` (root-mean-square prediction error, response units) and ``bias``
            (mean of observed - predicted). F and p are NaN for an exact fit.
        """
        from .terms import model_matrix

        response = self.model.response if response is None else response
        units = self.model.units if units is None else units
        if len(data) == 0:
            raise ValueError("the new runs are empty")
        obs = check_numeric_column(data, response, "response")
        z = points_to_coded(data, self.factors, self.levels, units)
        Xn = model_matrix(z, self.model.monomials)
        e = obs - Xn @ self.params.to_numpy()
        m = len(e)
        V = np.eye(m) + Xn @ self._xtx_inv @ Xn.T
        if self.exact_fit:
            F = p = float("nan")
        else:
            F = float(e @ np.linalg.solve(V, e) / (m * self.mse_resid))
            p = _f_sf(F, m, self.df_resid)
        return {"n": int(m), "F": F, "df_num": int(m), "df_den": int(self.df_resid), "p": p,
                "rmse_pred": float(np.sqrt(np.mean(e**2))), "bias": float(np.mean(e))}

    def validate(
        self,
        data: pd.DataFrame,
        response: str | None = None,
        units: str | None = None,
        alpha: float | None = None,
    ) -> ValidationResult:
        """Compare predictions with held-out runs (the paper's Fig. 13 check).

        Parameters
        ----------
        data : DataFrame
            Held-out runs with every factor column and the response column.
        response : str, optional
            Response column (default the model's response).
        units : {'coded', 'actual'}, optional
            Units of the factor columns (default the fitted data's units).
        alpha : float, optional
            Prediction-interval level for ``pi_coverage``.

        Returns
        -------
        ValidationResult
            RMSE, MAE, max error, bias, R2 and the fraction of observations inside the
            ``1 - alpha`` prediction interval.
        """
        response = self.model.response if response is None else response
        alpha = self.alpha if alpha is None else alpha
        obs = check_numeric_column(data, response, "response")
        pred = self.predict(data, units=units, alpha=alpha)
        return validation_metrics(obs, pred["mean"].to_numpy(), pred["obs_ci_lower"].to_numpy(),
                                  pred["obs_ci_upper"].to_numpy(), alpha=alpha)

    # ------------------------------------------------------------------ surface analysis
    def design_box(self) -> list[tuple[float, float]]:
        """Coded per-factor (min, max) of the fitted runs."""
        z = self.model.x_coded
        return [(float(a), float(b)) for a, b in zip(z.min(axis=0), z.max(axis=0))]

    def canonical(self) -> CanonicalAnalysis:
        """Canonical analysis of the second-order model (coded units); see
        :meth:`rsm.surface.PolynomialSurface.canonical`. ``inside_design`` refers to the
        box of the fitted runs."""
        return self.surface.canonical(box=self.design_box())

    def optimum(
        self,
        goal: str = "min",
        bounds: Sequence[tuple[float, float]] | None = None,
        seed: int | None = 0,
    ) -> Optimum:
        """Minimum (or maximum) of the fitted surface inside the design box.

        Parameters
        ----------
        goal : {'min', 'max'}
        bounds : sequence of (low, high), optional
            Coded bounds; default the box of the fitted runs (for a BBD: [-1, 1]^k).
        seed : int, optional
            Seed of the random starts.
        """
        return self.surface.optimize(goal, self.design_box() if bounds is None else bounds,
                                     seed=seed)

    # ------------------------------------------------------------------ reporting
    def fit_statistics(self) -> dict[str, float]:
        """``r2, r2_adj, r2_pred, press, adeq_precision, std_dev, mean, cv_percent, rmse, aic, bic``."""
        mean = float(np.mean(self.model.y))
        return {
            "r2": self.r2, "r2_adj": self.r2_adj, "r2_pred": self.r2_pred, "press": self.press,
            "adeq_precision": self.adeq_precision, "std_dev": self.sigma, "mean": mean,
            "cv_percent": 100 * self.sigma / abs(mean) if mean else float("nan"),
            "rmse": self.rmse, "aic": self.aic, "bic": self.bic,
        }

    def to_dict(self) -> dict:
        """JSON-ready summary (NaN values stay float NaN; see :func:`rsm.cli.jsonable`)."""
        anova = {src: {c: (int(row[c]) if c == "df" else float(row[c])) for c in ANOVA_COLUMNS}
                 for src, row in self.anova.iterrows()}
        out = {
            "response": self.model.response,
            "factors": self.factors,
            "units": self.model.units,
            "n_runs": self.nobs,
            "terms": self.term_names,
            "anova": anova,
            **self.fit_statistics(),
            "coefficients": {
                "coded": {k: float(v) for k, v in self.params.items()},
                "actual": (None if self.params_actual is None
                           else {k: float(v) for k, v in self.params_actual.items()}),
            },
            "coefficient_table": {
                "coded": self.coefficients("coded").to_dict(orient="index"),
                "actual": (None if self.levels is None
                           else self.coefficients("actual").to_dict(orient="index")),
            },
            "pure_error_is_zero": self.pure_error_is_zero,
            "notes": list(self.notes),
        }
        return out

    def summary(self) -> str:
        """Human-readable report: ANOVA, fit statistics, coefficients and notes."""
        lines = [
            f"Response surface fit: {self.model.response} ~ {' + '.join(self.term_names[1:])}",
            f"runs: {self.nobs}, coefficients: {self.n_params}, residual df: {self.df_resid}, "
            f"data units: {self.model.units}",
            "",
            "Analysis of variance (partial sums of squares, coded factors)",
            _format_anova(self.anova),
            "",
        ]
        st = self.fit_statistics()
        lines.append(
            f"R2 = {st['r2']:.4f}   R2adj = {st['r2_adj']:.4f}   R2pred = {st['r2_pred']:.4f}   "
            f"Adeq precision = {st['adeq_precision']:.3f}"
        )
        lines.append(
            f"Std dev = {st['std_dev']:.4g}   Mean = {st['mean']:.4g}   C.V. % = {st['cv_percent']:.2f}   "
            f"PRESS = {st['press']:.4g}"
        )
        lines.append("")
        pct = int(round(100 * (1 - self.alpha)))
        lines.append(f"Coefficients (coded units, {pct}% CI)")
        lines.append(_format_coefs(self.coefficients("coded")))
        if self.levels is not None:
            lines.append("")
            units = ", ".join(f"{f} [{self.levels.unit(f)}]" for f in self.factors if self.levels.unit(f))
            lines.append(f"Coefficients (actual units{': ' + units if units else ''})")
            lines.append(_format_coefs(self.coefficients("actual")))
        if self.notes:
            lines.append("")
            lines.extend(f"NOTE: {n}" for n in self.notes)
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"<RSMResults {self.model.response}: {self.n_params} terms, n={self.nobs}, "
                f"R2={self.r2:.4f}, R2adj={self.r2_adj:.4f}>")


def _fmt(v: float, width: int = 11) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "/".rjust(width)
    a = abs(v)
    if a != 0 and (a < 1e-3 or a >= 1e5):
        return f"{v:{width}.3e}"
    return f"{v:{width}.4f}"


def _format_anova(table: pd.DataFrame) -> str:
    head = f"{'Source':<12}{'Sum sq':>11}{'DF':>5}{'Mean sq':>11}{'F value':>11}{'P value':>11}"
    out = [head]
    for src, r in table.iterrows():
        p = r["p"]
        ps = "/".rjust(11) if not np.isfinite(p) else ("< 0.0001".rjust(11) if p < 1e-4 else f"{p:11.4f}")
        out.append(f"{src:<12}{_fmt(r['sum_sq'])}{int(r['df']):>5}{_fmt(r['mean_sq'])}{_fmt(r['F'])}{ps}")
    return "\n".join(out)


def _format_coefs(tab: pd.DataFrame) -> str:
    out = [f"{'Term':<12}{'Coef':>13}{'Std err':>12}{'CI low':>13}{'CI high':>13}{'p':>9}"]
    for name, r in tab.iterrows():
        p = r["p"]
        ps = "/" if not np.isfinite(p) else ("<0.0001" if p < 1e-4 else f"{p:.4f}")
        out.append(f"{name:<12}{r['coef']:>13.6g}{r['std_err']:>12.4g}{r['ci_lower']:>13.6g}"
                   f"{r['ci_upper']:>13.6g}{ps:>9}")
    return "\n".join(out)
