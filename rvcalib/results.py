"""Records of the loop: the state it carries, the candidates it passes between its stages, and what
it reports.

* state: :class:`Active` (an effect in the model with its parameters), :class:`EmpiricalTerm` (a
  labelled empirical term absorbing unexplained residual);
* candidates (typed records passed from the screening to the selection policy):
  :class:`Candidate` (a library effect screened against the residual), :class:`HarmonicCandidate`
  (a harmonic-only competitor), :class:`Validated` (a candidate refitted through the nonlinear
  model);
* results: :class:`FittedEffect`, :class:`Unexplained`, :class:`CalibrationResult` (the ``--json``
  object, :meth:`CalibrationResult.to_dict`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from rvcalib.dataset import MeasuredDataset
from rvcalib.effects import Effect
from rvcalib.residual import Diagnostics


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
    ``direction_offset`` (``direction * c``). ``factor`` says how it depends on the run: ``common``
    (the same in every run), ``load`` (proportional to the run's load, coefficients per N m) or
    ``direction`` (sign of the run's direction).
    """

    kind: str
    order: int = 0
    factor: str = "common"

    @property
    def label(self) -> str:
        """Human label."""
        suffix = {"common": "", "load": " proportional to the load",
                  "direction": " with the sign of the direction"}[self.factor]
        if self.kind == "harmonic":
            return f"unexplained order-{self.order} harmonic" + suffix
        if self.kind == "offset":
            return "unexplained constant offset" + suffix if self.factor != "common" else "unexplained constant offset"
        return "unexplained direction-dependent offset"

    @property
    def unit(self) -> str:
        """Unit of its coefficients."""
        return "arcsec/(N m)" if self.factor == "load" else "arcsec"

    @property
    def note(self) -> str:
        """What such a term can be, where the data cannot say more (empty for a harmonic)."""
        if self.kind == "offset":
            return ("the same constant in every run, load and direction: a zero offset between the input and "
                    "output encoders, or a rotation of the whole pin housing (all pins), which the TE cannot "
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

    def columns(self, output_rad: np.ndarray, direction: int, load_Nm: float = 0.0) -> np.ndarray:
        """Design columns (n, n_cols) at output angles (rad) of a run (direction, load N m)."""
        f = {"common": 1.0, "load": float(load_Nm), "direction": float(direction)}[self.factor]
        if self.kind == "harmonic":
            k = self.order
            return f * np.column_stack([np.cos(k * output_rad), np.sin(k * output_rad)])
        if self.kind == "offset" and self.factor != "common":
            return np.full((output_rad.size, 1), f)
        if self.kind == "offset":
            return np.ones((output_rad.size, 1))
        return np.full((output_rad.size, 1), float(direction))


# ---------------------------------------------------------------------------------------------
# candidates passed between screening and selection
@dataclass
class Candidate:
    """A library effect screened against the current residual.

    Attributes
    ----------
    effect : Effect
    explained : float
        Fraction of the residual sum of squares its best signature fit removes (screening grid).
    p : ndarray
        Parameters of that fit (actual units).
    cols : ndarray or None
        Its (projected) signature columns on the full screening grid (None for effects screened
        on a sparser grid).
    fit : ndarray or None
        ``cols @ coefficients``: the fitted signature on the screening grid.
    pair_explained : float or None
        Fraction explained by the best pair it belongs to (set by the look-ahead).
    partner : str or None
        The other member of that pair.
    to_p : callable or None
        Coefficients of ``cols`` -> the effect's parameters (sign or quadrant of the best option).
    """

    effect: Effect
    explained: float
    p: np.ndarray
    cols: np.ndarray | None = None
    fit: np.ndarray | None = None
    pair_explained: float | None = None
    partner: str | None = None
    to_p: Callable[[np.ndarray], np.ndarray] | None = None

    @property
    def family_key(self) -> str:
        """Instances that share a screening template count as one family."""
        return self.effect.template or self.effect.name


@dataclass
class HarmonicCandidate:
    """A harmonic-only competitor (one order, a constant or a direction-signed constant)."""

    term: "EmpiricalTerm"
    rss: float
    explained: float
    cols: np.ndarray


@dataclass
class Validated:
    """A candidate refitted through the nonlinear model at the current state.

    Attributes
    ----------
    effect : Effect
    explained : float
        Fraction explained after the nonlinear refit (screening grid).
    p : ndarray
        Refitted parameters.
    screen_explained : float
        Fraction explained by the linear screening.
    pair : float
        Best of the pair fraction and ``explained``.
    partner : str or None
    cols, fit : ndarray or None
        As in :class:`Candidate`.
    entry : Candidate
        The screening record it came from.
    """

    effect: Effect
    explained: float
    p: np.ndarray
    screen_explained: float
    pair: float
    partner: str | None
    cols: np.ndarray | None
    fit: np.ndarray | None
    entry: Candidate


@dataclass
class PoolMember:
    """A member of the joint selection's pool, linearised at the current state: a library effect or
    an empirical term already in the model (which a subset may drop, giving its part back to the
    residual for physical effects to explain).

    Attributes
    ----------
    effect : Effect or None
        None for an empirical term.
    cols : ndarray
        (n_coarse, k) columns of the TE change per unit of its coefficients at the current state
        on the screening grid.
    contribution : ndarray or None
        For a member in the model: its present contribution to the model TE (for an effect the TE
        of the state minus the TE of the state without it); None for a new candidate.
    to_p : callable
        Coefficients of ``cols`` -> the effect's parameters (for an effect in the model: its present
        parameters plus the change).
    active : Active or None
        The model's record of it, if it is in the model.
    entry : Candidate or None
        Its screening record at the current state, if it is a new candidate.
    """

    effect: Effect | None
    cols: np.ndarray
    contribution: np.ndarray | None
    to_p: Callable[[np.ndarray], np.ndarray]
    active: "Active | None" = None
    entry: Candidate | None = None
    term: "EmpiricalTerm | None" = None

    @property
    def name(self) -> str:
        """The effect's name or the empirical term's label."""
        return self.effect.name if self.effect is not None else self.term.label

    @property
    def n_params(self) -> int:
        """Parameters it holds (an effect's components or an empirical term's columns)."""
        return self.effect.n_params if self.effect is not None else self.term.n_cols

    @property
    def in_model(self) -> bool:
        """True for an effect or empirical term in the model now (a new empirical term has no
        contribution yet)."""
        return self.active is not None or (self.term is not None and self.contribution is not None)


@dataclass
class SubsetFit:
    """One subset of the pool fitted jointly by linear least squares at the current state.

    Attributes
    ----------
    members : tuple of int
        Pool indices in the subset.
    dropped : tuple of int
        Pool indices of effects in the model that the subset leaves out (a swap when it also adds).
    n_params : int
        Parameters (effects' components and empirical columns).
    rss : float
        Residual sum of squares on the screening grid.
    bic, aic : float
        Information criteria on the screening grid.
    coef : ndarray
        Coefficients of the members' columns, concatenated.
    """

    members: tuple[int, ...]
    dropped: tuple[int, ...]
    n_params: int
    rss: float
    bic: float
    aic: float
    coef: np.ndarray


# ---------------------------------------------------------------------------------------------
# results
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
    alternatives : list of dict
        Candidates (library effects and empirical terms) that explained the residual as well within
        the noise when it was added: ``{name, value, unit, rms_after_arcsec}`` (+ ``angle_deg``), each
        at its own fitted size and sign.
    declared_value : float or None
        For a mis-declared error (the runs declare this error's default instance): the value declared
        (the same in every run; None otherwise).
    implied_total : float or None
        The declared value plus the correction found (the magnitude for a two-component error,
        whose declared part lies along 0 deg).
    selection : dict
        How it was chosen: ``method`` (``joint best subset`` or ``greedy``); for a joint choice the
        BIC and AIC inclusion weights (sum of the model weights of the subsets that held it, at the
        step that chose it) and the effects chosen with it (see :mod:`rvcalib.joint`).
    at_bound : str or None
        ``"lower"`` or ``"upper"`` when the size ended at that bound of the effect's range, where the residual
        does not depend on it (a pin out of contact at any larger size): the interval then runs from the
        bound to the end of the profiled confidence region, a one-sided limit (``value`` is the bound, not a
        measured size). None otherwise.
    equivalents : list of dict
        Physical parameters that give the same TE, which the data cannot tell from this effect
        (:func:`rvcalib.causes.effect_equivalents`: a profile modification for the all-pins radius and pin circle
        diameter, ``implied_design_value`` the design's value with it; :func:`rvcalib.causes.compliance_equivalents`:
        a compliance as Coulomb friction of the pins or bearings): ``{parameter, value, ci_low, ci_high, unit,
        meaning}``.
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
    alternatives: list[dict] = field(default_factory=list)
    declared_value: float | None = None
    implied_total: float | None = None
    selection: dict = field(default_factory=dict)
    at_bound: str | None = None
    equivalents: list[dict] = field(default_factory=list)

    def size_text(self) -> str:
        """The size for a verdict: ``name = value unit``, or the one-sided limit of a size at a bound of its range
        (``name >= limit unit (at its upper bound value)``)."""
        if self.at_bound == "upper":
            return f"{self.name} >= {self.ci_low:.4g} {self.unit} (at its upper bound {self.value:.4g})"
        if self.at_bound == "lower":
            return f"{self.name} <= {self.ci_high:.4g} {self.unit} (at its lower bound {self.value:.4g})"
        return f"{self.name} = {self.value:.4g} {self.unit}"

    @property
    def alternative_names(self) -> list[str]:
        """Names of the alternatives."""
        return [a["name"] for a in self.alternatives]

    def to_dict(self) -> dict:
        """JSON-ready form."""
        d = {"name": self.name, "key": self.key, "family": self.family, "value": self.value, "unit": self.unit,
             "ci_low": self.ci_low, "ci_high": self.ci_high, "std_err": self.std_err, "meaning": self.meaning,
             "params": self.params, "iteration": self.iteration, "explained_fraction": self.explained_fraction,
             "F": self.F, "p_value": self.p_value, "delta_bic": self.delta_bic, "alternatives": self.alternatives,
             "declared_value": self.declared_value, "implied_total": self.implied_total,
             "selection": self.selection, "at_bound": self.at_bound, "equivalents": self.equivalents}
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
    factor: str = "common"
    unit: str = "arcsec"
    per_run: list[dict] = field(default_factory=list)
    candidates: list[dict] = field(default_factory=list)
    equivalents: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready form. ``amplitude_arcsec`` is the coefficient (per N m for a load-proportional
        term, see ``unit``); ``per_run`` the size of the same order fitted to each run's residual after
        the physical effects (its load and direction dependence); ``candidates`` the library effects
        that could produce it, each with the size it would need and the RMS it would leave; ``equivalents`` the
        design parameters that give the same TE (:func:`rvcalib.causes.offset_equivalents`: a constant offset as a
        profile rotation)."""
        return {"label": self.label, "kind": self.kind, "order": self.order, "factor": self.factor,
                "unit": self.unit, "amplitude_arcsec": self.amplitude_arcsec, "phase_deg": self.phase_deg,
                "iteration": self.iteration, "explained_fraction": self.explained_fraction, "note": self.note,
                "per_run": self.per_run, "candidates": self.candidates, "equivalents": self.equivalents}


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
    stopped_by : str
        What ended the search (nothing more significant, the term limit, the time budget).
    groups : list of dict
        Identifiability groups: effects (and empirical terms) the data cannot tell apart, each member
        with its size and the RMS it leaves (see :meth:`rvcalib.groups.GroupsMixin.identifiability_groups`).
    recommended_runs : list of dict
        Extra runs that would split each group, chosen by a D-optimal criterion on the members'
        sensitivities.
    declared_case, calibrated_case : dict
        The reducer as the dataset declares it (its design and the first run's declared errors) and as calibrated
        (plus every physical effect found: Table 4 errors and model options), as case JSON without load and
        direction (:func:`rvcalib.causes.reducer_case`); measurement effects are not the reducer's.
    datasheet : dict
        The datasheet figures of the declared and of the calibrated reducer
        (:func:`rvcalib.causes.calibrated_datasheet`; the CLI fills it, ``calibrate`` leaves it empty: it costs
        two stiffness sweeps).
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
    stopped_by: str = ""
    groups: list[dict] = field(default_factory=list)
    recommended_runs: list[dict] = field(default_factory=list)
    declared_case: dict = field(default_factory=dict)
    calibrated_case: dict = field(default_factory=dict)
    datasheet: dict = field(default_factory=dict)

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
        return {"dataset": str(self.dataset.path), "reducer": self.dataset.reducer(), "ratio": self.dataset.ratio,
                "status": self.status, "verdict": self.verdict,
                "rms_before_arcsec": self.rms_before, "rms_after_arcsec": self.rms_after,
                "rms_after_physical_arcsec": self.after_physical.rms, "noise_arcsec": self.noise_arcsec,
                "white_after": self.after.white,
                "effects": [e.to_dict() for e in self.effects],
                "unexplained": [u.to_dict() for u in self.unexplained],
                "dependence_before": self.before.dependence, "dependence_after": self.after.dependence,
                "stopped_by": self.stopped_by, "groups": self.groups, "recommended_runs": self.recommended_runs,
                "runs": runs, "iterations": self.iterations, "notes": self.notes, "steps": self.steps,
                "seconds": self.seconds, "solver": self.solver_stats, "declared_case": self.declared_case,
                "calibrated_case": self.calibrated_case, "datasheet": self.datasheet}
