"""The response-surface model: data checks, model matrix and least-squares fit.

The model works in coded units (each factor scaled so that the levels table's low/centre/
high are -1/0/+1). ANOVA sums of squares, standard errors and tests refer to the coded
model, as Design-Expert and the paper do; coefficients are also reported in actual units
by exact polynomial re-expansion (see :meth:`rsm.results.RSMResults.params_actual`).

Example
-------
>>> import pandas as pd
>>> from rsm import ResponseSurfaceModel
>>> data = pd.read_csv("paper_table6_bbd_runs.csv")                     # doctest: +SKIP
>>> res = ResponseSurfaceModel(data, ["EA", "EB", "EC", "ED"], "te_arcmin",
...                            levels="paper_table5_levels.csv").fit()  # doctest: +SKIP
>>> res.anova.loc["EA^2", "F"]                                           # doctest: +SKIP
446.6...
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import linalg

from .checks import NotEstimableError, check_numeric_column
from .coding import Levels
from .csvio import read_csv_strict
from .results import RSMResults
from .terms import Monomial, model_matrix, parse_terms, term_name, validate_factor_names

#: ``check_numeric_column`` and ``NotEstimableError`` live in :mod:`rsm.checks` (re-exported here).
__all__ = ["ResponseSurfaceModel", "ZeroPureErrorWarning", "fit", "check_numeric_column", "NotEstimableError"]


class ZeroPureErrorWarning(UserWarning):
    """Replicated runs have identical responses (a deterministic simulator)."""


class ResponseSurfaceModel:
    """A polynomial response-surface model (statsmodels style: ``fit()`` returns results).

    Parameters
    ----------
    data : DataFrame
        One row per run with the factor columns and the response column.
    factors : sequence of str
        Factor column names, in model order (term names use this order).
    response : str
        Response column name (any unit; the paper's is arcmin).
    terms : str or sequence of str, default 'quadratic'
        Model terms: a preset (``linear``, ``2fi``, ``quadratic``), a list of terms, or a
        mix such as ``["quadratic", "EA^3", "EA:EB:EC"]``. See :mod:`rsm.terms`.
    levels : Levels, DataFrame, path or None
        Levels table (``factor, low, center, high[, unit]``). Needed for actual-unit
        coefficients and for ``units='actual'`` data.
    units : {'coded', 'actual'}, default 'coded'
        Units of the factor columns in ``data``. ``actual`` data are coded with ``levels``.
        Without levels the factor columns are used as given (treated as coded).

    Raises
    ------
    ValueError
        Missing/non-numeric/constant factor column, missing/constant response, a levels
        table without a factor, a term naming an unknown factor, fewer runs than
        coefficients + 1, or a term that the runs cannot estimate
        (:class:`rsm.checks.NotEstimableError`, a ValueError carrying the terms).
    """

    def __init__(
        self,
        data: pd.DataFrame,
        factors: Sequence[str],
        response: str,
        terms: str | Sequence[str] = "quadratic",
        levels: Levels | pd.DataFrame | str | Path | None = None,
        units: str = "coded",
    ) -> None:
        if not isinstance(data, pd.DataFrame):
            raise ValueError(f"data must be a pandas DataFrame, not {type(data).__name__}")
        self.factors: list[str] = validate_factor_names(factors)
        self.response: str = str(response)
        if self.response in self.factors:
            raise ValueError(f"column '{self.response}' is both a factor and the response")
        if units not in ("coded", "actual"):
            raise ValueError(f"units must be 'coded' or 'actual', not '{units}'")
        self.units = units
        lv = Levels.coerce(levels)
        self.levels: Levels | None = lv.subset(self.factors) if lv is not None else None
        if units == "actual" and self.levels is None:
            raise ValueError("units='actual' needs a levels table to code the factors")

        if len(data) == 0:
            raise ValueError("the data has no rows")
        cols = [check_numeric_column(data, f, "factor") for f in self.factors]
        y = check_numeric_column(data, self.response, "response")
        x = np.column_stack(cols)
        for j, f in enumerate(self.factors):
            if np.ptp(x[:, j]) == 0.0:
                raise ValueError(
                    f"factor column '{f}' is constant (value {float(x[0, j])!r}); a constant factor "
                    "cannot be estimated: drop it from the factors"
                )
        if np.ptp(y) == 0.0:
            raise ValueError(
                f"response column '{self.response}' is constant (value {float(y[0])!r}); there is "
                "nothing to fit"
            )
        self.data = data
        self.x_input = x
        self.x_coded = self.levels.actual_to_coded(x, self.factors) if units == "actual" else x
        self.y = y

        self.terms_spec = terms
        self.monomials: list[Monomial] = parse_terms(terms, self.factors)
        self.term_names: list[str] = [term_name(m, self.factors) for m in self.monomials]
        self.exog = model_matrix(self.x_coded, self.monomials)
        n, p = self.exog.shape
        if n < p + 1:
            raise ValueError(
                f"too few runs for the model: {n} runs but the model has {p} coefficients "
                f"({', '.join(self.term_names)}); at least {p + 1} runs are needed for one "
                "residual degree of freedom"
            )
        self._check_estimable()

    # ------------------------------------------------------------------ helpers
    def _check_estimable(self) -> None:
        """Raise :class:`NotEstimableError` naming every term whose column depends on earlier ones.

        Terms are taken in model order; a term is not estimable when its (norm-scaled) column
        does not raise the rank of the columns kept before it.
        """
        X = self.exog
        scale = np.linalg.norm(X, axis=0)
        Xs = X / np.where(scale > 0, scale, 1.0)
        if np.linalg.matrix_rank(Xs) == Xs.shape[1]:
            return
        kept: list[int] = []
        bad: list[str] = []
        for j in range(Xs.shape[1]):
            if np.linalg.matrix_rank(Xs[:, kept + [j]]) < len(kept) + 1:
                bad.append(self.term_names[j])
            else:
                kept.append(j)
        raise NotEstimableError(bad)

    @property
    def nobs(self) -> int:
        """Number of runs."""
        return int(self.exog.shape[0])

    def with_terms(self, terms: str | Iterable[str]) -> "ResponseSurfaceModel":
        """A new model on the same data, factors, levels and units with other terms."""
        if not isinstance(terms, str):
            terms = list(terms)
        return ResponseSurfaceModel(self.data, self.factors, self.response, terms,
                                    self.levels, self.units)

    @classmethod
    def from_csv(
        cls, path: str | Path, factors: Sequence[str], response: str, **kwargs
    ) -> "ResponseSurfaceModel":
        """Read the data from a CSV file (``.`` decimal point, header row)."""
        return cls(read_csv_strict(path, "data file"), factors, response, **kwargs)

    # ------------------------------------------------------------------ fit
    def fit(self, alpha: float = 0.05, warn: bool = True) -> "RSMResults":
        """Least-squares fit.

        Parameters
        ----------
        alpha : float, default 0.05
            Significance level of the default confidence intervals (``1 - alpha``).
        warn : bool, default True
            Issue a :class:`ZeroPureErrorWarning` when replicated runs have zero pure error
            (the note is always recorded in ``results.notes``).

        Returns
        -------
        RSMResults
        """
        X, y = self.exog, self.y
        Q, R = np.linalg.qr(X)
        beta = linalg.solve_triangular(R, Q.T @ y)
        Rinv = linalg.solve_triangular(R, np.eye(R.shape[0]))
        xtx_inv = Rinv @ Rinv.T
        leverage = np.sum(Q**2, axis=1)
        res = RSMResults(self, beta, xtx_inv, leverage, alpha=alpha)
        if warn and res.pure_error_is_zero:
            warnings.warn(res.pure_error_note, ZeroPureErrorWarning, stacklevel=2)
        return res

    def __repr__(self) -> str:
        return (f"ResponseSurfaceModel(response='{self.response}', factors={self.factors}, "
                f"terms={self.term_names[1:]}, n={self.nobs})")


def fit(
    data: pd.DataFrame,
    factors: Sequence[str],
    response: str,
    terms: str | Sequence[str] = "quadratic",
    levels: Levels | pd.DataFrame | str | Path | None = None,
    units: str = "coded",
    alpha: float = 0.05,
) -> "RSMResults":
    """Shortcut for ``ResponseSurfaceModel(...).fit(alpha)``; see the class for parameters."""
    return ResponseSurfaceModel(data, factors, response, terms, levels, units).fit(alpha=alpha)
