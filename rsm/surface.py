"""A fitted (or truncated) polynomial surface: evaluation, unit conversion, canonical
analysis, bounded optimisation and validation metrics.

:class:`PolynomialSurface` holds coefficients of coded-unit monomials. It is what both a
least-squares fit (:class:`rsm.results.RSMResults`) and the paper's "drop terms without
refitting" simplification (:func:`rsm.reduce.paper_reduction`) produce.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import optimize

from .checks import check_numeric_column
from .coding import Levels
from .terms import Monomial, affine_transform_matrix, model_matrix, term_name

__all__ = [
    "PolynomialSurface",
    "CanonicalAnalysis",
    "Optimum",
    "ValidationResult",
    "validation_metrics",
    "points_to_coded",
]


def points_to_coded(
    points: pd.DataFrame | np.ndarray | Mapping[str, Sequence[float]],
    factors: Sequence[str],
    levels: Levels | None,
    units: str,
) -> np.ndarray:
    """Factor values of new points as a coded (n, k) array.

    Parameters
    ----------
    points : DataFrame, mapping or array
        A DataFrame/mapping needs every factor column (extra columns are ignored); an
        array must have ``k`` columns in factor order.
    factors : sequence of str
        Factor names.
    levels : Levels or None
        Needed when ``units == 'actual'``.
    units : {'coded', 'actual'}
        Units of ``points``.
    """
    if units not in ("coded", "actual"):
        raise ValueError(f"units must be 'coded' or 'actual', not '{units}'")
    if isinstance(points, Mapping) and not isinstance(points, pd.DataFrame):
        points = pd.DataFrame({k: np.atleast_1d(v) for k, v in points.items()})
    if isinstance(points, pd.DataFrame):
        x = np.column_stack([check_numeric_column(points, f, "factor") for f in factors])
    else:
        x = np.atleast_2d(np.asarray(points, dtype=float))
        if x.shape[1] != len(factors):
            raise ValueError(f"points need {len(factors)} columns ({list(factors)}), got {x.shape[1]}")
        if not np.all(np.isfinite(x)):
            raise ValueError("points contain a non-finite value")
    if units == "actual":
        if levels is None:
            raise ValueError("units='actual' needs a levels table")
        x = levels.actual_to_coded(x, factors)
    return x


@dataclass
class CanonicalAnalysis:
    """Canonical analysis of a second-order surface ``y = b0 + x'b + x'Bx`` (coded units).

    Attributes
    ----------
    stationary_point : Series
        ``x_s = -B^{-1} b / 2`` in coded units (NaN if ``B`` is singular).
    stationary_point_actual : Series or None
        The same in actual units (None without levels).
    value : float
        Predicted response at the stationary point.
    eigenvalues : ndarray
        Eigenvalues of ``B`` (ascending); all > 0: minimum, all < 0: maximum, mixed:
        saddle, any ~0: ridge.
    eigenvectors : DataFrame
        Columns are the canonical axes (``w1``, ``w2``, ...) in coded factor space.
    nature : str
        ``minimum``, ``maximum``, ``saddle`` or ``ridge``.
    inside_design : bool
        True if the stationary point lies in the coded box of the data.
    B : ndarray
        The symmetric matrix of second-order coefficients.
    b : ndarray
        The first-order coefficients.
    """

    stationary_point: pd.Series
    stationary_point_actual: pd.Series | None
    value: float
    eigenvalues: np.ndarray
    eigenvectors: pd.DataFrame
    nature: str
    inside_design: bool
    B: np.ndarray
    b: np.ndarray


@dataclass
class Optimum:
    """Result of a bounded optimisation of the surface.

    Attributes
    ----------
    goal : str
        ``min`` or ``max``.
    x_coded : Series
        Location in coded units.
    x_actual : Series or None
        Location in actual units (None without levels).
    value : float
        Predicted response there (response units).
    bounds : list of (float, float)
        Coded bounds searched.
    at_bound : list of str
        Factors whose optimum lies on a bound.
    success : bool
        scipy's success flag of the best start.
    """

    goal: str
    x_coded: pd.Series
    x_actual: pd.Series | None
    value: float
    bounds: list[tuple[float, float]]
    at_bound: list[str]
    success: bool


@dataclass
class ValidationResult:
    """Metrics of predictions against held-out observations.

    Attributes
    ----------
    n : int
        Number of validation points.
    rmse, mae, max_abs_error, bias : float
        Root-mean-square, mean absolute, largest absolute and mean error
        (``predicted - observed``), in response units.
    r2 : float
        ``1 - SSE/SST`` on the held-out set (NaN for fewer than 2 points or constant data).
    pi_coverage : float
        Fraction of observations inside the ``1 - alpha`` prediction interval (NaN when the
        predictor has no intervals, e.g. the paper-mode surface).
    alpha : float
        Interval level used.
    table : DataFrame
        Per point: ``observed, predicted, error`` and, if available, ``obs_ci_lower,
        obs_ci_upper, inside``.
    """

    n: int
    rmse: float
    mae: float
    max_abs_error: float
    bias: float
    r2: float
    pi_coverage: float
    alpha: float
    table: pd.DataFrame = field(repr=False)

    def to_dict(self) -> dict:
        """Scalar metrics as a dict."""
        return {"n": self.n, "rmse": self.rmse, "mae": self.mae,
                "max_abs_error": self.max_abs_error, "bias": self.bias, "r2": self.r2,
                "pi_coverage": self.pi_coverage, "alpha": self.alpha}


def validation_metrics(
    observed: np.ndarray,
    predicted: np.ndarray,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
    alpha: float = 0.05,
) -> ValidationResult:
    """Compare predictions with observations.

    Parameters
    ----------
    observed, predicted : array_like
        Same length.
    lower, upper : array_like, optional
        Prediction-interval bounds; if given, ``pi_coverage`` is the fraction inside.
    alpha : float
        Level of the interval (recorded only).

    Returns
    -------
    ValidationResult
    """
    obs = np.asarray(observed, dtype=float)
    pred = np.asarray(predicted, dtype=float)
    if obs.shape != pred.shape or obs.ndim != 1:
        raise ValueError("observed and predicted must be 1-D arrays of the same length")
    if obs.size == 0:
        raise ValueError("the validation set is empty")
    err = pred - obs
    table = pd.DataFrame({"observed": obs, "predicted": pred, "error": err})
    sst = float(np.sum((obs - obs.mean()) ** 2))
    r2 = 1.0 - float(np.sum(err**2)) / sst if obs.size > 1 and sst > 0 else float("nan")
    cov = float("nan")
    if lower is not None and upper is not None:
        lo = np.asarray(lower, dtype=float)
        hi = np.asarray(upper, dtype=float)
        inside = (obs >= lo) & (obs <= hi)
        table["obs_ci_lower"] = lo
        table["obs_ci_upper"] = hi
        table["inside"] = inside
        cov = float(np.mean(inside))
    return ValidationResult(
        n=int(obs.size), rmse=float(np.sqrt(np.mean(err**2))), mae=float(np.mean(np.abs(err))),
        max_abs_error=float(np.max(np.abs(err))), bias=float(np.mean(err)), r2=r2,
        pi_coverage=cov, alpha=alpha, table=table,
    )


class PolynomialSurface:
    """A polynomial in the coded factors.

    Parameters
    ----------
    factors : sequence of str
        Factor names.
    monomials : sequence of tuple of int
        Exponents per factor for each coefficient (coded units).
    coefs : array_like
        Coefficients (response units per coded unit^degree).
    levels : Levels or None
        Levels table for actual units.
    """

    def __init__(
        self,
        factors: Sequence[str],
        monomials: Sequence[Monomial],
        coefs: np.ndarray,
        levels: Levels | None = None,
    ) -> None:
        self.factors = list(factors)
        self.monomials = [tuple(int(p) for p in m) for m in monomials]
        self.coefs = np.asarray(coefs, dtype=float)
        self.levels = levels
        if self.coefs.shape != (len(self.monomials),):
            raise ValueError("one coefficient per monomial is required")

    # ------------------------------------------------------------------ basics
    @property
    def names(self) -> list[str]:
        """Term names (``Intercept``, ``EA``, ``EA:EB``, ``EA^2`` ...)."""
        return [term_name(m, self.factors) for m in self.monomials]

    @property
    def params(self) -> pd.Series:
        """Coded-unit coefficients keyed by term name."""
        return pd.Series(self.coefs, index=self.names, name="coded")

    def actual_transform(self) -> tuple[list[Monomial], np.ndarray]:
        """Monomials in actual units and the matrix ``T`` with ``b_actual = T @ b_coded``."""
        if self.levels is None:
            raise ValueError("actual-unit coefficients need a levels table")
        c = self.levels.center(self.factors)
        h = self.levels.half_range(self.factors)
        return affine_transform_matrix(self.monomials, -c / h, 1.0 / h)

    @property
    def params_actual(self) -> pd.Series | None:
        """Actual-unit coefficients keyed by term name (None without levels).

        The coded polynomial is re-expanded exactly with ``z = (x - center)/half_range``;
        a non-zero centre can create lower-order terms that the coded model lacks, and they
        are listed too.
        """
        if self.levels is None:
            return None
        target, T = self.actual_transform()
        return pd.Series(T @ self.coefs, index=[term_name(m, self.factors) for m in target],
                         name="actual")

    @classmethod
    def from_actual(
        cls,
        factors: Sequence[str],
        monomials: Sequence[Monomial],
        coefs_actual: np.ndarray,
        levels: Levels,
    ) -> "PolynomialSurface":
        """Build from actual-unit coefficients (re-expanded into coded units)."""
        c = levels.center(factors)
        h = levels.half_range(factors)
        target, T = affine_transform_matrix(monomials, c, h)
        return cls(factors, target, T @ np.asarray(coefs_actual, dtype=float), levels)

    def predict_coded(self, x_coded: np.ndarray) -> np.ndarray:
        """Evaluate at coded points, shape (n, k) -> (n,)."""
        return model_matrix(x_coded, self.monomials) @ self.coefs

    def predict(
        self,
        points: pd.DataFrame | np.ndarray | Mapping[str, Sequence[float]],
        units: str = "coded",
    ) -> np.ndarray:
        """Evaluate at new points given in ``units`` (see :func:`points_to_coded`)."""
        return self.predict_coded(points_to_coded(points, self.factors, self.levels, units))

    @property
    def max_degree(self) -> int:
        """Highest total degree of any term."""
        return max(sum(m) for m in self.monomials)

    # ------------------------------------------------------------------ analysis
    def second_order_parts(self) -> tuple[float, np.ndarray, np.ndarray]:
        """``(b0, b, B)`` with ``y = b0 + x'b + x'Bx`` (coded); ValueError above degree 2."""
        if self.max_degree > 2:
            bad = [n for n, m in zip(self.names, self.monomials) if sum(m) > 2]
            raise ValueError(
                f"canonical analysis needs a model of degree <= 2; terms {bad} are higher"
            )
        k = len(self.factors)
        b0, b, B = 0.0, np.zeros(k), np.zeros((k, k))
        for m, c in zip(self.monomials, self.coefs):
            idx = [i for i, p in enumerate(m) for _ in range(p)]
            if not idx:
                b0 += c
            elif len(idx) == 1:
                b[idx[0]] += c
            elif idx[0] == idx[1]:
                B[idx[0], idx[0]] += c
            else:
                B[idx[0], idx[1]] += c / 2
                B[idx[1], idx[0]] += c / 2
        return b0, b, B

    def canonical(self, box: Sequence[tuple[float, float]] | None = None,
                  rtol: float = 1e-8) -> CanonicalAnalysis:
        """Stationary point and eigen-analysis of the second-order part.

        Parameters
        ----------
        box : sequence of (low, high), optional
            Coded box for ``inside_design``; default ``[-1, 1]`` per factor.
        rtol : float
            Eigenvalues below ``rtol * max|eigenvalue|`` count as zero (ridge).
        """
        b0, b, B = self.second_order_parts()
        if not np.any(B):
            raise ValueError("canonical analysis needs second-order terms; the model has none")
        evals, evecs = np.linalg.eigh(B)
        scale = np.max(np.abs(evals))
        if np.any(np.abs(evals) <= rtol * scale):
            nature = "ridge"
        elif np.all(evals > 0):
            nature = "minimum"
        elif np.all(evals < 0):
            nature = "maximum"
        else:
            nature = "saddle"
        if nature == "ridge":
            xs = np.full(len(self.factors), np.nan)
            value = float("nan")
        else:
            xs = -0.5 * np.linalg.solve(B, b)
            value = float(b0 + xs @ b + xs @ B @ xs)
        box = [(-1.0, 1.0)] * len(self.factors) if box is None else list(box)
        inside = bool(np.all(np.isfinite(xs)) and all(lo - 1e-12 <= v <= hi + 1e-12
                                                       for v, (lo, hi) in zip(xs, box)))
        xs_act = (pd.Series(self.levels.coded_to_actual(xs, self.factors), index=self.factors)
                  if self.levels is not None else None)
        return CanonicalAnalysis(
            stationary_point=pd.Series(xs, index=self.factors), stationary_point_actual=xs_act,
            value=value, eigenvalues=evals,
            eigenvectors=pd.DataFrame(evecs, index=self.factors,
                                      columns=[f"w{i + 1}" for i in range(len(evals))]),
            nature=nature, inside_design=inside, B=B, b=b,
        )

    def _exponents(self) -> tuple[np.ndarray, np.ndarray]:
        """Exponent matrix ``E`` (p, k) and derivative exponents ``D`` (k, p, k)."""
        E = np.array(self.monomials, dtype=float).reshape(len(self.monomials), len(self.factors))
        D = np.repeat(E[None, :, :], E.shape[1], axis=0)
        for i in range(E.shape[1]):
            D[i, :, i] = np.maximum(E[:, i] - 1, 0)
        return E, D

    def value_and_gradient(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Value and gradient with respect to the coded factors at one point."""
        x = np.asarray(x, dtype=float)
        E, D = self._exponents()
        value = float(np.prod(x**E, axis=1) @ self.coefs)
        terms = np.prod(x[None, None, :] ** D, axis=2)  # (k, p)
        grad = (terms * (self.coefs[None, :] * E.T)).sum(axis=1)
        return value, grad

    def gradient_coded(self, x: np.ndarray) -> np.ndarray:
        """Gradient with respect to the coded factors at one point."""
        return self.value_and_gradient(x)[1]

    def optimize(
        self,
        goal: str = "min",
        bounds: Sequence[tuple[float, float]] | None = None,
        n_random: int = 16,
        seed: int | None = 0,
    ) -> Optimum:
        """Bounded minimum (or maximum) of the surface (scipy L-BFGS-B, multi-start).

        Parameters
        ----------
        goal : {'min', 'max'}
        bounds : sequence of (low, high), optional
            Coded bounds; default ``[-1, 1]`` per factor.
        n_random : int
            Random starts in addition to the centre, the corners (for up to 5 factors) and the
            stationary point of a second-order model.
        seed : int, optional
            Seed for the random starts.
        """
        if goal not in ("min", "max"):
            raise ValueError(f"goal must be 'min' or 'max', not '{goal}'")
        k = len(self.factors)
        bounds = [(-1.0, 1.0)] * k if bounds is None else [(float(a), float(b)) for a, b in bounds]
        if len(bounds) != k:
            raise ValueError(f"need {k} bounds, got {len(bounds)}")
        lo = np.array([b[0] for b in bounds])
        hi = np.array([b[1] for b in bounds])
        sign = 1.0 if goal == "min" else -1.0

        E, D = self._exponents()
        cE = self.coefs[None, :] * E.T

        def fg(x: np.ndarray) -> tuple[float, np.ndarray]:
            value = float(np.prod(x**E, axis=1) @ self.coefs)
            grad = (np.prod(x[None, None, :] ** D, axis=2) * cE).sum(axis=1)
            return sign * value, sign * grad

        starts = [0.5 * (lo + hi)]
        if k <= 5:
            starts += [np.array(c) for c in itertools.product(*zip(lo, hi))]
        rng = np.random.default_rng(seed)
        starts += list(lo + (hi - lo) * rng.random((n_random, k)))
        if self.max_degree <= 2:
            try:
                ca = self.canonical()
                if np.all(np.isfinite(ca.stationary_point.to_numpy())):
                    starts.append(np.clip(ca.stationary_point.to_numpy(), lo, hi))
            except ValueError:
                pass
        best = None
        for x0 in starts:
            r = optimize.minimize(fg, x0, jac=True, method="L-BFGS-B", bounds=bounds)
            if best is None or r.fun < best.fun:
                best = r
        x = np.clip(best.x, lo, hi)
        span = np.maximum(hi - lo, 1e-300)
        at_bound = [fn for fn, v, a, b, s in zip(self.factors, x, lo, hi, span)
                    if min(v - a, b - v) <= 1e-7 * s]
        xa = (pd.Series(self.levels.coded_to_actual(x, self.factors), index=self.factors)
              if self.levels is not None else None)
        return Optimum(goal=goal, x_coded=pd.Series(x, index=self.factors), x_actual=xa,
                       value=float(self.predict_coded(x[None, :])[0]), bounds=bounds,
                       at_bound=at_bound, success=bool(best.success))
