"""Monte Carlo tolerance stack-up: tolerance distributions, sampling, yield and variance shares.

Default tolerances (documented in docs/guide.md and the report): every Table 4 error type is normal
with mean 0 and standard deviation = its paper value / 3 (``ERROR_TYPES[key].paper_value``: 10 um
for B..I, 5 um for J, 0.1 deg for K, 0.01 deg for L), applied to its default instance (sun; crank 0;
crank 0 / disc 0; disc 0 / hole 0; all pins for I and J; pin 0 for L), i.e. the paper value is the
3-sigma limit.

A tolerance is written ``KEY=DIST:PARAMS`` (``--tolerance``) or as a CSV row ``error,dist,p1,p2,p3``
(``--tolerances FILE``):

* ``normal:SIGMA[:MEAN]`` -- normal, standard deviation SIGMA, mean MEAN (default 0);
* ``uniform:LOW:HIGH`` -- uniform on [LOW, HIGH];
* ``truncnormal:SIGMA:LOW:HIGH[:MEAN]`` -- normal (SIGMA, MEAN default 0) truncated to [LOW, HIGH];
* ``triangular:LOW:MODE:HIGH``;
* ``fixed:VALUE`` -- a constant;
* ``none`` -- the error is absent (0).

Values are in the error's unit (um or deg, ``ERROR_TYPES[key].unit``). A model effect of rvdyn
(:data:`rvdyn.options.MODEL_OPTIONS`, numeric options only, e.g. the cam-bearing clearance) is written ``model.KEY`` and drawn
in its option's unit; its distribution must stay inside the option's range (normal: mean +- 6 sigma).

Scope (which instances of an error type a tolerance draws, written ``KEY[SCOPE]=...`` or in a ``scope``
column): ``each`` (default) -- every feature of the drawing independently: each pin's radius, pitch
and radial position, each cam (crank x disc), each crank's planet and carrier hole, each disc hole,
each disc's profile phase; ``common`` -- one value for every instance (e.g. all pins oversize by the
same amount); ``default`` -- the error's default instance only (the paper's Table 4 reading).
Errors with a direction (sun and planet eccentricity, pin-circle offset) are positional: the x and y
components of the offset are drawn independently from the distribution (a true-position zone).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from rvcad.errors import ERROR_TYPES, MAX_ABS
from rvdyn.options import MODEL_OPTIONS
from rsm.csvio import read_csv_strict
from rvcad.validation import TableError, read_json_file

DISTRIBUTIONS = ("normal", "uniform", "truncnormal", "triangular", "fixed", "none")
_NPARAMS = {"normal": (1, 2), "uniform": (2, 2), "truncnormal": (3, 4), "triangular": (3, 3), "fixed": (1, 1),
            "none": (0, 0)}
#: Which instances a tolerance draws (see the module docstring).
SCOPES = ("each", "common", "default")
#: Prefix of a model-effect tolerance key (``model.cam_bearing_clearance_um``).
MODEL_PREFIX = "model."
#: Columns of a tolerance CSV file.
CSV_COLUMNS = ("error", "dist", "p1", "p2", "p3", "p4", "scope")


def tolerance_unit(key: str) -> str:
    """Unit of the values of tolerance key ``key`` (error type or ``model.OPTION``)."""
    if key.startswith(MODEL_PREFIX) and key[len(MODEL_PREFIX):] in MODEL_OPTIONS:
        return MODEL_OPTIONS[key[len(MODEL_PREFIX):]].unit
    return ERROR_TYPES[key].unit


@dataclass(frozen=True)
class Tolerance:
    """Distribution of one error type's value (in its unit).

    Attributes
    ----------
    error : str
        ``ERROR_TYPES`` key.
    dist : str
        One of :data:`DISTRIBUTIONS`.
    params : tuple of float
        See the module docstring.
    """

    error: str
    dist: str
    params: tuple[float, ...] = ()
    scope: str = "each"

    def __post_init__(self) -> None:
        where = f"tolerance {self.error}"
        model = self.error.startswith(MODEL_PREFIX)
        if model and (self.error[len(MODEL_PREFIX):] not in MODEL_OPTIONS
                      or MODEL_OPTIONS[self.error[len(MODEL_PREFIX):]].choices):
            raise ValueError(f"{where}: model effect {self.error!r} is unknown or not a number; allowed: "
                             f"{sorted(MODEL_PREFIX + k for k, o in MODEL_OPTIONS.items() if not o.choices)}")
        if not model and self.error not in ERROR_TYPES:
            raise ValueError(f"{where}: error key {self.error!r} is unknown; allowed: {sorted(ERROR_TYPES)} "
                             f"or model.OPTION")
        if self.scope not in SCOPES:
            raise ValueError(f"{where}: scope {self.scope!r} is unknown; allowed: {list(SCOPES)}")
        if self.dist not in DISTRIBUTIONS:
            raise ValueError(f"{where}: distribution {self.dist!r} is unknown; allowed: {list(DISTRIBUTIONS)}")
        lo, hi = _NPARAMS[self.dist]
        if not lo <= len(self.params) <= hi:
            raise ValueError(f"{where}: {self.dist} takes {lo}..{hi} parameters, got {len(self.params)}")
        if not all(math.isfinite(p) for p in self.params):
            raise ValueError(f"{where}: parameters must be finite numbers, got {self.params}")
        p = self.params
        if self.dist == "normal" and p[0] < 0:
            raise ValueError(f"{where}: normal SIGMA {p[0]} must be >= 0")
        if self.dist == "uniform" and not p[0] <= p[1]:
            raise ValueError(f"{where}: uniform needs LOW <= HIGH, got {p[0]} > {p[1]}")
        if self.dist == "triangular" and not p[0] <= p[1] <= p[2]:
            raise ValueError(f"{where}: triangular needs LOW <= MODE <= HIGH, got {p}")
        if self.dist == "truncnormal" and not (p[0] > 0 and p[1] < p[2]):
            raise ValueError(f"{where}: truncnormal needs SIGMA > 0 and LOW < HIGH, got {p}")

    @property
    def unit(self) -> str:
        """Unit of the values (``um``, ``deg`` or the model option's unit)."""
        return tolerance_unit(self.error)

    @property
    def is_model(self) -> bool:
        """Whether this is a model effect (``model.KEY``) rather than a Table 4 error."""
        return self.error.startswith(MODEL_PREFIX)

    def support(self) -> tuple[float, float]:
        """Smallest and largest value a draw can take (normal: mean -+ 6 sigma, beyond which a draw has
        probability 2e-9)."""
        p = self.params
        if self.dist == "normal":
            m = p[1] if len(p) > 1 else 0.0
            return m - 6.0 * p[0], m + 6.0 * p[0]
        if self.dist in ("uniform",):
            return p[0], p[1]
        if self.dist == "truncnormal":
            return p[1], p[2]
        if self.dist == "triangular":
            return p[0], p[2]
        v = p[0] if self.dist == "fixed" else 0.0
        return v, v

    def _tn(self) -> Any:
        p = self.params
        mu = p[3] if len(p) > 3 else 0.0
        return stats.truncnorm((p[1] - mu) / p[0], (p[2] - mu) / p[0], loc=mu, scale=p[0])

    def pdf(self, x: np.ndarray) -> np.ndarray:
        """Probability density at ``x`` (``fixed``/``none``: 1 at their value, else 0)."""
        x = np.asarray(x, float)
        p = self.params
        if self.dist == "normal":
            m = p[1] if len(p) > 1 else 0.0
            return stats.norm.pdf(x, m, p[0]) if p[0] > 0 else (x == m) * 1.0
        if self.dist == "uniform":
            return np.where((x >= p[0]) & (x <= p[1]), 1.0 / (p[1] - p[0]), 0.0) if p[1] > p[0] else (x == p[0]) * 1.0
        if self.dist == "truncnormal":
            return self._tn().pdf(x)
        if self.dist == "triangular":
            return (stats.triang.pdf(x, (p[1] - p[0]) / (p[2] - p[0]), p[0], p[2] - p[0]) if p[2] > p[0]
                    else (x == p[0]) * 1.0)
        return (x == (p[0] if self.dist == "fixed" else 0.0)) * 1.0

    def tightened(self, factor: float) -> "Tolerance":
        """The same distribution with its spread scaled by ``factor`` (0 < factor <= 1) about its centre
        (normal, truncnormal: sigma and the limits about the mean; uniform, triangular: the limits about
        the midpoint / mode); ``fixed`` and ``none`` are returned unchanged."""
        p, f = self.params, float(factor)
        if self.dist == "normal":
            q = (p[0] * f,) + tuple(p[1:])
        elif self.dist == "uniform":
            m = 0.5 * (p[0] + p[1])
            q = (m + f * (p[0] - m), m + f * (p[1] - m))
        elif self.dist == "truncnormal":
            mu = p[3] if len(p) > 3 else 0.0
            q = (p[0] * f, mu + f * (p[1] - mu), mu + f * (p[2] - mu)) + tuple(p[3:])
        elif self.dist == "triangular":
            q = (p[1] + f * (p[0] - p[1]), p[1], p[1] + f * (p[2] - p[1]))
        else:
            return self
        return Tolerance(self.error, self.dist, q, self.scope)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` values (float64, in :attr:`unit`)."""
        p = self.params
        if self.dist == "normal":
            return rng.normal(p[1] if len(p) > 1 else 0.0, p[0], n)
        if self.dist == "uniform":
            return rng.uniform(p[0], p[1], n)
        if self.dist == "truncnormal":  # inverse CDF of a uniform draw: deterministic for a given rng
            tn = self._tn()
            return tn.ppf(rng.uniform(tn.cdf(p[1]), tn.cdf(p[2]), n))
        if self.dist == "triangular":
            if p[0] == p[2]:
                return np.full(n, p[0])
            return rng.triangular(p[0], p[1], p[2], n)
        if self.dist == "fixed":
            return np.full(n, p[0])
        return np.zeros(n)

    @property
    def std(self) -> float:
        """Standard deviation of the distribution (unit of the error)."""
        p = self.params
        if self.dist == "normal":
            return p[0]
        if self.dist == "uniform":
            return (p[1] - p[0]) / math.sqrt(12)
        if self.dist == "truncnormal":
            return float(self._tn().std())
        if self.dist == "triangular":
            a, c, b = p
            return math.sqrt((a * a + b * b + c * c - a * b - a * c - b * c) / 18)
        return 0.0

    def describe(self) -> str:
        """``normal(sigma=3.333 um), each``-style text (distribution and scope)."""
        p, u = self.params, self.unit
        if self.dist == "normal":
            m = f", mean={p[1]:g} {u}" if len(p) > 1 and p[1] else ""
            d = f"normal(sigma={p[0]:.4g} {u}{m})"
        elif self.dist == "uniform":
            d = f"uniform({p[0]:g}..{p[1]:g} {u})"
        elif self.dist == "truncnormal":
            m = f", mean={p[3]:g}" if len(p) > 3 and p[3] else ""
            d = f"truncnormal(sigma={p[0]:.4g}{m}, {p[1]:g}..{p[2]:g} {u})"
        elif self.dist == "triangular":
            d = f"triangular({p[0]:g}, {p[1]:g}, {p[2]:g} {u})"
        elif self.dist == "fixed":
            d = f"fixed({p[0]:g} {u})"
        else:
            return "none"
        return f"{d}, {self.scope}"


def default_tolerances() -> dict[str, Tolerance]:
    """Every Table 4 error type normal(0, paper value / 3) on every feature (scope ``each``)."""
    return {k: Tolerance(k, "normal", (e.paper_value / 3.0,)) for k, e in ERROR_TYPES.items()}


def parse_tolerance(text: str) -> Tolerance:
    """Parse ``KEY[SCOPE]=DIST:P1:P2...`` (e.g. ``pin_pitch=normal:0.005``); TableError names the option."""
    if "=" not in text:
        raise TableError(f"--tolerance {text!r} must look like KEY=DIST:PARAMS, e.g. pin_radius=normal:1.5",
                         field="--tolerance", value=text, allowed="KEY=DIST:PARAMS")
    key, spec = text.split("=", 1)
    return _parse_spec(key.strip(), spec.strip(), f"--tolerance {text!r}")


def _split_scope(key: str) -> tuple[str, str]:
    """``pin_radius[common]`` -> (``pin_radius``, ``common``); no brackets -> scope ``each``."""
    key = key.strip()
    if key.endswith("]") and "[" in key:
        k, sc = key[:-1].split("[", 1)
        return k.strip(), sc.strip().lower()
    return key, "each"


def _parse_spec(key: str, spec: str, where: str, scope: str | None = None) -> Tolerance:
    key, sc = _split_scope(key)
    parts = [s for s in spec.split(":")]
    dist = parts[0].strip().lower()
    try:
        params = tuple(float(s) for s in parts[1:] if s.strip() != "")
    except ValueError:
        raise TableError(f"{where}: parameters must be numbers, got {spec!r}", field=where, value=spec,
                         allowed="DIST:NUMBER[:NUMBER...]") from None
    try:
        tol = Tolerance(key, dist, params, scope or sc)
    except ValueError as exc:
        raise TableError(f"{where}: {exc}", field=where, value=spec) from None
    if tol.is_model:  # a model effect's draws must stay inside its option's range
        o = MODEL_OPTIONS[tol.error[len(MODEL_PREFIX):]]
        lo, hi = tol.support()
        if lo < o.low or hi > o.high:
            raise TableError(f"{where}: {tol.describe()} reaches {lo:g}..{hi:g} {tol.unit}; allowed: draws within "
                             f"[{o.low:g}, {o.high:g}] {o.unit} (for normal: mean -+ 6 sigma; use uniform, "
                             "truncnormal or triangular)", field=where, value=spec,
                             allowed=f"[{o.low:g}, {o.high:g}] {o.unit}")
        return tol
    # physical range: every drawn value must stay a valid case value (|value| <= MAX_ABS of the unit);
    # a normal distribution within 6 sigma (a draw beyond it has probability 2e-9)
    lim = MAX_ABS[tol.unit]
    p = tol.params
    reach = abs(p[1] if len(p) > 1 else 0.0) + 6.0 * p[0] if tol.dist == "normal" else max(
        (abs(x) for x in p), default=0.0)
    if reach > lim:
        raise TableError(f"{where}: {tol.describe()} reaches {reach:g} {tol.unit}; allowed: draws within "
                         f"|value| <= {lim:g} {tol.unit} (for normal: |mean| + 6 sigma)", field=where, value=spec,
                         allowed=f"|value| <= {lim:g} {tol.unit}")
    return tol


def load_tolerances(path: str | Path) -> dict[str, Tolerance]:
    """Read a tolerance file: CSV ``error,dist,p1[,p2[,p3]]`` or JSON ``{key: "dist:p1:p2"}``.

    Raises TableError naming the file, row and field (a key given twice, an unknown column, a bad value).
    """
    p = Path(path)
    if not p.is_file():
        raise TableError(f"--tolerances file {str(p)!r} does not exist", field="--tolerances", value=str(p),
                         allowed="an existing CSV or JSON file")
    out: dict[str, Tolerance] = {}
    if p.suffix.lower() == ".json":
        d = read_json_file(p, "--tolerances file", TableError)
        if not isinstance(d, dict):
            raise TableError(f"--tolerances file {str(p)!r} must hold an object {{error: 'dist:params'}}",
                             field="--tolerances", value=str(p), allowed="a JSON object")
        for k, v in d.items():
            if not isinstance(v, str):
                raise TableError(f"--tolerances {p.name} key {k!r}: {v!r} is not a string; allowed: 'dist:params'",
                                 field=k, value=v, allowed="'dist:params'")
            t = _parse_spec(k, v, f"--tolerances {p.name} key {k!r}")
            out[t.error] = t
        return out
    df = read_csv_strict(p, "--tolerances file", lambda m: TableError(
        m, field="--tolerances", value=str(p), allowed="CSV error,dist,p1,p2,p3"), dtype=str).fillna("")
    for c in ("error", "dist"):
        if c not in df.columns:
            raise TableError(f"--tolerances file {str(p)!r} needs columns error,dist,p1..p3; '{c}' is missing",
                             field="--tolerances", value=list(df.columns), allowed="error,dist,p1,p2,p3")
    for c in df.columns:
        if c not in CSV_COLUMNS:
            raise TableError(f"--tolerances file {str(p)!r}: column {c!r} is unknown; allowed: {','.join(CSV_COLUMNS)}",
                             field=c, value=c, allowed=",".join(CSV_COLUMNS))
    for i, r in df.iterrows():
        spec = ":".join([r["dist"]] + [r[c] for c in ("p1", "p2", "p3", "p4") if c in df.columns and r[c] != ""])
        sc = r["scope"].strip().lower() if "scope" in df.columns and r["scope"].strip() else None
        key = _split_scope(r["error"])[0]
        if key in out:
            raise TableError(f"--tolerances {p.name} row {i + 1}: error {key!r} is given twice; allowed: each "
                             "error once", field=key, value=key, allowed="each error once")
        out[key] = _parse_spec(r["error"], spec, f"--tolerances {p.name} row {i + 1}", sc)
    return out


def tolerance_table(tols: Mapping[str, Tolerance]) -> pd.DataFrame:
    """One row per error type (and model effect): ``letter, error, unit, distribution, scope, std, paper_value``."""
    rows = []
    for k, et in ERROR_TYPES.items():
        t = tols.get(k, Tolerance(k, "none"))
        rows.append({"letter": et.letter, "error": k, "unit": et.unit, "distribution": t.describe(),
                     "scope": t.scope, "std": t.std, "paper_value": et.paper_value})
    for k, t in tols.items():
        if t.is_model:
            rows.append({"letter": "model", "error": k, "unit": t.unit, "distribution": t.describe(),
                         "scope": "common", "std": t.std, "paper_value": float("nan")})
    return pd.DataFrame(rows)


def sample_errors(tols: Mapping[str, Tolerance], n: int, rng: np.random.Generator,
                  keys: list[str] | None = None) -> pd.DataFrame:
    """``n`` independent draws of every error type (columns in :data:`ERROR_TYPES` order)."""
    keys = list(ERROR_TYPES) if keys is None else keys
    return pd.DataFrame({k: (tols[k].sample(rng, n) if k in tols else np.zeros(n)) for k in keys})


def sobol_indices(f: Callable[[pd.DataFrame], np.ndarray], tols: Mapping[str, Tolerance], keys: list[str],
                  n: int, rng: np.random.Generator) -> pd.DataFrame:
    """First-order and total Sobol indices of ``f`` over independent inputs ``keys``.

    Saltelli (2010) estimator for the first order, Jansen (1999) for the total effect, from two
    independent sample matrices A, B of ``n`` rows and the ``k`` matrices A with column i from B
    (``n (k + 2)`` evaluations of ``f``).

    Returns
    -------
    DataFrame
        ``error, S1, ST, variance`` (variance of ``f``, response units squared).
    """
    A = sample_errors(tols, n, rng, keys)
    B = sample_errors(tols, n, rng, keys)
    fA, fB = np.asarray(f(A), float), np.asarray(f(B), float)
    var = float(np.var(np.r_[fA, fB]))
    rows = []
    for k in keys:
        AB = A.copy()
        AB[k] = B[k].to_numpy()
        fAB = np.asarray(f(AB), float)
        if var > 0:
            s1 = float(np.mean(fB * (fAB - fA)) / var)
            st = float(0.5 * np.mean((fA - fAB) ** 2) / var)
        else:
            s1 = st = float("nan")
        rows.append({"error": k, "S1": s1, "ST": st, "variance": var})
    return pd.DataFrame(rows)


def yield_estimate(values: np.ndarray, spec: float) -> dict[str, float]:
    """Fraction of ``values <= spec`` with its 95 % Wilson interval.

    Returns
    -------
    dict
        ``yield, lower, upper, n``.
    """
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    n = v.size
    if n == 0:
        return {"yield": float("nan"), "lower": float("nan"), "upper": float("nan"), "n": 0}
    p = float(np.mean(v <= spec))
    z = float(stats.norm.ppf(0.975))
    den = 1 + z * z / n
    c = (p + z * z / (2 * n)) / den
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return {"yield": p, "lower": max(0.0, c - h), "upper": min(1.0, c + h), "n": int(n)}


def percentiles(values: np.ndarray, qs: tuple[float, ...] = (1, 5, 50, 95, 99)) -> dict[str, float]:
    """``mean, std`` and the given percentiles of the finite values."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    out = {"mean": float(v.mean()) if v.size else float("nan"),
           "std": float(v.std(ddof=1)) if v.size > 1 else float("nan")}
    for q in qs:
        out[f"p{q:g}"] = float(np.percentile(v, q)) if v.size else float("nan")
    return out
