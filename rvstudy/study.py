"""The default study of ``rv-stackup``: the paper's sections 4.2-5 end to end, plus a tolerance stack-up.

Stages (each one a list of cases solved through the cached, parallel :class:`rvdyn.runner.Runner`):

1. ``screen`` -- every Table 4 error alone at +-its paper value and case A (Fig. 9), and the four RSM
   factors swept over their Table 5 range (Fig. 11) (:mod:`rvstudy.screen`).
2. ``doe`` -- the response-surface design (Box-Behnken by default, from :func:`rsm.make_design`,
   in the paper's Table 6 run order when the point sets agree) on the factors of the levels table;
   responses ``mean_abs_arcmin`` (mean of |TE| over the revolution: our reading of the paper's
   "mean value of transmission error") and ``pp_arcmin`` (peak to peak); full quadratic fits with
   ANOVA (Table 7, Eq. 8), reduced models (backward with refits, and the paper's no-refit
   shortcut, Eq. 9), surfaces and contours (Fig. 12).
3. ``validation`` -- random cases inside the design box (seeded), predicted vs simulated (Fig. 13):
   RMSE and prediction-interval coverage.
4. ``mc`` -- Monte Carlo tolerance stack-up: every error type drawn from its tolerance
   distribution; many draws through the fitted surfaces (the RSM factors), a sample through the
   full solver with all eleven errors, TE percentiles, yield against the pp spec, variance shares
   (Sobol indices on the surface; one-at-a-time shares of all eleven errors from the screen).

:func:`run_study` returns a :class:`StudyResult`; :func:`rvstudy.report.write_report` writes it.
"""
from __future__ import annotations

import math
import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import rsm
from rsm.terms import preset_terms
from rvcad.errors import ERROR_TYPES, MAX_ABS, Case
from rvcad.params import Design
from rvcad.validation import TableError
from rvdyn.contacts import ContactLaw
from rvstudy.screen import (
    ARCSEC_PER_ARCMIN,
    RSM_FACTORS,
    ScreenResult,
    make_case,
    run_screen,
)
from rvdyn.te import SOLVERS
import rvpaper as paper
from rvdyn.cache import CaseCache
from rvdyn.runner import Executor, make_executor
from rvdyn.runner import Runner as CachedRunner
from rvstudy.paper_readings import READINGS_STEPS, run_readings
from rvstudy.montecarlo import (
    Tolerance,
    default_tolerances,
    oat_variance_shares,
    percentiles,
    sample_errors,
    sobol_indices,
    yield_estimate,
)

STAGES = ("screen", "doe", "validation", "mc", "readings")
DESIGNS = ("bbd", "ccd")
#: Responses of the design, in arcmin: the paper's statistic first.
RESPONSES = ("mean_abs_arcmin", "pp_arcmin")
RESPONSE_LABEL = {"mean_abs_arcmin": "mean |TE| [arcmin]", "pp_arcmin": "TE peak-to-peak [arcmin]"}

#: Default steps per output revolution (see README: 360 resolves every single-pin event; 240 and
#: fewer alias the peak-to-peak TE of several Table 4 errors by up to a factor 3).
DEFAULT_STEPS = 360
DEFAULT_SEED = 20240


@dataclass
class StudyConfig:
    """Options of the study (CLI flags in brackets); the defaults reproduce the paper's study.

    Attributes
    ----------
    out : Path
        Output folder (``--out``).
    solver : str
        Contact provider, ``fcl`` or ``analytic`` (``--solver``).
    steps : int
        Steps per output revolution (``--steps``).
    load_Nm : float
        Output load torque, N m (``--load-Nm``).
    workers : int
        Local worker processes (``--workers``); 1 solves in this process.
    scheduler : str or None
        Dask scheduler address (``--scheduler``); overrides ``workers``.
    scheduler_timeout_s : float
        Seconds to wait for the scheduler (``--scheduler-timeout``).
    design : str
        ``bbd`` or ``ccd`` (``--design``).
    ccd_alpha : str
        CCD axial distance: ``rotatable``, ``face`` or a number (``--ccd-alpha``).
    center : int or None
        Centre runs (``--center``; default 3).
    levels : str or None
        Levels CSV ``factor,low,center,high[,unit][,error]`` (``--levels``); default paper Table 5.
    factors : list of str or None
        Factors of the levels table to use (``--factors``); default all.
    sweep_points : int
        Points per factor sweep (``--sweep-points``).
    n_validation : int
        Random validation cases (``--validation-cases``).
    seed : int
        Seed of the validation and Monte Carlo draws (``--seed``).
    mc_samples : int
        Monte Carlo draws through the fitted surfaces (``--mc-samples``).
    mc_check : int
        Monte Carlo draws through the full solver (``--mc-check``).
    tolerances : dict
        ``{error key: Tolerance}`` (``--tolerance``, ``--tolerances``).
    spec_arcmin : float
        TE peak-to-peak specification for the yield, arcmin (``--spec-arcmin``).
    cache_dir : Path or None
        Case cache (``--cache``; default ``OUT/cache``).
    use_cache : bool
        ``--no-cache`` turns it off.
    stages : tuple of str
        Stages to run (``--stages``).
    alpha : float
        Significance level (term selection and intervals).
    K, n : float
        Contact law ``F = K delta**n`` (N/mm^n).
    progress : bool
        tqdm bars.
    figures : bool
        Draw the PNG figures (``--no-figures``: tables and report text only).
    """

    out: Path = Path("rv-stackup-out")
    solver: str = "fcl"
    steps: int = DEFAULT_STEPS
    load_Nm: float = 20.0
    workers: int = 2
    scheduler: str | None = None
    scheduler_timeout_s: float = 20.0
    design: str = "bbd"
    ccd_alpha: str = "rotatable"
    center: int | None = None
    levels: str | None = None
    factors: list[str] | None = None
    sweep_points: int = 7
    n_validation: int = 15
    seed: int = DEFAULT_SEED
    mc_samples: int = 20000
    mc_check: int = 100
    tolerances: dict[str, Tolerance] = field(default_factory=default_tolerances)
    spec_arcmin: float = 1.0
    cache_dir: Path | None = None
    use_cache: bool = True
    stages: tuple[str, ...] = STAGES
    alpha: float = 0.05
    K: float = ContactLaw.K
    n: float = ContactLaw.n
    progress: bool = True
    figures: bool = True

    def validate(self) -> None:
        """Raise ValueError naming the option and its allowed range."""
        def integer(v: Any, opt: str, lo: int) -> None:
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
                raise ValueError(f"{opt} {v!r} must be an integer >= {lo}")

        if self.solver not in SOLVERS:
            raise ValueError(f"--solver {self.solver!r} is unknown; allowed: {list(SOLVERS)}")
        integer(self.steps, "--steps", 2)
        integer(self.workers, "--workers", 1)
        integer(self.sweep_points, "--sweep-points", 2)
        integer(self.n_validation, "--validation-cases", 0)
        integer(self.mc_samples, "--mc-samples", 100)
        integer(self.mc_check, "--mc-check", 0)
        integer(self.seed, "--seed", 0)
        if self.center is not None:
            integer(self.center, "--center", 0)
        if not (isinstance(self.load_Nm, (int, float)) and math.isfinite(self.load_Nm) and self.load_Nm >= 0):
            raise ValueError(f"--load-Nm {self.load_Nm!r} must be a finite number >= 0 (N m)")
        if not (math.isfinite(self.spec_arcmin) and self.spec_arcmin > 0):
            raise ValueError(f"--spec-arcmin {self.spec_arcmin!r} must be a finite number > 0 (arcmin)")
        if self.design not in DESIGNS:
            raise ValueError(f"--design {self.design!r} is unknown; allowed: {list(DESIGNS)}")
        bad = [s for s in self.stages if s not in STAGES]
        if bad or not self.stages:
            raise ValueError(f"--stages {','.join(self.stages)!r}: allowed stages are {','.join(STAGES)}")
        if not (math.isfinite(self.scheduler_timeout_s) and self.scheduler_timeout_s > 0):
            raise ValueError(f"--scheduler-timeout {self.scheduler_timeout_s!r} must be a number > 0 (s)")
        if not 0 < self.alpha < 1:
            raise ValueError(f"--alpha {self.alpha!r} must lie in (0, 1)")
        ContactLaw(self.K, self.n)  # raises naming K / n
        if self.solver == "fcl":
            import importlib.util

            if importlib.util.find_spec("rvdyn.fcl_contacts") is None:
                raise ValueError("--solver fcl: the fcl contact provider (rvdyn.fcl_contacts) is not installed "
                                 "in this version; use --solver analytic")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings (tolerances as text)."""
        d = {k: (str(v) if isinstance(v, Path) else v) for k, v in self.__dict__.items() if k != "tolerances"}
        d["stages"] = list(self.stages)
        d["tolerances"] = {k: t.describe() for k, t in self.tolerances.items()}
        return d


#: Steps per output revolution that sample the crank order 121 (one period per input turn) twice.
MIN_RESOLVING_STEPS = 2 * 121

# ---------------------------------------------------------------------------------------------- factors
#: Pin patterns a factor of a pin-wise error (pin_pitch, pin_circle_diameter, pin_radius) can take,
#: written ``key[pattern]`` in the levels table's ``error`` column: ``all`` = every pin gets the
#: factor's value (for pin_pitch a rotation of the whole pin ring), ``alternate`` = the even pins
#: 0, 2, ..., 38 get it and the odd pins none. Without a pattern the value goes to the error's
#: default instance (pin_pitch: pin 0 only; the radius errors: all pins).
PIN_PATTERNS = ("all", "alternate")


def pattern_value(key: str, pattern: str | None, value: float, z_pins: int | None = None) -> float | list[float]:
    """The case-JSON value of a factor setting: the number itself, or the list of ``z_pins`` pin values
    (default: the default design's 40) of a pin pattern (see :data:`PIN_PATTERNS`), in the error's unit."""
    if pattern is None:
        return value
    z_pins = Design().z_pins if z_pins is None else int(z_pins)
    if pattern == "all":
        return [value] * z_pins
    if pattern == "alternate":
        return [value if i % 2 == 0 else 0.0 for i in range(z_pins)]
    raise ValueError(f"pattern {pattern!r} of {key} is unknown; allowed: {list(PIN_PATTERNS)}")


@dataclass
class FactorSet:
    """RSM factors: names, the error type of each (and its pin pattern), and the levels table
    (actual units = error units)."""

    names: list[str]
    errors: dict[str, str]
    levels: rsm.Levels
    table: pd.DataFrame
    is_paper: bool
    patterns: dict[str, str | None] = field(default_factory=dict)

    @property
    def error_keys(self) -> list[str]:
        return [self.errors[f] for f in self.names]

    def spec(self, f: str) -> str:
        """``key`` or ``key[pattern]`` of factor ``f``."""
        p = self.patterns.get(f)
        return self.errors[f] + (f"[{p}]" if p else "")

    def case_errors(self, values: dict[str, float]) -> dict[str, float | list[float]]:
        """Case-JSON errors of error values keyed by error type: a factor's pattern is applied to its
        error type's value; other error types keep their default instance."""
        pat = {self.errors[f]: self.patterns.get(f) for f in self.names}
        return {k: pattern_value(k, pat.get(k), float(v)) for k, v in values.items()}


def load_factors(levels_path: str | None, factors: list[str] | None) -> FactorSet:
    """Levels table (paper Table 5 by default) and the error type of each factor.

    The error type comes from an ``error`` column, else from the paper's map (EA = pin_pitch,
    EB = pin_circle_diameter, EC = pin_radius, ED = disc_hole_eccentricity), else from the factor
    name itself when it is a Table 4 error key. A ``unit`` column must match the error's unit.
    """
    if levels_path is None:
        df = paper.table5_levels()
    else:
        p = Path(levels_path)
        if not p.is_file():
            raise TableError(f"--levels file {str(p)!r} does not exist")
        try:
            df = pd.read_csv(p)
        except Exception as exc:  # noqa: BLE001 - any parse problem is a bad option (messages on one line)
            exc = " ".join(str(exc).split())
            raise TableError(f"--levels file {str(p)!r} cannot be read as CSV: {exc}") from None
    df.columns = [str(c).strip() for c in df.columns]
    if "factor" not in df.columns:
        raise TableError(f"--levels file needs a 'factor' column; columns are {list(df.columns)}")
    try:
        levels = rsm.Levels.from_frame(df)
    except ValueError as exc:
        raise TableError(f"--levels: {exc}") from None
    names = levels.names if not factors else list(factors)
    for f in names:
        if f not in levels:
            raise TableError(f"--factors {f!r} is not in the levels table; it lists {levels.names}")
    if len(set(names)) != len(names):
        raise TableError(f"--factors {names} lists a factor twice")
    if not 3 <= len(names) <= 7:
        raise TableError(f"--factors: the designs need 3 to 7 factors, got {len(names)} ({names})")
    errors: dict[str, str] = {}
    patterns: dict[str, str | None] = {}
    for f in names:
        row = df[df["factor"].astype(str).str.strip() == f].iloc[0]
        key = str(row["error"]).strip() if "error" in df.columns and pd.notna(row.get("error")) else (
            RSM_FACTORS.get(f, f))
        m = re.fullmatch(r"([A-Za-z_]+)\s*\[\s*([A-Za-z_]+)\s*\]", key)
        pattern = None
        if m:
            key, pattern = m.group(1), m.group(2)
            if pattern not in PIN_PATTERNS:
                raise TableError(f"--levels: factor {f!r} has pin pattern {pattern!r}; allowed: {list(PIN_PATTERNS)}")
            if key in ERROR_TYPES and not ERROR_TYPES[key].pinwise:
                raise TableError(f"--levels: factor {f!r}: a pin pattern needs a pin-wise error "
                                 f"({sorted(k for k, e in ERROR_TYPES.items() if e.pinwise)}), not {key!r}")
        patterns[f] = pattern
        if key not in ERROR_TYPES:
            raise TableError(f"--levels: factor {f!r} maps to no Table 4 error (error {key!r}); add an 'error' "
                             f"column with one of {sorted(ERROR_TYPES)}")
        unit = str(row["unit"]).strip() if "unit" in df.columns and pd.notna(row.get("unit")) else ""
        if unit and unit != ERROR_TYPES[key].unit:
            raise TableError(f"--levels: factor {f!r} ({key}) has unit {unit!r}; the error's unit is "
                             f"{ERROR_TYPES[key].unit!r}")
        lim = MAX_ABS[ERROR_TYPES[key].unit]
        for lev in ("low", "center", "high"):
            x = getattr(levels[f], lev)
            if not (math.isfinite(x) and abs(x) <= lim):
                raise TableError(f"--levels: factor {f!r} ({key}) {lev} {x!r} {ERROR_TYPES[key].unit} is out of range; allowed: a finite "
                                 f"value with |value| <= {lim:g} {ERROR_TYPES[key].unit}", field=f"{f}.{lev}", value=x)
        errors[f] = key
    if len(set(errors.values())) != len(errors):
        raise TableError(f"--levels: two factors map to the same error type ({errors})")
    levels = levels.subset(names)
    ptab = paper.table5_levels().set_index("factor")
    is_paper = names == list(ptab.index) and all(
        errors[f] == ptab.loc[f, "error"] and patterns[f] is None and levels[f].low == ptab.loc[f, "low"]
        and levels[f].center == ptab.loc[f, "center"] and levels[f].high == ptab.loc[f, "high"] for f in names)
    table = levels.to_frame()
    table["error"] = [errors[f] for f in table["factor"]]
    table["pattern"] = [patterns[f] or "default instance" for f in table["factor"]]
    return FactorSet(names, errors, levels, table, is_paper, patterns)


# ---------------------------------------------------------------------------------------------- results
@dataclass
class FitBundle:
    """Fits of one response: full quadratic, reductions and validation."""

    response: str
    results: Any = None                    # rsm.RSMResults
    comparison: Any = None                 # rsm.ReductionComparison
    validation: dict[str, Any] = field(default_factory=dict)   # model -> ValidationResult
    error: str = ""
    notes: list[str] = field(default_factory=list)


@dataclass
class StudyResult:
    """Everything the report needs (tables as DataFrames, fits as rsm results)."""

    config: StudyConfig
    factors: FactorSet
    executor: str = ""
    screen: ScreenResult | None = None
    design: pd.DataFrame | None = None
    design_kind: str = ""
    paper_order: bool = False
    fits: dict[str, FitBundle] = field(default_factory=dict)
    validation: pd.DataFrame | None = None
    mc: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    counters: dict[str, Any] = field(default_factory=dict)
    cache_counters: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    readings: Any = None                   # rvstudy.paper_readings.ReadingsResult


def _responses(results: list[dict[str, Any]]) -> pd.DataFrame:
    st = pd.DataFrame([r["stats"] for r in results])
    return pd.DataFrame({
        "mean_abs_arcmin": st["mean_abs"].astype(float) / ARCSEC_PER_ARCMIN,
        "pp_arcmin": st["pp"].astype(float) / ARCSEC_PER_ARCMIN,
        "mean_arcmin": st["mean"].astype(float) / ARCSEC_PER_ARCMIN,
        "rms_arcmin": st["rms"].astype(float) / ARCSEC_PER_ARCMIN,
        "seconds": st["seconds"].astype(float),
        "status": [r.get("status", "ok") for r in results],
        "error_message": [r.get("error", "") for r in results],
        "case_key": [r["key"] for r in results],
        "cached": [bool(r.get("cached")) for r in results],
    })


def _cases_for(fs: FactorSet, actual: np.ndarray, prefix: str, cfg: StudyConfig) -> list[Case]:
    out = []
    for i, row in enumerate(np.atleast_2d(actual)):
        errs = fs.case_errors({fs.errors[f]: float(v) for f, v in zip(fs.names, row)})
        try:
            out.append(make_case(errs, f"{prefix}-{i + 1}", cfg.load_Nm))
        except ValueError as exc:
            raise ValueError(f"{prefix} point {i + 1} ({errs}) is not a valid case: {exc}; "
                             "narrow --levels or --ccd-alpha") from None
    return out


def _design(cfg: StudyConfig, fs: FactorSet) -> tuple[pd.DataFrame, bool]:
    """Coded design table (``run, std_order, point_type, <factors>``); paper Table 6 order if it matches."""
    kw: dict[str, Any] = {"factors": fs.names, "levels": fs.levels}
    if cfg.design == "ccd":
        a = cfg.ccd_alpha
        try:
            kw["alpha"] = float(a)
        except ValueError:
            kw["alpha"] = a
    try:
        d = rsm.make_design(cfg.design, len(fs.names), cfg.center, **kw)
    except ValueError as exc:
        raise ValueError(f"--design {cfg.design}: {exc}") from None
    coded = d.coded.copy()
    if cfg.design == "bbd" and fs.is_paper:
        t6 = paper.table6_runs()
        key = lambda df: sorted(map(tuple, df[fs.names].to_numpy(float).tolist()))  # noqa: E731
        if key(t6) == key(coded):
            # same point set: adopt the paper's run numbering so that row i sits beside paper row i
            rows, used = [], set()
            for r in t6.itertuples():
                pt = tuple(float(getattr(r, f)) for f in fs.names)
                for j, cr in coded.iterrows():
                    if j not in used and tuple(cr[fs.names].astype(float)) == pt:
                        used.add(j)
                        rows.append(cr)
                        break
            coded = pd.DataFrame(rows).reset_index(drop=True)
            coded["run"] = np.arange(1, len(coded) + 1)
            coded["paper_te_arcmin"] = t6["te_arcmin"].to_numpy()
            return coded, True
    return coded, False


def _fit(data: pd.DataFrame, fs: FactorSet, response: str, alpha: float) -> FitBundle:
    """Full quadratic fit of the solved runs and its reductions.

    When failed runs leave a term inestimable (e.g. every run that carries ``EA:EC`` failed), that
    term is dropped, the rest is fitted, and a note says so.
    """
    b = FitBundle(response)
    ok = data[data["status"] == "ok"]
    terms = preset_terms("quadratic", len(fs.names))
    names = [rsm.term_name(m, fs.names) for m in terms if sum(m) > 0]
    dropped: list[str] = []
    try:
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            while True:
                try:
                    model = rsm.ResponseSurfaceModel(ok, fs.names, response, names, levels=fs.levels, units="coded")
                    break
                except rsm.NotEstimableError as exc:
                    bad = [t for t in exc.terms if t in names]
                    if not bad or len(bad) >= len(names):
                        raise
                    names = [t for t in names if t not in bad]
                    dropped.extend(bad)
            b.results = model.fit(alpha=alpha)
            b.comparison = rsm.compare_reductions(b.results, alpha=alpha, alpha_out=alpha)
        b.notes = list(dict.fromkeys([str(x.message) for x in w] + list(b.results.notes)))
        if dropped:
            b.notes.insert(0, f"{len(ok)} of {len(data)} runs solved; terms not estimable from them and left out "
                              f"of the model: {', '.join(dropped)}")
    except ValueError as exc:
        b.error = f"{response}: {exc}"
    return b


def run_study(cfg: StudyConfig, executor: Executor | None = None, solve_fn: Any = None) -> StudyResult:
    """Run the study and return its results (no files but the cache are written here).

    Parameters
    ----------
    cfg : StudyConfig
    executor : Executor or None
        Default: from ``cfg.workers`` / ``cfg.scheduler``; closed at the end only if created here.
    solve_fn : callable or None
        Worker function override (tests).
    """
    cfg.validate()
    fs = load_factors(cfg.levels, cfg.factors)
    t_start = time.perf_counter()
    own = executor is None
    ex = make_executor(cfg.workers, cfg.scheduler, cfg.scheduler_timeout_s) if own else executor
    cache = CaseCache((cfg.cache_dir or Path(cfg.out) / "cache") if cfg.use_cache else None)
    kw = {} if solve_fn is None else {"solve_fn": solve_fn}
    runner = CachedRunner(ex, cache, cfg.solver, cfg.steps, ContactLaw(cfg.K, cfg.n), progress=cfg.progress, **kw)
    res = StudyResult(config=cfg, factors=fs, executor=getattr(ex, "describe", lambda: ex.name)())
    if cfg.steps < MIN_RESOLVING_STEPS:
        res.notes.append(f"--steps {cfg.steps} is below {MIN_RESOLVING_STEPS}: the TE has content at the crank "
                         "order 121 (one period per input turn), which needs two steps a period, so peak-to-peak "
                         "values are undersampled (the mean is less affected)")
    try:
        if "screen" in cfg.stages or "mc" in cfg.stages:
            t0 = time.perf_counter()
            half = {f: fs.levels[f].half_range for f in fs.names if f in RSM_FACTORS and fs.errors[f] == RSM_FACTORS[f]
                    and fs.patterns.get(f) is None and fs.levels[f].center == 0}
            res.screen = run_screen(cfg.solver, cfg.steps, cfg.sweep_points, cfg.load_Nm, runner=runner,
                                    both_signs=True, half_range=half or None, progress=cfg.progress,
                                    sweeps="screen" in cfg.stages)
            res.timings["screen"] = time.perf_counter() - t0
        if {"doe", "validation", "mc"} & set(cfg.stages):
            t0 = time.perf_counter()
            coded, res.paper_order = _design(cfg, fs)
            actual = fs.levels.coded_to_actual(coded[fs.names].to_numpy(float), fs.names)
            cases = _cases_for(fs, actual, "doe", cfg)
            out = runner(cases, f"design ({cfg.design}, {len(cases)} runs)")
            table = coded.copy()
            for j, f in enumerate(fs.names):
                table[f"{f}_actual"] = [float(f"{v:.12g}") for v in actual[:, j]]
            res.design = pd.concat([table.reset_index(drop=True), _responses(out)], axis=1)
            res.design_kind = cfg.design
            failed = res.design[res.design["status"] != "ok"]
            for r in failed.itertuples():
                res.notes.append(f"design run {r.run} failed and is left out of the fit: {r.error_message}")
            for resp in RESPONSES:
                res.fits[resp] = _fit(res.design, fs, resp, cfg.alpha)
            res.timings["doe"] = time.perf_counter() - t0
        if "validation" in cfg.stages and cfg.n_validation > 0:
            t0 = time.perf_counter()
            res.validation = _validation(cfg, fs, runner, res)
            res.timings["validation"] = time.perf_counter() - t0
        if "mc" in cfg.stages:
            t0 = time.perf_counter()
            res.mc = _monte_carlo(cfg, fs, runner, res)
            res.timings["mc"] = time.perf_counter() - t0
        if "readings" in cfg.stages and fs.is_paper:  # Table 6 as measurements (rvstudy.paper_readings)
            t0 = time.perf_counter()
            res.readings = run_readings(fs, ex, cache, min(cfg.steps, READINGS_STEPS), cfg.load_Nm,
                                        ContactLaw(cfg.K, cfg.n), progress=cfg.progress, **kw)
            res.notes.extend(res.readings.notes)
            res.timings["readings"] = time.perf_counter() - t0
    finally:
        if own:
            ex.close()
    res.timings["total"] = time.perf_counter() - t_start
    res.counters = runner.counters()
    res.cache_counters = cache.counters()
    return res


def _validation(cfg: StudyConfig, fs: FactorSet, runner: CachedRunner, res: StudyResult) -> pd.DataFrame:
    """Random cases uniform in the coded box [-1, 1]^k (seed ``[seed, 1]``), simulated and predicted."""
    rng = np.random.default_rng([cfg.seed, 1])
    z = rng.uniform(-1.0, 1.0, (cfg.n_validation, len(fs.names)))
    actual = np.vectorize(lambda v: float(f"{v:.6g}"))(fs.levels.coded_to_actual(z, fs.names))
    z = fs.levels.actual_to_coded(actual, fs.names)
    out = runner(_cases_for(fs, actual, "validation", cfg), f"validation ({cfg.n_validation} cases)")
    df = pd.DataFrame({"case": np.arange(1, len(z) + 1)})
    for j, f in enumerate(fs.names):
        df[f] = z[:, j]
    for j, f in enumerate(fs.names):
        df[f"{f}_actual"] = actual[:, j]
    df = pd.concat([df, _responses(out)], axis=1)
    ok = df[df["status"] == "ok"]
    for r in df[df["status"] != "ok"].itertuples():
        res.notes.append(f"validation case {r.case} failed and is left out: {r.error_message}")
    for resp, b in res.fits.items():
        if b.results is None or ok.empty:
            continue
        pred = b.results.predict(df, units="coded")
        df[f"{resp}_pred_full"] = pred["mean"].to_numpy()
        df[f"{resp}_pi_lower"] = pred["obs_ci_lower"].to_numpy()
        df[f"{resp}_pi_upper"] = pred["obs_ci_upper"].to_numpy()
        df[f"{resp}_pred_paper_mode"] = b.comparison.paper.predict(df, units="coded")
        df[f"{resp}_pred_backward"] = b.comparison.backward.results.predict(df, units="coded")["mean"].to_numpy()
        b.validation = {
            "full": b.results.validate(ok, response=resp, units="coded"),
            "paper_mode": b.comparison.paper.validate(ok, resp, units="coded"),
            "backward": b.comparison.backward.results.validate(ok, response=resp, units="coded"),
        }
    return df


def _screen_nodes(screen: ScreenResult, column: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Single-factor (value, response) nodes of every error type from the screen and the sweeps."""
    s = screen.screen
    a = float(s.loc[s["letter"] == "A", column].iloc[0])
    nodes: dict[str, tuple[list[float], list[float]]] = {k: ([0.0], [a]) for k in ERROR_TYPES}
    for r in s[s["letter"] != "A"].itertuples():
        nodes[r.error][0].append(float(r.value))
        nodes[r.error][1].append(float(getattr(r, column)))
    if len(screen.sweeps):
        for r in screen.sweeps.itertuples():
            if r.error in nodes and float(r.value) not in nodes[r.error][0]:
                nodes[r.error][0].append(float(r.value))
                nodes[r.error][1].append(float(getattr(r, column)))
    out = {}
    for k, (x, y) in nodes.items():
        x, y = np.array(x, float), np.array(y, float)
        keep = np.isfinite(y)  # a failed single-factor case is left out of the interpolation
        out[k] = (x[keep], y[keep])
    return out


def _monte_carlo(cfg: StudyConfig, fs: FactorSet, runner: CachedRunner, res: StudyResult) -> dict[str, Any]:
    """Tolerance stack-up through the fitted surfaces and a full-solver check sample."""
    tols = cfg.tolerances
    out: dict[str, Any] = {"tolerances": tols, "spec_arcmin": cfg.spec_arcmin}
    rng = np.random.default_rng([cfg.seed, 2])
    S = sample_errors(tols, cfg.mc_samples, rng)
    keys = fs.error_keys
    X = pd.DataFrame({f: S[fs.errors[f]].to_numpy() for f in fs.names})
    z = fs.levels.actual_to_coded(X.to_numpy(float), fs.names)
    out["outside_box_fraction"] = float(np.mean(np.any(np.abs(z) > 1.0 + 1e-12, axis=1)))
    surf: dict[str, np.ndarray] = {}
    dist_rows, sobol = [], []
    for resp, b in res.fits.items():
        if b.results is None:
            continue
        surface = b.results.surface
        y = surface.predict(X, units="actual")
        surf[resp] = y
        dist_rows.append({"source": "surface (RSM factors only)", "response": resp, "n": len(y),
                          **percentiles(y), "negative_fraction": float(np.mean(y < 0))})

        def f(D: pd.DataFrame, surface: Any = surface) -> np.ndarray:
            return surface.predict(pd.DataFrame({g: D[fs.errors[g]].to_numpy() for g in fs.names}), units="actual")

        si = sobol_indices(f, tols, keys, max(1000, cfg.mc_samples // 4), np.random.default_rng([cfg.seed, 4]))
        si.insert(0, "response", resp)
        si.insert(1, "factor", [next(g for g in fs.names if fs.errors[g] == k) for k in si["error"]])
        sobol.append(si)
    out["surface_samples"] = pd.concat([S, pd.DataFrame({f"{r}_surface": v for r, v in surf.items()})], axis=1)
    if "pp_arcmin" in surf:
        out["yield_surface"] = yield_estimate(surf["pp_arcmin"], cfg.spec_arcmin)
    out["sobol"] = pd.concat(sobol, ignore_index=True) if sobol else pd.DataFrame()
    # one-at-a-time shares of all eleven errors, from the screen's single-factor solver runs
    if res.screen is not None:
        oat = []
        for col, resp in (("te_mean_abs_arcmin", "mean_abs_arcmin"), ("te_pp_arcmin", "pp_arcmin")):
            o = oat_variance_shares(_screen_nodes(res.screen, col), S)
            o.insert(0, "response", resp)
            o.insert(1, "letter", [ERROR_TYPES[k].letter for k in o["error"]])
            oat.append(o)
        out["oat"] = pd.concat(oat, ignore_index=True)
    # full-solver check with every error type drawn
    if cfg.mc_check > 0:
        C = sample_errors(tols, cfg.mc_check, np.random.default_rng([cfg.seed, 3]))
        C = C.apply(lambda col: col.map(lambda v: float(f"{v:.6g}")))
        cases, valid = [], []
        for i, row in C.iterrows():
            try:
                cases.append(make_case(fs.case_errors(row.to_dict()), f"mc-{i + 1}", cfg.load_Nm))
                valid.append(i)
            except ValueError as exc:
                res.notes.append(f"Monte Carlo check draw {i + 1} is not a valid case and is skipped: {exc}")
        rr = runner(cases, f"MC check ({len(cases)} cases, all errors)")
        chk = pd.concat([C.loc[valid].reset_index(drop=True).rename(columns=lambda c: f"{c}"),
                         _responses(rr)], axis=1)
        chk.insert(0, "case", [v + 1 for v in valid])
        Xc = pd.DataFrame({f: chk[fs.errors[f]].to_numpy() for f in fs.names})
        for resp, b in res.fits.items():
            if b.results is None:
                continue
            chk[f"{resp}_surface"] = b.results.surface.predict(Xc, units="actual")
        ok = chk[chk["status"] == "ok"]
        for r in chk[chk["status"] != "ok"].itertuples():
            res.notes.append(f"Monte Carlo check case {r.case} failed and is left out: {r.error_message}")
        out["check"] = chk
        for resp in RESPONSES:
            if len(ok):
                dist_rows.append({"source": "full solver (all 11 errors)", "response": resp, "n": len(ok),
                                  **percentiles(ok[resp].to_numpy())})
            if f"{resp}_surface" in chk and len(ok):
                e = ok[f"{resp}_surface"].to_numpy() - ok[resp].to_numpy()
                out[f"check_{resp}"] = {"rmse": float(np.sqrt(np.mean(e ** 2))), "bias": float(np.mean(e)),
                                        "max_abs": float(np.max(np.abs(e))), "n": int(len(e))}
        if len(ok):
            out["yield_solver"] = yield_estimate(ok["pp_arcmin"].to_numpy(), cfg.spec_arcmin)
    out["distribution"] = pd.DataFrame(dist_rows)
    return out
