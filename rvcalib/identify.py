"""The closed loop: residual -> missing effect -> model update -> residual again.

Algorithm (:func:`calibrate`)
-----------------------------
0. The residual of every run against the model built from its declared errors only
   (:mod:`rvcalib.forward`).
1. Screening signatures: for every candidate of :mod:`rvcalib.effects` the change of the model TE
   when the candidate is set to its typical size (both signs where the sign matters; four
   directions for the eccentricities in rotating frames), solved through rvdyn on a coarse grid
   (a subset of the model grid, at most 120 points per output revolution) for every run
   condition, at the declared model. They are solved once and reused in every iteration; pin
   instances and the direction of the pin-circle offset and ovality are the solved signature
   rotated by whole pin pitches / grid steps (rotational symmetry of the 40 pins; exact for a
   symmetric declared model, a screening approximation otherwise). Measurement effects are
   analytic.
2. Ranking: each candidate's signature (piecewise linear in its parameter: one secant per sign or
   quadrant) is fitted to the current residual at the coarse points; the fraction of the residual
   sum of squares it explains ranks it. The best harmonic-only model (one order of the output
   angle, a constant, or a direction-signed constant, common to all runs) is ranked beside.
3. Validation of the ranking: the ``top_k`` candidates are re-fitted through the full nonlinear
   model at the current state (``scipy.optimize.least_squares`` on the coarse grid, rvdyn
   re-solved at each trial value), because the contact model is strongly nonlinear (one-sided
   contacts: a +10 um and a -10 um error do not give opposite TE).
4. Decision: the best physical candidate is added if it passes both the F test on the residual
   sum of squares (p below ``alpha`` / the number of hypotheses screened: Bonferroni over every
   candidate instance and harmonic order) and the BIC (it must lower it), and if the best
   harmonic-only model is not clearly better (BIC lower by more than 2). If the harmonic-only
   model is better, what is left is reported as *unexplained* (its order and size) and absorbed by
   a labelled empirical harmonic term; it is never named as a physical effect.
5. Estimation: all added parameters are re-fitted jointly through the full nonlinear model
   solved exactly at every reading (``least_squares``; empirical terms are projected out linearly) and
   the F test and BIC are confirmed on all samples.
6. Repeat until nothing passes; then confidence intervals from the Jacobian (forward differences)
   and the residual variance, widened by ``sqrt((1 + rho) / (1 - rho))`` for a lag-1 residual
   autocorrelation ``rho > 0`` (the residual is then not white and the plain interval too narrow).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy import optimize, stats

from rvcalib.dataset import PERIOD_DEG, RATIO, MeasuredDataset, RunRecord
from rvcalib.effects import Effect, Library, build_library, polar_to_xy, trial_points
from rvcalib.forward import ModelEvaluationError, cache_stats, coarse_stride, grid_te, merge_case, te_at
from rvcalib.dataset import noise_estimate
from rvcalib.residual import Diagnostics, diagnose, lag1_autocorr

#: A residual trend over a record is reported when its t value exceeds RAMP_T and its size exceeds
#: RAMP_NOISE_FACTOR times the noise (see :func:`rvcalib.residual.ramp_fit`).
RAMP_T = 6.0
RAMP_NOISE_FACTOR = 3.0

#: Margin (BIC units) by which a harmonic-only model must beat the best physical candidate before
#: the residual is called unexplained (a tie goes to the physical effect).
HARMONIC_BIC_MARGIN = 2.0


# ---------------------------------------------------------------------------------------------
# state
@dataclass
class Active:
    """An effect in the model with its current parameters (actual units)."""

    effect: Effect
    p: np.ndarray
    iteration: int
    cov: np.ndarray | None = None
    info: dict = field(default_factory=dict)


@dataclass(frozen=True)
class EmpiricalTerm:
    """A labelled empirical term absorbing unexplained residual (not a physical effect).

    ``kind``: ``harmonic`` (``a cos(k th_out) + b sin(k th_out)``), ``offset`` (a constant) or
    ``direction_offset`` (``direction * c``); the same for every run.
    """

    kind: str
    order: int = 0

    @property
    def label(self) -> str:
        """Human label."""
        if self.kind == "harmonic":
            return f"unexplained order-{self.order} harmonic"
        if self.kind == "offset":
            return "unexplained constant offset"
        return "unexplained direction-dependent offset"

    @property
    def note(self) -> str:
        """What such a term can be, where the data cannot say more (empty for a harmonic)."""
        if self.kind == "offset":
            return ("the same constant in every run, load and direction: a zero offset between the input and "
                    "output encoders, or a rotation of the whole pin housing (all 40 pins), which the TE cannot "
                    "tell apart; not a clearance (that changes sign with the direction) or a compliance (that "
                    "grows with the load)")
        if self.kind == "direction_offset":
            return ("a lost motion (sign follows the direction) that no clearance or friction of the library "
                    "explains better")
        return ""

    @property
    def n_cols(self) -> int:
        """Columns it adds."""
        return 2 if self.kind == "harmonic" else 1

    def columns(self, output_rad: np.ndarray, direction: int) -> np.ndarray:
        """Design columns (n, n_cols) at output angles (rad)."""
        if self.kind == "harmonic":
            k = self.order
            return np.column_stack([np.cos(k * output_rad), np.sin(k * output_rad)])
        if self.kind == "offset":
            return np.ones((output_rad.size, 1))
        return np.full((output_rad.size, 1), float(direction))


@dataclass
class FittedEffect:
    """A found effect as reported.

    Attributes
    ----------
    name, key, family, unit, meaning : str
    value : float
        The size (magnitude for two-component effects), in ``unit``.
    ci_low, ci_high : float
        95 % confidence interval of ``value`` (widened for residual autocorrelation).
    angle_deg : float or None
        Direction of a two-component effect.
    std_err : float
        Standard error of ``value`` before the autocorrelation widening.
    params : dict
        The fitted components.
    iteration : int
        Iteration that added it.
    explained_fraction : float
        Fraction of the residual sum of squares it removed when it was added.
    F, p_value, delta_bic : float
        Its tests when it was added (all samples).
    alternatives : list of str
        Candidates that explained the residual as well within the noise when it was added.
    """

    name: str
    key: str
    family: str
    unit: str
    meaning: str
    value: float
    ci_low: float
    ci_high: float
    angle_deg: float | None
    std_err: float
    params: dict
    iteration: int
    explained_fraction: float
    F: float
    p_value: float
    delta_bic: float
    alternatives: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready form."""
        d = {"name": self.name, "key": self.key, "family": self.family, "value": self.value, "unit": self.unit,
             "ci_low": self.ci_low, "ci_high": self.ci_high, "std_err": self.std_err, "meaning": self.meaning,
             "params": self.params, "iteration": self.iteration, "explained_fraction": self.explained_fraction,
             "F": self.F, "p_value": self.p_value, "delta_bic": self.delta_bic, "alternatives": self.alternatives}
        if self.angle_deg is not None:
            d["angle_deg"] = self.angle_deg
        return d


@dataclass
class Unexplained:
    """Residual structure outside the library, absorbed by an empirical term."""

    label: str
    kind: str
    order: int
    amplitude_arcsec: float
    phase_deg: float | None
    iteration: int
    explained_fraction: float
    note: str = ""

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {"label": self.label, "kind": self.kind, "order": self.order,
                "amplitude_arcsec": self.amplitude_arcsec, "phase_deg": self.phase_deg,
                "iteration": self.iteration, "explained_fraction": self.explained_fraction, "note": self.note}


@dataclass
class CalibrationResult:
    """Everything the loop found.

    Attributes
    ----------
    dataset : MeasuredDataset
    effects : list of FittedEffect
        Physical and measurement effects added (in the order found).
    unexplained : list of Unexplained
        Residual outside the library (empirical terms), with orders and sizes.
    before, after : Diagnostics
        Residual diagnostics with the declared model, and with everything added.
    after_physical : Diagnostics
        Residual with the found effects but without the empirical terms.
    residual_before, residual_after : list of ndarray
        Per run, arcsec.
    iterations : list of dict
        Log: ranking, validated candidates, harmonic competitor, decision.
    status : str
        ``fits`` (nothing added and the residual is white noise), ``explained`` (effects added,
        white residual left), ``unexplained`` (empirical terms needed or structure left).
    verdict : str
        One-sentence summary.
    noise_arcsec : float
        Noise estimate from the final residual (second differences), arcsec.
    steps : int
        Model grid points per output revolution.
    seconds : float
    notes : list of str
    """

    dataset: MeasuredDataset
    effects: list[FittedEffect]
    unexplained: list[Unexplained]
    before: Diagnostics
    after: Diagnostics
    after_physical: Diagnostics
    residual_before: list[np.ndarray]
    residual_after: list[np.ndarray]
    iterations: list[dict]
    status: str
    verdict: str
    noise_arcsec: float
    steps: int
    seconds: float
    notes: list[str]
    solver_stats: dict = field(default_factory=dict)

    @property
    def rms_before(self) -> float:
        """Pooled residual RMS with the declared model, arcsec."""
        return self.before.rms

    @property
    def rms_after(self) -> float:
        """Pooled residual RMS after the loop (effects and empirical terms), arcsec."""
        return self.after.rms

    def to_dict(self) -> dict:
        """The ``--json`` object."""
        runs = []
        for b, a, ap, run in zip(self.before.runs, self.after.runs, self.after_physical.runs, self.dataset.runs):
            runs.append({"run": run.run, "load_Nm": run.load_Nm, "direction": run.direction, "n_samples": run.n,
                         "revolutions": run.revolutions, "dropped": run.dropped,
                         "rms_before_arcsec": b.rms, "rms_after_arcsec": a.rms,
                         "rms_after_physical_arcsec": ap.rms, "peak_before_arcsec": b.peak,
                         "peak_after_arcsec": a.peak, "mean_before_arcsec": b.mean, "mean_after_arcsec": a.mean,
                         "ljung_box_p_before": b.ljung_box_p, "ljung_box_p_after": a.ljung_box_p,
                         "orders_before_arcsec": {str(k): v for k, v in b.orders.items()},
                         "orders_after_arcsec": {str(k): v for k, v in a.orders.items()},
                         "dominant_orders_after": [{"order": k, "amplitude_arcsec": v} for k, v in a.dominant]})
        return {"dataset": str(self.dataset.path), "status": self.status, "verdict": self.verdict,
                "rms_before_arcsec": self.rms_before, "rms_after_arcsec": self.rms_after,
                "rms_after_physical_arcsec": self.after_physical.rms, "noise_arcsec": self.noise_arcsec,
                "white_after": self.after.white,
                "effects": [e.to_dict() for e in self.effects],
                "unexplained": [u.to_dict() for u in self.unexplained],
                "dependence_before": self.before.dependence, "dependence_after": self.after.dependence,
                "runs": runs, "iterations": self.iterations, "notes": self.notes, "steps": self.steps,
                "seconds": self.seconds, "solver": self.solver_stats}


# ---------------------------------------------------------------------------------------------
# helpers
def _proj(E: np.ndarray | None):
    """Projector onto the orthogonal complement of the columns of E (a function)."""
    if E is None or E.shape[1] == 0:
        return lambda v: v
    Q, _ = np.linalg.qr(E)

    def P(v: np.ndarray) -> np.ndarray:
        return v - Q @ (Q.T @ v)
    return P


def _bic(rss: float, n: int, k: int) -> float:
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def _ftest(rss0: float, rss1: float, k: int, n: int, p1: int) -> tuple[float, float]:
    df2 = n - p1
    if rss1 <= 0 or df2 <= 0 or rss0 <= rss1:
        return 0.0, 1.0
    F = ((rss0 - rss1) / k) / (rss1 / df2)
    return float(F), float(stats.f.sf(F, k, df2))


def _coarse_values(run: RunRecord, values: np.ndarray, m: int) -> np.ndarray:
    """A run's sampled values at the m coarse grid angles: the mean of the samples on each grid
    angle (all revolutions), periodic linear interpolation where no sample sits on it."""
    x = np.mod(run.input_deg, PERIOD_DEG)
    step = PERIOD_DEG / m
    k = x / step
    kr = np.rint(k)
    on = np.abs(k - kr) < 1e-6
    idx = kr.astype(int) % m
    out = np.full(m, np.nan)
    if on.any():
        s = np.bincount(idx[on], weights=values[on], minlength=m)
        c = np.bincount(idx[on], minlength=m)
        good = c > 0
        out[good] = s[good] / c[good]
    miss = np.isnan(out)
    if miss.any():
        order = np.argsort(x)
        out[miss] = np.interp(np.arange(m)[miss] * step, x[order], values[order], period=PERIOD_DEG)
    return out


# ---------------------------------------------------------------------------------------------
class Calibrator:
    """State and machinery of the loop for one dataset (see the module docstring).

    Parameters
    ----------
    dataset : MeasuredDataset
    steps : int
        Model grid points per output revolution (a multiple of 40).
    alpha : float
        Family-wise significance level of the F tests (Bonferroni over the hypotheses screened).
    max_terms : int
        Largest number of effects plus empirical terms added.
    top_k : int
        Candidates validated through the nonlinear model per iteration.
    library : Library or None
        Candidates (default :func:`rvcalib.effects.build_library`).
    log : callable or None
        Called with progress strings.
    screen_points : int
        Largest number of points per output revolution of the screening grid (a subset of the
        model grid whose size is a multiple of 40).
    """

    def __init__(self, dataset: MeasuredDataset, steps: int = 360, alpha: float = 0.01, max_terms: int = 6,
                 top_k: int = 4, library: Library | None = None, log: Callable[[str], None] | None = None,
                 screen_points: int = 120) -> None:
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 40 or steps % 40:
            raise ValueError(f"steps {steps!r} must be a multiple of 40 (>= 40): the pin-wise signatures are "
                             "shifted by whole pin pitches")
        if not 0 < alpha < 1:
            raise ValueError(f"alpha {alpha!r} must lie in (0, 1)")
        self.ds = dataset
        self.steps = int(steps)
        self.alpha = float(alpha)
        self.max_terms = int(max_terms)
        self.top_k = int(top_k)
        self.lib = library if library is not None else build_library(dataset)
        self.log = log or (lambda s: None)
        self.stride = coarse_stride(self.steps, screen_points)
        self.m = self.steps // self.stride
        self.runs = dataset.runs
        self.base = [r.case_dict() for r in self.runs]
        for b in self.base:
            b.pop("name", None)
        # conditions: runs that share a declared case are solved once
        keys: dict[str, int] = {}
        self.cond_of: list[int] = []
        self.cond_base: list[dict] = []
        for b in self.base:
            k = json.dumps(b, sort_keys=True)
            if k not in keys:
                keys[k] = len(self.cond_base)
                self.cond_base.append(b)
            self.cond_of.append(keys[k])
        self._cond_runs = [[i for i, c in enumerate(self.cond_of) if c == cc] for cc in range(len(self.cond_base))]
        self.y = [r.te_arcsec for r in self.runs]
        self.n = int(sum(v.size for v in self.y))
        self.nc = self.m * len(self.runs)
        gdeg = np.arange(self.m) * (PERIOD_DEG / self.m)
        self.coarse_in_deg = gdeg
        self.coarse_out_deg = gdeg / RATIO
        self.active: list[Active] = []
        self.empirical: list[EmpiricalTerm] = []
        self.emp_coef = np.zeros(0)
        self.sig: dict[str, list[list[np.ndarray] | None]] = {}
        self.notes: list[str] = list(self.lib.notes)
        self._emp_info: dict[EmpiricalTerm, tuple[int, float]] = {}
        self.fit_stats: list[dict] = []

    # ------------------------------------------------------------------ model
    def _case(self, i_cond: int, active: list[tuple[Effect, np.ndarray]]) -> dict:
        errs: list[tuple[str, dict]] = []
        model: dict[str, float] = {}
        for e, p in active:
            errs.extend(e.error_items(p))
            model.update(e.model_options(p))
        return merge_case(self.cond_base[i_cond], errs, model)

    def _phys_grid(self, active: list[tuple[Effect, np.ndarray]], steps: int) -> list[np.ndarray]:
        """Model TE on the grid for each condition."""
        phys = [(e, p) for e, p in active if e.family != "measurement"]
        return [grid_te(self._case(c, phys), steps) for c in range(len(self.cond_base))]

    def _meas(self, active, input_deg: np.ndarray, output_deg: np.ndarray) -> np.ndarray:
        out = np.zeros(np.asarray(input_deg).size)
        for e, p in active:
            if e.family == "measurement":
                out = out + e.reading_arcsec(input_deg, output_deg, p)
        return out

    def predict(self, active: list[tuple[Effect, np.ndarray]]) -> list[np.ndarray]:
        """Model TE (physics + measurement effects) at every sample of every run, arcsec.

        The physics is solved exactly at the readings (:func:`rvcalib.forward.te_at`, one solve per
        run condition over the union of its runs' readings), not interpolated from the model grid:
        the TE has kinks and crank-order content that no practical grid resolves.
        """
        phys = [(e, p) for e, p in active if e.family != "measurement"]
        out: list[np.ndarray] = [np.empty(0)] * len(self.runs)
        for c, members in enumerate(self._cond_runs):
            x = np.concatenate([self.runs[i].input_deg for i in members])
            te = te_at(self._case(c, phys), x)
            j = 0
            for i in members:
                r = self.runs[i]
                out[i] = te[j:j + r.input_deg.size] + self._meas(active, r.input_deg, r.output_deg)
                j += r.input_deg.size
        return out

    def predict_grid(self, active, ms: int | None = None) -> list[np.ndarray]:
        """Model TE at the points of an ``ms``-point grid (default the coarse grid) for every run,
        solved on that grid (``ms`` divides the coarse grid)."""
        ms = self.m if ms is None else int(ms)
        g = self._phys_grid(active, ms)
        sub = self.m // ms
        meas = self._meas(active, self.coarse_in_deg[::sub], self.coarse_out_deg[::sub])
        return [g[self.cond_of[i]] + meas for i in range(len(self.runs))]

    def _sub_idx(self, ms: int) -> np.ndarray:
        """Indices of an ``ms``-point grid's points in the concatenated coarse vector."""
        sub = self.m // ms
        return np.concatenate([i * self.m + np.arange(0, self.m, sub) for i in range(len(self.runs))])

    def _emp_matrix(self, terms: list[EmpiricalTerm], coarse: bool = False) -> np.ndarray | None:
        if not terms:
            return None
        blocks = []
        for r in self.runs:
            th = np.radians(self.coarse_out_deg) if coarse else np.radians(r.input_deg / RATIO)
            blocks.append(np.column_stack([t.columns(th, r.direction) for t in terms]))
        return np.vstack(blocks)

    def _pairs(self, active: list[Active] | None = None) -> list[tuple[Effect, np.ndarray]]:
        return [(a.effect, a.p) for a in (self.active if active is None else active)]

    def full_residual(self, active_pairs, terms: list[EmpiricalTerm]) -> tuple[np.ndarray, np.ndarray]:
        """Concatenated residual after projecting out the empirical terms, and their coefficients."""
        pred = self.predict(active_pairs)
        r = np.concatenate([y - p for y, p in zip(self.y, pred)])
        E = self._emp_matrix(terms)
        if E is None:
            return r, np.zeros(0)
        coef, *_ = np.linalg.lstsq(E, r, rcond=None)
        return r - E @ coef, coef

    def split(self, v: np.ndarray) -> list[np.ndarray]:
        """Split a concatenated per-sample vector into runs."""
        out, i = [], 0
        for y in self.y:
            out.append(v[i:i + y.size])
            i += y.size
        return out

    # ------------------------------------------------------------------ screening signatures
    def _ms(self, e: Effect) -> int:
        """Screening grid points of an effect (a multiple of 40 that divides the coarse grid)."""
        ms = e.screen_steps or self.m
        return ms if (ms < self.m and self.m % ms == 0 and ms % 40 == 0) else self.m

    def screening_signatures(self) -> None:
        """Solve every template candidate at its trial values on its screening grid, per condition."""
        t0 = time.perf_counter()
        base: dict[int, list[np.ndarray]] = {}
        for e in self.lib.templates():
            if e.expensive:
                continue  # solved on demand (see _ensure_expensive)
            ms = self._ms(e)
            if ms not in base:
                base[ms] = [grid_te(b, ms) for b in self.cond_base]
            sigs: list[list[np.ndarray] | None] = []
            for p in trial_points(e):
                try:
                    sigs.append([grid_te(self._case(c, [(e, p)]), ms) - base[ms][c]
                                 for c in range(len(self.cond_base))])
                except ModelEvaluationError:
                    sigs.append(None)
            self.sig[e.name] = sigs
        self.log(f"screening signatures: {len(self.sig)} candidates x {len(self.cond_base)} conditions on "
                 f"{self.m} points in {time.perf_counter() - t0:.1f} s")

    def _ensure_expensive(self, rc: np.ndarray, P) -> None:
        """Solve the screening signatures of the expensive candidates (cam-bearing clearance) when the
        residual has a significant offset or direction-dependent offset (p < 0.01): a clearance
        always shows as lost motion far larger than its ripple, so without one it cannot be there."""
        todo = [e for e in self.lib.templates() if e.expensive and e.name not in self.sig]
        if not todo:
            return
        cols = [np.ones(self.nc)]
        if len({r.direction for r in self.runs}) > 1:
            cols.append(np.concatenate([np.full(self.m, float(r.direction)) for r in self.runs]))
        A = np.column_stack([P(c) for c in cols])
        rss0 = float(rc @ rc)
        c, *_ = np.linalg.lstsq(A, rc, rcond=None)
        rss1 = float(np.sum((rc - A @ c) ** 2))
        _, pv = _ftest(rss0, rss1, A.shape[1], self.nc, self._p_cur() + A.shape[1])
        if pv >= 0.01:
            return
        t0 = time.perf_counter()
        for e in todo:
            ms = self._ms(e)
            base = [grid_te(b, ms) for b in self.cond_base]
            sigs: list[list[np.ndarray] | None] = []
            for p in trial_points(e):
                try:
                    sigs.append([grid_te(self._case(c, [(e, p)]), ms) - base[c] for c in range(len(self.cond_base))])
                except ModelEvaluationError:
                    sigs.append(None)
            self.sig[e.name] = sigs
        self.log(f"screening signatures of {', '.join(e.name for e in todo)} (the residual has an offset) in "
                 f"{time.perf_counter() - t0:.1f} s")

    def _sig_stack(self, e: Effect, j: int, roll_deg: float = 0.0) -> np.ndarray | None:
        """Trial j's signature of effect e over all runs' screening points, rotated by ``roll_deg``
        of output angle (a whole number of grid steps)."""
        src = self.sig.get(e.template or e.name)
        if e.trial_map is not None:
            j = e.trial_map[j]
        if src is None or src[j] is None:
            return None
        s = src[j]
        ms = s[0].size
        roll = int(round(roll_deg / 360.0 * ms))
        return np.concatenate([np.roll(s[self.cond_of[i]], roll) for i in range(len(self.runs))])

    def _options(self, e: Effect, meas_cols: np.ndarray | None) -> list[tuple[np.ndarray, bool, Callable]]:
        """Screening options of an effect: (columns, nonneg, coefficients -> parameters)."""
        s = e.scale
        opts: list[tuple[np.ndarray, bool, Callable]] = []
        if e.screen in ("two_sided", "one_sided"):
            for j, sign in enumerate([1.0, -1.0] if e.screen == "two_sided" else [1.0]):
                S = self._sig_stack(e, j, e.shift_deg)
                if S is not None:
                    opts.append((S[:, None], True, lambda c, sign=sign: np.array([sign * c[0] * s])))
        elif e.screen == "vector4":
            S = [self._sig_stack(e, j) for j in range(4)]
            u = [np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.array([-1.0, 0.0]), np.array([0.0, -1.0])]
            for q in range(4):
                a, b = S[q], S[(q + 1) % 4]
                if a is None or b is None:
                    continue
                opts.append((np.column_stack([a, b]), True,
                             lambda c, q=q: s * (c[0] * u[q] + c[1] * u[(q + 1) % 4])))
        elif e.screen == "angle_shift":
            ms = self._ms(e)
            for j in range(int(round(ms * e.angle_period_deg / 360.0))):
                ang = 360.0 * j / ms
                S = self._sig_stack(e, 0, ang)
                if S is None:
                    continue
                opts.append((S[:, None], True, lambda c, ang=ang: polar_to_xy(c[0] * s, ang, e.polar_factor)))
        elif e.screen == "analytic" and meas_cols is not None:
            opts.append((meas_cols, False, lambda c: np.array(c[:2], dtype=float)))
        return opts

    @staticmethod
    def _fit_option(r: np.ndarray, A: np.ndarray, nonneg: bool) -> tuple[float, np.ndarray]:
        if A.shape[1] == 1:
            aa = float(A[:, 0] @ A[:, 0])
            if aa <= 0:
                return float(r @ r), np.zeros(1)
            c = float(A[:, 0] @ r) / aa
            if nonneg and c < 0:
                c = 0.0
            res = r - c * A[:, 0]
            return float(res @ res), np.array([c])
        if nonneg:
            c, rn = optimize.nnls(A, r)
            return float(rn ** 2), c
        c, *_ = np.linalg.lstsq(A, r, rcond=None)
        res = r - A @ c
        return float(res @ res), c

    def _group(self, ms: int, rc_cat: np.ndarray, Ec: np.ndarray | None):
        """Residual, projector and residual sum of squares restricted to an ``ms``-point grid."""
        idx = self._sub_idx(ms)
        Pg = _proj(None if Ec is None else Ec[idx])
        r = Pg(rc_cat[idx])
        return r, Pg, float(r @ r)

    def rank(self, rc_cat: np.ndarray, Ec: np.ndarray | None, r_full: np.ndarray | None = None) -> list[dict]:
        """Screen every candidate against the coarse residual (``rc_cat``: unprojected, concatenated).

        Measurement effects (analytic) are fitted to the full residual ``r_full`` (projected) when
        given: on the coarse grid the input encoder's order 121 aliases onto low orders.

        Returns dicts ``effect, explained, p`` sorted by explained fraction (descending).
        """
        groups: dict[int, tuple] = {}
        active_names = {a.effect.name for a in self.active}
        out = []
        for e in self.lib:
            if e.name in active_names:
                continue
            ms = self._ms(e)
            if ms not in groups:
                groups[ms] = self._group(ms, rc_cat, Ec)
            r, Pg, rss0 = groups[ms]
            if rss0 <= 0:
                continue
            meas = None
            if e.screen == "analytic":
                sub = self.m // ms
                meas = np.vstack([e.basis(self.coarse_in_deg[::sub], self.coarse_out_deg[::sub]) for _ in self.runs])
                if r_full is not None:
                    expl, c = self._analytic_full(e, r_full)
                    cols = np.column_stack([Pg(meas[:, k]) for k in range(2)]) if ms == self.m else None
                    out.append({"effect": e, "explained": expl, "p": c, "cols": cols,
                                "fit": None if cols is None else cols @ c})
                    continue
            best = None
            for A, nonneg, to_p in self._options(e, meas):
                A = np.column_stack([Pg(A[:, k]) for k in range(A.shape[1])])
                rss, c = self._fit_option(r, A, nonneg)
                if best is None or rss < best[0]:
                    best = (rss, to_p(c), A, A @ c)
            if best is None:
                continue
            out.append({"effect": e, "explained": 1.0 - best[0] / rss0, "p": best[1],
                        "cols": best[2] if ms == self.m else None, "fit": best[3] if ms == self.m else None})
        # ties (e.g. pins 20 apart, whose TE signatures coincide) go to the library order
        order = {e.name: i for i, e in enumerate(self.lib)}
        out.sort(key=lambda d: (-round(d["explained"], 6), order[d["effect"].name]))
        return out

    def lookahead(self, ranking: list[dict], rc: np.ndarray, n_top: int = 12) -> list[dict]:
        """Re-order the ranking by what each candidate explains together with its best partner.

        Greedy forward selection can pick one effect whose signature mimics the sum of two others
        (a cam-bearing clearance for a cam error plus a torsional compliance). For the ``n_top``
        best candidates (one per family) the best pair of their screening signatures is fitted
        jointly (linear least squares on the coarse grid). If the best pair leaves less than half
        the residual the best single candidate leaves, candidates are ordered by the explained
        fraction of the best pair they belong to (rounded to 1e-3), then by their own; otherwise
        the order stays. Each entry gets ``pair_explained`` and ``partner``.
        """
        fam_seen: set[str] = set()
        top: list[dict] = []
        for d in ranking:
            fam = d["effect"].template or d["effect"].name
            if fam in fam_seen or d.get("cols") is None:
                continue
            fam_seen.add(fam)
            top.append(d)
            if len(top) >= n_top:
                break
        rss0 = float(rc @ rc)
        if rss0 <= 0 or len(top) < 2:
            return ranking
        for d in ranking:
            d["pair_explained"] = d["explained"]
            d["partner"] = None
        for i in range(len(top)):
            for j in range(i + 1, len(top)):
                A = np.column_stack([top[i]["cols"], top[j]["cols"]])
                c, *_ = np.linalg.lstsq(A, rc, rcond=None)
                res = rc - A @ c
                expl = 1.0 - float(res @ res) / rss0
                for a, b in ((top[i], top[j]), (top[j], top[i])):
                    if expl > a["pair_explained"]:
                        a["pair_explained"] = expl
                        a["partner"] = b["effect"].name
        order = {id(d): k for k, d in enumerate(ranking)}
        best_single = max(d["explained"] for d in ranking)
        best_pair = max(d["pair_explained"] for d in ranking)
        if 1.0 - best_pair > 0.5 * (1.0 - best_single):
            return ranking  # no pair explains much more than the best single candidate: keep the order
        return sorted(ranking, key=lambda d: (-round(d["pair_explained"], 3), -round(d["explained"], 6),
                                              order[id(d)]))

    def _analytic_full(self, e: Effect, r_full: np.ndarray) -> tuple[float, np.ndarray]:
        """Explained fraction and components of a measurement effect fitted to the full residual."""
        P = _proj(self._emp_matrix(self.empirical))
        A = np.vstack([e.basis(r.input_deg, r.output_deg) for r in self.runs])
        A = np.column_stack([P(A[:, k]) for k in range(A.shape[1])])
        c, *_ = np.linalg.lstsq(A, r_full, rcond=None)
        res = r_full - A @ c
        rss0 = float(r_full @ r_full)
        return (1.0 - float(res @ res) / rss0 if rss0 > 0 else 0.0), c

    def harmonic_rank(self, rc: np.ndarray, P) -> list[dict]:
        """Best harmonic-only terms (one order, a constant or a direction-signed constant)."""
        rss0 = float(rc @ rc)
        have = set(self.empirical)
        cands = [EmpiricalTerm("offset"), EmpiricalTerm("direction_offset")]
        cands += [EmpiricalTerm("harmonic", k) for k in range(1, self.m // 2)]
        out = []
        th = np.radians(self.coarse_out_deg)
        for t in cands:
            if t in have:
                continue
            if t.kind == "direction_offset" and len({r.direction for r in self.runs}) < 2:
                continue
            A = np.vstack([t.columns(th, r.direction) for r in self.runs])
            A = np.column_stack([P(A[:, k]) for k in range(A.shape[1])])
            if np.linalg.norm(A) < 1e-12:
                continue
            rss, _ = self._fit_option(rc, A, False)
            out.append({"term": t, "rss": rss, "explained": 1.0 - rss / rss0, "cols": A})
        out.sort(key=lambda d: d["rss"])
        return out

    # ------------------------------------------------------------------ nonlinear fits
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
            A = np.vstack([e.basis(self.coarse_in_deg[::sub], self.coarse_out_deg[::sub]) for _ in self.runs])
            A = np.column_stack([Pg(A[:, k]) for k in range(2)])
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
                fun(x0)
                break
            except ModelEvaluationError:
                x0 = x0 * 0.5
        else:
            return 0.0, p0
        got = self._chord_fit(fun, x0, lo, hi, max_iter=3, h=0.02, xtol=1e-3)
        if got is None:
            return 0.0, p0
        x, r, _, _ = got
        return 1.0 - float(r @ r) / rss0, x * scale

    @staticmethod
    def _fd_jac(fun, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, h: float = 0.02,
                f0: np.ndarray | None = None, central: bool = False) -> np.ndarray:
        f0 = fun(x) if (f0 is None and not central) else f0
        cols = []
        for j in range(x.size):
            step = h * max(1.0, abs(x[j]))
            xp = x.copy()
            xm = x.copy()
            if central and x[j] - step >= lo[j] and x[j] + step <= hi[j]:
                xp[j] += step
                xm[j] -= step
                cols.append((fun(xp) - fun(xm)) / (2 * step))
                continue
            if f0 is None:
                f0 = fun(x)
            if x[j] + step <= hi[j]:
                xp[j] += step
                try:
                    cols.append((fun(xp) - f0) / step)
                    continue
                except ModelEvaluationError:
                    pass
            xm[j] -= step
            cols.append((f0 - fun(xm)) / step)
        return np.column_stack(cols)

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
        P = _proj(self._emp_matrix(terms))

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
        got = self._chord_fit(fun, x0, lo, hi)
        if got is not None:
            x, r, J, nfev = got
            self.fit_stats.append({"effects": [e.name for e in effects], "method": "chord", "nfev": nfev})
            return [p for _, p in unpack(x)], float(r @ r), x, fun, J
        sol = optimize.least_squares(fun, x0, jac=lambda x: self._fd_jac(fun, x, lo, hi, h=0.01), bounds=(lo, hi),
                                     method="trf", x_scale=1.0, max_nfev=max_nfev, xtol=1e-5, ftol=1e-7)
        self.fit_stats.append({"effects": [e.name for e in effects], "method": "trf", "nfev": int(sol.nfev),
                               "njev": int(sol.njev or 0), "status": int(sol.status)})
        params = [p for _, p in unpack(sol.x)]
        return params, float(2.0 * sol.cost), sol.x, fun, sol.jac

    def _chord_fit(self, fun, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, max_iter: int = 8,
                   h: float = 0.01, xtol: float = 1e-3):
        """Gauss-Newton with a Jacobian kept while it predicts the decrease well (chord method):
        the start is already the coarse-grid estimate, so a few full-grid solves suffice.
        Returns (x, residual, Jacobian, solves) or None if no decrease could be made."""
        try:
            r = fun(x0)
            J = self._fd_jac(fun, x0, lo, hi, h=h, f0=r)
        except ModelEvaluationError:
            return None
        nfev = 1 + x0.size
        x, rss = x0.copy(), float(r @ r)
        for _ in range(max_iter):
            dx, *_ = np.linalg.lstsq(J, -r, rcond=None)
            pred = rss - float(np.sum((r + J @ dx) ** 2))
            alpha, accepted = 1.0, False
            for _ in range(5):
                xn = np.clip(x + alpha * dx, lo, hi)
                try:
                    rn = fun(xn)
                    nfev += 1
                except ModelEvaluationError:
                    alpha *= 0.5
                    continue
                rssn = float(rn @ rn)
                if rssn <= rss:
                    accepted = True
                    break
                alpha *= 0.5
            if not accepted:
                return (x, r, J, nfev) if nfev > 1 + x0.size else None
            step = float(np.max(np.abs(xn - x)))
            act = rss - rssn
            x, r, rss = xn, rn, rssn
            if step < xtol or act <= 1e-6 * rss:
                break
            if act < 0.5 * alpha * pred:  # the linearisation is off: take a new Jacobian here
                try:
                    J = self._fd_jac(fun, x, lo, hi, h=h, f0=r)
                except ModelEvaluationError:
                    break
                nfev += x.size
        return x, r, J, nfev

    # ------------------------------------------------------------------ the loop
    def run(self) -> CalibrationResult:
        """Run the loop and return the result."""
        t_start = time.perf_counter()
        try:
            r0 = [y - p for y, p in zip(self.y, self.predict([]))]
        except ModelEvaluationError as exc:
            raise ValueError(f"the declared errors of the dataset cannot be evaluated by rvdyn: {exc}") from None
        before = diagnose(self.ds, r0)
        self.log(f"declared model: residual RMS {before.rms:.4g} arcsec over {self.n} samples")
        self.screening_signatures()
        iterations: list[dict] = []
        r_full, self.emp_coef = self.full_residual(self._pairs(), self.empirical)
        self.rss_full = float(r_full @ r_full)
        n_hyp = len(self.lib) + (self.m // 2 + 1)
        self.thr = thr = self.alpha / n_hyp
        it = 0
        tried: set[str] = set()
        while len(self.active) + len(self.empirical) < self.max_terms:
            it += 1
            t_it = time.perf_counter()
            p_cur = self._p_cur()
            # the residual at the readings (the model solved there) taken to the coarse grid: where the
            # readings are off the grid only this smooth remainder is interpolated, not the TE's kinks
            Ec = self._emp_matrix(self.empirical, coarse=True)
            rc_raw = [_coarse_values(r, y - q, self.m)
                      for r, y, q in zip(self.runs, self.y, self.predict(self._pairs()))]
            rc_cat = np.concatenate(rc_raw)
            Pc = _proj(Ec)
            rc = Pc(rc_cat)
            rss0c = float(rc @ rc)
            bic0 = _bic(rss0c, self.nc, p_cur)
            self._ensure_expensive(rc, Pc)
            ranking = [d for d in self.rank(rc_cat, Ec, r_full) if d["effect"].name not in tried]
            harms = self.harmonic_rank(rc, Pc)
            ranking = self.lookahead(ranking, rc)
            log: dict[str, Any] = {"iteration": it, "rms_arcsec": math.sqrt(self.rss_full / self.n),
                                   "n_coarse": self.nc, "hypotheses": n_hyp, "threshold_p": thr,
                                   "ranking": [{"name": d["effect"].name, "explained_fraction": d["explained"],
                                                "pair_explained_fraction": d.get("pair_explained"),
                                                "partner": d.get("partner"),
                                                "estimate": np.asarray(d["p"]).tolist()} for d in ranking[:10]]}

            def tests(explained: float, k: int, extra: int = 0) -> tuple[float, float, float]:
                rss1 = rss0c * max(1.0 - explained, 1e-12)
                F, pv = _ftest(rss0c, rss1, k, self.nc, p_cur + k + extra)
                return F, pv, _bic(rss1, self.nc, p_cur + k + extra) - bic0

            refined = self._validate(ranking, rc_raw, Ec, lambda e: tests(e, 1)[0], thr, p_cur)
            log["seconds_validation"] = time.perf_counter() - t_it
            log["validated"] = [{"name": d["effect"].name, "explained_fraction": d["explained"],
                                 "pair_explained_fraction": d["pair"], "partner": d["partner"],
                                 "estimate": np.asarray(d["p"]).tolist()} for d in refined]
            best = refined[0] if refined else None
            hbest = harms[0] if harms else None
            Fp, pp, dbp = tests(best["explained"], best["effect"].n_params) if best else (0.0, 1.0, math.inf)
            Fh, ph, dbh = tests(hbest["explained"], hbest["term"].n_cols) if hbest else (0.0, 1.0, math.inf)
            sig_p = pp < thr and dbp < 0
            sig_h = ph < thr and dbh < 0
            # encompassing test: does the physical candidate explain what the best harmonic-only model
            # cannot (then it is physical), or only a part of what the harmonic explains?
            phys_adds, harm_adds = True, False
            if best is not None and hbest is not None and best.get("cols") is not None:
                A = np.column_stack([best["cols"], hbest["cols"]])
                cj, *_ = np.linalg.lstsq(A, rc, rcond=None)
                rss_j = float(np.sum((rc - A @ cj) ** 2))
                kp, kh = best["effect"].n_params, hbest["term"].n_cols
                rss_p_lin = rss0c * (1.0 - best["screen_explained"])
                dof = max(1, self.nc - p_cur - kp - kh)
                _, p_pa = _ftest(hbest["rss"], rss_j, kp, self.nc, p_cur + kp + kh)
                _, p_ha = _ftest(min(rss_p_lin, rss0c * (1.0 - best["explained"])), rss_j, kh, self.nc,
                                 p_cur + kp + kh)
                phys_adds, harm_adds = p_pa < thr, p_ha < thr
                log["encompassing"] = {"physical_adds_to_harmonic_p": p_pa, "harmonic_adds_to_physical_p": p_ha,
                                       "dof": dof}
            elif best is not None and hbest is not None:
                phys_adds = not (dbh < dbp - HARMONIC_BIC_MARGIN)
                harm_adds = not phys_adds
            log["physical_best"] = None if best is None else {
                "name": best["effect"].name, "F": Fp, "p": pp, "delta_bic": dbp,
                "explained_fraction": best["explained"]}
            log["harmonic_best"] = None if hbest is None else {
                "label": hbest["term"].label, "F": Fh, "p": ph, "delta_bic": dbh,
                "explained_fraction": hbest["explained"]}
            # a constant (or direction-signed constant) that each adds to the other with the physical
            # candidate goes first when it is clearly better by BIC: many library effects (pin circle
            # diameter, pin radius, disc phase, clearances) shift the whole curve, so a constant such as
            # an encoder zero offset is otherwise absorbed by a mixture of them. Harmonics keep the rule
            # above (physical first when it adds), as physical signatures span several orders.
            harm_first = (sig_h and harm_adds and hbest["term"].kind != "harmonic"
                          and dbh < dbp - HARMONIC_BIC_MARGIN)
            dec = "stop"
            if sig_p and (phys_adds or not harm_adds) and not harm_first:
                dec = "physical"
            elif sig_h:
                dec = "empirical"
            if dec == "physical":
                ok, msg = self._add_physical(best, ranking, r_full, it, log)
                log["decision"] = msg
                if not ok:
                    tried.add(best["effect"].name)
                    dec = "retry" if len(tried) < 3 else "stop"
            elif dec == "empirical":
                ok, msg = self._add_empirical(hbest["term"], it, log)
                log["decision"] = msg
                if not ok:
                    dec = "stop"
            else:
                log["decision"] = "stop: no candidate passes the F test and the BIC"
            r_full, self.emp_coef = self.full_residual(self._pairs(), self.empirical)
            self.rss_full = float(r_full @ r_full)
            log["seconds"] = time.perf_counter() - t_it
            iterations.append(log)
            self.log(f"iteration {it}: {log['decision']} (RMS {math.sqrt(self.rss_full / self.n):.4g} arcsec, "
                     f"{log['seconds']:.1f} s)")
            if dec == "stop":
                break
        if self.active:
            r_full, _ = self.full_residual(self._pairs(), self.empirical)
            removed = self._backward([a.effect for a in self.active], np.zeros(0), np.zeros((0, 0)),
                                     float(r_full @ r_full), include_last=True)
            if removed:
                iterations.append({"iteration": len(iterations) + 1,
                                   "decision": "removed " + ", ".join(removed) + ": not needed by the final joint fit"})
        self._drop_empirical(iterations)
        return self._finish(r0, before, iterations, t_start)

    def _p_cur(self) -> int:
        return sum(a.effect.n_params for a in self.active) + sum(t.n_cols for t in self.empirical)

    def _validate(self, ranking: list[dict], rc_raw, Ec, F_of, thr: float, p_cur: int) -> list[dict]:
        """Re-fit the leading candidates through the nonlinear model (one per family; candidates
        with the signature of one already validated are skipped)."""
        refined: list[dict] = []
        if not ranking:
            return refined
        F_crit = float(stats.f.isf(thr, 1, max(1, self.nc - p_cur - 1)))
        best_expl = max(d["explained"] for d in ranking)
        if F_of(best_expl) < 0.5 * F_crit:
            return refined
        seen: set[str] = set()
        fits: list[np.ndarray] = []
        for d in ranking:
            fam = d["effect"].template or d["effect"].name
            if fam in seen:
                continue
            if len(refined) >= self.top_k:
                break
            if d["explained"] < 0.5 * best_expl and d.get("pair_explained", 0.0) < best_expl:
                continue
            if d["effect"].expensive and d is not ranking[0]:
                continue  # expensive to solve: validated only when it ranks first
            f = d.get("fit")
            u = None
            if f is not None and np.linalg.norm(f) > 0:
                u = f / np.linalg.norm(f)
                if any(abs(float(u @ v)) > 0.9999 for v in fits):
                    continue  # the same signature as a candidate already validated (mirror instances)
            if u is not None:
                fits.append(u)
            seen.add(fam)
            if d["effect"].family == "measurement":
                expl, p = d["explained"], d["p"]
            else:
                expl, p = self.refine_coarse(d["effect"], d["p"], rc_raw, Ec)
            refined.append({"effect": d["effect"], "explained": expl, "p": p, "screen_explained": d["explained"],
                            "pair": max(d.get("pair_explained", d["explained"]), expl),
                            "partner": d.get("partner"), "cols": d.get("cols"), "fit": d.get("fit"),
                            "entry": d})
        # the validated candidate of the best pair is preferred (ties within 1e-3 by its own fit)
        refined.sort(key=lambda d: (-round(d["pair"], 3), -d["explained"]))
        if refined and refined[0]["effect"].expensive and self._ms(refined[0]["effect"]) < self.m:
            # judged on a sparse subset so far: re-validate on the full coarse grid like the others
            d = refined[0]
            d["explained"], d["p"] = self.refine_coarse(d["effect"], d["p"], rc_raw, Ec, ms=self.m)
            d["pair"] = d["explained"]
            refined.sort(key=lambda d: (-round(d["pair"], 3), -d["explained"]))
        return refined

    def _add_physical(self, best: dict, ranking: list[dict], r_full: np.ndarray, it: int,
                      log: dict) -> tuple[bool, str]:
        """Joint nonlinear fit with the new effect, confirmation on all samples, backward elimination."""
        e = best["effect"]
        thr = self.thr
        p_cur = self._p_cur()
        effects = [a.effect for a in self.active] + [e]
        p0 = [a.p for a in self.active] + [np.asarray(best["p"], dtype=float)]
        t_fit = time.perf_counter()
        try:
            params, rss1, x, _, jac = self.fit_full(effects, p0, self.empirical)
        except ModelEvaluationError as exc:
            log["full_fit_error"] = str(exc)
            return False, f"{e.name} could not be fitted ({exc})"
        log["seconds_full_fit"] = time.perf_counter() - t_fit
        pt = p_cur + e.n_params
        F, pv = _ftest(self.rss_full, rss1, e.n_params, self.n, pt)
        dbic = _bic(rss1, self.n, pt) - _bic(self.rss_full, self.n, p_cur)
        log["full"] = {"F": F, "p": pv, "delta_bic": dbic, "rss": rss1}
        if not (pv < thr and dbic < 0):
            return False, f"{e.name} did not pass on all samples (p {pv:.3g}, dBIC {dbic:.3g})"
        sigma2 = self._noise2(r_full)
        alts = self._alternatives(best, ranking, sigma2)
        info = {"explained_fraction": 1.0 - rss1 / self.rss_full, "F": F, "p_value": pv, "delta_bic": dbic,
                "alternatives": alts}
        for a, p in zip(self.active, params[:-1]):
            a.p = p
        self.active.append(Active(e, params[-1], it, info=info))
        msg = f"added {e.name}"
        removed = self._backward(effects, x, jac, rss1)
        if removed:
            msg += "; removed " + ", ".join(removed) + " (no longer significant)"
            log["removed"] = removed
        return True, msg

    def _backward(self, effects: list[Effect], x: np.ndarray, jac: np.ndarray, rss: float,
                  include_last: bool = False) -> list[str]:
        """Drop effects that the joint fit no longer needs.

        For each effect (the newest only if ``include_last``): the residual with its parameters set to
        zero and the others kept is an upper bound of the residual without it; if even that increase
        is not significant it is removed; if the increase is significant but not overwhelmingly so
        (F below 100 times the critical value) or the estimate is small (|p| < 0.1 typical size), the
        others are refitted without it and the F test decides. Returns the removed names.
        """
        removed: list[str] = []
        changed = True
        while changed and self.active:
            changed = False
            p_tot = self._p_cur()
            dof = max(1, self.n - p_tot)
            F_crit = float(stats.f.isf(self.thr, 1, dof))
            pool = self.active if include_last else self.active[:-1]
            for a in sorted(pool, key=lambda a: float(np.linalg.norm(a.p)) / a.effect.scale):
                k = a.effect.n_params
                others = [(b.effect, b.p) for b in self.active if b is not a]
                try:
                    r0, _ = self.full_residual(others, self.empirical)
                    rss_fixed = float(r0 @ r0)
                except ModelEvaluationError:
                    rss_fixed = math.inf
                F_fixed, p_fixed = _ftest(rss_fixed, rss, k, self.n, p_tot)
                small = float(np.linalg.norm(a.p)) < 0.1 * a.effect.scale
                if p_fixed <= self.thr and F_fixed >= 100 * F_crit and not small:
                    continue
                keep = [b for b in self.active if b is not a]
                if p_fixed > self.thr:
                    params, rss_w = [b.p for b in keep], rss_fixed
                    if keep:
                        try:
                            params, rss_w, _, _, _ = self.fit_full([b.effect for b in keep], [b.p for b in keep],
                                                                   self.empirical)
                        except ModelEvaluationError:
                            params, rss_w = [b.p for b in keep], rss_fixed
                else:
                    try:
                        params, rss_w, _, _, _ = self.fit_full([b.effect for b in keep], [b.p for b in keep],
                                                               self.empirical) if keep else ([], rss_fixed, None, None, None)
                    except ModelEvaluationError:
                        continue
                    _, pv = _ftest(rss_w, rss, k, self.n, p_tot)
                    if pv <= self.thr:
                        continue
                for b, p in zip(keep, params):
                    b.p = p
                self.active = keep
                rss = rss_w
                removed.append(a.effect.name)
                changed = True
                break
        return removed

    def _add_empirical(self, t: EmpiricalTerm, it: int, log: dict) -> tuple[bool, str]:
        """Absorb an unexplained harmonic (refitting the physical parameters with it)."""
        thr = self.thr
        p_cur = self._p_cur()
        terms = self.empirical + [t]
        effects = [a.effect for a in self.active]
        if effects:
            params, rss1, _, _, _ = self.fit_full(effects, [a.p for a in self.active], terms)
        else:
            params, rss1 = [], float(np.sum(self.full_residual([], terms)[0] ** 2))
        pt = p_cur + t.n_cols
        F, pv = _ftest(self.rss_full, rss1, t.n_cols, self.n, pt)
        dbic = _bic(rss1, self.n, pt) - _bic(self.rss_full, self.n, p_cur)
        log["full"] = {"F": F, "p": pv, "delta_bic": dbic, "rss": rss1}
        if not (pv < thr and dbic < 0):
            return False, "stop: the harmonic term did not pass on all samples"
        for a, p in zip(self.active, params):
            a.p = p
        self.empirical.append(t)
        self._emp_info[t] = (it, 1.0 - rss1 / self.rss_full)
        return True, (f"absorbed {t.label}: no physical candidate explains it better than the harmonic-only "
                      "model (outside the library)")

    def _drop_empirical(self, iterations: list[dict]) -> None:
        """Drop empirical terms that later physical effects made insignificant (linear F test)."""
        changed = True
        while changed and self.empirical:
            changed = False
            r, _ = self.full_residual(self._pairs(), self.empirical)
            rss = float(r @ r)
            for t in list(self.empirical):
                rest = [u for u in self.empirical if u != t]
                r2, _ = self.full_residual(self._pairs(), rest)
                _, pv = _ftest(float(r2 @ r2), rss, t.n_cols, self.n, self._p_cur())
                if pv > self.thr:
                    self.empirical = rest
                    self._emp_info.pop(t, None)
                    iterations.append({"iteration": len(iterations) + 1, "decision":
                                       f"removed {t.label}: no longer significant (p {pv:.3g})"})
                    changed = True
                    break

    def _noise2(self, r_full: np.ndarray) -> float:
        """Noise variance estimate (second differences of the current residual, pooled), arcsec^2."""
        parts = self.split(r_full)
        v = [noise_estimate(p) ** 2 * p.size for p in parts if p.size >= 5]
        return float(sum(v) / max(1, sum(p.size for p in parts)))

    def _alternatives(self, best: dict, ranking: list[dict], sigma2: float) -> list[str]:
        """Candidates whose signature reproduces the winner's fitted signature within the noise:
        ``|fit_w - S_c b|^2 * n / n_coarse / sigma^2 < 3.84`` (chi-square, 95 %). Such candidates
        cannot be told apart by these data (e.g. pins 20 apart, cam errors of crank 0 disc 1 and
        crank 1 disc 0)."""
        fw = best.get("fit")
        if fw is None or sigma2 <= 0:
            return []
        out = []
        we = best["effect"]
        for d in ranking:
            if d["effect"].name == we.name or d.get("cols") is None:
                continue
            if d["effect"].family == "measurement" or we.family == "measurement":
                # judged on all samples: on the coarse grid the input encoder's order 121 aliases
                if d["effect"].family == "measurement" and we.family == "measurement":
                    P = _proj(self._emp_matrix(self.empirical))
                    Aw = np.vstack([we.basis(r.input_deg, r.output_deg) for r in self.runs])
                    Ac = np.vstack([d["effect"].basis(r.input_deg, r.output_deg) for r in self.runs])
                    Aw = np.column_stack([P(Aw[:, k]) for k in range(2)])
                    Ac = np.column_stack([P(Ac[:, k]) for k in range(2)])
                    fwf = Aw @ np.asarray(best["p"], dtype=float)
                    b, *_ = np.linalg.lstsq(Ac, fwf, rcond=None)
                    delta = fwf - Ac @ b
                    if float(delta @ delta) / sigma2 < 3.84:
                        out.append(d["effect"].name)
                continue
            A = d["cols"]
            b, *_ = np.linalg.lstsq(A, fw, rcond=None)
            delta = fw - A @ b
            stat = float(delta @ delta) * (self.n / self.nc) / sigma2
            if stat < 3.84:
                out.append(d["effect"].name)
        return out

    # ------------------------------------------------------------------ wrap up
    def _finish(self, r0, before: Diagnostics, iterations: list[dict], t_start: float) -> CalibrationResult:
        effects = [a.effect for a in self.active]
        n_emp = sum(t.n_cols for t in self.empirical)
        fitted: list[FittedEffect] = []
        if effects:
            scales = np.concatenate([np.full(e.n_params, e.scale) for e in effects])
            lo = np.concatenate([np.array(e.lower) for e in effects]) / scales
            hi = np.concatenate([np.array(e.upper) for e in effects]) / scales
            P = _proj(self._emp_matrix(self.empirical))
            sizes = [e.n_params for e in effects]

            def fun(xs):
                out, i = [], 0
                for e, k in zip(effects, sizes):
                    out.append((e, xs[i:i + k] * e.scale))
                    i += k
                pred = self.predict(out)
                return P(np.concatenate([y - p for y, p in zip(self.y, pred)]))

            x = np.concatenate([a.p for a in self.active]) / scales
            r = fun(x)
            J = self._fd_jac(fun, x, lo, hi, h=0.01, f0=r)
            p_tot = x.size + n_emp
            dof = max(1, self.n - p_tot)
            s2 = float(r @ r) / dof
            try:
                cov_s = s2 * np.linalg.pinv(J.T @ J)
            except np.linalg.LinAlgError:
                cov_s = np.full((x.size, x.size), np.nan)
            cov = cov_s * np.outer(scales, scales)
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
                fitted.append(FittedEffect(
                    e.name, e.key, e.family, e.unit, e.meaning, float(val), float(val - half), float(val + half),
                    angle, se, params, a.iteration, float(a.info.get("explained_fraction", float("nan"))),
                    float(a.info.get("F", float("nan"))), float(a.info.get("p_value", float("nan"))),
                    float(a.info.get("delta_bic", float("nan"))), list(a.info.get("alternatives", []))))
            if rho > 0.2:
                self.notes.append(f"the final residual is autocorrelated (lag-1 {rho:.2f}): the confidence intervals "
                                  f"are widened by {infl:.2f}")
        pairs = self._pairs()
        r_phys = [y - p for y, p in zip(self.y, self.predict(pairs))]
        r_all_cat, coef = self.full_residual(pairs, self.empirical)
        r_all = self.split(r_all_cat)
        unexplained: list[Unexplained] = []
        j = 0
        emp_iter = self._emp_info
        for t in self.empirical:
            c = coef[j:j + t.n_cols]
            j += t.n_cols
            if t.kind == "harmonic":
                amp = float(math.hypot(c[0], c[1]))
                phase = float(math.degrees(math.atan2(-c[1], c[0])))  # a cos(k th) + b sin = A cos(k th + phase)
            else:
                amp, phase = float(c[0]), None
            itn, frac = emp_iter.get(t, (0, float("nan")))
            unexplained.append(Unexplained(t.label, t.kind, t.order, amp, phase, itn, frac, t.note))
        after = diagnose(self.ds, r_all)
        after_phys = diagnose(self.ds, r_phys)
        noise = math.sqrt(sum(noise_estimate(r) ** 2 * r.size for r in r_all) / self.n)
        if not fitted and not unexplained:
            if after.white:
                status = "fits"
                verdict = (f"The declared model fits: no candidate effect is supported, and the residual "
                           f"({after.rms:.3g} arcsec RMS) is white noise at the noise level ({noise:.3g} arcsec).")
            else:
                status = "unexplained"
                dom = ", ".join(f"order {k} ({v:.3g} arcsec)" for k, v in after.runs[0].dominant)
                verdict = (f"No candidate effect is supported, but the residual ({after.rms:.3g} arcsec RMS) is not "
                           f"white (dominant in run {after.runs[0].run}: {dom}).")
        else:
            names = ", ".join(f"{f.name} = {f.value:.4g} {f.unit}" for f in fitted) or "none"
            status = "explained" if not unexplained and after.white else "unexplained"
            verdict = (f"Found {len(fitted)} effect(s): {names}. Residual RMS {before.rms:.3g} -> {after.rms:.3g} "
                       f"arcsec (noise {noise:.3g} arcsec); {'white' if after.white else 'not white'}.")
            if unexplained:
                verdict += " Unexplained (outside the library): " + ", ".join(
                    f"{u.label} {abs(u.amplitude_arcsec):.3g} arcsec" for u in unexplained) + "."
        ramps = [d for d in after.runs
                 if abs(d.ramp_t) > RAMP_T and abs(d.ramp_arcsec) > RAMP_NOISE_FACTOR * noise]
        if ramps:
            status = "unexplained"
            verdict += (" The residual ramps over the record in run(s) " + ", ".join(
                f"{d.run} ({d.ramp_arcsec:+.3g} arcsec, t {d.ramp_t:.1f})" for d in ramps)
                + ": a drift in time or an encoder scale error, not in the library; the effects found may "
                  "partly compensate it.")
        return CalibrationResult(self.ds, fitted, unexplained, before, after, after_phys, r0, r_all, iterations,
                                 status, verdict, noise, self.steps, time.perf_counter() - t_start,
                                 list(self.ds.notes) + self.notes, dict(cache_stats(), fits=self.fit_stats))


def calibrate(dataset: MeasuredDataset, steps: int = 360, alpha: float = 0.01, max_terms: int = 6,
              top_k: int = 4, log: Callable[[str], None] | None = None, screen_points: int = 120) -> CalibrationResult:
    """Close the loop on a measured dataset (see the module docstring).

    Parameters
    ----------
    dataset : MeasuredDataset
        From :func:`rvcalib.dataset.read_dataset`.
    steps : int
        Model grid points per output revolution (a multiple of 40). Records sampled on this grid
        are evaluated without interpolation error.
    alpha : float
        Family-wise significance level.
    max_terms : int
        Largest number of effects plus empirical terms.
    top_k : int
        Candidates validated through the nonlinear model per iteration.
    log : callable or None
        Progress messages.
    screen_points : int
        Largest screening grid, points per output revolution.

    Returns
    -------
    CalibrationResult
    """
    return Calibrator(dataset, steps=steps, alpha=alpha, max_terms=max_terms, top_k=top_k, log=log,
                      screen_points=screen_points).run()
