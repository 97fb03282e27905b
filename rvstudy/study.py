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
4. ``mc`` -- Monte Carlo tolerance stack-up through the full solver (:mod:`rvstudy.stackup`): every
   toleranced feature of the drawing drawn, every draw solved (analytic; fcl on a check subsample),
   stack-up statistics per response (Cp, Cpk, out of spec with an exact interval), variance-based
   contributors from a designed sample, tolerance allocation; the fitted surface only as a comparison.

The reducer is the paper's by default or a user's design JSON (``--reducer``): every count and ratio
of the study comes from that :class:`rvcad.params.Design`.

With more than one worker the stages' cases are all submitted at the start (the paper stages' cases
in one batch, the Table 6 readings, the Monte Carlo draws and their fcl check, each from a thread of
this process), so the workers never wait while this process fits a stage or builds the next one's
cases; the stages then read their results in the order above (the numbers are those of a serial run).

:func:`run_study` returns a :class:`StudyResult`; :func:`rvstudy.report.write_report` writes it.
"""
from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import rsm
from rsm.terms import preset_terms
from rvcad.errors import Case
from rvcad.params import Design
from rvcad.validation import DesignError, as_mapping, read_json_file
from rvdyn.contacts import ContactLaw
from rvstudy.screen import (
    ARCSEC_PER_ARCMIN,
    RSM_FACTORS,
    ScreenResult,
    make_case,
    run_screen,
    screen_cases,
    sweep_cases,
)
from rvdyn.te import SOLVERS
import rvpaper as paper
from rvdyn.cache import CaseCache
from rvdyn.runner import Executor, Runner, make_executor
from rvstudy.factors import PIN_PATTERNS, FactorSet, load_factors, pattern_value  # noqa: F401  (re-exported)
from rvstudy.paper_readings import LAWS as READINGS_LAWS
from rvstudy.paper_readings import READINGS_STEPS, readings_cases, run_readings
from rvstudy.montecarlo import Tolerance, default_tolerances
from rvstudy.stackup import MC_RESPONSES, run_full_mc, solve_full_mc

STAGES = ("screen", "doe", "validation", "mc", "readings")
DESIGNS = ("bbd", "ccd")
#: Responses of the design, in arcmin: the paper's statistic first.
RESPONSES = ("mean_abs_arcmin", "pp_arcmin")
RESPONSE_LABEL = {"mean_abs_arcmin": "mean |TE| [arcmin]", "pp_arcmin": "TE peak-to-peak [arcmin]"}

#: Words for the physical contact law in the report (rvdyn.options, docs/physics.md sections 7-8).
PHYSICAL_LAW_TEXT = ("physical: Hertz line contact at the pins (local profile curvature), ISO 6336-1 mesh stiffness, "
                     "cam and journal bearings, crankshafts, carrier and pin seats elastic (rvdyn's default law)")
#: Contact law of the Monte Carlo by default (``--mc-contact``): physical, the full physics of the mission. Its
#: responses (TE peak-to-peak, play at +-3 % rated, torsional rigidity) are set against datasheet limits, which
#: only the physical law computes (the impact law's rigidity follows the draw's preload, not the parts'
#: compliance). It costs about 3.5 times the impact law's CPU a draw (``benchmarks/bench_mc_draw.py``, figures in
#: ``benchmarks/results.csv``).
DEFAULT_MC_CONTACT = "physical"
#: Default steps per output revolution (360 resolves every single-pin event; 240 and
#: fewer alias the peak-to-peak TE of several Table 4 errors by up to a factor 3).
DEFAULT_STEPS = 360
DEFAULT_SEED = 20240
#: Full-solver Monte Carlo draws, designed-sample block size, fcl check draws (defaults).
DEFAULT_MC_DRAWS = 1500
DEFAULT_MC_SOBOL = 50
DEFAULT_MC_CHECK = 8


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
    mc_draws : int
        Independent Monte Carlo draws, each solved by the full (analytic) solver (``--mc-draws``).
    mc_sobol : int
        Rows of each block of the designed sample for the contributors (``--mc-sobol``): the first
        2 x mc_sobol draws are A and B, plus mc_sobol solver draws per tolerance; 0 = no contributors.
    mc_check : int
        Draws solved again with the fcl provider to check the analytic one (``--mc-check``).
    tolerances : dict
        ``{error key: Tolerance}`` (``--tolerance``, ``--tolerances``).
    spec_arcmin : float
        USL of TE peak-to-peak, arcmin (``--spec-arcmin``).
    play_spec_arcmin : float
        USL of the two-direction play at +-3 % rated torque, arcmin (``--play-spec-arcmin``).
    spec_limits : dict
        ``{response: (LSL, USL)}`` overriding the above (``--spec RESPONSE=LSL:USL``).
    rated_Nm : float
        Rated output torque, N m (``--rated-Nm``; 167 = the RV-20E class of the paper's reducer).
    mc_contact : str
        Contact law of the Monte Carlo solves (``--mc-contact``): ``physical`` (default,
        :data:`DEFAULT_MC_CONTACT`: Hertz line contact, ISO 6336 mesh stiffness, elastic supports;
        ``rvdyn.contacts.ContactLaw``) or ``impact`` (the paper's Eq. 1 with ``K``, ``n``, as every
        paper-reproduction section uses).
    rigidity_lsl : float
        LSL of the torsional rigidity, N m/arcmin (``--rigidity-lsl``; 49 = the RV-20E datasheet figure).
    yield_target : float
        Yield the tolerance allocation aims at (``--yield-target``).
    reducer : str or None
        Design JSON of the reducer (``--reducer``); default the paper's.
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
    solver: str = "analytic"
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
    mc_draws: int = DEFAULT_MC_DRAWS
    mc_sobol: int = DEFAULT_MC_SOBOL
    mc_check: int = DEFAULT_MC_CHECK
    tolerances: dict[str, Tolerance] = field(default_factory=default_tolerances)
    spec_arcmin: float = 1.0
    play_spec_arcmin: float = 1.0
    spec_limits: dict[str, tuple[float | None, float | None]] = field(default_factory=dict)
    rated_Nm: float = 167.0
    rigidity_lsl: float = 49.0
    mc_contact: str = DEFAULT_MC_CONTACT
    yield_target: float = 0.9973
    reducer: str | None = None
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
        integer(self.mc_draws, "--mc-draws", 2)
        integer(self.mc_sobol, "--mc-sobol", 0)
        integer(self.mc_check, "--mc-check", 0)
        for opt, v in (("--rated-Nm", self.rated_Nm), ("--play-spec-arcmin", self.play_spec_arcmin),
                       ("--rigidity-lsl", self.rigidity_lsl)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{opt} {v!r} must be a finite number > 0")
        if self.mc_contact not in ContactLaw.KINDS:
            raise ValueError(f"--mc-contact {self.mc_contact!r} is unknown; allowed: {list(ContactLaw.KINDS)}")
        if not 0 < self.yield_target < 1:
            raise ValueError(f"--yield-target {self.yield_target!r} must lie in (0, 1)")
        for r, (lo, hi) in self.spec_limits.items():
            if r not in MC_RESPONSES:
                raise ValueError(f"--spec {r!r}: unknown response; allowed: {list(MC_RESPONSES)}")
            if lo is not None and hi is not None and not lo < hi:
                raise ValueError(f"--spec {r}: LSL {lo} must be below USL {hi}")
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

    def contact_models(self) -> dict[str, str]:
        """The contact model each section of the report uses (the report says it per section).

        The sections that reproduce the paper (screen, sweeps, design runs and their fits, validation, the
        response-surface loop on them) use the paper's impact law with ``K`` and ``n``, named explicitly
        (rvdyn's own default is the physical law); the Table 6 readings solve both laws, one row each; the
        Monte Carlo uses ``mc_contact``."""
        impact = f"impact: F = {self.K:g} delta^{self.n:g} (N, mm), paper Eq. 1 without damping"
        return {"screen": impact, "sweeps": impact, "design": impact, "fits": impact + " (the design runs)",
                "validation": impact, "augment": impact + " (design and validation runs)",
                "readings": "both, one row each: " + impact + "; " + PHYSICAL_LAW_TEXT,
                "monte_carlo": (impact if self.mc_contact == "impact" else PHYSICAL_LAW_TEXT) + " (--mc-contact)"}

    def specs(self) -> dict[str, tuple[float | None, float | None]]:
        """``{response: (LSL, USL)}`` of the Monte Carlo responses (None = no limit)."""
        d: dict[str, tuple[float | None, float | None]] = {
            "te_pp_arcmin": (None, float(self.spec_arcmin)), "play_3pct_arcmin": (None, float(self.play_spec_arcmin)),
            "torsional_rigidity_Nm_per_arcmin": (float(self.rigidity_lsl), None), "te_mean_abs_arcmin": (None, None)}
        d.update(self.spec_limits)
        return d

    def reducer_design(self) -> Design:
        """The reducer of the study: ``--reducer`` design JSON, or the paper's default design."""
        return load_reducer(self.reducer)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings (tolerances as text)."""
        d = {k: (str(v) if isinstance(v, Path) else v) for k, v in self.__dict__.items() if k != "tolerances"}
        d["stages"] = list(self.stages)
        d["tolerances"] = {k: t.describe() for k, t in self.tolerances.items()}
        d["spec_limits"] = {k: list(v) for k, v in self.spec_limits.items()}
        return d


def load_reducer(path: str | None) -> Design:
    """Design of a reducer from a JSON file: the ``design`` object of a case (``rvcad.Design`` fields), or a
    whole case whose ``design`` is used; None = the paper's default design. ValueError names the file."""
    if path is None:
        return Design()
    p = Path(path)
    d = read_json_file(p, "--reducer file", DesignError)  # strict: a repeated key or NaN is an error
    if isinstance(d, dict) and "design" in d:  # a whole case: its design object
        d = as_mapping(d["design"], f"--reducer {p.name}: design", "an object of Design fields", DesignError)
    if not isinstance(d, dict):
        raise DesignError(f"--reducer file {str(p)!r} must hold a JSON object of Design fields (e.g. "
                          '{"z_sun": 18, "z_planet": 36})', field="--reducer", value=str(p))
    try:
        design = Design.from_dict(d)
        Case.from_dict({"design": design.to_dict()})  # the parts of the nominal reducer are valid
    except ValueError as exc:
        raise DesignError(f"--reducer {p.name}: {exc}", field="--reducer", value=str(p)) from None
    return design


def min_resolving_steps(design: Design) -> int:
    """Steps per output revolution that sample the input order (one period per input turn, the ratio's
    order: 121 for the paper's design) twice."""
    return 2 * math.ceil(design.ratio)


#: For the paper's design: 242.
MIN_RESOLVING_STEPS = min_resolving_steps(Design())

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
    reducer: Design = field(default_factory=Design)
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


def _cases_for(fs: FactorSet, actual: np.ndarray, prefix: str, cfg: StudyConfig,
               base: dict[str, Any] | None = None) -> list[Case]:
    out = []
    for i, row in enumerate(np.atleast_2d(actual)):
        errs = fs.case_errors({fs.errors[f]: float(v) for f, v in zip(fs.names, row)})
        try:
            out.append(make_case(errs, f"{prefix}-{i + 1}", cfg.load_Nm, base=base))
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
            try:
                b.comparison = rsm.compare_reductions(b.results, alpha=alpha, alpha_out=alpha)
            except ValueError as exc:  # the full fit stands; only the reduced models are missing
                b.comparison = None
                b.notes.append(f"reduced models (Eq. 9) could not be formed from the {len(ok)} solved runs: {exc}")
        b.notes = list(dict.fromkeys(b.notes + [str(x.message) for x in w] + list(b.results.notes)))
        if dropped:
            b.notes.insert(0, f"{len(ok)} of {len(data)} runs solved; terms not estimable from them and left out "
                              f"of the model: {', '.join(dropped)}")
    except ValueError as exc:
        b.error = f"{response}: {exc}"
    return b


@dataclass
class _Stages:
    """What the study's stages solve, made before any case is solved (so that all can be submitted at once).
    ``coded`` and ``val_points`` are None and ``readings`` and ``mc`` (their runners) empty for a stage not run."""

    half: dict[str, float]                        # sweep half ranges: RSM factors on their own error, centre 0
    coded: pd.DataFrame | None = None             # the design, coded (:func:`_design`)
    actual: np.ndarray | None = None              # its points in actual units
    doe_cases: list[Case] = field(default_factory=list)
    val_points: tuple[np.ndarray, np.ndarray] | None = None
    val_cases: list[Case] = field(default_factory=list)
    readings: dict[str, Runner] = field(default_factory=dict)
    mc: dict[str, Runner] = field(default_factory=dict)


def _plan_stages(cfg: StudyConfig, res: StudyResult, base: dict[str, Any], law: ContactLaw,
                 make_runner: Callable[..., Runner]) -> _Stages:
    """The cases and runners of every stage of ``cfg.stages`` (sets ``res.paper_order``; a note when the fcl
    check of the Monte Carlo cannot run)."""
    fs = res.factors
    st = _Stages({f: fs.levels[f].half_range for f in fs.names if f in RSM_FACTORS and fs.errors[f] == RSM_FACTORS[f]
                  and fs.patterns.get(f) is None and fs.levels[f].center == 0})
    if {"doe", "validation", "mc"} & set(cfg.stages):
        st.coded, res.paper_order = _design(cfg, fs)
        st.actual = fs.levels.coded_to_actual(st.coded[fs.names].to_numpy(float), fs.names)
        st.doe_cases = _cases_for(fs, st.actual, "doe", cfg, base)
    if "validation" in cfg.stages and cfg.n_validation > 0:
        st.val_points = _validation_points(cfg, fs)
        st.val_cases = _cases_for(fs, st.val_points[1], "validation", cfg, base)
    if "readings" in cfg.stages and fs.is_paper:
        st.readings = {ln: make_runner("analytic", min(cfg.steps, READINGS_STEPS),
                                       law if ln == "impact" else ContactLaw(kind=ln)) for ln in READINGS_LAWS}
    if "mc" in cfg.stages:
        mc_law = law if cfg.mc_contact == "impact" else ContactLaw(cfg.K, cfg.n, kind=cfg.mc_contact)
        st.mc["mc"] = make_runner("analytic", cfg.steps, mc_law)
        if cfg.mc_check > 0:
            import importlib.util

            if importlib.util.find_spec("fcl") is None or importlib.util.find_spec("rvdyn.fcl_contacts") is None:
                res.notes.append("the fcl check of the Monte Carlo is skipped: python-fcl is not installed")
            else:
                st.mc["check"] = make_runner("fcl", cfg.steps, mc_law)
    return st


def _submit_ahead(bg: ThreadPoolExecutor, cfg: StudyConfig, res: StudyResult, base: dict[str, Any],
                  runner: Runner, st: _Stages) -> dict[str, Future]:
    """Submit every stage's cases to the workers at once, from the threads of ``bg``: the paper stages'
    cases in one batch (``paper``), the readings per law and the Monte Carlo (``mc``). Returns the futures."""
    pending: dict[str, Future] = {}
    ahead: list[Case] = []
    if "screen" in cfg.stages:
        ahead += list(screen_cases(cfg.load_Nm, True, base)["case"])
        ahead += list(sweep_cases(cfg.sweep_points, cfg.load_Nm, st.half or None, base)["case"])
    ahead += st.doe_cases + st.val_cases
    if ahead:
        pending["paper"] = bg.submit(runner.prefetch, ahead, f"paper stages ({len(ahead)} cases)")
    for ln, r in st.readings.items():
        pending[ln] = bg.submit(r.prefetch, readings_cases(res.factors, cfg.load_Nm, ln), f"Table 6 readings, {ln} law")
    if st.mc:
        pending["mc"] = bg.submit(solve_full_mc, cfg, res.reducer, st.mc, None, bg)
    return pending


def _ready(pending: dict[str, Future], name: str) -> None:
    """Wait until the cases submitted ahead as ``name`` (if any) are solved, re-raising their error."""
    if name in pending:
        pending.pop(name).result()


def _run_paper_stages(res: StudyResult, runner: Runner, st: _Stages, pending: dict[str, Future],
                      base: dict[str, Any]) -> None:
    """Run the screen and sweeps, the design runs with their fits, and the validation, into ``res``, each
    timed (``res.timings``)."""
    cfg, fs = res.config, res.factors
    if "screen" in cfg.stages:
        t0 = time.perf_counter()
        _ready(pending, "paper")
        res.screen = run_screen(cfg.solver, cfg.steps, cfg.sweep_points, cfg.load_Nm, runner=runner,
                                both_signs=True, half_range=st.half or None, progress=cfg.progress,
                                sweeps="screen" in cfg.stages, base=base)
        res.timings["screen"] = time.perf_counter() - t0
    if st.coded is not None:
        t0 = time.perf_counter()
        _ready(pending, "paper")
        out = runner(st.doe_cases, f"design ({cfg.design}, {len(st.doe_cases)} runs)")
        table = st.coded.copy()
        for j, f in enumerate(fs.names):
            table[f"{f}_actual"] = [float(f"{v:.12g}") for v in st.actual[:, j]]
        res.design = pd.concat([table.reset_index(drop=True), _responses(out)], axis=1)
        res.design_kind = cfg.design
        failed = res.design[res.design["status"] != "ok"]
        for r in failed.itertuples():
            res.notes.append(f"design run {r.run} failed and is left out of the fit: {r.error_message}")
        for resp in RESPONSES:
            res.fits[resp] = _fit(res.design, fs, resp, cfg.alpha)
        res.timings["doe"] = time.perf_counter() - t0
    if st.val_points is not None:
        t0 = time.perf_counter()
        _ready(pending, "paper")
        res.validation = _validation(cfg, fs, runner, res, st.val_points, st.val_cases)
        res.timings["validation"] = time.perf_counter() - t0


def _run_readings_and_mc(res: StudyResult, st: _Stages, pending: dict[str, Future], ex: Executor,
                         cache: CaseCache, kw: dict[str, Any], parallel: bool) -> None:
    """Run the Table 6 readings and the Monte Carlo into ``res``, each timed; ``parallel``: the draws were
    submitted ahead, so the Monte Carlo's wait for them is timed too (``mc_wait_and_analysis``)."""
    cfg, fs = res.config, res.factors
    if st.readings:  # Table 6 as measurements (rvstudy.paper_readings)
        t0 = time.perf_counter()
        for ln in st.readings:
            _ready(pending, ln)
        res.readings = run_readings(fs, ex, cache, min(cfg.steps, READINGS_STEPS), cfg.load_Nm,
                                    ContactLaw(cfg.K, cfg.n), progress=cfg.progress, runners=st.readings, **kw)
        res.notes.extend(res.readings.notes)
        res.timings["readings"] = time.perf_counter() - t0
    if st.mc:
        t0 = time.perf_counter()
        solved = pending.pop("mc").result() if "mc" in pending else None
        res.mc = run_full_mc(cfg, fs, res.reducer, st.mc, res.fits, res.notes, workers=getattr(ex, "workers", 1),
                             solved=solved)
        res.timings["mc"] = res.mc["timing"]["wall_s"]
        if parallel:  # the draws were solved beside the other stages
            res.timings["mc_wait_and_analysis"] = time.perf_counter() - t0


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
    design = cfg.reducer_design()
    fs.z_pins = design.z_pins
    if design != Design():
        fs.is_paper = False  # the paper's numbers are of its own reducer: no side-by-side for another one
    base = {"design": design.to_dict()}
    t_start = time.perf_counter()
    own = executor is None
    ex = make_executor(cfg.workers, cfg.scheduler, cfg.scheduler_timeout_s) if own else executor
    cache = CaseCache((cfg.cache_dir or Path(cfg.out) / "cache") if cfg.use_cache else None)
    kw = {} if solve_fn is None else {"solve_fn": solve_fn}
    law = ContactLaw(cfg.K, cfg.n)

    made: list[Runner] = []

    def make_runner(solver: str, steps: int, law: ContactLaw = law) -> Runner:
        made.append(Runner(ex, cache, solver, steps, law, progress=cfg.progress, **kw))
        return made[-1]

    runner = make_runner(cfg.solver, cfg.steps)
    res = StudyResult(config=cfg, factors=fs, executor=getattr(ex, "describe", lambda: ex.name)(), reducer=design)
    n_min = min_resolving_steps(design)
    if cfg.steps < n_min:
        res.notes.append(f"--steps {cfg.steps} is below {n_min}: the TE has content at the input order "
                         f"{design.ratio:g} (one period per input turn), which needs two steps a period, so "
                         "peak-to-peak values are undersampled (the mean is less affected)")
    # With more than one worker every stage's cases are submitted at once (the paper stages, the Table 6
    # readings, the Monte Carlo draws and their fcl check, each from its own thread), so that no worker
    # waits while this process fits a stage or builds the next stage's cases; the stages then read their
    # results in the usual order (Runner.prefetch keeps them in memory, counted once).
    bg = ThreadPoolExecutor(max_workers=6, thread_name_prefix="rv-stackup") if getattr(ex, "workers", 1) > 1 else None
    try:
        st = _plan_stages(cfg, res, base, law, make_runner)
        pending = _submit_ahead(bg, cfg, res, base, runner, st) if bg is not None else {}
        _run_paper_stages(res, runner, st, pending, base)
        _run_readings_and_mc(res, st, pending, ex, cache, kw, bg is not None)
    finally:
        if own:
            ex.close()
        if bg is not None:
            bg.shutdown(wait=True, cancel_futures=True)
    res.timings["total"] = time.perf_counter() - t_start
    res.counters = _merged_counters(made)
    res.cache_counters = cache.counters()
    return res


def _merged_counters(runners: list[Runner]) -> dict[str, Any]:
    """The counters of every runner of the run added up (solve-time statistics over all computed cases)."""
    out = {k: sum(getattr(r, k) for r in runners) for k in ("computed", "reused", "failed")}
    s = np.array([x for r in runners for x in r.solve_seconds], dtype=float)
    out.update({"solve_seconds_mean": float(np.nanmean(s)) if s.size else float("nan"),
                "solve_seconds_median": float(np.nanmedian(s)) if s.size else float("nan"),
                "solve_seconds_total": float(np.nansum(s)) if s.size else 0.0,
                "wall_seconds": float(sum(r.wall_seconds for r in runners))})
    return out


def _validation_points(cfg: StudyConfig, fs: FactorSet) -> tuple[np.ndarray, np.ndarray]:
    """Coded and actual points of the validation: uniform in the coded box [-1, 1]^k (seed ``[seed, 1]``),
    actual values rounded to 6 significant digits (and the coded ones recomputed from them)."""
    rng = np.random.default_rng([cfg.seed, 1])
    z = rng.uniform(-1.0, 1.0, (cfg.n_validation, len(fs.names)))
    actual = np.vectorize(lambda v: float(f"{v:.6g}"))(fs.levels.coded_to_actual(z, fs.names))
    return fs.levels.actual_to_coded(actual, fs.names), actual


def _validation(cfg: StudyConfig, fs: FactorSet, runner: Runner, res: StudyResult,
                points: tuple[np.ndarray, np.ndarray], cases: list[Case]) -> pd.DataFrame:
    """The validation cases (:func:`_validation_points`), simulated and predicted."""
    z, actual = points
    out = runner(cases, f"validation ({cfg.n_validation} cases)")
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
        if b.comparison is None:
            b.validation = {"full": b.results.validate(ok, response=resp, units="coded")}
            continue
        df[f"{resp}_pred_paper_mode"] = b.comparison.paper.predict(df, units="coded")
        df[f"{resp}_pred_backward"] = b.comparison.backward.results.predict(df, units="coded")["mean"].to_numpy()
        b.validation = {
            "full": b.results.validate(ok, response=resp, units="coded"),
            "paper_mode": b.comparison.paper.validate(ok, resp, units="coded"),
            "backward": b.comparison.backward.results.validate(ok, response=resp, units="coded"),
        }
    return df
